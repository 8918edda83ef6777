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

Command line (the workflow's rule runs the first form; the second is equivalent)::

    becos synthetic OUT_DIR --seed 0 --poses 4
    python -m becos.synthetic OUT_DIR --seed 0 --poses 4

Deterministic (byte-identical files for the same seed and poses, any process, any PYTHONHASHSEED)
and fast: about 5-10 s for the default 13 classes x 4 poses on 2 cores.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from becos.synthetic.bodies import CLASSES, ClassSpec, class_spec, semantic_part
from becos.synthetic.collection import (
    CHIRALITY_TEMPLATES,
    DATASETS,
    MANIFEST,
    TREE_EDGES,
    ClassModel,
    SyntheticDataset,
    body_part_labels,
    build_class,
    edge_edits,
    generate_collection,
    template_correspondence,
)

REGISTRY_POSES = 4
"""Poses per class that the registry YAMLs (config/datasets/synthy.yaml, synthz.yaml) count on."""

__all__ = [
    "CLASSES",
    "CHIRALITY_TEMPLATES",
    "DATASETS",
    "MANIFEST",
    "REGISTRY_POSES",
    "TREE_EDGES",
    "ClassModel",
    "ClassSpec",
    "SyntheticDataset",
    "body_part_labels",
    "build_class",
    "class_spec",
    "configure_parser",
    "edge_edits",
    "generate_collection",
    "main",
    "run_cli",
    "semantic_part",
    "template_correspondence",
]


def configure_parser(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the ``synthetic`` sub-command's arguments to ``parser`` (for ``becos synthetic``)."""
    parser.add_argument("out_dir", type=Path, help="folder to write (replaced if it holds a previous collection)")
    parser.add_argument("--seed", type=int, default=0, help="pose seed (default 0)")
    parser.add_argument(
        "--poses",
        type=int,
        default=REGISTRY_POSES,
        dest="poses_per_class",
        help=f"shapes per class, 1-20 (default {REGISTRY_POSES}; 13 classes). The dataset registry "
        f"(config/datasets/synthy.yaml, synthz.yaml: expected_count, expected_per_class) "
        f"expects {REGISTRY_POSES}",
    )
    return parser


def run_cli(args: argparse.Namespace) -> int:
    """Generate the collection from parsed arguments; print its folder on stdout."""
    import time

    start = time.perf_counter()
    out = generate_collection(args.out_dir, seed=args.seed, poses_per_class=args.poses_per_class)
    if args.poses_per_class != REGISTRY_POSES:
        print(
            f"becos synthetic: warning: {args.poses_per_class} poses per class, but config/datasets/synthy.yaml and "
            f"synthz.yaml expect {REGISTRY_POSES} (expected_count, expected_per_class); update them before listing "
            f"the shapes",
            file=sys.stderr,
        )
    print(
        f"synthetic collection: {len(CLASSES)} classes x {args.poses_per_class} poses in "
        f"{time.perf_counter() - start:.1f} s",
        file=sys.stderr,
    )
    print(out)
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m becos.synthetic OUT_DIR [--seed N] [--poses K]``."""
    from becos.errors import BecosError

    parser = configure_parser(argparse.ArgumentParser(prog="becos synthetic", description=__doc__.splitlines()[0]))
    args = parser.parse_args(argv)
    try:
        return run_cli(args)
    except BecosError as exc:
        print(f"becos synthetic: {exc}", file=sys.stderr)
        return 2
