"""The synthetic collection: classes built and posed, template correspondences, files on disk.

Layout written by :func:`generate_collection` (``OUT`` = its ``out_dir``)::

    OUT/synthetic.json                       what was generated (seed, poses, datasets, sha256 of every file)
    OUT/data/<folder_name>/<class><k>.off    shapes, k = 0 .. poses_per_class-1 (k = 0 is the template)
    OUT/annotations/                          a folder shaped like the BeCoS reference checkout:
        config/adjacency_matrix.csv           the template network (a tree over <dataset>_<class>0)
        config/templates_all.csv              one row per class, key <dataset>_<class>
        config/templates_chirality_all.csv    the templates that carry left/right labels
        precomputed_corr_templates/<A>[_edit]_<B>[_edit]_corres.txt   one file per directed edge
        corres_comp/default_faces/<template>.npy                        int64 (F, 3) template faces
        precomputed_chirality_templates/<dataset>_<template>.txt        one 0/1 per template vertex

Datasets (the file frames differ on purpose, to exercise the registry's scale and rotation):

- ``synthy``: files in the common frame (metres, +y up, facing +z): scale 1, rot [0, 0, 0].
- ``synthz``: files z-up in centimetres and offset, like TOSCA: scale 0.01, rot [90, 0, 0] (the
  registry maps ``(V * scale - mean) @ R`` to the common frame, R = Rx(90) in row-vector form).

Ground truth between classes comes from the construction: both templates are meshes of bodies whose
parts share canonical capsules (:meth:`becos.synthetic.bodies.Body.chart`), the shared parameter
domain. A template vertex of class A on part p is mapped to the point of class B's surface with the
same chart position, located in B's triangulation by a closest-point query among B's part-p faces
*in chart space* (so the barycentric weights are those of B's piecewise-linear chart). Two
refinements make part boundaries meet: each class's chart is rescaled per angle so its part region
starts exactly at its boundary with the parent (:attr:`ClassModel.extents`), and next to a child's
junction both sides use the child's chart (:data:`ZONE_WIDTH`). Vertices on parts B lacks (horns,
tail, the centaur's other half) get ``-1 0 0 0``.

Measured (tests/test_synthetic.py): 98.9 % of matched template vertices land on the same body region
(torso, head, each limb, tail, horn; dominant vertex of the image face), 98.0 % on the same bone
segment; the misses sit at part junctions and where a part of B covers A's surface (the centaur's
human torso over the pony's withers, horn bases).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from becos.errors import ConfigError
from becos.geometry import barycentric_coordinates
from becos.mesh import TriMesh
from becos.synthetic.bodies import (CHART_BINS, CLASSES, PART_GROUPS, Body, ClassSpec, chart_profile, class_spec,
                                    draw_pose, pose_vertices, skinning_weights)
from becos.synthetic.meshing import mesh_body

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
        "synthy", "synthy-off", 1.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 7000,
        {"human": {"train": ["alba"], "val": ["brute"], "test": ["cyra"]},
         "four-legged": {"train": ["hound"], "val": ["goat"], "test": ["tapir"]}}),
    "synthz": SyntheticDataset(
        "synthz", "synthz-off", 0.01, (90.0, 0.0, 0.0), (40.0, -25.0, 10.0), 14000,
        {"human": {"train": ["elin"], "val": ["dario"], "test": ["faun"]},
         "four-legged": {"train": ["pony"], "val": ["lynx"], "test": ["ram"]}}),
}

TREE_EDGES: tuple[tuple[str, str], ...] = (
    ("synthy_alba0", "synthy_brute0"), ("synthy_alba0", "synthy_cyra0"), ("synthy_alba0", "synthz_elin0"),
    ("synthz_elin0", "synthz_dario0"), ("synthz_elin0", "synthz_faun0"),
    ("synthy_hound0", "synthy_goat0"), ("synthy_hound0", "synthy_tapir0"), ("synthy_hound0", "synthz_lynx0"),
    ("synthz_lynx0", "synthz_pony0"), ("synthz_pony0", "synthz_ram0"),
    ("synthz_centaur0", "synthz_elin0"), ("synthz_centaur0", "synthz_pony0"),
)
"""The template network: undirected edges of a tree over all class templates (humanoids and
four-legged classes are connected only through the centaur, as in BeCoS)."""

CHIRALITY_TEMPLATES: tuple[str, ...] = ("synthy_alba0", "synthy_hound0", "synthz_centaur0")
"""Templates that carry left/right labels (1 = anatomical left = +x in the common frame)."""

ZONE_WIDTH = 0.6
"""A vertex of part p is mapped in the chart of p's child c where f_c - f_p < ZONE_WIDTH * (c's radius
at its joint): next to the junction, on either side, one chart (c's) is used by both classes."""

SKINNING_SIGMA = 0.012
"""Width (metres, at unit class size) of the skinning softmax."""


# --- classes -----------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class ClassModel:
    """A built class: its body, its template mesh (rest pose) and per-vertex construction data.

    Attributes:
        spec: the :class:`~becos.synthetic.bodies.ClassSpec`.
        body: array form of its parts.
        mesh: template (pose 0) mesh in the common frame (metres, +y up, facing +z), before the
            vertical shift that puts the feet on y = 0 (poses and files have that shift).
        labels: (V,) int64 part index (into ``spec.part_names``) of each vertex.
        face_labels: (F,) int64 part index of each face (the part whose field is smallest at its centroid).
        weights: (V, P) skinning weights.
        extents: (P, 2, CHART_BINS) per part and angle, the axial chart coordinates mapped to 0 and
            to CANONICAL_LENGTH by :meth:`~becos.synthetic.bodies.Body.normalised_chart`: the
            boundary with the parent (exact, from the label boundary's crossings of mesh edges; the
            region's lowest point for the root) and the region's highest point.
        part_values: (V, P) part field values at the vertices (metres).
    """

    spec: ClassSpec
    body: Body
    mesh: TriMesh
    labels: np.ndarray
    face_labels: np.ndarray
    weights: np.ndarray
    extents: np.ndarray
    part_values: np.ndarray

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


@lru_cache(maxsize=None)
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
            raise ValueError(f"part {body.names[p]} of {spec.node} has no faces (buried inside its neighbours); "
                             f"the class definition must make every part visible")
        extents[p] = body.chart_extent(mesh.vertices[np.unique(faces)], p)
        mine = crossings[crossing_part == p]
        if len(mine):
            extents[p, 0] = chart_profile(body.chart(mine, p))
    return ClassModel(spec, body, mesh, labels, face_labels, weights, extents, part_values)


def _parent_boundary_points(body: Body, mesh: TriMesh, labels: np.ndarray, values: np.ndarray):
    """Points where the boundary between each part and its parent crosses mesh edges.

    On an edge whose ends are labelled child c and parent q, the crossing is where the linear
    interpolation of f_c - f_q vanishes. Returns (K, 3) points and (K,) the child part of each.
    """
    F = mesh.faces
    edges = np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1), axis=0)
    la, lb = labels[edges[:, 0]], labels[edges[:, 1]]
    parents = body.parents
    a_child = parents[la] == lb          # end 0 is the child
    b_child = parents[lb] == la          # end 1 is the child
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


