"""Cost and accuracy of the geodesic-matrix export on one remeshed TOSCA shape: before/after in one run.

    PYTHONPATH=. python benchmarks/geodesics_speed.py [--shape cat0] [--vertices 10000] [--exact 20]
    PYTHONPATH=. python benchmarks/geodesics_speed.py --writes 3 [--shape cat0] [--vertices 10000] [--out DIR]

Remeshes ``<shape>`` of ``../shared`` TOSCA to ``--vertices`` (becos.build.remesh), then computes its whole
(V, V) float32 matrix with

- before: potpourri3d's ``MeshHeatMethodDistanceSolver`` one source per call (becos.core.geodesics.
  GeodesicDistances, the export's former ``distance_rows``);
- after: :class:`becos.core.geodesics.HeatDistanceSolver` (both systems factored once, blocks of sources
  solved as multi-column right-hand sides), i.e. today's ``distance_rows``;

and prints CPU seconds (``time.process_time``, all threads), the matrix size, the relative difference
after vs before (over off-diagonal entries farther than 3 mean edge lengths, where relative error is
meaningful) and each method's error against libigl's exact geodesics from ``--exact`` random sources.

``--writes K`` measures instead the cost of writing that matrix as a full shape's geo-lora file in K
places (e.g. 3: both sides of full-to-full pairs and the full side of partial-to-full ones), wall and
CPU seconds with every file flushed to disk (``fsync``), before/after in one run, in ``--out``:

- before: the rows job saves the (V, V) rows; each of the K layout writes maps them, symmetrises,
  divides by the sqrt-area and saves its own file (the former ``write_geodesic_matrices``);
- after: the rows job symmetrises, divides and saves the block once (``symmetric_block``,
  ``save_npy``); the K layout files are hard links of it (``link_or_copy``).
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
    parser.add_argument("--writes", type=int, default=0, help="measure writing the matrix in this many places")
    parser.add_argument("--out", type=Path, default=Path("/tmp/becos-geodesics-writes"), help="folder for --writes")
    args = parser.parse_args()

    from becos.build.remesh import remesh
    from becos.core.geodesics import GeodesicDistances, distance_rows
    from becos.core.mesh import MeshCache, TriMesh
    from becos.sources.datasets import DatasetSpec, prepare_shape

    root = Path(__file__).resolve().parents[1]
    code = Path(
        subprocess.run([str(root.parent / "shared" / "unpack")], check=True, capture_output=True, text=True)
        .stdout.strip()
        .splitlines()[-1]
    )
    from becos.sources.annotations import AnnotationSource

    cache = MeshCache(Path("/tmp/becos-geodesics-bench-cache"))
    entries = {e.name: e for e in DatasetSpec.load("tosca").list_shapes(code / "data", AnnotationSource(code))}
    mesh = remesh(prepare_shape(entries[args.shape], cache).mesh, target_vertices=args.vertices).mesh
    v, f = mesh.vertices, mesh.faces
    n = len(v)
    all_sources = np.arange(n)
    if args.writes:
        print(json.dumps(write_costs(v, f, args.writes, args.out, args.shape), indent=1))
        return

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


def write_costs(v: np.ndarray, f: np.ndarray, places: int, out: Path, shape: str) -> dict:
    """Wall and CPU seconds of writing the (V, V) matrix of one full shape in ``places`` layout files,
    the former way and today's (module docstring, ``--writes``), in one run. Deletes its files."""
    import shutil

    from becos.atomic import link_or_copy, save_npy
    from becos.core.geodesics import distance_rows
    from becos.products.export.geodesics import GeodesicShape, shape_matrix, symmetric_block

    n = len(v)
    sources = np.arange(n)
    sqrt_area = float(
        np.sqrt(0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1).sum())
    )
    rows = distance_rows(v, f, sources, "heat")
    full = GeodesicShape("test", "p", 0, "tosca", shape, "0_x", "m", "k", sources, sqrt_area)

    def synced(path: Path) -> None:
        with open(path, "rb+") as fh:
            os.fsync(fh.fileno())

    def timed(step) -> dict:
        wall, cpu = time.monotonic(), time.process_time()
        step()
        return {"wall_s": round(time.monotonic() - wall, 2), "cpu_s": round(time.process_time() - cpu, 2)}

    out.mkdir(parents=True, exist_ok=True)
    result = {"shape": shape, "vertices": n, "places": places, "load_average_start": os.getloadavg()}
    try:

        def before_rows():
            np.save(out / "rows.npy", rows)
            synced(out / "rows.npy")

        def before_layouts():
            memmap = np.load(out / "rows.npy", mmap_mode="r")
            for k in range(places):
                matrix = shape_matrix(full, sources, memmap)
                np.save(out / f"before_{k}.npy", (matrix / np.float32(sqrt_area)).astype(np.float32, copy=False))
                synced(out / f"before_{k}.npy")

        def after_rows():
            save_npy(out / "block.npy", symmetric_block(rows, sources, sqrt_area))
            synced(out / "block.npy")

        def after_layouts():
            for k in range(places):
                link_or_copy(out / "block.npy", out / f"after_{k}.npy")

        before = {"rows_job": timed(before_rows), "layout_jobs": timed(before_layouts)}
        same = np.array_equal(np.load(out / "before_0.npy"), symmetric_block(rows, sources, sqrt_area))
        for p in out.glob("before_*.npy"):
            p.unlink()
        (out / "rows.npy").unlink()
        after = {"rows_job": timed(after_rows), "layout_jobs": timed(after_layouts)}
        same = same and np.array_equal(np.load(out / "after_0.npy"), np.load(out / "block.npy"))
        for figures in (before, after):
            figures["total"] = {k: round(sum(step[k] for step in figures.values()), 2) for k in ("wall_s", "cpu_s")}
        result.update(
            {
                "bytes_on_disk": {"before": (1 + places) * rows.nbytes, "after": rows.nbytes},
                "before": before,
                "after": after,
                "ratio_before_over_after": {
                    k: round(before["total"][k] / max(after["total"][k], 1e-3), 1) for k in ("wall_s", "cpu_s")
                },
                "same_bytes": bool(same),
                "load_average_end": os.getloadavg(),
            }
        )
    finally:
        shutil.rmtree(out, ignore_errors=True)
    return result


if __name__ == "__main__":
    main()
