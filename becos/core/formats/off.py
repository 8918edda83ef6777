"""OFF files: the one header parser (:func:`off_header`), the cheap structure check, and the one OFF reader
of becos (:func:`read_off`; :func:`read_plain_off` for the files :func:`becos.core.mesh.read_mesh` reads
without trimesh)."""

from __future__ import annotations

import io

import numpy as np

from becos.core.formats.text import TextLines, check_text_body


def off_header(lines: TextLines) -> tuple[int, int, int]:
    """(announced vertices, announced faces, index of the first data line) of an OFF file's lines."""
    words: list[bytes] = []
    header_end = -1
    for i in range(min(len(lines), 4)):
        words += lines.tokens(i)
        if words and not words[0].upper().endswith(b"OFF"):
            break
        if len(words) >= 3:
            header_end = i
            break
    if header_end < 0 or not words[0].upper().endswith(b"OFF"):
        raise ValueError(f"does not start with an OFF header (first words {b' '.join(words[:4])[:60]!r})")
    try:
        n_vertices, n_faces = int(words[1]), int(words[2])
    except ValueError:
        raise ValueError(f"the OFF header {b' '.join(words[:4])!r} has no vertex and face counts") from None
    return n_vertices, n_faces, header_end + 1


def off_data_lines(data: bytes) -> tuple[int, int, int]:
    """(announced vertices, announced faces, non-blank non-comment lines after the header) of OFF bytes.

    Raises:
        ValueError: no OFF header with counts.
    """
    lines = TextLines(data)
    n_vertices, n_faces, first = off_header(lines)
    return n_vertices, n_faces, len(lines) - first


def check_off(data: bytes) -> tuple[int, int]:
    lines = TextLines(data)
    n_vertices, n_faces, first = off_header(lines)
    check_text_body(lines, first, n_vertices, n_faces, "OFF")
    return n_vertices, n_faces


def read_off(data: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """(V, 3) float64 vertices and (F, 3) int64 faces of a triangle OFF file's bytes, else None.

    Read when the header's counts match the data lines exactly (blank lines and ``#`` lines skipped),
    every vertex line holds ``x y z`` and every face line ``3 i j k``. The values are those trimesh reads
    (numpy's conversion of the same tokens), located with numpy, without importing trimesh. Anything else
    (polygons, colours, normals, counts that disagree, a non-number) returns None: :func:`becos.core.mesh.read_mesh`
    then parses the file with trimesh, and :func:`check_off` names what is wrong.
    """
    arrays = _contiguous_arrays(data)
    return arrays if arrays is not None else _triangle_arrays(data, TextLines(data))


def read_plain_off(data: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`read_off` of a PLAIN triangle OFF file's bytes, else None (what :func:`becos.core.mesh.read_mesh`
    reads without trimesh).

    Plain: ASCII, no comment, an ``OFF`` line, a line of three counts, exactly the announced number of
    vertex lines (three numbers each) and face lines (``3 i j k``), nothing else. Anything else returns
    None: :func:`becos.core.mesh.read_mesh` then parses it with trimesh and reports faults precisely.
    """
    arrays = _contiguous_arrays(data)
    if arrays is not None or b"#" in data or not data.isascii():
        return arrays
    lines = TextLines(data)  # blank lines or CR line ends: located line by line
    if len(lines) < 2 or lines.tokens(0) != [b"OFF"]:
        return None
    counts = lines.tokens(1)
    if len(counts) != 3 or not all(c.isdigit() for c in counts):
        return None
    return _triangle_arrays(data, lines)


def _contiguous_arrays(data: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """The arrays of :func:`read_off` for the common layout, else None: no comment, an ``OFF`` line, a
    line of counts, then exactly the announced vertex lines and face lines, no blank line between.

    numpy's C text parser (``np.loadtxt``) on each block: the same float64 and int64 values as the
    token-by-token conversion of :func:`_triangle_arrays` (both round correctly), ~4x faster on TOSCA.
    """
    if b"#" in data or not data.isascii():
        return None
    newlines = np.flatnonzero(np.frombuffer(data, dtype=np.uint8) == ord("\n"))
    if len(newlines) < 2 or data[: newlines[0]].split() != [b"OFF"]:
        return None
    counts = data[newlines[0] + 1 : newlines[1]].split()
    if len(counts) != 3 or not all(c.isdigit() for c in counts):
        return None
    n_vertices, n_faces = int(counts[0]), int(counts[1])
    last_line = 1 + n_vertices + n_faces  # index of the newline ending the last face line
    if n_vertices <= 0 or n_faces <= 0 or len(newlines) < last_line:
        return None
    middle = newlines[1 + n_vertices] + 1
    end = newlines[last_line] if len(newlines) > last_line else len(data)
    if data[end:].strip():
        return None  # more lines than announced
    try:
        vertices = np.loadtxt(io.BytesIO(data[newlines[1] + 1 : middle]), dtype=np.float64, ndmin=2)
        faces = np.loadtxt(io.BytesIO(data[middle:end]), dtype=np.int64, ndmin=2)
    except (ValueError, OverflowError):  # a non-number, or lines of different lengths
        return None
    if vertices.shape != (n_vertices, 3) or faces.shape != (n_faces, 4) or (faces[:, 0] != 3).any():
        return None  # a blank line inside a block, or a face that is no triangle
    return vertices, np.ascontiguousarray(faces[:, 1:])


def _triangle_arrays(data: bytes, lines: TextLines) -> tuple[np.ndarray, np.ndarray] | None:
    """The arrays of :func:`read_off`, from the data ``lines`` of ``data``."""
    try:
        n_vertices, n_faces, first = off_header(lines)
    except (ValueError, IndexError):
        return None
    if n_vertices <= 0 or n_faces <= 0 or len(lines) - first != n_vertices + n_faces:
        return None
    middle, last = first + n_vertices, first + n_vertices + n_faces
    if (lines.token_counts(first, middle) != 3).any() or (lines.token_counts(middle, last) != 4).any():
        return None
    try:
        vertices = np.array(data[lines.starts[first] : lines.ends[middle - 1]].split(), dtype=np.float64)
        faces = np.array(data[lines.starts[middle] : lines.ends[last - 1]].split(), dtype=np.int64)
    except ValueError:  # a non-number
        return None
    if vertices.size != 3 * n_vertices or faces.size != 4 * n_faces or (faces[::4] != 3).any():
        return None  # comment lines inside a block, or a face that is no triangle
    return vertices.reshape(n_vertices, 3), np.ascontiguousarray(faces.reshape(n_faces, 4)[:, 1:])
