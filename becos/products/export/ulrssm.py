"""ULRSSM style layout (:func:`write_ulrssm`): one ``off/``, ``corres/*.vts`` (template convention) and
optional ``dist/*.mat`` root per pair, with the disk and memory estimate of the geodesic matrices
(``docs/released-layout.md``, section ULRSSM).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from becos.build.record import PairRecord
from becos.core.formats.write import off_text, vts_text
from becos.products.export.geodesics import (
    GeodesicShape,
    cut_chunks,
    geodesic_plan,
    mesh_blocks,
    mesh_sqrt_areas,
    task_rows,
)
from becos.products.export.mat import WRITE_CHUNK_BYTES, mat_size, write_symmetric_mat
from becos.products.export.staging import (
    IDS_FILE,
    LOGS_DIR,
    SIDES,
    Staging,
    free_space,
    gigabytes,
    place_by_split,
    require_room,
    staged_dir,
    write_ids,
    write_log,
)


def ulrssm_template_vts(record: PairRecord) -> tuple[str, str]:
    """The two ``corres/<k>.vts`` texts of a pair in ULRSSM's template convention: line t of each file
    is the 1-based vertex of that shape at template point t, so that point t pairs vertex
    ``vts0[t] - 1`` of shape 0 with vertex ``vts1[t] - 1`` of shape 1. The template points are the
    vertices of shape 1 that have a counterpart (record ``corr_10`` != -1, in vertex order): the pair's
    ground truth Y -> X, the direction every setting has (P2F: partial Y -> full X). ULRSSM subtracts 1
    and has no "none" value, hence only matched vertices."""
    corr = np.asarray(record["corr_10"], dtype=np.int64)
    matched = np.flatnonzero(corr >= 0)
    return vts_text(corr[matched] + 1), vts_text(matched + 1)


def write_ulrssm(
    records: Iterable[PairRecord],
    out_dir: str | Path,
    *,
    metadata: Mapping | None = None,
    overwrite: bool = False,
    progress: bool = False,
    geodesics: bool = False,
    method: str = "heat",
    splits=None,
    jobs: int = 1,
    rows=None,
    free_bytes: int | None = None,
) -> Path:
    """Write the records ULRSSM style (``docs/released-layout.md``, section ULRSSM): one data root per
    pair, ``<out>/<split>/<i>/`` with ``off/0.off``, ``off/1.off``, ``corres/0.vts``, ``corres/1.vts``
    (:func:`ulrssm_template_vts`) and, with ``geodesics``, ``dist/0.mat``, ``dist/1.mat``: MATLAB v5
    files, key ``dist``, (V, V) float32 geodesic distances on the full shape divided by its sqrt-area
    (the values of :func:`write_geodesic_matrices`; only for ``splits`` when given).
    ULRSSM's ``PairDataset`` pairs every two shapes of its data root, so one root per pair keeps our
    pairs. ``ids.csv`` and ``logs/config.yaml`` as :func:`write_released`.

    Geodesics (:func:`_write_ulrssm_dist`): each distinct matrix (a full mesh up to rigid motion, or
    one cut of it that a scan keeps) is written ONCE, streamed from its mesh's (R, R) block, and every
    other pair side showing it gets a hard link (a copy only where the file system refuses links,
    reported on stderr and in ``logs/geodesics.json``). The blocks are computed one mesh at a time by
    ``jobs`` processes, or read from ``rows`` (folders of ``becos geodesic-rows``: the workflow's one
    geodesic computation). Before any matrix is written the disk (distinct files × V² × 4 bytes) and
    the peak memory are estimated and printed; an estimate above the free space of the output's file
    system (``free_bytes`` when given, else :func:`shutil.disk_usage`) stops the export
    (:class:`DiskEstimateError`) and leaves ``out`` untouched."""
    out = Path(out_dir)
    with staged_dir(out, overwrite) as tmp:
        staging = Staging(tmp, "export-ulrssm", progress)
        settings = set()

        def write_pair(record: PairRecord) -> None:
            settings.add(record.meta["setting"])
            folder = staging.add(record)
            (folder / "off").mkdir()
            (folder / "corres").mkdir()
            for s, k in SIDES:
                (folder / "off" / f"{k}.off").write_text(
                    off_text(record[f"{s}_vertices"], record[f"{s}_faces"]), encoding="utf-8"
                )
            for k, text in enumerate(ulrssm_template_vts(record)):
                (folder / "corres" / f"{k}.vts").write_text(text, encoding="utf-8")

        shapes, meshes, needed, numbers = geodesic_plan(records, splits if geodesics else [], each=write_pair)
        id_rows, counts = place_by_split(staging, tmp)
        if geodesics and shapes:
            summary = _write_ulrssm_dist(
                tmp, out, shapes, meshes, needed, numbers, method, jobs, progress, rows, free_bytes
            )
            (tmp / LOGS_DIR).mkdir(exist_ok=True)
            (tmp / LOGS_DIR / "geodesics.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
        write_ids(tmp / IDS_FILE, ["split", "index", "pair_id", "x", "y"], id_rows)
        setting = settings.pop() if len(settings) == 1 else None
        write_log(tmp, "becos.products.export.write_ulrssm", "becos ULRSSM-style layout", counts, setting, metadata)
    return out


_SOLVER_BYTES_PER_VERTEX = 40_000
"""Peak memory of one heat-method task beyond its result, per mesh vertex (factorisations, (V, B) and
(2F, B) solve blocks; measured: 0.34 GB at 9,369 vertices), for :func:`ulrssm_geodesic_estimate`."""


_PROCESS_BYTES = 150 << 20
"""Resident memory of a Python process with numpy, scipy and libigl loaded (a worker or this one)."""


def distinct_matrices(shapes: list[GeodesicShape]) -> dict[str, dict[bytes, list[GeodesicShape]]]:
    """The pair sides grouped by the distance matrix they show: ``{mesh key: {cut digest: [sides]}}``,
    one group per full mesh (up to rigid motion) and vertices kept (a scan's cut); each group is one
    file, the other sides hard links of it."""
    import hashlib

    groups: dict[str, dict[bytes, list[GeodesicShape]]] = {}
    for sh in shapes:
        digest = hashlib.sha1(np.ascontiguousarray(sh.p2f, dtype=np.int64).tobytes()).digest()
        groups.setdefault(sh.key, {}).setdefault(digest, []).append(sh)
    return groups


def ulrssm_geodesic_estimate(
    groups: dict[str, dict[bytes, list[GeodesicShape]]], needed: dict, meshes: dict, jobs: int, computed: bool
) -> dict:
    """The ULRSSM geodesics export's cost before it starts: ``files`` distinct matrices
    (:func:`distinct_matrices` ``groups``) for ``sides`` pair sides, ``disk_bytes`` their MAT files
    (Σ 4 n² + headers; links cost nothing), ``memory_bytes`` the peak resident memory of this process
    and its ``jobs`` workers together (the largest (R, R) float32 block, a write chunk, and while
    ``computed``: the tasks in flight, (rows, V) float32 each, plus each worker's solver)."""
    distinct = [group for by_cut in groups.values() for group in by_cut.values()]
    disk = sum(mat_size(len(group[0].p2f)) for group in distinct)
    memory = 0
    for key, sources in needed.items():
        r, v = len(sources), len(meshes[key][0])
        peak = _PROCESS_BYTES + 4 * r * r + WRITE_CHUNK_BYTES  # this process: the block, a write chunk
        if computed:  # `jobs` results waiting here + one being cut in; per worker: its solve and pickled result
            task = 4 * min(r, task_rows(v, len(meshes[key][1]))) * v  # one task's (rows, V) float32 result
            workers = max(1, jobs)
            peak += (workers + 1) * task + workers * (_PROCESS_BYTES + _SOLVER_BYTES_PER_VERTEX * v + 2 * task)
        memory = max(memory, peak)
    return {
        "meshes": len(needed),
        "files": len(distinct),
        "sides": sum(len(group) for group in distinct),
        "disk_bytes": int(disk),
        "memory_bytes": int(memory),
        "largest_mesh_rows": max((len(s) for s in needed.values()), default=0),
    }


def _write_ulrssm_dist(
    tmp: Path,
    out: Path,
    shapes: list[GeodesicShape],
    meshes: dict,
    needed: dict,
    numbers: dict,
    method: str,
    jobs: int,
    progress: bool,
    rows_folders=None,
    free_bytes: int | None = None,
) -> dict:
    """Write ``<tmp>/<split>/<i>/dist/<side>.mat`` of every shape (:func:`write_ulrssm`); returns the
    summary written to ``logs/geodesics.json`` (estimate, files, links, copies, bytes, seconds)."""
    import time

    started = time.monotonic()
    scales = mesh_sqrt_areas(shapes)
    groups = distinct_matrices(shapes)
    estimate, free = _ulrssm_estimate_with_room(tmp, out, groups, needed, meshes, jobs, rows_folders, free_bytes)

    def dist_path(sh: GeodesicShape) -> Path:
        return tmp / sh.split / str(numbers[(sh.split, sh.pair_id)]) / "dist" / f"{sh.side}.mat"

    written = links = copies = nbytes = 0
    for key, sources, block in mesh_blocks(
        meshes, needed, scales, method, jobs, progress, rows_folders, "export-ulrssm geodesics"
    ):
        for group in groups[key].values():
            n_links, n_copies, n_bytes = _write_distinct_matrix(group, sources, block, dist_path)
            written, links, copies, nbytes = written + 1, links + n_links, copies + n_copies, nbytes + n_bytes
        del block
    if copies:
        print(
            f"export-ulrssm geodesics: {out}: the file system refused hard links; {copies} dist files are "
            f"copies ({gigabytes(nbytes - estimate['disk_bytes'])} more than estimated)",
            file=sys.stderr,
            flush=True,
        )
    summary = {
        "method": method,
        "estimate": {**estimate, "free_bytes": free},
        "written": written,
        "hard_links": links,
        "copies": copies,
        "bytes": nbytes,
        "seconds": round(time.monotonic() - started, 1),
        "rows_from": [str(p) for p in rows_folders] if rows_folders is not None else None,
    }
    if progress:
        print(f"export-ulrssm geodesics: {json.dumps(summary)}", file=sys.stderr, flush=True)
    return summary


def _ulrssm_estimate_with_room(tmp: Path, out: Path, groups, needed, meshes, jobs: int, rows_folders, free_bytes):
    """:func:`ulrssm_geodesic_estimate` and the free bytes under ``tmp``, printed, once the disk has room
    for the dist files (:class:`DiskEstimateError` naming ``out`` otherwise)."""
    estimate = ulrssm_geodesic_estimate(groups, needed, meshes, jobs, rows_folders is None)
    free = free_space(tmp, free_bytes)
    print(
        f"export-ulrssm geodesics: {estimate['files']} distinct dist matrices of {estimate['meshes']} meshes for "
        f"{estimate['sides']} pair sides (the rest hard links): disk {gigabytes(estimate['disk_bytes'])}, peak memory "
        f"~{gigabytes(estimate['memory_bytes'])} ({jobs} jobs, largest mesh {estimate['largest_mesh_rows']} vertices); "
        f"free on the output's disk: {gigabytes(free)}",
        file=sys.stderr,
        flush=True,
    )
    require_room(
        out,
        estimate["disk_bytes"],
        free,
        "the ULRSSM geodesic matrices",
        "free disk space, choose another --out on a larger disk, or export geodesics of fewer splits (--splits test)",
        f"{estimate['files']} distinct (V, V) float32 .mat files of {estimate['meshes']} meshes",
    )
    return estimate, free


def _write_distinct_matrix(group: list[GeodesicShape], sources: np.ndarray, block: np.ndarray, dist_path):
    """One distinct dist matrix: the first shape of ``group`` gets the MAT file of ``block`` (rows and
    columns ``sources``) cut to its vertices, the others hard links to it (copies where refused).
    Returns (links, copies, bytes written)."""
    from becos.atomic import link_or_copy

    first = group[0]
    cut = np.searchsorted(sources, first.p2f)
    whole = len(cut) == len(sources) and np.array_equal(cut, np.arange(len(sources)))
    path = dist_path(first)
    path.parent.mkdir(exist_ok=True)
    nbytes, links, copies = write_symmetric_mat(path, len(cut), cut_chunks(block, None if whole else cut)), 0, 0
    for sh in group[1:]:
        dist_path(sh).parent.mkdir(exist_ok=True)
        if link_or_copy(path, dist_path(sh)):
            links += 1
        else:
            copies += 1
            nbytes += path.stat().st_size
    return links, copies, nbytes
