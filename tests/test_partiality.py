"""Partial shapes on remeshed TOSCA pairs: exact bookkeeping, overlap rule, retries, reproducibility.

Pairs are two poses of one TOSCA class (same vertex order), remeshed to ~10k vertices; the ground
truth between the remeshes is honest: remesh A -> points on A, identity to B, B -> remesh B
(``becos.build.remesh`` when available, else a pymeshlab decimation whose maps are closest points).
Overlaps are checked against a recomputation from the saved *positions and faces* only.
"""

from __future__ import annotations

import numpy as np
import pytest

from becos.build.cameras import REGIMES, camera_angles
from becos.build.partiality import Partial, Scanner, cast_p2f, cast_p2p, cut, overlap_mask, partial_map, whole
from becos.core.align import RigidTransform
from becos.core.mesh import TriMesh, edge_neighbours
from becos.core.surface_map import SurfaceMap, VertexRounding, compose_path
from becos.seeding import rng_for

TARGET_VERTICES = 10_000
_CACHE: dict = {}


def y_up(mesh: TriMesh) -> TriMesh:
    """TOSCA's raw frame is z-up; the reference multiplies by its scale 0.0095 and rotates 90° about x."""
    v = mesh.vertices * 0.0095
    return TriMesh(np.c_[v[:, 0], v[:, 2], -v[:, 1]], mesh.faces)


def remeshed(mesh: TriMesh) -> tuple[TriMesh, SurfaceMap, SurfaceMap]:
    """(remeshed mesh, remeshed -> original map, original -> remeshed map)."""
    from becos.build.remesh import remesh

    r = remesh(mesh, target_vertices=TARGET_VERTICES)
    return r.mesh, r.to_original, r.from_original


def remeshed_pair(tosca_dir, mesh_cache, a: str, b: str):
    """(x, y, gt_xy, gt_yx) for two poses of one TOSCA class, remeshed; cached per session."""
    key = (a, b)
    if key not in _CACHE:
        A, B = (y_up(mesh_cache.load(tosca_dir / f"{n}.off")) for n in (a, b))
        (x, x_to, x_from), (y, y_to, y_from) = remeshed(A), remeshed(B)
        gt_xy = compose_path([x_to, None, y_from], [A.faces, B.faces], y)
        gt_yx = compose_path([y_to, None, x_from], [B.faces, A.faces], x)
        _CACHE[key] = (x, y, gt_xy, gt_yx)
    return _CACHE[key]


@pytest.fixture(scope="module")
def cat_pair(tosca_dir, mesh_cache):
    return remeshed_pair(tosca_dir, mesh_cache, "cat0", "cat3")


@pytest.fixture(scope="module")
def horse_pair(tosca_dir, mesh_cache):
    return remeshed_pair(tosca_dir, mesh_cache, "horse0", "horse5")


# ---------------------------------------------------------------- independent recomputations


def _position_index(points: np.ndarray) -> dict:
    return {p.tobytes(): i for i, p in enumerate(np.ascontiguousarray(points))}


def brute_force_mask(full_x: TriMesh, gt_xy: SurfaceMap, full_y: TriMesh, px_mesh: TriMesh, py_mesh: TriMesh):
    """Overlap mask of X̂'s vertices recomputed from positions and faces only (no bookkeeping arrays):
    each partial X vertex is found in full X by its exact position; its ground-truth face of full Y
    is looked up as a triangle of positions among Ŷ's triangles."""
    full_index = _position_index(full_x.vertices)
    rows = np.array([full_index[p.tobytes()] for p in np.ascontiguousarray(px_mesh.vertices)])
    tri_key = lambda t: b"".join(sorted(r.tobytes() for r in t))  # noqa: E731
    kept = {tri_key(t) for t in py_mesh.vertices[py_mesh.faces]}
    out = np.zeros(len(rows), dtype=bool)
    for i, r in enumerate(rows):
        f = gt_xy.face[r]
        out[i] = f >= 0 and tri_key(full_y.vertices[full_y.faces[f]]) in kept
    return out


def n_components(mesh: TriMesh) -> int:
    import trimesh

    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    return len(trimesh.graph.connected_components(tm.face_adjacency, nodes=np.arange(len(mesh.faces)), min_len=1))


