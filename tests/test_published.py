"""Published pair lists (config/pairings_original_*.pkl) <-> manifests (becos.build.published)."""

from __future__ import annotations

import pickle
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_sampling import template_rows, tosca_entries

from becos.build.published import (
    SHAPE_FIELDS,
    import_published,
    load_cameras,
    load_published,
    published_shapes,
    rotation_to_xyz_degrees,
    save_cameras,
    write_published_pickle,
    y_rotation,
)
from becos.build.sampling import MANIFEST_COLUMNS, read_manifest, sample_pairs, write_manifest
from becos.errors import ConfigError, InputFileError
from becos.sources.catalog import catalog_table

SETTINGS = ("full_full", "partial_partial")
EXPECTED_SHAPES = {
    "faust": 100,
    "scape": 71,
    "kids": 32,
    "tosca": 76,
    "smal": 49,
    "shrec20": 11,
    "dt4d_animal": 1948,
    "dt4d_human": 246,
}


@pytest.fixture(scope="module")
def pickles(becos_code):
    return {s: becos_code / "config" / f"pairings_original_{s}.pkl" for s in SETTINGS}


@pytest.fixture(scope="module")
def imported(pickles):
    return {s: import_published(p) for s, p in pickles.items()}


@pytest.fixture(scope="module")
def tosca_catalog(tosca_dir):
    return catalog_table(tosca_entries(tosca_dir))


@pytest.mark.parametrize("setting", SETTINGS)
def test_import_counts_and_shapes(imported, pickles, setting):
    imp = imported[setting]
    m = imp.manifest
    assert imp.report["n_pairs"] == {"train": 10185, "test": 142, "val": 137}
    shapes = published_shapes(m)
    assert len(shapes) == 2533
    assert shapes.groupby("dataset").size().to_dict() == EXPECTED_SHAPES
    assert m["pair_id"].is_unique and (m["setting"] == setting).all()
    assert list(m.columns[: len(MANIFEST_COLUMNS)]) == list(MANIFEST_COLUMNS)
    # the pair category and the published cross-category counts (facts §4)
    cross = Counter(tuple(sorted(p)) for p in zip(m["x_category"], m["y_category"]) if p[0] != p[1])
    assert cross == {("centaur", "human"): 410, ("centaur", "four-legged"): 412}
    assert ((m["x_category"] == "centaur") & (m["y_category"] == "centaur")).sum() == 9
    assert set(m.loc[m["x_category"] != m["y_category"], "split"]) == {"train"}
    test = m[m["split"] == "test"]["category"].value_counts().to_dict()
    assert test == {"four-legged": 110, "human": 32}
    assert m["x_face_target"].between(18000, 20000).all() and m["y_face_target"].between(18000, 20000).all()
    # rows agree with the raw list
    raw = load_published(pickles[setting])
    r = m.iloc[123]
    x, y = raw[("train", "test", "val").index(r["split"])][r["published_index"]]
    assert (x["name"], y["name"], x["org_dataset"]) == (r["x_name"], r["y_name"], r["x_dataset"])
    np.testing.assert_array_equal(y["random_rot"].ravel(), r[[f"y_random_rot_{i}" for i in range(9)]].to_numpy(float))
    # cameras only in the partial-to-partial file
    if setting == "partial_partial":
        assert len(imp.cameras) == len(m)
        cam = imp.cameras[r["pair_id"]]
        assert cam.shape == (2, 10, 3)
        np.testing.assert_array_equal(cam[1], y["cam_pos"])
        np.testing.assert_allclose(np.linalg.norm(cam, axis=2), 1.0, atol=1e-9)
    else:
        assert imp.cameras is None


def test_tosca_subset(imported, pickles, tmp_path):
    raw = load_published(pickles["full_full"])
    sub = import_published(pickles["full_full"], datasets={"tosca"})
    want = {
        s: sum(1 for x, y in pairs if x["org_dataset"] == y["org_dataset"] == "tosca")
        for s, pairs in zip(("train", "test", "val"), raw)
    }
    assert sub.report["n_pairs"] == want
    assert set(sub.manifest["x_dataset"]) | set(sub.manifest["y_dataset"]) == {"tosca"}
    full = imported["full_full"].manifest
    assert set(sub.manifest["pair_id"]) <= set(full["pair_id"])  # same ids as in the whole import
    total = {s: n for s, n in zip(("train", "test", "val"), (10185, 142, 137))}
    assert {s: want[s] + sub.report["dropped_missing_dataset"].get(s, 0) for s in total} == total
    write_manifest(sub.manifest, tmp_path / "tosca.csv")  # extras survive the CSV form
    pd.testing.assert_frame_equal(read_manifest(tmp_path / "tosca.csv"), sub.manifest)
    print(
        f"\npublished F2F pairs with both shapes from TOSCA: {want}; "
        f"TOSCA shapes used by them: {len(published_shapes(sub.manifest))}"
    )


