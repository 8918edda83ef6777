"""Shapes of one class: every shape that shares its class template's triangulation (the network's
identity hop: vertex i is vertex i) is compared with the template (:func:`compare_with_class_template`:
faces as vertex sets, median edge-length ratio, flatness); :func:`check_classes` runs the comparison
over a dataset's shapes for the dataset check.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from becos.errors import BecosError
from becos.process_split import ProcessSplit
from becos.sources.check.meshes import mesh_arrays

CLASS_EDGE_RATIO = 1.5
"""Shapes that share their class template's triangulation (the network's identity hop: vertex i is
vertex i) must have a median edge length within this factor of the template's (and its inverse).
Measured on the 76 TOSCA meshes: every pose's median ratio to its class template is 1 ± 6e-5 (the
poses are near-isometric), while a file in other units is off by its unit factor (10, 100, 1000,
2.54...). 1.5 also leaves room for classes of different bodies on one template (FAUST subjects)."""


@dataclass(eq=False)
class ClassTemplate:
    """A class template's (V, 3) float64 vertices and (F, 3) int faces, and what every comparison of a
    shape with it needs, computed once per class (:func:`check_classes`)."""

    vertices: np.ndarray
    faces: np.ndarray

    @cached_property
    def face_keys(self) -> np.ndarray:
        """Sorted distinct vertex-set keys of its faces (:func:`becos.core.mesh.vertex_set_keys`)."""
        from becos.core.mesh import vertex_set_keys

        return np.unique(vertex_set_keys(self.faces, len(self.vertices)))

    @cached_property
    def edges(self) -> np.ndarray:
        """(E, 2) its undirected edges."""
        from becos.core.mesh import undirected_edges

        return undirected_edges(self.faces)[0]

    @cached_property
    def edge_lengths(self) -> np.ndarray:
        """(E,) lengths of :attr:`edges` in its own units."""
        return np.linalg.norm(self.vertices[self.edges[:, 0]] - self.vertices[self.edges[:, 1]], axis=1)


def compare_with_class_template(
    path: Path, template_path: Path, shape_arrays, template_arrays: ClassTemplate | tuple
) -> str | None:
    """Why the mesh in ``path`` cannot share the triangulation of its class template, or None.

    Faces are compared as vertex SETS (sorted triples; TOSCA poses of a class hold the same triples,
    some rows with reversed winding); faces the shape lacks, duplicates and rows with a repeated index
    are left to the remesh's repairs, a triple the template lacks is an error. Scale as the median
    ratio of the lengths of the template's edges in the two meshes (:data:`CLASS_EDGE_RATIO`).
    ``template_arrays``: the template's (vertices, faces) or its :class:`ClassTemplate`."""
    from becos.core.mesh import FLAT_RTOL, flatness, repeated_index_faces, vertex_set_keys

    template = template_arrays if isinstance(template_arrays, ClassTemplate) else ClassTemplate(*template_arrays)
    v, f = shape_arrays
    tv = template.vertices
    if flatness(v) <= FLAT_RTOL:
        return (
            f"all its {len(v)} vertices lie in one plane (thickness {flatness(v):.2g} of its largest extent): a "
            f"flattened or 2-D mesh, and becos matches 3-D surfaces"
        )
    if len(v) != len(tv):
        return (
            f"has {len(v)} vertices but its class template {template_path} has {len(tv)}; the shapes of a class "
            f"share one triangulation (vertex i = vertex i)"
        )
    # faces as vertex sets; rows that remeshing drops or ignores (a repeated index, duplicates) and faces
    # the file lost (a subset) are repairs, a triple the template lacks is not
    f = np.asarray(f, dtype=np.int64)
    f = f[~repeated_index_faces(f)] if len(f) else f
    keys = np.unique(vertex_set_keys(f, len(v)))
    foreign = len(np.setdiff1d(keys, template.face_keys, assume_unique=True))
    if foreign:
        return (
            f"has the vertex count of its class template {template_path} but {foreign} of its {len(keys)} "
            f"distinct faces name vertex triples the template has not: its vertex lines are re-ordered (or it "
            f"was re-triangulated), so vertex i no longer corresponds to vertex i of the class"
        )
    edges, template_lengths = template.edges, template.edge_lengths
    lengths = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)
    ratio = float(np.median(lengths[template_lengths > 0] / template_lengths[template_lengths > 0]))
    if not 1 / CLASS_EDGE_RATIO <= ratio <= CLASS_EDGE_RATIO:
        return (
            f"its edges are {ratio:.3g} times as long as those of its class template {template_path} "
            f"(median; poses of a class keep edge lengths, within {CLASS_EDGE_RATIO}x): the file is "
            f"scaled or in other units"
        )
    return None


CLASS_FIX = (
    "restore the original file (re-download or re-extract it); never rescale or re-order a dataset's "
    "files: becos applies each dataset's scale itself (`scale` in config/datasets/<dataset>.yaml)"
)
"""The fix named for a shape that does not fit its class template (:func:`check_classes`)."""


def check_classes(shapes: list, annotations, skip: set[str], split: ProcessSplit) -> list[dict]:
    """``[{"path", "template", "problem", "fix"}]`` for shapes that differ from their class template.

    Only shapes the ground truth joins to their template by vertex identity are compared: the
    template is a shape of the same dataset (:meth:`becos.build.network.ShapeNetwork.hop`). Files in
    ``skip`` (already reported) are left out. ``split``: half of the comparisons go to its second
    process, if it has one (:class:`becos.process_split.ProcessSplit`), the same list."""

    by_name = {e.name: e for e in shapes}
    groups: dict[str, list] = {}
    for e in shapes:
        groups.setdefault(e.template_key, []).append(e)
    pairs = []  # (shape file, template file), class by class
    for key, members in groups.items():
        try:
            dataset, template_name = annotations.node_template(annotations.node_of_key(key))
        except BecosError:
            continue  # reported by the annotation check
        template = by_name.get(template_name)
        if template is None or template.dataset != members[0].dataset or str(template.path) in skip:
            continue
        pairs += [(e.path, template.path) for e in members if e.name != template_name and str(e.path) not in skip]
    problems = split.map(_compare_files, pairs)
    return [
        {"path": str(path), "template": str(template), "problem": problem, "fix": CLASS_FIX}
        for (path, template), problem in zip(pairs, problems)
        if problem is not None
    ]


def _compare_files(pairs: list[tuple[Path, Path]]) -> list[str | None]:
    """:func:`compare_with_class_template` of each (shape file, template file), an unreadable shape's
    problem included; ``pairs`` come class by class, so each template is read once."""
    template_path, template, out = None, None, []
    for path, pair_template in pairs:
        if pair_template != template_path:
            template_path, template = pair_template, ClassTemplate(*mesh_arrays(pair_template))
        try:
            out.append(compare_with_class_template(path, template_path, mesh_arrays(path), template))
        except (BecosError, ValueError) as exc:
            out.append(f"could not be read to compare with its class template ({exc})")
    return out
