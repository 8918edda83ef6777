"""Stage 1 of a run: check that the enabled datasets and the annotation folder are present and sound.

:func:`check_datasets` looks at every enabled dataset below the data root (folder, shape count, a cheap
check of every mesh file) and at the BeCoS annotation folder (shape network, template table, the edge
files and default faces the enabled datasets need), and returns a JSON-able report. Every problem is
collected first; one :class:`DatasetCheckError` (a :class:`~becos.errors.ConfigError`) then lists them
all, with, for a missing dataset, where to get it, its licence, the folder to create and the config key
to change (``data_dir``, ``datasets``, ``annotations``).

One module per part: :mod:`becos.check.datasets` (:func:`check_datasets`, the dataset folders and
counts), :mod:`becos.check.meshes` (mesh files: the cheap check and the full inspection),
:mod:`becos.check.templates` (shapes against their class template), :mod:`becos.check.edges` (edge
files: plausibility, rows against the meshes) and :mod:`becos.check.annotations` (the annotation
folder). The pinned annotation download, ``becos fetch-annotations``, is
:func:`becos.download.fetch_annotations`.

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

from becos.check.datasets import MAX_LISTED_MESHES, DatasetCheckError, check_datasets
from becos.check.edges import (
    EDGE_MAX_RESIDUAL,
    EDGE_MAX_STRETCH,
    EDGE_ROW_MAX_JUMP,
    edge_plausibility,
    edge_row_jumps,
    require_plausible_edge,
)
from becos.check.meshes import check_mesh_file, inspect_mesh_file, mesh_arrays
from becos.check.templates import CLASS_EDGE_RATIO, compare_with_class_template

__all__ = [
    "CLASS_EDGE_RATIO",
    "EDGE_MAX_RESIDUAL",
    "EDGE_MAX_STRETCH",
    "EDGE_ROW_MAX_JUMP",
    "MAX_LISTED_MESHES",
    "DatasetCheckError",
    "check_datasets",
    "check_mesh_file",
    "compare_with_class_template",
    "edge_plausibility",
    "edge_row_jumps",
    "inspect_mesh_file",
    "mesh_arrays",
    "require_plausible_edge",
]
