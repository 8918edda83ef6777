"""The matching-instance record, schema version 1: everything a pair's consumer needs, as flat arrays.

A record holds shape 0 (X), shape 1 (Y) and the ground truth between them; arrays that index a shape's
vertices are *named after that shape* (``x_overlap_mask``: one entry per vertex of X). The schema (keys,
dtypes, shapes, store groups, meanings) is one table, :data:`RECORD_SCHEMA`, from :data:`SIDE_FIELDS` (per
shape ``s`` in x, y) and :data:`PAIR_FIELDS` (``corr_01`` (V_x,) X vertex -> Y vertex, -1 = none, and its
barycentric form ``corr_01_face``/``corr_01_weights``; ``corr_10*`` from Y to X), listed at the end of this
docstring. Final frame: ``((file * scale - centre) @ frame_rotation @ align_rotation + align_translation)
@ random_rotation``. ``meta``: schema_version, pair_id, seed, setting, split, n_tries, accepted, try_index,
area_normalised, vertex_rounding (:data:`VERTEX_MAP_ROUNDING`), options, per shape name, dataset, category, class.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from becos.atomic import save_npz
from becos.build.record_sources import DERIVED_MEMBER, RecordSources, derive, leave_out, read_derived
from becos.digests import content_digest
from becos.settings import SETTINGS  # noqa: F401 (re-exported: becos.build.record.SETTINGS)

SCHEMA_VERSION = 1
SIDES = ("x", "y")
VERTEX_MAP_ROUNDING = "nearest_along_surface"
"""How a record's final vertex maps (``corr_01``, ``corr_10``) round a point to a vertex, written as meta
``vertex_rounding``: the vertex nearest the point along the surface among the holding face's corners and
its edge neighbours' far corners (:meth:`becos.core.surface_map.SurfaceMap.to_nearest_vertices`)."""
NEAREST_CORNER_VERTEX_MAP_ROUNDING = "nearest_corner"
"""The rounding of records with meta ``vertex_rounding: nearest_corner`` (becos between issue #20's first
fix and :data:`VERTEX_MAP_ROUNDING`): the corner of the holding face nearest the point in 3D."""
LEGACY_VERTEX_MAP_ROUNDING = "largest_weight"
"""The rounding of records without meta ``vertex_rounding`` (becos before issue #20; the reference's rule): the
largest-weight corner of the holding face."""


@dataclass(frozen=True)
class Field:
    """One record key of :data:`RECORD_SCHEMA`.

    Attributes:
        dtype: dtype of the array in a :class:`PairRecord` (what every reader returns).
        shape: ragged keys: the shape of one row (the leading length is the pair's); per-pair keys:
            the whole array's shape.
        group: ragged keys: the store's offsets group (``x_vertex``: one row per vertex of X ...),
            None for per-pair keys (stacked as (N, ...) in the store).
        meaning: what the array holds (units, frames, -1 conventions).
        stored: dtype on disk (pair record files and the store) when narrower than ``dtype``:
            vertex and face indices fit int32; readers widen them back, values unchanged.
        identity: the key is ``arange`` for a full shape; record files then omit it and readers
            derive it (:func:`encode_arrays` / :func:`decode_arrays`).
    """

    dtype: str
    shape: tuple[int, ...]
    group: str | None
    meaning: str
    stored: str | None = None
    identity: bool = False

    @property
    def disk_dtype(self) -> str:
        return self.stored or self.dtype


