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
   :func:`~becos.remesh.decimate.to_vertex_target`).
   The decimator of steps 3-4 (``decimator``, config key of the same name, :data:`DECIMATORS`):
   ``pymeshlab`` (default) or ``fast-simplification`` (the Fast-Quadric-Mesh-Simplification
   package: on 8 TOSCA shapes × 2 variants, pre-decimation, subdivision and decimation take a median
   0.56 CPU-s instead of pymeshlab's 0.75 (the whole remesh job 2.01 instead of 2.15); less even
   triangles: no quality threshold, longest edge up to 13x the median instead of 8x, about four
   times as many faces with an angle under 10 degrees). fast-simplification does not preserve topology: each
   of its results (the pre-decimation, the decimation to ~the target) is checked (one component, no non-manifold
   edge or vertex, oriented, Euler characteristic and boundary loops of the input kept,
   :func:`~becos.remesh.decimate.fast_decimate`); a result that fails is thrown away and that call is made with
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
   neighbours' cells (:func:`~becos.remesh.snap.snap_to_original`; counted as ``snap_moved_off_other_part``). So
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

One module per step: :mod:`~becos.remesh.pipeline` (:func:`remesh`, :func:`remesh_with_stats`: the
steps in order; :func:`variant_target_vertices`), :mod:`~becos.remesh.shape` (steps 0-1,
:class:`RemeshInput`), :mod:`~becos.remesh.jitter` (2), :mod:`~becos.remesh.decimate` (3-5),
:mod:`~becos.remesh.snap` (6), :mod:`~becos.remesh.maps` (7 and :class:`Remeshed`),
:mod:`~becos.remesh.topology` (:func:`mesh_checks`), :mod:`~becos.remesh.diagnostics` (CPU seconds by
step, sample-sharing measures) and :mod:`~becos.remesh.files` (.npz and PLY files).
"""

from becos.remesh.decimate import DECIMATORS, FAST_SIMPLIFICATION_SIZE, PRE_DECIMATION_FACTOR
from becos.remesh.diagnostics import coincident_original_vertices, intrinsic_coincidence, shared_vertex_share
from becos.remesh.files import FILE_FORMAT_VERSION, load_remeshed, save_remeshed, write_ply
from becos.remesh.jitter import DEFAULT_JITTER
from becos.remesh.maps import (
    FROM_ORIGINAL_DETOUR,
    FROM_ORIGINAL_MIN_COS,
    FROM_ORIGINAL_RINGS,
    Remeshed,
    original_vertex_normals,
)
from becos.remesh.pipeline import VERTEX_TARGET_RANGE, remesh, remesh_with_stats, variant_target_vertices
from becos.remesh.shape import RemeshInput
from becos.remesh.snap import SNAP_ROUNDS
from becos.remesh.topology import mesh_checks

__all__ = [
    "DECIMATORS",
    "DEFAULT_JITTER",
    "FAST_SIMPLIFICATION_SIZE",
    "FILE_FORMAT_VERSION",
    "FROM_ORIGINAL_DETOUR",
    "FROM_ORIGINAL_MIN_COS",
    "FROM_ORIGINAL_RINGS",
    "PRE_DECIMATION_FACTOR",
    "SNAP_ROUNDS",
    "VERTEX_TARGET_RANGE",
    "RemeshInput",
    "Remeshed",
    "coincident_original_vertices",
    "intrinsic_coincidence",
    "load_remeshed",
    "mesh_checks",
    "original_vertex_normals",
    "remesh",
    "remesh_with_stats",
    "save_remeshed",
    "shared_vertex_share",
    "variant_target_vertices",
    "write_ply",
]
