"""``becos prepare-dt4d``: DeformingThings4D frames as OBJ files (:mod:`becos.sources.dt4d`)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from becos.sources.dt4d import KINDS, output_folder, prepare_dt4d


def configure_parser(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    parser.add_argument(
        "--data-dir",
        type=Path,
        required=True,
        help="data root (config key `data_dir`) holding DeformingThings4D/<kind>/",
    )
    parser.add_argument(
        "--info",
        type=Path,
        required=True,
        help="info JSON {class: {action: [frame ids]}} (the annotation folder's data/info_dt4d_<kind>.json)",
    )
    parser.add_argument("--kind", required=True, choices=KINDS, help="animals or humanoids")
    parser.add_argument("--classes", nargs="+", metavar="CLASS", help="only these classes (default: all listed)")
    parser.add_argument(
        "--anime",
        nargs="*",
        type=Path,
        metavar="FILE",
        help="the .anime files to read (the workflow's rule passes its inputs); default: every listed one",
    )
    return parser


def run_cli(args: argparse.Namespace) -> int:
    def log(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    total = prepare_dt4d(args.data_dir, args.info, args.kind, args.classes, log=log, anime=args.anime)
    print(json.dumps({"out": str(output_folder(args.data_dir, args.kind)), **total}))
    return 0


COMMANDS = {"prepare-dt4d": (configure_parser, run_cli)}
"""The sub-command's (arguments, handler) pair (:mod:`becos.cli`)."""
