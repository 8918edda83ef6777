"""Partial shapes: virtual scans, exact bookkeeping, overlap and partial ground truth.

A *partial* of a full mesh is the faces one virtual scan keeps (:mod:`becos.build.visibility`) with the
vertices they use; :func:`cut` builds it from the face mask alone, so every partial vertex knows its full
vertex and every partial face its full face. :func:`overlap_mask`: a vertex of partial X̂ has a
counterpart on partial Ŷ when its ground-truth point lies in a face Ŷ kept; :func:`partial_map`
re-expresses those points on Ŷ's faces. :func:`cast_p2p`, :func:`cast_p2f` scan each shape in its
unit-box frame (:mod:`becos.build.cameras`), Y first moved rigidly into X's frame for P2P. In detail:
docs/design/partiality.md.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from becos.build.cameras import Camera, draw_camera, draw_camera_pair, normalise_to_unit_box
from becos.build.visibility import DEFAULT_SAMPLES_PER_FACE, VisibilityScene
from becos.core.align import RigidTransform, procrustes
from becos.core.mesh import TriMesh
from becos.core.surface_map import NONE, SurfaceMap, VertexRounding
from becos.seeding import rng_for
from becos.settings import MAX_OVERLAP, MIN_OVERLAP

# --------------------------------------------------------------------------------------------
# Exact bookkeeping


@dataclass(frozen=True, eq=False)
class Partial:
    """A partial shape cut from a full mesh, with exact index maps both ways.

    Attributes:
        mesh: the partial mesh; vertices are exact float64 copies of full vertices (same frame and
            units as the full mesh), faces index them, in ascending order of full face id.
        kept_faces: (F_full,) bool, the full faces the partial keeps.
        partial_to_full: (V_p,) int64 full vertex id of each partial vertex, strictly increasing.
        full_to_partial: (V_full,) int64 partial vertex id of each full vertex, -1 where absent.
        face_ids: (F_p,) int64 full face id of each partial face, strictly increasing.
    """

    mesh: TriMesh
    kept_faces: np.ndarray
    partial_to_full: np.ndarray
    full_to_partial: np.ndarray
    face_ids: np.ndarray

    @property
    def n_full_vertices(self) -> int:
        return len(self.full_to_partial)

    @property
    def n_full_faces(self) -> int:
        return len(self.kept_faces)

    def round_to_vertices(self, surface_map: SurfaceMap, full_rounding: VertexRounding) -> np.ndarray:
        """(N,) int64 partial vertex per row of ``surface_map`` (points on this partial; -1 = none): its
        :meth:`SurfaceMap.to_nearest_vertices`, through the full mesh's ``full_rounding`` (a partial
        face keeps its full face's corner order; neighbours the partial does not keep are absent)."""
        out = np.full(len(surface_map), -1, dtype=np.int64)
        matched = surface_map.matched
        full = full_rounding.nearest(
            self.face_ids[surface_map.face[matched]], surface_map.weights[matched], self.kept_faces
        )
        out[matched] = self.full_to_partial[full]
        return out

    @property
    def full_to_partial_face(self) -> np.ndarray:
        """(F_full,) int64 partial face id of each full face, -1 where not kept."""
        out = np.full(self.n_full_faces, NONE, dtype=np.int64)
        out[self.face_ids] = np.arange(len(self.face_ids))
        return out

    @property
    def vertex_share(self) -> float:
        """Partial vertices as a share of the full mesh's vertices."""
        return len(self.partial_to_full) / max(self.n_full_vertices, 1)


