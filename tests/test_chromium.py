"""Our headless Chromium starts the processes its pages need, and no renderer for its own UI."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from playwright.async_api import Browser

pytestmark = [
    pytest.mark.browser,
    pytest.mark.asyncio(loop_scope="module"),
    pytest.mark.skipif(shutil.which("chromium") is None, reason="needs Debian's chromium"),
]


def descendants(root: int) -> dict[int, list[str]]:
    """Every process under ``root``, with its command line split into arguments."""
    parents: dict[int, int] = {}
    commands: dict[int, list[str]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            command = (entry / "cmdline").read_bytes()
        except OSError:  # ended while we looked
            continue
        pid = int(entry.name)
        parents[pid] = int(stat[stat.rindex(")") + 2 :].split()[1])
        # Chromium's children rewrite their title into one space-separated string.
        commands[pid] = command.replace(b"\0", b" ").decode(errors="replace").split()
    found: dict[int, list[str]] = {}
    frontier = {root}
    while frontier:
        frontier = {pid for pid, parent in parents.items() if parent in frontier}
        found.update((pid, commands[pid]) for pid in frontier)
    return found


async def test_only_the_page_gets_a_renderer(module_browser: Browser) -> None:
    session = await module_browser.new_browser_cdp_session()
    info = await session.send("SystemInfo.getProcessInfo")
    browser_pid = next(p["id"] for p in info["processInfo"] if p["type"] == "browser")
    assert os.path.exists(f"/proc/{browser_pid}")  # the same process namespace as ours
    page = await module_browser.new_page()
    await page.goto("about:blank")
    await page.evaluate("1 + 1")  # the page's renderer is up
    renderers = [args for args in descendants(browser_pid).values() if "--type=renderer" in args]
    assert renderers, "the page's renderer is missing: the walk found no renderer"
    # Chromium 156 preloads its omnibox popup, a web page, in a renderer of its own at every
    # start (0.7 CPU-seconds); BASE_FLAGS turn it off. A new Chromium that renames the
    # feature shows up here.
    ui = [args for args in renderers if "--top-chrome-webui" in args]
    assert not ui, ui
    await page.close()
