"""Stage 1 of a run: check that the enabled datasets and the annotation folder are present and sound.

:func:`check_datasets` looks at every enabled dataset below the data root (folder, shape count, a cheap
check of every mesh file) and at the BeCoS annotation folder (shape network, template table, the edge
files and default faces the enabled datasets need), and returns a JSON-able report. Every problem is
collected first; one :class:`DatasetCheckError` (a :class:`~becos.errors.ConfigError`) then lists them
all, with, for a missing dataset, where to get it, its licence, the folder to create and the config key
to change (``data_dir``, ``datasets``, ``annotations``).

:func:`fetch_annotations` downloads a pinned annotation archive (``.tar.gz``/``.tgz``/``.tar``/``.zip``,
``http(s)://`` or ``file://``) with :mod:`becos.download` (resumable, SHA-256 checked, extracted
safely), and moves it into place atomically; a second call with the same digest does nothing.

Mesh check (default, cheap; :mod:`becos.formats` holds it, one module per file format): the file is non-empty; for OFF and ASCII PLY the header's vertex and face
counts are compared with the number of non-blank data lines, and the last vertex line and the first and
last face lines are parsed (3 coordinates; ``k i_1 .. i_k`` with ``k >= 3`` and indices in
``[0, V)``); for binary PLY the file size must hold the announced elements (faces counted as
triangles) and the last face row is checked when the size matches exactly; for OBJ at least one
``v``/``f`` line must exist and the last line must parse with in-range indices. This catches empty and
truncated files at ~10 ms per 5 MB. Vertex lines (text formats) and the vertex block (binary PLY) are
also scanned for NaN / infinite coordinates. ``full_parse=True`` additionally reads every mesh with
:func:`becos.mesh.read_mesh` (~0.4 s per 50k-vertex mesh) and lists, per mesh, the repair remeshing
will apply to a copy (:func:`inspect_mesh_file`: faces with a repeated index, zero-area and duplicate
faces, unreferenced vertices, small extra components, inconsistent winding); a mesh whose extra
components are too large to drop is a problem. With mesh checks on, the edge files the enabled datasets
need are parsed, and where both templates' files are present their row counts and face indices are
compared with the meshes' header counts; an edge file into a present template must also be
geometrically plausible (:func:`edge_plausibility`): as a whole (Procrustes residual, median stretch) and
row by row (no row's mapped point far from its template neighbours', :data:`EDGE_ROW_MAX_JUMP`; a file
with such rows is refused, naming their line numbers). With mesh checks on, every shape that shares its
class template's triangulation is compared with the template (:func:`compare_with_class_template`:
faces as vertex sets, median edge-length ratio, flatness), every vertex line must hold 3 values and
every face line be a triangle, a header may not announce fewer lines than the file holds, and stray
files (names no class rule matches) are named, and so is every entry with a mesh file's name that is no
regular file (a folder, a named pipe, a link to a device, a dangling link: :func:`becos.formats.not_a_regular_file`,
decided by ``stat`` without opening it), instead of being counted as missing.

Report layout (``check_datasets`` return value)::

    {<dataset>: {"ok", "path", "folder", "found", "expected", "excluded_found", "meshes_checked",
                 "bad_meshes": [{"path", "problem", "fix"}], "repairs": [{"path", "repair", <counts>}],
                 "class_mismatches": [{"path", "template", "problem", "fix"}], "stray_files": [...],
                 "not_mesh_files": {path: what it is}, "problems": [...]},
     ...,
     "annotations": {"ok", "path", "found", "nodes", "edges", "template_rows", "files": {rel: bool},
                     "edge_files": {"needed", "missing"}, "default_faces": {"needed", "missing"},
                     "edge_contents": {"parsed", "compared_with_meshes", "bad",
                                       "plausibility": {"a -> b": {"residual", "stretch", "matched", "rows",
                                                                   "max_row_jump", "outlier_rows",
                                                                   "outlier_lines", "outlier_jumps"}}},
                     "unresolved_template_keys", "problems", "notes"},
     "ok": bool, "data_dir": str}
"""

from __future__ import annotations

import json
import os
import re
import shutil
import sys
import tempfile
import time
import urllib.parse
from pathlib import Path

