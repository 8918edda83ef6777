"""DPFM's own loading code on a finished run's DPFM export (issue #34): prints JSON, asserts nothing.

For each setting whose ``results/<setting>/dpfm`` the run wrote (``exports: {dpfm: true}``), every
split is read item by item with DPFM's transcribed ``ShrecPartialDataset`` (``tests/test_dpfm_export.py``:
``dpfm_items``) and each item's ground-truth functional map ``C_gt`` is compared with the one built from
the pair's true correspondences (``-1`` rows left out): ``items`` (what DPFM trains or tests on),
``c_gt_correct``, and the relative Frobenius difference of the wrong ones. ``maps_with_none``: the map
files DPFM cannot represent, kept beside ``maps/``.

Usage::

    python benchmarks/dpfm_loader.py RUN_FOLDER
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))  # the transcribed loader lives with its test

from test_dpfm_export import dpfm_items  # noqa: E402

from becos.products.export import DPFM_NONE_MAPS  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="a finished run folder (holding results/<setting>/dpfm)")
    args = parser.parse_args()
    out: dict = {}
    for export in sorted(args.run.glob("results/*/dpfm")):
        start = time.perf_counter()
        setting = {"items": 0, "c_gt_correct": 0, "maps_with_none": 0, "wrong_relative_difference": []}
        for split in sorted(p for p in export.iterdir() if (p / "maps").is_dir()):
            setting["maps_with_none"] += len(list((split / DPFM_NONE_MAPS).glob("*.map")))
            for item in dpfm_items(split):
                setting["items"] += 1
                if np.array_equal(item["C_gt"], item["C_true"]):
                    setting["c_gt_correct"] += 1
                else:
                    diff = np.linalg.norm(item["C_gt"] - item["C_true"]) / np.linalg.norm(item["C_true"])
                    setting["wrong_relative_difference"].append(round(float(diff), 3))
        setting["seconds"] = round(time.perf_counter() - start, 1)
        out[export.parent.name] = setting
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
