"""Shapes as a chunk job sees them: catalog entries, parsed, prepared and remeshed meshes and the
structures built on them, kept while the chunk's pairs still use them (:class:`ShapeStore`)."""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from becos.digests import bytes_digest
from becos.errors import ConfigError
from becos.workflow.layout import Layout, centre_file, remesh_token, remeshed_file
from becos.workflow.plan import annotation_source

if TYPE_CHECKING:
    import pandas as pd  # imported where used: write-config, metadata and remesh jobs start without it

SHAPES_KEPT = 16
"""Shapes (prepared, remeshed, locators, scanners) a chunk job keeps in memory at most; each is dropped
as soon as the chunk's remaining pairs no longer use it (:meth:`ShapeStore.release`)."""
MESHES_KEPT = 12
"""Original meshes a chunk job keeps parsed in memory (:class:`becos.core.mesh.MeshCache`)."""


def shape_entry(row) -> object:
    from becos.sources.catalog import frame_rotation
    from becos.sources.datasets import ShapeEntry

    return ShapeEntry(
        dataset=row["dataset"],
        name=row["name"],
        path=Path(row["file"]),
        category=row["category"],
        shape_class=row["class"],
        template_key=row["template_key"],
        split=row["split"],
        scale=float(row["scale"]),
        frame_rotation=frame_rotation(row),
        usage=int(row["usage"]),
    )


class _Recent(OrderedDict):
    """A dict that keeps only its ``size`` most recently used entries."""

    def __init__(self, size: int, on_drop=None):
        super().__init__()
        self.size = size
        self.on_drop = on_drop  # called with each value pushed out (not with values popped by the caller)

    def get_or_make(self, key, make):
        if key in self:
            self.move_to_end(key)
            return self[key]
        value = self[key] = make()
        while len(self) > self.size:
            _, dropped = self.popitem(last=False)
            if self.on_drop is not None:
                self.on_drop(dropped)
        return value


ShapeKey = tuple[str, str, str]
"""``(dataset, name, token)``: one pair side's shape as a chunk job loads it."""


@dataclass(frozen=True)
class RemeshFiles:
    """The remesh files a chunk job was given: ``files`` by shape key, from the list file ``source``."""

    source: Path
    files: dict[ShapeKey, Path]

    def path(self, dataset: str, name: str, token: str) -> Path:
        try:
            return self.files[(dataset, name, token)]
        except KeyError:
            raise ConfigError(
                f"{self.source}: lists no remesh file of {dataset}/{name} {token}, which the chunk's pairs use. "
                "Fix: re-run the workflow (the list is older than the manifest; snakemake --forcerun manifest)"
            ) from None


def pair_shape_keys(row: dict, remesh: bool) -> tuple[ShapeKey, ShapeKey]:
    """The shapes of a manifest row's two sides."""
    return (
        (row["x_dataset"], row["x_name"], remesh_token(row, "x", remesh)),
        (row["y_dataset"], row["y_name"], remesh_token(row, "y", remesh)),
    )


def visit_order(records: list[dict], remesh: bool) -> tuple[list[dict], list[list[ShapeKey]]]:
    """The order a chunk job computes its pairs in, and per pair the shapes it uses for the last time.

    Pairs are sorted by their smaller then larger shape key (then id), so a shape's pairs come close
    together; a shape is released after its last pair (:meth:`ShapeStore.release`), which keeps a
    chunk's working set small without reloading shapes. The order changes no output: every pair's
    files depend on that pair alone, and the chunk's index is sorted by pair id.
    """

    def sort_key(row):
        a, b = pair_shape_keys(row, remesh)
        return (min(a, b), max(a, b), row["pair_id"])

    ordered = sorted(records, key=sort_key)
    last_use: dict[ShapeKey, int] = {}
    for i, row in enumerate(ordered):
        for key in pair_shape_keys(row, remesh):
            last_use[key] = i
    done: list[list[ShapeKey]] = [[] for _ in ordered]
    for key, i in last_use.items():
        done[i].append(key)
    return ordered, done


