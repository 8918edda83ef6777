"""Geodesic distances on triangle meshes, for evaluating correspondences.

Two estimators, both in the units of the mesh's vertex coordinates: ``"heat"`` (the heat method,
potpourri3d, factored once per mesh) and ``"dijkstra"`` (shortest paths along edges: exact for the edge
graph, an upper bound of the surface geodesic). Whole distance matrices (the exports) come from
:func:`distance_rows` with :class:`HeatDistanceSolver` (many sources per solve). Surface points are
(face, barycentric weights) in face-column order (:mod:`becos.core.geometry`). Accuracy and costs:
docs/design/evaluate.md.
"""

from __future__ import annotations

import weakref
from collections import OrderedDict

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from becos.core.mesh import TriMesh

METHODS = ("heat", "dijkstra")

_CHUNK_ELEMENTS = 1 << 22
"""Largest number of float64 entries of one block of distance rows held at a time (32 MB)."""


def edge_graph(mesh: TriMesh) -> sp.csr_matrix:
    """(V, V) symmetric CSR matrix of Euclidean edge lengths of the mesh's unique undirected edges.

    Zero-length edges (duplicate vertex positions) are given a tiny positive length so that csgraph
    does not read them as "no edge".
    """
    from becos.core.mesh import undirected_edges

    edges = undirected_edges(mesh.faces)[0].astype(mesh.faces.dtype)  # np.unique(axis=0)'s rows, ~10x faster
    length = np.linalg.norm(mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]], axis=1)
    length = np.maximum(length, 1e-300)
    n = mesh.n_vertices
    rows = np.concatenate([edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 1], edges[:, 0]])
    return sp.csr_matrix((np.concatenate([length, length]), (rows, cols)), shape=(n, n))


