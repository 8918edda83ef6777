"""The workflow on a real single-node SLURM cluster through ``profiles/slurm`` (issue 8).

``cluster/slurm_harness.py`` installs (apt-get, when missing) and starts munged, MariaDB, slurmdbd,
slurmctld and slurmd on localhost with all state in a temporary folder. The tiny TOSCA configuration
of ``tests/test_workflow.py`` (``tests/tiny_tosca.py``; one chunk job per setting and stage) then runs
with ``--profile profiles/slurm`` and is compared with the local ``--cores 2`` run (conftest's
``tiny_tosca_reference``, which the workflow tests share); manifests, catalog and every array,
offset table, pair meta and table of the three Zarr stores must hash equal, every SLURM job of the
run must be COMPLETED in ``sacct``, and the profile's groups must hold: one SLURM job per 25 remesh
jobs (shapes) and per chunk (its ground_truth and pairs jobs), fewer submissions than jobs. ``profiles/cluster-generic`` submits one remesh job to the same cluster.

Everything happens in ONE test: under ``pytest -n 2`` a module fixture is built once per worker
that runs a test of the module, and one machine holds one harness cluster. Skipped (with the exact
command and error) when a daemon cannot run here; ``BECOS_SKIP_SLURM=1`` skips it,
``BECOS_REQUIRE_SLURM=1`` turns that skip into a failure. ``pytest -s`` prints the harness log,
``sinfo`` and the ``sacct`` listing. About 4-5 minutes on 2 cores (plus the apt-get install on a
fresh machine); docs/cluster.md.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from snakemake_cmd import snakemake_cmd
from tiny_tosca import fingerprint_differences, results_fingerprint, tiny_tosca_config, write_config_file

REPO = Path(__file__).resolve().parents[1]
# test-only speed-ups (a real cluster keeps the plugin's defaults: first check after 40 s, then every 10 s+)
FAST_STATUS = ["--slurm-init-seconds-before-status-checks", "2", "--seconds-between-status-checks", "2"]
RUN_TIMEOUT_S = 1800


def _load_harness():
    spec = importlib.util.spec_from_file_location("slurm_harness", REPO / "cluster" / "slurm_harness.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def slurm_cluster():
    """A started :class:`SlurmHarness` (state in a fresh /tmp folder); stopped and removed at teardown."""
    if os.environ.get("BECOS_SKIP_SLURM") == "1":
        pytest.skip("BECOS_SKIP_SLURM=1")
    harness_module = _load_harness()
    state = Path(tempfile.mkdtemp(prefix="becos-slurm-"))  # short: unix socket paths must stay < 108 bytes
    harness = harness_module.SlurmHarness(state)
    try:
        harness.start()
    except harness_module.HarnessError as error:
        print("\n".join(harness.lines))
        harness.stop()
        shutil.rmtree(state, ignore_errors=True)
        message = f"the SLURM test cluster cannot start here: {error}"
        if os.environ.get("BECOS_REQUIRE_SLURM") == "1":
            pytest.fail(message)
        pytest.skip(message)
    yield harness
    harness.stop()
    print("\n--- harness log\n" + "\n".join(harness.lines))
    shutil.rmtree(state, ignore_errors=True)


def _env(harness) -> dict[str, str]:
    """This process's environment without SLURM job/client variables, plus the cluster's and the profile's."""
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith(("SLURM_", "SBATCH_", "SRUN_")) and k != "SNAKEMAKE_PROFILE"
    }
    env.update(
        harness.env(),
        BECOS_SLURM_ACCOUNT=harness.account,
        BECOS_SLURM_PARTITION=harness.partition,
        PYTHONUNBUFFERED="1",
    )
    return env


def _snakemake(workdir: Path, args: list[str], env: dict[str, str]) -> tuple[float, str]:
    """Run Snakemake in ``workdir`` (its working directory, as on a login node); returns (seconds, output)."""
    start = time.perf_counter()
    try:
        result = subprocess.run(
            snakemake_cmd(workdir, *args),
            cwd=workdir,
            env=env,
            capture_output=True,
            text=True,
            timeout=RUN_TIMEOUT_S,
        )
    except subprocess.TimeoutExpired as e:
        raise AssertionError(
            f"snakemake {' '.join(args)} did not finish in {RUN_TIMEOUT_S} s:\n"
            f"{(e.stdout or '')[-4000:]}\n{(e.stderr or '')[-4000:]}"
        ) from None
    seconds = time.perf_counter() - start
    output = result.stdout + result.stderr
    if result.returncode != 0:
        logs = "\n".join(
            f"--- {p}\n{p.read_text(errors='replace')[-3000:]}"
            for p in sorted(workdir.rglob("*.log"))
            if "Error" in p.read_text(errors="replace")
        )
        raise AssertionError(
            f"snakemake {' '.join(args)} failed (exit {result.returncode}) in {workdir}:\n"
            f"{output[-8000:]}\n{logs[-8000:]}"
        )
    return seconds, output


