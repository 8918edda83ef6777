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

Command line (``python -m becos.synthetic OUT_DIR``, or ``becos synthetic OUT_DIR`` once wired)::

    python -m becos.synthetic /tmp/synth --seed 0 --poses 4
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from becos.synthetic.bodies import CLASSES, ClassSpec, class_spec, semantic_part
from becos.synthetic.collection import (CHIRALITY_TEMPLATES, DATASETS, MANIFEST, TREE_EDGES, ClassModel,
                                        SyntheticDataset, body_part_labels, build_class, edge_edits,
                                        generate_collection, template_correspondence)

__all__ = [
    "CLASSES", "CHIRALITY_TEMPLATES", "DATASETS", "MANIFEST", "TREE_EDGES", "ClassModel", "ClassSpec",
    "SyntheticDataset", "body_part_labels", "build_class", "class_spec", "configure_parser", "edge_edits",
    "generate_collection", "main", "run_cli", "semantic_part", "template_correspondence",
]


def configure_parser(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the ``synthetic`` sub-command's arguments to ``parser`` (for ``becos synthetic``)."""
    parser.add_argument("out_dir", type=Path, help="folder to write (replaced if it holds a previous collection)")
    parser.add_argument("--seed", type=int, default=0, help="pose seed (default 0)")
    parser.add_argument("--poses", type=int, default=4, dest="poses_per_class",
                        help="shapes per class, 1-20 (default 4; 13 classes)")
    return parser


def run_cli(args: argparse.Namespace) -> int:
    """Generate the collection from parsed arguments; print its folder on stdout."""
    import time

    start = time.perf_counter()
    out = generate_collection(args.out_dir, seed=args.seed, poses_per_class=args.poses_per_class)
    print(f"synthetic collection: {len(CLASSES)} classes x {args.poses_per_class} poses in "
          f"{time.perf_counter() - start:.1f} s", file=sys.stderr)
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
