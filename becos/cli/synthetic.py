"""``becos synthetic``: generate the built-in synthetic shape collection (:mod:`becos.sources.synthetic`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from becos.sources.synthetic import CLASSES, DEFAULT_POSES, generate_collection


def configure_parser(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the ``synthetic`` sub-command's arguments to ``parser`` (for ``becos synthetic``)."""
    parser.add_argument("out_dir", type=Path, help="folder to write (replaced if it holds a previous collection)")
    parser.add_argument("--seed", type=int, default=0, help="pose seed (default 0)")
    size = parser.add_mutually_exclusive_group()
    size.add_argument(
        "--poses",
        type=int,
        default=DEFAULT_POSES,
        dest="poses_per_class",
        help=f"shapes per class, 1-20 (default {DEFAULT_POSES}; 13 classes)",
    )
    size.add_argument(
        "--fraction",
        type=float,
        default=None,
        help="instead of --poses: this fraction (0, 1] of the BeCoS-size collection (2,537 shapes at 1; "
        "per-class counts: becos.sources.synthetic.FULL_SCALE_POSES), e.g. 0.0625 for 1/16",
    )
    return parser


def run_cli(args: argparse.Namespace) -> int:
    """Generate the collection from parsed arguments; print its folder on stdout."""
    import json
    import sys
    import time

    from becos.sources.synthetic import MANIFEST

    start = time.perf_counter()
    out = generate_collection(
        args.out_dir, seed=args.seed, poses_per_class=args.poses_per_class, fraction=args.fraction
    )
    manifest = json.loads((out / MANIFEST).read_text())
    n_shapes = sum(1 for f in manifest["files"] if f.startswith("data/"))
    size = f"{args.poses_per_class} poses" if args.fraction is None else f"fraction {args.fraction} of BeCoS size"
    print(
        f"synthetic collection: {len(CLASSES)} classes, {n_shapes} shapes ({size}) in "
        f"{time.perf_counter() - start:.1f} s",
        file=sys.stderr,
    )
    print(out)
    return 0


COMMANDS = {"synthetic": (configure_parser, run_cli)}
"""The sub-command's (arguments, handler) pair (:mod:`becos.cli`)."""
