"""Triangle meshes: the in-memory type, reading mesh files, and a cache of parsed arrays.

Vertex order is always the file's order (ground truth is indexed by it): files are read with
trimesh ``process=False, maintain_order=True`` and never merged, re-ordered or repaired in place.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from becos.atomic import save_npz as atomic_save_npz
from becos.errors import InputFileError

MESH_SUFFIXES = (".off", ".ply", ".obj")


@dataclass(frozen=True, eq=False)
class TriMesh:
    """A triangle mesh.

    Attributes:
        vertices: (V, 3) float64 positions, in the units and frame of whoever built the mesh.
        faces: (F, 3) int64 vertex indices, counter-clockwise seen from outside where oriented.
    """

    vertices: np.ndarray
    faces: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "vertices", np.ascontiguousarray(self.vertices, dtype=np.float64))
        object.__setattr__(self, "faces", np.ascontiguousarray(self.faces, dtype=np.int64))

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_faces(self) -> int:
        return len(self.faces)

    def with_vertices(self, vertices: np.ndarray) -> "TriMesh":
        """The same connectivity with new (V, 3) positions."""
        return TriMesh(vertices, self.faces)


def check_mesh_arrays(path: str | Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    """Raise :class:`InputFileError` unless the arrays form a usable triangle mesh."""
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) == 0:
        raise InputFileError(path, f"no vertices could be read (vertex array shape {vertices.shape})",
                             "check that the file is a complete OFF/PLY/OBJ mesh (re-download or re-extract it)")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise InputFileError(path, f"no triangles could be read (face array shape {faces.shape})",
                             "check that the file is a complete triangle mesh (re-download or re-extract it)")
    if not np.isfinite(vertices).all():
        bad = int((~np.isfinite(vertices)).any(axis=1).sum())
        raise InputFileError(path, f"{bad} vertices have NaN or infinite coordinates",
                             "re-export or re-download the mesh; becos cannot guess the positions")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InputFileError(path, f"face indices span [{faces.min()}, {faces.max()}] but the file has "
                             f"{len(vertices)} vertices", "the file is truncated or corrupt: re-download it")


def read_mesh(path: str | Path) -> TriMesh:
    """Read an OFF, PLY or OBJ triangle mesh keeping the file's vertex and face order.

    Raises:
        InputFileError: missing file, unknown type, unreadable or inconsistent content.
    """
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise InputFileError(path, "mesh file not found",
                             "check the dataset folder in the config (data_dir) and that the download is complete")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise InputFileError(path, f"unknown mesh type '{path.suffix}'", f"convert it to one of {MESH_SUFFIXES}")
    try:
        loaded = trimesh.load(path, process=False, maintain_order=True, force="mesh", skip_materials=True)
        vertices = np.asarray(loaded.vertices, dtype=np.float64)
        faces = np.asarray(loaded.faces, dtype=np.int64)
    except Exception as exc:  # trimesh raises many types on corrupt input
        raise InputFileError(path, f"could not be parsed as a mesh ({type(exc).__name__}: {exc})",
                             "the file is truncated or corrupt: re-download or re-extract it") from exc
    check_mesh_arrays(path, vertices, faces)
    if path.suffix.lower() == ".off":
        _check_off_header(path, len(vertices), len(faces))
    return TriMesh(vertices, faces)


def _check_off_header(path: Path, n_vertices: int, n_faces: int) -> None:
    """A truncated OFF can still parse (face lines read as vertices): compare with the header's counts."""
    with open(path, "rb") as fh:
        words: list[bytes] = []
        for line in fh:
            words += line.split(b"#")[0].split()
            if (len(words) >= 3 and words[0].upper().endswith(b"OFF")) or len(words) >= 4:
                break
    counts = words[1:3] if words and words[0].upper().endswith(b"OFF") else words[0:2]
    try:
        header_vertices, header_faces = (int(c) for c in counts)
    except ValueError:
        raise InputFileError(path, "the OFF header has no vertex and face counts",
                             "the file is corrupt: re-download or re-extract it") from None
    if (header_vertices, header_faces) != (n_vertices, n_faces):
        raise InputFileError(path, f"the OFF header announces {header_vertices} vertices and {header_faces} faces "
                             f"but {n_vertices} and {n_faces} were read (truncated or corrupt file)",
                             "re-download or re-extract the file")


class MeshCache:
    """Parse each mesh file once: arrays are kept in ``cache_dir`` as .npz, keyed by path, size and mtime.

    Parsing a 50k-vertex OFF with trimesh takes ~0.4 s; reading the cached arrays a few ms.
    ``cache_dir=None`` keeps only an in-process cache.
    """

    def __init__(self, cache_dir: str | Path | None = None, max_in_memory: int = 32):
        self.cache_dir = Path(cache_dir) if cache_dir is not None else None
        self.max_in_memory = max_in_memory
        self._memory: OrderedDict[str, TriMesh] = OrderedDict()

    def _key(self, path: Path) -> str:
        stat = path.stat()
        text = f"{path.resolve()}|{stat.st_size}|{stat.st_mtime_ns}"
        return hashlib.sha1(text.encode()).hexdigest()[:20]

    def load(self, path: str | Path) -> TriMesh:
        """The mesh in ``path`` (see :func:`read_mesh`), from the cache when the file is unchanged."""
        path = Path(path)
        if not path.is_file():
            return read_mesh(path)  # raises the explanatory error
        key = self._key(path)
        if key in self._memory:
            self._memory.move_to_end(key)
            return self._memory[key]
        mesh = None
        if self.cache_dir is not None:
            cached = self.cache_dir / f"{path.stem}-{key}.npz"
            if cached.is_file():
                with np.load(cached) as data:
                    mesh = TriMesh(data["vertices"], data["faces"])
            else:
                mesh = read_mesh(path)
                atomic_save_npz(cached, vertices=mesh.vertices, faces=mesh.faces)
        else:
            mesh = read_mesh(path)
        self._memory[key] = mesh
        while len(self._memory) > self.max_in_memory:  # a long job must not hold every mesh it met
            self._memory.popitem(last=False)
        return mesh
