"""``autopilot demo`` as a user runs it: it starts, prints the client URL, piloting works from
the client page, SIGTERM ends every process it started, and its flight recording replays.

Run inside the private network namespace: ``scripts/in-netns python -m pytest tests/test_demo.py``.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import ssl
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from queue import Queue
from typing import Any

import pytest
from playwright.sync_api import sync_playwright

from app.chromium import launch_options
from app.protocol import events as ev
from app.recording import EVENT_CHANNELS, IMAGE_TOPIC
from app.relay import cli as relay_cli
from app.simulators import SimulatorName
from app.tools.demo import children_for
from tests.helpers.demo import REPO, running_demo, wait_for_line
from tests.helpers.processes import descendants, wait_all_gone
from vehicle_agent import cli as agent_cli

pytestmark = [pytest.mark.browser, pytest.mark.e2e, pytest.mark.slow]


def turtle_theta(base: str, token: str, context: ssl.SSLContext | None = None) -> float:
    request = urllib.request.Request(
        f"{base}/turtlesim/state", headers={"Authorization": f"Bearer {token}"}
    )
    with urllib.request.urlopen(request, timeout=10, context=context) as response:
        state = json.load(response)
    turtle = next(t for t in state["turtles"] if t["name"] == "turtle1")
    return float(turtle["theta"])


# On loopback the demo serves plain HTTP, and records its flight for the test to replay; bound to
# every address it serves HTTPS with its own local CA (kept in --state-dir), so that the URLs it
# prints work from another machine.
SETUPS = {"loopback": ["--record", "{dir}"], "any-address": ["--host", "0.0.0.0"]}
# How long the client keeps piloting once the turtle turned, for the recording.
RECORDED_PILOTING_S = 3.0


@pytest.fixture(params=list(SETUPS))
def demo(
    request: pytest.FixtureRequest, tmp_path: Path
) -> Iterator[tuple[subprocess.Popen[str], Queue[str], Path]]:
    extra = [arg.format(dir=tmp_path) for arg in SETUPS[request.param]]
    with running_demo([*extra, "--state-dir", str(tmp_path)]) as (process, lines):
        yield process, lines, tmp_path


def test_demo_runs_pilots_and_ends_every_child_on_sigterm(
    demo: tuple[subprocess.Popen[str], Queue[str], Path],
) -> None:
    process, lines, state_dir = demo
    # The demo mints its own tokens; the client's rides in the URL fragment.
    url = wait_for_line(lines, r"(https?://\S+/client\?room=default#token=\S+)", 60).group(1)
    base = url.split("/client")[0]
    token = url.split("#token=", 1)[1]
    context = None
    ca_file: Path | None = None
    if url.startswith("https://"):
        # The first URL printed is the machine's first non-loopback address (in-netns: 10.203.0.1),
        # and its certificate is the demo's own CA's.
        assert not base.startswith("https://127."), url
        ca_file = state_dir / "ca.pem"
        context = ssl.create_default_context(cafile=str(ca_file))
    with urllib.request.urlopen(url, timeout=10, context=context) as response:
        assert response.status == 200
        assert "Start Piloting" in response.read().decode()

    with sync_playwright() as pw:
        browser = pw.chromium.launch(**launch_options(trust_ca=ca_file))
        try:
            page = browser.new_page()
            page.goto(url)
            # What a person does: Connect, Join Room, then Start Piloting once it is enabled.
            page.get_by_role("button", name="Connect").click()
            join = page.get_by_role("button", name="Join Room")
            page.wait_for_function(
                "() => !document.querySelector('[data-action=join]').disabled", timeout=30_000
            )
            join.click()
            page.wait_for_function(
                "() => !document.querySelector('[data-action=start]').disabled", timeout=120_000
            )
            before = turtle_theta(base, token, context)
            page.get_by_role("button", name="Start Piloting").click()
            clicked = time.monotonic()
            # Goals reach the agent, whose Twists turn the server's turtle through /rosbridge.
            while abs(math.remainder(turtle_theta(base, token, context) - before, math.tau)) < 0.3:
                assert time.monotonic() - clicked < 30, "the turtle did not turn after Start"
                time.sleep(0.1)
            time.sleep(RECORDED_PILOTING_S)
            (REPO / "artifacts").mkdir(exist_ok=True)
            page.screenshot(path=str(REPO / "artifacts" / f"demo-client-{base.split(':')[0]}.png"))
        finally:
            browser.close()

    children = descendants(process.pid)
    # The relay's Chromium and the agent are among them.
    assert len(children) >= 3, children
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=60) == 0
    assert wait_all_gone(children) == []
    recordings = sorted(state_dir.glob("*.mcap"))
    if ca_file is None:  # the loopback run, recorded
        check_recording(recordings)
    else:
        assert recordings == []


def check_recording(files: list[Path]) -> None:
    """The demo's flight recording holds the run, and replaying it through the relay's vision
    gives the goals the relay sent."""
    assert len(files) == 1, files

    def replay(*options: str) -> dict[str, Any]:
        argv = [sys.executable, "-m", "app.cli", "replay", *options, "--json", *map(str, files)]
        done = subprocess.run(argv, cwd=REPO, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stdout + done.stderr
        result: dict[str, Any] = json.loads(done.stdout.splitlines()[-1])
        return result

    channels = replay("--summary")["channels"]
    counts = {topic: entry["messages"] for topic, entry in channels.items()}
    # Images at the recording's 5 per second while the turtle turned and then for a while.
    assert counts[IMAGE_TOPIC] >= 5 * RECORDED_PILOTING_S, counts
    for kind in (ev.GoalApplied, ev.TwistSent, ev.PoseReport):
        assert counts[EVENT_CHANNELS[kind].topic] > 0, counts
    assert counts[EVENT_CHANNELS[ev.LinkChanged].topic] >= 2, (
        counts
    )  # offered, up (and down at the end)
    replayed = replay()
    assert replayed["goals_compared"] >= 10, replayed
    assert replayed["agreement_pct"] == 100.0, replayed


@pytest.mark.parametrize("profile", ["follow", "thesis", "onboard"])
def test_demo_profile_drives_the_vehicle_and_paces_the_relay(profile: str) -> None:
    # The relay page paces its snapshots by the relay profile the vehicle profile pairs with and
    # starts with its operation (tests/server/test_pages.py): the relay is told the vehicle's.
    relay, vehicle = children_for("http://127.0.0.1:8000", "r", profile)
    assert relay.argv[relay.argv.index("--profile") + 1] == profile
    assert vehicle.argv[vehicle.argv.index("--profile") + 1] == profile
    # Both command lines are ones the relay and the agent accept.
    for child, add_arguments in (
        (relay, relay_cli.add_arguments),
        (vehicle, agent_cli.add_arguments),
    ):
        parser = argparse.ArgumentParser()
        add_arguments(parser)
        args = parser.parse_args(child.argv[child.argv.index(child.name) + 1 :])
        assert args.profile == profile


def test_demo_two_faces_video_reaches_the_agent() -> None:
    _, vehicle = children_for("http://127.0.0.1:8000", "r", "default", video="two-faces")
    parser = argparse.ArgumentParser()
    agent_cli.add_arguments(parser)
    args = parser.parse_args(vehicle.argv[vehicle.argv.index("vehicle") + 1 :])
    assert args.video == "two-faces"


@pytest.mark.parametrize("robot", ["turtlesim", "diffdrive"])
def test_demo_agent_drives_the_servers_robot(robot: SimulatorName) -> None:
    _, vehicle = children_for("http://127.0.0.1:8000", "r", "default", robot=robot)
    parser = argparse.ArgumentParser()
    agent_cli.add_arguments(parser)
    args = parser.parse_args(vehicle.argv[vehicle.argv.index("vehicle") + 1 :])
    assert args.robot.name == robot
    # The room's robot films itself: the agent's video is its description's camera topic.
    assert (args.video == "ros") == (robot == "diffdrive")
