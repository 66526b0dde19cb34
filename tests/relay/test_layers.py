"""The relay package's dependencies point one way: the command over the service and the pool,
both over what they share, and nothing of the tools beneath any of it."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

PROBE = """
import importlib, json, sys
importlib.import_module(sys.argv[1])
print(json.dumps(sorted(sys.modules)))
"""


def loaded_by(module: str) -> set[str]:
    """Every module a fresh interpreter holds after importing ``module``."""
    done = subprocess.run(
        [sys.executable, "-c", PROBE, module],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return set(json.loads(done.stdout))


@pytest.mark.parametrize(
    ("module", "not_loaded"),
    [
        # The one-room relay needs no Redis: only `--pool` loads it.
        ("app.relay.cli", {"app.relay.pool", "redis"}),
        ("app.relay.service", {"app.relay.pool", "app.relay.cli", "app.relay.metrics"}),
        ("app.relay.pool", {"app.relay.service", "app.relay.cli", "app.relay.metrics"}),
        ("app.relay.metrics", {"app.relay.service", "app.relay.pool", "app.relay.cli"}),
        ("app.relay.page", {"app.relay.service", "app.relay.pool", "playwright"}),
    ],
)
def test_each_relay_module_loads_only_what_it_stands_on(module: str, not_loaded: set[str]) -> None:
    loaded = loaded_by(module)
    assert module in loaded
    assert not loaded & not_loaded, sorted(loaded & not_loaded)
    tools = sorted(name for name in loaded if name.startswith("app.tools"))
    assert tools == [], f"{module} loads the tools: {tools}"
