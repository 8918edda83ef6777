"""A stand-in data root for the whole published BeCoS benchmark (test and benchmark support).

Only TOSCA's meshes are in ``../shared``; FAUST, SCAPE, KIDS, SMAL, SHREC'20 and DeformingThings4D
need the user's own downloads. To plan the full benchmark anyway (all 8 dataset entries, three
settings: ``benchmarks/workflow.py --full-plan``, ``tests/test_fullplan.py``), :func:`build_standin_tree`
writes a small, valid mesh at every file path the published pair lists name
(``config/pairings_original_{full_full,partial_partial}.pkl``, field ``file_path``) and at every DT4D
frame of ``data/info_dt4d_{animals,humanoids}.json`` (4 frames there are used by no published pair,
but the registry lists the whole info file): 2,537 files below ``<out>/data``.

Which meshes are real-sized. The dataset check (:func:`becos.sources.check.check_datasets`) compares every
network edge file with the template meshes it connects: one row per source-template vertex, face
indices below the target template's face count. So each template shape gets its real vertex count
(the edge files' row count; FAUST ``tr_reg_000``: 6,890), shared by DT4D classes with one
triangulation (``same_triangulation_dt4d_animals.txt``), and enough faces: its real faces where the
annotation folder ships them (``corres_comp/default_faces``, 45 templates; some real templates have
more than the ``2V - 4`` faces of a closed genus-0 mesh), over distinct points on the unit sphere;
else the bipyramid below. Every other shape is a 10-vertex bipyramid: nothing but the remesh and
chunk jobs reads a mesh's geometry, and planning runs none of them. The shapes are not the real ones
(test support, not data).

Bipyramid: over a regular ``n``-gon, ``V = n + 2`` vertices, ``F = 2n = 2V - 4`` triangles; closed,
manifold, genus 0, outward-oriented, within the unit ball (unitless). Files are ASCII OFF, OBJ or
binary little-endian PLY, as the dataset's ``file_type`` says: about 90 MB in 2-3 s.

Kept in ``tests/`` (imported by ``benchmarks/workflow.py`` from there): it is a fixture for
planning and checks, not a becos feature. ``becos synthetic`` is the feature that makes real,
runnable data.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

PUBLISHED_SETTINGS = ("full_full", "partial_partial")
DATASETS = ("faust", "scape", "kids", "tosca", "smal", "shrec20", "dt4d_animal", "dt4d_human")
"""The 8 registry entries of the published benchmark (``config/datasets/<name>.yaml``)."""
SHREC20_MODELS = (
    *("bison", "camel_a", "cow", "dog", "elephant_a", "pig", "elephant_b"),
    *("giraffe_b", "leopard", "giraffe_a", "rhino", "bear", "camel_b", "hippo"),
)
"""The 14 SHREC'20 models (``SHREC20b_hires/models/<name>.obj``), written out here rather than read from
``shrec20.yaml``, so the tests check that file's splits against a list of their own."""
PUBLISHED_SHAPES = 2533
"""Distinct shapes named by the two published pair lists."""
PUBLISHED_PAIRS = {"train": 10185, "val": 137, "test": 142}
"""Pairs per split of each published list (full_full and partial_partial)."""
SMALL_VERTICES = 10
"""Vertex count of a shape whose count nothing constrains."""


