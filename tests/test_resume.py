"""Interrupted, concurrent and repeated runs of the workflow (real Snakemake on TOSCA meshes).

The tiny TOSCA configuration (8 shapes, all three settings, at most 6 pairs each) is built three ways
and compared with :func:`tiny_tosca.results_fingerprint`:

- ``--cores 2`` without interruption (the reference: conftest's ``tiny_tosca_reference``);
- ``--cores 1`` without interruption: same manifests byte for byte, same arrays;
- ``--cores 2`` killed with SIGKILL (the whole process tree: Snakemake and its jobs, as a crash or a
  cluster pre-emption would) while remeshing, while building pair records and while writing the Zarr
  stores, each time resumed with the documented commands (``snakemake --unlock``, then the same
  command with ``--rerun-incomplete``): ends identical to the reference.

And a second Snakemake started on a ``results/`` folder that a running one is writing is refused by
Snakemake's lock, before it runs any job.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import psutil
import pytest
from snakemake_cmd import snakemake, snakemake_cmd
from tiny_tosca import SETTINGS, fingerprint_differences, results_fingerprint, tiny_tosca_config, write_config_file


def small_config(workdir: Path, becos_code: Path) -> Path:
    """``workdir`` with the tiny TOSCA configuration: the one conftest's ``tiny_tosca_reference`` ran."""
    return write_config_file(workdir, tiny_tosca_config(becos_code))


def leftovers(workdir: Path) -> list[str]:
    """Temporary files and folders of atomic writes left in results/ (hidden ``.<name>.*tmp*``)."""
    return sorted(str(p.relative_to(workdir)) for p in (workdir / "results").rglob(".*") if "tmp" in p.name)


def kill_tree(process: subprocess.Popen) -> int:
    """SIGKILL Snakemake and every process it started; the number of processes killed."""
    try:
        procs = [psutil.Process(process.pid)]
        procs += procs[0].children(recursive=True)
    except psutil.NoSuchProcess:
        return 0
    for p in procs:
        try:
            p.send_signal(signal.SIGKILL)
        except psutil.NoSuchProcess:
            pass
    process.wait()
    psutil.wait_procs(procs, timeout=10)
    return len(procs)


def holds_lock(workdir: Path) -> bool:
    """Whether a Snakemake run holds its lock on ``workdir`` (its lock files exist)."""
    return any((workdir / ".snakemake" / "locks").glob("*.lock"))


def run_until(workdir: Path, cores: str, marker, *extra: str, timeout: float = 600) -> tuple[bool, int]:
    """Start ``snakemake --cores N`` and SIGKILL it once ``marker(workdir)`` is true while it holds its lock
    (a temporary folder a previous kill left can match a marker before the new run has taken the lock).

    Returns (killed, processes killed); killed is False when the run ended before the marker."""
    cmd = snakemake_cmd(workdir, "--cores", cores, *extra)
    with open(workdir / f"run-{time.monotonic_ns()}.out", "w") as out:
        process = subprocess.Popen(
            cmd,
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            env=dict(os.environ, PYTHONUNBUFFERED="1"),
        )
        deadline = time.monotonic() + timeout
        while process.poll() is None and time.monotonic() < deadline:
            if marker(workdir) and holds_lock(workdir):
                return True, kill_tree(process)
            time.sleep(0.05)
        if process.poll() is None:
            kill_tree(process)
            raise AssertionError(f"snakemake did not reach the kill point within {timeout} s")
    return False, 0


def remeshing(workdir: Path) -> bool:
    """At least one remesh finished and others still to run."""
    return any((workdir / "results" / "remeshed").rglob("v0.npz"))


def building_pairs(workdir: Path) -> bool:
    """A pair record written by a chunk job that has not finished (more pair files than the pairs of
    the finished chunks' indices)."""
    base = workdir / "results" / "partial_partial" / "pairs"
    finished = sum(json.loads(p.read_text())["n_pairs"] for p in base.glob("chunk_*.json"))
    return len(list(base.glob("[!.]*.npz"))) > finished


def writing_stores(workdir: Path) -> bool:
    """A Zarr store being written in its temporary folder (renamed into place when complete)."""
    return any(p.is_dir() for p in (workdir / "results").glob("*/.benchmark.zarr.*tmp"))