SIDE_FIELDS: dict[str, Field] = {
    "vertices": Field(
        "float64",
        (3,),
        "vertex",
        "(V_s, 3) in the final frame (after the random rotation), at dataset scale unless ``area_normalised``",
    ),
    "faces": Field("int64", (3,), "face", "(F_s, 3)", stored="int32"),
    "full_vertices": Field(
        "float64",
        (3,),
        "full_vertex",
        "(V_full, 3) the full (remeshed) shape in the same final frame, for errors measured on "
        "the full shape; (0, 3) when the shape is full (then it is ``s_vertices``)",
    ),
    "full_faces": Field(
        "int64", (3,), "full_face", "(F_full, 3) its faces; (0, 3) when the shape is full", stored="int32"
    ),
    "partial_to_full": Field(
        "int64",
        (),
        "vertex",
        "(V_s,) vertex of the full (remeshed) shape; arange when full",
        stored="int32",
        identity=True,
    ),
    "full_to_partial": Field(
        "int64",
        (),
        "full_to_partial",
        "(V_full,) -1 where the full vertex was not kept (V_full rows also for a full shape)",
        stored="int32",
        identity=True,
    ),
    "full_face_ids": Field(
        "int64", (), "face", "(F_s,) face of the full (remeshed) shape of each face", stored="int32", identity=True
    ),
    "overlap_mask": Field("bool", (), "vertex", "(V_s,) the vertex's ground-truth point lies on the other shape"),
    "annotation": Field("int8", (), "vertex", "(V_s,) reserved per-vertex label (left/right), -1 = none/unset"),
    "full_area": Field("float64", (), None, "area of the full remeshed shape at dataset scale"),
    "full_sqrt_area": Field("float64", (), None, "its square root (the Princeton error normaliser)"),
    "dataset_scale": Field("float64", (), None, "scale applied to the file's coordinates"),
    "frame_rotation": Field("float64", (3, 3), None, "file frame -> common y-up frame (row vectors, V @ R)"),
    "centre": Field("float64", (3,), None, "subtracted after scaling, before the frame rotation"),
    "align_rotation": Field("float64", (3, 3), None, "rigid alignment onto X (identity for X), row vectors"),
    "align_translation": Field("float64", (3,), None, "added after the alignment rotation"),
    "random_rotation": Field("float64", (3, 3), None, "applied last (row vectors)"),
    "camera": Field(
        "float64",
        (3, 3),
        None,
        "rows: position, look-at target, up, in the shape's common frame (before alignment); NaN for a full shape",
    ),
    "remesh_variant": Field("int64", (), None, "remesh variant index (-1 = not remeshed)"),
    "overlap": Field("float64", (), None, "share of V_s with ``s_overlap_mask`` (1.0 for F2F)"),
}
"""Per-shape keys, named ``<s>_<key>`` for s in :data:`SIDES`; group ``vertex`` means ``<s>_vertex``."""

PAIR_FIELDS: dict[str, Field] = {
    "": Field(
        "int64",
        (),
        "vertex",
        "(V_s,) vertex of the other shape: the corner of ``_face`` nearest the point, -1 = no counterpart",
        stored="int32",
    ),
    "_face": Field("int64", (), "vertex", "(V_s,) face of the other shape holding the point", stored="int32"),
    "_weights": Field("float64", (3,), "vertex", "(V_s, 3) barycentric weights in that face"),
}
"""Ground-truth keys, named ``corr_01<key>`` (X -> Y, rows of X) and ``corr_10<key>`` (Y -> X)."""

CORR_OF_SIDE = {"x": "corr_01", "y": "corr_10"}


def _schema() -> dict[str, Field]:
    out = {}
    for s in SIDES:
        for key, f in SIDE_FIELDS.items():
            out[f"{s}_{key}"] = replace(f, group=None if f.group is None else f"{s}_{f.group}")
    for s in SIDES:
        for key, f in PAIR_FIELDS.items():
            out[f"{CORR_OF_SIDE[s]}{key}"] = replace(f, group=f"{s}_{f.group}")
    return out


RECORD_SCHEMA: dict[str, Field] = _schema()
"""Record key -> :class:`Field`: the one definition of the pair-record schema."""
SHAPE_KEYS = tuple(SIDE_FIELDS)
PAIR_KEYS = tuple(f"{c}{k}" for c in CORR_OF_SIDE.values() for k in PAIR_FIELDS)
RECORD_KEYS = tuple(RECORD_SCHEMA)
IDENTITY_MEMBER = "__identity__"
"""Record-file member: JSON ``{key: length}`` of the identity maps left out of the file."""


def _schema_doc() -> str:
    rows = [
        (f"s_{k}", f.dtype + ("" if f.stored is None else f" ({f.stored} on disk)"), f.meaning)
        for k, f in SIDE_FIELDS.items()
    ]
    rows += [
        (f"corr_01{k}", f.dtype + ("" if f.stored is None else f" ({f.stored} on disk)"), f.meaning)
        for k, f in PAIR_FIELDS.items()
    ]
    w = [max(len(r[i]) for r in rows) for i in range(2)]
    rule = f"{'=' * w[0]}  {'=' * w[1]}  {'=' * 60}"
    lines = [rule, f"{'key':<{w[0]}}  {'dtype':<{w[1]}}  meaning", rule]
    lines += [f"{a:<{w[0]}}  {b:<{w[1]}}  {c}" for a, b, c in rows]
    return "\n".join(["", "Record keys (generated from :data:`RECORD_SCHEMA`; ``s`` is x or y):", "", *lines, rule, ""])


