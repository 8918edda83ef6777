"""Edits the workflow must notice (issue #21, BAD 5 and 6), on the workflow's own stage functions (the
work of the ``ground_truth``, ``pairs`` and ``zarr_store`` jobs) over 4 real TOSCA shapes:

- an edge file of the annotation folder changed, then restored: the ground truth of every pair whose
  network path reads it is recomputed both times (the input key covers the edge files' digests; the
  Snakemake rule declares them as inputs), and the restored run gives the original files back;
- a pair record edited by hand: the pairs job rebuilds it (its content digest no longer matches),
  and the store writer refuses a record that differs from what its chunk index records.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from tiny_tosca import tosca_config

from becos import workflow as bw
from becos.cli import main as becos_main
from becos.errors import InputFileError
from becos.products.store import read_record_index

SHAPES = ["tosca/wolf0", "tosca/wolf1", "tosca/horse0", "tosca/horse5"]  # train classes; path wolf0-dog0-horse0
EDGE = "tosca_dog0_tosca_wolf0_corres.txt"


@pytest.fixture(scope="module")
def built(becos_code, tmp_path_factory):
    """(workdir, config): catalog, manifest, remeshes, ground truth and pair records of full_full, one chunk,
    with an annotation folder whose edge files are copies (so a test may edit them)."""
    work = tmp_path_factory.mktemp("stale-inputs")
    ann = work / "annotations"
    ann.mkdir()
    for p in becos_code.iterdir():
        (ann / p.name).symlink_to(p)
    (ann / "precomputed_corr_templates").unlink()
    shutil.copytree(becos_code / "precomputed_corr_templates", ann / "precomputed_corr_templates")
    config = bw.resolve_config(
        tosca_config(
            becos_code,
            annotations=str(ann),
            shapes=SHAPES,
            setting="full_full",
            n_chunks=1,
            caps={"train": 6, "val": 1, "test": 1},
            results=str(work / "results"),
        )
    )
    layout = bw.Layout.of(config)
    bw.write_catalog_stage(config, layout.catalog)
    bw.write_manifest_stage(
        config, "full_full", layout.catalog, layout.manifest("full_full"), layout.remesh_files("full_full")
    )
    plan = bw.Plan.build(config)
    rows = {(r["dataset"], r["name"]): r for r in plan.catalog.to_dict("records")}
    for (dataset, name), tokens in plan.remesh_jobs.items():
        bw.remesh_stage(config, rows[(dataset, name)], tokens, layout.remeshed_folder(dataset, name))
    bw.ground_truth_stage(config, "full_full", 0, layout.ground_truth_index("full_full", 0), **_inputs(config))
    bw.pairs_stage(
        config,
        "full_full",
        0,
        layout.ground_truth_index("full_full", 0),
        layout.pairs_index("full_full", 0),
        **_inputs(config),
    )
    return work, config


def _inputs(config) -> dict:
    """The paths a chunk job of full_full is given (its rule's manifest, catalog and remesh list file)."""
    layout = bw.Layout.of(config)
    return {
        "manifest": layout.manifest("full_full"),
        "catalog": layout.catalog,
        "remesh_files": layout.remesh_files("full_full"),
    }


def _ground_truth(config) -> tuple[dict, dict]:
    """pair_id -> ground-truth file bytes, and pair_id -> whether the last run computed it (from its log)."""
    layout = bw.Layout.of(config)
    index = json.loads(layout.ground_truth_index("full_full", 0).read_text())
    return {e["pair_id"]: Path(e["path"]).read_bytes() for e in index["pairs"]}, index


def test_an_edited_then_restored_edge_file_recomputes_the_ground_truth_that_reads_it(built, capsys):
    work, config = built
    layout = bw.Layout.of(config)
    plan = bw.Plan.build(config)
    edge = Path(config["annotations"]) / "precomputed_corr_templates" / EDGE
    manifest = plan.manifests["full_full"]
    crossing = set(manifest["pair_id"][manifest["x_name"].str[:3] != manifest["y_name"].str[:3]])
    assert crossing and len(crossing) < len(manifest)
    before, _ = _ground_truth(config)

    original = edge.read_text()
    lines = original.splitlines()
    for i in range(0, len(lines), 7):  # a plausible edit: weights rotated
        f, a, b, c = lines[i].split()
        lines[i] = f"{f} {c} {a} {b}"
    edge.write_text("\n".join(lines) + "\n")
    capsys.readouterr()
    counts = bw.ground_truth_stage(config, "full_full", 0, layout.ground_truth_index("full_full", 0), **_inputs(config))
    edited, _ = _ground_truth(config)
    assert counts["computed"] == len(crossing), (counts, capsys.readouterr().err)
    assert {p for p in before if edited[p] != before[p]} == crossing  # the pairs across wolf and horse changed

    edge.write_text(original)  # restored: recomputed, as before
    counts = bw.ground_truth_stage(config, "full_full", 0, layout.ground_truth_index("full_full", 0), **_inputs(config))
    restored, _ = _ground_truth(config)
    assert counts["computed"] == len(crossing)
    assert restored == before
    assert str(edge) in plan.chunk_edge_files("full_full", 0)  # a declared input of the ground_truth rule


def test_a_hand_edited_pair_record_is_rebuilt_and_refused_by_the_store_writer(built, capsys, tmp_path):
    work, config = built
    layout = bw.Layout.of(config)
    gt_index, pairs_index = layout.ground_truth_index("full_full", 0), layout.pairs_index("full_full", 0)
    bw.pairs_stage(config, "full_full", 0, gt_index, pairs_index, **_inputs(config))  # up to date after the other test
    entry = json.loads(pairs_index.read_text())["pairs"][0]
    path = Path(entry["path"])
    original = path.read_bytes()

    def edit_by_hand():
        with np.load(path) as data:
            arrays = {k: data[k] for k in data.files}
        arrays["corr_01"] = np.roll(arrays["corr_01"], 1)  # meta (and its input key) unchanged
        np.savez(path, **arrays)

    edit_by_hand()
    capsys.readouterr()
    counts = bw.pairs_stage(
        config, "full_full", 0, gt_index, pairs_index, **_inputs(config)
    )  # what --forcerun pairs runs
    err = capsys.readouterr().err
    assert counts["computed"] == 1, err
    assert f"{path}: its content no longer matches the digest becos recorded when writing it" in err
    assert path.read_bytes() == original

    edit_by_hand()  # edited after the job: the store refuses
    with pytest.raises(InputFileError, match=r"is not the file the pairs job wrote: its digest is") as exc:
        read_record_index(pairs_index)
    assert exc.value.path == path and "snakemake --forcerun pairs" in exc.value.fix
    code = becos_main(["export-zarr", str(pairs_index), "--setting", "full_full", "--out", str(tmp_path / "s.zarr")])
    assert code == 2 and "is not the file the pairs job wrote" in capsys.readouterr().err
    path.write_bytes(original)


def test_a_hand_edited_ground_truth_file_is_recomputed_and_never_reaches_a_record(built, capsys):
    """Issue #29, BAD 6: a ``ground_truth/<id>.npz`` edited by hand (a map changed, its input key kept)."""
    work, config = built
    layout = bw.Layout.of(config)
    gt_index, pairs_index = layout.ground_truth_index("full_full", 0), layout.pairs_index("full_full", 0)
    bw.ground_truth_stage(config, "full_full", 0, gt_index, **_inputs(config))  # up to date after the other tests
    bw.pairs_stage(config, "full_full", 0, gt_index, pairs_index, **_inputs(config))
    entry = json.loads(gt_index.read_text())["pairs"][0]
    path = Path(entry["path"])
    original = path.read_bytes()
    record = layout.record("full_full", entry["pair_id"])
    record_bytes = record.read_bytes()

    def edit_by_hand():
        with np.load(path) as data:
            arrays = {k: data[k] for k in data.files}
        arrays["xy_face"] = np.roll(arrays["xy_face"], 1)  # input key (and stored digest) unchanged
        np.savez_compressed(path, **arrays)

    edit_by_hand()
    assert not bw.ground_truth_intact(path)
    capsys.readouterr()
    counts = bw.ground_truth_stage(config, "full_full", 0, gt_index, **_inputs(config))  # --forcerun ground_truth
    err = capsys.readouterr().err
    assert counts["computed"] == 1, err
    assert f"{path}: its content no longer matches the digest becos recorded when writing it" in err
    assert path.read_bytes() == original

    edit_by_hand()  # edited after the job, then a record that reads it is rebuilt: refused
    record.unlink()
    with pytest.raises(InputFileError, match="is not the file the ground-truth job wrote") as exc:
        bw.pairs_stage(config, "full_full", 0, gt_index, pairs_index, **_inputs(config))
    assert exc.value.path == path and "snakemake --forcerun ground_truth" in exc.value.fix
    path.write_bytes(original)
    bw.pairs_stage(config, "full_full", 0, gt_index, pairs_index, **_inputs(config))
    assert record.read_bytes() == record_bytes


def test_an_edge_file_with_moved_rows_after_the_check_is_refused_by_the_ground_truth_job(built, becos_code):
    """Issue #29, BAD 5 after a finished run: three rows of tosca_dog0_tosca_wolf0_corres.txt moved to the
    wolf0 face farthest from their mapped point. The ground-truth job checks each edge file it reads row by
    row (``becos.sources.check.edges.edge_plausibility``) and refuses it, naming the lines; restored, it runs again."""
    from becos.core.mesh import read_mesh

    work, config = built
    edge = Path(config["annotations"]) / "precomputed_corr_templates" / EDGE
    original = edge.read_text()
    wolf = read_mesh(becos_code / "data" / "tosca-off" / "wolf0.off")
    centroids = wolf.vertices[wolf.faces].mean(axis=1)
    lines = original.splitlines()
    for r in (10, 5000, 20000):
        face, *w = lines[r].split()
        here = np.asarray(w, dtype=float) @ wolf.vertices[wolf.faces[int(face)]]
        lines[r] = f"{int(np.argmax(np.linalg.norm(centroids - here, axis=1)))} 0.333333 0.333333 0.333334"
    edge.write_text("\n".join(lines) + "\n")
    layout = bw.Layout.of(config)
    try:
        with pytest.raises(InputFileError) as exc:
            bw.ground_truth_stage(config, "full_full", 0, layout.ground_truth_index("full_full", 0), **_inputs(config))
        assert exc.value.path == edge
        assert f"{edge}: 3 of its {len(lines)} rows map a vertex of template tosca_dog0 far from where its " in str(
            exc.value
        )
        assert "file lines 11, 5001, 20001 (1-based line numbers in the file" in str(exc.value)
        assert "restore the annotation folder's original file" in exc.value.fix
    finally:
        edge.write_text(original)
    bw.ground_truth_stage(config, "full_full", 0, layout.ground_truth_index("full_full", 0), **_inputs(config))


def _rewrite_npz(path: Path, change) -> bytes:
    """Rewrite the .npz at ``path`` with ``change(arrays)`` applied (its other members kept); returns its old bytes."""
    original = path.read_bytes()
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    change(arrays)
    np.savez(path, **arrays)
    return original


def test_records_leave_out_what_their_sources_give_and_a_changed_source_stops_the_store(built, capsys, tmp_path):
    """Issue #31, disk: a workflow pair record leaves out the members its remesh and ground-truth files
    give back byte for byte (``becos.build.record_sources``); its store is the store of whole records, byte
    for byte; a source changed after the pairs job stops export-zarr, naming the record and the file."""
    from becos.build.record import PairRecord
    from becos.products.store import write_store

    work, config = built
    layout = bw.Layout.of(config)
    gt_index, pairs_index = layout.ground_truth_index("full_full", 0), layout.pairs_index("full_full", 0)
    bw.ground_truth_stage(config, "full_full", 0, gt_index, **_inputs(config))  # up to date after the other tests
    bw.pairs_stage(config, "full_full", 0, gt_index, pairs_index, **_inputs(config))
    entries = json.loads(pairs_index.read_text())["pairs"]
    paths = [Path(e["path"]) for e in entries]
    sides = {f"{s}_{k}" for s in "xy" for k in ("faces", "vertices")}
    maps = {f"{m}_{k}" for m in ("corr_01", "corr_10") for k in ("face", "weights")}
    for path in paths:
        with np.load(path) as data:
            members, derived = set(data.files), json.loads(str(data["__derived__"]))
        assert set(derived["arrays"]) == sides | maps, path  # full_full: every copy of the sources
        assert not {f"{k}.npy" for k in derived["arrays"]} & members
        assert set(derived["sources"]) == {"x", "y", "ground_truth"}

    whole = tmp_path / "whole"
    whole.mkdir()
    for path in paths:
        PairRecord.load(path).save(whole / path.name)  # no sources: every member in the file
    slim_bytes, whole_bytes = (sum(p.stat().st_size for p in ps) for ps in (paths, list(whole.glob("*.npz"))))
    assert slim_bytes < 0.1 * whole_bytes, (slim_bytes, whole_bytes)
    stores = [
        write_store(ps, tmp_path / f"{name}.zarr", setting="full_full", progress=False)
        for name, ps in (("slim", paths), ("whole", sorted(whole.glob("*.npz"))))
    ]
    trees = [
        {
            p.relative_to(s): p.read_bytes()
            for p in s.rglob("*")
            if p.is_file() and p.relative_to(s) != Path("zarr.json")
        }
        for s in stores
    ]
    assert trees[0] == trees[1]  # the root zarr.json differs by its creation time only

    with np.load(paths[0]) as data:
        sources = json.loads(str(data["__derived__"]))["sources"]
    remesh = Path(os.path.normpath(paths[0].parent / sources["x"]["path"]))
    gt = Path(os.path.normpath(paths[0].parent / sources["ground_truth"]["path"]))
    out = ["--setting", "full_full", "--out", str(tmp_path / "s.zarr")]
    for source, what, change in (
        (remesh, "remesh file of shape x", lambda a: a.update(vertices=a["vertices"] + 1e-9)),
        (gt, "ground-truth file", lambda a: a.update(xy_weights=a["xy_weights"][::-1].copy())),
    ):
        original = _rewrite_npz(source, change)
        try:
            capsys.readouterr()
            assert becos_main(["export-zarr", str(pairs_index), *out]) == 2
            err = capsys.readouterr().err
            assert f"its {what} {source} has changed since the record was written" in err, err
            assert "Fix: rebuild the pair records: snakemake --forcerun pairs" in err and "Traceback" not in err
            assert any(f"{p}: its {what}" in err for p in paths), err
            with pytest.raises(InputFileError, match="has changed since the record was written"):
                [PairRecord.load(p) for p in paths]
        finally:
            source.write_bytes(original)
    assert becos_main(["export-zarr", str(pairs_index), *out]) == 0  # restored: the records read again
