"""Remeshing a shape to ~9,000–10,000 vertices, with exact maps to and from the original surface.

Why not plain decimation: quadric edge collapse leaves every vertex that no collapse touched at its
original position, so two remeshes of one shape class (same triangulation, different poses) share
13–88 % of their samples, and two remeshes of one shape with different targets share ~88 % of them
(the run to the smaller target is the run to the larger one continued). The pipeline below breaks
both:

0. a COPY of the input without faces that repeat a vertex index, duplicate faces, unreferenced
   vertices and small extra components (:func:`becos.mesh.surface_for_remeshing`; a warning names
   the ``source`` file and the repair). Zero-area faces stay in the copy (they close the surface)
   but no map point is placed in one (:class:`becos.geometry.SurfaceLocator` skips them). Everything below runs on that copy; the
   copy remembers the input vertex and face row of each of its vertices and faces, so both maps
   refer to the input as given. Original vertices that the copy dropped (unreferenced, or on a
   dropped speck) have no image in ``from_original`` (face -1). A clean input is used as is.
1. the copy is re-oriented coherently (pymeshlab ``meshing_re_orient_faces_coherently``;
   TOSCA michael0/david0/horse5/6/centaur3/4 have inconsistently wound faces). The input's vertex
   order and face rows are never touched: both maps are computed against the input as given.
2. seeded jitter: every interior vertex of the copy moves to a random point of one of its own
   incident triangles, every boundary vertex to a random point of one of its boundary edges, at most
   :data:`DEFAULT_JITTER` of the way to the other corners. Each vertex therefore stays exactly ON the
   original surface (and the boundary where it is); only the triangulation between them is perturbed
   (by less than the local edge length), which changes the quadric errors and the collapse order,
   and no vertex keeps its input position, also where no collapse touches it. The seed is derived
   from the mesh content and the target, so the same input and target give byte-identical output,
   and different targets (the remesh variants of one shape) or different poses of one class give
   unrelated samplings.
3. a large input (more than :data:`PRE_DECIMATION_FACTOR` × the face target faces; TOSCA's cats,
   dogs, horses and humans) is decimated directly to the target (step 4 without the subdivision):
   on the jittered input, whose every vertex has moved, the subdivision is not needed to break the
   sharing (no original vertex shared between variants). Decimating the 4× larger subdivided mesh
   (after a pre-decimation to this size) took 3-5× the CPU (``benchmarks/remesh.py --steps``, 8
   shapes × 2 variants: decimation median 2.09 -> 0.73 CPU-s, pre-decimation + subdivision 0.32 ->
   0.04), and the direct remesh is as close to the original (largest ``from_original`` distance
   6.2e-3 -> 5.6e-3 of the bounding-box diagonal) with fewer thin triangles (faces with an angle
   under 10 degrees: median 825 -> 378 per remesh). An input between 1× and this × the face target
   (TOSCA's centaurs: 1.6×) is still subdivided: decimated directly, its remesh keeps much of the
   input's uneven triangulation (centaur3: 99.9th-percentile edge 6.1-6.3× the median instead of
   3.9-4.1×). With fast-simplification a large input is instead first decimated to that size and
   goes on to step 4.
4. a smaller input gets ONE Loop subdivision with threshold 0 (every edge split; every old vertex
   moved by the Loop smoothing), then quadric edge-collapse decimation with optimal placement and
   topology preservation to the target; the vertex target is reached by continuing the decimation
   with the boundary kept (each interior collapse removes one vertex and two faces:
   :func:`_to_vertex_target`).
   The decimator of steps 3-4 (``decimator``, config key of the same name, :data:`DECIMATORS`):
   ``pymeshlab`` (default) or ``fast-simplification`` (the Fast-Quadric-Mesh-Simplification
   package: on 8 TOSCA shapes × 2 variants, pre-decimation, subdivision and decimation take a median
   0.56 CPU-s instead of pymeshlab's 0.75 (the whole remesh job 2.01 instead of 2.15); less even
   triangles: no quality threshold, longest edge up to 13x the median instead of 8x, about four
   times as many faces with an angle under 10 degrees). fast-simplification does not preserve topology: each
   of its results (the pre-decimation, the decimation to ~the target) is checked (one component, no non-manifold
   edge or vertex, oriented, Euler characteristic and boundary loops of the input kept,
   :func:`_decimation_problem`); a result that fails is thrown away and that call is made with
   pymeshlab instead (a warning; ``stats["decimator_fallbacks"]`` names the step and the failure).
   The exact vertex target is then reached as above, by pymeshlab's continuation of the
   (small, already decimated) mesh, which preserves topology.
5. only the largest connected component (by area) is kept if decimation left specks (a warning is
   logged and the count is recorded), unreferenced vertices are dropped.
6. the remesh is oriented like the majority of the input (area-weighted vote of face normals against
   the input's normals at the closest points) and every remeshed vertex is snapped to its closest
   point on the input surface with a compatible normal (:class:`becos.geometry.SurfaceLocator`:
   not onto a touching part that faces the other way). Parts that meet at an angle are not told
   apart by normals: a vertex whose point lies on another part than its mesh neighbours' (their
   points' geodesic Voronoi cells on the input are more than two cell hops apart; TOSCA victoria25:
   a hip vertex snapped onto the hand lying on it) is snapped again among the input faces in its
   neighbours' cells (:func:`_snap_onto_own_part`; counted as ``snap_moved_off_other_part``). So
   ``to_original`` is exact (distance 0) and vertices sit on the
   original surface, not on the Loop-smoothed one; the snap moves vertices by ~1e-4 of the bounding
   box diagonal, far less than an edge. Where it would fold a sliver face in a crease (a few faces
   on some TOSCA shapes), that face's corners stay where decimation put them (their
   ``to_original.distance`` is then the small projection distance; counted in
   :func:`remesh_with_stats` as ``unsnapped_vertices``).
7. ``from_original``: each original vertex goes to the closest point of a remeshed face that has a
   corner within :data:`FROM_ORIGINAL_RINGS` rings of a remeshed vertex nearest ALONG the original
   surface to it or to one of its 1-ring neighbours (a geodesic Voronoi partition of the remeshed
   vertices' ``to_original`` points, :func:`becos.geometry.nearest_along_surface`; the neighbours
   reach across thin parts, a horse's tail, that a few long remeshed faces cover). Where two parts touch or pass through each other
   (TOSCA victoria1: a hand at the hip; the arch of a foot against its heel) the plain or
   normal-aware closest point can lie on the other part, 0.01 mm away in space and a body length away
   along the surface; normals do not tell them apart there (the parts meet at an angle), mesh
   connectivity does (issue #20). Where the closest such face bends away from the vertex's normal
   (over the rim of a thin part: a horse's ear tip is two sheets closer together than the remesh's
   chordal error), a face that agrees with it is taken if it is nearly as close.

Guarantee on counts: with ``target_vertices`` the result has EXACTLY that many vertices unless the
decimation cannot get there (it stalls when every remaining collapse would break the topology or a
face quality threshold; not met on TOSCA), in which case it is within 1 % and
:func:`remesh_with_stats` reports it. With ``target_faces`` the face count is the target, or one
less where boundary collapses remove one face at a time (pymeshlab's own behaviour).

Units and frames: the remesh is in the input's units and frame; nothing is scaled or centred here.
"""

