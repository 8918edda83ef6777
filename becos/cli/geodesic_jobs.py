"""``becos geodesic-plan`` and ``becos geodesic-rows`` (:mod:`becos.products.geodesic_jobs`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from becos.products.geodesic_jobs import GeodesicJobError, solve_part, write_plan


def plan_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("stores", type=Path, nargs="+", help="benchmark stores (one per setting)")
    parser.add_argument("--out", type=Path, required=True, help="plan folder (part_<k>.npz, plan.json)")
    parser.add_argument("--parts", type=int, required=True, help="number of part files (jobs)")
    parser.add_argument("--splits", nargs="+", metavar="SPLIT", help="these splits only (default: all)")


def run_plan(args: argparse.Namespace) -> int:
    if args.parts < 1:
        raise GeodesicJobError(f"--parts must be at least 1, got {args.parts}")
    summary = write_plan(args.stores, args.out, args.parts, args.splits)
    print(
        json.dumps(
            {
                "out": str(args.out),
                "parts": summary["parts"],
                "meshes": len(summary["meshes"]),
                "rows": sum(m["n_rows"] for m in summary["meshes"].values()),
            }
        )
    )
    return 0


def rows_arguments(parser: argparse.ArgumentParser) -> None:
    from becos.core.geodesics import METHODS

    parser.add_argument("part", type=Path, help="a part file of `becos geodesic-plan`")
    parser.add_argument("out", type=Path, help="output folder (<key>.npy rows, <key>.sources.npy)")
    parser.add_argument("--geodesic-method", choices=METHODS, default="heat")


def run_rows(args: argparse.Namespace) -> int:
    timings = solve_part(args.part, args.out, args.geodesic_method, progress=True)
    print(
        json.dumps(
            {
                "out": str(args.out),
                "meshes": len(timings),
                "cpu_s": round(sum(t["cpu_s"] for t in timings.values()), 2),
                "bytes": sum(t["bytes"] for t in timings.values()),
            }
        )
    )
    return 0


COMMANDS = {
    "geodesic-plan": (plan_arguments, run_plan),
    "geodesic-rows": (rows_arguments, run_rows),
}
"""Each sub-command's (arguments, handler) pair (:mod:`becos.cli`)."""
