"""BeCoS-size cost of becos (issue 30, items 1-2): prints JSON, asserts nothing.

Runs the workflow of ``config/scale.yaml`` (the built-in synthetic collection at BeCoS size; every
key of that file is written to each run's ``--configfile``) at each of ``--fractions`` of full size
(``synthetic.fraction``), each from scratch on ``--cores 2``, in ``WORKDIR/f<n>-<d>/``:

1. ``snakemake --cores 2 --until manifest`` (collection, dataset check, catalog, manifests: the job
   graph is then known), 2. ``snakemake -n --cores 2`` (the DAG: ``dag``), 3. ``snakemake --cores 2``
   (everything else), 4. ``snakemake --cores 2`` again (``noop_rerun``). Steps 1 and 3 are the run:

- ``wall_seconds`` (sum of 1 and 3; the machine may be shared: wall counts other users' load, CPU
  seconds do not), ``cpu_seconds_total`` (the whole process tree);
- ``cpu_by_stage``: CPU seconds per process kind (``snakemake``: the Snakemake process itself; a
  ``becos`` sub-command: ``remesh``, ``ground-truth``, ``pairs``, ``store``, ``validate``, ``report``,
  ``export-*``, ...), from the per-process hook of ``benchmarks/workflow.py`` (``CPU_HOOK``);
  ``other``: the rest of the tree (the jobs' shells);
- ``peak_rss_mb``: the largest RSS of any process and per process kind (sampled every 0.2 s), i.e. of
  Snakemake and of the largest job of each stage;
- ``disk_mb``: disk used (blocks) per artefact kind: each folder of ``results/`` (a setting's
  sub-folders summed over the settings, e.g. ``<setting>/ground_truth``), the generated collection,
  ``logs/``, ``.snakemake/``;
- ``shapes`` and ``pairs`` per setting and split (the manifests).

Then ``growth``: per figure, the log-log slope over the fractions run (1: linear in the size; a figure
of the scale that grows faster than linearly has a slope clearly above 1), and the full-size figure
two ways: the power law through the points (``at_full_fit``) and the largest run times
1/fraction (``at_full_linear``). ``ground_truth_error``: at the largest fraction run, the exact
ground-truth error (``benchmarks/gt_error.py``: geodesic distance over sqrt(area) from each predicted
vertex to the true point) of a seeded random sample of ``--gt-sample`` pairs per setting (all if
fewer) among the pairs whose truth the construction gives: two poses of one class share one
triangulation (vertex i is vertex i), so the true map is the identity of the original vertices. Other
pairs (two classes, or a class of each dataset) have no such truth: the construction's cross-class map is
the template correspondence itself (charts matched part by part, :mod:`becos.sources.synthetic.collection`),
which becos composes into its ground truth, so it is no independent check; those pairs are counted.

Usage::

    python benchmarks/scale.py --fractions 1/16,1/8 [--workdir /work/runs-scale] [--gt-sample 500]
    python benchmarks/scale.py --fractions 1/16,1/8 --reuse   # runs already measured: analysis only
    python benchmarks/scale.py --fractions 1/16 --gt-only --gt-settings partial_full   # GT error only
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import shutil
import subprocess
import sys
import time
from fractions import Fraction
from pathlib import Path

import numpy as np
import yaml

BENCH = Path(__file__).resolve().parent
REPO = BENCH.parent
sys.path.insert(0, str(BENCH))
from workflow import cpu_by_process, install_cpu_hook, job_counts, snakemake  # noqa: E402

SETTINGS = ("full_full", "partial_full", "partial_partial")


def run_name(fraction: Fraction) -> str:
    return f"f{fraction.numerator}-{fraction.denominator}"


def write_config(run: Path, fraction: Fraction) -> dict:
    """``config/scale.yaml`` with ``synthetic.fraction`` set, written whole to ``run/config.yaml``."""
    config = yaml.safe_load((REPO / "config" / "scale.yaml").read_text())
    config["synthetic"]["fraction"] = float(fraction)
    run.mkdir(parents=True)
    (run / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
    return config


def disk_mb(run: Path, config: dict) -> dict[str, float]:
    """Disk used (``du`` blocks, MB) per artefact kind (module docstring)."""

    def du(paths: list[Path]) -> float:
        paths = [p for p in paths if p.exists()]
        if not paths:
            return 0.0
        out = subprocess.run(["du", "-s", "-B1", "-c", *map(str, paths)], capture_output=True, text=True).stdout
        return round(int(out.strip().splitlines()[-1].split()[0]) / 1e6, 1)

    results = run / config["results"]
    kinds: dict[str, list[Path]] = {}
    for entry in sorted(results.iterdir()):
        if entry.name in SETTINGS:
            for sub in sorted(entry.iterdir()):
                kinds.setdefault(f"<setting>/{sub.name}", []).append(sub)
        else:
            kinds.setdefault(entry.name, []).append(entry)
    out = {kind: du(paths) for kind, paths in kinds.items()}
    out["synthetic_collection (input)"] = du([run / config["synthetic"]["out"]])
    out["logs"] = du([run / "logs"])
    out[".snakemake"] = du([run / ".snakemake"])
    out["results_total"] = du([results])
    return out


def counts(run: Path, config: dict) -> dict:
    """Shapes (catalog) and pairs per setting and split (manifests)."""
    import pandas as pd

    results = run / config["results"]
    catalog = pd.read_csv(results / "catalog.csv")
    pairs = {}
    for setting in SETTINGS:
        manifest = pd.read_csv(results / setting / "manifest.csv")
        pairs[setting] = {s: int((manifest["split"] == s).sum()) for s in ("train", "val", "test")}
        pairs[setting]["total"] = int(len(manifest))
    return {
        "shapes": int(len(catalog)),
        "shapes_per_split": {s: int(n) for s, n in catalog["split"].value_counts().sort_index().items()},
        "pairs": pairs,
        "pairs_all_settings": sum(p["total"] for p in pairs.values()),
    }


def merge_peaks(*memories: dict) -> dict[str, float]:
    peaks: dict[str, float] = {}
    for memory in memories:
        for kind, mb in memory["peak_rss_mb_by_kind"].items():
            peaks[kind] = max(peaks.get(kind, 0.0), mb)
    return dict(sorted(peaks.items(), key=lambda kv: -kv[1]))


def measure(workdir: Path, fraction: Fraction) -> dict:
    """Steps 1-4 of the module docstring for one fraction, from scratch; the figures (also saved as
    ``<run>/measure.json``)."""
    run = workdir / run_name(fraction)
    shutil.rmtree(run, ignore_errors=True)
    config = write_config(run, fraction)
    hook, log = install_cpu_hook(run)
    env = {
        "BECOS_BENCH_CPU_LOG": str(log),
        # the jobs' `becos` is this interpreter's (its venv's bin first on PATH)
        "PATH": os.pathsep.join((str(Path(sys.executable).parent), os.environ.get("PATH", ""))),
    }

    def step(*args: str, measured: bool = True) -> tuple[float, str, dict]:
        started = time.strftime("%H:%M:%S", time.gmtime())
        print(f"{run.name}: snakemake {' '.join(args)} (started {started} UTC)", file=sys.stderr, flush=True)
        return snakemake(run, *args, hook=hook if measured else None, env_extra=env)

    setup_s, _, setup_mem = step("--cores", "2", "--until", "manifest")
    dag_s, dag_out, dag_mem = step("-n", "--cores", "2", measured=False)
    main_s, main_out, main_mem = step("--cores", "2")
    noop_s, noop_out, noop_mem = step("--cores", "2", measured=False)
    stages = cpu_by_process(log)
    python_cpu = sum(k["cpu_seconds"] for k in stages.values())
    total_cpu = setup_mem["cpu_seconds"] + main_mem["cpu_seconds"]
    result = {
        "fraction": str(fraction),
        "run": str(run),
        **counts(run, config),
        "wall_seconds": round(setup_s + main_s, 1),
        "wall_seconds_setup": round(setup_s, 1),
        "cpu_seconds_total": round(total_cpu, 1),
        "cpu_by_stage": {k: v["cpu_seconds"] for k, v in stages.items()} | {"other": round(total_cpu - python_cpu, 1)},
        "processes_by_stage": {k: v["processes"] for k, v in stages.items()},
        "peak_rss_mb": {"largest_process": max(setup_mem["peak_rss_mb"], main_mem["peak_rss_mb"])}
        | merge_peaks(setup_mem, main_mem),
        "disk_mb": disk_mb(run, config),
        "dag": {
            "command": "snakemake -n --cores 2 (after --until manifest)",
            "seconds": round(dag_s, 2),
            "cpu_seconds": dag_mem["cpu_seconds"],
            "peak_rss_mb": dag_mem["peak_rss_mb"],
            "jobs": job_counts(dag_out),
        },
        "noop_rerun": {
            "seconds": round(noop_s, 2),
            "cpu_seconds": noop_mem["cpu_seconds"],
            "nothing_to_do": "Nothing to be done" in noop_out,
        },
        "jobs_run": job_counts(main_out),
        "load_average_at_end": [round(x, 2) for x in os.getloadavg()],
    }
    (run / "measure.json").write_text(json.dumps(result, indent=1))
    return result


def _figures(result: dict) -> dict[str, float]:
    """The figures whose growth is fitted, flat: ``cpu/<stage>``, ``rss/<kind>``, ``disk/<kind>``, ..."""
    out = {
        "shapes": result["shapes"],
        "pairs_all_settings": result["pairs_all_settings"],
        "wall_seconds": result["wall_seconds"],
        "cpu_seconds_total": result["cpu_seconds_total"],
        "dag_seconds": result["dag"]["seconds"],
        "dag_jobs": sum(v for k, v in result["dag"]["jobs"].items() if k == "total"),
        "noop_rerun_seconds": result["noop_rerun"]["seconds"],
    }
    out |= {f"cpu/{k}": v for k, v in result["cpu_by_stage"].items()}
    out |= {f"peak_rss_mb/{k}": v for k, v in result["peak_rss_mb"].items()}
    out |= {f"disk_mb/{k}": v for k, v in result["disk_mb"].items()}
    return out


def growth(results: list[dict]) -> dict:
    """Per figure: log-log slope against the fraction and the full-size figure (module docstring)."""
    if len(results) < 2:
        return {}
    fractions = np.array([float(Fraction(r["fraction"])) for r in results])
    figures = [_figures(r) for r in results]
    largest = int(np.argmax(fractions))
    out = {}
    for key in figures[0]:
        values = np.array([f.get(key, np.nan) for f in figures], dtype=float)
        if not np.all(values > 0):
            continue
        slope, intercept = np.polyfit(np.log(fractions), np.log(values), 1)
        out[key] = {
            "values": [round(float(v), 2) for v in values],
            "slope": round(float(slope), 3),
            "at_full_fit": round(float(math.exp(intercept)), 1),
            "at_full_linear": round(float(values[largest] / fractions[largest]), 1),
        }
    return out


def ground_truth_error(
    run: Path, config: dict, sample: int, settings=SETTINGS, reuse: bool = False, seed: int = 0
) -> dict:
    """GT error against the construction over a seeded sample of same-class pairs per setting (each
    setting's figures saved as ``<run>/gt_error_<setting>.json``; ``reuse``: read them from there)."""
    import pandas as pd
    from gt_error import Run, audit_setting, distribution_table

    results = (run / config["results"]).resolve()
    os.chdir(run)  # the catalog's mesh paths are relative to the run's folder
    gt_run = Run(results)
    catalog = pd.read_csv(results / "catalog.csv")
    class_of = {(d, n): c for d, n, c in zip(catalog["dataset"], catalog["name"], catalog["class"])}
    out: dict = {"run": str(run), "bound": 0.04}
    for setting in settings:
        saved = run / f"gt_error_{setting}.json"
        if reuse and saved.is_file():
            out[setting] = json.loads(saved.read_text())
            continue
        manifest = pd.read_csv(results / setting / "manifest.csv")
        x = [class_of[(d, n)] for d, n in zip(manifest["x_dataset"], manifest["x_name"])]
        y = [class_of[(d, n)] for d, n in zip(manifest["y_dataset"], manifest["y_name"])]
        same = (manifest["x_dataset"] == manifest["y_dataset"]).to_numpy() & (np.array(x) == np.array(y))
        ids = sorted(manifest.loc[same, "pair_id"])
        chosen = set(random.Random(seed).sample(ids, min(sample, len(ids))))
        started = time.process_time()
        log = lambda m: print(m, file=sys.stderr, flush=True)  # noqa: E731
        directions = [r.summary() for r in audit_setting(gt_run, setting, chosen, log)]
        table = distribution_table(directions)
        maxima = np.array([d["max"] for d in directions])
        means = np.array([d["mean"] for d in directions])
        out[setting] = {
            "pairs": int(len(manifest)),
            "pairs_with_truth": int(same.sum()),
            "pairs_without_truth": int((~same).sum()),
            "without_truth_by_split": {
                s: int(((manifest["split"] == s).to_numpy() & ~same).sum()) for s in ("train", "val", "test")
            },
            "sampled_pairs": len(chosen),
            "directions": len(directions),
            "mean_of_direction_means": round(float(np.nanmean(means)), 5),
            "median_of_direction_means": round(float(np.nanmedian(means)), 5),
            "p95_of_direction_max": round(float(np.nanpercentile(maxima, 95)), 5),
            "max": round(float(np.nanmax(maxima)), 5),
            "directions_above_bound": int((maxima > 0.04).sum()),
            "table": json.loads(table.to_json(orient="index")) if len(table) else {},
            "cpu_seconds": round(time.process_time() - started, 1),
        }
        saved.write_text(json.dumps(out[setting], indent=1))
        print(f"ground truth error, {setting}: {out[setting]['max']} max", file=sys.stderr, flush=True)
    return out


def parse_fraction(text: str) -> Fraction:
    fraction = Fraction(text.strip())
    if not 0 < fraction <= 1:
        raise SystemExit(f"--fractions: {text} is not in (0, 1]")
    return fraction


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fractions", default="1/16,1/8,1/4", help="fractions of full size (comma-separated)")
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/becos-scale"))
    parser.add_argument(
        "--reuse", action="store_true", help="use a fraction's measure.json where a run left one (no rerun)"
    )
    parser.add_argument("--gt-sample", type=int, default=500, help="pairs per setting for the GT error (0: none)")
    parser.add_argument(
        "--gt-fraction", default=None, help="the run whose GT error is measured (default: the largest fraction)"
    )
    parser.add_argument("--gt-settings", default=",".join(SETTINGS), help="settings of the GT error (comma-separated)")
    parser.add_argument("--gt-only", action="store_true", help="only the GT error of --gt-fraction's finished run")
    args = parser.parse_args()
    fractions = sorted(parse_fraction(f) for f in args.fractions.split(","))
    gt_run = args.workdir / run_name(parse_fraction(args.gt_fraction) if args.gt_fraction else fractions[-1])
    gt_settings = tuple(args.gt_settings.split(","))
    if args.gt_only:
        config = yaml.safe_load((gt_run / "config.yaml").read_text())
        print(json.dumps(ground_truth_error(gt_run, config, args.gt_sample, gt_settings, args.reuse), indent=1))
        return
    results = []
    for fraction in fractions:
        saved = args.workdir / run_name(fraction) / "measure.json"
        if args.reuse and saved.is_file():
            results.append(json.loads(saved.read_text()))
        else:
            results.append(measure(args.workdir, fraction))
        print(json.dumps({"fraction": str(fraction), "wall_seconds": results[-1]["wall_seconds"]}), file=sys.stderr)
    out = {"machine_cores": os.cpu_count(), "config": "config/scale.yaml", "runs": results, "growth": growth(results)}
    if args.gt_sample > 0:
        config = yaml.safe_load((gt_run / "config.yaml").read_text())
        out["ground_truth_error"] = ground_truth_error(gt_run, config, args.gt_sample, gt_settings, args.reuse)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
