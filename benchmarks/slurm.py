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
median, mean, max), the jobs' summed ``Elapsed``, and whether every digest of
``tests/tiny_tosca.py::results_fingerprint`` (result files, remeshes, ground truth, pair files, store
arrays, offsets, metas, tables, metadata) equals the local run's. Wall times on a shared machine count
other users' load: compare runs made back to back. Status checks every ``--status-seconds`` (the
plugin's defaults, 40 s before the first and 10 s between, add up to 10 s per dependent step).

Usage (root)::

    python benchmarks/slurm.py --workdir /tmp/becos-slurm-bench [--configfile config/config.yaml]
        [--modes local,grouped,ungrouped] [--local DIR] [--repo PATH] [--state DIR] [--config KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import re
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


def load_harness():
    spec = importlib.util.spec_from_file_location("slurm_harness", REPO / "cluster" / "slurm_harness.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run_snakemake(workdir: Path, args: list[str], env: dict[str, str], repo: Path) -> dict:
    """Run ``repo``'s Snakefile in ``workdir`` (its config.yaml); wall seconds and the output."""
    start = time.perf_counter()
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
    return {"wall_s": round(seconds, 1), "output": output}


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
    return [dict(zip(fields, line.split("|"))) for line in out.splitlines() if line.strip()]


def _seconds(text: str) -> int:
    """sacct's ``[D-]HH:MM:SS`` as seconds."""
    days, _, hms = text.rpartition("-")
    h, m, s = (int(x) for x in hms.split(":"))
    return int(days or 0) * 86400 + h * 3600 + m * 60 + s


def slurm_figures(harness, output: str, wall_s: float, local_wall_s: float | None) -> dict:
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
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workdir", type=Path, required=True, help="one folder per mode is made below it")
    parser.add_argument("--configfile", type=Path, default=REPO / "config" / "config.yaml")
    parser.add_argument("--config", nargs="*", default=[], help="extra --config KEY=VALUE for every run")
    parser.add_argument("--modes", default="local,grouped,ungrouped")
    parser.add_argument("--local", type=Path, help="an earlier local run's working directory (skips mode local)")
    parser.add_argument("--repo", type=Path, default=REPO, help="the checkout whose Snakefile and profile run")
    parser.add_argument("--state", type=Path, help="state folder of a running harness cluster (else one is started)")
    parser.add_argument("--status-seconds", default="2", help="seconds before the first and between status checks")
    args = parser.parse_args()

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

    local_dir, local_wall = args.local, None
    if "local" in modes and local_dir is None:
        local_dir = workdir("local")
        run = run_snakemake(local_dir, ["--cores", "2", *extra], env, repo)
        local_wall = run["wall_s"]
        report["local"] = {"wall_s": local_wall, "snakemake_jobs": snakemake_jobs(run["output"])}
    elif local_dir is not None:
        report["local"] = {"workdir": str(local_dir), "wall_s": None, "note": "earlier run, not timed here"}
    settings = config.get("setting", ["full_full", "partial_full", "partial_partial"])
    reference = results_fingerprint(local_dir, settings) if local_dir else None

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
            figures = slurm_figures(harness, run["output"], run["wall_s"], local_wall)
            if reference is not None:
                got = results_fingerprint(path, settings)
                differ = fingerprint_differences(reference, got)
                figures["digests_compared"] = len(reference)
                figures["identical_to_local"] = not differ
                figures["differing"] = differ[:20]
            report[mode] = figures
    finally:
        if own_state:
            harness.stop()
            shutil.rmtree(state, ignore_errors=True)
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
