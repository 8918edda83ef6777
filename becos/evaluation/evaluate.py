"""Scoring predicted correspondences against a benchmark: per-pair metrics, summary tables, PCK plots.

``becos evaluate STORE PRED [PRED ...] --out DIR`` writes ``per_pair.csv``, ``summary.csv``/``.md``
(means x 100 per split, category and dataset; AUC columns name their preset), ``pck.csv``/``pck.png``
and ``evaluation.json``. A prediction is a folder of ``<pair_id>.npy`` (V_y,) int maps Y -> X (-1 = no
counterpart; optional ``_overlap_x``/``_overlap_y`` masks) or a Zarr group of the same arrays;
``--direction xy`` for X -> Y. Errors: geodesic distance on the full X between predicted vertex and
truth (``corr_10`` by default), over sqrt(area of the full X). Formats, metric rules and costs in
detail: docs/design/evaluate.md.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from becos.atomic import atomic_path, write_text
from becos.build.record import PairRecord
from becos.core.geodesics import GeodesicsCache, shape_key
from becos.core.mesh import TriMesh
from becos.core.surface_map import SurfaceMap
from becos.errors import InputFileError
from becos.evaluation.metrics import (
    DEFAULT_AUC_PRESET,
    PAPER_PRESET,
    get_preset,
    left_right_accuracy,
    overlap_f1,
    overlap_iou,
    pck_curve,
    summarise,
)
from becos.settings import SETTINGS

DIRECTIONS = {"yx": ("y", "x", "corr_10"), "xy": ("x", "y", "corr_01")}
"""direction -> (shape whose vertices the map covers, shape the map points into, true map key)."""

OVERLAP_SUFFIXES = {"x": "_overlap_x", "y": "_overlap_y"}

TRUTHS = ("vertex", "point")
"""What the error is measured against: the true vertex (default) or the exact barycentric point."""

CURVE_THRESHOLDS = np.round(np.arange(0, 201) * 0.005, 3)
"""Thresholds (units of sqrt(area)) of the stored PCK curves: 0, 0.005, ..., 1.0."""

OVERLAP_SCORE_THRESHOLD = 0.5


class PredictionError(InputFileError):
    """A prediction file or array is missing or malformed."""


# --------------------------------------------------------------------------------------------
# Predictions


@dataclass
class Prediction:
    """One method's output for one pair.

    Attributes:
        map: (V_src,) int64 vertex of the other shape per vertex, -1 = no counterpart.
        overlap_x: (V_x,) bool predicted overlap of X, or None.
        overlap_y: (V_y,) bool predicted overlap of Y, or None.
    """

    map: np.ndarray
    overlap_x: np.ndarray | None = None
    overlap_y: np.ndarray | None = None

    def overlap(self, shape: str) -> np.ndarray | None:
        return self.overlap_x if shape == "x" else self.overlap_y


def _as_map(array: np.ndarray, where: Path | str) -> np.ndarray:
    array = np.asarray(array)
    if array.ndim != 1 or not (
        np.issubdtype(array.dtype, np.integer)
        or (np.issubdtype(array.dtype, np.floating) and np.all(array == np.round(array)))
    ):
        raise PredictionError(
            where,
            f"a map must be a 1-D integer array (vertex ids, -1 = none); got dtype {array.dtype}, shape {array.shape}",
            "save one int array per pair with np.save(path, map.astype(np.int64))",
        )
    return array.astype(np.int64)


def _as_mask(array: np.ndarray, where: Path | str) -> np.ndarray:
    array = np.asarray(array)
    if array.ndim != 1:
        raise PredictionError(
            where, f"an overlap mask must be 1-D; got shape {array.shape}", "save one bool (or float score) per vertex"
        )
    return array.astype(bool) if array.dtype == bool else array.astype(np.float64) > OVERLAP_SCORE_THRESHOLD


class PredictionFolder:
    """Predictions stored as ``<pair_id>.npy`` (+ optional ``_overlap_x``/``_overlap_y``) in a folder."""

    def __init__(self, path: str | Path, name: str | None = None):
        self.path = Path(path)
        if not self.path.is_dir():
            raise PredictionError(
                self.path, "prediction folder not found", "pass a folder of <pair_id>.npy files or a Zarr store"
            )
        self.name = name or self.path.name

    def pair_ids(self) -> list[str]:
        names = sorted(p.name[:-4] for p in self.path.glob("*.npy"))
        return [n for n in names if not n.endswith(tuple(OVERLAP_SUFFIXES.values()))]

    def get(self, pair_id: str) -> Prediction | None:
        path = self.path / f"{pair_id}.npy"
        if not path.is_file():
            return None
        out = Prediction(_as_map(np.load(path, allow_pickle=False), path))
        for shape, suffix in OVERLAP_SUFFIXES.items():
            mask_path = self.path / f"{pair_id}{suffix}.npy"
            if mask_path.is_file():
                setattr(out, f"overlap_{shape}", _as_mask(np.load(mask_path, allow_pickle=False), mask_path))
        return out


class PredictionZarr:
    """Predictions stored as arrays ``<pair_id>`` (+ ``_overlap_x``/``_overlap_y``) of a Zarr group."""

    def __init__(self, path: str | Path, name: str | None = None):
        import zarr

        self.path = Path(path)
        try:
            self.group = zarr.open_group(str(self.path), mode="r")
        except Exception as exc:  # zarr raises several types for "not a group"
            raise PredictionError(
                self.path,
                f"cannot open as a Zarr group ({exc})",
                "write the predictions with zarr.open_group(path, mode='w')",
            ) from exc
        self.name = name or (self.path.name[:-5] if self.path.name.endswith(".zarr") else self.path.name)
        self._keys = set(self.group.array_keys())

    def pair_ids(self) -> list[str]:
        return sorted(k for k in self._keys if not k.endswith(tuple(OVERLAP_SUFFIXES.values())))

    def get(self, pair_id: str) -> Prediction | None:
        if pair_id not in self._keys:
            return None
        where = f"{self.path}[{pair_id}]"
        out = Prediction(_as_map(self.group[pair_id][...], where))
        for shape, suffix in OVERLAP_SUFFIXES.items():
            if f"{pair_id}{suffix}" in self._keys:
                setattr(out, f"overlap_{shape}", _as_mask(self.group[f"{pair_id}{suffix}"][...], where + suffix))
        return out


def open_predictions(path: str | Path, name: str | None = None) -> PredictionFolder | PredictionZarr:
    """A method's predictions: a Zarr group (``zarr.json`` or ``.zgroup`` inside) or a folder of .npy."""
    path = Path(path)
    if (path / "zarr.json").is_file() or (path / ".zgroup").is_file():
        return PredictionZarr(path, name)
    return PredictionFolder(path, name)