def test_workflow_on_slurm_equals_local_run(slurm_cluster, tiny_tosca_reference, becos_code, tmp_path_factory):
    harness = slurm_cluster
    env = _env(harness)
    print(f"\ncluster: install {harness.timings['install_s']:.1f} s, start {harness.timings['start_s']:.1f} s")

    # 1. the cluster itself: node idle with this machine's CPUs, the harness's srun job accounted
    hardware = json.loads((harness.state / "harness.json").read_text())["hardware"]
    nodes = harness.run("sinfo", "-h", "-N", "-o", "%N|%P|%t|%c|%m").stdout.split()
    assert nodes == [f"{harness.node}|{harness.partition}*|idle|{hardware['CPUs']}|{hardware['RealMemory']}"], nodes
    smoke = [j for j in harness.jobs() if j["JobName"] == "hostname"]
    assert smoke and smoke[0]["State"] == "COMPLETED", harness.sacct()

    # 2. the configuration of the local run (tiny_tosca_reference) through the SLURM profile, in its own working directory
    local = tiny_tosca_reference.workdir
    remote = write_config_file(tmp_path_factory.mktemp("slurm-remote"), tiny_tosca_config(becos_code))
    slurm_s, out = _snakemake(remote, ["--profile", str(REPO / "profiles" / "slurm"), *FAST_STATUS], env)
    print(f"tiny TOSCA run through the SLURM profile: {slurm_s:.1f} s")

    # 3. every job Snakemake submitted is a COMPLETED SLURM job of this run, with its rule in the comment
    run_id = re.search(r"SLURM run ID: (\S+)", out).group(1)
    # "Job <id> has been submitted with SLURM jobid N": a group job's Snakemake id is a uuid, not a number
    submitted = dict(re.findall(r"Job (\S+) has been submitted with SLURM jobid (\d+)", out))
    listing = harness.sacct(
        fmt="JobID,JobName%45,Comment%55,State,ExitCode,Elapsed,MaxRSS", all_steps=True, extra=("--name", run_id)
    )
    print(f"\n$ sinfo\n{harness.run('sinfo').stdout}\n$ sacct --name {run_id} (every step)\n{listing}")
    jobs = {j["JobID"]: j for j in harness.jobs() if j["JobName"] == run_id}
    assert submitted and set(submitted.values()) == set(jobs), (sorted(submitted.values()), sorted(jobs))
    bad = {
        i: (j["State"], j["ExitCode"]) for i, j in jobs.items() if (j["State"], j["ExitCode"]) != ("COMPLETED", "0:0")
    }
    assert not bad, f"SLURM jobs not COMPLETED 0:0: {bad}\n{listing}"
    # a single job's comment names its rule, a group job's its group and rules (remesh_remesh, chunk_ground_truth_pairs)
    kinds = [re.match(r"rule_([a-z_]+?)(_wildcards_.*)?$", j["Comment"]).group(1) for j in jobs.values()]
    rules = set(kinds)
    assert {"remesh_remesh", "chunk_ground_truth_pairs", "zarr_store", "validate_store"} <= rules, rules
    local_rules = {
        "all",
        "resolved_config",
        "check_datasets",
        "catalog",
        "manifest",
        "store_metadata",
        "published_pairings",
    }
    print(f"{len(jobs)} SLURM jobs, all COMPLETED 0:0; rules and groups on SLURM: {sorted(rules)}")
    assert not rules & local_rules, rules & local_rules

    # grouping: the remesh jobs go in batches of the profile's group size, a chunk's ground_truth and pairs
    # jobs in one SLURM job; without groups each would be its own submission
    sizes = yaml.safe_load((REPO / "profiles" / "slurm" / "config.yaml").read_text())["group-components"]
    n_remesh = len({p.parent for p in (remote / "results" / "remeshed").rglob("*.npz")})  # one job per shape
    n_chunks = len(list((remote / "results").glob("*/ground_truth/chunk_*.json")))
    assert kinds.count("remesh_remesh") == -(-n_remesh // sizes["remesh"]), (n_remesh, kinds)
    assert kinds.count("chunk_ground_truth_pairs") == n_chunks and sizes["chunk"] == 1, (n_chunks, kinds)
    ungrouped = (
        len(jobs) - kinds.count("remesh_remesh") - kinds.count("chunk_ground_truth_pairs") + n_remesh + 2 * n_chunks
    )
    print(f"grouping: {len(jobs)} submissions instead of {ungrouped} ({n_remesh} remesh jobs, {n_chunks} chunks)")
    assert len(jobs) < ungrouped, (len(jobs), ungrouped)

    # 4. identical outputs
    expected, got = tiny_tosca_reference.fingerprint, results_fingerprint(remote)
    differ = fingerprint_differences(expected, got)
    assert not differ, f"SLURM run differs from the local run in {differ}"
    n_arrays = sum("/arrays/" in k for k in expected)
    n_files = sum(
        "/" not in k or k.split("/")[1] in ("manifest.csv", "ground_truth", "pairs") or k.startswith("remeshed/")
        for k in expected
    )
    print(
        f"identical: {len(expected)} sha256 digests ({n_files} result files: catalog, manifests, remeshes, "
        f"ground truth, pair files; {n_arrays} store arrays, offsets, metas, tables, metadata)"
    )

    # 5. the cluster-generic profile (its SLURM example) submits a remesh job; same file as the local run
    generic = write_config_file(tmp_path_factory.mktemp("slurm-generic"), tiny_tosca_config(becos_code))
    target = "results/remeshed/tosca/cat0/v0.npz"
    generic_s, out = _snakemake(
        generic,
        [
            "--profile",
            str(REPO / "profiles" / "cluster-generic"),
            "--seconds-between-status-checks",
            "2",
            str(Path(target).parent),  # the remesh job's output: the shape's folder
        ],
        env,
    )
    job = re.search(r"Submitted (?:group )?job \S+ with external jobid '(\d+)'", out)  # remesh is a group
    assert job, out[-3000:]
    state = harness.run("sacct", "-j", job.group(1), "-X", "-n", "-P", "-o", "JobName,State,ExitCode").stdout.strip()
    assert state == "becos-remesh|COMPLETED|0:0", state
    with np.load(local / target) as a, np.load(generic / target) as b:
        assert set(a.files) == set(b.files)
        for key in a.files:
            assert np.array_equal(a[key], b[key]), key
    print(
        f"cluster-generic profile: {target} as SLURM job {job.group(1)} ({state}) in {generic_s:.1f} s, "
        "equal to the local run's"
    )
