"""The layers of docs/architecture.md ("Layers") hold in the code: every Python package and module
of the project stands in one row of the layer diagram, every name of the diagram is one of them,
and none imports from a row above its own or from another package beside it on its row; every
JavaScript module of the role pages imports only what the layer table's
"imports" column lets its folder import. The rows are read from the document itself, so a row
added, moved or dropped there is checked here at once."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ARCHITECTURE = ROOT / "docs" / "architecture.md"
JS = ROOT / "app" / "static" / "js"
# Where the diagram's Python rows stand: the first fenced block under "## Layers".
PACKAGES = ("app", "vehicle_agent")


def _layers_section() -> str:
    text = ARCHITECTURE.read_text()
    start = text.index("## Layers")
    return text[start : text.index("\n## ", start + 1)]


def python_rows() -> list[list[str]]:
    """The diagram's rows, top first, each the dotted names of the packages and modules on it."""
    block = _layers_section().split("```")[1]
    rows = []
    for line in block.splitlines():
        if not line or line[0].isspace():
            continue  # a description's continuation
        names = re.findall(r"(?<!\S)((?:app|vehicle_agent)/[\w./]*)", line)
        dotted = {n.removesuffix("/").removesuffix(".py").replace("/", ".") for n in names}
        if dotted:
            rows.append(sorted(dotted))
    return rows


def js_rules() -> dict[str, tuple[str, ...] | None]:
    """Each folder of the table (or ``config.js``): what it may import, as paths under js/
    (a folder ends with ``/``); None for "everything"."""
    rules: dict[str, tuple[str, ...] | None] = {}
    for line in _layers_section().splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if len(cells) != 3 or not cells[0].startswith("`"):
            continue
        folder = cells[0].strip("`")
        imports = cells[2]
        if imports == "everything":
            rules[folder] = None
            continue
        allowed = re.findall(r"`([\w./-]+)`", imports)
        rules[folder] = tuple(a for a in allowed if a.endswith(("/", ".js")))
    return rules


def project_modules() -> dict[str, Path]:
    """Every Python module of the project, by dotted name."""
    found = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found[".".join(parts)] = path
    return found


def placed(module: str, rows: list[list[str]]) -> str | None:
    """The diagram's name that holds ``module``: the module or package itself, or the longest
    name of a package it is in."""
    names = [n for row in rows for n in row if module == n or module.startswith(n + ".")]
    return max(names, key=len, default=None)


def row_of(module: str, rows: list[list[str]]) -> int | None:
    """The index of the row that holds ``module`` (or the package it is in)."""
    name = placed(module, rows)
    return None if name is None else next(i for i, row in enumerate(rows) if name in row)


def imports_of(path: Path) -> set[str]:
    """The project modules ``path`` imports, anywhere in it (functions and type checks too)."""
    tree = ast.parse(path.read_text())
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            found |= {f"{node.module}.{alias.name}" for alias in node.names}
    return {name for name in found if name.split(".")[0] in PACKAGES}


def test_the_diagram_has_the_rows_it_is_known_by() -> None:
    rows = python_rows()
    assert rows[0] == ["app.cli"] and "app.protocol" in rows[-1], rows
    assert ["app.server", "vehicle_agent"] in rows


def test_every_python_module_stands_in_a_row_of_the_diagram() -> None:
    rows = python_rows()
    unplaced = sorted(m for m in project_modules() if m not in PACKAGES and row_of(m, rows) is None)
    assert unplaced == [], f"not in the diagram of docs/architecture.md: {unplaced}"


def test_every_name_of_the_diagram_is_a_module_or_package_of_the_project() -> None:
    modules = project_modules()
    missing = [name for row in python_rows() for name in row if name not in modules]
    assert missing == [], f"the diagram of docs/architecture.md names what is gone: {missing}"


def test_the_packages_of_a_row_stand_side_by_side() -> None:
    """A row's packages import none of each other: the row above them is the one that uses
    both."""
    rows = python_rows()
    sideways = []
    for module, path in sorted(project_modules().items()):
        own = row_of(module, rows)
        if own is None:
            continue
        for imported in imports_of(path):
            if row_of(imported, rows) == own and placed(imported, rows) != placed(module, rows):
                sideways.append(f"{module} imports {imported}, beside it on row {own}")
    assert sideways == []