def write_prediction(folder: str | Path, pair_id: str, prediction: Prediction) -> None:
    """Write one pair's prediction in the folder format (atomically, one file per array)."""
    folder = Path(folder)
    arrays = {"": np.asarray(prediction.map, dtype=np.int64)}
    for shape, suffix in OVERLAP_SUFFIXES.items():
        mask = prediction.overlap(shape)
        if mask is not None:
            arrays[suffix] = np.asarray(mask, dtype=bool)
    for suffix, array in arrays.items():
        with atomic_path(folder / f"{pair_id}{suffix}.npy", suffix=".tmp.npy") as tmp:
            np.save(tmp, array)


# --------------------------------------------------------------------------------------------
# One record


@dataclass(frozen=True)
class FullShape:
    """The full shape a shape's errors are measured on.

    Attributes:
        mesh: the full mesh (record's final frame; units of the record's vertices).
        vertex_to_full: (V_s,) record vertex -> mesh vertex.
        face_to_full: (F_s,) record face -> mesh face (same corner order).
        sqrt_area: sqrt of the full shape's area, in the units of ``mesh`` (1 for area-normalised records).
    """

    mesh: TriMesh
    vertex_to_full: np.ndarray
    face_to_full: np.ndarray
    sqrt_area: float


def full_shape(record: PairRecord, s: str) -> FullShape:
    """The full shape of shape ``s`` (``"x"`` or ``"y"``) of a record: ``s_full_vertices`` /
    ``s_full_faces`` for a partial shape (checked: the partial's vertices and faces must be those of the
    full shape mapped through ``s_partial_to_full`` / ``s_full_face_ids``), the shape itself when those
    are empty (a full shape, schema v1)."""
    a = record.arrays
    vertices, faces = a[f"{s}_vertices"], np.asarray(a[f"{s}_faces"], dtype=np.int64)
    to_full = np.asarray(a[f"{s}_partial_to_full"], dtype=np.int64)
    face_ids = np.asarray(a[f"{s}_full_face_ids"], dtype=np.int64)
    sqrt_area = 1.0 if record.meta.get("area_normalised") else float(a[f"{s}_full_sqrt_area"])
    pair_id = record.meta.get("pair_id", "?")
    full_faces = a.get(f"{s}_full_faces")
    if full_faces is None or len(full_faces) == 0:
        if len(a[f"{s}_full_to_partial"]) != len(vertices):
            raise ValueError(
                f"pair {pair_id}: shape {s} is partial but the record has no {s}_full_vertices / "
                f"{s}_full_faces; errors must be measured on the full shape (rebuild the record)"
            )
        return FullShape(TriMesh(vertices, faces), np.arange(len(vertices)), np.arange(len(faces)), sqrt_area)
    mesh = TriMesh(a[f"{s}_full_vertices"], full_faces)
    if (len(to_full) and to_full.max() >= mesh.n_vertices) or (len(face_ids) and face_ids.max() >= mesh.n_faces):
        raise ValueError(
            f"pair {pair_id}: {s}_partial_to_full / {s}_full_face_ids point beyond {s}_full_vertices / {s}_full_faces"
        )
    if not np.array_equal(mesh.faces[face_ids], to_full[faces]):
        raise ValueError(
            f"pair {pair_id}: {s}_full_faces[{s}_full_face_ids] differ from {s}_faces mapped "
            f"through {s}_partial_to_full: the full shape is not the one the partial was cut from"
        )
    scale = max(float(np.abs(mesh.vertices).max()), 1e-300)
    if not np.allclose(mesh.vertices[to_full], vertices, rtol=0, atol=1e-6 * scale):
        raise ValueError(
            f"pair {pair_id}: {s}_full_vertices[{s}_partial_to_full] differ from {s}_vertices: "
            "the full shape must be stored in the record's final frame"
        )
    return FullShape(mesh, to_full, face_ids, sqrt_area)


