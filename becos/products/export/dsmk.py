"""DeepShapeMatchingKit's geodesic cache layout: its file names (:func:`dsmk_cache_name`), the pointer
files that read a geo-lora matrix instead of holding a copy (:func:`save_dsmk_pointer`), and which shapes
its loader asks geodesics for (:func:`dsmk_reads`). Written by
:func:`becos.products.export.geodesics.write_geodesic_matrices`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

DSMK_FOLDER = "dsmk"
"""Folder of DeepShapeMatchingKit's geodesic cache layout (:func:`write_geodesic_matrices`)."""


def dsmk_cache_name(vertices: np.ndarray, faces: np.ndarray) -> str:
    """DeepShapeMatchingKit's geodesic cache file name of a shape, ``<sha1>_0.npz``, as its
    ``BeCoSDataset`` (``shape_scale: default``) looks it up: ``utils.cache_util.get_cached_compute`` hashes
    the loaded OFF's vertices as float32 and its faces as int64 (``hash_arrays``: SHA-1 over the raw bytes
    of each array in turn); ``_0`` is the first slot of its collision chain.

    Args:
        vertices: (V, 3) the shape's written vertices (any float dtype; cast to float32 as the loader does).
        faces: (F, 3) its faces.
    """
    import hashlib

    digest = hashlib.sha1()
    digest.update(np.ascontiguousarray(vertices, dtype=np.float32).view(np.uint8))
    digest.update(np.ascontiguousarray(faces, dtype=np.int64).view(np.uint8))
    return f"{digest.hexdigest()}_0.npz"


class _NpyFile:
    """Pickles as ``numpy.load(path)``."""

    def __init__(self, path: str):
        self.path = path

    def __reduce__(self):
        return (np.load, (self.path,))


class _ScaledNpyFile:
    """Pickles as ``operator.mul(numpy.load(path), scale)``: the (V, V) float32 file times a Python float
    (float32 arithmetic, the same bytes as ``array * np.float32(scale)``). Only ``numpy.load`` and
    ``_operator.mul`` are named, so any numpy version reads it."""

    def __init__(self, path: str, scale: float):
        self.path, self.scale = path, float(scale)

    def __reduce__(self):
        import operator

        return (operator.mul, (_NpyFile(self.path), self.scale))


def save_dsmk_pointer(path: str | Path, vertices: np.ndarray, faces: np.ndarray, target: Path, scale: float) -> int:
    """Write DeepShapeMatchingKit's cache file ``path`` (:func:`dsmk_cache_name`) without a copy of the
    matrix: ``verts`` (V, 3) float32 and ``faces`` (F, 3) int64 as its cache holds them, and ``result``
    a pickle that reads the geo-lora file ``target`` (absolute; (V, V) float32, divided by the sqrt-area)
    and multiplies it by ``scale`` (the sqrt-area), so the loader's ``np.load(path,
    allow_pickle=True)["result"]`` is the (V, V) float32 matrix in the units of the vertices, equal to
    the copy :func:`write_geodesic_matrices` would write. A few hundred bytes plus the mesh; if
    ``target`` is gone (the export moved), the lookup raises FileNotFoundError, which the loader's
    cache treats as a miss: it computes the matrix itself and replaces this file. Atomic; returns the
    bytes written."""
    import io
    import pickle
    import zipfile

    from becos.atomic import atomic_path

    result = io.BytesIO()
    np.lib.format.write_array_header_1_0(result, {"descr": "|O", "fortran_order": False, "shape": ()})
    pickle.dump(_ScaledNpyFile(str(Path(target).resolve()), scale), result, protocol=2)
    members = {
        "verts.npy": np.ascontiguousarray(vertices, dtype=np.float32),
        "faces.npy": np.ascontiguousarray(faces, dtype=np.int64),
    }
    with atomic_path(path, suffix=".tmp.npz") as tmp:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_STORED) as z:
            for name, array in members.items():
                with z.open(zipfile.ZipInfo(name), "w") as fh:  # default timestamp 1980-01-01, as numpy's
                    np.lib.format.write_array(fh, array, allow_pickle=False)
            z.writestr(zipfile.ZipInfo("result.npy"), result.getvalue())
    return Path(path).stat().st_size


def dsmk_reads(setting: str, side: int) -> bool:
    """Whether DeepShapeMatchingKit's BeCoSDataset asks for the geodesics of this shape: only the first
    shape of each pair it forms is given ``dist``; it forms (0, 1) always and (1, 0) for F2F and P2P."""
    return side == 0 or setting in ("partial_partial", "full_full")