def check_partial(full: TriMesh, p: Partial):
    assert p.partial_to_full.dtype == np.int64 and p.full_to_partial.dtype == np.int64
    assert (np.diff(p.partial_to_full) > 0).all()
    assert p.partial_to_full.min() >= 0 and p.partial_to_full.max() < full.n_vertices
    assert (np.diff(p.face_ids) > 0).all() and p.face_ids.max() < full.n_faces
    np.testing.assert_array_equal(p.full_to_partial[p.partial_to_full], np.arange(len(p.partial_to_full)))
    assert (p.full_to_partial >= 0).sum() == len(p.partial_to_full)
    assert p.mesh.vertices.dtype == np.float64
    np.testing.assert_array_equal(p.mesh.vertices, full.vertices[p.partial_to_full])  # exact copies
    np.testing.assert_array_equal(p.partial_to_full[p.mesh.faces], full.faces[p.face_ids])  # same corners, same order
    np.testing.assert_array_equal(np.flatnonzero(p.kept_faces), p.face_ids)
    assert np.unique(p.mesh.faces).size == p.mesh.n_vertices  # no unused vertex


# ---------------------------------------------------------------- tests


def test_cut_is_exact_on_a_random_mask(cat_pair):
    x = cat_pair[0]
    mask = np.random.default_rng(0).random(x.n_faces) < 0.3
    p = cut(x, mask)
    check_partial(x, p)
    assert p.mesh.n_faces == mask.sum()
    assert (p.full_to_partial_face[p.face_ids] == np.arange(p.mesh.n_faces)).all()
    assert (p.full_to_partial_face[~mask] == -1).all()
    w = whole(x)
    np.testing.assert_array_equal(w.partial_to_full, np.arange(x.n_vertices))
    np.testing.assert_array_equal(w.mesh.faces, x.faces)
    # rounding a partial's points through the full mesh's VertexRounding (its kept faces) is rounding
    # on the partial itself (a random mask: many neighbours cut away)
    rng = np.random.default_rng(1)
    points = SurfaceMap(rng.integers(0, p.mesh.n_faces, 3000), rng.dirichlet(np.ones(3), 3000))
    own = points.to_nearest_vertices(p.mesh.vertices, p.mesh.faces)
    np.testing.assert_array_equal(p.round_to_vertices(points, VertexRounding(x.vertices, x.faces)), own)
    assert (edge_neighbours(p.mesh.faces)[1] < 0).sum() > (edge_neighbours(x.faces)[1] < 0).sum()
    with pytest.raises(ValueError):
        cut(x, mask[:-1])


@pytest.mark.parametrize("pair_name", ["cat_pair", "horse_pair"])
def test_p2p_pair_is_consistent(pair_name, request):
    x, y, gt_xy, gt_yx = request.getfixturevalue(pair_name)
    for pair_id in ("a", "b"):
        r = cast_p2p(x, y, gt_xy, gt_yx, (2024, f"{pair_name}-{pair_id}"))
        px, py = r.partial_x, r.partial_y
        check_partial(x, px)
        check_partial(y, py)
        assert n_components(px.mesh) == 1 and n_components(py.mesh) == 1
        # overlap = brute force from positions/faces
        bx = brute_force_mask(x, gt_xy, y, px.mesh, py.mesh)
        by = brute_force_mask(y, gt_yx, x, py.mesh, px.mesh)
        np.testing.assert_array_equal(r.mask_x, bx)
        np.testing.assert_array_equal(r.mask_y, by)
        assert r.overlap_x == pytest.approx(bx.mean(), abs=1e-15)
        assert r.overlap_y == pytest.approx(by.mean(), abs=1e-15)
        assert r.accepted == (0.1 <= r.overlap_x <= 0.9 and 0.1 <= r.overlap_y <= 0.9)
        assert 0 <= r.try_index < r.n_tries_used <= 10
        # partial maps: -1 exactly off the mask; the points are the ground truth's points on Ŷ
        for m, mask, src, gt, dst, full_dst in (
            (r.map_xy, r.mask_x, px, gt_xy, py, y),
            (r.map_yx, r.mask_y, py, gt_yx, px, x),
        ):
            assert len(m) == src.mesh.n_vertices
            np.testing.assert_array_equal(m.face >= 0, mask)
            assert m.face.max() < dst.mesh.n_faces
            np.testing.assert_allclose(
                m.positions(dst.mesh)[mask], gt.positions(full_dst)[src.partial_to_full[mask]], atol=1e-12
            )
        # geometry, camera and masks belong together: re-scanning the stored camera gives the stored partial
        np.testing.assert_array_equal(Scanner(x).kept_faces(r.camera_x), px.kept_faces)
        np.testing.assert_array_equal(Scanner(y).kept_faces(r.camera_y), py.kept_faces)


