"""Benchmark of the Zarr benchmark store: write and read time and file count for N pair records.

One pair record is built (``--record PATH`` to use a saved one instead): a full_full pair of an
icosphere (subdivision 5: 10,242 vertices, 20,480 faces — the size of a remeshed TOSCA pair) with
itself, identity ground truth, through :func:`becos.build.pairs.build_pair`; it is saved ``--n`` times
with different pair ids (splits train/val/test in turn; vertex coordinates jittered by 1e-4 per
copy unless ``--no-jitter``, so compression does not see identical copies), then :func:`becos.products.store.write_store`
collects them. Prints JSON ``{n_pairs, write_seconds, read_all_seconds, n_files, ...}``;
``read_all_seconds`` is one pass of :meth:`Benchmark.records` over every pair.

``reads``: CPU time of a random ``Benchmark.record(i)`` against ``np.load`` of the same pair's npz,
interleaved in one run, and of one sequential pass (``records()`` against ``np.load`` of every npz).

``--results DIR`` (a workflow run's results folder) measures that run instead: MB per pair by
artefact kind (pair records, ground truth, store, released export) as found and as this becos
writes them (records, ground truth and store re-encoded from the run's own files; the released
export's format is the reference's and counted as found), and the reads on the re-encoded files,
also against ``np.load`` of the records as store format 1 wrote them (uncompressed, int64)::

    PYTHONPATH=. python benchmarks/store.py --results results --random 40

Aim (issue "store"): O(10 s) for 1,000 records (the brief's measure: 13 s for concatenated arrays
with offsets vs 72–129 s for one array per pair).

Run from the repository root: ``/work/venv/bin/python benchmarks/store.py [--n 1000] [--keep DIR]``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from becos.build.record import PairRecord  # noqa: E402
from becos.products.store import count_files, open_benchmark, write_store  # noqa: E402


def sphere_record(subdivisions: int = 5) -> PairRecord:
    """A schema-complete full_full record of an icosphere paired with itself (identity ground truth)."""
    import trimesh

    from becos.build.pairs import PairOptions, ShapeInstance, build_pair
    from becos.core.mesh import TriMesh
    from becos.core.surface_map import SurfaceMap

    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    mesh = TriMesh(np.asarray(sphere.vertices, dtype=np.float64), np.asarray(sphere.faces, dtype=np.int64))
    shape = ShapeInstance("synthetic", "sphere", "four-legged", "sphere", mesh)
    gt = SurfaceMap.identity(mesh.faces, mesh.n_vertices)
    return build_pair(
        shape,
        shape,
        gt,
        gt,
        pair_id="bench000000000000",
        seed=0,
        split="train",
        options=PairOptions(setting="full_full"),
    )


def _cpu() -> float:
    return time.process_time()


def _np_load(path: Path) -> dict:
    """What a user of the npz files does: every member read."""
    with np.load(path, allow_pickle=False) as data:
        return {k: data[k] for k in data.files}


def _save_format_1(record: PairRecord, path: Path) -> None:
    """A record file as store format 1 wrote it: uncompressed np.savez, int64 indices, identity maps."""
    from becos.atomic import save_npz
    from becos.digests import content_digest

    meta = dict(record.meta, content_digest=content_digest(record.arrays, record.meta))
    save_npz(path, __meta__=np.array(json.dumps(meta, sort_keys=True)), **record.arrays)


def read_timings(store: Path, npz_of: dict[str, Path], npz_v1_of: dict[str, Path] | None, n_random: int) -> dict:
    """CPU time of a random ``Benchmark.record(i)`` vs ``np.load`` of the same pair's npz (interleaved,
    one run), and of one sequential pass of ``Benchmark.records()`` vs ``np.load`` of every npz in
    store order."""
    bench = open_benchmark(store)
    rows = np.random.default_rng(1).integers(0, len(bench), size=n_random)
    ids = list(bench.table["pair_id"])
    bench.record(0), _np_load(npz_of[ids[0]])  # warm: imports, shard indexes
    t_store = t_npz = t_v1 = t_zarr = 0.0
    for i in rows:
        t = _cpu()
        bench.record(int(i))
        t_store += _cpu() - t
        t = _cpu()
        _np_load(npz_of[ids[i]])
        t_npz += _cpu() - t
        if npz_v1_of is not None:
            t = _cpu()
            _np_load(npz_v1_of[ids[i]])
            t_v1 += _cpu() - t
        t = _cpu()
        bench.read_block(int(i), int(i) + 1).record(0)
        t_zarr += _cpu() - t
    t = _cpu()
    n_seq = sum(1 for _ in bench.records())
    seq_store = _cpu() - t
    t = _cpu()
    for pid in ids:
        _np_load(npz_of[pid])
    seq_npz = _cpu() - t
    out = {
        "n_random": int(n_random),
        "record_cpu_ms": round(1000 * t_store / n_random, 2),
        "np_load_cpu_ms": round(1000 * t_npz / n_random, 2),
        "record_over_np_load": round(t_store / t_npz, 3),
        "zarr_read_block_cpu_ms": round(1000 * t_zarr / n_random, 2),
    }
    if npz_v1_of is not None:
        out.update(
            np_load_format_1_cpu_ms=round(1000 * t_v1 / n_random, 2),
            record_over_np_load_format_1=round(t_store / t_v1, 3),
        )
    out["sequential"] = {
        "n_pairs": n_seq,
        "records_cpu_s": round(seq_store, 3),
        "np_load_cpu_s": round(seq_npz, 3),
        "records_over_np_load": round(seq_store / seq_npz, 3),
    }
    return out


def _bytes(paths) -> int:
    return sum(p.stat().st_size for p in paths if p.is_file())


def _tree_bytes(folder: Path) -> int:
    return _bytes(folder.rglob("*")) if folder.exists() else 0


def run_artefacts(results: Path, work: Path, n_random: int) -> dict:
    """MB per pair by artefact kind of a workflow run's results (as found, and re-encoded by this becos:
    pair records re-saved, ground truth re-saved, the store re-written from the re-saved records;
    the released export's format is not this module's and is counted as found), plus read timings on
    the re-encoded files."""
    from becos.atomic import save_npz
    from becos.workflow import narrow_faces

    out, timings = {}, {}
    for setting_dir in sorted(p for p in results.iterdir() if (p / "pairs").is_dir()):
        setting = setting_dir.name
        pairs = sorted((setting_dir / "pairs").glob("*.npz"))
        if not pairs:
            continue
        n = len(pairs)
        found = {
            "pairs": _bytes(pairs),
            "ground_truth": _tree_bytes(setting_dir / "ground_truth"),
            "store": _tree_bytes(setting_dir / "benchmark.zarr"),
            "released": _tree_bytes(setting_dir / "released"),
        }
        dest = work / setting
        (dest / "pairs").mkdir(parents=True, exist_ok=True)
        (dest / "pairs_v1").mkdir(exist_ok=True)
        (dest / "ground_truth").mkdir(exist_ok=True)
        npz_of, npz_v1_of, new_pairs = {}, {}, []
        for path in pairs:
            record = PairRecord.load(path)
            record.save(dest / "pairs" / path.name)
            _save_format_1(record, dest / "pairs_v1" / path.name)
            npz_of[record.pair_id], npz_v1_of[record.pair_id] = (
                dest / "pairs" / path.name,
                dest / "pairs_v1" / path.name,
            )
            new_pairs.append(dest / "pairs" / path.name)
        for path in sorted((setting_dir / "ground_truth").glob("*.npz")):
            with np.load(path) as d:
                g = {k: d[k] for k in d.files}
            save_npz(
                dest / "ground_truth" / path.name,
                compressed=True,
                input_key=g["input_key"],
                **{k: (narrow_faces(v) if k.endswith("_face") else v) for k, v in g.items() if k != "input_key"},
            )
        write_store(new_pairs, dest / "benchmark.zarr", setting=setting, progress=False)
        after = {
            "pairs": _bytes(new_pairs),
            "ground_truth": _tree_bytes(dest / "ground_truth"),
            "store": _tree_bytes(dest / "benchmark.zarr"),
            "released": found["released"],
        }
        out[setting] = {"n_pairs": n}
        for label, sizes in (("before", found), ("after", after)):
            mb = {k: round(v / n / 1e6, 3) for k, v in sizes.items()}
            mb["total"] = round(sum(sizes.values()) / n / 1e6, 3)
            out[setting][label] = mb
        timings[setting] = read_timings(dest / "benchmark.zarr", npz_of, npz_v1_of, n_random)
        shutil.rmtree(dest, ignore_errors=True)
    every = {
        label: round(
            sum(v[label]["total"] * v["n_pairs"] for v in out.values()) / sum(v["n_pairs"] for v in out.values()), 3
        )
        for label in ("before", "after")
    }
    return {"disk_mb_per_pair": out, "disk_mb_per_pair_all_settings": every, "reads": timings}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1000, help="number of pair records")
    parser.add_argument("--record", type=Path, help="a saved pair record to duplicate (default: a sphere pair)")
    parser.add_argument(
        "--no-jitter",
        dest="jitter",
        action="store_false",
        help="store exact copies (default: vertex coordinates jittered per copy)",
    )
    parser.add_argument("--keep", type=Path, help="work folder to keep (default: a temporary one, deleted)")
    parser.add_argument(
        "--results",
        type=Path,
        help="a workflow run's results folder: measure MB per pair by artefact kind (as found and "
        "re-encoded by this becos) and the reads on its own records, instead of the sphere copies",
    )
    parser.add_argument("--random", type=int, default=50, help="random record(i) reads timed (default 50)")
    args = parser.parse_args()
    load = os.getloadavg()[0]
    if args.results is not None:
        work = Path(tempfile.mkdtemp(prefix="becos-store-bench-"))
        try:
            result = run_artefacts(args.results, work, args.random)
        finally:
            shutil.rmtree(work, ignore_errors=True)
        print(json.dumps({"results": str(args.results), "load_average_1min": round(load, 2), **result}, indent=1))
        return

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

        reads = read_timings(store, {p.stem: p for p in paths}, None, args.random)
        record_bytes = sum(a.nbytes for a in record.arrays.values())
        store_bytes = sum(p.stat().st_size for p in store.rglob("*") if p.is_file())
        print(
            json.dumps(
                {
                    "n_pairs": n_read,
                    "write_seconds": round(write_seconds, 2),
                    "read_all_seconds": round(read_all_seconds, 2),
                    "n_files": count_files(store),
                    "one_record_ms": round(one_record_ms, 1),
                    "record_mb": round(record_bytes / 2**20, 2),
                    "store_mb": round(store_bytes / 2**20, 1),
                    "prepare_seconds": round(prepare_seconds, 2),
                    "vertices_per_shape": int(len(record["x_vertices"])),
                    "npz_mb_per_pair": round(sum(p.stat().st_size for p in paths) / len(paths) / 2**20, 3),
                    "load_average_1min": round(load, 2),
                    "reads": reads,
                },
                indent=1,
            )
        )
    finally:
        if args.keep is None:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
