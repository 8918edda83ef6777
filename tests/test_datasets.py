"""The dataset registry: TOSCA on the real meshes; the other datasets' rules on names (their data is licensed)."""

from __future__ import annotations

import json
import random
from collections import Counter

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from standin import SHREC20_MODELS

from becos.errors import BecosError, ConfigError, InputFileError
from becos.sources.datasets import (
    DatasetSpec,
    available_datasets,
    frame_rotation_matrix,
    prepare_shape,
    reference_sort_key,
    up_vector,
)

TOSCA_CLASSES = {"cat": 11, "centaur": 6, "david": 7, "dog": 9, "horse": 8, "michael": 20, "victoria": 12, "wolf": 3}


@pytest.fixture(scope="session")
def tosca(tosca_entries):
    return tosca_entries


@pytest.fixture(scope="session")
def prepared(tosca, mesh_cache):
    return {n: prepare_shape(tosca[n], mesh_cache) for n in ("michael0", "horse0", "cat0", "dog0", "wolf0")}


def test_registry_lists_the_eight_datasets():
    reference = ["dt4d_animal", "dt4d_human", "faust", "kids", "scape", "shrec20", "smal", "tosca"]
    assert set(reference) <= set(available_datasets())  # plus the built-in synthetic ones
    for name in reference:
        spec = DatasetSpec.load(name)
        assert spec.name == name and spec.expected_count > 0 and spec.usage > 0
        assert spec.source["url"].startswith("http") and spec.source["citation"]
    with pytest.raises(ConfigError, match="gorilla.*available"):
        DatasetSpec.load("gorilla")


def test_tosca_listing(tosca, annotations):
    assert len(tosca) == 76
    assert Counter(e.shape_class for e in tosca.values()) == TOSCA_CLASSES
    category = {
        "michael": "human",
        "david": "human",
        "victoria": "human",
        "cat": "four-legged",
        "dog": "four-legged",
        "horse": "four-legged",
        "wolf": "four-legged",
        "centaur": "centaur",
    }
    for e in tosca.values():
        assert e.category == category[e.shape_class]
        assert e.template_key == f"tosca_{e.shape_class}"
        assert annotations.node_of_key(e.template_key) in annotations.graph
        assert e.path.is_file() and e.path.name == f"{e.name}.off"
        assert e.scale == 0.0095 and e.usage == 70
    splits = {}
    for e in tosca.values():
        splits.setdefault(e.split, set()).add(e.shape_class)
    assert splits == {
        "train": {"michael", "horse", "wolf", "centaur"},
        "val": {"david", "dog"},
        "test": {"victoria", "cat"},
    }
    # class hold-out: no class in two splits
    per_class = {}
    for e in tosca.values():
        per_class.setdefault(e.shape_class, set()).add(e.split)
    assert all(len(s) == 1 for s in per_class.values())


def test_michael_is_head_up_with_the_reference_extents(prepared):
    p = prepared["michael0"]
    v = p.mesh.vertices
    extents = np.ptp(v, axis=0)
    print(f"\nmichael0 extents {np.round(extents, 3)}, sqrt area {p.sqrt_area:.4f}")
    assert np.allclose(extents, (1.73, 1.74, 0.41), atol=0.006)
    assert extents.argmax() == 1
    assert np.allclose(v.mean(axis=0), 0.0, atol=1e-9)
    # the top-most vertices are the head: narrow and central in x (the hands lie far to the sides)
    top = v[v[:, 1] > np.quantile(v[:, 1], 0.99)]
    assert abs(top[:, 0].mean()) < 0.05 and np.ptp(top[:, 0]) < 0.25
    assert p.area == pytest.approx(p.sqrt_area**2) and 1.84 <= p.area <= 1.93  # facts §10


