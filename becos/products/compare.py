"""Comparison of two benchmark stores (:mod:`becos.products.store`) of one setting: which pairs differ, and why.

:func:`compare_stores` matches the pairs of stores A and B by ``pair_id`` and returns a
:class:`StoreComparison`: pairs only in one store, per common pair the arrays that differ sorted into
reasons (remeshing, partial view, ground truth, rotations, annotations, scalars, meta), and the root
attributes (library versions, config keys) and layout differences that explain them. NaN equals NaN;
``atol`` is a float tolerance. Stores are read block-wise, so memory does not grow with the store.
Command line: ``becos validate STORE --against OTHER``. Reasons and their keys: docs/design/validate.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from becos.errors import BecosError

COMPARE_BLOCK_BYTES = 32 << 20
"""Uncompressed bytes of arrays read at once from each store."""
MAX_EXAMPLES = 3
IGNORED_ATTRIBUTES = ("created",)
"""Root attributes that always differ between two builds and are not compared."""
BUILD_ATTRIBUTES = ("versions",)
"""Root attributes compared and reported, but not counted against :attr:`StoreComparison.identical`."""

SIDE_REASONS = {
    "remeshing": ("full_vertices", "full_faces", "remesh_variant"),
    "partial view": ("overlap_mask", "overlap", "partial_to_full", "full_to_partial", "full_face_ids", "camera"),
    "rotations": ("frame_rotation", "centre", "align_rotation", "align_translation", "random_rotation"),
    "annotations": ("annotation",),
    "scalars": ("full_area", "full_sqrt_area", "dataset_scale"),
}
COORDINATE_KEYS = ("vertices", "full_vertices")
"""Side keys holding coordinates in the pair's final frame."""
TRANSFORM_KEYS = ("random_rotation", "align_rotation", "align_translation", "full_sqrt_area")
"""Per-pair transforms between a shape's common frame and the final frame (the last one only with
``area_normalised``)."""
CANONICAL_RTOL = 1e-9
"""Coordinates equal to this fraction of the shape's extent in the common frame count as the same
geometry (two rotations of one shape never agree to the last bit)."""
MESH_KEYS = ("vertices", "faces")
"""Side keys whose reason depends on the shape: remeshing when full, partial view when partial."""
REASONS = (
    "remeshing of X differs",
    "remeshing of Y differs",
    "partial view of X differs",
    "partial view of Y differs",
    "ground truth differs",
    "rotations of X differ",
    "rotations of Y differ",
    "annotations differ",
    "scalars differ",
    "meta differs",
    "other arrays differ",
)
"""Every reason, in the order the summary lists them (roughly cause before effect)."""


def key_reason(key: str) -> str:
    """The reason a differing ``key`` is reported under (for s_vertices / s_faces: the full-shape one,
    ``remeshing of S differs``; :func:`compare_stores` uses ``partial view of S differs`` for
    partial shapes)."""
    if key.startswith("corr_"):
        return "ground truth differs"
    side, _, rest = key.partition("_")
    if side in ("x", "y"):
        S = side.upper()
        if rest in MESH_KEYS or rest in SIDE_REASONS["remeshing"]:
            return f"remeshing of {S} differs"
        if rest in SIDE_REASONS["partial view"]:
            return f"partial view of {S} differs"
        if rest in SIDE_REASONS["rotations"]:
            return f"rotations of {S} differ"
        if rest in SIDE_REASONS["annotations"]:
            return "annotations differ"
        if rest in SIDE_REASONS["scalars"]:
            return "scalars differ"
    return "other arrays differ"


