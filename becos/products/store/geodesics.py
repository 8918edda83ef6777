"""Geodesic distances of a store's shapes on demand: the lazy route beside the geodesics export.

:class:`GeodesicView` gives, without writing any (V, V) matrix, :meth:`~GeodesicView.to_truth` (per
vertex of x, the distance on y between a predicted vertex and its truth) and :meth:`~GeodesicView.rows`
(rows of a shape's matrix). Values are those of the export (``docs/released-layout.md`` section 3):
on the shape's FULL remeshed mesh, heat method, float32, divided by the full shape's sqrt-area. One
factorisation per distinct full mesh, each in a worker process of its own. Costs and caching:
docs/design/store.md.
"""

from __future__ import annotations

import multiprocessing
from collections import OrderedDict
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from becos.products.store.read import TrainingView

_SOLVER = None  # the worker process's HeatDistanceSolver


def _start_solver(vertices: np.ndarray, faces: np.ndarray) -> None:
    global _SOLVER
    from becos.core.geodesics import HeatDistanceSolver

    _SOLVER = HeatDistanceSolver(vertices, faces)


def _solve_rows(sources: np.ndarray) -> np.ndarray:
    """(len(sources), V) float32 rows of the worker's mesh, in the solver's batches."""
    out = np.empty((len(sources), _SOLVER.n_vertices), dtype=np.float32)
    size = _SOLVER.block_size()
    for start in range(0, len(sources), size):
        out[start : start + size] = _SOLVER.distances(sources[start : start + size])
    return out


