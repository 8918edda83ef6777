"""Workflow scale benchmark (issue 4): prints JSON, asserts nothing.

Measures, on the TOSCA meshes of ``../shared`` (all 76 shapes, partial-to-partial):

- ``dag_10k``: seconds of ``snakemake -n`` on a ~10,000-pair configuration (after the dataset check,
  so the whole job graph is known), and its job counts;
- ``run_1000``: wall time, pairs/s and peak RSS (largest single process) of a ~1,000-pair run on
  ``--cores 2`` from scratch (remeshing included); the reference needs ~6.2 s per pair here
  (0.16 pairs/s);
- ``noop_rerun``: seconds of a second ``snakemake`` call on the finished 1,000-pair run;
- ``run_100``: the same for ~100 pairs (remesh files copied from the 1,000-pair run), for the peak-RSS
  ratio ``rss_ratio_1000_vs_100``.

``--full-plan`` measures instead the plan of the whole published benchmark (issue 14, item 4), on the
stand-in data root of ``tests/standin.py`` (2,537 small meshes at the published file paths; real
template vertex counts): all 8 dataset entries, the three settings, default usage counts, no caps:

- ``default`` (sampled pairs) and ``original_settings`` (the published lists, full_full and
  partial_partial), each with ``setup``: seconds of ``snakemake --until manifest`` (dataset check,
  catalog, manifests run for real, so the dry run knows every chunk job); ``dry_run``: seconds of
  ``snakemake -n`` and its job counts (``dry_run_quiet``: with ``--quiet``, no per-job listing);
  ``pairs``: pairs per split of each setting's manifest, next to the published 10,185 / 137 / 142
  (train / val / test). Wall and CPU seconds (the machine may be shared);
- ``default.plan_build``: where the plan's own time goes, measured in this process:
  :meth:`becos.workflow.Plan.build` split into catalog and per-setting manifests, and the chunk jobs'
  input lists; with ``--profile``, ``default.dry_run_profile``: the dry run under cProfile, the share
  of its time in Snakemake's DAG building, its checkpoint update, the dry-run job listing and becos's
  plan functions.

Every configuration key is written to the run's ``--configfile`` (the resolved config), so the
figures do not depend on the repository's ``config/config.yaml``.

``--stages`` measures instead the CPU seconds by stage of a ~150-pair TOSCA run from scratch
(issue 18): partial-to-partial, ``caps`` train 120 / val 15 / test 15, one remesh variant,
``n_chunks: 64``, no released/pickle/report exports. Every Python process of the run (Snakemake and
each ``becos`` job) appends its own CPU time at exit to a log (a ``sitecustomize`` hook on the jobs'
``PYTHONPATH``), summed per ``becos`` sub-command; ``total`` is the CPU of the whole process tree.
``--repo PATH`` runs another checkout's Snakefile and code (e.g. a worktree of ``main``, for a
before/after comparison) with this script. ``--remeshed DIR`` copies a finished run's
``results/remeshed`` in first (the remesh jobs are then done; every later stage still runs from
scratch), for a quicker comparison of the chunk stages on a loaded machine; the parsed original meshes
that code before issue 32 item 2 left in ``results/cache/meshes`` are copied too when they are beside it
(that code's ground-truth jobs read them; since then each chunk job parses the original meshes its rule
declares, in memory).

``--scaling`` measures end-to-end throughput (issue 16, target 3) for each setting and each size in
``--sizes`` (default 150 and 1,000 pairs): one run per (setting, size) from scratch on ``--cores 2``,
TOSCA, one remesh variant, ``caps`` train ``size - 30`` / val 15 / test 15 (TOSCA has about 16 val and
23 test pairs per setting), ``usage_scale`` 0.5, exports as ``--stages``. Per run: pairs, wall seconds,
pairs/s next to the reference's and the issue's target (10x the reference at 150 pairs, 30x at
1,000), CPU seconds of the whole process tree, and CPU seconds by stage from the same per-process hook
as ``--stages`` (``snakemake``: the Snakemake process itself; ``other``: non-Python processes such as
the jobs' shells), with CPU seconds per pair for ``ground-truth`` and ``pairs``. ``--repo`` and
``--remeshed`` work as for ``--stages`` (with ``--remeshed`` the remesh jobs are skipped, so pairs/s is
not from scratch; the JSON says so). ``--decimator NAME`` sets the config key ``decimator`` of every run
(issue #31: ``fast-simplification`` beside the default ``pymeshlab``). Ratios are given against the
reference's rate of issue 16 (``times_reference``) and the one measured beside becos for issue #31
(``times_reference_side_by_side``, the faster reference).

Usage::

    python benchmarks/workflow.py [--workdir /tmp/becos-bench] [--variants 1] [--skip-run] [--full-plan [--profile]]
    python benchmarks/workflow.py --stages [--repo PATH] [--remeshed DIR] [--workdir /tmp/becos-bench]
    python benchmarks/workflow.py --scaling [--sizes 150,1000] [--settings full_full,...] [--repo PATH] [--remeshed DIR]
        [--decimator fast-simplification]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import psutil
import yaml

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))  # tests/standin.py: the stand-in data root; tests/snakemake_cmd.py
from snakemake_cmd import snakemake_cmd  # noqa: E402


def becos_code() -> Path:
    out = subprocess.run([str(SHARED / "unpack")], check=True, capture_output=True, text=True).stdout
    return Path(out.strip().splitlines()[-1])


def write_config(workdir: Path, code: Path, **overrides) -> None:
    config = {
        "synthetic": {"enabled": False},
        "data_dir": str(code / "data"),
        "annotations": str(code),
        "datasets": ["tosca"],
        "template_file": "templates_tosca_demo.csv",
        "setting": "partial_partial",
        "combinations": "all",
        "store_vis": False,
        "exports": {"released": False, "published_pickle": False, "report": False},
    }
    config.update(overrides)
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))


class PeakRss:
    """Largest RSS of any single process in the tree under ``pid``, sampled every 0.2 s; also per process
    kind (:func:`_process_kind` of its command line: ``snakemake``, a ``becos`` sub-command, ...)."""

    def __init__(self, pid: int):
        self.root, self.peak, self.peak_cmd = psutil.Process(pid), 0, ""
        self.by_kind: dict[str, int] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        while not self._stop.is_set():
            try:
                procs = [self.root, *self.root.children(recursive=True)]
            except psutil.NoSuchProcess:
                return
            for p in procs:
                try:
                    rss = p.memory_info().rss
                    cmdline = p.cmdline()
                    if rss > self.peak:
                        self.peak, self.peak_cmd = rss, " ".join(cmdline[:6])
                    kind = _process_kind(_python_argv(cmdline))
                    self.by_kind[kind] = max(self.by_kind.get(kind, 0), rss)
                except (psutil.NoSuchProcess, psutil.AccessDenied):
                    pass
            time.sleep(0.2)

    def stop(self) -> dict:
        self._stop.set()
        self._thread.join()
        return {
            "peak_rss_mb": round(self.peak / 2**20, 1),
            "peak_process": self.peak_cmd,
            "peak_rss_mb_by_kind": {k: round(v / 2**20, 1) for k, v in sorted(self.by_kind.items())},
        }


def _python_argv(cmdline: list[str]) -> list[str]:
    """A process's command line as its ``sys.argv`` would be: without the interpreter and its options
    (``python -m snakemake ...`` -> ``[snakemake, ...]``; ``python .../bin/becos remesh`` -> ``[.../becos, remesh]``)."""
    if cmdline and Path(cmdline[0]).name.startswith("python"):
        rest = cmdline[1:]
        while rest and rest[0].startswith("-") and rest[0] != "-m":
            rest = rest[1:]
        return rest[1:] if rest[:1] == ["-m"] else rest
    return cmdline


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def snakemake(
    workdir: Path, *args: str, repo: Path = REPO, hook: Path | None = None, env_extra: dict | None = None
) -> tuple[float, str, dict]:
    """Run ``repo``'s Snakefile in ``workdir``; ``hook``: a folder put first on ``PYTHONPATH``."""
    cmd = snakemake_cmd(workdir, *args, repo=repo)
    start = time.perf_counter()
    cpu_start = _children_cpu()
    # the jobs' `becos` runs this checkout's code, whatever the environment installed
    path = (str(hook) if hook else None, str(repo), os.environ.get("PYTHONPATH"))
    env = {**os.environ, **(env_extra or {}), "PYTHONPATH": os.pathsep.join(p for p in path if p)}
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    rss = PeakRss(proc.pid)
    out, _ = proc.communicate()
    seconds = time.perf_counter() - start
    memory = rss.stop()
    # CPU of snakemake and its jobs: on a shared machine, wall time also counts other users' load
    memory["cpu_seconds"] = round(_children_cpu() - cpu_start, 2)
    if proc.returncode != 0:
        raise SystemExit(f"snakemake {' '.join(args)} failed in {workdir}:\n{out[-5000:]}")
    return seconds, out, memory


