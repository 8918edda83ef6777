"""No private name crosses a module boundary inside ``becos`` (issue #32, item 4).

A name with a leading underscore (not a dunder) is its module's own. The test parses every module of
the package and the workflow's Snakemake files (nothing is imported) and collects:

- ``from becos.x import _y`` (relative imports too) in one ``becos`` module;
- ``x._y`` where ``x`` is a ``becos`` module the file imported (``import becos.x as x``,
  ``from becos import x``, or the dotted ``becos.x._y``);
- ``__all__`` lists naming a private name;
- ``bw._y`` / ``becos.x._y`` in ``Snakefile`` and ``workflow/rules/*.smk``.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

from test_imports import package_modules

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "becos"
SNAKE_FILES = [ROOT / "Snakefile", *sorted((ROOT / "workflow").rglob("*.smk"))]
SNAKE_PRIVATE = re.compile(r"\b(?:bw|becos(?:\.\w+)*)\.(_[A-Za-z]\w*)")


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def _dotted(node: ast.expr) -> str | None:
    """``a.b.c`` of a Name/Attribute chain, else None."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return None
    return ".".join([node.id, *reversed(parts)])


def private_uses(package: Path = PACKAGE) -> list[str]:
    """``"module: what"`` for every private name used across modules of the package (the docstring)."""
    root = package.name
    modules = package_modules(package)
    out = []
    for name, path in sorted(modules.items(), key=lambda item: item[1]):
        parent = name if path.name == "__init__.py" else name.rpartition(".")[0]
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        aliases: set[str] = set()  # local names bound to becos modules
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name.split(".")[0] == root:
                        aliases.add(alias.asname or root)
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = parent.split(".")
                    anchor = anchor[: len(anchor) - (node.level - 1)]
                    base = ".".join(anchor + ([base] if base else []))
                if base.split(".")[0] != root:
                    continue
                for alias in node.names:
                    if f"{base}.{alias.name}" in modules:
                        aliases.add(alias.asname or alias.name)
                    elif _private(alias.name) and base != name:
                        out.append(f"{name}: from {base} import {alias.name}")
            elif isinstance(node, ast.Attribute) and _private(node.attr):
                owner = _dotted(node.value)
                if owner is not None and owner.split(".")[0] in aliases:
                    out.append(f"{name}: {owner}.{node.attr}")
            elif isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
            ):
                if isinstance(node.value, (ast.List, ast.Tuple)):
                    for elt in node.value.elts:
                        if isinstance(elt, ast.Constant) and isinstance(elt.value, str) and _private(elt.value):
                            out.append(f"{name}: __all__ names {elt.value}")
    return sorted(set(out))


def snake_private_uses(files: list[Path] = SNAKE_FILES) -> list[str]:
    out = []
    for path in files:
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            for match in SNAKE_PRIVATE.finditer(line):
                label = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
                out.append(f"{label}:{number}: {match.group(0)}")
    return out


def test_the_finder_sees_every_kind(tmp_path):
    files = {
        "__init__.py": "from pkg.a import _x\n__all__ = ['_x', 'y', '__version__']\n",
        "a.py": "_x = 1\ndef _own(): return _x\n",
        "b.py": "from . import a\nimport pkg.a as m\nfrom .a import _x as z\nprint(a._x, m._x, a.__name__)\n",
        "c.py": "import pkg.a\ndef f(self):\n    return pkg.a._x, self._y, pkg.a.y\n",
    }
    (tmp_path / "pkg").mkdir()
    for name, text in files.items():
        (tmp_path / "pkg" / name).write_text(text)
    assert private_uses(tmp_path / "pkg") == [
        "pkg.b: a._x",
        "pkg.b: from pkg.a import _x",
        "pkg.b: m._x",
        "pkg.c: pkg.a._x",
        "pkg: __all__ names _x",
        "pkg: from pkg.a import _x",
    ]
    smk = tmp_path / "x.smk"
    smk.write_text("params: bw._entry(x), bw.entry(y), becos.products.store._read(z)\n")
    assert [line.split(": ", 1)[1] for line in snake_private_uses([smk])] == ["bw._entry", "becos.products.store._read"]


def test_no_private_name_crosses_a_module():
    found = private_uses() + snake_private_uses()
    assert not found, "private names used across modules:\n" + "\n".join(found)
