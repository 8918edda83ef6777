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
from becos.workflow.layout import Layout, remesh_token
from becos.workflow.options import (
    AnnotationOptions,
    CatalogOptions,
    ManifestOptions,
    PairsOptions,
    pairs_options,
    settings_of,
)

if TYPE_CHECKING:
    import pandas as pd  # imported where used: write-config, metadata and remesh jobs start without it


def annotation_source(options, cache: str | Path | None = None):
    """The annotation folder of ``options`` (a resolved config or any options with ``annotations``,
    ``template_file`` and ``results``), its parsed edge files cached in the folder ``cache`` (default
    ``results/cache/annotations``, the Snakemake process's)."""
    from becos.sources.annotations import AnnotationSource

    options = AnnotationOptions.of(options)
    return AnnotationSource(
        options.annotations,
        cache_dir=Layout.of(options).cache / "annotations" if cache is None else cache,
        template_table=options.template_file,
    )


def build_catalog(options, annotations=None) -> pd.DataFrame:
    """The catalog of every enabled dataset's shapes (:mod:`becos.sources.catalog`); ``options``: the catalog's
    (:class:`CatalogOptions`, or a resolved config)."""
    from becos.sources.catalog import catalog_table
    from becos.sources.datasets import DatasetSpec

    options = CatalogOptions.of(options)
    annotations = annotations or annotation_source(options)
    entries = []
    for name in options.datasets:
        entries.extend(DatasetSpec.load(name).list_shapes(options.data_dir, annotations))
    patterns = options.shapes
    if patterns:
        from fnmatch import fnmatchcase

        entries = [e for e in entries if any(fnmatchcase(f"{e.dataset}/{e.name}", p) for p in patterns)]
        if not entries:
            raise ConfigError(
                f"shapes: no shape of datasets {options.datasets} matches {patterns}. Fix: give "
                "<dataset>/<name> patterns of shapes in those datasets (globs allowed, e.g. tosca/cat*), "
                "or add their dataset to `datasets`"
            )
    return catalog_table(entries)


def build_manifest(options, setting: str, catalog: pd.DataFrame, annotations=None) -> pd.DataFrame:
    """The pair manifest of ``setting`` (:mod:`becos.build.sampling`, or the published lists); ``options``: the
    manifest's (:class:`ManifestOptions`, or a resolved config)."""
    from becos.build.sampling import sample_pairs

    o = ManifestOptions.of(options)
    if o.original_settings:
        return _published_manifest(o, setting, catalog)
    annotations = annotations or annotation_source(o)
    caps = {k: v for k, v in o.caps.items() if v is not None}
    return sample_pairs(
        catalog,
        setting,
        seed=o.seed,
        combinations=o.combinations,
        template_rows=annotations,
        n_variants=o.remesh_variants,
        n_chunks=o.n_chunks,
        pairs_per_chunk=o.pairs_per_chunk,
        min_chunks=o.min_chunks,
        caps=caps or None,
        usage_scale=o.usage_scale,
    )


def _published_manifest(o: ManifestOptions, setting: str, catalog: pd.DataFrame) -> pd.DataFrame:
    """The published pair list of ``setting`` (with its cameras), restricted to the catalog and the caps."""
    import pandas as pd

    from becos.build.published import import_published
    from becos.build.sampling import assign_chunks

    path = Path(o.annotations) / "config" / f"pairings_original_{setting}.pkl"
    imported = import_published(
        path, setting=setting, seed=o.seed, n_variants=o.remesh_variants, n_chunks=o.n_chunks, datasets=o.datasets
    )
    manifest = imported.manifest
    if imported.cameras:  # P2P: the published cameras travel with their pair (x_cam_pos_0..29, y_...)
        cams = np.stack([imported.cameras[p] for p in manifest["pair_id"]]).reshape(len(manifest), 2, -1)
        columns = {f"{side}_cam_pos_{i}": cams[:, s, i] for s, side in enumerate("xy") for i in range(cams.shape[2])}
        manifest = pd.concat([manifest, pd.DataFrame(columns, index=manifest.index)], axis=1)
        manifest.attrs = imported.manifest.attrs
    manifest = _restrict_published(manifest, catalog, o, setting)
    manifest["chunk"] = assign_chunks(
        manifest["pair_id"], n_chunks=o.n_chunks, pairs_per_chunk=o.pairs_per_chunk, min_chunks=o.min_chunks
    )
    return manifest


