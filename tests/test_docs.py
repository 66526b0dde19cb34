"""The docs stay true: their links resolve, the files and commands they name exist, and nothing
cites a document outside the repository. Cheap checks on the text, run in every lane."""

from __future__ import annotations

import argparse
import importlib
import re
import subprocess
from functools import cache
from pathlib import Path

import pytest

from app.cli import SUBCOMMANDS
from app.server import tls
from app.server.config import Settings

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
# The pages a reader lands on: the README, every page under docs/ and the agent's README.
PAGES = sorted([README, ROOT / "vehicle_agent" / "README.md", *(ROOT / "docs").rglob("*.md")])
# The pages that describe the code as it is now (docs/bench/ holds dated reports and notes).
CURRENT = [page for page in PAGES if page.parent.name != "bench"]
README_MAX_LINES = 250

LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
CODE_SPAN = re.compile(r"`([^`\n]+)`")
FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.MULTILINE | re.DOTALL)
HEADING = re.compile(r"^#{1,6} +(.+?) *$", re.MULTILINE)
# A section cited as `docs/NAME.md, "Section"` (or without the comma), in code or docs.
CITED_SECTION = re.compile(r'docs/([\w/.-]+\.md),? "([^"]+)"')
# A path in backticks: letters, digits and _.-/, with a slash, ending in a known extension or /.
PATH = re.compile(r"^[\w.-]+(?:/[\w.-]+)+(?:\.(?:py|js|md|json|html|yml|css)|/)$")
PATH_ROOTS = ("", "app/static/", "app/static/js/")
# Not read for cited sections: this file's own examples, and the vendored OpenCV.js builds.
SKIP_CITING = {Path(__file__).name, "opencv.js", "opencv-simd.js"}


def relative(page: Path) -> str:
    return str(page.relative_to(ROOT))


@cache
def tracked_files() -> list[Path]:
    listed = subprocess.run(
        ["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True
    ).stdout.decode()
    return [ROOT / name for name in listed.split("\0") if name]


def slug(heading: str) -> str:
    """The anchor GitHub gives a heading: lower case, markup and punctuation dropped, each space
    a hyphen."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading).lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def headings(page: Path) -> list[str]:
    text = FENCE.sub("", page.read_text())
    return [h.replace("`", "") for h in HEADING.findall(text)]


def links(page: Path) -> list[str]:
    text = FENCE.sub("", page.read_text())
    return [t for t in LINK.findall(text) if not re.match(r"[a-z]+:", t)]


@pytest.mark.parametrize("page", PAGES, ids=relative)
def test_every_relative_link_resolves(page: Path) -> None:
    broken = []
    for target in links(page):
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if not file.exists():
            broken.append(f"{target}: no such file")
        elif anchor and file.suffix == ".md" and anchor not in {slug(h) for h in headings(file)}:
            broken.append(f"{target}: no such section in {relative(file)}")
    assert not broken, f"{relative(page)}: " + "; ".join(broken)


@pytest.mark.parametrize("page", CURRENT, ids=relative)
def test_every_path_in_backticks_exists(page: Path) -> None:
    named = {span for span in CODE_SPAN.findall(page.read_text()) if PATH.match(span)}
    missing = [p for p in sorted(named) if not any((ROOT / f"{r}{p}").exists() for r in PATH_ROOTS)]
    assert not missing, f"{relative(page)} names files that do not exist: {missing}"


def test_nothing_cites_a_document_outside_the_repository() -> None:
    # Spelt apart, so that this file does not cite it either.
    outside = ("DESIGN" + " §", "DESIGN" + ".md", "../" + "sha" + "red/", "sha" + "red/docs")
    citing = []
    for file in tracked_files():
        if file.suffix in {".png", ".jpg", ".mp4", ".y4m", ".wasm"} or "opencv" in file.name:
            continue
        text = file.read_text(errors="replace")
        citing += [f"{relative(file)}: {w}" for w in outside if w in text]
    assert not citing, citing


def test_every_cited_section_exists() -> None:
    """``docs/architecture.md, "Lossy links"`` in a comment names a heading of that page (its
    start), read with comment markers and line breaks folded into spaces."""
    wrong = []
    for file in tracked_files():
        if file.suffix not in {".py", ".js", ".md", ".html"} or file.name in SKIP_CITING:
            continue
        text = re.sub(r"\s*\n\s*(?:#|//|\*)?\s*", " ", file.read_text())
        for page, section in CITED_SECTION.findall(text):
            target = ROOT / "docs" / page
            if not target.exists():
                wrong.append(f"{relative(file)}: docs/{page} does not exist")
            elif not any(h.startswith(section) for h in headings(target)):
                wrong.append(f'{relative(file)}: no section "{section}" in docs/{page}')
    assert not wrong, wrong


def test_the_readme_fits_in_250_lines() -> None:
    lines = len(README.read_text().splitlines())
    assert lines <= README_MAX_LINES, f"README.md has {lines} lines; move detail into docs/"


@cache
def options_of(command: str) -> set[str]:
    parser = argparse.ArgumentParser()
    importlib.import_module(SUBCOMMANDS[command][0]).add_arguments(parser)
    return {o for action in parser._actions for o in action.option_strings}


def shown_commands(page: Path) -> list[str]:
    """Every ``autopilot ...`` command the page shows, in code spans and code blocks, up to
    where a shell would start another command."""
    text = page.read_text()
    blocks = [b.replace("\\\n", " ") for b in FENCE.findall(text)]
    spans = CODE_SPAN.findall(FENCE.sub("", text))
    commands = []
    for chunk in [*spans, *(line for b in blocks for line in b.splitlines())]:
        for found in re.finditer(r"(?<![\w-])autopilot ([a-z][a-z-]*)(.*)", chunk):
            rest = re.split(r" (?:\||&&|;|&|#) ?|\)|`", found.group(2))[0]
            commands.append(f"{found.group(1)}{rest}")
    return commands


@pytest.mark.parametrize("page", CURRENT, ids=relative)
def test_the_commands_shown_exist_with_their_flags(page: Path) -> None:
    wrong = []
    for command in shown_commands(page):
        name, *words = command.split()
        if name not in SUBCOMMANDS:
            wrong.append(f"autopilot {name}: no such command")
            continue
        for flag in (w.split("=")[0] for w in words if w.startswith("--")):
            if flag not in options_of(name):
                wrong.append(f"autopilot {name} {flag}: no such option")
    assert not wrong, f"{relative(page)}: {sorted(set(wrong))}"


def test_the_readme_shows_the_two_commands_and_the_main_ones() -> None:
    text = README.read_text()
    for command in ("scripts/demo", "scripts/test", "autopilot serve", "autopilot vehicle"):
        assert command in text
    assert {c.split()[0] for c in shown_commands(README)} >= {"demo", "relay", "token", "bench"}


def test_every_setting_is_in_the_configuration_page() -> None:
    page = (ROOT / "docs" / "configuration.md").read_text()
    missing = [
        f"AUTOPILOT_{name.upper()}"
        for name in Settings.model_fields
        if name != "token" and f"AUTOPILOT_{name.upper()}" not in page
    ]
    assert not missing, f"docs/configuration.md does not describe {missing}"


def test_the_deploying_page_gives_the_trust_line_the_server_prints() -> None:
    page = (ROOT / "docs" / "deploying.md").read_text()
    assert tls.chromium_trust_command("ca.pem") in page