def job_counts(text: str) -> dict[str, int]:
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^([a-z_]+)\s+(\d+)$", text, re.M)}


def n_pairs(workdir: Path) -> int:
    return sum(1 for _ in open(workdir / "results" / "partial_partial" / "manifest.csv")) - 1


def split_counts(manifest) -> dict[str, int]:
    return {s: int((manifest["split"] == s).sum()) for s in ("train", "val", "test")}


def plan_run(run: Path, config: dict, quiet: bool = True) -> dict:
    """Write ``config`` (every key) to ``run/config.yaml``; run the dataset check, catalog and manifests
    (``--until manifest``), then time ``snakemake -n`` (and ``-n --quiet``); pairs per split."""
    from standin import PUBLISHED_PAIRS, PUBLISHED_SETTINGS

    from becos.build.sampling import read_manifest
    from becos.workflow import settings_of

    run.mkdir(parents=True)
    (run / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
    out: dict = {
        "config": {
            k: config[k] for k in ("original_settings", "setting", "usage_scale", "caps", "remesh_variants", "n_chunks")
        }
    }
    seconds, _, memory = snakemake(run, "--cores", "2", "--until", "manifest")
    out["setup"] = {
        "command": "snakemake --cores 2 --until manifest",
        "seconds": round(seconds, 2),
        "cpu_seconds": memory["cpu_seconds"],
    }
    seconds, text, memory = snakemake(run, "-n", "--cores", "2")
    out["dry_run"] = {
        "command": "snakemake -n --cores 2",
        "seconds": round(seconds, 2),
        "cpu_seconds": memory["cpu_seconds"],
        "peak_rss_mb": memory["peak_rss_mb"],
        "jobs": job_counts(text),
    }
    if quiet:
        seconds, _, memory = snakemake(run, "-n", "--quiet", "--cores", "2")
        out["dry_run_quiet"] = {
            "command": "snakemake -n --quiet --cores 2",
            "seconds": round(seconds, 2),
            "cpu_seconds": memory["cpu_seconds"],
        }
    out["pairs"] = {
        s: {
            "manifest": split_counts(read_manifest(run / "results" / s / "manifest.csv")),
            "published": PUBLISHED_PAIRS if s in PUBLISHED_SETTINGS else None,
        }
        for s in settings_of(config)
    }
    return out


PROFILED = {
    "snakemake_build_dag": ("snakemake/workflow.py", "_build_dag"),
    "snakemake_checkpoint_update": ("snakemake/dag.py", "update_checkpoint_dependencies"),
    "snakemake_dry_run_job_listing": ("snakemake/executors/dryrun.py", "printjob"),
    "becos_plan_build": ("becos/workflow.py", "build"),
    "becos_chunk_inputs": ("becos/workflow.py", "chunk_inputs"),
    "becos_plan_calls": ("rules/common.smk", "plan"),
}
"""Functions whose cumulative time ``--profile`` reports: (file path ending, function name)."""


def profile_dry_run(run: Path) -> dict:
    """``snakemake -n`` under cProfile: cumulative seconds of :data:`PROFILED` (cProfile slows
    everything ~3x; compare the shares, not the seconds, with the plain dry run)."""
    import pstats

    out = run / "dry_run.prof"
    cmd = snakemake_cmd(run, "-n", "--cores", "2", python=(sys.executable, "-m", "cProfile", "-o", str(out)))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)}
    subprocess.run(cmd, check=True, capture_output=True, env=env)
    stats = pstats.Stats(str(out)).stats
    total = max(ct for (_, _, _, ct, _) in stats.values())
    found = {"total": round(total, 1)}
    for label, (path_end, name) in PROFILED.items():
        found[label] = round(
            sum(ct for (file, _, fn), (_, _, _, ct, _) in stats.items() if fn == name and file.endswith(path_end)), 1
        )
    return {
        "cumulative_seconds_under_cprofile": found,
        "share": {k: round(v / total, 3) for k, v in found.items() if k != "total"},
    }


