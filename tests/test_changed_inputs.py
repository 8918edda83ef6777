"""Inputs that change after a finished run (issue #29, BAD 1-4): real Snakemake runs on real TOSCA data.

A run of 4 TOSCA shapes (wolf0, wolf1, horse0, horse5; full_full, one chunk) is made once per pytest run
(shared by the xdist workers, as ``tiny_tosca_reference``) in a working folder whose config names its data
and annotation folders by relative paths: ``data/tosca-off`` (links to the 76 TOSCA meshes) and
``annotations`` (links to the BeCoS annotation folder's entries; its edge files linked one by one). Each
test copies that folder (links as links, times kept), so the copy is a finished run that Snakemake finds
up to date, and replaces one input the way a user does: a re-downloaded mesh, a re-ordered export, a
deleted check report, an edge file restored from a backup with ``cp -p`` (older modification time).
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from snakemake_cmd import snakemake as run_snakemake
from tiny_tosca import tosca_config, write_config_file

SHAPES = ["tosca/wolf0", "tosca/wolf1", "tosca/horse0", "tosca/horse5"]  # network path wolf0-dog0-horse0
EDGE = "tosca_dog0_tosca_wolf0_corres.txt"  # read by the wolf-horse pairs' ground truth, not by wolf-wolf
OLD = 1_500_000_000  # a modification time long before the run (2017): what `cp -p` of a backup keeps


def snakemake(workdir: Path, *args: str) -> subprocess.CompletedProcess:
    """Snakemake on ``workdir`` with ``--cores 2``; its result, failed or not."""
    return run_snakemake(workdir, "--cores", "2", *args, check=False)


def _link_tree(source: Path, dest: Path) -> None:
    dest.mkdir(parents=True)
    for p in source.iterdir():
        (dest / p.name).symlink_to(p)


@pytest.fixture(scope="session")
def finished_run(becos_code, tmp_path_factory) -> Path:
    """The finished run's working folder (module docstring); made once, under a lock, and never changed:
    tests work on copies (:func:`copy_of`)."""
    shared = os.environ.get("PYTEST_XDIST_WORKER") is not None
    root = tmp_path_factory.getbasetemp().parent if shared else tmp_path_factory.mktemp("changed")
    workdir, done = root / "changed-inputs", root / "changed-inputs.done"
    with open(root / "changed-inputs.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            shutil.rmtree(workdir, ignore_errors=True)  # a worker that died mid-run
            _link_tree(becos_code / "data" / "tosca-off", workdir / "data" / "tosca-off")
            _link_tree(becos_code, workdir / "annotations")
            (workdir / "annotations" / "precomputed_corr_templates").unlink()
            _link_tree(
                becos_code / "precomputed_corr_templates", workdir / "annotations" / "precomputed_corr_templates"
            )
            config = tosca_config(
                becos_code,
                data_dir="data",
                annotations="annotations",
                shapes=SHAPES,
                setting="full_full",
                n_chunks=1,
                caps={"train": 6, "val": 0, "test": 0},
                exports={"released": False, "psmal": False, "published_pickle": False, "report": False},
            )
            write_config_file(workdir, config)
            result = snakemake(workdir)
            assert result.returncode == 0, result.stderr[-5000:]
            done.write_text("ok")
    return workdir


@pytest.fixture
def copy_of(finished_run, tmp_path):
    """A copy of the finished run (links kept as links, modification times kept); Snakemake finds it up to
    date."""
    work = tmp_path / "run"
    shutil.copytree(finished_run, work, symlinks=True)
    return work


def _read_off(path: Path) -> tuple[np.ndarray, np.ndarray]:
    lines = path.read_text().split("\n")
    n_vertices, n_faces = (int(v) for v in lines[1].split()[:2])
    vertices = np.array([line.split() for line in lines[2 : 2 + n_vertices]], dtype=float)
    faces = np.array([line.split()[1:4] for line in lines[2 + n_vertices : 2 + n_vertices + n_faces]], dtype=int)
    return vertices, faces


def _replace_off(path: Path, vertices: np.ndarray, faces: np.ndarray, mtime: float | None = None) -> None:
    """Replace the file (a link) at ``path`` by a regular OFF file, with ``mtime`` as its times if given."""
    body = "\n".join(
        ["OFF", f"{len(vertices)} {len(faces)} 0"]
        + [" ".join(f"{x:.6f}" for x in v) for v in vertices]
        + [f"3 {a} {b} {c}" for a, b, c in faces]
    )
    path.unlink()
    path.write_text(body + "\n")
    if mtime is not None:
        os.utime(path, (mtime, mtime))


def _store_bytes(work: Path) -> dict[str, bytes]:
    store = work / "results" / "full_full" / "benchmark.zarr"
    return {str(p.relative_to(store)): p.read_bytes() for p in sorted(store.rglob("*")) if p.is_file()}


def _assert_stopped_by_the_check(result, work: Path, store_before: dict, problem: str) -> None:
    """The run failed at the dataset check, named wolf1.off and ``problem``, and ran no later job."""
    assert result.returncode != 0, "the run went through a mesh that no longer fits its class template"
    out = result.stdout + result.stderr
    assert "becos check:" in out and "wolf1.off" in out and problem in out, out[-3000:]
    assert "Traceback" not in out
    for rule in ("remesh", "ground_truth", "pairs", "zarr_store"):
        assert f"rule {rule}:" not in out, f"{rule} ran after the check failed"
    assert _store_bytes(work) == store_before


def test_a_finished_run_is_up_to_date_in_its_copy(copy_of):
    result = snakemake(copy_of, "-n")
    assert result.returncode == 0 and "Nothing to be done" in result.stdout, result.stdout[-3000:]


def test_a_mesh_scaled_after_a_finished_run_stops_at_the_check(copy_of):
    """BAD 1: wolf1.off x 1e6 (same faces), newer than the run's outputs."""
    store_before = _store_bytes(copy_of)
    wolf1 = copy_of / "data" / "tosca-off" / "wolf1.off"
    vertices, faces = _read_off(wolf1)
    _replace_off(wolf1, vertices * 1e6, faces)
    _assert_stopped_by_the_check(snakemake(copy_of), copy_of, store_before, "1e+06 times as long")


