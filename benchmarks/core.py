"""Core-library benchmark: remeshing time per TOSCA shape and ground-truth composition time per pair.

Run: ``python benchmarks/core.py [--sample]`` → JSON on stdout. ``--sample`` remeshes one shape per
TOSCA class instead of all 76. Aims (issue "core library"): remesh ≤ 8 s for a 50k-vertex shape with
both maps; composition ≤ 50 ms for a 4-hop pair once edge files and meshes are cached.
"""

from __future__ import annotations

import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from remesh import SAMPLE, _tosca_dir, remesh_benchmark  # noqa: E402


def composition_benchmark(repeats: int = 5) -> dict:
    """Milliseconds per ground-truth map once caches are warm: remeshed X -> remeshed Y, and
    original X -> original Y (``remesh: false``)."""
    from becos.build.network import ShapeNetwork
    from becos.build.remesh import remesh, variant_target_vertices
    from becos.core.mesh import MeshCache
    from becos.sources.annotations import AnnotationSource
    from becos.sources.datasets import DatasetSpec, prepare_shape

    tosca = _tosca_dir()
    root = tosca.parent.parent
    annotations = AnnotationSource(root)
    entries = {e.name: e for e in DatasetSpec.load("tosca").list_shapes(root / "data", annotations)}
    cache = MeshCache(None)
    network = ShapeNetwork(annotations, lambda ds, name: cache.load(tosca / f"{name}.off") if ds == "tosca" else None)
    pairs = [("cat3", "horse5"), ("wolf1", "cat2"), ("michael4", "victoria2"), ("centaur1", "horse7"), ("cat0", "cat3")]
    remeshed = {}
    for name in {n for pair in pairs for n in pair}:
        prepared = prepare_shape(entries[name], cache)
        remeshed[name] = remesh(prepared.mesh, variant_target_vertices(42, "tosca", name, 0))
    rows = {}
    for x, y in pairs:
        hops = sum(h is not None for h in _hops(network, entries[x], entries[y])) + 2
        network.ground_truth(entries[x], entries[y], x_remesh=remeshed[x], y_remesh=remeshed[y])  # warm caches
        network.ground_truth(entries[x], entries[y])  # warm caches (original meshes)
        times, originals = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            network.ground_truth(entries[x], entries[y], x_remesh=remeshed[x], y_remesh=remeshed[y])
            t1 = time.perf_counter()
            network.ground_truth(entries[x], entries[y])  # `remesh: false`: exact transplant
            times.append(1000 * (t1 - t0))
            originals.append(1000 * (time.perf_counter() - t1))
        rows[f"{x}->{y}"] = {
            "non_identity_hops": hops,
            "ms_median": round(statistics.median(times), 1),
            "ms_median_original_meshes": round(statistics.median(originals), 1),
        }
    return rows


def _hops(network, x, y):
    surfaces = network.surface_path(x, y)
    return [network.hop(a, b) for a, b in zip(surfaces, surfaces[1:])]


def main() -> None:
    sample = "--sample" in sys.argv
    remesh_result = remesh_benchmark(SAMPLE if sample else None)
    summary = remesh_result.get("summary", remesh_result)
    out = {
        "remesh": summary,
        "remesh_seconds_per_shape": {k: v.get("seconds") for k, v in remesh_result.get("shapes", {}).items()},
        "composition_ms": composition_benchmark(),
    }
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
