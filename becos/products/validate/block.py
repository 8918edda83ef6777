"""The row-wise checks of one block of pairs (:class:`becos.products.store.Block`): every check of the
:mod:`becos.products.validate` table from ``index_range`` to ``alignment``, vectorised over the block's rows.

Arrays of a block are concatenated over its pairs: a ragged group's rows (vertices, faces ...) of pair
``i`` are ``offsets[i]:offsets[i + 1]``, and ``pair_of[group]`` maps every row back to its pair.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

import numpy as np

from becos.build.record import LEGACY_VERTEX_MAP_ROUNDING, NEAREST_CORNER_VERTEX_MAP_ROUNDING, VERTEX_MAP_ROUNDING
from becos.core.mesh import edge_neighbours
from becos.core.surface_map import VertexRounding
from becos.products.validate.report import Problems

WEIGHT_TOL = 1e-6
"""Barycentric weights may be this far below 0 and their sum this far from 1."""
ROTATION_TOL = 1e-6
"""Largest entry of R R^T - I and |det R - 1| of a rotation."""
NEIGHBOUR_CACHE_BYTES = 64 << 20
"""Bytes of edge neighbours a validation keeps for meshes met again (:class:`EdgeNeighbourCache`)."""


class EdgeNeighbourCache:
    """:func:`becos.core.mesh.edge_neighbours` of the meshes of a store, computed once per distinct face
    array: the pairs of a store share their remeshes (a 1,000-pair TOSCA store holds 68 distinct face
    arrays in its 2,000 shapes). An entry is used only for a face array equal to the one it was computed
    from (compared in full), so the result is the function's own. Least recently used entries go beyond
    ``max_bytes`` (the faces and both results are kept, as int32). Safe to share between threads."""

    def __init__(self, max_bytes: int = NEIGHBOUR_CACHE_BYTES):
        self.max_bytes, self.bytes = max_bytes, 0
        self._entries: OrderedDict[bytes, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = OrderedDict()
        self._lock = threading.Lock()  # shared by the checking threads; computed outside the lock

    def part(self, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``edge_neighbours(faces)`` of one mesh: (F, 3) int64 faces in its own vertex numbers."""
        if not len(faces) or faces.min() < 0 or faces.max() >= 1 << 31:
            return edge_neighbours(faces)
        step = max(len(faces) // 32, 1)
        key = np.int64(len(faces)).tobytes() + faces[::step].tobytes()  # equal faces, equal key
        with self._lock:
            entries = list(self._entries.get(key, []))
        for stored, neighbour, far in entries:
            if np.array_equal(stored, faces):
                with self._lock:
                    if key in self._entries:
                        self._entries.move_to_end(key)
                return neighbour.astype(np.int64), far.astype(np.int64)
        neighbour, far = edge_neighbours(faces)
        entry = (faces.astype(np.int32), neighbour.astype(np.int32), far.astype(np.int32))
        with self._lock:
            entries = self._entries.get(key, [])
            if any(np.array_equal(stored, faces) for stored, _, _ in entries):  # another thread's, meanwhile
                return neighbour, far
            self._entries[key] = [*entries, entry]
            self._entries.move_to_end(key)
            self.bytes += sum(e.nbytes for e in entry)
            while self.bytes > self.max_bytes and len(self._entries) > 1:
                _, dropped = self._entries.popitem(last=False)
                self.bytes -= sum(e.nbytes for stored in dropped for e in stored)
        return neighbour, far

    def by_part(
        self, faces: np.ndarray, face_offsets: np.ndarray, vertex_offsets: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """:func:`becos.core.mesh.edge_neighbours_by_part` through the cache: ``faces`` (F, 3) int64 in
        each part's own vertex numbers (not the stack's), parts as there; neighbours and far corners
        in the stack's numbers."""
        neighbour, far = np.full(faces.shape, -1, dtype=np.int64), np.full(faces.shape, -1, dtype=np.int64)
        for first, last, vertex_start in zip(face_offsets[:-1], face_offsets[1:], vertex_offsets[:-1], strict=True):
            if last > first:
                part_neighbour, part_far = self.part(faces[first:last])
                neighbour[first:last] = np.where(part_neighbour >= 0, part_neighbour + first, -1)
                far[first:last] = np.where(part_far >= 0, part_far + vertex_start, -1)
        return neighbour, far


class BlockChecker:
    """The row-wise checks of one :class:`becos.products.store.Block` (``neighbours``: an
    :class:`EdgeNeighbourCache` shared by the blocks of a store, or None for one of this block's own)."""

    def __init__(
        self, block, setting: str, ids: np.ndarray, problems: Problems, neighbours: EdgeNeighbourCache | None = None
    ):
        self.b, self.setting, self.ids, self.p = block, setting, ids, problems
        self.neighbours = EdgeNeighbourCache() if neighbours is None else neighbours
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
        """Every check of one side ``s`` (``x`` or ``y``; ``o`` the other, ``corr`` its correspondence
        key ``corr_01`` or ``corr_10``), in the order of the table in docs/design/validate.md."""
        partial = self.cnt[f"{s}_full_face"] > 0  # (n,) bool: the shape is a partial view
        self.side_index_ranges(s, o, corr, partial)
        self.side_unmatched(s, corr)
        self.side_corr_face(s, o, corr)
        self.side_overlap(s)
        self.side_index_maps(s, partial)
        self.side_full_shape(s, partial)
        if partial.any():
            self.partial_side(s, partial)

    def side_index_ranges(self, s: str, o: str, corr: str, partial: np.ndarray) -> None:
        """``index_range``: indices of side ``s`` inside their targets (-1 only where allowed)."""
        cnt = self.cnt
        gv, gf, go_v, go_f = f"{s}_vertex", f"{s}_face", f"{o}_vertex", f"{o}_face"
        gfv, gftp, gff = f"{s}_full_vertex", f"{s}_full_to_partial", f"{s}_full_face"
        V, F, Vo, Fo = cnt[gv], cnt[gf], cnt[go_v], cnt[go_f]
        v_full = np.where(partial, cnt[gfv], cnt[gftp])
        f_full = np.where(partial, cnt[gff], F)
        self.in_range(f"{s}_faces", gf, 0, V, f"V_{s}")
        self.in_range(corr, gv, -1, Vo, f"V_{o}")
        self.in_range(f"{corr}_face", gv, -1, Fo, f"F_{o}")
        self.in_range(f"{s}_partial_to_full", gv, 0, v_full, f"V_full_{s}")
        self.in_range(f"{s}_full_to_partial", gftp, -1, V, f"V_{s}")
        self.in_range(f"{s}_full_face_ids", gf, 0, f_full, f"F_full_{s}")
        self.in_range(f"{s}_full_faces", gff, 0, cnt[gfv], f"V_full_{s}")

    def side_unmatched(self, s: str, corr: str) -> None:
        """``unmatched`` and ``weights``: -1 exactly where the overlap mask is False, weight rows
        all 0 (or NaN) there and finite, >= 0, summing to 1 elsewhere."""
        a, gv = self.a, f"{s}_vertex"
        mask = a[f"{s}_overlap_mask"]  # (V,) bool, rows of group s_vertex
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

    def side_corr_face(self, s: str, o: str, corr: str) -> None:
        """``corr_face``: ``corr`` is the vertex its point on ``corr_face`` rounds to, by the rule of
        the record's meta ``vertex_rounding`` (rows whose indices are out of range: ``index_range``)."""
        a, gv, go_v, go_f = self.a, f"{s}_vertex", f"{o}_vertex", f"{o}_face"
        Vo, Fo = self.cnt[go_v], self.cnt[go_f]
        c, face, w = a[corr], a[f"{corr}_face"], a[f"{corr}_weights"]
        matched, fmatched = c >= 0, face >= 0
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
            _, far = self.neighbours.by_part(local_faces, self.b.offsets[go_f], self.b.offsets[go_v])
            # each face's data per point on it: few faces hold two points (a full shape's hold under half)
            candidates, along = VertexRounding.candidates_once(a[f"{o}_vertices"], block_faces, far, gface, wr)
            target = c[rows] + vertex_start[gface]
            # the record rounds in the remesh frame: a near tie may fall either way in this frame
            rounding = [m.get("vertex_rounding", LEGACY_VERTEX_MAP_ROUNDING) for m in self.b.metas]
            current = self.rep(np.array([r == VERTEX_MAP_ROUNDING for r in rounding], dtype=bool), gv)[rows]
            nearest_corner = self.rep(
                np.array([r == NEAREST_CORNER_VERTEX_MAP_ROUNDING for r in rounding], dtype=bool), gv
            )[rows]
            legacy = ~current & ~nearest_corner
            wrong = self.rounded_wrong(candidates, along, target, np.flatnonzero(current), 6)
            self.report(
                "corr_face",
                f"{corr} is not the vertex nearest its point along the surface (corners of {corr}_face and far corners of its neighbours)",
                np.unique(self.pair_of[gv][rows[wrong]]),
            )
            # dist: to the corners, the straight line, as the nearest-corner rule measures
            wrong_corner = self.rounded_wrong(candidates, along, target, np.flatnonzero(nearest_corner), 3)
            self.report(
                "corr_face",
                f"{corr} is not the corner of {corr}_face nearest its point (a record of an older becos, vertex_rounding nearest_corner)",
                np.unique(self.pair_of[gv][rows[wrong_corner]]),
            )
            old = np.flatnonzero(legacy)
            corners = candidates[old, :3] - vertex_start[gface[old], None]  # vertices of the other shape, per pair
            largest = corners[np.arange(len(old)), np.nan_to_num(w[rows[old]], nan=-1.0).argmax(axis=1)]
            self.report(
                "corr_face",
                f"{corr} is not the largest-weight corner of {corr}_face (a record of an older becos, no meta vertex_rounding)",
                np.unique(self.pair_of[gv][rows[old[largest != c[rows[old]]]]]),
            )

    @staticmethod
    def rounded_wrong(
        candidates: np.ndarray, along: np.ndarray, target: np.ndarray, rows: np.ndarray, first: int
    ) -> np.ndarray:
        """Rows ``rows`` of (R, 6) ``candidates`` / ``along`` (:meth:`VertexRounding.candidates`) whose
        ``target`` (R,) is not nearest (beyond a relative 1e-9 of the corners' distances) among their
        first ``first`` candidates. Returns indices into the R rows."""
        if not len(rows):
            return rows
        cand, dist = candidates[rows, :first], along[rows, :first]
        nearest = dist.argmin(axis=1)
        # where the nearest candidate is the target, its distance is the minimum: never wrong (the
        # tolerance is > 0, no distance is NaN); the others are measured as in full
        rows = rows[cand[np.arange(len(rows)), nearest] != target[rows]]
        cand, dist, corner = candidates[rows, :first], along[rows, :first], along[rows, :3]
        own = np.where(cand == target[rows, None], dist, np.inf).min(axis=1)
        tol = 1e-9 * (corner.max(axis=1) + 1e-12)
        return rows[own > dist.min(axis=1) + tol]

    def side_overlap(self, s: str) -> None:
        """``overlap``: the stored overlap is the mask's mean; accepted partial_partial pairs inside
        their meta's [min_overlap, max_overlap]."""
        a, gv = self.a, f"{s}_vertex"
        V, mask = self.cnt[gv], a[f"{s}_overlap_mask"]
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

    def side_index_maps(self, s: str, partial: np.ndarray) -> None:
        """``index_maps``: partial_to_full strictly increasing, full_to_partial its inverse."""
        a, cnt = self.a, self.cnt
        gv, gfv, gftp = f"{s}_vertex", f"{s}_full_vertex", f"{s}_full_to_partial"
        V = cnt[gv]
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

    def side_full_shape(self, s: str, partial: np.ndarray) -> None:
        """``full_shape``, ``setting`` and ``camera``: a full shape keeps every face and vertex, the
        setting's full shapes are full, cameras NaN for them and finite for scanned shapes."""
        a, cnt = self.a, self.cnt
        gv, gf, gfv, gftp = f"{s}_vertex", f"{s}_face", f"{s}_full_vertex", f"{s}_full_to_partial"
        V, ptf = cnt[gv], a[f"{s}_partial_to_full"]
        local = np.arange(len(ptf)) - self.rep(self.start[gv], gv)
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

    def partial_side(self, s: str, partial: np.ndarray) -> None:
        """``face_map``, ``vertex_map`` and ``connectivity`` of side ``s`` for the pairs whose shape is
        partial (``partial``: (n,) bool per pair)."""
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
        self.partial_connectivity(s, partial)

    def partial_connectivity(self, s: str, partial: np.ndarray) -> None:
        """``connectivity``: a partial shape (``partial``: (n,) bool per pair) is one edge-connected
        component and every vertex lies on a face."""
        a, cnt, gv, gf = self.a, self.cnt, f"{s}_vertex", f"{s}_face"
        faces, ptf, V = a[f"{s}_faces"], a[f"{s}_partial_to_full"], cnt[gv]
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        rows_f = self.rep(partial, gf)
        frows = np.flatnonzero(rows_f & (faces >= 0).all(axis=1) & (faces < self.rep(V, gf)[:, None]).all(axis=1))
        if not len(frows):
            return
        gfaces = faces[frows] + self.rep(self.start[gv], gf)[frows, None]  # block-wide vertex ids
        n_v = int(len(ptf))
        ends = gfaces[:, [1, 2, 0]]  # edge k of a face runs from corner k to corner k + 1
        edge_key = (np.minimum(gfaces, ends) * n_v + np.maximum(gfaces, ends)).T.ravel()  # edges 0, then 1, then 2
        edge_face = np.tile(np.arange(len(frows)), 3)
        order = np.argsort(edge_key)  # any order of a shared edge's faces links them all
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