from __future__ import annotations

import functools
import hashlib
import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from becos.atomic import save_npz as atomic_save_npz
from becos.atomic import write_bytes
from becos.errors import InputFileError
from becos.geometry import SurfaceLocator, face_areas, points_on_surface
from becos.mesh import TriMesh, face_components, misoriented_edge_count, surface_for_remeshing, undirected_edges
from becos.seeding import rng_for, stable_hash
from becos.surface_map import SurfaceMap

log = logging.getLogger(__name__)

DEFAULT_JITTER = 0.3
"""Largest fraction of the way towards the other two corners of an incident triangle a vertex moves."""

PRE_DECIMATION_FACTOR = 2.0
"""Inputs with more faces than this × the face target are not Loop-subdivided: pymeshlab decimates
them directly to the target; fast-simplification first decimates them to this × the face target
(module docstring, steps 3-4)."""

VERTEX_TARGET_RANGE = (9000, 10000)
"""The paper's vertex-count rule: a remesh has a count drawn uniformly in this range (inclusive)."""

FILE_FORMAT_VERSION = 1

DECIMATORS = ("pymeshlab", "fast-simplification")
"""The quadric decimators of steps 3-4 (config ``decimator``); the first is the default."""

FAST_SIMPLIFICATION_SIZE = 1000.0
"""fast-simplification decimates a copy scaled to this square root of its surface area (results are
scaled back). Its collapse thresholds are absolute (``1e-9 (iteration + 3)^7`` of quadric error): on
area-normalised TOSCA shapes (sqrt(area) ~1.3) every candidate is under the first thresholds, so edges
collapse nearly in index order rather than by error: cat0, dog0 and michael0 (prepared) got
non-manifold edges at size 1, none at 1000, and no fast-simplification result of the 8 benchmark
shapes × 2 variants (``benchmarks/remesh.py --steps``) failed a check at 1000."""

_DECIMATION = dict(
    preservetopology=True,
    optimalplacement=True,
    preserveboundary=False,
    planarquadric=False,
    qualitythr=0.3,
    autoclean=True,
)


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
        seconds: wall time of :func:`remesh`, maps included.
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


# ----------------------------------------------------------------------------------------------
# small mesh utilities (numpy)


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


