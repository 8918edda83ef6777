"""Scoring predictions on real pair records (remeshed TOSCA cat0 -> cat3, all three settings)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from becos.build.record import PairRecord
from becos.core.geodesics import GeodesicsCache
from becos.evaluation.evaluate import (
    Prediction,
    PredictionError,
    evaluate_record,
    evaluate_records,
    full_shape,
    open_predictions,
    summary_table,
    write_evaluation,
    write_prediction,
)
from becos.evaluation.metrics import DEFAULT_AUC_PRESET, PAPER_PRESET

SETTINGS = ("full_full", "partial_full", "partial_partial")


def label_left_right(record: PairRecord) -> PairRecord:
    """Left/right labels set by hand: X split by a vertical plane through its centroid (label 0/1, a
    band around the plane left unlabelled, -1); each Y vertex gets the label of its true X vertex, or
    its own side's when it has none. Returns a copy."""
    a = dict(record.arrays)
    x = a["x_vertices"] - a["x_vertices"].mean(axis=0)
    side = x[:, 0]
    labels_x = np.where(side > 0, 1, 0).astype(np.int8)
    labels_x[np.abs(side) < 0.02 * np.ptp(side)] = -1
    truth = a["corr_10"]
    y = a["y_vertices"] - a["y_vertices"].mean(axis=0)
    labels_y = np.where(truth >= 0, labels_x[np.maximum(truth, 0)], (y[:, 0] > 0).astype(np.int8)).astype(np.int8)
    a["x_annotation"], a["y_annotation"] = labels_x, labels_y
    return PairRecord(a, dict(record.meta))


@pytest.fixture(scope="module")
def records(pair_record_files) -> dict[str, list[PairRecord]]:
    return {s: [PairRecord.load(p) for p in paths] for s, paths in pair_record_files.items()}


@pytest.fixture(scope="module")
def geodesics() -> GeodesicsCache:
    return GeodesicsCache("heat")


def ground_truth(record: PairRecord) -> Prediction:
    return Prediction(record["corr_10"].copy(), record["x_overlap_mask"].copy(), record["y_overlap_mask"].copy())


