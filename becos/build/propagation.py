"""Per-vertex left/right labels on every shape, propagated through the shape network.

A few templates carry per-vertex labels (``config/templates_chirality_all.csv``); any other shape gets
those of the annotated template nearest its class template in the network (ties: the file's first row),
through the network's exact map, taking the label of the largest-weight corner of each image point.
Labels are int8: 1 = left, 0 = right, :data:`NO_LABEL` (-1) where a vertex has no image.
``propagate_labels(network, entry, *, remesh=None) -> (V,) int8``; :func:`labels_for_instance` is the
cached pair-building entry point (None where the data to reach a template is missing). The choice of
template, caching, timings and the API: docs/design/ground-truth.md.
"""

from __future__ import annotations

import hashlib
import logging
import weakref
from collections import OrderedDict
from dataclasses import dataclass

import networkx as nx
import numpy as np

from becos.build.network import Surface
from becos.core.surface_map import SurfaceMap
from becos.errors import BecosError, InputFileError

log = logging.getLogger(__name__)

NO_LABEL = -1
"""Label of a vertex without a counterpart on its annotated template."""

LABEL_NAMES = {NO_LABEL: "none", 0: "right", 1: "left"}
"""What the label values mean. The files and the table only hold 0/1; the meaning is geometric: on
horse0 and centaur0 in the common frame (y up, the animal facing +z, so its own left is +x) label 1
covers the +x side (99.95 % / 99.0 % of vertices agree with the sign of x; checked in the tests), so
1 = anatomical left, 0 = right. The other files follow the same convention as far as the network
maps show (propagated labels keep the +x = 1 rule on TOSCA four-legged shapes)."""

_MAX_CACHED_INSTANCES = 4096


@dataclass(frozen=True)
class AnnotatedTemplate:
    """One row of ``templates_chirality_all.csv``, placed in the network.

    Attributes:
        key: the row's template key (``tosca_horse``, ``faust``, ``dt4d_animal_elephantLN0``).
        annotated: the labelled shape the row names (``horse0``, ``elephantLN0/act2053``).
        node: its network node (``tosca_horse0``, ``dt4d_animal_elephantLN0``).
        dataset: dataset of the node's template.
        name: the node's template shape, where maps land (``horse0``, ``elephantLN0/act1008``); the
            same triangulation as ``annotated``.
        order: 0-based row position in the CSV (the tie-break).
    """

    key: str
    annotated: str
    node: str
    dataset: str
    name: str
    order: int

    @property
    def template_key(self) -> str:  # so it can stand as the target shape of ShapeNetwork.ground_truth
        return self.key


@dataclass(frozen=True)
class _ClassTemplate:
    """A class template as a shape of the network (ShapeLike)."""

    dataset: str
    name: str
    template_key: str


def _validate_labels(labels: np.ndarray, what: str) -> np.ndarray:
    labels = np.asarray(labels)
    if labels.ndim != 1 or not np.issubdtype(labels.dtype, np.integer):
        raise ValueError(f"{what} must be a 1-D integer label array, got {labels.dtype} {labels.shape}")
    return labels


def labels_for_partial(full_labels: np.ndarray, partial_to_full: np.ndarray) -> np.ndarray:
    """Labels of a partial shape: ``full_labels[partial_to_full]``.

    Args:
        full_labels: (V_full,) int8 labels of the full (remeshed) shape, -1 = none.
        partial_to_full: (V_partial,) int full vertex of each partial vertex (``Partial.partial_to_full``).
    Returns:
        (V_partial,) int8.
    """
    full_labels = _validate_labels(full_labels, "full_labels")
    partial_to_full = np.asarray(partial_to_full, dtype=np.int64)
    if len(partial_to_full) and (partial_to_full.min() < 0 or partial_to_full.max() >= len(full_labels)):
        raise ValueError(
            f"partial_to_full indexes vertices {int(partial_to_full.min())}..{int(partial_to_full.max())}"
            f" but the full shape has {len(full_labels)} labels"
        )
    return full_labels[partial_to_full].astype(np.int8)