import numpy as np

from becos.atomic import remove_stale_temporaries, write_text
from becos.download import (
    RECORD_NAME,
    CorruptArchiveError,
    UnsafeArchiveError,
    discard_partial,
    extract_archive,
    fetch,
    partial_path,
)
from becos.errors import BecosError, ConfigError, InputFileError
from becos.formats import check_file, not_a_mesh_file, not_a_regular_file
from becos.formats.off import read_off
from becos.formats.problems import TRUNCATED_FIX

MAX_LISTED_MESHES = 20
"""At most this many bad mesh files are named per dataset in the error message (the report has all)."""

MARKER_NAME = RECORD_NAME
"""File written into a fetched annotation folder: ``{"url", "sha256", "fetched_at"}``."""


class DatasetCheckError(ConfigError):
    """The dataset / annotation check failed. ``report`` holds the full report (JSON-able dict),
    ``problems`` the list of problem texts (also joined into the message)."""

    def __init__(self, message: str, report: dict, problems: list[str]):
        super().__init__(message)
        self.report = report
        self.problems = problems


# --- mesh files ------------------------------------------------------------------------------------
def check_mesh_file(path: str | Path, full_parse: bool = False) -> tuple[int, int]:
    """Cheap check that a mesh file is complete (see the module docstring; :func:`becos.formats.check_file`);
    returns (V, F) counts.

    For OBJ the counts are the numbers of ``v`` and ``f`` lines. ``full_parse`` also reads the mesh
    with :func:`becos.mesh.read_mesh` and returns its array sizes.

    Raises:
        InputFileError: missing, empty, truncated or unparsable file.
    """
    counts = check_file(path)
    if full_parse:
        from becos.mesh import read_mesh

        mesh = read_mesh(path)
        counts = (mesh.n_vertices, mesh.n_faces)
    return counts


def inspect_mesh_file(path: str | Path):
    """Check a mesh file completely and say how remeshing will repair it.

    The cheap check of :func:`check_mesh_file`, then :func:`becos.mesh.read_mesh` (NaN coordinates,
    face indices out of range, OFF header counts) and :func:`becos.mesh.surface_for_remeshing`
    (faces with a repeated index, zero-area and duplicate faces, unreferenced vertices, extra
    components, inconsistent winding).

    Returns:
        The :class:`becos.mesh.MeshRepair` report (``needs_attention`` is False for a clean mesh).

    Raises:
        InputFileError: any problem no repair handles, naming the file, the problem and the fix.
    """
    from becos.mesh import read_mesh, surface_for_remeshing

    path = Path(path)
    check_mesh_file(path)
    return surface_for_remeshing(read_mesh(path), source=path)[1]


# --- shapes of one class ---------------------------------------------------------------------------
CLASS_EDGE_RATIO = 1.5
"""Shapes that share their class template's triangulation (the network's identity hop: vertex i is
vertex i) must have a median edge length within this factor of the template's (and its inverse).
Measured on the 76 TOSCA meshes: every pose's median ratio to its class template is 1 ± 6e-5 (the
poses are near-isometric), while a file in other units is off by its unit factor (10, 100, 1000,
2.54...). 1.5 also leaves room for classes of different bodies on one template (FAUST subjects)."""


