"""Code bars of issue #32, rerunnable by anyone: no module over 800 lines and no function over 80 lines
in ``becos/`` (read with :mod:`ast`, nothing imported). The import-circle bar is ``tests/test_imports.py``."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "becos"
MAX_MODULE_LINES = 800
MAX_FUNCTION_LINES = 80


def _modules() -> dict[str, Path]:
    """Dotted name -> file of every module of the package (a package's name stands for its __init__)."""
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


MODULES = _modules()
TREES = {name: ast.parse(path.read_text(), filename=str(path)) for name, path in MODULES.items()}


def _rel(name: str) -> str:
    return str(MODULES[name].relative_to(PACKAGE.parent))


def test_no_module_over_800_lines():
    long = {_rel(n): len(p.read_text().splitlines()) for n, p in MODULES.items()}
    long = {n: lines for n, lines in long.items() if lines > MAX_MODULE_LINES}
    assert not long, f"modules over {MAX_MODULE_LINES} lines (split them along a seam): {long}"


def _long_functions() -> dict[str, int]:
    """``"<file> <name>"`` -> lines of every function (methods and nested ones too) over the bar."""
    return {
        f"{_rel(name)} {node.name}": node.end_lineno - node.lineno + 1
        for name, tree in TREES.items()
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES
    }


def test_no_function_over_80_lines():
    long = _long_functions()
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines (split them along their seams): {long}"
