"""A pair's ground-truth file: the exact maps between its two full shapes, both ways, as the
ground-truth stage writes them and the pairs and store stages read them (:func:`load_ground_truth`)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from becos.digests import content_digest

if TYPE_CHECKING:
    from becos.core.surface_map import SurfaceMap


def save_ground_truth(path: Path, key: str, gt_xy: SurfaceMap, gt_yx: SurfaceMap) -> None:
    """Write a pair's ground-truth file (:func:`load_ground_truth`), with its ``content_digest``."""
    from becos.atomic import save_npz

    arrays = {
        "input_key": np.array(key),
        "xy_face": narrow_faces(gt_xy.face),
        "xy_weights": gt_xy.weights,
        "xy_distance": gt_xy.distance,
        "yx_face": narrow_faces(gt_yx.face),
        "yx_weights": gt_yx.weights,
        "yx_distance": gt_yx.distance,
    }
    save_npz(path, compressed=True, content_digest=np.array(_ground_truth_digest(arrays)), **arrays)


def _ground_truth_digest(arrays: dict[str, np.ndarray]) -> str:
    return content_digest({k: v for k, v in arrays.items() if k != "content_digest"}, {})


def ground_truth_intact(path: Path) -> bool:
    """True when the ground-truth file at ``path`` still holds what :func:`save_ground_truth` wrote (its
    ``content_digest`` matches its arrays); False for an edited, unreadable or digest-less file."""
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except Exception:
        return False
    stored = arrays.get("content_digest")
    return stored is not None and str(stored) == _ground_truth_digest(arrays)


def narrow_faces(face: np.ndarray) -> np.ndarray:
    """Face indices as int32 on disk when they fit (:class:`SurfaceMap` widens them on load)."""
    return face.astype(np.int32) if len(face) and face.max() <= np.iinfo(np.int32).max else face


def load_ground_truth(path: Path):
    """``(gt_xy, gt_yx)`` :class:`becos.core.surface_map.SurfaceMap` from a ground-truth file (a .npz,
    :func:`becos.atomic.save_npz` compressed:
    ``input_key``, ``xy_face`` (V_x,) int32, ``xy_weights`` (V_x, 3), ``xy_distance`` (V_x,), the same
    for ``yx``, and ``content_digest`` (:func:`ground_truth_intact`); files of older becos hold int64
    faces, uncompressed, and no digest, so the ground-truth stage recomputes them)."""
    from becos.core.surface_map import SurfaceMap

    with np.load(path, allow_pickle=False) as d:
        return (
            SurfaceMap(d["xy_face"], d["xy_weights"], d["xy_distance"]),
            SurfaceMap(d["yx_face"], d["yx_weights"], d["yx_distance"]),
        )
