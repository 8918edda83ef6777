"""``becos download-dataset``: download and unpack a dataset's public archive (:mod:`becos.sources.download`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from becos.atomic import write_text
from becos.sources.download import download_dataset


def configure_parser(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Arguments of ``becos download-dataset``."""
    parser.add_argument("dataset", help="dataset with a public archive (source.archive of its YAML): kids, shrec20")
    parser.add_argument("--data-dir", type=Path, required=True, help="data root (config key `data_dir`)")
    parser.add_argument(
        "--url", help="download from this URL instead of the YAML's (a mirror; config key `download_urls`)"
    )
    parser.add_argument("--out", type=Path, help="write the result as JSON here (the workflow's stamp)")
    parser.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")
    return parser


def run_cli(args: argparse.Namespace) -> int:
    """Run ``becos download-dataset``; BecosError propagates (the CLI exits 2)."""
    result = download_dataset(args.dataset, args.data_dir, args.url, progress=args.progress)
    text = json.dumps(result, indent=2) + "\n"
    if args.out is not None:
        write_text(args.out, text)
    print(result["folder"])
    return 0


COMMANDS = {"download-dataset": (configure_parser, run_cli)}
"""The sub-command's (arguments, handler) pair (:mod:`becos.cli`)."""
