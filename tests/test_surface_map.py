"""Surface maps: vertex form, composition rules, projection, on hand-built and real TOSCA meshes."""

import numpy as np
import pytest

from becos.core.geometry import SurfaceLocator
from becos.core.mesh import TriMesh, edge_neighbours, edge_neighbours_by_part
from becos.core.surface_map import SurfaceMap, VertexRounding, compose, compose_path


def grid(n: int = 6, z: float = 0.0) -> TriMesh:
    """An n x n vertex grid in the plane z, two triangles per cell."""
    xs, ys = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    vertices = np.stack([xs.ravel(), ys.ravel(), np.full(n * n, z)], axis=1)
    i = np.arange(n - 1)
    a = (i[:, None] * n + i[None, :]).ravel()
    faces = np.concatenate([np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)])
    return TriMesh(vertices, faces)


def test_vertex_form_round_trip():
    mesh = grid()
    idx = np.array([0, 5, -1, 35, 17])
    m = SurfaceMap.from_vertex_indices(idx, mesh.faces)
    assert (m.to_vertex_indices(mesh.faces) == idx).all()
    assert np.allclose(m.positions(mesh)[[0, 1, 3, 4]], mesh.vertices[idx[[0, 1, 3, 4]]])
    assert np.isnan(m.positions(mesh)[2]).all()
    assert m.missing_fraction == pytest.approx(0.2)


def test_edge_neighbours_pair_each_inner_edge_and_mark_boundaries():
    mesh = grid(4)
    neighbour, far = edge_neighbours(mesh.faces)
    f = mesh.faces
    for face, k in zip(*np.nonzero(far >= 0)):
        a, b = f[face, k], f[face, (k + 1) % 3]
        other = np.flatnonzero((f == a).any(1) & (f == b).any(1) & (np.arange(len(f)) != face))
        assert len(other) == 1 and neighbour[face, k] == other[0]
        assert far[face, k] in f[other[0]] and far[face, k] not in (a, b)
    n_edges = len({tuple(sorted(e)) for e in f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2).tolist()})
    n_boundary = 4 * 3  # the 4 x 4 grid's outline
    assert (far >= 0).sum() == 2 * (n_edges - n_boundary) and (far < 0).sum() == n_boundary
    assert ((far < 0) == (neighbour < 0)).all()


def test_edge_neighbours_are_the_same_by_either_sort_and_part_by_part(tosca_dir, mesh_cache):
    # cat0 (~28k vertices) sorts by two 16-bit radix passes, the same faces numbered past 65,536 by
    # one int64 argsort; a non-manifold edge (a face used three times) is -1 either way
    cat = mesh_cache.load(tosca_dir / "cat0.off").faces
    faces = np.concatenate([cat, cat[:1], cat[:1]])
    neighbour, far = edge_neighbours(faces)
    shifted = edge_neighbours(faces + 70_000)
    assert np.array_equal(shifted[0], neighbour) and np.array_equal(shifted[1] - 70_000 * (far >= 0), far)
    assert (neighbour[0] < 0).all() and (neighbour >= 0).sum() > 2.9 * len(cat)
    # meshes stacked as a store block stacks them: part by part gives the whole stack's result
    michael = mesh_cache.load(tosca_dir / "michael0.off")
    parts = [faces, michael.faces, cat[:5000]]
    n_vertices = [int(p.max()) + 1 for p in parts]
    vertex_offsets = np.concatenate([[0], np.cumsum(n_vertices)])
    face_offsets = np.concatenate([[0], np.cumsum([len(p) for p in parts])])
    stack = np.concatenate([p + start for p, start in zip(parts, vertex_offsets[:-1])])
    by_part = edge_neighbours_by_part(stack, face_offsets, vertex_offsets)
    whole = edge_neighbours(stack)
    assert np.array_equal(by_part[0], whole[0]) and np.array_equal(by_part[1], whole[1])


def test_rounding_distances_are_along_the_surface():
    # flat: unfolding changes nothing, so every finite distance is the straight line in 3D
    mesh = grid(5)
    rng = np.random.default_rng(0)
    face = rng.integers(0, len(mesh.faces), 200)
    weights = rng.dirichlet(np.ones(3), 200)
    cand, along = VertexRounding(mesh.vertices, mesh.faces).candidates(face, weights)
    point = np.einsum("nk,nkd->nd", weights, mesh.vertices[mesh.faces[face]])
    chord = np.linalg.norm(mesh.vertices[cand] - point[:, None], axis=2)
    finite = np.isfinite(along)
    assert finite[:, :3].all() and finite[:, 3:].any()
    # the per-face data of the points' faces alone (the validator's way): the same candidates and distances
    some = VertexRounding(mesh.vertices, mesh.faces, only=np.unique(face)).candidates(face, weights)
    assert np.array_equal(some[0], cand) and np.array_equal(some[1], along)
    np.testing.assert_allclose(along[finite], chord[finite], rtol=1e-12, atol=1e-12)
    # a large face beside a small one: the neighbour's far corner is nearer than every corner
    big = TriMesh(np.array([[0, 0, 0], [4, 0, 0], [2, 4, 0], [2, -0.5, 0]], float), np.array([[0, 1, 2], [1, 0, 3]]))
    m = SurfaceMap(np.array([0]), np.array([[0.49, 0.49, 0.02]]))
    assert m.to_nearest_corners(big.vertices, big.faces)[0] in (0, 1)
    assert m.to_nearest_vertices(big.vertices, big.faces)[0] == 3

    # a thin fold: the neighbour folded back over the face. Its far corner D is 0.05 above the point in
    # 3D, but along the surface the path runs over the edge y = 0, 1.8 away: the face's corner C (0.3) wins
    fold = TriMesh(
        np.array([[0, 0, 0], [2, 0, 0], [1, 1.2, 0], [1, 0.9, 0.05]], float), np.array([[0, 1, 2], [1, 0, 3]])
    )
    m = SurfaceMap(np.array([0]), np.array([[0.125, 0.125, 0.75]]))  # (1, 0.9, 0)
    point = m.positions(fold)[0]
    assert np.linalg.norm(fold.vertices - point, axis=1).argmin() == 3  # nearest in 3D: across the fold
    _, along = VertexRounding(fold.vertices, fold.faces).candidates(m.face, m.weights)
    assert along[0, 3] > 1.5  # edge 0 (corners 0, 1) has D across it
    assert m.to_nearest_vertices(fold.vertices, fold.faces)[0] == 2


