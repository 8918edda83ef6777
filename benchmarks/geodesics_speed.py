"""Cost and accuracy of the geodesic-matrix export on one remeshed TOSCA shape: before/after in one run.

    PYTHONPATH=. python benchmarks/geodesics_speed.py [--shape cat0] [--vertices 10000] [--exact 20]

Remeshes ``<shape>`` of ``../shared`` TOSCA to ``--vertices`` (becos.remesh), then computes its whole
(V, V) float32 matrix with

- before: potpourri3d's ``MeshHeatMethodDistanceSolver`` one source per call (becos.geodesics.
  GeodesicDistances, the export's former ``distance_rows``);
- after: :class:`becos.geodesics.HeatDistanceSolver` (both systems factored once, blocks of sources
  solved as multi-column right-hand sides), i.e. today's ``distance_rows``;

and prints CPU seconds (``time.process_time``, all threads), the matrix size, the relative difference
after vs before (over off-diagonal entries farther than 3 mean edge lengths, where relative error is
meaningful) and each method's error against libigl's exact geodesics from ``--exact`` random sources.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import time
from pathlib import Path

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shape", default="cat0")
    parser.add_argument("--vertices", type=int, default=10000)
    parser.add_argument("--exact", type=int, default=20, help="random sources compared with exact geodesics")
    args = parser.parse_args()

    from becos.datasets import DatasetSpec, prepare_shape
    from becos.geodesics import GeodesicDistances, distance_rows
    from becos.mesh import MeshCache, TriMesh
    from becos.remesh import remesh

    root = Path(__file__).resolve().parents[1]
    code = Path(
        subprocess.run([str(root.parent / "shared" / "unpack")], check=True, capture_output=True, text=True)
        .stdout.strip()
        .splitlines()[-1]
    )
    from becos.annotations import AnnotationSource

    cache = MeshCache(Path("/tmp/becos-geodesics-bench-cache"))
    entries = {e.name: e for e in DatasetSpec.load("tosca").list_shapes(code / "data", AnnotationSource(code))}
    mesh = remesh(prepare_shape(entries[args.shape], cache).mesh, target_vertices=args.vertices).mesh
    v, f = mesh.vertices, mesh.faces
    n = len(v)
    all_sources = np.arange(n)

    t0 = time.process_time()
    old_solver = GeodesicDistances(TriMesh(v, f), "heat", cache_bytes=0)
    before = np.empty((n, n), dtype=np.float32)
    for start in range(0, n, 256):
        before[start : start + 256] = old_solver.from_vertices(all_sources[start : start + 256])
    cpu_before = time.process_time() - t0

    t0 = time.process_time()
    after = distance_rows(v, f, all_sources, "heat")
    cpu_after = time.process_time() - t0

    edge = float(np.linalg.norm(v[f[:, [1, 2, 0]]] - v[f], axis=2).mean())
    far = before > 3 * edge
    rel = np.abs(after[far] - before[far]) / before[far]
    sym_after = float(np.abs(after - after.T).max() / after.max())

    import igl

    rng = np.random.default_rng(0)
    picks = rng.choice(n, size=min(args.exact, n), replace=False)
    exact = np.stack(
        [igl.exact_geodesic(v, f.astype(np.int64), VS=np.array([s], dtype=np.int64), VT=all_sources) for s in picks]
    )
    mask = exact > 3 * edge
    err = {
        name: np.abs(m[picks][mask] - exact[mask]) / exact[mask] for name, m in (("before", before), ("after", after))
    }
    print(
        json.dumps(
            {
                "shape": args.shape,
                "vertices": n,
                "faces": len(f),
                "load_average": os.getloadavg(),
                "bytes_float32_matrix": int(after.nbytes),
                "cpu_s": {
                    "before": round(cpu_before, 2),
                    "after": round(cpu_after, 2),
                    "ratio": round(cpu_before / cpu_after, 1),
                },
                "cpu_ms_per_row": {"before": round(1e3 * cpu_before / n, 3), "after": round(1e3 * cpu_after / n, 3)},
                "after_vs_before_relative": {
                    "mean": float(rel.mean()),
                    "p99": float(np.quantile(rel, 0.99)),
                    "max": float(rel.max()),
                },
                "after_asymmetry_rel_to_max": sym_after,
                "vs_exact_relative": {k: {"mean": float(e.mean()), "max": float(e.max())} for k, e in err.items()},
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
