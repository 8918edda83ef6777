"""Steps 3-5 of :mod:`becos.build.remesh`: quadric decimation (pymeshlab or fast-simplification, whose
results are checked) to the face or the exact vertex target, and the pymeshlab mesh sets."""

from __future__ import annotations

import logging

import numpy as np

from becos.build.remesh.topology import largest_component, mesh_checks, surface_topology
from becos.core.geometry import face_areas
from becos.core.mesh import TriMesh

log = logging.getLogger(__name__)

PRE_DECIMATION_FACTOR = 2.0
"""Inputs with more faces than this × the face target are not Loop-subdivided: pymeshlab decimates
them directly to the target; fast-simplification first decimates them to this × the face target
(:mod:`becos.build.remesh`, steps 3-4)."""

SUBDIVISION_EDGE = 1.0
"""The Loop subdivision of step 4 (:func:`loop_subdivided`) splits the edges longer than this × the
remesh's edge length (that of an equilateral triangulation of the input's area with the face target's
faces): it refines where the input is coarser than the remesh (which is what evens out the remesh of
an unevenly triangulated input) instead of everywhere."""

SUBDIVISION_MIN_FACES = 1.2
"""A refinement by :data:`SUBDIVISION_EDGE` that leaves fewer faces than this × the face target (an
input at most about as fine as the remesh; TOSCA's wolves are not) is replaced by a subdivision of
every edge, so the decimation always has faces to remove."""

LONG_EDGE = 6.0
"""A large input (decimated directly: :data:`PRE_DECIMATION_FACTOR`) with an edge longer than this × the
remesh's edge length is Loop-subdivided like a small one (:func:`has_long_edges`). The decimation only
lengthens edges, so an input's long edge stays in the remesh, and a true point at its middle is half
its length from every vertex: TOSCA horse7's original has an edge of 10.5 × (0.12 × sqrt(area)), kept
by its remesh, where the best possible vertex map is 0.056 × sqrt(area) off (issue #20's bound: 0.04)."""

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


def meshset(vertices: np.ndarray, faces: np.ndarray):
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(
        pymeshlab.Mesh(
            vertex_matrix=np.ascontiguousarray(vertices, dtype=np.float64),
            face_matrix=np.ascontiguousarray(faces, dtype=np.int32),
        )
    )
    return ms


def meshset_arrays(ms) -> tuple[np.ndarray, np.ndarray]:
    m = ms.current_mesh()
    return (
        np.array(m.vertex_matrix(), dtype=np.float64, copy=True),
        np.array(m.face_matrix(), dtype=np.int64, copy=True),
    )


def remesh_edge_length(vertices: np.ndarray, faces: np.ndarray, face_goal: int) -> float:
    """The edge length of an equilateral triangulation of the surface's area with ``face_goal`` faces
    (input units): the remesh's typical edge."""
    return float(np.sqrt(4.0 * face_areas(TriMesh(vertices, faces)).sum() / (np.sqrt(3.0) * face_goal)))


def has_long_edges(vertices: np.ndarray, faces: np.ndarray, face_goal: int) -> bool:
    """Whether an edge of the (V, 3) / (F, 3) surface is longer than :data:`LONG_EDGE` × the remesh's
    edge length (:func:`remesh_edge_length`)."""
    tri = vertices[faces]
    longest = float(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max())
    return longest > LONG_EDGE * remesh_edge_length(vertices, faces, face_goal)


def loop_subdivided(vertices: np.ndarray, faces: np.ndarray, face_goal: int):
    """A pymeshlab mesh set holding ONE Loop subdivision of (V, 3) ``vertices`` / (F, 3) ``faces``
    (input units) that splits the edges longer than :data:`SUBDIVISION_EDGE` × the edge length of
    an equilateral triangulation of the surface's area with ``face_goal`` faces; every edge is split
    instead where that leaves fewer than :data:`SUBDIVISION_MIN_FACES` × ``face_goal`` faces.

    Splitting every edge (the remesher before issue #31) quadrupled the faces the decimation then
    removes: on TOSCA centaur3 (31.5k faces) 126k faces, 1.9 CPU-s of decimation, against 55k faces
    and 0.47 CPU-s with the same or better triangles (99.9th-percentile edge 3.89 vs 3.87 × the
    median, faces with an angle under 10 degrees 391 vs 825)."""
    import pymeshlab

    edge = SUBDIVISION_EDGE * remesh_edge_length(vertices, faces, face_goal)
    ms = meshset(vertices, faces)
    ms.meshing_surface_subdivision_loop(iterations=1, threshold=pymeshlab.PureValue(edge))
    if ms.current_mesh().face_number() < SUBDIVISION_MIN_FACES * face_goal:
        ms = meshset(vertices, faces)
        ms.meshing_surface_subdivision_loop(iterations=1, threshold=pymeshlab.PercentageValue(0))
    return ms


