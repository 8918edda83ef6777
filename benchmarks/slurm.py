"""SLURM submissions and per-job overhead, with and without job grouping (issue #30, item 3): prints JSON.

Runs one configuration (default: the built-in synthetic one, config/config.yaml) in its own working
directory per mode, under ``--workdir``:

- ``local``: ``snakemake --cores 2`` (skipped with ``--local DIR``: an earlier local run of the same
  configuration and code, compared as it is);
- ``grouped``: ``--profile profiles/slurm`` as shipped (groups ``remesh``, ``dt4d``, ``chunk`` batched by
  its ``group-components``);
- ``ungrouped``: the same profile with every job its own SLURM job (``--group-components remesh=1 dt4d=1
  chunk=1 --groups ground_truth=ground_truth pairs=pairs``: one-job groups, as many submissions as a
  workflow without ``group:``).

on the single-node cluster of ``cluster/slurm_harness.py`` (started here, as root, and stopped at the
end; ``--state DIR`` uses one already running). Per SLURM run: the sbatch submissions (Snakemake's
``has been submitted with SLURM jobid`` lines, checked against ``sacct --name <run id>``), the SLURM jobs
by group or rule (their comment), the Snakemake jobs they ran, wall seconds, the overhead per
submission ((SLURM wall - local wall) / submissions), the start latency (sacct ``Start - Submit``:
median, mean, max), the jobs' summed ``Elapsed``, the CPU seconds of the SLURM jobs (sacct ``TotalCPU``:
batch scripts and steps) and of the login-node Snakemake, the extra CPU over the local run (Snakemake
and its jobs) in all and per submission (load-independent, unlike wall), and whether every digest of
``tests/tiny_tosca.py::results_fingerprint`` (result files, remeshes, ground truth, pair files, store
arrays, offsets, metas, tables, metadata) equals the local run's (:func:`compare`: the few files that
quote the working directory's path are compared by content or skipped). Wall times on a shared machine count
other users' load: compare runs made back to back. Status checks every ``--status-seconds`` (the
plugin's defaults, 40 s before the first and 10 s between, add up to 10 s per dependent step).

``--compare LOCAL SLURM`` only compares two finished runs' folders (no cluster, no run): e.g. a SLURM
run with the local run brought to the same code by Snakemake.

Usage (root)::

    python benchmarks/slurm.py --workdir /tmp/becos-slurm-bench [--configfile config/config.yaml]
        [--modes local,grouped,ungrouped] [--local DIR] [--repo PATH] [--state DIR] [--config KEY=VALUE ...]
    python benchmarks/slurm.py --compare LOCAL_RUN SLURM_RUN
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))  # snakemake_cmd, tiny_tosca.results_fingerprint

from snakemake_cmd import snakemake_cmd  # noqa: E402
from tiny_tosca import fingerprint_differences, results_fingerprint  # noqa: E402

from becos.settings import SETTINGS  # noqa: E402

UNGROUPED = [
    "--group-components",
    "remesh=1",
    "dt4d=1",
    "chunk=1",
    "--groups",
    "ground_truth=ground_truth",
    "pairs=pairs",
]
"""Command-line options that make every job of the shipped profile its own SLURM job."""


PATH_DEPENDENT = ("checks/datasets.json", "cache/input_digests.json")
"""Result files that quote the working directory's absolute paths (its data and annotation folders)."""


def compare(reference: dict[str, str], got: dict[str, str]) -> dict:
    """Two :func:`results_fingerprint` results of runs in different working directories: every digest
    equal, except :data:`PATH_DEPENDENT` (skipped) and the files under ``cache/``, whose names carry a
    hash of their source's path (compared by content, as a multiset)."""

    def exact(fp):
        return {k: v for k, v in fp.items() if not k.startswith("cache/") and k not in PATH_DEPENDENT}

    def cache(fp):
        return sorted(v for k, v in fp.items() if k.startswith("cache/") and k not in PATH_DEPENDENT)

    differ = fingerprint_differences(exact(reference), exact(got))
    return {
        "digests_compared": len(exact(reference)),
        "identical_to_local": not differ,
        "differing": differ[:20],
        "cache_files_compared": len(cache(reference)),
        "cache_contents_identical": cache(reference) == cache(got),
    }


