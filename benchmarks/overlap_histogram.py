"""P2P overlap histograms of finished stores beside the published BeCoS one (shares per 10 % bin).

For each ``STORE`` (a ``partial_partial`` ``benchmark.zarr``, or a workflow folder holding
``results/partial_partial/benchmark.zarr``) prints, as one JSON document (also written to ``--out``):
the camera regime its pairs were drawn with (from the pair metas), pairs, directions, the counts and
shares per bin (:func:`becos.products.report.overlap_histogram`, both directions), the share of pairs
accepted (both overlaps in range), mean tries, mean overlap, and the total variation distance to the
published histogram (:func:`becos.products.report.published_overlap_comparison`); and the published
histogram itself (:data:`becos.build.published.P2P_OVERLAP_HISTOGRAM`).

Run from the repository root, e.g. after two TOSCA runs that differ only in ``cam_pos_regime``::

    python benchmarks/overlap_histogram.py /tmp/run-high /tmp/run-reference-high
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from becos.atomic import write_text  # noqa: E402
from becos.build.published import P2P_OVERLAP_HISTOGRAM  # noqa: E402
from becos.products.report import overlap_histogram, published_overlap_comparison  # noqa: E402
from becos.products.store import open_benchmark  # noqa: E402


def store_path(path: Path) -> Path:
    """The P2P store of ``path`` (itself, or ``path/results/partial_partial/benchmark.zarr``)."""
    candidate = path / "results" / "partial_partial" / "benchmark.zarr"
    return candidate if candidate.exists() else path


def summarise(path: Path) -> dict:
    """The histogram of one P2P store beside the published one (see the module doc)."""
    bench = open_benchmark(store_path(path))
    if bench.setting != "partial_partial":
        raise SystemExit(f"{path}: a {bench.setting} store; pass a partial_partial one")
    table = bench.table
    options = bench.record(str(table["pair_id"].iloc[0])).meta.get("options", {}) if len(table) else {}
    hist = overlap_histogram(table)
    comparison = published_overlap_comparison(hist)
    overlaps = np.concatenate([table["x_overlap"].to_numpy(float), table["y_overlap"].to_numpy(float)])
    return {
        "store": str(store_path(path)),
        "cam_pos_regime": options.get("cam_pos_regime"),
        "camera_distance": options.get("camera_distance"),
        "n_pairs": int(len(table)),
        "n_directions": hist["n_directions"],
        "count": comparison["count"],
        "share": [round(s, 4) for s in comparison["share"]],
        "total_variation_to_published": round(comparison["total_variation"], 4),
        "share_accepted": round(float(table["accepted"].mean()), 4),
        "mean_tries": round(float(table["n_tries"].mean()), 3),
        "mean_overlap": round(float(overlaps.mean()), 4),
        "median_overlap": round(float(np.median(overlaps)), 4),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("stores", nargs="+", type=Path, help="P2P stores or workflow folders")
    parser.add_argument("--out", type=Path, help="also write the JSON here")
    args = parser.parse_args(argv)
    published = np.asarray(P2P_OVERLAP_HISTOGRAM)
    result = {
        "bin_centre_percent": list(range(5, 100, 10)),
        "published": {
            "count": published.tolist(),
            "share": [round(float(s), 4) for s in published / published.sum()],
            "n_directions": int(published.sum()),
        },
        "runs": [summarise(p) for p in args.stores],
    }
    # one line per list of numbers, so the histograms read side by side
    text = re.sub(
        r"\[\s+([^\[\]{}]*?)\s+\]", lambda m: "[" + re.sub(r"\s+", " ", m.group(1)) + "]", json.dumps(result, indent=1)
    )
    print(text)
    if args.out:
        write_text(args.out, text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