def test_rounding_without_the_face_table_gives_the_same_values_in_slices(tosca_dir, mesh_cache):
    # the validator's way (candidates_once, points handled a slice at a time) against the builder's
    # (a per-face table, one query): bit for bit, over more points than one slice on a real surface
    from becos.core.surface_map import _POINTS_AT_ONCE

    cat = mesh_cache.load(tosca_dir / "cat0.off")
    rng = np.random.default_rng(3)
    n = 2 * _POINTS_AT_ONCE + 123
    face = rng.integers(0, len(cat.faces), n)
    weights = rng.dirichlet(np.ones(3), n)
    far = edge_neighbours(cat.faces)[1]
    table = VertexRounding(cat.vertices, cat.faces).candidates(face, weights)
    once = VertexRounding.candidates_once(cat.vertices, cat.faces, far, face, weights)
    assert np.array_equal(once[0], table[0]) and np.array_equal(once[1], table[1])
    assert np.isfinite(table[1][:, 3:]).mean() > 0.3  # the far corners were measured, not all inf
    none = VertexRounding.candidates_once(cat.vertices, cat.faces, far, face[:0], weights[:0])
    assert none[0].shape == (0, 6) and none[1].shape == (0, 6)


def test_compose_with_identity_is_exact_and_needs_no_projection():
    mesh = grid()
    rng = np.random.default_rng(0)
    face = rng.integers(0, mesh.n_faces, 50)
    w = rng.dirichlet(np.ones(3), 50)
    first = SurfaceMap(face, w)
    second = SurfaceMap.identity(mesh.faces, mesh.n_vertices)
    out = compose(first, mesh.faces, second, mesh)
    assert np.allclose(out.positions(mesh), first.positions(mesh), atol=1e-12)
    assert np.nanmax(out.distance) < 1e-12


def test_missing_rule_dominant_vertex_decides_and_weights_renormalise():
    mesh = grid()
    # vertex 0 has no image; the others map to themselves
    second = SurfaceMap.from_vertex_indices(np.where(np.arange(36) == 0, -1, np.arange(36)), mesh.faces)
    f0 = 0  # face (0, 1, 7)
    first = SurfaceMap(np.array([f0, f0]), np.array([[0.6, 0.3, 0.1], [0.2, 0.5, 0.3]]))
    out = compose(first, mesh.faces, second, mesh)
    assert out.face[0] == -1  # dominant corner (vertex 0) has no image
    assert out.face[1] >= 0  # dominant corner has one: renormalise over 1 and 7
    expected = (0.5 * mesh.vertices[1] + 0.3 * mesh.vertices[7]) / 0.8
    assert np.allclose(out.positions(mesh)[1], expected, atol=1e-12)


def test_projection_onto_curved_target_records_distance():
    source = grid()
    target = grid(z=0.0)
    bent = target.vertices.copy()
    bent[:, 2] = 0.05 * (bent[:, 0] - 2.5) ** 2  # a parabolic sheet
    target = target.with_vertices(bent)
    # each source vertex -> the target vertex two columns over: combinations leave the surface
    idx = np.arange(36).reshape(6, 6)
    shifted = np.clip(idx + 2 * (idx % 6 < 4), 0, 35).ravel()
    second = SurfaceMap.from_vertex_indices(shifted, target.faces)
    first = SurfaceMap(np.arange(source.n_faces), np.full((source.n_faces, 3), 1 / 3))
    out = compose(first, source.faces, second, target)
    locator = SurfaceLocator(target)
    p = out.positions(target)
    _, _, d = locator.closest(p)
    assert np.abs(d).max() < 1e-9  # the result lies on the target
    assert np.nanmax(out.distance) > 0  # and some points had to be projected


def test_compose_path_skips_identity_hops_and_keeps_winding(tosca_dir, mesh_cache):
    # michael0 and michael3 share vertices, but 1,594 face rows are reversed (reference facts, §10)
    m0 = mesh_cache.load(tosca_dir / "michael0.off")
    m3 = mesh_cache.load(tosca_dir / "michael3.off")
    differ = (m0.faces != m3.faces).any(axis=1)
    assert differ.sum() > 1000
    rng = np.random.default_rng(1)
    face = np.flatnonzero(differ)[:500]
    w = rng.dirichlet(np.ones(3), len(face))
    first = SurfaceMap(face, w)  # points on michael0, in michael0's face order
    out = compose_path([first, None], [m0.faces], m3)  # michael0 -> michael3 is an identity hop
    truth = np.einsum("nk,nkd->nd", w, m3.vertices[m0.faces[face]])
    assert np.abs(out.positions(m3) - truth).max() < 1e-9
