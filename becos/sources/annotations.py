"""The BeCoS annotation folder: shape network, template tables, template-to-template edge files.

A folder laid out like the reference checkout (``config/adjacency_matrix.csv``, ``config/templates_all.csv``,
``precomputed_corr_templates/`` ...). Names: a *key* is the template table's first column
(``tosca_cat``), a *node* a network node (``tosca_cat0``), a *template* a shape name inside its dataset
(``cat0``). Edge files (``A_B_corres.txt``) hold one row per vertex of A: a face index into B's faces and
three barycentric weights (``-1 0 0 0`` = no counterpart), parsed once into a binary cache. The folder's
files: docs/design/ground-truth.md.
"""

from __future__ import annotations

import csv
import glob
import hashlib
import logging
import os
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import networkx as nx
import numpy as np

from becos.atomic import save_npz
from becos.core.surface_map import SurfaceMap
from becos.errors import BecosError, InputFileError
from becos.settings import SPLITS
from becos.sources.registry import available_datasets

log = logging.getLogger(__name__)

DATASETS = ("faust", "scape", "kids", "tosca", "shrec20", "smal", "dt4d_animal", "dt4d_human")
"""Dataset names as the template table and the network use them."""

WHOLE_DATASET_KEYS = ("faust", "scape", "kids")
"""Template-table keys that are a dataset name (one template for the whole dataset)."""

UNDEFINED = "undefined"
NO_TEMPLATE = "-"

ADJACENCY_CSV = Path("config") / "adjacency_matrix.csv"
CHIRALITY_CSV = Path("config") / "templates_chirality_all.csv"
EDGE_DIR = Path("precomputed_corr_templates")
SAME_TRIANGULATION_TXT = EDGE_DIR / "same_triangulation_dt4d_animals.txt"
DEFAULT_FACES_DIR = Path("corres_comp") / "default_faces"
CHIRALITY_DIR = Path("precomputed_chirality_templates")
SMAL_CLASSES = ("big_cats", "cows", "dogs", "hippos", "horses")

FIX_ANNOTATION_FOLDER = (
    "point becos at an unmodified BeCoS annotation folder (e.g. the path printed by "
    "`../shared/unpack`, or a fresh clone of github.com/NafieAmrani/becos-code)"
)
_CACHE_VERSION = 4
_warned_zero_weight: set[str] = set()


@dataclass(frozen=True)
class TemplateRow:
    """One row of ``config/templates_all.csv`` (or ``templates_tosca_demo.csv``).

    Attributes:
        key: dataset-class key (``tosca_cat``, ``faust``, ``dt4d_animal_bearVGG``, ``smal_big_cats``).
        template: its template shape (``cat0``, ``tr_reg_000``, ``bearVGG/Attack2012``); ``-`` where the
            reference lists the class without a template (excluded SHREC'20 shapes).
        split: ``train``/``val``/``test`` (DT4D rows) or ``-``.
        partial_full_template: full template shape of partial-to-full pairs, or ``undefined``.
        partial_full_dataset: its dataset, or ``undefined``.
    """

    key: str
    template: str
    split: str
    partial_full_template: str
    partial_full_dataset: str

    @property
    def has_template(self) -> bool:
        """False for the flagged rows whose template is ``-``."""
        return self.template not in (NO_TEMPLATE, "")

    @property
    def has_partial_full(self) -> bool:
        return UNDEFINED not in (self.partial_full_template, self.partial_full_dataset)


@dataclass(frozen=True)
class EdgeSource:
    """Where the map of the directed network edge ``source -> target`` comes from.

    ``kind`` is ``'file'`` (``path`` = the ``*_corres.txt``) or ``'identity'`` (two DT4D classes that
    share one mesh, listed in ``same_triangulation_dt4d_animals.txt``; ``path`` is None).
    """

    source: str
    target: str
    kind: str
    path: Path | None