def _largest_component(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
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


def _jitter_on_surface(vertices: np.ndarray, faces: np.ndarray, amount: float, rng: np.random.Generator) -> np.ndarray:
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


class RemeshInput:
    """The per-shape part of a remesh: what every remesh variant of one input mesh reuses.

    Built once per shape (pass it as ``shape`` to :func:`remesh_with_stats` for each variant), each
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
        ms = _meshset(self.surface.vertices, self.surface.faces)
        ms.meshing_re_orient_faces_coherently()
        return _arrays(ms)

    @functools.cached_property
    def topology(self) -> tuple[int, int]:
        """(Euler characteristic, boundary loops) of ``oriented``: what every decimation of it keeps."""
        v, f = self.oriented
        return _surface_topology(f, len(v))

    @functools.cached_property
    def locator(self) -> SurfaceLocator:
        """Closest points on ``surface`` (the snap, step 6)."""
        return SurfaceLocator(self.surface)

    @functools.cached_property
    def edge_graph(self):
        """:func:`becos.geodesics.edge_graph` of ``surface``."""
        from becos.geodesics import edge_graph

        return edge_graph(self.surface)

    def cells(self, anchor: np.ndarray) -> np.ndarray:
        """(V_s,) int64: for each vertex of ``surface``, the index into ``anchor`` (surface vertices) of
        the anchor nearest to it ALONG the surface (geodesic Voronoi cells; the first of equal anchors)."""
        from becos.geometry import nearest_along_surface

        return nearest_along_surface(self.surface, anchor, self.edge_graph)

    @functools.cached_property
    def surface_edges(self) -> np.ndarray:
        """(E, 2) int64 unique undirected edges of ``surface``."""
        return undirected_edges(self.surface.faces)[0]

    @functools.cached_property
    def adjacency(self) -> tuple[np.ndarray, np.ndarray]:
        """Rows and columns of the non-zeros of ``surface``'s vertex adjacency (with the diagonal)."""
        from becos.geometry import vertex_adjacency

        return vertex_adjacency(self.surface.faces, self.surface.n_vertices).nonzero()

    @functools.cached_property
    def vertex_normals(self) -> np.ndarray:
        """(V_s, 3) unit vertex normals of ``surface`` with its faces oriented consistently."""
        locator = self.locator
        known = locator.face_normals if locator.searches_every_face else None
        return original_vertex_normals(self.surface, known)


def _vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) area-weighted unit vertex normals of a consistently oriented mesh."""
    from becos.geometry import vertex_normals

    return vertex_normals(TriMesh(vertices, faces))


def original_vertex_normals(mesh: TriMesh, face_normals: np.ndarray | None = None) -> np.ndarray:
    """(V, 3) vertex normals of the input after orienting its faces consistently (on a copy).

    ``face_normals``: :func:`becos.geometry.oriented_face_normals` of ``mesh``, if already computed."""
    from becos.geometry import oriented_face_normals

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
    nearest to them along the original surface (:func:`becos.geometry.nearest_along_surface`); the
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

    from becos.geometry import SparsePairs, VertexRings

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


SNAP_ROUNDS = 4
"""Rounds of :func:`_snap_onto_own_part` (each settles the vertices with settled neighbours)."""


def _off_part(shape: RemeshInput, remesh_edges: np.ndarray, n: int, anchor: np.ndarray) -> np.ndarray:
    """(n,) bool: the remeshed vertex sits on another part of ``surface`` than most of its neighbours.

    ``anchor`` (n,): each remeshed vertex's snapped point as a surface vertex (its largest weight).
    The anchors' geodesic Voronoi cells on the surface are adjacent (share a surface edge) where the
    anchors are neighbours along the surface; a remesh edge is consistent when its ends' cells are
    within two cell hops. Across a contact between two parts the cells are a body length apart.
    """
    import scipy.sparse as sp

    owner = shape.cells(anchor)
    cell = owner[anchor]  # (n,) the cell a remeshed vertex is in
    surface_edges = shape.surface_edges
    a, b = owner[surface_edges[:, 0]], owner[surface_edges[:, 1]]
    reached = (a >= 0) & (b >= 0)  # all, on a connected surface
    a, b = a[reached], b[reached]
    hop = sp.coo_matrix(
        (
            np.ones(2 * len(a) + n, dtype=np.float32),
            (np.concatenate([a, b, np.arange(n)]), np.concatenate([b, a, np.arange(n)])),
        ),
        shape=(n, n),
    ).tocsr()
    hop.data[:] = 1.0
    two = (hop @ hop).tocsr()
    ok = np.asarray(two[cell[remesh_edges[:, 0]], cell[remesh_edges[:, 1]]]).ravel() > 0
    degree = np.bincount(remesh_edges.ravel(), minlength=n)
    consistent = np.bincount(remesh_edges[ok].ravel(), minlength=n)
    return 2 * consistent < degree


def _snap_onto_own_part(
    shape: RemeshInput,
    v: np.ndarray,
    f: np.ndarray,
    face: np.ndarray,
    weights: np.ndarray,
    dist: np.ndarray,
):
    """Re-snap the remeshed vertices whose snapped point lies on another part than their neighbours'.

    Where two parts of the original touch or pass through each other at an angle (TOSCA victoria: a
    hand at the hip; michael: an arm against the body), the normal-aware closest point of a vertex
    (``face``, ``weights``, ``dist`` for the (V_r, 3) positions ``v``, faces ``f``)
    can sit on the part its mesh neighbours do not belong to: it looks right in this pose, and is
    a body length off in every other pose of the class. Such a vertex (:func:`_off_part`) is snapped
    again to the closest point among the surface faces in the geodesic Voronoi cells of its settled
    neighbours' points (1-ring, else 2-ring of the remesh): the part it is connected to (no normal
    test: the cells already pick the part, and flipped windings mislead normals). Repeated
    until no vertex is off its part (at most :data:`SNAP_ROUNDS` rounds).

    Returns face, weights, dist (as given, updated) and the number of vertices moved and left
    unresolved (no candidate face found; their snap is kept).
    """
    from becos.geometry import VertexRings

    surface, locator = shape.surface, shape.locator
    n = len(v)
    remesh_edges, _ = undirected_edges(f)
    face, weights, dist = face.copy(), weights.copy(), dist.copy()
    moved = np.zeros(n, dtype=bool)
    unresolved = np.zeros(n, dtype=bool)
    rings = {}
    for _ in range(SNAP_ROUNDS):
        anchor = surface.faces[face, weights.argmax(axis=1)]
        off = _off_part(shape, remesh_edges, n, anchor)
        if not off.any():
            break
        settled = np.flatnonzero(~off)
        cells = shape.cells(anchor[settled])
        owner = np.where(cells >= 0, settled[np.maximum(cells, 0)], -1)  # (V_s,) a settled remeshed vertex
        todo = np.flatnonzero(off)
        for ring in (1, 2):
            if len(todo) == 0:
                break
            if ring not in rings:
                rings[ring] = VertexRings(f, n, ring)

            def accept(rows, cand, near=rings[ring], todo=todo, owner=owner):
                return near.near(todo[rows][:, None, None], owner[surface.faces[cand]]).any(axis=2)

            fc, wc, dc, lost = locator.closest_near(v[todo], accept)
            done = todo[~lost]
            face[done], weights[done], dist[done] = fc[~lost], wc[~lost], dc[~lost]
            moved[done] = True
            todo = todo[lost]
        unresolved[:] = False
        unresolved[todo] = True
    return face, weights, dist, int(moved.sum()), int(unresolved.sum())


class _CpuSteps:
    """CPU seconds (``time.process_time``: this process, all threads) per pipeline step, into
    ``stats["cpu_seconds"]`` in call order."""

    def __init__(self, stats: dict):
        self.seconds = stats.setdefault("cpu_seconds", {})
        self._last = time.process_time()

    def lap(self, step: str) -> None:
        now = time.process_time()
        self.seconds[step] = self.seconds.get(step, 0.0) + now - self._last
        self._last = now


def _content_key(mesh: TriMesh) -> str:
    h = hashlib.sha1()
    h.update(mesh.vertices.tobytes())
    h.update(mesh.faces.tobytes())
    return h.hexdigest()


# ----------------------------------------------------------------------------------------------
# pymeshlab stages


def _meshset(vertices: np.ndarray, faces: np.ndarray):
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(
        pymeshlab.Mesh(
            vertex_matrix=np.ascontiguousarray(vertices, dtype=np.float64),
            face_matrix=np.ascontiguousarray(faces, dtype=np.int32),
        )
    )
    return ms


def _arrays(ms) -> tuple[np.ndarray, np.ndarray]:
    m = ms.current_mesh()
    return (
        np.array(m.vertex_matrix(), dtype=np.float64, copy=True),
        np.array(m.face_matrix(), dtype=np.int64, copy=True),
    )


def _decimate(ms, target_faces: int, **settings) -> None:
    """pymeshlab's quadric edge collapse of ``ms``'s mesh to ``target_faces`` faces (``_DECIMATION``,
    with ``settings`` overriding it)."""
    ms.meshing_decimation_quadric_edge_collapse(targetfacenum=int(max(target_faces, 4)), **{**_DECIMATION, **settings})


def _surface_topology(faces: np.ndarray, n_vertices: int) -> tuple[int, int]:
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


def _decimation_problem(vertices: np.ndarray, faces: np.ndarray, topology: tuple[int, int]) -> str | None:
    """Why a decimation result ((V, 3) ``vertices``, (F, 3) ``faces``) of a surface whose
    :func:`_surface_topology` is ``topology`` breaks a remesh guarantee, or None if it keeps them all:
    every vertex referenced, one component, no non-manifold edge or vertex, no misoriented edge, the
    Euler characteristic and the boundary loops kept."""
    from becos.mesh import non_manifold_vertices

    n = len(vertices)
    if not len(faces):
        return "no face left"
    checks = mesh_checks(TriMesh(vertices, faces))
    problems = {
        "unreferenced vertices": checks["unreferenced_vertices"],
        "components beyond the first": checks["components"] - 1,
        "non-manifold edges": checks["non_manifold_edges"],
        "non-manifold vertices": len(non_manifold_vertices(faces, n)),
        "misoriented edges": checks["misoriented_edges"],
    }
    for what, count in problems.items():
        if count:
            return f"{count} {what}"
    euler, loops = _surface_topology(faces, n)
    if (euler, loops) != tuple(topology):
        return f"topology changed: Euler characteristic {euler}, {loops} boundary loops (input: {topology[0]}, {topology[1]})"
    return None


def _fast_decimate(
    vertices: np.ndarray, faces: np.ndarray, target_faces: int, topology: tuple[int, int], stats: dict, step: str
) -> tuple[np.ndarray, np.ndarray]:
    """Quadric decimation of (V, 3) ``vertices`` / (F, 3) ``faces`` to ``target_faces`` faces with
    fast-simplification (on a copy scaled to :data:`FAST_SIMPLIFICATION_SIZE`), checked by
    :func:`_decimation_problem` against the input's ``topology``. A result that breaks a guarantee
    (or an exception of the extension) is dropped and the call is made with pymeshlab (:func:`_decimate`) instead: a warning, and ``"<step>: <problem>"`` appended to
    ``stats["decimator_fallbacks"]``. Returns float64 (V', 3) vertices and int64 (F', 3) faces
    (the input itself when ``target_faces`` is not below F: nothing to remove)."""
    import fast_simplification

    target = int(max(target_faces, 4))
    if target >= len(faces):
        return vertices, faces
    size = float(np.sqrt(face_areas(TriMesh(vertices, faces)).sum()))
    scale = FAST_SIMPLIFICATION_SIZE / size if size > 0 else 1.0
    try:
        v, f = fast_simplification.simplify(vertices * scale, faces, target_count=target)
        v, f = np.asarray(v, dtype=np.float64) / scale, np.asarray(f, dtype=np.int64)
        problem = _decimation_problem(v, f, topology)
    except (RuntimeError, ValueError) as exc:  # the C++ extension's errors
        problem = f"{type(exc).__name__}: {exc}"
    if problem is None:
        return v, f
    stats.setdefault("decimator_fallbacks", []).append(f"{step}: {problem}")
    log.warning("remesh: fast-simplification's %s broke a guarantee (%s); made it with pymeshlab", step, problem)
    ms = _meshset(vertices, faces)
    _decimate(ms, target)
    return _arrays(ms)


def _to_vertex_target(
    sub_v: np.ndarray,
    sub_f: np.ndarray,
    target_vertices: int,
    stats: dict,
    decimator: str = DECIMATORS[0],
    topology: tuple[int, int] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Decimate the subdivided mesh until it has ``target_vertices`` vertices (one component).

    The first decimation of each attempt is made by ``decimator`` (fast-simplification's result is
    checked against ``topology``, :func:`_fast_decimate`); the continuation to the exact count is
    always pymeshlab's (topology-preserving; cheap: the mesh is already small). The first decimation
    asks for a face count that leaves a few vertices more than the target whatever the boundary
    (``topology``: the input's Euler characteristic, :func:`_surface_topology`; 2 if None); the
    continuation keeps the boundary (interior collapses only), so one call removes the exact excess
    (two pymeshlab calls in all on the 8 benchmark shapes × 2 variants, instead of 5-8 when the
    continuation also collapsed boundary edges: those remove one face each, so a face target
    removed between half and all of the excess per call)."""
    # Euler: V - E + F = chi and 2E = 3F + B  =>  V = (F + B) / 2 + chi. Ask for F = 2 (target - chi)
    # + 16 faces: the vertex count lands at target + 8 + B / 2 (B: boundary edges left), just above
    # the target whatever the boundary, and the continuation (cheap: the mesh is already small) only
    # ever removes vertices
    chi = int(topology[0]) if topology is not None else 2
    first_faces = 2 * (target_vertices - chi) + 16
    best = None
    for attempt in range(6):  # noqa: B007 (read after the loop)
        if decimator == "fast-simplification":
            ms = _meshset(*_fast_decimate(sub_v, sub_f, first_faces, topology, stats, "decimation"))
        else:
            ms = _meshset(sub_v, sub_f)
            _decimate(ms, first_faces)
        keep_boundary = True
        for _ in range(40):
            m = ms.current_mesh()
            excess = m.vertex_number() - target_vertices
            if excess <= 0:
                break
            before = (m.vertex_number(), m.face_number())
            if keep_boundary:
                # boundary vertices kept: every collapse is interior (one vertex, two faces), so asking
                # for 2 × `excess` fewer faces removes exactly `excess` vertices in one call (a boundary
                # collapse, were one made, would overshoot: the attempt is then redone with more faces)
                _decimate(ms, m.face_number() - 2 * excess, preserveboundary=True)
            else:
                # every collapse removes one vertex and one (boundary) or two faces: asking for `excess`
                # fewer faces removes between excess/2 and excess vertices, so the target is never passed
                _decimate(ms, m.face_number() - excess)
            if (ms.current_mesh().vertex_number(), ms.current_mesh().face_number()) == before:
                if keep_boundary:  # stalled with the boundary kept: continue with boundary collapses too
                    keep_boundary = False
                    continue
                break  # stalled
        v, f = _arrays(ms)
        v, f, dropped = _largest_component(v, f)
        stats["dropped_faces"] += dropped
        best = (v, f) if best is None or abs(len(v) - target_vertices) < abs(len(best[0]) - target_vertices) else best
        if len(v) == target_vertices:
            break
        if len(v) < target_vertices:  # overshoot (specks dropped, autoclean): redo
            first_faces += 2 * (target_vertices - len(v)) + 8
        else:  # stalled above the target
            break
    stats["attempts"] = attempt + 1
    stats["vertices_off_target"] = len(best[0]) - target_vertices
    if stats["vertices_off_target"]:
        log.warning("remesh: decimation stopped at %d vertices for a target of %d", len(best[0]), target_vertices)
    return best


