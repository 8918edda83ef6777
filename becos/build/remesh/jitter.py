"""Step 2 of :mod:`becos.build.remesh`: the seeded jitter that moves every vertex to a random point of the
surface near it."""

from __future__ import annotations

import numpy as np

from becos.core.mesh import undirected_edges

DEFAULT_JITTER = 0.3
"""Largest fraction of the way towards the other two corners of an incident triangle a vertex moves."""


def jitter_on_surface(vertices: np.ndarray, faces: np.ndarray, amount: float, rng: np.random.Generator) -> np.ndarray:
    """Move each vertex to a random point of the surface near it: an interior vertex into one of its
    incident triangles, a boundary vertex along one of its boundary edges (the boundary stays where
    it is).

    Vertex p of a randomly chosen incident face (p, q, r) goes to p + a (q - p) + b (r - p) with
    a, b ~ U(0, amount / 2): a point of that triangle, hence of the surface. A boundary vertex p of a
    randomly chosen boundary edge (p, q) goes to p + a (q - p). So no vertex keeps its input position
    (the decimation leaves the vertices no collapse touched where they are). ``vertices``: (V, 3)
    float; ``faces``: (F, 3) int. Returns new (V, 3) positions (unreferenced vertices stay).
    """
    n = len(vertices)
    flat = faces.ravel()
    slot_order = np.argsort(rng.random(len(flat)), kind="stable")
    incident_slot = np.full(n, -1, dtype=np.int64)
    incident_slot[flat[slot_order]] = slot_order  # last write wins: a random incident slot
    edges, counts = undirected_edges(faces)
    rim = edges[counts == 1]
    on_rim = np.zeros(n, dtype=bool)
    on_rim[rim.ravel()] = True
    move = (incident_slot >= 0) & ~on_rim
    idx = np.flatnonzero(move)
    slot = incident_slot[idx]
    face, corner = slot // 3, slot % 3
    q = faces[face, (corner + 1) % 3]
    r = faces[face, (corner + 2) % 3]
    ab = rng.random((n, 2))[idx] * (amount / 2.0)
    out = vertices.copy()
    p = vertices[idx]
    out[idx] = p + ab[:, :1] * (vertices[q] - p) + ab[:, 1:] * (vertices[r] - p)
    # boundary vertices: along a random one of their boundary edges (ends: (2 E_b,) slots of `rim`)
    ends = rim.ravel()
    end_order = np.argsort(rng.random(len(ends)), kind="stable")
    rim_slot = np.full(n, -1, dtype=np.int64)
    rim_slot[ends[end_order]] = end_order
    b_idx = np.flatnonzero(rim_slot >= 0)
    other = rim[rim_slot[b_idx] // 2, 1 - rim_slot[b_idx] % 2]
    t = rng.random(len(b_idx))[:, None] * (amount / 2.0)
    out[b_idx] = vertices[b_idx] + t * (vertices[other] - vertices[b_idx])
    return out
