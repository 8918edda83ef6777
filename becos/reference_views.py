"""The reference's partial views from the published cameras (reference facts §7.5, §7.6).

A view of a full shape (the reference's remesh, :mod:`becos.reference_remesh`) from a published
camera position ``cam_pos`` (a unit vector, one per try) is:

1. the triangles hit: the shipped ``precomputed_triangle_ids/<setting>/<name, / -> _>_cam_<x>_<y>_<z>.npy``
   (3-decimal coordinates; sorted unique ids) when it exists, else a cast of the reference's camera
   (:func:`cast_pinhole`): a pinhole of 5000 × 5000 rays, 90° field of view, eye at ``cam_pos``,
   looking at the origin, up +y, onto the shape in the reference's casting frame
   (:func:`becos.reference_remesh.reference_pose`, Y aligned to X, divided by its sqrt-area);
2. the component the reference keeps (:func:`reference_component`): trimesh's
   ``split(only_watertight=False)`` of those triangles (float32 vertex positions, as Open3D's tensor
   mesh holds them), the largest by area (ties: trimesh's first). trimesh's split also fills 3- and
   4-edge holes; a fill triangle is a face of the full mesh, or (a 4-edge hole filled along the other
   diagonal: trimesh 4.4, the reference's, and 5.x choose differently) one of two triangles spanning
   two full faces. The kept set is therefore a set of full faces
   (:attr:`ReferenceComponent.kept_faces`, :func:`full_faces_covering`), equal whichever diagonal.

Reference quirk kept (its ``save_corres_for_shape_pair``): for Y the triangle-id file is named with
X's camera of the same try, while the file's content is Y's view from Y's own camera (checked on
the oracle: a cast from Y's ``cam_pos`` gives exactly that file's set). :func:`pair_view_files`
encodes that naming. A shipped file is one per (shape, camera), while a train shape sits in many
pairs: the files of wolf1 and centaur1 read as Y of oracle pairs train/384 and train/477 are their
views in their OWN, unaligned frame (as the X of another pair; Jaccard 1.0 there, 0.77 / 0.52 in the
pair's aligned frame). So the file is always preferred; a cast (file absent) uses the pair's frame,
as the reference does when it casts.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from becos.errors import InputFileError
from becos.mesh import TriMesh

PIXELS = 5000
"""Rays per image side of the reference's pinhole (5000 × 5000 = 25 M rays)."""
FOV_DEG = 90.0
UP = (0.0, 1.0, 0.0)
SHRINK_DIAGONAL = 2.0
"""The reference casts onto the vertices × :data:`SHRINK` when the bounding-box diagonal reaches this."""
SHRINK = 0.8


def triangle_ids_path(root: str | Path, setting: str, name: str, cam_pos) -> Path:
    """The shipped file of ``name``'s view from ``cam_pos`` (``root``: the annotation folder)."""
    c = np.asarray(cam_pos, dtype=np.float64).reshape(3)
    return Path(root) / "precomputed_triangle_ids" / setting / f"{name.replace('/', '_')}_cam_{c[0]:.3f}_{c[1]:.3f}_{c[2]:.3f}.npy"


def pair_view_files(root: str | Path, setting: str, x_name: str, y_name: str, x_cam_pos, try_index: int) -> tuple[Path, Path]:
    """The files the reference reads for try ``try_index`` of a P2P pair: both named with X's camera."""
    cam = np.asarray(x_cam_pos, dtype=np.float64).reshape(-1, 3)[try_index]
    return triangle_ids_path(root, setting, x_name, cam), triangle_ids_path(root, setting, y_name, cam)


def read_triangle_ids(path: str | Path, n_faces: int) -> np.ndarray:
    """(K,) int64 sorted unique face ids from a ``precomputed_triangle_ids`` file.

    Raises:
        InputFileError: unreadable, not a 1-D integer array, or ids outside ``[0, n_faces)`` (the file
            belongs to another remesh: the face target or the remesher differs).
    """
    path = Path(path)
    try:
        ids = np.load(path, allow_pickle=False)
    except Exception as exc:
        raise InputFileError(path, f"could not be read as .npy ({type(exc).__name__}: {exc})",
                             "restore the file from the BeCoS annotation folder") from exc
    if ids.ndim != 1 or ids.dtype.kind not in "iu":
        raise InputFileError(path, f"is not a 1-D array of triangle ids (shape {ids.shape}, dtype {ids.dtype})",
                             "restore the file from the BeCoS annotation folder")
    ids = ids.astype(np.int64)
    if len(ids) and (ids.min() < 0 or ids.max() >= n_faces):
        raise InputFileError(path, f"names triangles up to {ids.max()} but the remeshed shape has {n_faces} faces",
                             "views from the published lists need remesher: reference and the published face targets")
    return np.unique(ids)


def cast_pinhole(vertices: np.ndarray, faces: np.ndarray, cam_pos, pixels: int = PIXELS) -> np.ndarray:
    """(K,) int64 sorted ids of the faces some ray of the reference's pinhole hits first.

    ``vertices`` (V, 3) in the reference's casting frame (unit area); ``cam_pos`` (3,) the eye. Cast
    with Embree (:meth:`becos.visibility.VisibilityScene.grid_visible_faces`: pixel-centre rays over
    the square 90° field of view); a mesh with bounding-box diagonal ≥ 2 is shrunk × 0.8 first, as
    the reference does (the camera stays)."""
    from becos.cameras import Camera
    from becos.visibility import VisibilityScene

    v = np.asarray(vertices, dtype=np.float64)
    if np.linalg.norm(v.max(axis=0) - v.min(axis=0)) >= SHRINK_DIAGONAL:
        v = SHRINK * v
    camera = Camera(np.asarray(cam_pos, dtype=np.float64), np.zeros(3), np.array(UP), FOV_DEG)
    return np.flatnonzero(VisibilityScene(TriMesh(v, faces)).grid_visible_faces(camera, pixels)).astype(np.int64)


