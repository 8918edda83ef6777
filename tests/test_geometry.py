"""becos.core.geometry helpers that other tests do not reach through the pipeline."""

from __future__ import annotations

import numpy as np

from becos.core.geometry import nearest_along_surface
from becos.core.mesh import TriMesh


def _strip(n: int, offset: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A 2 x n vertex strip of unit squares along x, shifted by ``offset``."""
    x = np.arange(n, dtype=float)
    vertices = (
        np.concatenate([np.stack([x, np.zeros(n), np.zeros(n)], 1), np.stack([x, np.ones(n), np.zeros(n)], 1)]) + offset
    )
    i = np.arange(n - 1)
    faces = np.concatenate([np.stack([i, i + 1, n + i], 1), np.stack([i + 1, n + i + 1, n + i], 1)])
    return vertices, faces


def test_nearest_along_surface_never_crosses_a_contact():
    """Two strips touching in space (0.01 apart): each vertex gets a source of its own strip, the one
    nearest along it, although a source of the other strip is nearer in space; a strip without a
    source gets -1."""
    va, fa = _strip(10, np.zeros(3))
    vb, fb = _strip(10, np.array([0.0, 0.0, 0.01]))
    mesh = TriMesh(np.concatenate([va, vb]), np.concatenate([fa, fb + len(va)]))
    sources = np.array([0, 29])  # strip A's vertex 0, strip B's vertex 9 (far end)
    owner = nearest_along_surface(mesh, sources)
    assert (owner[:20] == 0).all() and (owner[20:] == 1).all()
    assert (nearest_along_surface(mesh, np.array([0]))[20:] == -1).all()


def test_sparse_pairs_keys_are_the_sorted_unique_non_zeros():
    """SparsePairs reads its keys off the canonical CSR (no sort): the same keys as np.unique of the
    (row, column) pairs, for canonical products and for matrices with unsorted or repeated entries."""
    import scipy.sparse as sp

    from becos.core.geometry import SparsePairs

    rng = np.random.default_rng(7)
    rows, cols = rng.integers(0, 50, 400), rng.integers(0, 70, 400)  # repeats included
    raw = sp.csr_matrix((np.ones(400, dtype=np.float32), (rows, cols)), shape=(50, 70))
    unsorted = sp.csr_matrix((raw.data[::-1].copy(), raw.indices.copy(), raw.indptr.copy()), shape=raw.shape)
    for row in range(50):  # reverse each row's columns: valid CSR, not canonical
        s, e = unsorted.indptr[row], unsorted.indptr[row + 1]
        unsorted.indices[s:e] = unsorted.indices[s:e][::-1]
    unsorted.has_sorted_indices = False
    duplicated = sp.csr_matrix((np.ones(800, dtype=np.float32), (np.r_[rows, rows], np.r_[cols, cols])), shape=(50, 70))
    product = raw @ raw.T
    for matrix in (raw, unsorted, duplicated, product, sp.coo_matrix(raw)):
        coo = sp.coo_matrix(matrix)
        expected = np.unique(coo.row.astype(np.int64) * matrix.shape[1] + coo.col)
        pairs = SparsePairs(matrix)
        assert np.array_equal(pairs._keys, expected)
        a, b = rng.integers(0, matrix.shape[0], 300), rng.integers(0, matrix.shape[1], 300)
        assert np.array_equal(pairs.near(a, b), np.isin(a.astype(np.int64) * matrix.shape[1] + b, expected))


def test_vertex_rings_pattern_and_diagonal():
    """VertexRings holds the canonical 0/1 CSR of the non-zeros of ``(A + I) ** r`` (the same matrix
    as thresholding each product), and every vertex is within the rings of itself (compose accepts a
    face that shares a corner with an image face without a lookup)."""
    from becos.core.geometry import VertexRings, vertex_adjacency

    vertices, faces = _strip(12, np.zeros(3))
    n = len(vertices)
    a = vertex_adjacency(faces, n)
    for rings in (1, 2, 3, 5):
        expected = a
        for _ in range(rings - 1):
            expected = ((expected @ a) > 0).astype(np.float32)
        expected = expected.tocsr()
        got = VertexRings(faces, n, rings)
        assert got.matrix.has_canonical_format and got.matrix.dtype == np.float32
        assert np.array_equal(got.matrix.indptr, expected.indptr)
        assert np.array_equal(got.matrix.indices, expected.indices)
        assert np.array_equal(got.matrix.data, expected.data)
        assert got.near(np.arange(n), np.arange(n)).all()


def test_closest_point_on_a_degenerate_triangle_is_silent_and_exact():
    """Triangles collapsed to a segment (c on ab, in general position) or to a point: the closest point
    of the segment (or the point), without a floating-point warning. Ericson's regions rest on cross
    terms that are rounding noise there: it was up to 2.5 off on these (and warned "invalid value
    encountered in add")."""
    import warnings

    from becos.core.geometry import closest_points_on_triangles

    rng = np.random.default_rng(0)
    a, d, points = rng.normal(size=(3, 2000, 3))
    b, c = a + 1.3 * d, a + 0.37 * d
    a[-1] = b[-1] = c[-1]  # and one point-triangle
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        closest = closest_points_on_triangles(points, a, b, c)
    t = np.clip(((points - a) * (b - a)).sum(1) / np.maximum(((b - a) ** 2).sum(1), 1e-300), 0, 1)
    expected = a + t[:, None] * (b - a)
    np.testing.assert_allclose(closest, expected, rtol=0, atol=1e-12)
