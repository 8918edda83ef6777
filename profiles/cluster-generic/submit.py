#!/usr/bin/env python3
"""Submit one Snakemake jobscript to the scheduler; print the scheduler's job id (cluster-generic profile).

Called by snakemake-executor-plugin-cluster-generic as ``submit.py JOBSCRIPT``. The jobscript's second
line is ``# properties = {json}`` (rule, wildcards, threads, resources ...); this script turns the
rule's ``threads``, ``resources.mem_mb`` (MB) and ``resources.runtime`` (minutes) into scheduler
options. Account and queue come from ``BECOS_SLURM_ACCOUNT`` / ``BECOS_SLURM_PARTITION`` (or the
``slurm_account`` / ``slurm_partition`` resources). Scheduler output goes to
``logs/cluster/<rule>/<job id>.log`` below the working directory.

This file submits to SLURM (``sbatch``); for another scheduler replace :func:`command` (examples for
PBS Pro / OpenPBS, LSF and Grid Engine in docs/cluster.md) and ``status.py``. Standard library only.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path


def job_properties(jobscript: Path) -> dict:
    """The ``# properties = {...}`` line Snakemake writes into every jobscript."""
    for line in jobscript.read_text().splitlines()[:5]:
        if line.startswith("# properties = "):
            return json.loads(line[len("# properties = ") :])
    sys.exit(f"{jobscript}: no '# properties = ' line; is this a Snakemake jobscript?")


def command(props: dict, jobscript: Path, log: Path) -> list[str]:
    """The ``sbatch`` call for one job."""
    res = props.get("resources", {})
    name = props.get("groupid") if props.get("type") == "group" else props.get("rule", "job")
    cmd = [
        "sbatch",
        "--parsable",
        f"--job-name=becos-{name}",
        f"--cpus-per-task={props.get('threads', 1)}",
        f"--output={log}",
    ]
    if res.get("mem_mb"):
        cmd.append(f"--mem={int(res['mem_mb'])}")
    if res.get("runtime"):
        cmd.append(f"--time={int(res['runtime'])}")
    account = os.environ.get("BECOS_SLURM_ACCOUNT") or res.get("slurm_account")
    partition = os.environ.get("BECOS_SLURM_PARTITION") or res.get("slurm_partition")
    if account:
        cmd.append(f"--account={account}")
    if partition:
        cmd.append(f"--partition={partition}")
    return [*cmd, str(jobscript)]


def main() -> int:
    jobscript = Path(sys.argv[-1])
    props = job_properties(jobscript)
    rule = re.sub(r"[^A-Za-z0-9_.-]", "_", str(props.get("rule") or props.get("groupid") or "job"))
    logdir = Path("logs") / "cluster" / rule
    logdir.mkdir(parents=True, exist_ok=True)
    cmd = command(props, jobscript, logdir / "%j.log")
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        sys.stderr.write(f"{' '.join(cmd)}\n{result.stdout}{result.stderr}")
        return result.returncode
    print(result.stdout.strip().split(";")[0])  # "<id>" or "<id>;<cluster>"
    return 0


if __name__ == "__main__":
    sys.exit(main())
