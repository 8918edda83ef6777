"""Store validation: real stores validate clean; each specific corruption is reported by its check."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import zarr

from becos.cli import main
from becos.record import PairRecord
from becos.store import open_benchmark, table_row, write_pairs, write_store
from becos.validate import validate, validate_store


@pytest.fixture(scope="module")
def clean_stores(pair_record_files, tmp_path_factory):
    """{setting: store} of the fixture records, relabelled into one split.

    The fixture puts cat0 -> cat3 in train *and* test, which breaks class hold-out (the check
    ``split_classes`` must catch exactly that, see below); TOSCA holds cats out for test.
    """
    folder = tmp_path_factory.mktemp("clean")
    out = {}
    for setting, paths in pair_record_files.items():
        relabelled = []
        for p in paths:
            record = PairRecord.load(p)
            record.meta["split"] = "test"
            relabelled.append(folder / setting / p.name)
            record.save(relabelled[-1])
        out[setting] = write_store(relabelled, folder / f"{setting}.zarr", setting=setting, progress=False)
    return out


@pytest.fixture()
def p2p_copy(clean_stores, tmp_path):
    """A writable copy of the clean partial_partial store."""
    path = tmp_path / "corrupt.zarr"
    shutil.copytree(clean_stores["partial_partial"], path)
    return path


def _array(store, key):
    return zarr.open_array(str(store / "arrays" / key), mode="r+")


def _problems_of(store, check):
    problems = validate_store(store)
    assert problems, "the corruption went unnoticed"
    return [p for p in problems if p.startswith(check + ":")], problems


def test_clean_stores_validate(clean_stores):
    for setting, path in clean_stores.items():
        report = validate(path)
        assert report.problems == [], (setting, report.problems)
        assert report.n_pairs == 2 and report.splits == {"test": 2} and report.setting == setting


def test_class_in_train_and_test(pair_record_files, tmp_path):
    """The fixture's own split labels (cat in train and test) break class hold-out."""
    path = write_store(pair_record_files["full_full"], tmp_path / "ff.zarr", setting="full_full", progress=False)
    problems = validate_store(path)
    assert len(problems) == 1, problems
    assert problems[0].startswith("split_classes: class tosca/cat in splits train+test")


def test_index_out_of_range(p2p_copy):
    bench = open_benchmark(p2p_copy)
    row = int(bench.offsets["x_vertex"][1]) + 5                 # pair 1, vertex 5
    _array(p2p_copy, "corr_01")[row] = bench.table["y_n_vertices"][1] + 7
    hits, _ = _problems_of(p2p_copy, "index_range")
    assert len(hits) == 1 and "corr_01 outside [-1, V_y)" in hits[0] and bench.table["pair_id"][1] in hits[0]


def test_minus_one_where_mask_says_matched(p2p_copy):
    bench = open_benchmark(p2p_copy)
    mask, offsets = bench.concatenated("y_overlap_mask")
    row = int(np.flatnonzero(mask[offsets[0]:offsets[1]])[3])       # a matched Y vertex of pair 0
    _array(p2p_copy, "corr_10")[row] = -1
    hits, _ = _problems_of(p2p_copy, "unmatched")
    assert hits and "corr_10 >= 0 differs from y_overlap_mask" in hits[0]
    assert bench.table["pair_id"][0] in hits[0]


def test_weights_not_summing_to_one(p2p_copy):
    bench = open_benchmark(p2p_copy)
    mask, offsets = bench.concatenated("x_overlap_mask")
    row = int(np.flatnonzero(mask)[10])
    weights = _array(p2p_copy, "corr_01_weights")
    weights[row] = np.array([0.5, 0.4, 0.0])
    hits, _ = _problems_of(p2p_copy, "weights")
    assert "corr_01_weights" in hits[0]


def test_non_orthonormal_rotation(p2p_copy):
    rotation = _array(p2p_copy, "y_random_rotation")
    rotation[1] = rotation[1] * 1.01
    hits, problems = _problems_of(p2p_copy, "rotation")
    assert hits == [f"rotation: y_random_rotation not orthonormal with det +1 in 1 pair(s), "
                    f"e.g. {open_benchmark(p2p_copy).table['pair_id'][1]}"], problems


