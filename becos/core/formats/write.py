"""OFF and VTS text, as the exports write them (:mod:`becos.products.export`).

Vertices are written exactly as stored in the record (its final frame, dataset scale unless the record
is area-normalised), as shortest round-trip decimal strings, so that parsing the text gives back the
same float64 values.
"""

from __future__ import annotations

import numpy as np


def off_text(vertices: np.ndarray, faces: np.ndarray) -> str:
    """OFF text: ``OFF``, ``nV nF 0``, one ``x y z`` line per vertex, one ``3 i j k`` line per face.

    Args:
        vertices: (V, 3) float positions, written as shortest round-trip decimal strings (numpy's
            float64 ``str``), so ``float(token)`` gives back the exact float64 value.
        faces: (F, 3) int 0-based vertex indices.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"OFF needs (V, 3) vertices and (F, 3) faces; got {v.shape} and {f.shape}")
    if not np.isfinite(v).all():
        raise ValueError("OFF vertices must be finite")
    return f"OFF\n{len(v)} {len(f)} 0\n" + _rows_text(v.astype(str)) + _rows_text(f.astype(str), lead="3 ")


def _rows_text(cells: np.ndarray, lead: str = "") -> str:
    """(N, C) strings -> N lines ``<lead>c0 c1 ... c(C-1)``, each ending in a newline (one join over
    an interleaved token array; no per-row Python code)."""
    n, c = cells.shape
    if n == 0:
        return ""
    offset = 1 if lead else 0
    tokens = np.empty((n, offset + 2 * c), dtype=object)
    if lead:
        tokens[:, 0] = lead
    tokens[:, offset::2] = cells
    tokens[:, offset + 1 :: 2] = [" "] * (c - 1) + ["\n"]
    return "".join(tokens.ravel().tolist())


def vts_text(indices: np.ndarray) -> str:
    """One integer per line (PSMAL ``.vts``): 0-based target vertex index, -1 = no counterpart."""
    return _rows_text(np.asarray(indices, dtype=np.int64).reshape(-1, 1).astype(str))
