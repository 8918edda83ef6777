"""Pair assembly on remeshed TOSCA shapes with network ground truth: all three settings."""

from __future__ import annotations

import numpy as np
import pytest

from becos.build.pairs import PairOptions, build_pair
from becos.build.record import PairRecord
from becos.build.visibility import largest_component


@pytest.fixture(scope="module")
def pair_inputs(tosca_pair_inputs):
    return tosca_pair_inputs


@pytest.mark.parametrize("setting", ["full_full", "partial_full", "partial_partial"])
def test_pair_record_is_consistent(setting, pair_inputs, tmp_path):
    x, y, gt_xy, gt_yx = pair_inputs
    record = build_pair(
        x, y, gt_xy, gt_yx, pair_id=f"test-{setting}", seed=7, split="test", options=PairOptions(setting=setting)
    )
    record.save(tmp_path / "r.npz")
    loaded = PairRecord.load(tmp_path / "r.npz")
    assert loaded.meta == record.meta
    for key, value in record.arrays.items():
        assert np.array_equal(loaded[key], value, equal_nan=value.dtype.kind == "f"), key
    r = loaded
    nx, ny = len(r["x_vertices"]), len(r["y_vertices"])
    # indices in range, -1 exactly where the mask says no counterpart
    assert r["corr_01"].min() >= -1 and r["corr_01"].max() < ny
    assert r["corr_10"].min() >= -1 and r["corr_10"].max() < nx
    assert np.array_equal(r["corr_01"] >= 0, r["x_overlap_mask"])
    assert np.array_equal(r["corr_10"] >= 0, r["y_overlap_mask"])
    # brute force: X̂ vertex has a counterpart iff its full ground-truth point lies in a face Ŷ kept
    kept_y = np.zeros(y.mesh.n_faces, bool)
    kept_y[r["y_full_face_ids"]] = True
    gt_face = gt_xy.face[r["x_partial_to_full"]]
    brute = (gt_face >= 0) & kept_y[np.where(gt_face >= 0, gt_face, 0)]
    assert np.array_equal(brute, r["x_overlap_mask"])
    assert r["x_overlap"] == pytest.approx(brute.mean())
    # partial shapes are one connected component; full ones keep everything
    for s, full in (("x", x), ("y", y)):
        mask = np.zeros(full.mesh.n_faces, bool)
        mask[r[f"{s}_full_face_ids"]] = True
        assert np.array_equal(largest_component(full.mesh, mask), mask)
        assert np.array_equal(r[f"{s}_partial_to_full"][r[f"{s}_faces"]], full.mesh.faces[r[f"{s}_full_face_ids"]])
    # transforms are rotations and undo to the common frame exactly
    for s in ("x", "y"):
        for key in ("random_rotation", "align_rotation", "frame_rotation"):
            m = r[f"{s}_{key}"]
            assert np.allclose(m @ m.T, np.eye(3), atol=1e-12) and np.linalg.det(m) == pytest.approx(1.0)
    common_y = ((r["y_vertices"] @ r["y_random_rotation"].T) - r["y_align_translation"]) @ r["y_align_rotation"].T
    assert np.abs(common_y - y.mesh.vertices[r["y_partial_to_full"]]).max() < 1e-9
    if setting == "partial_partial":
        assert 0.1 <= r["x_overlap"] <= 0.9 and 0.1 <= r["y_overlap"] <= 0.9
        assert r.meta["n_tries"] >= 1 and np.isfinite(r["x_camera"]).all()
    if setting != "full_full":
        assert ny < y.mesh.n_vertices


def test_same_seed_same_record_and_other_id_other_cameras(pair_inputs):
    x, y, gt_xy, gt_yx = pair_inputs
    opts = PairOptions(setting="partial_partial")
    a = build_pair(x, y, gt_xy, gt_yx, pair_id="a", seed=1, split="train", options=opts)
    b = build_pair(x, y, gt_xy, gt_yx, pair_id="a", seed=1, split="train", options=opts)
    c = build_pair(x, y, gt_xy, gt_yx, pair_id="c", seed=1, split="train", options=opts)
    for key in a.arrays:
        assert np.array_equal(a[key], b[key], equal_nan=True), key
    assert not np.allclose(a["x_camera"], c["x_camera"])
    assert not np.allclose(a["x_random_rotation"], c["x_random_rotation"])


def test_full_shape_travels_with_a_partial_record(pair_inputs):
    from becos.build.record import full_shape

    x, y, gt_xy, gt_yx = pair_inputs
    record = build_pair(
        x, y, gt_xy, gt_yx, pair_id="full-shape", seed=3, split="test", options=PairOptions(setting="partial_partial")
    )
    for side, shape in (("x", x), ("y", y)):
        full_v, full_f = full_shape(record, side)
        assert full_v.shape == shape.mesh.vertices.shape and np.array_equal(full_f, shape.mesh.faces)
        # the partial's vertices are exactly the kept full vertices, in the same final frame
        assert np.array_equal(full_v[record[f"{side}_partial_to_full"]], record[f"{side}_vertices"])
    f2f = build_pair(x, y, gt_xy, gt_yx, pair_id="f2f", seed=3, split="test", options=PairOptions())
    assert f2f["x_full_faces"].shape == (0, 3) and full_shape(f2f, "x")[0] is f2f["x_vertices"]