def load_harness():
    spec = importlib.util.spec_from_file_location("slurm_harness", REPO / "cluster" / "slurm_harness.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run_snakemake(workdir: Path, args: list[str], env: dict[str, str], repo: Path) -> dict:
    """Run ``repo``'s Snakefile in ``workdir`` (its config.yaml); wall and CPU seconds (Snakemake and
    its child processes: all jobs of a local run, only the login-node side of a SLURM run) and the output."""
    start, cpu_start = time.perf_counter(), _children_cpu()
    result = subprocess.run(
        snakemake_cmd(workdir, *args, repo=repo), cwd=workdir, env=env, capture_output=True, text=True
    )
    seconds = time.perf_counter() - start
    output = result.stdout + result.stderr
    (workdir / "snakemake.out").write_text(output)
    if result.returncode != 0:
        raise SystemExit(
            f"snakemake {' '.join(args)} failed in {workdir} (exit {result.returncode}):\n{output[-6000:]}"
        )
    return {"wall_s": round(seconds, 1), "cpu_s": round(_children_cpu() - cpu_start, 1), "output": output}


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def snakemake_jobs(output: str) -> int:
    """Jobs Snakemake ran (its last ``N of M steps`` line)."""
    steps = re.findall(r"(\d+) of (\d+) steps", output)
    return int(steps[-1][0]) if steps else 0


def sacct_jobs(harness, run_id: str) -> list[dict[str, str]]:
    fields = [
        "JobID",
        "State",
        "ExitCode",
        "Submit",
        "Start",
        "End",
        "Elapsed",
        "Timelimit",
        "ReqMem",
        "AllocCPUS",
        "Comment",
    ]
    out = harness.run(
        "sacct", "-a", "-X", "-n", "-P", "-S", "now-1days", "--name", run_id, f"--format={','.join(fields)}"
    ).stdout
    jobs = [dict(zip(fields, line.split("|"))) for line in out.splitlines() if line.strip()]
    # TotalCPU of an allocation is 0 with -X; without it the allocation line sums its batch script and steps
    ids = ",".join(j["JobID"] for j in jobs)
    out = harness.run("sacct", "-a", "-n", "-P", "-j", ids, "--format=JobID,TotalCPU").stdout if jobs else ""
    total = dict(line.split("|") for line in out.splitlines() if line.strip() and "." not in line.split("|")[0])
    for job in jobs:
        job["TotalCPU"] = total.get(job["JobID"], "0:00")
    return jobs


def _seconds(text: str) -> float:
    """sacct's ``[D-][HH:]MM:SS[.mmm]`` as seconds."""
    days, _, hms = text.rpartition("-")
    parts = [float(x) for x in hms.split(":")]
    while len(parts) < 3:
        parts.insert(0, 0.0)
    return int(days or 0) * 86400 + parts[0] * 3600 + parts[1] * 60 + parts[2]


def slurm_figures(harness, run: dict, local: dict) -> dict:
    """Submissions, requests, latency, wall and CPU of one SLURM run against the local run (``local``:
    its ``wall_s`` and ``cpu_s``, or None when not measured here)."""
    output, wall_s = run["output"], run["wall_s"]
    run_id = re.search(r"SLURM run ID: (\S+)", output).group(1)
    submitted = re.findall(r"has been submitted with SLURM jobid (\d+)", output)
    jobs = sacct_jobs(harness, run_id)
    by_kind: dict[str, dict] = {}
    for job in jobs:
        # a single job's comment names its rule, a group job's its group and rules (remesh_remesh)
        kind = re.match(r"rule_([a-z0-9_]+?)(_wildcards_.*)?$", job["Comment"]).group(1)
        entry = by_kind.setdefault(kind, {"jobs": 0, "requests": set(), "longest_elapsed_s": 0})
        entry["jobs"] += 1
        entry["requests"].add(f"{job['AllocCPUS']} CPUs, {job['ReqMem']}, {job['Timelimit']}")
        entry["longest_elapsed_s"] = max(entry["longest_elapsed_s"], _seconds(job["Elapsed"]))
    for entry in by_kind.values():
        entry["requests"] = sorted(entry["requests"])
    stamp = "%Y-%m-%dT%H:%M:%S"
    latency = [
        (datetime.strptime(j["Start"], stamp) - datetime.strptime(j["Submit"], stamp)).total_seconds() for j in jobs
    ]
    n = len(submitted)
    jobs_cpu = sum(_seconds(j["TotalCPU"]) for j in jobs)  # batch script and every srun step of every job
    local_wall_s, local_cpu_s = local.get("wall_s"), local.get("cpu_s")
    extra_cpu = jobs_cpu + run["cpu_s"] - local_cpu_s if local_cpu_s else None
    return {
        "run_id": run_id,
        "sbatch_submissions": n,
        "sacct_jobs": len(jobs),
        "sacct_equals_submitted": sorted(submitted) == sorted(j["JobID"] for j in jobs),
        "all_completed": all((j["State"], j["ExitCode"]) == ("COMPLETED", "0:0") for j in jobs),
        "slurm_jobs_by_group_or_rule": dict(sorted(by_kind.items())),
        "snakemake_jobs": snakemake_jobs(output),
        "wall_s": wall_s,
        "overhead_per_submission_s": round((wall_s - local_wall_s) / n, 2) if local_wall_s and n else None,
        "start_latency_s": {
            "median": statistics.median(latency),
            "mean": round(statistics.fmean(latency), 2),
            "max": max(latency),
        }
        if latency
        else None,
        "sum_elapsed_s": sum(_seconds(j["Elapsed"]) for j in jobs),
        "cpu_s": {"slurm_jobs": round(jobs_cpu, 1), "login_node_snakemake": run["cpu_s"]},
        "extra_cpu_s": round(extra_cpu, 1) if extra_cpu is not None else None,
        "extra_cpu_per_submission_s": round(extra_cpu / n, 2) if extra_cpu is not None and n else None,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workdir", type=Path, help="one folder per mode is made below it")
    parser.add_argument("--configfile", type=Path, default=REPO / "config" / "config.yaml")
    parser.add_argument("--config", nargs="*", default=[], help="extra --config KEY=VALUE for every run")
    parser.add_argument("--modes", default="local,grouped,ungrouped")
    parser.add_argument("--local", type=Path, help="an earlier local run's working directory (skips mode local)")
    parser.add_argument("--local-wall", type=float, help="that run's wall seconds, for the overhead per submission")
    parser.add_argument("--local-cpu", type=float, help="that run's CPU seconds (Snakemake and all its jobs)")
    parser.add_argument("--repo", type=Path, default=REPO, help="the checkout whose Snakefile and profile run")
    parser.add_argument("--state", type=Path, help="state folder of a running harness cluster (else one is started)")
    parser.add_argument("--status-seconds", default="2", help="seconds before the first and between status checks")
    parser.add_argument(
        "--compare", nargs=2, type=Path, metavar=("LOCAL", "SLURM"), help="only compare two finished runs' folders"
    )
    args = parser.parse_args()
    if args.compare:
        # the settings whose store the first run has (a one-setting run compares that setting)
        stores = [s for s in SETTINGS if (args.compare[0] / "results" / s / "benchmark.zarr" / "zarr.json").is_file()]
        missing = [
            f"{path}/results/{s}"
            for path in args.compare[1:]
            for s in stores
            if not (path / "results" / s / "benchmark.zarr" / "zarr.json").is_file()
        ]
        if missing:
            sys.exit(f"--compare: no store in {', '.join(missing)}; the first run has one (finish that run first)")
        local, slurm = (results_fingerprint(path, stores) for path in args.compare)
        print(
            json.dumps({"local": str(args.compare[0]), "slurm": str(args.compare[1])} | compare(local, slurm), indent=1)
        )
        return
    if args.workdir is None:
        parser.error("--workdir is required (unless --compare)")

    repo = args.repo.resolve()
    modes = args.modes.split(",")
    config = yaml.safe_load(args.configfile.read_text())
    extra = ["--config", *args.config] if args.config else []
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith(("SLURM_", "SBATCH_", "SRUN_")) and k != "SNAKEMAKE_PROFILE"
    }
    # the jobs' `becos` runs this checkout's code, whatever the environment installed
    env.update(PYTHONPATH=os.pathsep.join(p for p in (str(repo), env.get("PYTHONPATH")) if p), PYTHONUNBUFFERED="1")
    report: dict = {"configfile": str(args.configfile), "config": args.config, "repo": str(repo)}

    def workdir(mode: str) -> Path:
        path = args.workdir / mode
        shutil.rmtree(path, ignore_errors=True)
        path.mkdir(parents=True)
        (path / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
        return path

    local_dir = args.local
    if "local" in modes and local_dir is None:
        local_dir = workdir("local")
        run = run_snakemake(local_dir, ["--cores", "2", *extra], env, repo)
        report["local"] = {
            "wall_s": run["wall_s"],
            "cpu_s": run["cpu_s"],
            "snakemake_jobs": snakemake_jobs(run["output"]),
        }
    elif local_dir is not None:
        report["local"] = {
            "workdir": str(local_dir),
            "wall_s": args.local_wall,
            "cpu_s": args.local_cpu,
            "note": "an earlier run, not timed here",
        }
    settings = config.get("setting", ["full_full", "partial_full", "partial_partial"])

    harness_module = load_harness()
    own_state = args.state is None
    state = Path(tempfile.mkdtemp(prefix="becos-slurm-")) if own_state else args.state
    harness = harness_module.SlurmHarness(state)
    try:
        if own_state:
            harness.start()
            report["cluster_start_s"] = round(harness.timings.get("start_s", 0.0), 1)
        report["node"] = json.loads((state / "harness.json").read_text())["hardware"] if own_state else None
        slurm_env = dict(
            env, **harness.env(), BECOS_SLURM_ACCOUNT=harness.account, BECOS_SLURM_PARTITION=harness.partition
        )
        status = [
            "--slurm-init-seconds-before-status-checks",
            args.status_seconds,
            "--seconds-between-status-checks",
            args.status_seconds,
        ]
        for mode in ("grouped", "ungrouped"):
            if mode not in modes:
                continue
            path = workdir(mode)
            options = [
                "--profile",
                str(repo / "profiles" / "slurm"),
                *status,
                *(UNGROUPED if mode == "ungrouped" else []),
            ]
            run = run_snakemake(path, [*options, *extra], slurm_env, repo)
            figures = slurm_figures(harness, run, report.get("local", {}))
            report[mode] = figures
    finally:
        if own_state:
            harness.stop()
            shutil.rmtree(state, ignore_errors=True)
    if local_dir is not None:  # read last: --local may name a run that was still going when this started
        reference = results_fingerprint(local_dir, settings)
        for mode in ("grouped", "ungrouped"):
            if mode in report:
                report[mode].update(compare(reference, results_fingerprint(args.workdir / mode, settings)))
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