def labels_through_remesh(labels: np.ndarray, remesh, original_faces: np.ndarray) -> np.ndarray:
    """Carry per-vertex labels of an original triangulation to its remesh.

    Each remeshed vertex takes the label of the largest-weight corner of its point on the original
    surface (``remesh.to_original``); -1 where that point is none or the corner's label is -1.

    Args:
        labels: (V_original,) int labels, -1 = none.
        remesh: :class:`becos.build.remesh.Remeshed` of that shape.
        original_faces: (F, 3) faces of the original mesh as ``remesh.to_original`` indexes them.
    Returns:
        (V_remeshed,) int8.
    """
    labels = _validate_labels(labels, "labels")
    vertex = remesh.to_original.to_vertex_indices(original_faces)
    if vertex.max(initial=-1) >= len(labels):
        raise ValueError(f"the remesh maps onto vertex {int(vertex.max())} but only {len(labels)} labels were given")
    return np.where(vertex >= 0, labels[np.maximum(vertex, 0)], NO_LABEL).astype(np.int8)


def agreement(a: np.ndarray, b: np.ndarray) -> float:
    """Share of vertices labelled (not -1) in ``a`` or ``b`` whose two labels are equal (NaN if none)."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        raise ValueError(f"label arrays differ in shape: {a.shape} vs {b.shape}")
    counted = (a != NO_LABEL) | (b != NO_LABEL)
    if not counted.any():
        return float("nan")
    return float((a[counted] == b[counted]).mean())


def _remesh_fingerprint(remesh) -> str:
    if remesh is None:
        return "original"
    h = hashlib.sha1()
    for array in (remesh.mesh.vertices, remesh.mesh.faces, remesh.to_original.face, remesh.to_original.weights):
        h.update(np.ascontiguousarray(array).tobytes())
    return h.hexdigest()


class LabelPropagator:
    """Propagation with caches, bound to one :class:`~becos.build.network.ShapeNetwork`.

    Use :func:`propagator` to get the one attached to a network; the module-level functions do.
    """

    def __init__(self, network):
        self.network = network
        self.annotations = network.annotations
        self._annotated: list[AnnotatedTemplate] | None = None
        self._file_labels: dict[str, np.ndarray] = {}
        self._class: dict[tuple[str, str], tuple[SurfaceMap, np.ndarray]] = {}
        self._instances: OrderedDict[tuple[str, str, str], np.ndarray | None] = OrderedDict()
        self._warned: set[tuple[str, str]] = set()

    # --- annotated templates ------------------------------------------------------------------
    def annotated_templates(self) -> list[AnnotatedTemplate]:
        """The rows of ``templates_chirality_all.csv`` in file order, placed in the network.

        Raises:
            InputFileError: a row whose template is no network node.
        """
        if self._annotated is None:
            from becos.sources.annotations import CHIRALITY_CSV, dataset_of_key

            path = self.annotations.root / CHIRALITY_CSV
            out = []
            for order, (key, annotated) in enumerate(self.annotations.chirality_table().items()):
                dataset = dataset_of_key(key)
                node = key if dataset.startswith("dt4d") else f"{dataset}_{annotated.replace('/', '_')}"
                if node not in self.annotations.graph:
                    raise InputFileError(
                        path,
                        f"row '{key},{annotated}' names node '{node}', which the network does not contain",
                        "restore the annotation folder's table, or list "
                        "only shapes that are network templates (or poses of a DT4D class node)",
                    )
                try:
                    dataset, name = self.annotations.node_template(node)
                except BecosError:  # a DT4D node the template table does not list: land on the pose itself
                    name = annotated
                out.append(AnnotatedTemplate(key, annotated, node, dataset, name, order))
            self._annotated = out
        return self._annotated

    def nearest_annotated(self, entry) -> tuple[AnnotatedTemplate, int]:
        """The annotated template nearest to ``entry``'s class template node, and the hop count.

        Nearest = fewest network hops; ties -> first row of ``templates_chirality_all.csv``.
        """
        node = self.network.template_node(entry)
        hops = nx.single_source_shortest_path_length(self.annotations.graph, node)
        candidates = [(hops[a.node], a.order, a) for a in self.annotated_templates() if a.node in hops]
        if not candidates:
            raise BecosError(
                f"no annotated template is connected to node '{node}' of {entry.dataset}/{entry.name}. "
                f"Fix: restore the annotation folder's templates_chirality_all.csv"
            )
        n_hops, _, best = min(candidates, key=lambda c: (c[0], c[1]))
        return best, n_hops

    def _annotated_by_key(self, key: str) -> AnnotatedTemplate:
        for a in self.annotated_templates():
            if a.key == key:
                return a
        raise BecosError(
            f"'{key}' is not a row of templates_chirality_all.csv (rows: "
            f"{[a.key for a in self.annotated_templates()]}). Fix: pass one of those keys"
        )

    def file_labels(self, source: AnnotatedTemplate) -> np.ndarray:
        """(V,) int8 labels of an annotated template, as its file holds them."""
        if source.node not in self._file_labels:
            self._file_labels[source.node] = self.annotations.chirality_labels(source.dataset, source.annotated)
        return self._file_labels[source.node]

    # --- class level --------------------------------------------------------------------------
    def class_map(self, entry, source: AnnotatedTemplate) -> tuple[SurfaceMap, np.ndarray]:
        """The map from ``entry``'s class template vertices to points on ``source``'s template, and the
        labels it gives them ((V_template,) int8, -1 = none). Composed once per (class, source)."""
        from becos.sources.annotations import CHIRALITY_DIR

        node = self.network.template_node(entry)
        key = (node, source.node)
        if key not in self._class:
            dataset, name = self.annotations.node_template(node)
            template = _ClassTemplate(dataset, name, entry.template_key)
            surface_map = self.network.ground_truth(template, source)
            faces = self.network.faces_of(Surface(source.dataset, source.name))
            file_labels = self.file_labels(source)
            n_target = int(faces.max()) + 1  # vertices the faces use (the files hold one label per vertex)
            if len(file_labels) < n_target:
                stem = f"{source.dataset}_{source.annotated.replace('/', '_')}"
                raise InputFileError(
                    self.annotations.root / CHIRALITY_DIR / f"{stem}.txt",
                    f"holds {len(file_labels)} labels but the faces of template "
                    f"{source.dataset}/{source.name} use {n_target} vertices",
                    "restore the file from the annotation folder, or use the dataset's original mesh of the template",
                )
            vertex = surface_map.to_vertex_indices(faces)
            labels = np.where(vertex >= 0, file_labels[np.maximum(vertex, 0)], NO_LABEL).astype(np.int8)
            labels.setflags(write=False)
            self._class[key] = (surface_map, labels)
        return self._class[key]

    # --- shapes -------------------------------------------------------------------------------
    def labels(self, entry, remesh=None, annotated: str | None = None) -> np.ndarray:
        """See :func:`propagate_labels`."""
        source = self._annotated_by_key(annotated) if annotated is not None else self.nearest_annotated(entry)[0]
        class_map, class_labels = self.class_map(entry, source)
        node = self.network.template_node(entry)
        shape = Surface(entry.dataset, entry.name)
        template = Surface(*self.annotations.node_template(node), node)
        if (shape.dataset, shape.name) != (template.dataset, template.name):
            # shape -> its class template is an identity hop (one triangulation; vertex counts checked)
            if self.network.hop(shape, template) is not None:
                raise BecosError(
                    f"{shape} and its class template {template} do not share a triangulation; "
                    "label propagation assumes they do (as the network's ground truth does)"
                )
        if remesh is None:
            return class_labels.copy()
        faces = self.network.faces_of(shape)
        if remesh.to_original.face.max(initial=-1) >= len(faces):
            raise ValueError(
                f"the remesh maps onto face {int(remesh.to_original.face.max())} but {shape} has "
                f"{len(faces)} faces: it is the remesh of another shape"
            )
        # remeshed shape -> shape -> class template -> ... -> annotated template; the network composes
        # the template chain once per class pair and caches it, so only the last compose runs here
        composed = self.network.ground_truth(entry, source, x_remesh=remesh)
        vertex = composed.to_vertex_indices(self.network.faces_of(Surface(source.dataset, source.name)))
        return np.where(vertex >= 0, self.file_labels(source)[np.maximum(vertex, 0)], NO_LABEL).astype(np.int8)

    def instance_labels(self, entry, remesh=None) -> np.ndarray | None:
        """See :func:`labels_for_instance`."""
        key = (entry.dataset, entry.name, _remesh_fingerprint(remesh))
        if key in self._instances:
            self._instances.move_to_end(key)
            return self._instances[key]
        try:
            labels = self.labels(entry, remesh)
        except BecosError as exc:
            if isinstance(exc, InputFileError):
                raise
            warn_key = (entry.dataset, entry.template_key)
            if warn_key not in self._warned:
                self._warned.add(warn_key)
                log.warning("no left/right labels for %s shapes (class %s): %s", entry.dataset, entry.template_key, exc)
            labels = None
        if labels is not None:
            labels.setflags(write=False)
        self._instances[key] = labels
        while len(self._instances) > _MAX_CACHED_INSTANCES:
            self._instances.popitem(last=False)
        return labels


_PROPAGATORS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def propagator(network) -> LabelPropagator:
    """The :class:`LabelPropagator` attached to ``network`` (created on first use, dropped with it)."""
    prop = _PROPAGATORS.get(network)
    if prop is None:
        prop = LabelPropagator(network)
        _PROPAGATORS[network] = prop
    return prop


def nearest_annotated(network, entry) -> tuple[AnnotatedTemplate, int]:
    """The annotated template ``entry``'s labels come from, and its distance in network hops."""
    return propagator(network).nearest_annotated(entry)