def test_restricted_unpickler_refuses_other_globals(tmp_path):
    class Evil:
        def __reduce__(self):
            import os

            return (os.getcwd, ())

    bad = tmp_path / "pairings_original_full_full.pkl"
    bad.write_bytes(pickle.dumps([[(Evil(), {})], [], []]))
    with pytest.raises(InputFileError, match="not allowed"):
        load_published(bad)
    wrong = tmp_path / "wrong.pkl"
    wrong.write_bytes(pickle.dumps({"a": 1}))
    with pytest.raises(InputFileError, match="3 lists"):
        load_published(wrong)


@pytest.mark.parametrize("setting", ["full_full", "partial_partial", "partial_full"])
def test_round_trip_manifest_pickle_manifest(becos_code, tosca_catalog, tmp_path, setting):
    rows = template_rows(becos_code / "config" / "templates_tosca_demo.csv")
    m = sample_pairs(tosca_catalog, setting, seed=5, combinations="all", usage_scale=0.1, template_rows=rows)
    cams = None
    if setting == "partial_partial":
        rng = np.random.default_rng(0)
        cams = {pid: rng.normal(size=(2, 10, 3)) for pid in m["pair_id"]}
    path = tmp_path / "pairs.pkl"
    write_published_pickle(m, path, tosca_catalog, template_rows=rows, cameras=cams)
    data = path.read_bytes()
    assert b"numpy._core" not in data and b"numpy.core" not in data  # loadable by numpy 1.x and 2.x
    raw = load_published(path)
    assert [len(s) for s in raw] == [int((m["split"] == s).sum()) for s in ("train", "test", "val")]
    x, y = raw[0][0]
    assert set(SHAPE_FIELDS) <= set(x) and set(SHAPE_FIELDS) <= set(y)
    assert x["rot"] == [90, 0, 0] and x["scale"] == 0.0095
    assert y["random_rot"].shape == (3, 3) and abs(np.linalg.det(y["random_rot"]) - 1) < 1e-12
    assert ("cam_pos" in y) == (setting != "full_full")
    cls = "".join(c for c in y["name"] if c.isalpha())
    assert y["partial_full_template"] == rows[f"tosca_{cls}"]["partial_full_template"]
    back = import_published(path)  # setting read from the pickle's becos metadata
    pd.testing.assert_frame_equal(back.manifest[list(MANIFEST_COLUMNS)], m)
    if cams is not None:
        assert back.cameras.keys() == cams.keys()
        for pid in cams:
            np.testing.assert_array_equal(back.cameras[pid], cams[pid])
        save_cameras(tmp_path / "cams.npz", back.cameras)
        loaded = load_cameras(tmp_path / "cams.npz")
        assert loaded.keys() == cams.keys()
        np.testing.assert_array_equal(loaded[m["pair_id"].iloc[0]], cams[m["pair_id"].iloc[0]])


def test_rotation_helpers():
    rx90 = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    assert rotation_to_xyz_degrees(rx90) == [90, 0, 0]
    from scipy.spatial.transform import Rotation

    m = Rotation.from_euler("XYZ", [180, 0, -90], degrees=True).as_matrix()
    got = rotation_to_xyz_degrees(m)
    np.testing.assert_allclose(Rotation.from_euler("XYZ", got, degrees=True).as_matrix(), m, atol=1e-9)
    r = y_rotation(0.3)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-15)
    assert r[1, 1] == 1.0 and np.isclose(np.arccos(r[0, 0]), 0.3)


# --------------------------------------------------------------------------------------------------
# a store's pickle describes the store: rotations, cameras, face targets, reference-style file paths


def _manifest_of(records) -> pd.DataFrame:
    from becos.build.sampling import sort_manifest

    rows = [
        {
            "pair_id": r.pair_id,
            "setting": r.meta["setting"],
            "split": r.meta["split"],
            "category": "four-legged",
            "copy": 0,
            "x_dataset": r.meta["x"]["dataset"],
            "x_name": r.meta["x"]["name"],
            "y_dataset": r.meta["y"]["dataset"],
            "y_name": r.meta["y"]["name"],
            "seed": int(r.meta["seed"]),
            "x_variant": 0,
            "y_variant": 0,
            "chunk": 0,
        }
        for r in records
    ]
    return sort_manifest(pd.DataFrame(rows, columns=list(MANIFEST_COLUMNS)))