@pytest.mark.parametrize("name", ["horse0", "cat0", "dog0", "wolf0"])
def test_four_legged_stand_on_their_feet_and_face_plus_z(name, prepared):
    v = prepared[name].mesh.vertices
    extents = np.ptp(v, axis=0)
    assert extents[2] > extents[1] > extents[0]  # long along z, tall along y, narrow along x
    low, high = v[:, 1].min(), v[:, 1].max()
    # the head (top-most vertices: ears / head) is at the front, +z
    top = v[v[:, 1] > np.quantile(v[:, 1], 0.99)]
    assert top[:, 2].mean() > 0.1 * extents[2]
    # the rear-most vertices (tail) hang well above the ground, the lowest ones (hooves / paws) touch it
    rear = v[v[:, 2] < np.quantile(v[:, 2], 0.01)]
    assert rear[:, 1].mean() > low + 0.3 * (high - low)
    feet = v[v[:, 1] < low + 0.05 * (high - low)]
    assert np.ptp(feet[:, 2]) > 0.3 * extents[2]  # front and back feet both on the ground


def test_horse_prepared_matches_the_reference(prepared, mesh_cache):
    p = prepared["horse0"]
    assert np.allclose(np.ptp(p.mesh.vertices, axis=0), (0.65, 1.82, 2.47), atol=0.006)
    assert 6.22 <= p.area <= 6.41
    # common = (V * scale - centre) @ R, so V = (common @ R.T + centre) / scale
    original = mesh_cache.load(p.entry.path)
    back = (p.mesh.vertices @ p.entry.frame_rotation.T + p.centre) / p.entry.scale
    assert np.allclose(back, original.vertices, atol=1e-9)
    assert np.array_equal(p.mesh.faces, original.faces)


def test_frame_rotation_is_open3d_xyz():
    rng = np.random.default_rng(0)
    for angles in rng.uniform(-180, 180, size=(5, 3)):
        expected = Rotation.from_euler("XYZ", angles, degrees=True).as_matrix()  # intrinsic = Rx @ Ry @ Rz
        assert np.allclose(frame_rotation_matrix(angles), expected)
    r = frame_rotation_matrix([90, 0, 0])
    assert np.allclose(np.array([0, 0, 1.0]) @ r, [0, 1, 0])  # TOSCA / KIDS / DT4D: z-up -> y-up
    s = frame_rotation_matrix([180, 0, -90])  # SCAPE (facts §2.2)
    assert np.allclose(np.eye(3) @ s, [[0, 1, 0], [1, 0, 0], [0, 0, -1]])
    assert np.allclose(up_vector(), [0, 1, 0]) and np.allclose(up_vector("-z"), [0, 0, -1])
    with pytest.raises(ConfigError):
        up_vector("w")


@pytest.mark.parametrize(
    "dataset, name, category, shape_class, key",
    [
        ("faust", "tr_reg_015", "human", "subject01", "faust"),
        ("faust", "tr_reg_099", "human", "subject09", "faust"),
        ("dt4d_animal", "bear3EP/Attack4009", "four-legged", "bear3EP", "dt4d_animal_bear3EP"),
        ("dt4d_human", "crypto/Standing2HMagicAttack01058", "human", "crypto", "dt4d_human_crypto"),
        ("smal", "big_cats/lion3", "four-legged", "big_cats", "smal_big_cats"),
        ("kids", "0001.isometry.4", "human", "kid0001", "kids"),
        ("scape", "mesh012", "human", "scape", "scape"),
        ("shrec20", "elephant_b", "four-legged", "elephant_b", "shrec20_elephant_b"),
        ("tosca", "centaur3", "centaur", "centaur", "tosca_centaur"),
        ("tosca", "Victoria10", "human", "Victoria", "tosca_Victoria"),  # categories are case-insensitive
    ],
)
def test_name_rules_of_every_dataset(dataset, name, category, shape_class, key, annotations):
    spec = DatasetSpec.load(dataset)
    assert (spec.category_of(name), spec.class_of(name), spec.template_key_of(name)) == (category, shape_class, key)
    if key != "tosca_Victoria":
        assert annotations.node_of_key(key) in annotations.graph