def test_a_killed_write_leaves_a_temporary_file_the_next_writer_removes(tmp_path):
    """SIGKILL inside :func:`becos.atomic.save_npz` leaves a hidden temporary file (never a partial file
    under the final name); :func:`becos.atomic.remove_stale_temporaries` removes exactly those of
    the names it is given."""
    import sys

    from becos.atomic import remove_stale_temporaries

    script = (
        "import os, signal, sys, numpy as np\n"
        "from becos import atomic\n"
        "def killed(path, **arrays):\n"
        "    open(path, 'wb').write(b'half a file')\n"
        "    os.kill(os.getpid(), signal.SIGKILL)\n"
        "atomic.np.savez = killed\n"
        "atomic.save_npz(sys.argv[1], x=np.zeros(3))\n"
    )
    for name in ("mine.npz", "mine.npz", "other.npz"):
        run = subprocess.run([sys.executable, "-c", script, str(tmp_path / name)])
        assert run.returncode == -signal.SIGKILL
    (tmp_path / "other.npz").write_bytes(b"finished")
    left = sorted(p.name for p in tmp_path.iterdir())
    assert len(left) == 4 and not (tmp_path / "mine.npz").exists(), left
    assert remove_stale_temporaries(tmp_path, ["mine.npz"]) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(n for n in left if not n.startswith(".mine.npz."))
    assert remove_stale_temporaries(tmp_path / "absent", ["mine.npz"]) == 0
    # a folder built aside and renamed into place (an export, the synthetic collection): a killed run
    # leaves ".<name>.tmp-<random>" or, between the two renames, the replaced ".<name>.old-<random>"
    for name in (".released.tmp-k1", ".released.old-k2", ".released-extra.tmp-k3", ".psmal.tmp-k4"):
        (tmp_path / name).mkdir()
    assert remove_stale_temporaries(tmp_path, ["released"]) == 2
    assert sorted(p.name for p in tmp_path.glob(".*-k*")) == [".psmal.tmp-k4", ".released-extra.tmp-k3"]


def test_a_folder_is_written_whole_or_not_at_all(tmp_path):
    """:func:`becos.atomic.atomic_folder` (a remesh job's shape folder): nothing under the final name until
    the folder is complete, a failed write keeps the old folder, a new one replaces it whole (a token
    gone from it goes with it), and a killed write's temporary folder is removed by the next write."""
    from becos.atomic import atomic_folder

    out = tmp_path / "tosca" / "cat0"
    (tmp_path / "tosca" / ".cat0.tmp-killed").mkdir(parents=True)  # what a SIGKILLed job leaves
    (tmp_path / "tosca" / ".cat0.1.tmp-running").mkdir()  # another shape's job, writing beside it
    with atomic_folder(out) as folder:
        (folder / "v0.npz").write_bytes(b"first")
        assert not out.exists()
    assert sorted(p.name for p in (tmp_path / "tosca").iterdir()) == [".cat0.1.tmp-running", "cat0"]
    assert out.stat().st_mode & 0o777 == 0o755
    (tmp_path / "tosca" / ".cat0.1.tmp-running").rmdir()
    with pytest.raises(RuntimeError):
        with atomic_folder(out) as folder:
            (folder / "v0.npz").write_bytes(b"half")
            raise RuntimeError("the job failed")
    assert [p.name for p in (tmp_path / "tosca").iterdir()] == ["cat0"]
    assert (out / "v0.npz").read_bytes() == b"first"
    with atomic_folder(out) as folder:
        (folder / "v1.npz").write_bytes(b"second")
    assert [p.name for p in (tmp_path / "tosca").iterdir()] == ["cat0"]
    assert [p.name for p in out.iterdir()] == ["v1.npz"]


@pytest.fixture(scope="module")
def reference_run(tiny_tosca_reference) -> tuple[Path, dict]:
    """The uninterrupted ``--cores 2`` run and its fingerprint."""
    return tiny_tosca_reference.workdir, tiny_tosca_reference.fingerprint


def test_cores_1_and_cores_2_give_identical_results(reference_run, becos_code, tmp_path):
    reference_dir, reference = reference_run
    workdir = small_config(tmp_path / "cores1", becos_code)
    snakemake(workdir, "--cores", "1")
    fingerprint = results_fingerprint(workdir)
    manifests = [k for k in reference if k.endswith("manifest.csv")]
    assert len(manifests) == 3 and sum("/arrays/" in k for k in reference) > 3
    differ = fingerprint_differences(reference, fingerprint)
    assert not differ, differ[:20]
    print(
        f"\n--cores 1 vs --cores 2: {len(reference)} files and store records compared, all identical "
        f"({len(manifests)} manifests byte-identical)"
    )


