"""Suite-wide scheduling for ``scripts/test``'s xdist workers (``--dist loadgroup``).

Two rules, both about the two cores this suite shares:

- **Longest first.** The workers take tests in collection order, so the few long runs (the
  benches, then the browser flows) start first and the many short tests fill the other workers
  around them, instead of a long run starting last and holding the whole suite up.
- **A module-scoped fixture is set up once.** Tests that share one (a headless Chromium with
  OpenCV.js loaded, a parity harness, a Redis server) form one xdist group, so they run on one
  worker and pay for it once, not once per worker. The other tests of the module stay free.
"""

from __future__ import annotations

import pytest

# Lower ranks start first: the markers of tests that take tens of seconds, longest kind first.
_RANKS = ("bench", "e2e", "browser")


def _rank(item: pytest.Item) -> int:
    return next(
        (rank for rank, name in enumerate(_RANKS) if item.get_closest_marker(name)), len(_RANKS)
    )


def _shares_a_module_fixture(item: pytest.Item) -> bool:
    info = getattr(item, "_fixtureinfo", None)
    if info is None:
        return False
    return any(
        definition.scope == "module"
        for definitions in info.name2fixturedefs.values()
        for definition in definitions
    )


@pytest.hookimpl(tryfirst=True)  # before xdist turns the group marks into node ids
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Group the tests of a module-scoped fixture; order longest first (``sorted`` is stable,
    so within a rank the collection order stays and a module's tests stay together)."""
    for item in items:
        if _shares_a_module_fixture(item):
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::", 1)[0]))
    items[:] = sorted(items, key=_rank)
