"""A built-in synthetic shape collection, generated from code: no licence, no download.

Shaped like the real thing so every stage runs on it for real: two datasets with different
triangulations, units and file frames, six humanoid and six four-legged classes and a centaur, several
poses per class sharing one triangulation, and a BeCoS-format annotation folder derived from the
construction. Modules: ``bodies`` (parts, skeletons, implicit surface, charts, posing), ``meshing``
(marching cubes, relaxation), ``collection`` (correspondences, files). ``becos synthetic OUT_DIR --seed 0
--poses 4`` (or ``python -m becos.sources.synthetic``; ``--fraction`` for a share of the BeCoS-size collection);
deterministic, byte-identical for the same seed and poses. Timing and more: docs/design/data.md.
"""

from __future__ import annotations

from becos.sources.synthetic.bodies import CLASSES, ClassSpec, class_spec, semantic_part
from becos.sources.synthetic.collection import (
    CHIRALITY_TEMPLATES,
    DATASETS,
    FULL_SCALE_POSES,
    MANIFEST,
    TREE_EDGES,
    ClassModel,
    SyntheticDataset,
    body_part_labels,
    build_class,
    edge_edits,
    generate_collection,
    poses_at_fraction,
    template_correspondence,
)

DEFAULT_POSES = 4
"""Poses per class of ``becos synthetic`` without ``--poses`` (the workflow passes ``synthetic.poses``,
whose default is in becos/data/schema.yaml). The registry entries (config/datasets/synthy.yaml,
synthz.yaml) count the shapes the collection's manifest lists, at any pose count."""

__all__ = [
    "CLASSES",
    "CHIRALITY_TEMPLATES",
    "DATASETS",
    "DEFAULT_POSES",
    "FULL_SCALE_POSES",
    "MANIFEST",
    "TREE_EDGES",
    "ClassModel",
    "ClassSpec",
    "SyntheticDataset",
    "body_part_labels",
    "build_class",
    "class_spec",
    "edge_edits",
    "generate_collection",
    "poses_at_fraction",
    "semantic_part",
    "template_correspondence",
]