def test_no_python_module_imports_from_a_row_above_its_own() -> None:
    rows = python_rows()
    modules = project_modules()
    upward = []
    for module, path in sorted(modules.items()):
        own = row_of(module, rows)
        if own is None:
            continue
        for imported in imports_of(path):
            target = row_of(imported, rows)
            if target is not None and target < own:
                upward.append(f"{module} ({own}) imports {imported} ({target})")
    assert upward == []


def test_the_python_vehicle_never_imports_the_server() -> None:
    modules = project_modules()
    found = [
        (module, imported)
        for module, path in modules.items()
        if module.startswith("vehicle_agent")
        for imported in imports_of(path)
        if imported.startswith("app.server")
    ]
    assert found == []


IMPORT = re.compile(r"""(?:^|\n)\s*(?:import|export)\b[^'"]*?from\s*['"]([^'"]+)['"]""")
DYNAMIC = re.compile(r"""\bimport\(\s*['"]([^'"]+)['"]\s*\)|new URL\(\s*['"]([^'"]+\.js)['"]""")


def js_imports(path: Path) -> set[str]:
    """The modules ``path`` imports (statically, dynamically, or starts as a worker), as paths
    under js/."""
    text = path.read_text()
    specs = set(IMPORT.findall(text)) | {a or b for a, b in DYNAMIC.findall(text)}
    return {
        (path.parent / spec).resolve().relative_to(JS).as_posix()
        for spec in specs
        if spec.startswith(".")
    }


def js_folder(module: str) -> str:
    return module.split("/")[0] + "/" if "/" in module else module


def test_every_js_folder_is_a_row_of_the_table() -> None:
    rules = js_rules()
    folders = {js_folder(p.relative_to(JS).as_posix()) for p in JS.rglob("*.js")}
    assert folders == set(rules), "the layer table names other folders than js/ holds"


@pytest.mark.parametrize("module", sorted(p.relative_to(JS).as_posix() for p in JS.rglob("*.js")))
def test_each_js_module_imports_only_what_its_folder_may(module: str) -> None:
    folder = js_folder(module)
    allowed = js_rules()[folder]
    if allowed is None:
        return  # pages: everything
    wrong = [
        imported
        for imported in sorted(js_imports(JS / module))
        if js_folder(imported) != folder
        and not any(imported == a or (a.endswith("/") and imported.startswith(a)) for a in allowed)
    ]
    assert wrong == [], f"{module} ({folder}) may import {allowed}, not {wrong}"


EXPORT = re.compile(
    r"^export\s+(?:async\s+)?(?:function\*?|class|const|let)\s+([A-Za-z_$][\w$]*)"
    r"|^export\s*\{([^}]*)\}",
    re.M,
)
# What the relay's worker loads by name from its spec (``import(`./operations/${module}`)``):
# the operation interface every module there offers (docs/operations.md).
OPERATION_INTERFACE = ("worker/operations/", "create")


def js_exports(text: str) -> list[str]:
    """The names a module exports (``export function f``, ``export { a as b } from ...``)."""
    names = []
    for declared, listed in EXPORT.findall(text):
        names += (
            [declared] if declared else [n.split(" as ")[-1].strip() for n in listed.split(",")]
        )
    return [n for n in names if n]


def test_every_js_export_is_used_by_another_page_module() -> None:
    """An export is a module's interface to the pages. One that only a test reaches would be an
    interface for the tests alone: they go through the public one instead."""
    modules = {p.relative_to(JS).as_posix(): p for p in JS.rglob("*.js")}
    importers: dict[str, list[str]] = {}
    for module, path in modules.items():
        for imported in js_imports(path):
            importers.setdefault(imported, []).append(modules[module].read_text())
    unused = [
        f"{module}: {name}"
        for module, path in sorted(modules.items())
        for name in js_exports(path.read_text())
        if (module.startswith(OPERATION_INTERFACE[0]), name) != (True, OPERATION_INTERFACE[1])
        and not any(
            re.search(rf"\b{re.escape(name)}\b", text) for text in importers.get(module, [])
        )
    ]
    assert unused == []