def cut(full: TriMesh, kept_faces: np.ndarray) -> Partial:
    """The partial of ``full`` made of the faces ``kept_faces`` ((F,) bool) and the vertices they use.

    Partial vertex ids follow full vertex order (``partial_to_full`` strictly increasing), partial
    faces follow full face order and keep each face's column order, so barycentric weights in a
    full face are valid unchanged in its partial face. Nothing is repaired or filled.
    """
    kept_faces = np.asarray(kept_faces, dtype=bool)
    if kept_faces.shape != (full.n_faces,):
        raise ValueError(f"kept_faces must have shape ({full.n_faces},), got {kept_faces.shape}")
    face_ids = np.flatnonzero(kept_faces).astype(np.int64)
    used = np.zeros(full.n_vertices, dtype=bool)
    used[full.faces[face_ids].ravel()] = True
    partial_to_full = np.flatnonzero(used).astype(np.int64)
    full_to_partial = np.full(full.n_vertices, NONE, dtype=np.int64)
    full_to_partial[partial_to_full] = np.arange(len(partial_to_full), dtype=np.int64)
    faces = full_to_partial[full.faces[face_ids]].reshape(-1, 3)
    mesh = TriMesh(full.vertices[partial_to_full], faces)
    return Partial(mesh, kept_faces.copy(), partial_to_full, full_to_partial, face_ids)


def whole(full: TriMesh) -> Partial:
    """The "partial" that keeps every face (the full side of a partial-to-full pair)."""
    return cut(full, np.ones(full.n_faces, dtype=bool))


# --------------------------------------------------------------------------------------------
# Overlap and partial ground truth


def _check_gt(partial_x: Partial, gt_xy: SurfaceMap, partial_y: Partial) -> None:
    if len(gt_xy) != partial_x.n_full_vertices:
        raise ValueError(f"the ground truth has {len(gt_xy)} rows but full X has {partial_x.n_full_vertices} vertices")
    if len(gt_xy) and gt_xy.face.max(initial=-1) >= partial_y.n_full_faces:
        raise ValueError(
            f"the ground truth points at face {gt_xy.face.max()} but full Y has {partial_y.n_full_faces} faces"
        )


def overlap_mask(partial_x: Partial, gt_xy: SurfaceMap, partial_y: Partial) -> np.ndarray:
    """(V_px,) bool: the X̂ vertex's ground-truth point lies in a face Ŷ kept (False for -1 ground truth).

    Args:
        partial_x: X̂, cut from full X.
        gt_xy: full X vertices -> points on full Y (len = full X vertex count).
        partial_y: Ŷ, cut from full Y.
    """
    _check_gt(partial_x, gt_xy, partial_y)
    face = gt_xy.face[partial_x.partial_to_full]
    return (face >= 0) & partial_y.kept_faces[np.maximum(face, 0)]


def overlap_ratio(partial_x: Partial, gt_xy: SurfaceMap, partial_y: Partial) -> float:
    """Share of X̂'s vertices whose counterpart is on Ŷ (0 for an empty X̂)."""
    mask = overlap_mask(partial_x, gt_xy, partial_y)
    return float(mask.mean()) if len(mask) else 0.0


def partial_map(partial_x: Partial, gt_xy: SurfaceMap, partial_y: Partial) -> SurfaceMap:
    """X̂ vertices -> points on Ŷ: faces re-indexed into Ŷ's faces, -1 exactly where :func:`overlap_mask` is False.

    Weights are the ground truth's (Ŷ faces keep the full faces' column order); ``distance`` is
    inherited. For a partial-to-full pair pass ``whole(full_x)`` as the full side.
    """
    mask = overlap_mask(partial_x, gt_xy, partial_y)
    rows = partial_x.partial_to_full
    face = np.full(len(rows), NONE, dtype=np.int64)
    face[mask] = partial_y.full_to_partial_face[gt_xy.face[rows[mask]]]
    weights = np.where(mask[:, None], gt_xy.weights[rows], 0.0)
    distance = np.where(mask, gt_xy.distance[rows], np.nan)
    return SurfaceMap(face, weights, distance)


# --------------------------------------------------------------------------------------------
# Scans