def test_reflection_is_not_a_rotation(p2p_copy):
    rotation = _array(p2p_copy, "x_frame_rotation")
    rotation[0] = rotation[0] @ np.diag([1.0, 1.0, -1.0])      # orthonormal, det -1
    hits, _ = _problems_of(p2p_copy, "rotation")
    assert "x_frame_rotation" in hits[0]


def test_duplicated_pair_id(p2p_copy):
    bench = open_benchmark(p2p_copy)
    metas = bench.read_metas()
    metas[1]["pair_id"] = metas[0]["pair_id"]
    rows = [table_row(i, m, *bench.table.loc[i, ["x_n_vertices", "y_n_vertices", "x_overlap", "y_overlap"]])
            for i, m in enumerate(metas)]
    write_pairs(zarr.open_group(str(p2p_copy), mode="r+"), metas, rows)
    hits, problems = _problems_of(p2p_copy, "pair_id")
    assert hits == [f"pair_id: duplicate pair id in 1 pair(s), e.g. {metas[0]['pair_id']} (2 rows share 1 id(s))"]
    assert problems == hits                                      # nothing else is wrong


def test_partial_split_into_two_components(p2p_copy):
    bench = open_benchmark(p2p_copy)
    faces, offsets = bench.concatenated("x_faces")
    f0, f1 = int(offsets[0]), int(offsets[1])
    local = faces[f0:f1]
    # re-point one face at three vertices of faces far apart: it shares no edge with any other face
    far = local[[0, len(local) // 2, len(local) - 1], [0, 1, 2]]
    _array(p2p_copy, "x_faces")[f0 + len(local) // 3] = far
    hits, problems = _problems_of(p2p_copy, "connectivity")
    assert any("partial x shape is not one edge-connected component" in h for h in hits), problems
    assert any(p.startswith("face_map:") for p in problems)   # the face no longer matches its full face


def test_full_shape_must_keep_every_face(clean_stores, tmp_path):
    path = tmp_path / "ff.zarr"
    shutil.copytree(clean_stores["full_full"], path)
    ids = _array(path, "y_full_face_ids")
    ids[3] = 4
    hits, _ = _problems_of(path, "full_shape")
    assert "full y shape does not keep every face" in hits[0]


def test_partial_to_full_inverse(p2p_copy):
    bench = open_benchmark(p2p_copy)
    offsets = bench.offsets["y_vertex"]
    ptf = _array(p2p_copy, "y_partial_to_full")
    start = int(offsets[0])
    ptf[start + 1] = ptf[start + 0]                               # no longer strictly increasing
    hits, _ = _problems_of(p2p_copy, "index_maps")
    text = "\n".join(hits)
    assert "y_partial_to_full not strictly increasing" in text and "is not the identity" in text


def test_overlap_out_of_accepted_range(p2p_copy):
    overlap = _array(p2p_copy, "x_overlap")
    overlap[0] = 0.95
    hits, _ = _problems_of(p2p_copy, "overlap")
    text = "\n".join(hits)
    assert "x_overlap differs from the mean of x_overlap_mask" in text
    assert "outside [min_overlap, max_overlap]" in text


def test_cli_exit_status_and_json(clean_stores, p2p_copy, tmp_path, capsys):
    out = tmp_path / "validation.json"
    assert main(["validate", str(clean_stores["full_full"]), "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["valid"] is True and report["problems"] == [] and report["n_pairs"] == 2
    _array(p2p_copy, "x_random_rotation")[0] = np.zeros((3, 3))
    capsys.readouterr()
    assert main(["validate", str(p2p_copy), "--json", str(out)]) == 1
    err = capsys.readouterr().err
    assert "becos validate: rotation: x_random_rotation" in err
    assert json.loads(out.read_text())["problems"][0].startswith("rotation:")
    assert main(["validate", str(tmp_path)]) == 1                 # not a store at all
    assert "is not a Zarr v3 store" in capsys.readouterr().err
