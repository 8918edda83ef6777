"""Paths through the shape network and dense ground truth between any two shapes of a category.

A path from shape X to shape Y runs X -> X's template -> network templates ... -> Y's template -> Y
(optionally with remeshed X and Y at the ends). Each hop is a :class:`~becos.surface_map.SurfaceMap`
from the vertices of one surface to points on the next:

- shape <-> its template: identity (vertex i is vertex i) when both are meshes of one triangulation
  -- poses of one class (TOSCA, DT4D), or a whole dataset built on one template mesh (FAUST, SCAPE,
  KIDS, SMAL). Vertex counts are checked; face rows may differ by winding, so every surface keeps
  its own faces.
- template -> template: the annotation folder's edge file, or identity for DT4D classes listed as
  sharing a triangulation.
- remeshed X -> X: :attr:`becos.remesh.Remeshed.to_original`; Y -> remeshed Y: ``from_original``.

The template-to-template part is composed once per pair of classes and cached (projected onto the
last template, whose mesh is in Y's dataset); the shape and remesh hops are then composed onto the
target per pair. Compositions run backwards from their target
(:func:`becos.surface_map.compose_path`), so an intermediate template needs only its faces (from
the dataset when present, else the annotation folder's default faces).
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from becos.errors import BecosError, InputFileError
from becos.geometry import SurfaceLocator
from becos.mesh import TriMesh
from becos.surface_map import SurfaceMap, compose_path

class ShapeLike(Protocol):
    """What the network needs to know of a shape (``becos.datasets.ShapeEntry`` satisfies it)."""

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
        annotations: a :class:`becos.annotations.AnnotationSource`.
        meshes: lookup of original meshes by (dataset, name); None for a shape that is not available.
    """

    def __init__(self, annotations, meshes: MeshLookup):
        self.annotations = annotations
        self._meshes = meshes
        self._faces_cache: dict[tuple[str, str], np.ndarray] = {}
        self._chains: dict[tuple[str, ...], SurfaceMap] = {}
        self._locators: OrderedDict[int, tuple[TriMesh, SurfaceLocator]] = OrderedDict()

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
                        f"for '{surface.name}'. Fix: enable/download dataset '{surface.dataset}'")
            self._faces_cache[key] = np.asarray(faces, dtype=np.int64)
        return self._faces_cache[key]

    def _n_vertices(self, surface: Surface) -> int | None:
        mesh = self._meshes(surface.dataset, surface.name)
        return None if mesh is None else mesh.n_vertices

    def _is_identity_hop(self, a: Surface, b: Surface) -> bool:
        """A shape and its own template are one triangulation (the template table pairs them by class,
        or by dataset where one template mesh underlies the whole dataset); vertex counts are checked."""
        if a.node is not None and b.node is not None:
            return False  # template -> template: decided by the annotation folder
        if a.dataset != b.dataset:
            raise BecosError(f"{a} and its template {b} belong to different datasets, so they need an edge file. "
                             f"Fix: point the template table row of {a} at a template of its own dataset")
        na, nb = self._n_vertices(a), self._n_vertices(b)
        if na is not None and nb is not None and na != nb:
            raise BecosError(f"{a} and its template {b} should share one triangulation (vertex i = vertex i) but "
                             f"have {na} and {nb} vertices. Fix: check that both files come from the same "
                             f"dataset release and were not re-processed")
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
            raise InputFileError(source.path, f"has {len(edge)} rows but template {a} has {n_source} vertices",
                                 "the edge file and the mesh come from different versions; restore the annotation "
                                 "folder's file or the dataset's original mesh")
        if len(edge) and edge.face.max() >= n_target_faces:
            raise InputFileError(source.path, f"face index {int(edge.face.max())} is out of range for template {b} "
                                 f"({n_target_faces} faces)", "restore the annotation folder's original file")
        return edge

    # --- ground truth ---------------------------------------------------------------------------
    def locator(self, mesh: TriMesh) -> SurfaceLocator:
        """A closest-point structure of ``mesh``, kept for the last few meshes used as targets."""
        key = id(mesh)
        if key in self._locators:
            self._locators.move_to_end(key)
            return self._locators[key][1]
        locator = SurfaceLocator(mesh)
        self._locators[key] = (mesh, locator)  # holding the mesh keeps its id from being reused
        while len(self._locators) > 8:
            self._locators.popitem(last=False)
        return locator

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
            middle = [self.faces_of(t) for t in templates[1:-1]]
            self._chains[key] = compose_path(hops, middle, mesh, self.locator(mesh))
        return self._chains[key]

    def ground_truth(self, x: ShapeLike, y: ShapeLike, *, x_remesh=None, y_remesh=None,
                     y_mesh: TriMesh | None = None) -> SurfaceMap:
        """Dense ground truth from X's vertices to points on Y's surface.

        Args:
            x, y: the two shapes (``becos.datasets.ShapeEntry`` or alike).
            x_remesh, y_remesh: :class:`becos.remesh.Remeshed` of X / Y. With ``x_remesh`` the map
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
        for a, b in zip(surfaces[:first], surfaces[1:first + 1]):      # X -> its template (identity)
            steps.append((self.hop(a, b), b))
        chain = self.template_chain(surfaces[first:last + 1]) if last > first else None
        if chain is not None:
            steps.append((chain, surfaces[last]))
        else:
            for a, b in zip(surfaces[first:last], surfaces[first + 1:last + 1]):
                steps.append((self.hop(a, b), b))
        for a, b in zip(surfaces[last:], surfaces[last + 1:]):        # Y's template -> Y (identity)
            steps.append((self.hop(a, b), b))
        if y_remesh is not None:
            steps.append((y_remesh.from_original, None))
            target = y_remesh.mesh
        else:
            target = self._meshes(y.dataset, y.name)
            if target is None:
                raise BecosError(f"shape {y.dataset}/{y.name} is not available. Fix: enable/download "
                                 f"dataset '{y.dataset}'")
        if not steps:
            return SurfaceMap.identity(target.faces, target.n_vertices)
        if y_mesh is not None:
            if y_mesh.n_vertices != target.n_vertices or y_mesh.n_faces != target.n_faces:
                raise ValueError("y_mesh must have the connectivity of the target surface")
            target = y_mesh
        hops = [hop for hop, _ in steps]
        middle = [self.faces_of(surface) for _, surface in steps[:-1]]
        return compose_path(hops, middle, target, self.locator(target))