class Scanner:
    """A full mesh ready to be scanned: its unit-box normalisation and an Embree scene of it.

    Build one per shape and reuse it across pairs (≈ 10 ms for 20k faces).

    Attributes:
        mesh: the full mesh, in its input frame.
        centre, scale: its bounding-box centre (3,) and largest side; the unit-box frame is
            ``(p - centre) / scale``.
        scene: :class:`VisibilityScene` of the mesh in its unit-box frame.
    """

    def __init__(self, mesh: TriMesh):
        self.mesh = mesh
        normalised, self.centre, self.scale = normalise_to_unit_box(mesh.vertices)
        self.scene = VisibilityScene(TriMesh(normalised, mesh.faces))

    def kept_faces(self, camera: Camera, samples_per_face: int = DEFAULT_SAMPLES_PER_FACE) -> np.ndarray:
        """(F,) bool faces kept by a scan from ``camera`` given in the mesh's INPUT frame."""
        local = camera.transformed(scale=1.0 / self.scale, translation=-self.centre / self.scale)
        return self.scene.scan(local, samples_per_face)

    def scan(self, camera: Camera, samples_per_face: int = DEFAULT_SAMPLES_PER_FACE) -> Partial:
        """The partial seen from ``camera`` (INPUT frame of the mesh)."""
        return cut(self.mesh, self.kept_faces(camera, samples_per_face))


RngSource = Callable[[int], np.random.Generator] | tuple


def _rng_factory(source: RngSource) -> Callable[[int], np.random.Generator]:
    """``try_index -> Generator``: a callable as given, or ``(seed, pair_id)`` ->
    ``rng_for(seed, pair_id, "cameras", try_index)``."""
    if callable(source):
        return source
    seed, pair_id = source
    return lambda try_index: rng_for(seed, pair_id, "cameras", try_index)


def _unit_box_to_input(centre: np.ndarray, scale: float, to_input: RigidTransform | None = None):
    """A function mapping a camera from a unit-box frame ``(p - centre) / scale`` back to the input
    frame, optionally followed by a rigid motion ``to_input``."""

    def convert(camera: Camera) -> Camera:
        cam = camera.transformed(scale=scale, translation=centre)
        if to_input is not None:
            cam = cam.transformed(to_input.rotation, to_input.translation)
        return cam

    return convert


def _distance_to_range(value: float, lo: float, hi: float) -> float:
    return max(0.0, lo - value) + max(0.0, value - hi)


@dataclass(frozen=True, eq=False)
class P2PResult:
    """The kept scan of a partial-to-partial pair; every field belongs to the same (kept) try.

    Frames: ``partial_x.mesh`` / ``camera_x`` are in X's input frame and ``partial_y.mesh`` /
    ``camera_y`` in Y's input frame (the frames of the meshes passed in). ``drawn_cameras`` are the
    same two cameras as drawn, in the shared *unit-box frame* where the regime's bounds hold: X's
    frame for both, each shape centred on its own bounding box (Y's box taken after alignment) and
    scaled by its largest side — ``(p - centre_x) / scale_x`` for X and
    ``(alignment.apply(p) - centre_y) / scale_y`` for Y.

    Attributes:
        partial_x, partial_y: the partials.
        camera_x, camera_y: the cameras in the input frames (see above).
        drawn_cameras: (camera of X, camera of Y) in the shared unit-box frame.
        alignment: rigid motion of Y's input frame into X's, fitted by :func:`becos.core.align.procrustes`
            from the ground-truth points on Y to the X vertices (``-1`` rows masked).
        centre_x, scale_x, centre_y, scale_y: the unit-box normalisations (centre_y in X's frame).
        overlap_x, overlap_y: share of X̂ (Ŷ) vertices whose counterpart is on Ŷ (X̂).
        mask_x: (V_px,) bool, mask_y: (V_py,) bool: those vertices.
        map_xy: X̂ -> Ŷ surface map (-1 exactly where ``~mask_x``); map_yx: Ŷ -> X̂.
        try_index: the kept try (0-based); n_tries_used: tries cast; accepted: both overlaps in range.
        range_distance: summed distance of the two overlaps to ``[min_overlap, max_overlap]`` (0 if accepted).
    """

    partial_x: Partial
    partial_y: Partial
    camera_x: Camera
    camera_y: Camera
    drawn_cameras: tuple[Camera, Camera]
    alignment: RigidTransform
    centre_x: np.ndarray
    scale_x: float
    centre_y: np.ndarray
    scale_y: float
    overlap_x: float
    overlap_y: float
    mask_x: np.ndarray
    mask_y: np.ndarray
    map_xy: SurfaceMap
    map_yx: SurfaceMap
    try_index: int
    n_tries_used: int
    accepted: bool
    range_distance: float


