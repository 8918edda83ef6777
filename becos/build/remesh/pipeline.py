"""The remesh pipeline of :mod:`becos.build.remesh` (steps 0-7 in order) and the paper's vertex targets."""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from becos.build.remesh.decimate import (
    DECIMATORS,
    PRE_DECIMATION_FACTOR,
    fast_decimate,
    has_long_edges,
    loop_subdivided,
    meshset,
    meshset_arrays,
    pymeshlab_decimate,
    to_vertex_target,
)
from becos.build.remesh.diagnostics import CpuSteps
from becos.build.remesh.jitter import DEFAULT_JITTER, jitter_on_surface
from becos.build.remesh.maps import Remeshed, from_original_map
from becos.build.remesh.shape import RemeshInput
from becos.build.remesh.snap import snap_to_original
from becos.build.remesh.topology import largest_component
from becos.core.mesh import TriMesh
from becos.core.surface_map import SurfaceMap
from becos.errors import InputFileError
from becos.seeding import rng_for, stable_hash

log = logging.getLogger(__name__)

VERTEX_TARGET_RANGE = (9000, 10000)
"""The paper's vertex-count rule: a remesh has a count drawn uniformly in this range (inclusive)."""


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
    ``input_repair``: the counts of :class:`becos.core.mesh.MeshRepair` for step 0, ``cpu_seconds``: CPU
    seconds of this process by step: ``shape`` (the per-shape part, when built here), ``jitter``,
    ``subdivide``, ``decimate``, ``snap``, ``from_original``; ``decimator`` and
    ``decimator_fallbacks``: the calls of fast-simplification whose result broke a guarantee and were
    made with pymeshlab instead, as ``"<step>: <problem>"``; empty for pymeshlab).

    ``jitter`` (fraction, see :data:`DEFAULT_JITTER`; 0 disables it) and ``seed`` (default: derived
    from the mesh content and the target) control step 2 of the pipeline. ``source`` (the mesh's
    file) is named in the repair warning and in errors. ``shape``: the per-shape part of ``mesh``
    (:class:`RemeshInput`) when the caller remeshes several variants of it (built here if None).
    ``decimator``: one of :data:`DECIMATORS`, the quadric decimator of steps 3-4 (:mod:`becos.build.remesh`)."""
    _check_arguments(mesh, target_vertices, target_faces, shape, decimator)
    t0 = time.perf_counter()
    stats: dict = {"dropped_faces": 0, "attempts": 1, "decimator": decimator, "decimator_fallbacks": []}
    cpu = CpuSteps(stats)
    if shape is None:
        # 0. the surface to remesh: a repaired copy (the input itself when clean)
        shape = RemeshInput(mesh, source=source)
    v, f = _decimated(shape, target_vertices, target_faces, jitter, seed, stats, t0, cpu, decimator)
    stats["seconds_decimate"] = time.perf_counter() - t0 - stats["seconds_prepare"]
    # 6. orientation vote and snap onto the original surface (its repaired copy: same geometry,
    # no degenerate or duplicate faces; face and vertex indices are translated back below)
    remeshed, face, weights, dist, kept = snap_to_original(shape, v, f, stats)
    cpu.lap("snap")
    # snapped vertices ARE their image (distance 0); unsnapped ones keep their projection distance.
    # Faces are rows of the input as given (the copy keeps each kept row's columns).
    to_original = SurfaceMap(shape.repair.face_index[face], weights, np.where(kept, dist, 0.0))
    # 7. original vertices -> remeshed surface
    from_original = from_original_map(shape, remeshed, face, weights, stats)
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


def _check_arguments(
    mesh: TriMesh,
    target_vertices: int | None,
    target_faces: int | None,
    shape: RemeshInput | None,
    decimator: str,
) -> None:
    """The ValueErrors of :func:`remesh_with_stats`: an unknown ``decimator``, no target or both, a
    target below 4, a ``shape`` made from another mesh."""
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


def _decimated(
    shape: RemeshInput,
    target_vertices: int | None,
    target_faces: int | None,
    jitter: float,
    seed: int | None,
    stats: dict,
    t0: float,
    cpu: CpuSteps,
    decimator: str,
) -> tuple[np.ndarray, np.ndarray]:
    """Steps 1-5 on ``shape``: (V_r, 3) vertices and (F_r, 3) faces of the remesh before the snap
    (:func:`_remesh_surface`), with the step-0 repair counts in ``stats["input_repair"]``. A pymeshlab
    failure becomes an :class:`InputFileError` naming the shape's file."""
    import pymeshlab

    face_goal = int(target_faces) if target_faces is not None else 2 * int(target_vertices)
    try:
        if "oriented" not in shape.__dict__:
            shape.oriented  # noqa: B018 (1. built on first use; timed as the shape's part)
            cpu.lap("shape")
        stats["input_repair"] = shape.repair.counts()
        return _remesh_surface(shape, target_vertices, target_faces, face_goal, jitter, seed, stats, t0, cpu, decimator)
    except pymeshlab.PyMeshLabException as exc:
        message = " ".join(str(exc).split())
        raise InputFileError(
            Path(shape.where),
            f"the remesher (pymeshlab) failed on this surface: {message}",
            "repair the mesh (e.g. MeshLab: Filters > Cleaning and Repairing) or leave the shape out",
        ) from None


def _remesh_surface(
    shape: RemeshInput,
    target_vertices: int | None,
    target_faces: int | None,
    face_goal: int,
    jitter: float,
    seed: int | None,
    stats: dict,
    t0: float,
    cpu: CpuSteps,
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
        v = jitter_on_surface(v, f, float(jitter), rng_for(seed, "jitter"))
    cpu.lap("jitter")
    # 3.-4. pre-decimation of large inputs, one Loop subdivision
    fast = decimator == "fast-simplification"
    topology = shape.topology
    large = len(f) > PRE_DECIMATION_FACTOR * face_goal
    if fast and large:
        v, f = fast_decimate(v, f, int(PRE_DECIMATION_FACTOR * face_goal), topology, stats, "pre-decimation")
    # pymeshlab decimates a large input directly (:mod:`becos.build.remesh`, step 3), unless an edge of it
    # is so long that the remesh would keep it
    if fast or not large or has_long_edges(v, f, face_goal):
        ms = loop_subdivided(v, f, face_goal)
    else:
        ms = meshset(v, f)
    stats["seconds_prepare"] = time.perf_counter() - t0
    cpu.lap("subdivide")
    # decimation to the target
    if target_vertices is not None:
        v, f = to_vertex_target(*meshset_arrays(ms), int(target_vertices), stats, decimator, topology)
    elif fast:
        v, f = fast_decimate(*meshset_arrays(ms), int(target_faces), topology, stats, "decimation")
    else:
        pymeshlab_decimate(ms, int(target_faces))
        v, f = meshset_arrays(ms)
        v, f, dropped = largest_component(v, f)
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

    See :mod:`becos.build.remesh` for the pipeline and guarantees. Exactly one target must be given.
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