def remesh_with_stats(
    mesh: TriMesh,
    target_vertices: int | None = None,
    target_faces: int | None = None,
    *,
    jitter: float = DEFAULT_JITTER,
    seed: int | None = None,
    source: str | Path | None = None,
    shape: RemeshInput | None = None,
    decimator: str = DECIMATORS[0],
) -> tuple[Remeshed, dict]:
    """:func:`remesh`, also returning a dict of diagnostics (stage times in s, snap distances in input
    units, dropped faces, decimation attempts, ``vertices_off_target`` (0 when the vertex target is
    met exactly), ``unsnapped_vertices`` and ``snap_flipped_faces`` (always 0 after the fix-up),
    ``snap_moved_off_other_part`` / ``snap_off_part_unresolved`` (step 6's re-snap onto a vertex's own
    part), ``from_original_unresolved`` (original vertices with no remeshed face near them along the
    surface; their normal-aware closest point is kept),
    ``input_repair``: the counts of :class:`becos.mesh.MeshRepair` for step 0, ``cpu_seconds``: CPU
    seconds of this process by step: ``shape`` (the per-shape part, when built here), ``jitter``,
    ``subdivide``, ``decimate``, ``snap``, ``from_original``; ``decimator`` and
    ``decimator_fallbacks``: the calls of fast-simplification whose result broke a guarantee and were
    made with pymeshlab instead, as ``"<step>: <problem>"``; empty for pymeshlab).

    ``jitter`` (fraction, see :data:`DEFAULT_JITTER`; 0 disables it) and ``seed`` (default: derived
    from the mesh content and the target) control step 2 of the pipeline. ``source`` (the mesh's
    file) is named in the repair warning and in errors. ``shape``: the per-shape part of ``mesh``
    (:class:`RemeshInput`) when the caller remeshes several variants of it (built here if None).
    ``decimator``: one of :data:`DECIMATORS`, the quadric decimator of steps 3-4 (module docstring)."""
    if decimator not in DECIMATORS:
        raise ValueError(f"remesh: decimator must be one of {', '.join(DECIMATORS)}, got {decimator!r}")
    if (target_vertices is None) == (target_faces is None):
        raise ValueError(
            "remesh needs exactly one of target_vertices (the paper's rule, e.g. 9000-10000) "
            "or target_faces (the published pair lists' desired_n_face_remeshed)"
        )
    target = target_vertices if target_vertices is not None else target_faces
    if int(target) < 4:
        raise ValueError(f"remesh target must be at least 4, got {target}")
    if shape is not None and shape.mesh is not mesh:
        raise ValueError("remesh_with_stats: `shape` is the per-shape part of another mesh")
    t0 = time.perf_counter()
    stats: dict = {"dropped_faces": 0, "attempts": 1, "decimator": decimator, "decimator_fallbacks": []}
    cpu = _CpuSteps(stats)
    face_goal = int(target_faces) if target_faces is not None else 2 * int(target_vertices)
    if shape is None:
        # 0. the surface to remesh: a repaired copy (the input itself when clean)
        shape = RemeshInput(mesh, source=source)
    import pymeshlab

    try:
        if "oriented" not in shape.__dict__:
            shape.oriented  # noqa: B018 (1. built on first use; timed as the shape's part)
            cpu.lap("shape")
        surface, repair = shape.surface, shape.repair
        stats["input_repair"] = repair.counts()
        v, f = _remesh_surface(shape, target_vertices, target_faces, face_goal, jitter, seed, stats, t0, cpu, decimator)
    except pymeshlab.PyMeshLabException as exc:
        message = " ".join(str(exc).split())
        raise InputFileError(
            Path(shape.where),
            f"the remesher (pymeshlab) failed on this surface: {message}",
            "repair the mesh (e.g. MeshLab: Filters > Cleaning and Repairing) or leave the shape out",
        ) from None
    stats["seconds_decimate"] = time.perf_counter() - t0 - stats["seconds_prepare"]

    # 6. orientation vote and snap onto the original surface (its repaired copy: same geometry,
    # no degenerate or duplicate faces; face and vertex indices are translated back below)
    locator = shape.locator
    face, weights, dist = locator.closest(v)
    tri = v[f]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # length = 2 × area
    orig_tri = surface.vertices[surface.faces]
    orig_n = np.cross(orig_tri[:, 1] - orig_tri[:, 0], orig_tri[:, 2] - orig_tri[:, 0])
    orig_n /= np.maximum(np.linalg.norm(orig_n, axis=1, keepdims=True), 1e-300)
    ref = orig_n[face[f]].sum(axis=1)  # input normal at the corners
    if np.einsum("ij,ij->i", normals, ref).sum() < 0:
        f = f[:, ::-1].copy()
        normals = -normals
    # snap again with normals: where two parts touch (a hand on a hip, a horse's legs) the plain
    # closest point can sit on the other part; their normals are opposite there
    face, weights, dist = locator.closest(v, _vertex_normals(v, f))
    # ... and keep each vertex on its own part: normals do not separate parts that meet at an angle
    face, weights, dist, moved, unresolved = _snap_onto_own_part(shape, v, f, face, weights, dist)
    stats["snap_moved_off_other_part"], stats["snap_off_part_unresolved"] = moved, unresolved
    stats["snap_distance_mean"] = float(dist.mean())
    stats["snap_distance_max"] = float(dist.max())
    snapped = points_on_surface(surface, face, weights)
    kept = np.zeros(len(v), dtype=bool)  # vertices left where decimation put them
    flipped = np.zeros(len(f), dtype=bool)
    for _ in range(10):
        # a snap may fold a sliver face in a crease: leave the corners of folded faces unsnapped
        tri = snapped[f]
        new_normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        flipped = (np.einsum("ij,ij->i", normals, new_normals) <= 0) & (np.abs(normals).sum(axis=1) > 0)
        if not flipped.any():
            break
        back = np.unique(f[flipped].ravel())
        kept[back] = True
        snapped[back] = v[back]
    stats["snap_flipped_faces"] = int(flipped.sum())
    stats["unsnapped_vertices"] = int(kept.sum())
    cpu.lap("snap")
    remeshed = TriMesh(snapped, f)
    # snapped vertices ARE their image (distance 0); unsnapped ones keep their projection distance.
    # Faces are rows of the input as given (the copy keeps each kept row's columns).
    to_original = SurfaceMap(repair.face_index[face], weights, np.where(kept, dist, 0.0))
    # 7. original vertices -> remeshed surface; vertices the copy dropped have no image. A vertex
    # lands only in a remeshed face whose corners sit (by ``to_original``) within a few edge rings of
    # it on the original: never on a part that merely touches it in space (a hand on a hip, the two
    # sheets of a foot's arch), where distance and normals cannot tell the parts apart.
    rf, rw, rd, unresolved = _from_original(shape, remeshed, face, weights)
    stats["from_original_unresolved"] = int(unresolved.sum())
    of = np.full(mesh.n_vertices, -1, dtype=np.int64)
    ow = np.zeros((mesh.n_vertices, 3))
    od = np.full(mesh.n_vertices, np.nan)
    of[repair.vertex_index], ow[repair.vertex_index], od[repair.vertex_index] = rf, rw, rd
    from_original = SurfaceMap(of, ow, od)
    cpu.lap("from_original")
    seconds = time.perf_counter() - t0
    stats["seconds"] = seconds
    result = Remeshed(
        remeshed,
        to_original,
        from_original,
        None if target_vertices is None else int(target_vertices),
        None if target_faces is None else int(target_faces),
        seconds,
    )
    return result, stats


