"""The reference's partial views from the published cameras (reference facts §7.5, §7.6).

A view of a full shape (the reference's remesh, :mod:`becos.build.reference_remesh`) from a published camera
``cam_pos`` (a unit vector per try) is the triangles hit (the shipped ``precomputed_triangle_ids`` file
when it exists, else :func:`cast_pinhole`, the reference's 5000 × 5000, 90° pinhole cast) reduced to the
component the reference keeps (:func:`reference_component`: trimesh's split, the largest by area), as a
set of full faces. :func:`pair_view_files` keeps the reference's file naming quirk. The steps and the
quirk: docs/design/partiality.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from becos.core.mesh import TriMesh
from becos.errors import InputFileError
from becos.settings import MAX_OVERLAP, MIN_OVERLAP

PIXELS = 5000
"""Rays per image side of the reference's pinhole (5000 × 5000 = 25 M rays)."""
FOV_DEG = 90.0
UP = (0.0, 1.0, 0.0)
SHRINK_DIAGONAL = 2.0
"""The reference casts onto the vertices × :data:`SHRINK` when the bounding-box diagonal reaches this."""
SHRINK = 0.8


def triangle_ids_folder(root: str | Path, setting: str) -> Path:
    """The folder of a setting's shipped view files (``root``: the annotation folder)."""
    return Path(root) / "precomputed_triangle_ids" / setting


def triangle_ids_path(root: str | Path, setting: str, name: str, cam_pos) -> Path:
    """The shipped file of ``name``'s view from ``cam_pos`` (``root``: the annotation folder)."""
    c = np.asarray(cam_pos, dtype=np.float64).reshape(3)
    return triangle_ids_folder(root, setting) / f"{name.replace('/', '_')}_cam_{c[0]:.3f}_{c[1]:.3f}_{c[2]:.3f}.npy"


def pair_view_files(
    root: str | Path, setting: str, x_name: str, y_name: str, x_cam_pos, try_index: int
) -> tuple[Path, Path]:
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
        raise InputFileError(
            path,
            f"could not be read as .npy ({type(exc).__name__}: {exc})",
            "restore the file from the BeCoS annotation folder",
        ) from exc
    if ids.ndim != 1 or ids.dtype.kind not in "iu":
        raise InputFileError(
            path,
            f"is not a 1-D array of triangle ids (shape {ids.shape}, dtype {ids.dtype})",
            "restore the file from the BeCoS annotation folder",
        )
    ids = ids.astype(np.int64)
    if len(ids) and (ids.min() < 0 or ids.max() >= n_faces):
        raise InputFileError(
            path,
            f"names triangles up to {ids.max()} but the remeshed shape has {n_faces} faces",
            "views from the published lists need remesher: reference and the published face targets",
        )
    return np.unique(ids)


def cast_pinhole(vertices: np.ndarray, faces: np.ndarray, cam_pos, pixels: int = PIXELS) -> np.ndarray:
    """(K,) int64 sorted ids of the faces some ray of the reference's pinhole hits first.

    ``vertices`` (V, 3) in the reference's casting frame (unit area); ``cam_pos`` (3,) the eye. Cast
    with Embree (:meth:`becos.build.visibility.VisibilityScene.grid_visible_faces`: pixel-centre rays over
    the square 90° field of view); a mesh with bounding-box diagonal ≥ 2 is shrunk × 0.8 first, as
    the reference does (the camera stays)."""
    from becos.build.cameras import Camera
    from becos.build.visibility import VisibilityScene

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
    selects it (docs/design/partiality.md). ``vertices`` in the casting frame (only area ratios matter)."""
    import trimesh
    from scipy.spatial import cKDTree

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

    from becos.build.visibility import face_adjacency
    from becos.core.mesh import vertex_set_keys

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
    graph = np.zeros((len(loose), len(loose)), dtype=bool)  # few triangles: a dense graph is fine
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


# ----------------------------------------------------------------------------------------------
# a P2P pair from the published cameras: the reference's casting frame and its choice of try


def reference_alignment(x_posed: np.ndarray, y_posed: np.ndarray, p2p_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(R (3, 3), t (3,))`` as the reference's ``rigid_transform_3d(x, y[p2p])`` computes them (Kabsch,
    reflection fixed), ``y ≈ R x + t`` in column form; ``-1`` entries of ``p2p_xy`` index Y's LAST vertex,
    as numpy does there (facts §7.4). The reference then moves Y as ``y @ R + t``."""
    a = np.asarray(x_posed, dtype=np.float64)
    b = np.asarray(y_posed, dtype=np.float64)[np.asarray(p2p_xy, dtype=np.int64)]
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    r = vt.T @ u.T
    if np.linalg.det(r) < 0:
        vt[2, :] *= -1
        r = vt.T @ u.T
    return r, cb - r @ ca