def mesh_arrays(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) float64 vertices and (F, 3) int64 faces of a mesh file that passed the cheap check.

    Triangle OFF files are read by :func:`becos.formats.off.read_off` (numpy, ~4x faster than trimesh);
    other files with :func:`becos.mesh.read_mesh`."""
    path = Path(path)
    if path.suffix.lower() == ".off":
        arrays = read_off(path.read_bytes())
        if arrays is not None:
            return arrays
    from becos.mesh import read_mesh

    mesh = read_mesh(path)
    return mesh.vertices, mesh.faces


def compare_with_class_template(path: Path, template_path: Path, shape_arrays, template_arrays) -> str | None:
    """Why the mesh in ``path`` cannot share the triangulation of its class template, or None.

    Faces are compared as vertex SETS (sorted triples; TOSCA poses of a class hold the same triples,
    some rows with reversed winding); faces the shape lacks, duplicates and rows with a repeated index
    are left to the remesh's repairs, a triple the template lacks is an error. Scale as the median
    ratio of the lengths of the template's edges in the two meshes (:data:`CLASS_EDGE_RATIO`)."""
    from becos.mesh import FLAT_RTOL, flatness, repeated_index_faces, undirected_edges, vertex_set_keys

    (v, f), (tv, tf) = shape_arrays, template_arrays
    if flatness(v) <= FLAT_RTOL:
        return (
            f"all its {len(v)} vertices lie in one plane (thickness {flatness(v):.2g} of its largest extent): a "
            f"flattened or 2-D mesh, and becos matches 3-D surfaces"
        )
    if len(v) != len(tv):
        return (
            f"has {len(v)} vertices but its class template {template_path} has {len(tv)}; the shapes of a class "
            f"share one triangulation (vertex i = vertex i)"
        )
    # faces as vertex sets; rows that remeshing drops or ignores (a repeated index, duplicates) and faces
    # the file lost (a subset) are repairs, a triple the template lacks is not
    f = np.asarray(f, dtype=np.int64)
    f = f[~repeated_index_faces(f)] if len(f) else f
    keys, template_keys = np.unique(vertex_set_keys(f, len(v))), np.unique(vertex_set_keys(tf, len(tv)))
    foreign = len(np.setdiff1d(keys, template_keys, assume_unique=True))
    if foreign:
        return (
            f"has the vertex count of its class template {template_path} but {foreign} of its {len(keys)} "
            f"distinct faces name vertex triples the template has not: its vertex lines are re-ordered (or it "
            f"was re-triangulated), so vertex i no longer corresponds to vertex i of the class"
        )
    edges, _ = undirected_edges(tf)
    lengths = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)
    template_lengths = np.linalg.norm(tv[edges[:, 0]] - tv[edges[:, 1]], axis=1)
    ratio = float(np.median(lengths[template_lengths > 0] / template_lengths[template_lengths > 0]))
    if not 1 / CLASS_EDGE_RATIO <= ratio <= CLASS_EDGE_RATIO:
        return (
            f"its edges are {ratio:.3g} times as long as those of its class template {template_path} "
            f"(median; poses of a class keep edge lengths, within {CLASS_EDGE_RATIO}x): the file is "
            f"scaled or in other units"
        )
    return None


_CLASS_FIX = (
    "restore the original file (re-download or re-extract it); never rescale or re-order a dataset's "
    "files: becos applies each dataset's scale itself (`scale` in config/datasets/<dataset>.yaml)"
)


def _check_classes(shapes: list, annotations, skip: set[str]) -> list[dict]:
    """``[{"path", "template", "problem", "fix"}]`` for shapes that differ from their class template.

    Only shapes the ground truth joins to their template by vertex identity are compared: the
    template is a shape of the same dataset (:meth:`becos.network.ShapeNetwork.hop`). Files in
    ``skip`` (already reported) are left out."""
    by_name = {e.name: e for e in shapes}
    groups: dict[str, list] = {}
    for e in shapes:
        groups.setdefault(e.template_key, []).append(e)
    bad = []
    for key, members in groups.items():
        try:
            dataset, template_name = annotations.node_template(annotations.node_of_key(key))
        except BecosError:
            continue  # reported by the annotation check
        template = by_name.get(template_name)
        if template is None or template.dataset != members[0].dataset or str(template.path) in skip:
            continue
        others = [e for e in members if e.name != template_name and str(e.path) not in skip]
        if not others:
            continue
        template_arrays = mesh_arrays(template.path)
        for e in others:
            try:
                problem = compare_with_class_template(e.path, template.path, mesh_arrays(e.path), template_arrays)
            except (BecosError, ValueError) as exc:
                problem = f"could not be read to compare with its class template ({exc})"
            if problem is not None:
                bad.append({"path": str(e.path), "template": str(template.path), "problem": problem, "fix": _CLASS_FIX})
    return bad


# --- datasets --------------------------------------------------------------------------------------
_PUBLISHED_CACHE: dict[str, dict[str, set[str]]] = {}