def test_store_metadata_names_the_library_versions_and_the_config_hash(reference_run):
    from becos.products.store import open_benchmark
    from becos.workflow import digest

    workdir, _ = reference_run
    for setting in SETTINGS:
        meta = open_benchmark(workdir / "results" / setting / "benchmark.zarr").metadata
        for package in ("numpy", "trimesh", "pymeshlab", "embreex", "zarr", "becos", "python"):
            assert meta["versions"].get(package), (setting, package, meta["versions"])
        assert meta["config_hash"] == digest(meta["config"]) and meta["config"]["seed"] is not None
    print(f"\nstore metadata: config_hash {meta['config_hash']}, versions {meta['versions']}")


def test_killed_runs_resume_to_the_uninterrupted_result(reference_run, becos_code, tmp_path):
    _, reference = reference_run
    workdir = small_config(tmp_path / "killed", becos_code)
    report = []
    for point in (remeshing, building_pairs, writing_stores):
        killed, n = run_until(workdir, "2", point, "--rerun-incomplete")
        report.append(f"{point.__name__}: {'killed ' + str(n) + ' processes' if killed else 'run ended first'}")
        if killed:
            # a killed Snakemake leaves its lock: the documented resume is --unlock, then the same command
            locked = snakemake(workdir, "--cores", "2", "--rerun-incomplete", check=False)
            assert locked.returncode != 0 and "cannot be locked" in locked.stdout + locked.stderr
            snakemake(workdir, "--unlock")
    assert sum(r.endswith("processes") for r in report) >= 2, report
    snakemake(workdir, "--cores", "2", "--rerun-incomplete")
    fingerprint = results_fingerprint(workdir)
    differ = fingerprint_differences(reference, fingerprint)
    assert not differ, differ[:20]
    assert not leftovers(workdir)  # each job removes the temporary files a killed run of it left
    print(
        f"\nkill -9 and resume: {'; '.join(report)}; final results identical to the uninterrupted run "
        f"({len(reference)} files and store records); no temporary file left by the kills"
    )


def test_a_second_run_on_the_same_results_is_refused(becos_code, tmp_path):
    """A second Snakemake on a folder a running one is writing runs no job.

    Snakemake checks for incomplete files while building its DAG, before it takes the lock, so a
    second run that looks while one of the first run's jobs is finishing stops with "incomplete
    files" and the advice ``--rerun-incomplete``; following that advice must then meet the lock."""
    workdir = small_config(tmp_path / "shared", becos_code)
    cmd = snakemake_cmd(workdir, "--cores", "1")
    out = open(workdir / "first-run.out", "w")  # a file, not a pipe nobody reads (it would fill and block)
    first = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + 300
        while not remeshing(workdir) and first.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert first.poll() is None, "the first run ended before the test could start a second one"
        before = sorted(p.name for p in (workdir / "results" / "remeshed").rglob("*.npz"))
        second = snakemake(workdir, "--cores", "1", check=False)
        text = second.stdout + second.stderr
        assert second.returncode != 0, text[-2000:]
        assert "cannot be locked" in text or "incomplete" in text.lower(), text[-2000:]
        assert "rule remesh" not in text and "localrule" not in text, text[-2000:]  # no job started
        advised = snakemake(workdir, "--cores", "1", "--rerun-incomplete", check=False)
        advised_text = advised.stdout + advised.stderr
        assert advised.returncode != 0 and "cannot be locked" in advised_text, advised_text[-2000:]
        after = sorted(p.name for p in (workdir / "results" / "remeshed").rglob("*.npz"))
        assert set(before) <= set(after), "the refused runs removed the first run's outputs"
        assert first.poll() is None, "the first run stopped while the second ones were refused"
        refusal = next(line for line in advised_text.splitlines() if "cannot be locked" in line)
        print(
            f"\nsecond run refused: {next(line for line in text.splitlines() if 'locked' in line or 'ncomplete' in line)}"
            f"; with --rerun-incomplete: {refusal}"
        )
    finally:
        kill_tree(first)
        out.close()
