"""The reference generator's remesh, reproduced bit for bit (config ``remesher: reference``).

Only with this remesh do the published lists' face targets, rotations and cameras refer to the meshes
they were made for. On the shape's FILE coordinates: × :data:`COORDINATE_FACTOR`, libigl BFS
orientation, one Loop subdivision, fast-simplification to ``desired_n_face_remeshed``, / 1000; nothing
else. :func:`remesh_like_reference` gives it becos's own exact maps (``to_original``: closest point with
a compatible normal, the distance recorded; ``from_original`` likewise); the reference's vertex maps are
kept on :class:`ReferenceRemesh` for comparisons. The procedure step by step: docs/design/remesh.md.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from becos.core.mesh import TriMesh
from becos.errors import InputFileError

COORDINATE_FACTOR = 1000.0
"""The reference multiplies file coordinates by this during remeshing (and divides after)."""


@dataclass(frozen=True, eq=False)
class ReferenceRemesh:
    """The reference's remesh of one mesh, in the input's (file) units and frame.

    Attributes:
        mesh: (V_r, 3) float64 vertices, (F_r, 3) int64 faces exactly as the reference produces them.
        subdivision: (V_s, V) sparse Loop subdivision matrix S of the oriented input (V_s = V + edges).
        subdivided: (V_s, 3) float64 subdivided vertices ``S @ (V × 1000)`` (× 1000 units).
        subdivided_to_remeshed: (V_s,) int64 remeshed vertex each subdivided vertex collapsed into.
        target_faces: the face target asked for.
    """

    mesh: TriMesh
    subdivision: object
    subdivided: np.ndarray
    subdivided_to_remeshed: np.ndarray
    target_faces: int

    @cached_property
    def remeshed_to_source(self) -> np.ndarray:
        """(V_r,) int64: the reference's remeshed -> input vertex map (its ``source_to_remeshed_p2p``).

        For each remeshed vertex, the closest (Euclidean, × 1000 units) subdivided vertex among those
        collapsed into it (ties: the lowest index), then that vertex's largest-weight input vertex."""
        v3 = self.mesh.vertices * COORDINATE_FACTOR
        group = self.subdivided_to_remeshed
        dist = np.sqrt(((v3[group] - self.subdivided) ** 2).sum(axis=1))
        order = np.lexsort((np.arange(len(group)), dist, group))
        first = np.ones(len(order), dtype=bool)
        first[1:] = group[order][1:] != group[order][:-1]
        nearest = np.full(self.mesh.n_vertices, -1, dtype=np.int64)
        nearest[group[order][first]] = order[first]
        sub_to_source = np.asarray(self.subdivision.argmax(axis=1)).ravel()
        return sub_to_source[nearest]

    @cached_property
    def source_to_remeshed(self) -> np.ndarray:
        """(V,) int64: the reference's input -> remeshed vertex map (its ``remeshed_to_source_p2p``):
        the remeshed vertex into which the input vertex's own (even) subdivided vertex collapsed."""
        even = np.asarray(self.subdivision.argmax(axis=0)).ravel()
        return self.subdivided_to_remeshed[even]