def test_name_based_splits(annotations):
    smal, shrec = DatasetSpec.load("smal"), DatasetSpec.load("shrec20")
    assert [
        smal.split_of(n) for n in ("big_cats/lion3", "dogs/dog2", "horses/grazing", "hippos/hippo5", "cows/cow2")
    ] == ["train", "train", "train", "val", "test"]
    assert [shrec.split_of(n) for n in ("cow", "giraffe_b", "rhino", "bear")] == ["train", "val", "test", "excluded"]
    with pytest.raises(BecosError, match="shrec20.yaml.*unicorn"):
        shrec.split_of("unicorn")
    dt4d = DatasetSpec.load("dt4d_animal")
    assert dt4d.split_of("tigerD8H/Actions6028010", annotations) == "test"
    assert dt4d.split_of("huskydog3T/Actions3060001", annotations) == "val"
    with pytest.raises(ConfigError, match="template table"):
        dt4d.split_of("tigerD8H/Actions6028010")
    with pytest.raises(BecosError, match="slices"):
        DatasetSpec.load("faust").split_of("tr_reg_000")


def test_count_based_slices_follow_the_numeric_order_not_the_input_order():
    faust = [f"tr_reg_{i:03d}" for i in range(100)]
    random.Random(1).shuffle(faust)
    splits = DatasetSpec.load("faust").assign_splits(faust)
    assert all(splits[f"tr_reg_{i:03d}"] == ("train" if i < 80 else "val" if i < 90 else "test") for i in range(100))
    scape = [f"mesh{i:03d}" for i in range(72) if i != 51]
    splits = DatasetSpec.load("scape").assign_splits(scape[::-1])
    assert Counter(splits.values()) == {"train": 56, "val": 7, "test": 8}
    assert splits["mesh056"] == "train" and splits["mesh057"] == "val" and splits["mesh064"] == "test"
    kids = [f"000{k}.{kind}.{i}" for k in (1, 2) for kind, n in (("isometry", range(1, 16)), ("null", [0])) for i in n]
    random.Random(2).shuffle(kids)
    splits = DatasetSpec.load("kids").assign_splits(kids)
    # the reference's realised KIDS split (facts §2.2)
    assert sorted(n for n, s in splits.items() if s == "val") == [f"0002.isometry.{i}" for i in (3, 4, 5, 6)]
    assert sorted(n for n, s in splits.items() if s == "test") == [
        "0002.isometry.7",
        "0002.isometry.8",
        "0002.isometry.9",
        "0002.null.0",
    ]
    assert reference_sort_key("tr_reg_010.ply") > reference_sort_key("tr_reg_009.ply")
    with pytest.raises(BecosError, match="cover 100 shapes but 99"):
        DatasetSpec.load("faust").assign_splits(faust[:99])


def test_dt4d_listing_uses_the_info_json_and_the_template_table(becos_code, annotations, tmp_path):
    info = json.loads((becos_code / "data" / "info_dt4d_humanoids.json").read_text())
    folder = tmp_path / "dt4d_humanoids"
    for cls, actions in info.items():
        (folder / cls).mkdir(parents=True)
        for action, frames in actions.items():
            for f in frames:
                (folder / cls / f"{action}{f:03d}.obj").touch()
    spec = DatasetSpec.load("dt4d_human")
    entries = spec.list_shapes(tmp_path, annotations)
    assert len(entries) == 248 and all(e.path.is_file() for e in entries)
    per_class = {}
    for e in entries:
        per_class.setdefault(e.shape_class, set()).add(e.split)
        assert annotations.node_of_key(e.template_key) == e.template_key
    assert Counter(per_class[c].pop() for c in per_class) == {"train": 6, "val": 1, "test": 1}
    assert {c for c in per_class if not per_class[c]} == set(info)
    template = annotations.template_row("dt4d_human_crypto").template
    assert any(e.name == template for e in entries)  # the class template is one of the listed frames
    next(folder.glob("*/*.obj")).unlink()
    with pytest.raises(InputFileError, match="1 of the 248 shapes.*missing.*prepare-dt4d"):
        spec.list_shapes(tmp_path, annotations)


def test_dt4d_animal_classes_all_have_template_rows(becos_code, annotations):
    info = json.loads((becos_code / "data" / "info_dt4d_animals.json").read_text())
    spec = DatasetSpec.load("dt4d_animal")
    splits = Counter()
    for cls, actions in info.items():
        action, frames = next(iter(actions.items()))
        name = f"{cls}/{action}{frames[0]:03d}"
        assert annotations.node_of_key(spec.template_key_of(name)) in annotations.graph
        splits[spec.split_of(name, annotations)] += 1
    assert splits == {"train": 31, "val": 4, "test": 4}