def test_a_mesh_with_permuted_vertices_and_an_old_time_stops_at_the_check(copy_of):
    """BAD 2: wolf1.off's vertex lines permuted and its faces re-indexed (the same surface), with a
    modification time older than the run's outputs."""
    store_before = _store_bytes(copy_of)
    wolf1 = copy_of / "data" / "tosca-off" / "wolf1.off"
    vertices, faces = _read_off(wolf1)
    order = np.random.default_rng(29).permutation(len(vertices))  # new vertex i is old vertex order[i]
    new_index = np.empty_like(order)
    new_index[order] = np.arange(len(order))
    _replace_off(wolf1, vertices[order], new_index[faces], mtime=OLD)
    _assert_stopped_by_the_check(snakemake(copy_of), copy_of, store_before, "re-ordered")


def test_a_deleted_check_report_is_rebuilt_and_sees_a_replaced_mesh(copy_of):
    """BAD 3: results/checks/datasets.json deleted, then a mesh replaced: the check runs again (dry run
    too) and stops the run."""
    store_before = _store_bytes(copy_of)
    (copy_of / "results" / "checks" / "datasets.json").unlink()
    dry = snakemake(copy_of, "-n")
    assert "Nothing to be done" not in dry.stdout and "check_datasets" in dry.stdout, dry.stdout[-3000:]
    wolf1 = copy_of / "data" / "tosca-off" / "wolf1.off"
    vertices, faces = _read_off(wolf1)
    _replace_off(wolf1, vertices * 1e6, faces, mtime=OLD)
    _assert_stopped_by_the_check(snakemake(copy_of), copy_of, store_before, "1e+06 times as long")


