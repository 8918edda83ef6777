"""``becos export-zarr``: collect a setting's pair records into one Zarr store (:mod:`becos.products.store`)."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from becos.errors import InputFileError
from becos.products.store import count_files, expand_inputs, open_benchmark, write_store
from becos.settings import SETTINGS


def configure_parser(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--setting", required=True, choices=SETTINGS)
    parser.add_argument(
        "--out",
        required=True,
        type=Path,
        help="store folder to write: new, empty, or a becos store (replaced); anything else needs --force",
    )
    parser.add_argument(
        "--force",
        dest="overwrite",
        action="store_true",
        help="replace an --out folder that is not a becos store, deleting what it holds "
        "(refused while an input lies inside it)",
    )
    parser.add_argument(
        "--metadata",
        type=Path,
        help="JSON file of extra root attributes (config, config_hash, "
        "datasets ...), e.g. becos.workflow.store_metadata",
    )
    parser.add_argument(
        "--processes",
        type=int,
        choices=(1, 2),
        default=1,
        help="2: a second process fills about half of the arrays of a large store (over 256 MiB of "
        "arrays), which is faster on 2 free cores; the store is the same (default 1)",
    )
    parser.add_argument(
        "inputs",
        nargs="+",
        type=Path,
        help="pair record .npz files and/or index files (a chunk index JSON of `becos pairs`, "
        "or text with one record path per line)",
    )


def run_cli(args: argparse.Namespace) -> int:
    metadata = None
    if args.metadata is not None:
        try:
            metadata = json.loads(Path(args.metadata).read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputFileError(
                args.metadata, f"cannot be read as JSON ({exc})", "give the metadata JSON written by `becos metadata`"
            ) from exc
        if not isinstance(metadata, dict):
            raise InputFileError(args.metadata, "is not a JSON object", "give a {key: value} JSON file")
    paths = expand_inputs(args.inputs, args.setting)
    started = time.perf_counter()
    protect = [*args.inputs, *([args.metadata] if args.metadata is not None else [])]
    write_store(
        paths,
        args.out,
        setting=args.setting,
        metadata=metadata,
        overwrite=args.overwrite,
        protect=protect,
        processes=args.processes,
    )
    bench = open_benchmark(args.out)
    print(
        json.dumps(
            {
                "store": str(args.out),
                "setting": bench.setting,
                "n_pairs": len(bench),
                "splits": bench.metadata.get("splits"),
                "n_files": count_files(args.out),
                "seconds": round(time.perf_counter() - started, 2),
            }
        )
    )
    return 0


COMMANDS = {"export-zarr": (configure_parser, run_cli)}
"""The sub-command's (arguments, handler) pair (:mod:`becos.cli`)."""
