"""Matching metrics: geodesic errors, PCK curves and their AUC, overlap IoU/F1, left/right accuracy.

A prediction maps each vertex of Y to a vertex of X or -1 (like ``corres_10``). The error of a Y vertex
is the geodesic distance on X (a partial X: its FULL shape) between predicted vertex and true point,
over sqrt(area of X). Error arrays: (N,) float64, NaN = excluded, inf = P2P failure (matched without a
counterpart, or unmatched with one). Fractions are in [0, 1]. AUC conventions are named presets
(:func:`get_preset`): ``mean-<T>x<N>`` (default ``mean-0.10x40``), ``ulrssm-<T>x<N>`` and
``paper-0.00-0.99`` (the one that reproduces the BeCoS paper's figures). Conventions and presets in
detail: docs/design/evaluate.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from becos.core.mesh import TriMesh

_trapezoid = getattr(np, "trapezoid", None) or np.trapz  # numpy < 2 names it trapz

AUC_RULES = ("trapezoid-normalised", "trapezoid", "mean")


@dataclass(frozen=True)
class AucPreset:
    """How an AUC is computed.

    Attributes:
        name: the preset's name, recorded with every result.
        thresholds: (T,) increasing error thresholds (units of sqrt(area)).
        rule: ``"trapezoid-normalised"`` = trapezoid over the thresholds divided by their range (1 for a
            perfect curve); ``"trapezoid"`` = plain trapezoid over the thresholds (perfect = the range);
            ``"mean"`` = arithmetic mean of the PCK values.
    """

    name: str
    thresholds: np.ndarray = field(repr=False)
    rule: str
    description: str = ""

    def area(self, pck: np.ndarray) -> float:
        """The AUC of a (T,) PCK curve under this preset's rule."""
        return _area(np.asarray(pck, dtype=np.float64), self.thresholds, self.rule)


def _area(pck: np.ndarray, thresholds: np.ndarray, rule: str) -> float:
    if rule == "mean":
        return float(np.mean(pck))
    if rule == "trapezoid":
        return float(_trapezoid(pck, thresholds))
    if rule == "trapezoid-normalised":
        span = float(thresholds[-1] - thresholds[0])
        return float(_trapezoid(pck, thresholds) / span) if span > 0 else float(pck[0])
    raise ValueError(f"unknown AUC rule {rule!r}; choose one of {AUC_RULES}")


PRESET_FAMILIES = {"mean": "mean", "ulrssm": "trapezoid-normalised"}
"""Parametrised preset families ``<family>-<T>x<N>`` -> their AUC rule."""

PAPER_PRESET = "paper-0.00-0.99"
DEFAULT_AUC_PRESET = "mean-0.10x40"


def preset_name(family: str, max_threshold: float, steps: int) -> str:
    """The name of a parametrised preset, e.g. ``preset_name("mean", 0.1, 40) == "mean-0.10x40"``
    (T written with at least two decimals, exactly)."""
    if family not in PRESET_FAMILIES:
        raise ValueError(f"unknown AUC preset family {family!r}; choose one of {sorted(PRESET_FAMILIES)}")
    text = f"{max_threshold:.2f}"
    if float(text) != float(max_threshold):
        text = repr(float(max_threshold))
    return f"{family}-{text}x{int(steps)}"


def get_preset(name: str) -> AucPreset:
    """The :class:`AucPreset` of a name: ``"paper-0.00-0.99"`` or ``"<family>-<T>x<N>"`` with family
    ``mean`` or ``ulrssm`` (see docs/design/evaluate.md), T > 0 in units of sqrt(area), N >= 2."""
    if name in AUC_PRESETS:
        return AUC_PRESETS[name]
    family, _, rest = str(name).partition("-")
    t_text, _, n_text = rest.partition("x")
    try:
        max_threshold, steps = float(t_text), int(n_text)
    except ValueError:
        max_threshold, steps = float("nan"), 0
    if family not in PRESET_FAMILIES or not max_threshold > 0 or steps < 2:
        raise ValueError(
            f"unknown AUC preset {name!r}; choose {PAPER_PRESET!r} or '<family>-<T>x<N>' with "
            f"family in {sorted(PRESET_FAMILIES)}, T > 0 and N >= 2 (e.g. {DEFAULT_AUC_PRESET!r})"
        )
    rule = PRESET_FAMILIES[family]
    what = "mean of the PCK values" if rule == "mean" else "trapezoid normalised by the range (ULRSSM)"
    return AucPreset(
        name,
        np.linspace(0.0, max_threshold, steps),
        rule,
        f"PCK at linspace(0, {max_threshold:g}, {steps}); AUC = {what}; ground truth = 1",
    )