@dataclass
class StoreComparison:
    """Result of :func:`compare_stores` (A = ``path_a``, B = ``path_b``).

    Attributes:
        path_a, path_b: the stores.
        setting_a, setting_b, n_a, n_b: their settings and pair counts.
        only_a, only_b: pair ids in one store only (sorted).
        common: (M,) pair ids in both stores, in A's store order.
        values: key -> (M,) int64 differing values per common pair (0 = equal, -1 = different row
            count or trailing shape); keys compared: those of both layouts.
        max_abs: key -> (M,) float64 largest absolute difference per common pair (float keys only;
            inf where a value is NaN in one store only, NaN where the row counts differ).
        reasons: (M, len(REASONS)) bool, pair i differs for reason j.
        meta: pair_id -> {dotted meta key: [value in A, value in B]} for pairs whose meta differs.
        attributes: dotted root attribute -> [A, B] for attributes that differ (``created`` ignored;
            ``None`` = absent).
        layout: key -> {"a": ..., "b": ...} for keys absent from one store or with another dtype,
            row shape or offset group.
        atol: float tolerance used.
        partial: side ("x", "y") -> (M,) bool, the shape is partial in either store (its s_vertices /
            s_faces differences count as partial view, else as remeshing).
        moved: coordinate key (s_vertices, s_full_vertices) -> (M,) bool, the coordinates differ only
            through the pair's transforms (same geometry in the common frame): reported under
            ``rotations of S differ`` only.
    """

    path_a: Path
    path_b: Path
    setting_a: str
    setting_b: str
    n_a: int
    n_b: int
    only_a: list[str]
    only_b: list[str]
    common: np.ndarray
    values: dict[str, np.ndarray]
    max_abs: dict[str, np.ndarray]
    reasons: np.ndarray
    meta: dict[str, dict] = field(default_factory=dict)
    attributes: dict[str, list] = field(default_factory=dict)
    layout: dict[str, dict] = field(default_factory=dict)
    atol: float = 0.0
    partial: dict[str, np.ndarray] = field(default_factory=dict)
    moved: dict[str, np.ndarray] = field(default_factory=dict)

    # ----------------------------------------------------------------------------------------------
    @property
    def differing(self) -> np.ndarray:
        """(M,) bool: common pairs with any difference."""
        return self.reasons.any(axis=1)

    @property
    def differing_ids(self) -> list[str]:
        return [str(p) for p in self.common[self.differing]]

    @property
    def version_differences(self) -> dict[str, list]:
        """package -> [version in A, version in B] (None = not recorded)."""
        return {k.split(".", 1)[1]: v for k, v in self.attributes.items() if k.startswith("versions.")}

    @property
    def data_identical(self) -> bool:
        """Same pair ids, and every common pair's arrays and meta equal, same layout."""
        return not (self.only_a or self.only_b or self.layout or self.differing.any())

    @property
    def identical(self) -> bool:
        """:attr:`data_identical` and the same root attributes apart from ``created`` and ``versions``."""
        return self.data_identical and not any(k.split(".")[0] not in BUILD_ATTRIBUTES for k in self.attributes)

    def pair_reasons(self, pair_id: str) -> list[str]:
        """Reasons a common pair differs (empty: identical); KeyError for a pair not in both stores."""
        rows = np.flatnonzero(self.common == pair_id)
        if not len(rows):
            raise KeyError(f"pair {pair_id!r} is not in both stores")
        return [r for r, hit in zip(REASONS, self.reasons[rows[0]]) if hit]

    def pair_keys(self, pair_id: str) -> dict[str, dict]:
        """key -> {"values": n differing (-1: shape differs), "max_abs": float or None} for one pair."""
        return self._row_keys(int(np.flatnonzero(self.common == pair_id)[0]))

    def _row_keys(self, i: int) -> dict[str, dict]:
        """:meth:`pair_keys` of common row ``i``."""
        out = {}
        for key, v in self.values.items():
            if v[i]:
                m = self.max_abs.get(key)
                out[key] = {"values": int(v[i]), "max_abs": None if m is None else _json_float(m[i])}
                if key in self.moved and self.moved[key][i]:
                    out[key]["same_in_common_frame"] = True
        return out

    def reason_counts(self) -> dict[str, int]:
        """reason -> number of common pairs differing for it (reasons with no pair left out)."""
        return {r: int(n) for r, n in zip(REASONS, self.reasons.sum(axis=0)) if n}

    def key_stats(self) -> dict[str, dict]:
        """key -> {"pairs", "values", "max_abs", "example", "reason"} over the differing pairs."""
        out = {}
        for key, v in self.values.items():
            hit = v != 0
            if not hit.any():
                continue
            m = self.max_abs.get(key)
            finite = m[hit][~np.isnan(m[hit])] if m is not None else np.zeros(0)
            moved = self.moved[key] & hit if key in self.moved else np.zeros(len(v), dtype=bool)
            out[key] = {
                "pairs": int(hit.sum()),
                "values": int(v[v > 0].sum()),
                "shape_differs": int((v < 0).sum()),
                "same_in_common_frame": int(moved.sum()),
                "max_abs": _json_float(finite.max()) if len(finite) else None,
                "example": str(self.common[np.flatnonzero(hit)[0]]),
                "reason": key_reason(key),
            }
        return out

    def _key_reasons(self, key: str) -> set[str]:
        """Reasons a differing key contributed to (s_vertices / s_faces: remeshing and/or partial view)."""
        side, _, rest = key.partition("_")
        hit = self.values[key] != 0
        moved = self.moved.get(key, np.zeros(len(hit), dtype=bool))
        out = {f"rotations of {side.upper()} differ"} if (hit & moved).any() else set()
        hit &= ~moved
        if side in ("x", "y") and rest in MESH_KEYS:
            partial = self.partial.get(side, np.zeros(len(hit), dtype=bool))
            S = side.upper()
            out |= ({f"remeshing of {S} differs"} if (hit & ~partial).any() else set()) | (
                {f"partial view of {S} differs"} if (hit & partial).any() else set()
            )
        elif hit.any():
            out.add(key_reason(key))
        return out

    # ----------------------------------------------------------------------------------------------
    def to_json(self) -> dict:
        """The full report, JSON-able: counts, per reason and key statistics, every differing pair."""
        pairs = {}
        for i in np.flatnonzero(self.differing):
            pid = str(self.common[i])
            entry = {
                "reasons": [r for r, hit in zip(REASONS, self.reasons[i]) if hit],
                "arrays": self._row_keys(int(i)),
            }
            if pid in self.meta:
                entry["meta"] = self.meta[pid]
            pairs[pid] = entry
        reason_pairs = {
            r: [str(p) for p in self.common[self.reasons[:, j]]]
            for j, r in enumerate(REASONS)
            if self.reasons[:, j].any()
        }
        return {
            "store_a": str(self.path_a),
            "store_b": str(self.path_b),
            "identical": self.identical,
            "data_identical": self.data_identical,
            "setting": [self.setting_a, self.setting_b],
            "n_pairs": [self.n_a, self.n_b],
            "n_common": int(len(self.common)),
            "n_differing": int(self.differing.sum()),
            "only_a": self.only_a,
            "only_b": self.only_b,
            "reasons": reason_pairs,
            "arrays": self.key_stats(),
            "attributes": self.attributes,
            "versions": self.version_differences,
            "layout": self.layout,
            "atol": self.atol,
            "pairs": pairs,
        }

    def summary(self) -> str:
        """A readable multi-line summary: pair counts, reasons with example pairs and the arrays behind
        them, layout and metadata (versions, config) differences, and the verdict."""
        n_diff = int(self.differing.sum())
        lines = [
            f"compare: {self.path_a} ({self.n_a} pairs, {self.setting_a}) against {self.path_b} "
            f"({self.n_b} pairs, {self.setting_b})"
        ]
        if self.setting_a != self.setting_b:
            lines.append(f"  settings differ: {self.setting_a} vs {self.setting_b} (compare stores of one setting)")
        lines.append(
            f"  pairs: {len(self.common)} in both ({len(self.common) - n_diff} identical, {n_diff} differ), "
            f"{len(self.only_a)} only in {self.path_a.name}, {len(self.only_b)} only in {self.path_b.name}"
        )
        if self.only_a:
            lines.append(f"  only in {self.path_a}: {len(self.only_a)} pair(s), e.g. {_examples(self.only_a)}")
        if self.only_b:
            lines.append(f"  only in {self.path_b}: {len(self.only_b)} pair(s), e.g. {_examples(self.only_b)}")
        stats = self.key_stats()
        for j, reason in enumerate(REASONS):
            hit = self.reasons[:, j]
            if hit.any():
                detail = self._reason_detail(reason, stats)
                lines.append(f"  {reason}: {int(hit.sum())} pair(s), e.g. {_examples(self.common[hit])} ({detail})")
        for key, d in self.layout.items():
            lines.append(f"  layout of {key} differs: {d['a']} vs {d['b']}")
        versions = self.version_differences
        if versions:
            lines.append(
                "  versions differ: " + "; ".join(f"{k} {_show(a)} -> {_show(b)}" for k, (a, b) in versions.items())
            )
        other = {k: v for k, v in self.attributes.items() if not k.startswith("versions.")}
        for key, (a, b) in list(other.items())[:12]:
            lines.append(f"  metadata {key}: {_show(a)} -> {_show(b)}")
        if len(other) > 12:
            lines.append(f"  ... {len(other) - 12} more metadata differences (see --json)")
        lines.append(f"  result: {self._verdict(n_diff)}")
        return "\n".join(lines)

    def _reason_detail(self, reason: str, stats: dict) -> str:
        """The summary's parenthesis after a reason: the meta keys that differ, or the arrays behind it."""
        if reason == "meta differs":
            keys = sorted({k for m in self.meta.values() for k in m})
            return "keys " + ", ".join(keys[:6]) + (" ..." if len(keys) > 6 else "")
        parts = []
        for key, st in stats.items():
            if reason in self._key_reasons(key):
                # under a rotations reason, the rotations before the coordinates they moved
                parts.append(
                    (reason.startswith("rotations") and _is_coordinate_key(key), self._key_text(key, st, reason))
                )
        parts = [text for _, text in sorted(parts, key=lambda p: p[0])]
        more = f"; {len(parts) - 4} more array(s), see --json" if len(parts) > 4 else ""
        tol = f" (atol {self.atol:g})" if self.atol else ""
        return "; ".join(parts[:4]) + more + tol

    def _key_text(self, key: str, st: dict, reason: str) -> str:
        """One array's part of a reason's detail (:meth:`key_stats` ``st``)."""
        text = f"{key}: {st['pairs']} pair(s)"
        if st["pairs"] > st["shape_differs"]:
            text += f", {st['values']} value(s)"
            if key in self.max_abs:
                text += f", max |diff| {_number(st['max_abs'])}"
        if st["shape_differs"]:
            text += (
                ", row count differs"
                if st["shape_differs"] == st["pairs"]
                else f", row count differs in {st['shape_differs']}"
            )
        if st["same_in_common_frame"] and reason.startswith("rotations"):
            text += (
                ", same in the common frame"
                if st["same_in_common_frame"] == st["pairs"]
                else f", same in the common frame in {st['same_in_common_frame']}"
            )
        return text

    def _verdict(self, n_diff: int) -> str:
        if self.identical:
            return "identical" + (" data (built with other library versions)" if self.attributes else "")
        if self.data_identical:
            return "same pairs and arrays, but the metadata differs"
        return (
            f"the stores differ: {n_diff} pair(s) differ, {len(self.only_a) + len(self.only_b)} "
            f"in one store only{', layouts differ' if self.layout else ''}"
        )


