"""Benchmark of the Zarr benchmark store: write and read time and file count for N pair records.

One pair record is built (``--record PATH`` to use a saved one instead): a full_full pair of an
icosphere (subdivision 5: 10,242 vertices, 20,480 faces — the size of a remeshed TOSCA pair) with
itself, identity ground truth, through :func:`becos.pairs.build_pair`; it is saved ``--n`` times
with different pair ids (splits train/val/test in turn; vertex coordinates jittered by 1e-4 per
copy unless ``--no-jitter``, so compression does not see identical copies), then :func:`becos.store.write_store`
collects them. Prints JSON ``{n_pairs, write_seconds, read_all_seconds, n_files, ...}``;
``read_all_seconds`` is one pass of :meth:`Benchmark.records` over every pair.

Aim (issue "store"): O(10 s) for 1,000 records (the brief's measure: 13 s for concatenated arrays
with offsets vs 72–129 s for one array per pair).

Run from the repository root: ``/work/venv/bin/python benchmarks/store.py [--n 1000] [--keep DIR]``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from becos.record import PairRecord  # noqa: E402
from becos.store import count_files, open_benchmark, write_store  # noqa: E402


def sphere_record(subdivisions: int = 5) -> PairRecord:
    """A schema-complete full_full record of an icosphere paired with itself (identity ground truth)."""
    import trimesh

    from becos.mesh import TriMesh
    from becos.pairs import PairOptions, ShapeInstance, build_pair
    from becos.surface_map import SurfaceMap

    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    mesh = TriMesh(np.asarray(sphere.vertices, dtype=np.float64), np.asarray(sphere.faces, dtype=np.int64))
    shape = ShapeInstance("synthetic", "sphere", "four-legged", "sphere", mesh)
    gt = SurfaceMap.identity(mesh.faces, mesh.n_vertices)
    return build_pair(shape, shape, gt, gt, pair_id="bench000000000000", seed=0, split="train",
                      options=PairOptions(setting="full_full"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1000, help="number of pair records")
    parser.add_argument("--record", type=Path, help="a saved pair record to duplicate (default: a sphere pair)")
    parser.add_argument("--no-jitter", dest="jitter", action="store_false",
                        help="store exact copies (default: vertex coordinates jittered per copy)")
    parser.add_argument("--keep", type=Path, help="work folder to keep (default: a temporary one, deleted)")
    args = parser.parse_args()

    record = PairRecord.load(args.record) if args.record else sphere_record()
    work = Path(tempfile.mkdtemp(prefix="becos-store-bench-")) if args.keep is None else args.keep
    work.mkdir(parents=True, exist_ok=True)
    try:
        records = work / "records"
        records.mkdir(exist_ok=True)
        paths = []
        t0 = time.perf_counter()
        splits = ("train", "val", "test")
        rng = np.random.default_rng(0)
        for i in range(args.n):
            meta = dict(record.meta, pair_id=f"bench{i:012d}", split=splits[i % 3])
            arrays = dict(record.arrays)
            if args.jitter:  # distinct coordinates per copy, so compression sees realistic data
                for key in ("x_vertices", "y_vertices"):
                    arrays[key] = arrays[key] + rng.normal(scale=1e-4, size=arrays[key].shape)
            path = records / f"{meta['pair_id']}.npz"
            PairRecord(arrays, meta).save(path)
            paths.append(path)
        prepare_seconds = time.perf_counter() - t0

        store = work / "benchmark.zarr"
        t0 = time.perf_counter()
        write_store(paths, store, setting=record.meta["setting"], metadata={"benchmark": "store"}, progress=False)
        write_seconds = time.perf_counter() - t0

        t0 = time.perf_counter()
        bench = open_benchmark(store)
        n_read = sum(1 for _ in bench.records())
        read_all_seconds = time.perf_counter() - t0

        t0 = time.perf_counter()
        bench.record(args.n // 2)
        one_record_ms = 1000 * (time.perf_counter() - t0)

        record_bytes = sum(a.nbytes for a in record.arrays.values())
        store_bytes = sum(p.stat().st_size for p in store.rglob("*") if p.is_file())
        print(json.dumps({
            "n_pairs": n_read,
            "write_seconds": round(write_seconds, 2),
            "read_all_seconds": round(read_all_seconds, 2),
            "n_files": count_files(store),
            "one_record_ms": round(one_record_ms, 1),
            "record_mb": round(record_bytes / 2**20, 2),
            "store_mb": round(store_bytes / 2**20, 1),
            "prepare_seconds": round(prepare_seconds, 2),
            "vertices_per_shape": int(len(record["x_vertices"])),
        }, indent=1))
    finally:
        if args.keep is None:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
