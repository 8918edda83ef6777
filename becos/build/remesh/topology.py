"""Topology facts of a triangle mesh (components, non-manifold and misoriented edges, Euler
characteristic, boundary loops) and the largest-component clean-up of step 5 of :mod:`becos.build.remesh`."""

from __future__ import annotations

import numpy as np

from becos.core.geometry import face_areas
from becos.core.mesh import TriMesh, face_components, misoriented_edge_count, undirected_edges


def mesh_checks(mesh: TriMesh) -> dict:
    """Topology facts of a triangle mesh, all computed with numpy/scipy.

    Returns a dict with ``components`` (vertex-connected, over faces), ``non_manifold_edges`` (edges
    used by more than two faces), ``misoriented_edges`` (directed edges used twice, i.e. two faces
    wound against each other), ``boundary_edges``, ``unreferenced_vertices``, ``euler_characteristic``.
    """
    f = mesh.faces
    n = mesh.n_vertices
    edges, counts = undirected_edges(f)
    referenced = np.zeros(n, dtype=bool)
    referenced[f.ravel()] = True
    return {
        "components": face_components(f, n)[1],
        "non_manifold_edges": int((counts > 2).sum()),
        "misoriented_edges": misoriented_edge_count(f),
        "boundary_edges": int((counts == 1).sum()),
        "unreferenced_vertices": int((~referenced).sum()),
        "euler_characteristic": int(referenced.sum() - len(edges) + len(f)),
    }


def surface_topology(faces: np.ndarray, n_vertices: int) -> tuple[int, int]:
    """(Euler characteristic V - E + F over the referenced vertices, number of boundary loops) of a
    triangle mesh given by (F, 3) int ``faces`` over ``n_vertices`` vertices. Boundary loops are the
    connected parts of the graph of boundary edges (edges of one face). With one component and no
    non-manifold edge or vertex, the two fix the surface's topology (genus = (2 - chi - loops) / 2)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    edges, counts = undirected_edges(faces)
    referenced = np.zeros(n_vertices, dtype=bool)
    referenced[np.asarray(faces).ravel()] = True
    euler = int(referenced.sum() - len(edges) + len(faces))
    boundary = edges[counts == 1]
    if not len(boundary):
        return euler, 0
    ids, local = np.unique(boundary, return_inverse=True)
    local = local.reshape(-1, 2)
    graph = sp.coo_matrix((np.ones(len(local)), (local[:, 0], local[:, 1])), shape=(len(ids), len(ids)))
    return euler, int(connected_components(graph, directed=False)[0])


def largest_component(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Keep the vertex-connected component of largest area; drop unreferenced vertices.

    Returns (vertices, faces, number of faces dropped). Vertex order of the kept ones is preserved.
    """
    n = len(vertices)
    face_label, n_comp = face_components(faces, n)
    dropped = 0
    if n_comp > 1:
        area = np.bincount(face_label, weights=face_areas(TriMesh(vertices, faces)), minlength=n_comp)
        keep = face_label == int(area.argmax())
        dropped = int((~keep).sum())
        faces = faces[keep]
    used = np.zeros(n, dtype=bool)
    used[faces.ravel()] = True
    if not used.all():
        new_index = np.cumsum(used) - 1
        vertices, faces = vertices[used], new_index[faces]
    return vertices, faces, dropped
