"""Geodesic distances (heat method and edge-graph Dijkstra) on decimated real TOSCA meshes."""

from __future__ import annotations

import numpy as np
import pytest

from becos.core.geodesics import GeodesicDistances, dijkstra_to_points, edge_graph, geodesics_for
from becos.core.geometry import surface_area
from becos.core.mesh import TriMesh

SHAPES = ["cat0", "horse0", "michael0"]


def decimate(mesh: TriMesh, faces: int) -> TriMesh:
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(mesh.vertices, mesh.faces))
    ms.meshing_decimation_quadric_edge_collapse(targetfacenum=faces, preservetopology=True, preserveboundary=True)
    out = ms.current_mesh()
    return TriMesh(out.vertex_matrix(), out.face_matrix())


@pytest.fixture(scope="module")
def small_tosca(tosca_dir, mesh_cache) -> dict[str, TriMesh]:
    """~8k-vertex decimations of three TOSCA shapes (original units, centimetres-ish)."""
    return {name: decimate(mesh_cache.load(tosca_dir / f"{name}.off"), 16000) for name in SHAPES}


def grid_mesh(n: int = 41, size: float = 2.0) -> TriMesh:
    """A flat n x n square grid in the z=0 plane, each square cut along one diagonal."""
    xs = np.linspace(0.0, size, n)
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    vertices = np.stack([gx.ravel(), gy.ravel(), np.zeros(n * n)], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return TriMesh(vertices, faces)


@pytest.mark.parametrize("name", SHAPES)
def test_dijkstra_over_heat_ratio_on_tosca(name, small_tosca):
    mesh = small_tosca[name]
    rng = np.random.default_rng(1)
    sources = rng.choice(mesh.n_vertices, 60, replace=False)
    heat = GeodesicDistances(mesh, "heat").from_vertices(sources)
    graph = GeodesicDistances(mesh, "dijkstra").from_vertices(sources)
    scale = np.sqrt(surface_area(mesh))
    far = heat > 0.1 * scale  # pairs not too close
    ratio = graph[far] / heat[far]
    p = np.percentile(ratio, [0, 1, 50, 99, 100])
    print(
        f"\n{name} ({mesh.n_vertices} V): Dijkstra/heat over {far.sum()} pairs: min {p[0]:.3f}, "
        f"1% {p[1]:.3f}, median {p[2]:.3f}, 99% {p[3]:.3f}, max {p[4]:.3f}"
    )
    inside = np.mean((ratio >= 0.97) & (ratio <= 1.2))
    print(f"  share of pairs with a ratio in [0.97, 1.2]: {inside:.4f}")
    assert far.sum() > 0.5 * far.size
    assert (
        inside >= 0.97
    )  # measured 0.981-0.997; the tails are skinny decimated triangles (Dijkstra) and thin parts (heat)
    assert 1.0 <= p[2] <= 1.1  # the edge graph is an upper bound of the surface geodesic


@pytest.mark.parametrize("method", ["heat", "dijkstra"])
def test_zero_at_source_and_symmetric(method, small_tosca):
    mesh = small_tosca["cat0"]
    rng = np.random.default_rng(2)
    sources = rng.choice(mesh.n_vertices, 40, replace=False)
    rows = GeodesicDistances(mesh, method).from_vertices(sources)
    assert rows.shape == (40, mesh.n_vertices)
    assert np.all(rows[np.arange(40), sources] == 0.0)
    assert np.all(rows >= 0.0) and np.isfinite(rows).all()
    # every other vertex is strictly farther away than the source itself
    assert (np.sort(rows, axis=1)[:, 1] > 0).all()
    square = rows[:, sources]
    rel = np.abs(square - square.T) / np.maximum(square, square.T).clip(min=1e-12)
    off = ~np.eye(40, dtype=bool)
    print(f"\n{method}: asymmetry median {np.median(rel[off]):.4f}, max {rel[off].max():.4f}")
    if method == "dijkstra":
        np.testing.assert_allclose(square, square.T, rtol=1e-12)
    else:
        assert np.median(rel[off]) < 0.01 and rel[off].max() < 0.1


def test_heat_close_to_exact_geodesic_paths(tosca_dir, mesh_cache):
    """Against potpourri3d's edge-flip geodesic paths (locally shortest polylines on the surface), on the
    full-resolution wolf0 (4,344 vertices, consistently oriented, closed)."""
    import potpourri3d as pp3d

    mesh = mesh_cache.load(tosca_dir / "wolf0.off")
    rng = np.random.default_rng(3)
    pairs = rng.choice(mesh.n_vertices, (40, 2), replace=False)
    heat = GeodesicDistances(mesh, "heat").between(pairs[:, 0], *vertex_points(mesh, pairs[:, 1]))
    flip = pp3d.EdgeFlipGeodesicSolver(mesh.vertices, mesh.faces)
    exact = np.array(
        [np.linalg.norm(np.diff(flip.find_geodesic_path(int(a), int(b)), axis=0), axis=1).sum() for a, b in pairs]
    )
    far = exact > 0.05 * np.sqrt(surface_area(mesh))  # the heat method smooths within an edge or two
    ratio = heat[far] / exact[far]
    print(
        f"\nheat / edge-flip geodesic over {far.sum()} pairs: min, median, max "
        f"{np.percentile(ratio, [0, 50, 100]).round(4)}"
    )
    assert far.sum() >= 30
    assert 0.98 <= np.median(ratio) <= 1.02
    # an edge-flip path is only locally shortest (an upper bound), so heat may fall a little below it
    assert ratio.min() > 0.9 and ratio.max() < 1.07


def vertex_points(mesh: TriMesh, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(face, one-hot weights) of each vertex as a surface point."""
    face_of = np.empty(mesh.n_vertices, dtype=np.int64)
    corner_of = np.empty(mesh.n_vertices, dtype=np.int64)
    face_of[mesh.faces.ravel()] = np.repeat(np.arange(mesh.n_faces), 3)
    corner_of[mesh.faces.ravel()] = np.tile(np.arange(3), mesh.n_faces)
    weights = np.zeros((len(vertices), 3))
    weights[np.arange(len(vertices)), corner_of[vertices]] = 1.0
    return face_of[vertices], weights


@pytest.mark.parametrize("method", ["heat", "dijkstra"])
def test_between_interpolates_the_source_field(method, small_tosca):
    mesh = small_tosca["horse0"]
    rng = np.random.default_rng(4)
    n = 500
    sources = rng.choice(mesh.n_vertices, 30)[rng.integers(0, 30, n)]  # repeated sources
    geo = GeodesicDistances(mesh, method)
    # at vertices: the row entry itself
    targets = rng.choice(mesh.n_vertices, n)
    face, weights = vertex_points(mesh, targets)
    rows = geo.from_vertices(sources)
    np.testing.assert_allclose(geo.between(sources, face, weights), rows[np.arange(n), targets], rtol=1e-12)
    # inside faces: the barycentric combination of the corner values
    face = rng.integers(0, mesh.n_faces, n)
    weights = rng.dirichlet(np.ones(3), n)
    expected = (rows[np.arange(n)[:, None], mesh.faces[face]] * weights).sum(axis=1)
    np.testing.assert_allclose(geo.between(sources, face, weights), expected, rtol=1e-12)
    # without cached rows (Dijkstra then searches only as far as each pair needs): the same values
    fresh = GeodesicDistances(mesh, method, cache_bytes=0)
    np.testing.assert_allclose(fresh.between(sources, face, weights), expected, rtol=1e-12)


def test_dijkstra_to_points_is_exact_and_bounded(small_tosca):
    mesh = small_tosca["cat0"]
    rng = np.random.default_rng(5)
    n = 400
    sources = rng.choice(mesh.n_vertices, 50)[rng.integers(0, 50, n)]
    face = rng.integers(0, mesh.n_faces, n)
    weights = rng.dirichlet(np.ones(3), n)
    # half the targets right next to the source, half anywhere on the shape
    near = np.arange(n) < n // 2
    incident = np.flatnonzero(np.isin(mesh.faces, sources[near]).any(axis=1))
    for i in np.flatnonzero(near):
        face[i] = incident[(mesh.faces[incident] == sources[i]).any(axis=1)][0]
    rows = GeodesicDistances(mesh, "dijkstra").from_vertices(sources)
    corners = mesh.faces[face]
    points = np.einsum("nk,nkd->nd", weights, mesh.vertices[corners])
    brute = (
        rows[np.arange(n)[:, None], corners] + np.linalg.norm(mesh.vertices[corners] - points[:, None], axis=2)
    ).min(axis=1)

    exact = dijkstra_to_points(mesh, sources, face, weights)
    np.testing.assert_allclose(exact, brute, rtol=1e-12)
    # never shorter than the straight line, at least for the far pairs
    assert (exact >= np.linalg.norm(mesh.vertices[sources] - points, axis=1) - 1e-9).all()

    limit = float(np.median(brute))
    bounded = dijkstra_to_points(mesh, sources, face, weights, limit=limit, graph=edge_graph(mesh))
    inside = brute <= limit
    assert 0 < inside.sum() < n
    np.testing.assert_allclose(bounded[inside], brute[inside], rtol=1e-12)
    assert np.isinf(bounded[~inside]).all()


def test_flat_grid_distances():
    """On a plane the geodesic is the straight line, and the heat method is close to it. Dijkstra on a
    grid whose squares are all cut along the (1, 1) diagonal follows axis and diagonal steps exactly:
    for a displacement (dx, dy) it is max + (sqrt 2 - 1) min of |dx|, |dy| when dx, dy share a sign,
    |dx| + |dy| otherwise."""
    mesh = grid_mesh()
    centre = int(np.argmin(np.linalg.norm(mesh.vertices - [1.0, 1.0, 0.0], axis=1)))
    euclid = np.linalg.norm(mesh.vertices - mesh.vertices[centre], axis=1)
    ring = (euclid > 0.3) & (euclid < 0.9)
    heat = GeodesicDistances(mesh, "heat").from_vertices([centre])[0]
    graph = GeodesicDistances(mesh, "dijkstra").from_vertices([centre])[0]
    heat_ratio = heat[ring] / euclid[ring]
    graph_ratio = graph[ring] / euclid[ring]
    print(
        f"\nflat grid: heat/euclid {heat_ratio.min():.4f}..{heat_ratio.max():.4f}, "
        f"dijkstra/euclid {graph_ratio.min():.4f}..{graph_ratio.max():.4f}"
    )
    assert np.abs(heat_ratio - 1).max() < 0.05
    dx, dy = (mesh.vertices[:, :2] - mesh.vertices[centre, :2]).T
    lo, hi = np.minimum(abs(dx), abs(dy)), np.maximum(abs(dx), abs(dy))
    expected = np.where(dx * dy >= 0, hi + (np.sqrt(2) - 1) * lo, abs(dx) + abs(dy))
    np.testing.assert_allclose(graph, expected, rtol=1e-9, atol=1e-12)


def test_rows_are_cached_per_mesh(small_tosca):
    mesh = small_tosca["cat0"]
    geo = geodesics_for(mesh, "dijkstra")
    assert geodesics_for(mesh, "dijkstra") is geo
    assert geodesics_for(mesh, "heat") is not geo
    before = geo.n_computed
    first = geo.from_vertices([3, 7, 3])
    assert geo.n_computed == before + 2  # each unique source once
    again = geo.from_vertices([7, 3])
    assert geo.n_computed == before + 2
    np.testing.assert_array_equal(again, first[[1, 0]])
    uncached = GeodesicDistances(mesh, "dijkstra", cache_bytes=0)
    uncached.from_vertices([3])
    uncached.from_vertices([3])
    assert uncached.n_computed == 2


def test_bad_arguments(small_tosca):
    mesh = small_tosca["cat0"]
    with pytest.raises(ValueError, match="unknown geodesic method"):
        GeodesicDistances(mesh, "exact")
    geo = GeodesicDistances(mesh, "dijkstra")
    with pytest.raises(IndexError):
        geo.from_vertices([mesh.n_vertices])
    with pytest.raises(IndexError):
        geo.between([0], [-1], [[1.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match="equally long"):
        dijkstra_to_points(mesh, [0, 1], [0], [[1.0, 0.0, 0.0]])


@pytest.mark.parametrize("method", ["heat", "dijkstra"])
def test_point_to_vertices_reads_rows_from_the_points_side(method, small_tosca):
    """Σ_k w_k d(corner_k, target): equal to :meth:`between` from the target's side where distances are
    symmetric (Dijkstra exactly; heat within its small asymmetry), with rows only for corners that
    differ from their targets."""
    mesh = small_tosca["horse0"]
    rng = np.random.default_rng(6)
    n = 300
    face = rng.integers(0, mesh.n_faces, n)
    weights = rng.dirichlet(np.ones(3), n)
    targets = np.stack([rng.integers(0, mesh.n_vertices, n), rng.integers(0, mesh.n_vertices, n)], axis=1)
    targets[:10, 1] = -1
    geo = GeodesicDistances(mesh, method)
    out = geo.point_to_vertices(face, weights, targets)
    assert out.shape == (n, 2) and np.isnan(out[:10, 1]).all() and np.isfinite(out[10:]).all()
    rows = geo.from_vertices(mesh.faces[face].ravel()).reshape(n, 3, -1)
    expected = np.einsum(
        "nk,nkm->nm", weights, rows[np.arange(n)[:, None], :, np.maximum(targets, 0)].transpose(0, 2, 1)
    )
    np.testing.assert_allclose(out[:, 0], expected[:, 0], rtol=1e-12)
    from_target = GeodesicDistances(mesh, method).between(targets[:, 0], face, weights)
    rel = np.abs(out[:, 0] - from_target) / from_target
    if method == "dijkstra":
        np.testing.assert_allclose(out[:, 0], from_target, rtol=1e-12)
    else:
        assert np.median(rel) < 0.01
    # one-hot points whose vertex is the target: zero, and no row computed
    fresh = GeodesicDistances(mesh, method)
    same = mesh.faces[face, 0]
    one_hot = np.zeros((n, 3))
    one_hot[:, 0] = 1.0
    assert np.all(fresh.point_to_vertices(face, one_hot, same) == 0.0) and fresh.n_computed == 0
    moved = same.copy()
    moved[:7] = mesh.faces[face[:7], 1]
    d = fresh.point_to_vertices(face, one_hot, moved)
    assert fresh.n_computed == len(np.unique(same[:7])) and (d[:7] > 0).all() and (d[7:] == 0).all()


def test_geodesics_cache_per_shape(small_tosca):
    from becos.core.geodesics import GeodesicsCache, shape_key

    mesh = small_tosca["cat0"]
    angle = 1.1
    rot = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    moved = TriMesh(mesh.vertices @ rot + [3.0, -1.0, 2.0], mesh.faces)
    # a rigid motion keeps the key; a rescaled copy or another shape does not
    assert shape_key(moved, "tosca", "cat0") == shape_key(mesh, "tosca", "cat0")
    assert shape_key(TriMesh(mesh.vertices * 2.0, mesh.faces), "tosca", "cat0") != shape_key(mesh, "tosca", "cat0")
    cache = GeodesicsCache("dijkstra", max_shapes=2)
    a = cache.get(shape_key(mesh, "cat0"), mesh)
    assert cache.get(shape_key(moved, "cat0"), moved) is a and cache.hits == 1
    b = cache.get(shape_key(small_tosca["horse0"], "horse0"), small_tosca["horse0"])
    c = cache.get(shape_key(small_tosca["michael0"], "michael0"), small_tosca["michael0"])
    assert len({id(a), id(b), id(c)}) == 3
    assert cache.get(shape_key(mesh, "cat0"), mesh) is not a  # evicted: least recently used first
    with pytest.raises(ValueError, match="unknown geodesic method"):
        GeodesicsCache("exact")
