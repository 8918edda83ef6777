"""What the loaders read from the geodesics export, against float64, and the lazy route (issue 33): prints JSON.

On a finished run with ``exports.geodesics`` (e.g. ``benchmarks/geodesics_export.py``'s workdir: pass
its ``run`` folder), for every test pair of ``--setting``:

- a known prediction: the ground truth ``corr_01`` with a third of shape x's vertices sent to random
  vertices of y (seeded);
- ``float64``: its geodesic errors from float64 heat-method rows (the solver's output before the
  export rounds it to float32) against the errors read from the exported float32 geo-lora file: the
  largest difference of an error and of the mean error (the geodesic error metric), relative;
- geo-lora: ``np.load(geodesic_dist_matrices/<stem>.npy)`` as its loader does; DeepShapeMatchingKit:
  its cache lookup (``np.load(dist/<sha1>_0.npz, allow_pickle=True)["result"]``, the lookup transcribed
  in ``tests/test_geodesic_export.py``) divided by the sqrt-area: equal to geo-lora's file;
- ``--ulrssm OUT``: ``becos export-ulrssm --geodesics --splits test`` into OUT, then each pair's
  ``dist/<k>.mat`` by ULRSSM's ``scipy.io.loadmat(...)["dist"]``: equal to geo-lora's file;
- the lazy route: :meth:`becos.products.store.GeodesicView.to_truth` of the same prediction, its wall seconds
  per pair (the first pair of a mesh pays the solver's start and factorisation) and its largest
  difference from the exported errors.

Usage::

    python benchmarks/geodesic_loaders.py RUN [--setting full_full] [--ulrssm /tmp/ulrssm-out]
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))
from test_geodesic_export import dsmk_cached_result  # noqa: E402  (DeepShapeMatchingKit's lookup, transcribed)


def main() -> None:
    from becos.core.geodesics import HeatDistanceSolver, shape_key
    from becos.core.mesh import TriMesh
    from becos.products.export import dsmk_cache_name, full_shape
    from becos.products.store import GeodesicView, open_benchmark

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="the workflow's working folder (results/ below it)")
    parser.add_argument("--setting", default="full_full")
    parser.add_argument("--ulrssm", type=Path, help="also export ULRSSM's dist files here and read them")
    args = parser.parse_args()
    results = args.run / "results" / args.setting
    store, geodesics = results / "benchmark.zarr", results / "geodesics"
    with open(geodesics / "geodesic_dist_matrices" / "index.csv", encoding="utf-8", newline="") as fh:
        index = {(r["pair_id"], int(r["side"])): r for r in csv.DictReader(fh)}
    bench = open_benchmark(store)
    rng = np.random.default_rng(0)
    out = {"setting": args.setting, "pairs": []}
    ulrssm_numbers = {}
    if args.ulrssm:
        shutil.rmtree(args.ulrssm, ignore_errors=True)
        started = time.monotonic()
        cmd = [
            sys.executable,
            "-m",
            "becos",
            "export-ulrssm",
            str(store),
            str(args.ulrssm),
            "--geodesics",
            "--splits",
            "test",
            "--jobs",
            "2",
        ]
        subprocess.run(cmd, check=True, capture_output=True)
        out["ulrssm_export_seconds"] = round(time.monotonic() - started, 1)
        with open(args.ulrssm / "ids.csv", encoding="utf-8", newline="") as fh:
            ulrssm_numbers = {r["pair_id"]: r["index"] for r in csv.DictReader(fh) if r["split"] == "test"}
    with GeodesicView(store, "test") as view:
        meshes_seen = set()
        for i in range(len(view)):
            row = int(view.pairs.rows[i])
            record = bench.read_rows(row, row + 1).record(0)
            truth = np.asarray(record["corr_01"], dtype=np.int64)
            n_y = len(record["y_vertices"])
            predicted = truth.copy()
            moved = rng.random(len(truth)) < 1 / 3
            predicted[moved] = rng.integers(0, n_y, moved.sum())
            valid = (truth >= 0) & (predicted >= 0)
            entry = index[(record.pair_id, 1)]
            geolora = np.load(geodesics / "geodesic_dist_matrices" / f"{entry['stem']}.npy")  # as geo-lora reads it
            exported = geolora[truth[valid], predicted[valid]]
            scale = float(entry["sqrt_area"])
            # float64 rows of the same solver, symmetrised and normalised as the export, before any float32
            fv, ff = full_shape(record, "y")
            p2f = np.asarray(record["y_partial_to_full"], dtype=np.int64)
            a, b = p2f[truth[valid]], p2f[predicted[valid]]
            sources, inverse = np.unique(np.concatenate([a, b]), return_inverse=True)
            solver = HeatDistanceSolver(fv, ff)
            rows = np.concatenate(
                [
                    solver.distances(sources[s : s + solver.block_size()])
                    for s in range(0, len(sources), solver.block_size())
                ]
            )
            ia, ib = inverse[: len(a)], inverse[len(a) :]
            exact = 0.5 * (rows[ia, b] + rows[ib, a]) / scale
            exact[a == b] = 0.0
            del rows, solver
            started = time.monotonic()
            lazy = view.to_truth(i, predicted)[valid]
            lazy_seconds = time.monotonic() - started
            key = shape_key(TriMesh(np.asarray(fv, dtype=np.float64), np.asarray(ff, dtype=np.int64)))
            first = key not in meshes_seen
            meshes_seen.add(key)
            pair = {
                "pair_id": record.pair_id,
                "n_x": len(truth),
                "n_y": n_y,
                "mean_error_float64": float(exact.mean()),
                "mean_error_exported": float(exported.astype(np.float64).mean()),
                "max_abs_error_difference": float(np.abs(exported - exact).max()),
                "lazy_seconds": round(lazy_seconds, 2),
                "lazy_first_use_of_mesh": first,
                "lazy_max_abs_difference": float(np.abs(lazy - exported).max()),
            }
            pair["mean_error_relative_difference"] = abs(pair["mean_error_exported"] / pair["mean_error_float64"] - 1)
            # DeepShapeMatchingKit: the file of each shape it gives dist to (shape 0 always)
            for side, s in ((0, "x"), (1, "y")):
                dsmk_dir = geodesics / "dsmk" / "test" / "dist"
                if not index[(record.pair_id, side)]["dsmk_file"]:
                    continue
                name = dsmk_cache_name(record[f"{s}_vertices"], record[f"{s}_faces"])
                assert (dsmk_dir / name).exists(), name
                result = dsmk_cached_result(
                    np.asarray(record[f"{s}_vertices"], dtype=np.float32),
                    np.asarray(record[f"{s}_faces"], dtype=np.int64),
                    str(dsmk_dir),
                )
                other = np.load(geodesics / "geodesic_dist_matrices" / f"{index[(record.pair_id, side)]['stem']}.npy")
                pair[f"dsmk_{s}_equals_geolora_times_sqrt_area"] = bool(
                    np.array_equal(result, other * np.float32(index[(record.pair_id, side)]["sqrt_area"]))
                )
                pair[f"dsmk_{s}_file_bytes"] = (dsmk_dir / name).stat().st_size
            if args.ulrssm:
                import scipy.io as sio

                folder = args.ulrssm / "test" / ulrssm_numbers[record.pair_id] / "dist"
                dist = sio.loadmat(folder / "1.mat")["dist"]  # ULRSSM's read, before its .float()
                pair["ulrssm_y_equals_geolora"] = bool(dist.dtype == np.float32 and np.array_equal(dist, geolora))
            out["pairs"].append(pair)
            print(json.dumps(pair), file=sys.stderr, flush=True)
    pairs = out["pairs"]
    out["summary"] = {
        "pairs": len(pairs),
        "max_mean_error_relative_difference": max(p["mean_error_relative_difference"] for p in pairs),
        "max_abs_error_difference": max(p["max_abs_error_difference"] for p in pairs),
        "lazy_seconds_first_use_of_mesh_median": float(
            np.median([p["lazy_seconds"] for p in pairs if p["lazy_first_use_of_mesh"]] or [np.nan])
        ),
        "lazy_seconds_mesh_cached_median": float(
            np.median([p["lazy_seconds"] for p in pairs if not p["lazy_first_use_of_mesh"]] or [np.nan])
        ),
        "lazy_seconds_mean": float(np.mean([p["lazy_seconds"] for p in pairs])),
        "lazy_max_abs_difference": max(p["lazy_max_abs_difference"] for p in pairs),
        "dsmk_all_equal": all(
            v for p in pairs for k, v in p.items() if k.startswith("dsmk_") and k.endswith("sqrt_area")
        ),
        "dsmk_max_file_bytes": max((v for p in pairs for k, v in p.items() if k.endswith("_file_bytes")), default=0),
    }
    if args.ulrssm:
        out["summary"]["ulrssm_all_equal"] = all(p["ulrssm_y_equals_geolora"] for p in pairs)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
