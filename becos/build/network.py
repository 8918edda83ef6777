"""Paths through the shape network and dense ground truth between any two shapes of a category.

A path X -> X's template -> network templates ... -> Y's template -> Y (optionally remeshed X and Y at
the ends) is a chain of :class:`~becos.core.surface_map.SurfaceMap` hops: identity between a shape and its
template (one triangulation), the annotation folder's edge files between templates, and the remesh maps.
:meth:`ShapeNetwork.ground_truth` composes it backwards from the target, so an intermediate template
needs only its faces; template-to-template parts are cached per pair of classes. The hops, exact
identity ends and caching: docs/design/ground-truth.md.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from becos.core.geometry import SurfaceLocator
from becos.core.mesh import TriMesh, surface_faces, vertex_set_keys
from becos.core.surface_map import NONE, SurfaceMap, compose, compose_path
from becos.errors import BecosError, InputFileError


def identity_map(mesh: TriMesh, usable_rows: np.ndarray | None = None) -> SurfaceMap:
    """Vertex i -> vertex i of ``mesh`` (weight 1 at its corner of an incident face).

    Only usable faces (:func:`becos.core.mesh.surface_faces`; ``usable_rows``, their rows, when already
    known) carry the points; a vertex in no usable face (unreferenced, or used only by degenerate
    faces) gets no counterpart (face -1). On a clean mesh this equals :meth:`SurfaceMap.identity`.
    """
    rows = np.flatnonzero(surface_faces(mesh)) if usable_rows is None else usable_rows
    faces = mesh.faces[rows]
    incident = np.full(mesh.n_vertices, NONE, dtype=np.int64)
    corner = np.zeros(mesh.n_vertices, dtype=np.int64)
    incident[faces.ravel()] = np.repeat(rows, 3)  # the last write wins, as SurfaceMap.identity
    corner[faces.ravel()] = np.tile(np.arange(3), len(faces))
    weights = np.zeros((mesh.n_vertices, 3))
    has = np.flatnonzero(incident >= 0)
    weights[has, corner[has]] = 1.0
    return SurfaceMap(incident, weights)


class FacesByVertexSet:
    """The usable faces of ``mesh`` (:func:`becos.core.mesh.surface_faces`), found by their vertex set.

    Built once per target mesh and shared by every :func:`transplant` onto it (sorting the keys of a
    100k-face mesh costs tens of ms; a pair's lookups are one ``searchsorted``)."""

    def __init__(self, mesh: TriMesh):
        self.mesh = mesh
        self.rows = np.flatnonzero(surface_faces(mesh))  # (U,) usable rows of mesh.faces
        keys = vertex_set_keys(mesh.faces[self.rows], mesh.n_vertices)
        self._order = np.argsort(keys, kind="stable")
        self._sorted_keys = keys[self._order]
        self._identity: SurfaceMap | None = None

    def find(self, triples: np.ndarray) -> np.ndarray:
        """(K,) int64 row of ``mesh.faces`` with the vertex set of each of ``triples`` ((K, 3) vertex
        ids, any order), -1 where no usable face has it."""
        keys = vertex_set_keys(triples, self.mesh.n_vertices)
        out = np.full(len(keys), NONE, dtype=np.int64)
        if len(self._sorted_keys):
            pos = np.minimum(np.searchsorted(self._sorted_keys, keys), len(self._sorted_keys) - 1)
            found = self._sorted_keys[pos] == keys
            out[found] = self.rows[self._order[pos[found]]]
        return out

    def identity(self) -> SurfaceMap:
        """:func:`identity_map` of ``mesh`` (computed on first use; read it, do not modify it)."""
        if self._identity is None:
            self._identity = identity_map(self.mesh, self.rows)
        return self._identity


def transplant(
    m: SurfaceMap, source_faces: np.ndarray, target: TriMesh | FacesByVertexSet, locator: SurfaceLocator | None = None
) -> SurfaceMap:
    """Carry ``m`` (points on a surface with faces ``source_faces``) to ``target``, a mesh with the
    same vertex order (another pose of the class, or the class template), by vertex identity.
    Pass the target's :class:`FacesByVertexSet` to reuse it across calls.

    A point with weights w in source face (a, b, c) lands in the usable target face with the vertex
    set {a, b, c}, with w permuted into that face's column order: exactly the same vertices and
    weights. Points whose vertex set is no usable target face (the triangulations differ there) are
    composed with :func:`identity_map` (closest-point projection, :func:`becos.core.surface_map.compose`).
    Distances are inherited.

    Raises:
        BecosError: ``source_faces`` index vertices the target does not have.
    """
    index = target if isinstance(target, FacesByVertexSet) else FacesByVertexSet(target)
    target = index.mesh
    source_faces = np.asarray(source_faces, dtype=np.int64)
    if len(source_faces) and int(source_faces.max()) >= target.n_vertices:
        raise BecosError(
            f"a ground-truth path carries points by vertex identity onto a mesh with "
            f"{target.n_vertices} vertices from a surface whose faces use vertex "
            f"{int(source_faces.max())}. Fix: check that the shape and its template come from the "
            f"same dataset release (same vertex count and order)"
        )
    face = np.full(len(m), NONE, dtype=np.int64)
    weights = np.zeros((len(m), 3))
    distance = np.full(len(m), np.nan)
    alive = np.flatnonzero(m.matched)
    src = source_faces[m.face[alive]]  # (M, 3) vertex ids
    rows = index.find(src)
    found = rows >= 0
    hit = alive[found]
    target_face = rows[found]
    # (H, 3 source columns, 3 target columns): where each source corner sits in the target row
    same = (src[found][:, :, None] == target.faces[target_face][:, None, :]).astype(np.float64)
    face[hit] = target_face
    weights[hit] = np.einsum("hk,hkj->hj", m.weights[hit], same)
    distance[hit] = m.distance[hit]
    rest = alive[~found]
    if len(rest):
        sub = SurfaceMap(m.face[rest], m.weights[rest], m.distance[rest])
        projected = compose(sub, source_faces, index.identity(), target, locator)
        face[rest], weights[rest], distance[rest] = projected.face, projected.weights, projected.distance
    return SurfaceMap(face, weights, distance)


class ShapeLike(Protocol):
    """What the network needs to know of a shape (``becos.sources.datasets.ShapeEntry`` satisfies it)."""

    dataset: str
    name: str
    template_key: str


MeshLookup = Callable[[str, str], "TriMesh | None"]
"""``meshes(dataset, name)`` -> the shape's original mesh, or None when the dataset is absent."""


@dataclass(frozen=True)
class Surface:
    """One surface along a path: a dataset shape (or template) identified by dataset and name."""

    dataset: str
    name: str
    node: str | None = None  # the network node, for templates

    def __str__(self) -> str:
        return f"{self.dataset}/{self.name}"


class ShapeNetwork:
    """Ground-truth maps between shapes, through the templates of an annotation folder.

    Args:
        annotations: a :class:`becos.sources.annotations.AnnotationSource`.
        meshes: lookup of original meshes by (dataset, name); None for a shape that is not available.
    """

    def __init__(self, annotations, meshes: MeshLookup):
        self.annotations = annotations
        self._meshes = meshes
        self._faces_cache: dict[tuple[str, str], np.ndarray] = {}
        self._chains: dict[tuple[str, ...], SurfaceMap] = {}
        self._per_mesh: OrderedDict[tuple, tuple] = OrderedDict()
        self._geometries: OrderedDict[tuple, tuple] = OrderedDict()
        self._tails: OrderedDict[tuple, tuple] = OrderedDict()
        self._vertex_counts: dict[tuple[str, str], int | None] = {}

    # --- paths ----------------------------------------------------------------------------------
    def template_node(self, shape: ShapeLike) -> str:
        return self.annotations.node_of_key(shape.template_key)

    def surface_path(self, x: ShapeLike, y: ShapeLike) -> list[Surface]:
        """Surfaces from X to Y: X, X's template (if different), network templates, Y's template, Y."""
        nodes = self.annotations.path(self.template_node(x), self.template_node(y))
        surfaces = [Surface(x.dataset, x.name)]
        for node in nodes:
            dataset, name = self.annotations.node_template(node)
            surface = Surface(dataset, name, node)
            if (surface.dataset, surface.name) != (surfaces[-1].dataset, surfaces[-1].name):
                surfaces.append(surface)
            else:
                surfaces[-1] = surface  # X is its own template: keep the node
        if (y.dataset, y.name) != (surfaces[-1].dataset, surfaces[-1].name):
            surfaces.append(Surface(y.dataset, y.name))
        return surfaces

    # --- hops -----------------------------------------------------------------------------------
    def faces_of(self, surface: Surface) -> np.ndarray:
        """Faces of a surface as its original file has them (dataset mesh, else default faces)."""
        key = (surface.dataset, surface.name)
        if key not in self._faces_cache:
            mesh = self._meshes(surface.dataset, surface.name)
            if mesh is not None:
                faces = mesh.faces
            else:
                faces = self.annotations.default_faces(surface.name)
                if faces is None:
                    raise BecosError(
                        f"the faces of template {surface} are needed on a ground-truth path, but dataset "
                        f"'{surface.dataset}' is not available and the annotation folder has no default faces "
                        f"for '{surface.name}'. Fix: enable/download dataset '{surface.dataset}'"
                    )
            self._faces_cache[key] = np.asarray(faces, dtype=np.int64)
        return self._faces_cache[key]

    def _n_vertices(self, surface: Surface) -> int | None:
        key = (surface.dataset, surface.name)
        if key not in self._vertex_counts:  # asked on every hop of every pair; the file does not change
            mesh = self._meshes(surface.dataset, surface.name)
            self._vertex_counts[key] = None if mesh is None else mesh.n_vertices
        return self._vertex_counts[key]

    def _is_identity_hop(self, a: Surface, b: Surface) -> bool:
        """A shape and its own template are one triangulation (the template table pairs them by class,
        or by dataset where one template mesh underlies the whole dataset); vertex counts are checked."""
        if a.node is not None and b.node is not None:
            return False  # template -> template: decided by the annotation folder
        if a.dataset != b.dataset:
            raise BecosError(
                f"{a} and its template {b} belong to different datasets, so they need an edge file. "
                f"Fix: point the template table row of {a} at a template of its own dataset"
            )
        na, nb = self._n_vertices(a), self._n_vertices(b)
        if na is not None and nb is not None and na != nb:
            raise BecosError(
                f"{a} and its template {b} should share one triangulation (vertex i = vertex i) but "
                f"have {na} and {nb} vertices. Fix: check that both files come from the same "
                f"dataset release and were not re-processed"
            )
        return True

    def hop(self, a: Surface, b: Surface) -> SurfaceMap | None:
        """The map from the vertices of ``a`` to points on ``b``; None for an identity hop."""
        if self._is_identity_hop(a, b):
            return None
        edge = self.annotations.edge_map(a.node, b.node)
        if edge is None:
            return None
        n_source = self._n_vertices(a)
        n_target_faces = len(self.faces_of(b))
        source = self.annotations.edge_source(a.node, b.node)
        if n_source is not None and len(edge) != n_source:
            raise InputFileError(
                source.path,
                f"has {len(edge)} rows but template {a} has {n_source} vertices",
                "the edge file and the mesh come from different versions; restore the annotation "
                "folder's file or the dataset's original mesh",
            )
        if len(edge) and edge.face.max() >= n_target_faces:
            raise InputFileError(
                source.path,
                f"face index {int(edge.face.max())} is out of range for template {b} ({n_target_faces} faces)",
                "restore the annotation folder's original file",
            )
        return edge

    # --- ground truth ---------------------------------------------------------------------------
    def _kept(self, make: Callable[[TriMesh], object], mesh: TriMesh):
        """``make(mesh)``, kept for the last few meshes used as targets."""
        key = (make, id(mesh))
        if key in self._per_mesh:
            self._per_mesh.move_to_end(key)
            return self._per_mesh[key][1]
        value = make(mesh)
        self._per_mesh[key] = (mesh, value)  # holding the mesh keeps its id from being reused
        while len(self._per_mesh) > self.MESHES_KEPT:
            self._per_mesh.popitem(last=False)
        return value

    MESHES_KEPT = 24
    """Target meshes whose locator (and face index) are kept; a caller that knows it is done with a
    mesh drops them at once (:meth:`forget`)."""

    def forget(self, mesh: TriMesh) -> None:
        """Drop what was built for ``mesh`` as a target (locator, face index, geometry copies)."""
        for key in [k for k in self._per_mesh if k[1] == id(mesh)]:
            del self._per_mesh[key]
        for key in [k for k in self._geometries if k[1] == id(mesh)]:
            del self._geometries[key]
        for key in [k for k in self._tails if k[0] == id(mesh)]:
            del self._tails[key]

    def locator(self, mesh: TriMesh) -> SurfaceLocator:
        """A closest-point structure of ``mesh``, kept for the last few meshes used as targets."""
        return self._kept(SurfaceLocator, mesh)

    def template_chain(self, templates: list[Surface]) -> SurfaceMap | None:
        """Template ``templates[0]`` vertices -> points on ``templates[-1]``, composed along the network
        path and cached: every pair between the same two classes shares it. None when the last
        template's mesh is not available (then the caller composes onto its own target)."""
        key = tuple(t.node for t in templates)
        if key not in self._chains:
            last = templates[-1]
            mesh = self._meshes(last.dataset, last.name)
            if mesh is None:
                return None
            hops = [self.hop(a, b) for a, b in zip(templates, templates[1:])]
            self._chains[key] = self._compose_onto(hops, templates[1:], mesh)
        return self._chains[key]

    def _geometry_with_faces(self, target: TriMesh, faces: np.ndarray) -> TriMesh:
        """``target``'s vertices with ``faces`` (a surface of the same vertex order), kept for reuse."""
        if faces is target.faces or (faces.shape == target.faces.shape and np.array_equal(faces, target.faces)):
            return target
        key = ("geometry", id(target), id(faces))
        if key not in self._geometries:
            self._geometries[key] = (target, faces, TriMesh(target.vertices, faces))  # refs keep the ids
            while len(self._geometries) > 8:
                self._geometries.popitem(last=False)
        return self._geometries[key][2]

    TAILS_KEPT = 16
    """Composed path tails (:meth:`_tail`) kept; those onto a mesh are dropped with it (:meth:`forget`)."""

    def _tail(
        self,
        hops: list[SurfaceMap | None],
        landing: list[Surface | None],
        middle: list[np.ndarray],
        target: TriMesh,
        locator: SurfaceLocator,
    ) -> SurfaceMap:
        """:func:`compose_path` of ``hops`` (all but a path's first hop) onto ``target``, kept.

        In a chunk the paths from every shape X of one class to one remeshed Y differ only in their
        first hop (remeshed X -> X); the rest -- X's template -> network templates -> Y's template ->
        Y -> remeshed Y, a map from the vertices of X's template (= X's vertex order) to points on
        the remeshed Y -- is the same, so it is composed once and the pair composes only its first
        hop onto it (:func:`becos.core.surface_map.compose` of the same arrays: the same bytes). Keyed by
        the target mesh, the mapped hop objects (the cached template chain, Y's ``from_original``)
        and the surfaces they land on (identity hops are skipped by the composition, so X's template
        itself and the other poses of its class share one tail); the entry holds the hops, so their
        ids are not reused while it is kept.
        """
        key = (id(target), tuple((id(h), s) for h, s in zip(hops, landing) if h is not None))
        if key in self._tails:
            self._tails.move_to_end(key)
            return self._tails[key][2]
        tail = compose_path(hops, middle, target, locator)
        self._tails[key] = (target, hops, tail)
        while len(self._tails) > self.TAILS_KEPT:
            self._tails.popitem(last=False)
        return tail

    def _compose_onto(
        self, hops: list[SurfaceMap | None], landing: list[Surface | None], target: TriMesh
    ) -> SurfaceMap:
        """Compose ``hops`` (hop j lands on ``landing[j]``; the last lands on ``target``) onto ``target``.

        Trailing identity hops are applied exactly by :func:`transplant`; everything before them is
        composed onto the last mapped surface, with the target's vertex positions."""
        mapped = [j for j, h in enumerate(hops) if h is not None]
        if not mapped:
            return identity_map(target, self._kept(FacesByVertexSet, target).rows)
        k = mapped[-1]
        middle = [self.faces_of(surface) for surface in landing[:k]]
        if k == len(hops) - 1:
            locator = self.locator(target)
            if len(mapped) > 2 and mapped[0] == 0:  # the tail needs a composition of its own: share it
                tail = self._tail(hops[1:], landing[1:], middle[1:], target, locator)
                return compose(hops[0], middle[0], tail, target, locator)
            return compose_path(hops, middle, target, locator)
        faces = self.faces_of(landing[k])
        geometry = self._geometry_with_faces(target, faces)
        head = compose_path(hops[: k + 1], middle, geometry, self.locator(geometry))
        return transplant(head, faces, self._kept(FacesByVertexSet, target), self.locator(target))

    def ground_truth(
        self, x: ShapeLike, y: ShapeLike, *, x_remesh=None, y_remesh=None, y_mesh: TriMesh | None = None
    ) -> SurfaceMap:
        """Dense ground truth from X's vertices to points on Y's surface.

        Args:
            x, y: the two shapes (``becos.sources.datasets.ShapeEntry`` or alike).
            x_remesh, y_remesh: :class:`becos.build.remesh.Remeshed` of X / Y. With ``x_remesh`` the map
                starts at the remeshed X's vertices; with ``y_remesh`` it lands on the remeshed Y.
            y_mesh: the target mesh geometry, when it differs from the original / remeshed Y only by a
                similarity transform (e.g. the prepared, common-frame Y). Defaults to the remeshed Y
                or Y's original mesh. Closest-point projection is invariant under such transforms.

        Returns:
            SurfaceMap of length V_X (or V_remeshed_X); face -1 where X's point has no counterpart on Y.
        """
        surfaces = self.surface_path(x, y)
        nodes = [i for i, s in enumerate(surfaces) if s.node is not None]
        first, last = nodes[0], nodes[-1]
        steps: list[tuple[SurfaceMap | None, Surface | None]] = []  # (hop, the surface it lands on)
        if x_remesh is not None:
            steps.append((x_remesh.to_original, surfaces[0]))
        for a, b in zip(surfaces[:first], surfaces[1 : first + 1]):  # X -> its template (identity)
            steps.append((self.hop(a, b), b))
        chain = self.template_chain(surfaces[first : last + 1]) if last > first else None
        if chain is not None:
            steps.append((chain, surfaces[last]))
        else:
            for a, b in zip(surfaces[first:last], surfaces[first + 1 : last + 1]):
                steps.append((self.hop(a, b), b))
        for a, b in zip(surfaces[last:], surfaces[last + 1 :]):  # Y's template -> Y (identity)
            steps.append((self.hop(a, b), b))
        if y_remesh is not None:
            steps.append((y_remesh.from_original, None))
            target = y_remesh.mesh
        else:
            target = self._meshes(y.dataset, y.name)
            if target is None:
                raise BecosError(
                    f"shape {y.dataset}/{y.name} is not available. Fix: enable/download dataset '{y.dataset}'"
                )
        if y_mesh is not None:
            if y_mesh.n_vertices != target.n_vertices or y_mesh.n_faces != target.n_faces:
                raise ValueError("y_mesh must have the connectivity of the target surface")
            target = y_mesh
        return self._compose_onto([hop for hop, _ in steps], [surface for _, surface in steps], target)
