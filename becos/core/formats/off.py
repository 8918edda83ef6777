"""OFF files: the one header parser (:func:`off_header`), the cheap structure check, and the one OFF reader
of becos (:func:`read_off`; :func:`read_plain_off` for the files :func:`becos.core.mesh.read_mesh` reads
without trimesh)."""

from __future__ import annotations

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
    return _triangle_arrays(data, TextLines(data))


def read_plain_off(data: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`read_off` of a PLAIN triangle OFF file's bytes, else None (what :func:`becos.core.mesh.read_mesh`
    reads without trimesh).

    Plain: ASCII, no comment, an ``OFF`` line, a line of three counts, exactly the announced number of
    vertex lines (three numbers each) and face lines (``3 i j k``), nothing else. Anything else returns
    None: :func:`becos.core.mesh.read_mesh` then parses it with trimesh and reports faults precisely.
    """
    if b"#" in data or not data.isascii():
        return None
    lines = TextLines(data)
    if len(lines) < 2 or lines.tokens(0) != [b"OFF"]:
        return None
    counts = lines.tokens(1)
    if len(counts) != 3 or not all(c.isdigit() for c in counts):
        return None
    return _triangle_arrays(data, lines)


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
