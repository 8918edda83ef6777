"""Store comparison (``becos validate STORE --against OTHER``) on real stores: identical copies and
rebuilds are identical; a perturbed, removed, re-split or swapped pair and changed library versions
or config are reported with the right reasons."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import zarr

from becos.build.record import PairRecord
from becos.cli import main
from becos.products.compare import REASONS, compare_stores, key_reason
from becos.products.store import open_benchmark, write_store


@pytest.fixture(scope="module")
def records(pair_record_files, tmp_path_factory):
    """{setting: [record path, record path]} relabelled into one split (so the stores validate clean)."""
    folder = tmp_path_factory.mktemp("records")
    out = {}
    for setting, paths in pair_record_files.items():
        out[setting] = []
        for p in paths:
            record = PairRecord.load(p)
            record.meta["split"] = "test"
            out[setting].append(folder / setting / p.name)
            record.save(out[setting][-1])
    return out


@pytest.fixture(scope="module")
def stores(records, tmp_path_factory):
    folder = tmp_path_factory.mktemp("stores")
    return {s: write_store(paths, folder / f"{s}.zarr", setting=s, progress=False) for s, paths in records.items()}


def _copy(stores, setting, tmp_path, name="b.zarr"):
    path = tmp_path / name
    shutil.copytree(stores[setting], path)
    return path


def _array(store, key):
    return zarr.open_array(str(store / "arrays" / key), mode="r+")


def _rows(store, key, pair):
    bench = open_benchmark(store)
    o = bench.offsets[bench.layout[key]]
    return int(o[pair]), int(o[pair + 1])


def _perturb(store, key, pair, vertex, delta):
    row = _rows(store, key, pair)[0] + vertex
    arr = _array(store, key)
    arr[row] = arr[row] + delta


def _set_attrs(store, **attrs):
    zarr.open_group(str(store), mode="r+").attrs.update(attrs)


def test_identical_copy_and_rebuild(stores, records, tmp_path):
    copy = _copy(stores, "partial_partial", tmp_path)
    rebuilt = write_store(
        records["partial_partial"], tmp_path / "rebuilt.zarr", setting="partial_partial", progress=False
    )
    assert open_benchmark(rebuilt).metadata["created"]  # differs between builds: not compared
    for other in (copy, rebuilt):
        c = compare_stores(stores["partial_partial"], other)
        assert c.identical and c.data_identical, c.summary()
        assert not c.only_a and not c.only_b and c.differing_ids == [] and c.reason_counts() == {}
        assert c.summary().endswith("result: identical")
        assert c.to_json()["pairs"] == {} and c.to_json()["n_common"] == 2


def test_perturbed_x_vertices_is_remeshing_of_x(stores, tmp_path):
    a = stores["full_full"]
    b = _copy(stores, "full_full", tmp_path)
    _perturb(b, "x_vertices", 1, 10, np.array([1e-3, 0.0, -2e-3]))
    ids = list(open_benchmark(a).table["pair_id"])
    c = compare_stores(a, b)
    assert not c.identical and not c.data_identical
    assert c.differing_ids == [ids[1]]
    assert c.pair_reasons(ids[1]) == ["remeshing of X differs"] and c.pair_reasons(ids[0]) == []
    keys = c.pair_keys(ids[1])
    assert list(keys) == ["x_vertices"] and keys["x_vertices"]["values"] == 2
    assert keys["x_vertices"]["max_abs"] == pytest.approx(2e-3, rel=1e-6)
    assert (
        f"remeshing of X differs: 1 pair(s), e.g. {ids[1]} (x_vertices: 1 pair(s), 2 value(s), max |diff| 0.002)"
        in c.summary()
    )
    assert compare_stores(a, b, atol=1e-2).identical  # within tolerance
    assert not compare_stores(a, b, atol=1e-3).identical


def test_partial_shapes_reasons(stores, tmp_path):
    """P2P: the full remeshed X -> remeshing; Y's camera and mask -> partial view; corr -> ground truth."""
    a = stores["partial_partial"]
    b = _copy(stores, "partial_partial", tmp_path)
    ids = list(open_benchmark(a).table["pair_id"])
    _perturb(b, "x_full_vertices", 0, 5, 1e-6)
    camera = _array(b, "y_camera")  # stacked (N, 3, 3)
    camera[1] = camera[1] + np.array([[0.0, 0.0, 0.1], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    row = _rows(b, "corr_01", 1)[0] + 3
    corr = _array(b, "corr_01")
    corr[row] = corr[row] + 1
    _perturb(b, "x_vertices", 1, 0, 1e-9)  # a partial X: its partial view differs
    c = compare_stores(a, b)
    assert c.pair_reasons(ids[0]) == ["remeshing of X differs"]
    assert c.pair_reasons(ids[1]) == ["partial view of X differs", "partial view of Y differs", "ground truth differs"]
    assert c.pair_keys(ids[1])["corr_01"] == {"values": 1, "max_abs": None}  # ints: count only
    assert c.pair_keys(ids[1])["y_camera"]["max_abs"] == pytest.approx(0.1)
    assert c.reason_counts() == {
        "remeshing of X differs": 1,
        "partial view of X differs": 1,
        "partial view of Y differs": 1,
        "ground truth differs": 1,
    }
    whole = compare_stores(a, b)
    pairwise = compare_stores(a, b, max_bytes=1)  # one pair per read: same answer
    for key in whole.values:
        assert np.array_equal(whole.values[key], pairwise.values[key]), key
        if key in whole.max_abs:
            assert np.array_equal(whole.max_abs[key], pairwise.max_abs[key], equal_nan=True), key
    assert np.array_equal(whole.reasons, pairwise.reasons)


def test_new_random_rotation_is_not_a_remeshing(stores, tmp_path):
    """Pair 1's X turned by another random rotation (its vertices rotated consistently): the geometry
    is the same in the common frame, so only the rotation is reported; a real change on top is not."""
    a = stores["full_full"]
    b = _copy(stores, "full_full", tmp_path)
    pid = open_benchmark(a).table["pair_id"][1]
    rotation = _array(b, "x_random_rotation")
    old = rotation[1]
    turn = np.array([[0.6, 0.0, -0.8], [0.0, 1.0, 0.0], [0.8, 0.0, 0.6]])
    rotation[1] = old @ turn
    start, stop = _rows(b, "x_vertices", 1)
    vertices = _array(b, "x_vertices")
    vertices[start:stop] = vertices[start:stop] @ turn  # (v @ R.T) @ (R @ turn) = v @ turn
    c = compare_stores(a, b)
    assert c.pair_reasons(pid) == ["rotations of X differ"], c.summary()
    assert c.pair_keys(pid)["x_vertices"]["same_in_common_frame"] is True
    assert "x_vertices: 1 pair(s)" in c.summary() and "same in the common frame" in c.summary()
    _perturb(b, "x_vertices", 1, 7, 1e-4)
    c = compare_stores(a, b)
    assert c.pair_reasons(pid) == ["remeshing of X differs", "rotations of X differ"]


def test_removed_pair_and_changed_versions(stores, records, tmp_path):
    a = stores["full_full"]
    ids = list(open_benchmark(a).table["pair_id"])
    b = write_store(records["full_full"][:1], tmp_path / "one.zarr", setting="full_full", progress=False)
    versions = dict(open_benchmark(b).metadata["versions"], pymeshlab="2022.2.post3")
    del versions["embreex"]
    _set_attrs(b, versions=versions)
    c = compare_stores(a, b)
    assert c.only_a == [ids[1]] and c.only_b == [] and c.differing_ids == [] and not c.identical
    assert c.version_differences == {
        "embreex": [open_benchmark(a).metadata["versions"]["embreex"], None],
        "pymeshlab": [open_benchmark(a).metadata["versions"]["pymeshlab"], "2022.2.post3"],
    }
    assert c.attributes["n_pairs"] == [2, 1] and c.attributes["splits.test"] == [2, 1]
    text = c.summary()
    assert f"only in {a}: 1 pair(s), e.g. {ids[1]}" in text
    assert "versions differ: embreex " in text and " -> (absent); pymeshlab " in text and "-> 2022.2.post3" in text
    assert "result: the stores differ: 0 pair(s) differ, 1 in one store only" in text
    reverse = compare_stores(b, a)
    assert reverse.only_b == [ids[1]] and reverse.only_a == []


def test_versions_only_and_config_change(stores, tmp_path):
    a = stores["full_full"]
    b = _copy(stores, "full_full", tmp_path)
    _set_attrs(b, versions={**open_benchmark(a).metadata["versions"], "numpy": "1.26.4"})
    c = compare_stores(a, b)
    assert c.data_identical and c.identical  # same data, built with another numpy
    assert c.version_differences == {"numpy": [open_benchmark(a).metadata["versions"]["numpy"], "1.26.4"]}
    assert "result: identical data (built with other library versions)" in c.summary()
    _set_attrs(b, config_hash="abc123", config={"remesh": {"target_vertices": 5000}, "seed": 1})
    c = compare_stores(a, b)
    assert c.data_identical and not c.identical
    assert c.attributes["config_hash"] == [None, "abc123"]
    assert c.attributes["config.remesh.target_vertices"] == [None, 5000]
    assert "metadata config_hash: (absent) -> abc123" in c.summary()


def test_resplit_pair_is_matched_by_id(stores, records, tmp_path):
    """Pair 1 moved to train: B's store order differs (train first); arrays still match by pair id."""
    moved = []
    for i, path in enumerate(records["partial_full"]):
        record = PairRecord.load(path)
        if i == 1:
            record.meta["split"] = "train"
        moved.append(tmp_path / "records" / path.name)
        record.save(moved[-1])
    b = write_store(moved, tmp_path / "moved.zarr", setting="partial_full", progress=False)
    ids_a = list(open_benchmark(stores["partial_full"]).table["pair_id"])
    assert list(open_benchmark(b).table["pair_id"]) == ids_a[::-1]
    for max_bytes in (1, 1 << 30):
        c = compare_stores(stores["partial_full"], b, max_bytes=max_bytes)
        assert c.differing_ids == [ids_a[1]] and c.pair_reasons(ids_a[1]) == ["meta differs"]
        assert c.meta == {ids_a[1]: {"split": ["test", "train"]}}
        assert all(not v.any() for v in c.values.values())
    assert "meta differs: 1 pair(s), e.g. " + ids_a[1] + " (keys split)" in c.summary()


def test_another_pair_under_the_same_id(stores, records, tmp_path):
    """Pair 0's id given to pair 1's content: other vertex counts (row counts differ), rotations ..."""
    paths = []
    for i, path in enumerate(records["partial_partial"]):
        record = PairRecord.load(records["partial_partial"][1] if i == 0 else path)
        record.meta["pair_id"] = PairRecord.load(path).meta["pair_id"]
        paths.append(tmp_path / "swap" / path.name)
        record.save(paths[-1])
    b = write_store(paths, tmp_path / "swap.zarr", setting="partial_partial", progress=False)
    c = compare_stores(stores["partial_partial"], b)
    pid = PairRecord.load(records["partial_partial"][0]).pair_id
    assert c.differing_ids == [pid]
    assert c.pair_keys(pid)["x_vertices"] == {"values": -1, "max_abs": None}  # 3585 vs 3730 rows
    reasons = c.pair_reasons(pid)
    assert {
        "partial view of X differs",
        "partial view of Y differs",
        "ground truth differs",
        "rotations of X differ",
        "meta differs",
    } <= set(reasons)
    # the same remeshed cat0 / cat3 under other random rotations: not a remeshing change
    assert "remeshing of X differs" not in reasons and "remeshing of Y differs" not in reasons
    assert c.pair_keys(pid)["x_full_vertices"]["same_in_common_frame"] is True
    assert "x_vertices: 1 pair(s), row count differs" in c.summary()


def test_key_reasons():
    assert key_reason("x_full_vertices") == "remeshing of X differs"
    assert key_reason("y_overlap_mask") == "partial view of Y differs"
    assert key_reason("corr_10_weights") == "ground truth differs"
    assert key_reason("y_random_rotation") == "rotations of Y differ"
    assert key_reason("x_annotation") == "annotations differ"
    assert key_reason("y_full_sqrt_area") == "scalars differ"
    assert key_reason("extra_key") == "other arrays differ"
    assert len(set(REASONS)) == len(REASONS)


def test_cli_against(stores, tmp_path, capsys):
    a = stores["full_full"]
    b = _copy(stores, "full_full", tmp_path)
    out = tmp_path / "report.json"
    capsys.readouterr()
    assert main(["validate", str(a), "--against", str(b), "--json", str(out)]) == 0
    stdout = capsys.readouterr().out
    assert "result: identical" in stdout and json.loads(out.read_text())["comparison"]["identical"] is True

    _perturb(b, "x_vertices", 1, 10, 1e-3)
    _set_attrs(b, versions={**open_benchmark(a).metadata["versions"], "trimesh": "4.0.0"})
    pid = open_benchmark(a).table["pair_id"][1]
    assert main(["validate", str(a), "--against", str(b), "--json", str(out)]) == 1
    stdout = capsys.readouterr().out
    print(stdout)
    assert json.loads(stdout.splitlines()[0])["valid"] is True  # STORE validated first
    assert f"remeshing of X differs: 1 pair(s), e.g. {pid}" in stdout
    assert "versions differ: trimesh " in stdout and "-> 4.0.0" in stdout
    report = json.loads(out.read_text())
    assert report["valid"] is True and report["comparison"]["pairs"][pid]["reasons"] == ["remeshing of X differs"]
    assert report["comparison"]["pairs"][pid]["arrays"]["x_vertices"]["values"] == 3
    assert report["comparison"]["versions"]["trimesh"][1] == "4.0.0"

    assert main(["validate", str(a), "--against", str(tmp_path / "nothere.zarr")]) == 2
    err = capsys.readouterr().err
    assert "becos validate: --against: " in err and "nothere.zarr: not found" in err and "Traceback" not in err
    shutil.rmtree(b / "arrays" / "x_faces")
    assert main(["validate", str(a), "--against", str(b)]) == 2
    err = capsys.readouterr().err
    assert "1 of its arrays missing: arrays/x_faces" in err and "Traceback" not in err
    c = _copy(stores, "full_full", tmp_path, "c.zarr")
    chunk = next((c / "arrays" / "x_vertices").glob("c.*"))
    chunk.write_bytes(chunk.read_bytes()[:50])  # a truncated chunk in OTHER
    assert main(["validate", str(a), "--against", str(c)]) == 2
    err = capsys.readouterr().err
    assert f"becos validate: --against: {c}: pairs 0:2 cannot be read" in err and "Fix: re-export" in err, err