def pair_info(record: PairRecord, row: Mapping | None = None) -> dict:
    """Identity columns of a pair: from the store's table row when given, else from the record's meta.

    ``category``: the table's (F2F/P2P: the pool; P2F: Y's category), else X's category when both
    shapes share it and Y's otherwise. ``dataset``: the shapes' dataset, ``a+b`` when they differ.
    """
    meta = record.meta
    x, y = meta.get("x", {}), meta.get("y", {})
    info = {
        "pair_id": meta.get("pair_id"),
        "setting": meta.get("setting"),
        "split": meta.get("split"),
        "x_dataset": x.get("dataset"),
        "x_name": x.get("name"),
        "y_dataset": y.get("dataset"),
        "y_name": y.get("name"),
    }
    category = meta.get("category")
    if category is None:
        category = x.get("category") if x.get("category") == y.get("category") else y.get("category")
    info["category"] = category
    if row is not None:
        for key in ("pair_id", "split", "category", "x_dataset", "x_name", "y_dataset", "y_name"):
            if key in row and row[key] is not None:
                info[key] = row[key]
    xd, yd = info["x_dataset"], info["y_dataset"]
    info["dataset"] = xd if xd == yd else f"{xd}+{yd}"
    return info


@dataclass
class PairResult:
    """Per-method results of one pair: table rows and (V_src,) error arrays (NaN excluded, inf failure)."""

    rows: list[dict]
    errors: dict[str, np.ndarray] = field(repr=False)