def _restrict_published(
    manifest: pd.DataFrame, catalog: pd.DataFrame, o: ManifestOptions, setting: str
) -> pd.DataFrame:
    """Published pairs whose two shapes are in the catalog (``shapes`` filter), then the per-split caps
    (pairs ranked by a keyed hash of their id, as for sampled pairs)."""
    from becos.build.sampling import sort_manifest
    from becos.seeding import stable_hash

    known = set(zip(catalog["dataset"], catalog["name"]))
    keep = [
        (xd, xn) in known and (yd, yn) in known
        for xd, xn, yd, yn in zip(manifest["x_dataset"], manifest["x_name"], manifest["y_dataset"], manifest["y_name"])
    ]
    out = manifest[np.asarray(keep, dtype=bool)]
    for split, cap in o.caps.items():
        rows = out[out["split"] == split]
        if cap is not None and len(rows) > cap:
            rank = sorted(rows["pair_id"], key=lambda p: stable_hash(o.seed, setting, "cap", p))
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

    options: ManifestOptions
    catalog: pd.DataFrame
    manifests: dict[str, pd.DataFrame]
    layout: Layout = field(init=False)
    _chunk_inputs: dict[tuple[str, int], list[str]] = field(init=False, default_factory=dict, repr=False)

    def __post_init__(self):
        self.options = ManifestOptions.of(self.options)  # a resolved config is accepted too
        self.layout = Layout.of(self.options)

    @classmethod
    def build(cls, config: dict) -> Plan:
        """The plan of a resolved config (its manifest options, every configured setting)."""
        options = ManifestOptions.of(config)
        annotations = annotation_source(options)
        catalog = build_catalog(options, annotations)
        manifests = {s: build_manifest(options, s, catalog, annotations) for s in settings_of(config)}
        return cls(options, catalog, manifests)

    @cached_property
    def files(self) -> dict[tuple[str, str], str]:
        return {(d, n): f for d, n, f in zip(self.catalog["dataset"], self.catalog["name"], self.catalog["file"])}

    def _side_files(self, rows: pd.DataFrame) -> list[tuple[str, str, str]]:
        return side_shapes(rows, self.options.remesh)

    @cached_property
    def remesh_variants(self) -> list[tuple[str, str, str]]:
        """Every (dataset, name, token) some pair uses, remeshing only (not ``original``)."""
        if not self.options.remesh:
            return []
        variants = set()
        for manifest in self.manifests.values():
            variants.update(self._side_files(manifest))
        return sorted(variants)

    @cached_property
    def remesh_jobs(self) -> dict[tuple[str, str], list[str]]:
        """The remesh jobs, one per shape: ``{(dataset, name): [token, ...]}``, the sorted tokens of the
        shape's :attr:`remesh_variants` (the variants the job writes into :meth:`Layout.remeshed_folder`)."""
        jobs: dict[tuple[str, str], list[str]] = {}
        for dataset, name, token in self.remesh_variants:
            jobs.setdefault((dataset, name), []).append(token)
        return jobs

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
        """The remesh folders (:meth:`Layout.remeshed_folder`, one per shape: its remesh job's output) that
        hold the remesh files the chunk reads, sorted (none without remeshing); computed once per chunk."""
        if not self.options.remesh:
            return []
        key = (setting, int(chunk))
        if key not in self._chunk_inputs:
            shapes = {(d, n) for d, n, _ in self._side_files(self.chunk_rows(setting, chunk))}
            self._chunk_inputs[key] = [str(self.layout.remeshed_folder(d, n)) for d, n in sorted(shapes)]
        return list(self._chunk_inputs[key])

    def setting_inputs(self, setting: str) -> list[str]:
        """The remesh folders every chunk of ``setting`` reads (:meth:`chunk_inputs`, united), sorted."""
        return sorted({folder for chunk in self.chunks(setting) for folder in self.chunk_inputs(setting, chunk)})

    def chunk_original_files(self, setting: str, chunk: int) -> list[str]:
        """The original mesh files of the chunk's pairs' shapes (what a chunk job reads without remeshing)."""
        rows = self.chunk_rows(setting, chunk)
        return sorted({self.files[key] for side in "xy" for key in zip(rows[f"{side}_dataset"], rows[f"{side}_name"])})

    def chunk_mesh_files(self, setting: str, chunk: int) -> list[str]:
        """Every original mesh file a chunk job reads: its pairs' shapes (their centres, and their geometry
        without remeshing) and the catalogued templates on the network paths between them (the ground
        truth's edge maps land on their faces; :func:`network_templates_between`)."""
        keys = self._catalog_rows
        rows = self.chunk_rows(setting, chunk)
        files = set(self.chunk_original_files(setting, chunk))
        for xd, xn, yd, yn in zip(rows["x_dataset"], rows["x_name"], rows["y_dataset"], rows["y_name"]):
            x_key, y_key = keys[(xd, xn)]["template_key"], keys[(yd, yn)]["template_key"]
            for template in network_templates_between(self._annotations, x_key, y_key):
                if template in self.files:
                    files.add(self.files[template])
        return sorted(files)

    @cached_property
    def _catalog_rows(self) -> dict[tuple[str, str], dict]:
        return {(r["dataset"], r["name"]): r for r in self.catalog.to_dict("records")}

    def shape_json(self, dataset: str, name: str) -> str:
        """A shape's catalog row as JSON but its ``file`` (the remesh job's description of its shape; the
        rule passes the file itself)."""
        row = self._catalog_rows[(dataset, name)]
        return json.dumps({k: v for k, v in row.items() if k != "file"}, sort_keys=True)

    def remesh_targets(self, dataset: str, name: str) -> dict[str, dict]:
        """``{token: target}`` of the shape's remesh job (:func:`remesh_target` of each of its tokens)."""
        return {t: remesh_target(self.options.seed, dataset, name, t) for t in self.remesh_jobs[(dataset, name)]}

    @cached_property
    def _annotations(self):
        return annotation_source(self.options)

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