def _published_names(root: Path | None) -> dict[str, set[str]]:
    """Dataset -> shape names used by the published pair lists in ``root/config`` (empty if absent)."""
    if root is None:
        return {}
    key = str(root)
    if key not in _PUBLISHED_CACHE:
        out: dict[str, set[str]] = {}
        for setting in ("full_full", "partial_partial"):
            path = Path(root) / "config" / f"pairings_original_{setting}.pkl"
            if not path.is_file():
                continue
            try:
                from becos.published import load_published

                for split in load_published(path):
                    for pair in split:
                        for shape in pair:
                            out.setdefault(str(shape["org_dataset"]), set()).add(str(shape["name"]))
            except Exception:  # an unreadable list only loses the names in a message
                continue
        _PUBLISHED_CACHE[key] = out
    return _PUBLISHED_CACHE[key]


def _missing_dataset_text(spec, folder: Path, data_dir: Path) -> str:
    s = spec.source
    parts = [
        f"dataset '{spec.name}' ({spec.title}) not found: folder {folder} does not exist.",
        f"Get it: {s.get('instructions', '').strip().rstrip('.')}.",
    ]
    if s.get("url"):
        parts.append(f"Site: {s['url']} .")
    if s.get("licence"):
        parts.append(f"Licence: {s['licence'].strip().rstrip('.')}.")
    if spec.layout == "dt4d":
        from becos.dt4d import dataset_kind, source_folder

        kind = dataset_kind(spec)
        source = source_folder(data_dir, kind)
        parts.append(
            f"Put it there: unpack the download into {data_dir / 'DeformingThings4D'} (data_dir + "
            f"'DeformingThings4D'); the workflow then prepares {folder} from {source} "
            f"(`becos prepare-dt4d`)."
        )
        if source.is_dir():
            parts.append(
                f"{source} is present but not prepared yet: run the workflow (it plans one preparation "
                f"job per class once the annotation folder's data/{spec.info_file} exists), or "
                f"`becos prepare-dt4d --data-dir {data_dir} --info <annotations>/data/{spec.info_file} "
                f"--kind {kind}`."
            )
    else:
        parts.append(
            f"Put it there: create {folder} (data_dir {data_dir} + '{spec.folder}') and place the "
            f"{spec.file_type.upper()} files in it."
        )
    if spec.archive is not None:
        parts.append(
            f"Or let the workflow download it: add '{spec.name}' to the config key `download` (you accept "
            f"its licence), or run `becos download-dataset {spec.name} --data-dir {data_dir}`."
        )
    parts.append(
        f"Or change the config: set `data_dir` to the folder that holds '{spec.folder}', or remove "
        f"'{spec.name}' from `datasets`."
    )
    return " ".join(parts)


def _classified(spec, name: str) -> bool:
    """Whether ``name`` matches a class and a category rule of the dataset ``spec``."""
    try:
        spec.class_of(name)
        spec.category_of(name)
    except BecosError:
        return False
    return True