class _MeshRows:
    """Distance rows of one full mesh (mesh units, float32), computed by its own worker process and
    kept in a ring of at most ``cache_bytes`` (and at most V rows: the whole matrix), oldest out first."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, cache_bytes: int):
        n = self.n_vertices = len(vertices)
        n_slots = int(min(n, max(1, int(cache_bytes) // (4 * max(n, 1)))))
        self.buffer = np.empty((n_slots, n), dtype=np.float32)  # pages are taken as rows are written
        self.slot_of = np.full(n, -1, dtype=np.int64)  # (V,) row of `buffer` holding a source's row, or -1
        self.source_of = np.full(n_slots, -1, dtype=np.int64)  # (n_slots,) the source each row holds
        self.next_slot = 0
        self.n_computed = 0
        self._pool = ProcessPoolExecutor(
            max_workers=1,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_start_solver,
            initargs=(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)),
        )

    def get(self, sources: np.ndarray) -> np.ndarray:
        """(len(sources), V) float32 distances from each full-mesh vertex in ``sources``."""
        unique, inverse = np.unique(np.asarray(sources, dtype=np.int64), return_inverse=True)
        known = self.slot_of[unique] >= 0
        missing = unique[~known]
        out = np.empty((len(unique), self.n_vertices), dtype=np.float32)
        out[known] = self.buffer[self.slot_of[unique[known]]]
        if len(missing):
            out[~known] = self._pool.submit(_solve_rows, missing).result()
            self.n_computed += len(missing)
            keep = min(len(missing), len(self.buffer))  # the last ones, when more than the ring holds
            slots = (self.next_slot + np.arange(keep)) % len(self.buffer)
            evicted = self.source_of[slots]
            self.slot_of[evicted[evicted >= 0]] = -1
            self.buffer[slots] = out[~known][len(missing) - keep :]
            self.source_of[slots] = missing[len(missing) - keep :]
            self.slot_of[missing[len(missing) - keep :]] = slots
            self.next_slot = int((self.next_slot + keep) % len(self.buffer))
        return out[inverse.reshape(-1)]

    def close(self) -> None:
        self._pool.shutdown(cancel_futures=True)


class GeodesicView:
    """Geodesic distances of the pairs of a store (or of one split), computed on first use.

    ``view.to_truth(i, predicted)`` and ``view.rows(i, side, vertices)`` for pair ``i`` in the order of
    :class:`becos.products.store.TrainingView` (same ``path`` and ``split``). Use as a context manager, or call
    :meth:`close`, to end the worker processes. Pickling it (a ``DataLoader`` worker) carries the path
    and settings, not the solvers: each process starts its own.

    Args:
        path: the store folder.
        split: only the pairs of this split (train, val, test ...), in store order; None: all.
        max_meshes: full meshes whose solvers and rows are kept (one worker process each).
        cache_bytes: rows kept per mesh (float32; 1 GiB holds ~26k rows of a 10k-vertex mesh).
    """

    def __init__(self, path: str | Path, split: str | None = None, max_meshes: int = 2, cache_bytes: int = 1 << 30):
        self.pairs = TrainingView(path, split, keys=())
        self.max_meshes = max(1, int(max_meshes))
        self.cache_bytes = int(cache_bytes)
        self._meshes: OrderedDict[tuple, _MeshRows] = OrderedDict()

    def __len__(self) -> int:
        return len(self.pairs)

    def __getstate__(self) -> dict:
        # a DataLoader worker gets the path and settings, and starts its own solvers
        return {**self.__dict__, "_meshes": OrderedDict()}

    def __enter__(self) -> GeodesicView:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """End every mesh's worker process (the view stays usable: they start again on demand)."""
        while self._meshes:
            self._meshes.popitem(last=False)[1].close()

    @property
    def n_computed(self) -> int:
        """Rows solved by the meshes currently kept."""
        return sum(m.n_computed for m in self._meshes.values())

    def _shape(self, i: int, side: str):
        """Pair ``i``'s record, the full mesh's rows, the shape's (V_s,) full vertices and its float32 scale."""
        from becos.build.record import full_shape
        from becos.core.geodesics import shape_key
        from becos.core.mesh import TriMesh

        if side not in ("x", "y"):
            raise ValueError(f"side must be 'x' or 'y', not {side!r}")
        row = int(self.pairs.rows[i])
        record = self.pairs.benchmark().read_rows(row, row + 1).record(0)
        vertices, faces = full_shape(record, side)
        mesh = TriMesh(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64))
        key = shape_key(mesh)
        rows = self._meshes.get(key)
        if rows is None:
            rows = self._meshes[key] = _MeshRows(mesh.vertices, mesh.faces, self.cache_bytes)
            while len(self._meshes) > self.max_meshes:
                self._meshes.popitem(last=False)[1].close()
        self._meshes.move_to_end(key)
        normalised = bool(record.meta.get("area_normalised", False))
        scale = np.float32(1.0 if normalised else float(record[f"{side}_full_sqrt_area"]))
        return record, rows, np.asarray(record[f"{side}_partial_to_full"], dtype=np.int64), scale

    def rows(self, i: int, side: str, vertices) -> np.ndarray:
        """(k, V_s) float32: distances from the shape's vertices ``vertices`` (k indices into its written
        vertices) to all its written vertices, divided by the sqrt-area. Rows of the heat method, not
        symmetrised: the export's matrix is (D + Dᵀ)/2, so they differ from its rows by the method's
        asymmetry (measured in ``docs/released-layout.md``); :meth:`to_truth` is symmetrised."""
        _, mesh_rows, p2f, scale = self._shape(i, side)
        vertices = np.asarray(vertices, dtype=np.int64).reshape(-1)
        out = mesh_rows.get(p2f[vertices])[:, p2f]
        out /= scale
        return out

    def to_truth(self, i: int, predicted) -> np.ndarray:
        """(V_x,) float32: for each vertex of shape x, the geodesic distance on shape y between its
        predicted vertex ``predicted[v]`` (an index into y's written vertices, -1 for none) and its
        ground-truth vertex ``corr_01[v]``, divided by y's sqrt-area; NaN where either is -1. Equal to
        the export's matrix of y at ``[corr_01[v], predicted[v]]`` (symmetrised, zero when equal)."""
        record, mesh_rows, p2f, scale = self._shape(i, "y")
        truth = np.asarray(record["corr_01"], dtype=np.int64)
        predicted = np.asarray(predicted, dtype=np.int64).reshape(-1)
        if predicted.shape != truth.shape:
            raise ValueError(f"predicted: {predicted.shape[0]} vertices, shape x of pair {i} has {truth.shape[0]}")
        n_y = len(p2f)
        if len(predicted) and (predicted.max() >= n_y or predicted.min() < -1):
            raise ValueError(f"predicted vertices must lie in [-1, {n_y}) (shape y of pair {i})")
        out = np.full(len(truth), np.nan, dtype=np.float32)
        valid = (truth >= 0) & (predicted >= 0)
        a, b = p2f[truth[valid]], p2f[predicted[valid]]
        sources, inverse = np.unique(np.concatenate([a, b]), return_inverse=True)
        rows = mesh_rows.get(sources)
        ia, ib = inverse[: len(a)], inverse[len(a) :]
        d = rows[ia, b] + rows[ib, a]  # float32, as the export's symmetrisation
        d *= np.float32(0.5)
        d /= scale
        d[a == b] = 0.0
        out[valid] = d
        return out
