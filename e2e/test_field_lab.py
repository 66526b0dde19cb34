"""The whole system across the field lab: the agent at the robot site behind its NAT, the server,
coturn and the relay in the cloud, the client page at the operator site behind another NAT.

Run inside the private namespace: ``scripts/in-netns python3 -m pytest e2e/test_field_lab.py``.
"""

from __future__ import annotations

import json
import math
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import Page, Playwright

from app.tools.browser import chromium_args, chromium_path
from app.tools.lab import Lab
from app.tools.lab.lab import CLOUD
from e2e.conftest import artifacts_dir
from tests.helpers.waiting import wait_until

pytestmark = [pytest.mark.e2e, pytest.mark.browser, pytest.mark.slow]

PORT = 8000
SERVER = f"http://{CLOUD}:{PORT}"
ROOM = "field"
# The agent's synthetic face holds on the left, then on the right (vehicle_agent.video.SweepPath):
# seen from the terrain centre that is about 170 degrees, then about 10.
LEFT = (150.0, 180.0)
RIGHT = (0.0, 30.0)


@pytest.fixture(scope="module")
def lab() -> Iterator[Lab]:
    with Lab() as built:
        yield built


@dataclass
class Field:
    """The running system in the lab; ``events`` reads what the agent recorded so far."""

    lab: Lab
    agent: subprocess.Popen[Any]
    events_path: Path
    client: Page

    def events(self, kind: str | None = None) -> list[dict[str, Any]]:
        lines = self.events_path.read_text().splitlines() if self.events_path.exists() else []
        events = [json.loads(line) for line in lines if line.endswith("}")]
        return [e for e in events if kind is None or e["ev"] == kind]

    def heading_deg(self) -> float | None:
        poses = self.events("pose")
        return math.degrees(poses[-1]["theta"]) % 360 if poses else None

    def heading_within(self, band: tuple[float, float]) -> bool:
        heading = self.heading_deg()
        return heading is not None and band[0] <= heading <= band[1]


def _start(
    lab: Lab, playwright: Playwright, request: pytest.FixtureRequest, condition: str
) -> Iterator[Field]:
    lab.apply(condition)
    folder = artifacts_dir(request)
    events_path = folder / "agent-events.jsonl"
    events_path.unlink(missing_ok=True)
    logs = [(folder / f"{name}.log").open("w") for name in ("server", "relay", "agent")]
    server_log, relay_log, agent_log = logs
    started = [
        lab.python(
            "cloud",
            ["-m", "app.cli", "serve", "--host", CLOUD, "--port", str(PORT)],
            env=lab.server_env(),
            stdout=server_log,
            stderr=subprocess.STDOUT,
        )
    ]
    browser = None
    try:
        lab.wait_for_tcp("cloud", (CLOUD, PORT))
        started.append(
            lab.python(
                "cloud",
                ["-m", "app.cli", "relay", "--server", SERVER, "--room", ROOM],
                stdout=relay_log,
                stderr=subprocess.STDOUT,
            )
        )
        agent = lab.python(
            "robot",
            ["-m", "app.cli", "-v", "vehicle", "--server", SERVER, "--room", ROOM]
            + ["--events", str(events_path)],
            stdout=agent_log,
            stderr=subprocess.STDOUT,
        )
        started.append(agent)
        browser = playwright.chromium.launch(
            executable_path=str(lab.chromium("operator", chromium_path())),
            args=chromium_args(),
            headless=True,
        )
        client = browser.new_page()
        console: list[str] = []
        client.on("console", lambda message: console.append(f"{message.type}: {message.text}"))
        client.goto(f"{SERVER}/client?room={ROOM}&name=client&auto=1")
        field = Field(lab, agent, events_path, client)
        yield field
        client.screenshot(path=str(folder / "client.png"), full_page=True)
        (folder / "client.console.log").write_text("\n".join(console) + "\n")
    finally:
        if browser is not None:
            browser.close()
        for process in reversed(started):
            lab.stop(process)
        for log in logs:
            log.close()


@pytest.fixture
def field(lab: Lab, playwright: Playwright, request: pytest.FixtureRequest) -> Iterator[Field]:
    yield from _start(lab, playwright, request, request.param)


def _start_piloting(field: Field) -> None:
    start = field.client.get_by_role("button", name="Start Piloting")
    field.client.wait_for_function(
        "() => !document.querySelector('[data-action=start]').disabled", timeout=120_000
    )
    start.click()


def _turns_to_the_face_both_ways(field: Field) -> None:
    wait_until(lambda: bool(field.events("goal")), 90, "the first goal at the agent")
    wait_until(lambda: field.heading_within(LEFT), 60, "the turtle to face the face on the left")
    wait_until(lambda: field.heading_within(RIGHT), 60, "the turtle to face the face on the right")


@pytest.mark.parametrize("field", ["clean", "turn_only"], indirect=True)
def test_the_turtle_turns_to_the_face_across_the_nats(field: Field) -> None:
    _start_piloting(field)
    _turns_to_the_face_both_ways(field)
    up = field.events("link")[0]
    assert up["state"] == "up"
    assert field.events("goal_dropped") == [] or all(
        e["why"] in ("old", "stale") for e in field.events("goal_dropped")
    )
    if field.lab.condition.ice_transport_policy == "relay":
        # The agent gathered relayed candidates only (a relayed candidate exists only after
        # coturn accepted the credentials the server minted for this login), so the link it
        # piloted through went through coturn.
        assert up["local_candidates"] == ["relay"]
    else:
        assert "host" in up["local_candidates"]


@pytest.mark.parametrize("field", ["link_drop"], indirect=True)
def test_a_link_outage_stops_the_turtle_and_piloting_resumes_by_itself(field: Field) -> None:
    _start_piloting(field)
    wait_until(lambda: len(field.events("goal")) >= 20, 90, "goals to flow")
    outage = field.lab.condition.outage_s
    with field.lab.outage():
        dark_at = time.monotonic()
        time.sleep(outage)
    back_at = time.monotonic()
    # Goals resume by themselves: no agent restart, no page reload.
    wait_until(
        lambda: any(e["t"] > back_at for e in field.events("goal")), 60, "goals after the outage"
    )
    assert field.agent.poll() is None, "the agent restarted"
    goals = field.events("goal")
    last_before = max(e["t"] for e in goals if e["t"] < dark_at + 0.1)
    stops = [
        e
        for e in field.events("twist")
        if e["seq"] is None and e["angular"] == 0 and last_before < e["t"] < back_at
    ]
    assert stops, "no zero Twist while the link was dark"
    first_after = min(e["t"] for e in goals if e["t"] > back_at)
    # Measured here for the report; the targets (0.75 s, 3 s) belong to the bench.
    print(
        f"link_drop: stop {stops[0]['t'] - last_before:.2f} s after the last goal, "
        f"goals again {first_after - back_at:.2f} s after the link came back"
    )