__doc__ = (__doc__ or "") + _schema_doc()


def encode_arrays(arrays: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray], dict[str, int]]:
    """The arrays as a record file stores them: schema index keys narrowed to their ``stored`` dtype
    when every value fits, identity maps (``arange``) left out. Returns ``(arrays, {left-out key: length})``;
    :func:`decode_arrays` inverts it exactly."""
    out, identity = {}, {}
    for key, value in arrays.items():
        f = RECORD_SCHEMA.get(key)
        if (
            f is not None
            and f.identity
            and value.ndim == 1
            and value.dtype == np.dtype(f.dtype)
            and len(value)
            and value[0] == 0
            and np.array_equal(value, np.arange(len(value)))
        ):
            identity[key] = len(value)
            continue
        if f is not None and f.stored is not None and value.dtype == np.dtype(f.dtype) and value.size:
            info = np.iinfo(f.stored)
            if info.min <= value.min() and value.max() <= info.max:
                value = value.astype(f.stored)
        out[key] = value
    return out, identity


def decode_arrays(stored: dict[str, np.ndarray], identity: dict[str, int] | None = None) -> dict[str, np.ndarray]:
    """Record arrays from :func:`encode_arrays`' output: schema keys widened back to their dtype,
    identity maps derived (``arange(length)``)."""
    out = {}
    for key, value in stored.items():
        f = RECORD_SCHEMA.get(key)
        if f is not None and f.stored is not None and value.dtype == np.dtype(f.stored):
            value = value.astype(f.dtype)
        out[key] = value
    for key, n in (identity or {}).items():
        out[key] = np.arange(int(n), dtype=RECORD_SCHEMA[key].dtype)
    return out


@dataclass
class PairRecord:
    """One matching instance: ``arrays`` (keys as in the module docstring) and ``meta`` (JSON-able)."""

    arrays: dict[str, np.ndarray]
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        missing = [k for k in RECORD_KEYS if k not in self.arrays]
        if missing:
            raise ValueError(f"pair record lacks {missing}")
        self.meta.setdefault("schema_version", SCHEMA_VERSION)

    def __getitem__(self, key: str) -> np.ndarray:
        return self.arrays[key]

    @property
    def pair_id(self) -> str:
        return self.meta["pair_id"]

    def save(self, path: str | Path, sources: RecordSources | None = None) -> None:
        """Write one .npz (arrays + ``meta`` as JSON), atomically. ``meta["content_digest"]`` is set to
        :func:`content_digest` of the record, so an edit of the file is noticed (:func:`is_intact`).

        The file is a .npz with deflated integer members (:func:`becos.atomic.save_npz`;
        :func:`encode_arrays`: int32 indices, no identity maps;
        ``__identity__`` lists the maps left out), read back exactly by :meth:`load`. With ``sources``
        (the files the record was made from) it also leaves out the members they give back byte for byte,
        listed in ``__derived__`` (:mod:`becos.build.record_sources`)."""
        self.meta["content_digest"] = content_digest(self.arrays, self.meta)
        derived = {} if sources is None else leave_out(self.arrays, self.meta, sources, Path(path).parent)
        kept = {k: v for k, v in self.arrays.items() if k not in derived.get("arrays", {})}
        stored, identity = encode_arrays(kept)
        extra = {DERIVED_MEMBER: np.array(json.dumps(derived, sort_keys=True))} if derived else {}
        save_npz(
            path,
            compressed=True,
            __meta__=np.array(json.dumps(self.meta, sort_keys=True)),
            **{IDENTITY_MEMBER: np.array(json.dumps(identity, sort_keys=True))},
            **extra,
            **stored,
        )

    @classmethod
    def load(cls, path: str | Path) -> PairRecord:
        """The record of a file :meth:`save` wrote; members it left out are made again from their sources
        (:func:`becos.build.record_sources.derive`, which raises when a source changed)."""
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["__meta__"]))
            identity = json.loads(str(data[IDENTITY_MEMBER])) if IDENTITY_MEMBER in data.files else {}
            derived = read_derived(data[DERIVED_MEMBER]) if DERIVED_MEMBER in data.files else {}
            stored = {k: data[k] for k in data.files if k not in ("__meta__", IDENTITY_MEMBER, DERIVED_MEMBER)}
        arrays = decode_arrays(stored, identity)
        if derived:
            arrays.update(derive(Path(path), derived, arrays, meta))
        return cls(arrays, meta)


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
