"""Remeshing a shape to ~9,000–10,000 vertices, with exact maps to and from the original surface.

Input: a mesh ((V, 3) float vertices, (F, 3) int faces) and a vertex or face target. Output:
:class:`Remeshed`, the remesh in the input's units and frame (nothing scaled or centred), with
``to_original`` (every remeshed vertex exactly on the input surface) and ``from_original`` (each input
vertex to a point of the remesh; face -1 where the repaired copy dropped it). With ``target_vertices``
the vertex count is exact unless decimation stalls (then within 1 %, reported by
:func:`remesh_with_stats`). One module per step: ``shape`` (repair, orientation), ``jitter``, ``decimate``,
``snap``, ``maps``; ``pipeline`` runs them in order. Each step, why, and measurements: docs/design/remesh.md.
"""

from becos.build.remesh.decimate import DECIMATORS, FAST_SIMPLIFICATION_SIZE, PRE_DECIMATION_FACTOR
from becos.build.remesh.diagnostics import coincident_original_vertices, intrinsic_coincidence, shared_vertex_share
from becos.build.remesh.files import FILE_FORMAT_VERSION, load_remeshed, save_remeshed, write_ply
from becos.build.remesh.jitter import DEFAULT_JITTER
from becos.build.remesh.maps import (
    FROM_ORIGINAL_DETOUR,
    FROM_ORIGINAL_MIN_COS,
    FROM_ORIGINAL_RINGS,
    Remeshed,
    original_vertex_normals,
)
from becos.build.remesh.pipeline import VERTEX_TARGET_RANGE, remesh, remesh_with_stats, variant_target_vertices
from becos.build.remesh.shape import RemeshInput
from becos.build.remesh.snap import SNAP_ROUNDS
from becos.build.remesh.topology import mesh_checks

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
