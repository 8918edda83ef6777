# Shared names and the plan. Every job runs `becos <sub-command>` from the environment that runs
# Snakemake (its bin folder goes first on PATH): the pip-installed environment is the only one.
import atexit
import functools
import json
import os
import shlex
import sys
from pathlib import Path

from snakemake.exceptions import IncompleteCheckpointException

from becos.sources import dt4d as bdt4d
from becos import progress_panel
from becos import workflow as bw
from becos.sources.download import archive_url
from becos.errors import BecosError
from becos.resources import RuleResources
from becos.workflow.scheduling import one_pending_reevaluation

SETTINGS = bw.settings_of(config)
# Every path of the rules is stated once, in becos.workflow.layout.Layout. Outputs are LAYOUT patterns;
# inputs are the producing rule's output (rules.<name>.output) or, across settings, LAYOUT with values.
LAYOUT = bw.Layout.of(config)
EXPORTS = config["exports"]
BASELINES = config["evaluation"]["baselines"]
# mem_mb / runtime per rule from measured peaks (benchmarks/resources.py); x attempt on retries
RESOURCES = RuleResources.load(Path(workflow.basedir) / "workflow" / "resources.yaml")
# Snakemake's scheduler keeps at most one re-evaluation timer pending: its own CPU then grows linearly
# with the job count, not with its square (becos.workflow.scheduling)
one_pending_reevaluation()


# bookkeeping rules run in the Snakemake process's machine, never as cluster jobs
localrules:
    all,
    resolved_config,
    check_datasets,
    catalog,
    manifest,
    store_metadata,
    published_pairings,


envvars:
    "PATH",


os.environ["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")])

_plans = {}


def plan():
    """The catalog, manifests and job lists; known once the dataset check has run."""
    checkpoints.check_datasets.get()
    if "plan" not in _plans:
        try:
            _plans["plan"] = bw.Plan.build(config)
        except BecosError as error:
            # one line, as the CLI prints it, instead of Snakemake's InputFunctionException and traceback;
            # printed here because a running scheduler reports SystemExit only as a termination
            print(f"becos plan: {error}", file=sys.stderr, flush=True)
            raise SystemExit(1) from None
    return _plans["plan"]


def chunk_pairs(wildcards):
    """Pairs in a chunk job's chunk (its run time grows with them)."""
    return len(plan().chunk_rows(wildcards.setting, int(wildcards.chunk)))


def shape_variants(wildcards):
    """Remesh variants a remesh job writes (its run time grows with them)."""
    return len(plan().remesh_jobs[(wildcards.dataset, wildcards.name)])


def setting_pairs(wildcards):
    """Pairs of a setting (the run time of its store, export and evaluation jobs grows with them);
    0 while the dataset check has not run (a dry run before it, or one after its inputs changed), then
    the real count."""
    if not LAYOUT.checks.exists():
        return 0  # calling plan() from a resource before the checkpoint crashes Snakemake 9's dry run
    try:
        return len(plan().manifests[wildcards.setting])
    except IncompleteCheckpointException:  # the check reruns (e.g. a DT4D class was added): same crash
        return 0


@functools.cache
def geodesics_disk_mb():
    """The geodesics export's disk in MB, an upper bound from the manifests (becos.products.export.geodesics.
    manifest_disk_estimate), printed once per Snakemake call with the free space, a dry run included,
    and a warning above it; 0 before the dataset check, and where no vertex bound is known before
    remeshing (the geodesic_plan job's log then has the estimate)."""
    import shutil

    from becos.products.export.geodesics import manifest_disk_estimate
    from becos.products.export.staging import gigabytes
    from becos.build.remesh import VERTEX_TARGET_RANGE

    if not LAYOUT.checks.exists() or not (config["remesh"] and config["remesher"] == "becos"):
        return 0
    try:
        manifests = plan().manifests
    except IncompleteCheckpointException:  # as setting_pairs
        return 0
    estimate = manifest_disk_estimate(manifests, EXPORTS["geodesic_splits"], VERTEX_TARGET_RANGE[1])
    free = shutil.disk_usage(LAYOUT.results).free
    print(
        f"becos: the geodesics export ({' '.join(EXPORTS['geodesic_splits'] or ['every'])} split) needs at most "
        f"{gigabytes(estimate['disk_bytes'])}: {estimate['meshes']} full meshes and {estimate['scans']} scans of at "
        f"most {VERTEX_TARGET_RANGE[1]:,} vertices, (V, V) float32 each; free on disk: {gigabytes(free)}",
        file=sys.stderr,
        flush=True,
    )
    if estimate["disk_bytes"] > free:
        print(
            "becos: warning: the geodesics export may not fit the free disk. Fix: free disk space, or export "
            "fewer splits (exports.geodesic_splits: [test])",
            file=sys.stderr,
            flush=True,
        )
    return estimate["disk_bytes"] // 10**6


