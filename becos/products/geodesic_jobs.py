"""Geodesic rows as parallel jobs: each distinct full mesh of every setting solved once, in parts.

Three steps (``workflow/rules/export.smk``): ``becos geodesic-plan`` lists every distinct full mesh of
the stores with the vertices the chosen splits keep and spreads them over N parts
(``PLAN/part_<k>.npz``, ``PLAN/plan.json``); ``becos geodesic-rows`` solves one part into (R, R)
float32 blocks ``OUT/<key>.npy`` (heat-method distances over the full mesh's sqrt-area);
``becos export-geodesics`` links or cuts each shape's matrix from those blocks into the loaders'
layouts. File contents and shapes per step: docs/design/evaluate.md.
"""

from __future__ import annotations

import json
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from becos.products.export.geodesics import (
    GeodesicJobError,
    estimate_text,
    geodesic_disk_estimate,
    geodesic_plan,
    mesh_sqrt_areas,
    symmetric_block,
)

WORKFLOW_PARTS = 8
"""Parts (``geodesic_rows`` jobs) of the workflow's geodesic plan: enough to keep a few cores or cluster
nodes busy with the ~10-100 distinct full meshes of a test split, few enough that each job's start-up
(~2 s) stays small against its meshes (~13 s of CPU per 10k-vertex mesh)."""

SEPARATOR = "|"
"""Between a mesh key and the array name in a part file (keys are file-name safe, never hold it)."""


def plan_parts(meshes: dict, needed: dict, parts: int) -> list[list[str]]:
    """Mesh keys per part: largest cost (rows x vertices) first, each onto the least loaded part.
    Deterministic (ties by key)."""
    load = [0] * max(1, int(parts))
    out: list[list[str]] = [[] for _ in load]
    for key in sorted(meshes, key=lambda k: (-len(needed[k]) * len(meshes[k][0]), k)):
        k = min(range(len(load)), key=lambda i: (load[i], i))
        out[k].append(key)
        load[k] += len(needed[key]) * len(meshes[key][0])
    return out


def write_plan(stores: list[Path], out: Path, parts: int, splits=None) -> dict:
    """Write ``out/part_<k>.npz`` (k < ``parts``, some possibly empty) and ``out/plan.json`` for the
    stores' shapes of ``splits`` (None: every split). Returns the plan summary."""
    from becos.atomic import save_npz, write_text
    from becos.products.store import open_benchmark

    meshes, needed, scales, every_shape = {}, {}, {}, []
    for store in stores:
        shapes, store_meshes, store_needed, _ = geodesic_plan(open_benchmark(store).records(), splits)
        every_shape += shapes
        for key, mesh in store_meshes.items():
            meshes.setdefault(key, mesh)
            needed.setdefault(key, []).append(store_needed[key])
        for key, scale in mesh_sqrt_areas(shapes, scales).items():
            scales.setdefault(key, scale)
    needed = {key: np.unique(np.concatenate(v)) for key, v in needed.items()}
    assignment = plan_parts(meshes, needed, parts)
    out.mkdir(parents=True, exist_ok=True)
    summary = {
        "parts": len(assignment),
        "splits": None if splits is None else sorted(splits),
        "stores": [str(s) for s in stores],
        "meshes": {},
    }
    for k, keys in enumerate(assignment):
        arrays = {}
        for key in keys:
            vertices, faces = meshes[key]
            arrays[f"{key}{SEPARATOR}vertices"] = vertices
            arrays[f"{key}{SEPARATOR}faces"] = faces
            arrays[f"{key}{SEPARATOR}sources"] = needed[key]
            arrays[f"{key}{SEPARATOR}sqrt_area"] = np.float64(scales[key])
            summary["meshes"][key] = {"part": k, "n_vertices": len(vertices), "n_rows": len(needed[key])}
        save_npz(out / f"part_{k}.npz", **arrays)
    # the disk of every setting's geo-lora layout: blocks (the full shapes' files link them) and scans' cuts
    summary["estimate"] = geodesic_disk_estimate(every_shape, needed, ("geo-lora",))
    free = shutil.disk_usage(out).free
    print(f"geodesic-plan: {estimate_text(summary['estimate'], free)}", file=sys.stderr, flush=True)
    if summary["estimate"]["disk_bytes"] > free:
        print(
            "geodesic-plan: warning: the geodesics export will not fit the free disk. Fix: free disk space, "
            "or export fewer splits (exports.geodesic_splits)",
            file=sys.stderr,
            flush=True,
        )
    write_text(out / "plan.json", json.dumps(summary, indent=1, sort_keys=True) + "\n")
    return summary


PART_FIELDS = ("vertices", "faces", "sources", "sqrt_area")
"""The arrays of one mesh in a part file."""


def read_part(path: Path) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, float]]:
    """``{key: (vertices, faces, sources, sqrt_area)}`` of one part file."""
    try:
        data = np.load(path)
    except (OSError, ValueError) as exc:
        raise GeodesicJobError(f"{path}: not a geodesic part file ({exc}). Fix: rerun `becos geodesic-plan`") from exc
    out = {}
    with data:
        for name in data.files:
            key, _, field = name.rpartition(SEPARATOR)
            out.setdefault(key, {})[field] = data[name]
    for key, fields in out.items():
        if set(fields) != set(PART_FIELDS):
            raise GeodesicJobError(
                f"{path}: mesh {key} lacks {sorted(set(PART_FIELDS) - set(fields))}. Fix: rerun `becos geodesic-plan`"
            )
    return {key: (f["vertices"], f["faces"], f["sources"], float(f["sqrt_area"])) for key, f in out.items()}


def solve_part(part: Path, out: Path, method: str = "heat", progress: bool = False) -> dict:
    """Write the normalised symmetric block of every mesh of ``part`` into the folder ``out`` (built
    aside, renamed in). Returns ``{key: {n_vertices, n_rows, sqrt_area, cpu_s, write_s, bytes}}`` (also
    ``out/timings.json``; ``write_s``: wall seconds of symmetrising and writing the block)."""
    from becos.atomic import atomic_folder, save_npy
    from becos.core.geodesics import distance_rows

    meshes = read_part(part)
    with atomic_folder(out) as tmp:  # one job solves a part
        timings = {}
        for key, (vertices, faces, sources, sqrt_area) in meshes.items():
            started = time.process_time()
            rows = distance_rows(vertices, faces, sources, method)
            cpu = time.process_time() - started
            started = time.monotonic()
            block = symmetric_block(rows, sources, sqrt_area)
            del rows
            written = save_npy(tmp / f"{key}.npy", block)
            del block
            save_npy(tmp / f"{key}.sources.npy", sources)
            timings[key] = {
                "n_vertices": len(vertices),
                "n_rows": len(sources),
                "sqrt_area": sqrt_area,
                "cpu_s": round(cpu, 3),
                "write_s": round(time.monotonic() - started, 3),
                "bytes": written,
            }
            if progress:
                print(json.dumps({key: timings[key]}), file=sys.stderr, flush=True)
        (tmp / "timings.json").write_text(json.dumps(timings, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    return timings
