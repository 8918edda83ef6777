"""``becos export-released``, ``export-psmal``, ``export-ulrssm``, ``export-dpfm`` and ``export-geodesics``
(:mod:`becos.export`)."""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

from becos.export import (
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


def configure_parser(parser: argparse.ArgumentParser, name: str) -> argparse.ArgumentParser:
    """Arguments of ``becos export-released STORE OUT``, ``becos export-psmal STORE OUT [--geodesics]``
    and ``becos export-geodesics STORE OUT``."""
    from becos.geodesics import METHODS

    parser.add_argument("store", type=Path, help="benchmark store written by `becos export-zarr`")
    if name == "export-released":
        parser.add_argument(
            "out",
            type=Path,
            help="output folder, best named after the setting "
            "(e.g. BeCoS/partial_partial): some loaders read the setting "
            "from the path",
        )
    elif name in ("export-psmal", "export-dpfm"):
        parser.add_argument("out", type=Path, help="output folder (<out>/<split>/shapes, maps)")
        if name == "export-psmal":
            parser.add_argument(
                "--geodesics",
                action="store_true",
                help="also write (V, V) float32 geodesic matrices per shape (<split>/geodesics)",
            )
    elif name == "export-ulrssm":
        parser.add_argument("out", type=Path, help="output folder (<out>/<split>/<i>/off, corres, dist)")
        parser.add_argument(
            "--geodesics",
            action="store_true",
            help="also write dist/<k>.mat (key dist: (V, V) float32 geodesics divided by the sqrt-area; each "
            "distinct matrix once, hard links for the other pair sides; disk and memory estimated first)",
        )
        parser.add_argument(
            "--rows",
            type=Path,
            nargs="+",
            metavar="DIR",
            help="with --geodesics: read each mesh's matrix from these `becos geodesic-rows` folders (the "
            "workflow's one geodesic computation) instead of computing it",
        )
    else:
        parser.add_argument(
            "out",
            type=Path,
            help="output folder (<out>/geodesic_dist_matrices/<stem>.npy, <out>/dsmk/<split>/dist/<hash>_0.npz)",
        )
        parser.add_argument(
            "--rows",
            type=Path,
            nargs="+",
            metavar="DIR",
            help="read the distance rows from these `becos geodesic-rows` folders instead of computing them",
        )
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
    if name in ("export-psmal", "export-geodesics", "export-ulrssm"):
        parser.add_argument(
            "--geodesic-method", choices=METHODS, default="heat", help="geodesic estimator (default: heat)"
        )
        parser.add_argument(
            "--splits",
            nargs="+",
            metavar="SPLIT",
            help="geodesics of these splits only (e.g. test); default: every split",
        )
        parser.add_argument("--jobs", type=int, default=1, help="processes computing distance rows (default 1)")
    parser.add_argument("--force", action="store_true", help="replace OUT if it exists")
    parser.set_defaults(export_kind=name)
    return parser


def run_cli(args: argparse.Namespace) -> int:
    from becos.store import open_benchmark

    bench = open_benchmark(args.store)
    out = Path(args.out)
    if getattr(args, "jobs", 1) < 1:
        raise ExportError(f"--jobs must be at least 1, got {args.jobs}")
    if getattr(args, "rows", None) and args.export_kind == "export-ulrssm" and not args.geodesics:
        raise ExportError("--rows reads geodesic matrices: pass it with --geodesics")
    if args.export_kind == "export-geodesics":
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
        print(
            json.dumps(
                {
                    "out": str(out.resolve()),
                    "setting": bench.setting,
                    "method": args.geodesic_method,
                    "splits": args.splits,
                    "matrices": len(list((out / GEODESIC_FOLDER).glob("*.npy"))),
                    "bytes": sum(p.stat().st_size for p in (out / GEODESIC_FOLDER).glob("*.npy")),
                    "linked": sum(p.stat().st_nlink > 1 for p in (out / GEODESIC_FOLDER).glob("*.npy")),
                    "dsmk_files": len({r["dsmk_file"] for r in rows if r["dsmk_file"]}),
                    "dsmk_bytes": sum(p.stat().st_size for p in out.glob(f"{DSMK_FOLDER}/*/dist/*.npz")),
                }
            )
        )
        return 0
    if args.export_kind == "export-released":
        if bench.setting not in out.resolve().parts:
            print(
                f"becos export-released: note: DeepShapeMatchingKit's BeCoSDataset reads the setting from "
                f"its data_root path; name the folder after it (e.g. {out / bench.setting})",
                file=sys.stderr,
            )
        write_released(
            bench.records(), out, setting=bench.setting, metadata=bench.metadata, overwrite=args.force, progress=True
        )
    elif args.export_kind == "export-ulrssm":
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
    elif args.export_kind == "export-dpfm":
        write_dpfm(bench.records(), out, metadata=bench.metadata, overwrite=args.force, progress=True)
    else:
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
    with open(out / IDS_FILE, encoding="utf-8", newline="") as fh:
        splits = [row["split"] for row in csv.DictReader(fh)]
    result = {
        "out": str(out.resolve()),
        "setting": bench.setting,
        "pairs": {s: splits.count(s) for s in dict.fromkeys(splits)},
    }
    if args.export_kind in ("export-psmal", "export-ulrssm"):
        result["geodesics"] = args.geodesic_method if args.geodesics else None
    summary = out / "logs" / "geodesics.json"
    if args.export_kind == "export-ulrssm" and summary.exists():
        done = json.loads(summary.read_text(encoding="utf-8"))
        result.update({k: done[k] for k in ("written", "hard_links", "copies", "bytes")})
    print(json.dumps(result))
    return 0
