"""The workflow's stages as library functions: config -> plan -> the work of one job.

Snakemake (``Snakefile``, ``workflow/rules/*.smk``) only names files; every job runs one ``becos``
sub-command, which calls one function of this module (or of :mod:`becos.store`, :mod:`becos.export`,
:mod:`becos.validate`, :mod:`becos.report`).

Files under ``results`` (config key ``results``)::

    config.json                         the resolved configuration (defaults filled in)
    checks/datasets.json                what the dataset check found
    catalog.csv                         every shape of the enabled datasets (becos.catalog)
    remeshed/<dataset>/<name>/<v>.npz   one remesh variant: mesh + maps to/from the original (.ply beside)
    <setting>/manifest.csv              the pairs of a setting (becos.sampling)
    <setting>/ground_truth/chunk_<k>.json  index of the chunk's ground-truth files <pair_id>.npz
    <setting>/pairs/chunk_<k>.json      index of the chunk's pair records <pair_id>.npz (becos.record)
    <setting>/benchmark.zarr            the store (becos.store), validated into validation.json
    cache/                              parsed meshes and edge files (safe to delete)

Incremental rebuilds. A pair's chunk job is a contiguous range of fixed hash buckets of its id
(:func:`becos.sampling.assign_chunks`; the manifest's ``chunk`` column records the grouping), so
growth adds pairs to chunks and moves one only when the number of chunk jobs doubles; a moved pair
keeps its files (named by pair id; the chunk is not part of any input key). A chunk job reruns when
the manifest or catalog is rewritten or its stage's options change (they are its Snakemake
``params``, :func:`job_options`); a remesh job only when its shape's catalog row or target changes.
Inside a chunk job, a pair's file is rewritten only when the pair's *input key* changed: the digest
of its manifest row (except its chunk), the stage options and the digests of the files
it reads (remesh variants, ground truth). So enabling another dataset recomputes only the new or
re-partnered pairs, and changing ``min_overlap`` recomputes records but no remesh and no ground truth.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
import time
from collections import OrderedDict
from copy import deepcopy
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from becos.atomic import remove_stale_temporaries, write_text
from becos.errors import ConfigError

if TYPE_CHECKING:
    import pandas as pd  # imported where used: write-config, metadata and remesh jobs start without it

SETTINGS = ("full_full", "partial_full", "partial_partial")
SCHEMA_PATH = Path(__file__).resolve().parents[1] / "config" / "schema.yaml"
GROUND_TRUTH_VERSION = 1
"""Bumped when the ground-truth computation changes, so cached files are recomputed."""
RECORD_VERSION = 1
"""Bumped when pair assembly changes, so cached records are rebuilt."""
STAGE_VERSIONS = {"ground_truth": GROUND_TRUTH_VERSION, "pairs": RECORD_VERSION}
SHAPES_KEPT = 6
"""Shapes (prepared, remeshed, scanners) a chunk job keeps in memory."""

STAGE_KEYS: dict[str, tuple[str, ...]] = {
    "catalog": ("data_dir", "annotations", "datasets", "shapes", "template_file"),
    "manifest": ("data_dir", "annotations", "datasets", "shapes", "template_file", "combinations", "seed", "usage_scale",
                 "caps", "remesh", "remesh_variants", "n_chunks", "pairs_per_chunk", "original_settings"),
    "remesh": ("seed", "remesh", "remesher"),
    "export": (),
    "ground_truth": ("annotations", "template_file", "remesh"),
    "pairs": ("one_axis_rotation", "up_axis", "area_normalised", "propagate_annotations", "annotations",
              "template_file", "original_settings", "remesher"),
}
"""The config keys each stage depends on: a change to one of them reruns that stage (and only it)."""
SETTING_KEYS: dict[str, tuple[str, ...]] = {
    "full_full": (),
    "partial_full": ("camera_distance",),
    "partial_partial": ("camera_distance", "cam_pos_regime", "n_cam_pos", "min_overlap", "max_overlap"),
}
"""Extra keys the ``pairs`` stage depends on, per setting."""


# --------------------------------------------------------------------------------------------------
# configuration

def _schema() -> dict:
    import yaml

    return yaml.safe_load(SCHEMA_PATH.read_text())


def _fill_defaults(schema: dict, instance):
    """Fill ``default`` values of object properties, recursively (like Snakemake's ``validate``)."""
    if not isinstance(instance, dict) or schema.get("type") != "object":
        return instance
    for key, sub in schema.get("properties", {}).items():
        if key not in instance and "default" in sub:
            instance[key] = deepcopy(sub["default"])
        if key in instance:
            _fill_defaults(sub, instance[key])
    return instance


def resolve_config(raw: dict) -> dict:
    """Validate ``raw`` against ``config/schema.yaml``, fill defaults, check what a schema cannot.

    Raises:
        ConfigError: listing every problem (unknown key, wrong type, reversed overlap range, ...).
    """
    import jsonschema

    schema = _schema()
    config = _fill_defaults(schema, deepcopy(dict(raw)))
    if config.get("remesher") == "auto":  # the published targets, rotations and views refer to the reference's remesh
        config["remesher"] = "reference" if config.get("original_settings") else "becos"
    validator = jsonschema.Draft202012Validator(schema)
    errors = sorted(validator.iter_errors(config), key=lambda e: list(e.path))
    if errors:
        lines = [f"  {'/'.join(map(str, e.path)) or '(top level)'}: {e.message}" for e in errors]
        raise ConfigError("invalid configuration:\n" + "\n".join(lines) + "\n(see config/README.md)")
    check_config(config)
    return config


def check_config(config: dict) -> None:
    """Checks across keys, run right after the schema (so a bad config fails before any job)."""
    from becos.datasets import available_datasets

    problems = []
    if config.get("min_overlap", 0.1) > config.get("max_overlap", 0.9):
        problems.append(f"min_overlap ({config['min_overlap']}) > max_overlap ({config['max_overlap']}): "
                        "the overlap range is reversed")
    known = set(available_datasets())
    unknown = [d for d in config["datasets"] if d not in known]
    if unknown:
        problems.append(f"datasets {unknown} are not in the registry (config/datasets/*.yaml: {sorted(known)})")
    if config.get("download") or config.get("download_urls"):
        from becos.download import download_config_problems

        problems += download_config_problems(config)
    if config.get("original_settings") and "partial_full" in settings_of(config):
        problems.append("original_settings: the reference publishes no partial_full pair list; "
                        "use setting full_full / partial_partial or original_settings: false")
    synthetic = config.get("synthetic") or {}
    if synthetic.get("enabled"):
        out = Path(synthetic.get("out", "resources/synthetic"))
        for key, expected in (("data_dir", out / "data"), ("annotations", out / "annotations")):
            if Path(config[key]) != expected:
                problems.append(f"{key} is {config[key]!r} but the synthetic collection is generated into "
                                f"{str(expected)!r}: set {key}: {expected} (or synthetic.enabled: false)")
    if problems:
        raise ConfigError("invalid configuration:\n" + "\n".join(f"  {p}" for p in problems))


def settings_of(config: dict) -> list[str]:
    """The configured settings as a list, in the canonical order."""
    value = config.get("setting", list(SETTINGS))
    wanted = {value} if isinstance(value, str) else set(value)
    return [s for s in SETTINGS if s in wanted]


def digest(value) -> str:
    """16 hex digits of SHA-256 of a JSON-able value (sorted keys): stable across runs and machines."""
    text = json.dumps(value, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def stage_options(config: dict, stage: str, setting: str | None = None) -> dict:
    """The part of ``config`` that ``stage`` (of ``setting``) depends on (:data:`STAGE_KEYS`,
    :data:`SETTING_KEYS`)."""
    keys = STAGE_KEYS[stage] + (SETTING_KEYS[setting] if stage == "pairs" and setting else ())
    return {k: config.get(k) for k in keys}


def job_options(config: dict, stage: str, setting: str | None = None) -> str:
    """The JSON a job of ``stage`` receives (its :func:`stage_options` + ``results``).

    Rules pass it as a parameter, so Snakemake reruns a job exactly when one of these values changes.
    """
    options = stage_options(config, stage, setting)
    options["results"] = config.get("results", "results")
    if stage in STAGE_VERSIONS:
        options["version"] = STAGE_VERSIONS[stage]  # a bump reruns the stage's chunk jobs
    return json.dumps(options, sort_keys=True)


def load_config(path: str | Path) -> dict:
    """Read a config (JSON or YAML) and resolve it (:func:`resolve_config`)."""
    import yaml

    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: config file not found")
    return resolve_config(yaml.safe_load(path.read_text()) or {})


# --------------------------------------------------------------------------------------------------
# layout

@dataclass(frozen=True)
class Layout:
    """Where every artefact of a run lives (relative to the working directory unless absolute)."""

    results: Path

    @classmethod
    def of(cls, config: dict) -> "Layout":
        return cls(Path(config.get("results", "results")))

    @property
    def config(self) -> Path:
        return self.results / "config.json"

    @property
    def checks(self) -> Path:
        return self.results / "checks" / "datasets.json"

    def downloaded(self, dataset: str) -> Path:
        """Stamp of a dataset's download (``becos download-dataset --out``)."""
        return self.results / "downloads" / f"{dataset}.json"

    @property
    def catalog(self) -> Path:
        return self.results / "catalog.csv"

    @property
    def cache(self) -> Path:
        return self.results / "cache"

    def manifest(self, setting: str) -> Path:
        return self.results / setting / "manifest.csv"

    def remeshed(self, dataset: str, name: str, token: str) -> Path:
        return self.results / "remeshed" / dataset / name / f"{token}.npz"

    def ground_truth_index(self, setting: str, chunk: int) -> Path:
        return self.results / setting / "ground_truth" / f"chunk_{chunk:04d}.json"

    def ground_truth(self, setting: str, pair_id: str) -> Path:
        return self.results / setting / "ground_truth" / f"{pair_id}.npz"

    def pairs_index(self, setting: str, chunk: int) -> Path:
        return self.results / setting / "pairs" / f"chunk_{chunk:04d}.json"

    def record(self, setting: str, pair_id: str) -> Path:
        return self.results / setting / "pairs" / f"{pair_id}.npz"


def remesh_token(row, side: str, remesh: bool) -> str:
    """The remesh file a pair side uses: ``v<k>`` (variant k), ``f<n>`` (published face target n) or
    ``original`` (no remeshing)."""
    if not remesh:
        return "original"
    target = row.get(f"{side}_face_target") if hasattr(row, "get") else None
    if target is not None and not math.isnan(float(target)) and int(target) > 0:
        return f"f{int(target)}"
    return f"v{int(row[f'{side}_variant'])}"


# --------------------------------------------------------------------------------------------------
# the plan: everything Snakemake needs to know to build the job graph

def annotation_source(config: dict):
    from becos.annotations import AnnotationSource

    return AnnotationSource(config["annotations"], cache_dir=Layout.of(config).cache / "annotations",
                            template_table=config.get("template_file", "templates_all.csv"))


def build_catalog(config: dict, annotations=None) -> pd.DataFrame:
    """The catalog of every enabled dataset's shapes (:mod:`becos.catalog`)."""
    from becos.catalog import catalog_table
    from becos.datasets import DatasetSpec

    annotations = annotations or annotation_source(config)
    entries = []
    for name in config["datasets"]:
        entries.extend(DatasetSpec.load(name).list_shapes(config["data_dir"], annotations))
    patterns = config.get("shapes")
    if patterns:
        from fnmatch import fnmatchcase

        entries = [e for e in entries if any(fnmatchcase(f"{e.dataset}/{e.name}", p) for p in patterns)]
        if not entries:
            raise ConfigError(f"shapes: no shape of datasets {config['datasets']} matches {patterns}")
    return catalog_table(entries)


def build_manifest(config: dict, setting: str, catalog: pd.DataFrame, annotations=None) -> pd.DataFrame:
    """The pair manifest of ``setting`` (:mod:`becos.sampling`, or the published lists)."""
    import pandas as pd

    from becos.sampling import assign_chunks, sample_pairs

    if config.get("original_settings"):
        from becos.published import import_published

        path = Path(config["annotations"]) / "config" / f"pairings_original_{setting}.pkl"
        imported = import_published(path, setting=setting, seed=config["seed"],
                                    n_variants=config["remesh_variants"], n_chunks=config["n_chunks"],
                                    datasets=config["datasets"])
        manifest = imported.manifest
        if imported.cameras:  # P2P: the published cameras travel with their pair (x_cam_pos_0..29, y_...)
            cams = np.stack([imported.cameras[p] for p in manifest["pair_id"]]).reshape(len(manifest), 2, -1)
            columns = {f"{side}_cam_pos_{i}": cams[:, s, i] for s, side in enumerate("xy") for i in range(cams.shape[2])}
            manifest = pd.concat([manifest, pd.DataFrame(columns, index=manifest.index)], axis=1)
            manifest.attrs = imported.manifest.attrs
        manifest = _restrict_published(manifest, catalog, config, setting)
        manifest["chunk"] = assign_chunks(manifest["pair_id"], n_chunks=config["n_chunks"],
                                          pairs_per_chunk=config["pairs_per_chunk"])
        return manifest
    annotations = annotations or annotation_source(config)
    caps = {k: v for k, v in (config.get("caps") or {}).items() if v is not None}
    return sample_pairs(catalog, setting, seed=config["seed"], combinations=config["combinations"],
                        template_rows=annotations, n_variants=config["remesh_variants"],
                        n_chunks=config["n_chunks"], pairs_per_chunk=config["pairs_per_chunk"], caps=caps or None,
                        usage_scale=config["usage_scale"])


def _restrict_published(manifest: pd.DataFrame, catalog: pd.DataFrame, config: dict, setting: str) -> pd.DataFrame:
    """Published pairs whose two shapes are in the catalog (``shapes`` filter), then the per-split caps
    (pairs ranked by a keyed hash of their id, as for sampled pairs)."""
    from becos.sampling import sort_manifest
    from becos.seeding import stable_hash

    known = set(zip(catalog["dataset"], catalog["name"]))
    keep = [(xd, xn) in known and (yd, yn) in known for xd, xn, yd, yn in
            zip(manifest["x_dataset"], manifest["x_name"], manifest["y_dataset"], manifest["y_name"])]
    out = manifest[np.asarray(keep, dtype=bool)]
    for split, cap in (config.get("caps") or {}).items():
        rows = out[out["split"] == split]
        if cap is not None and len(rows) > cap:
            rank = sorted(rows["pair_id"], key=lambda p: stable_hash(config["seed"], setting, "cap", p))
            out = out[(out["split"] != split) | out["pair_id"].isin(rank[:cap])]
    report = dict(manifest.attrs.get("report", {}))
    report["n_pairs"] = {s: int((out["split"] == s).sum()) for s in ("train", "val", "test")}
    out = sort_manifest(out)
    out.attrs["report"] = report
    return out


@dataclass
class Plan:
    """The catalog and manifests of a config, and the jobs they imply.

    Computed in the Snakemake process (after the dataset check) and again, identically, by the jobs
    that write the catalog and manifests.
    """

    config: dict
    catalog: pd.DataFrame
    manifests: dict[str, pd.DataFrame]
    layout: Layout = field(init=False)
    _chunk_inputs: dict[tuple[str, int], list[str]] = field(init=False, default_factory=dict, repr=False)

    def __post_init__(self):
        self.layout = Layout.of(self.config)

    @classmethod
    def build(cls, config: dict) -> "Plan":
        annotations = annotation_source(config)
        catalog = build_catalog(config, annotations)
        manifests = {s: build_manifest(config, s, catalog, annotations) for s in settings_of(config)}
        return cls(config, catalog, manifests)

    @cached_property
    def files(self) -> dict[tuple[str, str], str]:
        return {(d, n): f for d, n, f in zip(self.catalog["dataset"], self.catalog["name"], self.catalog["file"])}

    def _side_files(self, rows: pd.DataFrame) -> list[tuple[str, str, str]]:
        remesh = bool(self.config.get("remesh", True))
        out = set()
        for row in rows.to_dict("records"):
            for side in ("x", "y"):
                out.add((row[f"{side}_dataset"], row[f"{side}_name"], remesh_token(row, side, remesh)))
        return sorted(out)

    @cached_property
    def remesh_jobs(self) -> list[tuple[str, str, str]]:
        """Every (dataset, name, token) some pair uses, remeshing only (not ``original``)."""
        if not self.config.get("remesh", True):
            return []
        jobs = set()
        for manifest in self.manifests.values():
            jobs.update(self._side_files(manifest))
        return sorted(jobs)

    @cached_property
    def _chunk_groups(self) -> dict[str, dict[int, pd.DataFrame]]:
        """``{setting: {chunk: rows}}``, split once (Snakemake asks per chunk job, several times)."""
        return {s: {int(c): rows for c, rows in m.groupby("chunk", sort=True)} for s, m in self.manifests.items()}

    def chunks(self, setting: str) -> list[int]:
        return list(self._chunk_groups[setting])

    def chunk_rows(self, setting: str, chunk: int) -> pd.DataFrame:
        rows = self._chunk_groups[setting].get(int(chunk))
        return self.manifests[setting].iloc[:0] if rows is None else rows

    def chunk_inputs(self, setting: str, chunk: int) -> list[str]:
        """Remesh files the chunk reads (none without remeshing); computed once per chunk."""
        if not self.config.get("remesh", True):
            return []
        key = (setting, int(chunk))
        if key not in self._chunk_inputs:
            rows = self.chunk_rows(setting, chunk)
            self._chunk_inputs[key] = [str(self.layout.remeshed(*k)) for k in self._side_files(rows)]
        return list(self._chunk_inputs[key])

    @cached_property
    def _catalog_rows(self) -> dict[tuple[str, str], dict]:
        return {(r["dataset"], r["name"]): r for r in self.catalog.to_dict("records")}

    def shape_json(self, dataset: str, name: str) -> str:
        """A shape's catalog row as JSON (the remesh job's description of its shape)."""
        return json.dumps(self._catalog_rows[(dataset, name)], sort_keys=True)

    def remesh_target(self, dataset: str, name: str, token: str) -> dict:
        return remesh_target(self.config, dataset, name, token)


def remesh_target(config: dict, dataset: str, name: str, token: str) -> dict:
    """Arguments of :func:`becos.remesh.remesh` for a token."""
    from becos.remesh import variant_target_vertices

    if token.startswith("f"):
        return {"target_faces": int(token[1:])}
    return {"target_vertices": int(variant_target_vertices(config["seed"], dataset, name, int(token[1:])))}


# --------------------------------------------------------------------------------------------------
# shapes as the jobs see them

def _entry(row) -> "object":
    from becos.catalog import frame_rotation
    from becos.datasets import ShapeEntry

    return ShapeEntry(dataset=row["dataset"], name=row["name"], path=Path(row["file"]), category=row["category"],
                      shape_class=row["class"], template_key=row["template_key"], split=row["split"],
                      scale=float(row["scale"]), frame_rotation=frame_rotation(row), usage=int(row["usage"]))


class _Recent(OrderedDict):
    """A dict that keeps only its ``size`` most recently used entries."""

    def __init__(self, size: int):
        super().__init__()
        self.size = size

    def get_or_make(self, key, make):
        if key in self:
            self.move_to_end(key)
            return self[key]
        value = self[key] = make()
        while len(self) > self.size:
            self.popitem(last=False)
        return value


class ShapeStore:
    """The shapes of one job: catalog entries, parsed meshes, prepared meshes and remesh variants.

    A chunk job visits its pairs sorted by shape, so a few recently used shapes are kept
    (:data:`SHAPES_KEPT`): the job's memory does not grow with the number of pairs in a chunk.
    """

    def __init__(self, config: dict, catalog: "pd.DataFrame | list[dict]"):
        """``catalog``: the catalog table, or some of its rows as dicts."""
        from becos.mesh import MeshCache

        self.config = config
        self.layout = Layout.of(config)
        rows = catalog if isinstance(catalog, list) else catalog.to_dict("records")
        self.entries = {(r["dataset"], r["name"]): _entry(r) for r in rows}
        self.mesh_cache = MeshCache(self.layout.cache / "meshes", max_in_memory=2 * SHAPES_KEPT)
        self._prepared = _Recent(SHAPES_KEPT)
        self._remeshed = _Recent(SHAPES_KEPT)
        self._digests: dict[Path, str] = {}
        self._network = None

    def entry(self, dataset: str, name: str):
        try:
            return self.entries[(dataset, name)]
        except KeyError:
            raise ConfigError(f"shape {dataset}/{name} is not in the catalog; was the dataset disabled? "
                              f"Re-run the workflow so the catalog and manifests are rebuilt") from None

    def mesh(self, dataset: str, name: str):
        """The original mesh of a catalogued shape, or None (the network then uses default faces)."""
        entry = self.entries.get((dataset, name))
        return None if entry is None else self.mesh_cache.load(entry.path)

    def prepared(self, dataset: str, name: str):
        from becos.datasets import prepare_shape

        return self._prepared.get_or_make((dataset, name),
                                          lambda: prepare_shape(self.entry(dataset, name), self.mesh_cache))

    def remeshed(self, dataset: str, name: str, token: str):
        """The remesh variant (:class:`becos.remesh.Remeshed`), or None for ``original``."""
        from becos.remesh import load_remeshed

        if token == "original":
            return None
        return self._remeshed.get_or_make((dataset, name, token),
                                          lambda: load_remeshed(self.layout.remeshed(dataset, name, token)))

    def file_digest(self, path: Path) -> str:
        path = Path(path)
        if path not in self._digests:
            self._digests[path] = hashlib.sha256(path.read_bytes()).hexdigest()[:16]
        return self._digests[path]

    def source_digest(self, dataset: str, name: str, token: str) -> str:
        """Digest of the file a pair side is built from (remesh variant, or the original mesh)."""
        if token == "original":
            return self.file_digest(self.entry(dataset, name).path)
        return self.file_digest(self.layout.remeshed(dataset, name, token))

    @property
    def network(self):
        from becos.network import ShapeNetwork

        if self._network is None:
            self._network = ShapeNetwork(annotation_source(self.config), self.mesh)
        return self._network

    def instance(self, dataset: str, name: str, token: str):
        """A :class:`becos.pairs.ShapeInstance` (common frame, dataset scale; remeshed unless ``original``)."""
        from becos.pairs import ShapeInstance

        entry, prepared = self.entry(dataset, name), self.prepared(dataset, name)
        remeshed = self.remeshed(dataset, name, token)
        mesh = prepared.mesh if remeshed is None else remeshed.mesh
        variant = int(token[1:]) if token.startswith("v") else -1
        return ShapeInstance(entry.dataset, entry.name, entry.category, entry.shape_class, mesh, entry.scale,
                             entry.frame_rotation, prepared.centre, variant)


# --------------------------------------------------------------------------------------------------
# stage functions (one per job kind)

def _log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def write_catalog_stage(config: dict, out: Path) -> pd.DataFrame:
    from becos.catalog import write_catalog

    catalog = build_catalog(config)
    write_catalog(catalog, out)
    counts = catalog.groupby(["dataset", "split"]).size().to_dict()
    _log(f"catalog: {len(catalog)} shapes -> {out}; per dataset/split: {counts}")
    return catalog


def write_manifest_stage(config: dict, setting: str, catalog_path: Path, out: Path) -> pd.DataFrame:
    from becos.catalog import read_catalog
    from becos.sampling import write_manifest

    manifest = build_manifest(config, setting, read_catalog(catalog_path))
    write_manifest(manifest, out)
    report = manifest.attrs.get("report", {})
    _log(f"manifest {setting}: {len(manifest)} pairs -> {out}; {json.dumps(report, sort_keys=True)}")
    return manifest


def remesh_stage(config: dict, shape_row: dict, token: str, out: Path, ply: Path | None = None) -> None:
    """Remesh one shape variant (prepared, common-frame mesh) and write the maps (+ a PLY to look at).

    ``shape_row`` is the shape's catalog row (:mod:`becos.catalog` columns). With ``remesher:
    reference`` the reference's remesh of the file coordinates (:mod:`becos.reference_remesh`; a vertex
    target n becomes the face target 2n).
    """
    from becos.remesh import remesh, save_remeshed, write_ply

    dataset, name = shape_row["dataset"], shape_row["name"]
    shapes = ShapeStore(config, [shape_row])
    target = remesh_target(config, dataset, name, token)
    prepared = shapes.prepared(dataset, name)
    start = time.perf_counter()
    if config.get("remesher") == "reference":
        from becos.reference_remesh import remesh_like_reference

        faces = target.get("target_faces") or 2 * int(target["target_vertices"])
        result, _ = remesh_like_reference(shapes.mesh(dataset, name), prepared, faces, source=prepared.entry.path)
    else:
        result = remesh(prepared.mesh, **target, source=prepared.entry.path)
    _remove_killed_writes([Path(p) for p in (out, ply) if p is not None])
    save_remeshed(Path(out), result)
    if ply is not None:
        write_ply(Path(ply), result.mesh)
    _log(f"remesh {dataset}/{name} {token} ({config.get('remesher', 'becos')}): {prepared.mesh.n_vertices} -> "
         f"{result.mesh.n_vertices} vertices ({target}) in {time.perf_counter() - start:.1f} s")


def _stored_key(path: Path, member: str) -> str | None:
    """The input key stored in an .npz (None if absent or unreadable)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            value = str(data[member]) if member in data.files else None
    except Exception:
        return None
    if value is not None and member == "__meta__":
        return json.loads(value).get("input_key")
    return value


def _chunk_rows(config: dict, setting: str, chunk: int) -> pd.DataFrame:
    from becos.sampling import read_manifest

    manifest = read_manifest(Layout.of(config).manifest(setting))
    rows = manifest[manifest["chunk"] == int(chunk)]
    # shapes in order, so consecutive pairs share loaded meshes and scanners
    return rows.sort_values(["x_dataset", "x_name", "y_dataset", "y_name", "pair_id"])


def _progress(stage: str, setting: str, chunk: int, entries: list[dict], n_rows: int, started: float) -> None:
    """A progress line every 10 pairs and at the end of a chunk."""
    done = len(entries)
    if done % 10 == 0 or done == n_rows:
        _log(f"{stage} {setting} chunk {chunk}: {done}/{n_rows} pairs ({sum(e['computed'] for e in entries)} "
             f"computed, the rest up to date) {time.perf_counter() - started:.1f} s")


def _remove_killed_writes(paths: list[Path]) -> None:
    """Before a job writes ``paths``: remove the temporary files a killed run of it left beside them."""
    for folder in {p.parent for p in paths}:
        n = remove_stale_temporaries(folder, [p.name for p in paths if p.parent == folder])
        if n:
            _log(f"removed {n} temporary file(s) left in {folder} by an interrupted run")


def _write_index(path: Path, setting: str, chunk: int, entries: list[dict], started: float) -> dict:
    """Write a chunk's index (pairs, their files, input keys and digests); return its counts.

    The index holds content only, so a resumed or re-ordered run writes the same bytes; what was
    computed or reused and how long it took go to the job's log."""
    computed = sum(e["computed"] for e in entries)
    index = {"setting": setting, "chunk": int(chunk), "n_pairs": len(entries),
             "pairs": sorted(({k: v for k, v in e.items() if k != "computed"} for e in entries),
                             key=lambda e: e["pair_id"])}
    write_text(path, json.dumps(index, indent=1) + "\n")
    _log(f"chunk {chunk} of {setting}: {len(entries)} pairs, {computed} computed, {len(entries) - computed} "
         f"reused, {time.perf_counter() - started:.1f} s")
    return {"n": len(entries), "computed": computed}


def ground_truth_stage(config: dict, setting: str, chunk: int, out_index: Path) -> dict:
    """Ground truth both ways for every pair of a chunk; files already up to date are kept."""
    from becos.atomic import save_npz
    from becos.catalog import read_catalog

    started = time.perf_counter()
    layout = Layout.of(config)
    remesh = bool(config.get("remesh", True))
    shapes = ShapeStore(config, read_catalog(layout.catalog))
    rows = _chunk_rows(config, setting, chunk)
    _remove_killed_writes([*(layout.ground_truth(setting, pid) for pid in rows["pair_id"]), Path(out_index)])
    entries = []
    for row in rows.to_dict("records"):
        tx, ty = remesh_token(row, "x", remesh), remesh_token(row, "y", remesh)
        key = digest({"version": GROUND_TRUTH_VERSION, "x": [row["x_dataset"], row["x_name"], tx],
                      "y": [row["y_dataset"], row["y_name"], ty],
                      "sources": [shapes.source_digest(row["x_dataset"], row["x_name"], tx),
                                  shapes.source_digest(row["y_dataset"], row["y_name"], ty)],
                      "options": stage_options(config, "ground_truth")})
        path = layout.ground_truth(setting, row["pair_id"])
        computed = _stored_key(path, "input_key") != key
        if computed:
            x, y = shapes.entry(row["x_dataset"], row["x_name"]), shapes.entry(row["y_dataset"], row["y_name"])
            rx, ry = shapes.remeshed(x.dataset, x.name, tx), shapes.remeshed(y.dataset, y.name, ty)
            gt_xy = shapes.network.ground_truth(x, y, x_remesh=rx, y_remesh=ry)
            gt_yx = shapes.network.ground_truth(y, x, x_remesh=ry, y_remesh=rx)
            save_npz(path, input_key=np.array(key), xy_face=gt_xy.face, xy_weights=gt_xy.weights,
                     xy_distance=gt_xy.distance, yx_face=gt_yx.face, yx_weights=gt_yx.weights,
                     yx_distance=gt_yx.distance)
        entries.append({"pair_id": row["pair_id"], "path": str(path), "input_key": key, "computed": computed,
                        "digest": shapes.file_digest(path)})
        _progress("ground truth", setting, chunk, entries, len(rows), started)
    return _write_index(Path(out_index), setting, chunk, entries, started)


def load_ground_truth(path: Path):
    """``(gt_xy, gt_yx)`` :class:`becos.surface_map.SurfaceMap` from a ground-truth file."""
    from becos.surface_map import SurfaceMap

    with np.load(path, allow_pickle=False) as d:
        return (SurfaceMap(d["xy_face"], d["xy_weights"], d["xy_distance"]),
                SurfaceMap(d["yx_face"], d["yx_weights"], d["yx_distance"]))


def pair_options(config: dict, setting: str):
    from becos.pairs import PairOptions

    fields = {k: config[k] for k in PairOptions.__dataclass_fields__ if k in config and k != "setting"}
    return PairOptions(setting=setting, **fields)  # keys a setting does not use keep their defaults


def pairs_stage(config: dict, setting: str, chunk: int, gt_index: Path, out_index: Path) -> dict:
    """Pair records (partiality, alignment, rotation, annotations) for every pair of a chunk."""
    from becos.catalog import read_catalog
    from becos.pairs import build_pair
    from becos.partiality import Scanner

    started = time.perf_counter()
    layout = Layout.of(config)
    remesh = bool(config.get("remesh", True))
    shapes = ShapeStore(config, read_catalog(layout.catalog))
    options = pair_options(config, setting)
    gt_files = {e["pair_id"]: e for e in json.loads(Path(gt_index).read_text())["pairs"]}
    rows = _chunk_rows(config, setting, chunk)
    _remove_killed_writes([*(layout.record(setting, pid) for pid in rows["pair_id"]), Path(out_index)])
    scanners = _Recent(SHAPES_KEPT)
    labels = _labeller(config, shapes) if config.get("propagate_annotations", True) else None
    entries = []
    for row in rows.to_dict("records"):
        tx, ty = remesh_token(row, "x", remesh), remesh_token(row, "y", remesh)
        gt = gt_files.get(row["pair_id"])
        if gt is None:
            raise ConfigError(f"{gt_index}: no ground truth for pair {row['pair_id']}; re-run the workflow "
                              "(the ground-truth index is older than the manifest)")
        key = digest({"version": RECORD_VERSION, "row": {k: row[k] for k in sorted(row) if k != "chunk"},
                      "options": stage_options(config, "pairs", setting), "ground_truth": gt["digest"],
                      "sources": [shapes.source_digest(row["x_dataset"], row["x_name"], tx),
                                  shapes.source_digest(row["y_dataset"], row["y_name"], ty)]})
        path = layout.record(setting, row["pair_id"])
        computed = _stored_key(path, "__meta__") != key
        if computed:
            x = shapes.instance(row["x_dataset"], row["x_name"], tx)
            y = shapes.instance(row["y_dataset"], row["y_name"], ty)
            gt_xy, gt_yx = load_ground_truth(Path(gt["path"]))
            pair_scanners = (None, None)
            if setting != "full_full":
                pair_scanners = tuple(scanners.get_or_make((s.dataset, s.name, t), lambda s=s: Scanner(s.mesh))
                                      for s, t in ((x, tx), (y, ty)))
            record = build_pair(x, y, gt_xy, gt_yx, pair_id=row["pair_id"], seed=int(row["seed"]),
                                split=row["split"], options=options, scanners=pair_scanners,
                                rotations=_published_rotations(row),
                                published_views=_published_views(config, row, options))
            if labels is not None:
                for side, s, t in (("x", x, tx), ("y", y, ty)):
                    full = labels(s.dataset, s.name, t)
                    if full is not None:
                        record.arrays[f"{side}_annotation"] = full[record[f"{side}_partial_to_full"]]
            record.meta.update(input_key=key, category=row["category"], copy=int(row["copy"]),
                               x_token=tx, y_token=ty)  # no chunk: regrouping keeps the record
            record.save(path)
        entries.append({"pair_id": row["pair_id"], "path": str(path), "input_key": key, "computed": computed,
                        "split": row["split"]})
        _progress("pairs", setting, chunk, entries, len(rows), started)
    return _write_index(Path(out_index), setting, chunk, entries, started)


def _published_views(config: dict, row: dict, options):
    """``original_settings`` P2P with the reference remesh: the views of the pair's published cameras
    (:func:`becos.reference_views.published_scan`), else None (the pairs stage draws cameras)."""
    if (options.setting != "partial_partial" or not config.get("original_settings")
            or config.get("remesher") != "reference" or "x_cam_pos_0" not in row):
        return None
    from becos.reference_views import published_scan

    n = sum(1 for k in row if k.startswith("x_cam_pos_"))
    cameras = np.array([[row[f"{side}_cam_pos_{i}"] for i in range(n)] for side in "xy"],
                       dtype=np.float64).reshape(2, -1, 3)
    return lambda x, y, gt_xy, gt_yx: published_scan(
        x, y, gt_xy, gt_yx, config["annotations"], row["x_name"], row["y_name"], cameras,
        options.n_cam_pos, options.min_overlap, options.max_overlap)


def _published_rotations(row: dict):
    """The published lists' random rotations of a pair (``original_settings``), else None."""
    if "x_random_rot_0" not in row or math.isnan(float(row["x_random_rot_0"])):
        return None
    return tuple(np.array([row[f"{side}_random_rot_{i}"] for i in range(9)], dtype=np.float64).reshape(3, 3)
                 for side in ("x", "y"))


def _labeller(config: dict, shapes: ShapeStore):
    """``labels(dataset, name, token) -> (V,) int8 or None``: propagated left/right labels of a full shape."""
    from becos.propagation import labels_for_instance

    cache: dict = {}

    def labels(dataset: str, name: str, token: str):
        key = (dataset, name, token)
        if key not in cache:
            cache[key] = labels_for_instance(shapes.network, shapes.entry(dataset, name),
                                             remesh=shapes.remeshed(dataset, name, token))
        return cache[key]

    return labels


def store_metadata(config: dict, setting: str) -> dict:
    """Metadata for a setting's store: config and its digest, datasets with licence and citation."""
    from becos.datasets import DatasetSpec

    datasets = {}
    for name in config["datasets"]:
        spec = DatasetSpec.load(name)
        datasets[name] = {"title": spec.title, **{k: spec.source.get(k) for k in ("url", "licence", "citation")}}
    return {"setting": setting, "config": config, "config_hash": digest(config),
            "datasets": datasets, "generator": "becos workflow",
            "follows_published_lists": published_parts(config, setting)}


def published_parts(config: dict, setting: str) -> dict[str, bool | None]:
    """Per part of a setting's benchmark, whether it follows the published pair lists (None: the
    setting has no such part). P2P views follow them with the reference remesh (their triangle ids
    index its faces; :mod:`becos.reference_views`); P2F has no published list."""
    original = bool(config.get("original_settings"))
    remesh = bool(config.get("remesh", True))
    reference = original and remesh and config.get("remesher") == "reference"
    return {"pairs": original, "rotations": original, "face_targets": original and remesh,
            "remesh": reference,
            "views": None if setting == "full_full" else (reference and setting == "partial_partial")}


def export_pairings_stage(config: dict, setting: str, out: Path) -> None:
    """The manifest in the published pickle schema (share a benchmark as pair lists + code)."""
    from becos.catalog import read_catalog
    from becos.published import write_published_pickle
    from becos.sampling import read_manifest

    layout = Layout.of(config)
    write_published_pickle(read_manifest(layout.manifest(setting)), out, read_catalog(layout.catalog))


# --------------------------------------------------------------------------------------------------
# command line

def configure_parser(parser: argparse.ArgumentParser, name: str) -> None:
    parser.add_argument("--options", required=True,
                        help="JSON: the job's options (becos.workflow.job_options), or the whole config for write-config "
                             "and metadata")
    if name in ("manifest", "ground-truth", "pairs", "metadata", "export-pairings"):
        parser.add_argument("--setting", required=True, choices=SETTINGS)
    if name in ("ground-truth", "pairs"):
        parser.add_argument("--chunk", required=True, type=int)
    if name == "pairs":
        parser.add_argument("--ground-truth", required=True, type=Path, help="the chunk's ground-truth index")
    if name == "manifest":
        parser.add_argument("--catalog", required=True, type=Path)
    if name == "remesh":
        parser.add_argument("--shape", required=True, help="JSON: the shape's catalog row")
        parser.add_argument("--token", required=True, help="v<k> (variant k) or f<n> (target faces n)")
        parser.add_argument("--ply", type=Path, help="also write the remeshed mesh as PLY")
    parser.add_argument("--out", required=True, type=Path)


def run_cli(args: argparse.Namespace) -> int:
    config = json.loads(args.options)
    if args.command == "write-config":
        write_text(args.out, json.dumps(resolve_config(config), indent=1, sort_keys=True) + "\n")
        return 0
    if args.command == "catalog":
        write_catalog_stage(config, args.out)
    elif args.command == "manifest":
        write_manifest_stage(config, args.setting, args.catalog, args.out)
    elif args.command == "remesh":
        remesh_stage(config, json.loads(args.shape), args.token, args.out, args.ply)
    elif args.command == "ground-truth":
        ground_truth_stage(config, args.setting, args.chunk, args.out)
    elif args.command == "pairs":
        pairs_stage(config, args.setting, args.chunk, args.ground_truth, args.out)
    elif args.command == "metadata":
        write_text(args.out, json.dumps(store_metadata(config, args.setting), indent=1, sort_keys=True,
                                        default=str) + "\n")
    elif args.command == "export-pairings":
        export_pairings_stage(config, args.setting, args.out)
    return 0
