"""Remeshing benchmark on all 76 TOSCA shapes: time, vertex counts, distances, sample sharing.

Run: ``python benchmarks/remesh.py [--sample]`` (JSON on stdout). ``--sample`` runs one shape per
class only. All distances are relative to the input's bounding-box diagonal.

``--steps`` measures instead the CPU seconds per shape variant of the real remesh JOB (``becos
remesh``, one process per variant; with ``--per-shape`` one process per shape making all its variants,
as the workflow runs it, for a checkout whose job does that: its shared steps ``startup``, ``load``,
``prepare``, ``shape`` and ``other`` are divided evenly over the variants, so a variant's ``total`` is
its own steps plus its share, and ``job_total_per_variant`` is each job's CPU over its variants; on
one core), by step: ``startup``
(interpreter, imports, config), ``load`` (parsing the mesh file; the first variant of a shape
parses it, later ones read the job cache), ``prepare`` (common frame), the remesh's own steps
(``stats["cpu_seconds"]`` of :func:`becos.build.remesh.remesh_with_stats`: shape (repair and
orientation), jitter, subdivide (pre-decimation + Loop), decimate, snap, from_original), ``save`` (npz + PLY) and ``other`` (the rest of the
process's CPU: exit, ...). ``total`` is the process's own CPU (user + system, from ``wait4``).
Per tree it prints the median and max of every step over the variants, and the guarantees checked on
the written files (with this checkout's code): exact vertex targets, one component, no
non-manifold or misoriented edge, Euler characteristic kept, ``to_original`` exact (snapped vertices
at distance 0 from their image), ``from_original`` complete, shared original vertices between the
two variants of a shape and between poses of a class (0 expected), and the triangle quality per
shape (longest edge / median edge, 99.9th percentile edge / median, smallest angle, faces with an
angle under 10 degrees). ``--before PATH`` runs another
checkout's code (e.g. ``git archive main | tar -x -C /tmp/before``) on the same variants,
interleaved, so the ratio is measured in one run on a loaded machine. ``--decimators
pymeshlab,fast-simplification`` runs this checkout's jobs once per decimator (config ``decimator``),
interleaved in the same way, labelled ``after:<decimator>`` (one decimator: ``after``); each label
also counts the variants whose fast-simplification result failed a check and was made with
pymeshlab (``decimator_fallbacks``, from the job logs). Variants are compared byte for byte with the
first label's (``variants_byte_identical``)::

    python benchmarks/remesh.py --steps [--before PATH] [--decimators pymeshlab,fast-simplification]
        [--shapes cat0,michael0] [--variants 2] [--per-shape]
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
    from becos.build.remesh import (
        intrinsic_coincidence,
        mesh_checks,
        remesh_with_stats,
        shared_vertex_share,
        variant_target_vertices,
    )
    from becos.core.geometry import SurfaceLocator, points_on_surface
    from becos.core.mesh import MeshCache

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


STEP_SAMPLE = [
    "michael0",
    "michael5",
    "michael11",
    "victoria0",
    "victoria7",
    "david0",
    "cat0",
    "cat5",
    "dog0",
    "horse5",
    "centaur3",
    "wolf0",
]
"""The ``--steps`` shapes: TOSCA's classes in about their proportions (humans are half of its 76)."""

STEPS = (
    "startup",
    "load",
    "prepare",
    "shape",
    "jitter",
    "subdivide",
    "decimate",
    "snap",
    "from_original",
    "save",
    "other",
    "total",
)


def _per_shape_cli(tree: Path) -> bool:
    """Whether ``tree``'s ``becos remesh`` remeshes several variants of a shape in one job (``--tokens``
    and ``--out-dir``; before: one variant per job, ``--token``, ``--out`` and ``--ply``)."""
    return "--tokens" in (tree / "becos" / "cli" / "workflow.py").read_text()