def chunk_files(setting, kind):
    """Index files of every chunk of a setting (kind: ground_truth or pairs)."""
    p = plan()
    path = LAYOUT.ground_truth_index if kind == "ground_truth" else LAYOUT.pairs_index
    drop_stale_indexes(setting)
    return [str(path(setting, c)) for c in p.chunks(setting)]


@functools.cache
def drop_stale_indexes(setting):
    """Remove each chunk index of ``setting`` that lists files which are gone (ground truth or pair records
    deleted after a finished run), so that its chunk job runs again and writes them back (the others'
    files are kept): Snakemake itself does not rerun a job whose outputs exist, for a deleted file they
    list. Once per setting and Snakemake call."""
    for c in plan().chunks(setting):
        for index in (LAYOUT.ground_truth_index(setting, c), LAYOUT.pairs_index(setting, c)):
            missing = bw.missing_indexed_files(index)
            if missing:
                try:
                    index.unlink(missing_ok=True)
                except OSError as exc:  # a read-only results folder: the store writer names the record
                    print(f"becos: {index} lists files that are gone, and cannot be removed ({exc})", file=sys.stderr)
                    continue
                print(
                    f"becos: {index} lists {len(missing)} file(s) that are gone (e.g. {missing[0]}); removed "
                    "it, so that its chunk job writes them again",
                    file=sys.stderr,
                    flush=True,
                )


def published_views_input(wildcards):
    """The folder of shipped triangle ids a pairs job of the setting reads (original_settings P2P with the
    reference remesh; becos.workflow.published_views_folder), or none."""
    if not bw.uses_published_views(config, wildcards.setting):
        return []
    checkpoints.check_datasets.get()  # the annotation folder may be fetched by a job first
    folder = bw.published_views_folder(config, wildcards.setting)
    return [] if folder is None else [str(folder)]


def optional_path(option, paths):
    """``option 'path'`` for an optional input (a list of at most one path), or "" without one."""
    paths = [paths] if isinstance(paths, str) else list(paths)
    return " ".join(f"{option} {shlex.quote(str(p))}" for p in paths)


def all_targets(wildcards):
    # the dataset check is a target itself: a deleted check report is rebuilt (the targets below reach it
    # only through input functions, which Snakemake does not follow to a checkpoint whose output is gone)
    targets = [str(LAYOUT.config), str(LAYOUT.checks)]
    for setting in SETTINGS:
        targets.append(str(LAYOUT.validation(setting)))
        for export, path in (
            ("released", LAYOUT.released),
            ("psmal", LAYOUT.psmal),
            ("ulrssm", LAYOUT.ulrssm),
            ("dpfm", LAYOUT.dpfm),
            ("geodesics", LAYOUT.geodesics),
            ("published_pickle", LAYOUT.published_pickle),
            ("report", LAYOUT.report),
        ):
            if EXPORTS[export]:
                targets.append(str(path(setting)))
        if BASELINES:
            targets.append(str(LAYOUT.evaluation(setting) / "summary.csv"))
    # every remesh folder is a target once the dataset check has run, so a deleted one, or one missing a file
    # (e.g. the PLY that no job reads; drop_incomplete_remesh_folders), is rebuilt; before the check the
    # targets above are listed (a first dry run shows them all)
    if LAYOUT.checks.exists():
        drop_incomplete_remesh_folders()
        targets += [str(LAYOUT.remeshed_folder(*shape)) for shape in plan().remesh_jobs]
    return targets


