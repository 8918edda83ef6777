"""Maps from the vertices of one mesh to points on another surface, and their composition.

A :class:`SurfaceMap` sends each vertex of a *source* mesh to a point of a *target* surface (a target
face and barycentric weights in face-column order) or to "none" (face ``-1``: a part the target lacks).
It is the one representation of ground truth in becos; the vertex-index form (``-1`` = none) is derived
only at the end (:meth:`SurfaceMap.to_nearest_vertices`; :meth:`SurfaceMap.to_vertex_indices` for labels).
:func:`compose` maps a point through the images of its face's vertices, projected onto the target among
faces near them along its connectivity (:data:`COMPOSE_RINGS`); maps compose from the target backwards,
so intermediate templates need only their faces. The rule in full: docs/design/ground-truth.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from becos.core.geometry import SurfaceLocator, points_on_surface
from becos.core.mesh import TriMesh, edge_neighbours

NONE = -1
"""Face (or vertex) index meaning "no counterpart"."""

COMPOSE_RINGS = 2
"""A composed point that needs a projection lands in a target face with a corner within this many
edge rings of a corner of its images' faces (:func:`compose`)."""


@dataclass(frozen=True, eq=False)
class SurfaceMap:
    """Source vertex i -> point ``weights[i]`` of target face ``face[i]``, or none (``face[i] == -1``).

    Attributes:
        face: (N,) int64 target face per source vertex, -1 where the vertex has no counterpart.
        weights: (N, 3) float64 barycentric weights (face-column order), rows sum to 1; zero rows where none.
        distance: (N,) float64 largest projection distance met while composing, in target units
            (0 for maps read from files or built by identity); NaN where none.
    """

    face: np.ndarray
    weights: np.ndarray
    distance: np.ndarray = field(default=None)

    def __post_init__(self):
        face = np.ascontiguousarray(self.face, dtype=np.int64)
        weights = np.ascontiguousarray(self.weights, dtype=np.float64)
        if face.ndim != 1 or weights.shape != (len(face), 3):
            raise ValueError(f"SurfaceMap needs face (N,) and weights (N, 3); got {face.shape} and {weights.shape}")
        distance = self.distance
        if distance is None:
            distance = np.where(face >= 0, 0.0, np.nan)
        object.__setattr__(self, "face", face)
        object.__setattr__(self, "weights", weights)
        object.__setattr__(self, "distance", np.ascontiguousarray(distance, dtype=np.float64))

    def __len__(self) -> int:
        return len(self.face)

    @property
    def matched(self) -> np.ndarray:
        """(N,) bool: the source vertex has a counterpart."""
        return self.face >= 0

    @property
    def missing_fraction(self) -> float:
        """Share of source vertices without a counterpart."""
        return float((~self.matched).mean()) if len(self) else 0.0

    @classmethod
    def from_vertex_indices(cls, target_vertex: np.ndarray, target_faces: np.ndarray) -> SurfaceMap:
        """Map each source vertex onto a target *vertex* (``-1`` = none).

        The point is stored in some face incident to that vertex with weight 1 at its corner.
        Raises ValueError if a target vertex is referenced by no face.
        """
        target_vertex = np.asarray(target_vertex, dtype=np.int64)
        target_faces = np.asarray(target_faces, dtype=np.int64)
        n_target = int(target_faces.max()) + 1 if len(target_faces) else 0
        incident_face = np.full(max(n_target, int(target_vertex.max(initial=-1)) + 1), -1, dtype=np.int64)
        corner = np.zeros_like(incident_face)
        # the last write wins; any incident face will do
        flat = target_faces.ravel()
        incident_face[flat] = np.repeat(np.arange(len(target_faces)), 3)
        corner[flat] = np.tile(np.arange(3), len(target_faces))
        matched = target_vertex >= 0
        face = np.full(len(target_vertex), NONE, dtype=np.int64)
        face[matched] = incident_face[target_vertex[matched]]
        if (face[matched] < 0).any():
            bad = np.unique(target_vertex[matched][face[matched] < 0])[:5]
            raise ValueError(f"target vertices {bad.tolist()} belong to no face; they cannot carry a surface point")
        weights = np.zeros((len(target_vertex), 3))
        weights[np.flatnonzero(matched), corner[target_vertex[matched]]] = 1.0
        return cls(face, weights)

    @classmethod
    def identity(cls, mesh_faces: np.ndarray, n_vertices: int) -> SurfaceMap:
        """Vertex i -> vertex i of a mesh with the same vertex order (e.g. two poses of one TOSCA class)."""
        return cls.from_vertex_indices(np.arange(n_vertices), mesh_faces)

    def to_vertex_indices(self, target_faces: np.ndarray) -> np.ndarray:
        """(N,) int64 target vertex per source vertex (-1 = none): the corner of the face holding the
        point with the largest weight. Never the nearest vertex in 3D, which can jump between touching
        parts (two legs)."""
        out = np.full(len(self), NONE, dtype=np.int64)
        matched = self.matched
        corner = self.weights[matched].argmax(axis=1)
        out[matched] = np.asarray(target_faces)[self.face[matched], corner]
        return out

    def to_nearest_vertices(self, target_vertices: np.ndarray, target_faces: np.ndarray) -> np.ndarray:
        """(N,) int64 target vertex per source vertex (-1 = none): the vertex nearest the point ALONG
        the target surface among the holding face's three corners and the far corners of its three
        edge neighbours (:class:`VertexRounding`; ties: the first candidate). This is the final vertex
        map of a pair record (``corr_01``/``corr_10``, :data:`becos.build.record.VERTEX_MAP_ROUNDING`).

        On a large face the nearest vertex is often a neighbour's far corner rather than a corner of
        the face; its distance is measured in the two faces unfolded into one plane, so a vertex that
        is near in 3D only across a fold, a thin part or a contact is never preferred (measured against
        the other rules: docs/measurements.md, vertex rounding).

        Args:
            target_vertices: (V, 3) float target vertex positions (any frame: distances are compared,
                and a similarity keeps their order).
            target_faces: (F, 3) target faces, as ``face`` indexes them. (A partial cut from a shape
                rounds through its full shape's :class:`VertexRounding` instead:
                :meth:`becos.build.partiality.Partial.round_to_vertices`.)
        """
        out = np.full(len(self), NONE, dtype=np.int64)
        matched = self.matched
        out[matched] = VertexRounding(target_vertices, target_faces).nearest(self.face[matched], self.weights[matched])
        return out

    def to_nearest_corners(self, target_vertices: np.ndarray, target_faces: np.ndarray) -> np.ndarray:
        """(N,) int64 target vertex per source vertex (-1 = none): the corner of the face holding the
        point that is nearest to the point in 3D (ties: the first face column). This was the final
        vertex map of a pair record from issue #20's first fix until :meth:`to_nearest_vertices`
        (records with meta ``vertex_rounding: nearest_corner``; :func:`becos.products.validate` checks them by it).

        The largest-weight corner is the nearest only on equilateral faces (its regions are bounded by
        the medians, not the perpendicular bisectors; measured: docs/measurements.md, vertex rounding). The
        three corners of one face lie on one part, so the choice never jumps across a contact.

        Args:
            target_vertices: (V, 3) float target vertex positions (any frame; a similarity does not
                change which corner is nearest).
            target_faces: (F, 3) target faces, as ``face`` indexes them.
        """
        out = np.full(len(self), NONE, dtype=np.int64)
        matched = self.matched
        corners = np.asarray(target_faces)[self.face[matched]]  # (M, 3)
        at = np.asarray(target_vertices, dtype=np.float64)[corners]  # (M, 3, 3)
        point = np.einsum("mk,mkd->md", self.weights[matched], at)
        nearest = np.linalg.norm(at - point[:, None], axis=2).argmin(axis=1)
        out[matched] = corners[np.arange(len(corners)), nearest]
        return out

    def positions(self, target: TriMesh) -> np.ndarray:
        """(N, 3) positions of the image points on ``target``; NaN rows where none."""
        out = np.full((len(self), 3), np.nan)
        matched = self.matched
        out[matched] = points_on_surface(target, self.face[matched], self.weights[matched])
        return out


