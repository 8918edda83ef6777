"""The plan: the catalog and manifests of a config, and the jobs they imply (everything Snakemake needs to
know to build the job graph)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from becos.errors import ConfigError
from becos.settings import SPLITS
from becos.workflow.config import settings_of
from becos.workflow.layout import Layout, remesh_token

if TYPE_CHECKING:
    import pandas as pd  # imported where used: write-config, metadata and remesh jobs start without it


def annotation_source(config: dict):
    from becos.annotations import AnnotationSource

    return AnnotationSource(
        config["annotations"],
        cache_dir=Layout.of(config).cache / "annotations",
        template_table=config.get("template_file", "templates_all.csv"),
    )


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
            raise ConfigError(
                f"shapes: no shape of datasets {config['datasets']} matches {patterns}. Fix: give "
                "<dataset>/<name> patterns of shapes in those datasets (globs allowed, e.g. tosca/cat*), "
                "or add their dataset to `datasets`"
            )
    return catalog_table(entries)


def build_manifest(config: dict, setting: str, catalog: pd.DataFrame, annotations=None) -> pd.DataFrame:
    """The pair manifest of ``setting`` (:mod:`becos.sampling`, or the published lists)."""
    import pandas as pd

    from becos.sampling import assign_chunks, sample_pairs

    if config.get("original_settings"):
        from becos.published import import_published

        path = Path(config["annotations"]) / "config" / f"pairings_original_{setting}.pkl"
        imported = import_published(
            path,
            setting=setting,
            seed=config["seed"],
            n_variants=config["remesh_variants"],
            n_chunks=config["n_chunks"],
            datasets=config["datasets"],
        )
        manifest = imported.manifest
        if imported.cameras:  # P2P: the published cameras travel with their pair (x_cam_pos_0..29, y_...)
            cams = np.stack([imported.cameras[p] for p in manifest["pair_id"]]).reshape(len(manifest), 2, -1)
            columns = {
                f"{side}_cam_pos_{i}": cams[:, s, i] for s, side in enumerate("xy") for i in range(cams.shape[2])
            }
            manifest = pd.concat([manifest, pd.DataFrame(columns, index=manifest.index)], axis=1)
            manifest.attrs = imported.manifest.attrs
        manifest = _restrict_published(manifest, catalog, config, setting)
        manifest["chunk"] = assign_chunks(
            manifest["pair_id"], n_chunks=config["n_chunks"], pairs_per_chunk=config["pairs_per_chunk"]
        )
        return manifest
    annotations = annotations or annotation_source(config)
    caps = {k: v for k, v in (config.get("caps") or {}).items() if v is not None}
    return sample_pairs(
        catalog,
        setting,
        seed=config["seed"],
        combinations=config["combinations"],
        template_rows=annotations,
        n_variants=config["remesh_variants"],
        n_chunks=config["n_chunks"],
        pairs_per_chunk=config["pairs_per_chunk"],
        caps=caps or None,
        usage_scale=config["usage_scale"],
    )


def _restrict_published(manifest: pd.DataFrame, catalog: pd.DataFrame, config: dict, setting: str) -> pd.DataFrame:
    """Published pairs whose two shapes are in the catalog (``shapes`` filter), then the per-split caps
    (pairs ranked by a keyed hash of their id, as for sampled pairs)."""
    from becos.sampling import sort_manifest
    from becos.seeding import stable_hash

    known = set(zip(catalog["dataset"], catalog["name"]))
    keep = [
        (xd, xn) in known and (yd, yn) in known
        for xd, xn, yd, yn in zip(manifest["x_dataset"], manifest["x_name"], manifest["y_dataset"], manifest["y_name"])
    ]
    out = manifest[np.asarray(keep, dtype=bool)]
    for split, cap in (config.get("caps") or {}).items():
        rows = out[out["split"] == split]
        if cap is not None and len(rows) > cap:
            rank = sorted(rows["pair_id"], key=lambda p: stable_hash(config["seed"], setting, "cap", p))
            out = out[(out["split"] != split) | out["pair_id"].isin(rank[:cap])]
    report = dict(manifest.attrs.get("report", {}))
    report["n_pairs"] = {s: int((out["split"] == s).sum()) for s in SPLITS}
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
    def build(cls, config: dict) -> Plan:
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

    def chunk_original_files(self, setting: str, chunk: int) -> list[str]:
        """The original mesh files of the chunk's pairs' shapes (what a chunk job reads without remeshing)."""
        rows = self.chunk_rows(setting, chunk)
        return sorted({self.files[key] for side in "xy" for key in zip(rows[f"{side}_dataset"], rows[f"{side}_name"])})

    @cached_property
    def _catalog_rows(self) -> dict[tuple[str, str], dict]:
        return {(r["dataset"], r["name"]): r for r in self.catalog.to_dict("records")}

    def shape_json(self, dataset: str, name: str) -> str:
        """A shape's catalog row as JSON (the remesh job's description of its shape)."""
        return json.dumps(self._catalog_rows[(dataset, name)], sort_keys=True)

    def remesh_target(self, dataset: str, name: str, token: str) -> dict:
        return remesh_target(self.config, dataset, name, token)

    @cached_property
    def _annotations(self):
        return annotation_source(self.config)

    def chunk_edge_files(self, setting: str, chunk: int) -> list[str]:
        """The annotation folder's edge files the chunk's ground truth reads (both directions), so that
        editing or restoring one reruns the chunk (:func:`edge_files_between`)."""
        keys = self._catalog_rows
        rows = self.chunk_rows(setting, chunk)
        pairs = {
            (keys[(xd, xn)]["template_key"], keys[(yd, yn)]["template_key"])
            for xd, xn, yd, yn in zip(rows["x_dataset"], rows["x_name"], rows["y_dataset"], rows["y_name"])
        }
        return sorted({str(p) for kx, ky in pairs for p in edge_files_between(self._annotations, kx, ky)})


def remesh_target(config: dict, dataset: str, name: str, token: str) -> dict:
    """Arguments of :func:`becos.remesh.remesh` for a token."""
    from becos.remesh import variant_target_vertices

    if token.startswith("f"):
        return {"target_faces": int(token[1:])}
    return {"target_vertices": int(variant_target_vertices(config["seed"], dataset, name, int(token[1:])))}


def uses_published_views(config: dict, setting: str) -> bool:
    """Whether the pairs stage of ``setting`` takes its views from the published cameras
    (``original_settings`` P2P with the reference remesh: the shipped triangle ids index its faces)."""
    return (
        setting == "partial_partial" and bool(config.get("original_settings")) and config.get("remesher") == "reference"
    )


def published_views_folder(config: dict, setting: str) -> Path | None:
    """The folder of shipped triangle-id files the pairs stage of ``setting`` reads
    (:func:`becos.reference_views.triangle_ids_folder`), or None: the stage reads none (it draws its
    cameras, or the annotation folder ships no views and every published view is cast)."""
    if not uses_published_views(config, setting):
        return None
    from becos.reference_views import triangle_ids_folder

    folder = triangle_ids_folder(config["annotations"], setting)
    return folder if folder.is_dir() else None


def edge_files_between(annotations, x_key: str, y_key: str) -> list[Path]:
    """Edge files on the network path between the templates of template keys ``x_key`` and ``y_key``,
    both directions (the ground truth both ways reads them); identity edges have none."""
    nodes = annotations.path(annotations.node_of_key(x_key), annotations.node_of_key(y_key))
    out = []
    for a, b in zip(nodes, nodes[1:]):
        for u, v in ((a, b), (b, a)):
            source = annotations.edge_source(u, v)
            if source.kind == "file":
                out.append(Path(source.path))
    return out
