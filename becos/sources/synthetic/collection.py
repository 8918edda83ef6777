"""The synthetic collection: classes built and posed, template correspondences, files on disk.

:func:`generate_collection` writes into ``out_dir``: ``synthetic.json`` (what was generated, sha256 of
every file), the shapes ``data/<folder_name>/<class><k>.off`` (k = 0 is the template) of two datasets
whose file frames differ on purpose (``synthy``: metres, y-up; ``synthz``: centimetres, z-up, offset),
and ``annotations/``, a folder shaped like the BeCoS reference checkout (network, template tables, edge
files, default faces, left/right labels). Template correspondences come from the construction (shared
part charts); vertices on parts the other class lacks get ``-1 0 0 0``. The layout, the charts and
measured part agreement: docs/design/data.md.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np

from becos.atomic import atomic_folder
from becos.core.geometry import barycentric_coordinates
from becos.core.mesh import TriMesh
from becos.errors import ConfigError
from becos.sources.synthetic.bodies import (
    CHART_BINS,
    CLASSES,
    PART_GROUPS,
    Body,
    ClassSpec,
    chart_profile,
    class_spec,
    draw_pose,
    pose_vertices,
    skinning_weights,
)
from becos.sources.synthetic.meshing import mesh_body

MANIFEST = "synthetic.json"
FORMAT_VERSION = 1


@dataclass(frozen=True)
class SyntheticDataset:
    """One synthetic dataset and the frame its files are written in.

    Attributes:
        name: dataset name (lowercase alphanumeric, no underscore).
        folder_name: folder under ``OUT/data``.
        scale: file units -> metres (registry ``scale``).
        rot: registry ``rot`` in degrees (Open3D xyz convention, applied as ``V @ R``, row vectors).
        offset: (3,) translation added in file units (the registry subtracts the mean anyway).
        target_vertices: approximate vertex count of its meshes.
        splits: category -> {"train"/"val"/"test": [class names]} (class held out per split).
    """

    name: str
    folder_name: str
    scale: float
    rot: tuple[float, float, float]
    offset: tuple[float, float, float]
    target_vertices: int
    splits: dict

    def rotation(self) -> np.ndarray:
        """(3, 3) R with common = (file * scale) @ R (row vectors): Rx(a) Ry(b) Rz(c), column form."""
        return rotation_xyz(self.rot)

    def to_file_frame(self, vertices: np.ndarray) -> np.ndarray:
        """(N, 3) common-frame metres -> file coordinates."""
        return vertices @ self.rotation().T / self.scale + np.asarray(self.offset)

    def to_common_frame(self, vertices: np.ndarray) -> np.ndarray:
        """(N, 3) file coordinates -> common-frame metres (inverse of :meth:`to_file_frame`, not centred)."""
        return ((vertices - np.asarray(self.offset)) * self.scale) @ self.rotation()


def rotation_xyz(degrees) -> np.ndarray:
    """Open3D ``get_rotation_matrix_from_xyz``: Rx(a) @ Ry(b) @ Rz(c) for angles in degrees."""
    a, b, c = np.radians(np.asarray(degrees, dtype=float))
    Rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    Ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    Rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    R = Rx @ Ry @ Rz
    R[np.abs(R) < 1e-15] = 0.0
    return R


DATASETS: dict[str, SyntheticDataset] = {
    "synthy": SyntheticDataset(
        "synthy",
        "synthy-off",
        1.0,
        (0.0, 0.0, 0.0),
        (0.0, 0.0, 0.0),
        7000,
        {
            "human": {"train": ["alba"], "val": ["brute"], "test": ["cyra"]},
            "four-legged": {"train": ["hound"], "val": ["goat"], "test": ["tapir"]},
        },
    ),
    "synthz": SyntheticDataset(
        "synthz",
        "synthz-off",
        0.01,
        (90.0, 0.0, 0.0),
        (40.0, -25.0, 10.0),
        14000,
        {
            "human": {"train": ["elin"], "val": ["dario"], "test": ["faun"]},
            "four-legged": {"train": ["pony"], "val": ["lynx"], "test": ["ram"]},
        },
    ),
}

TREE_EDGES: tuple[tuple[str, str], ...] = (
    ("synthy_alba0", "synthy_brute0"),
    ("synthy_alba0", "synthy_cyra0"),
    ("synthy_alba0", "synthz_elin0"),
    ("synthz_elin0", "synthz_dario0"),
    ("synthz_elin0", "synthz_faun0"),
    ("synthy_hound0", "synthy_goat0"),
    ("synthy_hound0", "synthy_tapir0"),
    ("synthy_hound0", "synthz_lynx0"),
    ("synthz_lynx0", "synthz_pony0"),
    ("synthz_pony0", "synthz_ram0"),
    ("synthz_centaur0", "synthz_elin0"),
    ("synthz_centaur0", "synthz_pony0"),
)
"""The template network: undirected edges of a tree over all class templates (humanoids and
four-legged classes are connected only through the centaur, as in BeCoS)."""

FULL_SCALE_POSES: dict[str, int] = {
    "synthy_alba": 218,
    "synthz_elin": 218,
    "synthy_hound": 908,
    "synthz_pony": 908,
    "synthz_centaur": 6,
    "synthy_brute": 14,
    "synthz_dario": 13,
    "synthy_goat": 55,
    "synthz_lynx": 55,
    "synthy_cyra": 14,
    "synthz_faun": 14,
    "synthy_tapir": 57,
    "synthz_ram": 57,
}
"""Shapes per class (key ``<dataset>_<class>``) of the BeCoS-size collection (``fraction`` 1 of
:func:`generate_collection`), modelled on the published benchmark: 2,537 distinct shapes, of them 496
humanoid (with the 6 centaurs) and 2,047 four-legged (with the centaurs), and one shape per val/test
pair, i.e. 137 val and 142 test shapes (the published 137 / 142 val / test pairs per setting). Val and
test shapes are split between the categories by their share of the shapes (about 1 in 5 humanoid) and
evenly between each split's two classes; the train classes take the rest (436 humanoid, 1,816
four-legged, 6 centaurs: 2,258 train shapes). With usage 10 (config/datasets/synthy.yaml, synthz.yaml)
and ``usage_scale`` 0.5 every train shape anchors 5 pairs: 11,290 train pairs per setting, 11 % more
than the published 10,185 (whose usage counts differ by dataset)."""

CHIRALITY_TEMPLATES: tuple[str, ...] = ("synthy_alba0", "synthy_hound0", "synthz_centaur0")
"""Templates that carry left/right labels (1 = anatomical left = +x in the common frame)."""

ZONE_WIDTH = 0.6
"""Half-width of a junction band: the vertices with |f_parent - f_child| < ZONE_WIDTH * (the child's
radius at its joint) are mapped in the junction's band chart (:func:`junction_chart`)."""

