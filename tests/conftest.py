"""Shared fixtures: the reference data laid out by ``../shared/unpack`` (TOSCA meshes, annotations)."""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"


@pytest.fixture(scope="session")
def becos_code() -> Path:
    """The BeCoS reference checkout (annotation files + TOSCA meshes), unpacked once per machine."""
    unpack = SHARED / "unpack"
    if not unpack.exists():
        pytest.skip(f"{unpack} not found: the real-data tests need ../shared beside the repository")
    out = subprocess.run([str(unpack)], check=True, capture_output=True, text=True).stdout.strip()
    return Path(out.splitlines()[-1])


@pytest.fixture(scope="session")
def tosca_dir(becos_code: Path) -> Path:
    return becos_code / "data" / "tosca-off"


@pytest.fixture(scope="session")
def mesh_cache(tmp_path_factory):
    """One parsed-mesh cache for the whole test session."""
    from becos.core.mesh import MeshCache

    return MeshCache(tmp_path_factory.mktemp("mesh-cache"))


@pytest.fixture(scope="session")
def annotations(becos_code, tmp_path_factory):
    """The BeCoS annotation folder (``becos.sources.annotations.AnnotationSource``, full template table)."""
    from becos.sources.annotations import AnnotationSource

    return AnnotationSource(becos_code, cache_dir=tmp_path_factory.mktemp("edge-cache"))


@pytest.fixture(scope="session")
def tosca_entries(becos_code, annotations) -> dict:
    """The 76 TOSCA shapes as ``becos.sources.datasets.ShapeEntry``, by name."""
    from becos.sources.datasets import DatasetSpec

    return {e.name: e for e in DatasetSpec.load("tosca").list_shapes(becos_code / "data", annotations)}


@pytest.fixture(scope="session")
def tosca_network(annotations, tosca_dir, mesh_cache):
    """A shape network that knows TOSCA only (FAUST, DT4D absent, as on a fresh machine)."""
    from becos.build.network import ShapeNetwork

    def meshes(dataset, name):
        path = tosca_dir / f"{name}.off"
        return mesh_cache.load(path) if dataset == "tosca" and path.is_file() else None

    return ShapeNetwork(annotations, meshes)


def remeshed_cat_pair(entries, network, mesh_cache, targets: tuple[int, int]):
    """TOSCA cat0 and cat3 remeshed to ``targets`` vertices, with network ground truth both ways.

    Returns ``(x, y, gt_xy, gt_yx)``: two :class:`becos.build.pairs.ShapeInstance` and two
    :class:`becos.core.surface_map.SurfaceMap`.
    """
    from becos.build.pairs import ShapeInstance
    from becos.build.remesh import remesh
    from becos.sources.datasets import prepare_shape

    shapes, remeshes = {}, {}
    for name, target in zip(("cat0", "cat3"), targets):
        entry = entries[name]
        prepared = prepare_shape(entry, mesh_cache)
        remeshes[name] = remesh(prepared.mesh, target_vertices=target)
        shapes[name] = ShapeInstance(
            entry.dataset,
            entry.name,
            entry.category,
            entry.shape_class,
            remeshes[name].mesh,
            entry.scale,
            entry.frame_rotation,
            prepared.centre,
            0,
        )
    x, y = entries["cat0"], entries["cat3"]
    gt_xy = network.ground_truth(x, y, x_remesh=remeshes["cat0"], y_remesh=remeshes["cat3"])
    gt_yx = network.ground_truth(y, x, x_remesh=remeshes["cat3"], y_remesh=remeshes["cat0"])
    return shapes["cat0"], shapes["cat3"], gt_xy, gt_yx


@pytest.fixture(scope="session")
def cat_pair(tosca_entries, tosca_network, mesh_cache):
    """:func:`remeshed_cat_pair` on the session's TOSCA entries: call it with the two vertex targets."""
    return lambda targets: remeshed_cat_pair(tosca_entries, tosca_network, mesh_cache, targets)


@pytest.fixture(scope="session")
def small_cat_records(cat_pair) -> dict:
    """Per setting (all three): two test pairs cat0 -> cat3 (seeds 1, 2: the same two full meshes,
    different scans) and one train pair, cat0 and cat3 remeshed to ~1,500 vertices; in-memory records."""
    from becos.build.pairs import PairOptions, build_pair

    x, y, gt_xy, gt_yx = cat_pair((1500, 1400))
    return {
        setting: [
            build_pair(
                x,
                y,
                gt_xy,
                gt_yx,
                pair_id=f"{setting[:1]}{setting.split('_')[1][:1]}{i:014d}",
                seed=i + 1,
                split=split,
                options=PairOptions(setting=setting),
            )
            for i, split in enumerate(("test", "test", "train"))
        ]
        for setting in ("full_full", "partial_full", "partial_partial")
    }


