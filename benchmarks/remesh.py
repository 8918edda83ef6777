"""Remeshing benchmark on all 76 TOSCA shapes: time, vertex counts, distances, sample sharing.

Run: ``python benchmarks/remesh.py [--sample]`` (JSON on stdout). ``--sample`` runs one shape per
class only. All distances are relative to the input's bounding-box diagonal.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SEED = 42
SAMPLE = ["cat0", "centaur3", "david0", "dog0", "horse5", "michael0", "victoria0", "wolf0"]


def _tosca_dir() -> Path:
    out = subprocess.run(
        [str(REPO.parent / "shared" / "unpack")], check=True, capture_output=True, text=True
    ).stdout.strip()
    return Path(out.splitlines()[-1]) / "data" / "tosca-off"


def remesh_benchmark(names: list[str] | None = None, variant_shapes: list[str] | None = None) -> dict:
    """Remesh TOSCA shapes (variant 0 targets, seed 42) and measure them.

    Args:
        names: shapes to remesh (default: all 76).
        variant_shapes: shapes also remeshed as variant 1, to measure sharing between variants
            (default: one per class).
    Returns a JSON-ready dict: per-shape rows and a summary.
    """
    from becos.geometry import SurfaceLocator, points_on_surface
    from becos.mesh import MeshCache
    from becos.remesh import (
        intrinsic_coincidence,
        mesh_checks,
        remesh_with_stats,
        shared_vertex_share,
        variant_target_vertices,
    )

    tosca = _tosca_dir()
    all_names = sorted(p.stem for p in tosca.glob("*.off"))
    names = all_names if names is None else names
    variant_shapes = SAMPLE if variant_shapes is None else variant_shapes
    cache = MeshCache(None)
    rows, results = {}, {}
    t_all = time.perf_counter()
    for name in names:
        original = cache.load(tosca / f"{name}.off")
        target = variant_target_vertices(SEED, "tosca", name, 0)
        r, stats = remesh_with_stats(original, target)
        d = float(np.linalg.norm(np.ptp(original.vertices, axis=0)))
        facts = mesh_checks(r.mesh)
        loc = SurfaceLocator(original)
        on_remesh = points_on_surface(r.mesh, r.from_original.face, r.from_original.weights)
        bf, bw, _ = loc.closest(on_remesh)
        round_trip = np.linalg.norm(points_on_surface(original, bf, bw) - original.vertices, axis=1)
        rows[name] = {
            "original_vertices": original.n_vertices,
            "target_vertices": target,
            "vertices": r.mesh.n_vertices,
            "faces": r.mesh.n_faces,
            "seconds": round(r.seconds, 3),
            "seconds_prepare": round(stats["seconds_prepare"], 3),
            "seconds_decimate": round(stats["seconds_decimate"], 3),
            "attempts": stats["attempts"],
            "dropped_faces": stats["dropped_faces"],
            "snap_flipped_faces": stats["snap_flipped_faces"],
            "unsnapped_vertices": stats["unsnapped_vertices"],
            "presnap_distance_mean_rel": stats["snap_distance_mean"] / d,
            "presnap_distance_max_rel": stats["snap_distance_max"] / d,
            "to_original_distance_max_rel": float(r.to_original.distance.max()) / d,
            "from_original_distance_mean_rel": float(r.from_original.distance.mean()) / d,
            "from_original_distance_p99_rel": float(np.percentile(r.from_original.distance, 99)) / d,
            "from_original_distance_max_rel": float(r.from_original.distance.max()) / d,
            "round_trip_mean_rel": float(round_trip.mean()) / d,
            "round_trip_max_rel": float(round_trip.max()) / d,
            "components": facts["components"],
            "non_manifold_edges": facts["non_manifold_edges"],
            "misoriented_edges": facts["misoriented_edges"],
            "euler_ok": facts["euler_characteristic"] == mesh_checks(original)["euler_characteristic"],
        }
        results[name] = (original, r)
        print(f"{name}: {rows[name]['vertices']} v in {r.seconds:.2f} s", file=sys.stderr, flush=True)

    # sample sharing between poses of one class (pose listed first vs every other pose)
    same_class = {}
    classes: dict[str, list[str]] = {}
    for name in names:
        classes.setdefault(re.sub(r"\d+$", "", name), []).append(name)
    for members in classes.values():
        members = sorted(members, key=lambda n: int(re.search(r"\d+$", n).group()))
        a = members[0]
        for b in members[1:]:
            (oa, ra), (ob, rb) = results[a], results[b]
            same_class[f"{a}/{b}"] = {
                "shared_original_vertex": shared_vertex_share(ra, oa.faces, rb, ob.faces),
                "intrinsic": max(
                    intrinsic_coincidence(ra, oa.faces, rb, ob), intrinsic_coincidence(rb, ob.faces, ra, oa)
                ),
            }
    variants = {}
    for name in variant_shapes:
        if name not in results:
            continue
        original, r0 = results[name]
        r1, _ = remesh_with_stats(original, variant_target_vertices(SEED, "tosca", name, 1))
        variants[name] = {
            "targets": [r0.target_vertices, r1.target_vertices],
            "shared_original_vertex": shared_vertex_share(r0, original.faces, r1, original.faces),
            "intrinsic": intrinsic_coincidence(r0, original.faces, r1, original),
        }

    secs = np.array([row["seconds"] for row in rows.values()])
    humans = [row["seconds"] for n, row in rows.items() if n.startswith(("michael", "david"))]
    summary = {
        "shapes": len(rows),
        "wall_seconds": round(time.perf_counter() - t_all, 1),
        "seconds_per_shape": {"min": float(secs.min()), "median": float(np.median(secs)), "max": float(secs.max())},
        "seconds_michael_david": {"median": float(np.median(humans)), "max": float(max(humans))} if humans else None,
        "all_exact_vertex_target": all(row["vertices"] == row["target_vertices"] for row in rows.values()),
        "vertex_range": [min(r["vertices"] for r in rows.values()), max(r["vertices"] for r in rows.values())],
        "all_single_component_manifold_oriented": all(
            r["components"] == 1 and r["non_manifold_edges"] == 0 and r["misoriented_edges"] == 0 and r["euler_ok"]
            for r in rows.values()
        ),
        "snap_flipped_faces_total": sum(r["snap_flipped_faces"] for r in rows.values()),
        "dropped_faces_total": sum(r["dropped_faces"] for r in rows.values()),
        "unsnapped_vertices_max": max(r["unsnapped_vertices"] for r in rows.values()),
        "presnap_distance_mean_rel_max": max(r["presnap_distance_mean_rel"] for r in rows.values()),
        "from_original_distance_mean_rel_max": max(r["from_original_distance_mean_rel"] for r in rows.values()),
        "from_original_distance_max_rel_max": max(r["from_original_distance_max_rel"] for r in rows.values()),
        "round_trip_mean_rel_max": max(r["round_trip_mean_rel"] for r in rows.values()),
        "same_class_shared_original_vertex_max": max(
            (v["shared_original_vertex"] for v in same_class.values()), default=None
        ),
        "same_class_intrinsic_max": max((v["intrinsic"] for v in same_class.values()), default=None),
        "variants_shared_original_vertex_max": max(
            (v["shared_original_vertex"] for v in variants.values()), default=None
        ),
        "variants_intrinsic_max": max((v["intrinsic"] for v in variants.values()), default=None),
    }
    return {"summary": summary, "shapes": rows, "same_class": same_class, "variants": variants}


if __name__ == "__main__":
    sample = "--sample" in sys.argv[1:]
    print(json.dumps(remesh_benchmark(SAMPLE if sample else None), indent=1))