JUNCTION_KAPPA = 0.5
"""Weight of ``zeta`` against the angle (radians) in a band chart. Along the surface, zeta grows by
about 1.5 / ZONE_WIDTH per child radius of arc length, the angle by 1 per radius, so 0.5 keeps the
chart roughly isotropic (the agreement figures change by < 0.01 % between 0.25 and 1)."""

COLLAR_GAP = 0.15
"""Where class B has a part that class A lacks (a tail, horns, the centaur's human torso on the
barrel), the surface of A that part covers and the collar around it (|zeta| < 1 on the parent's
side) are spread over B's collar, whose inner edge zeta = -COLLAR_GAP is where A's deepest point lands."""

SKINNING_SIGMA = 0.012
"""Width (metres, at unit class size) of the skinning softmax."""


# --- classes -----------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ClassModel:
    """A built class: its body, its template mesh (rest pose) and per-vertex construction data.

    Attributes:
        spec: the :class:`~becos.sources.synthetic.bodies.ClassSpec`.
        body: array form of its parts.
        mesh: template (pose 0) mesh in the common frame (metres, +y up, facing +z), before the
            vertical shift that puts the feet on y = 0 (poses and files have that shift).
        labels: (V,) int64 part index (into ``spec.part_names``) of each vertex.
        face_labels: (F,) int64 part index of each face (the part whose field is smallest at its centroid).
        weights: (V, P) skinning weights.
        extents: (P, 2, CHART_BINS) per part and angle, the axial chart coordinates mapped to 0 and
            to CANONICAL_LENGTH by :meth:`~becos.sources.synthetic.bodies.Body.normalised_chart`: the
            boundary with the parent (exact, from the label boundary's crossings of mesh edges; the
            region's lowest point for the root) and the region's highest point.
        part_values: (V, P) part field values at the vertices (metres).
        boundary_points: (K, 3) points where the boundary between a part and its parent crosses a
            mesh edge (common frame, metres); boundary_child: (K,) that part's index.
    """

    spec: ClassSpec
    body: Body
    mesh: TriMesh
    labels: np.ndarray
    face_labels: np.ndarray
    weights: np.ndarray
    extents: np.ndarray
    part_values: np.ndarray
    boundary_points: np.ndarray
    boundary_child: np.ndarray

    def region(self, part: int) -> np.ndarray:
        """(F_p,) indices of the faces of part ``part``."""
        return np.flatnonzero(self.face_labels == part)

    def chart(self, points: np.ndarray, part: int) -> np.ndarray:
        """(N, 3) normalised chart positions (shared domain of part ``part``'s name) of (N, 3) points."""
        return self.body.normalised_chart(points, part, self.extents[part])

    def pose(self, seed: int, pose: int) -> np.ndarray:
        """(V, 3) vertices of pose ``pose`` in the common frame (metres), feet at y = 0."""
        rotations = draw_pose(self.body, seed, f"{self.spec.dataset}/{self.spec.name}", pose)
        return pose_vertices(self.body, self.mesh.vertices, self.weights, rotations)


