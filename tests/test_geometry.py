"""becos.geometry helpers that other tests do not reach through the pipeline."""

from __future__ import annotations

import numpy as np

from becos.geometry import nearest_along_surface
from becos.mesh import TriMesh


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