def _remesh_surface(
    shape: RemeshInput,
    target_vertices: int | None,
    target_faces: int | None,
    face_goal: int,
    jitter: float,
    seed: int | None,
    stats: dict,
    t0: float,
    cpu: _CpuSteps,
    decimator: str = DECIMATORS[0],
) -> tuple[np.ndarray, np.ndarray]:
    """Steps 2-5 on ``shape``'s oriented copy: (V_r, 3) vertices and (F_r, 3) faces of the remesh
    before the snap (diagnostics go into ``stats``). The jitter seed is derived from the INPUT
    mesh (as before the repair step); ``t0`` is the start time of the whole remesh. ``decimator``
    makes the pre-decimation and the decimation to ~the target (:data:`DECIMATORS`)."""
    v, f = shape.oriented
    # 2. seeded jitter on the surface
    if seed is None:
        seed = stable_hash("remesh-jitter", shape.content_key, target_vertices, target_faces)
    if jitter > 0:
        v = _jitter_on_surface(v, f, float(jitter), rng_for(seed, "jitter"))
    cpu.lap("jitter")
    # 3.-4. pre-decimation of large inputs, one Loop subdivision
    import pymeshlab

    fast = decimator == "fast-simplification"
    topology = shape.topology
    large = len(f) > PRE_DECIMATION_FACTOR * face_goal
    if fast and large:
        v, f = _fast_decimate(v, f, int(PRE_DECIMATION_FACTOR * face_goal), topology, stats, "pre-decimation")
    ms = _meshset(v, f)
    if fast or not large:  # pymeshlab decimates a large input directly (module docstring, step 3)
        ms.meshing_surface_subdivision_loop(iterations=1, threshold=pymeshlab.PercentageValue(0))
    stats["seconds_prepare"] = time.perf_counter() - t0
    cpu.lap("subdivide")
    # decimation to the target
    if target_vertices is not None:
        v, f = _to_vertex_target(*_arrays(ms), int(target_vertices), stats, decimator, topology)
    elif fast:
        v, f = _fast_decimate(*_arrays(ms), int(target_faces), topology, stats, "decimation")
    else:
        _decimate(ms, int(target_faces))
        v, f = _arrays(ms)
        v, f, dropped = _largest_component(v, f)
        stats["dropped_faces"] += dropped
    if stats["dropped_faces"]:
        log.warning(
            "remesh: decimation left %d faces in small components; kept the largest component", stats["dropped_faces"]
        )
    cpu.lap("decimate")
    return v, f