def test_overlap_rule_with_missing_ground_truth(cat_pair):
    """-1 ground truth never counts; rows whose point leaves Ŷ's kept faces are -1 in the partial map."""
    x, y, gt_xy, gt_yx = cat_pair
    r = cast_p2p(x, y, gt_xy, gt_yx, (1, "missing"))
    head = x.vertices[:, 1] > np.quantile(x.vertices[:, 1], 0.8)  # pretend Y lacks this part
    gt_cut = SurfaceMap(np.where(head, -1, gt_xy.face), np.where(head[:, None], 0.0, gt_xy.weights))
    mask = overlap_mask(r.partial_x, gt_cut, r.partial_y)
    np.testing.assert_array_equal(mask, r.mask_x & ~head[r.partial_x.partial_to_full])
    pm = partial_map(r.partial_x, gt_cut, r.partial_y)
    np.testing.assert_array_equal(pm.face == -1, ~mask)
    assert np.isnan(pm.distance[~mask]).all() and (pm.weights[~mask] == 0).all()


def test_same_seed_same_arrays_and_pair_ids_independent(cat_pair):
    x, y, gt_xy, gt_yx = cat_pair
    a = cast_p2p(x, y, gt_xy, gt_yx, (3, "pair-17"), regime="medium")
    b = cast_p2p(x, y, gt_xy, gt_yx, (3, "pair-17"), regime="medium", scanners=(Scanner(x), Scanner(y)))
    for name in ("mask_x", "mask_y"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    for name in ("partial_to_full", "face_ids"):
        np.testing.assert_array_equal(getattr(a.partial_x, name), getattr(b.partial_x, name))
        np.testing.assert_array_equal(getattr(a.partial_y, name), getattr(b.partial_y, name))
    np.testing.assert_array_equal(a.map_xy.face, b.map_xy.face)
    np.testing.assert_array_equal(a.camera_x.position, b.camera_x.position)
    assert (a.overlap_x, a.overlap_y, a.try_index) == (b.overlap_x, b.overlap_y, b.try_index)
    c = cast_p2p(x, y, gt_xy, gt_yx, (3, "pair-18"), regime="medium")
    assert np.linalg.norm(c.drawn_cameras[0].position - a.drawn_cameras[0].position) > 1e-6
    assert not np.array_equal(c.partial_x.face_ids, a.partial_x.face_ids)


def test_kept_try_is_the_closest_to_the_range(cat_pair):
    """An unreachable range forces all tries; the kept one minimises the summed distance, recomputed try by try."""
    x, y, gt_xy, gt_yx = cat_pair
    scanners = (Scanner(x), Scanner(y))
    lo, hi = 0.97, 0.99
    r = cast_p2p(x, y, gt_xy, gt_yx, (5, "fallback"), n_tries=4, min_overlap=lo, max_overlap=hi, scanners=scanners)
    assert not r.accepted and r.n_tries_used == 4
    dist = []
    for k in range(4):
        single = cast_p2p(
            x,
            y,
            gt_xy,
            gt_yx,
            lambda _, k=k: rng_for(5, "fallback", "cameras", k),
            n_tries=1,
            min_overlap=lo,
            max_overlap=hi,
            scanners=scanners,
        )
        dist.append(
            max(0, lo - single.overlap_x)
            + max(0, single.overlap_x - hi)
            + max(0, lo - single.overlap_y)
            + max(0, single.overlap_y - hi)
        )
        if k == r.try_index:
            np.testing.assert_array_equal(single.partial_x.face_ids, r.partial_x.face_ids)
            np.testing.assert_array_equal(single.drawn_cameras[1].position, r.drawn_cameras[1].position)
    assert r.try_index == int(np.argmin(dist))
    assert r.range_distance == pytest.approx(min(dist), abs=1e-15)


def test_alignment_makes_the_scan_frame_independent(cat_pair):
    """Moving Y rigidly does not change what is cut: Y is aligned to X before the cameras are placed."""
    x, y, gt_xy, gt_yx = cat_pair
    rng = np.random.default_rng(9)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    moved = TriMesh(RigidTransform(q, [3.0, -1.0, 2.0]).apply(y.vertices), y.faces)
    a = cast_p2p(x, y, gt_xy, gt_yx, (8, "frame"))
    b = cast_p2p(x, moved, gt_xy, gt_yx, (8, "frame"))
    np.testing.assert_allclose(b.alignment.rotation, a.alignment.rotation @ q.T, atol=1e-9)
    ja = (a.partial_y.kept_faces & b.partial_y.kept_faces).sum() / (
        a.partial_y.kept_faces | b.partial_y.kept_faces
    ).sum()
    assert ja > 0.99
    assert abs(a.overlap_x - b.overlap_x) < 0.01 and abs(a.overlap_y - b.overlap_y) < 0.01


def test_drawn_cameras_respect_the_regime(cat_pair):
    x, y, gt_xy, gt_yx = cat_pair
    scanners = (Scanner(x), Scanner(y))
    for regime in ("high", "low"):
        r = cast_p2p(x, y, gt_xy, gt_yx, (4, regime), regime=regime, scanners=scanners)
        (az1, el1), (az2, el2) = (camera_angles(c) for c in r.drawn_cameras)
        d_az = abs(az1 - az2) % (2 * np.pi)
        assert min(d_az, 2 * np.pi - d_az) <= REGIMES[regime][0] + 1e-9
        assert abs(el1 - el2) <= REGIMES[regime][1] + 1e-9
        # the stored input-frame camera is the drawn one moved back: X's eye at distance scale_x from its box centre
        assert np.linalg.norm(r.camera_x.position - r.centre_x) == pytest.approx(r.scale_x)
        np.testing.assert_allclose(r.camera_x.target, r.centre_x, atol=1e-12)


def test_overlaps_fall_in_range_for_most_pairs(cat_pair, horse_pair):
    inside, shares = [], []
    for name, (x, y, gt_xy, gt_yx) in (("cat", cat_pair), ("horse", horse_pair)):
        scanners = (Scanner(x), Scanner(y))
        for k in range(15):
            r = cast_p2p(x, y, gt_xy, gt_yx, (0, f"{name}-{k}"), scanners=scanners)
            inside.append(r.accepted)
            shares.append(r.partial_x.vertex_share)
    assert np.mean(inside) >= 0.9
    assert 0.15 < np.mean(shares) < 0.6


def test_p2f(cat_pair):
    x, y, gt_xy, gt_yx = cat_pair
    r = cast_p2f(x, y, gt_xy, gt_yx, (0, "p2f-1"))
    check_partial(y, r.partial_y)
    assert n_components(r.partial_y.mesh) == 1
    np.testing.assert_array_equal(r.mask_y, gt_yx.matched[r.partial_y.partial_to_full])
    np.testing.assert_array_equal(r.mask_x, brute_force_mask(x, gt_xy, y, x, r.partial_y.mesh))
    assert r.overlap_x == pytest.approx(r.mask_x.mean())
    # Ŷ -> full X: faces are full X faces, the points are the ground truth's
    np.testing.assert_array_equal(r.map_yx.face, gt_yx.face[r.partial_y.partial_to_full])
    np.testing.assert_array_equal(r.map_xy.face >= 0, r.mask_x)
    np.testing.assert_allclose(r.map_xy.positions(r.partial_y.mesh)[r.mask_x], gt_xy.positions(y)[r.mask_x], atol=1e-12)
    np.testing.assert_array_equal(Scanner(y).kept_faces(r.camera_y), r.partial_y.kept_faces)
    again = cast_p2f(x, y, gt_xy, gt_yx, (0, "p2f-1"))
    np.testing.assert_array_equal(again.partial_y.face_ids, r.partial_y.face_ids)
    other = cast_p2f(x, y, gt_xy, gt_yx, (0, "p2f-2"))
    assert not np.array_equal(other.drawn_camera.position, r.drawn_camera.position)