@cache
def build_class(dataset: str, name: str) -> ClassModel:
    """Build (and cache in-process) the template of a class: mesh, part labels, skinning weights.

    Independent of any seed: the seed only changes the poses.
    """
    spec = class_spec(dataset, name)
    body = Body.from_parts(spec.parts)
    mesh = mesh_body(body, DATASETS[dataset].target_vertices)
    part_values = body.part_fields(mesh.vertices)
    labels = part_values.argmin(axis=1).astype(np.int64)
    face_labels = body.labels(mesh.vertices[mesh.faces].mean(axis=1))
    size = float(np.ptp(mesh.vertices, axis=0).max())
    weights = skinning_weights(body, mesh.vertices, labels, SKINNING_SIGMA * size)
    crossings, crossing_part = _parent_boundary_points(body, mesh, labels, part_values)
    extents = np.zeros((body.n_parts, 2, CHART_BINS))
    for p in range(body.n_parts):  # ~25 parts
        faces = mesh.faces[face_labels == p]
        if len(faces) == 0:
            raise ValueError(
                f"part {body.names[p]} of {spec.node} has no faces (buried inside its neighbours); "
                f"the class definition must make every part visible"
            )
        extents[p] = body.chart_extent(mesh.vertices[np.unique(faces)], p)
        mine = crossings[crossing_part == p]
        if len(mine):
            extents[p, 0] = chart_profile(body.chart(mine, p))
    return ClassModel(spec, body, mesh, labels, face_labels, weights, extents, part_values, crossings, crossing_part)


