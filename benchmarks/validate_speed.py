"""CPU seconds of ``becos validate`` per pair (issue #31: at most 0.02): prints JSON, asserts nothing.

Runs ``becos validate STORE`` as the workflow's ``validate_store`` job does (a fresh process, imports
included) on each store given, with this checkout's code and, with ``--repo``, another checkout's
(e.g. a worktree of ``main``: before and after on the same stores, in one run, alternating, so both see
the same machine load). Per store and checkout: the child process's CPU seconds (user + system, every
thread), their median over ``--repeat`` runs, per pair, and whether the store validated.

Usage::

    python benchmarks/validate_speed.py STORE [STORE ...] [--repo OTHER_CHECKOUT] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def validate_once(repo: Path, store: Path) -> tuple[float, dict]:
    """CPU seconds of one ``becos validate`` process on ``store`` with ``repo``'s code, and its summary."""
    env = {**os.environ, "PYTHONPATH": str(repo)}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "validation.json"
        cmd = [sys.executable, "-c", "import sys; from becos.cli import main; sys.exit(main())", "validate"]
        before = children_cpu()
        # cwd: not a checkout (``python -c`` puts the working directory first on sys.path)
        subprocess.run([*cmd, str(store), "--json", str(out)], env=env, cwd=tmp, capture_output=True, text=True)
        cpu = children_cpu() - before
        summary = json.loads(out.read_text()) if out.is_file() else {}
    return cpu, summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("stores", nargs="+", type=Path)
    parser.add_argument("--repo", type=Path, help="another checkout to compare with (its becos package)")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    repos = {"this": REPO} | ({"other": args.repo.resolve()} if args.repo else {})
    out: dict = {"repos": {k: str(v) for k, v in repos.items()}, "load_average": list(os.getloadavg()), "stores": {}}
    for store in args.stores:
        runs: dict[str, list[float]] = {k: [] for k in repos}
        summaries: dict[str, dict] = {}
        for _ in range(args.repeat):
            for name, repo in repos.items():
                cpu, summaries[name] = validate_once(repo, store.resolve())
                runs[name].append(round(cpu, 2))
        entry = {}
        for name in repos:
            pairs = summaries[name].get("n_pairs", 0)
            median = statistics.median(runs[name])
            entry[name] = {
                "pairs": pairs,
                "valid": summaries[name].get("valid"),
                "cpu_seconds": runs[name],
                "cpu_seconds_median": median,
                "cpu_seconds_per_pair": round(median / pairs, 4) if pairs else None,
            }
        out["stores"][str(store)] = entry
        print(json.dumps({str(store): entry}), file=sys.stderr, flush=True)
    out["load_average_after"] = list(os.getloadavg())
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
