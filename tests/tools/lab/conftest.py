"""One lab per test module; each test starts from the ``clean`` condition."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from app.tools.lab import Lab


@pytest.fixture(scope="module")
def built_lab() -> Iterator[Lab]:
    """A lab shared by the tests of one module (building one takes about a second)."""
    with Lab() as lab:
        yield lab


@pytest.fixture
def lab(built_lab: Lab) -> Iterator[Lab]:
    """The module's lab, reset to ``clean`` with the robot link up after the test."""
    built_lab.apply("clean")
    yield built_lab
    built_lab.set_robot_link(True)
    built_lab.apply("clean")