class VertexRounding:
    """Rounds points of one mesh's surface to the vertex nearest them ALONG the surface, among the
    holding face's three corners and the far corners of its three edge neighbours
    (:meth:`SurfaceMap.to_nearest_vertices`, a pair record's final vertex maps).

    What depends on the mesh alone is computed once here: per face f and edge k (corners k, k+1) the
    edge's unit direction and length, and the neighbour's far corner unfolded into f's plane (its
    distances to the edge's two ends kept, on the side away from f).

    Args:
        vertices: (V, 3) float64 positions (any frame: only distances are compared).
        faces: (F, 3) int64 faces.
        only: optional (K,) int64 distinct face ids: the per-face data is computed for these faces
            alone (the same values), and :meth:`candidates` may then be asked about points on them only;
            for a caller that knows its points' faces in advance and needs few of them.
        neighbours: optional ``edge_neighbours(faces)`` when the caller has it (e.g. from
            :func:`becos.core.mesh.edge_neighbours_by_part` for meshes stacked into one array).
    """

    def __init__(
        self,
        vertices: np.ndarray,
        faces: np.ndarray,
        only: np.ndarray | None = None,
        neighbours: tuple[np.ndarray, np.ndarray] | None = None,
    ):
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        neighbour, far = edge_neighbours(self.faces) if neighbours is None else neighbours
        used = self.faces
        self._row = None  # face id -> row of the per-face data (None: the identity)
        if only is not None:
            self._row = np.full(len(self.faces), -1, dtype=np.int64)
            self._row[only] = np.arange(len(only))
            used, neighbour, far = used[only], neighbour[only], far[only]
        # (6, F, 3) per row, face and edge: unit direction x, y, z, length, far corner x, y (component
        # major: every quantity of the queries below is a contiguous (M, 3) array); one gather per query
        self._by_component = np.ascontiguousarray(self.vertices.T)  # (3, V)
        unit, length, far_x, far_y = _edge_data(self._by_component, used, far)
        self._edges = np.concatenate([unit, np.stack([length, far_x, far_y])])
        self._indices = np.stack([used, far, neighbour], axis=2)  # (F, 3, 3)

    def candidates(
        self, face: np.ndarray, weights: np.ndarray, kept_faces: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The vertices each point may round to, and their distances from it along the surface.

        Args:
            face: (M,) int64 face holding each point (all >= 0); weights: (M, 3) its barycentric weights.
            kept_faces: optional (F,) bool: only these faces exist (a partial cut from this mesh, with
                its faces' corner order); a neighbour outside them has no far corner.

        Returns:
            candidates: (M, 6) int64 vertices: the holding face's corners 0, 1, 2, then for its edges
                k = 0, 1, 2 the far corner of the face across that edge (-1 where there is none).
            distance: (M, 6) float64, in the units of ``vertices``: to a corner, the straight line
                inside the face; to a far corner, the straight line in the two faces unfolded into one
                plane, which is the geodesic when it crosses the shared edge. Where it does not (the
                shortest path then runs through a corner of that edge, which is nearer), where there is
                no far corner, or on a degenerate face: inf.
        """
        row = face if self._row is None else self._row[face]
        indices = np.take(self._indices, row, axis=0)  # (M, 3, 3): corner, far corner, neighbour per edge
        corners, across = indices[..., 0], indices[..., 1]
        if kept_faces is not None:
            across = np.where(kept_faces[np.maximum(indices[..., 2], 0)], across, -1)
        edges = np.take(self._edges, row, axis=1)  # (6, M, 3)
        return _candidates(self._by_component, corners, across, weights, edges[:3], edges[3], edges[4], edges[5])

    @staticmethod
    def candidates_once(
        vertices: np.ndarray, faces: np.ndarray, far: np.ndarray, face: np.ndarray, weights: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`candidates` without the per-face table, for a caller whose points lie on distinct faces
        mostly (each point's face data is computed for it, by the same operations: the same values).

        Args:
            vertices: (V, 3) float64; faces: (F, 3) int64; far: (F, 3) int64 the far corners of
                ``edge_neighbours(faces)``; face: (M,) int64 >= 0 and weights: (M, 3) as :meth:`candidates`.
        """
        by_component = np.ascontiguousarray(np.asarray(vertices, dtype=np.float64).T)
        parts = []
        for first in range(0, max(len(face), 1), _POINTS_AT_ONCE):  # a few MB of temporaries at a time
            rows = slice(first, first + _POINTS_AT_ONCE)
            corners, across = np.take(faces, face[rows], axis=0), np.take(far, face[rows], axis=0)
            unit, length, far_x, far_y = _edge_data(by_component, corners, across)
            parts.append(_candidates(by_component, corners, across, weights[rows], unit, length, far_x, far_y))
        if len(parts) == 1:
            return parts[0]
        return np.concatenate([c for c, _ in parts]), np.concatenate([d for _, d in parts])

    def nearest(self, face: np.ndarray, weights: np.ndarray, kept_faces: np.ndarray | None = None) -> np.ndarray:
        """(M,) int64 the candidate nearest each point along the surface (ties: the first candidate);
        arguments as :meth:`candidates`."""
        candidates, distance = self.candidates(face, weights, kept_faces)
        return candidates[np.arange(len(candidates)), distance.argmin(axis=1)]


_POINTS_AT_ONCE = 16384
"""Points :meth:`VertexRounding.candidates_once` handles at once: its temporaries stay small enough for
the allocator to reuse (larger ones cost the validator more system time in page faults than the work)."""


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot products of (3, ...) component-major vectors, summed (x + z) + y: the order in which numpy's
    einsum summed a trailing axis of 3 in the form this replaced (measured on this project's machine),
    so records and validations keep their values bit for bit."""
    return (a[0] * b[0] + a[2] * b[2]) + a[1] * b[1]


def _edge_data(
    by_component: np.ndarray, corners: np.ndarray, far: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per face (rows of ``corners`` (F, 3) and ``far`` (F, 3) int64: its corners and the far corners of
    its edge neighbours, -1 for none) and edge k (corners k, k + 1), from the (3, V) float64 vertex
    coordinates ``by_component``: (3, F, 3) unit direction (component first), (F, 3) length, and the far
    corner unfolded into the face's plane, (F, 3) x along the edge from its start and (F, 3) y < 0 (across
    it); :class:`VertexRounding`."""
    start = np.take(by_component, corners, axis=1)  # (3, F, 3): edge k runs from corner k ...
    edge = np.take(start, [1, 2, 0], axis=2) - start  # ... to corner k + 1
    to_far = np.take(by_component, far, axis=1) - start  # columns with far == -1 are never used
    with np.errstate(divide="ignore", invalid="ignore"):
        length2 = _dot(edge, edge)
        length = np.sqrt(length2)
        far2 = _dot(to_far, to_far)
        beyond = to_far - edge
        far_x = (far2 - _dot(beyond, beyond) + length2) / (2 * length)
        far_y = -np.sqrt(np.maximum(far2 - far_x**2, 0.0))
        unit = edge / length
    return unit, length, far_x, far_y


def _candidates(
    by_component: np.ndarray,
    corners: np.ndarray,
    across: np.ndarray,
    weights: np.ndarray,
    unit: np.ndarray,
    length: np.ndarray,
    qx: np.ndarray,
    qy: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`VertexRounding.candidates` from each point's (M, 3) corners, (M, 3) far corners (-1: none),
    (M, 3) weights and its face's :func:`_edge_data` (M columns: unit (3, M, 3), the others (M, 3)), with
    ``by_component`` the (3, V) float64 vertex coordinates."""
    start = np.take(by_component, corners, axis=1)  # (3, M, 3)
    w = np.asarray(weights, dtype=np.float64).T  # (3, M): the point is sum_k w_k corner_k, summed in k order
    to_point = ((w[0] * start[..., 0] + w[1] * start[..., 1]) + w[2] * start[..., 2])[..., None] - start
    with np.errstate(divide="ignore", invalid="ignore"):
        corner2 = _dot(to_point, to_point)
        px = _dot(to_point, unit)
        py = np.sqrt(np.maximum(corner2 - px * px, 0.0))  # the point's distance from the edge's line
        crossing = px + py / (py - qy) * (qx - px)  # where the straight line meets the edge's line
        straight = np.hypot(px - qx, py - qy)
        ok = (across >= 0) & (py - qy > 0) & (crossing >= 0) & (crossing <= length) & np.isfinite(straight)
        distance = np.concatenate([np.sqrt(corner2), np.where(ok, straight, np.inf)], axis=1)
    distance[~np.isfinite(distance)] = np.inf
    return np.concatenate([corners, across], axis=1), distance


def compose(
    first: SurfaceMap,
    middle_faces: np.ndarray,
    second: SurfaceMap,
    target: TriMesh,
    locator: SurfaceLocator | None = None,
) -> SurfaceMap:
    """The map ``second ∘ first``: source -> middle surface -> target surface.

    Args:
        first: source vertices -> points on the middle surface, whose faces are ``middle_faces`` (F_m, 3).
        middle_faces: faces of the middle mesh as ``first.face`` indexes them (only faces are needed).
        second: middle *vertices* -> points on ``target``.
        target: the target mesh (its geometry is needed for the projection).
        locator: a :class:`SurfaceLocator` of ``target`` to reuse across calls (built if omitted).

    Returns:
        The composed map; ``distance`` is the larger of the inherited distance and this projection's.
    """
    n = len(first)
    middle_faces = np.asarray(middle_faces, dtype=np.int64)
    face = np.full(n, NONE, dtype=np.int64)
    weights = np.zeros((n, 3))
    distance = np.full(n, np.nan)

    # np.take gathers rows as fancy indexing does (the same values, C-contiguous), several times faster
    alive = np.flatnonzero(first.matched)
    corner_vertices = np.take(middle_faces, np.take(first.face, alive), axis=0)  # (M, 3) middle vertices
    w = np.take(first.weights, alive, axis=0)  # (M, 3)
    image_face = np.take(second.face, corner_vertices)  # (M, 3) each corner's image face; -1: none
    has_image = image_face >= 0
    keep = np.take_along_axis(has_image, w.argmax(axis=1)[:, None], axis=1)[:, 0]  # the dominant corner's
    if not keep.all():
        alive, corner_vertices, w = alive[keep], corner_vertices[keep], w[keep]
        image_face, has_image = image_face[keep], has_image[keep]
    w = np.where(has_image, w, 0.0)
    w /= w.sum(axis=1, keepdims=True)

    # image_face: -1 now only where w == 0
    image_weights = np.take(second.weights, corner_vertices, axis=0)  # (M, 3, 3)

    # Exact case: all three images lie in one target face (always true for an identity map on the
    # same connectivity); then the combination is that face with summed weights, no projection.
    same_face = (image_face == image_face[:, :1]) | (w == 0)
    exact = same_face.all(axis=1)
    anchor = np.take_along_axis(image_face, w.argmax(axis=1)[:, None], axis=1)[:, 0]
    combined = np.einsum("mk,mkj->mj", w, image_weights)
    face[alive[exact]] = anchor[exact]
    weights[alive[exact]] = combined[exact]
    distance[alive[exact]] = 0.0

    loose = ~exact
    if loose.any():
        locator = locator if locator is not None else SurfaceLocator(target)
        f, bw, d = _project_near_images(w[loose], image_face[loose], image_weights[loose], target, locator)
        face[alive[loose]] = f
        weights[alive[loose]] = bw
        distance[alive[loose]] = d

    inherited = np.where(np.isnan(first.distance), 0.0, first.distance)
    distance = np.where(face >= 0, np.fmax(distance, inherited), np.nan)
    return SurfaceMap(face, weights, distance)


def _project_near_images(
    w: np.ndarray, image_face: np.ndarray, image_weights: np.ndarray, target: TriMesh, locator: SurfaceLocator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points whose corner images lie in different target faces, projected onto ``target`` near them.

    ``w`` (L, 3) weights of the corners, ``image_face`` (L, 3) and ``image_weights`` (L, 3, 3) the corners'
    images (face -1 only where ``w`` is 0). The ``w``-combination of the images (a point between them, off
    the surface) goes to its closest point (:meth:`SurfaceLocator.closest_near`, with the images' normals)
    among the faces within :data:`COMPOSE_RINGS` rings of the image faces' corners. Returns (L,) faces, (L, 3) barycentric weights, (L,) distances."""
    safe_face = np.where(image_face >= 0, image_face, 0)
    # (L, 3, 3) corners of the image faces (the locator is the target's, as its normals and rings are)
    image_points = np.einsum("mkj,mkjd->mkd", image_weights, np.take(locator.triangles, safe_face, axis=0))
    points = np.einsum("mk,mkd->md", w, image_points)
    # the point lies between its images: it may only land near their faces along the target's
    # connectivity, never on another part that touches them in space (normals alone are misled
    # where parts pass through each other or meet at an angle)
    normals = np.einsum("mk,mkd->md", w, np.take(locator.face_normals, safe_face, axis=0))
    near_vertices = np.take(np.asarray(target.faces), safe_face, axis=0).reshape(-1, 9)  # (L, 9) image corners
    used = np.repeat(w > 0, 3, axis=1)  # (L, 9)
    near_vertices = np.where(used, near_vertices, near_vertices[np.arange(len(used)), used.argmax(axis=1)][:, None])
    rings = locator.rings(COMPOSE_RINGS)
    target_faces = np.asarray(target.faces)

    def accept(rows, cand):
        corners = np.take(target_faces, cand, axis=0)  # (M, K, 3)
        near = np.take(near_vertices, rows, axis=0)  # (M, 9)
        # a face sharing a corner with an image face is within the rings (a vertex is within 0 rings
        # of itself): only the others need the sparse lookup
        ok = (near[:, None, :, None] == corners[:, :, None, :]).any(axis=(2, 3))  # (M, K)
        row, col = np.nonzero(~ok)
        ok[row, col] = rings.near(near[row][:, :, None], corners[row, col][:, None, :]).any(axis=(1, 2))
        return ok

    f, bw, d, _ = locator.closest_near(points, accept, normals)
    return f, bw, d


def compose_path(
    hops: list[SurfaceMap | None],
    middle_faces: list[np.ndarray],
    target: TriMesh,
    locator: SurfaceLocator | None = None,
) -> SurfaceMap:
    """Compose a chain surface_0 -> surface_1 -> ... -> surface_k+1 (= target), backwards from the target.

    Args:
        hops: k+1 maps; ``hops[j]`` sends the vertices of surface j to points on surface j+1.
            ``None`` marks an identity hop (same vertex order on both sides), which is skipped.
        middle_faces: k arrays; ``middle_faces[j]`` holds the faces of surface j+1 exactly as
            ``hops[j]`` indexes them (for a TOSCA pose these may differ from its template's faces
            by winding, which is why identity hops keep each side's own faces).
        target: the target mesh, surface k+1.
        locator: a :class:`SurfaceLocator` of ``target`` to reuse (built if omitted).
    """
    if len(middle_faces) != len(hops) - 1:
        raise ValueError(f"compose_path needs {len(hops) - 1} face arrays, got {len(middle_faces)}")
    locator = locator if locator is not None else SurfaceLocator(target)
    result: SurfaceMap | None = None
    for j in range(len(hops) - 1, -1, -1):
        if hops[j] is None:
            if result is None:  # the target itself: keep its own faces (winding may differ)
                result = SurfaceMap.identity(target.faces, target.n_vertices)
            continue
        result = hops[j] if result is None else compose(hops[j], middle_faces[j], result, target, locator)
    return result