@pytest.fixture(scope="session")
def tosca_pair_inputs(cat_pair):
    """Remeshed cat0 (9,200 vertices) and cat3 (9,800): :func:`remeshed_cat_pair`."""
    return cat_pair((9200, 9800))


@pytest.fixture(scope="session")
def pair_record_files(tosca_pair_inputs, tmp_path_factory) -> dict[str, list[Path]]:
    """Saved pair records (cat0 -> cat3), two per setting with different seeds and splits.

    ``{setting: [path, path]}``; files are ``<pair_id>.npz`` in one folder per setting.
    """
    from becos.build.pairs import PairOptions, build_pair

    x, y, gt_xy, gt_yx = tosca_pair_inputs
    out = {}
    for setting in ("full_full", "partial_full", "partial_partial"):
        folder = tmp_path_factory.mktemp(setting)
        paths = []
        for i, split in enumerate(("train", "test")):
            pair_id = f"{setting[:1]}{setting.split('_')[1][:1]}{i:014d}"
            record = build_pair(
                x, y, gt_xy, gt_yx, pair_id=pair_id, seed=100 + i, split=split, options=PairOptions(setting=setting)
            )
            path = folder / f"{pair_id}.npz"
            record.save(path)
            paths.append(path)
        out[setting] = paths
    return out


@pytest.fixture
def store_of(tmp_path):
    """``store_of(records, setting) -> Path``: save PairRecords and write them into one Zarr store."""
    from becos.products.store import write_store

    def build(records, setting: str) -> Path:
        folder = tmp_path / f"{setting}-records"
        folder.mkdir(exist_ok=True)
        paths = []
        for record in records:
            path = folder / f"{record.pair_id}.npz"
            record.save(path)
            paths.append(path)
        return write_store(paths, tmp_path / f"{setting}.zarr", setting=setting, progress=False)

    return build


@dataclass(frozen=True)
class TinyReference:
    """The tiny TOSCA reference run: its working folder, :func:`tiny_tosca.results_fingerprint`, taken as
    soon as the run ended (before any test touched the folder), and the folder of its jobs' opened-paths
    audit records (:mod:`becos.cli.audit`)."""

    workdir: Path
    fingerprint: dict[str, str]
    opened: Path


@pytest.fixture(scope="session")
def tiny_tosca_reference(becos_code, tmp_path_factory) -> TinyReference:
    """A finished ``--cores 2`` run of the tiny TOSCA configuration (``.test/config/config.yaml``): all three
    settings, every export; made ONCE per pytest run, shared by the xdist workers.

    Under pytest-xdist each worker has its own session, so the run goes to the folder the workers share
    (the parent of their base temporary folders, new for each pytest run, as pytest-xdist's docs
    advise) under an exclusive ``flock``: the first worker to ask makes it, the other waits and reads
    it. The fingerprint is written after the run; its file marks the run complete. Each job records the
    paths it opens (``BECOS_AUDIT_OPENS``) into the folder ``opened``."""
    from snakemake_cmd import snakemake
    from tiny_tosca import results_fingerprint, tiny_tosca_config, write_config_file

    from becos.cli.audit import AUDIT_ENV

    shared = os.environ.get("PYTEST_XDIST_WORKER") is not None
    root = tmp_path_factory.getbasetemp().parent if shared else tmp_path_factory.mktemp("tiny")
    workdir, done = root / "tiny-tosca", root / "tiny-tosca.fingerprint.json"
    opened = root / "tiny-tosca-opened"
    with open(root / "tiny-tosca.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            shutil.rmtree(workdir, ignore_errors=True)  # a worker that died mid-run
            shutil.rmtree(opened, ignore_errors=True)
            write_config_file(workdir, tiny_tosca_config(becos_code))
            snakemake(workdir, "--cores", "2", env={AUDIT_ENV: str(opened)})
            partial = done.with_suffix(".tmp")
            partial.write_text(json.dumps(results_fingerprint(workdir)))
            partial.replace(done)
    return TinyReference(workdir, json.loads(done.read_text()), opened)


@pytest.fixture(scope="session")
def tiny_tosca_run(tiny_tosca_reference) -> Path:
    """The working folder of the tiny TOSCA reference run. Tests on both workers read it at the same
    time: a test may run Snakemake in it only without changing it (``-n``, ``--report``); one that
    changes files works on a copy of it."""
    return tiny_tosca_reference.workdir