def remesh(
    mesh: TriMesh,
    target_vertices: int | None = None,
    target_faces: int | None = None,
    *,
    source: str | Path | None = None,
    decimator: str = DECIMATORS[0],
) -> Remeshed:
    """Remesh ``mesh`` to a vertex target (paper: 9,000–10,000) or a face target (pair lists: 18,000–20,000).

    See the module docstring for the pipeline and guarantees. Exactly one target must be given.
    The input is never modified; the maps refer to its vertex order and its face rows as given,
    also when step 0 remeshes a repaired copy (the warning then names ``source``, the mesh's file).
    Deterministic: the same input arrays, target and ``decimator`` (:data:`DECIMATORS`) give
    byte-identical output.

    Raises:
        ValueError: no target, both targets, a target below 4, or an unknown ``decimator``.
        InputFileError: the mesh is several shapes (large extra components), has no face of non-zero
            area, or still has non-manifold edges that stop the remesher (names ``source``).
    """
    return remesh_with_stats(mesh, target_vertices, target_faces, source=source, decimator=decimator)[0]


def variant_target_vertices(
    seed: int,
    dataset: str,
    name: str,
    variant: int,
    low: int = VERTEX_TARGET_RANGE[0],
    high: int = VERTEX_TARGET_RANGE[1],
) -> int:
    """Vertex target of remesh variant ``variant`` of shape ``dataset/name``: uniform in [low, high]
    (inclusive), drawn from ``rng_for(seed, "remesh", dataset, name, variant)``."""
    if low > high:
        raise ValueError(f"variant_target_vertices: low {low} > high {high}")
    return int(rng_for(seed, "remesh", dataset, name, variant).integers(low, high + 1))


