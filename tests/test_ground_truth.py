"""Ground truth through the shape network, on real TOSCA meshes and the real BeCoS annotation folder.

Errors are Princeton-style: geodesic distance on the target between the predicted vertex and the true
point, over sqrt of the target's area. Geodesics use the edge graph (an upper bound of the surface
geodesic), so the bounds asserted here are conservative.
"""

from __future__ import annotations

import numpy as np
import pytest

from becos.core.geodesics import dijkstra_to_points
from becos.core.geometry import SurfaceLocator, oriented_face_normals, surface_area
from becos.core.surface_map import compose


@pytest.fixture(scope="session")
def remeshed(tosca_dir, mesh_cache):
    """Remeshes of the same-class test shapes, each with its own vertex target."""
    from becos.build.remesh import remesh

    targets = {"cat0": 9100, "cat3": 9900, "michael0": 9300, "michael3": 9700, "horse0": 9200, "horse5": 9800}
    return {name: remesh(mesh_cache.load(tosca_dir / f"{name}.off"), target_vertices=t) for name, t in targets.items()}


TRUE_POINT_RINGS = 5
"""The reference point on Y's remesh lies in a remeshed face with a corner whose image on Y's original
(``to_original``) is within this many edge rings of the true point's nearest original vertex."""


def true_point_on_remesh(ry, oy, points, y_face, y_weights, normals):
    """The test's reference: true points on Y's original (``points``, (N, 3), in original face rows
    ``y_face`` (N,) with weights (N, 3), normals (N, 3)) -> Y's remesh ``ry``: the closest point with a
    compatible normal among the remeshed faces near it along Y's ORIGINAL surface
    (:data:`TRUE_POINT_RINGS`, by ``ry.to_original``). The plain normal-aware closest point can lie on
    a part that touches the true point's part (TOSCA horse5's tail tip against its hind leg: 0.003
    sqrt(area) away in space, 0.1 along the surface). Returns face (N,), weights (N, 3), distance (N,)."""
    from becos.core.geometry import VertexRings

    near = VertexRings(oy.faces, oy.n_vertices, TRUE_POINT_RINGS)
    true_vertex = oy.faces[y_face, np.argmax(y_weights, axis=1)]
    image_vertex = oy.faces[ry.to_original.face, np.argmax(ry.to_original.weights, axis=1)]

    def accept(rows, cand):
        corners = image_vertex[ry.mesh.faces[cand]]  # (M, K, 3) original vertices of the corners' images
        return near.near(true_vertex[rows][:, None, None], corners).any(axis=2)

    face, weights, distance, _ = SurfaceLocator(ry.mesh).closest_near(points, accept, normals)
    return face, weights, distance


@pytest.mark.parametrize("x_name, y_name", [("cat0", "cat3"), ("michael0", "michael3"), ("horse0", "horse5")])
def test_same_class_remeshed_ground_truth_is_accurate(
    x_name, y_name, tosca_network, tosca_entries, remeshed, tosca_dir, mesh_cache
):
    x, y = tosca_entries[x_name], tosca_entries[y_name]
    rx, ry = remeshed[x_name], remeshed[y_name]
    gt = tosca_network.ground_truth(x, y, x_remesh=rx, y_remesh=ry)
    predicted = gt.to_vertex_indices(ry.mesh.faces)
    assert len(predicted) == rx.mesh.n_vertices
    assert (predicted >= 0).all() and predicted.max() < ry.mesh.n_vertices

    # the true point: remeshed-X vertex -> its point on X (face, weights) -> the same barycentric
    # point on Y (same vertex order; X's face triple, since winding may differ) -> Y's remeshed surface
    ox = mesh_cache.load(tosca_dir / f"{x_name}.off")
    oy = mesh_cache.load(tosca_dir / f"{y_name}.off")
    to_x = rx.to_original
    true_on_y = np.einsum("nk,nkd->nd", to_x.weights, oy.vertices[ox.faces[to_x.face]])
    true_normals = oriented_face_normals(oy)[to_x.face]
    true_face, true_weights, off_surface = true_point_on_remesh(
        ry, oy, true_on_y, to_x.face, to_x.weights, true_normals
    )
    errors = dijkstra_to_points(ry.mesh, predicted, true_face, true_weights) / np.sqrt(surface_area(ry.mesh))
    print(
        f"\n{x_name}->{y_name}: mean error {errors.mean():.5f}, max {errors.max():.5f}, "
        f"true point off the remesh by at most {off_surface.max() / np.sqrt(surface_area(ry.mesh)):.2e}"
    )
    assert errors.mean() <= 0.008
    assert errors.max() <= 0.04