def pymeshlab_decimate(ms, target_faces: int, **settings) -> None:
    """pymeshlab's quadric edge collapse of ``ms``'s mesh to ``target_faces`` faces (``_DECIMATION``,
    with ``settings`` overriding it)."""
    ms.meshing_decimation_quadric_edge_collapse(targetfacenum=int(max(target_faces, 4)), **{**_DECIMATION, **settings})


def _decimation_problem(vertices: np.ndarray, faces: np.ndarray, topology: tuple[int, int]) -> str | None:
    """Why a decimation result ((V, 3) ``vertices``, (F, 3) ``faces``) of a surface whose
    :func:`surface_topology` is ``topology`` breaks a remesh guarantee, or None if it keeps them all:
    every vertex referenced, one component, no non-manifold edge or vertex, no misoriented edge, the
    Euler characteristic and the boundary loops kept."""
    from becos.core.mesh import non_manifold_vertices

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
    euler, loops = surface_topology(faces, n)
    if (euler, loops) != tuple(topology):
        return f"topology changed: Euler characteristic {euler}, {loops} boundary loops (input: {topology[0]}, {topology[1]})"
    return None


def fast_decimate(
    vertices: np.ndarray, faces: np.ndarray, target_faces: int, topology: tuple[int, int], stats: dict, step: str
) -> tuple[np.ndarray, np.ndarray]:
    """Quadric decimation of (V, 3) ``vertices`` / (F, 3) ``faces`` to ``target_faces`` faces with
    fast-simplification (on a copy scaled to :data:`FAST_SIMPLIFICATION_SIZE`), checked by
    :func:`_decimation_problem` against the input's ``topology``. A result that breaks a guarantee
    (or an exception of the extension) is dropped and the call is made with pymeshlab
    (:func:`pymeshlab_decimate`) instead: a warning, and ``"<step>: <problem>"`` appended to
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
    ms = meshset(vertices, faces)
    pymeshlab_decimate(ms, target)
    return meshset_arrays(ms)


def to_vertex_target(
    sub_v: np.ndarray,
    sub_f: np.ndarray,
    target_vertices: int,
    stats: dict,
    decimator: str = DECIMATORS[0],
    topology: tuple[int, int] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Decimate the subdivided mesh until it has ``target_vertices`` vertices (one component).

    The first decimation of each attempt is made by ``decimator`` (fast-simplification's result is
    checked against ``topology``, :func:`fast_decimate`); the continuation to the exact count is
    always pymeshlab's (topology-preserving; cheap: the mesh is already small). The first decimation
    asks for a face count that leaves a few vertices more than the target whatever the boundary
    (``topology``: the input's Euler characteristic, :func:`surface_topology`; 2 if None); the
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
            ms = meshset(*fast_decimate(sub_v, sub_f, first_faces, topology, stats, "decimation"))
        else:
            ms = meshset(sub_v, sub_f)
            pymeshlab_decimate(ms, first_faces)
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
                pymeshlab_decimate(ms, m.face_number() - 2 * excess, preserveboundary=True)
            else:
                # every collapse removes one vertex and one (boundary) or two faces: asking for `excess`
                # fewer faces removes between excess/2 and excess vertices, so the target is never passed
                pymeshlab_decimate(ms, m.face_number() - excess)
            if (ms.current_mesh().vertex_number(), ms.current_mesh().face_number()) == before:
                if keep_boundary:  # stalled with the boundary kept: continue with boundary collapses too
                    keep_boundary = False
                    continue
                break  # stalled
        v, f = meshset_arrays(ms)
        v, f, dropped = largest_component(v, f)
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