def plan_build_profile(config: dict) -> dict:
    """Where the plan's own time goes, in this process (the Snakemake process does the same once)."""
    from becos.workflow import Plan, build_catalog, build_manifest, settings_of

    timings: dict = {}
    start = time.perf_counter()
    catalog = build_catalog(config)
    timings["catalog"] = round(time.perf_counter() - start, 2)
    for setting in settings_of(config):
        t = time.perf_counter()
        build_manifest(config, setting, catalog)
        timings[f"manifest_{setting}"] = round(time.perf_counter() - t, 2)
    t = time.perf_counter()
    plan = Plan.build(config)
    timings["plan_build_total"] = round(time.perf_counter() - t, 2)
    t = time.perf_counter()
    n_inputs = sum(len(plan.chunk_inputs(s, c)) for s in plan.manifests for c in plan.chunks(s))
    timings["chunk_inputs_every_chunk_once"] = round(time.perf_counter() - t, 2)
    return {
        "seconds": timings,
        "shapes": len(plan.catalog),
        "remesh_jobs": len(plan.remesh_jobs),  # one per shape
        "remesh_variants": len(plan.remesh_variants),
        "chunks_per_stage": {s: len(plan.chunks(s)) for s in plan.manifests},
        "remesh_inputs_over_all_chunks": n_inputs,
    }


