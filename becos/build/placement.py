"""A shape's vertices in a pair record's final frame (:mod:`becos.build.record`): Y moved onto X, divided
by the full shape's sqrt-area when area-normalised, then turned by the shape's random rotation. One
definition for the pairs stage that places them and the readers that place a remesh again
(:mod:`becos.build.record_sources`)."""

from __future__ import annotations

import numpy as np

from becos.core.align import RigidTransform


def place(
    vertices: np.ndarray, norm: float, rotation: np.ndarray, alignment: RigidTransform | None = None
) -> np.ndarray:
    """(N, 3) ``vertices`` (common frame, dataset scale) in a record's final frame: moved by
    ``alignment`` (Y onto X; None for X), divided by ``norm`` (the full shape's sqrt-area, or 1.0), then
    rotated by the (3, 3) ``rotation`` (row vectors)."""
    moved = vertices if alignment is None else alignment.apply(vertices)
    return (moved / norm) @ rotation


def place_side(vertices: np.ndarray, arrays: dict, meta: dict, side: str) -> np.ndarray:
    """:func:`place` with the values a record holds for ``side`` (x or y): its ``full_area`` (when the meta
    says ``area_normalised``), its alignment (Y only: X is never moved) and its random rotation; the
    same arrays give the same bytes as the pairs stage's placement."""
    norm = np.sqrt(arrays[f"{side}_full_area"]) if meta["area_normalised"] else 1.0
    alignment = None
    if side == "y":  # the record holds the rotation transposed (row vectors); rebuilt C-ordered, as aligned
        rotation = np.ascontiguousarray(arrays["y_align_rotation"].T)
        alignment = RigidTransform(rotation, arrays["y_align_translation"])
    return place(vertices, norm, arrays[f"{side}_random_rotation"], alignment)