def reference_remesh(mesh: TriMesh, target_faces: int, *, source: str | Path | None = None) -> ReferenceRemesh:
    """Remesh ``mesh`` (FILE coordinates, as read) exactly as the reference generator does.

    Args:
        mesh: the shape as read from its file (vertex order and face rows kept), file units.
        target_faces: the face target (the published lists' ``desired_n_face_remeshed``).
        source: the mesh's file, named in errors.

    Returns:
        :class:`ReferenceRemesh` (file units). Deterministic: the same arrays give the same bytes.

    Raises:
        ValueError: a target below 4.
        InputFileError: libigl or fast-simplification failed on the mesh (names ``source``).
    """
    import fast_simplification
    import igl

    from becos.core.mesh import duplicate_faces, repeated_index_faces

    if int(target_faces) < 4:
        raise ValueError(f"reference remesh: face target must be at least 4, got {target_faces}")
    where = Path(source) if source is not None else Path(f"<mesh with {mesh.n_vertices} vertices>")
    # fast-simplification crashes the process (no exception) on these; the reference would too
    repeated = int(repeated_index_faces(mesh.faces).sum())
    duplicated = int((duplicate_faces(mesh.faces, mesh.n_vertices) >= 0).sum()) if not repeated else 0
    if repeated or duplicated:
        what = (
            f"{repeated} faces name a vertex twice"
            if repeated
            else f"{duplicated} faces repeat another face's vertices"
        )
        raise InputFileError(
            where,
            f"{what}; the reference remesher (fast-simplification) cannot decimate such a mesh",
            "remove those faces from the file, or use remesher: becos (it repairs a copy)",
        )
    if 4 * mesh.n_faces <= int(target_faces):
        raise InputFileError(
            where,
            f"the face target {int(target_faces)} is not below the {4 * mesh.n_faces} faces of "
            "the subdivided mesh, so the reference remesh is undefined",
            "use a smaller face target (remesh_variants / the pair list), or remesher: becos",
        )
    try:
        v1 = mesh.vertices * COORDINATE_FACTOR
        f1, _ = igl.bfs_orient(np.ascontiguousarray(mesh.faces, dtype=np.int64))
        s, f2 = igl.loop_matrix(f1, len(v1))
        v2 = s @ v1
        v3, f3, collapses = fast_simplification.simplify(v2, f2, target_count=int(target_faces), return_collapses=True)
        _, _, v2_v3 = fast_simplification.replay_simplification(v2.astype(np.float32), f2, collapses)
    except Exception as exc:  # the C++ extensions raise RuntimeError/ValueError on broken input
        raise InputFileError(
            where,
            f"the reference remesher (libigl + fast-simplification) failed: {type(exc).__name__}: {exc}",
            "repair the mesh (single manifold surface) or use remesher: becos",
        ) from exc
    return ReferenceRemesh(
        TriMesh(v3 / COORDINATE_FACTOR, f3), s, v2, np.asarray(v2_v3, dtype=np.int64), int(target_faces)
    )


def exact_maps(original: TriMesh, remeshed: TriMesh):
    """becos's exact maps between an original surface and a remesh of it (same frame and units).

    Returns ``(to_original, from_original)`` (:class:`becos.core.surface_map.SurfaceMap`):

    - ``to_original`` (V_r,): each remeshed vertex -> the closest point of the original surface whose
      face normal is compatible with the remeshed vertex normal (never across a contact between
      touching parts); faces are rows of ``original.faces``; distance in the frame's units.
    - ``from_original`` (V,): each original vertex -> the closest compatible point of the remeshed
      surface (faces are rows of ``remeshed.faces``).

    Both surfaces may be wound either way (the locator detects a global sign flip).
    """
    from becos.build.remesh import original_vertex_normals
    from becos.core.geometry import SurfaceLocator, vertex_normals
    from becos.core.surface_map import SurfaceMap

    face, weights, dist = SurfaceLocator(original).closest(remeshed.vertices, vertex_normals(remeshed))
    to_original = SurfaceMap(face, weights, dist)
    face, weights, dist = SurfaceLocator(remeshed).closest(original.vertices, original_vertex_normals(original))
    return to_original, SurfaceMap(face, weights, dist)


def to_common_frame(vertices: np.ndarray, scale: float, centre: np.ndarray, frame_rotation: np.ndarray) -> np.ndarray:
    """(N, 3) file-unit vertices -> becos's common frame: ``(V × scale − centre) @ frame_rotation``
    (:func:`becos.sources.datasets.prepare_shape`; ``centre`` is the ORIGINAL mesh's scaled vertex mean)."""
    return (np.asarray(vertices, dtype=np.float64) * float(scale) - np.asarray(centre, dtype=np.float64)) @ np.asarray(
        frame_rotation, dtype=np.float64
    )