def full_plan(workdir: Path, code: Path, profile: bool = False) -> dict:
    """The ``full_plan`` figures (module docstring) for a stand-in tree built under ``workdir``."""
    from standin import DATASETS, PUBLISHED_SETTINGS, build_standin_tree

    from becos.workflow import resolve_config

    shutil.rmtree(workdir, ignore_errors=True)
    tree = build_standin_tree(workdir / "standin", code)
    out: dict = {
        "standin": {
            "files": len(tree.files),
            "published_shapes": len(tree.published),
            "real_size_templates": len(tree.template_vertices),
            "seconds": tree.seconds,
        }
    }
    base = {
        "synthetic": {"enabled": False},
        "data_dir": str(tree.data_dir),
        "annotations": str(code),
        "datasets": list(DATASETS),
        "template_file": "templates_all.csv",
        "check_geometry": False,
    }  # stand-in meshes have no real geometry
    config = resolve_config(base)
    out["default"] = plan_run(workdir / "default", config)
    out["default"]["plan_build"] = plan_build_profile({**config, "results": str(workdir / "default" / "results")})
    if profile:
        out["default"]["dry_run_profile"] = profile_dry_run(workdir / "default")
    original = resolve_config({**base, "original_settings": True, "setting": list(PUBLISHED_SETTINGS)})
    out["original_settings"] = plan_run(workdir / "original", original, quiet=False)
    return out


CPU_HOOK = """\
import atexit, json, os, resource, sys

def _becos_bench_record(log=os.environ.get("BECOS_BENCH_CPU_LOG")):
    if not log:
        return
    usage = resource.getrusage(resource.RUSAGE_SELF)
    line = json.dumps({"argv": sys.argv[:2], "cpu": usage.ru_utime + usage.ru_stime}) + "\\n"
    fd = os.open(log, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        os.write(fd, line.encode())
    finally:
        os.close(fd)

atexit.register(_becos_bench_record)
"""
"""``sitecustomize``: each Python process appends ``{"argv", "cpu"}`` (its own CPU seconds) at exit."""