def _run_job(tree: Path, config: dict, row: dict, tokens: list[str], folder: Path) -> str:
    """One ``becos remesh`` process with ``tree`` first on the path (one thread) writing the variants
    ``tokens`` into ``folder`` (``<token>.npz`` and ``.ply``); its log. A tree of one variant per job
    (:func:`_per_shape_cli` false) takes one token."""
    import os

    from becos.workflow import job_options

    cmd = [sys.executable, "-m", "becos", "remesh", "--options", job_options(config, "remesh")]
    cmd += ["--shape", json.dumps(row, sort_keys=True)]
    if _per_shape_cli(tree):
        cmd += ["--tokens", ",".join(tokens), "--out-dir", str(folder)]
    else:
        (token,) = tokens
        folder.mkdir(parents=True, exist_ok=True)
        cmd += ["--token", token, "--out", str(folder / f"{token}.npz"), "--ply", str(folder / f"{token}.ply")]
    env = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    # cwd: ``python -m`` puts the working directory first on the path, before PYTHONPATH
    proc = subprocess.run(cmd, env=env, cwd=tree, capture_output=True, text=True, check=False)
    if proc.returncode:
        raise SystemExit(f"becos remesh {row['name']} {','.join(tokens)} ({tree}) failed:\n{proc.stderr[-3000:]}")
    return proc.stderr


SHARED_STEPS = ("startup", "load", "prepare", "shape", "other")
"""The steps a job of several variants does once for its shape (``shape``: the repaired, re-oriented
copy; ``other``: exit and the rest), shared out evenly over its variants."""


def _job_cpu(tree: Path, config: dict, row: dict, tokens: list[str], folder: Path) -> tuple[list[dict], list[str]]:
    """Per variant of the job (``tokens``) its CPU seconds by step (:data:`STEPS`): its own steps as
    logged, the job's :data:`SHARED_STEPS` divided by the number of variants, so that the variants'
    totals add up to the job's; and the job's decimator fallbacks (empty if none or not logged)."""
    import resource

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    stderr = _run_job(tree, config, row, tokens, folder)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    total = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    lines = [ln for ln in stderr.splitlines() if ln.startswith("remesh cpu seconds: ")]
    # a tree whose job logs no steps (before they were logged) is measured by its total alone
    logged = [json.loads(ln.split(": ", 1)[1]) for ln in lines] or [{"job_start": 0.0}]
    for steps in logged:
        steps["startup"] = steps.pop("job_start", 0.0)
    other = total - sum(sum(steps.values()) for steps in logged)
    n = len(tokens)
    shared = {
        k: (sum(steps.get(k, 0.0) for steps in logged) + (other if k == "other" else 0.0)) / n for k in SHARED_STEPS
    }
    variants = []
    for steps in logged + [{}] * (n - len(logged)):
        own = {k: v for k, v in steps.items() if k not in SHARED_STEPS}
        variant = {**own, **shared}
        variant["total"] = sum(variant.values())
        variants.append(variant)
    decimator = [ln for ln in stderr.splitlines() if ln.startswith("remesh decimator: ")]
    fallbacks = [f for ln in decimator for f in json.loads(ln.split(": ", 1)[1])["decimator_fallbacks"]]
    return variants, fallbacks


