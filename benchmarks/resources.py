"""Per-rule resource peaks of a real run (issue 7): prints JSON, asserts nothing.

Runs the workflow on all 76 TOSCA shapes of ``../shared`` (all three settings, ~``--pairs`` pairs
per setting, ``--chunks`` chunks per setting) on ``--cores 2`` and samples every ``becos``
process every 0.1 s: each workflow job is one ``becos <sub-command>`` process, so the sub-command
names the rule. Per rule it reports the jobs, the peak RSS of the largest job (MiB), the longest
job's wall time (s), and for rules whose time grows with pairs the seconds per pair (largest over
jobs of time / pairs of the job's chunk or setting), and for remesh (one job per shape) the seconds
per variant. ``--write`` rewrites ``workflow/resources.yaml`` from the peaks (memory × 1.5 rounded up
to 250 MiB, at least 500; time × 3, at least 5 min; seconds per pair or variant × 3).

Usage::

    python benchmarks/resources.py [--workdir /tmp/becos-resources] [--pairs 300] [--chunks 4] [--write]
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import threading
import time
from collections import defaultdict
from datetime import date
from pathlib import Path

import psutil

sys.path.insert(0, str(Path(__file__).resolve().parent))
from workflow import REPO, becos_code, snakemake_cmd, write_config  # noqa: E402

# becos sub-command -> rule
RULES = {
    "write-config": "resolved_config",
    "check": "check_datasets",
    "catalog": "catalog",
    "manifest": "manifest",
    "remesh": "remesh",
    "ground-truth": "ground_truth",
    "pairs": "pairs",
    "metadata": "store_metadata",
    "export-zarr": "zarr_store",
    "validate": "validate_store",
    "export-released": "released_layout",
    "export-psmal": "psmal_layout",
    "export-ulrssm": "ulrssm_layout",
    "export-dpfm": "dpfm_layout",
    "export-geodesics": "geodesics",
    "export-pairings": "published_pairings",
    "report": "report",
    "baseline": "baseline",
    "evaluate": "evaluate",
    "synthetic": "synthetic_collection",
}
SETTINGS = ("full_full", "partial_full", "partial_partial")
# rules whose time grows with pairs: per chunk (ground truth, pairs) or per setting (the rest)
PAIR_RULES = (
    "ground_truth",
    "pairs",
    "zarr_store",
    "validate_store",
    "released_layout",
    "psmal_layout",
    "ulrssm_layout",
    "dpfm_layout",
    "report",
    "baseline",
    "evaluate",
)


class JobSampler:
    """Peak RSS (bytes) and lifetime (s) of every ``becos`` process under ``pid``, sampled every 0.1 s."""

    def __init__(self, pid: int):
        self.root = psutil.Process(pid)
        self.jobs: dict[tuple[int, float], dict] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                children = self.root.children(recursive=True)
            except psutil.NoSuchProcess:
                return
            now = time.monotonic()
            for p in children:
                try:
                    key = (p.pid, p.create_time())  # pids are reused over a long run
                    job = self.jobs.get(key)
                    if job is None:
                        cmd = p.cmdline()
                        words = [w for w in cmd if not w.startswith("-")]
                        if len(cmd) < 2 or not any(Path(w).name == "becos" for w in cmd[:2]):
                            continue
                        sub = words[words.index(next(w for w in words if Path(w).name == "becos")) + 1]
                        job = self.jobs[key] = {
                            "rule": RULES.get(sub, sub),
                            "cmd": cmd,
                            "peak": 0,
                            "start": now,
                            "end": now,
                        }
                    job["peak"] = max(job["peak"], p.memory_info().rss)
                    job["end"] = now
                except (psutil.NoSuchProcess, psutil.AccessDenied, StopIteration, IndexError):
                    pass
            time.sleep(0.1)

    def stop(self) -> list[dict]:
        self._stop.set()
        self._thread.join()
        return list(self.jobs.values())


def job_pairs(workdir: Path, cmd: list[str]) -> int | None:
    """Pairs a job worked on: its chunk's (ground truth, pairs) or its setting's (store, exports,
    evaluation); None for a job of no setting (remesh, catalog ...)."""
    if "--chunk" in cmd:
        setting, chunk = cmd[cmd.index("--setting") + 1], int(cmd[cmd.index("--chunk") + 1])
        index = workdir / "results" / setting / "pairs" / f"chunk_{chunk:04d}.json"
        return json.loads(index.read_text())["n_pairs"]
    for setting in SETTINGS:
        if any(f"/{setting}/" in w or w == setting for w in cmd):
            return sum(1 for _ in open(workdir / "results" / setting / "manifest.csv")) - 1
    return None


def summarise(workdir: Path, jobs: list[dict]) -> dict:
    per_rule: dict[str, dict] = defaultdict(lambda: {"jobs": 0, "peak_rss_mb": 0.0, "max_seconds": 0.0})
    for job in jobs:
        r = per_rule[job["rule"]]
        seconds = job["end"] - job["start"]
        r["jobs"] += 1
        r["peak_rss_mb"] = round(max(r["peak_rss_mb"], job["peak"] / 2**20), 1)
        r["max_seconds"] = round(max(r["max_seconds"], seconds), 1)
        n = job_pairs(workdir, job["cmd"]) if job["rule"] in PAIR_RULES else None
        if n:
            r["max_pairs_per_job"] = max(r.get("max_pairs_per_job", 0), n)
            r["seconds_per_pair"] = round(max(r.get("seconds_per_pair", 0.0), seconds / n), 4)
        if job["rule"] == "remesh":  # one job per shape: --tokens lists its variants
            n = len(job["cmd"][job["cmd"].index("--tokens") + 1].split(","))
            r["max_variants_per_job"] = max(r.get("max_variants_per_job", 0), n)
            r["seconds_per_variant"] = round(max(r.get("seconds_per_variant", 0.0), seconds / n), 4)
    return dict(sorted(per_rule.items()))


# rules this benchmark does not run (baselines and evaluation need `evaluation.baselines`; the PSMAL,
# ULRSSM and DPFM layouts are off by default): written as estimates, marked so
ESTIMATES = {
    "psmal_layout": {"mem_mb": 4000, "runtime": 60},
    "ulrssm_layout": {"mem_mb": 4000, "runtime": 60},
    "dpfm_layout": {"mem_mb": 4000, "runtime": 60},
    "baseline": {"mem_mb": 4000, "runtime": 120},
    "evaluate": {"mem_mb": 6000, "runtime": 240},
}


def resources_yaml(measured: dict, source: str) -> str:
    """workflow/resources.yaml text from the measured peaks (see the module docstring for the margins)."""
    lines = [
        "# Per-rule resources for schedulers (mem_mb: MiB, runtime: minutes), from measured peaks.",
        f"# Measured by benchmarks/resources.py: {source}.",
        "# memory = peak x 1.5, time = longest x 3",
        "# (rules with seconds_per_pair: at least that x 3 x the pairs of the job's chunk or setting;",
        "# remesh, seconds_per_variant: at least that x 3 x the variants of the job's shape).",
        "# A retried job gets attempt x these (profiles set retries). Rules not listed get",
        "# becos.resources.DEFAULT. Override one rule with --set-resources RULE:mem_mb=N.",
        "rules:",
    ]
    for rule, r in measured.items():
        mem = max(500, math.ceil(r["peak_rss_mb"] * 1.5 / 250) * 250)
        entry = f"  {rule}: {{mem_mb: {mem}, runtime: {max(5, math.ceil(r['max_seconds'] * 3 / 60))}"
        for key in ("seconds_per_pair", "seconds_per_variant"):
            if key in r:
                entry += f", {key}: {round(r[key] * 3, 3)}"
        lines.append(entry + "}" + f"  # peak {r['peak_rss_mb']} MiB, longest {r['max_seconds']} s, {r['jobs']} jobs")
    for rule, r in ESTIMATES.items():
        if rule not in measured:
            lines.append(f"  {rule}: {{mem_mb: {r['mem_mb']}, runtime: {r['runtime']}}}  # estimate, not measured")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/becos-resources"))
    parser.add_argument("--pairs", type=int, default=300, help="pairs per setting (approximate)")
    parser.add_argument("--chunks", type=int, default=4, help="chunks per setting")
    parser.add_argument("--write", action="store_true", help="rewrite workflow/resources.yaml")
    args = parser.parse_args()
    code = becos_code()
    shutil.rmtree(args.workdir, ignore_errors=True)
    # usage_scale 0.38 gives ~1,038 partial-to-partial pairs on TOSCA (benchmarks/workflow.py)
    write_config(
        args.workdir,
        code,
        setting=["full_full", "partial_full", "partial_partial"],
        usage_scale=round(0.38 * args.pairs / 1038, 4),
        n_chunks=args.chunks,
        caps={"train": None, "val": None, "test": None},
        exports={"released": True, "published_pickle": True, "report": True},
    )
    cmd = snakemake_cmd(args.workdir, "--cores", "2")
    started = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    sampler = JobSampler(proc.pid)
    out, _ = proc.communicate()
    jobs = sampler.stop()
    if proc.returncode != 0:
        raise SystemExit(f"snakemake failed in {args.workdir}:\n{out[-5000:]}")
    measured = summarise(args.workdir, jobs)
    pairs = {
        s: sum(1 for _ in open(args.workdir / "results" / s / "manifest.csv")) - 1
        for s in ("full_full", "partial_full", "partial_partial")
    }
    result = {
        "seconds": round(time.perf_counter() - started, 1),
        "pairs": pairs,
        "chunks_per_setting": args.chunks,
        "rules": measured,
    }
    if args.write:
        source = f"{date.today()}, TOSCA 76 shapes, {sum(pairs.values())} pairs, {args.chunks} chunks per setting"
        (REPO / "workflow" / "resources.yaml").write_text(resources_yaml(measured, source))
        result["written"] = "workflow/resources.yaml"
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