def _ground_truth_files(work: Path) -> dict[str, bytes]:
    index = json.loads((work / "results" / "full_full" / "ground_truth" / "chunk_0000.json").read_text())
    return {e["pair_id"]: (work / e["path"]).read_bytes() for e in index["pairs"]}


def _pair_classes(work: Path) -> dict[str, tuple[str, str]]:
    import pandas as pd

    manifest = pd.read_csv(work / "results" / "full_full" / "manifest.csv")
    return {
        p: (x.rstrip("0123456789"), y.rstrip("0123456789"))
        for p, x, y in manifest[["pair_id", "x_name", "y_name"]].values
    }


def test_an_edge_file_with_other_content_and_an_old_time_recomputes_the_ground_truth_that_reads_it(copy_of):
    """BAD 4: an edge file replaced by other content with an older modification time (what `cp -p` of a
    backup does, in either direction: the edited file, or the original restored after an edit). The
    ground truth of exactly the pairs whose network path reads it is recomputed; the store follows."""
    before = _ground_truth_files(copy_of)
    classes = _pair_classes(copy_of)
    reads_edge = {p for p, pair in classes.items() if set(pair) == {"wolf", "horse"}}
    assert reads_edge and set(classes) - reads_edge, classes  # both kinds of pair are in the run
    edge = copy_of / "annotations" / "precomputed_corr_templates" / EDGE
    rows = edge.read_text().splitlines()
    # another valid map: every row's barycentric weights rotated (the same faces, other points in them)
    edited = []
    for line in rows:
        face, *weights = line.split()
        edited.append(" ".join([face, *weights[1:], weights[0]]) if face != "-1" else line)
    edge.unlink()
    edge.write_text("\n".join(edited) + "\n")
    os.utime(edge, (OLD, OLD))

    dry = snakemake(copy_of, "-n")  # the chunk jobs are known after the check (a checkpoint) only
    assert "check_datasets" in dry.stdout and "params have changed" in dry.stdout, dry.stdout[-3000:]
    result = snakemake(copy_of)
    assert result.returncode == 0, result.stderr[-3000:]
    after = _ground_truth_files(copy_of)
    changed = {p for p in before if after[p] != before[p]}
    assert changed == reads_edge
    assert snakemake(copy_of, "-n").stdout.count("Nothing to be done") == 1


def _records(work: Path) -> dict[str, bytes]:
    folder = work / "results" / "full_full" / "pairs"
    return {p.name: p.read_bytes() for p in sorted(folder.glob("*.npz"))}


def test_deleted_pair_records_are_written_again_by_the_next_store_rebuild(copy_of):
    """POOR: results/<setting>/pairs/ deleted after a finished run is fine while the store is intact
    ("Nothing to be done"); a later store rebuild writes the records again, the same bytes. A single
    record deleted (its chunk index kept) likewise: the workflow drops the index that lists it."""
    from becos.products.store import open_benchmark

    records = _records(copy_of)
    folder = copy_of / "results" / "full_full" / "pairs"
    shutil.rmtree(folder)
    assert "Nothing to be done" in snakemake(copy_of, "-n").stdout
    result = snakemake(copy_of, "--forcerun", "zarr_store")
    assert result.returncode == 0, result.stderr[-3000:]
    assert _records(copy_of) == records

    gone = sorted(folder.glob("*.npz"))[0]
    gone.unlink()
    result = snakemake(copy_of, "--forcerun", "zarr_store")
    assert result.returncode == 0, (result.stdout + result.stderr)[-3000:]
    assert f"lists 1 file(s) that are gone (e.g. results/full_full/pairs/{gone.name})" in result.stderr
    assert _records(copy_of) == records
    bench = open_benchmark(copy_of / "results" / "full_full" / "benchmark.zarr")
    assert sorted(bench.table["pair_id"]) == sorted(name[:-4] for name in records)
    assert "Nothing to be done" in snakemake(copy_of, "-n").stdout
