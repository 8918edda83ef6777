"""Matching metrics on real TOSCA shapes: errors, PCK/AUC presets, P2P infinity rule, overlap, left/right."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from becos.core.geodesics import GeodesicDistances
from becos.core.geometry import surface_area
from becos.core.surface_map import SurfaceMap
from becos.evaluation.metrics import (
    AUC_PRESETS,
    DEFAULT_AUC_PRESET,
    PAPER_PRESET,
    auc,
    auc_preset,
    get_preset,
    left_right_accuracy,
    overlap_f1,
    overlap_iou,
    pair_errors,
    pair_record,
    pck_curve,
    preset_name,
    summarise,
)


@pytest.fixture(scope="module")
def wolf(tosca_dir, mesh_cache):
    """X = wolf0 (4,344 vertices, full resolution), Y = wolf1 (same vertex order: the true map is the
    identity), with Dijkstra geodesics on X (exact edge lengths between neighbours)."""
    x = mesh_cache.load(tosca_dir / "wolf0.off")
    y = mesh_cache.load(tosca_dir / "wolf1.off")
    assert x.n_vertices == y.n_vertices
    return x, y, GeodesicDistances(x, "dijkstra"), np.sqrt(surface_area(x))


def a_neighbour(mesh, rng) -> np.ndarray:
    """(V,) for each vertex a random vertex sharing an edge with it."""
    edges = np.concatenate([mesh.faces[:, [0, 1]], mesh.faces[:, [1, 2]], mesh.faces[:, [2, 0]]])
    edges = np.concatenate([edges, edges[:, ::-1]])
    edges = edges[rng.permutation(len(edges))]
    out = np.full(mesh.n_vertices, -1)
    out[edges[:, 0]] = edges[:, 1]  # the last write wins: a random neighbour
    assert (out >= 0).all()
    return out


def test_ground_truth_prediction_scores_perfectly(wolf):
    x, y, geo, sqrt_area = wolf
    gt = np.arange(y.n_vertices)
    errors = pair_errors(gt, gt, geo, sqrt_area)
    assert errors.shape == (y.n_vertices,) and np.all(errors == 0.0)
    result = auc_preset(errors)
    assert result.preset == DEFAULT_AUC_PRESET == "mean-0.10x40"
    assert result.value * 100 == pytest.approx(100.0, abs=1e-12)
    assert auc_preset(errors, "ulrssm-0.10x40").value * 100 == pytest.approx(100.0, abs=1e-12)
    assert auc_preset(errors, "paper-0.00-0.99").value * 100 == pytest.approx(99.0, abs=1e-9)
    overlap = x.vertices[:, 2] > np.median(x.vertices[:, 2])  # any true overlap mask
    assert overlap_iou(overlap, overlap) * 100 == 100.0
    assert overlap_f1(overlap, overlap) * 100 == 100.0
    labels = (x.vertices[:, 0] > 0).astype(int)
    assert left_right_accuracy(gt, labels[gt], labels) * 100 == 100.0


def test_neighbour_displacement_gives_the_edge_length(wolf):
    """Mapping each vertex to a neighbour is off by exactly that edge's length (the edge is the shortest
    path: no path is shorter than the straight segment), over sqrt(area)."""
    x, y, geo, sqrt_area = wolf
    rng = np.random.default_rng(7)
    pred = a_neighbour(x, rng)
    truth = np.arange(y.n_vertices)
    expected = np.linalg.norm(x.vertices[pred] - x.vertices[truth], axis=1) / sqrt_area
    errors = pair_errors(pred, truth, geo, sqrt_area)
    np.testing.assert_allclose(errors, expected, rtol=1e-12)
    print(f"\nneighbour displacement on wolf0: error {expected.min():.4f}..{expected.max():.4f} x sqrt(area)")
    # the PCK curve steps from 0 to 1 across exactly those values
    assert pck_curve(errors, [expected.min() * 0.999])[0] == 0.0
    assert pck_curve(errors, [expected.max()])[0] == 1.0
    # heat geodesics agree within their smoothing near the source
    some = rng.choice(x.n_vertices, 400, replace=False)
    heat = pair_errors(pred[some], truth[some], GeodesicDistances(x, "heat"), sqrt_area)
    print(f"heat / exact at one edge: median {np.median(heat / expected[some]):.3f}")
    assert 0.8 < np.median(heat / expected[some]) < 1.2

    # true points at edge midpoints, predicted at one end of the edge: half the edge length
    faces = np.arange(0, x.n_faces, 3)
    corner = rng.integers(0, 3, len(faces))
    weights = np.zeros((len(faces), 3))
    weights[np.arange(len(faces)), corner] = 0.5
    weights[np.arange(len(faces)), (corner + 1) % 3] = 0.5
    pred = x.faces[faces, corner]
    other = x.faces[faces, (corner + 1) % 3]
    half = 0.5 * np.linalg.norm(x.vertices[pred] - x.vertices[other], axis=1) / sqrt_area
    np.testing.assert_allclose(pair_errors(pred, faces, geo, sqrt_area, gt_weights=weights), half, rtol=1e-12)
    np.testing.assert_allclose(pair_errors(pred, SurfaceMap(faces, weights), geo, sqrt_area), half, rtol=1e-12)


def test_p2p_infinity_rule_on_a_hand_built_case(wolf):
    x, _, geo, sqrt_area = wolf
    a, b = 100, int(x.faces[x.faces[:, 0] == 100][0, 1])  # two neighbouring vertices of wolf0
    #              ok   missed  spurious  both-none  ok   off by one edge
    truth = np.array([a, 11, -1, -1, 12, a])
    pred = np.array([a, -1, 13, -1, 12, b])
    errors = pair_errors(pred, truth, geo, sqrt_area)
    edge = np.linalg.norm(x.vertices[a] - x.vertices[b]) / sqrt_area
    np.testing.assert_array_equal(np.isnan(errors), [False, False, False, True, False, False])
    np.testing.assert_array_equal(np.isinf(errors), [False, True, True, False, False, False])
    np.testing.assert_allclose(errors[[0, 4, 5]], [0.0, 0.0, edge], rtol=1e-12)
    # 5 vertices count; the two infinite ones are never correct
    pck = pck_curve(errors, [0.0, edge, 1e9])
    np.testing.assert_allclose(pck, [2 / 5, 3 / 5, 3 / 5])
    record = pair_record(errors, presets=("mean-0.10x40", "paper-0.00-0.99"))
    assert record["n_scored"] == 5 and record["n_infinite"] == 2
    assert record["auc_preset"] == "mean-0.10x40"
    assert record["auc"] == record["auc_mean-0.10x40"] <= 3 / 5

    # F2F/P2F rule: vertices without a true counterpart are excluded whatever the prediction
    lenient = pair_errors(pred, truth, geo, sqrt_area, p2p=False)
    np.testing.assert_array_equal(np.isnan(lenient), [False, False, True, True, False, False])
    np.testing.assert_array_equal(np.isinf(lenient), [False, True, False, False, False, False])
    assert record["mean_error"] == pytest.approx(edge / 3)

    # left/right: the two failures count 0, the correctly unmatched vertex is excluded
    labels_x = np.zeros(x.n_vertices, int)
    labels_x[[a, 12]] = 1
    true_labels = np.array([1, 0, 0, 0, 1, 1])
    gt_matched = truth >= 0
    # scored: 0 (right), 1 (missed), 2 (spurious), 4 (right), 5 (b has label 0: wrong)
    assert left_right_accuracy(pred, true_labels, labels_x, gt_matched) == pytest.approx(2 / 5)
    unlabelled = true_labels.copy()
    unlabelled[5] = -1
    assert left_right_accuracy(pred, unlabelled, labels_x, gt_matched) == pytest.approx(2 / 4)


def test_partial_x_errors_are_measured_on_the_full_shape(wolf):
    x, _, geo, sqrt_area = wolf
    rng = np.random.default_rng(8)
    partial2full = np.flatnonzero(x.vertices[:, 2] > np.median(x.vertices[:, 2]))
    truth_partial = rng.integers(0, len(partial2full), 300)
    truth_partial[:20] = -1
    pred_partial = rng.integers(0, len(partial2full), 300)
    pred_partial[10:30] = -1
    errors = pair_errors(pred_partial, truth_partial, geo, sqrt_area, x_to_full=partial2full)
    both = (pred_partial >= 0) & (truth_partial >= 0)
    rows = geo.from_vertices(partial2full[pred_partial[both]])
    expected = rows[np.arange(both.sum()), partial2full[truth_partial[both]]] / sqrt_area
    np.testing.assert_allclose(errors[both], expected, rtol=1e-12)
    assert np.isnan(errors[10:20]).all() and np.isinf(errors[:10]).all() and np.isinf(errors[20:30]).all()


def test_the_auc_presets_differ_as_expected():
    n = 1000
    # every error 0.03: thresholds k*0.1/39 reach it from k = 12 -> mean 28/40; ULRSSM trapezoid
    # (27 + 1/2) / 39; paper thresholds reach it at 0.03 exactly -> 0.005 (the step 0.02..0.03) + 0.96
    errors = np.full(n, 0.03)
    assert auc_preset(errors, "mean-0.10x40").value == pytest.approx(28 / 40)
    assert auc_preset(errors, "ulrssm-0.10x40").value == pytest.approx(27.5 / 39)
    assert auc_preset(errors, PAPER_PRESET).value == pytest.approx(0.965)
    # every error 0.5: beyond the [0, 0.1] range (0), halfway in the paper's (0.005 + 0.49)
    errors = np.full(n, 0.5)
    assert auc_preset(errors, "mean-0.10x40").value == 0.0
    assert auc_preset(errors, "ulrssm-0.10x40").value == 0.0
    assert auc_preset(errors, PAPER_PRESET).value == pytest.approx(0.495)
    # infinite errors score 0 under every preset; NaN (excluded) entries change nothing
    errors = np.concatenate([np.zeros(n), np.full(n, np.inf), np.full(n, np.nan)])
    assert auc_preset(errors, "mean-0.10x40").value == pytest.approx(0.5)
    assert auc_preset(errors, "ulrssm-0.10x40").value == pytest.approx(0.5)
    assert auc_preset(errors, PAPER_PRESET).value == pytest.approx(0.495)
    # the generic function's defaults are the default preset; the trapezoid rule is a different number
    rng = np.random.default_rng(9)
    errors = rng.exponential(0.03, n)
    assert auc(errors) == auc_preset(errors).value
    assert auc(errors, rule="trapezoid-normalised") == auc_preset(errors, "ulrssm-0.10x40").value
    assert auc(errors, rule="trapezoid-normalised") != pytest.approx(auc(errors), abs=1e-6)
    assert set(AUC_PRESETS) == {"mean-0.10x40", "ulrssm-0.10x40", "paper-0.00-0.99"}
    # parametrised names: T and the number of steps are in the name
    assert preset_name("mean", 0.1, 40) == "mean-0.10x40"
    assert preset_name("ulrssm", 0.125, 50) == "ulrssm-0.125x50"
    wide = get_preset("mean-0.25x60")
    assert len(wide.thresholds) == 60 and wide.thresholds[-1] == 0.25 and wide.rule == "mean"
    assert auc_preset(errors, "mean-0.25x60").value == auc(errors, 0.25, 60)
    assert auc_preset(errors, "mean-0.25x60").value > auc(errors)  # a wider range forgives more
    for bad in ("princeton", "mean-0.1", "mean-0x40", "median-0.10x40", "mean-0.10x1"):
        with pytest.raises(ValueError, match="unknown AUC preset"):
            auc_preset(errors, bad)
    assert np.isnan(auc_preset(np.full(3, np.nan)).value)


def test_pck_is_monotone_on_real_errors(wolf):
    x, _, geo, sqrt_area = wolf
    rng = np.random.default_rng(10)
    truth = np.arange(x.n_vertices)
    pred = truth.copy()
    for _ in range(6):  # a random walk of up to 6 edges: errors spread over several rings
        step = rng.random(x.n_vertices) < 0.6
        pred[step] = a_neighbour(x, rng)[pred[step]]
    pred[rng.random(x.n_vertices) < 0.05] = -1  # missed vertices: infinite errors
    errors = pair_errors(pred, truth, geo, sqrt_area)
    thresholds = np.linspace(0, 0.2, 200)
    pck = pck_curve(errors, thresholds)
    assert (np.diff(pck) >= 0).all()
    assert pck[0] == pytest.approx(np.mean(errors == 0))
    assert pck[-1] <= 1 - np.mean(np.isinf(errors)) + 1e-12
    assert 0 < auc(errors) < 1


def test_overlap_scores():
    true = np.zeros(10, bool)
    true[:6] = True
    pred = np.zeros(10, bool)
    pred[3:8] = True  # 3 shared, 8 in the union
    assert overlap_iou(pred, true) == pytest.approx(3 / 8)
    assert overlap_f1(pred, true) == pytest.approx(2 * 3 / (5 + 6))
    scores = np.where(pred, 0.9, 0.1)
    assert overlap_iou(scores, true) == overlap_iou(pred, true)
    assert overlap_iou(np.zeros(4, bool), np.zeros(4, bool)) == 1.0
    assert overlap_f1(np.zeros(4, bool), np.ones(4, bool)) == 0.0
    with pytest.raises(ValueError, match="differ in length"):
        overlap_iou(pred, true[:5])


def test_left_right_on_the_real_horse_labels(becos_code, tosca_dir, mesh_cache):
    """horse0's shipped chirality labels; horse5 shares its vertex order, so the truth is the identity.
    A left/right mirrored prediction must score badly."""
    from scipy.spatial import cKDTree

    labels = np.loadtxt(becos_code / "precomputed_chirality_templates" / "tosca_horse0.txt", dtype=int)
    x = mesh_cache.load(tosca_dir / "horse0.off")
    assert len(labels) == x.n_vertices and set(np.unique(labels)) == {0, 1}
    truth = np.arange(x.n_vertices)
    assert left_right_accuracy(truth, labels[truth], labels) == 1.0
    mirrored = x.vertices * [-1.0, 1.0, 1.0]  # label 1 lies on +x in the file frame too
    pred = cKDTree(x.vertices).query(mirrored)[1]
    score = left_right_accuracy(pred, labels[truth], labels)
    print(f"\nhorse0 mirrored prediction: left/right accuracy {score:.3f}")
    assert score < 0.2


def test_summarise_means_per_pair_then_over_pairs(wolf):
    x, _, geo, sqrt_area = wolf
    rng = np.random.default_rng(11)
    truth = np.arange(x.n_vertices)
    rows = []
    for k, (split, category) in enumerate(
        [("test", "four-legged"), ("test", "four-legged"), ("val", "four-legged"), ("test", "human")]
    ):
        pred = truth.copy()
        moved = rng.random(x.n_vertices) < 0.2 * (k + 1)
        pred[moved] = a_neighbour(x, rng)[pred[moved]]
        errors = pair_errors(pred, truth, geo, sqrt_area)
        for preset in AUC_PRESETS:
            rows.append(
                {
                    "method": "shifted",
                    "split": split,
                    "category": category,
                    "dataset": "tosca",
                    "pair": k,
                    **pair_record(errors, presets=(preset,)),
                }
            )
    per_pair = pd.DataFrame(rows)
    table = summarise(per_pair)
    assert set(table["grouping"]) == {"all", "split", "category", "dataset"}
    assert "pair" in table.columns  # numeric column, averaged like any other
    for preset in AUC_PRESETS:
        mine = per_pair[per_pair["auc_preset"] == preset]
        overall = table[(table["auc_preset"] == preset) & (table["grouping"] == "all")]
        assert len(overall) == 1 and overall["n_pairs"].item() == 4
        assert overall["auc"].item() == pytest.approx(mine["auc"].mean())
        test_row = table[(table["auc_preset"] == preset) & (table["grouping"] == "split") & (table["group"] == "test")]
        assert test_row["n_pairs"].item() == 3
        assert test_row["auc"].item() == pytest.approx(mine[mine["split"] == "test"]["auc"].mean())
        human = table[(table["auc_preset"] == preset) & (table["group"] == "human")]
        assert human["mean_error"].item() == pytest.approx(mine["mean_error"].iloc[3])
    # more displaced pairs score lower, and the presets were never averaged together
    default = per_pair[per_pair["auc_preset"] == DEFAULT_AUC_PRESET]["auc"].to_numpy()
    assert (np.diff(default) < 0).all()
    assert len(table) == len(AUC_PRESETS) * (1 + 2 + 2 + 1)
