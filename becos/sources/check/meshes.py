"""Mesh files of the dataset check: the cheap completeness check of a file, the full inspection that
says how remeshing will repair it, and the arrays the class-template and edge checks compare.

The cheap check (:func:`check_mesh_file`) is :func:`becos.core.formats.check_file` (one module per file
format, ~10 ms per 5 MB file); ``full_parse`` adds :func:`becos.core.mesh.read_mesh` (~0.4 s per 50k-vertex
mesh). :func:`inspect_mesh_file` lists the repairs of :func:`becos.core.mesh.surface_for_remeshing`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from becos.core.formats import check_file
from becos.core.formats.off import read_off


def check_mesh_file(path: str | Path, full_parse: bool = False) -> tuple[int, int]:
    """Cheap check that a mesh file is complete (see :mod:`becos.sources.check`; :func:`becos.core.formats.check_file`);
    returns (V, F) counts.

    For OBJ the counts are the numbers of ``v`` and ``f`` lines. ``full_parse`` also reads the mesh
    with :func:`becos.core.mesh.read_mesh` and returns its array sizes.

    Raises:
        InputFileError: missing, empty, truncated or unparsable file.
    """
    counts = check_file(path)
    if full_parse:
        from becos.core.mesh import read_mesh

        mesh = read_mesh(path)
        counts = (mesh.n_vertices, mesh.n_faces)
    return counts


def inspect_mesh_file(path: str | Path):
    """Check a mesh file completely and say how remeshing will repair it.

    The cheap check of :func:`check_mesh_file`, then :func:`becos.core.mesh.read_mesh` (NaN coordinates,
    face indices out of range, OFF header counts) and :func:`becos.core.mesh.surface_for_remeshing`
    (faces with a repeated index, zero-area and duplicate faces, unreferenced vertices, extra
    components, inconsistent winding).

    Returns:
        The :class:`becos.core.mesh.MeshRepair` report (``needs_attention`` is False for a clean mesh).

    Raises:
        InputFileError: any problem no repair handles, naming the file, the problem and the fix.
    """
    from becos.core.mesh import read_mesh, surface_for_remeshing

    path = Path(path)
    check_mesh_file(path)
    return surface_for_remeshing(read_mesh(path), source=path)[1]


def mesh_arrays(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) float64 vertices and (F, 3) int64 faces of a mesh file that passed the cheap check.

    Triangle OFF files are read by :func:`becos.core.formats.off.read_off` (numpy, ~4x faster than trimesh);
    other files with :func:`becos.core.mesh.read_mesh`."""
    path = Path(path)
    if path.suffix.lower() == ".off":
        arrays = read_off(path.read_bytes())
        if arrays is not None:
            return arrays
    from becos.core.mesh import read_mesh

    mesh = read_mesh(path)
    return mesh.vertices, mesh.faces