@dataclass(frozen=True, eq=False)
class CastingFrames:
    """A P2P pair's full shapes in the reference's casting frame (facts §7.4) and the way back.

    Casting frame of X: ``(p - x_centre) / x_area``; of Y: ``((p - y_centre) @ rotation + translation)
    / y_area`` (the reference's alignment, applied as it applies it), for points ``p`` of the meshes
    given to :func:`casting_frames` (becos's common frame).

    Attributes:
        x_vertices, y_vertices: (V, 3) the shapes in the casting frame.
        x_centre, y_centre: (3,) vertex means; x_area, y_area: sqrt-areas.
        rotation, translation: the reference-style alignment (:func:`reference_alignment`).
    """

    x_vertices: np.ndarray
    y_vertices: np.ndarray
    x_centre: np.ndarray
    y_centre: np.ndarray
    x_area: float
    y_area: float
    rotation: np.ndarray
    translation: np.ndarray

    def camera(self, side: int, cam_pos):
        """The reference's camera at ``cam_pos`` (casting frame) as a :class:`becos.build.cameras.Camera` in
        the side's input frame (0: X, 1: Y)."""
        from becos.build.cameras import Camera

        cam = Camera(np.asarray(cam_pos, dtype=np.float64), np.zeros(3), np.array(UP), FOV_DEG)
        if side == 0:
            return cam.transformed(scale=self.x_area, translation=self.x_centre)
        cam = cam.transformed(scale=self.y_area, translation=-self.translation)
        return cam.transformed(rotation=self.rotation, translation=self.y_centre)


def casting_frames(x: TriMesh, y: TriMesh, gt_xy) -> CastingFrames:
    """The two full shapes in the reference's casting frame (facts §7.4): centred, Y moved by
    :func:`reference_alignment` from ``gt_xy`` rounded to vertices (becos's exact ground truth, where
    the reference rounds at every hop: the alignment can differ slightly), each divided by its own
    sqrt-area. ``x``, ``y``: full remeshed meshes in becos's common frame."""
    from becos.build.reference_remesh import sqrt_area

    cx, cy = np.mean(x.vertices, axis=0), np.mean(y.vertices, axis=0)
    xp, yp = x.vertices - cx, y.vertices - cy
    r, t = reference_alignment(xp, yp, gt_xy.to_vertex_indices(y.faces))
    ax, ay = sqrt_area(xp, x.faces), sqrt_area(yp, y.faces)
    return CastingFrames(xp / ax, (yp @ r + t) / ay, cx, cy, ax, ay, r, t)


