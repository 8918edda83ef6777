"""``becos synthetic``: generate the built-in synthetic shape collection (:mod:`becos.synthetic`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from becos.synthetic import CLASSES, REGISTRY_POSES, generate_collection


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


COMMANDS = {"synthetic": (configure_parser, run_cli)}
"""The sub-command's (arguments, handler) pair (:mod:`becos.cli`)."""
