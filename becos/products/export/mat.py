"""MAT v5 files of ULRSSM's ``dist/<k>.mat``: one real (n, n) float32 matrix, streamed to disk in row
blocks with the bytes ``scipy.io.savemat`` would write (``scipy.io.loadmat`` reads them back)."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from becos.products.export.staging import ExportError

_MI_INT8, _MI_INT32, _MI_UINT32, _MI_SINGLE, _MI_MATRIX = 1, 5, 6, 7, 14


_MX_SINGLE_CLASS = 7


MAT_MAX_VERTICES = 32767
"""Largest V of a (V, V) float32 MAT v5 matrix: its element's byte count is a uint32 (4 V² + 48 < 2³²).
scipy's ``loadmat`` (ULRSSM's reader) cannot read the HDF5-based v7.3 files that would hold more."""


_MAT_TEXT = b"MATLAB 5.0 MAT-file, Platform: posix, Created by: becos (scipy.io.loadmat reads it)"


WRITE_CHUNK_BYTES = 32 << 20
"""Bytes per buffered write of a matrix (rows of a cut, gathered at a time)."""


def _mat_pad(nbytes: int) -> int:
    return -nbytes % 8


def mat_prefix(n: int, name: str = "dist") -> bytes:
    """The first bytes of a little-endian MAT v5 file holding one real (n, n) float32 matrix ``name``:
    the 128-byte header (fixed text, no date, so the bytes depend on the matrix alone) and the tags of
    the ``miMATRIX`` element (array flags ``mxSINGLE_CLASS``, dimensions (n, n), name, ``miSINGLE``
    data of 4 n² bytes) laid out as ``scipy.io.savemat`` lays them out. The 4 n² data bytes follow in
    column-major order, then zeros up to a multiple of 8 bytes. For a symmetric matrix column-major is
    row-major: the rows of a C-ordered array are written as they are, in as many pieces as wanted."""
    import struct

    if not 0 <= n <= MAT_MAX_VERTICES:
        raise ExportError(
            f"a {n} x {n} float32 matrix does not fit a MATLAB v5 file (at most {MAT_MAX_VERTICES} rows), "
            f"and ULRSSM's scipy.io.loadmat reads no v7.3 file. Fix: leave out --geodesics for shapes this "
            f"large (ULRSSM computes dist itself), or remesh to fewer vertices"
        )
    label = name.encode("ascii")
    if len(label) <= 4:  # small data element: byte count and type in one word, data in the next four bytes
        name_element = struct.pack("<HH", _MI_INT8, len(label)) + label.ljust(4, b"\0")
    else:
        name_element = struct.pack("<II", _MI_INT8, len(label)) + label + b"\0" * _mat_pad(len(label))
    data = 4 * n * n
    body = (
        struct.pack("<IIII", _MI_UINT32, 8, _MX_SINGLE_CLASS, 0)
        + struct.pack("<IIii", _MI_INT32, 8, n, n)
        + name_element
        + struct.pack("<II", _MI_SINGLE, data)
    )
    header = _MAT_TEXT.ljust(116, b" ") + b"\0" * 8 + struct.pack("<H", 0x0100) + b"IM"
    return header + struct.pack("<II", _MI_MATRIX, len(body) + data + _mat_pad(data)) + body


def mat_size(n: int, name: str = "dist") -> int:
    """Bytes of the MAT v5 file of an (n, n) float32 matrix (:func:`mat_prefix`)."""
    data = 4 * n * n
    return len(mat_prefix(n, name)) + data + _mat_pad(data)


def write_symmetric_mat(path: str | Path, n: int, chunks: Iterable[np.ndarray], name: str = "dist") -> int:
    """Write a symmetric (n, n) float32 matrix as the MAT v5 file ``path`` (variable ``name``),
    atomically, from ``chunks``: consecutive (k, n) float32 row blocks whose rows add up to n (the
    matrix is never whole in memory here). Returns the bytes written; ``scipy.io.loadmat(path)[name]``
    gives the matrix back (float32, (n, n))."""
    from becos.atomic import atomic_path

    data = 4 * n * n
    with atomic_path(path, suffix=".tmp.mat") as tmp:
        with open(tmp, "wb") as fh:
            fh.write(mat_prefix(n, name))
            done = 0
            for chunk in chunks:
                chunk = np.ascontiguousarray(chunk, dtype=np.float32)
                if chunk.ndim != 2 or chunk.shape[1] != n:
                    raise ValueError(f"row block of shape {chunk.shape}, expected (k, {n})")
                if chunk.size:
                    fh.write(memoryview(chunk).cast("B"))
                done += chunk.shape[0]
            if done != n:
                raise ValueError(f"{done} rows written, expected {n}")
            fh.write(b"\0" * _mat_pad(data))
    return Path(path).stat().st_size
