"""``becos baseline``: run a baseline matcher on a benchmark store (:mod:`becos.evaluation.baselines`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from becos.errors import InputFileError
from becos.evaluation.baselines import BASELINES, run_baseline


def configure_parser(parser: argparse.ArgumentParser) -> None:
    parser.description = "Run a baseline matcher on a benchmark store; write per-pair .npy predictions."
    parser.add_argument(
        "name",
        choices=sorted(BASELINES),
        help="nn: nearest neighbour in 3D (a floor); zoomout: WKS functional map + ZoomOut",
    )
    parser.add_argument("store", type=Path, help="benchmark store (becos export-zarr)")
    parser.add_argument("--out", type=Path, required=True, help="prediction folder to write")
    parser.add_argument("--split", default="test", help="split to run on, or 'all' (default: test)")


def run_cli(args: argparse.Namespace) -> int:
    from becos.products.store import open_benchmark

    benchmark = open_benchmark(args.store)
    if args.split != "all" and args.split not in benchmark.splits():
        raise InputFileError(
            args.store,
            f"has no split {args.split!r} (splits: {benchmark.splits()})",
            "pass --split with one of them, or 'all'",
        )
    records = benchmark.records(None if args.split == "all" else args.split)
    facts = run_baseline(args.name, records, args.out, progress=True)
    print(json.dumps(facts))
    return 0


COMMANDS = {"baseline": (configure_parser, run_cli)}
"""The sub-command's (arguments, handler) pair (:mod:`becos.cli`)."""
