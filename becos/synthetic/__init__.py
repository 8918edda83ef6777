"""A built-in synthetic shape collection, generated from code (issue 5).

Most source datasets need a licence and a manual download; this collection needs neither. It is
shaped like the real thing so every stage of the workflow runs on it for real: two datasets with
different triangulations, units and file frames (``synthy``: metres, y-up; ``synthz``: centimetres,
z-up like TOSCA), six humanoid classes, six four-legged classes and a centaur, several poses per
class sharing one triangulation, and a BeCoS-format annotation folder (template network, template
tables, barycentric template correspondences with semantic missing parts, default faces,
left/right labels) derived from the construction.

Modules: :mod:`~becos.synthetic.bodies` (parts, skeletons, implicit surface, charts, posing),
:mod:`~becos.synthetic.meshing` (marching cubes and relaxation), :mod:`~becos.synthetic.collection`
(correspondences and the files).

Command line (:mod:`becos.cli.synthetic`; the workflow's rule runs the first form, the second is equivalent)::

    becos synthetic OUT_DIR --seed 0 --poses 4
    python -m becos.synthetic OUT_DIR --seed 0 --poses 4
    becos synthetic OUT_DIR --fraction 0.0625     # 1/16 of the BeCoS-size collection (161 shapes)

Deterministic (byte-identical files for the same seed and poses, any process, any PYTHONHASHSEED)
and fast: about 5-10 s for the default 13 classes x 4 poses on 2 cores.
"""

from __future__ import annotations

from becos.synthetic.bodies import CLASSES, ClassSpec, class_spec, semantic_part
from becos.synthetic.collection import (
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