def remesh_like_reference(file_mesh: TriMesh, prepared, target_faces: int, *, source: str | Path | None = None):
    """The reference's remesh of a shape as a :class:`becos.build.remesh.Remeshed` in the common frame.

    Args:
        file_mesh: the shape as read from its file (file units).
        prepared: its :class:`becos.sources.datasets.PreparedShape` (common frame: scaled, centred, rotated).
        target_faces: ``desired_n_face_remeshed``.
        source: the mesh file, named in errors.

    Returns ``(remeshed, stats)``: the Remeshed (vertices in the common frame, the reference's faces,
    :func:`exact_maps` against ``prepared.mesh``; ``target_faces`` set) and a dict of diagnostics
    (seconds of the remesh and of the maps; mean / max ``to_original`` distance in common-frame units).
    """
    from becos.build.remesh import Remeshed

    entry = prepared.entry
    t0 = time.perf_counter()
    ref = reference_remesh(file_mesh, target_faces, source=source)
    t1 = time.perf_counter()
    mesh = TriMesh(
        to_common_frame(ref.mesh.vertices, entry.scale, prepared.centre, entry.frame_rotation), ref.mesh.faces
    )
    to_original, from_original = exact_maps(prepared.mesh, mesh)
    seconds = time.perf_counter() - t0
    stats = {
        "seconds_remesh": t1 - t0,
        "seconds_maps": seconds - (t1 - t0),
        "seconds": seconds,
        "to_original_distance_mean": float(to_original.distance.mean()),
        "to_original_distance_max": float(to_original.distance.max()),
    }
    return Remeshed(mesh, to_original, from_original, None, int(target_faces), seconds), stats


# ----------------------------------------------------------------------------------------------
# the reference's frames (facts §7.2, §7.4, §7.5): to compare with its output, or to cast its views


def open3d_rotation(rot_deg_xyz) -> np.ndarray:
    """(3, 3) Open3D ``get_rotation_matrix_from_xyz(radians(rot))`` = Rx @ Ry @ Rz as the reference
    computes it, tiny entries kept (``cos(90°)`` = 6.1e-17; :func:`becos.sources.datasets.frame_rotation_matrix`
    zeroes them, which changes results by an ulp). Row-vector convention: ``V @ R``."""
    a, b, c = np.radians(np.asarray(rot_deg_xyz, dtype=np.float64).reshape(3))
    rx = np.array([[1.0, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1.0, 0], [-np.sin(b), 0, np.cos(b)]])
    rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1.0]])
    return rx @ ry @ rz


def reference_pose(vertices: np.ndarray, scale: float, rotation: np.ndarray) -> np.ndarray:
    """(N, 3) the reference's frame of a remeshed full shape before alignment, as it computes it:
    ``V × scale``, minus the vertex mean, ``@ rotation`` (dataset frame, :func:`open3d_rotation`),
    minus the vertex mean again (``align_shapes``). ``vertices`` in file units."""
    v = np.asarray(vertices, dtype=np.float64) * float(scale)
    v = v - np.mean(v, axis=0)
    v = np.dot(v, np.asarray(rotation, dtype=np.float64))
    return v - np.mean(v, axis=0)


def sqrt_area(vertices: np.ndarray, faces: np.ndarray) -> float:
    """The reference's ``surface_area``: sqrt of the total area (its potpourri3d vertex areas sum to it)."""
    from becos.core.geometry import surface_area

    return float(np.sqrt(surface_area(TriMesh(vertices, faces))))


def reference_output(
    posed: np.ndarray,
    area: float,
    random_rotation: np.ndarray,
    align_rotation: np.ndarray | None = None,
    align_translation: np.ndarray | None = None,
) -> np.ndarray:
    """(N, 3) the vertices the reference saves for a full shape (``0_<x>.off`` / ``1_<y>.off``).

    ``posed``: :func:`reference_pose`; ``area``: its sqrt-area (info ``surface_area``); Y alone is
    aligned as ``V @ align_rotation + align_translation`` (its translation is not inverted, facts
    §7.4); divided and multiplied back by ``area`` (the unit-area casting frame); ``@ random_rotation``."""
    v = np.array(posed, dtype=np.float64)
    if align_rotation is not None:
        v = v @ np.asarray(align_rotation, dtype=np.float64) + np.asarray(align_translation, dtype=np.float64)
    v /= area
    v *= area
    return np.dot(v, np.asarray(random_rotation, dtype=np.float64))


def undo_reference_output(
    saved: np.ndarray,
    random_rotation: np.ndarray,
    align_rotation: np.ndarray | None = None,
    align_translation: np.ndarray | None = None,
) -> np.ndarray:
    """(N, 3) the inverse of :func:`reference_output`: the saved vertices back in :func:`reference_pose`'s
    frame (rotations are orthogonal: inverted by their transpose)."""
    v = np.asarray(saved, dtype=np.float64) @ np.asarray(random_rotation, dtype=np.float64).T
    if align_rotation is not None:
        v = (v - np.asarray(align_translation, dtype=np.float64)) @ np.asarray(align_rotation, dtype=np.float64).T
    return v