@pytest.mark.parametrize(
    "x_name, y_name, reversed_rows", [("michael0", "michael3", 1594), ("horse5", "horse0", 108), ("cat0", "cat3", 0)]
)
def test_same_class_ground_truth_onto_an_original_pose_is_the_identity_transplant(
    x_name, y_name, reversed_rows, tosca_network, tosca_entries, remeshed, tosca_dir, mesh_cache
):
    """Poses of a class share vertex i, but michael0 and horse5 wind some faces the other way (real
    TOSCA data). The ground truth of a remeshed X vertex on Y's original mesh must be its point on X
    carried over by vertex identity: the same vertices with the same weights (permuted into Y's
    column order where the winding differs), not a projection."""
    import scipy.sparse as sp

    x, y = tosca_entries[x_name], tosca_entries[y_name]
    ox = mesh_cache.load(tosca_dir / f"{x_name}.off")
    oy = mesh_cache.load(tosca_dir / f"{y_name}.off")
    differ = (ox.faces != oy.faces).any(axis=1)
    assert differ.sum() == reversed_rows
    assert (np.sort(ox.faces, axis=1) == np.sort(oy.faces, axis=1)).all()  # same triangles, winding aside

    to_x = remeshed[x_name].to_original
    gt = tosca_network.ground_truth(x, y, x_remesh=remeshed[x_name])

    def vertex_weights(face, weights, faces):
        rows = np.repeat(np.arange(len(face)), 3)
        return sp.csr_matrix((weights.ravel(), (rows, faces[face].ravel())), shape=(len(face), ox.n_vertices))

    assert gt.matched.all()
    diff = abs(vertex_weights(gt.face, gt.weights, oy.faces) - vertex_weights(to_x.face, to_x.weights, ox.faces))
    assert diff.max() <= 1e-12
    assert np.nanmax(gt.distance) == np.nanmax(to_x.distance)  # no projection added on the way


def cycle_error(tosca_network, x, y, mx, my) -> np.ndarray:
    """X vertex -> Y surface -> X surface, distance to where it started, over sqrt(area of X)."""
    gt_xy = tosca_network.ground_truth(x, y)
    gt_yx = tosca_network.ground_truth(y, x)
    back = compose(gt_xy, my.faces, gt_yx, mx)
    matched = back.matched
    start = np.flatnonzero(matched)
    # geodesic from the start vertex to the returned point
    d = dijkstra_to_points(mx, start, back.face[matched], back.weights[matched])
    return d / np.sqrt(surface_area(mx))


@pytest.mark.parametrize(
    "x_name, y_name, via, missing_range",
    [
        ("cat3", "horse5", ["tosca_cat0", "tosca_dog0", "tosca_horse0"], (0.0, 0.10)),
        ("wolf1", "cat2", ["tosca_wolf0", "tosca_dog0", "tosca_cat0"], (0.0, 0.10)),
        ("michael4", "victoria2", ["tosca_michael0", "faust_tr_reg_000", "tosca_victoria0"], (0.0, 0.10)),
        ("centaur1", "horse7", ["tosca_centaur0", "tosca_horse0"], (0.55, 0.70)),
    ],
)
def test_cross_class_paths(x_name, y_name, via, missing_range, tosca_network, tosca_entries, tosca_dir, mesh_cache):
    x, y = tosca_entries[x_name], tosca_entries[y_name]
    nodes = [s.node for s in tosca_network.surface_path(x, y) if s.node is not None]
    assert nodes == via
    mx = mesh_cache.load(tosca_dir / f"{x_name}.off")
    my = mesh_cache.load(tosca_dir / f"{y_name}.off")
    gt = tosca_network.ground_truth(x, y)
    idx = gt.to_vertex_indices(my.faces)
    assert len(gt) == mx.n_vertices
    assert idx.max() < my.n_vertices and idx.min() >= -1
    assert ((idx == -1) == ~gt.matched).all()
    lo, hi = missing_range
    assert lo <= gt.missing_fraction <= hi, gt.missing_fraction
    scale = np.sqrt(surface_area(my))
    projection = np.nanmax(gt.distance) / scale
    errors = cycle_error(tosca_network, x, y, mx, my)
    print(
        f"\n{x_name}->{y_name} via {'->'.join(via)}: missing {gt.missing_fraction:.3f}, largest projection "
        f"{projection:.4f} (x sqrt area), cycle error mean {errors.mean():.4f} median {np.median(errors):.4f} "
        f"over {len(errors)} vertices"
    )
    assert projection < 0.1
    assert np.median(errors) < 0.05


