"""The whole system placed in the field lab, for tests and the field bench.

The server (with the lab's STUN/TURN and the condition's ICE policy) and the relay service run
in the cloud, the Python agent (synthetic face video, JSON-lines event log) at the robot site,
and a headless client page at the operator site, driven by Playwright through a Chromium
launcher that enters the operator's namespace.
"""

from __future__ import annotations

import contextlib
import math
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from playwright.sync_api import Browser, Page, Playwright
from playwright.sync_api import Error as PlaywrightError

from app.chromium import chromium_path, launch_options
from app.protocol.events import AnyEvent, E, PoseReport, of_kind
from app.recording import read_event_log
from app.tools.lab.lab import CLOUD, Lab
from app.tools.lab.netns import LabError

PORT = 8000
SERVER = f"http://{CLOUD}:{PORT}"
ROOM = "field"
START_ENABLED_TIMEOUT_MS = 120_000


@dataclass
class FieldStack:
    """The running system; :meth:`events` reads what the agent recorded so far."""

    lab: Lab
    agent: subprocess.Popen[Any]
    events_path: Path
    client: Page
    console: list[str]

    def all_events(self) -> list[AnyEvent]:
        """The agent's events so far, oldest first."""
        if not self.events_path.exists():
            return []
        return read_event_log(self.events_path, growing=True)

    def events(self, kind: type[E]) -> list[E]:
        """The agent's events of one kind so far, oldest first."""
        return of_kind(self.all_events(), kind)

    def heading_deg(self) -> float | None:
        """The turtle's last reported heading in [0, 360), or None before any pose."""
        poses = self.events(PoseReport)
        return math.degrees(poses[-1].theta) % 360 if poses else None

    def start_piloting(self) -> None:
        """Press Start Piloting on the client page once the relay is ready for it."""
        self.client.wait_for_function(
            "() => !document.querySelector('[data-action=start]').disabled",
            timeout=START_ENABLED_TIMEOUT_MS,
        )
        self.client.get_by_role("button", name="Start Piloting").click()


@contextlib.contextmanager
def field_stack(
    lab: Lab, playwright: Playwright, folder: Path, fps: float | None = None
) -> Iterator[FieldStack]:
    """Start everything under the lab's current condition; stop it all on exit.

    ``folder`` receives the processes' logs and the agent's event log.
    """
    folder.mkdir(parents=True, exist_ok=True)
    events_path = folder / "agent-events.jsonl"
    events_path.unlink(missing_ok=True)
    started: list[subprocess.Popen[Any]] = []
    browser: Browser | None = None
    with contextlib.ExitStack() as files:
        logs: dict[str, IO[str]] = {
            name: files.enter_context((folder / f"{name}.log").open("w"))
            for name in ("server", "relay", "agent")
        }
        try:
            server = lab.python(
                "cloud",
                ["-m", "app.cli", "serve", "--host", CLOUD, "--port", str(PORT)],
                env=lab.server_env(),
                stdout=logs["server"],
                stderr=subprocess.STDOUT,
            )
            started.append(server)
            try:
                lab.wait_for_tcp("cloud", (CLOUD, PORT), server=server)
            except LabError as exc:
                logs["server"].flush()
                tail = (folder / "server.log").read_text()[-2000:]
                raise LabError(f"{exc}; the server's log ends:\n{tail}") from exc
            started.append(
                lab.python(
                    "cloud",
                    ["-m", "app.cli", "relay", "--server", SERVER, "--room", ROOM],
                    stdout=logs["relay"],
                    stderr=subprocess.STDOUT,
                )
            )
            agent_args = ["-m", "app.cli", "vehicle", "--server", SERVER, "--room", ROOM]
            agent_args += ["--events", str(events_path)]
            if fps is not None:
                agent_args += ["--fps", str(fps)]
            agent = lab.python("robot", agent_args, stdout=logs["agent"], stderr=subprocess.STDOUT)
            started.append(agent)
            browser = playwright.chromium.launch(
                **launch_options(executable=str(lab.chromium("operator", chromium_path())))
            )
            client = browser.new_page()
            console: list[str] = []
            client.on("console", lambda message: console.append(f"{message.type}: {message.text}"))
            client.goto(f"{SERVER}/client?room={ROOM}&name=client&auto=1")
            yield FieldStack(lab, agent, events_path, client, console)
            with contextlib.suppress(PlaywrightError):  # a page that died still leaves its logs
                client.screenshot(path=str(folder / "client.png"), full_page=True)
            (folder / "client.console.log").write_text("\n".join(console) + "\n")
        finally:
            if browser is not None:
                browser.close()
            for process in reversed(started):
                lab.stop(process)
