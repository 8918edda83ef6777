"""The lazy route (issue #33): :class:`becos.products.store.GeodesicView` gives a pair's geodesic errors and a
shape's matrix rows on demand, equal to the geodesics export's files, with no matrix written."""

from __future__ import annotations

import csv
import pickle

import numpy as np
import psutil

from becos.cli import main


def test_the_lazy_route_gives_the_exported_distances_on_demand(small_cat_records, store_of, tmp_path, capsys):
    from becos.products.store import GeodesicView, TrainingView

    setting = "partial_partial"
    store = store_of(small_cat_records[setting], setting)
    out = tmp_path / "geodesics"
    assert main(["export-geodesics", str(store), str(out), "--splits", "test", "--layouts", "geo-lora"]) == 0
    capsys.readouterr()
    with open(out / "geodesic_dist_matrices" / "index.csv", encoding="utf-8", newline="") as fh:
        stems = {(r["pair_id"], int(r["side"])): r["stem"] for r in csv.DictReader(fh)}

    pairs = TrainingView(store, "test", keys=["corr_01", "y_vertices"])
    rng = np.random.default_rng(0)
    with GeodesicView(store, "test") as view:
        assert len(view) == len(pairs) == 2
        for i in range(len(view)):
            item = pairs[i]
            pair_id = view.pairs.benchmark().table["pair_id"].iloc[int(item["row"])]
            exported = np.load(out / "geodesic_dist_matrices" / f"{stems[(pair_id, 1)]}.npy")
            truth = item["corr_01"]
            # a known prediction: the truth, with a third of the vertices sent to random vertices of y
            predicted = truth.copy()
            moved = rng.random(len(truth)) < 1 / 3
            predicted[moved] = rng.integers(0, len(item["y_vertices"]), moved.sum())
            predicted[0] = -1
            errors = view.to_truth(i, predicted)
            valid = (truth >= 0) & (predicted >= 0)
            assert errors.dtype == np.float32 and np.isnan(errors[~valid]).all() and valid.sum() > 100
            expected = exported[truth[valid], predicted[valid]]
            assert (expected[moved[valid]] > 0).mean() > 0.9  # the moved vertices have errors to check
            # the export solved its rows in other batches of sources: equal up to float32 round-off
            np.testing.assert_allclose(errors[valid], expected, rtol=1e-5, atol=1e-6)
            assert (errors[valid & ~moved] == 0).all()
            # rows on demand: the heat method's rows, the export's symmetrised matrix up to its asymmetry
            rows = view.rows(i, "y", [0, 5, 7])
            assert rows.shape == (3, len(exported)) and rows.dtype == np.float32
            assert np.abs(rows - exported[[0, 5, 7]]).max() < 0.03 * exported.max()
            computed = view.n_computed
            view.to_truth(i, predicted)  # the same rows again: read from the mesh's cache, none solved
            assert view.n_computed == computed
        # a DataLoader worker gets a copy without the solvers, which starts its own
        copy = pickle.loads(pickle.dumps(view))
        assert copy.n_computed == 0 and len(copy) == len(view)
        workers = [p for p in psutil.Process().children() if "spawn_main" in " ".join(p.cmdline())]
        assert workers  # one solver process per full mesh kept
    gone, alive = psutil.wait_procs(workers, timeout=30)
    assert not alive  # closing the view ends them (and the solver library's memory)