def _process_kind(argv: list[str]) -> str:
    """``becos <sub-command>``, ``snakemake`` or the program's name."""
    program = Path(argv[0]).name if argv else "?"
    if program == "becos" and len(argv) > 1:
        return argv[1]
    if argv and "snakemake" in argv[0]:
        return "snakemake"
    return program


def install_cpu_hook(workdir: Path) -> tuple[Path, Path]:
    """Write :data:`CPU_HOOK` as ``workdir/cpu-hook/sitecustomize.py``; return (hook folder, an emptied
    log path). Pass them to :func:`snakemake` as ``hook=`` and ``env_extra={"BECOS_BENCH_CPU_LOG": log}``."""
    hook = workdir / "cpu-hook"
    hook.mkdir(parents=True, exist_ok=True)
    (hook / "sitecustomize.py").write_text(CPU_HOOK)
    log = workdir / "cpu-by-process.jsonl"
    log.unlink(missing_ok=True)
    return hook, log


def cpu_by_process(log: Path) -> dict[str, dict]:
    """The hook's log summed per process kind: processes, CPU seconds, CPU seconds per process (largest first)."""
    by_kind: dict[str, dict] = {}
    for line in log.read_text().splitlines() if log.is_file() else ():
        entry = json.loads(line)
        kind = by_kind.setdefault(_process_kind(entry["argv"]), {"processes": 0, "cpu_seconds": 0.0})
        kind["processes"] += 1
        kind["cpu_seconds"] += entry["cpu"]
    for kind in by_kind.values():
        kind["cpu_seconds"] = round(kind["cpu_seconds"], 1)
        kind["cpu_seconds_per_process"] = round(kind["cpu_seconds"] / kind["processes"], 2)
    return dict(sorted(by_kind.items(), key=lambda kv: -kv[1]["cpu_seconds"]))