def dataset_of_key(key: str) -> str:
    """The dataset of a template-table key or a network node (longest known prefix).

    Raises:
        BecosError: the name starts with no known dataset.
    """
    known = set(DATASETS) | set(available_datasets())  # the registry may add datasets (e.g. the synthetic ones)
    for ds in sorted(known, key=len, reverse=True):
        if key == ds or key.startswith(ds + "_"):
            return ds
    raise BecosError(
        f"'{key}' does not start with a known dataset name {sorted(known)}. "
        f"Fix: use keys/nodes of the BeCoS template table and network"
    )


def file_name_part(dataset: str, template: str) -> str:
    """How the reference names a template inside edge-file names: ``<ds>_<name>``.

    DT4D kinds both become ``dt4d`` and ``/`` becomes ``_`` (``dt4d_pumaRW_Walk0023``); SMAL keeps only
    the file's base name (``smal_muybridge_075_04``).
    """
    ds = "dt4d" if dataset.startswith("dt4d") else dataset
    name = template.rsplit("/", 1)[-1] if dataset == "smal" else template.replace("/", "_")
    return f"{ds}_{name}"


def user_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "becos"


def _writable_dir(path: Path) -> bool:
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return os.access(path, os.W_OK | os.X_OK)


def parse_edge_file(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Parse an edge text file and validate it; no repair of the weights.

    Returns:
        face: (N,) int64 target-face index per source vertex, -1 = no counterpart.
        weights: (N, 3) float64 weights as written in the file.

    Raises:
        InputFileError: empty file, non-numeric text, not 4 columns, non-integer or < -1 face index,
            negative or non-finite weights.
    """
    import pandas as pd

    path = Path(path)
    fix = f"restore the file from the BeCoS annotation folder; {FIX_ANNOTATION_FOLDER}"
    if not path.is_file():
        raise InputFileError(path, "edge file not found", fix)
    try:
        df = pd.read_csv(path, sep=r"\s+", header=None, engine="c", comment=None)
    except pd.errors.EmptyDataError:
        raise InputFileError(path, "the edge file is empty", fix) from None
    except pd.errors.ParserError as exc:
        raise InputFileError(
            path,
            f"rows have different numbers of columns ({str(exc).strip()}); "
            "every row must hold 4 columns: face index and 3 barycentric weights",
            fix,
        ) from None
    if df.shape[1] != 4:
        raise InputFileError(
            path, f"has {df.shape[1]} columns; every row must hold 4: face index and 3 barycentric weights", fix
        )
    for col in range(4):
        if not pd.api.types.is_numeric_dtype(df[col]):
            numeric = pd.to_numeric(df[col], errors="coerce")
            bad = int(np.flatnonzero(numeric.isna().to_numpy())[0])
            raise InputFileError(
                path, f"line {bad + 1} holds non-numeric text {str(df[col].iat[bad])!r} in column {col + 1}", fix
            )
    values = df.to_numpy(dtype=np.float64)
    if np.isnan(values).any():
        bad = int(np.flatnonzero(np.isnan(values).any(axis=1))[0])
        raise InputFileError(path, f"line {bad + 1} has fewer than 4 columns", fix)
    if not np.isfinite(values).all():
        bad = int(np.flatnonzero(~np.isfinite(values).all(axis=1))[0])
        raise InputFileError(path, f"line {bad + 1} holds an infinite value", fix)
    face_f = values[:, 0]
    if (face_f != np.round(face_f)).any():
        bad = int(np.flatnonzero(face_f != np.round(face_f))[0])
        raise InputFileError(path, f"line {bad + 1}: face index {face_f[bad]} is not an integer", fix)
    face = face_f.astype(np.int64)
    if (face < -1).any():
        bad = int(np.flatnonzero(face < -1)[0])
        raise InputFileError(
            path,
            f"line {bad + 1}: face index {face[bad]} is below -1 (-1 is the only "
            "allowed negative value, meaning 'no counterpart')",
            fix,
        )
    weights = values[:, 1:]
    if (weights < 0).any():
        bad = int(np.flatnonzero((weights < 0).any(axis=1))[0])
        raise InputFileError(path, f"line {bad + 1}: negative barycentric weight {weights[bad].tolist()}", fix)
    return face, weights


_REPORT_KEYS = ("rows", "matched", "missing", "zero_weight_rows", "renormalised_rows", "max_face")


def _process_edge(face: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
    """Repair the weights of a parsed edge file.

    Zero-weight matched rows -> face centroid (1/3 each); other matched rows renormalised to sum 1;
    unmatched rows (face -1) zero.

    Returns:
        face (N,) int64, weights (N, 3) float64, and the counts of :data:`_REPORT_KEYS`.
    """
    face = face.astype(np.int64)
    weights = weights.astype(np.float64)
    matched = face >= 0
    sums = weights.sum(axis=1)
    zero = matched & (sums == 0)
    off = matched & ~zero & (np.abs(sums - 1.0) > 1e-4)
    out = np.zeros_like(weights)
    ok = matched & ~zero
    out[ok] = weights[ok] / sums[ok, None]
    out[zero] = 1.0 / 3.0
    report = {
        "rows": int(len(face)),
        "matched": int(matched.sum()),
        "missing": int((~matched).sum()),
        "zero_weight_rows": int(zero.sum()),
        "renormalised_rows": int(off.sum()),
        "max_face": int(face.max(initial=-1)),
    }
    return face, out, report


def _warn_zero_weights(path: Path, report: dict) -> None:
    if report["zero_weight_rows"] and str(path) not in _warned_zero_weight:
        _warned_zero_weight.add(str(path))
        log.warning(
            "%s: %d of %d matched rows have all-zero barycentric weights; using the face centroid "
            "for them (reference quirk: weights truncated to 0/1)",
            path,
            report["zero_weight_rows"],
            report["matched"],
        )


@dataclass(frozen=True)
class _EdgeData:
    """A processed edge file: the map and what was repaired."""

    surface_map: SurfaceMap
    report: dict


class AnnotationSource:
    """Read a BeCoS annotation folder (laid out like the reference checkout).

    Args:
        root: the folder.
        cache_dir: where parsed edge files are cached; default ``<root>/.becos-cache`` when writable,
            else ``$XDG_CACHE_HOME/becos`` (``~/.cache/becos``).
        template_table: file name in ``<root>/config`` (or a path) of the template table.

    Attributes:
        root: the folder.
        graph: the undirected shape network (networkx), validated to be a tree.
        cache_dir: the edge-file cache folder.
    """

    def __init__(
        self, root: str | Path, cache_dir: str | Path | None = None, template_table: str = "templates_all.csv"
    ):
        self.root = Path(root).expanduser()
        if not self.root.is_dir():
            raise InputFileError(self.root, "annotation folder not found", FIX_ANNOTATION_FOLDER)
        table = Path(template_table)
        self.template_table_path = table if table.is_absolute() else self.root / "config" / table
        if cache_dir is None:
            cache_dir = self.root / ".becos-cache"
            if not _writable_dir(cache_dir):
                cache_dir = user_cache_dir()
        self.cache_dir = Path(cache_dir) / "edges"
        self.graph: nx.Graph = read_adjacency(self.root / ADJACENCY_CSV)
        self._rows, self.duplicate_keys = read_template_table(self.template_table_path)
        self._node_rows: dict[str, TemplateRow] | None = None
        self._node_templates: dict[str, tuple[str, str]] = {}
        self._key_nodes: dict[str, str] = {}
        self._identity_pairs: set[frozenset[str]] | None = None
        self._edge_sources: dict[tuple[str, str], EdgeSource] = {}
        self._edges: OrderedDict[Path, _EdgeData] = OrderedDict()  # least recently used first
        self.max_cached_maps = 48
        """How many parsed edge maps stay in memory (least recently used dropped first)."""

    def __repr__(self) -> str:
        return f"AnnotationSource({str(self.root)!r})"

    # --- template table ---------------------------------------------------------------------------
    def template_rows(self) -> dict[str, TemplateRow]:
        """Key -> row; the first row of a key wins (``shrec20_camel_b`` appears twice upstream).

        Rows whose template is ``-`` are kept; :attr:`TemplateRow.has_template` flags them.
        """
        return dict(self._rows)

    def template_row(self, key: str) -> TemplateRow:
        """The row of ``key``. Raises :class:`BecosError` naming the table if absent."""
        try:
            return self._rows[key]
        except KeyError:
            raise BecosError(
                f"{self.template_table_path}: no row for '{key}' (the table has "
                f"{len(self._rows)} keys). Fix: add a row for it or check the dataset's "
                f"template-key rule"
            ) from None

    def node_of_key(self, key: str) -> str:
        """The network node of a template key.

        DT4D keys are nodes themselves (``dt4d_animal_bearVGG``); otherwise
        ``<dataset>_<template with / -> _>`` (``tosca_cat`` -> ``tosca_cat0``, ``faust`` ->
        ``faust_tr_reg_000``, ``smal_big_cats`` -> ``smal_horses_muybridge_075_04``).

        Raises:
            BecosError: no row, a row without template, or a node missing from the network.
        """
        if key not in self._key_nodes:  # asked for every pair
            self._key_nodes[key] = self._node_of_key(key)
        return self._key_nodes[key]

    def _node_of_key(self, key: str) -> str:
        row = self.template_row(key)
        if not row.has_template:
            raise BecosError(
                f"{self.template_table_path}: '{key}' has no template ('{row.template}'), so its "
                f"shapes cannot be placed in the network. Fix: exclude these shapes (the reference "
                f"excludes them) or give the row a template"
            )
        dataset = dataset_of_key(key)
        node = key if dataset.startswith("dt4d") else f"{dataset}_{row.template.replace('/', '_')}"
        if node not in self.graph:
            raise BecosError(
                f"{self.template_table_path}: template '{row.template}' of '{key}' is node '{node}', "
                f"which {self.root / ADJACENCY_CSV} does not contain. Fix: use a template that is a "
                f"network node, or add the node and its edge files"
            )
        return node

    def _rows_by_node(self) -> dict[str, TemplateRow]:
        if self._node_rows is None:
            out: dict[str, TemplateRow] = {}
            for key, row in self._rows.items():
                if not row.has_template:
                    continue
                try:
                    node = self.node_of_key(key)
                except BecosError:
                    continue
                out.setdefault(node, row)
            self._node_rows = out
        return self._node_rows

    def node_template(self, node: str) -> tuple[str, str]:
        """Node -> (dataset, template shape name).

        ``tosca_cat0`` -> (``tosca``, ``cat0``); ``dt4d_animal_bearVGG`` -> (``dt4d_animal``,
        ``bearVGG/Attack2012``); ``smal_horses_muybridge_075_04`` -> (``smal``, ``horses/muybridge_075_04``).
        """
        if node not in self._node_templates:  # asked for every hop of every pair
            self._node_templates[node] = self._node_template(node)
        return self._node_templates[node]

    def _node_template(self, node: str) -> tuple[str, str]:
        if node not in self.graph:
            raise BecosError(
                f"{self.root / ADJACENCY_CSV}: no network node '{node}'. "
                f"Fix: use one of its {self.graph.number_of_nodes()} node names"
            )
        dataset = dataset_of_key(node)
        row = self._rows_by_node().get(node)
        if row is not None:
            return dataset, row.template
        if dataset.startswith("dt4d") or dataset == "smal":
            raise BecosError(
                f"{self.template_table_path}: no row has network node '{node}' as template, so "
                f"its shape name (with its '/' sub-folder) is unknown. Fix: add its row to the table"
            )
        return dataset, node[len(dataset) + 1 :]

    # --- network ------------------------------------------------------------------------------------
    def path(self, node_a: str, node_b: str) -> list[str]:
        """The unique tree path of nodes from ``node_a`` to ``node_b`` (both included)."""
        for node in (node_a, node_b):
            if node not in self.graph:
                raise BecosError(
                    f"{self.root / ADJACENCY_CSV}: no network node '{node}' (path {node_a} -> "
                    f"{node_b}). Fix: check the template key rule / template table row"
                )
        try:
            return nx.shortest_path(self.graph, node_a, node_b)
        except nx.NetworkXNoPath:
            raise BecosError(
                f"{self.root / ADJACENCY_CSV}: no path between '{node_a}' and '{node_b}'. Fix: {FIX_ANNOTATION_FOLDER}"
            ) from None

    def _identity(self) -> set[frozenset[str]]:
        if self._identity_pairs is None:
            path = self.root / SAME_TRIANGULATION_TXT
            pairs: set[frozenset[str]] = set()
            if path.is_file():
                dt4d_nodes = {n.split("_", 2)[2]: n for n in self.graph if n.startswith("dt4d_")}
                for i, line in enumerate(path.read_text().splitlines()):
                    line = line.strip()
                    if not line:
                        continue
                    parts = [p.strip() for p in line.split(",")]
                    if len(parts) != 2 or not all(p.startswith("dt4d_") for p in parts):
                        raise InputFileError(
                            path,
                            f"line {i + 1} {line!r} is not 'dt4d_<classA>,dt4d_<classB>'",
                            f"restore the file; {FIX_ANNOTATION_FOLDER}",
                        )
                    nodes = []
                    for p in parts:
                        cls = p[len("dt4d_") :]
                        if cls not in dt4d_nodes:
                            raise InputFileError(
                                path,
                                f"line {i + 1}: class '{cls}' is no DT4D network node",
                                f"restore the file; {FIX_ANNOTATION_FOLDER}",
                            )
                        nodes.append(dt4d_nodes[cls])
                    pairs.add(frozenset(nodes))
            self._identity_pairs = pairs
        return self._identity_pairs

    def edge_source(self, a: str, b: str) -> EdgeSource:
        """Where the map of the directed edge ``a -> b`` comes from.

        Identity if both are DT4D classes listed in ``same_triangulation_dt4d_animals.txt``; otherwise
        the single file matching ``<dsA>_<nameA>*_<dsB>_<nameB>*_corres.txt`` (reference lookup; a
        ``*_corres_old.txt`` twin never matches).

        Raises:
            BecosError: not adjacent; InputFileError: no file, or several files match.
        """
        key = (a, b)
        if key in self._edge_sources:
            return self._edge_sources[key]
        if not self.graph.has_edge(a, b):
            for node in (a, b):
                if node not in self.graph:
                    raise BecosError(f"{self.root / ADJACENCY_CSV}: no network node '{node}'. Fix: use node names")
            raise BecosError(
                f"{self.root / ADJACENCY_CSV}: '{a}' and '{b}' are not adjacent, so no edge file "
                f"links them. Fix: go through AnnotationSource.path({a!r}, {b!r})"
            )
        if a.startswith("dt4d_") and b.startswith("dt4d_") and frozenset((a, b)) in self._identity():
            source = EdgeSource(a, b, "identity", None)
        else:
            folder = self.root / EDGE_DIR
            pa = file_name_part(*self.node_template(a))
            pb = file_name_part(*self.node_template(b))
            pattern = f"{glob.escape(pa)}*_{glob.escape(pb)}*_corres.txt"
            hits = sorted(Path(p) for p in glob.glob(str(folder / pattern)))
            if not hits:
                raise InputFileError(
                    folder / f"{pa}*_{pb}*_corres.txt",
                    f"no edge file for network edge {a} -> {b}",
                    f"restore the annotation folder's precomputed_corr_templates; {FIX_ANNOTATION_FOLDER}",
                )
            if len(hits) > 1:
                raise InputFileError(
                    folder / f"{pa}*_{pb}*_corres.txt",
                    f"edge {a} -> {b} is ambiguous: {[h.name for h in hits]} all match",
                    "remove or rename the extra files (keep the one shipped with BeCoS)",
                )
            source = EdgeSource(a, b, "file", hits[0])
        self._edge_sources[key] = source
        return source

    def edge_sources(self) -> list[EdgeSource]:
        """Every directed edge of the network, sorted by (source, target)."""
        pairs = sorted({(u, v) for e in self.graph.edges for (u, v) in (e, e[::-1])})
        return [self.edge_source(u, v) for u, v in pairs]

    # --- edge maps ----------------------------------------------------------------------------------
    def _cache_file(self, path: Path) -> Path:
        stat = path.stat()
        text = f"{_CACHE_VERSION}|{path.resolve()}|{stat.st_size}|{stat.st_mtime_ns}|{stat.st_ctime_ns}|{stat.st_ino}"
        digest = hashlib.sha1(text.encode()).hexdigest()[:20]
        return self.cache_dir / f"{path.stem}-{digest}.npz"

    def _load_edge(self, path: Path) -> _EdgeData:
        if path in self._edges:
            self._edges.move_to_end(path)
            return self._edges[path]
        if not path.is_file():
            raise InputFileError(path, "edge file not found", f"restore it; {FIX_ANNOTATION_FOLDER}")
        cached = self._cache_file(path)
        loaded = None
        if cached.is_file():
            try:
                with np.load(cached) as data:
                    counts = data["report"]
                    loaded = (
                        data["face"].astype(np.int64),
                        data["weights"].astype(np.float64),
                        dict(zip(_REPORT_KEYS, counts.tolist())),
                    )
            except Exception:  # a damaged cache entry is re-parsed
                loaded = None
        if loaded is None:
            loaded = _process_edge(*parse_edge_file(path))
            face, weights, report = loaded
            try:
                # weights stay float64: a cached load must equal a fresh parse
                save_npz(
                    cached,
                    face=face.astype(np.int32),
                    weights=weights,
                    report=np.array([report[k] for k in _REPORT_KEYS], dtype=np.int64),
                )
            except OSError as exc:
                log.warning("could not write the edge cache %s (%s); parsing each time", cached, exc)
        face, weights, report = loaded
        _warn_zero_weights(path, report)
        data = _EdgeData(SurfaceMap(face, weights), {"path": str(path), **report})
        self._edges[path] = data
        while len(self._edges) > self.max_cached_maps:
            self._edges.popitem(last=False)
        return data

    def edge_map(self, a: str, b: str) -> SurfaceMap | None:
        """The map of edge ``a -> b`` (vertices of a's template -> points on b's template), None for identity.

        Weights: all-zero matched rows become the face centroid (1/3 each; counted in
        :meth:`edge_report`, one logged warning per file); other matched rows are renormalised to sum 1.
        """
        source = self.edge_source(a, b)
        if source.kind == "identity":
            return None
        return self._load_edge(source.path).surface_map

    def edge_report(self, a: str, b: str) -> dict:
        """Row counts of edge ``a -> b``: ``rows``, ``matched``, ``missing`` (-1 rows), ``zero_weight_rows``,
        ``renormalised_rows`` (sum off 1 by > 1e-4), ``max_face``, ``path``, ``kind``."""
        source = self.edge_source(a, b)
        if source.kind == "identity":
            return {
                "kind": "identity",
                "path": None,
                "rows": None,
                "matched": None,
                "missing": 0,
                "zero_weight_rows": 0,
                "renormalised_rows": 0,
                "max_face": None,
            }
        return {"kind": "file", **self._load_edge(source.path).report}

    def check_edge(self, a: str, b: str, n_source_vertices: int, n_target_faces: int) -> None:
        """Raise :class:`InputFileError` (naming the file) unless edge ``a -> b`` has one row per source
        vertex and only face indices below ``n_target_faces``. Identity edges pass."""
        source = self.edge_source(a, b)
        if source.kind == "identity":
            return
        edge = self._load_edge(source.path)
        rows, max_face = edge.report["rows"], edge.report["max_face"]
        if rows != n_source_vertices:
            raise InputFileError(
                source.path,
                f"has {rows} rows but template {a} has {n_source_vertices} vertices",
                "the edge file and the template mesh come from different versions: restore the "
                "annotation folder's file or use the dataset's original mesh",
            )
        if max_face >= n_target_faces:
            raise InputFileError(
                source.path,
                f"face index {max_face} is out of range for template {b} ({n_target_faces} faces)",
                "restore the annotation folder's original file, "
                "or use the dataset's original (unprocessed) mesh of the target template",
            )

    # --- faces and labels ---------------------------------------------------------------------------
    def default_faces(self, template_name: str, dataset: str | None = None) -> np.ndarray | None:
        """(F, 3) int64 faces of a template from ``corres_comp/default_faces``, None if absent.

        The file is ``<name with / -> _>.npy``; SMAL templates use the base name
        (``horses/muybridge_075_04`` -> ``muybridge_075_04.npy``). Without ``dataset``, a name whose
        folder is a SMAL class is taken as SMAL.
        """
        folder = self.root / DEFAULT_FACES_DIR
        first = template_name.split("/", 1)[0] if "/" in template_name else None
        if dataset == "smal" or (dataset is None and first in SMAL_CLASSES):
            stem = template_name.rsplit("/", 1)[-1]
        else:
            stem = template_name.replace("/", "_")
        path = folder / f"{stem}.npy"
        if not path.is_file():
            return None
        try:
            faces = np.load(path, allow_pickle=False)
        except Exception as exc:
            raise InputFileError(
                path, f"cannot be read as a numpy array ({exc})", f"restore it; {FIX_ANNOTATION_FOLDER}"
            ) from exc
        if faces.ndim != 2 or faces.shape[1] != 3 or not np.issubdtype(faces.dtype, np.integer) or faces.min() < 0:
            raise InputFileError(
                path,
                f"is not an (F, 3) array of non-negative integers (shape {faces.shape}, dtype {faces.dtype})",
                f"restore it; {FIX_ANNOTATION_FOLDER}",
            )
        return faces.astype(np.int64)

    def chirality_table(self) -> dict[str, str]:
        """``templates_chirality_all.csv``: template key -> annotated template shape (first row wins)."""
        path = self.root / CHIRALITY_CSV
        rows = _read_csv_rows(path, ("dataset", "annotated_template"))
        out: dict[str, str] = {}
        for row in rows:
            out.setdefault(row["dataset"], row["annotated_template"])
        return out

    def chirality_labels(self, dataset: str, template: str) -> np.ndarray:
        """(V,) int8 left/right labels (0/1) of a template's vertices, from
        ``precomputed_chirality_templates/<dataset>_<template with / -> _>.txt``."""
        path = self.root / CHIRALITY_DIR / f"{dataset}_{template.replace('/', '_')}.txt"
        if not path.is_file():
            raise InputFileError(
                path,
                f"no left/right labels for {dataset}/{template}",
                f"use a template listed in {CHIRALITY_CSV}, or restore the file; {FIX_ANNOTATION_FOLDER}",
            )
        import pandas as pd

        try:
            values = pd.read_csv(path, sep=r"\s+", header=None, engine="c").to_numpy()
        except Exception as exc:
            raise InputFileError(
                path, f"cannot be parsed ({type(exc).__name__}: {exc})", f"restore it; {FIX_ANNOTATION_FOLDER}"
            ) from exc
        if values.ndim != 2 or values.shape[1] != 1 or not np.isin(values, (0, 1)).all():
            raise InputFileError(
                path,
                "must hold one 0 or 1 per line (one label per template vertex)",
                f"restore it; {FIX_ANNOTATION_FOLDER}",
            )
        return values[:, 0].astype(np.int8)


# --- readers ------------------------------------------------------------------------------------------
def _read_csv_rows(path: Path, columns: tuple[str, ...]) -> list[dict[str, str]]:
    if not path.is_file():
        raise InputFileError(path, "file not found", FIX_ANNOTATION_FOLDER)
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        header = [h.strip() for h in (reader.fieldnames or [])]
        missing = [c for c in columns if c not in header]
        if missing:
            raise InputFileError(
                path, f"lacks columns {missing} (header: {header})", f"the header must be {','.join(columns)}"
            )
        rows = []
        for i, raw in enumerate(reader):
            row = {k.strip(): (v or "").strip() for k, v in raw.items() if k is not None}
            if any(not row.get(c) for c in columns):
                raise InputFileError(
                    path,
                    f"line {i + 2} has an empty field: {raw}",
                    f"fill every column ({','.join(columns)}); use 'undefined' or '-' for none",
                )
            rows.append(row)
    return rows


def read_template_table(path: str | Path) -> tuple[dict[str, TemplateRow], list[str]]:
    """Rows of a template table, first row per key, and the keys that appeared more than once."""
    path = Path(path)
    fields = ("dataset", "template", "split", "partial_full_template", "partial_full_dataset")
    rows: dict[str, TemplateRow] = {}
    duplicates: list[str] = []
    for raw in _read_csv_rows(path, fields):
        row = TemplateRow(
            raw["dataset"], raw["template"], raw["split"], raw["partial_full_template"], raw["partial_full_dataset"]
        )
        if row.split not in (*SPLITS, NO_TEMPLATE):
            raise InputFileError(path, f"row '{row.key}' has split '{row.split}'", "use train, val, test or -")
        if row.key in rows:
            duplicates.append(row.key)
            continue
        rows[row.key] = row
    if duplicates:
        log.info("%s: keys listed more than once (first row used): %s", path, sorted(set(duplicates)))
    return rows, duplicates


def read_adjacency(path: str | Path) -> nx.Graph:
    """The shape network from a 0/1 adjacency CSV (header row and first column = node names).

    Raises:
        InputFileError: missing file, names differing between header and rows, values other than
            0/1, asymmetric matrix, self-loops, or a graph that is not a tree (disconnected / cycle).
    """
    import pandas as pd

    path = Path(path)
    fix = f"restore config/adjacency_matrix.csv; {FIX_ANNOTATION_FOLDER}"
    if not path.is_file():
        raise InputFileError(path, "adjacency matrix not found", FIX_ANNOTATION_FOLDER)
    try:
        df = pd.read_csv(path, index_col=0)
    except Exception as exc:
        raise InputFileError(path, f"cannot be parsed as CSV ({type(exc).__name__}: {exc})", fix) from exc
    rows = [str(r).strip() for r in df.index]
    cols = [str(c).strip() for c in df.columns]
    if rows != cols:
        raise InputFileError(
            path,
            f"row names and column names differ (first difference: "
            f"{next(((r, c) for r, c in zip(rows, cols) if r != c), (len(rows), len(cols)))})",
            "the first column and the header must list the same nodes in the same order",
        )
    if len(set(rows)) != len(rows):
        raise InputFileError(path, "node names repeat", fix)
    values = df.apply(pd.to_numeric, errors="coerce").to_numpy(dtype=np.float64)
    if np.isnan(values).any() or not np.isin(values, (0.0, 1.0)).all():
        i, j = np.argwhere(np.isnan(values) | ~np.isin(values, (0.0, 1.0)))[0]
        raise InputFileError(path, f"entry ({rows[i]}, {cols[j]}) is {df.iat[i, j]!r}; only 0 and 1 are allowed", fix)
    if not (values == values.T).all():
        i, j = np.argwhere(values != values.T)[0]
        raise InputFileError(
            path,
            f"the matrix is not symmetric: ({rows[i]}, {cols[j]}) = {values[i, j]:g} but "
            f"({cols[j]}, {rows[i]}) = {values[j, i]:g}",
            "make the edge two-way (set both entries)",
        )
    if np.diag(values).any():
        i = int(np.flatnonzero(np.diag(values))[0])
        raise InputFileError(path, f"node {rows[i]} is linked to itself", "set the diagonal to 0")
    graph = nx.Graph()
    graph.add_nodes_from(rows)
    iu, ju = np.nonzero(np.triu(values, 1))
    graph.add_edges_from((rows[i], rows[j]) for i, j in zip(iu, ju))
    if not nx.is_connected(graph):
        parts = sorted(nx.connected_components(graph), key=len)
        raise InputFileError(
            path,
            f"the network is not connected ({len(parts)} parts; smallest: {sorted(parts[0])[:5]})",
            "add the missing edges so every template is reachable",
        )
    if graph.number_of_edges() != graph.number_of_nodes() - 1:
        cycle = nx.find_cycle(graph)
        raise InputFileError(
            path,
            f"the network is not a tree ({graph.number_of_edges()} edges over "
            f"{graph.number_of_nodes()} nodes; cycle {[u for u, _ in cycle]})",
            "remove edges until paths between templates are unique",
        )
    return graph
