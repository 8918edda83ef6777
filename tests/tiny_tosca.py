"""The tiny TOSCA workflow configuration of ``tests/test_workflow.py`` (fixture ``tiny_tosca_run``).

Defined once, in ``.test/config/config.yaml`` (the configuration CI runs, as the snakemake-workflows
keep it): 8 TOSCA shapes, caps train 4 / val 1 / test 1, one remesh variant, renders on: every stage of
the workflow runs for all three settings in about a minute on 2 cores. Used by ``tests/test_slurm.py``
to run the same configuration locally and on SLURM; ``tests/test_workflow.py`` builds its other
configurations from :func:`tosca_config`.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import yaml

SETTINGS = ("full_full", "partial_full", "partial_partial")

TINY_CONFIG = Path(__file__).resolve().parents[1] / ".test" / "config" / "config.yaml"
"""The tiny TOSCA configuration without its two paths (``data_dir``, ``annotations``)."""
TINY_SHAPES = yaml.safe_load(TINY_CONFIG.read_text())["shapes"]


def tosca_config(becos_code: Path, **overrides) -> dict:
    """A TOSCA workflow configuration (keys: ``config/README.md``) for tests: TOSCA only, one remesh
    variant, no renders; ``overrides`` replace top-level keys."""
    config = {
        "synthetic": {"enabled": False},
        "data_dir": str(Path(becos_code) / "data"),
        "annotations": str(becos_code),
        "datasets": ["tosca"],
        "template_file": "templates_tosca_demo.csv",
        "remesh_variants": 1,
        "store_vis": False,
    }
    config.update(overrides)
    return config


def tiny_tosca_config(becos_code: Path, **overrides) -> dict:
    """The configuration dict of the tiny TOSCA run (``becos_code``: the BeCoS code checkout that
    ``../shared/unpack`` prints)."""
    tiny = yaml.safe_load(TINY_CONFIG.read_text())
    paths = {"data_dir": str(Path(becos_code) / "data"), "annotations": str(becos_code)}
    return {"synthetic": tiny.pop("synthetic"), **paths, **tiny, **overrides}


def write_config_file(workdir: Path, config: dict) -> Path:
    """Write ``config`` to ``workdir/config.yaml`` (creating ``workdir``); returns ``workdir``."""
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
    return workdir


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def results_fingerprint(workdir: Path, settings=SETTINGS) -> dict[str, str]:
    """sha256 of what must not depend on how a run went (cores, interruptions, executor).

    Files under ``results/`` by path: catalog, manifests, remeshes, ground truth, pair files and
    chunk indices (not ``config.json``, ``validation.json``, the reports, which quote the store's
    creation time, or hidden temporary files). Per Zarr store
    (:func:`becos.products.store.open_benchmark`): each array key (dtype, shape and bytes of all pairs' rows),
    each offsets group, the pair metas, the pairs table and the root metadata without ``created``
    (the export's wall-clock time).
    """
    from becos.products.store import open_benchmark

    results = Path(workdir) / "results"
    out = {}
    for path in sorted(results.rglob("*")):
        rel = path.relative_to(results)
        if (
            path.is_file()
            and ".zarr" not in str(rel)
            and path.suffix in (".csv", ".npz", ".json", ".ply")
            and not path.name.startswith(".")
            and path.name not in ("config.json", "validation.json")
            and "report" not in rel.parts
        ):
            out[str(rel)] = _sha(path.read_bytes())
    for setting in settings:
        bench = open_benchmark(results / setting / "benchmark.zarr")
        for key in sorted(bench.layout):
            data = np.ascontiguousarray(bench.concatenated(key)[0])
            out[f"{setting}/arrays/{key}"] = _sha(f"{data.dtype.str}{data.shape}".encode() + data.tobytes())
        for group, offsets in sorted(bench.offsets.items()):
            out[f"{setting}/offsets/{group}"] = _sha(np.ascontiguousarray(offsets).tobytes())
        out[f"{setting}/metas"] = _sha(json.dumps(bench.read_metas(), sort_keys=True).encode())
        out[f"{setting}/table"] = _sha(bench.table.to_json(orient="split").encode())
        metadata = {k: v for k, v in bench.metadata.items() if k != "created"}
        out[f"{setting}/metadata"] = _sha(json.dumps(metadata, sort_keys=True, default=str).encode())
    return out


def fingerprint_differences(a: dict[str, str], b: dict[str, str]) -> list[str]:
    """Keys of two :func:`results_fingerprint` results that differ or stand in only one of them."""
    return sorted(k for k in a.keys() | b.keys() if a.get(k) != b.get(k))
