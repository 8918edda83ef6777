"""Steps 0-1 of :mod:`becos.build.remesh`: the per-shape part of a remesh (:class:`RemeshInput`: the repaired,
re-oriented copy and what every variant of one shape reuses)."""

from __future__ import annotations

import functools
import hashlib
import logging
from pathlib import Path

import numpy as np

from becos.build.remesh.decimate import meshset, meshset_arrays
from becos.build.remesh.maps import original_vertex_normals
from becos.build.remesh.topology import surface_topology
from becos.core.geometry import SurfaceLocator
from becos.core.mesh import TriMesh, surface_for_remeshing, undirected_edges

log = logging.getLogger(__name__)


class RemeshInput:
    """The per-shape part of a remesh: what every remesh variant of one input mesh reuses.

    Built once per shape (pass it as ``shape`` to :func:`~becos.build.remesh.remesh_with_stats` for each variant), each
    part on first use: the repaired copy ``surface`` (step 0) and its ``repair``, the coherently
    oriented copy step 1 gives the jitter (``oriented``: (V_s, 3) float64 vertices, (F_s, 3) int64
    faces), the closest-point ``locator`` of ``surface`` (step 6), its edge graph for geodesic
    Voronoi cells (:meth:`cells`; built once instead of once per query), its unique undirected
    edges, vertex adjacency and consistently oriented vertex normals (step 7), the ``topology`` that
    fast-simplification's results are checked against (steps 3-4). Every part is a
    deterministic function of the input, so a variant remeshed with it is byte-identical to one
    remeshed alone. ``source`` (the mesh's file) is named in the repair warning and errors.
    """

    def __init__(self, mesh: TriMesh, source: str | Path | None = None):
        self.mesh = mesh
        self.source = source
        self.where = (
            str(source) if source is not None else f"remesh input ({mesh.n_vertices} vertices, {mesh.n_faces} faces)"
        )
        self.surface, self.repair = surface_for_remeshing(mesh, source=source)
        if self.repair.changed or self.repair.zero_area_faces:
            log.warning("%s: %s", self.where, self.repair.summary())
        elif self.repair.misoriented_edges:
            log.info("%s: %s", self.where, self.repair.summary())

    @functools.cached_property
    def content_key(self) -> str:
        """Digest of the INPUT mesh's arrays (as before the repair): part of the jitter seed."""
        return _content_key(self.mesh)

    @functools.cached_property
    def oriented(self) -> tuple[np.ndarray, np.ndarray]:
        """Step 1: the repaired copy re-oriented coherently by pymeshlab (arrays; do not modify)."""
        ms = meshset(self.surface.vertices, self.surface.faces)
        ms.meshing_re_orient_faces_coherently()
        return meshset_arrays(ms)

    @functools.cached_property
    def topology(self) -> tuple[int, int]:
        """(Euler characteristic, boundary loops) of ``oriented``: what every decimation of it keeps."""
        v, f = self.oriented
        return surface_topology(f, len(v))

    @functools.cached_property
    def locator(self) -> SurfaceLocator:
        """Closest points on ``surface`` (the snap, step 6)."""
        return SurfaceLocator(self.surface)

    @functools.cached_property
    def edge_graph(self):
        """:func:`becos.core.geodesics.edge_graph` of ``surface``."""
        from becos.core.geodesics import edge_graph

        return edge_graph(self.surface)

    def cells(self, anchor: np.ndarray) -> np.ndarray:
        """(V_s,) int64: for each vertex of ``surface``, the index into ``anchor`` (surface vertices) of
        the anchor nearest to it ALONG the surface (geodesic Voronoi cells; the first of equal anchors)."""
        from becos.core.geometry import nearest_along_surface

        return nearest_along_surface(self.surface, anchor, self.edge_graph)

    @functools.cached_property
    def surface_edges(self) -> np.ndarray:
        """(E, 2) int64 unique undirected edges of ``surface``."""
        return undirected_edges(self.surface.faces)[0]

    @functools.cached_property
    def adjacency(self) -> tuple[np.ndarray, np.ndarray]:
        """Rows and columns of the non-zeros of ``surface``'s vertex adjacency (with the diagonal)."""
        from becos.core.geometry import vertex_adjacency

        return vertex_adjacency(self.surface.faces, self.surface.n_vertices).nonzero()

    @functools.cached_property
    def vertex_normals(self) -> np.ndarray:
        """(V_s, 3) unit vertex normals of ``surface`` with its faces oriented consistently."""
        locator = self.locator
        known = locator.face_normals if locator.searches_every_face else None
        return original_vertex_normals(self.surface, known)


def _content_key(mesh: TriMesh) -> str:
    h = hashlib.sha1()
    h.update(mesh.vertices.tobytes())
    h.update(mesh.faces.tobytes())
    return h.hexdigest()
