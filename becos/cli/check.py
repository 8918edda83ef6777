"""``becos check`` (:mod:`becos.sources.check`) and ``becos fetch-annotations`` (:func:`becos.sources.download.fetch_annotations`)."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from becos.atomic import write_text
from becos.sources.check import DatasetCheckError, check_datasets
from becos.sources.download import fetch_annotations


def check_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``becos check``."""
    parser.add_argument(
        "--datasets",
        nargs="+",
        required=True,
        metavar="NAME",
        help="enabled datasets (config key `datasets`), e.g. tosca faust",
    )
    parser.add_argument("--data-dir", type=Path, required=True, help="data root (config key `data_dir`)")
    parser.add_argument(
        "--annotations", type=Path, required=True, help="BeCoS annotation folder (config key `annotations`)"
    )
    parser.add_argument(
        "--template-table",
        default="templates_all.csv",
        help="template table in <annotations>/config (default templates_all.csv)",
    )
    parser.add_argument("--out", type=Path, help="write the JSON report here (also on failure)")
    parser.add_argument(
        "--no-mesh-check",
        dest="read_meshes",
        action="store_false",
        help="only check folders and counts, not the mesh files",
    )
    parser.add_argument(
        "--no-geometry-check",
        dest="compare_geometry",
        action="store_false",
        help="do not compare shapes with their class template nor check edge files for "
        "plausibility (only for stand-in meshes; config key `check_geometry`)",
    )
    parser.add_argument(
        "--processes",
        type=int,
        choices=(1, 2),
        default=1,
        help="2: check the mesh files and the class templates in two processes (the same report; default 1)",
    )
    parser.add_argument(
        "--full-parse",
        action="store_true",
        help="also parse every mesh completely with read_mesh and list the repairs remeshing "
        "applies to a copy (slow: ~35 s for TOSCA)",
    )


def fetch_annotations_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``becos fetch-annotations``."""
    parser.add_argument("--url", required=True, help="archive URL (http, https or file://)")
    parser.add_argument("--sha256", required=True, help="pinned SHA-256 of the archive")
    parser.add_argument("--dest", type=Path, required=True, help="folder to create (the annotation folder)")


def run_fetch_annotations(args: argparse.Namespace) -> int:
    """Run ``becos fetch-annotations``: print the installed folder."""
    print(fetch_annotations(args.url, args.sha256, args.dest))
    return 0


def run_check(args: argparse.Namespace) -> int:
    """Run ``becos check``; BecosError propagates (the CLI exits 2)."""
    start = time.perf_counter()
    try:
        report = check_datasets(
            args.datasets,
            args.data_dir,
            args.annotations,
            read_meshes=args.read_meshes,
            full_parse=args.full_parse,
            template_table=args.template_table,
            compare_geometry=args.compare_geometry,
            processes=args.processes,
        )
    except DatasetCheckError as exc:
        if args.out is not None:
            write_text(args.out, json.dumps(exc.report, indent=2) + "\n")
        raise
    text = json.dumps(report, indent=2) + "\n"
    for name in args.datasets:
        r = report[name]
        print(f"check: {name}: {r['found']} shapes in {r['path']}", file=sys.stderr)
        if r.get("repairs"):
            print(
                f"check: {name}: {len(r['repairs'])} meshes are repaired on a copy before remeshing (the files "
                f"are not changed):",
                file=sys.stderr,
            )
            for item in r["repairs"]:
                print(f"  {item['path']}: {item['repair']}", file=sys.stderr)
    print(f"check: all ok in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    if args.out is not None:
        write_text(args.out, text)
        print(args.out)
    else:
        sys.stdout.write(text)
    return 0


COMMANDS = {
    "check": (check_arguments, run_check),
    "fetch-annotations": (fetch_annotations_arguments, run_fetch_annotations),
}
"""Each sub-command's (arguments, handler) pair (:mod:`becos.cli`)."""