def _examples(ids) -> str:
    """Up to MAX_EXAMPLES pair ids, comma-separated (``...`` when there are more)."""
    ids = [str(p) for p in ids]
    return ", ".join(ids[:MAX_EXAMPLES]) + (" ..." if len(ids) > MAX_EXAMPLES else "")


def _number(x) -> str:
    return "n/a" if x is None else (x if isinstance(x, str) else f"{x:.3g}")


def _json_float(x) -> float | str | None:
    """A float for JSON: None for NaN (not applicable), "inf" for infinity (NaN in one store only)."""
    x = float(x)
    return None if x != x else ("inf" if np.isinf(x) else x)


def _show(value) -> str:
    text = "(absent)" if value is None else str(value)
    return text if len(text) <= 60 else text[:57] + "..."


# --------------------------------------------------------------------------------------------------
# comparing


def _flatten(value, prefix: str = "") -> dict:
    """Nested dicts -> {dotted key: leaf value} (lists are leaves)."""
    if isinstance(value, dict) and value:
        out = {}
        for k, v in value.items():
            out.update(_flatten(v, f"{prefix}{k}."))
        return out
    return {prefix[:-1]: value}


def _same(a, b) -> bool:
    """Equal JSON values (Python equality), NaN equal to NaN."""
    return bool(a == b) or (isinstance(a, float) and isinstance(b, float) and a != a and b != b)