def _check_one_dataset(
    name: str,
    data_dir: Path,
    annotations,
    read_meshes: bool,
    full_parse: bool,
    config_dir,
    compare_geometry: bool = True,
) -> tuple[dict, list[str], list]:
    """Report entry, problem texts and the listed ShapeEntry rows (empty unless the listing succeeded)."""
    from becos.catalog import natural_key
    from becos.datasets import DatasetSpec

    entry: dict = {
        "ok": False,
        "path": None,
        "folder": None,
        "found": 0,
        "expected": None,
        "excluded_found": 0,
        "meshes_checked": 0,
        "bad_meshes": [],
        "repairs": [],
        "problems": [],
    }
    problems: list[str] = []

    def stop(problem: str) -> tuple[dict, list[str], list]:
        problems.append(problem)
        entry["problems"] = problems
        return entry, problems, []

    try:
        spec = DatasetSpec.load(name, config_dir)
    except BecosError as exc:
        return stop(f"{exc} (config key `datasets`)")
    folder = data_dir / spec.folder
    entry.update(path=str(folder), folder=spec.folder, expected=spec.expected_count)
    if spec.expected_per_class:
        entry["expected_per_class"] = dict(spec.expected_per_class)
    if not folder.is_dir():
        return stop(_missing_dataset_text(spec, folder, data_dir))
    try:
        names = spec.list_names(data_dir, annotations)
    except BecosError as exc:
        return stop(f"dataset '{name}': {exc}")
    not_files = {}  # shape name: path, of the entries named like a mesh file that are none
    for p in sorted(folder.glob(spec.mesh_glob)):
        odd = not_a_mesh_file(p)
        if odd is not None:
            problems.append(f"{p}: {odd[0]}. Fix: {odd[1]}")
            not_files[spec.name_of(p)] = p
    if not_files:
        entry["not_mesh_files"] = {str(p): not_a_regular_file(p) for p in not_files.values()}
    stray = [n for n in names if not _classified(spec, n)]
    if stray:
        shown = ", ".join(f"{n}.{spec.file_type}" for n in stray[:MAX_LISTED_MESHES])
        problems.append(
            f"{folder}: {len(stray)} file(s) there are not shapes of dataset '{name}': {shown} (their "
            f"names match no class rule of the dataset registry {spec.path}). Fix: move them out of {folder} "
            f"(stray files); only if they are shapes of '{name}', add class and category rules for them "
            f"to {spec.path}"
        )
        entry["stray_files"] = [f"{n}.{spec.file_type}" for n in stray]
        names = [n for n in names if n not in stray]
    used = [n for n in names if n not in spec.excluded]
    entry.update(found=len(used), excluded_found=len(names) - len(used))
    counts_ok = not not_files  # named above; counted below as present, so that they are not called missing
    there = [*used, *(n for n in not_files if n not in spec.excluded and _classified(spec, n))]
    if len(there) != spec.expected_count:
        counts_ok = False
        published = _published_names(getattr(annotations, "root", None)).get(name, set())
        # the published lists name every shape of the reference's datasets; a registry that expects
        # another count (a subset, a newer release) gets no names
        present = set(names) | set(not_files)
        absent = sorted(published - present, key=natural_key) if len(published) == spec.expected_count else []
        entry["missing_published"] = absent
        named = ""
        if absent:
            shown = ", ".join(f"{n}.{spec.file_type}" for n in absent[:MAX_LISTED_MESHES])
            more = f" and {len(absent) - MAX_LISTED_MESHES} more" if len(absent) > MAX_LISTED_MESHES else ""
            named = f"; missing files named by the published BeCoS pair lists: {shown}{more}"
        problems.append(
            f"dataset '{name}': found {len(there)} shapes ({spec.file_glob}) in {folder}, expected "
            f"{spec.expected_count}{named}. Fix: complete or re-extract the download "
            f"({spec.download_help()}), or check `data_dir`"
        )
    if spec.expected_per_class:
        per_class: dict[str, int] = {}
        for n in there:
            c = spec.class_of(n)
            per_class[c] = per_class.get(c, 0) + 1
        entry["found_per_class"] = per_class
        diff = {
            c: (per_class.get(c, 0), spec.expected_per_class.get(c, 0))
            for c in sorted(set(per_class) | set(spec.expected_per_class))
            if per_class.get(c, 0) != spec.expected_per_class.get(c, 0)
        }
        if diff:
            counts_ok = False
            problems.append(
                f"dataset '{name}': shapes per class (found, expected) differ in {folder}: {diff}. "
                f"Fix: complete or re-extract the download"
            )
    if read_meshes:
        for n in names:
            path = folder / f"{n}.{spec.file_type}"
            try:
                if full_parse:
                    repair = inspect_mesh_file(path)
                    if repair.needs_attention:
                        entry["repairs"].append({"path": str(path), "repair": repair.summary(), **repair.counts()})
                else:
                    check_mesh_file(path)
            except InputFileError as exc:
                entry["bad_meshes"].append({"path": str(path), "problem": exc.problem, "fix": exc.fix})
            entry["meshes_checked"] += 1
        bad = entry["bad_meshes"]
        if bad:
            listed = "; ".join(
                f"{b['path']}: {b['problem']}" + (f" (fix: {b['fix']})" if b["fix"] != TRUNCATED_FIX else "")
                for b in bad[:MAX_LISTED_MESHES]
            )
            more = (
                f"; and {len(bad) - MAX_LISTED_MESHES} more (all in the report)" if len(bad) > MAX_LISTED_MESHES else ""
            )
            problems.append(
                f"dataset '{name}': {len(bad)} of {len(names)} mesh files are empty, truncated or corrupt: "
                f"{listed}{more}. Fix: re-download or re-extract them ({spec.download_help()})"
            )
    shapes: list = []
    if counts_ok and not stray:
        try:
            shapes = spec.list_shapes(data_dir, annotations)
        except BecosError as exc:
            problems.append(f"dataset '{name}': {exc}")
    if read_meshes and compare_geometry and shapes and annotations is not None:
        mismatched = _check_classes(shapes, annotations, {b["path"] for b in entry["bad_meshes"]})
        entry["class_mismatches"] = mismatched
        if mismatched:
            listed = "; ".join(f"{b['path']}: {b['problem']}" for b in mismatched[:MAX_LISTED_MESHES])
            more = (
                f"; and {len(mismatched) - MAX_LISTED_MESHES} more (all in the report)"
                if len(mismatched) > MAX_LISTED_MESHES
                else ""
            )
            problems.append(
                f"dataset '{name}': {len(mismatched)} mesh files do not fit their class template: "
                f"{listed}{more}. Fix: {_CLASS_FIX}"
            )
    entry["problems"] = problems
    entry["ok"] = not problems
    return entry, problems, shapes


