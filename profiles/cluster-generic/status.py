#!/usr/bin/env python3
"""Print ``running``, ``success`` or ``failed`` for one SLURM job id (cluster-generic profile).

Called by snakemake-executor-plugin-cluster-generic as ``status.py JOBID``. Asks ``sacct`` (the
accounting database keeps finished jobs) and, for a job it does not know yet, ``squeue``; a job
neither knows is reported failed. For another scheduler replace :func:`state` (e.g. ``qstat -x -f``
for PBS, ``bjobs -o stat`` for LSF) and the state sets. Standard library only.
"""

from __future__ import annotations

import subprocess
import sys

RUNNING = {
    "PENDING",
    "CONFIGURING",
    "RUNNING",
    "COMPLETING",
    "REQUEUED",
    "REQUEUE_FED",
    "REQUEUE_HOLD",
    "RESIZING",
    "SUSPENDED",
    "SIGNALING",
    "STAGE_OUT",
}


def state(jobid: str) -> str | None:
    """The job's SLURM state (``COMPLETED``, ``RUNNING`` ...), or None when SLURM does not know it."""
    out = subprocess.run(["sacct", "-j", jobid, "-X", "-n", "-P", "-o", "State"], capture_output=True, text=True)
    lines = [line.split()[0] for line in out.stdout.splitlines() if line.strip()]
    if out.returncode == 0 and lines:
        return lines[-1]  # "CANCELLED by 0" -> CANCELLED; a requeued job's last line is its current state
    out = subprocess.run(["squeue", "-h", "-j", jobid, "-o", "%T"], capture_output=True, text=True)
    lines = out.stdout.split()
    return lines[0] if out.returncode == 0 and lines else None


def main() -> int:
    s = state(sys.argv[1].split(";")[0])
    print("success" if s == "COMPLETED" else "running" if s in RUNNING else "failed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