def template_correspondence(a: ClassModel, b: ClassModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Dense map from the template vertices of class ``a`` to points on class ``b``'s template.

    Returns:
        face: (V_a,) int64 face of b (-1 where the vertex's part does not exist on b).
        weights: (V_a, 3) barycentric weights in b's face-column order (zero rows where -1).
        distance: (V_a,) chart-space distance from the vertex's chart position to b's chart mesh
            (unit = capsule radius; ~0 inside b's part, larger where a's part extends beyond b's
            part boundary in the chart); NaN where -1.
    """
    import igl

    n = a.mesh.n_vertices
    face = np.full(n, -1, dtype=np.int64)
    weights = np.zeros((n, 3))
    distance = np.full(n, np.nan)
    b_index = {name: i for i, name in enumerate(b.spec.part_names)}
    for pa, name in enumerate(a.spec.part_names):  # loop over parts (~25), vectorised inside
        source = np.flatnonzero(a.labels == pa)
        pb = b_index.get(name)
        if pb is None or len(source) == 0:
            continue
        # each source vertex is mapped in the chart of its own part, or, in the zone next to a
        # child's junction, in the chart of that child (whose boundary is normalised exactly)
        chart_of = np.full(len(source), pa)
        children = [c for c in np.flatnonzero(a.body.parents == pa) if a.spec.part_names[c] in b_index]
        if children:
            children = np.array(children)
            gap = ((a.part_values[source][:, children] - a.part_values[source, pa][:, None])
                   / (ZONE_WIDTH * a.body.ra[children]))
            best = gap.argmin(axis=1)
            inside = gap[np.arange(len(source)), best] < 1.0
            chart_of[inside] = children[best[inside]]
        b_faces_all = b.region(pb)
        for ca in np.unique(chart_of):
            rows = source[chart_of == ca]
            cb = b_index[a.spec.part_names[ca]]
            b_faces = b_faces_all
            if ca != pa:  # B's faces of part p near its junction with the same child
                corner_gap = ((b.part_values[b.mesh.faces[b_faces], cb] - b.part_values[b.mesh.faces[b_faces], pb])
                              / (ZONE_WIDTH * b.body.ra[cb]))
                b_faces = b_faces[corner_gap.min(axis=1) < 2.0]
                if len(b_faces) == 0:
                    b_faces = b_faces_all
            query = a.chart(a.mesh.vertices[rows], ca)
            corners = b.mesh.vertices[b.mesh.faces[b_faces]].reshape(-1, 3)
            soup = b.chart(corners, cb)
            soup_faces = np.arange(len(soup), dtype=np.int64).reshape(-1, 3)
            tree = igl.AABB()
            tree.init(soup, soup_faces)
            sq, hit, closest = tree.squared_distance(soup, soup_faces, query)
            hit = np.asarray(hit, dtype=np.int64)
            tri = soup[soup_faces[hit]]
            face[rows] = b_faces[hit]
            weights[rows] = barycentric_coordinates(closest, tri[:, 0], tri[:, 1], tri[:, 2])
            distance[rows] = np.sqrt(np.maximum(sq, 0.0))
    return face, weights, distance


# --- writing -----------------------------------------------------------------------------------

def format_off(vertices: np.ndarray, faces: np.ndarray) -> str:
    """OFF text: header, ``nV nF 0``, vertices with 6 decimals, faces ``3 i j k``."""
    v = np.asarray(vertices, dtype=np.float64) + 0.0  # +0.0 turns -0.0 into 0.0
    f = np.asarray(faces, dtype=np.int64)
    return (f"OFF\n{len(v)} {len(f)} 0\n" + ("%.6f %.6f %.6f\n" * len(v)) % tuple(v.ravel())
            + ("3 %d %d %d\n" * len(f)) % tuple(f.ravel()))


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

    for node, model in models.items():
        _write(root / "corres_comp" / "default_faces" / f"{model.spec.template}.npy", _npy_bytes(model.mesh.faces))

    for u, v in TREE_EDGES:
        for src, dst in ((u, v), (v, u)):
            a, b = models[src], models[dst]
            sa, sb = edge_edits(a.spec, b.spec)
            face, weights, _ = template_correspondence(a, b)
            _write(root / "precomputed_corr_templates" / f"{src}{sa}_{dst}{sb}_corres.txt",
                   format_corres(face, weights))


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _is_collection(path: Path) -> bool:
    manifest = path / MANIFEST
    if not manifest.is_file():
        return False
    try:
        return json.loads(manifest.read_text()).get("generator") == "becos.synthetic"
    except (OSError, ValueError):
        return False


def generate_collection(out_dir: str | Path, seed: int = 0, poses_per_class: int = 4) -> Path:
    """Generate the synthetic collection into ``out_dir`` (see the module docstring for the layout).

    Deterministic: the same (seed, poses_per_class) gives byte-identical files. The seed changes the
    poses only (templates, annotations and pose 0 are seed-independent). Atomic: everything is
    written to a temporary folder beside ``out_dir`` and renamed into place; an existing synthetic
    collection at ``out_dir`` is replaced, any other non-empty folder is refused.

    Args:
        out_dir: destination folder.
        seed: pose seed (non-negative integer).
        poses_per_class: shapes per class (1-20); 13 classes, so 52 shapes at the default 4.

    Returns:
        ``out_dir`` as a resolved Path.

    Raises:
        ConfigError: bad arguments, or ``out_dir`` is a non-empty folder that is not a collection.
    """
    out_dir = Path(out_dir).resolve()
    if not (isinstance(seed, (int, np.integer)) and seed >= 0):
        raise ConfigError(f"synthetic collection: seed must be a non-negative integer, got {seed!r}")
    if not (isinstance(poses_per_class, (int, np.integer)) and 1 <= poses_per_class <= 20):
        raise ConfigError(f"synthetic collection: poses_per_class must be an integer in 1..20, got {poses_per_class!r}")
    if out_dir.exists() and (not out_dir.is_dir() or (any(out_dir.iterdir()) and not _is_collection(out_dir))):
        raise ConfigError(f"{out_dir} exists and is not a synthetic collection (no {MANIFEST}); refusing to "
                          f"overwrite it. Fix: choose an empty or new folder")
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out_dir.parent, prefix=f".{out_dir.name}.tmp-"))
    try:
        models = {spec.node: build_class(spec.dataset, spec.name) for spec in CLASSES}
        for spec in CLASSES:
            ds = DATASETS[spec.dataset]
            model = models[spec.node]
            for k in range(poses_per_class):
                verts = ds.to_file_frame(model.pose(int(seed), k))
                _write(tmp / "data" / ds.folder_name / f"{spec.name}{k}.off", format_off(verts, model.mesh.faces))
        _write_annotations(tmp / "annotations", models)
        files = sorted(p for p in tmp.rglob("*") if p.is_file())
        manifest = {
            "generator": "becos.synthetic",
            "format_version": FORMAT_VERSION,
            "seed": int(seed),
            "poses_per_class": int(poses_per_class),
            "datasets": {n: {"folder_name": d.folder_name, "scale": d.scale, "rot": list(d.rot)}
                         for n, d in DATASETS.items()},
            "classes": [{"dataset": s.dataset, "name": s.name, "category": s.category, "template": s.template,
                         "n_vertices": models[s.node].mesh.n_vertices} for s in CLASSES],
            "files": {p.relative_to(tmp).as_posix(): _sha256(p) for p in files},
        }
        _write(tmp / MANIFEST, json.dumps(manifest, indent=1, sort_keys=True) + "\n")
        os.chmod(tmp, 0o755)
        if out_dir.exists():
            old = Path(tempfile.mkdtemp(dir=out_dir.parent, prefix=f".{out_dir.name}.old-"))
            os.replace(out_dir, old / "collection")
            os.replace(tmp, out_dir)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out_dir