AUC_PRESETS: dict[str, AucPreset] = {
    "mean-0.10x40": AucPreset(
        "mean-0.10x40",
        np.linspace(0.0, 0.10, 40),
        "mean",
        "PCK at linspace(0, 0.10, 40); AUC = mean of the PCK values; ground truth = 1",
    ),
    "ulrssm-0.10x40": AucPreset(
        "ulrssm-0.10x40",
        np.linspace(0.0, 0.10, 40),
        "trapezoid-normalised",
        "PCK at linspace(0, 0.10, 40); AUC = trapezoid normalised by the range (ULRSSM); ground truth = 1",
    ),
    PAPER_PRESET: AucPreset(
        PAPER_PRESET,
        np.round(np.arange(100) * 0.01, 2),
        "trapezoid",
        "PCK at 0.00..0.99 step 0.01; AUC = trapezoid, not renormalised (DeepShapeMatchingKit, the "
        "BeCoS paper's figures); ground truth = 0.99",
    ),
}
"""The standard presets (any other ``<family>-<T>x<N>`` name works too, see :func:`get_preset`)."""


def pck_curve(errors: np.ndarray, thresholds: np.ndarray) -> np.ndarray:
    """(T,) fraction of the included errors that are <= each threshold.

    Args:
        errors: (N,) normalised errors; inf counts as never correct; NaN entries are excluded.
        thresholds: (T,) thresholds, same units as ``errors``.

    Returns NaN for every threshold when no error is included.
    """
    errors = np.asarray(errors, dtype=np.float64).reshape(-1)
    thresholds = np.asarray(thresholds, dtype=np.float64).reshape(-1)
    included = np.sort(errors[~np.isnan(errors)])
    if len(included) == 0:
        return np.full(len(thresholds), np.nan)
    return np.searchsorted(included, thresholds, side="right") / len(included)


@dataclass(frozen=True)
class AucResult:
    """An AUC with the preset it was computed under. ``value`` in [0, 1] (NaN if nothing included)."""

    value: float
    preset: str
    pck: np.ndarray = field(repr=False)

    def as_dict(self) -> dict:
        return {"auc": self.value, "auc_preset": self.preset}


def auc_preset(errors: np.ndarray, preset: str = DEFAULT_AUC_PRESET) -> AucResult:
    """AUC of the PCK curve of ``errors`` (see :func:`pck_curve`) under a named preset
    (:func:`get_preset`)."""
    spec = get_preset(preset)
    pck = pck_curve(errors, spec.thresholds)
    return AucResult(spec.area(pck), preset, pck)


def auc(errors: np.ndarray, max_threshold: float = 0.10, steps: int = 40, rule: str = "mean") -> float:
    """AUC of the PCK curve over ``linspace(0, max_threshold, steps)`` (see :class:`AucPreset` for the
    rules). The defaults equal the default preset ``"mean-0.10x40"``."""
    thresholds = np.linspace(0.0, max_threshold, steps)
    return _area(pck_curve(errors, thresholds), thresholds, rule)


def _as_mask(mask: np.ndarray, threshold: float) -> np.ndarray:
    mask = np.asarray(mask).reshape(-1)
    return mask if mask.dtype == bool else mask > threshold


def overlap_iou(pred_mask: np.ndarray, true_mask: np.ndarray, threshold: float = 0.5) -> float:
    """|P ∩ G| / |P ∪ G| of two (N,) per-vertex overlap masks (1 when both are empty).

    A non-boolean ``pred_mask`` is read as overlap scores: overlap where score > ``threshold``.
    """
    p, g = _as_mask(pred_mask, threshold), _as_mask(true_mask, threshold)
    if p.shape != g.shape:
        raise ValueError(f"overlap masks differ in length: {p.shape} vs {g.shape}")
    union = np.count_nonzero(p | g)
    return 1.0 if union == 0 else np.count_nonzero(p & g) / union


def overlap_f1(pred_mask: np.ndarray, true_mask: np.ndarray, threshold: float = 0.5) -> float:
    """F1 = 2PR / (P + R), precision P = |P∩G|/|P|, recall R = |P∩G|/|G| (1 when both masks are empty,
    0 when exactly one is)."""
    p, g = _as_mask(pred_mask, threshold), _as_mask(true_mask, threshold)
    if p.shape != g.shape:
        raise ValueError(f"overlap masks differ in length: {p.shape} vs {g.shape}")
    total = np.count_nonzero(p) + np.count_nonzero(g)
    return 1.0 if total == 0 else 2.0 * np.count_nonzero(p & g) / total