def _chunks(items: np.ndarray, n_vertices: int):
    """Split ``items`` into consecutive blocks of at most _CHUNK_ELEMENTS // n_vertices rows."""
    size = max(1, _CHUNK_ELEMENTS // max(n_vertices, 1))
    for start in range(0, len(items), size):
        yield slice(start, min(start + size, len(items)))


def _point_queries(source_vertices, target_face, target_weights) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertex -> surface-point queries as (N,) int64, (N,) int64, (N, 3) float64; equal lengths checked."""
    source_vertices = np.asarray(source_vertices, dtype=np.int64).reshape(-1)
    target_face = np.asarray(target_face, dtype=np.int64).reshape(-1)
    target_weights = np.asarray(target_weights, dtype=np.float64).reshape(-1, 3)
    if not len(source_vertices) == len(target_face) == len(target_weights):
        raise ValueError(
            f"vertex -> point queries need equally long inputs; got {len(source_vertices)}, "
            f"{len(target_face)}, {len(target_weights)}"
        )
    return source_vertices, target_face, target_weights


class GeodesicDistances:
    """Geodesic distance fields on one mesh, from source vertices.

    Rows already computed are kept (least recently used first out) up to ``cache_bytes``, so asking
    for the same source twice in a process costs nothing; ``n_computed`` counts rows actually computed.

    Args:
        mesh: the surface; distances are in the units of ``mesh.vertices``.
        method: ``"heat"`` (default) or ``"dijkstra"`` (see docs/design/evaluate.md).
        cache_bytes: memory budget of the row cache (0 disables it).
        heat_t_coef: time-step coefficient of the heat method (potpourri3d's ``t_coef``; 1 = mean edge
            length squared).
    """

    def __init__(self, mesh: TriMesh, method: str = "heat", cache_bytes: int = 256 << 20, heat_t_coef: float = 1.0):
        if method not in METHODS:
            raise ValueError(f"unknown geodesic method {method!r}; choose one of {METHODS}")
        self.mesh = mesh
        self.method = method
        self.cache_bytes = int(cache_bytes)
        self.n_computed = 0
        self._rows: OrderedDict[int, np.ndarray] = OrderedDict()
        self._heat = None
        self._graph = None
        if method == "heat":
            import potpourri3d as pp3d

            self._heat = pp3d.MeshHeatMethodDistanceSolver(mesh.vertices, mesh.faces, t_coef=heat_t_coef)
        else:
            self._graph = edge_graph(mesh)

    @property
    def n_vertices(self) -> int:
        return self.mesh.n_vertices

    def _compute(self, sources: np.ndarray) -> np.ndarray:
        """(len(sources), V) fresh distance rows (no cache)."""
        self.n_computed += len(sources)
        if self.method == "heat":
            out = np.empty((len(sources), self.n_vertices))
            for k, s in enumerate(sources):
                row = np.asarray(self._heat.compute_distance(int(s)), dtype=np.float64)
                # the heat method's field is shifted to be 0 at the source; clip round-off below it
                out[k] = np.maximum(row, 0.0)
                out[k, s] = 0.0
            return out
        return dijkstra(self._graph, directed=False, indices=sources)

    def from_vertices(self, sources: np.ndarray) -> np.ndarray:
        """(len(sources), V) float64 distances from each source vertex to every vertex (mesh units).

        Only the rows asked for are computed (each unique source once); rows are cached.
        """
        sources = np.asarray(sources, dtype=np.int64).reshape(-1)
        if len(sources) and (sources.min() < 0 or sources.max() >= self.n_vertices):
            raise IndexError(
                f"source vertices must lie in [0, {self.n_vertices}); got [{sources.min()}, {sources.max()}]"
            )
        unique, inverse = np.unique(sources, return_inverse=True)
        out_unique = np.empty((len(unique), self.n_vertices))
        missing = []
        for k, s in enumerate(unique):
            row = self._rows.get(int(s))
            if row is None:
                missing.append(k)
            else:
                self._rows.move_to_end(int(s))
                out_unique[k] = row
        missing = np.asarray(missing, dtype=np.int64)
        for block in _chunks(missing, self.n_vertices):
            ks = missing[block]
            rows = self._compute(unique[ks])
            out_unique[ks] = rows
            for s, row in zip(unique[ks], rows):
                self._remember(int(s), row)
        return out_unique[inverse]

    def _remember(self, source: int, row: np.ndarray) -> None:
        row_bytes = row.nbytes
        if row_bytes > self.cache_bytes:
            return
        self._rows[source] = row.copy()
        while len(self._rows) * row_bytes > self.cache_bytes:
            self._rows.popitem(last=False)

    def between(self, source_vertices: np.ndarray, target_face: np.ndarray, target_weights: np.ndarray) -> np.ndarray:
        """(N,) distance from vertex ``source_vertices[i]`` to the surface point (``target_face[i]``,
        ``target_weights[i]``), in mesh units.

        The distance is the barycentric interpolation, at that point, of the per-vertex distance field
        of source i. Heat: each unique source's field is computed once (in blocks of bounded memory,
        cached rows reused). Dijkstra: unless every source's row is cached, searches are bounded to the
        radius each pair needs (exact values; ~0.1 ms per near pair on a 10k-vertex mesh instead of
        ~2 ms per unbounded row), so no rows are cached by this call.

        Args:
            source_vertices: (N,) int vertex ids.
            target_face: (N,) int face ids (must be valid, no -1).
            target_weights: (N, 3) barycentric weights in face-column order.
        """
        source_vertices, target_face, target_weights = _point_queries(source_vertices, target_face, target_weights)
        n = len(source_vertices)
        if n and (target_face.min() < 0 or target_face.max() >= self.mesh.n_faces):
            raise IndexError(
                f"target faces must lie in [0, {self.mesh.n_faces}); got [{target_face.min()}, {target_face.max()}]"
            )
        corners = self.mesh.faces[target_face]  # (N, 3)
        unique, inverse = np.unique(source_vertices, return_inverse=True)
        if self.method == "dijkstra" and not all(int(s) in self._rows for s in unique):
            return self._between_bounded(source_vertices, corners, target_weights)
        out = np.empty(n)
        unique, inverse = np.unique(source_vertices, return_inverse=True)
        order = np.argsort(inverse, kind="stable")
        starts = np.searchsorted(inverse[order], np.arange(len(unique) + 1))
        for block in _chunks(np.arange(len(unique)), self.n_vertices):
            rows = self.from_vertices(unique[block])  # (B, V)
            sel = order[starts[block.start] : starts[block.stop]]
            local = inverse[sel] - block.start
            out[sel] = np.einsum("nk,nk->n", rows[local[:, None], corners[sel]], target_weights[sel])
        return out

    def point_to_vertices(self, face: np.ndarray, weights: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """Distances from surface points to vertices, computed from the POINTS' side.

        ``out[i, m] = sum_k weights[i, k] * d(faces[face[i], k], targets[i, m])``: the barycentric
        interpolation, at point i, of the distance fields of ``targets[i, m]`` (geodesic distance being
        symmetric), evaluated with rows from the points' corners instead. Sources are the unique corners
        with a non-zero weight that differ from some target of their point (d(v, v) = 0 needs no row),
        so one set of rows serves every column of ``targets`` (e.g. the predictions of several methods
        against one ground truth), and a prediction equal to the true vertex costs nothing. Rows are
        computed in blocks of bounded memory and cached as by :meth:`from_vertices`.

        Args:
            face: (N,) int face ids (valid, no -1); weights: (N, 3) barycentric weights (face-column order).
            targets: (N,) or (N, M) int vertex ids; -1 = no target (NaN out).

        Returns:
            float64 array shaped like ``targets``, in mesh units.
        """
        face = np.asarray(face, dtype=np.int64).reshape(-1)
        weights = np.asarray(weights, dtype=np.float64).reshape(-1, 3)
        targets = np.asarray(targets, dtype=np.int64)
        squeeze = targets.ndim == 1
        targets = targets.reshape(len(targets), -1)
        if not len(face) == len(weights) == len(targets):
            raise ValueError(
                f"point -> vertex queries need equally long inputs; got {len(face)}, {len(weights)}, {len(targets)}"
            )
        if len(face) and (face.min() < 0 or face.max() >= self.mesh.n_faces):
            raise IndexError(f"faces must lie in [0, {self.mesh.n_faces}); got [{face.min()}, {face.max()}]")
        if targets.size and (targets.min() < -1 or targets.max() >= self.n_vertices):
            raise IndexError(
                f"target vertices must lie in [-1, {self.n_vertices}); got [{targets.min()}, {targets.max()}]"
            )
        out = np.zeros(targets.shape)
        point, corner = np.nonzero(weights != 0.0)  # the (point, corner) entries that contribute
        sources = self.mesh.faces[face[point], corner]
        needed = ((targets[point] != sources[:, None]) & (targets[point] >= 0)).any(axis=1)
        point, corner, sources = point[needed], corner[needed], sources[needed]
        unique, inverse = np.unique(sources, return_inverse=True)
        order = np.argsort(inverse, kind="stable")
        starts = np.searchsorted(inverse[order], np.arange(len(unique) + 1))
        safe_targets = np.maximum(targets, 0)
        for block in _chunks(np.arange(len(unique)), self.n_vertices):
            rows = self.from_vertices(unique[block])  # (B, V)
            sel = order[starts[block.start] : starts[block.stop]]  # entries whose source is in this block
            local = inverse[sel] - block.start
            values = rows[local[:, None], safe_targets[point[sel]]]  # (n_sel, M)
            np.add.at(out, point[sel], weights[point[sel], corner[sel]][:, None] * values)
        out[targets < 0] = np.nan
        return out[:, 0] if squeeze else out

    def _between_bounded(self, sources: np.ndarray, corners: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """Dijkstra variant of :meth:`between` with searches bounded to what each pair needs (identical
        values, far cheaper when sources are near their points): a pair is done once its three corners
        are reached; otherwise its source is searched again with twice the radius."""
        graph = self._graph
        vertices = self.mesh.vertices
        mean_edge = float(graph.data.mean()) if graph.nnz else 0.0
        total_length = float(graph.data.sum())
        reach = np.linalg.norm(vertices[corners] - vertices[sources][:, None, :], axis=2).max(axis=1)
        radius = 1.5 * reach + 3.0 * mean_edge

        def interpolate(d, pairs, used):
            done = np.isfinite(d).all(axis=1) | np.isinf(used)
            value = np.einsum("nk,nk->n", d, weights[pairs])
            grown = 2.0 * used
            return value, done, np.where(grown > total_length, np.inf, grown)

        self.n_computed += len(np.unique(sources))
        return _adaptive_corner_search(graph, self.n_vertices, sources, corners, radius, interpolate)


def heat_block_size(n_faces: int, budget_bytes: int = 1 << 27) -> int:
    """Sources per solve of :class:`HeatDistanceSolver` on a mesh of ``n_faces`` faces (1..1024), so
    that its (2F, B) float64 gradient block stays within ``budget_bytes``. :func:`distance_rows` solves
    its sources in batches starting at multiples of it, and picks float32 or float64 per batch: rows
    split into tasks at multiples of it give the same bytes as one call."""
    return int(max(1, min(1024, budget_bytes // (8 * max(2 * int(n_faces), 1)))))


class HeatDistanceSolver:
    """The heat method (Crane, Weischedel and Wardetzky 2013) on the intrinsic Delaunay triangulation,
    with both linear systems factored once per mesh and many sources solved together: the export's
    all-pairs solver.

    The mesh's edges are flipped intrinsically until Delaunay (libigl ``intrinsic_delaunay_triangulation``:
    same vertices and surface metric, triangles laid out from edge lengths), as potpourri3d's "robust"
    solver does, so the Laplacian is an M-matrix and the heat stays positive on the obtuse triangles a
    decimation leaves. On it: G the per-face gradient (2 rows per face, in each triangle's own plane), A
    the face areas, ``L = Gᵀ diag(A) G`` (the cotangent Laplacian), M the lumped (barycentric) mass,
    ``t = t_coef · mean edge length²``. Per block of B sources: one heat solve ``(M + t L) U = δ`` with a
    (V, B) right-hand side, ``X = -∇U / |∇U|`` per face, one Poisson solve ``(L + εM) Φ = Gᵀ diag(A) X``
    (ε = 1e-8 / area only makes L definite), each column shifted to 0 at its source and clipped at 0.

    Distances are in the units of ``vertices``. A mesh with several connected components gives
    meaningless values between components (no heat reaches them); becos's remeshed shapes are connected.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, t_coef: float = 1.0):
        import igl

        v = np.ascontiguousarray(vertices, dtype=np.float64)
        f = np.ascontiguousarray(faces, dtype=np.int64)
        self.n_vertices = n = len(v)
        original = igl.edge_lengths(v, f)  # (F, 3): opposite corners 0, 1, 2
        t = float(t_coef) * float(original.mean()) ** 2
        lengths, f = igl.intrinsic_delaunay_triangulation(original, f)[:2]
        l_bc, l_ca, l_ab = lengths[:, 0], lengths[:, 1], lengths[:, 2]
        # each triangle in its plane: corner 0 at the origin, corner 1 on the x axis, corner 2 above it
        x2 = (l_ab**2 + l_ca**2 - l_bc**2) / (2.0 * np.maximum(l_ab, 1e-300))
        y2 = np.sqrt(np.maximum(l_ca**2 - x2**2, 0.0))
        points = np.zeros((len(f), 3, 2))
        points[:, 1, 0] = l_ab
        points[:, 2, 0], points[:, 2, 1] = x2, y2
        double_area = np.maximum(l_ab * y2, 1e-300)
        area = 0.5 * double_area
        n_faces = len(f)
        rows, cols, vals = [], [], []
        for k in range(3):  # gradient of corner k's hat function: the opposite edge turned inwards / 2A
            edge = points[:, (k + 2) % 3] - points[:, (k + 1) % 3]
            for d, component in enumerate((-edge[:, 1], edge[:, 0])):
                rows.append(d * n_faces + np.arange(n_faces))
                cols.append(f[:, k])
                vals.append(component / double_area)
        self.gradient = sp.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(2 * n_faces, n)
        )  # rows: x of every face, then y
        self.divergence = (self.gradient.T @ sp.diags(np.tile(area, 2))).tocsr()  # (V, 2F) = Gᵀ diag(A)
        self._gradient32 = self.gradient.astype(np.float32)
        self._divergence32 = self.divergence.astype(np.float32)
        laplacian = (self.divergence @ self.gradient).tocsc()
        mass = np.bincount(f.reshape(-1), weights=np.repeat(area / 3.0, 3), minlength=n)
        self._factor_heat = sp.diags(mass) + t * laplacian
        self._factor_poisson = laplacian + sp.diags(mass * (1e-8 / max(float(area.sum()), 1e-300)))
        self._heat = _factor(self._factor_heat)
        self._poisson = _factor(self._factor_poisson)

    def block_size(self, budget_bytes: int = 1 << 27) -> int:
        """Sources per solve so that the (2F, B) gradient block stays within ``budget_bytes`` (float64)."""
        return heat_block_size(self.gradient.shape[0] // 2, budget_bytes)

    def distances(self, sources: np.ndarray) -> np.ndarray:
        """(len(sources), V) float64 distances from each source vertex (one block of multi-column solves)."""
        sources = np.asarray(sources, dtype=np.int64).reshape(-1)
        b = len(sources)
        delta = np.zeros((self.n_vertices, b))
        delta[sources, np.arange(b)] = 1.0
        heat = self._heat(delta)
        # the field's direction only matters: in float32 (half the memory traffic) when every column,
        # scaled to a maximum of 1e30, stays above float32's smallest normal number (heat spans ~50
        # orders of magnitude on a 10k-vertex shape); float64 otherwise
        heat *= 1e30 / np.maximum(heat.max(axis=0), 1e-300)
        single = bool(heat.min() > 1e-36)
        gradient, divergence = (self._gradient32, self._divergence32) if single else (self.gradient, self.divergence)
        grad = gradient @ (heat.astype(np.float32) if single else heat)  # (2F, B)
        half = grad.shape[0] // 2
        norm = np.hypot(grad[:half], grad[half:])
        np.maximum(norm, 1e-30, out=norm)
        grad[:half] /= norm
        grad[half:] /= norm
        phi = self._poisson(-(divergence @ grad).astype(np.float64))  # (V, B)
        phi -= phi[sources, np.arange(b)]
        np.maximum(phi, 0.0, out=phi)
        phi[sources, np.arange(b)] = 0.0
        return phi.T


def _factor(matrix: sp.spmatrix):
    """A solve function ``b (V, B) float64 -> x`` of the symmetric positive definite ``matrix``, factored
    once: cholespy's CHOLMOD-based sparse Cholesky, whose multi-column solve costs ~0.3 ms per column at
    10k vertices (SuperLU's: ~1 ms)."""
    from cholespy import CholeskySolverD, MatrixType

    coo = sp.coo_matrix(matrix)
    solver = CholeskySolverD(
        coo.shape[0], coo.row.astype(np.int32), coo.col.astype(np.int32), coo.data.astype(np.float64), MatrixType.COO
    )

    def solve(b: np.ndarray) -> np.ndarray:
        b = np.ascontiguousarray(b, dtype=np.float64)
        x = np.empty_like(b)
        solver.solve(b, x)
        return x

    return solve


def distance_rows(vertices: np.ndarray, faces: np.ndarray, sources: np.ndarray, method: str = "heat") -> np.ndarray:
    """(len(sources), V) float32 geodesic distances from each source vertex to every vertex of the mesh
    (units of ``vertices``), for exports of whole distance matrices.

    Heat: :class:`HeatDistanceSolver`, factored once per call, sources solved in blocks of many columns
    (measured in config/README.md, exports.geodesics). Dijkstra: scipy's csgraph,
    rows in blocks of bounded memory. Stored as float32. A module-level function (no object state) so
    process pools can call it.
    """
    sources = np.asarray(sources, dtype=np.int64).reshape(-1)
    n = len(vertices)
    if len(sources) and (sources.min() < 0 or sources.max() >= n):
        raise IndexError(f"source vertices must lie in [0, {n}); got [{sources.min()}, {sources.max()}]")
    out = np.empty((len(sources), n), dtype=np.float32)
    if method == "heat":
        solver = HeatDistanceSolver(vertices, faces)
        size = solver.block_size()
        for start in range(0, len(sources), size):
            out[start : start + size] = solver.distances(sources[start : start + size])
        return out
    mesh = TriMesh(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64))
    solver = GeodesicDistances(mesh, method, cache_bytes=0)
    for block in _chunks(np.arange(len(sources)), mesh.n_vertices):
        out[block] = solver.from_vertices(sources[block])
    return out


