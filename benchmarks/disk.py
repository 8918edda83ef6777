"""Disk of a finished run, in the two parts of issue #31's decision 2: prints JSON, asserts nothing.

Measured on a run folder (its ``results``, read through :class:`becos.workflow.layout.Layout`), per
setting and in MB (10^6 bytes) per pair of that setting:

- ``incremental``: what the run needs to stay incremental: the pair records (``pairs/``, with their
  chunk indexes), the ground truth (``ground_truth/``) and the store (``benchmark.zarr``), and their sum
  (issue #31's goal: at most 2 MB per pair);
- ``exports``: each export that is on disk: the released layout, PSMAL, ULRSSM, DPFM, geodesics, the
  published pickle and the report.

Sizes are apparent bytes (``st_size``) with every file counted once per inode: the geodesics export
hard-links each full mesh's matrix into every pair, side and setting that uses it, so a setting's
figure counts a file once however many names it has there, and ``all_settings`` counts it once across
settings (the sum of the settings' figures can be larger). ``allocated_mb`` is the same from the blocks
the file system allocated (``st_blocks``: small files take a whole block). Shared by every setting
(reported once, per pair of all settings): the remesh variants (``remeshed/``) and the parse cache
(``cache/``, safe to delete).

Usage::

    python benchmarks/disk.py RUN_FOLDER [--results results]
"""

from __future__ import annotations

import argparse
import json
import os
import stat
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from becos.settings import SETTINGS  # noqa: E402
from becos.workflow.layout import Layout  # noqa: E402

MB = 1e6


def files_under(path: Path) -> dict[tuple[int, int], os.stat_result]:
    """(device, inode) -> status of every regular file at or under ``path`` (none if it does not exist)."""
    if path.is_file():
        st = path.stat()
        return {(st.st_dev, st.st_ino): st}
    out = {}
    for folder, _, names in os.walk(path):
        for name in names:
            st = os.lstat(os.path.join(folder, name))
            if stat.S_ISREG(st.st_mode):  # symbolic links: their target is counted where it lies
                out[(st.st_dev, st.st_ino)] = st
    return out


def size(files: dict[tuple[int, int], os.stat_result]) -> dict[str, float]:
    """Apparent and allocated bytes of a set of files, each inode once."""
    return {
        "bytes": sum(st.st_size for st in files.values()),
        "allocated": sum(st.st_blocks * 512 for st in files.values()),
        "files": len(files),
    }


def per_pair(measured: dict, pairs: int) -> dict:
    return {
        "mb": round(measured["bytes"] / MB, 2),
        "mb_per_pair": round(measured["bytes"] / MB / max(pairs, 1), 3),
        "allocated_mb_per_pair": round(measured["allocated"] / MB / max(pairs, 1), 3),
        "files": measured["files"],
    }


def n_pairs(layout: Layout, setting: str) -> int:
    manifest = layout.manifest(setting)
    return max(len(manifest.read_text().splitlines()) - 1, 0) if manifest.is_file() else 0


def measure(run: Path, results: str = "results") -> dict:
    layout = Layout(run / results)
    out: dict = {"run": str(run), "settings": {}}
    export_paths = {
        "released": layout.released,
        "psmal": layout.psmal,
        "ulrssm": layout.ulrssm,
        "dpfm": layout.dpfm,
        "geodesics": layout.geodesics,
        "published_pickle": layout.published_pickle,
        "report": layout.report,
    }
    every_export: dict[str, dict] = {name: {} for name in export_paths}
    total_pairs = 0
    for setting in SETTINGS:
        pairs = n_pairs(layout, setting)
        if not pairs:
            continue
        total_pairs += pairs
        parts = {
            "records": files_under(layout.pairs_folder(setting)),
            "ground_truth": files_under(layout.ground_truth_folder(setting)),
            "store": files_under(layout.store(setting)),
        }
        incremental = {name: per_pair(size(files), pairs) for name, files in parts.items()}
        everything = {k: v for files in parts.values() for k, v in files.items()}
        incremental["total"] = per_pair(size(everything), pairs)
        exports = {}
        for name, path in export_paths.items():
            files = files_under(path(setting))
            if files:
                exports[name] = per_pair(size(files), pairs)
                every_export[name].update(files)
        out["settings"][setting] = {"pairs": pairs, "incremental": incremental, "exports": exports}
    out["all_settings"] = {
        "pairs": total_pairs,
        "exports": {name: per_pair(size(files), total_pairs) for name, files in every_export.items() if files},
        "shared": {
            "remeshed": per_pair(size(files_under(layout.remeshed_root)), total_pairs),
            "cache": per_pair(size(files_under(layout.cache)), total_pairs),
        },
    }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="the run folder (Snakemake's working directory)")
    parser.add_argument("--results", default="results", help="its results folder (config key results)")
    args = parser.parse_args()
    print(json.dumps(measure(args.run.resolve(), args.results), indent=1))


if __name__ == "__main__":
    main()
