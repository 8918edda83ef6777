"""Diagnostics of :mod:`becos.build.remesh`: CPU seconds per step and the sample-sharing measures (how many
samples two remeshes share)."""

from __future__ import annotations

import time

import numpy as np

from becos.build.remesh.maps import Remeshed
from becos.core.geometry import points_on_surface
from becos.core.mesh import TriMesh, undirected_edges


class CpuSteps:
    """CPU seconds (``time.process_time``: this process, all threads) per pipeline step, into
    ``stats["cpu_seconds"]`` in call order."""

    def __init__(self, stats: dict):
        self.seconds = stats.setdefault("cpu_seconds", {})
        self._last = time.process_time()

    def lap(self, step: str) -> None:
        now = time.process_time()
        self.seconds[step] = self.seconds.get(step, 0.0) + now - self._last
        self._last = now


def coincident_original_vertices(
    r: Remeshed, original_faces: np.ndarray, weight_tol: float = 1e-6, distance_tol: float = 1e-9
) -> np.ndarray:
    """(V_r,) int64: the original vertex a remeshed vertex sits on (a corner weight ≥ 1 − weight_tol
    and ``to_original.distance`` ≤ distance_tol, input units), else -1."""
    m = r.to_original
    on_vertex = (m.weights.max(axis=1) >= 1.0 - weight_tol) & (m.distance <= distance_tol) & m.matched
    out = np.full(len(m), -1, dtype=np.int64)
    out[on_vertex] = np.asarray(original_faces)[m.face[on_vertex], m.weights[on_vertex].argmax(axis=1)]
    return out


def shared_vertex_share(a: Remeshed, a_faces: np.ndarray, b: Remeshed, b_faces: np.ndarray) -> float:
    """Share of remeshed vertices sitting on the same original vertex in both remeshes.

    For remeshes of two shapes with one vertex order (poses of a TOSCA class) or of one shape:
    the larger, over the two directions, of the fraction of a remesh's vertices that sit on an
    original vertex also sat on by a vertex of the other remesh."""
    ca = coincident_original_vertices(a, a_faces)
    cb = coincident_original_vertices(b, b_faces)
    common = np.intersect1d(ca[ca >= 0], cb[cb >= 0])
    return float(max(np.isin(ca, common).mean(), np.isin(cb, common).mean()))


def intrinsic_coincidence(
    a: Remeshed, a_faces: np.ndarray, b: Remeshed, b_original: TriMesh, rel_tol: float = 0.01
) -> float:
    """Share of a's remeshed vertices whose sample point, carried to shape b's original surface by
    vertex order (a and b originals share vertices, faces may differ in winding), lies within
    ``rel_tol`` × b's mean remesh edge length of a vertex of b's remesh. Independent samplings give
    ~0; samplings that copy each other give ~1."""
    from scipy.spatial import cKDTree

    carried = points_on_surface(TriMesh(b_original.vertices, a_faces), a.to_original.face, a.to_original.weights)
    e, _ = undirected_edges(b.mesh.faces)
    edge = float(np.linalg.norm(b.mesh.vertices[e[:, 0]] - b.mesh.vertices[e[:, 1]], axis=1).mean())
    d, _ = cKDTree(b.mesh.vertices).query(carried)
    return float((d < rel_tol * edge).mean())
