"""ULRSSM's ``dist/<k>.mat`` (``export-ulrssm --geodesics``, issue #34 item 3) on real TOSCA meshes:
each distinct matrix written once and hard-linked to every pair side showing it, the values of the
previous per-side computation, read back as ULRSSM reads them (``scipy.io.loadmat(...)['dist']``),
the same bytes from the workflow's ``geodesic-rows`` blocks, and the disk estimate that stops an
export before it writes anything."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from becos.cli import main
from becos.errors import DiskFullError
from becos.products.export import DiskEstimateError, mat_size, write_symmetric_mat, write_ulrssm
from becos.products.export.geodesics import _compute_geodesic_rows, geodesic_plan, shape_matrix

SETTINGS = ("full_full", "partial_full")


@pytest.fixture(scope="module")
def cat_records(small_cat_records) -> dict:
    """Per setting: two test pairs cat0 -> cat3 (seeds 1, 2: the same two full meshes, different scans)
    and one train pair; cat0 and cat3 remeshed to ~1,500 vertices (conftest)."""
    return small_cat_records


def previous_dist(records, splits, tmp_path: Path) -> dict[tuple[str, int, int], np.ndarray]:
    """``{(split, index, side): matrix}`` as ``write_ulrssm`` computed it per pair side before (commit
    d6b27ce): all rows of every mesh in a memory map, each side's (V, V) float32 matrix symmetrised by
    ``shape_matrix`` and divided by the sqrt-area."""
    shapes, meshes, needed, numbers = geodesic_plan(records, splits)
    folder = tmp_path / "previous-rows"
    folder.mkdir()
    rows = _compute_geodesic_rows(meshes, needed, "heat", 1, folder, False)
    return {
        (sh.split, numbers[(sh.split, sh.pair_id)], sh.side): (
            shape_matrix(sh, needed[sh.key], rows[sh.key]) / np.float32(sh.sqrt_area)
        ).astype(np.float32, copy=False)
        for sh in shapes
    }


def ulrssm_dist(path: Path) -> np.ndarray:
    """ULRSSM ``SingleShapeDataset.__getitem__``: ``torch.from_numpy(sio.loadmat(path)['dist']).float()``
    (numpy in place of torch: ``.float()`` keeps a float32 array as it is)."""
    mat = scipy.io.loadmat(str(path))
    assert mat["dist"].dtype == np.float32  # so .float() is a no-op: the loader reads it unchanged
    return mat["dist"]


def _sides(out: Path) -> dict[tuple[str, int, int], Path]:
    return {
        (p.parts[-4], int(p.parts[-3]), int(p.stem)): p
        for p in out.glob("*/*/dist/*.mat")
        if p.parent.parent.parent.parent == out
    }


@pytest.mark.parametrize("setting", SETTINGS)
def test_ulrssm_dist_written_once_linked_and_equal_to_the_per_side_computation(setting, cat_records, tmp_path, capsys):
    recs = cat_records[setting]
    out = write_ulrssm(recs, tmp_path / "ulrssm", geodesics=True, splits=["test"], progress=True)
    log = capsys.readouterr().err
    assert "distinct dist matrices" in log and "peak memory" in log and "free on the output's disk" in log

    expected = previous_dist(recs, ["test"], tmp_path)
    files = _sides(out)
    assert set(files) == set(expected)  # both sides of the test pairs, nothing for the train pair
    assert not (out / "train" / "0" / "dist").exists()
    for side, path in files.items():
        d = ulrssm_dist(path)
        n_vertices = int((path.parent.parent / "off" / f"{side[2]}.off").read_text().split("\n")[1].split()[0])
        assert d.shape == (n_vertices, n_vertices)
        assert np.array_equal(d, expected[side])  # the same float32 values as before, bit for bit

    # pair sides showing the same matrix (the same full mesh, the same vertices kept) share one inode
    shapes, _, _, numbers = geodesic_plan(recs, ["test"])
    same = {(sh.split, numbers[(sh.split, sh.pair_id)], sh.side): (sh.key, sh.p2f.tobytes()) for sh in shapes}
    inode = {side: path.stat().st_ino for side, path in files.items()}
    for a in files:
        for b in files:
            assert (inode[a] == inode[b]) == (same[a] == same[b]), (a, b)
    n_distinct = len(set(same.values()))
    if setting == "full_full":
        assert n_distinct == 2 and len(files) == 4  # cat0 and cat3 once each, for both test pairs
    else:
        assert n_distinct == 3  # full cat0 once; each pair's scan of cat3 its own
    summary = json.loads((out / "logs" / "geodesics.json").read_text())
    assert summary["written"] == n_distinct and summary["hard_links"] == len(files) - n_distinct
    assert summary["copies"] == 0
    on_disk = {p.stat().st_ino: p.stat().st_size for p in files.values()}  # du: each inode once
    assert summary["bytes"] == sum(on_disk.values()) == summary["estimate"]["disk_bytes"]
    one_side_each = {matrix: side for side, matrix in same.items()}.values()
    assert summary["estimate"]["disk_bytes"] == sum(mat_size(len(expected[side])) for side in one_side_each)


def test_ulrssm_dist_same_bytes_in_parallel_and_from_the_workflow_rows(
    cat_records, store_of, tmp_path, monkeypatch, capsys
):
    """jobs=2 with several tasks per mesh (blocks filled across tasks in a bounded window), and the
    blocks of ``becos geodesic-plan`` / ``geodesic-rows`` read through ``export-ulrssm --rows``: the same
    files as one process computing them."""
    import becos.products.export.geodesics

    recs = cat_records["partial_full"]
    one = write_ulrssm(recs, tmp_path / "one", geodesics=True, splits=["test"])
    monkeypatch.setattr(becos.products.export.geodesics, "_GEODESIC_TASK_ROWS", 300)  # ~5 tasks per mesh
    two = write_ulrssm(recs, tmp_path / "two", geodesics=True, splits=["test"], jobs=2)

    store = store_of(recs, "partial_full")
    plan = tmp_path / "plan"
    assert main(["geodesic-plan", str(store), "--out", str(plan), "--parts", "2", "--splits", "test"]) == 0
    rows = [tmp_path / f"rows_{k}" for k in range(2)]
    for k in range(2):
        assert main(["geodesic-rows", str(plan / f"part_{k}.npz"), str(rows[k])]) == 0
    capsys.readouterr()
    cli = tmp_path / "cli"
    args = ["export-ulrssm", str(store), str(cli), "--geodesics", "--splits", "test", "--rows", *map(str, rows)]
    assert main(args) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["written"] == 3 and printed["hard_links"] == 1 and printed["copies"] == 0

    reference = _sides(one)
    assert len(reference) == 4
    for other in (two, cli):
        files = _sides(other)
        assert set(files) == set(reference)
        for side, path in reference.items():
            assert path.read_bytes() == files[side].read_bytes(), (other.name, side)
    assert main(["export-ulrssm", str(store), str(tmp_path / "x"), "--rows", str(rows[0])]) == 2  # without --geodesics
    assert "--geodesics" in capsys.readouterr().err


def test_ulrssm_geodesics_refused_before_writing_when_the_estimate_exceeds_free_space(cat_records, tmp_path):
    recs = cat_records["full_full"]
    out = tmp_path / "exports" / "ulrssm"
    with pytest.raises(DiskEstimateError) as info:
        write_ulrssm(recs, out, geodesics=True, splits=["test"], free_bytes=10_000_000)
    assert isinstance(info.value, DiskFullError)  # a disk-full error to every caller that handles one
    message = str(info.value)
    assert message.startswith(f"{out}: ")
    assert "need about 0.02 GB" in message and "0.01 GB free" in message and "nothing was written" in message
    assert "Fix: free disk space, choose another --out" in message and "--splits test" in message
    assert not out.exists() and not list(out.parent.iterdir())  # no staging folder left either
    # with enough room the same call writes it (the estimate is 2 matrices of ~1.4-1.5k vertices)
    write_ulrssm(recs, out, geodesics=True, splits=["test"], free_bytes=100_000_000)
    assert len(_sides(out)) == 4


@pytest.mark.parametrize("n", [1, 2, 5, 6, 33])
def test_streamed_mat_file_is_what_scipy_writes(n, tmp_path):
    """The streamed MAT v5 file holds the bytes ``scipy.io.savemat`` writes after its dated header text
    (n > 1; a 1 x 1 matrix scipy packs into a small element), written in row blocks of any size."""
    rng = np.random.default_rng(n)
    a = rng.random((n, n)).astype(np.float32)
    a = a + a.T
    mine, theirs = tmp_path / "mine.mat", tmp_path / "theirs.mat"
    size = write_symmetric_mat(mine, n, (a[i : i + 2] for i in range(0, n, 2)))
    scipy.io.savemat(theirs, {"dist": a})
    assert size == mat_size(n) == mine.stat().st_size
    got = scipy.io.loadmat(mine)["dist"]
    assert got.dtype == np.float32 and np.array_equal(got, a)
    if n > 1:
        assert mine.read_bytes()[116:] == theirs.read_bytes()[116:]
    with pytest.raises(ValueError, match="rows written"):
        write_symmetric_mat(tmp_path / "short.mat", n, [a[: n - 1]])
    assert not (tmp_path / "short.mat").exists()