def dict_differences(a: dict, b: dict, ignore: tuple[str, ...] = ()) -> dict[str, list]:
    """{dotted key: [value in a, value in b]} where two nested dicts differ (absent -> None);
    ``versions.*`` first, then sorted."""
    fa = {k: v for k, v in _flatten(a).items() if k.split(".")[0] not in ignore}
    fb = {k: v for k, v in _flatten(b).items() if k.split(".")[0] not in ignore}
    out = {}
    for key in sorted(set(fa) | set(fb), key=lambda k: (k.split(".")[0] != "versions", k)):
        if (key in fa) != (key in fb) or not _same(fa[key], fb[key]):
            out[key] = [fa.get(key), fb.get(key)]
    return out


def _open(path):
    """The :class:`becos.products.store.Benchmark` of a store; a missing or damaged store raises a
    :class:`BecosError` saying what is wrong (as ``becos validate`` would) instead of a traceback."""
    from becos.products.validate import open_for_validation

    bench, problems = open_for_validation(path)
    if bench is None:
        raise BecosError(problems[0].removeprefix("store: "))
    return bench


def _batches(
    rows_a: np.ndarray, rows_b: np.ndarray, bytes_a: np.ndarray, bytes_b: np.ndarray, max_bytes: int
) -> list[tuple[int, int]]:
    """Consecutive runs ``k0:k1`` of the common pairs (sorted by A row) whose spans of rows in A and in
    B each hold about ``max_bytes`` at most (at least one pair per run): one read per store and run.
    When the two stores share an order the runs are contiguous in both; otherwise they shrink."""
    cum_a = np.concatenate([[0], np.cumsum(bytes_a)])
    cum_b = np.concatenate([[0], np.cumsum(bytes_b)])
    out, k0 = [], 0
    lo_b = hi_b = None
    for k in range(len(rows_a)):
        rb = int(rows_b[k])
        if k > k0:
            span_a = cum_a[rows_a[k] + 1] - cum_a[rows_a[k0]]
            nlo, nhi = min(lo_b, rb), max(hi_b, rb)
            span_b = cum_b[nhi + 1] - cum_b[nlo]
            if span_a > max_bytes or span_b > max_bytes:
                out.append((k0, k))
                k0, lo_b, hi_b = k, rb, rb
                continue
            lo_b, hi_b = nlo, nhi
        else:
            lo_b = hi_b = rb
    if len(rows_a):
        out.append((k0, len(rows_a)))
    return out