def measured_run(workdir: Path, run: Path, repo: Path, remeshed: Path | None = None) -> dict:
    """Run ``repo``'s workflow in ``run`` (its ``config.yaml`` written) on ``--cores 2`` with the per-process
    CPU hook; optionally with ``remeshed`` copied in first. Wall and CPU seconds, CPU by process kind."""
    if remeshed is not None:
        shutil.copytree(remeshed, run / "results" / "remeshed")
        parsed = remeshed.parent / "cache" / "meshes"  # what the remesh jobs would have written
        if parsed.is_dir() and not (run / "results" / "cache" / "meshes").exists():
            shutil.copytree(parsed, run / "results" / "cache" / "meshes")
    hook, log = install_cpu_hook(workdir)
    seconds, out, memory = snakemake(
        run, "--cores", "2", repo=repo, hook=hook, env_extra={"BECOS_BENCH_CPU_LOG": str(log)}
    )
    return {
        "repo": str(repo),
        "commit": subprocess.run(
            ["git", "-C", str(repo), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
        ).stdout.strip(),
        "remeshed_copied_from": str(remeshed) if remeshed else None,
        "wall_seconds": round(seconds, 1),
        "cpu_seconds_total": memory["cpu_seconds"],
        "peak_rss_mb": memory["peak_rss_mb"],
        "jobs": job_counts(out),
        "cpu_by_process": cpu_by_process(log),
    }


def stages(workdir: Path, code: Path, repo: Path, remeshed: Path | None = None) -> dict:
    """CPU seconds by stage of a ~150-pair TOSCA run from scratch (module docstring, ``--stages``)."""
    run = workdir / "stages"
    shutil.rmtree(run, ignore_errors=True)
    write_config(run, code, caps={"train": 120, "val": 15, "test": 15}, remesh_variants=1, n_chunks=64)
    result = measured_run(workdir, run, repo, remeshed)
    return {**result, "pairs": n_pairs(run)}


REFERENCE_PAIRS_PER_SECOND = {"full_full": 0.248, "partial_full": 0.174, "partial_partial": 0.113}
"""The reference generator's pairs/s on this machine (n_jobs 2, 30 pairs per setting; issue 16)."""
REFERENCE_PAIRS_PER_SECOND_SIDE_BY_SIDE = {"full_full": 0.307, "partial_full": 0.233, "partial_partial": 0.128}
"""The reference's pairs/s measured again on this machine beside becos (issue #31): the faster of its two
measurements, so ``times_reference_side_by_side`` is the stricter ratio."""
TARGET_FACTOR = {150: 10, 1000: 30}
"""Issue 16's end-to-end targets: this many times the reference's pairs/s at 150 and 1,000 pairs."""


def scaling(
    workdir: Path,
    code: Path,
    repo: Path,
    sizes: list[int],
    settings: list[str],
    remeshed: Path | None = None,
    decimator: str | None = None,
    pairs_per_chunk: int | None = None,
) -> dict:
    """Pairs/s and CPU seconds by stage per (setting, size) (module docstring, ``--scaling``); ``decimator``
    and ``pairs_per_chunk``: those config keys (None: their defaults)."""
    overrides = {"decimator": decimator} if decimator else {}
    if pairs_per_chunk:
        overrides["pairs_per_chunk"] = pairs_per_chunk
    out: dict = {
        "repo": str(repo),
        "decimator": decimator or "default",
        "pairs_per_chunk": pairs_per_chunk or "default",
        "remeshed_copied_from": str(remeshed) if remeshed else None,
        "from_scratch": remeshed is None,
        "runs": {},
    }
    for size in sizes:
        for setting in settings:
            run = workdir / "scaling" / f"{setting}-{size}"
            shutil.rmtree(run, ignore_errors=True)
            write_config(
                run,
                code,
                setting=setting,
                caps={"train": size - 30, "val": 15, "test": 15},
                usage_scale=0.5,
                remesh_variants=1,
                n_chunks=64,
                **overrides,
            )
            result = measured_run(workdir, run, repo, remeshed)
            pairs = len((run / "results" / setting / "manifest.csv").read_text().splitlines()) - 1
            kinds = result["cpu_by_process"]
            python_cpu = sum(k["cpu_seconds"] for k in kinds.values())
            reference = REFERENCE_PAIRS_PER_SECOND[setting]
            per_second = pairs / result["wall_seconds"]
            summary = {
                "pairs": pairs,
                "pairs_per_second": round(per_second, 3),
                "reference_pairs_per_second": reference,
                "times_reference": round(per_second / reference, 2),
                "times_reference_side_by_side": round(per_second / REFERENCE_PAIRS_PER_SECOND_SIDE_BY_SIDE[setting], 2),
                "cpu_seconds_by_stage": {k: v["cpu_seconds"] for k, v in kinds.items()},
                "cpu_seconds_other": round(result["cpu_seconds_total"] - python_cpu, 1),
                "cpu_seconds_per_pair": {
                    k: round(kinds[k]["cpu_seconds"] / pairs, 3)
                    for k in ("ground-truth", "pairs", "remesh", "snakemake")
                    if k in kinds
                },
                "load_average": [round(x, 2) for x in os.getloadavg()],
            }
            if size in TARGET_FACTOR:
                summary["target_pairs_per_second"] = round(TARGET_FACTOR[size] * reference, 2)
            out["runs"][f"{setting}/{size}"] = {**summary, **result}
            print(json.dumps({f"{setting}/{size}": summary}), file=sys.stderr, flush=True)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/becos-bench"))
    parser.add_argument("--variants", type=int, default=1, help="remesh variants per shape (default 1)")
    parser.add_argument("--skip-run", action="store_true", help="only the 10k-pair dry run")
    parser.add_argument(
        "--full-plan",
        action="store_true",
        help="only the plan of the whole published benchmark on a stand-in data root",
    )
    parser.add_argument(
        "--profile", action="store_true", help="with --full-plan: also profile the dry run (cProfile; ~2 min more)"
    )
    parser.add_argument(
        "--stages", action="store_true", help="only the CPU seconds by stage of a ~150-pair TOSCA run from scratch"
    )
    parser.add_argument(
        "--repo",
        type=Path,
        default=REPO,
        help="with --stages/--scaling: the checkout whose Snakefile and code run (default: this one)",
    )
    parser.add_argument("--remeshed", type=Path, help="with --stages/--scaling: copy this results/remeshed in first")
    parser.add_argument(
        "--scaling", action="store_true", help="only pairs/s and CPU by stage per setting and size (issue 16, target 3)"
    )
    parser.add_argument("--sizes", default="150,1000", help="with --scaling: pairs per setting (comma-separated)")
    parser.add_argument(
        "--settings",
        default="full_full,partial_full,partial_partial",
        help="with --scaling: the settings (comma-separated)",
    )
    parser.add_argument(
        "--decimator",
        help="with --scaling: the config key decimator (pymeshlab, fast-simplification; default: its default)",
    )
    parser.add_argument(
        "--pairs-per-chunk",
        type=int,
        help="with --scaling: the config key pairs_per_chunk (the fewest pairs per chunk job; default: its default)",
    )
    args = parser.parse_args()
    code = becos_code()
    result: dict = {"machine_cores": os.cpu_count()}
    if args.scaling:
        result["scaling"] = scaling(
            args.workdir,
            code,
            args.repo.resolve(),
            [int(n) for n in args.sizes.split(",")],
            args.settings.split(","),
            args.remeshed,
            args.decimator,
            args.pairs_per_chunk,
        )
        print(json.dumps(result, indent=1))
        return
    if args.stages:
        result["stages"] = stages(args.workdir, code, args.repo.resolve(), args.remeshed)
        print(json.dumps(result, indent=1))
        return
    if args.full_plan:
        result["full_plan"] = full_plan(args.workdir / "fullplan", code, profile=args.profile)
        print(json.dumps(result, indent=1))
        return

    dag = args.workdir / "dag10k"
    shutil.rmtree(dag, ignore_errors=True)
    write_config(dag, code, usage_scale=3.86, remesh_variants=4)
    snakemake(dag, "--cores", "2", "--until", "check_datasets")
    seconds, out, _ = snakemake(dag, "-n", "--cores", "2")
    result["dag_10k"] = {"seconds": round(seconds, 2), "jobs": job_counts(out)}
    if args.skip_run:
        print(json.dumps(result, indent=1))
        return

    caps = {"train": None, "val": None, "test": None}
    big = args.workdir / "run1000"
    shutil.rmtree(big, ignore_errors=True)
    write_config(big, code, usage_scale=0.38, remesh_variants=args.variants, caps=caps)
    seconds, out, memory = snakemake(big, "--cores", "2")
    pairs = n_pairs(big)
    result["run_1000"] = {
        "pairs": pairs,
        "seconds": round(seconds, 1),
        "pairs_per_second": round(pairs / seconds, 3),
        "reference_pairs_per_second": 0.16,
        **memory,
        "jobs": job_counts(out),
        "remesh_variants": args.variants,
    }
    seconds, out, _ = snakemake(big, "--cores", "2")
    result["noop_rerun"] = {"seconds": round(seconds, 2), "nothing_to_do": "Nothing to be done" in out}

    small = args.workdir / "run100"
    shutil.rmtree(small, ignore_errors=True)
    write_config(small, code, usage_scale=0.038, remesh_variants=args.variants, caps=caps)
    shutil.copytree(big / "results" / "remeshed", small / "results" / "remeshed")
    seconds, out, memory = snakemake(small, "--cores", "2")
    result["run_100"] = {"pairs": n_pairs(small), "seconds": round(seconds, 1), **memory, "jobs": job_counts(out)}
    result["rss_ratio_1000_vs_100"] = round(result["run_1000"]["peak_rss_mb"] / result["run_100"]["peak_rss_mb"], 3)
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
