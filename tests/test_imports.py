"""No import circle inside ``becos`` (issue #32, item 3).

The test parses every module of the package (``ast``, nothing is imported) and collects its imports of
``becos`` modules: ``import`` and ``from ... import`` at module level and inside functions alike
(function-local imports break a circle at run time but not in the design), relative ones resolved.
``from becos.products.export import write_dpfm`` is an edge to ``becos.products.export``; ``from becos import export`` and
``import becos.products.export.dpfm`` to the module named. Imports under ``if TYPE_CHECKING:`` are left out
(they never run). One rule for packages: an edge from a package's ``__init__`` to one of its own
submodules is left out (the package re-exporting its parts is no circle); an edge from a submodule to
its package still counts. A circle is a strongly connected component of more than one module.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "becos"

# The floors of the package, lowest first: "base" is the small top-level modules (errors, atomic files,
# seeding, settings, defaults, ...); each layer subpackage imports only from its own floor or lower ones.
LAYERS = ("core", "sources", "build", "products", "evaluation")
FLOORS = ("base", *LAYERS, "workflow", "cli")
# Upward imports that stay, with the reason: ``python -m`` entry points call the command line; the
# dataset check names missing files from the published pair lists, whose reader lives beside their
# conversion to manifests (build.published).
UPWARD_ALLOWED = {
    ("becos.__main__", "becos.cli"),
    ("becos.sources.synthetic.__main__", "becos.cli"),
    ("becos.sources.check.datasets", "becos.build.published"),
}


def package_modules(package: Path) -> dict[str, Path]:
    """``{dotted module name: file}`` of every module of the package."""
    out = {}
    for path in sorted(package.rglob("*.py")):
        parts = list(path.relative_to(package.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _import_nodes(tree: ast.AST):
    """Every Import / ImportFrom node, at any depth, except under ``if TYPE_CHECKING:``."""
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            stack.extend(node.orelse)
            continue
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        stack.extend(ast.iter_child_nodes(node))


def _owner(name: str, modules: dict[str, Path]) -> str | None:
    """The module ``name`` stands for: itself, or its longest prefix that is a module."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def import_graph(package: Path = PACKAGE) -> dict[str, set[str]]:
    """``{module: modules of the package it imports}`` (the docstring's rules)."""
    modules = package_modules(package)
    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        parent = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in _import_nodes(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            else:
                base = node.module or ""
                if node.level:
                    anchor = parent.split(".")
                    anchor = anchor[: len(anchor) - (node.level - 1)]
                    base = ".".join(anchor + ([base] if base else []))
                for alias in node.names:
                    full = f"{base}.{alias.name}"
                    targets.append(full if full in modules else base)
            for target in targets:
                owner = _owner(target, modules) if target.split(".")[0] == package.name else None
                if owner is None or owner == name:
                    continue
                if path.name == "__init__.py" and owner.startswith(name + "."):
                    continue  # a package re-exporting its own submodules
                graph[name].add(owner)
    return graph


def import_circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph[node]):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                top = stack.pop()
                on_stack.discard(top)
                component.append(top)
                if top == node:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return sorted(out)


def test_the_graph_sees_imports_of_every_kind(tmp_path):
    """On a small package: module-level, function-local, relative and ``from pkg import module`` imports
    count, ``if TYPE_CHECKING:`` ones do not, and a package's ``__init__`` may re-export its submodules."""
    files = {
        "__init__.py": "",
        "a.py": "import pkg.b\n",
        "b.py": "def f():\n    from pkg import c\n",
        "c.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.a import x\nfrom .sub.d import y\n",
        "sub/__init__.py": "from pkg.sub.d import y\n",
        "sub/d.py": "from pkg.sub import z\nimport numpy\n",
    }
    for name, text in files.items():
        (tmp_path / "pkg" / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "pkg" / name).write_text(text)
    graph = import_graph(tmp_path / "pkg")
    assert graph == {
        "pkg": set(),
        "pkg.a": {"pkg.b"},
        "pkg.b": {"pkg.c"},
        "pkg.c": {"pkg.sub.d"},
        "pkg.sub": set(),
        "pkg.sub.d": {"pkg.sub"},
    }
    assert import_circles(graph) == []
    (tmp_path / "pkg" / "c.py").write_text("def g():\n    import pkg.a.q\n")  # pkg.a.q: its module pkg.a
    assert import_circles(import_graph(tmp_path / "pkg")) == [["pkg.a", "pkg.b", "pkg.c"]]
    real = import_graph()
    assert "becos.errors" in real["becos.sources.datasets"] and "becos.atomic" in real["becos.products.geodesic_jobs"]
    assert len(real) > 50


def test_becos_has_no_import_circle():
    graph = import_graph()
    circles = import_circles(graph)
    detail = "; ".join(
        " <-> ".join(c) + " (" + ", ".join(f"{a} -> {b}" for a in c for b in sorted(graph[a]) if b in c) + ")"
        for c in circles
    )
    assert not circles, f"import circles in becos: {detail}"


def floor(module: str) -> str:
    """The floor of a ``becos`` module (:data:`FLOORS`)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in FLOORS else "base"


def upward_imports(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    """Imports from a floor to a higher one (the package root ``becos`` itself counts as base)."""
    return sorted(
        (name, target)
        for name, targets in graph.items()
        for target in targets
        if FLOORS.index(floor(target)) > FLOORS.index(floor(name))
    )


def test_layers_import_only_downward():
    assert sorted(p.name for p in PACKAGE.iterdir() if p.name in LAYERS) == sorted(LAYERS)
    upward = [edge for edge in upward_imports(import_graph()) if edge not in UPWARD_ALLOWED]
    assert upward == [], f"imports to a higher floor ({' < '.join(FLOORS)}): {upward}"
    # the check sees an upward import: the workflow importing the command line would be one
    assert upward_imports({"becos.workflow.plan": {"becos.cli"}}) == [("becos.workflow.plan", "becos.cli")]