def align_to(x: TriMesh, y: TriMesh, gt_xy: SurfaceMap) -> RigidTransform:
    """The rigid motion of Y's frame onto X's: Procrustes from the ground-truth points of X's vertices
    on Y to those vertices (``-1`` rows excluded), so ``x.vertices ≈ T.apply(gt points on y)``."""
    return procrustes(gt_xy.positions(y), x.vertices, mask=gt_xy.matched)


def cast_p2p(
    x: TriMesh,
    y: TriMesh,
    gt_xy: SurfaceMap,
    gt_yx: SurfaceMap,
    rng: RngSource,
    regime: str = "high",
    up_axis: str = "y",
    camera_distance: float = 1.0,
    n_tries: int = 10,
    min_overlap: float = MIN_OVERLAP,
    max_overlap: float = MAX_OVERLAP,
    samples_per_face: int = DEFAULT_SAMPLES_PER_FACE,
    scanners: tuple[Scanner, Scanner] | None = None,
) -> P2PResult:
    """Scan both shapes of a partial-to-partial pair, retrying cameras until both overlaps are in range.

    Y is aligned rigidly to X (:func:`align_to`); for try k the two cameras are
    ``draw_camera_pair(rng(k), regime, up_axis, camera_distance)`` in the shared unit-box frame
    (:class:`P2PResult`); each shape is scanned; the try is accepted when both overlaps lie in
    ``[min_overlap, max_overlap]``. After ``n_tries`` without acceptance the try with the smallest
    summed distance to the range is kept (the first such). Everything returned comes from that one try.

    Args:
        x, y: full meshes (any frame and units; ``up_axis`` must be their up direction).
        gt_xy: full X vertices -> points on full Y; gt_yx: full Y vertices -> points on full X.
        rng: ``(seed, pair_id)`` (try k uses ``becos.seeding.rng_for(seed, pair_id, "cameras", k)``)
            or a callable ``k -> numpy Generator``.
        scanners: optional prebuilt ``(Scanner(x), Scanner(y))`` to reuse across pairs.
    """
    if n_tries < 1:
        raise ValueError(f"n_tries must be ≥ 1, got {n_tries}")
    factory = _rng_factory(rng)
    sx, sy = scanners if scanners is not None else (Scanner(x), Scanner(y))
    if sx.mesh.n_faces != x.n_faces or sy.mesh.n_faces != y.n_faces:
        raise ValueError("the scanners given do not belong to x and y")
    alignment = align_to(x, y, gt_xy)
    _, centre_y, scale_y = normalise_to_unit_box(alignment.apply(y.vertices))
    x_to_input = _unit_box_to_input(sx.centre, sx.scale)
    y_to_input = _unit_box_to_input(centre_y, scale_y, alignment.inverse())

    best = None
    n_used = 0
    for k in range(n_tries):
        n_used = k + 1
        drawn = draw_camera_pair(factory(k), regime, up_axis, camera_distance)
        cam_x, cam_y = x_to_input(drawn[0]), y_to_input(drawn[1])
        px, py = sx.scan(cam_x, samples_per_face), sy.scan(cam_y, samples_per_face)
        ox, oy = overlap_ratio(px, gt_xy, py), overlap_ratio(py, gt_yx, px)
        dist = _distance_to_range(ox, min_overlap, max_overlap) + _distance_to_range(oy, min_overlap, max_overlap)
        if best is None or dist < best[0]:
            best = (dist, k, drawn, cam_x, cam_y, px, py, ox, oy)
        if dist == 0.0:
            break
    dist, k, drawn, cam_x, cam_y, px, py, ox, oy = best
    return P2PResult(
        partial_x=px,
        partial_y=py,
        camera_x=cam_x,
        camera_y=cam_y,
        drawn_cameras=drawn,
        alignment=alignment,
        centre_x=sx.centre,
        scale_x=sx.scale,
        centre_y=centre_y,
        scale_y=scale_y,
        overlap_x=ox,
        overlap_y=oy,
        mask_x=overlap_mask(px, gt_xy, py),
        mask_y=overlap_mask(py, gt_yx, px),
        map_xy=partial_map(px, gt_xy, py),
        map_yx=partial_map(py, gt_yx, px),
        try_index=k,
        n_tries_used=n_used,
        accepted=dist == 0.0,
        range_distance=dist,
    )


