"""``becos evaluate``: score predictions against a benchmark store (:mod:`becos.evaluation.evaluate`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from becos.core.geodesics import METHODS as GEODESIC_METHODS
from becos.core.geodesics import GeodesicsCache
from becos.errors import BecosError, InputFileError
from becos.evaluation.evaluate import (
    DEFAULT_AUC_PRESET,
    DIRECTIONS,
    PAPER_PRESET,
    TRUTHS,
    benchmark_pairs,
    evaluate_records,
    get_preset,
    open_predictions,
    write_evaluation,
)


def configure_parser(parser: argparse.ArgumentParser) -> None:
    parser.description = "Score predictions (folders of <pair_id>.npy or Zarr stores) against a benchmark store."
    parser.add_argument("store", type=Path, help="benchmark store (becos export-zarr)")
    parser.add_argument("predictions", type=Path, nargs="+", help="one folder or Zarr store per method")
    parser.add_argument("--out", type=Path, required=True, help="output folder (CSV tables, PNG plot, JSON)")
    parser.add_argument("--split", default="test", help="split to score, or 'all' (default: test)")
    parser.add_argument(
        "--preset",
        default=DEFAULT_AUC_PRESET,
        help=f"AUC preset (default {DEFAULT_AUC_PRESET}; {PAPER_PRESET} is always added)",
    )
    parser.add_argument("--names", nargs="+", help="method names (default: the prediction folder names)")
    parser.add_argument("--geodesics", choices=GEODESIC_METHODS, default="heat", help="geodesic distance method")
    parser.add_argument(
        "--direction",
        choices=sorted(DIRECTIONS),
        default="yx",
        help="yx: maps Y -> X like corr_10 (default); xy: X -> Y like corr_01",
    )
    parser.add_argument(
        "--truth",
        choices=TRUTHS,
        default="vertex",
        help="measure errors to the true vertex (corr_10, default) or the exact barycentric point",
    )
    parser.add_argument("--allow-missing", action="store_true", help="skip pairs a method did not predict")
    parser.add_argument("--plot-max", type=float, default=0.25, help="largest threshold shown in pck.png")
    parser.add_argument("--cache-mb", type=int, default=1024, help="memory for cached geodesic rows")


def run_cli(args: argparse.Namespace) -> int:
    try:
        get_preset(args.preset)
    except ValueError as exc:
        raise BecosError(str(exc)) from exc
    names = args.names or [None] * len(args.predictions)
    if len(names) != len(args.predictions):
        raise BecosError(f"--names gives {len(names)} names for {len(args.predictions)} prediction sets")
    sources = {}
    for path, name in zip(args.predictions, names):
        source = open_predictions(path, name)
        if source.name in sources:
            raise BecosError(f"two prediction sets are both named {source.name!r}; pass --names")
        sources[source.name] = source
    benchmark = _open_store(args.store)
    if args.split not in ("all", *benchmark.splits()):
        raise InputFileError(
            args.store,
            f"has no split {args.split!r} (splits: {benchmark.splits()})",
            "pass --split with one of them, or 'all'",
        )
    evaluation = evaluate_records(
        benchmark_pairs(benchmark, args.split),
        sources,
        preset=args.preset,
        geodesics=GeodesicsCache(args.geodesics, cache_bytes=args.cache_mb << 20),
        direction=args.direction,
        truth=args.truth,
        allow_missing=args.allow_missing,
        progress=True,
    )
    title = f"{benchmark.setting} · split {args.split} · {evaluation.meta['n_pairs']} pairs"
    paths = write_evaluation(
        evaluation,
        args.out,
        title=title,
        plot_max=args.plot_max,
        extra_meta={
            "store": str(args.store),
            "split": args.split,
            "setting": benchmark.setting,
            "predictions": {n: str(s.path) for n, s in sources.items()},
        },
    )
    summary = evaluation.summary()
    if not summary.empty:
        overall = summary[summary["grouping"] == "all"]
        print(overall.to_string(index=False))
    print(paths["summary"])
    return 0


def _open_store(path: Path):
    from becos.products.store import open_benchmark

    return open_benchmark(path)


COMMANDS = {"evaluate": (configure_parser, run_cli)}
"""The sub-command's (arguments, handler) pair (:mod:`becos.cli`)."""
