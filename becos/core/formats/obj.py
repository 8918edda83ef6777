"""OBJ files: the cheap structure check (``v``/``f`` line counts, the last line). The arrays are read by
trimesh (:func:`becos.core.mesh.read_mesh`)."""

from __future__ import annotations

import re

from becos.core.formats.problems import NAN_FIX, FormatProblem
from becos.core.formats.text import TextLines, line_at, parse_numbers

_OBJ_V = re.compile(rb"^v[ \t]", re.MULTILINE)
_OBJ_F = re.compile(rb"^f[ \t]", re.MULTILINE)


def check_obj(data: bytes) -> tuple[int, int]:
    n_vertices = len(_OBJ_V.findall(data))
    n_faces = len(_OBJ_F.findall(data))
    if n_vertices == 0 or n_faces == 0:
        raise ValueError(f"holds {n_vertices} vertex lines and {n_faces} face lines (empty or truncated mesh)")
    bad = re.search(rb"^v[ \t][^\n]*?(nan|inf)", data, re.MULTILINE | re.IGNORECASE)
    if bad is not None:
        line = data.count(b"\n", 0, bad.start()) + 1
        raise FormatProblem(f"line {line} ({line_at(data, bad.start())!r}) holds a NaN or infinite coordinate", NAN_FIX)
    lines = TextLines(data)
    tokens = lines.tokens(len(lines) - 1)
    if tokens[0] == b"v":
        if len(tokens) < 4:
            raise ValueError(f"the last line {b' '.join(tokens)[:80]!r} is cut (truncated file)")
        parse_numbers(tokens[1:4], float, "the last vertex line")
    elif tokens[0] == b"f":
        if len(tokens) < 4:
            raise ValueError(f"the last face line {b' '.join(tokens)[:80]!r} has fewer than 3 corners (truncated file)")
        idx = parse_numbers([t.split(b"/")[0] for t in tokens[1:]], int, "the last face line")
        if any(i == 0 or i > n_vertices or i < -n_vertices for i in idx):
            raise ValueError(f"the last face line uses vertex indices {idx} outside 1..{n_vertices} (truncated file)")
    return n_vertices, n_faces
