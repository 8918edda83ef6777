"""``becos validate``: check a benchmark store, optionally compare it with another (:mod:`becos.products.validate`,
:mod:`becos.products.compare`)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from becos.errors import BecosError
from becos.products.validate import validate


def configure_parser(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("store", type=Path, help="benchmark store written by `becos export-zarr`")
    parser.add_argument(
        "--json",
        type=Path,
        help="also write the summary and the problems (and with --against the full comparison) to this JSON file",
    )
    parser.add_argument(
        "--threads",
        type=int,
        default=1,
        metavar="N",
        help="check N blocks of pairs at once (default 1; about N times the memory of one block's checks); "
        "the result does not depend on N",
    )
    parser.add_argument(
        "--against",
        type=Path,
        metavar="OTHER",
        help="then compare STORE with OTHER, a store of the same setting (e.g. rebuilt after a "
        "library upgrade): pairs only in one store, per pair which arrays differ and why, "
        "differing versions and config; exit status 1 when they differ",
    )
    parser.add_argument(
        "--atol",
        type=float,
        default=0.0,
        help="with --against: float values within ATOL count as equal (default 0: exact)",
    )


MALLOC_KEEP_BYTES = 32 << 20
"""glibc malloc settings of a ``becos validate`` process: blocks up to this size come from the heap, not
their own mmap, and freed heap memory up to 32 times this is kept for reuse instead of being returned to
the system."""


def keep_freed_memory() -> None:
    """Let glibc reuse the memory of the validator's large per-block temporaries (tens of MB, freed and
    allocated again for every block) instead of unmapping and faulting it in again: about a sixth of
    ``becos validate``'s CPU on 450 TOSCA pairs was the kernel zeroing those pages, at the same peak RSS.
    Does nothing where the C library is not glibc."""
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return
    m_trim_threshold, m_mmap_threshold = -1, -3  # glibc's malloc.h
    mallopt(m_mmap_threshold, MALLOC_KEEP_BYTES)
    mallopt(m_trim_threshold, 32 * MALLOC_KEEP_BYTES)


def run_cli(args: argparse.Namespace) -> int:
    from becos.atomic import write_text

    keep_freed_memory()
    report = validate(args.store, progress=True, threads=args.threads)
    summary = report.summary()
    out = {**summary, "problems": report.problems}
    print(json.dumps(summary))
    for problem in report.problems:
        print(f"becos validate: {problem}", file=sys.stderr)
    status = 0 if report.valid else 1
    against = getattr(args, "against", None)
    if against is not None:
        from becos.products.compare import compare_stores

        if any(problem.startswith("store:") for problem in report.problems):
            out["comparison"] = None
            print(f"becos validate: not compared with {against}: {args.store} is damaged (see above)", file=sys.stderr)
        else:
            try:
                comparison = compare_stores(args.store, against, atol=args.atol)
            except BecosError as exc:
                print(f"becos validate: --against: {exc}", file=sys.stderr)
                out["comparison"] = {"error": str(exc)}
                status = 2
            else:
                print(comparison.summary())
                out["comparison"] = comparison.to_json()
                if not comparison.identical:
                    status = max(status, 1)
    if args.json is not None:
        write_text(args.json, json.dumps(out, indent=1) + "\n")
    return status


COMMANDS = {"validate": (configure_parser, run_cli)}
"""The sub-command's (arguments, handler) pair (:mod:`becos.cli`)."""
