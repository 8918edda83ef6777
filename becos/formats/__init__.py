"""Mesh file formats, one module each (the model is trimesh's ``exchange/``): the cheap structure check
of a file, and for OFF the one reader of becos.

- :mod:`becos.formats.off`: the OFF header, :func:`~becos.formats.off.check_off` and
  :func:`~becos.formats.off.read_off` (plain triangle OFF, numpy; :func:`becos.mesh.read_mesh` uses it);
- :mod:`becos.formats.ply`: :func:`~becos.formats.ply.check_ply` (ASCII and binary, from the header
  and the file size);
- :mod:`becos.formats.obj`: :func:`~becos.formats.obj.check_obj`;
- :mod:`becos.formats.text`: data lines of text formats located with numpy, and the line-numbered
  checks of vertex and face lines that OFF and ASCII PLY share.

PLY, OBJ and irregular OFF files are read by trimesh (:func:`becos.mesh.read_mesh`). The checks are
what :func:`becos.check.check_mesh_file` runs on every mesh of a dataset (~10 ms per 5 MB file);
:func:`check_file` dispatches on the suffix.
"""

from __future__ import annotations

from pathlib import Path

from becos.errors import InputFileError
from becos.formats.obj import check_obj
from becos.formats.off import check_off
from becos.formats.ply import check_ply
from becos.formats.problems import TRUNCATED_FIX


def check_file(path: str | Path) -> tuple[int, int]:
    """Cheap check that a mesh file is complete (see :mod:`becos.check`); returns (V, F) counts.

    For OBJ the counts are the numbers of ``v`` and ``f`` lines.

    Raises:
        InputFileError: missing, empty, truncated or unparsable file.
    """
    path = Path(path)
    fix = TRUNCATED_FIX
    if not path.is_file():
        raise InputFileError(path, "mesh file not found", fix)
    size = path.stat().st_size
    if size == 0:
        raise InputFileError(path, "the mesh file is empty (0 bytes)", fix)
    suffix = path.suffix.lower()
    try:
        if suffix == ".off":
            counts = check_off(path.read_bytes())
        elif suffix == ".ply":
            counts = check_ply(path, size)
        elif suffix == ".obj":
            counts = check_obj(path.read_bytes())
        else:
            raise ValueError(f"unknown mesh type '{suffix}' (use .off, .ply or .obj)")
    except (ValueError, IndexError, OverflowError) as exc:
        raise InputFileError(path, str(exc) or type(exc).__name__, getattr(exc, "fix", fix)) from None
    return counts
