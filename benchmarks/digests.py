"""What content tracking of the input files costs (issue #29): prints JSON, asserts nothing.

:mod:`becos.workflow.digests` hashes every file the dataset check reads (the datasets' mesh files and
the annotation folder) each time Snakemake plans, from a cache keyed on each file's status. Measured, in
this process, on two trees:

- ``standin``: the full-scale stand-in data root of ``tests/standin.py`` (2,537 meshes at the published
  file paths, all 8 dataset entries) with the BeCoS annotation folder: the file count at BeCoS scale;
- ``tosca``: the 76 real TOSCA meshes (174 MB) with the annotation folder: real file sizes, for the
  hashing rate.

Per tree: files, MB, seconds to list them (:func:`becos.workflow.check_input_files`), to hash them with
an empty cache (``cold``; what the first plan after a download costs) and with the cache written
(``warm``: one ``stat`` per file, what every later plan costs), and MB/s of the cold hashing.
``full_scale_cold_seconds_estimate``: the cold time of the real BeCoS data volume (``--data-gb``,
default 3 GB of meshes) at the TOSCA rate.

Usage::

    python benchmarks/digests.py [--workdir /tmp/becos-digests] [--data-gb 3]
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))  # tests/standin.py: the stand-in data root


def becos_code() -> Path:
    out = subprocess.run([str(REPO.parent / "shared" / "unpack")], check=True, capture_output=True, text=True)
    return Path(out.stdout.strip().splitlines()[-1])


def measure(config: dict, cache: Path) -> dict:
    from becos.workflow import DigestCache, check_input_files, resolve_config

    config = resolve_config(config)
    cache.unlink(missing_ok=True)
    start = time.perf_counter()
    files = check_input_files(config)
    listing = time.perf_counter() - start
    size = sum(p.stat().st_size for p in files if p.is_file()) / 1e6
    start = time.perf_counter()
    digests = DigestCache(cache)
    cold_value = digests.files(files)
    digests.save()
    cold = time.perf_counter() - start
    start = time.perf_counter()
    warm_value = DigestCache(cache).files(files)
    warm = time.perf_counter() - start
    assert cold_value == warm_value
    return {
        "files": len(files),
        "mb": round(size, 1),
        "list_seconds": round(listing, 3),
        "cold_seconds": round(cold, 3),
        "warm_seconds": round(warm, 3),
        "cold_mb_per_second": round(size / cold, 1),
        "cache_kb": round(cache.stat().st_size / 1e3, 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/becos-digests"))
    parser.add_argument("--data-gb", type=float, default=3.0, help="BeCoS mesh data volume for the estimate")
    args = parser.parse_args()
    from standin import DATASETS, build_standin_tree

    code = becos_code()
    shutil.rmtree(args.workdir, ignore_errors=True)
    tree = build_standin_tree(args.workdir / "standin", code)
    base = {"synthetic": {"enabled": False}, "annotations": str(code), "check_geometry": False}
    out = {
        "standin": measure(
            {**base, "data_dir": str(tree.data_dir), "datasets": list(DATASETS)}, args.workdir / "standin.json"
        ),
        "tosca": measure(
            {
                **base,
                "data_dir": str(code / "data"),
                "datasets": ["tosca"],
                "template_file": "templates_tosca_demo.csv",
            },
            args.workdir / "tosca.json",
        ),
    }
    rate = out["tosca"]["cold_mb_per_second"]
    out["full_scale_cold_seconds_estimate"] = round(args.data_gb * 1e3 / rate, 1)
    out["data_gb_assumed"] = args.data_gb
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
