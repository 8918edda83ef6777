"""Geodesic matrices of the exports: the plan (each distinct full mesh once, with the vertices its shapes
keep), per-mesh blocks (solved in processes, or read from ``becos geodesic-rows`` folders) cut into row
chunks for streamed writes (ULRSSM's MAT files: :mod:`.mat`), and the loaders' layouts: :func:`write_geodesic_matrices`
(geo-lora's ``geodesic_dist_matrices/<stem>.npy``, DeepShapeMatchingKit's cache names) and
:func:`write_geodesics` (PSMAL ids). Matrices are (V, V) float32, measured on the shape's FULL mesh.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from becos.build.record import PairRecord, full_shape
from becos.errors import BecosError
from becos.products.export.dsmk import DSMK_FOLDER, dsmk_cache_name, dsmk_reads, save_dsmk_pointer
from becos.products.export.mat import WRITE_CHUNK_BYTES
from becos.products.export.psmal import psmal_shape_id
from becos.products.export.released import released_file_stem, released_infos
from becos.products.export.staging import (
    SIDES,
    ExportError,
    check_record,
    free_space,
    gigabytes,
    id_field,
    require_room,
    staged_dir,
    write_ids,
    write_log,
)


def cut_chunks(block: np.ndarray, cut: np.ndarray | None) -> Iterator[np.ndarray]:
    """Row blocks of ``block[np.ix_(cut, cut)]`` (of ``block`` itself when ``cut`` is None), of at most
    :data:`WRITE_CHUNK_BYTES` each."""
    n = len(block) if cut is None else len(cut)
    step = max(1, WRITE_CHUNK_BYTES // (4 * max(n, 1)))
    for start in range(0, n, step):
        if cut is None:
            yield block[start : start + step]
        else:
            yield block[cut[start : start + step]][:, cut]


def _symmetrise_in_place(block: np.ndarray, sqrt_area: float, tile: int = 1024) -> np.ndarray:
    """Turn the (R, R) float32 ``block`` of distance rows between R sources into
    :func:`symmetric_block`'s matrix in place, tile by tile: entry by entry the same float32 operations
    ((d(a, b) + d(b, a)) · 0.5 / sqrt_area, zero diagonal), so the same bytes, with one (R, R) array
    instead of three."""
    n = len(block)
    half, scale = np.float32(0.5), np.float32(sqrt_area)
    for i in range(0, n, tile):
        for j in range(i, n, tile):
            t = block[j : j + tile, i : i + tile].T + block[i : i + tile, j : j + tile]
            t *= half
            t /= scale
            block[i : i + tile, j : j + tile] = t
            block[j : j + tile, i : i + tile] = t.T
    np.fill_diagonal(block, 0.0)
    return block


def _read_npy_block(path: Path, pick: np.ndarray | None, out: np.ndarray) -> np.ndarray:
    """Fill ``out`` with rows and columns ``pick`` (sorted; all when None) of the (R, R) float32 ``.npy``
    file ``path``, by buffered reads of :data:`WRITE_CHUNK_BYTES` (no memory map: the file's pages do
    not stay in this process's memory)."""
    with open(path, "rb") as fh:
        version = np.lib.format.read_magic(fh)
        reader = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, fortran, dtype = reader(fh)
        if len(shape) != 2 or shape[0] != shape[1] or dtype != np.float32 or fortran:
            raise ExportError(
                f"{path}: a {shape} {dtype} block, expected (R, R) float32. Fix: rerun `becos geodesic-rows`"
            )
        n = shape[0]
        step = max(1, WRITE_CHUNK_BYTES // (4 * max(n, 1)))
        buffer = np.empty((step, n), dtype=np.float32)
        for start in range(0, n, step):
            rows = min(step, n - start)
            view = out[start : start + rows] if pick is None else buffer[:rows]
            if fh.readinto(memoryview(view).cast("B")) != 4 * rows * n:
                raise ExportError(f"{path}: truncated block. Fix: rerun `becos geodesic-rows`")
            if pick is not None:
                lo, hi = np.searchsorted(pick, [start, start + rows])
                out[lo:hi] = view[pick[lo:hi] - start][:, pick]
    return out


def rows_covering(rows_folders, needed: Mapping, keys) -> dict[str, tuple[np.ndarray, Path, float]]:
    """:func:`load_rows` of ``rows_folders`` for the meshes ``keys``: ``{key: (row vertices, block file,
    sqrt_area)}``, checking that each mesh is there with every row ``needed[key]`` names."""
    loaded = load_rows(rows_folders)
    out = {}
    for key in keys:
        if key not in loaded:
            raise ExportError(
                f"{', '.join(map(str, rows_folders))}: no geodesic rows of mesh {key}. Fix: plan the rows "
                f"with this store and the same splits (`becos geodesic-plan`), then rerun `becos geodesic-rows`"
            )
        have = loaded[key][0]
        if not np.isin(needed[key], have).all():
            raise ExportError(
                f"geodesic rows of mesh {key}: {len(have)} rows, missing some of the {len(needed[key])} this "
                f"store needs. Fix: rerun `becos geodesic-plan` and `becos geodesic-rows` with this store"
            )
        out[key] = loaded[key]
    return out


def mesh_blocks(
    meshes: dict,
    needed: dict,
    scales: Mapping[str, float],
    method: str,
    jobs: int,
    progress: bool,
    rows_folders=None,
    label: str = "geodesics",
) -> Iterator[tuple[str, np.ndarray, np.ndarray]]:
    """Yield ``(key, sources, block)`` for every mesh, ONE at a time, largest first: ``sources`` (R,)
    its sorted needed vertices, ``block`` the (R, R) float32 :func:`symmetric_block` between them
    (symmetrised, divided by ``scales[key]``, the sqrt-area). The caller writes it before asking for
    the next; only one block is in memory.

    Computed: tasks of :func:`task_rows` source rows, each in a fresh process (``jobs`` at a time,
    also for ``jobs=1``: the solver library keeps memory until its process ends), at most ``jobs``
    tasks submitted and not yet consumed (bounded memory), each task's (rows, V) float32 result cut to
    the block's columns as it arrives; no rows file on disk. From ``rows_folders`` (outputs of
    ``becos geodesic-rows``): each block read (and cut to ``needed``) from its file."""
    import time

    order = sorted(meshes, key=lambda k: (-len(needed[k]), k))
    started = time.monotonic()

    def say(text: str) -> None:  # progress on stderr, with the seconds since the start
        if progress:
            print(f"{text}, {time.monotonic() - started:.0f} s", file=sys.stderr, flush=True)

    if rows_folders is not None:
        yield from _blocks_read(rows_folders, needed, scales, order, say, label)
    else:
        yield from _blocks_computed(
            meshes, needed, scales, order, method, jobs, say, f"{label} ({method}, {jobs} jobs)"
        )


def _blocks_read(rows_folders, needed: dict, scales: Mapping[str, float], order: list, say, label: str):
    """:func:`mesh_blocks` read from the files of ``becos geodesic-rows`` (``rows_folders``) in ``order``;
    their sqrt-areas must equal ``scales``. ``say``: the progress printer."""
    loaded = rows_covering(rows_folders, needed, order)
    for key in order:
        _, path, scale = loaded[key]
        if abs(scale - scales[key]) > 1e-6 * abs(scale):
            raise ExportError(
                f"{path}: sqrt-area {scale!r} differs from {scales[key]!r} of this store. Fix: build every "
                f"setting's store with the same config (area_normalised) and rerun `becos geodesic-plan`"
            )
    for i, key in enumerate(order):
        have, path, _ = loaded[key]
        whole = len(have) == len(needed[key])
        block = np.empty((len(needed[key]),) * 2, dtype=np.float32)
        _read_npy_block(path, None if whole else np.searchsorted(have, needed[key]), block)
        say(f"{label}: read mesh {i + 1}/{len(order)} ({len(block)} rows) from {path.parent}")
        yield key, needed[key], block
        del block


def _blocks_computed(meshes: dict, needed: dict, scales: Mapping[str, float], order: list, method, jobs, say, label):
    """:func:`mesh_blocks` computed by ``jobs`` worker processes in ``order``: each mesh's block filled
    from its tasks' rows as they arrive (a mesh's tasks are consecutive), then symmetrised."""
    from contextlib import closing

    tasks = [
        (key, start, *meshes[key], needed[key][start : start + step], method)
        for key in order
        for step in [task_rows(len(meshes[key][0]), len(meshes[key][1]))]
        for start in range(0, len(needed[key]), step)
    ]
    total, done = sum(len(needed[k]) for k in order), 0
    block, filled = None, 0
    with closing(_task_results(tasks, jobs)) as results:
        for key, start, rows in results:
            sources = needed[key]
            if block is None:
                block, filled = np.empty((len(sources), len(sources)), dtype=np.float32), 0
            whole = len(sources) == rows.shape[1] and sources[-1] == len(sources) - 1
            block[start : start + len(rows)] = rows if whole else rows[:, sources]
            filled += len(rows)
            done += len(rows)
            del rows
            say(f"{label}: {done}/{total} rows of {len(order)} meshes")
            if filled == len(sources):
                yield key, sources, _symmetrise_in_place(block, scales[key])
                block = None


def _task_results(tasks: list, jobs: int) -> Iterator[tuple[str, int, np.ndarray]]:
    """``(key, start, rows)`` of each :func:`_geodesic_task` in the order of ``tasks``, each run in a fresh
    process, ``jobs`` at a time, at most ``jobs`` results held here (bounded memory)."""
    import multiprocessing
    from collections import deque
    from concurrent.futures import ProcessPoolExecutor

    # every task in a fresh process (also with jobs=1): the sparse Cholesky solver behind the heat
    # method (cholespy) keeps ~V x 447 x 8 bytes per factorisation that has solved, freed only when its
    # process ends (measured: +67 MB per 9.4k-vertex task; a long-lived process grew to 2 GB)
    pool = ProcessPoolExecutor(
        max_workers=max(1, jobs), mp_context=multiprocessing.get_context("spawn"), max_tasks_per_child=1
    )
    try:
        pending = deque()
        for task in tasks:
            pending.append(pool.submit(_geodesic_task, task))
            if len(pending) >= max(1, jobs):
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()
    finally:
        pool.shutdown(cancel_futures=True)


GEODESIC_FOLDER = "geodesic_dist_matrices"
"""Folder of the loaders' geodesic layout (:func:`write_geodesic_matrices`)."""


_GEODESIC_TASK_ROWS = 4096
"""Distance rows per parallel task (one solver set-up each: ~0.3 s against ~5 s of rows at 10k vertices)."""


_GEODESIC_TASK_BYTES = 80 << 20
"""Bytes of one task's (rows, V) float32 result in :func:`mesh_blocks` (it crosses a process pipe
and waits in memory): ~2,000 rows at 10k vertices, one solver set-up (~0.9 s) per ~15 s of rows."""


def task_rows(n_vertices: int, n_faces: int) -> int:
    """Source rows per task of :func:`mesh_blocks` on a mesh of ``n_vertices`` and ``n_faces``: at most
    :data:`_GEODESIC_TASK_ROWS`, and at most :data:`_GEODESIC_TASK_BYTES` of result (at least 256),
    rounded down to a multiple of the heat solver's batch (:func:`becos.core.geodesics.heat_block_size`), so
    the tasks' rows are bitwise those of one :func:`becos.core.geodesics.distance_rows` call over all sources
    (``becos geodesic-rows``)."""
    from becos.core.geodesics import heat_block_size

    rows = int(max(1, min(_GEODESIC_TASK_ROWS, max(256, _GEODESIC_TASK_BYTES // (4 * max(n_vertices, 1))))))
    batch = heat_block_size(n_faces)
    return rows - rows % batch if rows >= batch else rows


@dataclass(frozen=True)
class GeodesicShape:
    """One shape of one pair whose matrix is to be written."""

    split: str
    pair_id: str
    side: int  # 0 = X, 1 = Y
    dataset: str
    name: str
    stem: str  # released file stem (:func:`released_file_stem`)
    mesh_id: str
    key: str  # the full mesh up to rigid motion (cache key of its rows)
    p2f: np.ndarray  # (V,) its vertices on the full mesh
    sqrt_area: float  # the full shape's sqrt-area in the units of the record's vertices
    setting: str = ""
    vertices: np.ndarray | None = None  # (V, 3) float64 as written (only when the plan keeps arrays)
    faces: np.ndarray | None = None  # (F, 3) int64


def _full_mesh_key(vertices: np.ndarray, faces: np.ndarray, dataset: str, name: str, variant: int) -> str:
    """A file-name-safe key of a full mesh up to rigid motion (:func:`becos.core.geodesics.shape_key`)."""
    import hashlib

    from becos.core.geodesics import shape_key
    from becos.core.mesh import TriMesh

    digest = hashlib.sha1(repr(shape_key(TriMesh(vertices, faces))).encode()).hexdigest()[:16]
    return f"{id_field(dataset)}_{id_field(name)}_v{int(variant)}_{digest}"


def geodesic_plan(
    records: Iterable[PairRecord], splits, each=None, keep_arrays: bool = False
) -> tuple[list[GeodesicShape], dict, dict, dict]:
    """Shapes to write, unique full meshes ``{key: (vertices, faces)}``, the rows each needs
    ``{key: sorted unique full vertices}`` (the union of its shapes' ``partial_to_full``) and the pair
    numbers ``{(split, pair_id): index}`` of ALL records (ascending pair_id per split, as every export
    numbers pairs; so a split subset keeps the whole export's numbering). Streams the records, calling
    ``each(record)`` on every one (to write other files in the same pass). ``keep_arrays``: each shape
    also keeps its written vertices and faces."""
    keep = None if splits is None else {str(s) for s in splits}
    shapes, meshes, needed, ids = [], {}, {}, {}
    for record in records:
        check_record(record, None)
        if each is not None:
            each(record)
        ids.setdefault(str(record.meta["split"]), []).append(str(record.pair_id))
        if keep is not None and str(record.meta["split"]) not in keep:
            continue
        infos = released_infos(record)
        normalised = bool(record.meta.get("area_normalised", False))
        for (s, k), info in zip(SIDES, infos):
            vertices, faces = full_shape(record, s)
            key = _full_mesh_key(vertices, faces, info["org_dataset"], info["name"], info["remesh_variant"])
            meshes.setdefault(key, (np.array(vertices, dtype=np.float64), np.array(faces, dtype=np.int64)))
            p2f = np.asarray(record[f"{s}_partial_to_full"], dtype=np.int64)
            needed.setdefault(key, []).append(p2f)
            scanned = "partial2full" in info
            shapes.append(
                GeodesicShape(
                    str(record.meta["split"]),
                    str(record.pair_id),
                    k,
                    info["org_dataset"],
                    info["name"],
                    released_file_stem(k, info["name"], info["remesh_variant"], record.pair_id if scanned else None),
                    info["mesh_id"],
                    key,
                    p2f,
                    1.0 if normalised else float(record[f"{s}_full_sqrt_area"]),
                    str(record.meta["setting"]),
                    np.asarray(record[f"{s}_vertices"], dtype=np.float64) if keep_arrays else None,
                    np.asarray(record[f"{s}_faces"], dtype=np.int64) if keep_arrays else None,
                )
            )
    numbers = {}
    for split, pair_ids in ids.items():
        pair_ids.sort()
        dup = sorted({a for a, b in zip(pair_ids, pair_ids[1:]) if a == b})
        if dup:
            raise ExportError(f"split {split}: pair ids {dup[:5]} occur more than once. Fix: pass each pair once")
        numbers.update({(split, pid): i for i, pid in enumerate(pair_ids)})
    return shapes, meshes, {key: np.unique(np.concatenate(v)) for key, v in needed.items()}, numbers


def _geodesic_task(args):
    from becos.core.geodesics import distance_rows

    key, start, vertices, faces, sources, method = args
    return key, start, distance_rows(vertices, faces, sources, method)


def _compute_geodesic_rows(
    meshes: dict, needed: dict, method: str, jobs: int, folder: Path, progress: bool
) -> dict[str, np.ndarray]:
    """``{key: (len(needed[key]), V) float32 memmap}`` of distance rows, computed in tasks of
    :data:`_GEODESIC_TASK_ROWS` rows by ``jobs`` processes (1: in this process), in ``folder``."""
    import time
    from concurrent.futures import ProcessPoolExecutor

    out = {
        key: np.lib.format.open_memmap(
            folder / f"{key}.npy", mode="w+", dtype=np.float32, shape=(len(needed[key]), len(meshes[key][0]))
        )
        for key in meshes
    }
    tasks = [
        (key, start, *meshes[key], needed[key][start : start + _GEODESIC_TASK_ROWS], method)
        for key in sorted(meshes, key=lambda k: -len(needed[k]))
        for start in range(0, len(needed[key]), _GEODESIC_TASK_ROWS)
    ]
    started, done, total = time.monotonic(), 0, sum(len(r) for r in needed.values())
    pool = ProcessPoolExecutor(max_workers=jobs) if jobs > 1 and len(tasks) > 1 else None
    try:
        for key, start, rows in pool.map(_geodesic_task, tasks) if pool else map(_geodesic_task, tasks):
            out[key][start : start + len(rows)] = rows
            done += len(rows)
            if progress:
                print(
                    f"geodesics ({method}, {jobs} jobs): {done}/{total} rows of {len(meshes)} meshes, "
                    f"{time.monotonic() - started:.0f} s",
                    file=sys.stderr,
                    flush=True,
                )
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    return out


def shape_matrix(shape: GeodesicShape, rows: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """(V, V) float32 symmetrised matrix of a shape's vertices from its full mesh's rows (float32
    throughout: two (V, V) arrays at a time, no float64 copies of a 10k-vertex matrix)."""
    sub = np.asarray(matrix[np.searchsorted(rows, shape.p2f)], dtype=np.float32)
    if not (len(shape.p2f) == sub.shape[1] and np.array_equal(shape.p2f, np.arange(sub.shape[1]))):
        sub = sub[:, shape.p2f]
    sym = sub.T + sub
    sym *= np.float32(0.5)
    np.fill_diagonal(sym, 0.0)
    return sym


def write_geodesics(
    records: Iterable[PairRecord],
    out_dir: str | Path,
    method: str = "heat",
    *,
    overwrite: bool = False,
    progress: bool = False,
    splits=None,
    jobs: int = 1,
) -> Path:
    """Write ``<out>/<split>/geodesics/<shape id>.npy``: (V, V) float32 geodesic distances of both
    shapes of every pair (units of the record's vertices), with the shape ids of :func:`write_psmal`
    (pass the same records).

    Each distinct full mesh (up to rigid motion: a remesh variant recurring across pairs) is solved
    once, for the union of the vertices its shapes keep, by ``jobs`` processes; ``splits`` limits the
    export to those splits (numbering stays that of the whole split). ``out_dir`` may already hold a
    PSMAL export; each ``<split>/geodesics`` folder appears whole (built aside, renamed in). Existing
    geodesics folders are an error unless ``overwrite``.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ExportError(f"{out}: exists and is not a folder. Fix: choose another output path")
    existing = sorted(p for p in out.glob("*/geodesics") if p.exists()) if out.is_dir() else []
    if existing and not overwrite:
        raise ExportError(
            f"{existing[0]}: geodesic matrices exist already. Fix: pass overwrite=True (--force) "
            f"or write into a new folder"
        )
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out, prefix=".geodesics.tmp-"))
    try:
        shapes, meshes, needed, numbers = geodesic_plan(records, splits)
        rows = _compute_geodesic_rows(meshes, needed, method, jobs, tmp, progress)
        built = {}
        for sh in shapes:
            target = tmp / sh.split / "geodesics"
            target.mkdir(parents=True, exist_ok=True)
            built[sh.split] = target
            shape_id = psmal_shape_id(numbers[(sh.split, sh.pair_id)], sh.side, sh.dataset, sh.name)
            np.save(target / f"{shape_id}.npy", shape_matrix(sh, needed[sh.key], rows[sh.key]))
        del rows
        for split, target in built.items():
            final = out / split / "geodesics"
            final.parent.mkdir(exist_ok=True)
            if final.exists():
                if not overwrite:
                    raise ExportError(f"{final}: appeared while writing. Fix: rerun with overwrite=True (--force)")
                old = Path(tempfile.mkdtemp(dir=out, prefix=".geodesics.old-"))
                os.replace(final, old / "geodesics")
                os.replace(target, final)
                shutil.rmtree(old, ignore_errors=True)
            else:
                os.replace(target, final)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out


GEODESIC_LAYOUTS = ("geo-lora", "dsmk")
"""The geodesic layouts :func:`write_geodesic_matrices` can write (``exports.geodesic_layouts``)."""


def symmetric_block(rows: np.ndarray, sources: np.ndarray, sqrt_area: float) -> np.ndarray:
    """(R, R) float32: the distances between the R ``sources`` of a mesh, from its (R, V) ``rows``
    (row i from vertex ``sources[i]``), symmetrised (the mean of d(a, b) and d(b, a)), zero on the
    diagonal and divided by ``sqrt_area``: the geo-lora matrix of a shape keeping exactly those vertices,
    and, cut to ``[i][:, i]``, of any shape keeping a subset (the same float32 operations entry by entry
    as :func:`shape_matrix`, so the same bytes)."""
    n = rows.shape[1]
    whole = len(sources) == n and np.array_equal(sources, np.arange(n))
    sub = np.asarray(rows if whole else rows[:, sources], dtype=np.float32)
    sym = sub.T + sub
    del sub
    sym *= np.float32(0.5)
    np.fill_diagonal(sym, 0.0)
    sym /= np.float32(sqrt_area)
    return sym


def mesh_sqrt_areas(shapes: list[GeodesicShape], known: Mapping | None = None) -> dict[str, float]:
    """``{key: sqrt_area}`` of the full meshes of ``shapes`` (the one normaliser of each mesh's block:
    its first shape's, or ``known``'s), checking that every shape of a mesh agrees to 1e-6."""
    out = dict(known or {})
    for sh in shapes:
        scale = out.setdefault(sh.key, sh.sqrt_area)
        if abs(sh.sqrt_area - scale) > 1e-6 * abs(scale):
            raise ExportError(
                f"shape {sh.name} (pair {sh.pair_id}): sqrt-area {sh.sqrt_area!r} differs from {scale!r} of "
                f"the same full mesh {sh.key}. Fix: build every setting's store with the same config "
                f"(area_normalised) and rerun `becos geodesic-plan`"
            )
    return {sh.key: out[sh.key] for sh in shapes}


_NPY_HEADER_BYTES = 128
"""Bytes of a ``.npy`` file beyond its array (the header numpy writes for a 2-D float32 array)."""


_DSMK_FILE_BYTES_PER_VERTEX = 12 + 2 * 24
"""Bytes per vertex of a DeepShapeMatchingKit file beside its matrix: float32 vertices and int64 faces
(about two faces per vertex on a closed surface)."""


def geodesic_disk_estimate(
    shapes: list[GeodesicShape],
    needed: Mapping,
    layouts=GEODESIC_LAYOUTS,
    dsmk_points: bool = True,
    blocks: bool = True,
) -> dict:
    """Bytes the geodesic layouts of ``shapes`` put on disk, counted before anything is written:
    ``blocks_bytes`` one (R, R) float32 block per distinct full mesh (R = ``len(needed[key])``; the
    full shapes' geo-lora files are hard links of it; with ``blocks`` False, e.g. read from
    ``becos geodesic-rows`` folders, they are on disk already and not counted in ``disk_bytes``),
    ``cut_bytes`` one (V_s, V_s) float32 file per other geo-lora shape (a scan), ``dsmk_bytes`` the
    DeepShapeMatchingKit files (the mesh, and the matrix too unless ``dsmk_points``; counted per pair
    side it reads, an upper bound where sides share a file). ``disk_bytes`` is their sum."""
    keys = {sh.key for sh in shapes}
    blocks_bytes = sum(4 * len(needed[k]) ** 2 + _NPY_HEADER_BYTES for k in keys)
    cuts, dsmk = {}, {}
    for sh in shapes:
        n = len(sh.p2f)
        if "geo-lora" in layouts and n != len(needed[sh.key]):  # p2f ⊆ needed: equal sets iff equal lengths
            cuts.setdefault(sh.stem, 4 * n * n + _NPY_HEADER_BYTES)
        if "dsmk" in layouts and dsmk_reads(sh.setting, sh.side):
            matrix = 0 if dsmk_points and "geo-lora" in layouts else 4 * n * n
            dsmk[(sh.split, sh.pair_id, sh.side)] = matrix + _DSMK_FILE_BYTES_PER_VERTEX * n + 1024
    out = {
        "meshes": len(keys),
        "blocks_bytes": blocks_bytes,
        "cut_files": len(cuts),
        "cut_bytes": sum(cuts.values()),
        "dsmk_files": len(dsmk),
        "dsmk_bytes": sum(dsmk.values()),
    }
    out["disk_bytes"] = (blocks_bytes if blocks else 0) + out["cut_bytes"] + out["dsmk_bytes"]
    return out


def estimate_text(estimate: Mapping, free: int) -> str:
    """One line for a log: :func:`geodesic_disk_estimate`'s figures and the free space."""
    return (
        f"{estimate['meshes']} meshes (blocks {gigabytes(estimate['blocks_bytes'])}), {estimate['cut_files']} cut "
        f"matrices ({gigabytes(estimate['cut_bytes'])}), {estimate['dsmk_files']} DeepShapeMatchingKit files "
        f"({gigabytes(estimate['dsmk_bytes'])}): about {gigabytes(estimate['disk_bytes'])} to write; "
        f"free on the output's disk: {gigabytes(free)}"
    )


def manifest_disk_estimate(manifests: Mapping, splits, n_vertices: int) -> dict:
    """An upper bound of the workflow's geodesics export from the manifests alone (before any shape is
    remeshed, e.g. in a dry run): every distinct full mesh ``(dataset, name, variant)`` of the pairs of
    ``splits`` in all settings as one (V, V) float32 block, every scanned side (x in partial_full, both
    in partial_partial) as one more, with V = ``n_vertices`` (the remesh's vertex bound). Returns
    ``{"meshes", "scans", "disk_bytes"}``."""
    keep = None if splits is None else {str(s) for s in splits}
    meshes, scans = set(), 0
    for setting, manifest in manifests.items():
        rows = manifest if keep is None else manifest[manifest["split"].astype(str).isin(keep)]
        for s in "xy":
            meshes.update(zip(rows[f"{s}_dataset"], rows[f"{s}_name"], rows[f"{s}_variant"]))
        scans += len(rows) * {"full_full": 0, "partial_full": 1, "partial_partial": 2}.get(setting, 2)
    each = 4 * int(n_vertices) ** 2 + _NPY_HEADER_BYTES
    return {"meshes": len(meshes), "scans": scans, "disk_bytes": (len(meshes) + scans) * each}


def _block_cut(path: Path, cut: np.ndarray, whole: bool) -> np.ndarray:
    """(n, n) float32 in memory: the block file's rows and columns ``cut`` (all of it when ``whole``)."""
    block = np.load(path, mmap_mode="r")
    return np.array(block) if whole else block[np.ix_(cut, cut)]


def _blocks_for(
    shapes: list, meshes: dict, needed: dict, rows_folders, method: str, jobs: int, work: Path, progress: bool
) -> dict[str, tuple[np.ndarray, Path, float]]:
    """``{key: (sorted source vertices, (R, R) block file, sqrt_area)}`` (:func:`symmetric_block`):
    read from ``rows_folders`` (outputs of ``becos geodesic-rows``; they may hold more meshes, and
    rows other stores need) or computed here one mesh at a time (:func:`mesh_blocks`: no rows file)
    and saved into ``work``."""
    from becos.atomic import save_npy

    if rows_folders is None:
        scales = mesh_sqrt_areas(shapes)
        out = {}
        for key, sources, block in mesh_blocks(meshes, needed, scales, method, jobs, progress):
            path = work / f"{key}.block.npy"
            save_npy(path, block)
            del block
            out[key] = (sources, path, scales[key])
        return out
    out = rows_covering(rows_folders, needed, meshes)
    mesh_sqrt_areas(shapes, {key: scale for key, (_, _, scale) in out.items()})  # the store agrees with them
    return out


def write_geodesic_matrices(
    records: Iterable[PairRecord],
    out_dir: str | Path,
    method: str = "heat",
    *,
    splits=None,
    jobs: int = 1,
    metadata: Mapping | None = None,
    overwrite: bool = False,
    progress: bool = False,
    rows=None,
    layouts=GEODESIC_LAYOUTS,
    dsmk_copies: bool = False,
    free_bytes: int | None = None,
) -> Path:
    """Geodesic matrices in the layouts loaders read (``docs/released-layout.md``, section 3):

    - ``<out>/geodesic_dist_matrices/<stem>.npy``: (V, V) float32 distances between the vertices of the
      released file ``<stem>.off`` (:func:`released_file_stem`; measured on the shape's FULL mesh),
      divided by the full shape's sqrt-area (the released ``surface_area_after_scaling``): the file
      geo-lora's ``BecosDataset`` loads from ``./geodesic_dist_matrices/<off stem>.npy`` instead of
      computing it. ``index.csv`` beside them lists every shape of every pair with its split, pair
      index, pair_id, stem, mesh_id, vertex count, the sqrt-area (multiply to get the record's units)
      and its DeepShapeMatchingKit file.
    - ``<out>/dsmk/<split>/dist/<sha1>_0.npz``: DeepShapeMatchingKit's geodesic cache
      (:func:`dsmk_cache_name`; keys ``verts`` float32, ``faces`` int64, ``result`` (V, V) float32 in
      the units of the written vertices, which its ``BeCoSDataset`` divides by the info file's
      ``surface_area_after_scaling``) of every shape it gives geodesics to; link or copy
      ``dsmk/<split>/dist`` to ``<released export>/<split>/dist``.
    - ``<out>/logs/config.yaml`` as the other exports.

    Each distinct full mesh is solved once for the union of the vertices its shapes keep, by ``jobs``
    processes, or its blocks are read from ``rows`` (folders written by ``becos geodesic-rows``);
    ``splits`` (e.g. ``["test"]``) limits the export to those splits. ``layouts``: which of
    :data:`GEODESIC_LAYOUTS` to write (``index.csv`` is always written).

    Every matrix is written once: a geo-lora file equal to its mesh's block (:func:`symmetric_block`;
    every full shape) is a hard link of the block file (a copy where the file system has no hard
    links), so a full mesh shared by pairs, sides and settings costs its bytes once; other shapes' files
    are cut from the block, in one buffered write each. A DeepShapeMatchingKit file is a zip holding the
    shape's own (rotated) vertices, so it cannot be a link: with the geo-lora layout in the same export
    its ``result`` points at the shape's geo-lora file (:func:`save_dsmk_pointer`: the file holds the
    mesh and a few hundred bytes, the loader reads the geo-lora matrix times the sqrt-area); with
    ``dsmk_copies`` (a self-contained folder, e.g. to copy elsewhere) or without the geo-lora layout it
    holds the matrix itself (the block cut times the sqrt-area, equal to the unnormalised matrix to
    float32 round-off). Both give the loader the same bytes.

    Before anything is computed the disk the export adds is estimated (:func:`geodesic_disk_estimate`)
    and printed with the free space of the output's file system (``free_bytes`` when given); an estimate
    above it stops the export (:class:`DiskEstimateError`) and leaves ``out`` untouched.
    """
    unknown = sorted(set(layouts) - set(GEODESIC_LAYOUTS))
    if unknown or not layouts:
        raise ExportError(f"geodesic layouts {unknown or '(none)'}: unknown. Fix: choose from {GEODESIC_LAYOUTS}")

    out = Path(out_dir)
    dsmk_points = "geo-lora" in layouts and not dsmk_copies
    with staged_dir(out, overwrite) as tmp:
        shapes, meshes, needed, numbers = _geodesic_plan_with_room(
            records, splits, layouts, dsmk_points, rows, out, tmp, free_bytes
        )
        work = tmp / ".rows"
        work.mkdir()
        blocks = _blocks_for(shapes, meshes, needed, rows, method, jobs, work, progress)
        folder = tmp / GEODESIC_FOLDER
        folder.mkdir()
        table = _write_shapes(shapes, blocks, numbers, layouts, folder, tmp, out if dsmk_points else None)
        shutil.rmtree(work)
        _write_geodesic_index(tmp, folder, table, method, metadata)
    return out


def _geodesic_plan_with_room(records, splits, layouts, dsmk_points: bool, rows, out: Path, tmp: Path, free_bytes):
    """:func:`geodesic_plan` of ``records``, once the disk under ``tmp`` has room for what it writes
    (the estimate is printed; :class:`DiskEstimateError` naming ``out`` otherwise)."""
    shapes, meshes, needed, numbers = geodesic_plan(records, splits, keep_arrays=True)
    estimate = geodesic_disk_estimate(shapes, needed, layouts, dsmk_points, blocks=rows is None)
    free = free_space(tmp, free_bytes)
    print(f"export-geodesics: {estimate_text(estimate, free)}", file=sys.stderr, flush=True)
    require_room(
        out,
        estimate["disk_bytes"],
        free,
        "the geodesic matrices",
        "free disk space, choose another output folder on a larger disk, or export fewer splits "
        "(--splits test) or layouts (--layouts geo-lora)",
    )
    return shapes, meshes, needed, numbers


def _write_shapes(shapes, blocks, numbers, layouts, folder: Path, tmp: Path, pointed: Path | None) -> list[list]:
    """Each shape's files in ``layouts`` (geo-lora under ``folder``, DeepShapeMatchingKit under ``tmp``;
    its files point into ``pointed``'s geo-lora folder when given, else hold copies). Returns the
    index rows, one per pair side."""
    table, written, dsmk_written = [], set(), set()
    for sh in shapes:
        sources, path, scale = blocks[sh.key]
        cut = np.searchsorted(sources, sh.p2f)
        whole = len(cut) == len(sources) and np.array_equal(cut, np.arange(len(sources)))
        matrix = None  # the shape's geo-lora matrix, when read
        if "geo-lora" in layouts and sh.stem not in written:  # one full mesh in several pairs: one file
            written.add(sh.stem)
            matrix = _write_geo_lora(folder / f"{sh.stem}.npy", path, cut, whole)
        dsmk_file = ""
        if "dsmk" in layouts and dsmk_reads(sh.setting, sh.side):
            dsmk_file = f"{DSMK_FOLDER}/{sh.split}/dist/{dsmk_cache_name(sh.vertices, sh.faces)}"
            if dsmk_file not in dsmk_written:
                dsmk_written.add(dsmk_file)
                target = None if pointed is None else pointed.resolve() / GEODESIC_FOLDER / f"{sh.stem}.npy"
                _write_dsmk(tmp / dsmk_file, sh, target, path, cut, whole, matrix, scale)
        del matrix
        index = numbers[(sh.split, sh.pair_id)]
        table.append([sh.split, index, sh.pair_id, sh.side, sh.stem, sh.mesh_id, len(sh.p2f), repr(scale), dsmk_file])
    return table


def _write_geo_lora(path: Path, block: Path, cut: np.ndarray, whole: bool) -> np.ndarray | None:
    """Write the geo-lora file ``path`` of a shape: the mesh's ``block`` file itself (linked) when the
    shape keeps every vertex, else its ``cut`` rows and columns. Returns the cut matrix (None if linked)."""
    from becos.atomic import link_or_copy, save_npy

    if whole:
        link_or_copy(block, path)
        return None
    matrix = _block_cut(block, cut, whole)
    save_npy(path, matrix)
    return matrix


def _write_dsmk(path: Path, sh: GeodesicShape, target, block: Path, cut, whole: bool, matrix, scale: float) -> None:
    """Write DeepShapeMatchingKit's cache file ``path`` of shape ``sh``: a pointer to its geo-lora file
    ``target`` (when not None), else a copy of the matrix (``matrix``, or cut from ``block``) times
    ``scale``, the full shape's sqrt-area (its loader divides by it itself)."""
    from becos.atomic import save_npz

    path.parent.mkdir(parents=True, exist_ok=True)
    if target is not None:
        save_dsmk_pointer(path, sh.vertices, sh.faces, target, scale)
        return
    result = _block_cut(block, cut, whole) if matrix is None else matrix
    result *= np.float32(scale)  # DSMK divides by the info file's sqrt-area itself
    verts = sh.vertices.astype(np.float32)
    save_npz(path, verts=verts, faces=sh.faces, result=result)


def _write_geodesic_index(tmp: Path, folder: Path, table: list, method: str, metadata) -> None:
    """``index.csv`` of the geo-lora folder (one row per pair side) and the export's log."""
    write_ids(
        folder / "index.csv",
        ["split", "index", "pair_id", "side", "stem", "mesh_id", "n_vertices", "sqrt_area", "dsmk_file"],
        table,
    )
    counts = {split: len({r[2] for r in table if r[0] == split}) for split in dict.fromkeys(r[0] for r in table)}
    write_log(
        tmp,
        "becos.products.export.write_geodesic_matrices",
        f"becos geodesic matrices ({method}, divided by sqrt-area; DeepShapeMatchingKit cache)",
        counts,
        None,
        metadata,
    )


class GeodesicJobError(BecosError):
    """A geodesic plan or part file that cannot be used."""


def load_rows(folders) -> dict[str, tuple[np.ndarray, Path, float]]:
    """``{key: (sources (R,) int64 sorted, block file (R, R) float32, sqrt_area)}`` of every mesh in
    ``folders`` (outputs of :func:`becos.products.geodesic_jobs.solve_part`)."""
    out = {}
    for folder in folders:
        folder = Path(folder)
        if not folder.is_dir():
            raise GeodesicJobError(f"{folder}: no geodesic rows folder. Fix: run `becos geodesic-rows` for it")
        try:
            timings = json.loads((folder / "timings.json").read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise GeodesicJobError(
                f"{folder}/timings.json: unreadable ({exc}). Fix: rerun `becos geodesic-rows`"
            ) from exc
        for path in sorted(folder.glob("*.sources.npy")):
            key = path.name[: -len(".sources.npy")]
            block = np.load(folder / f"{key}.npy", mmap_mode="r")
            sources = np.load(path)
            if block.shape != (len(sources), len(sources)) or key not in timings:
                raise GeodesicJobError(
                    f"{folder / key}.npy: a {block.shape} block for {len(sources)} sources. "
                    f"Fix: rerun `becos geodesic-rows`"
                )
            out[key] = (sources, folder / f"{key}.npy", float(timings[key]["sqrt_area"]))
    return out
