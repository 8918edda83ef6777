"""The workflow's planning, without a Snakemake run: job options, remesh tokens, input keys, chunk inputs.

Every rule passes ``becos.workflow.job_options`` as a parameter, so Snakemake reruns a job exactly when
that JSON changes; chunk jobs then keep every pair file whose stored input key still matches. These
tests pin which config edits reach which stage, and which files a chunk job declares.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

import becos.workflow as bw
from becos.errors import ConfigError
from becos.settings import MAX_OVERLAP, MIN_OVERLAP, SETTINGS, overlap_range_problem

BASE = {"synthetic": {"enabled": False}, "data_dir": "data", "annotations": "ann", "datasets": ["tosca"]}


@pytest.fixture(scope="module")
def config() -> dict:
    return bw.resolve_config(dict(BASE))


JOB_STAGES = ("catalog", "manifest", "remesh", "export", "ground_truth", "pairs")
"""The stages whose rules pass ``job_options`` (the dataset check passes its paths one by one)."""


def _options_class(stage: str, setting: str | None) -> type:
    return bw.PAIRS_OPTIONS[setting] if stage == "pairs" else bw.STAGE_OPTIONS[stage]


def _jobs(config: dict) -> dict[tuple[str, str | None], dict]:
    """The options JSON of every stage (and setting, for pairs) as dicts."""
    out = {}
    for stage in JOB_STAGES:
        settings = SETTINGS if stage in ("pairs", "manifest") else (None,)
        for setting in settings:
            out[(stage, setting)] = json.loads(bw.job_options(config, stage, setting))
    return out


def _rerun(config: dict, **edit) -> set[tuple[str, str | None]]:
    """The (stage, setting) jobs whose options change when ``edit`` is applied to ``config``."""
    before, after = _jobs(config), _jobs(bw.resolve_config({**BASE, **edit}))
    return {job for job in before if before[job] != after[job]}


def test_job_options_are_the_stage_options_fields_and_version(config):
    for (stage, setting), options in _jobs(config).items():
        cls = _options_class(stage, setting)
        expected = set(cls.keys()) | ({"version"} if cls.version is not None else set())
        assert set(options) == expected, (stage, setting)
        assert options["results"] == "results"
        for key in expected - {"version"}:
            assert options[key] == config[key], (stage, key)
    # each stage's keys, as the rules passed them before the options were typed (a change reruns jobs)
    assert set(_jobs(config)[("pairs", "partial_partial")]) - set(_jobs(config)[("pairs", "full_full")]) == {
        "camera_distance",
        "cam_pos_regime",
        "n_cam_pos",
        "min_overlap",
        "max_overlap",
    }
    assert set(_jobs(config)[("remesh", None)]) == {"results", "version", "seed", "remesh", "remesher", "decimator"}
    # the store's metadata reruns for every key but those that say what is built from a store, or how the
    # data arrived
    store_blind = {"setting", "n_renders", "store_vis", "exports", "evaluation", "download", "download_urls"}
    assert set(json.loads(bw.store_keys(config))) == set(config) - store_blind
    # sorted keys: the same config gives the same parameter text, whatever the key order it was written in
    text = bw.job_options(config, "pairs", "partial_partial")
    assert text == json.dumps(json.loads(text), sort_keys=True)
    assert bw.job_options(dict(reversed(list(config.items()))), "pairs", "partial_partial") == text


@pytest.mark.parametrize(
    "edit, reruns",
    [
        ({"min_overlap": 0.2}, {("pairs", "partial_partial")}),
        ({"cam_pos_regime": "medium"}, {("pairs", "partial_partial")}),
        ({"camera_distance": 2.0}, {("pairs", "partial_partial"), ("pairs", "partial_full")}),
        ({"one_axis_rotation": False}, {("pairs", s) for s in SETTINGS}),
        ({"seed": 7}, {("remesh", None), *(("manifest", s) for s in SETTINGS)}),
        # the pairs stage reads the original meshes instead of remesh files (it used to look for v0.npz)
        (
            {"remesh": False},
            {
                ("remesh", None),
                ("ground_truth", None),
                *((stage, s) for s in SETTINGS for stage in ("manifest", "pairs")),
            },
        ),
        ({"decimator": "fast-simplification"}, {("remesh", None)}),
        ({"n_renders": 1}, set()),
        ({"store_vis": False}, set()),
        ({"exports": {"psmal": True}}, set()),
        ({"exports": {"ulrssm": True, "dpfm": True}}, set()),
        ({"results": "elsewhere"}, None),  # every job: the paths change
    ],
)
def test_an_edit_reaches_exactly_the_stages_that_read_the_key(config, edit, reruns):
    changed = _rerun(config, **edit)
    if reruns is None:
        assert changed == set(_jobs(config))
    else:
        assert changed == reruns, edit


@pytest.mark.parametrize("stage", ["remesh", "ground_truth"])
def test_a_stage_version_bump_reruns_only_that_stage(config, monkeypatch, stage):
    before = _jobs(config)
    cls = bw.STAGE_OPTIONS[stage]
    monkeypatch.setattr(cls, "version", cls.version + 1)
    after = _jobs(config)
    assert {job for job in before if before[job] != after[job]} == {(stage, None)}


@pytest.mark.parametrize(
    "row, remesh, token",
    [
        ({"x_variant": 2, "x_face_target": 11734}, True, "f11734"),  # a published face target wins
        ({"x_variant": 2, "x_face_target": math.nan}, True, "v2"),  # none published: the variant
        ({"x_variant": 0, "x_face_target": 0}, True, "v0"),
        ({"x_variant": 1}, True, "v1"),  # no face-target column at all
        ({"x_variant": 1, "x_face_target": 500}, False, "original"),  # remesh off: the original mesh
    ],
)
def test_remesh_tokens(row, remesh, token):
    assert bw.remesh_token(row, "x", remesh) == token
    assert bw.remesh_token(pd.Series(row), "x", remesh) == token


def test_remesh_targets_follow_the_token(config):
    assert bw.remesh_target(config["seed"], "tosca", "cat0", "f9000") == {"target_faces": 9000}
    v0 = bw.remesh_target(config["seed"], "tosca", "cat0", "v0")["target_vertices"]
    assert v0 == bw.remesh_target(config["seed"], "tosca", "cat0", "v0")["target_vertices"]  # seeded, stable
    assert {
        bw.remesh_target(config["seed"], "tosca", n, "v0")["target_vertices"] for n in ("cat0", "cat1", "dog0")
    } <= set(range(9000, 10001))


def _plan(config: dict) -> bw.Plan:
    """A plan over 4 TOSCA-named shapes: full_full has 3 pairs in chunks 0 and 5, one pair per side
    pinned to a published face target."""
    names = ["cat0", "cat1", "dog0", "dog1"]
    catalog = pd.DataFrame(
        {
            "dataset": "tosca",
            "name": names,
            "file": [f"data/{n}.off" for n in names],
            "template_key": [f"tosca_{n}" for n in names],
        }
    )
    manifest = pd.DataFrame(
        {
            "pair_id": ["p0", "p1", "p2"],
            "chunk": [0, 0, 5],
            "x_dataset": "tosca",
            "x_name": ["cat0", "cat1", "cat0"],
            "x_variant": [0, 1, 0],
            "x_face_target": [math.nan, math.nan, 12000],
            "y_dataset": "tosca",
            "y_name": ["cat1", "dog0", "dog1"],
            "y_variant": [1, 0, 2],
            "y_face_target": [math.nan, math.nan, math.nan],
        }
    )
    return bw.Plan(config, catalog, {"full_full": manifest})


def test_chunk_inputs_are_the_remesh_folders_the_chunk_reads(config):
    """A chunk job declares its shapes' remesh folders (the remesh jobs' outputs, one job per shape making
    every token some pair uses), its list file names the files in them (chunk_remesh_files)."""
    plan = _plan(config)
    folder = plan.layout.remeshed_folder
    assert plan.chunks("full_full") == [0, 5]
    assert plan.chunk_inputs("full_full", 0) == [str(folder("tosca", n)) for n in ("cat0", "cat1", "dog0")]
    # cat1 appears on both sides of chunk 0 and is listed once; a published target is a token of its shape
    assert plan.chunk_inputs("full_full", 5) == [str(folder("tosca", "cat0")), str(folder("tosca", "dog1"))]
    assert plan.chunk_inputs("full_full", 3) == []  # a chunk without pairs reads nothing
    assert plan.chunk_inputs("full_full", 0) is not plan.chunk_inputs("full_full", 0)  # callers get a copy
    from becos.workflow.plan import chunk_remesh_files

    listed = chunk_remesh_files(plan.manifests["full_full"], config)
    remeshed = plan.layout.remeshed
    assert listed["0"] == [
        ["tosca", n, t, str(remeshed("tosca", n, t))] for n, t in [("cat0", "v0"), ("cat1", "v1"), ("dog0", "v0")]
    ]
    assert all(Path(p).parent == folder(d, n) for rows in listed.values() for d, n, _, p in rows)
    assert plan.remesh_jobs == {
        ("tosca", "cat0"): ["f12000", "v0"],
        ("tosca", "cat1"): ["v1"],
        ("tosca", "dog0"): ["v0"],
        ("tosca", "dog1"): ["v2"],
    }
    targets = plan.remesh_targets("tosca", "cat0")  # the remesh rule's rerun trigger: every token's target
    assert targets["f12000"] == {"target_faces": 12000} and set(targets["v0"]) == {"target_vertices"}
    assert "file" not in json.loads(plan.shape_json("tosca", "dog0"))  # the rule passes the mesh itself
    assert plan.files[("tosca", "dog0")] == "data/dog0.off"


def test_without_remeshing_a_chunk_reads_no_remesh_file(config):
    plan = _plan({**config, "remesh": False})
    assert plan.chunk_inputs("full_full", 0) == [] and plan.remesh_jobs == {}


def test_stored_input_keys(tmp_path):
    """A chunk job keeps a pair file exactly when the input key stored in it equals the new one."""
    from becos.atomic import save_npz

    gt = tmp_path / "gt.npz"
    save_npz(gt, input_key=np.array("abc123"), xy_face=np.zeros(3, dtype=np.int64))
    assert bw.stored_key(gt, "input_key") == "abc123"
    assert bw.stored_key(gt, "other") is None  # written before keys existed
    record = tmp_path / "record.npz"
    save_npz(record, __meta__=np.array(json.dumps({"pair_id": "p0", "input_key": "def456"})))
    assert bw.stored_key(record, "__meta__") == "def456"
    broken = tmp_path / "broken.npz"
    broken.write_bytes(gt.read_bytes()[:40])  # a killed write
    assert bw.stored_key(broken, "input_key") is None
    assert bw.stored_key(tmp_path / "absent.npz", "input_key") is None
    # the key is a digest of everything the pair reads: any change gives another key
    parts = {"version": 1, "x": ["tosca", "cat0", "v0"], "sources": ["a", "b"], "options": {"remesh": True}}
    assert bw.digest(parts) == bw.digest(dict(reversed(list(parts.items()))))
    assert bw.digest(parts) != bw.digest({**parts, "sources": ["a", "c"]})


def test_the_overlap_range_has_one_default():
    schema = yaml.safe_load(bw.SCHEMA_PATH.read_text())["properties"]
    assert schema["min_overlap"]["default"] == MIN_OVERLAP and schema["max_overlap"]["default"] == MAX_OVERLAP
    from becos.build.pairs import PairOptions

    assert (PairOptions().min_overlap, PairOptions().max_overlap) == (MIN_OVERLAP, MAX_OVERLAP)
    assert overlap_range_problem(MIN_OVERLAP, MAX_OVERLAP) is None
    assert "reversed" in overlap_range_problem(0.8, 0.2)
    assert overlap_range_problem(0.1, 1.5).startswith("max_overlap: 1.5 is outside [0, 1]")
    with pytest.raises(ValueError, match="reversed"):
        PairOptions(min_overlap=0.8, max_overlap=0.2)


def test_exports_zarr_false_is_a_named_config_error():
    assert bw.resolve_config({**BASE, "exports": {"zarr": True}})["exports"]["zarr"] is True  # older configs
    with pytest.raises(ConfigError, match=r"exports.zarr: false is not supported.*Fix: remove exports.zarr"):
        bw.resolve_config({**BASE, "exports": {"zarr": False}})
