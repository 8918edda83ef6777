"""Edge files of the annotation folder: are they geometrically plausible, and do they fit the meshes.

An edge file maps each vertex of its source template to a point on its target template. Where the
target template's mesh is present, the map must be plausible (:func:`edge_plausibility`) as a whole
(Procrustes residual, median stretch: :data:`EDGE_MAX_RESIDUAL`, :data:`EDGE_MAX_STRETCH`) and row by
row (no row's mapped point far from its template neighbours', :func:`edge_row_jumps`,
:data:`EDGE_ROW_MAX_JUMP`); :func:`require_plausible_edge` refuses a file that is not, naming its
outlier rows by line number. :func:`check_edge_contents` runs these checks for the dataset check, and
compares each file's row count and face indices with the present meshes' header counts.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from becos.errors import BecosError, InputFileError
from becos.sources.check.meshes import check_mesh_file, mesh_arrays

EDGE_MAX_RESIDUAL = 0.5
"""Largest median Procrustes residual of a plausible edge file (see :func:`edge_plausibility`), in RMS
radii of the scale-normalised point sets. Measured on the 8 TOSCA-TOSCA edge files of the BeCoS annotation
folder (the only ones with both meshes here): 0.076-0.174; ``tosca_dog0_tosca_wolf0_corres.txt``
holding the content of ``tosca_dog0_smal_dog2_corres.txt``: 1.12."""

EDGE_MAX_STRETCH = 3.0
"""Largest median stretch of a plausible edge file (see :func:`edge_plausibility`). Measured on the 17
edge files into a TOSCA template whose source faces are known (mesh or default faces): 0.55-1.38; the
swapped file above: 4.85."""


EDGE_ROW_MAX_JUMP = 0.3
"""Largest row jump of a plausible edge file (see :func:`edge_row_jumps`), in units of
``sqrt(target template area)``: the median distance between a row's mapped point and its source-template
neighbours' mapped points. The rule: an edge file with any row above it is refused
(:func:`require_plausible_edge`), naming the rows; becos never drops rows (a file with moved rows may
have others moved less, below the limit: only the original file is safe). Measured on the 17 edge files
into a TOSCA template whose source faces are known (mesh or default faces): largest row jump per file
0.019-0.060, except ``shrec20_dog_tosca_dog0_corres.txt``: 0.218. ``tosca_wolf0_tosca_dog0_corres.txt``
with 217 of its 4,344 rows replaced by random faces and weights (issue #29, BAD 5): 154 rows above the
limit (exactly the randomised rows moved more than 0.3 from their original point), largest 1.16."""

MAX_LISTED_ROWS = 10
"""How many outlier rows (line numbers) an edge-file refusal lists; the check report lists them all."""


def edge_row_jumps(
    points: np.ndarray, ok: np.ndarray, edges: np.ndarray, area: float, trusted: np.ndarray | None = None
) -> np.ndarray:
    """Per-row locality of an edge map. ``points``: (N, 3) mapped point of each source template vertex on
    the target (NaN rows allowed), ``ok``: (N,) bool matched rows, ``edges``: (E, 2) undirected edges of
    the source template (:func:`becos.core.mesh.undirected_edges`, indices < N), ``area``: target surface area (> 0, in the target's squared units),
    ``trusted``: (N,) bool rows that may serve as neighbours (default ``ok``).

    Returns (N,) float64: for each matched row ``i``, the median over its trusted neighbours ``j`` (the
    source template's edges ``(i, j)``) of ``|P_i - P_j|``, divided by ``sqrt(area)`` (scale-free); NaN for
    unmatched rows and rows without a trusted neighbour. A real map keeps it small (neighbours stay
    neighbours: about one target edge length); a row moved elsewhere on the target has a large one,
    while its neighbours' medians stay small (one far neighbour among ~6)."""
    trusted = ok if trusted is None else ok & trusted
    out = np.full(len(points), np.nan)
    pairs = np.concatenate([edges, edges[:, ::-1]])  # each edge seen from both ends: (row, neighbour)
    pairs = pairs[ok[pairs[:, 0]] & trusted[pairs[:, 1]]]
    if not len(pairs) or area <= 0:
        return out
    row = pairs[:, 0]
    d = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1) / np.sqrt(area)
    order = np.lexsort((d, row))  # by row, then by distance
    row, d = row[order], d[order]
    count = np.bincount(row, minlength=len(points))
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    has = count > 0
    lo = start[has] + (count[has] - 1) // 2
    hi = start[has] + count[has] // 2
    out[has] = 0.5 * (d[lo] + d[hi])
    return out


def edge_plausibility(
    edge,
    target_vertices: np.ndarray,
    target_faces: np.ndarray,
    source_faces: np.ndarray | None,
    source_vertices: np.ndarray | None = None,
) -> dict:
    """How well an edge map (:class:`becos.core.surface_map.SurfaceMap`, source template vertex -> point on
    the target template) fits the two templates' geometry. Scale- and pose-free statistics over the
    matched rows (``face >= 0``), ``P_i`` being the mapped point of source vertex ``i``:

    - ``residual``: both point sets (source vertices, ``P``) centred and scaled to unit RMS radius,
      the source rigidly aligned onto ``P`` (:func:`becos.core.align.procrustes`); the median distance
      between an aligned vertex and its mapped point, in RMS radii. Needs ``source_vertices``.
    - ``stretch``: the median length of ``P_i - P_j`` over the source's edges ``(i, j)``, divided by
      ``sqrt(target area / source vertices)`` (the edge length of a uniform mesh with the source's
      vertex count on the target surface). Neighbours stay neighbours under a real map (~1); a map
      of other faces scatters them. Needs ``source_faces``.

    - ``max_row_jump``: the largest per-row jump (:func:`edge_row_jumps`, in ``sqrt(target area)``),
      ``outlier_rows``: how many rows exceed :data:`EDGE_ROW_MAX_JUMP`, ``outlier_lines``: all of them
      as 1-based line numbers of the file (line ``k`` = source vertex ``k - 1``), ``outlier_jumps``:
      their jumps (rounded to 4 decimals). Each row is measured against the neighbours that are no
      outliers themselves (a second pass), so a correct row beside moved ones is not named. A local
      test: a few rows moved elsewhere leave the global statistics unchanged. Needs ``source_faces``.

    Returns ``{"residual": float | None, "stretch": float | None, "matched": int, "rows": int (rows of
    the file), "max_row_jump": float | None, "outlier_rows": int, "outlier_lines": list[int],
    "outlier_jumps": list[float]}``.
    """
    from becos.core.align import procrustes
    from becos.core.mesh import undirected_edges

    ok = edge.face >= 0
    points = np.full((len(edge.face), 3), np.nan)
    points[ok] = np.einsum("ij,ijk->ik", edge.weights[ok], target_vertices[target_faces[edge.face[ok]]])
    out: dict = {
        "residual": None,
        "stretch": None,
        "matched": int(ok.sum()),
        "rows": len(edge.face),
        "max_row_jump": None,
        "outlier_rows": 0,
        "outlier_lines": [],
        "outlier_jumps": [],
    }
    if ok.sum() < 3:
        return out
    if source_vertices is not None and len(source_vertices) == len(edge.face):
        a = source_vertices[ok] - source_vertices[ok].mean(axis=0)
        p = points[ok] - points[ok].mean(axis=0)
        a /= np.sqrt((a**2).sum(axis=1).mean())
        p /= np.sqrt((p**2).sum(axis=1).mean())
        out["residual"] = float(np.median(np.linalg.norm(procrustes(a, p).apply(a) - p, axis=1)))
    if source_faces is not None and len(source_faces) and source_faces.max() < len(edge.face):
        edges, _ = undirected_edges(source_faces)
        pairs = edges[ok[edges[:, 0]] & ok[edges[:, 1]]]
        tri = target_vertices[target_faces]
        area = float(0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())
        if len(pairs) and area > 0:
            out["stretch"] = float(
                np.median(np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1))
                / np.sqrt(area / len(edge.face))
            )
            # second pass: rows are measured against neighbours that are no outliers themselves, so a
            # correct row beside moved ones is not named
            first = edge_row_jumps(points, ok, edges, area)
            jumps = edge_row_jumps(points, ok, edges, area, ~(first > EDGE_ROW_MAX_JUMP))
            jumps = np.where(np.isnan(jumps), first, jumps)
            if np.isfinite(jumps).any():
                out["max_row_jump"] = float(np.nanmax(jumps))
                outliers = np.flatnonzero(np.nan_to_num(jumps, nan=0.0) > EDGE_ROW_MAX_JUMP)
                out["outlier_rows"] = int(len(outliers))
                out["outlier_lines"] = (outliers + 1).tolist()
                out["outlier_jumps"] = [round(float(x), 4) for x in jumps[outliers]]
    return out


def require_plausible_edge(path: Path, a: str, b: str, stats: dict) -> None:
    """Raise :class:`InputFileError` naming the edge file ``path`` (edge ``a -> b``) when its
    :func:`edge_plausibility` ``stats`` exceed :data:`EDGE_MAX_RESIDUAL` or :data:`EDGE_MAX_STRETCH`
    (the whole map is elsewhere), or when any row exceeds :data:`EDGE_ROW_MAX_JUMP` (rows moved: the
    error names them by line number)."""
    from becos.sources.annotations import FIX_ANNOTATION_FOLDER

    too_far = stats["residual"] is not None and stats["residual"] > EDGE_MAX_RESIDUAL
    too_spread = stats["stretch"] is not None and stats["stretch"] > EDGE_MAX_STRETCH
    if not (too_far or too_spread):
        if stats.get("outlier_rows"):
            n, lines, jumps = stats["outlier_rows"], stats["outlier_lines"], stats["outlier_jumps"]
            listed = ", ".join(map(str, lines[:MAX_LISTED_ROWS]))
            more = f" and {n - MAX_LISTED_ROWS} more" if n > MAX_LISTED_ROWS else ""
            raise InputFileError(
                path,
                f"{n} of its {stats['rows']} rows map a vertex of template {a} far from where its neighbours "
                f"land on {b}: file lines {listed}{more} (1-based line numbers in the file, line k being vertex "
                f"k-1 of {a}{'; all in the check report' if more else ''}); each lies a median "
                f"{min(jumps):.3g} to {stats['max_row_jump']:.3g} x sqrt(area "
                f"of {b}) from its template neighbours' mapped points (real BeCoS edge files: at most 0.22; "
                f"limit {EDGE_ROW_MAX_JUMP}): the rows were edited or corrupted",
                f"restore the annotation folder's original file (becos refuses the file, it never drops rows); "
                f"{FIX_ANNOTATION_FOLDER}",
            )
        return
    found = []
    if stats["residual"] is not None:
        found.append(
            f"after the best rigid alignment (scale-normalised Procrustes) the vertices of template {a} lie "
            f"a median {stats['residual']:.3g} RMS radii from their mapped points on {b} (real BeCoS edge "
            f"files: at most 0.17; limit {EDGE_MAX_RESIDUAL})"
        )
    if stats["stretch"] is not None:
        found.append(
            f"neighbouring vertices land a median {stats['stretch']:.3g} mesh edges apart (real files: at "
            f"most 1.38; limit {EDGE_MAX_STRETCH})"
        )
    raise InputFileError(
        path,
        "the map does not land where its template belongs: "
        + " and ".join(found)
        + "; the file probably holds another edge's map",
        f"restore the annotation folder's original file; {FIX_ANNOTATION_FOLDER}",
    )


def check_edge_contents(
    source, edges: list[tuple[str, str]], present: dict[str, list], compare_geometry: bool = True
) -> tuple[dict, list[str]]:
    """Parse each needed edge file (non-numeric text, columns, face indices below -1...) and, where both
    templates' mesh files are present, compare its rows with the source template's vertex count and
    its face indices with the target template's face count (counts from the file headers); where the
    target template's mesh is present, check that the map is geometrically plausible
    (:func:`edge_plausibility`, :data:`EDGE_MAX_RESIDUAL`, :data:`EDGE_MAX_STRETCH`,
    :data:`EDGE_ROW_MAX_JUMP`)."""
    paths = {(e.dataset, e.name): e.path for entries in present.values() for e in entries}
    counts: dict = {}
    arrays: dict = {}

    def mesh_counts(node: str):
        key = source.node_template(node)
        if key not in counts:
            counts[key] = None
            if key in paths:
                try:
                    counts[key] = check_mesh_file(paths[key])
                except InputFileError:
                    pass  # reported with the dataset's meshes
        return counts[key]

    def mesh_of(node: str):
        key = source.node_template(node)
        if key not in arrays:
            arrays[key] = mesh_arrays(paths[key]) if mesh_counts(node) is not None else None
        return arrays[key]

    problems, bad, compared, plausible = [], [], 0, {}
    for a, b in sorted(edges):  # sorted: the report is byte-identical between runs
        try:
            edge_source = source.edge_source(a, b)
            if edge_source.kind != "file":
                continue
            source.edge_report(a, b)  # parses (and validates) the file once
            ca, cb = mesh_counts(a), mesh_counts(b)
            if ca is not None and cb is not None:
                source.check_edge(a, b, ca[0], cb[1])
                compared += 1
            if cb is None or not compare_geometry:
                continue
            target = mesh_of(b)
            source_mesh = mesh_of(a) if ca is not None else None
            source_faces = (
                source_mesh[1] if source_mesh is not None else source.default_faces(*source.node_template(a)[::-1])
            )
            edge = source.edge_map(a, b)
            if len(edge) and edge.face.max() >= len(target[1]):
                continue  # named by check_edge / the ground truth
            stats = edge_plausibility(
                edge, target[0], target[1], source_faces, source_mesh[0] if source_mesh is not None else None
            )
            plausible[f"{a} -> {b}"] = stats
            require_plausible_edge(edge_source.path, a, b, stats)
        except BecosError as exc:
            bad.append(f"{a} -> {b}")
            problems.append(f"annotation folder: {exc}")
    return {"parsed": len(edges), "compared_with_meshes": compared, "bad": bad, "plausibility": plausible}, problems