def _check_prediction(pred_10: np.ndarray, n_x: int | None) -> np.ndarray:
    pred = np.asarray(pred_10).reshape(-1)
    if not np.issubdtype(pred.dtype, np.integer):
        raise TypeError(f"a prediction holds vertex indices (integers, -1 = none); got dtype {pred.dtype}")
    pred = pred.astype(np.int64)
    if len(pred) and pred.min() < -1:
        raise ValueError(f"prediction entries must be >= -1; got {pred.min()}")
    if n_x is not None and len(pred) and pred.max() >= n_x:
        raise ValueError(f"prediction refers to vertex {pred.max()} but shape 0 has {n_x} vertices")
    return pred


def pair_errors(
    pred_10: np.ndarray,
    gt_10,
    geodesics_on_x,
    sqrt_area_x: float,
    gt_weights: np.ndarray | None = None,
    x_to_full: np.ndarray | None = None,
    p2p: bool = True,
) -> np.ndarray:
    """(V_y,) Princeton errors of one predicted map Y -> X, with the P2P infinity rule.

    Args:
        pred_10: (V_y,) int, predicted X vertex per Y vertex, -1 = no counterpart.
        gt_10: the true map, one of
            - a :class:`becos.core.surface_map.SurfaceMap` onto X's surface (faces of the mesh the geodesics
              are computed on);
            - (V_y,) int face ids of X (-1 = none), with ``gt_weights`` (V_y, 3) barycentric weights
              (faces of the mesh the geodesics are computed on, i.e. the FULL X);
            - (V_y,) int X vertex ids (-1 = none), with ``gt_weights=None``.
        geodesics_on_x: a :class:`becos.core.geodesics.GeodesicDistances` on the (full) X mesh.
        sqrt_area_x: sqrt of the total area of the full X, in the same units as the geodesics.
        x_to_full: (V_x_partial,) int, X's partial-to-full vertex map (partial2full) when ``pred_10`` and
            vertex-id ground truth refer to a partial X; None when they already index the full X.
        p2p: True (default) applies the P2P rule below to vertices without a true counterpart; False
            (F2F/P2F, where a method is not asked to detect missing parts) excludes them whatever the
            prediction.

    Returns:
        (V_y,) float64: geodesic error / sqrt_area_x where both predicted and true points exist; inf where
        exactly one of them exists (with ``p2p=False``: only where the true point exists and the
        prediction is -1); NaN (excluded) where neither does (with ``p2p=False``: wherever the true point
        is missing).
    """
    from becos.core.surface_map import SurfaceMap

    mesh: TriMesh = geodesics_on_x.mesh
    x_to_full = None if x_to_full is None else np.asarray(x_to_full, dtype=np.int64)
    n_x = mesh.n_vertices if x_to_full is None else len(x_to_full)
    pred = _check_prediction(pred_10, n_x)

    if isinstance(gt_10, SurfaceMap):
        true_map = gt_10
    elif gt_weights is not None:
        true_map = SurfaceMap(np.asarray(gt_10, dtype=np.int64), np.asarray(gt_weights, dtype=np.float64))
    else:
        gt_vertex = _check_prediction(gt_10, n_x)
        if x_to_full is not None:
            gt_vertex = np.where(gt_vertex >= 0, x_to_full[np.maximum(gt_vertex, 0)], -1)
        true_map = SurfaceMap.from_vertex_indices(gt_vertex, mesh.faces)
    if len(true_map) != len(pred):
        raise ValueError(
            f"prediction has {len(pred)} entries but the ground truth {len(true_map)}: both "
            "must have one entry per vertex of shape 1 (Y)"
        )
    if x_to_full is not None:
        pred = np.where(pred >= 0, x_to_full[np.maximum(pred, 0)], -1)

    has_pred = pred >= 0
    has_true = true_map.matched
    errors = np.full(len(pred), np.nan)
    errors[has_pred != has_true] = np.inf
    if not p2p:
        errors[~has_true] = np.nan
    both = np.flatnonzero(has_pred & has_true)
    if len(both):
        d = geodesics_on_x.between(pred[both], true_map.face[both], true_map.weights[both])
        errors[both] = d / float(sqrt_area_x)
    return errors


