"""The docs agree with the package: docs/architecture.md's module table names every module and subpackage
of ``becos`` (and, for a subpackage, every module in it) and nothing that is gone; the README's first
screen holds the set-up and main-job command and the test command that CI runs."""

from __future__ import annotations

import ast
import re
from pathlib import Path

from test_imports import LAYERS

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "becos"


def _package_tree(package: Path = PACKAGE, prefix: str = "") -> dict[str, set[str]]:
    """``{module or subpackage, dotted below becos: its modules}`` (no ``__init__``/``__main__``); a layer
    package (:data:`test_imports.LAYERS`) has no row of its own: its modules and subpackages have."""
    tree: dict[str, set[str]] = {}
    for path in package.iterdir():
        if path.is_dir() and (path / "__init__.py").exists():
            if not prefix and path.name in LAYERS:
                tree.update(_package_tree(path, f"{path.name}."))
            else:
                tree[prefix + path.name] = {p.stem for p in path.glob("*.py")} - {"__init__", "__main__"}
        elif path.suffix == ".py" and path.stem not in ("__init__", "__main__"):
            tree[prefix + path.stem] = set()
    return tree


def _module_table() -> dict[str, set[str]]:
    """The rows of docs/architecture.md's module table: ``{module: modules in its second column}``."""
    rows: dict[str, set[str]] = {}
    for line in (REPO / "docs" / "architecture.md").read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        match = re.fullmatch(r"`becos\.([\w.]+)`", cells[0]) if line.startswith("| `becos.") else None
        if match and len(cells) == 3:
            assert match[1] not in rows, f"docs/architecture.md: {match[1]} has two rows"
            rows[match[1]] = set(re.findall(r"`(\w+)`", cells[1]))
    return rows


def test_module_table_matches_the_package():
    package, table = _package_tree(), _module_table()
    assert sorted(set(package) - set(table)) == [], "modules missing from docs/architecture.md's table"
    assert sorted(set(table) - set(package)) == [], "stale rows in docs/architecture.md's table"
    for name, modules in package.items():
        assert table[name] == modules, f"becos.{name}: table lists {sorted(table[name])}, package has {sorted(modules)}"


def test_readme_first_screen_holds_the_commands():
    first_screen = (REPO / "README.md").read_text().splitlines()[:40]
    ci = (REPO / ".ci" / "run").read_text().splitlines()
    test_command = ci[-1]
    assert test_command.endswith("python -m pytest -n 2 -q") and test_command in first_screen
    setup_and_run = 'python3 -m venv .venv && .venv/bin/pip install -q -e ".[test]" && .venv/bin/snakemake --cores 2'
    assert setup_and_run in first_screen


def test_module_docstrings_are_short_and_their_pages_exist():
    """A module docstring says what the module is and its contract in at most 10 lines; the design notes it
    points to (``docs/design/<page>.md``) exist."""
    long, missing = [], []
    for path in sorted(PACKAGE.rglob("*.py")):
        doc = ast.get_docstring(ast.parse(path.read_text()), clean=True) or ""
        if len(doc.strip().splitlines()) > 10:
            long.append(f"{path.relative_to(REPO)}: {len(doc.strip().splitlines())} lines")
        missing += [page for page in re.findall(r"docs/design/[\w-]+\.md", doc) if not (REPO / page).exists()]
    assert long == [], "module docstrings over 10 lines (move design notes to docs/design/)"
    assert missing == []
