"""Rigid Procrustes alignment: exact recovery, masking of unmatched pairs, reflection fix, real meshes."""

from __future__ import annotations

import numpy as np
import pytest

from becos.build.partiality import align_to
from becos.core.align import RigidTransform, procrustes
from becos.core.mesh import TriMesh
from becos.core.surface_map import SurfaceMap


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


@pytest.fixture
def motion():
    rng = np.random.default_rng(11)
    source = rng.normal(size=(400, 3)) * [1.0, 2.0, 0.5]
    truth = RigidTransform(_random_rotation(rng), rng.normal(size=3) * 5)
    return rng, source, truth


def test_recovers_known_motion(motion):
    _, source, truth = motion
    target = source @ truth.rotation.T + truth.translation  # documented convention
    fit = procrustes(source, target)
    np.testing.assert_allclose(fit.rotation, truth.rotation, atol=1e-9)
    np.testing.assert_allclose(fit.translation, truth.translation, atol=1e-9)
    np.testing.assert_allclose(fit.apply(source), target, atol=1e-9)
    assert np.linalg.det(fit.rotation) == pytest.approx(1.0)


def test_masked_garbage_is_ignored(motion):
    rng, source, truth = motion
    target = truth.apply(source)
    mask = rng.random(len(source)) >= 0.4  # ~40 % masked
    assert 0.35 < 1 - mask.mean() < 0.45
    garbage_target = target.copy()
    garbage_target[~mask] = rng.normal(size=((~mask).sum(), 3)) * 1e3
    garbage_target[np.flatnonzero(~mask)[:10]] = np.nan  # like -1 ground-truth positions
    garbage_source = source.copy()
    garbage_source[np.flatnonzero(~mask)[10:20]] = np.inf
    fit = procrustes(garbage_source, garbage_target, mask=mask)
    np.testing.assert_allclose(fit.rotation, truth.rotation, atol=1e-9)
    np.testing.assert_allclose(fit.translation, truth.translation, atol=1e-9)
    # the same garbage breaks the fit when it is not masked (finite part only)
    finite = np.isfinite(garbage_target).all(axis=1) & np.isfinite(garbage_source).all(axis=1)
    broken = procrustes(garbage_source, garbage_target, mask=finite)
    assert np.abs(broken.translation - truth.translation).max() > 1.0
    with pytest.raises(ValueError):
        procrustes(garbage_source, garbage_target)  # NaN reaches the sums


def test_inverse_and_composition(motion):
    rng, source, truth = motion
    back = truth.inverse()
    np.testing.assert_allclose(back.apply(truth.apply(source)), source, atol=1e-12)
    other = RigidTransform(_random_rotation(rng), rng.normal(size=3))
    np.testing.assert_allclose(truth.then(other).apply(source), other.apply(truth.apply(source)), atol=1e-12)
    m = truth.as_matrix()
    np.testing.assert_allclose((m @ np.c_[source, np.ones(len(source))].T).T[:, :3], truth.apply(source), atol=1e-12)


def test_reflection_is_fixed(motion):
    _, source, _ = motion
    mirrored = source * [-1.0, 1.0, 1.0]
    fit = procrustes(source, mirrored)
    assert np.linalg.det(fit.rotation) == pytest.approx(1.0)
    np.testing.assert_allclose(fit.rotation @ fit.rotation.T, np.eye(3), atol=1e-12)
    # a reflection would fit exactly; the proper rotation cannot
    assert np.abs(fit.apply(source) - mirrored).max() > 0.1


def test_weights_and_too_few_pairs(motion):
    rng, source, truth = motion
    target = truth.apply(source)
    noisy = target.copy()
    noisy[:50] += rng.normal(size=(50, 3))
    weights = np.ones(len(source))
    weights[:50] = 0.0
    fit = procrustes(source, noisy, weights=weights)
    np.testing.assert_allclose(fit.rotation, truth.rotation, atol=1e-9)
    with pytest.raises(ValueError):
        procrustes(source[:2], target[:2])
    with pytest.raises(ValueError):
        procrustes(source, target, mask=np.zeros(len(source), bool))


def test_align_to_recovers_motion_of_a_tosca_mesh(tosca_dir, mesh_cache):
    """Y = a rigidly moved copy of wolf0 with 30 % of the ground truth set to -1 (garbage positions)."""
    x = mesh_cache.load(tosca_dir / "wolf0.off")
    rng = np.random.default_rng(5)
    truth = RigidTransform(_random_rotation(rng), rng.normal(size=3) * 50)
    y = TriMesh(truth.apply(x.vertices), x.faces)
    gt = SurfaceMap.identity(x.faces, x.n_vertices)
    dropped = rng.random(x.n_vertices) < 0.3
    gt = SurfaceMap(np.where(dropped, -1, gt.face), np.where(dropped[:, None], 0.0, gt.weights))
    fit = align_to(x, y, gt)  # moves Y onto X: the inverse motion
    np.testing.assert_allclose(fit.rotation, truth.rotation.T, atol=1e-9)
    np.testing.assert_allclose(fit.apply(y.vertices), x.vertices, atol=1e-8)