def left_right_accuracy(
    pred_10: np.ndarray, true_labels_y: np.ndarray, labels_x: np.ndarray, gt_matched_y: np.ndarray | None = None
) -> float:
    """Share of labelled Y vertices whose predicted X vertex carries the true left/right label.

    Args:
        pred_10: (V_y,) int predicted X vertex per Y vertex (-1 = none), indexing ``labels_x``.
        true_labels_y: (V_y,) int true label of each Y vertex (the label of its true image); < 0 = none.
        labels_x: (V_x,) int label of each X vertex; < 0 = none (counts as wrong when predicted).
        gt_matched_y: (V_y,) bool, True where the Y vertex truly has a counterpart on X (P2P); None = all.

    Vertices without a true label are ignored; correctly unmatched vertices are excluded; vertices matched
    without a counterpart or unmatched with one count as wrong. Returns NaN if nothing is scored.
    """
    labels_x = np.asarray(labels_x).reshape(-1)
    pred = _check_prediction(pred_10, len(labels_x))
    true = np.asarray(true_labels_y).reshape(-1)
    if len(true) != len(pred):
        raise ValueError(f"prediction has {len(pred)} entries but the labels {len(true)}")
    matched = np.ones(len(pred), bool) if gt_matched_y is None else np.asarray(gt_matched_y, bool).reshape(-1)
    has_pred = pred >= 0
    scored = (true >= 0) & (has_pred | matched)
    if not scored.any():
        return float("nan")
    predicted_label = np.where(has_pred, labels_x[np.maximum(pred, 0)], -1)
    correct = scored & has_pred & matched & (predicted_label == true) & (predicted_label >= 0)
    return float(np.count_nonzero(correct) / np.count_nonzero(scored))


def pair_record(
    errors: np.ndarray,
    presets: tuple[str, ...] = (DEFAULT_AUC_PRESET,),
    pred_overlap: np.ndarray | None = None,
    true_overlap: np.ndarray | None = None,
    left_right: float | None = None,
) -> dict:
    """One pair's metrics as a flat dict (a row of the per-pair table for :func:`summarise`).

    Keys: ``n_scored`` (included vertices), ``n_infinite``, ``mean_error`` (over finite errors),
    ``auc`` and ``auc_preset`` for the first preset, ``auc_<preset>`` for every preset, and ``iou``,
    ``f1``, ``left_right`` when given.
    """
    errors = np.asarray(errors, dtype=np.float64).reshape(-1)
    included = errors[~np.isnan(errors)]
    finite = included[np.isfinite(included)]
    record = {
        "n_scored": int(len(included)),
        "n_infinite": int(len(included) - len(finite)),
        "mean_error": float(finite.mean()) if len(finite) else float("nan"),
    }
    for k, name in enumerate(presets):
        result = auc_preset(errors, name)
        if k == 0:
            record.update(result.as_dict())
        record[f"auc_{name}"] = result.value
    if pred_overlap is not None and true_overlap is not None:
        record["iou"] = overlap_iou(pred_overlap, true_overlap)
        record["f1"] = overlap_f1(pred_overlap, true_overlap)
    if left_right is not None:
        record["left_right"] = float(left_right)
    return record


GROUPINGS = ("split", "category", "dataset")
KEEP_APART = ("method", "setting", "auc_preset")
"""Columns whose values are never averaged together (always part of the group key when present)."""


def summarise(per_pair: pd.DataFrame, groupings: tuple[str, ...] = GROUPINGS) -> pd.DataFrame:
    """Average per-pair metrics over pairs: overall, then per value of each grouping column.

    Args:
        per_pair: one row per pair; numeric columns are metrics (already averaged within the pair, e.g.
            by :func:`pair_record`); ``groupings`` columns (those present) name the pair's split, category,
            dataset...; columns of :data:`KEEP_APART` present are kept as keys, so that results of
            different methods, settings or AUC presets are never mixed.

    Returns:
        DataFrame with columns ``*KEEP_APART present, grouping, group, n_pairs, <metric means>``, where
        ``grouping`` is ``"all"`` (group ``"all"``) or a grouping column's name and ``group`` its value.
        NaN metrics (e.g. no left/right labels for a pair) are skipped in the means.
    """
    keys = [c for c in KEEP_APART if c in per_pair.columns]
    present = [c for c in groupings if c in per_pair.columns]
    metrics = [
        c
        for c in per_pair.columns
        if c not in keys
        and c not in present
        and pd.api.types.is_numeric_dtype(per_pair[c])
        and not pd.api.types.is_bool_dtype(per_pair[c])
    ]
    frames = []
    for grouping in ["all", *present]:
        data = per_pair.assign(_group="all") if grouping == "all" else per_pair.assign(_group=per_pair[grouping])
        by = [*keys, "_group"]
        grouped = data.groupby(by, sort=True, dropna=False)
        table = grouped[metrics].mean()
        table.insert(0, "n_pairs", grouped.size())
        table = table.reset_index().rename(columns={"_group": "group"})
        table.insert(len(keys), "grouping", grouping)
        frames.append(table)
    return pd.concat(frames, ignore_index=True)