class PublishedViews:
    """Try k of a published P2P pair -> the two kept face masks (full faces), reading the shipped files
    where they exist (named as the reference reads them, :func:`pair_view_files`), else casting.

    Args:
        root: the annotation folder (holds ``precomputed_triangle_ids/``).
        x_name, y_name: the shapes' names in the pair list.
        cameras: (2, n, 3) published ``cam_pos`` of x and y.
        frames: ((V_x, 3), (V_y, 3)) vertices in the casting frame (:attr:`CastingFrames.x_vertices`,
            ``y_vertices``).
        faces: ((F_x, 3), (F_y, 3)) the reference remeshes' faces.
    Attribute ``sources``: ``{(try, side): "file" | "cast"}`` for the tries asked for.
    """

    def __init__(
        self, root, x_name: str, y_name: str, cameras: np.ndarray, frames, faces, setting: str = "partial_partial"
    ):
        self.root, self.names, self.setting = Path(root), (x_name, y_name), setting
        self.cameras = np.asarray(cameras, dtype=np.float64).reshape(2, -1, 3)
        self.frames, self.faces = frames, faces
        self.sources: dict[tuple[int, int], str] = {}

    def __call__(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        files = pair_view_files(self.root, self.setting, *self.names, self.cameras[0], k)
        kept = []
        for side in (0, 1):
            vertices, faces = self.frames[side], np.asarray(self.faces[side])
            if files[side].is_file():
                ids, self.sources[(k, side)] = read_triangle_ids(files[side], len(faces)), "file"
            else:
                ids, self.sources[(k, side)] = cast_pinhole(vertices, faces, self.cameras[side][k]), "cast"
            kept.append(reference_component(vertices, faces, ids).kept_faces)
        return kept[0], kept[1]


def reference_overlap(partial_x, gt_xy, y_faces: np.ndarray, partial_y) -> float:
    """The reference's overlap of partial X: the share of its vertices whose ground-truth target VERTEX
    (``gt_xy`` rounded to its largest-weight corner) is a vertex of partial Y (facts §7.5)."""
    target = gt_xy.to_vertex_indices(y_faces)[partial_x.partial_to_full]
    found = (target >= 0) & (partial_y.full_to_partial[np.maximum(target, 0)] >= 0)
    return float(found.mean()) if len(found) else 0.0


@dataclass(frozen=True, eq=False)
class PublishedP2P:
    """The try of a published P2P pair, chosen as the reference chooses it (facts §7.5).

    Attributes:
        try_index: the try whose geometry is kept: the first accepted one, else the LAST try.
        camera_try: the try whose camera the reference records: ``try_index`` if accepted, else the
            try with the smallest summed shortfall below ``min_overlap`` (first such).
        accepted: some try had both reference overlaps in range.
        kept_x, kept_y: (F,) bool kept full faces of the geometry try.
        reference_overlaps: (n, 2) the reference rule's overlaps (x, y) of the tries it cast.
        exact_overlaps: (m, 2) becos's exact rule's overlaps, m ≥ n: tries are cast on until that rule
            accepts one too (or all are cast).
        exact_try: the try becos's exact rule keeps (first accepted, else the smallest summed distance
            to the range); ``exact_differs`` when that is not ``try_index``.
    """

    try_index: int
    camera_try: int
    accepted: bool
    kept_x: np.ndarray
    kept_y: np.ndarray
    reference_overlaps: np.ndarray
    exact_overlaps: np.ndarray
    exact_try: int

    @property
    def exact_differs(self) -> bool:
        return self.exact_try != self.try_index


def published_p2p(
    x: TriMesh,
    y: TriMesh,
    gt_xy,
    gt_yx,
    views,
    n_tries: int = 10,
    min_overlap: float = MIN_OVERLAP,
    max_overlap: float = MAX_OVERLAP,
) -> PublishedP2P:
    """Cast the tries of a published P2P pair in order and keep the one the reference keeps.

    ``views``: ``k -> (kept_x, kept_y)`` (e.g. :class:`PublishedViews`); ``gt_xy`` / ``gt_yx``: becos's
    exact ground truth between the full meshes ``x`` and ``y``. The reference rule runs on the ground
    truth rounded to vertices (:func:`reference_overlap`; the reference rounds at every hop of its
    path, so near the range limits its choice can differ from this one); becos's exact rule
    (:func:`becos.build.partiality.overlap_ratio`) is evaluated on the same tries and reported beside it.
    """
    from becos.build.partiality import cut, overlap_ratio

    def distance(value: float) -> float:
        return max(0.0, min_overlap - value) + max(0.0, value - max_overlap)

    if n_tries < 1:
        raise ValueError(f"n_tries must be ≥ 1, got {n_tries}")
    tries, ref_overlaps, exact_overlaps = [], [], []

    def cast(k: int) -> None:
        kept = views(k)
        px, py = cut(x, kept[0]), cut(y, kept[1])
        tries.append(kept)
        ref_overlaps.append((reference_overlap(px, gt_xy, y.faces, py), reference_overlap(py, gt_yx, x.faces, px)))
        exact_overlaps.append((overlap_ratio(px, gt_xy, py), overlap_ratio(py, gt_yx, px)))

    best_camera, min_shortfall, accepted = 0, 1.0, False
    for k in range(n_tries):
        cast(k)
        ox, oy = ref_overlaps[k]
        if min_overlap <= ox <= max_overlap and min_overlap <= oy <= max_overlap:
            accepted, best_camera = True, k
            break
        shortfall = max(0.0, min_overlap - ox) + max(0.0, min_overlap - oy)
        if shortfall < min_shortfall:
            best_camera, min_shortfall = k, shortfall
    geometry_try = k
    # becos's exact rule on the same tries, casting on where it would not have stopped yet
    while not any(distance(a) + distance(b) == 0 for a, b in exact_overlaps) and len(tries) < n_tries:
        cast(len(tries))
    exact_distance = np.array([distance(a) + distance(b) for a, b in exact_overlaps])
    ok = np.flatnonzero(exact_distance == 0)
    exact_try = int(ok[0]) if len(ok) else int(exact_distance.argmin())
    kept_x, kept_y = tries[geometry_try]
    return PublishedP2P(
        geometry_try,
        best_camera,
        accepted,
        kept_x,
        kept_y,
        np.asarray(ref_overlaps),
        np.asarray(exact_overlaps),
        exact_try,
    )


@dataclass(frozen=True, eq=False)
class PublishedScan:
    """:func:`published_scan`'s result: the chosen try, its cameras (input frames), where views came from."""

    choice: PublishedP2P
    camera_x: object
    camera_y: object
    sources: dict


def published_scan(
    x: TriMesh,
    y: TriMesh,
    gt_xy,
    gt_yx,
    root,
    x_name: str,
    y_name: str,
    cameras,
    n_tries: int = 10,
    min_overlap: float = MIN_OVERLAP,
    max_overlap: float = MAX_OVERLAP,
) -> PublishedScan:
    """A published P2P pair's views, end to end: :func:`casting_frames`, :class:`PublishedViews`,
    :func:`published_p2p`; the recorded cameras are the reference's (the camera try's, facts §7.5) in
    the meshes' input frames. ``x``, ``y``: the reference remeshes in becos's common frame."""
    frames = casting_frames(x, y, gt_xy)
    views = PublishedViews(root, x_name, y_name, cameras, (frames.x_vertices, frames.y_vertices), (x.faces, y.faces))
    choice = published_p2p(x, y, gt_xy, gt_yx, views, n_tries, min_overlap, max_overlap)
    cams = views.cameras
    return PublishedScan(
        choice,
        frames.camera(0, cams[0][choice.camera_try]),
        frames.camera(1, cams[1][choice.camera_try]),
        {f"{k}_{'xy'[side]}": v for (k, side), v in sorted(views.sources.items())},
    )
