"""The annotation-folder part of the dataset check (:func:`check_annotations`).

The BeCoS annotation folder must hold the shape network, the template table, the edge files and the
default faces the enabled datasets need: the files every run reads, the template node of every found
shape, the network subtree joining those nodes (each of its edges, both ways, needs an edge file,
:func:`becos.sources.check.edges.check_edge_contents` parses them), and default faces for the subtree's
templates of datasets that are not available.
"""

from __future__ import annotations

from pathlib import Path

from becos.errors import BecosError
from becos.sources.check.edges import check_edge_contents

ANNOTATIONS_FIX = (
    "set `annotations` to a BeCoS annotation folder (a clone of github.com/NafieAmrani/becos-code, "
    "or `becos fetch-annotations`)"
)
"""The fix named for a missing or unreadable annotation folder (config key ``annotations``)."""


def check_annotations(
    root: Path,
    template_table: str,
    enabled: list[str],
    present: dict[str, list],
    specs: dict,
    check_edges: bool = True,
    compare_geometry: bool = True,
) -> tuple[dict, list[str]]:
    """Annotation-folder part of the report; ``present`` maps found datasets to their ShapeEntry rows.
    ``check_edges`` also parses the needed edge files and compares them with the present meshes."""
    from becos.sources.annotations import ADJACENCY_CSV, AnnotationSource, user_cache_dir

    table = Path(template_table)
    table_rel = table if table.is_absolute() else Path("config") / table
    report: dict = {
        "ok": False,
        "path": str(root),
        "found": root.is_dir(),
        "template_table": str(table_rel),
        "files": {},
        "problems": [],
        "notes": [],
    }
    problems: list[str] = []
    if not root.is_dir():
        problems.append(f"annotation folder {root} not found. Fix: {ANNOTATIONS_FIX}")
        report["problems"] = problems
        return report, problems
    _check_files(root, table_rel, specs, report, problems)
    try:
        source = AnnotationSource(root, cache_dir=user_cache_dir(), template_table=template_table)
    except BecosError as exc:
        if not any("is missing" in p and (str(ADJACENCY_CSV) in p or str(table_rel) in p) for p in problems):
            problems.append(f"annotation folder: {exc}")
        report["problems"] = problems
        return report, problems
    report.update(
        nodes=source.graph.number_of_nodes(),
        edges=source.graph.number_of_edges(),
        template_rows=len(source.template_rows()),
    )
    terminals = _template_nodes(source, enabled, present, report, problems)
    nodes, edges = _joining_subtree(source, terminals, problems)
    missing_edges = _check_edge_files(source, edges, report, problems)
    if check_edges:
        missing = {tuple(m.split(" -> ")) for m in missing_edges}
        needed = [(a, b) for u, v in edges for a, b in ((u, v), (v, u)) if (a, b) not in missing]
        report["edge_contents"], edge_problems = check_edge_contents(source, needed, present, compare_geometry)
        problems += edge_problems
    report["default_faces"] = _check_default_faces(source, root, nodes, terminals, present, problems)
    report["problems"] = problems
    report["ok"] = not problems
    return report, problems


def _check_files(root: Path, table_rel: Path, specs: dict, report: dict, problems: list[str]) -> None:
    """Fill ``report["files"]`` (relative path: exists) with the files every run reads (network, template
    table, edge folder, the DT4D info files and rotation references of ``specs``) and the optional ones;
    a missing required file is a problem, a missing optional one a note."""
    from becos.sources.annotations import ADJACENCY_CSV, CHIRALITY_CSV, DEFAULT_FACES_DIR, EDGE_DIR

    required = [ADJACENCY_CSV, table_rel, EDGE_DIR]
    for spec in specs.values():
        if spec.layout == "dt4d" and spec.info_file:
            required.append(Path("data") / spec.info_file)
        ref = (spec.rotation_per_shape or {}).get("from_reference")
        if ref:
            required.append(Path(ref))
    optional = [CHIRALITY_CSV, DEFAULT_FACES_DIR]
    for rel in required + optional:
        path = rel if rel.is_absolute() else root / rel
        report["files"][str(rel)] = path.exists()
        if not path.exists():
            if rel in required:
                problems.append(f"annotation folder {root}: {rel} is missing. Fix: restore it, or {ANNOTATIONS_FIX}")
            else:
                report["notes"].append(f"{rel} is missing (optional)")


