"""Remesh files: the .npz of a :class:`~becos.build.remesh.maps.Remeshed` (both maps) and a PLY to look at."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from becos.atomic import save_npz as atomic_save_npz
from becos.atomic import write_bytes
from becos.build.remesh.maps import Remeshed
from becos.core.mesh import TriMesh
from becos.core.surface_map import SurfaceMap
from becos.errors import InputFileError

FILE_FORMAT_VERSION = 1


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
