"""Start-up cost of the ``becos`` command (issue 18, item 3): prints JSON, asserts nothing.

For ``becos --help`` and ``becos <sub-command> --help`` of every sub-command: the median wall and
CPU seconds (user + system) of ``--repeat`` runs, the number of modules imported and the heaviest
top-level imports (``python -X importtime``, cumulative microseconds). A sub-command's ``--help``
imports what its job imports before it starts work, so it is the start-up of every job of that
sub-command. ``--job 'ARGS'`` (repeatable) times a real job command line the same way (e.g. a chunk
job of a finished run, whose pair files are all up to date: its time is start-up and bookkeeping).

``--repo PATH`` measures another checkout (e.g. a worktree of ``main``) with the same environment.

Usage::

    python benchmarks/startup.py [--repo PATH] [--repeat 5] [--only remesh pairs] [--job 'metadata --options ...']
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shlex
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _cpu_children() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _command(args: list[str]) -> list[str]:
    # -P: the working directory does not go first on sys.path (PYTHONPATH picks the checkout)
    return [sys.executable, "-P", "-c", "import sys; from becos.cli import main; sys.exit(main())", *args]


def timed(args: list[str], env: dict, repeat: int, cwd: Path | None = None) -> dict:
    """Median wall and CPU seconds of ``becos ARGS`` over ``repeat`` runs (exit status must be 0)."""
    walls, cpus = [], []
    for _ in range(repeat):
        cpu, start = _cpu_children(), time.perf_counter()
        proc = subprocess.run(_command(args), env=env, capture_output=True, text=True, cwd=cwd)
        walls.append(time.perf_counter() - start)
        cpus.append(_cpu_children() - cpu)
        if proc.returncode != 0:
            raise SystemExit(f"becos {' '.join(args)} failed:\n{proc.stderr[-3000:]}")
    return {"wall_s": round(statistics.median(walls), 3), "cpu_s": round(statistics.median(cpus), 3)}


def imports(args: list[str], env: dict, cwd: Path | None = None, top: int = 5) -> dict:
    """Modules imported by ``becos ARGS`` and the ``top`` heaviest top-level packages
    (``-X importtime`` cumulative time, milliseconds)."""
    cmd = [sys.executable, "-X", "importtime", *_command(args)[1:]]
    err = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=cwd).stderr
    rows = re.findall(r"^import time:\s+(\d+) \|\s+(\d+) \|( *)(\S+)$", err, re.M)
    heavy = {}
    for _, cumulative, indent, name in rows:
        if len(indent) == 1:  # imported by the program itself, not by another module
            root = name.split(".")[0]
            heavy[root] = heavy.get(root, 0) + int(cumulative)
    ranked = sorted(heavy.items(), key=lambda kv: -kv[1])[:top]
    return {
        "modules": len(rows),
        "import_ms": round(sum(int(c) for _, c, i, _ in rows if len(i) == 1) / 1000),
        "heaviest_ms": {k: round(v / 1000) for k, v in ranked},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repo", type=Path, default=REPO, help="the checkout to measure (default: this one)")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument(
        "--job", action="append", default=[], help="a real job's arguments after `becos` (quoted), run in --cwd"
    )
    parser.add_argument("--cwd", type=Path, help="working directory of the --job runs")
    parser.add_argument("--only", nargs="+", help="measure only these sub-commands' --help (and becos --help)")
    args = parser.parse_args()
    repo = args.repo.resolve()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(repo), os.environ.get("PYTHONPATH")) if p)}
    sys.path.insert(0, str(repo))
    from becos.cli import SUBCOMMANDS

    commit = subprocess.run(
        ["git", "-C", str(repo), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    result: dict = {"repo": str(repo), "commit": commit, "repeat": args.repeat, "help": {}}
    for name in [None, *dict.fromkeys(n for n, _, _ in SUBCOMMANDS if not args.only or n in args.only)]:
        argv = ["--help"] if name is None else [name, "--help"]
        label = " ".join(["becos", *argv])
        result["help"][label] = {**timed(argv, env, args.repeat), **imports(argv, env)}
    for job in args.job:
        argv = shlex.split(job)
        result.setdefault("jobs", {})[" ".join(argv[:1] + ["..."])] = {
            "args": job,
            **timed(argv, env, args.repeat, args.cwd),
            **imports(argv, env, args.cwd),
        }
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