def propagate_labels(network, entry, *, remesh=None, annotated: str | None = None) -> np.ndarray:
    """Left/right labels of every vertex of a shape (or of its remesh).

    Args:
        network: a :class:`becos.build.network.ShapeNetwork`.
        entry: the shape (:class:`becos.sources.datasets.ShapeEntry` or alike).
        remesh: :class:`becos.build.remesh.Remeshed` of the shape; the labels are then per remeshed vertex.
        annotated: force this row (key) of ``templates_chirality_all.csv`` as the source instead of
            the nearest one (``"tosca_horse"``); for tests and comparisons.

    Returns:
        (V,) int8 (V = the shape's or the remesh's vertex count): :data:`LABEL_NAMES` values; -1 where
        the vertex's image on the annotated template does not exist.

    Raises:
        BecosError: a template on the way (or the annotated one) is not available (dataset absent and
            no default faces / mesh), or the shape is not placed in the network.
        InputFileError: a label or edge file disagrees with its mesh.
    """
    return propagator(network).labels(entry, remesh, annotated)


def labels_for_instance(network, entry, remesh=None) -> np.ndarray | None:
    """Labels of a full pair shape for the pair record (cached; the pair-building entry point).

    Same as :func:`propagate_labels` with the nearest annotated template, cached in-process per
    (dataset, name, remesh content) on the network's :class:`LabelPropagator` (the remesh is
    identified by a SHA-1 of its mesh and ``to_original`` arrays, so a reloaded remesh hits the
    cache). Returns a read-only (V,) int8 array, or None when the labels cannot be computed with the
    data available (e.g. TOSCA humans without FAUST: their annotated template is FAUST tr_reg_000);
    that is logged once per class. Damaged input files still raise.
    """
    return propagator(network).instance_labels(entry, remesh)
