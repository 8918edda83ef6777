"""Disk and cost of the geodesics export on the default run with every export on (issue 33): prints JSON.

Runs ``--repo``'s workflow (default: this checkout) in ``--workdir`` on ``--cores 2`` with the default
configuration (``config/config.yaml``: the built-in synthetic collection) and every export on
(released, PSMAL, ULRSSM, DPFM, published pickle, report), in two steps:

1. everything but the geodesics (``exports.geodesics: false``);
2. the same configuration with ``exports.geodesics: true``, ``geodesic_splits: [test]`` and
   ``geodesic_layouts`` (default: both, ``geo-lora dsmk``): only the geodesic jobs run, so this step's
   wall and CPU are the geodesics export's.

Prints both steps' wall and CPU seconds (CPU of Snakemake and every job; by process kind: ``becos
geodesic-plan``, ``geodesic-rows``, ``export-geodesics``), the largest process's peak RSS, and the disk
of every export folder per setting in GB, a file with several hard links counted once (as ``du``
does), and per setting the geodesics folder's GB by layout. Asserts nothing.

Usage::

    python benchmarks/geodesics_export.py [--workdir /tmp/becos-geodesics] [--repo PATH]
        [--layouts geo-lora dsmk]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from workflow import REPO, measured_run  # noqa: E402

SETTINGS = ("full_full", "partial_full", "partial_partial")
EXPORT_FOLDERS = ("benchmark.zarr", "released", "psmal", "ulrssm", "dpfm", "geodesics", "pairs", "ground_truth")


def disk_bytes(folder: Path, seen: set | None = None) -> int:
    """Bytes of the files below ``folder`` (allocated blocks, as ``du``), each inode counted once across
    calls sharing ``seen``."""
    seen = set() if seen is None else seen
    total = 0
    for root, _, files in os.walk(folder):
        for name in files:
            st = os.lstat(os.path.join(root, name))
            if (st.st_dev, st.st_ino) in seen:
                continue
            seen.add((st.st_dev, st.st_ino))
            total += st.st_blocks * 512
    return total


def gb(n: int) -> float:
    return round(n / 1e9, 3)


def disk_report(results: Path) -> dict:
    """GB per setting and export folder (hard links once per folder), the geodesics folder by layout,
    and the whole results tree (hard links once across settings)."""
    out = {}
    for setting in SETTINGS:
        base = results / setting
        entry = {name: gb(disk_bytes(base / name)) for name in EXPORT_FOLDERS if (base / name).exists()}
        geodesics = base / "geodesics"
        if geodesics.exists():
            entry["geodesics_by_layout"] = {
                "geo-lora": gb(disk_bytes(geodesics / "geodesic_dist_matrices")),
                "dsmk": gb(disk_bytes(geodesics / "dsmk")),
            }
        out[setting] = entry
    shared: set = set()
    out["all_settings_geodesics"] = gb(sum(disk_bytes(results / s / "geodesics", shared) for s in SETTINGS))
    out["results_total"] = gb(disk_bytes(results))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/becos-geodesics"))
    parser.add_argument("--repo", type=Path, default=REPO, help="checkout whose workflow and code run")
    parser.add_argument("--layouts", nargs="+", default=["geo-lora", "dsmk"])
    args = parser.parse_args()
    shutil.rmtree(args.workdir, ignore_errors=True)
    run = args.workdir / "run"
    run.mkdir(parents=True)
    config = yaml.safe_load((args.repo / "config" / "config.yaml").read_text())
    config["exports"] = {**config.get("exports", {}), "psmal": True, "ulrssm": True, "dpfm": True}
    config["exports"]["geodesics"] = False
    (run / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
    first = measured_run(args.workdir, run, args.repo)
    config["exports"].update(geodesics=True, geodesic_splits=["test"], geodesic_layouts=args.layouts)
    (run / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
    second = measured_run(args.workdir, run, args.repo)
    print(
        json.dumps(
            {
                "config": "config/config.yaml, every export on; geodesics: test split, layouts "
                + " ".join(args.layouts),
                "without_geodesics": first,
                "geodesics_export": second,
                "disk_gb": disk_report(run / "results"),
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