def _triangle_quality(mesh) -> dict:
    """Longest and 99.9th-percentile edge over the median edge, smallest angle (degrees), faces with
    an angle under 10 degrees."""
    from becos.core.mesh import undirected_edges

    v, f = mesh.vertices, mesh.faces
    e, _ = undirected_edges(f)
    length = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    tri = v[f]
    smallest = np.full(len(f), 180.0)
    for k in range(3):
        a, b = tri[:, (k + 1) % 3] - tri[:, k], tri[:, (k + 2) % 3] - tri[:, k]
        cos = (a * b).sum(axis=1) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300)
        smallest = np.minimum(smallest, np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    median = float(np.median(length))
    return {
        "edge_max_over_median": round(float(length.max()) / median, 3),
        "edge_p999_over_median": round(float(np.percentile(length, 99.9)) / median, 3),
        "min_angle_deg": round(float(smallest.min()), 3),
        "faces_under_10_deg": int((smallest < 10).sum()),
    }


def _guarantees(original, r, target: int) -> dict:
    from becos.build.remesh import mesh_checks

    facts = mesh_checks(r.mesh)
    d = float(np.linalg.norm(np.ptp(original.vertices, axis=0)))
    unsnapped = r.to_original.distance > 0
    return {
        "exact_vertex_target": r.mesh.n_vertices == target,
        "single_component": facts["components"] == 1,
        "manifold_oriented": facts["non_manifold_edges"] == 0 and facts["misoriented_edges"] == 0,
        "euler_kept": facts["euler_characteristic"] == mesh_checks(original)["euler_characteristic"],
        "to_original_complete": bool(r.to_original.matched.all()),
        "unsnapped_vertices": int(unsnapped.sum()),
        "to_original_distance_max_rel": float(r.to_original.distance.max()) / d,
        "from_original_complete": bool(r.from_original.matched.all()),
        "from_original_distance_mean_rel": float(r.from_original.distance.mean()) / d,
        "from_original_distance_max_rel": float(r.from_original.distance.max()) / d,
        **_triangle_quality(r.mesh),
    }


def step_benchmark(
    trees: dict[str, Path],
    names: list[str],
    variants: int,
    workdir: Path,
    decimators: dict[str, str] | None = None,
    per_shape: bool = False,
) -> dict:
    """The ``--steps`` figures (module docstring) for each label's code tree (``trees``: label -> tree),
    jobs interleaved over labels; ``decimators``: label -> config ``decimator`` (absent: the default);
    ``per_shape``: a tree whose job takes several variants runs one job per shape (else one per variant)."""
    import tempfile

    from becos.build.remesh import intrinsic_coincidence, load_remeshed, shared_vertex_share
    from becos.workflow import ShapeStore, build_catalog, remesh_target, resolve_config

    becos_code = _tosca_dir().parents[1]
    if workdir is not None:
        Path(workdir).mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="remesh-steps-", dir=workdir))
    configs = {
        label: resolve_config(
            {
                "synthetic": {"enabled": False},
                "data_dir": str(becos_code / "data"),
                "annotations": str(becos_code),
                "datasets": ["tosca"],
                "template_file": "templates_tosca_demo.csv",
                "remesh_variants": variants,
                "store_vis": False,
                "results": str(work / label / "results"),
                **({"decimator": decimators[label]} if label in (decimators or {}) else {}),
            }
        )
        for label in trees
    }
    catalog = build_catalog(next(iter(configs.values())))
    rows = {r["name"]: r for r in catalog.to_dict("records")}
    unknown = sorted(set(names) - set(rows))
    if unknown:
        raise SystemExit(f"not TOSCA shapes: {unknown}")
    jobs: dict[str, list[dict]] = {label: [] for label in trees}
    guarantees: dict[str, dict] = {label: {} for label in trees}
    files: dict[str, dict] = {label: {} for label in trees}
    fallbacks: dict[str, dict] = {label: {} for label in trees}
    # the job remeshes the PREPARED mesh (common frame, dataset scale): the guarantees compare with it
    # (with its own mesh cache: the jobs' caches stay empty, so each shape's first variant parses its file)
    config = {**configs[next(iter(trees))], "results": str(work / "prepared" / "results")}
    prepared = {name: ShapeStore(config, [rows[name]]).prepared("tosca", name).mesh for name in names}
    per_shape_jobs: dict[str, list[float]] = {label: [] for label in trees}
    tokens = [f"v{v}" for v in range(variants)]
    for name in names:
        original = prepared[name]
        # one job per variant, or (per_shape, a tree whose job takes several variants) one per shape
        batches = {
            label: [tokens] if per_shape and _per_shape_cli(tree) else [[t] for t in tokens]
            for label, tree in trees.items()
        }
        for round_ in range(max(len(b) for b in batches.values())):
            for label, tree in trees.items():
                if round_ >= len(batches[label]):
                    continue
                config, batch = configs[label], batches[label][round_]
                folder = work / label.replace(":", "_") / "_".join([name, *batch])
                steps, fell_back = _job_cpu(tree, config, rows[name], batch, folder)
                for token, variant in zip(batch, steps):
                    if fell_back:
                        fallbacks[label][f"{name}/{token}"] = fell_back
                    jobs[label].append(
                        {"variant": f"{name}/{token}", **{k: round(variant.get(k, 0.0), 3) for k in STEPS}}
                    )
                    r = load_remeshed(folder / f"{token}.npz")
                    target = remesh_target(config["seed"], "tosca", name, token)["target_vertices"]
                    guarantees[label][f"{name}/{token}"] = _guarantees(original, r, target)
                    files[label][(name, int(token[1:]))] = r
                job_total = sum(variant["total"] for variant in steps)
                per_shape_jobs[label].append(job_total / len(batch))
                print(
                    f"{label} {name} {','.join(batch)}: {job_total:.2f} CPU-s ({job_total / len(batch):.2f} per variant)",
                    file=sys.stderr,
                    flush=True,
                )
    out: dict = {"shapes": names, "variants_per_shape": variants, "cpu_seconds_per_variant": {}, "guarantees": {}}
    for label in trees:
        table = {k: np.array([j[k] for j in jobs[label]]) for k in STEPS}
        remesh_only = table["total"] - table["startup"] - table["other"]
        out["cpu_seconds_per_variant"][label] = {
            "median": {k: round(float(np.median(x)), 3) for k, x in table.items()},
            "max": {k: round(float(x.max()), 3) for k, x in table.items()},
            "median_without_startup": round(float(np.median(remesh_only)), 3),
            "jobs_per_shape": len(per_shape_jobs[label]) // len(names),
            # each job's CPU over its variants (start-up included): median and max over the jobs
            "job_total_per_variant": {
                "median": round(float(np.median(per_shape_jobs[label])), 3),
                "max": round(float(max(per_shape_jobs[label])), 3),
            },
            "jobs": jobs[label],
        }
        g = guarantees[label]
        originals = prepared
        fl = files[label]
        variant_share = [
            shared_vertex_share(fl[(n, 0)], originals[n].faces, fl[(n, 1)], originals[n].faces)
            for n in names
            if variants > 1
        ]
        variant_intrinsic = [
            intrinsic_coincidence(fl[(n, 0)], originals[n].faces, fl[(n, 1)], originals[n])
            for n in names
            if variants > 1
        ]
        classes: dict[str, list[str]] = {}
        for n in names:
            classes.setdefault(re.sub(r"\d+$", "", n), []).append(n)
        pose_pairs = [(a, b) for members in classes.values() for a in members[:1] for b in members[1:]]
        pose_share = [
            shared_vertex_share(fl[(a, 0)], originals[a].faces, fl[(b, 0)], originals[b].faces) for a, b in pose_pairs
        ]
        pose_intrinsic = [
            max(
                intrinsic_coincidence(fl[(a, 0)], originals[a].faces, fl[(b, 0)], originals[b]),
                intrinsic_coincidence(fl[(b, 0)], originals[b].faces, fl[(a, 0)], originals[a]),
            )
            for a, b in pose_pairs
        ]
        out["guarantees"][label] = {
            "decimator": configs[label].get("decimator"),
            "decimator_fallbacks": fallbacks[label],
            "all_exact_vertex_target": all(x["exact_vertex_target"] for x in g.values()),
            "all_single_component": all(x["single_component"] for x in g.values()),
            "all_manifold_oriented_euler_kept": all(x["manifold_oriented"] and x["euler_kept"] for x in g.values()),
            "all_maps_complete_both_ways": all(
                x["to_original_complete"] and x["from_original_complete"] for x in g.values()
            ),
            "unsnapped_vertices_max": max(x["unsnapped_vertices"] for x in g.values()),
            "to_original_distance_max_rel": max(x["to_original_distance_max_rel"] for x in g.values()),
            "from_original_distance_mean_rel_max": max(x["from_original_distance_mean_rel"] for x in g.values()),
            "from_original_distance_max_rel_max": max(x["from_original_distance_max_rel"] for x in g.values()),
            "variants_shared_original_vertex_max": max(variant_share, default=None),
            "poses_shared_original_vertex_max": max(pose_share, default=None),
            "variants_intrinsic_coincidence_max": max(variant_intrinsic, default=None),
            "poses_intrinsic_coincidence_max": max(pose_intrinsic, default=None),
            "triangle_quality": {
                k: {
                    q: g[k][q]
                    for q in ("edge_max_over_median", "edge_p999_over_median", "min_angle_deg", "faces_under_10_deg")
                }
                for k in g
            },
        }
    if len(trees) >= 2:
        a, *others = list(trees)

        def same(x, y) -> bool:
            pairs = [(x.mesh.vertices, y.mesh.vertices), (x.mesh.faces, y.mesh.faces)]
            for m, n in ((x.to_original, y.to_original), (x.from_original, y.from_original)):
                pairs += [(m.face, n.face), (m.weights, n.weights), (m.distance, n.distance)]
            return all(np.array_equal(p, q, equal_nan=True) for p, q in pairs)

        ma = out["cpu_seconds_per_variant"][a]["median"]
        out["variants_byte_identical"], out["median_total_ratio"] = {}, {}
        for b in others:
            identical = sum(same(files[a][k], files[b][k]) for k in files[a])
            out["variants_byte_identical"][f"{b} vs {a}"] = f"{identical}/{len(files[a])}"
            mb = out["cpu_seconds_per_variant"][b]["median"]
            out["median_total_ratio"][f"{b}/{a}"] = round(mb["total"] / ma["total"], 3)
    out["load_average"] = [round(x, 2) for x in __import__("os").getloadavg()]
    return out


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sample", action="store_true", help="one shape per class")
    parser.add_argument("--steps", action="store_true", help="CPU seconds of the remesh job by step")
    parser.add_argument("--before", type=Path, help="with --steps: another checkout to compare with")
    parser.add_argument("--shapes", help="with --steps: comma-separated TOSCA names (default: STEP_SAMPLE)")
    parser.add_argument("--variants", type=int, default=2, help="with --steps: variants per shape")
    parser.add_argument(
        "--per-shape",
        action="store_true",
        help="with --steps: one job per shape making all its variants, as the workflow runs it (a tree "
        "whose job takes one variant still runs one job per variant)",
    )
    parser.add_argument("--workdir", type=Path, default=Path("/tmp"), help="with --steps: where jobs write")
    parser.add_argument(
        "--decimators",
        help="with --steps: comma-separated config `decimator` values this checkout runs with (default: its default)",
    )
    args = parser.parse_args()
    if args.steps:
        trees = {"before": args.before.resolve()} if args.before else {}
        decimators = {}
        chosen = args.decimators.split(",") if args.decimators else [None]
        for decimator in chosen:
            label = "after" if len(chosen) == 1 else f"after:{decimator}"
            trees[label] = REPO
            if decimator is not None:
                decimators[label] = decimator
        names = args.shapes.split(",") if args.shapes else STEP_SAMPLE
        figures = step_benchmark(trees, names, args.variants, args.workdir, decimators, args.per_shape)
        print(json.dumps(figures, indent=1))
    else:
        print(json.dumps(remesh_benchmark(SAMPLE if args.sample else None), indent=1))
