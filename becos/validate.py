"""Validation of a benchmark store (:mod:`becos.store`): every invariant a consumer relies on.

:func:`validate_store` returns human-readable problems (empty = valid); each starts with the name
of the check that failed, then says what is wrong, in how many pairs, with example pair ids::

    index_range: corr_01 outside [-1, V_y) in 1 pair(s), e.g. pp00000000000001 (1 value(s))

Problems about the store as a whole (``store``, ``schema``, ``metadata``) name the store, array or
attribute instead of pairs. Checks (vectorised over blocks of pairs of about
:data:`VALIDATE_BLOCK_BYTES`, read with :meth:`becos.store.Benchmark.read_block`):

================  ==================================================================================
``store``         the store opens and reads: the folder exists and is a Zarr v3 becos store, every
                  array, offsets and pairs node its layout names is present with readable metadata,
                  every chunk decodes (a damaged store ends in this one problem, not a traceback)
``checksum``      every array's and offsets array's content has the sha256 recorded when the store was
                  written (``becos_store.sha256``): catches a chunk file deleted (Zarr reads it back
                  as zeros), truncated or edited afterwards; skipped for stores written before
                  becos recorded digests, and when a chunk does not decode (``store`` says which)
``schema``        keys, dtypes, trailing shapes and offset groups as in :mod:`becos.record` /
                  :mod:`becos.store`; offsets start at 0, never decrease and end at the array's rows
``metadata``      root attributes: schema version, setting, pair count, pairs per split, the
                  ``versions`` of the building libraries
``meta``          per pair: setting equals the store's, split is train/val/test, schema version
``table``         the pairs table agrees with the metas (every column :func:`becos.store.table_row`
                  derives from them) and the arrays (sizes, overlaps); index column 0..N-1; rows in
                  store order (split train, val, test, then others; by pair_id inside a split)
``pair_id``       pair ids unique
``index_range``   faces, corr_01/corr_10 (+ ``_face``), partial_to_full, full_to_partial,
                  full_face_ids, full_faces index inside their targets (-1 only where allowed)
``unmatched``     corr_01 >= 0 and corr_01_face >= 0 exactly where x_overlap_mask (same for Y);
                  weight rows of unmatched vertices are all 0 (or all NaN)
``weights``       weights of matched vertices finite, >= 0, summing to 1
``corr_face``     corr_01 is the vertex nearest its point along the surface among corr_01_face's corners
                  and its edge neighbours' far corners (same for corr_10); records of an older becos by
                  their meta ``vertex_rounding``: ``nearest_corner``, the corner nearest in 3D; none, the
                  largest-weight corner
``overlap``       s_overlap equals the mask's mean; partial_partial pairs whose meta says
                  ``accepted`` have both overlaps in [min_overlap, max_overlap] of meta ``options``
``index_maps``    partial_to_full strictly increasing, full_to_partial its inverse (-1 elsewhere)
``full_shape``    a full shape keeps every face and vertex (identity maps)
``setting``       full_full: both shapes full; partial_full: X full
``face_map``      partial shapes: partial_to_full[faces] == full_faces[full_face_ids]
``vertex_map``    partial shapes: vertices == full_vertices[partial_to_full] (to 1e-9 relative)
``connectivity``  partial shapes: one edge-connected component, every vertex on a face
``rotation``      frame, alignment and random rotations orthonormal with det +1
``alignment``     X's alignment is the identity (rotation I, translation 0)
``camera``        NaN for the shapes the setting keeps full (both in full_full, X in partial_full),
                  finite for scanned ones (a scan that happens to see every face is stored as a
                  full shape but keeps its camera)
``scalars``       full_area > 0, full_sqrt_area**2 == full_area, dataset_scale > 0, remesh_variant >= -1
``finite``        vertex coordinates, centres and translations finite
``split_classes`` no (dataset, class) in two splits — for datasets whose split rule holds classes
                  out (``by_class``, ``template_table`` or unknown; not ``slices``/``by_name``,
                  whose splits share classes by design); the X side of partial_full pairs (the
                  class template) is exempt
``centaur``       centaur shapes only in train
================  ==================================================================================

Command line: ``becos validate STORE [--json OUT] [--against OTHER [--atol TOL]]`` prints a JSON
summary; with problems it lists them on stderr and exits with status 1. With ``--against`` it then
compares STORE with OTHER (:func:`becos.compare.compare_stores`: pairs only in one store, per pair
which arrays differ and why, metadata and library versions that differ), prints the comparison's
summary on stdout and exits with status 1 when the stores differ too; ``--json`` then also holds the
full comparison under ``comparison``. Exit status 2: OTHER cannot be opened.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from becos.errors import BecosError
from becos.record import (
    LEGACY_VERTEX_MAP_ROUNDING,
    NEAREST_CORNER_VERTEX_MAP_ROUNDING,
    RECORD_SCHEMA,
    SCHEMA_VERSION,
    VERTEX_MAP_ROUNDING,
)
from becos.settings import SETTINGS, SPLITS
from becos.store import DAMAGED_STORE_FIX as STORE_FIX
from becos.surface_map import VertexRounding

WEIGHT_TOL = 1e-6
ROTATION_TOL = 1e-6
MAX_EXAMPLES = 3

VALIDATE_BLOCK_BYTES = 16 << 20
"""Uncompressed bytes checked at once (the checks make several temporaries per block, so the
block size sets the validator's memory, independent of the store's size)."""


def expected_schema() -> dict[str, tuple[str, tuple[int, ...]]]:
    """Record key -> (dtype name, trailing shape) as stored: ragged keys without their leading length,
    stacked keys with their full per-pair shape (from :data:`becos.record.RECORD_SCHEMA`)."""
    return {key: (f.disk_dtype, f.shape) for key, f in RECORD_SCHEMA.items()}


@dataclass
class _Problems:
    """Accumulates problems by (check, what) across blocks: pair count and example ids."""

    items: dict = field(default_factory=dict)

    def add(self, check: str, what: str, pair_ids, detail: str = "", values: int = 0) -> None:
        """Record ``pair_ids`` failing ``check``; ``values`` counts bad values (summed over calls)."""
        pair_ids = [str(p) for p in pair_ids]
        if not pair_ids:
            return
        entry = self.items.setdefault((check, what), {"n": 0, "examples": [], "detail": detail, "values": 0})
        entry["n"] += len(pair_ids)
        entry["values"] += int(values)
        entry["examples"].extend(pair_ids[: MAX_EXAMPLES - len(entry["examples"])])

    def messages(self) -> list[str]:
        out = []
        for (check, what), e in self.items.items():
            notes = ([f"{e['values']} value(s)"] if e["values"] else []) + ([e["detail"]] if e["detail"] else [])
            notes_text = f" ({'; '.join(notes)})" if notes else ""
            out.append(f"{check}: {what} in {e['n']} pair(s), e.g. {', '.join(e['examples'])}{notes_text}")
        return out


@dataclass
class ValidationReport:
    """Result of :func:`validate`: ``problems`` (empty = valid) and a summary."""

    path: Path
    problems: list[str]
    n_pairs: int = 0
    setting: str = ""
    splits: dict = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def valid(self) -> bool:
        return not self.problems

    def summary(self) -> dict:
        return {
            "store": str(self.path),
            "valid": self.valid,
            "setting": self.setting,
            "n_pairs": self.n_pairs,
            "splits": self.splits,
            "n_problems": len(self.problems),
            "seconds": round(self.seconds, 2),
        }


# --------------------------------------------------------------------------------------------------
# per-block checks


class _BlockChecker:
    """The row-wise checks of one :class:`becos.store.Block`."""

    def __init__(self, block, setting: str, ids: np.ndarray, problems: _Problems):
        self.b, self.setting, self.ids, self.p = block, setting, ids, problems
        self.a = block.arrays
        self.n = len(block)
        self.cnt = {g: block.counts(g) for g in block.offsets}
        self.start = {g: o[:-1] for g, o in block.offsets.items()}
        self.pair_of = {g: np.repeat(np.arange(self.n), c) for g, c in self.cnt.items()}

    # helpers ------------------------------------------------------------------------------------
    def rep(self, values: np.ndarray, group: str) -> np.ndarray:
        """Per-pair values repeated for every row of a group."""
        return np.repeat(values, self.cnt[group])

    def pairs_with(self, bad_rows: np.ndarray, group: str) -> np.ndarray:
        """Pair indices (in block) with any bad row of a group."""
        bad_rows = np.asarray(bad_rows, dtype=bool)
        if bad_rows.ndim > 1:
            bad_rows = bad_rows.any(axis=tuple(range(1, bad_rows.ndim)))
        return np.unique(self.pair_of[group][bad_rows])

    def report(self, check: str, what: str, pairs: np.ndarray, values: int = 0) -> None:
        """Pairs given as block indices or a (n,) bool mask."""
        pairs = np.asarray(pairs)
        if pairs.dtype == bool:
            pairs = np.flatnonzero(pairs)
        if len(pairs):
            self.p.add(check, what, self.ids[pairs], values=values)

    def in_range(self, key: str, group: str, lo: int, hi_per_pair: np.ndarray, hi_name: str) -> None:
        values = self.a[key]
        hi = self.rep(hi_per_pair, group)
        if values.ndim > 1:
            hi = hi[:, None]
        bad = (values < lo) | (values >= hi)
        if bad.any():
            pairs = self.pairs_with(bad, group)
            self.report("index_range", f"{key} outside [{lo}, {hi_name})", pairs, int(bad.sum()))

    # checks -------------------------------------------------------------------------------------
    def run(self) -> None:
        for s, o, corr in (("x", "y", "corr_01"), ("y", "x", "corr_10")):
            self.side(s, o, corr)
        self.stacked()

    def side(self, s: str, o: str, corr: str) -> None:
        a, cnt = self.a, self.cnt
        gv, gf, go_v, go_f = f"{s}_vertex", f"{s}_face", f"{o}_vertex", f"{o}_face"
        gfv, gftp, gff = f"{s}_full_vertex", f"{s}_full_to_partial", f"{s}_full_face"
        V, F, Vo, Fo = cnt[gv], cnt[gf], cnt[go_v], cnt[go_f]
        partial = cnt[gff] > 0
        v_full = np.where(partial, cnt[gfv], cnt[gftp])
        f_full = np.where(partial, cnt[gff], F)

        # index ranges
        self.in_range(f"{s}_faces", gf, 0, V, f"V_{s}")
        self.in_range(corr, gv, -1, Vo, f"V_{o}")
        self.in_range(f"{corr}_face", gv, -1, Fo, f"F_{o}")
        self.in_range(f"{s}_partial_to_full", gv, 0, v_full, f"V_full_{s}")
        self.in_range(f"{s}_full_to_partial", gftp, -1, V, f"V_{s}")
        self.in_range(f"{s}_full_face_ids", gf, 0, f_full, f"F_full_{s}")
        self.in_range(f"{s}_full_faces", gff, 0, cnt[gfv], f"V_full_{s}")

        # -1 consistency, weights, vertex form vs barycentric form
        mask = a[f"{s}_overlap_mask"]
        c, face, w = a[corr], a[f"{corr}_face"], a[f"{corr}_weights"]
        matched, fmatched = c >= 0, face >= 0
        self.report("unmatched", f"{corr} >= 0 differs from {s}_overlap_mask", self.pairs_with(matched != mask, gv))
        self.report(
            "unmatched", f"{corr}_face >= 0 differs from {s}_overlap_mask", self.pairs_with(fmatched != mask, gv)
        )
        unmatched_w = w[~fmatched]
        bad = ~((unmatched_w == 0).all(axis=1) | np.isnan(unmatched_w).all(axis=1))
        self.report(
            "unmatched",
            f"{corr}_weights not all 0 (or NaN) where {corr}_face is -1",
            np.unique(self.pair_of[gv][~fmatched][bad]),
        )
        wm = w[fmatched]
        bad = (
            (~np.isfinite(wm).all(axis=1)) | (wm < -WEIGHT_TOL).any(axis=1) | (np.abs(wm.sum(axis=1) - 1) > WEIGHT_TOL)
        )
        self.report(
            "weights",
            f"{corr}_weights negative, non-finite or not summing to 1",
            np.unique(self.pair_of[gv][fmatched][bad]),
        )
        face_ok = fmatched & (face < self.rep(Fo, gv)) & matched & (c < self.rep(Vo, gv))  # in range (else index_range)
        if face_ok.any():
            rows = np.flatnonzero(face_ok)
            gface = face[rows] + self.rep(self.start[go_f], gv)[rows]
            # the other shape's faces in block-wide vertex numbers (bad indices clipped: index_range reports them)
            vertex_start = self.rep(self.start[go_v], go_f)
            local_faces = np.clip(a[f"{o}_faces"], 0, np.maximum(self.rep(Vo, go_f)[:, None] - 1, 0))
            block_faces = local_faces + vertex_start[:, None]
            wr = np.nan_to_num(w[rows])
            wr = wr / np.where(np.abs(wr.sum(axis=1)) > 0, wr.sum(axis=1), 1.0)[:, None]  # sums: the weights check
            candidates, along = VertexRounding(a[f"{o}_vertices"], block_faces).candidates(gface, wr)
            corners = candidates[:, :3] - vertex_start[gface, None]  # (R, 3) vertices of the other shape, per pair
            target = c[rows, None] + vertex_start[gface, None]
            dist = along[:, :3]  # to the corners: the straight line, as the nearest-corner rule measures
            # the record rounds in the remesh frame: a near tie may fall either way in this frame
            rounding = np.array([m.get("vertex_rounding", LEGACY_VERTEX_MAP_ROUNDING) for m in self.b.metas])
            rule = self.rep(rounding, gv)[rows] if len(rounding) else np.zeros(len(rows), dtype=rounding.dtype)
            current, nearest_corner = rule == VERTEX_MAP_ROUNDING, rule == NEAREST_CORNER_VERTEX_MAP_ROUNDING
            own = np.where(candidates == target, along, np.inf).min(axis=1)
            tol = 1e-9 * (dist.max(axis=1) + 1e-12)
            wrong = own > along.min(axis=1) + tol
            own_corner = np.where(candidates[:, :3] == target, dist, np.inf).min(axis=1)
            wrong_corner = own_corner > dist.min(axis=1) + tol
            largest = corners[np.arange(len(rows)), np.nan_to_num(w[rows], nan=-1.0).argmax(axis=1)]
            legacy = ~current & ~nearest_corner
            self.report(
                "corr_face",
                f"{corr} is not the vertex nearest its point along the surface (corners of {corr}_face and far corners of its neighbours)",
                np.unique(self.pair_of[gv][rows[wrong & current]]),
            )
            self.report(
                "corr_face",
                f"{corr} is not the corner of {corr}_face nearest its point (a record of an older becos, vertex_rounding nearest_corner)",
                np.unique(self.pair_of[gv][rows[wrong_corner & nearest_corner]]),
            )
            self.report(
                "corr_face",
                f"{corr} is not the largest-weight corner of {corr}_face (a record of an older becos, no meta vertex_rounding)",
                np.unique(self.pair_of[gv][rows[legacy & (largest != c[rows])]]),
            )

        # overlap values
        share = np.bincount(self.pair_of[gv], weights=mask, minlength=self.n) / np.maximum(V, 1)
        stored = a[f"{s}_overlap"]
        self.report("overlap", f"{s}_overlap differs from the mean of {s}_overlap_mask", np.abs(stored - share) > 1e-9)
        if self.setting == "partial_partial":
            lo = np.array([m.get("options", {}).get("min_overlap", -np.inf) for m in self.b.metas], dtype=float)
            hi = np.array([m.get("options", {}).get("max_overlap", np.inf) for m in self.b.metas], dtype=float)
            accepted = np.array([bool(m.get("accepted", False)) for m in self.b.metas])
            self.report(
                "overlap",
                f"{s}_overlap outside [min_overlap, max_overlap] of an accepted pair",
                accepted & ((stored < lo - 1e-12) | (stored > hi + 1e-12)),
            )

        # index maps
        ptf, ftp = a[f"{s}_partial_to_full"], a[f"{s}_full_to_partial"]
        pair = self.pair_of[gv]
        if len(ptf) > 1:
            same = pair[1:] == pair[:-1]
            self.report(
                "index_maps",
                f"{s}_partial_to_full not strictly increasing",
                np.unique(pair[1:][same & (np.diff(ptf) <= 0)]),
            )
        ok = (ptf >= 0) & (ptf < self.rep(cnt[gftp], gv))
        local = np.arange(len(ptf)) - self.rep(self.start[gv], gv)
        inverse = np.full(len(ptf), -2, dtype=np.int64)
        inverse[ok] = ftp[ptf[ok] + self.rep(self.start[gftp], gv)[ok]]
        self.report(
            "index_maps",
            f"{s}_full_to_partial[{s}_partial_to_full] is not the identity",
            np.unique(pair[inverse != local]),
        )
        kept = np.bincount(self.pair_of[gftp], weights=ftp >= 0, minlength=self.n)
        self.report("index_maps", f"{s}_full_to_partial keeps a different number of vertices than V_{s}", kept != V)
        self.report(
            "index_maps",
            f"len({s}_full_to_partial) != len({s}_full_vertices) for a partial shape",
            partial & (cnt[gftp] != cnt[gfv]),
        )

        # full shapes and the setting
        full = ~partial
        full_rows_v, full_rows_f = self.rep(full, gv), self.rep(full, gf)
        local_f = np.arange(len(a[f"{s}_full_face_ids"])) - self.rep(self.start[gf], gf)
        bad_pairs = np.union1d(
            self.pairs_with(full_rows_v & (ptf != local), gv),
            self.pairs_with(full_rows_f & (a[f"{s}_full_face_ids"] != local_f), gf),
        )
        bad_pairs = np.union1d(bad_pairs, np.flatnonzero(full & ((cnt[gftp] != V) | (cnt[gfv] != 0))))
        self.report("full_shape", f"full {s} shape does not keep every face and vertex (identity maps)", bad_pairs)
        must_be_full = self.setting == "full_full" or (self.setting == "partial_full" and s == "x")
        if must_be_full:
            self.report("setting", f"{s} is partial in a {self.setting} store", partial)
        camera = a[f"{s}_camera"].reshape(self.n, -1)
        if must_be_full:  # (a partial shape here is the ``setting`` problem)
            self.report(
                "camera",
                f"{s}_camera not NaN though a {self.setting} store keeps {s} full",
                full & ~np.isnan(camera).all(axis=1),
            )
        else:
            self.report("camera", f"{s}_camera not finite for a scanned {s} shape", ~np.isfinite(camera).all(axis=1))

        if partial.any():
            self.partial_side(s, partial)

    def partial_side(self, s: str, partial: np.ndarray) -> None:
        a, cnt = self.a, self.cnt
        gv, gf, gfv, gff = f"{s}_vertex", f"{s}_face", f"{s}_full_vertex", f"{s}_full_face"
        faces, ptf, ids = a[f"{s}_faces"], a[f"{s}_partial_to_full"], a[f"{s}_full_face_ids"]
        rows_f = self.rep(partial, gf)
        V = cnt[gv]
        # faces through the vertex map == the full faces they came from
        ok = (
            rows_f
            & (faces >= 0).all(axis=1)
            & (faces < self.rep(V, gf)[:, None]).all(axis=1)
            & (ids >= 0)
            & (ids < self.rep(cnt[gff], gf))
        )
        rows = np.flatnonzero(ok)
        gvert = faces[rows] + self.rep(self.start[gv], gf)[rows, None]
        mapped = ptf[gvert]
        full_faces = a[f"{s}_full_faces"][ids[rows] + self.rep(self.start[gff], gf)[rows]]
        self.report(
            "face_map",
            f"{s}_partial_to_full[{s}_faces] != {s}_full_faces[{s}_full_face_ids]",
            np.unique(self.pair_of[gf][rows[(mapped != full_faces).any(axis=1)]]),
        )
        rows_v = np.flatnonzero(self.rep(partial, gv) & (ptf >= 0) & (ptf < self.rep(cnt[gfv], gv)))
        verts = a[f"{s}_vertices"][rows_v]
        full_v = a[f"{s}_full_vertices"][ptf[rows_v] + self.rep(self.start[gfv], gv)[rows_v]]
        scale = 1.0 + np.abs(full_v).max(axis=1)
        bad = ~(np.abs(verts - full_v).max(axis=1) <= 1e-9 * scale)
        self.report(
            "vertex_map",
            f"{s}_vertices != {s}_full_vertices[{s}_partial_to_full]",
            np.unique(self.pair_of[gv][rows_v[bad]]),
        )

        # one edge-connected component, no vertex off the faces
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        frows = np.flatnonzero(rows_f & (faces >= 0).all(axis=1) & (faces < self.rep(V, gf)[:, None]).all(axis=1))
        if not len(frows):
            return
        gfaces = faces[frows] + self.rep(self.start[gv], gf)[frows, None]  # block-wide vertex ids
        n_v = int(len(ptf))
        edges = np.sort(np.concatenate([gfaces[:, [0, 1]], gfaces[:, [1, 2]], gfaces[:, [2, 0]]]), axis=1)
        edge_key = edges[:, 0] * n_v + edges[:, 1]
        edge_face = np.tile(np.arange(len(frows)), 3)
        order = np.argsort(edge_key, kind="stable")
        k, f = edge_key[order], edge_face[order]
        same = k[1:] == k[:-1]
        graph = coo_matrix((np.ones(int(same.sum())), (f[:-1][same], f[1:][same])), shape=(len(frows), len(frows)))
        _, labels = connected_components(graph, directed=False)
        face_pair = self.pair_of[gf][frows]
        _, first = np.unique(labels, return_index=True)  # faces of two pairs never connect
        components = np.bincount(face_pair[first], minlength=self.n)
        self.report(
            "connectivity", f"partial {s} shape is not one edge-connected component", partial & (components > 1)
        )
        used = np.zeros(n_v, dtype=bool)
        used[gfaces.ravel()] = True
        unused = self.rep(partial, gv) & ~used
        self.report("connectivity", f"partial {s} shape has vertices on no face", self.pairs_with(unused, gv))

    def stacked(self) -> None:
        a = self.a
        for s in ("x", "y"):
            for key in ("frame_rotation", "align_rotation", "random_rotation"):
                r = a[f"{s}_{key}"]
                gram = np.einsum("nij,nkj->nik", r, r) - np.eye(3)
                det = np.linalg.det(r)
                bad = ~((np.abs(gram).max(axis=(1, 2)) <= ROTATION_TOL) & (np.abs(det - 1) <= ROTATION_TOL))
                self.report("rotation", f"{s}_{key} not orthonormal with det +1", bad)
            area, sqrt_area, scale = a[f"{s}_full_area"], a[f"{s}_full_sqrt_area"], a[f"{s}_dataset_scale"]
            bad = ~(
                (area > 0)
                & np.isfinite(area)
                & (np.abs(sqrt_area**2 - area) <= 1e-9 * np.abs(area))
                & (scale > 0)
                & np.isfinite(scale)
            )
            self.report("scalars", f"{s}_full_area / {s}_full_sqrt_area / {s}_dataset_scale inconsistent", bad)
            self.report("scalars", f"{s}_remesh_variant below -1", a[f"{s}_remesh_variant"] < -1)
            for key, group in ((f"{s}_vertices", f"{s}_vertex"), (f"{s}_full_vertices", f"{s}_full_vertex")):
                self.report("finite", f"{key} not finite", self.pairs_with(~np.isfinite(a[key]), group))
            bad = ~(np.isfinite(a[f"{s}_centre"]).all(axis=1) & np.isfinite(a[f"{s}_align_translation"]).all(axis=1))
            self.report("finite", f"{s}_centre or {s}_align_translation not finite", bad)
        bad = (np.abs(a["x_align_rotation"] - np.eye(3)).max(axis=(1, 2)) > 0) | (
            np.abs(a["x_align_translation"]).max(axis=1) > 0
        )
        self.report("alignment", "x_align_rotation / x_align_translation not the identity", bad)


# --------------------------------------------------------------------------------------------------
# store-wide checks


def _check_schema(bench, problems: list[str]) -> bool:
    """Keys, dtypes, shapes and groups; False if the row-wise checks cannot run."""
    ok = True
    expected = expected_schema()
    missing = sorted(set(expected) - set(bench.layout))
    if missing:
        problems.append(f"schema: the store lacks the record keys {missing}")
        ok = False
    for key, (dtype, trailing) in expected.items():
        if key not in bench.layout:
            continue
        array = bench.array(key)
        group = bench.layout[key]
        want_group = RECORD_SCHEMA[key].group
        if group != want_group:
            problems.append(
                f"schema: {key} is stored in offset group {group}, expected {want_group} "
                "(its lengths disagree with the other arrays of that group)"
            )
            ok = False
        if str(array.dtype) != dtype:
            problems.append(f"schema: {key} has dtype {array.dtype}, expected {dtype}")
            ok = False
        if tuple(array.shape[1:]) != trailing:
            problems.append(f"schema: {key} has rows of shape {tuple(array.shape[1:])}, expected {trailing}")
            ok = False
        if group is not None and array.shape[0] != bench.offsets[group][-1]:
            problems.append(
                f"schema: {key} has {array.shape[0]} rows but offsets '{group}' end at {bench.offsets[group][-1]}"
            )
            ok = False
        if group is None and array.shape[0] != len(bench):
            problems.append(f"schema: {key} has {array.shape[0]} rows for {len(bench)} pairs")
            ok = False
    ids = bench.table["pair_id"].to_numpy().astype(str)
    for group, o in bench.offsets.items():
        if len(o) and o[0] != 0:
            problems.append(f"schema: offsets '{group}' start at {o[0]}, not 0")
            ok = False
        bad = np.flatnonzero(np.diff(o) < 0)
        if len(bad):
            problems.append(
                f"schema: offsets '{group}' decrease (negative row count) in {len(bad)} pair(s), "
                f"e.g. {', '.join(ids[bad[:MAX_EXAMPLES]])}"
            )
            ok = False
    return ok


def _split_rule(dataset: str, cache: dict) -> str | None:
    if dataset not in cache:
        from becos.datasets import DatasetSpec

        try:
            cache[dataset] = DatasetSpec.load(dataset).split.get("rule")
        except BecosError:
            cache[dataset] = None
    return cache[dataset]


def _check_splits(table, setting: str, problems: _Problems) -> None:
    """Class-disjoint splits (``split_classes``) and centaurs in train only (``centaur``)."""
    import pandas as pd

    sides = ["y"] if setting == "partial_full" else ["x", "y"]
    parts = [
        pd.DataFrame(
            {
                "dataset": table[f"{s}_dataset"],
                "class": table[f"{s}_class"],
                "category": table[f"{s}_category"],
                "split": table["split"],
                "pair_id": table["pair_id"],
            }
        )
        for s in sides
    ]
    rows = pd.concat(parts, ignore_index=True)
    rules: dict = {}
    for (dataset, shape_class), group in rows.groupby(["dataset", "class"], sort=True):
        splits = sorted(set(group["split"]), key=lambda v: SPLITS.index(v) if v in SPLITS else len(SPLITS))
        if len(splits) < 2 or _split_rule(dataset, rules) in ("slices", "by_name"):
            continue
        examples = [group.loc[group["split"] == sp, "pair_id"].iloc[0] for sp in splits]
        problems.add(
            "split_classes",
            f"class {dataset}/{shape_class} in splits {'+'.join(splits)}",
            sorted(set(group["pair_id"])),
            ", ".join(f"{sp}: {e}" for sp, e in zip(splits, examples)),
        )
    centaurs = rows[(rows["category"] == "centaur") & (rows["split"] != "train")]
    problems.add("centaur", "centaur shape outside train", sorted(set(centaurs["pair_id"])))


def _node_problem(path: Path, node: str) -> str | None:
    """Why the Zarr node ``node`` (e.g. ``arrays/x_faces``) of a store cannot be opened, else None."""
    meta = path / node / "zarr.json"
    if not meta.is_file():
        return "missing"
    try:
        info = json.loads(meta.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        return f"has unreadable metadata ({node}/zarr.json: {exc})"
    if not isinstance(info, dict) or info.get("node_type") != "array":
        return f"is not a Zarr array ({node}/zarr.json)"
    return None


def _diagnose(path: Path, exc: Exception) -> list[str]:
    """Readable ``store`` problems of a store that exists but does not open (missing or damaged nodes)."""
    try:
        attrs = json.loads((path / "zarr.json").read_text(encoding="utf-8")).get("attributes", {})
        layout = dict(attrs["becos_store"]["layout"])
    except Exception:  # root metadata unreadable: nothing more specific to say
        layout = {}
    nodes = [f"arrays/{k}" for k in layout]
    nodes += [f"offsets/{g}" for g in sorted({g for g in layout.values() if g is not None})]
    nodes += ["pairs/meta_json", "pairs/meta_offsets", "pairs/table_json"]
    found: dict[str, list[str]] = {}
    for node in nodes:
        problem = _node_problem(path, node)
        if problem is not None:
            found.setdefault(problem if problem == "missing" else "unreadable", []).append(
                node if problem == "missing" else f"{node} {problem}"
            )
    out = []
    if "missing" in found:
        names = found["missing"]
        out.append(
            f"store: {path}: {len(names)} of its arrays missing: {', '.join(names[:8])}"
            f"{' ...' if len(names) > 8 else ''}. Fix: {STORE_FIX}"
        )
    if "unreadable" in found:
        out.append(f"store: {path}: {'; '.join(found['unreadable'][:4])}. Fix: {STORE_FIX}")
    if not out:
        out.append(f"store: {path}: cannot be opened ({type(exc).__name__}: {exc}). Fix: {STORE_FIX}")
    return out


def open_for_validation(path: str | Path):
    """``(Benchmark, [])`` or ``(None, [store problem])``: never raises for a missing or damaged store."""
    from becos.errors import InputFileError
    from becos.store import DamagedStoreError, open_benchmark

    path = Path(path)
    fix = "give a store folder (*.zarr) written by `becos export-zarr`"
    if not path.exists():
        return None, [f"store: {path}: not found. Fix: check the path; {fix}"]
    if not path.is_dir():
        return None, [f"store: {path}: is a file, not a store folder. Fix: {fix}"]
    try:
        return open_benchmark(path), []
    except DamagedStoreError as exc:  # name every missing or unreadable node, not just the first
        return None, _diagnose(path, exc.__cause__)
    except InputFileError as exc:
        return None, [f"store: {exc}"]
    except Exception as exc:  # zarr raises KeyError, JSONDecodeError ... for damaged stores
        return None, _diagnose(path, exc)


def _unreadable(bench, start: int, stop: int, exc: Exception, ids: np.ndarray) -> str:
    """The ``store`` problem of rows ``start:stop`` that failed to read: which arrays fail, why, and for
    which pairs (each failing array re-read pair by pair)."""

    def rows_of(key: str, i: int, j: int) -> tuple[int, int]:
        group = bench.layout[key]
        return (i, j) if group is None else (int(bench.offsets[group][i]), int(bench.offsets[group][j]))

    failing, bad = [], np.zeros(stop - start, dtype=bool)
    for key in bench.layout:
        try:
            bench.array(key)[slice(*rows_of(key, start, stop))]
        except Exception as err:
            failing.append(f"arrays/{key} ({type(err).__name__}: {err})")
            for i in range(start, stop):
                try:
                    bench.array(key)[slice(*rows_of(key, i, i + 1))]
                except Exception:
                    bad[i - start] = True
    if not failing:
        failing.append(f"pairs/meta_json ({type(exc).__name__}: {exc})")
    if not bad.any():
        bad[:] = True
    pairs = ids[start:stop][bad]
    return (
        f"store: {bench.path}: chunks of {'; '.join(failing[:4])}{' ...' if len(failing) > 4 else ''} cannot "
        f"be read, in {len(pairs)} pair(s), e.g. {', '.join(pairs[:MAX_EXAMPLES])}. Fix: {STORE_FIX}"
    )


def validate(path: str | Path, progress: bool = False) -> ValidationReport:
    """Run every check on a store; see the module docstring. Never raises for a bad store: a store that
    is missing or does not open gives one ``store`` problem."""
    started = time.perf_counter()
    path = Path(path)
    bench, problems = open_for_validation(path)
    if bench is None:
        return ValidationReport(path, problems, seconds=time.perf_counter() - started)
    found = _Problems()
    table = bench.table
    n = len(bench)
    ids = table["pair_id"].to_numpy().astype(str)
    _check_metadata(bench, problems)
    if list(table["index"]) != list(range(n)):
        problems.append("table: the index column is not 0..N-1")
    _check_order(table, problems)

    rows_ok = _check_schema(bench, problems)
    if not rows_ok:  # the arrays cannot be trusted: check the metas and the table only
        from becos.store import Block

        try:
            metas = bench.read_metas()
        except Exception as exc:
            problems.append(_unreadable(bench, 0, n, exc, ids))
        else:
            _check_metas(Block(0, n, {}, {}, bench.layout, metas), bench.setting, table, found)
    reported = 0
    digests = _digests_to_check(bench) if rows_ok else None
    for start, stop in bench.block_ranges(max_bytes=VALIDATE_BLOCK_BYTES) if rows_ok else []:
        try:
            block = bench.read_block(start, stop)
        except Exception as exc:  # a damaged chunk: name it, check the other blocks
            problems.append(_unreadable(bench, start, stop, exc, ids))
            digests = None
            continue
        if digests is not None:
            for key in bench.layout:
                digests.update(f"arrays/{key}", block.arrays[key])
        _BlockChecker(block, bench.setting, ids[start:stop], found).run()
        _check_metas(block, bench.setting, table, found)
        if progress and (10 * stop // n > reported or stop == n):  # about every 10 %
            reported = 10 * stop // n
            print(
                f"validate: {stop}/{n} pairs checked ({time.perf_counter() - started:.1f} s)",
                file=sys.stderr,
                flush=True,
            )

    if digests is not None:
        _check_digests(bench, digests, problems)
    values, counts = np.unique(ids, return_counts=True)
    dup = values[counts > 1]
    if len(dup):
        found.add("pair_id", "duplicate pair id", dup, f"{int(counts[counts > 1].sum())} rows share {len(dup)} id(s)")
    _check_splits(table, bench.setting, found)
    problems.extend(found.messages())
    splits = {str(k): int(v) for k, v in table["split"].value_counts().items()}
    return ValidationReport(path, problems, n, bench.setting, splits, time.perf_counter() - started)


def _check_order(table, problems: list[str]) -> None:
    """``table``: rows in store order (:func:`becos.store.store_order_key`)."""
    from becos.store import store_order_key

    keys = [store_order_key(split, pid) for split, pid in zip(table["split"], table["pair_id"])]
    late = [i for i in range(1, len(keys)) if keys[i] < keys[i - 1]]
    if late:
        i = late[0]
        problems.append(
            f"table: {len(late)} row(s) out of store order (split train, val, test, then pair_id), "
            f"first at row {i}: {table['pair_id'][i]} ({table['split'][i]}) after "
            f"{table['pair_id'][i - 1]} ({table['split'][i - 1]})"
        )


def _digests_to_check(bench):
    """A :class:`becos.store.ContentDigests` for the store's nodes, or None if it recorded none."""
    from becos.store import ContentDigests

    if not bench.content_digests:
        return None
    dtypes = {f"arrays/{key}": bench.array(key).dtype for key in bench.layout}
    dtypes.update({f"offsets/{group}": np.int64 for group in bench.offsets})
    return ContentDigests(dtypes)