# ----------------------------------------------------------------------------------------------
# sample-sharing measures


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


# ----------------------------------------------------------------------------------------------
# files


def save_remeshed(path: Path, r: Remeshed) -> None:
    """Write ``r`` to one .npz (atomic: temporary file + rename), maps with their distances."""
    atomic_save_npz(
        path,
        format_version=np.int64(FILE_FORMAT_VERSION),
        vertices=r.mesh.vertices,
        faces=r.mesh.faces,
        to_original_face=r.to_original.face,
        to_original_weights=r.to_original.weights,
        to_original_distance=r.to_original.distance,
        from_original_face=r.from_original.face,
        from_original_weights=r.from_original.weights,
        from_original_distance=r.from_original.distance,
        target_vertices=np.int64(-1 if r.target_vertices is None else r.target_vertices),
        target_faces=np.int64(-1 if r.target_faces is None else r.target_faces),
    )  # no wall time: the same input gives the same bytes (``seconds`` is logged instead)


_KEYS = (
    "format_version",
    "vertices",
    "faces",
    "to_original_face",
    "to_original_weights",
    "to_original_distance",
    "from_original_face",
    "from_original_weights",
    "from_original_distance",
    "target_vertices",
    "target_faces",
)


def load_remeshed(path: Path) -> Remeshed:
    """Read a file written by :func:`save_remeshed`.

    Raises:
        InputFileError: missing, unreadable, wrong version or missing arrays.
    """
    path = Path(path)
    fix = "delete it; becos recomputes remeshes it cannot read"
    if not path.is_file():
        raise InputFileError(path, "remesh file not found", "run the remeshing step again")
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in _KEYS if k not in data.files]
            if missing:
                raise InputFileError(path, f"not a becos remesh file (missing arrays {missing})", fix)
            d = {k: data[k] for k in _KEYS}
            seconds = float(data["seconds"]) if "seconds" in data.files else float("nan")  # files of becos < 0.2
    except InputFileError:
        raise
    except Exception as exc:
        raise InputFileError(path, f"could not be read as .npz ({type(exc).__name__}: {exc})", fix) from exc
    if int(d["format_version"]) != FILE_FORMAT_VERSION:
        raise InputFileError(
            path, f"remesh file format {int(d['format_version'])}, this becos reads {FILE_FORMAT_VERSION}", fix
        )
    tv, tf = int(d["target_vertices"]), int(d["target_faces"])
    return Remeshed(
        TriMesh(d["vertices"], d["faces"]),
        SurfaceMap(d["to_original_face"], d["to_original_weights"], d["to_original_distance"]),
        SurfaceMap(d["from_original_face"], d["from_original_weights"], d["from_original_distance"]),
        None if tv < 0 else tv,
        None if tf < 0 else tf,
        seconds,
    )


def write_ply(path: Path, mesh: TriMesh) -> None:
    """Write ``mesh`` as binary little-endian PLY (double x/y/z, int vertex indices), atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment written by becos\n"
        f"element vertex {mesh.n_vertices}\nproperty double x\nproperty double y\nproperty double z\n"
        f"element face {mesh.n_faces}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode("ascii")
    face_rec = np.empty(mesh.n_faces, dtype=[("n", "u1"), ("i", "<i4", (3,))])
    face_rec["n"] = 3
    face_rec["i"] = mesh.faces
    write_bytes(path, header + np.ascontiguousarray(mesh.vertices, dtype="<f8").tobytes() + face_rec.tobytes())