def _parent_boundary_points(body: Body, mesh: TriMesh, labels: np.ndarray, values: np.ndarray):
    """Points where the boundary between each part and its parent crosses mesh edges.

    On an edge whose ends are labelled child c and parent q, the crossing is where the linear
    interpolation of f_c - f_q vanishes. Returns (K, 3) points and (K,) the child part of each.
    """
    F = mesh.faces
    pairs = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1).astype(np.int64)
    n = np.int64(mesh.n_vertices)
    keys = np.unique(pairs[:, 0] * n + pairs[:, 1])  # each undirected edge once, sorted
    edges = np.stack([keys // n, keys % n], axis=1)
    la, lb = labels[edges[:, 0]], labels[edges[:, 1]]
    parents = body.parents
    a_child = parents[la] == lb  # end 0 is the child
    b_child = parents[lb] == la  # end 1 is the child
    keep = a_child | b_child
    edges, la, lb, a_child = edges[keep], la[keep], lb[keep], a_child[keep]
    child = np.where(a_child, la, lb)
    parent = np.where(a_child, lb, la)
    g0 = values[edges[:, 0], child] - values[edges[:, 0], parent]
    g1 = values[edges[:, 1], child] - values[edges[:, 1], parent]
    lam = np.clip(g0 / np.where(g0 == g1, 1.0, g0 - g1), 0.0, 1.0)
    V = mesh.vertices
    points = V[edges[:, 0]] + lam[:, None] * (V[edges[:, 1]] - V[edges[:, 0]])
    return points, child


def body_part_labels(dataset: str, name: str) -> tuple[np.ndarray, tuple[str, ...]]:
    """Per-vertex part labels of a class template (= of every pose: they share the triangulation).

    Returns:
        labels: (V,) int64 index into ``names`` for each vertex, in the OFF file's vertex order.
        names: part names, e.g. ``"q_fupper_l"`` (left front upper leg), ``"b_head"``.
    """
    model = build_class(dataset, name)
    return model.labels.copy(), model.spec.part_names


# --- correspondences ---------------------------------------------------------------------------


def edge_edits(a: ClassSpec, b: ClassSpec) -> tuple[str, str]:
    """File-name suffixes naming the edited templates of an edge (as the reference names them).

    A side whose parts are partly absent on the other side gets ``_top`` (centaur <-> humanoid),
    ``_bottom`` (centaur <-> four-legged) or ``_no_<group>`` for optional part groups (horns, tail).
    """

    def suffix(x: ClassSpec, y: ClassSpec) -> str:
        cats = {x.category, y.category}
        if cats == {"centaur", "human"}:
            return "_top"
        if cats == {"centaur", "four-legged"}:
            return "_bottom"
        missing = set(x.part_names) - set(y.part_names)
        groups = sorted(g for g, names in PART_GROUPS.items() if missing & set(names))
        return "".join(f"_no_{g}" for g in groups)

    return suffix(a, b), suffix(b, a)


def junction_coordinate(model: ClassModel, child: int, rows: np.ndarray | None = None) -> np.ndarray:
    """Signed position of vertices across the boundary between part ``child`` and its parent.

    ``zeta = (f_parent - f_child) / (ZONE_WIDTH * r_child)`` with ``r_child`` the child's radius at
    its joint: 0 exactly on the label boundary, > 0 on the child's side, |zeta| < 1 in the junction
    band. Dimensionless; (N,) for the vertex indices ``rows`` (all vertices if None).
    """
    values = model.part_values if rows is None else model.part_values[rows]
    parent = model.body.parents[child]
    return (values[:, parent] - values[:, child]) / (ZONE_WIDTH * model.body.ra[child])


def junction_chart(model: ClassModel, child: int, points: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """(N, 3) band chart of the junction of part ``child`` with its parent: the unit direction of each
    point around the child's bone, in its (e1 = anatomical left, e2) frame, and ``JUNCTION_KAPPA *
    zeta`` (see :func:`junction_coordinate`). A cylinder shared by all classes with that child, whose
    circle ``zeta = 0`` is exactly the part boundary on every class."""
    _, s1, s2, _ = model.body._local(points, np.array([child]))
    ring = np.concatenate([s1, s2], axis=1)
    ring /= np.maximum(np.linalg.norm(ring, axis=1, keepdims=True), 1e-12)
    return np.column_stack([ring, JUNCTION_KAPPA * zeta])


class _Soup:
    """A triangle soup in some chart of class b, with its AABB tree: ``region`` (M,) the faces of b
    it holds, ``soup`` (3M, 3) their corners' chart positions (face j = rows 3j..3j+2)."""

    def __init__(self, region: np.ndarray, soup: np.ndarray):
        import igl

        self.region, self.soup = region, soup
        self.faces = np.arange(len(soup), dtype=np.int64).reshape(-1, 3)
        self.tree = None
        if len(region):
            self.tree = igl.AABB()
            self.tree.init(soup, self.faces)

    def __len__(self) -> int:
        return len(self.region)

    def closest(self, query: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest points of (N, 3) chart points: (N,) face of b, (N, 3) barycentric weights in
        b's face-column order, (N,) chart distance."""
        sq, hit, closest = self.tree.squared_distance(self.soup, self.faces, query)
        hit = np.asarray(hit, dtype=np.int64)
        tri = self.soup[self.faces[hit]]
        weights = barycentric_coordinates(closest, tri[:, 0], tri[:, 1], tri[:, 2])
        return self.region[hit], weights, np.sqrt(np.maximum(sq, 0.0))


@cache
def _part_soup(b: ClassModel, part: int) -> _Soup:
    """b's faces of ``part`` in that part's normalised capsule chart."""
    region = b.region(part)
    return _Soup(region, b.chart(b.mesh.vertices[b.mesh.faces[region]].reshape(-1, 3), part))


@cache
def _band_soup(b: ClassModel, child: int, labels: tuple[int, ...]) -> _Soup:
    """b's faces in the junction band of ``child`` (some corner with |zeta| < 1.5) whose corners all
    carry one of ``labels``, in the band chart (:func:`junction_chart`)."""
    faces = b.mesh.faces
    zeta = junction_coordinate(b, child, faces.ravel()).reshape(-1, 3)
    keep = np.isin(b.labels[faces], labels).all(axis=1) & (np.abs(zeta).min(axis=1) < 1.5)
    region = np.flatnonzero(keep)
    return _Soup(region, junction_chart(b, child, b.mesh.vertices[faces[region]].reshape(-1, 3), zeta[region].ravel()))


def _junction_soup(b: ClassModel, child: int) -> _Soup:
    """b's faces of ``child`` and its parent in their junction band, in the band chart."""
    return _band_soup(b, int(child), (int(child), int(b.body.parents[child])))


def _spread_over_collars(
    b: ClassModel, part: int, holes: list, face: np.ndarray, weights: np.ndarray, residual: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Re-map the images that fall into the collar of one of b's extra parts ``holes`` (children of
    ``part`` that class A lacks) or into the patch that part covers.

    An image (``face``, ``weights``) on b's part with chart residual ``residual`` (> 0 where A's
    chart point lies on the patch, beyond the rim) gets a depth ``sigma = zeta + residual *
    r_part / (ZONE_WIDTH * r_hole)`` (zeta of the image, :func:`junction_coordinate`; -1 at the
    collar's outer edge, 0 at the rim, > 0 on the patch). Depths in (-1, max] are mapped linearly
    onto (-1, -COLLAR_GAP] and located in the hole's band chart at the image's angle around the
    hole's bone, among b's faces of the hole's junction band: continuous at the collar's outer edge and monotone in
    depth, so A's surface under the extra part is spread over B's collar instead of being pressed
    onto its rim. Returns the updated (face, weights, distance)."""
    faces = b.mesh.faces
    corners = faces[face]
    zeta = np.stack(
        [(junction_coordinate(b, h, corners.ravel()).reshape(-1, 3) * weights).sum(axis=1) for h in holes], axis=1
    )
    nearest = zeta.argmax(axis=1)
    depth = zeta[np.arange(len(face)), nearest]
    face, weights, residual = face.copy(), weights.copy(), residual.copy()
    points = (b.mesh.vertices[corners] * weights[:, :, None]).sum(axis=1)
    for k, h in enumerate(holes):
        sel = np.flatnonzero((nearest == k) & (depth > -1.0))
        if len(sel) == 0:
            continue
        sigma = depth[sel] + residual[sel] * b.body.ra[part] / (ZONE_WIDTH * b.body.ra[h])
        top = max(float(sigma.max()), 0.0)
        squeezed = -1.0 + (sigma + 1.0) * (1.0 - COLLAR_GAP) / (top + 1.0)
        collar = _junction_soup(b, h)
        if len(collar):
            query = junction_chart(b, h, points[sel], squeezed)
            face[sel], weights[sel], residual[sel] = collar.closest(query)
    return face, weights, residual


def template_correspondence(a: ClassModel, b: ClassModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Dense map from the template vertices of class ``a`` to points on class ``b``'s template.

    A vertex of part p (label = argmin of the part fields) is mapped to the point of b with the same
    position in a shared chart, found by a closest-point query among b's faces in chart space (so
    the barycentric weights are those of b's piecewise-linear chart):

    - in the junction band of a part c that both classes have (|zeta| < 1, :func:`junction_coordinate`;
      c = p next to p's parent, or a child c of p that has the same parent on b), in c's band chart
      (:func:`junction_chart`) among b's faces of c and its parent: zeta is preserved, so the part
      boundary maps onto the part boundary and each side onto the same side;
    - elsewhere, in p's normalised capsule chart (:meth:`ClassModel.chart`) among b's faces of p;
      images in the collar of a part of b that a lacks (the centaur's human torso on the barrel, a
      tail, horns), or beyond its rim, are then spread over that collar (:func:`_spread_over_collars`).

    Returns:
        face: (V_a,) int64 face of b (-1 where the vertex's part does not exist on b).
        weights: (V_a, 3) barycentric weights in b's face-column order (zero rows where -1).
        distance: (V_a,) chart-space distance from the query to b's chart mesh (~0 where the chart
            region of b covers the query); NaN where -1.
    """
    n = a.mesh.n_vertices
    face = np.full(n, -1, dtype=np.int64)
    weights = np.zeros((n, 3))
    distance = np.full(n, np.nan)
    a_names, b_names = a.spec.part_names, b.spec.part_names
    b_index = {name: i for i, name in enumerate(b_names)}

    def b_parent(part: int) -> str | None:
        q = b.body.parents[part]
        return None if q < 0 else b_names[q]

    for pa, name in enumerate(a_names):  # loop over parts (~25), vectorised inside
        source = np.flatnonzero(a.labels == pa)
        pb = b_index.get(name)
        if pb is None or len(source) == 0:
            continue
        # junctions this part takes part in, present on both classes: (child on a, child on b)
        junctions = []
        if a.body.parents[pa] >= 0 and b.body.parents[pb] >= 0:
            junctions.append((pa, pb))
        for c in np.flatnonzero(a.body.parents == pa):
            cb = b_index.get(a_names[c])
            if cb is not None and b_parent(cb) == name:
                junctions.append((c, cb))
        junctions = [(c, cb) for c, cb in junctions if len(_junction_soup(b, cb))]
        chart_of = np.full(len(source), -1)
        if junctions:
            zeta = np.column_stack([junction_coordinate(a, c, source) for c, _ in junctions])
            best = np.abs(zeta).argmin(axis=1)
            inside = np.abs(zeta[np.arange(len(source)), best]) < 1.0
            chart_of[inside] = best[inside]
        holes = [h for h in np.flatnonzero(b.body.parents == pb) if b_names[h] not in a_names]
        for j in np.unique(chart_of):
            rows = source[chart_of == j]
            if j < 0:
                f, w, d = _part_soup(b, pb).closest(a.chart(a.mesh.vertices[rows], pa))
                if holes:
                    f, w, d = _spread_over_collars(b, pb, holes, f, w, d)
            else:
                ca, cb = junctions[j]
                zeta_a = junction_coordinate(a, ca, rows)
                query = junction_chart(a, ca, a.mesh.vertices[rows], zeta_a)
                f, w, d = _junction_soup(b, cb).closest(query)
            face[rows] = f
            weights[rows] = w
            distance[rows] = d
    return face, weights, distance


# --- writing -----------------------------------------------------------------------------------


def format_off(vertices: np.ndarray, faces: np.ndarray) -> str:
    """OFF text: header, ``nV nF 0``, vertices with 6 decimals, faces ``3 i j k``."""
    v = np.asarray(vertices, dtype=np.float64) + 0.0  # +0.0 turns -0.0 into 0.0
    f = np.asarray(faces, dtype=np.int64)
    return (
        f"OFF\n{len(v)} {len(f)} 0\n"
        + ("%.6f %.6f %.6f\n" * len(v)) % tuple(v.ravel())
        + ("3 %d %d %d\n" * len(f)) % tuple(f.ravel())
    )


def format_corres(face: np.ndarray, weights: np.ndarray) -> str:
    """Correspondence text: ``face w1 w2 w3`` per source vertex (``-1 0.000000 0.000000 0.000000``)."""
    rows = np.column_stack([face.astype(np.float64), weights + 0.0])
    return ("%d %.6f %.6f %.6f\n" * len(rows)) % tuple(rows.ravel())


def _write(path: Path, text: str | bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(text, str):
        path.write_text(text)
    else:
        path.write_bytes(text)


def _npy_bytes(array: np.ndarray) -> bytes:
    import io

    buf = io.BytesIO()
    np.save(buf, array, allow_pickle=False)
    return buf.getvalue()


def _write_annotations(root: Path, models: dict[str, ClassModel]) -> None:
    nodes = [spec.node for spec in CLASSES]
    index = {n: i for i, n in enumerate(nodes)}
    adj = np.zeros((len(nodes), len(nodes)), dtype=np.int64)
    for u, v in TREE_EDGES:
        adj[index[u], index[v]] = adj[index[v], index[u]] = 1
    lines = ["," + ",".join(nodes)] + [n + "," + ",".join(map(str, row)) for n, row in zip(nodes, adj)]
    _write(root / "config" / "adjacency_matrix.csv", "\n".join(lines) + "\n")

    rows = ["dataset,template,split,partial_full_template,partial_full_dataset"]
    rows += [f"{s.dataset}_{s.name},{s.template},-,{s.template},{s.dataset}" for s in CLASSES]
    _write(root / "config" / "templates_all.csv", "\n".join(rows) + "\n")

    chir = ["dataset,annotated_template"]
    for node in CHIRALITY_TEMPLATES:
        spec = models[node].spec
        chir.append(f"{spec.dataset}_{spec.name},{spec.template}")
        left = (models[node].mesh.vertices[:, 0] > 0).astype(np.int64)
        _write(root / "precomputed_chirality_templates" / f"{node}.txt", "\n".join(map(str, left)) + "\n")
    _write(root / "config" / "templates_chirality_all.csv", "\n".join(chir) + "\n")

    for model in models.values():
        _write(root / "corres_comp" / "default_faces" / f"{model.spec.template}.npy", _npy_bytes(model.mesh.faces))

    for u, v in TREE_EDGES:
        for src, dst in ((u, v), (v, u)):
            a, b = models[src], models[dst]
            sa, sb = edge_edits(a.spec, b.spec)
            face, weights, _ = template_correspondence(a, b)
            _write(
                root / "precomputed_corr_templates" / f"{src}{sa}_{dst}{sb}_corres.txt", format_corres(face, weights)
            )


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _is_collection(path: Path) -> bool:
    manifest = path / MANIFEST
    if not manifest.is_file():
        return False
    try:
        return json.loads(manifest.read_text()).get("generator") == "becos.sources.synthetic"
    except (OSError, ValueError):
        return False


def poses_at_fraction(fraction: float) -> dict[str, int]:
    """Shapes per class (key ``<dataset>_<class>``) at ``fraction`` of the BeCoS-size collection:
    ``max(1, floor(fraction * FULL_SCALE_POSES[key] + 0.5))`` (half rounds up; every class keeps its
    template). ``fraction`` in (0, 1]; 1/16 gives 161 shapes, 1 gives 2,537."""
    if not (isinstance(fraction, (int, float, np.integer, np.floating)) and 0 < fraction <= 1):
        raise ConfigError(
            f"synthetic collection: fraction must be a number in (0, 1] (e.g. 0.0625 for 1/16), got {fraction!r}"
        )
    return {key: max(1, int(math.floor(fraction * n + 0.5))) for key, n in FULL_SCALE_POSES.items()}


def generate_collection(
    out_dir: str | Path, seed: int = 0, poses_per_class: int = 4, fraction: float | None = None
) -> Path:
    """Generate the synthetic collection into ``out_dir`` (the layout: docs/design/data.md).

    Deterministic: the same (seed, poses_per_class, fraction) gives byte-identical files. The seed
    changes the poses only (templates, annotations and pose 0 are seed-independent), and a class's
    pose k is the same at every pose count. Atomic: everything is written to a temporary folder
    beside ``out_dir`` and renamed into place; an existing synthetic collection at ``out_dir`` is
    replaced, any other non-empty folder is refused.

    Args:
        out_dir: destination folder.
        seed: pose seed (non-negative integer).
        poses_per_class: shapes per class (1-20); 13 classes, so 52 shapes at the default 4.
        fraction: instead of ``poses_per_class``, that fraction of the BeCoS-size collection
            (:data:`FULL_SCALE_POSES`, :func:`poses_at_fraction`), in (0, 1]. The manifest then
            records ``fraction`` and ``poses_per_class`` as ``{<dataset>_<class>: count}``.

    Returns:
        ``out_dir`` as a resolved Path.

    Raises:
        ConfigError: bad arguments, or ``out_dir`` is a non-empty folder that is not a collection.
    """
    out_dir = Path(out_dir).resolve()
    poses = _poses(seed, poses_per_class, fraction)
    if out_dir.exists() and (not out_dir.is_dir() or (any(out_dir.iterdir()) and not _is_collection(out_dir))):
        raise ConfigError(
            f"{out_dir} exists and is not a synthetic collection (no {MANIFEST}); refusing to "
            f"overwrite it. Fix: choose an empty or new folder"
        )
    with atomic_folder(out_dir) as tmp:  # one job writes the collection
        models = {spec.node: build_class(spec.dataset, spec.name) for spec in CLASSES}
        for spec in CLASSES:
            ds = DATASETS[spec.dataset]
            model = models[spec.node]
            for k in range(poses[f"{spec.dataset}_{spec.name}"]):
                verts = ds.to_file_frame(model.pose(int(seed), k))
                _write(tmp / "data" / ds.folder_name / f"{spec.name}{k}.off", format_off(verts, model.mesh.faces))
        _write_annotations(tmp / "annotations", models)
        manifest = _manifest(tmp, models, seed, poses_per_class, poses, fraction)
        _write(tmp / MANIFEST, json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    return out_dir


def _poses(seed, poses_per_class, fraction) -> dict[str, int]:
    """Shapes per class, ``{<dataset>_<class>: count}``, of :func:`generate_collection`'s arguments
    (checked; a bad one is a ConfigError)."""
    if not (isinstance(seed, (int, np.integer)) and seed >= 0):
        raise ConfigError(f"synthetic collection: seed must be a non-negative integer, got {seed!r}")
    if fraction is not None:
        return poses_at_fraction(fraction)
    if not (isinstance(poses_per_class, (int, np.integer)) and 1 <= poses_per_class <= 20):
        raise ConfigError(f"synthetic collection: poses_per_class must be an integer in 1..20, got {poses_per_class!r}")
    return {f"{s.dataset}_{s.name}": int(poses_per_class) for s in CLASSES}


def _manifest(tmp: Path, models: dict, seed: int, poses_per_class: int, poses: dict, fraction: float | None) -> dict:
    """The collection's manifest: generator, seed, poses per class (``poses_per_class``, or ``poses`` at a
    ``fraction``), datasets, classes and the sha256 of every file written so far under ``tmp``."""
    files = sorted(p for p in tmp.rglob("*") if p.is_file())
    manifest = {
        "generator": "becos.sources.synthetic",
        "format_version": FORMAT_VERSION,
        "seed": int(seed),
        "poses_per_class": int(poses_per_class) if fraction is None else poses,
        "datasets": {
            n: {"folder_name": d.folder_name, "scale": d.scale, "rot": list(d.rot)} for n, d in DATASETS.items()
        },
        "classes": [
            {
                "dataset": s.dataset,
                "name": s.name,
                "category": s.category,
                "template": s.template,
                "n_vertices": models[s.node].mesh.n_vertices,
            }
            for s in CLASSES
        ],
        "files": {p.relative_to(tmp).as_posix(): _sha256(p) for p in files},
    }
    if fraction is not None:
        manifest["fraction"] = float(fraction)
    return manifest