@functools.cache
def drop_incomplete_remesh_folders():
    """Remove each remesh folder that lacks a file its job writes (a .npz or .ply deleted after a finished
    run), so that its remesh job runs again and writes the folder whole: Snakemake itself does not rerun a
    job whose output folder exists, for a file deleted inside it. Once per Snakemake call."""
    import shutil

    for (dataset, name), tokens in plan().remesh_jobs.items():
        folder = LAYOUT.remeshed_folder(dataset, name)
        if not folder.is_dir():
            continue
        files = [bw.variant_file(folder, t) for t in tokens]
        missing = [p for f in files for p in (f, f.with_suffix(".ply")) if not p.is_file()]
        if missing:
            try:
                shutil.rmtree(folder)
            except OSError as exc:  # a read-only results folder: the chunk job reading it names the file
                print(f"becos: {folder} lacks {missing[0].name}, and cannot be removed ({exc})", file=sys.stderr)
                continue
            print(
                f"becos: {folder} lacks {len(missing)} file(s) its remesh job writes (e.g. {missing[0].name}); "
                "removed it, so that the job writes the folder again",
                file=sys.stderr,
                flush=True,
            )


# Content digests of the input files (becos.workflow.digests): the jobs that read a dataset or annotation
# file get its digest as a param, so a file replaced by other content reruns them whatever its modification
# time. The cache is written once, when Snakemake exits, except after a dry run (which writes nothing).
DIGESTS = bw.DigestCache(LAYOUT.input_digests.absolute())


def save_digests():
    """Write the digest cache when Snakemake exits, unless it was a dry run (``workflow.dryrun`` is known
    only once the run's settings are, so it is read at exit)."""
    if not workflow.dryrun:
        DIGESTS.save()


atexit.register(save_digests)


@functools.cache
def inputs_digest():
    """One digest over every file the dataset check reads (the check's, catalog's and manifests' trigger)."""
    return DIGESTS.files(bw.check_input_files(config))


@functools.cache
def annotations_digest():
    """One digest over the annotation folder's files."""
    return DIGESTS.files(bw.annotation_input_files(config))


def mesh_digest(wildcards):
    """The content digest of a remesh job's mesh file."""
    return DIGESTS.file(plan().files[(wildcards.dataset, wildcards.name)])


def chunk_sources_digest(wildcards):
    """What a chunk job reads from outside ``results``: the annotation folder and, without remeshing (the
    remesh files are declared inputs otherwise), the original meshes of its pairs."""
    if config["remesh"]:
        return annotations_digest()
    files = plan().chunk_original_files(wildcards.setting, int(wildcards.chunk))
    return f"{annotations_digest()}-{DIGESTS.files(files)}"


def generated_inputs(wildcards):
    inputs = []
    if config["synthetic"]["enabled"]:
        inputs.append(config["synthetic"]["out"])
    if config["annotations_archive"]:
        inputs.append(config["annotations"])
    inputs += [str(job.stamp) for job in DT4D_JOBS.values()]  # DeformingThings4D preparation (data.smk)
    inputs += [str(LAYOUT.downloaded(name)) for name in config["download"]]
    return inputs


# A failed job's own error lines (`becos <command>: <file>: <problem>. Fix: <fix>`) live in its log;
# print them at the end of a failed run, so nobody has to open the log to learn what to fix.
onerror:
    from becos.joblog import failure_report, snakemake_failed_jobs

    report = failure_report(snakemake_failed_jobs(workflow))
    if report:
        print(report, file=sys.stderr, flush=True)


# in a terminal (profiles/default): done/total jobs and an ETA in the progress panel
progress_panel.tune(getattr(getattr(workflow, "logger_manager", None), "plugin_handlers", None) or [])