def reference_shape_path(file_path: str, data_dir: str) -> str:
    """Where the reference generator reads a shape of a pair list: with ``data_dir`` other than
    ``data`` it rebuilds the path as ``f"{data_dir}/{file_path[4:]}"`` (BeCoS reference, generator
    script, function ``update_data_path_in_dict``; the expression the issue quotes), else it opens
    ``file_path`` as is, relative to its working folder."""
    return file_path if data_dir == "data" else f"{data_dir}/{file_path[4:]}"


@pytest.mark.parametrize("setting", ["full_full", "partial_full", "partial_partial"])
def test_store_pickle_round_trip(
    setting, pair_record_files, store_of, becos_code, tosca_catalog, tmp_path, monkeypatch
):
    from becos.build.cameras import draw_camera_pair
    from becos.build.published import N_CAMERAS, store_pair_facts
    from becos.build.record import PairRecord
    from becos.products.store import open_benchmark
    from becos.seeding import rng_for

    records = [PairRecord.load(p) for p in pair_record_files[setting]]
    records[1].meta["x_token"] = "f18765"  # a published face target: written as is
    bench = open_benchmark(store_of(records, setting))
    facts = store_pair_facts(bench)
    path = tmp_path / f"pairings_{setting}.pkl"
    write_published_pickle(
        _manifest_of(records),
        path,
        tosca_catalog,
        random_rotations=facts["random_rotations"],
        cameras=facts["cameras"],
        pair_face_targets=facts["face_targets"],
        data_root=becos_code / "data",
    )
    back = import_published(path)
    m = back.manifest.set_index("pair_id")
    assert sorted(m.index) == sorted(r.pair_id for r in records)
    for r in records:
        row = m.loc[r.pair_id]
        for s in ("x", "y"):
            rot = row[[f"{s}_random_rot_{i}" for i in range(9)]].to_numpy(float).reshape(3, 3)
            assert np.array_equal(rot, r[f"{s}_random_rotation"])  # the rotation the record applied
            full_faces = len(r[f"{s}_full_faces"]) or len(r[f"{s}_faces"])
            want = 18765 if (s, r is records[1]) == ("x", True) else full_faces
            assert row[f"{s}_face_target"] == want
        if setting == "full_full":
            assert back.cameras is None
            continue
        cams = back.cameras[r.pair_id]
        assert cams.shape == (2, N_CAMERAS, 3)
        for k, s in enumerate(("x", "y")):
            if setting == "partial_full" and s == "x":
                assert np.isnan(cams[k]).all()  # the full template has no camera
                continue
            camera = r[f"{s}_camera"]
            assert (cams[k] == cams[k, 0]).all() and np.linalg.norm(cams[k, 0]) == pytest.approx(1.0)
            # every try holds the camera that cut the record: position - target along it (shared frame)
            along = (camera[0] - camera[1]) @ r[f"{s}_align_rotation"]
            np.testing.assert_allclose(cams[k, 0] * np.linalg.norm(along), along, atol=1e-12)
        if setting == "partial_partial":  # ... and it is the try the scanner accepted, redrawn from its seed
            o = r.meta["options"]
            drawn = draw_camera_pair(
                rng_for(r.meta["seed"], r.pair_id, "cameras", r.meta["try_index"]),
                o["cam_pos_regime"],
                o["up_axis"],
                o["camera_distance"],
            )
            for k in (0, 1):
                np.testing.assert_allclose(cams[k, 0], drawn[k].position / np.linalg.norm(drawn[k].position), atol=1e-9)

    # file_path as the reference writes it; its path logic finds the meshes under another data_dir
    raw = load_published(path)
    shapes = [s for split in raw for pair in split for s in pair]
    assert {s["file_path"] for s in shapes} == {"data/tosca-off/cat0.off", "data/tosca-off/cat3.off"}
    elsewhere = tmp_path / "elsewhere" / "meshes"
    elsewhere.mkdir(parents=True)
    (elsewhere / "tosca-off").symlink_to(becos_code / "data" / "tosca-off", target_is_directory=True)
    for s in shapes:
        found = Path(reference_shape_path(s["file_path"], str(elsewhere)))
        assert (
            found.is_file()
            and found.read_bytes() == (becos_code / "data" / "tosca-off" / f"{s['name']}.off").read_bytes()
        )
    monkeypatch.chdir(becos_code)  # default data_dir "data": relative to the reference checkout
    assert all(Path(reference_shape_path(s["file_path"], "data")).is_file() for s in shapes)
    # a catalog file outside the data root cannot be written as data/...
    with pytest.raises(ConfigError, match="outside the data root"):
        write_published_pickle(_manifest_of(records), tmp_path / "x.pkl", tosca_catalog, data_root=tmp_path)
    with pytest.raises(ConfigError, match="no random rotations"):
        write_published_pickle(_manifest_of(records), tmp_path / "x.pkl", tosca_catalog, random_rotations={})