def a_neighbour(faces: np.ndarray, n_vertices: int, rng) -> np.ndarray:
    """(V,) for each vertex a random vertex sharing an edge with it (-1 for unreferenced vertices)."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges = np.concatenate([edges, edges[:, ::-1]])
    edges = edges[rng.permutation(len(edges))]
    out = np.full(n_vertices, -1)
    out[edges[:, 0]] = edges[:, 1]
    return out


def test_full_shapes_are_consistent_with_the_record(records, tosca_pair_inputs):
    x, y, _, _ = tosca_pair_inputs
    for setting, pair in records.items():
        for record in pair:
            for s, remeshed in (("x", x.mesh), ("y", y.mesh)):
                full = full_shape(record, s)  # raises if the full shape is not the partial's parent
                partial = bool((record[f"{s}_full_to_partial"] < 0).any())
                assert full.mesh.n_vertices == len(record[f"{s}_full_to_partial"]) == remeshed.n_vertices
                assert (full.mesh.n_vertices > len(record[f"{s}_vertices"])) == partial
                np.testing.assert_array_equal(full.mesh.faces, remeshed.faces)
                assert full.sqrt_area == pytest.approx(float(record[f"{s}_full_sqrt_area"]))
    # a partial shape whose full shape is missing cannot be scored
    a = dict(records["partial_partial"][0].arrays)
    a["x_full_vertices"], a["x_full_faces"] = np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    with pytest.raises(ValueError, match="no x_full_vertices"):
        full_shape(PairRecord(a, records["partial_partial"][0].meta), "x")


@pytest.mark.parametrize("setting", SETTINGS)
def test_ground_truth_scores_100(setting, records, geodesics):
    for record in records[setting]:
        record = label_left_right(record)
        before = geodesics.n_computed
        row = evaluate_record(record, {"truth": ground_truth(record)}, geodesics=geodesics).rows[0]
        assert geodesics.n_computed == before  # a prediction equal to the true vertex needs no geodesic row
        assert row["auc_preset"] == DEFAULT_AUC_PRESET == "mean-0.10x40"
        assert row["auc"] * 100 == 100.0 and row[f"auc_{DEFAULT_AUC_PRESET}"] * 100 == 100.0
        assert row[f"auc_{PAPER_PRESET}"] * 100 == pytest.approx(99.0)  # that preset's ceiling
        assert row["iou"] * 100 == 100.0 and row["f1"] * 100 == 100.0
        assert row["iou_x"] == row["iou_y"] == 1.0 and row["overlap_source"] == "files"
        assert row["left_right"] * 100 == 100.0
        assert row["n_infinite"] == 0 and row["mean_error"] == 0.0
        n_unmatched = int((record["corr_10"] < 0).sum())
        assert row["n_scored"] == len(record["y_vertices"]) - n_unmatched
        if setting == "partial_partial":
            assert n_unmatched > 0  # P2P: correctly unmatched vertices are excluded, not counted right


def test_ground_truth_other_direction_and_exact_points(records):
    record = label_left_right(records["partial_partial"][0])
    xy = Prediction(record["corr_01"].copy(), record["x_overlap_mask"], record["y_overlap_mask"])
    row = evaluate_record(record, {"truth": xy}, direction="xy").rows[0]
    assert row["auc"] == 1.0 and row["iou"] == 1.0 and row["n_vertices"] == len(record["x_vertices"])
    with pytest.raises(PredictionError, match="entries"):  # a Y -> X map given as X -> Y
        evaluate_record(record, {"truth": ground_truth(record)}, direction="xy")

    # against the exact barycentric points the vertex-form truth is off by its rounding: with exact
    # edge-graph distances that is sum_k w_k |v* - corner_k| where the rounded vertex v* is a corner of the
    # holding face (neighbouring corners: one edge each); elsewhere it is a neighbour's far corner
    row, errors = (lambda r: (r.rows[0], r.errors["truth"]))(
        evaluate_record(record, {"truth": ground_truth(record)}, truth="point", geodesics=GeodesicsCache("dijkstra"))
    )
    full = full_shape(record, "x")
    face, weights = record["corr_10_face"], record["corr_10_weights"]
    ok = face >= 0
    corners = full.mesh.faces[full.face_to_full[face[ok]]]
    rounded = full.vertex_to_full[record["corr_10"][ok]]
    on_face = (corners == rounded[:, None]).any(axis=1)
    assert on_face.mean() > 0.5 and not on_face.all()  # most points round to a corner, some to a far corner
    rounding = (
        np.einsum(
            "nk,nk->n",
            weights[ok][on_face],
            np.linalg.norm(
                full.mesh.vertices[corners[on_face]] - full.mesh.vertices[rounded[on_face]][:, None], axis=2
            ),
        )
        / full.sqrt_area
    )
    errors = errors[ok][on_face]
    np.testing.assert_allclose(errors, rounding, rtol=1e-9, atol=1e-15)
    print(
        f"\nvertex truth vs exact points: AUC x100 {row['auc'] * 100:.2f} ({DEFAULT_AUC_PRESET}), "
        f"{row[f'auc_{PAPER_PRESET}'] * 100:.2f} (paper); mean rounding {rounding.mean():.4f} x sqrt(area)"
    )
    assert 0.8 < row["auc"] < 1.0 and rounding.max() < 0.05  # at most about one edge (~0.01-0.03)


@pytest.mark.parametrize("setting", ["partial_full", "partial_partial"])
def test_displaced_prediction_gives_the_geodesic_distance(setting, records, geodesics):
    """Move some predictions away from the true vertex (one edge, or a random walk of 4 edges on X's
    record mesh); the error must be the geodesic distance on the FULL X between the two vertices,
    computed here independently (potpourri3d's heat solver on the full mesh; the edge length for one
    edge, which is the geodesic between neighbours), over sqrt(full area)."""
    import potpourri3d as pp3d

    record = records[setting][1]
    rng = np.random.default_rng(3)
    truth = record["corr_10"]
    full = full_shape(record, "x")
    n_x = len(record["x_vertices"])
    chosen = rng.choice(np.flatnonzero(truth >= 0), 120, replace=False)
    one, walk = chosen[:60], chosen[60:]
    pred = truth.copy()
    pred[one] = a_neighbour(record["x_faces"], n_x, rng)[truth[one]]
    for _ in range(4):
        pred[walk] = a_neighbour(record["x_faces"], n_x, rng)[pred[walk]]
    assert (pred[one] >= 0).all() and (pred[walk] >= 0).all()

    before = geodesics.n_computed
    result = evaluate_record(record, {"moved": Prediction(pred)}, geodesics=geodesics)
    errors = result.errors["moved"]
    assert geodesics.n_computed - before <= len(np.unique(truth[pred != truth]))  # only the rows it needs
    unchanged = np.setdiff1d(np.flatnonzero(truth >= 0), chosen)
    assert np.all(errors[unchanged] == 0.0)

    to_full = full.vertex_to_full
    solver = pp3d.MeshHeatMethodDistanceSolver(full.mesh.vertices, full.mesh.faces)
    independent = np.array([solver.compute_distance(int(to_full[truth[i]]))[to_full[pred[i]]] for i in chosen])
    np.testing.assert_allclose(errors[chosen], independent / full.sqrt_area, rtol=1e-9)
    edge = np.linalg.norm(full.mesh.vertices[to_full[pred[one]]] - full.mesh.vertices[to_full[truth[one]]], axis=1)
    ratio = errors[one] / (edge / full.sqrt_area)
    print(
        f"\n{setting}: heat / one edge: median {np.median(ratio):.3f}; 4-edge walk errors "
        f"{np.percentile(errors[walk], [0, 50, 100]).round(4)} x sqrt(area)"
    )
    assert 0.8 < np.median(ratio) < 1.2
    assert np.median(errors[walk]) > 1.5 * np.median(errors[one])

    # exact edge-graph distances: exactly the edge length for one edge
    exact = evaluate_record(record, {"moved": Prediction(pred)}, geodesics=GeodesicsCache("dijkstra")).errors["moved"]
    np.testing.assert_allclose(exact[one], edge / full.sqrt_area, rtol=1e-9)
    row = result.rows[0]
    assert row["n_infinite"] == 0 and 0.9 < row["auc"] < 1.0


def test_p2p_infinity_rule_on_a_hand_built_case(records, geodesics):
    record = label_left_right(records["partial_partial"][0])
    truth = record["corr_10"]
    matched, unmatched = np.flatnonzero(truth >= 0), np.flatnonzero(truth < 0)
    pred = truth.copy()
    missed = matched[:25]  # unmatched though they have a counterpart -> inf
    spurious = unmatched[:15]  # matched though they have none -> inf
    pred[missed] = -1
    pred[spurious] = 0
    result = evaluate_record(record, {"p": Prediction(pred)}, geodesics=geodesics)
    errors, row = result.errors["p"], result.rows[0]
    assert np.isinf(errors[missed]).all() and np.isinf(errors[spurious]).all()
    assert np.isnan(errors[unmatched[15:]]).all()  # correctly unmatched: excluded
    assert np.all(errors[matched[25:]] == 0.0)
    n_scored = len(truth) - (len(unmatched) - 15)
    assert row["n_scored"] == n_scored and row["n_infinite"] == 40 and row["n_excluded"] == len(unmatched) - 15
    assert row["auc"] == pytest.approx(1 - 40 / n_scored)  # the failures are never correct
    # left/right: the failures count 0 (where labelled), the correctly unmatched are left out
    labels = record["y_annotation"]
    scored = (labels >= 0) & ((pred >= 0) | (truth >= 0))
    failures = np.isin(np.arange(len(truth)), np.concatenate([missed, spurious])) & scored
    assert row["left_right"] == pytest.approx(1 - failures.sum() / scored.sum())
    # the predicted Y mask implied by the map (no files): spurious in, missed out
    assert row["overlap_source"] == "map" and np.isnan(row["iou_x"])
    true_y = record["y_overlap_mask"]
    assert row["iou_y"] == pytest.approx(((pred >= 0) & true_y).sum() / ((pred >= 0) | true_y).sum())

    # F2F/P2F rule on the same hand-built map: without a true counterpart the vertex is excluded
    p2f = PairRecord(dict(record.arrays), {**record.meta, "setting": "partial_full"})
    lenient = evaluate_record(p2f, {"p": Prediction(pred)}, geodesics=geodesics).errors["p"]
    assert np.isnan(lenient[unmatched]).all() and np.isinf(lenient[missed]).all()


def test_prediction_formats_tables_and_plot(records, geodesics, tmp_path):
    import zarr

    pairs = [label_left_right(r) for r in records["partial_partial"]]
    rng = np.random.default_rng(5)
    folders = {"truth": tmp_path / "truth", "noisy": tmp_path / "noisy"}
    store = zarr.open_group(str(tmp_path / "noisy-z.zarr"), mode="w")
    for record in pairs:
        gt = ground_truth(record)
        write_prediction(folders["truth"], record.pair_id, gt)
        noisy = gt.map.copy()
        moved = np.flatnonzero((noisy >= 0) & (rng.random(len(noisy)) < 0.3))
        noisy[moved] = a_neighbour(record["x_faces"], len(record["x_vertices"]), rng)[noisy[moved]]
        scores = np.where(gt.overlap_y, 0.9, 0.2)
        scores[np.flatnonzero(~gt.overlap_y)[:40]] = 0.7  # float scores: overlap where > 0.5
        prediction = Prediction(noisy, overlap_y=scores > 0.5)
        write_prediction(folders["noisy"], record.pair_id, prediction)
        store.create_array(record.pair_id, data=noisy)
        store.create_array(f"{record.pair_id}_overlap_y", data=scores)
    sources = {name: open_predictions(path) for name, path in folders.items()}
    assert sources["noisy"].name == "noisy" and sorted(sources["noisy"].pair_ids()) == sorted(r.pair_id for r in pairs)
    zsource = open_predictions(tmp_path / "noisy-z.zarr")
    assert zsource.name == "noisy-z" and zsource.pair_ids() == sources["noisy"].pair_ids()
    got = zsource.get(pairs[0].pair_id)
    assert got.overlap_y.dtype == bool and got.overlap_x is None
    np.testing.assert_array_equal(got.map, sources["noisy"].get(pairs[0].pair_id).map)

    sources["noisy-z"] = zsource
    evaluation = evaluate_records([(r, None) for r in pairs], sources, geodesics=geodesics)
    per_pair = evaluation.per_pair
    assert len(per_pair) == 3 * len(pairs) and set(per_pair["auc_preset"]) == {DEFAULT_AUC_PRESET}
    by = per_pair.set_index(["method", "pair_id"])
    for pid in (r.pair_id for r in pairs):
        assert by.loc[("truth", pid), "auc"] == 1.0
        assert by.loc[("noisy", pid), "auc"] == by.loc[("noisy-z", pid), "auc"] < 1.0
        assert by.loc[("noisy", pid), "iou_y"] == by.loc[("noisy-z", pid), "iou_y"] < 1.0

    paths = write_evaluation(evaluation, tmp_path / "out", title="partial_partial test")
    summary = pd.read_csv(paths["summary"])
    assert f"auc_x100[{PAPER_PRESET}]" in summary.columns and f"auc_x100[{DEFAULT_AUC_PRESET}]" in summary.columns
    overall = summary[summary["grouping"] == "all"].set_index("method")
    assert overall.loc["truth", f"auc_x100[{DEFAULT_AUC_PRESET}]"] == 100.0
    assert overall.loc["truth", f"auc_x100[{PAPER_PRESET}]"] == pytest.approx(99.0)
    assert overall.loc["truth", "miou_x100"] == 100.0 and overall.loc["truth", "left_right_x100"] == 100.0
    expected = 100 * per_pair[per_pair["method"] == "noisy"][f"auc_{PAPER_PRESET}"].mean()
    assert overall.loc["noisy", f"auc_x100[{PAPER_PRESET}]"] == pytest.approx(expected)
    assert set(summary["grouping"]) == {"all", "split", "category", "dataset"}
    assert PAPER_PRESET in paths["markdown"].read_text()
    assert paths["plot"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    curves = pd.read_csv(paths["curves"])
    for _, c in curves.groupby("method"):
        assert (np.diff(c["pck"]) >= 0).all()
    assert curves[curves["method"] == "truth"]["pck"].min() == 1.0
    meta = json.loads(paths["meta"].read_text())
    assert meta["preset"] == DEFAULT_AUC_PRESET and meta["truth"] == "vertex"

    # summary of a per-pair table alone (e.g. several runs concatenated) is the same
    pd.testing.assert_frame_equal(
        summary_table(per_pair, DEFAULT_AUC_PRESET).reset_index(drop=True), summary, check_dtype=False
    )


def test_bad_predictions_are_reported(records, tmp_path):
    record = records["full_full"][0]
    folder = tmp_path / "bad"
    folder.mkdir()
    np.save(folder / f"{record.pair_id}.npy", np.zeros((3, 2)))
    with pytest.raises(PredictionError, match="1-D integer array"):
        open_predictions(folder).get(record.pair_id)
    np.save(folder / f"{record.pair_id}.npy", np.zeros(5, dtype=np.int64))
    with pytest.raises(PredictionError, match="has 5 entries"):
        evaluate_records([(record, None)], {"bad": open_predictions(folder)})
    np.save(folder / f"{record.pair_id}.npy", np.full(len(record["y_vertices"]), len(record["x_vertices"])))
    with pytest.raises(PredictionError, match="must lie in"):
        evaluate_records([(record, None)], {"bad": open_predictions(folder)})
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(PredictionError, match="no prediction for pair"):
        evaluate_records([(record, None)], {"empty": open_predictions(empty)})
    evaluation = evaluate_records([(record, None)], {"empty": open_predictions(empty)}, allow_missing=True)
    assert evaluation.per_pair.empty and evaluation.meta["missing"] == {"empty": [record.pair_id]}
    with pytest.raises(PredictionError, match="not found"):
        open_predictions(tmp_path / "nowhere")


def test_store_level_evaluate_command(records, store_of, tmp_path):
    """``becos evaluate STORE PRED --out DIR`` end to end."""
    from becos.cli import main
    from becos.products.store import open_benchmark

    store = store_of([label_left_right(r) for r in records["partial_full"]], "partial_full")
    bench = open_benchmark(store)
    preds = tmp_path / "truth"
    for record in bench.records():
        write_prediction(preds, record.pair_id, Prediction(record["corr_10"]))
    out = tmp_path / "eval"
    assert main(["evaluate", str(store), str(preds), "--out", str(out), "--split", "all"]) == 0
    summary = pd.read_csv(out / "summary.csv")
    overall = summary[summary["grouping"] == "all"]
    assert overall["n_pairs"].item() == len(records["partial_full"])
    assert overall[f"auc_x100[{DEFAULT_AUC_PRESET}]"].item() == 100.0
    assert overall["left_right_x100"].item() == 100.0
    assert set(summary[summary["grouping"] == "split"]["group"]) == {"train", "test"}
    assert main(["evaluate", str(store), str(preds), "--out", str(out), "--split", "nope"]) == 2
