"""Benchmark of the partiality engine on remeshed TOSCA shapes (real data, real Embree).

Measures, and prints as JSON (also written to ``--out`` if given):

* ``p2p``: over ``--pairs`` default P2P pairs (same-class TOSCA pose pairs, remeshed to ~10k
  vertices, many seeds per shape pair): seconds per pair with retries (cold: the Embree scenes
  built inside the call, as for a pair seen once; warm: scenes reused), tries used, share of pairs
  with both overlaps inside [0.1, 0.9], a 10-bin histogram of both overlaps, mean partial size as a
  share of the full vertices.
* ``p2f``: seconds per partial-to-full pair (cold) and the partial's size.
* ``load_average_before/after``: the 1-minute load average before and after (wall times on a shared machine
  are inflated by other work; CPU-time figures are given beside them).
* ``visibility``: agreement (Jaccard of kept triangle sets after the largest-component step) of
  :meth:`VisibilityScene.scan` with a dense 5000×5000 pinhole cast (25 M rays, a triangle is seen if
  any pixel ray hits it first — the reference's Open3D cast), and the time ratio dense / ours.

Run from the repository root: ``/work/venv/bin/python benchmarks/partiality.py [--pairs 204]``.
The TOSCA meshes come from ``../shared/unpack``. Remeshing uses ``becos.build.remesh`` when it exists,
else a pymeshlab decimation (ground truth then by closest points).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from becos.build.cameras import draw_camera  # noqa: E402
from becos.build.partiality import Scanner, cast_p2f, cast_p2p  # noqa: E402
from becos.build.visibility import VisibilityScene  # noqa: E402
from becos.core.mesh import MeshCache, TriMesh  # noqa: E402
from becos.core.surface_map import SurfaceMap, compose_path  # noqa: E402
from becos.seeding import rng_for  # noqa: E402

SHAPE_PAIRS = [
    ("cat0", "cat3"),
    ("dog0", "dog5"),
    ("horse0", "horse5"),
    ("michael0", "michael3"),
    ("victoria0", "victoria4"),
    ("centaur0", "centaur1"),
]
TARGET_VERTICES = 10_000


def tosca_dir() -> Path:
    out = subprocess.run([str(REPO.parent / "shared" / "unpack")], check=True, capture_output=True, text=True)
    return Path(out.stdout.strip().splitlines()[-1]) / "data" / "tosca-off"


def y_up(mesh: TriMesh) -> TriMesh:
    v = mesh.vertices * 0.0095
    return TriMesh(np.c_[v[:, 0], v[:, 2], -v[:, 1]], mesh.faces)


def remeshed(mesh: TriMesh) -> tuple[TriMesh, SurfaceMap, SurfaceMap, str]:
    from becos.build.remesh import remesh

    r = remesh(mesh, target_vertices=TARGET_VERTICES)
    return r.mesh, r.to_original, r.from_original, "becos.build.remesh"


def load_pairs(folder: Path) -> tuple[list, str]:
    cache = MeshCache()
    pairs, method = [], ""
    for a, b in SHAPE_PAIRS:
        A, B = (y_up(cache.load(folder / f"{n}.off")) for n in (a, b))
        (x, x_to, x_from, method), (y, y_to, y_from, _) = remeshed(A), remeshed(B)
        gt_xy = compose_path([x_to, None, y_from], [A.faces, B.faces], y)
        gt_yx = compose_path([y_to, None, x_from], [B.faces, A.faces], x)
        pairs.append((f"{a}-{b}", x, y, gt_xy, gt_yx))
    return pairs, method


def bench_p2p(pairs, n_pairs: int, regime: str) -> dict:
    per_shape_pair = int(np.ceil(n_pairs / len(pairs)))
    cold, cold_cpu, warm, tries, overlaps, shares, accepted = [], [], [], [], [], [], []
    for name, x, y, gt_xy, gt_yx in pairs:
        scanners = (Scanner(x), Scanner(y))
        for k in range(per_shape_pair):
            key = (0, f"{name}#{k}")
            t0, c0 = time.perf_counter(), time.process_time()
            r = cast_p2p(x, y, gt_xy, gt_yx, key, regime=regime)
            cold.append(time.perf_counter() - t0)
            cold_cpu.append(time.process_time() - c0)
            t0 = time.perf_counter()
            cast_p2p(x, y, gt_xy, gt_yx, key, regime=regime, scanners=scanners)
            warm.append(time.perf_counter() - t0)
            tries.append(r.n_tries_used)
            overlaps += [r.overlap_x, r.overlap_y]
            shares += [r.partial_x.vertex_share, r.partial_y.vertex_share]
            accepted.append(r.accepted)
    hist, _ = np.histogram(overlaps, bins=10, range=(0.0, 1.0))
    return {
        "regime": regime,
        "n_pairs": len(cold),
        "median_s_per_pair_cold": float(np.median(cold)),
        "p90_s_per_pair_cold": float(np.quantile(cold, 0.9)),
        "median_cpu_s_per_pair_cold": float(np.median(cold_cpu)),
        "median_s_per_pair_warm": float(np.median(warm)),
        "mean_tries": float(np.mean(tries)),
        "max_tries": int(np.max(tries)),
        "share_inside_range_both_ways": float(np.mean(accepted)),
        "overlap_histogram_10_bins": hist.tolist(),
        "overlap_mean": float(np.mean(overlaps)),
        "mean_partial_vertex_share": float(np.mean(shares)),
    }


def bench_p2f(pairs, n: int) -> dict:
    times, cpu, shares = [], [], []
    for name, x, y, gt_xy, gt_yx in pairs:
        for k in range(n):
            t0, c0 = time.perf_counter(), time.process_time()
            r = cast_p2f(x, y, gt_xy, gt_yx, (0, f"{name}#p2f{k}"))
            times.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
            shares.append(r.partial_y.vertex_share)
    return {
        "n_pairs": len(times),
        "median_s_per_pair_cold": float(np.median(times)),
        "median_cpu_s_per_pair_cold": float(np.median(cpu)),
        "mean_partial_vertex_share": float(np.mean(shares)),
    }


def bench_visibility(pairs, cameras_per_shape: int, resolution: int) -> dict:
    """Ours vs the dense pixel cast, same camera. Time ratios use process CPU time (both casts run on
    one thread; CPU time is robust to other load on the machine); wall-clock medians are reported too."""
    jaccard, ratio_cast, ratio_total, ours_ms, dense_s, wall_ratio = [], [], [], [], [], []
    clock = time.process_time
    for name, x, y, _, _ in pairs:
        for shape_name, mesh in ((name + ":x", x), (name + ":y", y)):
            scene: VisibilityScene = Scanner(mesh).scene
            for k in range(cameras_per_shape):
                cam = draw_camera(rng_for(0, shape_name, "cameras", k))
                w0, t0 = time.perf_counter(), clock()
                seen = scene.visible_faces(cam)
                t1 = clock()
                ours = scene.largest_component(seen)
                w2, t2 = time.perf_counter(), clock()
                dense_seen = scene.grid_visible_faces(cam, resolution)
                t3 = clock()
                dense = scene.largest_component(dense_seen)
                w4, t4 = time.perf_counter(), clock()
                jaccard.append(float((ours & dense).sum() / (ours | dense).sum()))
                ratio_cast.append((t3 - t2) / max(t1 - t0, 1e-6))
                ratio_total.append((t4 - t2) / max(t2 - t0, 1e-6))
                wall_ratio.append((w4 - w2) / (w2 - w0))
                ours_ms.append(1e3 * (w2 - w0))
                dense_s.append(w4 - w2)
    return {
        "resolution": resolution,
        "n_views": len(jaccard),
        "jaccard_mean": float(np.mean(jaccard)),
        "jaccard_min": float(np.min(jaccard)),
        "median_ms_ours_with_component_wall": float(np.median(ours_ms)),
        "median_s_dense_with_component_wall": float(np.median(dense_s)),
        "time_ratio_dense_over_ours_cast_only_cpu": float(np.median(ratio_cast)),
        "time_ratio_dense_over_ours_with_component_cpu": float(np.median(ratio_total)),
        "time_ratio_dense_over_ours_with_component_wall": float(np.median(wall_ratio)),
    }


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=204, help="P2P pairs (spread over the shape pairs)")
    parser.add_argument("--p2f", type=int, default=5, help="P2F pairs per shape pair")
    parser.add_argument("--regime", default="high", choices=["high", "medium", "low"])
    parser.add_argument("--dense-cameras", type=int, default=2, help="cameras per shape for the dense comparison")
    parser.add_argument("--resolution", type=int, default=5000)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)

    t0 = time.perf_counter()
    pairs, method = load_pairs(tosca_dir())
    result = {
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count()},
        "remeshing": method,
        "shape_pairs": [p[0] for p in pairs],
        "mean_vertices": float(np.mean([m.n_vertices for p in pairs for m in p[1:3]])),
        "setup_s": time.perf_counter() - t0,
        "load_average_before": os.getloadavg()[0],
        "p2p": bench_p2p(pairs, args.pairs, args.regime),
        "p2f": bench_p2f(pairs, args.p2f),
        "visibility": bench_visibility(pairs, args.dense_cameras, args.resolution),
    }
    result["load_average_after"] = os.getloadavg()[0]
    text = json.dumps(result, indent=2)
    print(text)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")
    return result


if __name__ == "__main__":
    main()
