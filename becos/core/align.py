"""Rigid alignment of corresponding point sets (Kabsch / orthogonal Procrustes).

Convention (row vectors, as all becos point arrays): a :class:`RigidTransform` ``(R, t)`` sends
points ``p`` (N, 3) to ``p @ R.T + t`` — i.e. ``R @ p_i + t`` for each column point. Units are the
units of the points; no scaling is ever applied.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class RigidTransform:
    """A proper rigid motion ``p -> p @ rotation.T + translation``.

    Attributes:
        rotation: (3, 3) float64 rotation matrix, ``det = +1``.
        translation: (3,) float64 translation, in the units of the points.
    """

    rotation: np.ndarray
    translation: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "rotation", np.asarray(self.rotation, dtype=np.float64).reshape(3, 3))
        object.__setattr__(self, "translation", np.asarray(self.translation, dtype=np.float64).reshape(3))

    @classmethod
    def identity(cls) -> RigidTransform:
        return cls(np.eye(3), np.zeros(3))

    def apply(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) transformed copy of (N, 3) ``points`` (a (3,) point gives a (3,) result)."""
        points = np.asarray(points, dtype=np.float64)
        return points @ self.rotation.T + self.translation

    def inverse(self) -> RigidTransform:
        """The motion undoing this one: ``q -> (q - t) @ R``."""
        return RigidTransform(self.rotation.T, -self.translation @ self.rotation)

    def then(self, other: RigidTransform) -> RigidTransform:
        """The motion ``other ∘ self`` (first this one, then ``other``)."""
        return RigidTransform(other.rotation @ self.rotation, self.translation @ other.rotation.T + other.translation)

    def as_matrix(self) -> np.ndarray:
        """(4, 4) homogeneous matrix acting on column vectors ``[p; 1]``."""
        m = np.eye(4)
        m[:3, :3] = self.rotation
        m[:3, 3] = self.translation
        return m


def procrustes(
    source_points: np.ndarray,
    target_points: np.ndarray,
    mask: np.ndarray | None = None,
    weights: np.ndarray | None = None,
) -> RigidTransform:
    """The rigid motion minimising ``Σ w_i |source_i @ R.T + t - target_i|²`` (Kabsch, reflection-fixed).

    Args:
        source_points: (N, 3) points.
        target_points: (N, 3) corresponding points (row i matches row i).
        mask: optional (N,) bool, True = use the pair. Pairs left out may hold anything, NaN
            included (e.g. ground-truth positions of ``-1`` entries): they are never read into the sums.
        weights: optional (N,) non-negative weights of the pairs (applied after the mask).

    Returns:
        ``T`` with ``target ≈ T.apply(source) = source @ T.rotation.T + T.translation``; ``T.rotation``
        is a proper rotation (det +1) even when the best orthogonal fit would be a reflection.

    Raises:
        ValueError: shapes differ, or fewer than 3 usable pairs (zero total weight or non-finite data).
    """
    source = np.asarray(source_points, dtype=np.float64)
    target = np.asarray(target_points, dtype=np.float64)
    if source.shape != target.shape or source.ndim != 2 or source.shape[1] != 3:
        raise ValueError(f"procrustes needs two (N, 3) arrays, got {source.shape} and {target.shape}")
    use = np.ones(len(source), dtype=bool) if mask is None else np.asarray(mask, dtype=bool).copy()
    if use.shape != (len(source),):
        raise ValueError(f"mask must have shape ({len(source)},), got {use.shape}")
    w = np.ones(len(source)) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (len(source),):
        raise ValueError(f"weights must have shape ({len(source)},), got {w.shape}")
    use &= w > 0
    src, tgt, w = source[use], target[use], w[use]
    if len(src) < 3:
        raise ValueError(f"procrustes needs at least 3 corresponding pairs, {len(src)} are usable")
    if not (np.isfinite(src).all() and np.isfinite(tgt).all() and np.isfinite(w).all()):
        raise ValueError("procrustes: the unmasked points or weights contain NaN or infinite values")
    w = w / w.sum()
    mu_s = w @ src
    mu_t = w @ tgt
    cov = (src - mu_s).T @ ((tgt - mu_t) * w[:, None])  # (3, 3): Σ w s_c t_c^T
    u, _, vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    if d == 0:
        d = 1.0
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    translation = mu_t - mu_s @ rotation.T
    return RigidTransform(rotation, translation)
