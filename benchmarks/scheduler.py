"""Snakemake's own CPU per job selector, ILP against greedy, as the job count grows (issue #30): prints JSON.

A workflow of ``--jobs`` independent one-line ``shell:`` jobs (all ready at once, as becos's remesh
variants are after the manifests; with ``--own-input`` each reads a file of its own) runs from scratch with ``--cores 2 --scheduler S`` for each selector
and size, alternating. Per run: wall and the Snakemake process tree's CPU seconds (user + system, the
jobs' ``echo`` included, the same for both selectors). ``growth``: the log-log slope of CPU in the job
count per selector (1: linear). becos's workflow profile (profiles/default) selects ``greedy`` with
``--scheduler-subsample 100``; ``--subsample N`` compares greedy with and without it instead of ILP.

``--job-seconds S`` makes each job last S seconds (``sleep``), as real jobs do: Snakemake's job rate
limiter (``--max-jobs-per-timespan``, default 100/1s) starts a re-evaluation timer of one timespan at the
end of every scheduling round that leaves ready jobs waiting, and each timer's round starts another, so
the rounds per second grow with the jobs finished while others wait (snakemake/snakemake#3744), and each
round sizes the ready jobs' inputs. ``--timespan SPEC`` (e.g. ``1000/10s``) adds greedy + subsample with
``--max-jobs-per-timespan SPEC`` (fewer rounds, but Snakemake waits up to one timespan for its timers at
exit) and ``--one-timer`` greedy + subsample with becos's fix, at most one timer pending
(:mod:`becos.workflow.scheduling`, which the workflow applies); each is compared with greedy + subsample. Each run also reports its scheduling rounds
(``Select jobs to execute`` lines).

Usage::

    python benchmarks/scheduler.py [--jobs 100,400,800] [--own-input] [--subsample 100] [--workdir /tmp/becos-scheduler]
    python benchmarks/scheduler.py --jobs 100,200,400 --own-input --job-seconds 0.5 --subsample 100 --one-timer [--timespan 1000/10s]
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
if os.environ["BENCH_ONE_TIMER"] == "1":
    from becos.workflow.scheduling import one_pending_reevaluation
    one_pending_reevaluation()
rule all:
    input: expand("out/{i}.txt", i=range(N))
rule one:
    input: "in/{i}.txt" if OWN_INPUT else []
    output: "out/{i}.txt"
    shell: os.environ["BENCH_SLEEP"] + "echo {wildcards.i} > {output}"
"""


def run(
    workdir: Path,
    scheduler: str,
    jobs: int,
    own_input: bool,
    subsample: int | None = None,
    timespan: str | None = None,
    job_seconds: float = 0.0,
    one_timer: bool = False,
) -> dict:
    """One run from scratch; CPU from the children's rusage difference (Snakemake and its jobs).
    ``subsample``: Snakemake's ``--scheduler-subsample`` (ready jobs the selector sees per round);
    ``timespan``: its ``--max-jobs-per-timespan``; ``job_seconds``: each job's duration (s); ``one_timer``:
    the Snakefile applies :func:`becos.workflow.scheduling.one_pending_reevaluation`."""
    shutil.rmtree(workdir, ignore_errors=True)
    (workdir / "in").mkdir(parents=True)
    (workdir / "Snakefile").write_text(SNAKEFILE)
    for i in range(jobs if own_input else 0):
        (workdir / "in" / f"{i}.txt").write_text(str(i))
    command = [sys.executable, "-m", "snakemake", "--cores", "2", "--scheduler", scheduler]
    command += ["--scheduler-subsample", str(subsample)] if subsample else []
    command += ["--max-jobs-per-timespan", timespan] if timespan else []
    sleep = f"sleep {job_seconds}; " if job_seconds else ""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(
        command,
        cwd=workdir,
        env={
            **os.environ,
            "BENCH_JOBS": str(jobs),
            "BENCH_OWN_INPUT": str(int(own_input)),
            "BENCH_SLEEP": sleep,
            "BENCH_ONE_TIMER": str(int(one_timer)),
            "PYTHONPATH": str(Path(__file__).resolve().parents[1]),
        },
        check=True,
        capture_output=True,
        text=True,
    )
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    assert len(list((workdir / "out").iterdir())) == jobs
    return {
        "scheduler": scheduler
        + (f"+subsample {subsample}" if subsample else "")
        + (f"+timespan {timespan}" if timespan else "")
        + ("+one timer" if one_timer else ""),
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
    parser.add_argument("--job-seconds", type=float, default=0.0, help="each job's duration in seconds (sleep)")
    parser.add_argument(
        "--timespan", help="also greedy + --subsample with --max-jobs-per-timespan SPEC (e.g. 1000/10s)"
    )
    parser.add_argument(
        "--one-timer", action="store_true", help="also greedy + --subsample with becos's one pending timer"
    )
    args = parser.parse_args()
    sizes = [int(n) for n in args.jobs.split(",")]
    if args.timespan or args.one_timer:
        variants = [("greedy", args.subsample, None, False)]
        variants += [("greedy", args.subsample, args.timespan, False)] if args.timespan else []
        variants += [("greedy", args.subsample, None, True)] if args.one_timer else []
    elif args.subsample:
        variants = [("greedy", None, None, False), ("greedy", args.subsample, None, False)]
    else:
        variants = [("ilp", None, None, False), ("greedy", None, None, False)]
    runs = []
    for n in sizes:
        for s, sub, span, one in variants:
            runs.append(run(args.workdir, s, n, args.own_input, sub, span, args.job_seconds, one))
            print(json.dumps(runs[-1]), file=sys.stderr, flush=True)
    growth = {}
    for name in dict.fromkeys(r["scheduler"] for r in runs):
        cpu = [r["cpu_seconds"] for r in runs if r["scheduler"] == name]
        slope = np.polyfit(np.log(sizes), np.log(cpu), 1)[0] if len(sizes) > 1 else float("nan")
        growth[name] = {"cpu_seconds": cpu, "slope": round(float(slope), 3)}
    k = len(variants)
    first = runs[0]["scheduler"]
    ratios = {
        f"cpu_ratio_{first}_over_{runs[j]['scheduler']}": {
            str(n): round(runs[k * i]["cpu_seconds"] / runs[k * i + j]["cpu_seconds"], 2) for i, n in enumerate(sizes)
        }
        for j in range(1, k)
    }
    shutil.rmtree(args.workdir, ignore_errors=True)
    print(json.dumps({"runs": runs, "growth": growth, **ratios}, indent=1))


if __name__ == "__main__":
    main()
