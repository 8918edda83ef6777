"""The matching-instance record, schema version 1: everything a pair's consumer needs, as flat arrays.

A record holds shape 0 (X) and shape 1 (Y) and the ground truth between them. Arrays that index a
shape's vertices are *named after that shape*: ``x_overlap_mask`` has one entry per vertex of X.

Per shape ``s`` in (``x``, ``y``):

=====================  ==========  ===========================================================
key                    dtype       meaning
=====================  ==========  ===========================================================
s_vertices             float64     (V_s, 3) in the final frame (after the random rotation), at
                                   dataset scale unless ``area_normalised``
s_faces                int64       (F_s, 3)
s_full_vertices        float64     (V_full, 3) the full (remeshed) shape in the same final frame, for
                                   errors measured on the full shape; (0, 3) when the shape is full
                                   (then it is ``s_vertices``)
s_full_faces           int64       (F_full, 3) its faces; (0, 3) when the shape is full
s_partial_to_full      int64       (V_s,) vertex of the full (remeshed) shape; arange when full
s_full_to_partial      int64       (V_full,) -1 where the full vertex was not kept
s_full_face_ids        int64       (F_s,) face of the full (remeshed) shape of each face
s_overlap_mask         bool        (V_s,) the vertex's ground-truth point lies on the other shape
s_annotation           int8        (V_s,) reserved per-vertex label (left/right), -1 = none/unset
s_full_area            float64     area of the full remeshed shape at dataset scale
s_full_sqrt_area       float64     its square root (the Princeton error normaliser)
s_dataset_scale        float64     scale applied to the file's coordinates
s_frame_rotation       float64     (3, 3) file frame -> common y-up frame (row vectors, V @ R)
s_centre               float64     (3,) subtracted after scaling, before the frame rotation
s_align_rotation       float64     (3, 3) rigid alignment onto X (identity for X), row vectors
s_align_translation    float64     (3,) added after the alignment rotation
s_random_rotation      float64     (3, 3) applied last (row vectors)
s_camera               float64     (3, 3) rows: position, look-at target, up, in the shape's
                                   common frame (before alignment); NaN for a full shape
s_remesh_variant       int64       remesh variant index (-1 = not remeshed)
s_overlap              float64     share of V_s with ``s_overlap_mask`` (1.0 for F2F)
=====================  ==========  ===========================================================

Ground truth (vertex form and barycentric form):

- ``corr_01`` (V_x,) int64: X vertex -> Y vertex, -1 = no counterpart on Y;
  ``corr_01_face`` (V_x,) int64 Y face, ``corr_01_weights`` (V_x, 3) barycentric weights.
- ``corr_10``, ``corr_10_face``, ``corr_10_weights``: the same from Y to X.

Final frame: ``final = ((file * scale - centre) @ frame_rotation @ align_rotation + align_translation)
@ random_rotation``. Metadata (``meta``): schema_version, pair_id, seed, setting, split, n_tries,
accepted, area_normalised, and per shape name, dataset, category, class.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from becos.atomic import save_npz
from becos.settings import SETTINGS  # noqa: F401 (re-exported: becos.record.SETTINGS)

SCHEMA_VERSION = 1
SHAPE_KEYS = ("vertices", "faces", "full_vertices", "full_faces", "partial_to_full", "full_to_partial",
              "full_face_ids", "overlap_mask",
              "annotation", "full_area", "full_sqrt_area", "dataset_scale", "frame_rotation", "centre",
              "align_rotation", "align_translation", "random_rotation", "camera", "remesh_variant", "overlap")
PAIR_KEYS = ("corr_01", "corr_01_face", "corr_01_weights", "corr_10", "corr_10_face", "corr_10_weights")


@dataclass
class PairRecord:
    """One matching instance: ``arrays`` (keys as in the module docstring) and ``meta`` (JSON-able)."""

    arrays: dict[str, np.ndarray]
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        missing = [f"{s}_{k}" for s in ("x", "y") for k in SHAPE_KEYS if f"{s}_{k}" not in self.arrays]
        missing += [k for k in PAIR_KEYS if k not in self.arrays]
        if missing:
            raise ValueError(f"pair record lacks {missing}")
        self.meta.setdefault("schema_version", SCHEMA_VERSION)

    def __getitem__(self, key: str) -> np.ndarray:
        return self.arrays[key]

    @property
    def pair_id(self) -> str:
        return self.meta["pair_id"]

    def save(self, path: str | Path) -> None:
        """Write one .npz (arrays + ``meta`` as JSON), atomically. ``meta["content_digest"]`` is set to
        :func:`content_digest` of the record, so an edit of the file is noticed (:func:`is_intact`)."""
        self.meta["content_digest"] = content_digest(self.arrays, self.meta)
        save_npz(path, __meta__=np.array(json.dumps(self.meta, sort_keys=True)), **self.arrays)

    @classmethod
    def load(cls, path: str | Path) -> "PairRecord":
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["__meta__"]))
            arrays = {k: data[k] for k in data.files if k != "__meta__"}
        return cls(arrays, meta)


def content_digest(arrays: dict[str, np.ndarray], meta: dict) -> str:
    """SHA-256 (hex, 16 digits) of a record's arrays (name, dtype, shape, bytes; sorted by name) and of
    its meta without ``content_digest``."""
    h = hashlib.sha256(json.dumps({k: v for k, v in meta.items() if k != "content_digest"}, sort_keys=True).encode())
    for key in sorted(arrays):
        a = np.ascontiguousarray(arrays[key])
        h.update(f"|{key}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


def is_intact(path: str | Path) -> bool:
    """True when the record file at ``path`` still holds what :meth:`PairRecord.save` wrote (its content
    digest matches); False for an edited, unreadable or digest-less file."""
    try:
        record = PairRecord.load(path)
    except Exception:
        return False
    return record.meta.get("content_digest") == content_digest(record.arrays, record.meta)


def full_shape(record: PairRecord, side: str) -> tuple[np.ndarray, np.ndarray]:
    """The full shape of ``side`` (``'x'`` or ``'y'``) in the record's final frame: (V, 3), (F, 3)."""
    full_v, full_f = record[f"{side}_full_vertices"], record[f"{side}_full_faces"]
    if len(full_f) == 0:
        return record[f"{side}_vertices"], record[f"{side}_faces"]
    return full_v, full_f