@dataclass(frozen=True, eq=False)
class ReferenceComponent:
    """The part of a view the reference keeps.

    Attributes:
        kept_faces: (F,) bool, the full faces in the kept component (fill triangles included when they
            are full faces).
        partial_vertices: (V_p, 3) float64 positions as the reference saves them before scaling back
            (float32-rounded casting-frame positions).
        partial_faces: (F_p, 3) int64 faces in trimesh's component order (fill triangles last).
        partial_to_full: (V_p,) int64 full vertex of each partial vertex (nearest, as the reference).
        unmatched_faces: fill triangles of the component that neither are a full face nor span full
            faces (:func:`full_faces_covering`; 0 on the TOSCA oracle).
    """

    kept_faces: np.ndarray
    partial_vertices: np.ndarray
    partial_faces: np.ndarray
    partial_to_full: np.ndarray
    unmatched_faces: int


def reference_component(vertices: np.ndarray, faces: np.ndarray, triangle_ids: np.ndarray) -> ReferenceComponent:
    """The largest-area component of the triangles ``triangle_ids`` of the full mesh, as the reference
    selects it (module docstring). ``vertices`` in the casting frame (only area ratios matter)."""
    import trimesh
    from scipy.spatial import cKDTree

    from becos.mesh import vertex_set_keys

    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    kept = np.zeros(len(faces), dtype=bool)
    if len(triangle_ids) == 0:
        return ReferenceComponent(kept, np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int64), 0)
    v32 = vertices.astype(np.float32).astype(np.float64)
    seen = trimesh.Trimesh(vertices=v32, faces=faces[np.asarray(triangle_ids, dtype=np.int64)], process=False)
    parts = seen.split(only_watertight=False)
    best = sorted(parts, key=lambda m: m.area, reverse=True)[0]
    partial_vertices = np.asarray(best.vertices, dtype=np.float64)
    partial_faces = np.asarray(best.faces, dtype=np.int64)
    partial_to_full = cKDTree(vertices).query(partial_vertices)[1].astype(np.int64)
    kept, unmatched = full_faces_covering(faces, len(vertices), partial_to_full[partial_faces])
    return ReferenceComponent(kept, partial_vertices, partial_faces, partial_to_full, unmatched)


def full_faces_covering(faces: np.ndarray, n_vertices: int, triangles: np.ndarray) -> tuple[np.ndarray, int]:
    """The full faces a set of triangles covers: ``(kept (F,) bool, triangles left unmatched)``.

    ``triangles`` (T, 3) full-vertex indices (e.g. a reference partial's faces through its
    ``partial2full``). A triangle that is a full face (same vertex set) keeps that face. The others are
    hole fills whose diagonal differs from the full mesh's (trimesh's fill of a 4-edge hole depends on
    its version): each edge-connected group of them keeps the full faces spanned by the group's
    vertices, when those are as many as the group's triangles; otherwise the group counts as unmatched.
    """
    from scipy.sparse.csgraph import connected_components

    from becos.mesh import vertex_set_keys
    from becos.visibility import face_adjacency

    faces = np.asarray(faces, dtype=np.int64)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    kept = np.zeros(len(faces), dtype=bool)
    full_keys = vertex_set_keys(faces, n_vertices)
    order = np.argsort(full_keys, kind="stable")
    wanted = vertex_set_keys(triangles, n_vertices)
    pos = np.clip(np.searchsorted(full_keys[order], wanted), 0, len(order) - 1)
    found = full_keys[order][pos] == wanted
    kept[order[pos[found]]] = True
    loose = triangles[~found]
    if len(loose) == 0:
        return kept, 0
    pairs = face_adjacency(loose)
    graph = np.zeros((len(loose), len(loose)), dtype=bool)   # few triangles: a dense graph is fine
    graph[pairs[:, 0], pairs[:, 1]] = True
    n_groups, group = connected_components(graph, directed=False)
    vertex_group = np.full(n_vertices, -1, dtype=np.int64)
    vertex_group[loose.ravel()] = np.repeat(group, 3)
    g = vertex_group[faces]
    spanned = (g[:, 0] >= 0) & (g[:, 0] == g[:, 1]) & (g[:, 1] == g[:, 2]) & ~kept
    n_spanned = np.bincount(g[spanned, 0], minlength=n_groups)
    n_loose = np.bincount(group, minlength=n_groups)
    ok = n_spanned == n_loose
    kept[np.flatnonzero(spanned)[ok[g[spanned, 0]]]] = True
    return kept, int(n_loose[~ok].sum())


def full_triangles(partial_faces: np.ndarray, partial_to_full: np.ndarray) -> set[tuple[int, int, int]]:
    """A partial's triangles as full-vertex sets (sorted triples): compares views whatever their face
    order and winding."""
    tri = np.sort(np.asarray(partial_to_full)[np.asarray(partial_faces)], axis=1)
    return set(map(tuple, tri.tolist()))
