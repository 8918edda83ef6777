"""Workflow scale benchmark (issue 4): prints JSON, asserts nothing.

Measures, on the TOSCA meshes of ``../shared`` (all 76 shapes, partial-to-partial):

- ``dag_10k``: seconds of ``snakemake -n`` on a ~10,000-pair configuration (after the dataset check,
  so the whole job graph is known), and its job counts;
- ``run_1000``: wall time, pairs/s and peak RSS (largest single process) of a ~1,000-pair run on
  ``--cores 2`` from scratch (remeshing included); the reference needs ~6.2 s per pair here
  (0.16 pairs/s);
- ``noop_rerun``: seconds of a second ``snakemake`` call on the finished 1,000-pair run;
- ``run_100``: the same for ~100 pairs (remesh files copied from the 1,000-pair run), for the peak-RSS
  ratio ``rss_ratio_1000_vs_100``.

Usage::

    python benchmarks/workflow.py [--workdir /tmp/becos-bench] [--variants 1] [--skip-run]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import psutil
import yaml

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"


def becos_code() -> Path:
    out = subprocess.run([str(SHARED / "unpack")], check=True, capture_output=True, text=True).stdout
    return Path(out.strip().splitlines()[-1])


def write_config(workdir: Path, code: Path, **overrides) -> None:
    config = {"synthetic": {"enabled": False}, "data_dir": str(code / "data"), "annotations": str(code),
              "datasets": ["tosca"], "template_file": "templates_tosca_demo.csv", "setting": "partial_partial",
              "combinations": "all", "store_vis": False,
              "exports": {"released": False, "published_pickle": False, "report": False}}
    config.update(overrides)
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))


class PeakRss:
    """Largest RSS of any single process in the tree under ``pid``, sampled every 0.2 s."""

    def __init__(self, pid: int):
        self.root, self.peak, self.peak_cmd = psutil.Process(pid), 0, ""
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        while not self._stop.is_set():
            try:
                procs = [self.root, *self.root.children(recursive=True)]
            except psutil.NoSuchProcess:
                return
            for p in procs:
                try:
                    rss = p.memory_info().rss
                    if rss > self.peak:
                        self.peak, self.peak_cmd = rss, " ".join(p.cmdline()[:6])
                except (psutil.NoSuchProcess, psutil.AccessDenied):
                    pass
            time.sleep(0.2)

    def stop(self) -> dict:
        self._stop.set()
        self._thread.join()
        return {"peak_rss_mb": round(self.peak / 2**20, 1), "peak_process": self.peak_cmd}


def snakemake(workdir: Path, *args: str) -> tuple[float, str, dict]:
    cmd = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "-d", str(workdir),
           "--configfile", str(workdir / "config.yaml"), *args]
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    rss = PeakRss(proc.pid)
    out, _ = proc.communicate()
    seconds = time.perf_counter() - start
    memory = rss.stop()
    if proc.returncode != 0:
        raise SystemExit(f"snakemake {' '.join(args)} failed in {workdir}:\n{out[-5000:]}")
    return seconds, out, memory


def job_counts(text: str) -> dict[str, int]:
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^([a-z_]+)\s+(\d+)$", text, re.M)}


def n_pairs(workdir: Path) -> int:
    return sum(1 for _ in open(workdir / "results" / "partial_partial" / "manifest.csv")) - 1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/becos-bench"))
    parser.add_argument("--variants", type=int, default=1, help="remesh variants per shape (default 1)")
    parser.add_argument("--skip-run", action="store_true", help="only the 10k-pair dry run")
    args = parser.parse_args()
    code = becos_code()
    result: dict = {"machine_cores": os.cpu_count()}

    dag = args.workdir / "dag10k"
    shutil.rmtree(dag, ignore_errors=True)
    write_config(dag, code, usage_scale=3.86, remesh_variants=4)
    snakemake(dag, "--cores", "2", "--until", "check_datasets")
    seconds, out, _ = snakemake(dag, "-n", "--cores", "2")
    result["dag_10k"] = {"seconds": round(seconds, 2), "jobs": job_counts(out)}
    if args.skip_run:
        print(json.dumps(result, indent=1))
        return

    caps = {"train": None, "val": None, "test": None}
    big = args.workdir / "run1000"
    shutil.rmtree(big, ignore_errors=True)
    write_config(big, code, usage_scale=0.38, remesh_variants=args.variants, caps=caps)
    seconds, out, memory = snakemake(big, "--cores", "2")
    pairs = n_pairs(big)
    result["run_1000"] = {"pairs": pairs, "seconds": round(seconds, 1), "pairs_per_second": round(pairs / seconds, 3),
                          "reference_pairs_per_second": 0.16, **memory, "jobs": job_counts(out),
                          "remesh_variants": args.variants}
    seconds, out, _ = snakemake(big, "--cores", "2")
    result["noop_rerun"] = {"seconds": round(seconds, 2), "nothing_to_do": "Nothing to be done" in out}

    small = args.workdir / "run100"
    shutil.rmtree(small, ignore_errors=True)
    write_config(small, code, usage_scale=0.038, remesh_variants=args.variants, caps=caps)
    shutil.copytree(big / "results" / "remeshed", small / "results" / "remeshed")
    seconds, out, memory = snakemake(small, "--cores", "2")
    result["run_100"] = {"pairs": n_pairs(small), "seconds": round(seconds, 1), **memory, "jobs": job_counts(out)}
    result["rss_ratio_1000_vs_100"] = round(result["run_1000"]["peak_rss_mb"] / result["run_100"]["peak_rss_mb"], 3)
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