def _template_nodes(
    source, enabled: list[str], present: dict[str, list], report: dict, problems: list[str]
) -> set[str]:
    """Network nodes of the template keys of the found datasets' shapes (enabled but absent datasets are
    reported by the dataset check); keys without a node are problems, listed in
    ``report["unresolved_template_keys"]``."""
    terminals: set[str] = set()
    unresolved: dict[str, str] = {}
    keys = {(ds, e.template_key) for ds in enabled if ds in present for e in present[ds] if e.split != "excluded"}
    for ds, key in sorted(keys):
        try:
            terminals.add(source.node_of_key(key))
        except BecosError as exc:
            unresolved[key] = str(exc)
            problems.append(f"annotation folder: shapes of '{ds}' use template key '{key}': {exc}")
    report["unresolved_template_keys"] = sorted(unresolved)
    return terminals


def _joining_subtree(source, terminals: set[str], problems: list[str]) -> tuple[set[str], list[tuple[str, str]]]:
    """(nodes, sorted edges) of the network subtree joining the ``terminals``: its edges need edge files,
    its nodes of absent datasets default faces."""
    import networkx as nx

    nodes: set[str] = set()
    ordered = sorted(terminals)
    for t in ordered[1:]:
        try:
            nodes.update(nx.shortest_path(source.graph, ordered[0], t))
        except nx.NetworkXNoPath:  # pragma: no cover - read_adjacency guarantees a tree
            problems.append(f"annotation folder: no network path {ordered[0]} -> {t}")
    nodes |= terminals
    return nodes, sorted(source.graph.subgraph(nodes).edges)


def _check_edge_files(source, edges: list[tuple[str, str]], report: dict, problems: list[str]) -> list[str]:
    """Whether each of the subtree's ``edges``, both ways, has its edge file; sets ``report["edge_files"]``
    and returns the missing ones as ``"a -> b"``."""
    missing_edges = []
    n_edges = 0
    for u, v in edges:
        for a, b in ((u, v), (v, u)):
            n_edges += 1
            try:
                source.edge_source(a, b)
            except BecosError as exc:
                missing_edges.append(f"{a} -> {b}")
                problems.append(f"annotation folder: {exc}")
    report["edge_files"] = {"needed": n_edges, "missing": missing_edges}
    return missing_edges


def _check_default_faces(
    source, root: Path, nodes: set[str], terminals: set[str], present: dict[str, list], problems: list[str]
) -> dict:
    """``{"needed", "missing"}``: the subtree's template nodes of datasets that are not available need the
    annotation folder's default faces (the ground-truth paths pass through them)."""
    from becos.sources.annotations import DEFAULT_FACES_DIR

    missing_faces = []
    n_faces = 0
    for node in sorted(nodes):
        try:
            ds, template = source.node_template(node)
        except BecosError as exc:
            problems.append(f"annotation folder: {exc}")
            continue
        if ds in present or node in terminals:
            continue
        n_faces += 1
        try:
            faces = source.default_faces(template, ds)
        except BecosError as exc:
            problems.append(f"annotation folder: {exc}")
            continue
        if faces is None:
            missing_faces.append(node)
            problems.append(
                f"annotation folder {root}: the ground-truth paths of the enabled datasets pass through "
                f"template {node} of dataset '{ds}', which is not available, and "
                f"{DEFAULT_FACES_DIR}/ has no faces for '{template}'. Fix: add '{ds}' to `datasets` "
                f"(and download it), or restore the annotation folder's default faces"
            )
    return {"needed": n_faces, "missing": missing_faces}