def test_smal_rotations_come_from_the_reference_config(annotations, tmp_path):
    smal = DatasetSpec.load("smal")
    assert np.allclose(smal.rotation_of("big_cats/lion3", annotations), frame_rotation_matrix([0, 90, 90]))
    assert np.allclose(smal.rotation_of("horses/muybridge_075_04", annotations), frame_rotation_matrix([0, -90, 180]))
    assert np.allclose(smal.rotation_of("horses/unknown", annotations), np.eye(3))  # reference default
    with pytest.raises(ConfigError, match="annotation folder"):
        smal.rotation_of("big_cats/lion3")
    # a fake SMAL download: 49 files in class folders
    rot = __import__("yaml").safe_load((annotations.root / "config" / "smal.yaml").read_text())["rot"]
    for key in rot:
        cls = next(c for c in ("big_cats", "cows", "dogs", "hippos", "horses") if key.startswith(c + "_"))
        (tmp_path / "smal" / cls).mkdir(parents=True, exist_ok=True)
        (tmp_path / "smal" / cls / f"{key[len(cls) + 1 :]}.ply").touch()
    entries = smal.list_shapes(tmp_path, annotations)
    assert len(entries) == 49
    assert Counter(e.split for e in entries) == {"train": 35, "val": 6, "test": 8}
    for e in entries:
        assert np.allclose(e.frame_rotation, frame_rotation_matrix(rot[e.rot_key]))
    (tmp_path / "smal" / "cows" / "extra.ply").touch()
    with pytest.raises(InputFileError, match="found 50 smal shapes"):
        smal.list_shapes(tmp_path, annotations)


def test_shrec20_listing_marks_excluded_shapes(tmp_path):
    spec = DatasetSpec.load("shrec20")
    folder = tmp_path / spec.folder
    folder.mkdir(parents=True)
    for n in SHREC20_MODELS:
        (folder / f"{n}.obj").touch()
    entries = spec.list_shapes(tmp_path)
    assert len(entries) == 14
    assert Counter(e.split for e in entries) == {"train": 7, "val": 2, "test": 2, "excluded": 3}
    assert all(e.scale == 2.9 and e.template_key == f"shrec20_{e.name}" for e in entries)
    (folder / "rhino.obj").unlink()
    with pytest.raises(InputFileError, match="found 10 shrec20 shapes"):
        spec.list_shapes(tmp_path)


def test_missing_or_incomplete_data_is_an_error_with_download_instructions(tmp_path, tosca_dir):
    with pytest.raises(InputFileError) as err:
        DatasetSpec.load("tosca").list_shapes(tmp_path)
    assert "tosca-off" in str(err.value) and "download" in str(err.value) and "Fix:" in str(err.value)
    with pytest.raises(InputFileError) as err:
        DatasetSpec.load("faust").list_shapes(tmp_path)
    assert "faust-leaderboard.is.tuebingen.mpg.de" in str(err.value) and "MPI-FAUST" in str(err.value)
    (tmp_path / "tosca-off").mkdir()
    for p in sorted(tosca_dir.glob("*.off"))[:-1]:
        (tmp_path / "tosca-off" / p.name).symlink_to(p)
    with pytest.raises(InputFileError, match="found 75 tosca shapes"):
        DatasetSpec.load("tosca").list_shapes(tmp_path)


def test_faulty_yaml_is_an_error_naming_it(tmp_path):
    text = (DatasetSpec.load("tosca").path).read_text()
    (tmp_path / "tosca.yaml").write_text(text.replace("layout: flat", "layout: spiral"))
    with pytest.raises(InputFileError, match="tosca.yaml: layout 'spiral'"):
        DatasetSpec.load("tosca", tmp_path)
    (tmp_path / "tosca.yaml").write_text(text.replace("value: centaur", "value: horseman"))
    with pytest.raises(InputFileError, match="tosca.yaml: category value 'horseman'"):
        DatasetSpec.load("tosca", tmp_path)
