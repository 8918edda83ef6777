"""Snakemake's own CPU per job selector, ILP against greedy, as the job count grows (issue #30): prints JSON.

A workflow of ``--jobs`` independent one-line ``shell:`` jobs (all ready at once, as becos's remesh
variants are after the manifests; with ``--own-input`` each reads a file of its own) runs from scratch with ``--cores 2 --scheduler S`` for each selector
and size, alternating. Per run: wall and the Snakemake process tree's CPU seconds (user + system, the
jobs' ``echo`` included, the same for both selectors). ``growth``: the log-log slope of CPU in the job
count per selector (1: linear). becos's workflow profile (profiles/default) selects ``greedy`` with
``--scheduler-subsample 100``; ``--subsample N`` compares greedy with and without it instead of ILP.

Usage::

    python benchmarks/scheduler.py [--jobs 100,400,800] [--own-input] [--subsample 100] [--workdir /tmp/becos-scheduler]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

SNAKEFILE = """\
import os
N = int(os.environ["BENCH_JOBS"])
OWN_INPUT = os.environ["BENCH_OWN_INPUT"] == "1"
rule all:
    input: expand("out/{i}.txt", i=range(N))
rule one:
    input: "in/{i}.txt" if OWN_INPUT else []
    output: "out/{i}.txt"
    shell: "echo {wildcards.i} > {output}"
"""


def run(workdir: Path, scheduler: str, jobs: int, own_input: bool, subsample: int | None = None) -> dict:
    """One run from scratch; CPU from the children's rusage difference (Snakemake and its jobs).
    ``subsample``: Snakemake's ``--scheduler-subsample`` (ready jobs the selector sees per round)."""
    shutil.rmtree(workdir, ignore_errors=True)
    (workdir / "in").mkdir(parents=True)
    (workdir / "Snakefile").write_text(SNAKEFILE)
    for i in range(jobs if own_input else 0):
        (workdir / "in" / f"{i}.txt").write_text(str(i))
    command = [sys.executable, "-m", "snakemake", "--cores", "2", "--scheduler", scheduler, "--quiet", "all"]
    command += ["--scheduler-subsample", str(subsample)] if subsample else []
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(
        command,
        cwd=workdir,
        env={**os.environ, "BENCH_JOBS": str(jobs), "BENCH_OWN_INPUT": str(int(own_input))},
        check=True,
        capture_output=True,
    )
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    assert len(list((workdir / "out").iterdir())) == jobs
    return {
        "scheduler": scheduler + (f"+subsample {subsample}" if subsample else ""),
        "jobs": jobs,
        "own_input": own_input,
        "wall_seconds": round(wall, 2),
        "cpu_seconds": round(cpu, 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", default="100,400,800", help="job counts, comma-separated")
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/becos-scheduler"))
    parser.add_argument(
        "--own-input",
        action="store_true",
        help="each job reads its own input file, as each remesh job reads its shape's mesh (Snakemake checks "
        "the size of every ready job's inputs in every scheduling round)",
    )
    parser.add_argument(
        "--subsample",
        type=int,
        help="compare greedy with greedy plus --scheduler-subsample N (as profiles/default sets) instead of ILP",
    )
    args = parser.parse_args()
    sizes = [int(n) for n in args.jobs.split(",")]
    variants = [("greedy", None), ("greedy", args.subsample)] if args.subsample else [("ilp", None), ("greedy", None)]
    runs = [run(args.workdir, s, n, args.own_input, sub) for n in sizes for s, sub in variants]
    growth = {}
    for name in dict.fromkeys(r["scheduler"] for r in runs):
        cpu = [r["cpu_seconds"] for r in runs if r["scheduler"] == name]
        slope = np.polyfit(np.log(sizes), np.log(cpu), 1)[0] if len(sizes) > 1 else float("nan")
        growth[name] = {"cpu_seconds": cpu, "slope": round(float(slope), 3)}
    first, second = (r["scheduler"] for r in runs[:2])
    ratio = {str(n): round(runs[2 * i]["cpu_seconds"] / runs[2 * i + 1]["cpu_seconds"], 2) for i, n in enumerate(sizes)}
    shutil.rmtree(args.workdir, ignore_errors=True)
    print(json.dumps({"runs": runs, "growth": growth, f"cpu_ratio_{first}_over_{second}": ratio}, indent=1))


if __name__ == "__main__":
    main()