class GeodesicsCache:
    """Solvers of several shapes, least recently used first out: "cached per shape" across pairs.

    A shape recurs across the pairs of a benchmark under different rigid motions (random rotation,
    alignment), which leave geodesic distances unchanged; the caller names the shape by a ``key``
    (e.g. :func:`shape_key`) and the first mesh seen under that key is used for every later request.

    Args:
        method: ``"heat"`` or ``"dijkstra"`` (see :class:`GeodesicDistances`).
        max_shapes: how many shapes' solvers (and cached rows) are kept.
        cache_bytes: total row-cache budget, shared equally by the shapes kept.
    """

    def __init__(self, method: str = "heat", max_shapes: int = 2, cache_bytes: int = 1 << 30):
        if method not in METHODS:
            raise ValueError(f"unknown geodesic method {method!r}; choose one of {METHODS}")
        self.method = method
        self.max_shapes = max(1, int(max_shapes))
        self.cache_bytes = int(cache_bytes)
        self._solvers: OrderedDict[object, GeodesicDistances] = OrderedDict()
        self.hits = 0
        self.misses = 0

    def get(self, key, mesh: TriMesh) -> GeodesicDistances:
        """The solver of shape ``key`` (built from ``mesh`` on first use)."""
        solver = self._solvers.get(key)
        if solver is not None:
            self._solvers.move_to_end(key)
            self.hits += 1
            return solver
        self.misses += 1
        solver = GeodesicDistances(mesh, self.method, cache_bytes=self.cache_bytes // self.max_shapes)
        self._solvers[key] = solver
        while len(self._solvers) > self.max_shapes:
            self._solvers.popitem(last=False)
        return solver

    @property
    def n_computed(self) -> int:
        """Rows computed by the solvers currently kept."""
        return sum(s.n_computed for s in self._solvers.values())


def shape_key(mesh: TriMesh, *names) -> tuple:
    """A key naming a shape up to rigid motion: ``names`` (e.g. dataset, name, remesh variant), the
    vertex and face counts, a digest of the faces and the total edge length (rounded to 9 significant
    digits, so a rescaled copy gets another key)."""
    import hashlib

    digest = hashlib.sha1(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes()).hexdigest()
    edges = mesh.vertices[mesh.faces[:, [1, 2, 0]]] - mesh.vertices[mesh.faces]
    length = float(np.linalg.norm(edges, axis=2).sum())
    return (*names, mesh.n_vertices, mesh.n_faces, digest, float(f"{length:.9g}"))


_PER_MESH: weakref.WeakKeyDictionary[TriMesh, dict[str, GeodesicDistances]] = weakref.WeakKeyDictionary()


def geodesics_for(mesh: TriMesh, method: str = "heat") -> GeodesicDistances:
    """The process-wide :class:`GeodesicDistances` of this mesh object and method (built once).

    Keyed by the mesh object's identity (held weakly), so the solver factorisation and the cached rows
    are shared by every caller that holds the same :class:`TriMesh`, and freed with it.
    """
    per_method = _PER_MESH.setdefault(mesh, {})
    if method not in per_method:
        per_method[method] = GeodesicDistances(mesh, method)
    return per_method[method]


def dijkstra_to_points(
    mesh: TriMesh,
    source_vertices: np.ndarray,
    target_face: np.ndarray,
    target_weights: np.ndarray,
    limit: float | None = None,
    graph: sp.csr_matrix | None = None,
) -> np.ndarray:
    """(N,) edge-graph distance from vertex ``source_vertices[i]`` to the point (``target_face[i]``,
    ``target_weights[i]``), in mesh units.

    The distance to a point is min over the face's corners c of (Dijkstra distance(source, c) +
    Euclidean |V[c] - point|): an upper bound of the surface geodesic, exact at vertices for the edge
    graph.

    Args:
        mesh: the surface holding sources and points.
        source_vertices: (N,) int vertex ids.
        target_face: (N,) int face ids; target_weights: (N, 3) barycentric weights (face-column order).
        limit: None (default) gives the exact value for every pair, computed with bounded searches whose
            radius starts at 1.5x the Euclidean distance (+3 mean edge lengths) and grows only for the
            pairs that need it, so near pairs stay cheap. A number gives the exact value where it is
            <= ``limit`` and ``inf`` elsewhere (cheapest when only small errors matter).
        graph: the mesh's :func:`edge_graph`, if already built.
    """
    source_vertices, target_face, target_weights = _point_queries(source_vertices, target_face, target_weights)
    n = len(source_vertices)
    if n == 0:
        return np.zeros(0)
    if graph is None:
        graph = edge_graph(mesh)
    corners = mesh.faces[target_face]  # (N, 3)
    points = np.einsum("nk,nkd->nd", target_weights, mesh.vertices[corners])
    to_corner = np.linalg.norm(mesh.vertices[corners] - points[:, None, :], axis=2)  # (N, 3)

    mean_edge = float(graph.data.mean()) if graph.nnz else 0.0
    total_length = float(graph.data.sum())  # no finite distance exceeds it
    if limit is not None:
        radius = np.full(n, float(limit))
    else:
        radius = 1.5 * np.linalg.norm(mesh.vertices[source_vertices] - points, axis=1) + 3.0 * mean_edge

    def nearest_corner(d, pairs, used):
        cand = (d + to_corner[pairs]).min(axis=1)
        # corners farther than the limit were not reached, so a candidate is exact when <= the limit
        done = (cand <= used) | np.isinf(used) | (limit is not None)
        # a finite candidate bounds the true distance: searching up to it is exact next round
        grown = np.where(np.isfinite(cand), cand, 2.0 * used)
        return cand, done, np.where(grown > total_length, np.inf, grown)

    out = _adaptive_corner_search(graph, mesh.n_vertices, source_vertices, corners, radius, nearest_corner)
    if limit is not None:
        out[out > limit] = np.inf
    return out


def _adaptive_corner_search(
    graph: sp.csr_matrix, n_vertices: int, sources: np.ndarray, corners: np.ndarray, radius: np.ndarray, combine
) -> np.ndarray:
    """Bounded Dijkstra searches from ``sources`` (N,), read at ``corners`` (N, 3), repeated with larger
    radii for the pairs that need it.

    ``combine(d, pairs, used)`` gets the (n, 3) corner distances (inf beyond the search limit) of the
    pairs ``pairs`` (indices into the N inputs) searched with limits ``used`` (n,), and returns
    (value (n,), done (n,) bool, next radius (n,)). Each round searches each unique source once, up to
    the largest radius its pending pairs need; sources are sorted by radius so that one block of searches
    shares a similar limit (scipy takes one limit per call).
    """
    out = np.full(len(sources), np.inf)
    radius = radius.astype(np.float64, copy=True)
    todo = np.arange(len(sources))
    while len(todo):
        unique, inverse = np.unique(sources[todo], return_inverse=True)
        need = np.zeros(len(unique))
        np.maximum.at(need, inverse, radius[todo])
        by_radius = np.argsort(need, kind="stable")
        rank = np.empty_like(by_radius)
        rank[by_radius] = np.arange(len(by_radius))
        pair_rank = rank[inverse]
        pair_order = np.argsort(pair_rank, kind="stable")
        starts = np.searchsorted(pair_rank[pair_order], np.arange(len(unique) + 1))
        used = np.empty(len(todo))
        d = np.empty((len(todo), 3))
        for block in _chunks(by_radius, n_vertices):
            block_limit = float(need[by_radius[block]].max())
            rows = dijkstra(graph, directed=False, indices=unique[by_radius[block]], limit=block_limit)
            sel = pair_order[starts[block.start] : starts[block.stop]]
            local = pair_rank[sel] - block.start
            d[sel] = rows[local[:, None], corners[todo[sel]]]
            used[sel] = block_limit
        value, done, grown = combine(d, todo, used)
        out[todo[done]] = value[done]
        radius[todo[~done]] = grown[~done]
        todo = todo[~done]
    return out