def _row_index(starts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Concatenated ``arange(s, s + c)`` for every (s, c), vectorised."""
    total = int(counts.sum())
    if not total:
        return np.zeros(0, dtype=np.int64)
    seg_start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    return np.repeat(starts - seg_start, counts) + np.arange(total)


def _compare_rows(xa: np.ndarray, xb: np.ndarray, atol: float) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Per row of two (R, ...) arrays: (differing values (R,), largest |difference| (R,) for floats);
    ``(None, None)`` when every value is equal (the common case, decided in one pass)."""
    width = int(np.prod(xa.shape[1:], dtype=np.int64))
    xa, xb = xa.reshape(len(xa), width), xb.reshape(len(xb), width)
    neq = xa != xb
    if not neq.any():
        return None, None
    if xa.dtype.kind == "f" or xb.dtype.kind == "f":
        with np.errstate(invalid="ignore", over="ignore"):
            d = np.abs(xa.astype(np.float64, copy=False) - xb.astype(np.float64, copy=False))
        d[np.isnan(xa) & np.isnan(xb)] = 0.0
        d[np.isnan(d)] = np.inf  # NaN in one store only, or inf - inf
        return (d > atol).sum(axis=1), (d.max(axis=1) if width else np.zeros(len(d)))
    return neq.sum(axis=1), None


def compare_stores(
    a: str | Path, b: str | Path, *, atol: float = 0.0, max_bytes: int = COMPARE_BLOCK_BYTES
) -> StoreComparison:
    """Compare store ``a`` with store ``b`` pair by pair (reasons: docs/design/validate.md).

    Args:
        a, b: store folders written by :func:`becos.products.store.write_store`.
        atol: float values within ``atol`` count as equal (0: exact).
        max_bytes: uncompressed bytes of arrays read at once from each store.

    Returns:
        :class:`StoreComparison`. Raises :class:`BecosError` (naming the store, the problem and the fix)
        if a store is missing or cannot be opened.
    """
    A, B = _open(a), _open(b)
    ia, ib, common, only_a, only_b = _matched_pairs(A, B)
    layout, keys = _compare_layouts(A, B)

    m = len(common)
    values = {k: np.zeros(m, dtype=np.int64) for k in keys}
    max_abs = {}
    for k in keys:
        if A.array(k).dtype.kind == "f" or B.array(k).dtype.kind == "f":
            max_abs[k] = np.zeros(m, dtype=np.float64)
    partial = {s: np.zeros(m, dtype=bool) for s in ("x", "y")}
    moved = {k: np.zeros(m, dtype=bool) for k in keys if _is_coordinate_key(k)}
    meta_diffs: dict[str, dict] = {}
    meta_differs = np.zeros(m, dtype=bool)

    for k0, k1 in _batches(ia, ib, A.pair_bytes(), B.pair_bytes(), max_bytes):
        ra, rb = ia[k0:k1], ib[k0:k1]
        a0, a1, b0, b1 = int(ra.min()), int(ra.max()) + 1, int(rb.min()), int(rb.max()) + 1
        block_a, block_b = A.read_block(a0, a1), B.read_block(b0, b1)
        la, lb = ra - a0, rb - b0
        sel = slice(k0, k1)
        _mark_partial(partial, block_a, block_b, la, lb, sel)
        for key in keys:
            n_diff, dmax = _compare_key(key, block_a, block_b, la, lb, atol)
            values[key][sel] = n_diff
            if key in max_abs:
                max_abs[key][sel] = dmax
        for s in ("x", "y"):
            _explain_by_transforms(s, block_a, block_b, la, lb, values, sel, moved, atol)
        for j, diff in _meta_differences(block_a, block_b, la, lb):
            meta_differs[k0 + j] = True
            meta_diffs[str(common[k0 + j])] = diff

    reasons = _reasons(m, values, moved, partial, meta_differs)
    attributes = dict_differences(A.metadata, B.metadata, ignore=IGNORED_ATTRIBUTES)
    return StoreComparison(
        Path(a),
        Path(b),
        A.setting,
        B.setting,
        len(A),
        len(B),
        only_a,
        only_b,
        common,
        values,
        max_abs,
        reasons,
        meta_diffs,
        attributes,
        layout,
        float(atol),
        partial,
        moved,
    )


def _matched_pairs(A, B):
    """The pairs of stores ``A`` and ``B``: their rows ``ia``, ``ib`` of the pairs both hold (in A's
    order), those pairs' ids, and the ids only in A and only in B (sorted)."""
    ids_a = A.table["pair_id"].to_numpy().astype(str)
    ids_b = B.table["pair_id"].to_numpy().astype(str)
    _, ia, ib = np.intersect1d(ids_a, ids_b, assume_unique=False, return_indices=True)
    order = np.argsort(ia, kind="stable")
    ia, ib = ia[order].astype(np.int64), ib[order].astype(np.int64)
    only_a = sorted(set(ids_a) - set(ids_b))
    only_b = sorted(set(ids_b) - set(ids_a))
    return ia, ib, ids_a[ia], only_a, only_b


def _compare_layouts(A, B) -> tuple[dict[str, dict], list[str]]:
    """The array keys whose presence or description (dtype, row shape, offsets group) differs between
    the stores, and the keys both hold (to compare row by row)."""
    layout: dict[str, dict] = {}
    keys = []
    for key in list(A.layout) + [k for k in B.layout if k not in A.layout]:
        if key not in A.layout or key not in B.layout:
            layout[key] = {
                "a": "present" if key in A.layout else "absent",
                "b": "present" if key in B.layout else "absent",
            }
            continue
        arr_a, arr_b = A.array(key), B.array(key)
        ga, gb = A.layout[key], B.layout[key]
        desc_a = {"dtype": str(arr_a.dtype), "row_shape": list(arr_a.shape[1:]), "group": ga}
        desc_b = {"dtype": str(arr_b.dtype), "row_shape": list(arr_b.shape[1:]), "group": gb}
        if desc_a != desc_b:
            layout[key] = {"a": desc_a, "b": desc_b}
        keys.append(key)  # rows of another shape or kind: every common pair marked (_compare_key)
    return layout, keys


def _mark_partial(partial: dict, block_a, block_b, la, lb, sel: slice) -> None:
    """Mark in ``partial[s][sel]`` the pairs whose shape ``s`` is a partial view in either store."""
    for s in ("x", "y"):
        for block, local in ((block_a, la), (block_b, lb)):
            group = block.layout.get(f"{s}_full_faces")
            if group is not None:
                partial[s][sel] |= block.counts(group)[local] > 0


def _meta_differences(block_a, block_b, la, lb):
    """``(j, differences)`` of each pair j of the batch whose metas differ (the content digest aside)."""
    for j, (i_a, i_b) in enumerate(zip(la, lb)):
        # the record's content digest follows from its arrays and meta: a difference there says nothing new
        ma, mb = (
            {k: v for k, v in meta.items() if k != "content_digest"}
            for meta in (block_a.metas[i_a], block_b.metas[i_b])
        )
        if ma != mb:
            diff = dict_differences(ma, mb)
            if diff:
                yield j, diff


def _reasons(m: int, values: dict, moved: dict, partial: dict, meta_differs: np.ndarray) -> np.ndarray:
    """(m, len(REASONS)) bool: why each common pair differs, from the per-key difference counts (a
    coordinate difference a rigid motion explains excluded)."""
    reasons = np.zeros((m, len(REASONS)), dtype=bool)
    for key, v in values.items():
        hit = (v != 0) & ~moved[key] if key in moved else v != 0
        side, _, rest = key.partition("_")
        if side in ("x", "y") and rest in MESH_KEYS:
            S = side.upper()
            reasons[:, REASONS.index(f"remeshing of {S} differs")] |= hit & ~partial[side]
            reasons[:, REASONS.index(f"partial view of {S} differs")] |= hit & partial[side]
        else:
            reasons[:, REASONS.index(key_reason(key))] |= hit
    reasons[:, REASONS.index("meta differs")] = meta_differs
    return reasons


def _is_coordinate_key(key: str) -> bool:
    side, _, rest = key.partition("_")
    return side in ("x", "y") and rest in COORDINATE_KEYS


def _canonical(block, i: int, s: str, key: str) -> np.ndarray:
    """Pair ``i``'s rows of a coordinate key taken back to the shape's common frame (before alignment,
    area normalisation and random rotation): ``((v @ R.T) * norm - t) @ A.T`` (record docstring)."""
    group = block.layout[key]
    o = block.offsets[group]
    v = block.arrays[key][o[i] : o[i + 1]]
    R = block.arrays[f"{s}_random_rotation"][i]
    A = block.arrays[f"{s}_align_rotation"][i]
    t = block.arrays[f"{s}_align_translation"][i]
    norm = float(block.arrays[f"{s}_full_sqrt_area"][i]) if block.metas[i].get("area_normalised") else 1.0
    return ((v @ R.T) * norm - t) @ A.T


def _explain_by_transforms(
    s: str, block_a, block_b, la: np.ndarray, lb: np.ndarray, values: dict, sel: slice, moved: dict, atol: float
) -> None:
    """Mark in ``moved`` the pairs of this batch whose side-``s`` coordinates differ only through the
    pair's transforms (random rotation, alignment, area normalisation): equal, to
    :data:`CANONICAL_RTOL` of their extent, once taken back to the common frame."""
    needed = [f"{s}_{k}" for k in TRANSFORM_KEYS]
    if not all(k in values and block_a.layout.get(k, 0) is None and block_b.layout.get(k, 0) is None for k in needed):
        return
    transformed = np.zeros(len(la), dtype=bool)
    for key in needed:
        transformed |= values[key][sel] != 0
    if not transformed.any():
        return
    for key in (f"{s}_{k}" for k in COORDINATE_KEYS):
        if key not in moved or block_a.layout.get(key) is None or block_b.layout.get(key) is None:
            continue
        for j in np.flatnonzero(transformed & (values[key][sel] > 0)):  # same rows, values differ
            ca = _canonical(block_a, int(la[j]), s, key)
            cb = _canonical(block_b, int(lb[j]), s, key)
            scale = max(float(np.abs(ca).max(initial=0.0)), 1e-300)
            if np.all(np.abs(ca - cb) <= max(atol, CANONICAL_RTOL * scale)):
                moved[key][sel.start + j] = True


def _compare_key(
    key: str, block_a, block_b, la: np.ndarray, lb: np.ndarray, atol: float
) -> tuple[np.ndarray, np.ndarray]:
    """(differing values per pair (-1: shape differs), largest |difference| per pair (NaN: n/a))."""
    n = len(la)
    data_a, data_b = block_a.arrays[key], block_b.arrays[key]
    ga, gb = block_a.layout[key], block_b.layout[key]
    n_diff = np.full(n, -1, dtype=np.int64)
    dmax = np.full(n, np.nan)
    if (ga is None) != (gb is None) or data_a.shape[1:] != data_b.shape[1:]:
        return n_diff, dmax
    is_float = data_a.dtype.kind == "f" or data_b.dtype.kind == "f"
    if ga is None:  # stacked: one row per pair
        counts, rowmax = _compare_rows(data_a[la], data_b[lb], atol)
        if counts is None:
            return np.zeros(n, dtype=np.int64), (np.zeros(n) if is_float else dmax)
        return counts.astype(np.int64), (rowmax if rowmax is not None else dmax)
    oa, ob = block_a.offsets[ga], block_b.offsets[gb]
    ca, cb = np.diff(oa)[la], np.diff(ob)[lb]
    same = ca == cb
    cnt = ca[same]
    sa, sb = oa[:-1][la][same], ob[:-1][lb][same]
    total = int(cnt.sum())
    if len(cnt) and (np.diff(sa) == cnt[:-1]).all() and (np.diff(sb) == cnt[:-1]).all():
        xa, xb = data_a[sa[0] : sa[0] + total], data_b[sb[0] : sb[0] + total]  # one run in each block: views
    else:
        xa, xb = data_a[_row_index(sa, cnt)], data_b[_row_index(sb, cnt)]
    counts, rowmax = _compare_rows(xa, xb, atol)
    if counts is None:
        n_diff[same] = 0
        if is_float:
            dmax[same] = 0.0
        return n_diff, dmax
    pair = np.repeat(np.arange(len(cnt)), cnt)
    per_pair = np.bincount(pair, weights=counts, minlength=len(cnt)).astype(np.int64)
    n_diff[same] = per_pair
    if rowmax is not None:
        best = np.zeros(len(cnt))
        nonempty = cnt > 0
        if nonempty.any():
            starts = np.concatenate([[0], np.cumsum(cnt)[:-1]])[nonempty]
            best[nonempty] = np.maximum.reduceat(rowmax, starts)
        dmax[same] = best
    return n_diff, dmax
