"""The built-in synthetic collection (becos.synthetic): files, meshes, network, correspondences.

One collection is generated per test session (default arguments); a second one is generated in a
fresh process to check byte-identical output.
"""

from __future__ import annotations

import glob
import hashlib
import os
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import networkx as nx
import numpy as np
import pandas as pd
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from becos.errors import ConfigError
from becos.synthetic import (CHIRALITY_TEMPLATES, CLASSES, DATASETS, TREE_EDGES, body_part_labels,
                             generate_collection)
from becos.synthetic.bodies import semantic_part

REPO = Path(__file__).resolve().parents[1]
POSES = 4


def read_off(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) float64 vertices and (F, 3) int64 faces of an OFF file (fast, pandas)."""
    with open(path) as fh:
        assert fh.readline().strip() == "OFF"
        nv, nf, _ = map(int, fh.readline().split())
    table = pd.read_csv(path, sep=" ", header=None, skiprows=2, names=range(4), engine="c")
    vertices = table.iloc[:nv, :3].to_numpy(np.float64)
    faces = table.iloc[nv:nv + nf].to_numpy(np.float64)
    assert (faces[:, 0] == 3).all()
    return vertices, faces[:, 1:].astype(np.int64)


def read_corres(path: Path) -> tuple[np.ndarray, np.ndarray]:
    table = pd.read_csv(path, sep=" ", header=None, engine="c").to_numpy(np.float64)
    assert table.shape[1] == 4
    return table[:, 0].astype(np.int64), table[:, 1:]


@pytest.fixture(scope="session")
def collection(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("synthetic") / "collection"
    start = time.perf_counter()
    path = generate_collection(out, seed=0, poses_per_class=POSES)
    elapsed = time.perf_counter() - start
    print(f"\nsynthetic collection generated in {elapsed:.1f} s")
    assert elapsed < 60.0
    return path


def file_hashes(root: Path) -> dict[str, str]:
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def common_frame(dataset: str, vertices: np.ndarray) -> np.ndarray:
    return DATASETS[dataset].to_common_frame(vertices)


# --- files and determinism ---------------------------------------------------------------------

def test_layout_and_counts(collection):
    shapes = sorted((collection / "data").rglob("*.off"))
    assert len(shapes) == len(CLASSES) * POSES <= 60
    assert {c.dataset for c in CLASSES} == set(DATASETS) and len(DATASETS) >= 2
    categories = Counter(c.category for c in CLASSES)
    assert categories["human"] >= 3 and categories["four-legged"] >= 3 and categories["centaur"] >= 1
    for spec in CLASSES:
        assert spec.dataset.isalnum() and spec.dataset.islower() and "_" not in spec.dataset
        for k in range(POSES):
            assert (collection / "data" / DATASETS[spec.dataset].folder_name / f"{spec.name}{k}.off").is_file()
    # no class name is a prefix of another (the edge-file lookup globs "<ds>_<template>*")
    templates = [c.template for c in CLASSES]
    assert not any(a != b and b.startswith(a) for a in templates for b in templates)


def test_byte_identical_in_a_fresh_process(collection, tmp_path):
    second = tmp_path / "again"
    env = dict(os.environ, PYTHONHASHSEED="123")
    run = subprocess.run([sys.executable, "-m", "becos.synthetic", str(second), "--seed", "0", "--poses", str(POSES)],
                         capture_output=True, text=True, env=env, cwd=REPO)
    assert run.returncode == 0, run.stderr
    assert Path(run.stdout.strip()) == second.resolve()
    first_hashes, second_hashes = file_hashes(collection), file_hashes(second)
    n_files = len(CLASSES) * POSES + 3 + 2 * len(TREE_EDGES) + len(CLASSES) + len(CHIRALITY_TEMPLATES) + 1
    assert len(first_hashes) == n_files
    assert first_hashes == second_hashes
    assert not list(tmp_path.glob(".again.tmp-*"))  # the temporary folder was renamed into place


def test_refuses_to_overwrite_foreign_folder(tmp_path):
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("precious")
    with pytest.raises(ConfigError, match="not a synthetic collection"):
        generate_collection(foreign)
    assert (foreign / "thesis.tex").read_text() == "precious"
    with pytest.raises(ConfigError, match="poses_per_class"):
        generate_collection(tmp_path / "x", poses_per_class=0)


# --- meshes ------------------------------------------------------------------------------------

def mesh_topology(n_vertices: int, faces: np.ndarray) -> dict:
    """Closedness, orientation, manifoldness and components of a triangle mesh (vectorised)."""
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    undirected = np.sort(directed, axis=1)
    _, edge_count = np.unique(undirected, axis=0, return_counts=True)
    _, directed_count = np.unique(directed, axis=0, return_counts=True)
    adjacency = sp.coo_matrix((np.ones(len(directed)), (directed[:, 0], directed[:, 1])),
                              shape=(n_vertices, n_vertices))
    n_components = connected_components(adjacency, directed=False)[0]
    # vertex manifoldness: around each vertex the link edges (b, c) of its faces (v, b, c) form ONE cycle
    corners = np.concatenate([faces, faces[:, [1, 2, 0]], faces[:, [2, 0, 1]]])     # rows (v, b, c)
    keys = np.concatenate([corners[:, [0, 1]], corners[:, [0, 2]]])
    uniq, inverse = np.unique(keys, axis=0, return_inverse=True)
    m = len(corners)
    link = sp.coo_matrix((np.ones(m), (inverse.ravel()[:m], inverse.ravel()[m:])), shape=(len(uniq), len(uniq)))
    n_links = connected_components(link, directed=False)[0]
    return {
        "edges_in_two_faces": bool((edge_count == 2).all()),
        "oriented": bool((directed_count == 1).all()),
        "components": int(n_components),
        "vertex_manifold": n_links == len(np.unique(faces)) == n_vertices,
        "euler": n_vertices - len(edge_count) + len(faces),
    }


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    tri = vertices[faces]
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)


def test_meshes_closed_manifold_oriented_upright(collection):
    counts = {}
    for spec in CLASSES:
        labels, names = body_part_labels(spec.dataset, spec.name)
        region = np.array([semantic_part(n) for n in names])[labels]
        template_faces = None
        for k in range(POSES):
            verts, faces = read_off(collection / "data" / DATASETS[spec.dataset].folder_name / f"{spec.name}{k}.off")
            if template_faces is None:
                template_faces = faces
                topo = mesh_topology(len(verts), faces)
                assert topo == {"edges_in_two_faces": True, "oriented": True, "components": 1,
                                "vertex_manifold": True, "euler": 2}, (spec.name, topo)
                counts[spec.name] = len(verts)
                assert 5000 <= len(verts) <= 30000
            assert np.array_equal(faces, template_faces)           # one triangulation per class
            assert len(labels) == len(verts)
            common = common_frame(spec.dataset, verts)
            assert signed_volume(common, faces) > 0                 # outward normals
            y = common[:, 1]
            head = region == ("q_head" if spec.category == "four-legged" else "b_head")
            feet = np.isin(np.array(names)[labels], ["b_foot_l", "b_foot_r", "q_ffoot_l", "q_ffoot_r",
                                                     "q_hfoot_l", "q_hfoot_r"])
            assert y[head].mean() > y[feet].mean() + 0.3, (spec.name, k)
            assert y[feet].min() - y.min() < 0.05                   # feet at the bottom
            if spec.category != "human":                            # four-legged bodies face +z
                front = np.isin(region, ["q_frontleg_l", "q_frontleg_r"])
                hind = np.isin(region, ["q_hindleg_l", "q_hindleg_r"])
                assert common[front, 2].mean() > common[hind, 2].mean(), (spec.name, k)
    print("vertex counts:", counts)
    by_dataset = {ds: [counts[c.name] for c in CLASSES if c.dataset == ds] for ds in DATASETS}
    assert max(by_dataset["synthy"]) < min(by_dataset["synthz"])   # different triangulation densities


# --- the annotation folder ---------------------------------------------------------------------

def test_network_is_a_tree_with_one_file_per_directed_edge(collection):
    root = collection / "annotations"
    adj = pd.read_csv(root / "config" / "adjacency_matrix.csv", index_col=0)
    nodes = list(adj.columns)
    assert list(adj.index) == nodes == [c.node for c in CLASSES]
    a = adj.to_numpy()
    assert set(np.unique(a)) == {0, 1} and (a == a.T).all() and (np.diag(a) == 0).all()
    graph = nx.from_numpy_array(a)
    assert nx.is_tree(graph) and graph.number_of_edges() == len(nodes) - 1
    categories = {c.node: c.category for c in CLASSES}
    # humanoids and four-legged classes meet only through the centaur
    for u, v in TREE_EDGES:
        assert categories[u] == categories[v] or "centaur" in (categories[u], categories[v])
    folder = root / "precomputed_corr_templates"
    used = set()
    for i, j in zip(*np.nonzero(a)):
        hits = glob.glob(str(folder / f"{glob.escape(nodes[i])}*_{glob.escape(nodes[j])}*_corres.txt"))
        assert len(hits) == 1, (nodes[i], nodes[j], hits)
        used.add(Path(hits[0]).name)
    assert used == {p.name for p in folder.iterdir()}

    table = pd.read_csv(root / "config" / "templates_all.csv", dtype=str)
    assert list(table.columns) == ["dataset", "template", "split", "partial_full_template", "partial_full_dataset"]
    assert list(table["dataset"]) == [f"{c.dataset}_{c.name}" for c in CLASSES]
    assert all(f"{k.split('_')[0]}_{t}" in nodes for k, t in zip(table["dataset"], table["template"]))
    for spec in CLASSES:
        faces = np.load(root / "corres_comp" / "default_faces" / f"{spec.template}.npy")
        assert faces.dtype == np.int64
        _, file_faces = read_off(collection / "data" / DATASETS[spec.dataset].folder_name / f"{spec.template}.off")
        assert np.array_equal(faces, file_faces)


def test_chirality_labels_are_left_plus_x(collection):
    root = collection / "annotations"
    table = pd.read_csv(root / "config" / "templates_chirality_all.csv", dtype=str)
    assert list(table.columns) == ["dataset", "annotated_template"]
    assert len(table) == len(CHIRALITY_TEMPLATES)
    for key, template in zip(table["dataset"], table["annotated_template"]):
        dataset, name = key.split("_")
        values = np.loadtxt(root / "precomputed_chirality_templates" / f"{dataset}_{template}.txt", dtype=np.int64)
        verts, _ = read_off(collection / "data" / DATASETS[dataset].folder_name / f"{template}.off")
        common = common_frame(dataset, verts)
        labels, names = body_part_labels(dataset, name)
        part = np.array(names)[labels]
        assert set(np.unique(values)) == {0, 1} and len(values) == len(verts)
        left_parts = np.char.endswith(part.astype(str), "_l")
        right_parts = np.char.endswith(part.astype(str), "_r")
        assert values[left_parts].mean() > 0.97 and values[right_parts].mean() < 0.03
        centre_x = common[:, 0].mean()
        assert common[values == 1, 0].min() >= centre_x - 1e-3       # label 1 = +x side


def edge_data(collection):
    """Per directed edge: (source spec, target spec, face, weights)."""
    specs = {c.node: c for c in CLASSES}
    folder = collection / "annotations" / "precomputed_corr_templates"
    out = []
    for u, v in TREE_EDGES:
        for a, b in ((u, v), (v, u)):
            (path,) = glob.glob(str(folder / f"{a}*_{b}*_corres.txt"))
            face, weights = read_corres(Path(path))
            out.append((specs[a], specs[b], face, weights))
    return out


def test_missing_parts_are_exactly_the_marked_rows(collection):
    n_missing = {}
    for sa, sb, face, weights in edge_data(collection):
        la, names_a = body_part_labels(sa.dataset, sa.name)
        _, fb = read_off(collection / "data" / DATASETS[sb.dataset].folder_name / f"{sb.template}.off")
        assert len(face) == len(la)                                 # one row per source vertex
        assert face.max() < len(fb) and face.min() >= -1
        absent = ~np.isin(np.array(names_a), list(sb.part_names))[la]
        assert np.array_equal(face == -1, absent), (sa.node, sb.node)
        assert (weights[face == -1] == 0).all()
        matched = weights[face >= 0]
        assert (matched >= 0).all() and np.allclose(matched.sum(axis=1), 1.0, atol=5e-6)
        n_missing[(sa.name, sb.name)] = int(absent.sum())
    print("rows marked -1 per edge:", n_missing)
    # semantic missing parts exist where the construction says so, and only there
    assert n_missing[("brute", "alba")] > 0 and n_missing[("alba", "brute")] == 0      # horns
    assert n_missing[("dario", "elin")] > 0 and n_missing[("elin", "dario")] == 0      # tail
    assert n_missing[("hound", "tapir")] > 0                                            # tail
    assert n_missing[("centaur", "elin")] > 0 and n_missing[("elin", "centaur")] > 0    # lower / upper body
    assert n_missing[("centaur", "pony")] > 0 and n_missing[("pony", "centaur")] > 0    # upper body / neck+head


def test_correspondences_land_on_the_same_body_part(collection):
    """A matched template vertex lands on the same body region of the other class (dominant vertex)."""
    rows, total_fine, total_region = [], 0, 0
    total = 0
    left_front = [0, 0]
    for sa, sb, face, weights in edge_data(collection):
        la, names_a = body_part_labels(sa.dataset, sa.name)
        lb, names_b = body_part_labels(sb.dataset, sb.name)
        _, fb = read_off(collection / "data" / DATASETS[sb.dataset].folder_name / f"{sb.template}.off")
        ok = face >= 0
        dominant = fb[face[ok], weights[ok].argmax(axis=1)]
        part_a = np.array(names_a)[la[ok]]
        part_b = np.array(names_b)[lb[dominant]]
        region_a = np.array([semantic_part(n) for n in names_a])[la[ok]]
        region_b = np.array([semantic_part(n) for n in names_b])[lb[dominant]]
        same_region = region_a == region_b
        rows.append((sa.name, sb.name, round(100 * same_region.mean(), 2), round(100 * (part_a == part_b).mean(), 2)))
        total += ok.sum()
        total_region += same_region.sum()
        total_fine += (part_a == part_b).sum()
        lf = region_a == "q_frontleg_l"
        left_front[0] += lf.sum()
        left_front[1] += (region_b[lf] == "q_frontleg_l").sum()
        assert same_region.mean() > 0.965, rows[-1]
    overall_region, overall_fine = total_region / total, total_fine / total
    print("per edge (source, target, % same region, % same segment):", rows)
    print(f"overall: {100 * overall_region:.2f} % same body region, {100 * overall_fine:.2f} % same segment, "
          f"left front leg -> left front leg {100 * left_front[1] / left_front[0]:.2f} %")
    assert overall_region > 0.985
    assert overall_fine > 0.975
    assert left_front[1] / left_front[0] > 0.98


# --- readers of other modules ------------------------------------------------------------------

def test_dataset_registry_lists_the_collection(collection):
    from becos.datasets import DatasetSpec, frame_rotation_matrix, prepare_shape

    for name, ds in DATASETS.items():
        spec = DatasetSpec.load(name)
        assert spec.folder == ds.folder_name and spec.scale == ds.scale
        assert np.allclose(frame_rotation_matrix(spec.rotation_deg), ds.rotation())
        entries = spec.list_shapes(collection / "data")
        assert len(entries) == sum(c.dataset == name for c in CLASSES) * POSES
        by_name = {e.name: e for e in entries}
        for c in (c for c in CLASSES if c.dataset == name):
            entry = by_name[c.template]
            assert entry.shape_class == c.name
            assert entry.category == c.category and entry.template_key == f"{name}_{c.name}"
            in_split = [s for s, classes in ds.splits.get(c.category, {}).items() if c.name in classes]
            assert entry.split == (in_split[0] if in_split else "train")
            prepared = prepare_shape(entry)
            extent = np.ptp(prepared.mesh.vertices, axis=0)
            if c.category == "human":
                assert extent[1] > 1.4 and extent[1] > 2 * extent[2]       # upright, metres
            else:
                assert extent[2] > extent[0]                                 # long axis along z
        splits = Counter((e.category, e.split) for e in entries)
        for category in ("human", "four-legged"):
            assert all(splits[(category, s)] > 0 for s in ("train", "val", "test"))


def test_annotation_source_resolves_every_edge(collection):
    from becos import annotations

    source = annotations.AnnotationSource(collection / "annotations", cache_dir=collection.parent / "edge-cache")
    assert source.graph.number_of_nodes() == len(CLASSES)
    specs = {c.node: c for c in CLASSES}
    edges = source.edge_sources()
    assert len(edges) == 2 * len(TREE_EDGES) and all(e.kind == "file" for e in edges)
    for e in edges:
        a, b = specs[e.source], specs[e.target]
        assert source.node_of_key(f"{a.dataset}_{a.name}") == e.source
        assert source.node_template(e.source) == (a.dataset, a.template)
        va, _ = read_off(collection / "data" / DATASETS[a.dataset].folder_name / f"{a.template}.off")
        fb = source.default_faces(b.template, b.dataset)
        source.check_edge(e.source, e.target, len(va), len(fb))
        report = source.edge_report(e.source, e.target)
        assert report["zero_weight_rows"] == 0 and report["rows"] == len(va)
    path = source.path("synthy_alba0", "synthy_goat0")
    assert "synthz_centaur0" in path
    assert len(source.chirality_labels("synthz", "centaur0")) == len(
        read_off(collection / "data" / "synthz-off" / "centaur0.off")[0])
