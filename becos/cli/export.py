"""``becos export-released``, ``export-psmal``, ``export-ulrssm``, ``export-dpfm`` and ``export-geodesics``
(:mod:`becos.products.export`)."""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

from becos.products.export import (
    DSMK_FOLDER,
    GEODESIC_FOLDER,
    GEODESIC_LAYOUTS,
    IDS_FILE,
    ExportError,
    write_dpfm,
    write_geodesic_matrices,
    write_geodesics,
    write_psmal,
    write_released,
    write_ulrssm,
)


def _store(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("store", type=Path, help="benchmark store written by `becos export-zarr`")


def _geodesic_options(parser: argparse.ArgumentParser) -> None:
    """``--geodesic-method``, ``--splits``, ``--jobs``: the exports that compute geodesic matrices."""
    from becos.core.geodesics import METHODS

    parser.add_argument("--geodesic-method", choices=METHODS, default="heat", help="geodesic estimator (default: heat)")
    parser.add_argument(
        "--splits",
        nargs="+",
        metavar="SPLIT",
        help="geodesics of these splits only (e.g. test); default: every split",
    )
    parser.add_argument("--jobs", type=int, default=1, help="processes computing distance rows (default 1)")


def _rows(parser: argparse.ArgumentParser, help: str) -> None:
    parser.add_argument("--rows", type=Path, nargs="+", metavar="DIR", help=help)


def _force(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--force", action="store_true", help="replace OUT if it exists")


def _open(args: argparse.Namespace):
    """The store of ``args.store`` (:func:`becos.products.store.open_benchmark`); ``--jobs`` checked."""
    from becos.products.store import open_benchmark

    bench = open_benchmark(args.store)
    if getattr(args, "jobs", 1) < 1:
        raise ExportError(f"--jobs must be at least 1, got {args.jobs}")
    return bench


def _print_summary(out: Path, bench, **extra) -> int:
    """Print the JSON summary of a layout written to ``out``: its folder, setting, pairs per split
    (from its ids file) and ``extra``; exit status 0."""
    with open(out / IDS_FILE, encoding="utf-8", newline="") as fh:
        splits = [row["split"] for row in csv.DictReader(fh)]
    result = {
        "out": str(out.resolve()),
        "setting": bench.setting,
        "pairs": {s: splits.count(s) for s in dict.fromkeys(splits)},
        **extra,
    }
    print(json.dumps(result))
    return 0


# --- one pair per sub-command: its arguments, its handler -----------------------------------------------


def released_arguments(parser: argparse.ArgumentParser) -> None:
    _store(parser)
    parser.add_argument(
        "out",
        type=Path,
        help="output folder, best named after the setting "
        "(e.g. BeCoS/partial_partial): some loaders read the setting "
        "from the path",
    )
    _force(parser)


def run_released(args: argparse.Namespace) -> int:
    bench, out = _open(args), Path(args.out)
    if bench.setting not in out.resolve().parts:
        print(
            f"becos export-released: note: DeepShapeMatchingKit's BeCoSDataset reads the setting from "
            f"its data_root path; name the folder after it (e.g. {out / bench.setting})",
            file=sys.stderr,
        )
    write_released(
        bench.records(), out, setting=bench.setting, metadata=bench.metadata, overwrite=args.force, progress=True
    )
    return _print_summary(out, bench)


def psmal_arguments(parser: argparse.ArgumentParser) -> None:
    _store(parser)
    parser.add_argument("out", type=Path, help="output folder (<out>/<split>/shapes, maps)")
    parser.add_argument(
        "--geodesics",
        action="store_true",
        help="also write (V, V) float32 geodesic matrices per shape (<split>/geodesics)",
    )
    _geodesic_options(parser)
    _force(parser)


def run_psmal(args: argparse.Namespace) -> int:
    bench, out = _open(args), Path(args.out)
    write_psmal(bench.records(), out, metadata=bench.metadata, overwrite=args.force, progress=True)
    if args.geodesics:
        write_geodesics(
            bench.records(),
            out,
            args.geodesic_method,
            overwrite=args.force,
            progress=True,
            splits=args.splits,
            jobs=args.jobs,
        )
    return _print_summary(out, bench, geodesics=args.geodesic_method if args.geodesics else None)


def dpfm_arguments(parser: argparse.ArgumentParser) -> None:
    _store(parser)
    parser.add_argument("out", type=Path, help="output folder (<out>/<split>/shapes, maps)")
    _force(parser)


def run_dpfm(args: argparse.Namespace) -> int:
    bench, out = _open(args), Path(args.out)
    write_dpfm(bench.records(), out, metadata=bench.metadata, overwrite=args.force, progress=True)
    return _print_summary(out, bench)


def ulrssm_arguments(parser: argparse.ArgumentParser) -> None:
    _store(parser)
    parser.add_argument("out", type=Path, help="output folder (<out>/<split>/<i>/off, corres, dist)")
    parser.add_argument(
        "--geodesics",
        action="store_true",
        help="also write dist/<k>.mat (key dist: (V, V) float32 geodesics divided by the sqrt-area; each "
        "distinct matrix once, hard links for the other pair sides; disk and memory estimated first)",
    )
    _rows(
        parser,
        "with --geodesics: read each mesh's matrix from these `becos geodesic-rows` folders (the "
        "workflow's one geodesic computation) instead of computing it",
    )
    _geodesic_options(parser)
    _force(parser)


def run_ulrssm(args: argparse.Namespace) -> int:
    bench, out = _open(args), Path(args.out)
    if args.rows and not args.geodesics:
        raise ExportError("--rows reads geodesic matrices: pass it with --geodesics")
    write_ulrssm(
        bench.records(),
        out,
        metadata=bench.metadata,
        overwrite=args.force,
        progress=True,
        geodesics=args.geodesics,
        method=args.geodesic_method,
        splits=args.splits,
        jobs=args.jobs,
        rows=args.rows,
    )
    extra = {"geodesics": args.geodesic_method if args.geodesics else None}
    summary = out / "logs" / "geodesics.json"
    if summary.exists():
        done = json.loads(summary.read_text(encoding="utf-8"))
        extra.update({k: done[k] for k in ("written", "hard_links", "copies", "bytes")})
    return _print_summary(out, bench, **extra)


def geodesics_arguments(parser: argparse.ArgumentParser) -> None:
    _store(parser)
    parser.add_argument(
        "out",
        type=Path,
        help="output folder (<out>/geodesic_dist_matrices/<stem>.npy, <out>/dsmk/<split>/dist/<hash>_0.npz)",
    )
    _rows(parser, "read the distance rows from these `becos geodesic-rows` folders instead of computing them")
    parser.add_argument(
        "--layouts",
        nargs="+",
        choices=GEODESIC_LAYOUTS,
        default=list(GEODESIC_LAYOUTS),
        help="layouts to write (default: all): geo-lora geodesic_dist_matrices/<stem>.npy, "
        "dsmk dsmk/<split>/dist/<sha1>_0.npz",
    )
    parser.add_argument(
        "--dsmk-copies",
        action="store_true",
        help="DeepShapeMatchingKit files hold their matrix (a self-contained folder to copy elsewhere); "
        "default with the geo-lora layout: they read the shape's geo-lora file (no second copy)",
    )
    _geodesic_options(parser)
    _force(parser)


def run_geodesics(args: argparse.Namespace) -> int:
    bench, out = _open(args), Path(args.out)
    write_geodesic_matrices(
        bench.records(),
        out,
        args.geodesic_method,
        splits=args.splits,
        jobs=args.jobs,
        metadata=bench.metadata,
        overwrite=args.force,
        progress=True,
        rows=args.rows,
        layouts=args.layouts,
        dsmk_copies=args.dsmk_copies,
    )
    with open(out / GEODESIC_FOLDER / "index.csv", encoding="utf-8", newline="") as fh:
        rows = list(csv.DictReader(fh))
    matrices = list((out / GEODESIC_FOLDER).glob("*.npy"))
    print(
        json.dumps(
            {
                "out": str(out.resolve()),
                "setting": bench.setting,
                "method": args.geodesic_method,
                "splits": args.splits,
                "matrices": len(matrices),
                "bytes": sum(p.stat().st_size for p in matrices),
                "linked": sum(p.stat().st_nlink > 1 for p in matrices),
                "dsmk_files": len({r["dsmk_file"] for r in rows if r["dsmk_file"]}),
                "dsmk_bytes": sum(p.stat().st_size for p in out.glob(f"{DSMK_FOLDER}/*/dist/*.npz")),
            }
        )
    )
    return 0


COMMANDS = {
    "export-released": (released_arguments, run_released),
    "export-psmal": (psmal_arguments, run_psmal),
    "export-dpfm": (dpfm_arguments, run_dpfm),
    "export-ulrssm": (ulrssm_arguments, run_ulrssm),
    "export-geodesics": (geodesics_arguments, run_geodesics),
}
"""Each sub-command's (arguments, handler) pair (:mod:`becos.cli`)."""
