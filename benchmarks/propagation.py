"""Left/right propagation on remeshed TOSCA four-legged and centaur shapes (issue #6 must-show).

For each shape (cat, dog, horse, wolf, centaur; 37 shapes) the prepared common-frame mesh is remeshed
at its variant-0 target (``variant_target_vertices(42, 'tosca', name, 0)``), then

- A: labels propagated directly to the remeshed vertices (composition ending on the remesh's
  ``to_original`` map, :func:`becos.build.propagation.propagate_labels` with ``remesh``);
- B: labels propagated to the original triangulation, carried to the remeshed vertices through
  ``to_original`` (largest-weight corner, :func:`becos.build.propagation.labels_through_remesh`);

and the agreement = share of remeshed vertices labelled in A or B whose labels are equal.
Requirement: >= 0.98 on every shape.

Run: ``python benchmarks/propagation.py [--names cat0,horse5]`` (JSON on stdout, progress on stderr).
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SEED = 42
CLASSES = ("cat", "dog", "horse", "wolf", "centaur")
THRESHOLD = 0.98


def _becos_code() -> Path:
    out = subprocess.run(
        [str(REPO.parent / "shared" / "unpack")], check=True, capture_output=True, text=True
    ).stdout.strip()
    return Path(out.splitlines()[-1])


def propagation_benchmark(names: list[str] | None = None) -> dict:
    """Agreement of A and B (module docstring) per shape, and a summary. JSON-ready."""
    from becos.build.network import ShapeNetwork
    from becos.build.propagation import NO_LABEL, agreement, labels_through_remesh, nearest_annotated, propagate_labels
    from becos.build.remesh import remesh, variant_target_vertices
    from becos.core.mesh import MeshCache
    from becos.sources.annotations import AnnotationSource
    from becos.sources.datasets import DatasetSpec, prepare_shape

    root = _becos_code()
    annotations = AnnotationSource(root)
    entries = {e.name: e for e in DatasetSpec.load("tosca").list_shapes(root / "data", annotations)}
    if names is None:
        names = sorted(
            (n for n in entries if re.match(rf"^({'|'.join(CLASSES)})\d+$", n)),
            key=lambda n: (re.match(r"[a-z]+", n).group(), int(re.search(r"\d+", n).group())),
        )
    cache = MeshCache(None)

    def meshes(dataset, name):
        entry = entries.get(name)
        return cache.load(entry.path) if dataset == "tosca" and entry is not None else None

    network = ShapeNetwork(annotations, meshes)
    rows = {}
    started = time.perf_counter()
    for name in names:
        entry = entries[name]
        source, hops = nearest_annotated(network, entry)
        prepared = prepare_shape(entry, cache)
        target = variant_target_vertices(SEED, "tosca", name, 0)
        t0 = time.perf_counter()
        r = remesh(prepared.mesh, target_vertices=target)
        t1 = time.perf_counter()
        a = propagate_labels(network, entry, remesh=r)
        t2 = time.perf_counter()
        original = propagate_labels(network, entry)
        b = labels_through_remesh(original, r, prepared.mesh.faces)
        t3 = time.perf_counter()
        differ = (a != b) & ((a != NO_LABEL) | (b != NO_LABEL))
        rows[name] = {
            "annotated_template": source.key,
            "hops": hops,
            "original_vertices": int(prepared.mesh.n_vertices),
            "remeshed_vertices": int(r.mesh.n_vertices),
            "agreement": round(agreement(a, b), 6),
            "disagreeing_vertices": int(differ.sum()),
            "labelled_in_either": int(((a != NO_LABEL) | (b != NO_LABEL)).sum()),
            "none_direct": int((a == NO_LABEL).sum()),
            "none_carried": int((b == NO_LABEL).sum()),
            "left_share_direct": round(float((a == 1).mean()), 4),
            "seconds_remesh": round(t1 - t0, 3),
            "seconds_direct": round(t2 - t1, 3),
            "seconds_original_and_carry": round(t3 - t2, 3),
        }
        print(
            f"{name}: agreement {rows[name]['agreement']:.4f} ({rows[name]['disagreeing_vertices']} of "
            f"{rows[name]['labelled_in_either']} differ) via {source.key}, {t3 - t0:.1f} s",
            file=sys.stderr,
        )
    scores = np.array([row["agreement"] for row in rows.values()])
    summary = {
        "shapes": len(rows),
        "threshold": THRESHOLD,
        "min_agreement": float(scores.min()),
        "mean_agreement": round(float(scores.mean()), 6),
        "min_shape": min(rows, key=lambda n: rows[n]["agreement"]),
        "all_pass": bool((scores >= THRESHOLD).all()),
        "per_class_min": {
            c: min(row["agreement"] for n, row in rows.items() if re.match(rf"{c}\d+$", n))
            for c in CLASSES
            if any(re.match(rf"{c}\d+$", n) for n in rows)
        },
        "seconds": round(time.perf_counter() - started, 1),
    }
    return {"seed": SEED, "rows": rows, "summary": summary}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--names", help="comma-separated TOSCA shape names (default: all four-legged + centaur)")
    args = parser.parse_args(argv)
    result = propagation_benchmark(args.names.split(",") if args.names else None)
    print(json.dumps(result, indent=1))
    return 0 if result["summary"]["all_pass"] else 1


if __name__ == "__main__":
    sys.exit(main())