def _check_prediction(prediction: Prediction, n_src: int, n_dst: int, n: dict, method: str, pair_id: str):
    pred = prediction.map
    if len(pred) != n_src:
        raise PredictionError(
            method,
            f"pair {pair_id}: the map has {len(pred)} entries but the shape it covers has {n_src} vertices",
            "give one entry per vertex of the covered shape (Y for --direction yx), in the record's vertex order",
        )
    if len(pred) and (pred.min() < -1 or pred.max() >= n_dst):
        raise PredictionError(
            method,
            f"pair {pair_id}: map entries must lie in [-1, {n_dst}); got [{pred.min()}, {pred.max()}]",
            "use the record's vertex numbering, -1 = none",
        )
    for shape in ("x", "y"):
        mask = prediction.overlap(shape)
        if mask is not None and len(mask) != n[shape]:
            raise PredictionError(
                method,
                f"pair {pair_id}: overlap_{shape} has {len(mask)} entries, shape {shape} has {n[shape]} vertices",
                "one mask entry per vertex",
            )


def evaluate_record(
    record: PairRecord,
    predictions: Mapping[str, Prediction],
    *,
    presets: Iterable[str] = (DEFAULT_AUC_PRESET, PAPER_PRESET),
    geodesics: GeodesicsCache | None = None,
    direction: str = "yx",
    truth: str = "vertex",
    info: Mapping | None = None,
) -> PairResult:
    """Score several methods' predictions on one pair.

    Args:
        record: the pair (schema v1: partial shapes carry their full shape, see :func:`full_shape`).
        predictions: method name -> :class:`Prediction`.
        presets: AUC presets (names, :func:`becos.evaluation.metrics.get_preset`); the first one fills ``auc``.
        geodesics: the shared per-shape solver cache (a heat-method one is made when None).
        direction: ``"yx"`` (maps Y -> X like ``corr_10``) or ``"xy"`` (X -> Y like ``corr_01``).
        truth: ``"vertex"`` (default): the true point is the record's vertex-form truth ``corr_10`` (the
            corner of the exact point's face nearest it; the released ``corres_10``; the ground truth
            scores exactly 100); ``"point"``: the exact barycentric point
            ``corr_10_face``/``corr_10_weights`` (then even the ground-truth vertex map has errors up to
            about one edge; see docs/design/evaluate.md).
        info: identity columns (:func:`pair_info`); derived from the record when None.

    Returns:
        :class:`PairResult` with one row per method, in the order of ``predictions``.
    """
    presets = _checked_options(direction, truth, presets)
    geodesics = geodesics or GeodesicsCache("heat")
    src, dst, key = DIRECTIONS[direction]
    info = dict(pair_info(record) if info is None else info)
    pair_id = info.get("pair_id") or record.meta.get("pair_id")
    a = record.arrays
    n = {s: len(a[f"{s}_vertices"]) for s in ("x", "y")}
    p2p = _is_p2p(record, n)

    methods = list(predictions)
    for m in methods:
        _check_prediction(predictions[m], n[src], n[dst], n, m, pair_id)
    full = full_shape(record, dst)
    meta_dst = record.meta.get(dst, {})
    solver = geodesics.get(
        shape_key(full.mesh, meta_dst.get("dataset"), meta_dst.get("name"), int(a[f"{dst}_remesh_variant"])), full.mesh
    )
    face_on_full, weights, has_true = _true_points(a, key, full, truth)
    preds = np.stack([predictions[m].map for m in methods], axis=1) if methods else np.zeros((n[src], 0), np.int64)
    distances = _prediction_distances(solver, full, preds, face_on_full, weights, has_true)

    labels_src = np.asarray(a[f"{src}_annotation"], dtype=np.int64)
    labels_dst = np.asarray(a[f"{dst}_annotation"], dtype=np.int64)
    has_labels = bool((labels_src >= 0).any())
    true_labels = labels_src if p2p else np.where(has_true, labels_src, -1)

    result = PairResult([], {})
    for k, m in enumerate(methods):
        pred = preds[:, k]
        has_pred = pred >= 0
        errors = _method_errors(has_pred, has_true, distances[:, k] / full.sqrt_area, p2p)
        row = {
            "method": m,
            **info,
            "direction": direction,
            "truth": truth,
            "geodesics": solver.method,
            **_error_columns(errors, n[src]),
            **_auc_columns(errors, presets),
            **_overlap_scores(predictions[m], a, src, has_pred),
        }
        row["left_right"] = (
            left_right_accuracy(pred, true_labels, labels_dst, has_true if p2p else None)
            if has_labels
            else float("nan")
        )
        result.rows.append(row)
        result.errors[m] = errors
    return result


