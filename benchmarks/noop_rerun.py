"""No-op rerun of a ~1,000-pair TOSCA run, this checkout against another (issue #29): prints JSON.

Builds the partial_partial run of ``benchmarks/workflow.py`` (all 76 TOSCA shapes of ``../shared``,
``usage_scale`` 0.38, no caps: 1,038 pairs) with the ``--before`` checkout, copies the finished folder
and brings the copy up to date with this checkout (its first run reruns what its rules' parameters
changed). Then it times ``snakemake --cores 2`` on both finished folders, alternating (``--repeats``
rounds), so that the ratio is measured in one window of a shared machine:

- ``before_run`` / ``after_first_run_on_copy``: wall and CPU seconds of the two builds;
- ``noop``: (checkout, wall s, CPU s, "Nothing to be done" printed) per call; ``*_median_s`` and
  ``ratio_after_over_before``.

Usage::

    git worktree add /tmp/before <commit>
    python benchmarks/noop_rerun.py --before /tmp/before [--workdir /tmp/becos-noop] [--skip-build]
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
from pathlib import Path

import workflow as wb


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, required=True, help="the checkout to compare with")
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/becos-noop"))
    parser.add_argument("--repeats", type=int, default=3, help="no-op calls per checkout (default 3)")
    parser.add_argument("--skip-build", action="store_true", help="reuse the two finished folders of --workdir")
    args = parser.parse_args()
    before, after = args.before.resolve(), wb.REPO
    run_before, run_after = args.workdir / "run-before", args.workdir / "run-after"
    out: dict = {"before": str(before), "after": str(after)}
    if not args.skip_build:
        caps = {"train": None, "val": None, "test": None}
        shutil.rmtree(run_before, ignore_errors=True)
        wb.write_config(run_before, wb.becos_code(), usage_scale=0.38, remesh_variants=1, caps=caps)
        seconds, _, memory = wb.snakemake(run_before, "--cores", "2", repo=before)
        out["before_run"] = {
            "pairs": wb.n_pairs(run_before),
            "seconds": round(seconds, 1),
            "cpu": memory["cpu_seconds"],
        }
        shutil.rmtree(run_after, ignore_errors=True)
        shutil.copytree(run_before, run_after, symlinks=True)
        seconds, _, memory = wb.snakemake(run_after, "--cores", "2", repo=after)
        out["after_first_run_on_copy"] = {"seconds": round(seconds, 1), "cpu": memory["cpu_seconds"]}
    rows = []
    for _ in range(args.repeats):
        for name, repo, folder in (("before", before, run_before), ("after", after, run_after)):
            seconds, text, memory = wb.snakemake(folder, "--cores", "2", repo=repo)
            rows.append((name, round(seconds, 2), memory["cpu_seconds"], "Nothing to be done" in text))
    out["noop"] = rows
    for name in ("before", "after"):
        out[f"{name}_median_s"] = round(statistics.median(r[1] for r in rows if r[0] == name), 2)
    out["ratio_after_over_before"] = round(out["after_median_s"] / out["before_median_s"], 3)
    out["pairs"] = [wb.n_pairs(run_before), wb.n_pairs(run_after)]
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