def _absent_chunk_files(bench, node: str) -> list[str]:
    """Chunk (shard) file names of ``node`` that its shape calls for but are not on disk."""
    if not node.startswith("arrays/"):
        return []  # offsets are read whole when the store opens
    array = bench.array(node.removeprefix("arrays/"))
    files_per_axis = [-(-size // step) for size, step in zip(array.shape, array.shards or array.chunks)]
    names = [array.metadata.encode_chunk_key(idx) for idx in np.ndindex(*files_per_axis)]
    return [name for name in names if not (bench.path / node / name).exists()]


def _check_digests(bench, digests, problems: list[str]) -> None:
    """``checksum``: content read back (every block, then the offsets) against the recorded sha256."""
    for group, offsets in bench.offsets.items():
        digests.update(f"offsets/{group}", offsets)
    actual = digests.hexdigests()
    for node, recorded in sorted(bench.content_digests.items()):
        if node in actual and actual[node] != recorded:
            absent = _absent_chunk_files(bench, node)
            why = (
                f"; chunk files absent (Zarr reads them as zeros): {', '.join(absent[:MAX_EXAMPLES])}"
                f"{' ...' if len(absent) > MAX_EXAMPLES else ''}"
                if absent
                else "; a chunk file changed after the store was written"
            )
            problems.append(
                f"checksum: {node} content differs from the sha256 recorded when the store was "
                f"written{why}. Fix: rebuild the store (delete it and rerun the workflow, or "
                "`becos export-zarr`) or restore it from a copy"
            )


def _check_metadata(bench, problems: list[str]) -> None:
    """Root attributes (``metadata``)."""
    meta, n, table = bench.metadata, len(bench), bench.table
    if meta.get("schema_version") != SCHEMA_VERSION:
        problems.append(f"metadata: schema_version {meta.get('schema_version')}, expected {SCHEMA_VERSION}")
    if bench.setting not in SETTINGS:
        problems.append(f"metadata: setting {bench.setting!r} is not one of {SETTINGS}")
    if meta.get("n_pairs", n) != n:
        problems.append(f"metadata: n_pairs says {meta.get('n_pairs')} but the table has {n} rows")
    splits = {str(k): int(v) for k, v in table["split"].value_counts().items()}
    if "splits" in meta and meta["splits"] != splits:
        problems.append(f"metadata: splits says {meta['splits']} but the table has {splits}")
    versions = meta.get("versions")
    if not isinstance(versions, dict) or not {"python", "numpy", "zarr"} <= set(versions):
        problems.append(
            f"metadata: versions is {versions!r}, not a {{package: version}} mapping with at least "
            "python, numpy and zarr (the store does not say which libraries built it)"
        )


_ARRAY_COLUMNS = ("index", "x_n_vertices", "y_n_vertices", "x_overlap", "y_overlap")
"""Store table columns that follow from the arrays (checked against them), not from a pair's meta."""
"""Table columns :func:`becos.store.table_row` derives from a pair's meta alone."""


def _check_metas(block, setting: str, table, found: _Problems) -> None:
    from becos.store import TABLE_COLUMNS, table_row

    rows = table.iloc[block.start : block.stop]
    ids = rows["pair_id"].to_numpy().astype(str)
    metas = block.metas
    bad = np.array([m.get("setting", setting) != setting for m in metas])
    found.add("meta", f"meta setting differs from the store's ({setting})", ids[bad])
    bad = np.array([m.get("split") not in SPLITS for m in metas])
    found.add("meta", "meta split is not train/val/test", ids[bad])
    bad = np.array([m.get("schema_version", SCHEMA_VERSION) != SCHEMA_VERSION for m in metas])
    found.add("meta", f"meta schema_version is not {SCHEMA_VERSION}", ids[bad])
    expected, unreadable = [], np.zeros(len(metas), dtype=bool)
    for i, m in enumerate(metas):
        try:
            expected.append(table_row(block.start + i, {"pair_id": None, **m}, 0, 0, 0.0, 0.0))
        except (TypeError, ValueError, AttributeError):
            unreadable[i] = True
            expected.append([None] * len(TABLE_COLUMNS))
    found.add("meta", "meta seed/n_tries not integers or x/y not objects", ids[unreadable])
    for j, column in enumerate(TABLE_COLUMNS):
        if column in _ARRAY_COLUMNS:
            continue
        want = [row[j] for row in expected]
        have = rows[column].tolist()
        bad = np.array([w != h for w, h in zip(want, have)]) & ~unreadable
        found.add("table", f"table {column} differs from the pair meta", ids[bad])
    for s in ("x", "y"):
        group = f"{s}_vertex"
        if group in block.offsets:
            found.add(
                "table",
                f"table {s}_n_vertices differs from the arrays",
                ids[block.counts(group) != rows[f"{s}_n_vertices"].to_numpy()],
            )
        if f"{s}_overlap" in block.arrays and block.arrays[f"{s}_overlap"].shape == (len(block),):
            stored = block.arrays[f"{s}_overlap"]
            found.add(
                "table",
                f"table {s}_overlap differs from the arrays",
                ids[~(np.abs(stored - rows[f"{s}_overlap"].to_numpy()) <= 1e-12)],
            )


def validate_store(path: str | Path) -> list[str]:
    """Human-readable problems of a benchmark store; empty = valid (checks: module docstring)."""
    return validate(path).problems