def bipyramid(n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """The bipyramid over a regular ``(n_vertices - 2)``-gon in the xz-plane, apexes at y = +-1.

    Returns:
        vertices: (V, 3) float64, unit circle plus the two apexes (rows: ring, top, bottom).
        faces: (2V - 4, 3) int64, counter-clockwise seen from outside.
    """
    n = int(n_vertices) - 2
    if n < 3:
        raise ValueError(f"a bipyramid needs at least 5 vertices, got {n_vertices}")
    angle = 2.0 * np.pi * np.arange(n) / n
    ring = np.stack([np.cos(angle), np.zeros(n), np.sin(angle)], axis=1)
    vertices = np.concatenate([ring, [[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]]])
    i = np.arange(n)
    j = (i + 1) % n
    top = np.stack([i, np.full(n, n), j], axis=1)  # ring i -> apex -> ring i+1: outward (+y side)
    bottom = np.stack([j, np.full(n, n + 1), i], axis=1)
    return vertices, np.concatenate([top, bottom]).astype(np.int64)


def mesh_bytes(vertices: np.ndarray, faces: np.ndarray, file_type: str) -> bytes:
    """``(V, 3)`` vertices and ``(F, 3)`` 0-based faces as an ``off``, ``obj`` or ``ply`` file's bytes
    (text formatting by one C-level ``%`` over the whole array, not a loop per row)."""
    v, f = len(vertices), len(faces)
    coords = tuple(np.round(vertices, 6).ravel().tolist())
    if file_type == "off":
        body = ("%.6f %.6f %.6f\n" * v) % coords + ("3 %d %d %d\n" * f) % tuple(faces.ravel().tolist())
        return f"OFF\n{v} {f} 0\n{body}".encode()
    if file_type == "obj":
        body = ("v %.6f %.6f %.6f\n" * v) % coords + ("f %d %d %d\n" * f) % tuple((faces + 1).ravel().tolist())
        return body.encode()
    if file_type == "ply":
        header = (
            f"ply\nformat binary_little_endian 1.0\nelement vertex {v}\nproperty float x\nproperty float y\n"
            f"property float z\nelement face {f}\nproperty list uchar int vertex_indices\nend_header\n"
        )
        rows = np.zeros(f, dtype=[("k", "u1"), ("i", "<i4", (3,))])
        rows["k"], rows["i"] = 3, faces
        return header.encode() + vertices.astype("<f4").tobytes() + rows.tobytes()
    raise ValueError(f"unknown mesh file type {file_type!r} (off, obj or ply)")


def published_file_paths(annotations: Path) -> dict[tuple[str, str], str]:
    """``(dataset, name) -> file_path`` of every shape of the two published pair lists (2,533), the
    path relative to the reference checkout (``data/MPI-FAUST/training/registrations/tr_reg_015.ply``)."""
    from becos.build.published import load_published

    out: dict[tuple[str, str], str] = {}
    for setting in PUBLISHED_SETTINGS:
        for split in load_published(Path(annotations) / "config" / f"pairings_original_{setting}.pkl"):
            for pair in split:
                for shape in pair:
                    out[(str(shape["org_dataset"]), str(shape["name"]))] = os.path.normpath(str(shape["file_path"]))
    return out


@dataclass(frozen=True)
class TemplateNeeds:
    """What the dataset check demands of one template mesh.

    Attributes:
        n_vertices: rows of the template's outgoing edge files (shared across same-triangulation classes).
        min_faces: one more than the largest face index of its incoming edge files (0 if none).
        faces: (F, 3) int64 real faces from the annotation folder's ``corres_comp/default_faces``, or None.
    """

    n_vertices: int
    min_faces: int
    faces: np.ndarray | None = field(default=None, repr=False)


def template_needs(annotations: Path, cache_dir: Path | None = None) -> dict[tuple[str, str], TemplateNeeds]:
    """``(dataset, template name) -> TemplateNeeds`` of every network template with an edge file.

    Raises:
        ValueError: edge files (or identity partners) of one template disagree on its vertex count, or its
            default faces do not index exactly that many vertices.
    """
    import networkx as nx

    from becos.sources.annotations import AnnotationSource

    source = AnnotationSource(annotations, cache_dir=cache_dir)
    rows: dict[str, int] = {}
    max_face: dict[str, int] = {}
    identity = nx.Graph()
    identity.add_nodes_from(source.graph.nodes)
    for edge in source.edge_sources():
        if edge.kind == "identity":
            identity.add_edge(edge.source, edge.target)
            continue
        report = source.edge_report(edge.source, edge.target)
        n = int(report["rows"])
        if rows.setdefault(edge.source, n) != n:
            raise ValueError(
                f"edge files out of template {edge.source} disagree on its vertex count "
                f"({rows[edge.source]} vs {n}, {edge.path})"
            )
        max_face[edge.target] = max(max_face.get(edge.target, -1), int(report["max_face"]))
    out: dict[tuple[str, str], TemplateNeeds] = {}
    for group in nx.connected_components(identity):
        counts = {rows[node] for node in group if node in rows}
        if len(counts) > 1:
            raise ValueError(f"same-triangulation templates {sorted(group)} have edge files with {sorted(counts)} rows")
        if not counts:
            continue
        n = counts.pop()
        min_faces = max(max_face.get(node, -1) for node in group) + 1  # one triangulation for the group
        for node in group:
            dataset, template = source.node_template(node)
            faces = source.default_faces(template, dataset)
            if faces is not None and int(faces.max()) + 1 != n:
                raise ValueError(f"default faces of {node} index {int(faces.max()) + 1} vertices, its edge files {n}")
            out[(dataset, template)] = TemplateNeeds(n, min_faces, faces)
    return out


def sphere_points(n: int) -> np.ndarray:
    """(n, 3) float64 distinct points on the unit sphere (Fibonacci spiral)."""
    k = np.arange(n) + 0.5
    y = 1.0 - 2.0 * k / n
    r = np.sqrt(1.0 - y * y)
    phi = np.pi * (3.0 - np.sqrt(5.0)) * k
    return np.stack([r * np.cos(phi), y, r * np.sin(phi)], axis=1)


def template_mesh(key: tuple[str, str], needs: TemplateNeeds) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of a template's stand-in: its real faces (default faces) over sphere points
    where the annotation folder ships them, else the bipyramid with its vertex count.

    Raises:
        ValueError: the mesh would have fewer faces than the edge files index.
    """
    if needs.faces is not None:
        vertices, faces = sphere_points(needs.n_vertices), np.asarray(needs.faces, dtype=np.int64)
    else:
        vertices, faces = bipyramid(needs.n_vertices)
    if len(faces) < needs.min_faces:
        raise ValueError(
            f"stand-in template {key[0]}/{key[1]}: {len(faces)} faces, but its edge files index {needs.min_faces}"
        )
    return vertices, faces


@dataclass(frozen=True)
class StandinTree:
    """A written stand-in data root.

    Attributes:
        data_dir: the data root (config key ``data_dir``): ``<out>/data``.
        annotations: the BeCoS annotation folder it stands beside (config key ``annotations``).
        files: ``(dataset, name) -> mesh file`` of every written shape (2,537).
        published: the ``(dataset, name)`` of the published pair lists (2,533).
        template_vertices: ``(dataset, name) -> V`` of the shapes written with their real vertex count.
        seconds: wall time of the writing.
    """

    data_dir: Path
    annotations: Path
    files: dict[tuple[str, str], Path] = field(repr=False)
    published: frozenset = field(repr=False)
    template_vertices: dict[tuple[str, str], int] = field(repr=False)
    seconds: float = 0.0


def standin_shapes(
    annotations: Path, published: dict[tuple[str, str], str] | None = None
) -> dict[tuple[str, str], str]:
    """``(dataset, name) -> path relative to the reference checkout`` of every stand-in shape: the
    published ones (``published``: :func:`published_file_paths`, read if not given), plus DT4D frames
    of the info files that no published pair uses (at the path the registry lists them)."""
    from becos.sources.datasets import DatasetSpec

    shapes = dict(published_file_paths(annotations) if published is None else published)
    for dataset in ("dt4d_animal", "dt4d_human"):
        spec = DatasetSpec.load(dataset)
        info = json.loads((Path(annotations) / "data" / spec.info_file).read_text(encoding="utf-8"))
        for cls, actions in info.items():
            for action, frames in actions.items():
                for frame in frames:
                    name = f"{cls}/{action}{int(frame):03d}"
                    shapes.setdefault((dataset, name), f"data/{spec.folder}/{name}.{spec.file_type}")
    return shapes


def build_standin_tree(out: str | Path, annotations: str | Path, cache_dir: str | Path | None = None) -> StandinTree:
    """Write the stand-in meshes below ``out/data`` (see the module docstring); returns the tree.

    ``annotations``: the BeCoS annotation folder (``../shared/unpack`` prints it). ``cache_dir``: the
    edge-file cache (:class:`becos.sources.annotations.AnnotationSource`). Existing files are overwritten.
    """
    start = time.perf_counter()
    out, annotations = Path(out), Path(annotations)
    published = published_file_paths(annotations)
    shapes = standin_shapes(annotations, published)
    needs = template_needs(annotations, cache_dir)
    small: dict[str, bytes] = {}
    files: dict[tuple[str, str], Path] = {}
    written_counts: dict[tuple[str, str], int] = {}
    folders: set[Path] = set()
    for key, rel in sorted(shapes.items()):
        if not rel.startswith("data/"):
            raise ValueError(f"published file path {rel!r} of {key} is not below data/")
        path = out / rel
        file_type = path.suffix.lstrip(".").lower()
        if key in needs:
            data = mesh_bytes(*template_mesh(key, needs[key]), file_type)
            written_counts[key] = needs[key].n_vertices
        else:
            if file_type not in small:
                small[file_type] = mesh_bytes(*bipyramid(SMALL_VERTICES), file_type)
            data = small[file_type]
        if path.parent not in folders:
            path.parent.mkdir(parents=True, exist_ok=True)
            folders.add(path.parent)
        path.write_bytes(data)
        files[key] = path
    return StandinTree(
        out / "data", annotations, files, frozenset(published), written_counts, round(time.perf_counter() - start, 2)
    )