def side_shapes(rows: pd.DataFrame, remesh: bool) -> list[tuple[str, str, str]]:
    """``(dataset, name, token)`` of each shape the pairs of manifest ``rows`` use (:func:`remesh_token`), sorted."""
    out = set()
    for row in rows.to_dict("records"):
        for side in ("x", "y"):
            out.add((row[f"{side}_dataset"], row[f"{side}_name"], remesh_token(row, side, remesh)))
    return sorted(out)


def chunk_remesh_files(manifest: pd.DataFrame, options) -> dict[str, list[list[str]]]:
    """Per chunk of ``manifest`` (its number as a string), ``[dataset, name, token, path]`` of each remesh
    file its pairs use (none without remeshing), the paths of :meth:`Layout.remeshed`: what its chunk
    jobs read, the list file :meth:`Layout.remesh_files` holds. ``options``: the manifest's."""
    options = ManifestOptions.of(options)
    if not options.remesh:
        return {str(int(c)): [] for c in sorted(set(manifest["chunk"]))}
    layout = Layout.of(options)
    return {
        str(int(c)): [[*key, str(layout.remeshed(*key))] for key in side_shapes(rows, True)]
        for c, rows in manifest.groupby("chunk", sort=True)
    }


def remesh_target(seed: int, dataset: str, name: str, token: str) -> dict:
    """Arguments of :func:`becos.build.remesh.remesh` for a token (``seed``: config ``seed``)."""
    from becos.build.remesh import variant_target_vertices

    if token.startswith("f"):
        return {"target_faces": int(token[1:])}
    return {"target_vertices": int(variant_target_vertices(seed, dataset, name, int(token[1:])))}


def uses_published_views(config, setting: str) -> bool:
    """Whether the pairs stage of ``setting`` takes its views from the published cameras
    (:attr:`PairsOptions.published_views`; ``config``: a resolved config or the stage's options)."""
    return pairs_options(config, setting).published_views


def published_views_folder(config, setting: str) -> Path | None:
    """The folder of shipped triangle-id files the pairs stage of ``setting`` reads
    (:func:`becos.build.reference_views.triangle_ids_folder`), or None: the stage reads none (it draws its
    cameras, or the annotation folder ships no views and every published view is cast)."""
    if not uses_published_views(config, setting):
        return None
    from becos.build.reference_views import triangle_ids_folder

    folder = triangle_ids_folder(PairsOptions.of(config).annotations, setting)
    return folder if folder.is_dir() else None


def network_templates_between(annotations, x_key: str, y_key: str) -> list[tuple[str, str]]:
    """``(dataset, name)`` of each template on the network path between the templates of template keys
    ``x_key`` and ``y_key``, both ends included."""
    nodes = annotations.path(annotations.node_of_key(x_key), annotations.node_of_key(y_key))
    return [tuple(annotations.node_template(node)) for node in nodes]


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