def test_centaur_missing_part_is_the_human_torso(tosca_network, tosca_entries, tosca_dir, mesh_cache):
    """The centaur's vertices without a horse counterpart are its upper (human) body: high up."""
    x, y = tosca_entries["centaur0"], tosca_entries["horse0"]
    gt = tosca_network.ground_truth(x, y)
    mx = mesh_cache.load(tosca_dir / "centaur0.off")
    up = mx.vertices[:, 2]  # TOSCA files are z-up
    assert up[~gt.matched].mean() > up[gt.matched].mean()
    assert 0.55 < gt.missing_fraction < 0.70  # reference facts: about 63 % of the centaur is missing


def test_identity_path_is_exact(tosca_network, tosca_entries, tosca_dir, mesh_cache):
    gt = tosca_network.ground_truth(tosca_entries["cat1"], tosca_entries["cat4"])
    faces = mesh_cache.load(tosca_dir / "cat4.off").faces
    assert (gt.to_vertex_indices(faces) == np.arange(len(gt))).all()


def test_wrong_vertex_count_in_a_class_is_an_error(tosca_network, tosca_entries, tmp_path, tosca_dir):
    from becos.build.network import ShapeNetwork
    from becos.errors import BecosError

    def meshes(dataset, name):
        from becos.core.mesh import TriMesh, read_mesh

        mesh = read_mesh(tosca_dir / f"{name}.off")
        if name == "cat3":  # a shape whose file lost its last vertex
            keep = (mesh.faces < mesh.n_vertices - 1).all(axis=1)
            return TriMesh(mesh.vertices[:-1], mesh.faces[keep])
        return mesh

    broken = ShapeNetwork(tosca_network.annotations, meshes)
    with pytest.raises(BecosError, match="cat3.*share one triangulation"):
        broken.ground_truth(tosca_entries["cat3"], tosca_entries["cat1"])


def test_shared_path_tail_leaves_each_pair_unchanged(annotations, tosca_entries, remeshed, tosca_dir, mesh_cache):
    """Two cats onto one remeshed horse share the composed tail of their paths (cat0's template ->
    dog0 -> horse0 -> remeshed horse0, :meth:`ShapeNetwork._tail`): composed once, and each pair's
    ground truth is bit for bit what a job computing that pair alone gets."""
    from becos.build.network import ShapeNetwork

    def meshes(dataset, name):
        path = tosca_dir / f"{name}.off"
        return mesh_cache.load(path) if dataset == "tosca" and path.is_file() else None

    x0, x3, y = tosca_entries["cat0"], tosca_entries["cat3"], tosca_entries["horse0"]
    ry = remeshed["horse0"]
    shared = ShapeNetwork(annotations, meshes)
    first = shared.ground_truth(x0, y, x_remesh=remeshed["cat0"], y_remesh=ry)
    second = shared.ground_truth(x3, y, x_remesh=remeshed["cat3"], y_remesh=ry)
    assert len(shared._tails) == 1
    for x, got in ((x0, first), (x3, second)):
        alone = ShapeNetwork(annotations, meshes).ground_truth(x, y, x_remesh=remeshed[x.name], y_remesh=ry)
        for a, b in ((got.face, alone.face), (got.weights, alone.weights), (got.distance, alone.distance)):
            assert a.tobytes() == b.tobytes()
    shared.forget(ry.mesh)
    assert not shared._tails
