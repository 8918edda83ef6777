"""Geometry on triangle meshes: areas, barycentric coordinates, closest points on a surface.

Barycentric weights are always in face-column order: a point in face ``f`` with weights ``w`` is
``w[0] * V[F[f, 0]] + w[1] * V[F[f, 1]] + w[2] * V[F[f, 2]]``.
"""

from __future__ import annotations

import numpy as np

from becos.core.mesh import TriMesh, zero_area_triangles


def face_areas(mesh: TriMesh) -> np.ndarray:
    """(F,) area of each face, in squared units of the vertex coordinates."""
    tri = mesh.vertices[mesh.faces]
    return 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)


def surface_area(mesh: TriMesh) -> float:
    """Total surface area (squared units)."""
    return float(face_areas(mesh).sum())


def vertex_areas(mesh: TriMesh) -> np.ndarray:
    """(V,) barycentric vertex areas: a third of the area of each incident face."""
    areas = np.zeros(mesh.n_vertices)
    np.add.at(areas, mesh.faces.ravel(), np.repeat(face_areas(mesh) / 3.0, 3))
    return areas


def barycentric_coordinates(points: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(N, 3) barycentric weights of (N, 3) ``points`` in the triangles (a, b, c), each (N, 3).

    Points are assumed to lie in (or be projected onto) the triangle's plane. Degenerate triangles
    give the weights of the closest corner. Weights are clipped to [0, 1] and sum to 1.
    """
    v0, v1, v2 = b - a, c - a, points - a
    d00 = np.einsum("ij,ij->i", v0, v0)
    d01 = np.einsum("ij,ij->i", v0, v1)
    d11 = np.einsum("ij,ij->i", v1, v1)
    d20 = np.einsum("ij,ij->i", v2, v0)
    d21 = np.einsum("ij,ij->i", v2, v1)
    denom = d00 * d11 - d01 * d01
    ok = denom > 1e-300
    safe = np.where(ok, denom, 1.0)
    w1 = (d11 * d20 - d01 * d21) / safe
    w2 = (d00 * d21 - d01 * d20) / safe
    weights = np.stack([1.0 - w1 - w2, w1, w2], axis=1)
    if not ok.all():
        corners = np.stack([a, b, c], axis=1)[~ok]
        nearest = np.linalg.norm(corners - points[~ok, None, :], axis=2).argmin(axis=1)
        weights[~ok] = np.eye(3)[nearest]
    weights = np.clip(weights, 0.0, 1.0)
    return weights / weights.sum(axis=1, keepdims=True)


def face_normals(mesh: TriMesh) -> np.ndarray:
    """(F, 3) unit face normals (right-hand rule on the face's vertex order); zero for degenerate faces."""
    return _triangle_normals(np.take(mesh.vertices, mesh.faces, axis=0))


def _triangle_normals(tri: np.ndarray) -> np.ndarray:
    """(F, 3) unit normals of the (F, 3, 3) triangles ``tri`` (corner positions), as :func:`face_normals`."""
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def oriented_face_normals(mesh: TriMesh) -> np.ndarray:
    """(F, 3) unit face normals after orienting the faces consistently (a copy; libigl BFS per patch).

    Real data has inconsistently wound faces (TOSCA michael0: 1,594 rows differ from michael3 by
    winding); these normals agree across neighbouring faces. Each patch's global sign is arbitrary:
    it is made outward when the patch's signed volume says so.
    """
    import igl

    oriented, component = igl.bfs_orient(mesh.faces)
    tri = np.take(mesh.vertices, np.asarray(oriented, dtype=np.int64), axis=0)  # (F, 3, 3) oriented corners
    normals = _triangle_normals(tri)
    signed = np.einsum("fd,fd->f", tri[:, 0], np.cross(tri[:, 1], tri[:, 2]))  # 6 x signed volume
    volume = np.bincount(component, weights=signed)
    return normals * np.where(volume[component] < 0, -1.0, 1.0)[:, None]


def vertex_normals(mesh: TriMesh) -> np.ndarray:
    """(V, 3) unit vertex normals: area-weighted sums of the incident face normals."""
    tri = mesh.vertices[mesh.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # length = 2 * area
    out = np.zeros((mesh.n_vertices, 3))
    np.add.at(out, mesh.faces.ravel(), np.repeat(n, 3, axis=0))
    length = np.linalg.norm(out, axis=1, keepdims=True)
    return np.divide(out, length, out=np.zeros_like(out), where=length > 0)


def closest_points_on_triangles(
    points: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray, *, nondegenerate: bool = False
) -> np.ndarray:
    """(..., 3) closest point of each point to its triangle (a, b, c); all inputs broadcast to (..., 3).

    Ericson, Real-Time Collision Detection, 5.1.5, vectorised over the leading axes. A degenerate
    triangle (:func:`becos.core.mesh.zero_area_triangles`: a segment or a point) gets the closest
    point of its three sides, where Ericson's regions rest on cross terms that are rounding noise.
    ``nondegenerate``: the caller knows no triangle is degenerate (e.g. a :class:`SurfaceLocator`'s
    usable faces), which skips that test (a quarter of the function's time).
    """
    ab, ac, ap = b - a, c - a, points - a
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    bp = points - b
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    cp = points - c
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v_in, w_in = vb / denom, vc / denom
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        # a degenerate triangle (denom 0) gives inf x 0 here: an edge or vertex region below, or the
        # final isfinite guard, replaces it
        result = a + v_in[..., None] * ab + w_in[..., None] * ac
    # edge and vertex regions, checked from the most general to the most specific
    on_bc = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
    result = np.where(on_bc[..., None], b + t_bc[..., None] * (c - b), result)
    on_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    result = np.where(on_ac[..., None], a + t_ac[..., None] * ac, result)
    on_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    result = np.where(on_ab[..., None], a + t_ab[..., None] * ab, result)
    result = np.where(((d6 >= 0) & (d5 <= d6))[..., None], c, result)
    result = np.where(((d3 >= 0) & (d4 <= d3))[..., None], b, result)
    result = np.where(((d1 <= 0) & (d2 <= 0))[..., None], a, result)
    if nondegenerate:
        return np.where(np.isfinite(result), result, a)
    degenerate = zero_area_triangles(a, b, c)
    if np.any(degenerate):
        result = np.where(degenerate[..., None], _closest_points_on_sides(points, a, b, c), result)
    return np.where(np.isfinite(result), result, a)


def _closest_points_on_sides(points: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(..., 3) closest point of each point to the segments ab, bc, ca (inputs broadcast to (..., 3))."""
    best, best_sq = None, None
    for p, q in ((a, b), (b, c), (c, a)):
        pq = q - p
        length_sq = (pq * pq).sum(-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.clip(((points - p) * pq).sum(-1) / length_sq, 0.0, 1.0)
        t = np.where(length_sq > 0, t, 0.0)
        on_side = p + t[..., None] * pq
        sq = ((on_side - points) ** 2).sum(-1)
        if best is None:
            best, best_sq = on_side, sq
        else:
            closer = sq < best_sq
            best, best_sq = np.where(closer[..., None], on_side, best), np.where(closer, sq, best_sq)
    return best


def points_on_surface(mesh: TriMesh, face: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(N, 3) positions of the surface points (``face`` (N,) int, ``weights`` (N, 3))."""
    tri = mesh.vertices[mesh.faces[face]]
    return np.einsum("nk,nkd->nd", weights, tri)


class SurfaceLocator:
    """Closest-point queries on one mesh, with the AABB tree built once (libigl).

    Querying 10,000 points on a 100k-face mesh takes ~0.1 s including the build.

    With query normals (from a consistently oriented surface, e.g. :func:`oriented_face_normals`;
    a global sign flip is detected and undone), a point only lands on a face whose normal agrees with its own (cosine above
    ``min_cos``): where two parts of a shape touch (a hand on a hip, a horse's legs) the plain closest
    point can sit on the other part, a jump of a large geodesic distance; the two parts' normals are
    opposite there, so the normal test rejects it. Rejected queries are answered by the closest
    compatible face among the ``k`` faces with the nearest centroids (widened once), if it is at most
    ``max_detour`` (default: the mean edge length) farther than the plain closest point -- a jump
    across a contact is that local; farther answers mean the normal test misleads (thin or open
    parts) -- else by the plain closest point.

    Answers never lie in a degenerate face (repeated vertex index or zero area) or in a duplicate of
    an earlier face row (:func:`becos.core.mesh.surface_faces`): such faces are left out of the search, so
    barycentric weights are always well defined. Face indices returned are rows of ``mesh.faces``.
    """

    def __init__(self, mesh: TriMesh):
        import igl

        from becos.core.mesh import degenerate_faces, duplicate_faces

        self.mesh = mesh
        degenerate = degenerate_faces(mesh)
        self._first = duplicate_faces(mesh.faces, mesh.n_vertices, among=~degenerate)
        usable = ~degenerate & (self._first < 0)
        if not usable.any():
            raise ValueError(f"SurfaceLocator: none of the {mesh.n_faces} faces has a non-zero area")
        self._rows = None if usable.all() else np.flatnonzero(usable)  # searched rows (None: all)
        self._faces = mesh.faces if self._rows is None else mesh.faces[self._rows]
        self._tree = igl.AABB()
        self._tree.init(mesh.vertices, self._faces)
        self._normals = None
        self._centroids = None
        self._triangles = None
        self._rings: dict[int, VertexRings] = {}
        searched = self.triangles if self._rows is None else self.triangles[self._rows]  # (F_s, 3, 3)
        edges = searched - np.roll(searched, 1, axis=1)
        self.max_detour = float(np.linalg.norm(edges, axis=2).mean())

    def rings(self, rings: int) -> VertexRings:
        """:class:`VertexRings` of the mesh (built once per ring count)."""
        if rings not in self._rings:
            self._rings[rings] = VertexRings(self.mesh.faces, self.mesh.n_vertices, rings)
        return self._rings[rings]

    @property
    def searches_every_face(self) -> bool:
        """No face row is left out of the search (then :attr:`face_normals` is
        :func:`oriented_face_normals` of the mesh)."""
        return self._rows is None

    @property
    def triangles(self) -> np.ndarray:
        """(F, 3, 3) float64 corner positions of every row of ``mesh.faces`` (computed once)."""
        if self._triangles is None:
            self._triangles = np.take(self.mesh.vertices, self.mesh.faces, axis=0)
        return self._triangles

    def _row(self, index: np.ndarray) -> np.ndarray:
        """Rows of ``mesh.faces`` of indices into the searched faces."""
        return index if self._rows is None else self._rows[index]

    @property
    def face_normals(self) -> np.ndarray:
        """(F, 3) unit face normals of the mesh, consistently oriented (computed once).

        A duplicate row gets the normal of the row it repeats; a degenerate one zero."""
        if self._normals is None:
            if self._rows is None:
                self._normals = oriented_face_normals(self.mesh)
            else:
                normals = np.zeros((self.mesh.n_faces, 3))
                normals[self._rows] = oriented_face_normals(TriMesh(self.mesh.vertices, self._faces))
                dup = np.flatnonzero(self._first >= 0)
                normals[dup] = normals[self._first[dup]]
                self._normals = normals
        return self._normals

    def _plain(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        sq_dist, face, closest = self._tree.squared_distance(self.mesh.vertices, self._faces, points)
        return self._row(np.asarray(face, dtype=np.int64)), np.asarray(closest)

    def _compatible(self, points: np.ndarray, normals: np.ndarray, min_cos: float, k: int):
        """Closest point among the k nearest-centroid faces with a compatible normal; face -1 if none."""
        from scipy.spatial import cKDTree

        if self._centroids is None:
            self._centroids = cKDTree(self.mesh.vertices[self._faces].mean(axis=1))
        k = min(k, len(self._faces))
        _, cand = self._centroids.query(points, k=k)
        cand = self._row(np.asarray(cand).reshape(len(points), k))
        tri = np.take(self.triangles, cand, axis=0)  # (M, k, 3, 3)
        closest = closest_points_on_triangles(
            points[:, None, :],
            tri[..., 0, :],
            tri[..., 1, :],
            tri[..., 2, :],
            nondegenerate=True,  # usable faces only
        )
        dist = np.linalg.norm(closest - points[:, None, :], axis=2)
        ok = np.einsum("mkd,md->mk", np.take(self._normals, cand, axis=0), normals) > min_cos
        dist = np.where(ok, dist, np.inf)
        best = dist.argmin(axis=1)
        rows = np.arange(len(points))
        face = np.where(np.isfinite(dist[rows, best]), cand[rows, best], -1)
        return face, closest[rows, best]

    def closest(
        self, points: np.ndarray, normals: np.ndarray | None = None, min_cos: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest surface point of each of the (N, 3) ``points``.

        Args:
            points: (N, 3) query positions.
            normals: optional (N, 3) unit normals of the queries (see the class docstring).
            min_cos: the smallest accepted cosine between a query normal and a face normal.

        Returns:
            face: (N,) int64 face holding the closest point.
            weights: (N, 3) float64 barycentric weights of it in that face.
            distance: (N,) float64 Euclidean distance from the query to it.
        """
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if len(points) == 0:
            return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0)
        face, closest = self._plain(points)
        if normals is not None:
            normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
            has_normal = np.linalg.norm(normals, axis=1) > 0
            cosine = (np.take(self.face_normals, face, axis=0) * normals).sum(axis=1)
            if np.median(cosine[has_normal]) < 0:  # the queries come from a surface oriented the other way
                normals, cosine = -normals, -cosine
            flipped = np.flatnonzero(has_normal & (cosine <= min_cos))
            plain_distance = np.linalg.norm(closest - points, axis=1)
            for k in (32, 256):
                if len(flipped) == 0:
                    break
                f, c = self._compatible(points[flipped], normals[flipped], min_cos, k)
                detour = np.linalg.norm(c - points[flipped], axis=1) - plain_distance[flipped]
                found = (f >= 0) & (detour <= self.max_detour)
                face[flipped[found]], closest[flipped[found]] = f[found], c[found]
                flipped = flipped[(f < 0)]
        tri = np.take(self.triangles, face, axis=0)
        weights = barycentric_coordinates(closest, tri[:, 0], tri[:, 1], tri[:, 2])
        return face, weights, np.linalg.norm(closest - points, axis=1)

    def closest_near(
        self,
        points: np.ndarray,
        accept,
        normals: np.ndarray | None = None,
        ks: tuple[int, ...] = (32, 256),
        min_cos: float | None = None,
        detour: float = 0.0,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Closest surface point of each query among the faces ``accept`` allows: contact-safe by connectivity.

        Where two parts of a shape touch or pass through each other (a hand on a hip, the arch of a foot
        against its heel), neither distance nor normals say which part a point belongs to; what the
        caller knows of the point's neighbourhood along the surface does. ``accept(rows, faces)`` gets
        (M,) query indices and (M, K) candidate face rows and returns (M, K) bool: the face may hold
        that query's point.

        The answer of :meth:`closest` (with ``normals``, if given) is kept where accepted; otherwise the
        closest accepted face among the ``k`` faces with the nearest centroids, for ``k`` in ``ks``.

        With ``normals`` and ``min_cos``, an answer whose face normal makes a cosine of at most
        ``min_cos`` with the query's is replaced by the closest accepted face that agrees (cosine above
        ``min_cos``) if that is at most ``detour`` (mesh units) farther: at the tip of a thin part (two
        sheets closer than the mesh's chordal error) the closest allowed face can bend over the rim.

        Returns:
            face (N,), weights (N, 3), distance (N,) as :meth:`closest`, and ``unresolved`` (N,) bool:
            no accepted face was found, the answer is :meth:`closest`'s.
        """
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        face, weights, distance, unresolved = self._closest_accepted(points, accept, normals, ks)
        if min_cos is None or normals is None:
            return face, weights, distance, unresolved
        normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        cosine = np.einsum("nd,nd->n", self.face_normals[face], normals)
        sign = 1.0 if np.median(cosine) >= 0 else -1.0  # the queries' surface may be oriented the other way
        bent = np.flatnonzero(~unresolved & (sign * cosine <= min_cos))
        if len(bent):

            def agreeing(rows, cand):
                cos = np.einsum("mkd,md->mk", self.face_normals[cand], normals[bent[rows]])
                return np.asarray(accept(bent[rows], cand), dtype=bool) & (sign * cos > min_cos)

            f, w, d, u = self._closest_accepted(points[bent], agreeing, normals[bent], ks)
            better = ~u & (d <= distance[bent] + detour)
            face[bent[better]], weights[bent[better]], distance[bent[better]] = f[better], w[better], d[better]
        return face, weights, distance, unresolved

    def _closest_accepted(self, points: np.ndarray, accept, normals: np.ndarray | None, ks: tuple[int, ...]):
        """:meth:`closest_near` without the ``min_cos`` preference."""
        from scipy.spatial import cKDTree

        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        face, weights, distance = self.closest(points, normals)
        todo = np.flatnonzero(~np.asarray(accept(np.arange(len(points)), face[:, None]), dtype=bool)[:, 0])
        if len(todo) and self._centroids is None:
            self._centroids = cKDTree(self.mesh.vertices[self._faces].mean(axis=1))
        for k in ks:
            if len(todo) == 0:
                break
            k = min(k, len(self._faces))
            _, cand = self._centroids.query(points[todo], k=k)
            cand = self._row(np.asarray(cand).reshape(len(todo), k))
            tri = np.take(self.triangles, cand, axis=0)  # (M, k, 3, 3)
            closest = closest_points_on_triangles(
                points[todo, None, :],
                tri[..., 0, :],
                tri[..., 1, :],
                tri[..., 2, :],
                nondegenerate=True,  # usable faces only
            )
            dist = np.linalg.norm(closest - points[todo, None, :], axis=2)
            dist = np.where(np.asarray(accept(todo, cand), dtype=bool), dist, np.inf)
            best = dist.argmin(axis=1)
            rows = np.arange(len(todo))
            found = np.isfinite(dist[rows, best])
            hit, f, c = todo[found], cand[rows, best][found], closest[rows, best][found]
            tri = self.triangles[f]
            face[hit] = f
            weights[hit] = barycentric_coordinates(c, tri[:, 0], tri[:, 1], tri[:, 2])
            distance[hit] = np.linalg.norm(c - points[hit], axis=1)
            todo = todo[~found]
        unresolved = np.zeros(len(points), dtype=bool)
        unresolved[todo] = True
        return face, weights, distance, unresolved


class SparsePairs:
    """Membership test for the non-zeros of a sparse (R, C) matrix: is (a, b) one of them?

    Stored as the sorted keys ``a * C + b``; :meth:`near` looks up broadcast index arrays at once."""

    def __init__(self, matrix):
        import scipy.sparse as sp

        csr = sp.csr_matrix(matrix)
        if not csr.has_canonical_format:  # sorted column indices, no duplicates: the keys come out sorted
            csr = csr.copy()
            csr.sum_duplicates()
        self.n_columns = int(matrix.shape[1])
        rows = np.repeat(np.arange(csr.shape[0], dtype=np.int64), np.diff(csr.indptr))
        self._keys = rows * self.n_columns + csr.indices  # sorted and unique, without a sort

    def near(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Bool array (``a`` and ``b`` broadcast): (a, b) is a non-zero of the matrix."""
        keys = np.asarray(a, dtype=np.int64) * self.n_columns + np.asarray(b, dtype=np.int64)
        if len(self._keys) == 0:
            return np.zeros(keys.shape, dtype=bool)
        pos = np.minimum(np.searchsorted(self._keys, keys), len(self._keys) - 1)
        return self._keys[pos] == keys


def vertex_adjacency(faces: np.ndarray, n_vertices: int):
    """(V, V) float32 CSR 0/1 matrix: the face edges of the mesh, with the diagonal (A + I)."""
    import scipy.sparse as sp

    faces = np.asarray(faces, dtype=np.int64)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    n = int(n_vertices)
    a = sp.coo_matrix((np.ones(len(e), dtype=np.float32), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    return ((a + a.T + sp.identity(n, dtype=np.float32, format="csr")) > 0).astype(np.float32).tocsr()


class VertexRings(SparsePairs):
    """Which vertices of a mesh lie within ``rings`` edge rings of each other (mesh connectivity only).

    Two points that are close in space but far apart along the surface (two touching parts) are
    told apart by this; Euclidean distance and normals cannot. The non-zeros of ``(A + I) ** rings``
    (:func:`vertex_adjacency`; ``matrix``): ~(1 + 3 r (r + 1)) per vertex on a regular mesh (r = 5: 91).
    """

    def __init__(self, faces: np.ndarray, n_vertices: int, rings: int):
        a = vertex_adjacency(faces, n_vertices)
        self.rings = int(rings)
        reach = a
        for _ in range(self.rings - 1):
            reach = reach @ a
            reach.sum_duplicates()  # sorted indices, as a comparison's result has them
            reach.data[:] = 1.0  # products of 0/1 matrices without zeros: every stored entry is >= 1
        self.matrix = reach.tocsr()
        super().__init__(self.matrix)


def nearest_along_surface(mesh: TriMesh, sources: np.ndarray, graph=None) -> np.ndarray:
    """(V,) int64 index into ``sources`` of the source vertex nearest to each vertex ALONG the surface.

    Shortest paths on the mesh's edge graph from all sources at once (one multi-source Dijkstra,
    :func:`scipy.sparse.csgraph.dijkstra` with ``min_only``): a geodesic Voronoi partition, so a
    vertex is never given a source on another part that merely touches it in space. -1 for vertices
    no source reaches (other components). ``graph``: the mesh's :func:`becos.core.geodesics.edge_graph`, if
    already built (a caller with many queries on one mesh builds it once).
    """
    from scipy.sparse.csgraph import dijkstra

    from becos.core.geodesics import edge_graph

    sources = np.asarray(sources, dtype=np.int64)
    unique, first = np.unique(sources, return_index=True)
    graph = edge_graph(mesh) if graph is None else graph
    _, _, owner = dijkstra(graph, directed=False, indices=unique, min_only=True, return_predecessors=True)
    owner = np.asarray(owner, dtype=np.int64)
    lookup = np.full(mesh.n_vertices, -1, dtype=np.int64)
    lookup[unique] = first
    return np.where(owner >= 0, lookup[np.maximum(owner, 0)], -1)