# --- annotations -----------------------------------------------------------------------------------
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
    the source template (:func:`becos.mesh.undirected_edges`, indices < N), ``area``: target surface area (> 0, in the target's squared units),
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
    """How well an edge map (:class:`becos.surface_map.SurfaceMap`, source template vertex -> point on
    the target template) fits the two templates' geometry. Scale- and pose-free statistics over the
    matched rows (``face >= 0``), ``P_i`` being the mapped point of source vertex ``i``:

    - ``residual``: both point sets (source vertices, ``P``) centred and scaled to unit RMS radius,
      the source rigidly aligned onto ``P`` (:func:`becos.align.procrustes`); the median distance
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
    from becos.align import procrustes
    from becos.mesh import undirected_edges

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
    from becos.annotations import FIX_ANNOTATION_FOLDER

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


def _check_edge_contents(
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


def _check_annotations(
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
    from becos.annotations import (
        ADJACENCY_CSV,
        CHIRALITY_CSV,
        DEFAULT_FACES_DIR,
        EDGE_DIR,
        AnnotationSource,
        user_cache_dir,
    )

    fix_key = (
        "set `annotations` to a BeCoS annotation folder (a clone of github.com/NafieAmrani/becos-code, "
        "or `becos fetch-annotations`)"
    )
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
        problems.append(f"annotation folder {root} not found. Fix: {fix_key}")
        report["problems"] = problems
        return report, problems
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
                problems.append(f"annotation folder {root}: {rel} is missing. Fix: restore it, or {fix_key}")
            else:
                report["notes"].append(f"{rel} is missing (optional)")
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

    # template nodes of the found datasets (enabled but absent ones are reported above already)
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
    # the subtree joining them: its edges need edge files; nodes of absent datasets need default faces
    import networkx as nx

    nodes: set[str] = set()
    ordered = sorted(terminals)
    for t in ordered[1:]:
        try:
            nodes.update(nx.shortest_path(source.graph, ordered[0], t))
        except nx.NetworkXNoPath:  # pragma: no cover - read_adjacency guarantees a tree
            problems.append(f"annotation folder: no network path {ordered[0]} -> {t}")
    nodes |= terminals
    sub = source.graph.subgraph(nodes)
    missing_edges = []
    n_edges = 0
    for u, v in sorted(sub.edges):
        for a, b in ((u, v), (v, u)):
            n_edges += 1
            try:
                source.edge_source(a, b)
            except BecosError as exc:
                missing_edges.append(f"{a} -> {b}")
                problems.append(f"annotation folder: {exc}")
    report["edge_files"] = {"needed": n_edges, "missing": missing_edges}
    if check_edges:
        missing = {tuple(m.split(" -> ")) for m in missing_edges}
        needed = [(a, b) for u, v in sorted(sub.edges) for a, b in ((u, v), (v, u)) if (a, b) not in missing]
        report["edge_contents"], edge_problems = _check_edge_contents(source, needed, present, compare_geometry)
        problems += edge_problems
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
    report["default_faces"] = {"needed": n_faces, "missing": missing_faces}
    report["problems"] = problems
    report["ok"] = not problems
    return report, problems


def check_datasets(
    datasets: list[str],
    data_dir: str | Path,
    annotations_dir: str | Path | None,
    *,
    read_meshes: bool = True,
    full_parse: bool = False,
    template_table: str = "templates_all.csv",
    config_dir: str | Path | None = None,
    compare_geometry: bool = True,
) -> dict:
    """Check the enabled datasets and the annotation folder; return the report (module docstring).

    Args:
        datasets: enabled dataset names (registry: :func:`becos.datasets.available_datasets`).
        data_dir: the data root holding each dataset's ``folder``.
        annotations_dir: the BeCoS annotation folder; None skips its checks (DT4D and SMAL listings
            then fail, as they read files from it).
        read_meshes: check every listed mesh file (cheap header/size check, see module docstring);
            False checks folders and counts only.
        full_parse: also parse every mesh completely with :func:`becos.mesh.read_mesh` and report the
            repairs remeshing will apply (``<dataset>["repairs"]``; slow).
        template_table: the template table in ``<annotations>/config`` (config key ``template_file``).
        config_dir: dataset registry folder (default ``config/datasets`` or ``$BECOS_DATASETS_DIR``).
        compare_geometry: compare each shape with its class template (:func:`compare_with_class_template`)
            and check edge files for plausibility (:func:`edge_plausibility`); False only for stand-in
            meshes without real geometry (config key ``check_geometry``).

    Raises:
        DatasetCheckError (a ConfigError): one message listing every problem; ``.report`` holds the report.
    """
    from becos.annotations import AnnotationSource, user_cache_dir
    from becos.datasets import DatasetSpec

    data_dir = Path(data_dir).expanduser().absolute()
    enabled = list(dict.fromkeys(str(d) for d in datasets))
    report: dict = {}
    problems: list[str] = []
    if not enabled:
        problems.append("no dataset is enabled. Fix: list at least one dataset under `datasets`")
    if "annotations" in enabled or "ok" in enabled or "data_dir" in enabled:
        problems.append(
            "dataset names 'annotations', 'ok' and 'data_dir' are reserved in the check report. "
            "Fix: rename the dataset YAML"
        )
    if not data_dir.is_dir():
        problems.append(
            f"data root {data_dir} does not exist. Fix: set `data_dir` to the folder that holds the "
            f"dataset folders (e.g. tosca-off, MPI-FAUST)"
        )

    source = None
    root = Path(annotations_dir).expanduser().absolute() if annotations_dir is not None else None
    if root is not None and root.is_dir():
        try:
            source = AnnotationSource(root, cache_dir=user_cache_dir(), template_table=template_table)
        except BecosError:
            source = None  # reported by the annotation check below
    specs = {}
    present: dict[str, list] = {}
    for name in enabled:
        entry, ds_problems, shapes = _check_one_dataset(
            name, data_dir, source, read_meshes, full_parse, config_dir, compare_geometry
        )
        report[name] = entry
        problems += ds_problems
        try:
            specs[name] = DatasetSpec.load(name, config_dir)
        except BecosError:
            pass
        if shapes:
            present[name] = shapes
    if root is None:
        report["annotations"] = {"ok": None, "path": None, "notes": ["not checked (no annotation folder given)"]}
    else:
        report["annotations"], ann_problems = _check_annotations(
            root, template_table, enabled, present, specs, check_edges=read_meshes, compare_geometry=compare_geometry
        )
        problems += ann_problems
    report["ok"] = not problems
    report["data_dir"] = str(data_dir)
    if problems:
        lines = "\n".join(f"  {i + 1}. {p}" for i, p in enumerate(problems))
        raise DatasetCheckError(
            f"the dataset check found {len(problems)} problem(s) (data_dir {data_dir}, "
            f"annotations {root}, datasets {enabled}):\n{lines}",
            report,
            problems,
        )
    return report


# --- fetching the annotation folder ----------------------------------------------------------------
def _read_marker(dest: Path) -> dict | None:
    try:
        return json.loads((dest / MARKER_NAME).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def fetch_annotations(url: str, sha256: str, dest: str | Path) -> Path:
    """Download the pinned annotation archive ``url`` and install it as folder ``dest``.

    Steps: stream to a partial file beside ``dest`` (:func:`becos.download.fetch`: progress bar, an
    interrupted download resumes), compare its SHA-256 with
    ``sha256``, extract it (tar, tar.gz/tgz, tar.bz2/xz or zip; absolute paths, ``..`` members, links
    leaving the archive and device files are rejected), drop a single top-level folder, write
    ``dest/.becos-download.json`` (url, digest) and rename the result to ``dest``. If ``dest`` already
    holds a download with this digest, nothing is done. A previous download with another digest is
    replaced; a folder without the marker is never overwritten.

    Returns:
        ``dest`` (resolved).

    Raises:
        ConfigError: bad digest text, download failure, checksum mismatch (names both digests;
            ``dest`` is left untouched), unsafe or unreadable archive, ``dest`` is someone else's folder.
    """
    dest = Path(dest).expanduser().resolve()
    expected = str(sha256).strip().lower()
    if not re.fullmatch(r"[0-9a-f]{64}", expected):
        raise ConfigError(
            f"'{sha256}' is not a SHA-256 digest (64 hex digits). Fix: pin the archive's digest (sha256sum ARCHIVE)"
        )
    marker = _read_marker(dest) if dest.is_dir() else None
    if marker is not None and marker.get("sha256") == expected:
        print(f"fetch-annotations: {dest} already holds {expected[:12]}...; nothing to do", file=sys.stderr)
        return dest
    if dest.exists() and marker is None and (not dest.is_dir() or any(dest.iterdir())):
        raise ConfigError(
            f"{dest} already exists and was not made by `becos fetch-annotations` (no {MARKER_NAME}). "
            f"Fix: choose another --dest, or remove {dest} yourself"
        )
    dest.parent.mkdir(parents=True, exist_ok=True)
    part = partial_path(dest.parent / f"{dest.name}.{Path(urllib.parse.urlparse(url).path).name or 'archive'}")
    fetch(
        url,
        part,
        expected,
        label="annotations",
        fix="check the URL and the network connection, or download it by hand and pass a file:// URL",
        pinned_in="the annotations_archive config / --sha256",
    )
    remove_stale_temporaries(dest.parent, [dest.name])  # extraction folders of killed fetches
    work = Path(tempfile.mkdtemp(dir=dest.parent, prefix=f".{dest.name}.", suffix=".tmp-fetch"))
    try:
        out = work / "extract"
        out.mkdir()
        label = f"annotation archive {url}"
        try:
            extract_archive(part, out, label)
        except (UnsafeArchiveError, CorruptArchiveError):
            discard_partial(part)  # complete but unusable: a rerun must fetch it again
            raise
        discard_partial(part)
        entries = [p for p in out.iterdir() if p.name != "__MACOSX"]
        if not entries:
            raise ConfigError(f"{label} is empty. Fix: check the URL")
        root = entries[0] if len(entries) == 1 and entries[0].is_dir() and not entries[0].is_symlink() else out
        write_text(
            root / MARKER_NAME,
            json.dumps({"url": url, "sha256": expected, "fetched_at": time.strftime("%Y-%m-%dT%H:%M:%S%z")}, indent=2)
            + "\n",
        )
        os.chmod(root, 0o755)
        old = None
        if dest.exists():  # a previous download (other digest) or an empty folder: swap it out
            old = work / "previous"
            os.rename(dest, old)
        try:
            os.rename(root, dest)
        except OSError:
            done = _read_marker(dest) if dest.is_dir() else None
            if done is not None and done.get("sha256") == expected:  # a parallel fetch won
                return dest
            raise
        print(f"fetch-annotations: installed {dest}", file=sys.stderr)
        return dest
    finally:
        shutil.rmtree(work, ignore_errors=True)
