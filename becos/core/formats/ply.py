"""PLY files (ASCII and binary): the cheap structure check from the header and the file size. The arrays
are read by trimesh (:func:`becos.core.mesh.read_mesh`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from becos.core.formats.problems import NAN_FIX, FormatProblem
from becos.core.formats.text import TextLines, check_text_body

_PLY_SIZES = {
    "char": 1,
    "uchar": 1,
    "int8": 1,
    "uint8": 1,
    "short": 2,
    "ushort": 2,
    "int16": 2,
    "uint16": 2,
    "int": 4,
    "uint": 4,
    "int32": 4,
    "uint32": 4,
    "float": 4,
    "float32": 4,
    "double": 8,
    "float64": 8,
}
_PLY_DTYPES = {
    "char": "i1",
    "uchar": "u1",
    "int8": "i1",
    "uint8": "u1",
    "short": "i2",
    "ushort": "u2",
    "int16": "i2",
    "uint16": "u2",
    "int": "i4",
    "uint": "u4",
    "int32": "i4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}


def check_ply(path: Path, size: int) -> tuple[int, int]:
    """The (vertices, faces) a PLY file's header announces, once its body fits them: ASCII rows checked
    line by line, binary files by size, first vertex block (NaN/inf) and last face row. Raises
    ValueError (or :class:`FormatProblem`) saying what is wrong."""
    with open(path, "rb") as fh:
        head = fh.read(65536)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        raise ValueError("does not start with a PLY header ending in end_header")
    body_start = head.find(b"\n", end) + 1
    if body_start <= 0:
        raise ValueError("the PLY header is cut after end_header (truncated file)")
    fmt, elements = _ply_header(head[:end])
    counts = {e[0]: e[1] for e in elements}
    n_vertices, n_faces = counts.get("vertex", 0), counts.get("face", 0)
    if n_vertices <= 0 or n_faces <= 0:
        raise ValueError(f"the PLY header announces {n_vertices} vertices and {n_faces} faces (empty mesh)")
    if fmt == "ascii":
        lines = TextLines(path.read_bytes(), body_start)
        if [e[0] for e in elements][:2] != ["vertex", "face"]:  # unusual element order: count rows only
            total = sum(e[1] for e in elements)
            if len(lines) < total:
                raise ValueError(
                    f"the PLY header announces {total} element rows but only {len(lines)} data lines "
                    "follow (truncated file)"
                )
            return n_vertices, n_faces
        check_text_body(lines, 0, n_vertices, n_faces, "PLY", exact=len(elements) == 2)
        return n_vertices, n_faces
    if fmt not in ("binary_little_endian", "binary_big_endian"):
        raise ValueError(f"unknown PLY format {fmt!r}")
    need = body_start + sum(_binary_row_bytes(name, props) * count for name, count, props in elements)
    if size < need:
        raise ValueError(
            f"the binary PLY header announces {n_vertices} vertices and {n_faces} triangles, which need "
            f"at least {need} bytes, but the file has {size} (truncated file)"
        )
    order = "<" if fmt == "binary_little_endian" else ">"
    _check_binary_vertices(path, body_start, elements[0], n_vertices, order)
    if size == need:
        _check_last_binary_face(path, size, elements[-1], n_vertices, order)
    return n_vertices, n_faces


def _ply_header(header: bytes) -> tuple[str | None, list[list]]:
    """The format and the elements ``[name, count, [("scalar", type, name) | ("list", count type,
    index type, name)]]`` of a PLY header (the bytes before ``end_header``)."""
    fmt = None
    elements: list[list] = []
    for raw in header.decode("ascii", errors="replace").splitlines():
        parts = raw.split()
        if not parts:
            continue
        if parts[0] == "format" and len(parts) >= 2:
            fmt = parts[1]
        elif parts[0] == "element" and len(parts) >= 3:
            elements.append([parts[1], int(parts[2]), []])
        elif parts[0] == "property" and elements:
            if len(parts) >= 5 and parts[1] == "list":
                elements[-1][2].append(("list", parts[2], parts[3], parts[4]))
            elif len(parts) >= 3:
                elements[-1][2].append(("scalar", parts[1], parts[2]))
    return fmt, elements


def _binary_row_bytes(name: str, props: list) -> int:
    """Bytes of one binary row of element ``name`` (a face's lists counted as triangles, other lists empty)."""
    row = 0
    for prop in props:
        if prop[0] == "scalar":
            row += _PLY_SIZES.get(prop[1], 4)
        else:
            corners = 3 if name == "face" else 0
            row += _PLY_SIZES.get(prop[1], 1) + corners * _PLY_SIZES.get(prop[2], 4)
    return row


def _check_binary_vertices(path: Path, body_start: int, first_element: list, n_vertices: int, order: str) -> None:
    """FormatProblem if a float vertex property of a leading all-scalar ``vertex`` element is NaN or inf."""
    if first_element[0] == "vertex" and first_element[2] and all(p[0] == "scalar" for p in first_element[2]):
        dtype = np.dtype([(f"p{i}", order + _PLY_DTYPES.get(p[1], "f4")) for i, p in enumerate(first_element[2])])
        with open(path, "rb") as fh:
            fh.seek(body_start)
            block = np.frombuffer(fh.read(dtype.itemsize * n_vertices), dtype=dtype, count=n_vertices)
        for i, p in enumerate(first_element[2]):
            column = block[f"p{i}"]
            if column.dtype.kind == "f" and not np.isfinite(column).all():
                bad = int(np.flatnonzero(~np.isfinite(column))[0])
                raise FormatProblem(f"vertex {bad} has a NaN or infinite '{p[2]}' coordinate", NAN_FIX)


def _check_last_binary_face(path: Path, size: int, last: list, n_vertices: int, order: str) -> None:
    """ValueError unless the file's last row, when the last element is a face list alone, is a triangle
    over the vertices (a file of exactly the announced size ends on it)."""
    if last[0] == "face" and len(last[2]) == 1 and last[2][0][0] == "list":
        count_type, index_type = last[2][0][1:3]
        row = _PLY_SIZES.get(count_type, 1) + 3 * _PLY_SIZES.get(index_type, 4)
        with open(path, "rb") as fh:
            fh.seek(size - row)
            tail = fh.read(row)
        k = int(np.frombuffer(tail, order + _PLY_DTYPES.get(count_type, "u1"), count=1)[0])
        idx = np.frombuffer(tail, order + _PLY_DTYPES.get(index_type, "i4"), offset=_PLY_SIZES.get(count_type, 1))
        if k != 3 or idx.min() < 0 or idx.max() >= n_vertices:
            raise ValueError(f"the last face row ({k}: {idx.tolist()}) is not a triangle over [0, {n_vertices})")