@dataclass(frozen=True, eq=False)
class P2FResult:
    """The scan of a partial-to-full pair: Y partial, X full.

    Frames: ``partial_y.mesh`` and ``camera_y`` are in Y's input frame; ``drawn_camera`` is the same
    camera in Y's unit-box frame ``(p - centre_y) / scale_y`` (no alignment is needed: one shape is cut).

    Attributes:
        full_x: ``whole(x)``, the full side as a :class:`Partial` keeping every face.
        partial_y: Ŷ.
        camera_y, drawn_camera: the camera (input frame / unit-box frame).
        centre_y, scale_y: Y's unit-box normalisation.
        overlap_y: share of Ŷ vertices with a counterpart on X (ground truth not -1).
        overlap_x: share of X vertices whose ground-truth point lies on Ŷ.
        mask_y: (V_py,) bool; mask_x: (V_x,) bool (over full X vertices).
        map_yx: Ŷ -> full X surface map; map_xy: full X -> Ŷ (-1 where ``~mask_x``).
    """

    full_x: Partial
    partial_y: Partial
    camera_y: Camera
    drawn_camera: Camera
    centre_y: np.ndarray
    scale_y: float
    overlap_x: float
    overlap_y: float
    mask_x: np.ndarray
    mask_y: np.ndarray
    map_xy: SurfaceMap
    map_yx: SurfaceMap


def cast_p2f(
    x: TriMesh,
    y: TriMesh,
    gt_xy: SurfaceMap,
    gt_yx: SurfaceMap,
    rng: RngSource,
    up_axis: str = "y",
    camera_distance: float = 1.0,
    samples_per_face: int = DEFAULT_SAMPLES_PER_FACE,
    scanner: Scanner | None = None,
) -> P2FResult:
    """One scan of Y from ``draw_camera(rng(0), up_axis, camera_distance)`` (Y's unit-box frame); X stays full.

    ``rng`` is as in :func:`cast_p2p` (``(seed, pair_id)`` -> ``rng_for(seed, pair_id, "cameras", 0)``);
    ``scanner`` an optional prebuilt ``Scanner(y)``.
    """
    factory = _rng_factory(rng)
    sy = scanner if scanner is not None else Scanner(y)
    drawn = draw_camera(factory(0), up_axis, camera_distance)
    cam_y = _unit_box_to_input(sy.centre, sy.scale)(drawn)
    py = sy.scan(cam_y, samples_per_face)
    fx = whole(x)
    mask_y, mask_x = overlap_mask(py, gt_yx, fx), overlap_mask(fx, gt_xy, py)
    return P2FResult(
        full_x=fx,
        partial_y=py,
        camera_y=cam_y,
        drawn_camera=drawn,
        centre_y=sy.centre,
        scale_y=sy.scale,
        overlap_x=float(mask_x.mean()) if len(mask_x) else 0.0,
        overlap_y=float(mask_y.mean()) if len(mask_y) else 0.0,
        mask_x=mask_x,
        mask_y=mask_y,
        map_xy=partial_map(fx, gt_xy, py),
        map_yx=partial_map(py, gt_yx, fx),
    )