def _checked_options(direction: str, truth: str, presets: Iterable[str]) -> tuple[str, ...]:
    """The AUC presets as a tuple, once ``direction``, ``truth`` and each preset are known names."""
    if direction not in DIRECTIONS:
        raise ValueError(f"direction must be one of {sorted(DIRECTIONS)}, got {direction!r}")
    if truth not in TRUTHS:
        raise ValueError(f"truth must be one of {TRUTHS}, got {truth!r}")
    presets = tuple(presets)
    for p in presets:
        get_preset(p)
    return presets


def _method_errors(has_pred: np.ndarray, has_true: np.ndarray, scaled: np.ndarray, p2p: bool) -> np.ndarray:
    """(N,) errors of one method (``scaled``: its distances over the full shape's sqrt-area): NaN where
    neither a prediction nor a true point counts, inf for a missing prediction (and, P2P, for a
    prediction where no true point is)."""
    errors = np.where(has_pred & has_true, scaled, np.nan)
    errors[has_true & ~has_pred] = np.inf
    if p2p:
        errors[~has_true & has_pred] = np.inf
    return errors


def _is_p2p(record: PairRecord, n: Mapping[str, int]) -> bool:
    """Whether the pair is partial-to-partial: from its setting, or (records without one) from both
    shapes being cut (``n``: vertices per shape)."""
    a = record.arrays
    p2p = all(len(a[f"{s}_full_to_partial"]) != n[s] or (a[f"{s}_full_to_partial"] < 0).any() for s in ("x", "y"))
    if record.meta.get("setting") in SETTINGS:
        p2p = record.meta["setting"] == "partial_partial"
    return p2p


