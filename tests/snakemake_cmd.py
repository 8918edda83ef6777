"""The Snakemake command line of the tests and the benchmarks, built in one place.

:func:`snakemake_cmd` builds ``python -m snakemake -s <repo>/Snakefile [-d <workdir> --configfile
<workdir>/config.yaml] <args>``; :func:`snakemake` runs it the way most workflow tests do (output
captured, failures raised with the failed jobs' logs). The benchmarks import this module through the
``tests/`` folder they put on ``sys.path``.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def snakemake_cmd(
    workdir: Path | None, *args: str, repo: Path = REPO, python: Sequence[str] = (sys.executable,)
) -> list[str]:
    """The command that runs ``repo``'s Snakefile on ``workdir`` and its ``config.yaml``.

    ``workdir`` None: no ``-d`` and no ``--configfile`` (``args`` name them, or Snakemake's defaults
    apply). ``python``: the interpreter and its options before ``-m snakemake`` (e.g. a profiler's)."""
    where = ["-d", str(workdir), "--configfile", str(Path(workdir) / "config.yaml")] if workdir is not None else []
    return [*python, "-m", "snakemake", "-s", str(Path(repo) / "Snakefile"), *where, *args]


def snakemake(workdir: Path, *args: str, check: bool = True, env: dict | None = None) -> subprocess.CompletedProcess:
    """Run :func:`snakemake_cmd` (output captured as text, ``PYTHONUNBUFFERED=1``, ``env`` added to the
    environment); with ``check``, a failed run raises AssertionError with its output and the job logs
    that hold an error."""
    env = dict(os.environ, PYTHONUNBUFFERED="1", **(env or {}))
    result = subprocess.run(snakemake_cmd(workdir, *args), capture_output=True, text=True, env=env)
    if check and result.returncode != 0:
        logs = "\n".join(
            f"--- {p}\n{p.read_text()[-3000:]}"
            for p in sorted((workdir / "logs").rglob("*.log"))
            if "Error" in p.read_text() or "Traceback" in p.read_text()
        )
        raise AssertionError(
            f"snakemake {' '.join(args)} failed:\n{result.stdout[-4000:]}\n{result.stderr[-6000:]}\n{logs}"
        )
    return result
