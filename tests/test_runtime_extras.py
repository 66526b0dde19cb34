"""``scripts/demo`` installs only the runtime extras (``scripts/setup --runtime``: ``.[tools]``), so
nothing the demo runs may need a package that only the bench or the dev tools bring."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tomllib
from importlib.metadata import packages_distributions
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# The modules of the demo's three processes: the demo with its server, the relay, the agent.
DEMO_MODULES = ("app.tools.demo", "app.relay.cli", "vehicle_agent.cli")
PROBE = """
import importlib, json, sys
for name in sys.argv[1:]:
    importlib.import_module(name)
print(json.dumps(sorted({m.split(".")[0] for m in sys.modules})))
"""


def requirement_names(extra: str) -> set[str]:
    """The distributions an extra names itself, without the project's own extras."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]
    names = {re.split(r"[\[<>=!~; ]", r, maxsplit=1)[0].lower() for r in extras[extra]}
    return {n.replace("_", "-") for n in names} - {"webrtc-autopilot"}


def test_the_demo_loads_nothing_that_only_the_bench_or_the_dev_tools_install() -> None:
    beyond_runtime = requirement_names("dev") | requirement_names("bench")
    done = subprocess.run(
        [sys.executable, "-c", PROBE, *DEMO_MODULES],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    distributions = packages_distributions()
    needed = {
        (module, dist)
        for module in json.loads(done.stdout)
        for dist in distributions.get(module, [])
        if dist.lower().replace("_", "-") in beyond_runtime
    }
    assert not needed, f"the demo would need more than scripts/setup --runtime installs: {needed}"


def test_scripts_demo_sets_up_the_runtime_only() -> None:
    demo = (ROOT / "scripts" / "demo").read_text()
    assert "scripts/setup --runtime" in demo
    setup = (ROOT / "scripts" / "setup").read_text()
    assert "extras=tools" in setup and "extras=dev" in setup


# The tests' outside rosbridge client and what it runs on: none of it is the product's.
OUTSIDE_CLIENT = ("roslibpy", "twisted", "autobahn", "txaio")
IMPORT_ALL = """
import importlib, json, pkgutil, sys
import app, vehicle_agent
for package in (app, vehicle_agent):
    for module in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
        if not module.name.endswith("__main__"):  # that one runs the command
            importlib.import_module(module.name)
print(json.dumps(sorted({m.split(".")[0] for m in sys.modules})))
"""


def test_no_module_of_the_product_loads_roslibpy_or_twisted() -> None:
    done = subprocess.run(
        [sys.executable, "-c", IMPORT_ALL], capture_output=True, text=True, timeout=120, check=False
    )
    assert done.returncode == 0, done.stderr
    loaded = set(json.loads(done.stdout))
    assert "vehicle_agent" in loaded and "aiortc" in loaded
    assert not loaded & set(OUTSIDE_CLIENT), sorted(loaded & set(OUTSIDE_CLIENT))
    assert "roslibpy" in requirement_names("dev")
    assert not {"roslibpy", "twisted"} & (requirement_names("agent") | requirement_names("tools"))
