"""Baseline matchers on real pair records (remeshed TOSCA cat0 -> cat3, ~9.5k vertices, all settings)."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from becos.build.record import PairRecord
from becos.core.geodesics import dijkstra_to_points
from becos.core.surface_map import SurfaceMap
from becos.evaluation.baselines import BASELINES, ZoomOutOptions, nearest_neighbour, run_baseline, wks_zoomout
from becos.evaluation.evaluate import evaluate_record, full_shape, open_predictions

SETTINGS = ("full_full", "partial_full", "partial_partial")


@pytest.fixture(scope="module")
def records(pair_record_files) -> dict[str, list[PairRecord]]:
    return {s: [PairRecord.load(p) for p in paths] for s, paths in pair_record_files.items()}


@pytest.fixture(scope="module")
def predictions(records) -> dict:
    """{(setting, method): (Prediction, seconds)} for the first record of each setting."""
    out = {}
    for setting in SETTINGS:
        for name, (function, options) in BASELINES.items():
            started = time.perf_counter()
            out[setting, name] = function(records[setting][0], options()), time.perf_counter() - started
    return out


def auc_within(record: PairRecord, pred: np.ndarray, max_threshold: float = 0.10, steps: int = 40) -> float:
    """The ``mean-0.10x40`` AUC of a Y -> X map with exact edge-graph geodesics on the full X, searched
    only up to ``max_threshold`` x sqrt(area) (errors beyond score 0 under that preset anyway), so far
    predictions cost little. Vertex-form truth; vertices without a counterpart left out (F2F/P2F)."""
    full = full_shape(record, "x")
    truth = record["corr_10"]
    ok = np.flatnonzero((truth >= 0) & (pred >= 0))
    point = SurfaceMap.from_vertex_indices(full.vertex_to_full[truth[ok]], full.mesh.faces)
    d = (
        dijkstra_to_points(
            full.mesh, full.vertex_to_full[pred[ok]], point.face, point.weights, limit=max_threshold * full.sqrt_area
        )
        / full.sqrt_area
    )
    errors = np.full(int((truth >= 0).sum()), np.inf)
    errors[np.searchsorted(np.flatnonzero(truth >= 0), ok)] = d
    thresholds = np.linspace(0.0, max_threshold, steps)
    return float(np.mean((errors[None, :] <= thresholds[:, None]).mean(axis=1)))


def test_predictions_are_valid(records, predictions):
    for (setting, name), (prediction, seconds) in predictions.items():
        record = records[setting][0]
        n_x, n_y = len(record["x_vertices"]), len(record["y_vertices"])
        pred = prediction.map
        assert pred.dtype == np.int64 and pred.shape == (n_y,)
        assert pred.min() >= -1 and pred.max() < n_x
        if setting == "partial_partial":
            assert prediction.overlap_x.shape == (n_x,) and prediction.overlap_y.shape == (n_y,)
            assert prediction.overlap_x.dtype == bool and prediction.overlap_y.dtype == bool
            np.testing.assert_array_equal(pred < 0, ~prediction.overlap_y)
        else:
            assert pred.min() >= 0 and prediction.overlap_x is None and prediction.overlap_y is None
        print(f"\n{setting} {name}: {n_y} -> {n_x} vertices in {seconds:.2f} s")  # speed: printed, not asserted


def test_zoomout_beats_the_nearest_neighbour_floor_on_an_f2f_cat_pair(records, predictions):
    record = records["full_full"][0]
    nn = auc_within(record, predictions["full_full", "nn"][0].map)
    zoomout = auc_within(record, predictions["full_full", "zoomout"][0].map)
    print(
        f"\nF2F cat0 -> cat3, AUC x100 (mean-0.10x40, edge-graph geodesics): nn {100 * nn:.1f}, "
        f"zoomout {100 * zoomout:.1f}"
    )
    assert zoomout > 0.4 and zoomout > nn + 0.15
    # the spectral method is blind to the random rotations: the other F2F record holds the same two
    # shapes rotated differently, and gets (nearly) the same map; the 3D floor does not
    other = records["full_full"][1]
    assert not np.allclose(other["y_vertices"], record["y_vertices"])
    again = wks_zoomout(other, ZoomOutOptions()).map
    same = np.mean(again == predictions["full_full", "zoomout"][0].map)
    nn_same = np.mean(nearest_neighbour(other).map == predictions["full_full", "nn"][0].map)
    print(f"same map on the re-rotated pair: zoomout {same:.3f}, nn {nn_same:.3f}")
    assert same > 0.9 and nn_same < 0.5


def test_p2p_overlap_masks(records, predictions):
    record = records["partial_partial"][0]
    rows = {
        name: evaluate_record(record, {name: predictions["partial_partial", name][0]}).rows[0] for name in BASELINES
    }
    print("\nP2P IoU x100: " + ", ".join(f"{n} {100 * r['iou']:.1f}" for n, r in rows.items()))
    for row in rows.values():
        assert row["overlap_source"] == "files" and 0.0 <= row["iou"] <= 1.0
    assert rows["zoomout"]["iou"] > rows["nn"]["iou"]


def test_run_baseline_writes_the_folder_format(records, tmp_path):
    pairs = records["partial_partial"]
    facts = run_baseline("nn", pairs, tmp_path / "nn")
    assert (
        facts["n_pairs"] == len(pairs)
        and json.loads((tmp_path / "nn" / "baseline.json").read_text())["baseline"] == "nn"
    )
    source = open_predictions(tmp_path / "nn")
    assert source.name == "nn" and sorted(source.pair_ids()) == sorted(r.pair_id for r in pairs)
    for record in pairs:
        got, expected = source.get(record.pair_id), nearest_neighbour(record)
        np.testing.assert_array_equal(got.map, expected.map)
        np.testing.assert_array_equal(got.overlap_x, expected.overlap_x)
    with pytest.raises(Exception, match="unknown baseline"):
        run_baseline("icp", pairs, tmp_path / "icp")


def test_baseline_command_on_a_store(records, store_of, tmp_path):
    """``becos baseline nn STORE --out DIR`` then ``becos evaluate``."""
    from becos.cli import main

    store = store_of(records["full_full"], "full_full")
    assert main(["baseline", "nn", str(store), "--out", str(tmp_path / "nn"), "--split", "test"]) == 0
    test_ids = [r.pair_id for r in records["full_full"] if r.meta["split"] == "test"]
    assert sorted(open_predictions(tmp_path / "nn").pair_ids()) == sorted(test_ids)
    assert (
        main(["evaluate", str(store), str(tmp_path / "nn"), "--out", str(tmp_path / "eval"), "--geodesics", "dijkstra"])
        == 0
    )
    assert (tmp_path / "eval" / "pck.png").is_file()