def _true_points(a: Mapping, key: str, full, truth: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The true points of the map ``key`` on the full target shape ``full``: (N,) face on the full mesh,
    (N, 3) barycentric weights, and (N,) whether the source vertex has a true point at all. ``truth``
    ``"vertex"``: the record's vertex-form truth as one-hot points; ``"point"``: the exact points."""
    true_face = np.asarray(a[f"{key}_face"], dtype=np.int64)
    has_true = true_face >= 0
    if truth == "vertex":  # the record's vertex-form truth, as one-hot points on the full shape
        true_vertex = np.asarray(a[key], dtype=np.int64)
        full_vertex = np.where(true_vertex >= 0, full.vertex_to_full[np.maximum(true_vertex, 0)], -1)
        point = SurfaceMap.from_vertex_indices(full_vertex, full.mesh.faces)
        return point.face, point.weights, has_true
    face_on_full = np.where(has_true, full.face_to_full[np.maximum(true_face, 0)], -1)
    return face_on_full, np.asarray(a[f"{key}_weights"], dtype=np.float64), has_true


def _prediction_distances(solver, full, preds, face_on_full, weights, has_true) -> np.ndarray:
    """(N, M) geodesic distances on the full target mesh (units of its vertices) from each source
    vertex's true point to the M methods' predicted vertices (``preds``, (N, M) target vertex indices,
    -1: none); NaN where either is missing."""
    targets = np.where(preds >= 0, full.vertex_to_full[np.maximum(preds, 0)], -1)
    distances = np.full(preds.shape, np.nan)
    rows_true = np.flatnonzero(has_true)
    if len(rows_true) and preds.shape[1]:
        if solver.method == "dijkstra":  # bounded searches from each prediction: exact, cheap when near
            for k in range(preds.shape[1]):
                ok = rows_true[targets[rows_true, k] >= 0]
                distances[ok, k] = solver.between(targets[ok, k], face_on_full[ok], weights[ok])
        else:  # heat: one set of rows, from the true points' corners, serves every method
            distances[rows_true] = solver.point_to_vertices(
                face_on_full[rows_true], weights[rows_true], targets[rows_true]
            )
    return distances


def _error_columns(errors: np.ndarray, n_vertices: int) -> dict:
    """Counts and mean of one method's (N,) errors (NaN: not scored, inf: failed)."""
    included = errors[~np.isnan(errors)]
    finite = included[np.isfinite(included)]
    return {
        "n_vertices": int(n_vertices),
        "n_scored": int(len(included)),
        "n_infinite": int(len(included) - len(finite)),
        "n_excluded": int(n_vertices - len(included)),
        "mean_error": float(finite.mean()) if len(finite) else float("nan"),
    }


def _auc_columns(errors: np.ndarray, presets: tuple[str, ...]) -> dict:
    """``auc`` and ``auc_preset`` of the first preset, and ``auc_<preset>`` of each."""
    out = {}
    for j, name in enumerate(presets):
        spec = get_preset(name)
        value = spec.area(pck_curve(errors, spec.thresholds))
        if j == 0:
            out["auc"], out["auc_preset"] = value, name
        out[f"auc_{name}"] = value
    return out


def _overlap_scores(prediction: Prediction, a: Mapping, src: str, has_pred: np.ndarray) -> dict:
    out, ious, f1s, sources = {}, [], [], []
    for shape in ("x", "y"):
        mask = prediction.overlap(shape)
        source = "files"
        if mask is None and shape == src:
            mask, source = has_pred, "map"
        if mask is None:
            out[f"iou_{shape}"] = out[f"f1_{shape}"] = float("nan")
            continue
        true = np.asarray(a[f"{shape}_overlap_mask"], dtype=bool)
        out[f"iou_{shape}"] = iou = overlap_iou(mask, true)
        out[f"f1_{shape}"] = f1 = overlap_f1(mask, true)
        ious.append(iou)
        f1s.append(f1)
        sources.append(source)
    out["iou"] = float(np.mean(ious))
    out["f1"] = float(np.mean(f1s))
    out["overlap_source"] = "files" if all(s == "files" for s in sources) else "map"
    return out


# --------------------------------------------------------------------------------------------
# Many records


@dataclass
class Evaluation:
    """Results of scoring methods on a set of pairs.

    Attributes:
        per_pair: one row per (method, pair), see :func:`evaluate_record`.
        curves: columns method, threshold, pck, n_pairs: the mean over pairs of the per-pair PCK curves
            at :data:`CURVE_THRESHOLDS`.
        preset: the chosen AUC preset (``auc`` column); the paper preset is always computed too.
        meta: run facts (methods, missing pairs, geodesics, timings).
    """

    per_pair: pd.DataFrame
    curves: pd.DataFrame
    preset: str
    meta: dict = field(default_factory=dict)

    def summary(self) -> pd.DataFrame:
        return summary_table(self.per_pair, self.preset)


def evaluate_records(
    pairs: Iterable[tuple[PairRecord, Mapping | None]],
    sources: Mapping[str, object],
    *,
    preset: str = DEFAULT_AUC_PRESET,
    geodesic_method: str = "heat",
    geodesics: GeodesicsCache | None = None,
    direction: str = "yx",
    truth: str = "vertex",
    allow_missing: bool = False,
    progress: bool = False,
) -> Evaluation:
    """Score every method of ``sources`` (name -> object with ``get(pair_id) -> Prediction | None``,
    e.g. :func:`open_predictions`) on each ``(record, table row or None)`` of ``pairs``.

    A method without a prediction for a pair raises :class:`PredictionError` unless ``allow_missing``
    (the pair is then skipped for that method and listed in ``meta["missing"]``).
    """
    get_preset(preset)
    presets = (preset,) if preset == PAPER_PRESET else (preset, PAPER_PRESET)
    geodesics = geodesics or GeodesicsCache(geodesic_method)
    rows, curves, missing = [], {m: [] for m in sources}, {m: [] for m in sources}
    started = time.perf_counter()
    count = 0
    for record, row in pairs:
        info = pair_info(record, row)
        predictions = {}
        for name, source in sources.items():
            pred = source.get(info["pair_id"])
            if pred is None:
                if not allow_missing:
                    raise PredictionError(
                        getattr(source, "path", name),
                        f"no prediction for pair {info['pair_id']}",
                        "predict every pair of the split, or pass --allow-missing",
                    )
                missing[name].append(info["pair_id"])
                continue
            predictions[name] = pred
        result = evaluate_record(
            record, predictions, presets=presets, geodesics=geodesics, direction=direction, truth=truth, info=info
        )
        rows.extend(result.rows)
        for name, errors in result.errors.items():
            curves[name].append(pck_curve(errors, CURVE_THRESHOLDS))
        count += 1
        if progress:
            print(f"becos evaluate: {count} pairs ({time.perf_counter() - started:.0f} s)", file=sys.stderr)
    per_pair = pd.DataFrame(rows)
    curve_rows = []
    for name, per in curves.items():
        stack = np.array(per) if per else np.full((0, len(CURVE_THRESHOLDS)), np.nan)
        scored = ~np.isnan(stack).all(axis=1)
        mean = stack[scored].mean(axis=0) if scored.any() else np.full(len(CURVE_THRESHOLDS), np.nan)
        curve_rows.append(
            pd.DataFrame({"method": name, "threshold": CURVE_THRESHOLDS, "pck": mean, "n_pairs": int(scored.sum())})
        )
    meta = {
        "methods": list(sources),
        "preset": preset,
        "presets": list(presets),
        "direction": direction,
        "truth": truth,
        "geodesics": geodesics.method,
        "n_pairs": count,
        "missing": {m: ids for m, ids in missing.items() if ids},
        "geodesic_rows_computed": geodesics.n_computed,
        "seconds": round(time.perf_counter() - started, 2),
    }
    return Evaluation(per_pair, pd.concat(curve_rows, ignore_index=True), preset, meta)


SUMMARY_METRICS = ("auc", "iou", "f1", "left_right")


def summary_table(per_pair: pd.DataFrame, preset: str) -> pd.DataFrame:
    """The paper-style table: per method (and setting), overall / per split / category / dataset, the
    means over pairs x 100 of the paper-preset AUC (``auc_x100[paper-0.00-0.99]``, the one comparable
    with the paper), the chosen-preset AUC (``auc_x100[<preset>]``), ``miou_x100``, ``f1_x100`` and
    ``left_right_x100``; plus ``mean_error`` (x sqrt(area)) and ``infinite_share`` (share of scored
    vertices with an infinite error)."""
    if per_pair.empty:
        return pd.DataFrame()
    data = per_pair.copy()
    data["infinite_share"] = data["n_infinite"] / data["n_scored"].where(data["n_scored"] > 0)
    aucs = [PAPER_PRESET] + ([preset] if preset != PAPER_PRESET else [])
    keep = [
        "method",
        "setting",
        "split",
        "category",
        "dataset",
        "mean_error",
        "infinite_share",
        *[f"auc_{p}" for p in aucs],
        "iou",
        "f1",
        "left_right",
    ]
    table = summarise(data[[c for c in keep if c in data.columns]])
    out = table[[c for c in ("method", "setting", "grouping", "group", "n_pairs") if c in table.columns]].copy()
    for p in aucs:
        out[f"auc_x100[{p}]"] = 100.0 * table[f"auc_{p}"]
    out["miou_x100"] = 100.0 * table["iou"]
    out["f1_x100"] = 100.0 * table["f1"]
    out["left_right_x100"] = 100.0 * table["left_right"]
    out["mean_error"] = table["mean_error"]
    out["infinite_share"] = table["infinite_share"]
    return out


def summary_markdown(summary: pd.DataFrame, preset: str, title: str) -> str:
    """``summary`` as a Markdown table headed by the presets it uses."""
    lines = [
        f"# {title}",
        "",
        f"AUC x100 under `{PAPER_PRESET}` ({get_preset(PAPER_PRESET).description}) is the column to compare "
        "with the BeCoS paper; " + (f"`{preset}`: {get_preset(preset).description}." if preset != PAPER_PRESET else ""),
        "",
        "Means over pairs of per-pair means over vertices; mIoU / F1 from predicted vs true overlap "
        "masks; left/right over labelled vertices (NaN: no labels).",
        "",
    ]
    if summary.empty:
        return "\n".join(lines + ["(no pairs)", ""])
    cols = list(summary.columns)
    lines.append("| " + " | ".join(cols) + " |")
    lines.append("|" + "---|" * len(cols))
    for _, r in summary.iterrows():
        cells = [f"{v:.2f}" if isinstance(v, float) else str(v) for v in r.tolist()]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot_pck(
    curves: pd.DataFrame,
    path: str | Path,
    *,
    title: str = "",
    max_threshold: float = 0.25,
    legend_auc: Mapping[str, str] | None = None,
) -> Path:
    """One PCK curve per method (x: error threshold in units of sqrt(area) up to ``max_threshold``;
    y: % of vertices), written as PNG atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4.2), dpi=120)
    for name, group in curves.groupby("method", sort=False):
        shown = group[group["threshold"] <= max_threshold + 1e-12]
        label = name + (f" ({legend_auc[name]})" if legend_auc and name in legend_auc else "")
        ax.plot(shown["threshold"], 100.0 * shown["pck"], label=label, linewidth=1.8)
    ax.set_xlim(0, max_threshold)
    ax.set_ylim(0, 100)
    ax.set_xlabel("geodesic error / sqrt(area of the full shape)")
    ax.set_ylabel("% correspondences")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    if title:
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path, suffix=".tmp.png") as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return path


def write_evaluation(
    evaluation: Evaluation,
    out: str | Path,
    *,
    title: str = "",
    plot_max: float = 0.25,
    extra_meta: Mapping | None = None,
) -> dict[str, Path]:
    """Write per_pair.csv, summary.csv, summary.md, pck.csv, pck.png and evaluation.json into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary = evaluation.summary()
    paths = {
        k: out / v
        for k, v in (
            ("per_pair", "per_pair.csv"),
            ("summary", "summary.csv"),
            ("markdown", "summary.md"),
            ("curves", "pck.csv"),
            ("plot", "pck.png"),
            ("meta", "evaluation.json"),
        )
    }
    write_text(paths["per_pair"], evaluation.per_pair.to_csv(index=False))
    write_text(paths["summary"], summary.to_csv(index=False))
    write_text(paths["markdown"], summary_markdown(summary, evaluation.preset, title or "becos evaluation"))
    write_text(paths["curves"], evaluation.curves.to_csv(index=False))
    legend = {}
    if not summary.empty:
        overall = summary[summary["grouping"] == "all"]
        for _, r in overall.iterrows():
            legend[r["method"]] = f"AUC×100 {r[f'auc_x100[{PAPER_PRESET}]']:.1f} paper" + (
                f", {r[f'auc_x100[{evaluation.preset}]']:.1f} {evaluation.preset}"
                if evaluation.preset != PAPER_PRESET
                else ""
            )
    plot_pck(evaluation.curves, paths["plot"], title=title, max_threshold=plot_max, legend_auc=legend)
    meta = {**evaluation.meta, **(extra_meta or {}), "files": {k: p.name for k, p in paths.items()}}
    write_text(paths["meta"], json.dumps(meta, indent=2, sort_keys=True, default=str) + "\n")
    return paths


def benchmark_pairs(benchmark, split: str | None) -> Iterator[tuple[PairRecord, Mapping]]:
    """``(record, table row)`` of a :class:`becos.products.store.Benchmark`, in table order (``split`` None or
    ``"all"``: every split)."""
    table = benchmark.table
    if split not in (None, "all"):
        table = table[table["split"] == split]
    for _, row in table.iterrows():
        yield benchmark.record(row["pair_id"]), row.to_dict()
