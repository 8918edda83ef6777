"""The result of :mod:`becos.build.remesh` (:class:`Remeshed`: the remesh with its maps both ways) and
step 7, ``from_original``: each original vertex to its point on the remesh."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from becos.core.geometry import SurfaceLocator
from becos.core.mesh import TriMesh
from becos.core.surface_map import SurfaceMap

if TYPE_CHECKING:
    from becos.build.remesh.shape import RemeshInput


@dataclass(frozen=True)
class Remeshed:
    """A remesh of one input mesh, with maps both ways.

    Attributes:
        mesh: the remeshed mesh, (V_r, 3) float64 vertices in the input's units and frame,
            (F_r, 3) int64 faces, consistently oriented like the input's majority.
        to_original: (V_r,) map: remeshed vertex -> closest point of the ORIGINAL surface (face rows
            of the input as given; distance in input units, ~0 because vertices are snapped there).
        from_original: (V_original,) map: original vertex -> closest point of the remeshed surface
            near it along the original surface (step 7; distance in input units).
        target_vertices: the vertex target asked for (None in face-target mode).
        target_faces: the face target asked for (None in vertex-target mode).
        seconds: wall time of :func:`becos.build.remesh.remesh`, maps included.
    """

    mesh: TriMesh
    to_original: SurfaceMap
    from_original: SurfaceMap
    target_vertices: int | None
    target_faces: int | None
    seconds: float


FROM_ORIGINAL_RINGS = 2
"""An original vertex's point on its remesh lies in a face with a corner within this many edge rings
of the remeshed vertex nearest to it along the original surface (``from_original``)."""

FROM_ORIGINAL_MIN_COS = 0.5
"""An original vertex's point on its remesh lies in a face whose normal is within 60 degrees of the
vertex's own (cosine above this) wherever such a face is nearly as close as the closest one
(:data:`FROM_ORIGINAL_DETOUR`): the two sheets of a thin part (a TOSCA horse's ear tip, 0.0003
sqrt(area) thick, thinner than the remesh's chordal error) are within rings of each other around the
rim, and the closest face can be one that bends over the rim onto the other sheet (issue #20)."""

FROM_ORIGINAL_DETOUR = 0.1
"""How much farther (× the remesh's mean edge length) than the closest allowed face the face with an
agreeing normal may be (:data:`FROM_ORIGINAL_MIN_COS`); beyond it the closest face is kept."""


def original_vertex_normals(mesh: TriMesh, face_normals: np.ndarray | None = None) -> np.ndarray:
    """(V, 3) vertex normals of the input after orienting its faces consistently (on a copy).

    ``face_normals``: :func:`becos.core.geometry.oriented_face_normals` of ``mesh``, if already computed."""
    from becos.core.geometry import oriented_face_normals

    if face_normals is None:
        face_normals = oriented_face_normals(mesh)
    normals = np.zeros((mesh.n_vertices, 3))
    np.add.at(normals, mesh.faces.ravel(), np.repeat(face_normals, 3, axis=0))
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)


def _from_original(shape: RemeshInput, remeshed: TriMesh, face: np.ndarray, weights: np.ndarray):
    """Each vertex of ``surface`` (the original's repaired copy) -> its point on ``remeshed``.

    ``face``, ``weights``: the remeshed vertices' points on ``surface`` (rows of ``surface.faces``).
    Each original vertex and its 1-ring neighbours are given the remeshed vertex whose point is
    nearest to them along the original surface (:func:`becos.core.geometry.nearest_along_surface`); the
    vertex's point is then the closest point among remeshed faces with a corner within
    :data:`FROM_ORIGINAL_RINGS` rings of one of those (:meth:`SurfaceLocator.closest_near`): all of
    them lie on the vertex's own part, and together they reach across thin parts (a tail, an ear)
    whose few long remeshed faces one of them alone may miss. Among those faces, one whose normal
    agrees with the vertex's (:data:`FROM_ORIGINAL_MIN_COS`) is preferred when nearly as close
    (:data:`FROM_ORIGINAL_DETOUR`): at the tip of a thin part the rings reach round the rim onto the
    other sheet. Returns face, weights, distance and
    ``unresolved`` (no such face: the normal-aware closest point is kept). ``shape``: the original's
    per-shape part (``shape.surface``: its repaired copy).
    """
    import scipy.sparse as sp

    from becos.core.geometry import SparsePairs, VertexRings

    surface = shape.surface
    anchor = surface.faces[face, np.asarray(weights).argmax(axis=1)]  # (V_r,) surface vertex
    owner = shape.cells(anchor)  # (V_s,) remeshed vertex
    reached = owner >= 0
    rows, cols = shape.adjacency
    keep = reached[cols]
    owners = sp.csr_matrix(
        (np.ones(int(keep.sum()), dtype=np.float32), (rows[keep], owner[cols[keep]])),
        shape=(surface.n_vertices, remeshed.n_vertices),
    )  # original vertex -> owners near it
    rings = VertexRings(remeshed.faces, remeshed.n_vertices, FROM_ORIGINAL_RINGS)
    near = SparsePairs(owners @ rings.matrix)  # original vertex -> remeshed vertices

    def accept(rows, cand):
        ok = near.near(rows[:, None, None], remeshed.faces[cand]).any(axis=2)
        return ok | (~reached[rows])[:, None]

    locator = SurfaceLocator(remeshed)
    return locator.closest_near(
        surface.vertices,
        accept,
        shape.vertex_normals,
        min_cos=FROM_ORIGINAL_MIN_COS,
        detour=FROM_ORIGINAL_DETOUR * locator.max_detour,
    )


def from_original_map(
    shape: RemeshInput, remeshed: TriMesh, face: np.ndarray, weights: np.ndarray, stats: dict
) -> SurfaceMap:
    """Step 7, ``from_original``: each vertex of the INPUT mesh (``shape.mesh``, its vertex order as
    given) -> its point on ``remeshed``; input vertices the repaired copy dropped have no image (face
    -1, weights 0, distance NaN). ``face``, ``weights``: the remeshed vertices' points on
    ``shape.surface`` (step 6). A vertex lands only in a remeshed face whose corners sit within a few
    edge rings of it on the original: never on a part that merely touches it in space (a hand on a
    hip, the two sheets of a foot's arch), where distance and normals cannot tell the parts apart
    (:func:`_from_original`). ``stats["from_original_unresolved"]``: vertices with no such face."""
    rf, rw, rd, unresolved = _from_original(shape, remeshed, face, weights)
    stats["from_original_unresolved"] = int(unresolved.sum())
    n, index = shape.mesh.n_vertices, shape.repair.vertex_index
    of = np.full(n, -1, dtype=np.int64)
    ow = np.zeros((n, 3))
    od = np.full(n, np.nan)
    of[index], ow[index], od[index] = rf, rw, rd
    return SurfaceMap(of, ow, od)
