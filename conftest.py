"""Suite-wide ordering: the longest tests start first.

``scripts/test`` runs the suite on several xdist workers with ``--dist loadgroup``, which hands
out tests one at a time in collection order. Starting the few long runs first (the benches, then
the browser flows) lets the many short tests fill the other workers around them, instead of one
long run starting last and holding the whole suite up. Within each rank the collection order
stays, so a module's tests stay together and share their module-scoped browser.
"""

from __future__ import annotations

import pytest

# Lower ranks start first: the markers of tests that take tens of seconds, longest kind first.
_RANKS = ("bench", "e2e", "browser")


def _rank(item: pytest.Item) -> int:
    return next(
        (rank for rank, name in enumerate(_RANKS) if item.get_closest_marker(name)), len(_RANKS)
    )


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Longest-first order (stable: ``sorted`` keeps the collection order within a rank)."""
    items[:] = sorted(items, key=_rank)
