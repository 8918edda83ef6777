"""Pair assembly: two prepared shapes and their ground truth -> one matching instance (a PairRecord).

Settings: ``full_full`` (F2F, both full); ``partial_full`` (P2F: Y one virtual scan, X the full template
of Y's class); ``partial_partial`` (P2P: both scanned, camera pairs re-drawn until both overlaps lie in
``[min_overlap, max_overlap]``, :func:`becos.build.partiality.cast_p2p`). Frames: inputs are full meshes in the
common y-up frame at dataset scale; Y is moved rigidly onto X (Procrustes on the ground-truth pairs),
then each shape gets its own random rotation, applied last (about the up axis, or uniform on SO(3) with
``one_axis_rotation=False``); ``area_normalised`` divides by the full shape's sqrt-area (about the
common-frame origin) before it. Every draw comes from the pair's own seed (:func:`becos.seeding.rng_for`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.spatial.transform import Rotation

from becos.build.partiality import Partial, Scanner, align_to, cast_p2f, cast_p2p, whole
from becos.build.placement import place
from becos.build.record import VERTEX_MAP_ROUNDING, PairRecord
from becos.core.align import RigidTransform
from becos.core.mesh import TriMesh
from becos.core.surface_map import SurfaceMap
from becos.defaults import config_default
from becos.seeding import rng_for
from becos.settings import SETTINGS, overlap_range_problem

_UP = {"x": np.array([1.0, 0, 0]), "y": np.array([0, 1.0, 0]), "z": np.array([0, 0, 1.0])}


@dataclass(frozen=True)
class PairOptions:
    """Options of one setting (defaults: the config's, ``becos/data/schema.yaml``, the published
    benchmark's)."""

    setting: str = "full_full"
    cam_pos_regime: str = config_default("cam_pos_regime")
    up_axis: str = config_default("up_axis")
    camera_distance: float = config_default("camera_distance")
    n_cam_pos: int = config_default("n_cam_pos")
    min_overlap: float = config_default("min_overlap")
    max_overlap: float = config_default("max_overlap")
    one_axis_rotation: bool = config_default("one_axis_rotation")
    area_normalised: bool = config_default("area_normalised")

    def __post_init__(self):
        if self.setting not in SETTINGS:
            raise ValueError(f"setting must be one of {SETTINGS}, got {self.setting!r}")
        if self.up_axis not in _UP:
            raise ValueError(f"up_axis must be x, y or z, got {self.up_axis!r}")
        problem = overlap_range_problem(self.min_overlap, self.max_overlap)
        if problem:
            raise ValueError(problem)


@dataclass(frozen=True, eq=False)
class ShapeInstance:
    """A full shape ready to be paired.

    Attributes:
        dataset, name, category, shape_class: provenance.
        mesh: full mesh in the common frame at dataset scale (remeshed variant or original).
        scale: dataset scale applied to file coordinates.
        frame_rotation: (3, 3) file -> common frame rotation (row vectors).
        centre: (3,) subtracted after scaling, before the frame rotation.
        remesh_variant: index of the remesh variant, -1 if not remeshed.
    """

    dataset: str
    name: str
    category: str
    shape_class: str
    mesh: TriMesh
    scale: float = 1.0
    frame_rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    centre: np.ndarray = field(default_factory=lambda: np.zeros(3))
    remesh_variant: int = -1

    @cached_property
    def area(self) -> float:
        """Surface area of ``mesh`` (squared units), computed once per instance."""
        from becos.core.geometry import surface_area

        return surface_area(self.mesh)

    @cached_property
    def vertex_rounding(self):
        """:class:`becos.core.surface_map.VertexRounding` of ``mesh``, built once per instance; partials cut
        from it round through it with their kept faces."""
        from becos.core.surface_map import VertexRounding

        return VertexRounding(self.mesh.vertices, self.mesh.faces)


def random_rotation(rng: np.random.Generator, up_axis: str = "y", one_axis: bool = True) -> np.ndarray:
    """(3, 3) rotation for row vectors (``V @ R``): about the up axis by an angle uniform in [0, 2π),
    or uniform on SO(3)."""
    if one_axis:
        angle = rng.uniform(0.0, 2.0 * np.pi)
        return Rotation.from_rotvec(angle * _UP[up_axis]).as_matrix().T
    return Rotation.random(random_state=rng).as_matrix().T


def _camera_rows(camera) -> np.ndarray:
    if camera is None:
        return np.full((3, 3), np.nan)
    return np.stack([camera.position, camera.target, camera.up]).astype(np.float64)


def _shape_arrays(
    shape: ShapeInstance,
    partial: Partial,
    final_vertices: np.ndarray,
    overlap_mask: np.ndarray,
    align_rotation: np.ndarray,
    align_translation: np.ndarray,
    rotation: np.ndarray,
    camera,
    area: float,
    final_full_vertices: np.ndarray,
) -> dict[str, np.ndarray]:
    is_full = partial.mesh.n_faces == shape.mesh.n_faces
    return {
        "vertices": final_vertices,
        "faces": partial.mesh.faces,
        "full_vertices": np.zeros((0, 3)) if is_full else final_full_vertices,
        "full_faces": np.zeros((0, 3), dtype=np.int64) if is_full else np.asarray(shape.mesh.faces, dtype=np.int64),
        "partial_to_full": partial.partial_to_full,
        "full_to_partial": partial.full_to_partial,
        "full_face_ids": partial.face_ids,
        "overlap_mask": overlap_mask.astype(bool),
        "annotation": np.full(partial.mesh.n_vertices, -1, dtype=np.int8),
        "full_area": np.float64(area),
        "full_sqrt_area": np.float64(np.sqrt(area)),
        "dataset_scale": np.float64(shape.scale),
        "frame_rotation": np.asarray(shape.frame_rotation, dtype=np.float64),
        "centre": np.asarray(shape.centre, dtype=np.float64),
        "align_rotation": align_rotation,
        "align_translation": align_translation,
        "random_rotation": rotation,
        "camera": _camera_rows(camera),
        "remesh_variant": np.int64(shape.remesh_variant),
        "overlap": np.float64(overlap_mask.mean() if len(overlap_mask) else 0.0),
    }


@dataclass
class _Views:
    """What a setting keeps of a pair before the final placement: the two kept parts (``px`` of X,
    ``py`` of Y), the rigid alignment of Y onto X, the overlap masks, the maps between the parts, the
    cameras (None where no scan was made) and the setting's updates of the pair meta (tries)."""

    px: Partial
    py: Partial
    alignment: RigidTransform
    mask_x: np.ndarray
    mask_y: np.ndarray
    map_xy: SurfaceMap
    map_yx: SurfaceMap
    camera_x: object = None
    camera_y: object = None
    meta: dict = field(default_factory=dict)


def _published_p2p_views(x, y, gt_xy, gt_yx, published_views) -> _Views:
    """P2P on the published cameras' views (the try the reference keeps), with exact masks and maps."""
    from becos.build.partiality import cut, overlap_mask, partial_map

    pub = published_views(x.mesh, y.mesh, gt_xy, gt_yx)
    px, py = cut(x.mesh, pub.choice.kept_x), cut(y.mesh, pub.choice.kept_y)
    alignment = align_to(x.mesh, y.mesh, gt_xy)
    mask_x, mask_y = overlap_mask(px, gt_xy, py), overlap_mask(py, gt_yx, px)
    map_xy, map_yx = partial_map(px, gt_xy, py), partial_map(py, gt_yx, px)
    c = pub.choice
    meta = {
        "n_tries": len(c.reference_overlaps),
        "accepted": bool(c.accepted),
        "try_index": int(c.try_index),
        "published_views": {
            "camera_try": int(c.camera_try),
            "exact_try": int(c.exact_try),
            "exact_rule_keeps_another_try": bool(c.exact_differs),
            "reference_overlaps": c.reference_overlaps.tolist(),
            "exact_overlaps": c.exact_overlaps.tolist(),
            "sources": pub.sources,
        },
    }
    return _Views(px, py, alignment, mask_x, mask_y, map_xy, map_yx, pub.camera_x, pub.camera_y, meta)


def _cast_p2p_views(x, y, gt_xy, gt_yx, seed, pair_id, options: PairOptions, scanners) -> _Views:
    """P2P: both shapes scanned from cameras drawn from the pair's seed (:func:`becos.build.partiality.cast_p2p`)."""
    scan = cast_p2p(
        x.mesh,
        y.mesh,
        gt_xy,
        gt_yx,
        (seed, pair_id),
        regime=options.cam_pos_regime,
        up_axis=options.up_axis,
        camera_distance=options.camera_distance,
        n_tries=options.n_cam_pos,
        min_overlap=options.min_overlap,
        max_overlap=options.max_overlap,
        scanners=None if None in scanners else scanners,
    )
    meta = {"n_tries": scan.n_tries_used, "accepted": bool(scan.accepted), "try_index": scan.try_index}
    return _Views(
        scan.partial_x,
        scan.partial_y,
        scan.alignment,
        scan.mask_x,
        scan.mask_y,
        scan.map_xy,
        scan.map_yx,
        scan.camera_x,
        scan.camera_y,
        meta,
    )


def _p2f_views(x, y, gt_xy, gt_yx, seed, pair_id, options: PairOptions, scanner) -> _Views:
    """P2F: X whole, Y scanned from one camera drawn from the pair's seed (:func:`becos.build.partiality.cast_p2f`)."""
    scan = cast_p2f(
        x.mesh,
        y.mesh,
        gt_xy,
        gt_yx,
        (seed, pair_id),
        up_axis=options.up_axis,
        camera_distance=options.camera_distance,
        scanner=scanner,
    )
    alignment = align_to(x.mesh, y.mesh, gt_xy)
    meta = {"n_tries": 1, "try_index": 0}
    return _Views(
        scan.full_x,
        scan.partial_y,
        alignment,
        scan.mask_x,
        scan.mask_y,
        scan.map_xy,
        scan.map_yx,
        None,
        scan.camera_y,
        meta,
    )


def _views(x, y, gt_xy, gt_yx, seed, pair_id, options: PairOptions, scanners, published_views) -> _Views:
    """The setting's views of the pair (F2F: both shapes whole, the ground truth as the maps)."""
    if options.setting == "partial_partial" and published_views is not None:
        return _published_p2p_views(x, y, gt_xy, gt_yx, published_views)
    if options.setting == "partial_partial":
        return _cast_p2p_views(x, y, gt_xy, gt_yx, seed, pair_id, options, scanners)
    if options.setting == "partial_full":
        return _p2f_views(x, y, gt_xy, gt_yx, seed, pair_id, options, scanners[1])
    alignment = align_to(x.mesh, y.mesh, gt_xy)
    return _Views(whole(x.mesh), whole(y.mesh), alignment, gt_xy.matched, gt_yx.matched, gt_xy, gt_yx)


def _pair_meta(x, y, pair_id: str, seed: int, split: str, options: PairOptions) -> dict:
    """The pair meta before its views are made (their tries update it: :attr:`_Views.meta`)."""
    meta = {
        "pair_id": pair_id,
        "seed": int(seed),
        "setting": options.setting,
        "split": split,
        "area_normalised": options.area_normalised,
        "n_tries": 0,
        "accepted": True,
        "try_index": -1,
        "vertex_rounding": VERTEX_MAP_ROUNDING,
        "options": {k: getattr(options, k) for k in options.__dataclass_fields__},
    }
    for key, s in (("x", x), ("y", y)):
        meta[key] = {"name": s.name, "dataset": s.dataset, "category": s.category, "class": s.shape_class}
    return meta


def _final_rotations(seed: int, pair_id: str, options: PairOptions, rotations) -> tuple[np.ndarray, np.ndarray]:
    """(3, 3) rotations of x and y (row vectors, applied last): ``rotations`` if given, else drawn from
    the pair's seed."""
    if rotations is not None:
        rot_x, rot_y = (np.asarray(r, dtype=np.float64).reshape(3, 3) for r in rotations)
        return rot_x, rot_y
    rot_x = random_rotation(rng_for(seed, pair_id, "rotation", "x"), options.up_axis, options.one_axis_rotation)
    rot_y = random_rotation(rng_for(seed, pair_id, "rotation", "y"), options.up_axis, options.one_axis_rotation)
    return rot_x, rot_y


def _pair_arrays(x, y, views: _Views, rot_x: np.ndarray, rot_y: np.ndarray, area_normalised: bool) -> dict:
    """The record's arrays: each shape's kept part placed (Y aligned onto X, divided by the full shape's
    sqrt-area when ``area_normalised``, then rotated) and the maps between the parts."""
    area_x, area_y = x.area, y.area
    px, py, alignment = views.px, views.py, views.alignment
    norm_x = np.sqrt(area_x) if area_normalised else 1.0
    norm_y = np.sqrt(area_y) if area_normalised else 1.0
    final_x = place(px.mesh.vertices, norm_x, rot_x)
    final_y = place(py.mesh.vertices, norm_y, rot_y, alignment)
    full_x = place(x.mesh.vertices, norm_x, rot_x)
    full_y = place(y.mesh.vertices, norm_y, rot_y, alignment)

    arrays = {}
    shape_x = _shape_arrays(x, px, final_x, views.mask_x, np.eye(3), np.zeros(3), rot_x, views.camera_x, area_x, full_x)
    shape_y = _shape_arrays(
        y,
        py,
        final_y,
        views.mask_y,
        alignment.rotation.T.copy(),
        alignment.translation.copy(),
        rot_y,
        views.camera_y,
        area_y,
        full_y,
    )
    arrays.update({f"x_{k}": v for k, v in shape_x.items()})
    arrays.update({f"y_{k}": v for k, v in shape_y.items()})
    for name, m, target, full in (("corr_01", views.map_xy, py, y), ("corr_10", views.map_yx, px, x)):
        arrays[name] = target.round_to_vertices(m, full.vertex_rounding)
        arrays[f"{name}_face"] = m.face
        arrays[f"{name}_weights"] = m.weights
    return arrays


def build_pair(
    x: ShapeInstance,
    y: ShapeInstance,
    gt_xy: SurfaceMap,
    gt_yx: SurfaceMap,
    *,
    pair_id: str,
    seed: int,
    split: str,
    options: PairOptions,
    scanners: tuple[Scanner | None, Scanner | None] = (None, None),
    rotations: tuple[np.ndarray, np.ndarray] | None = None,
    published_views=None,
) -> PairRecord:
    """One matching instance.

    Args:
        x, y: the two full shapes (common frame).
        gt_xy: X vertices -> points on Y's surface; gt_yx: the converse (see :mod:`becos.build.network`).
        pair_id, seed: the pair's identity and seed; every random draw derives from them.
        split: train / val / test.
        options: the setting and its options.
        scanners: optional reusable :class:`becos.build.partiality.Scanner` of x and y.
        rotations: optional fixed (3, 3) random rotations of x and y (row vectors, applied last), e.g.
            the published pair lists' ``random_rot``; by default drawn from the pair's seed.
        published_views: P2P only, optional ``(x_mesh, y_mesh, gt_xy, gt_yx) ->``
            :class:`becos.build.reference_views.PublishedScan`: the views of the published cameras, the try
            the reference keeps; masks and maps are then computed on them with the exact ground truth.
    """
    if len(gt_xy) != x.mesh.n_vertices or len(gt_yx) != y.mesh.n_vertices:
        raise ValueError(
            f"pair {pair_id}: ground truth lengths {len(gt_xy)}, {len(gt_yx)} do not match the "
            f"meshes ({x.mesh.n_vertices}, {y.mesh.n_vertices} vertices)"
        )
    meta = _pair_meta(x, y, pair_id, seed, split, options)
    views = _views(x, y, gt_xy, gt_yx, seed, pair_id, options, scanners, published_views)
    meta.update(views.meta)
    rot_x, rot_y = _final_rotations(seed, pair_id, options, rotations)
    return PairRecord(_pair_arrays(x, y, views, rot_x, rot_y, options.area_normalised), meta)
