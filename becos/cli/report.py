"""``becos report``: counts, overlap histogram and renders of a store (:mod:`becos.products.report`)."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from becos.products.report import select_render_ids, write_report


def configure_parser(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("store", type=Path, help="benchmark store (Zarr folder written by `becos export-zarr`)")
    parser.add_argument("out", type=Path, help="output folder (index.html, counts, histogram, renders)")
    parser.add_argument("--renders", type=int, default=8, metavar="N", help="number of sample renders (default 8)")


def run_cli(args: argparse.Namespace) -> int:
    from becos.errors import InputFileError

    if not Path(args.store).exists():
        raise InputFileError(
            args.store,
            "benchmark store not found",
            "pass the folder written by `becos export-zarr` (or the workflow's store output)",
        )
    if args.renders < 0:
        raise InputFileError(args.store, f"--renders must be >= 0, got {args.renders}", "pass a count such as 8")
    from becos.products.store import open_benchmark

    start = time.perf_counter()
    bench = open_benchmark(args.store)
    table = bench.table
    chosen = select_render_ids(table, args.renders)
    print(f"becos report: {len(table)} pairs in {args.store}, rendering {len(chosen)}", file=sys.stderr)
    records = (bench.record(pid) for pid in chosen)
    metadata = dict(bench.metadata)
    metadata.setdefault("setting", bench.setting)
    summary = write_report(records, table, args.out, n_renders=args.renders, metadata=metadata)
    print(
        f"becos report: wrote {Path(args.out) / 'index.html'} in {time.perf_counter() - start:.1f} s", file=sys.stderr
    )
    print(
        json.dumps(
            {
                "index": str(Path(args.out) / "index.html"),
                "n_pairs": summary["n_pairs"],
                "renders": len(summary["renders"]),
                "overlap_directions": summary["overlap_histogram"]["n_directions"],
                "published_overlap_total_variation": (summary["published_overlap_histogram"] or {}).get(
                    "total_variation"
                ),
            }
        )
    )
    return 0


COMMANDS = {"report": (configure_parser, run_cli)}
"""The sub-command's (arguments, handler) pair (:mod:`becos.cli`)."""