class ShapeStore:
    """The shapes of one job: catalog entries, parsed meshes, prepared meshes, remesh variants and the
    per-shape structures built on them (closest-point locators, Embree scanners).

    A chunk job releases a shape after the last of its pairs that uses it (:func:`visit_order`,
    :meth:`release`) and keeps at most :data:`SHAPES_KEPT` shapes (least recently used dropped first):
    each shape is loaded and its structures built about once per chunk, and the job's memory does not
    grow with the number of pairs in a chunk.
    """

    def __init__(
        self,
        options,
        catalog: pd.DataFrame | list[dict],
        remeshed: str | Path | RemeshFiles | None = None,
        cache: str | Path | None = None,
    ):
        """``options``: the job's stage options (:mod:`becos.workflow.options`; or a resolved config): its
        ``results`` and, for the shape network, its annotation folder. ``catalog``: the catalog table, or
        some of its rows as dicts. ``remeshed``: the remesh files a chunk job was given
        (:class:`RemeshFiles`), or the folder of the remesh variants (default: :attr:`Layout.remeshed_root`). ``cache``: a folder where parsed meshes and
        edge files are kept across jobs (benchmarks, tests); default None: a job parses the files its
        rule declares, keeping them in memory only (parsed edge files in a temporary folder of its own),
        so it reads no file its rule does not name."""
        from becos.core.mesh import MeshCache

        self.layout = Layout.of(options)
        self._annotation_options = options
        self._remesh_files = remeshed if isinstance(remeshed, RemeshFiles) else None
        folder = remeshed if remeshed is not None and self._remesh_files is None else self.layout.remeshed_root
        self.remeshed_root = Path(folder)
        rows = catalog if isinstance(catalog, list) else catalog.to_dict("records")
        self.entries = {(r["dataset"], r["name"]): shape_entry(r) for r in rows}
        self._cache = None if cache is None else Path(cache)
        self.mesh_cache = MeshCache(None if self._cache is None else self._cache / "meshes", max_in_memory=MESHES_KEPT)
        self._edge_cache = None  # the temporary folder of parsed edge files without ``cache``
        self._prepared = _Recent(SHAPES_KEPT)
        self._remeshed = _Recent(SHAPES_KEPT, on_drop=self._forget_remeshed)
        self._scanners = _Recent(SHAPES_KEPT)
        self._instances = _Recent(SHAPES_KEPT)
        self._centres: dict[tuple[str, str], np.ndarray] = {}
        self._digests: dict[Path, str] = {}
        self._network = None

    def _forget_remeshed(self, remeshed) -> None:
        """Drop what the network built on a remesh variant's mesh (its closest-point locator)."""
        if self._network is not None:
            self._network.forget(remeshed.mesh)

    def release(self, keys: list[ShapeKey]) -> None:
        """Drop shapes no later pair of the chunk uses (their remesh, locator, scanner, prepared mesh)."""
        for dataset, name, token in keys:
            remeshed = self._remeshed.pop((dataset, name, token), None)
            if remeshed is not None:
                self._forget_remeshed(remeshed)
            self._scanners.pop((dataset, name, token), None)
            self._instances.pop((dataset, name, token), None)
            if not any(k[:2] == (dataset, name) for k in self._remeshed):
                self._prepared.pop((dataset, name), None)

    def scanner(self, dataset: str, name: str, token: str, mesh):
        """The :class:`becos.build.partiality.Scanner` of a pair side's ``mesh`` (built once while kept)."""
        from becos.build.partiality import Scanner

        return self._scanners.get_or_make((dataset, name, token), lambda: Scanner(mesh))

    def centre(self, dataset: str, name: str, token: str | None = None) -> np.ndarray:
        """(3,) the shape's centre in scaled file coordinates (:attr:`becos.sources.datasets.PreparedShape.centre`),
        without preparing the whole mesh: the one its remesh job wrote beside the variant ``token``
        (:func:`becos.workflow.layout.centre_file`, the same float64 values), else from its original mesh
        (parsing it costs ~0.1 CPU-s per TOSCA shape, most of a pairs job's own work)."""
        from becos.sources.datasets import shape_centre

        key = (dataset, name)
        if key in self._prepared:
            return self._prepared[key].centre
        if key not in self._centres and token is not None and token != "original":
            stored = centre_file(self.remesh_path(dataset, name, token).parent)
            try:
                centre = np.load(stored, allow_pickle=False) if stored.is_file() else None
            except (OSError, ValueError):  # unreadable: the original gives the same centre
                centre = None
            if centre is not None and centre.shape == (3,) and centre.dtype == np.float64:
                self._centres[key] = centre
        if key not in self._centres:
            entry = self.entry(dataset, name)
            self._centres[key] = shape_centre(self.mesh_cache.load(entry.path), entry.scale)
        return self._centres[key]

    def entry(self, dataset: str, name: str):
        try:
            return self.entries[(dataset, name)]
        except KeyError:
            raise ConfigError(
                f"shape {dataset}/{name} is not in the catalog; was the dataset disabled? "
                f"Re-run the workflow so the catalog and manifests are rebuilt"
            ) from None

    def mesh(self, dataset: str, name: str):
        """The original mesh of a catalogued shape, or None (the network then uses default faces)."""
        entry = self.entries.get((dataset, name))
        return None if entry is None else self.mesh_cache.load(entry.path)

    def prepared(self, dataset: str, name: str):
        from becos.sources.datasets import prepare_shape

        return self._prepared.get_or_make(
            (dataset, name), lambda: prepare_shape(self.entry(dataset, name), self.mesh_cache)
        )

    def remeshed(self, dataset: str, name: str, token: str):
        """The remesh variant (:class:`becos.build.remesh.Remeshed`), or None for ``original``."""
        from becos.build.remesh import load_remeshed

        if token == "original":
            return None
        return self._remeshed.get_or_make(
            (dataset, name, token), lambda: load_remeshed(self.remesh_path(dataset, name, token))
        )

    def remesh_path(self, dataset: str, name: str, token: str) -> Path:
        """The file of a remesh variant: the one the job was given, else its place under the remesh folder."""
        if self._remesh_files is not None:
            return self._remesh_files.path(dataset, name, token)
        return remeshed_file(self.remeshed_root, dataset, name, token)

    def file_digest(self, path: Path) -> str:
        path = Path(path)
        if path not in self._digests:
            self._digests[path] = bytes_digest(path.read_bytes())
        return self._digests[path]

    def source_digest(self, dataset: str, name: str, token: str) -> str:
        """Digest of the file a pair side is built from (remesh variant, or the original mesh)."""
        if token == "original":
            return self.file_digest(self.entry(dataset, name).path)
        return self.file_digest(self.remesh_path(dataset, name, token))

    def edge_digests(self, x, y) -> list[str]:
        """Digests of the edge files the ground truth between entries ``x`` and ``y`` reads (both ways),
        for its input key. Each file is checked once per job for geometric plausibility where its
        target template's mesh is available (:func:`becos.sources.check.edges.edge_plausibility`, whole map and row
        by row), since a file changed after the dataset check is only seen here."""
        from becos.sources.check.edges import edge_plausibility, require_plausible_edge

        annotations = self.network.annotations
        out = []
        nodes = annotations.path(annotations.node_of_key(x.template_key), annotations.node_of_key(y.template_key))
        for a, b in zip(nodes, nodes[1:]):
            for u, v in ((a, b), (b, a)):
                source = annotations.edge_source(u, v)
                if source.kind != "file":
                    out.append("identity")
                    continue
                key = Path(source.path)
                if key not in self._digests:
                    target = self.mesh(*annotations.node_template(v))
                    if target is not None:
                        source_mesh = self.mesh(*annotations.node_template(u))
                        edge = annotations.edge_map(u, v)
                        if not len(edge) or edge.face.max() < target.n_faces:  # else ground_truth names it
                            faces = (
                                source_mesh.faces
                                if source_mesh is not None
                                else annotations.default_faces(*annotations.node_template(u)[::-1])
                            )
                            stats = edge_plausibility(
                                edge,
                                target.vertices,
                                target.faces,
                                faces,
                                None if source_mesh is None else source_mesh.vertices,
                            )
                            require_plausible_edge(key, u, v, stats)
                out.append(self.file_digest(key))
        return out

    @property
    def network(self):
        from becos.build.network import ShapeNetwork

        if self._network is None:
            if self._cache is not None:
                cache = self._cache / "annotations"
            else:
                import tempfile

                self._edge_cache = tempfile.TemporaryDirectory(prefix="becos-edges-")  # removed with the store
                cache = Path(self._edge_cache.name)
            self._network = ShapeNetwork(annotation_source(self._annotation_options, cache), self.mesh)
        return self._network

    def instance(self, dataset: str, name: str, token: str):
        """A :class:`becos.build.pairs.ShapeInstance` (common frame, dataset scale; remeshed unless ``original``),
        the same object while the shape is kept (so its surface area is computed once)."""
        return self._instances.get_or_make((dataset, name, token), lambda: self._make_instance(dataset, name, token))

    def _make_instance(self, dataset: str, name: str, token: str):
        from becos.build.pairs import ShapeInstance

        entry, remeshed = self.entry(dataset, name), self.remeshed(dataset, name, token)
        if remeshed is None:
            prepared = self.prepared(dataset, name)
            mesh, centre = prepared.mesh, prepared.centre
        else:  # the prepared mesh itself is not needed, only its centre
            mesh, centre = remeshed.mesh, self.centre(dataset, name, token)
        variant = int(token[1:]) if token.startswith("v") else -1
        return ShapeInstance(
            entry.dataset,
            entry.name,
            entry.category,
            entry.shape_class,
            mesh,
            entry.scale,
            entry.frame_rotation,
            centre,
            variant,
        )
