"""The built-in synthetic collection (becos.sources.synthetic, issue 5): files, meshes, network, correspondences.

One collection is generated per test session (session fixture ``synthetic_collection``, default
arguments) while a second one is generated at the same time in a fresh process through the CLI the
workflow calls (``python -m becos synthetic OUT --seed 0 --poses 4``), to check byte-identical output.
Run with ``-s`` to see the measured figures (generation time, body-part agreement, missing rows).
"""

from __future__ import annotations

import contextlib
import glob
import hashlib
import json
import os
import re
import subprocess
import sys
import time
from collections import Counter
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import networkx as nx
import numpy as np
import pandas as pd
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from becos.errors import ConfigError
from becos.sources.synthetic import (
    CHIRALITY_TEMPLATES,
    CLASSES,
    DATASETS,
    FULL_SCALE_POSES,
    TREE_EDGES,
    body_part_labels,
    build_class,
    generate_collection,
    poses_at_fraction,
)
from becos.sources.synthetic.bodies import semantic_part

REPO = Path(__file__).resolve().parents[1]
POSES = 4
SEED = 0
SPECS = {c.node: c for c in CLASSES}

# class features, written out here (not derived from the generator) for the missing-part checks
HORNED = {"brute", "faun", "goat", "ram"}
TAILED = {"dario", "hound", "lynx", "pony", "goat", "ram", "centaur"}


def read_off(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) float64 vertices and (F, 3) int64 faces of an OFF file (fast, pandas)."""
    with open(path) as fh:
        assert fh.readline().strip() == "OFF"
        nv, nf, _ = map(int, fh.readline().split())
    table = pd.read_csv(path, sep=" ", header=None, skiprows=2, names=range(4), engine="c")
    vertices = table.iloc[:nv, :3].to_numpy(np.float64)
    faces = table.iloc[nv : nv + nf].to_numpy(np.float64)
    assert (faces[:, 0] == 3).all()
    return vertices, faces[:, 1:].astype(np.int64)


def read_corres(path: Path) -> tuple[np.ndarray, np.ndarray]:
    table = pd.read_csv(path, sep=" ", header=None, engine="c").to_numpy(np.float64)
    assert table.shape[1] == 4
    return table[:, 0].astype(np.int64), table[:, 1:]


def file_hashes(root: Path) -> dict[str, str]:
    return {
        p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


@dataclass
class Collection:
    root: Path  # generated in this process
    seconds: float  # its generation time (while the second run shares the cores)
    second_root: Path  # generated in a fresh process through the CLI
    second: subprocess.Popen

    def wait_second(self) -> tuple[int, str, str]:
        out, err = self.second.communicate(timeout=300)
        return self.second.returncode, out, err


def one_blas_thread():
    """Limit BLAS to one thread while the two generations share the cores (threads only thrash
    there; the generation is as fast single-threaded). threadpoolctl is optional."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


@pytest.fixture(scope="session")
def synthetic_collection(tmp_path_factory) -> Collection:
    base = tmp_path_factory.mktemp("synthetic")
    second_root = base / "again"
    # another hash seed; one BLAS thread (the two runs share the cores; threads only thrash here)
    env = dict(os.environ, PYTHONHASHSEED="123", OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    second = subprocess.Popen(
        [sys.executable, "-m", "becos", "synthetic", str(second_root), "--seed", str(SEED), "--poses", str(POSES)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=REPO,
    )
    try:
        start = time.perf_counter()
        with one_blas_thread():
            root = generate_collection(base / "collection", seed=SEED, poses_per_class=POSES)
        seconds = time.perf_counter() - start
        print(f"\nsynthetic collection generated in {seconds:.1f} s (a second run in parallel)")
        yield Collection(root, seconds, second_root, second)
    finally:
        if second.poll() is None:  # only the process this fixture started
            second.kill()
            second.communicate()


@pytest.fixture(scope="session")
def collection(synthetic_collection) -> Path:
    return synthetic_collection.root


def shape_path(root: Path, dataset: str, name: str) -> Path:
    return root / "data" / DATASETS[dataset].folder_name / f"{name}.off"


# --- files and determinism ---------------------------------------------------------------------


def test_layout_counts_and_generation_time(synthetic_collection):
    collection = synthetic_collection.root
    print(f"\ngenerated in {synthetic_collection.seconds:.1f} s")  # measured ~5-10 s on 2 cores; not asserted
    shapes = sorted((collection / "data").rglob("*.off"))
    assert len(shapes) == len(CLASSES) * POSES
    assert {c.dataset for c in CLASSES} == set(DATASETS) and len(DATASETS) >= 2
    categories = Counter(c.category for c in CLASSES)
    assert categories["human"] >= 3 and categories["four-legged"] >= 3 and categories["centaur"] >= 1
    for spec in CLASSES:
        assert spec.dataset.isalnum() and spec.dataset.islower() and "_" not in spec.dataset
        for k in range(POSES):
            assert shape_path(collection, spec.dataset, f"{spec.name}{k}").is_file()
    # no class name is a prefix of another (the edge-file lookup globs "<ds>_<template>*")
    templates = [c.template for c in CLASSES]
    assert not any(a != b and b.startswith(a) for a in templates for b in templates)
    # the manifest lists every other file with its sha256
    manifest = json.loads((collection / "synthetic.json").read_text())
    assert manifest["seed"] == SEED and manifest["poses_per_class"] == POSES
    hashes = file_hashes(collection)
    assert manifest["files"] == {k: v for k, v in hashes.items() if k != "synthetic.json"}


def test_byte_identical_across_two_runs(synthetic_collection):
    returncode, out, err = synthetic_collection.wait_second()
    assert returncode == 0, err
    second = synthetic_collection.second_root
    assert Path(out.strip()) == second.resolve()
    print("\n" + err.strip())  # the CLI reports its generation time
    assert re.search(r"in \d+\.\d s", err)
    first_hashes, second_hashes = file_hashes(synthetic_collection.root), file_hashes(second)
    n_files = len(CLASSES) * POSES + 3 + 2 * len(TREE_EDGES) + len(CLASSES) + len(CHIRALITY_TEMPLATES) + 1
    assert len(first_hashes) == n_files
    assert first_hashes == second_hashes
    print(f"{len(first_hashes)} files, sha256 identical across the two runs")
    assert not list(second.parent.glob(".again.tmp-*"))  # the temporary folder was renamed into place


def test_refuses_to_overwrite_foreign_folder(tmp_path):
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("precious")
    with pytest.raises(ConfigError, match="not a synthetic collection"):
        generate_collection(foreign)
    assert (foreign / "thesis.tex").read_text() == "precious"
    with pytest.raises(ConfigError, match="poses_per_class"):
        generate_collection(tmp_path / "x", poses_per_class=0)


def test_fraction_scales_the_collection_and_the_registry_counts_its_manifest(tmp_path):
    """``synthetic.fraction`` (config/scale.yaml): one knob sets every class's shapes, modelled on the
    published benchmark; the registry counts the shapes a collection's manifest lists, at any size
    (a manifest listing 1/16's files is enough here: no meshes are generated)."""
    from becos.errors import InputFileError
    from becos.sources.datasets import DatasetSpec

    split_of = {}
    for name in DATASETS:
        spec = DatasetSpec.load(name)
        assert spec.generated and spec.expected_count is None
        split_of |= {f"{name}_{c}": s for s in ("train", "val", "test") for c in spec.split[s]}
    assert set(split_of) == set(FULL_SCALE_POSES) == {f"{c.dataset}_{c.name}" for c in CLASSES}
    per_split = Counter()
    for key, n in FULL_SCALE_POSES.items():
        per_split[split_of[key]] += n
    # the published benchmark: 2,537 shapes, one per val / test pair (137 / 142)
    assert per_split == {"train": 2258, "val": 137, "test": 142}
    assert poses_at_fraction(1.0) == FULL_SCALE_POSES
    assert [sum(poses_at_fraction(f).values()) for f in (1 / 16, 1 / 8, 1 / 4)] == [161, 319, 637]
    assert min(poses_at_fraction(1 / 1000).values()) == 1  # every class keeps its template
    for bad in (0, 1.5, "1/16"):
        with pytest.raises(ConfigError, match="fraction"):
            poses_at_fraction(bad)

    poses = poses_at_fraction(1 / 16)
    files = {
        f"data/{DATASETS[c.dataset].folder_name}/{c.name}{k}.off": "-"
        for c in CLASSES
        for k in range(poses[f"{c.dataset}_{c.name}"])
    }
    files["annotations/config/templates_all.csv"] = "-"
    (tmp_path / "synthetic.json").write_text(json.dumps({"generator": "becos.sources.synthetic", "files": files}))
    for name in DATASETS:
        expected = {c.name: poses[f"{name}_{c.name}"] for c in CLASSES if c.dataset == name}
        assert DatasetSpec.load(name).expected_counts(tmp_path / "data") == (sum(expected.values()), expected)
    with pytest.raises(InputFileError, match="synthetic.json.*synthy counts its shapes there"):
        DatasetSpec.load("synthy").expected_counts(tmp_path / "elsewhere" / "data")


# --- meshes ------------------------------------------------------------------------------------


def mesh_topology(n_vertices: int, faces: np.ndarray) -> dict:
    """Closedness, orientation, manifoldness and components of a triangle mesh (vectorised; edges
    encoded as int64 keys ``i * n + j``)."""
    n = np.int64(n_vertices)
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]).astype(np.int64)
    undirected = np.sort(directed, axis=1)
    _, edge_count = np.unique(undirected[:, 0] * n + undirected[:, 1], return_counts=True)
    _, directed_count = np.unique(directed[:, 0] * n + directed[:, 1], return_counts=True)
    adjacency = sp.coo_matrix(
        (np.ones(len(directed)), (directed[:, 0], directed[:, 1])), shape=(n_vertices, n_vertices)
    )
    n_components = connected_components(adjacency, directed=False)[0]
    # vertex manifoldness: around each vertex the link edges (b, c) of its faces (v, b, c) form ONE cycle
    corners = np.concatenate([faces, faces[:, [1, 2, 0]], faces[:, [2, 0, 1]]]).astype(np.int64)  # (v, b, c)
    keys = np.concatenate([corners[:, 0] * n + corners[:, 1], corners[:, 0] * n + corners[:, 2]])
    uniq, inverse = np.unique(keys, return_inverse=True)
    m = len(corners)
    link = sp.coo_matrix((np.ones(m), (inverse[:m], inverse[m:])), shape=(len(uniq), len(uniq)))
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


class FastOffReader:
    """A mesh loader for ``prepare_shape(entry, mesh_cache)`` that parses OFF files with pandas
    (~15x faster than the trimesh-based ``becos.core.mesh.read_mesh``; checked equal on the templates)."""

    def load(self, path):
        from becos.core.mesh import TriMesh

        return TriMesh(*read_off(Path(path)))


def test_meshes_closed_manifold_upright_one_triangulation_per_class(collection):
    """Through the registry: every shape, after the dataset's scale and frame rotation
    (becos.sources.datasets.prepare_shape), is an outward-oriented closed 2-manifold of 5k-30k vertices,
    upright (+y) with its feet at the bottom, four-legged bodies facing +z; poses share faces."""
    from becos.sources.datasets import DatasetSpec, prepare_shape

    reader = FastOffReader()

    counts = {}
    for dataset in DATASETS:
        entries = DatasetSpec.load(dataset).list_shapes(collection / "data")
        by_class: dict[str, list] = {}
        for entry in entries:
            by_class.setdefault(entry.shape_class, []).append(entry)
        for name, members in by_class.items():
            spec = SPECS[f"{dataset}_{name}0"]
            labels, names = body_part_labels(dataset, name)
            part = np.array(names)[labels]
            region = np.array([semantic_part(n) for n in names])[labels]
            head = region == ("q_head" if spec.category == "four-legged" else "b_head")
            feet = np.char.find(part.astype(str), "foot") >= 0
            template = None
            for entry in sorted(members, key=lambda e: e.name):
                mesh = prepare_shape(entry, reader).mesh
                if template is None:
                    assert entry.name == spec.template
                    template = mesh
                    reference = prepare_shape(entry).mesh  # parsed by becos.core.mesh.read_mesh
                    assert np.array_equal(reference.faces, mesh.faces)
                    assert np.allclose(reference.vertices, mesh.vertices, atol=1e-9)
                    topo = mesh_topology(mesh.n_vertices, mesh.faces)
                    assert topo == {
                        "edges_in_two_faces": True,
                        "oriented": True,
                        "components": 1,
                        "vertex_manifold": True,
                        "euler": 2,
                    }, (name, topo)
                    counts[name] = mesh.n_vertices
                    assert 5000 <= mesh.n_vertices <= 30000
                else:  # a different, articulated pose
                    assert np.abs(mesh.vertices - template.vertices).max() > 0.05, entry.name
                assert np.array_equal(mesh.faces, template.faces)  # one triangulation per class
                assert len(labels) == mesh.n_vertices
                v = mesh.vertices
                assert signed_volume(v, mesh.faces) > 0  # outward normals
                y = v[:, 1]
                assert y[head].mean() > y[feet].mean() + 0.3, entry.name  # upright, +y up, metres
                assert y[feet].min() - y.min() < 0.05, entry.name  # standing on its feet
                if spec.category == "human":
                    assert np.ptp(y) > 1.2 and np.ptp(y) > 1.5 * np.ptp(v[:, 2]), entry.name
                else:  # four-legged bodies face +z
                    front = np.char.startswith(part.astype(str), "q_f")
                    hind = np.char.startswith(part.astype(str), "q_h")
                    assert v[front, 2].mean() > v[hind, 2].mean() + 0.05, entry.name
    print("\ntemplate vertex counts:", counts)
    by_dataset = {ds: [counts[c.name] for c in CLASSES if c.dataset == ds] for ds in DATASETS}
    assert max(by_dataset["synthy"]) < min(by_dataset["synthz"])  # different triangulation densities


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
    # edited-template suffixes as the reference names them
    assert (folder / "synthz_centaur0_bottom_synthz_pony0_bottom_corres.txt").is_file()
    assert (folder / "synthz_elin0_top_synthz_centaur0_top_corres.txt").is_file()
    assert (folder / "synthy_hound0_no_tail_synthy_tapir0_corres.txt").is_file()

    table = pd.read_csv(root / "config" / "templates_all.csv", dtype=str)
    assert list(table.columns) == ["dataset", "template", "split", "partial_full_template", "partial_full_dataset"]
    assert list(table["dataset"]) == [f"{c.dataset}_{c.name}" for c in CLASSES]
    assert all(f"{k.split('_')[0]}_{t}" in nodes for k, t in zip(table["dataset"], table["template"]))
    for spec in CLASSES:
        faces = np.load(root / "corres_comp" / "default_faces" / f"{spec.template}.npy")
        assert faces.dtype == np.int64
        _, file_faces = read_off(shape_path(collection, spec.dataset, spec.template))
        assert np.array_equal(faces, file_faces)


def test_chirality_labels_are_left_plus_x(collection):
    root = collection / "annotations"
    table = pd.read_csv(root / "config" / "templates_chirality_all.csv", dtype=str)
    assert list(table.columns) == ["dataset", "annotated_template"]
    assert len(table) == len(CHIRALITY_TEMPLATES)
    for key, template in zip(table["dataset"], table["annotated_template"]):
        dataset, name = key.split("_")
        values = np.loadtxt(root / "precomputed_chirality_templates" / f"{dataset}_{template}.txt", dtype=np.int64)
        verts, _ = read_off(shape_path(collection, dataset, template))
        common = DATASETS[dataset].to_common_frame(verts)
        labels, names = body_part_labels(dataset, name)
        part = np.array(names)[labels]
        assert set(np.unique(values)) == {0, 1} and len(values) == len(verts)
        left_parts = np.char.endswith(part.astype(str), "_l")
        right_parts = np.char.endswith(part.astype(str), "_r")
        assert values[left_parts].mean() > 0.97 and values[right_parts].mean() < 0.03
        centre_x = common[:, 0].mean()
        assert common[values == 1, 0].min() >= centre_x - 1e-3  # label 1 = +x side


@pytest.fixture(scope="session")
def edge_data(collection):
    """Per directed edge of the template tree: (source spec, target spec, face, weights) read from
    the ``*_corres.txt`` file."""
    folder = collection / "annotations" / "precomputed_corr_templates"
    out = []
    for u, v in TREE_EDGES:
        for a, b in ((u, v), (v, u)):
            (path,) = glob.glob(str(folder / f"{a}*_{b}*_corres.txt"))
            face, weights = read_corres(Path(path))
            out.append((SPECS[a], SPECS[b], face, weights))
    return out


def expected_missing(source, target, segment: np.ndarray, region: np.ndarray) -> np.ndarray:
    """(V,) bool: the source template's vertices on a semantic part the target class lacks, from
    the class features written out in this file (horns, tails, the centaur's halves)."""
    missing = np.zeros(len(segment), dtype=bool)
    if source.name in HORNED and target.name not in HORNED:
        missing |= np.char.find(region.astype(str), "horn") >= 0
    if source.name in TAILED and target.name not in TAILED:
        missing |= np.char.find(region.astype(str), "tail") >= 0
    kinds = (source.category, target.category)
    if kinds == ("centaur", "four-legged"):  # the human upper body
        missing |= np.char.startswith(segment.astype(str), "b_")
    elif kinds == ("four-legged", "centaur"):  # the animal's neck and head
        missing |= region == "q_head"
    elif kinds == ("centaur", "human"):  # the horse body (barrel, legs, tail)
        missing |= np.char.startswith(segment.astype(str), "q_")
    elif kinds == ("human", "centaur"):  # the human pelvis and legs
        missing |= (segment == "b_pelvis") | np.isin(region, ["b_leg_l", "b_leg_r"])
    return missing


def test_missing_parts_are_exactly_the_marked_rows(collection, edge_data):
    """Rows ``-1 0 0 0`` (and only they) are exactly the source vertices on a semantic part the
    target class lacks: a horn, a tail, the centaur's upper body against a four-legged class (and
    the four-legged neck and head against the centaur), the centaur's horse body against a human."""
    n_missing = {}
    for sa, sb, face, weights in edge_data:
        la, names_a = body_part_labels(sa.dataset, sa.name)
        segment = np.array(names_a)[la]
        region = np.array([semantic_part(n) for n in names_a])[la]
        _, fb = read_off(shape_path(collection, sb.dataset, sb.template))
        assert len(face) == len(la)  # one row per source vertex
        assert face.max() < len(fb) and face.min() >= -1
        expected = expected_missing(sa, sb, segment, region)
        assert np.array_equal(face == -1, expected), (sa.node, sb.node, int((face == -1).sum()), int(expected.sum()))
        zero_rows = (weights == 0).all(axis=1)
        assert np.array_equal(zero_rows, face == -1), (sa.node, sb.node)  # -1 rows are "-1 0 0 0", no others
        matched = weights[face >= 0]
        assert (matched >= 0).all() and np.allclose(matched.sum(axis=1), 1.0, atol=5e-6)
        n_missing[(sa.name, sb.name)] = (int(expected.sum()), sorted({str(r) for r in region[expected]}))
    print(
        "\nrows marked -1 per edge (count, semantic parts):",
        {f"{a}->{b}": v for (a, b), v in n_missing.items() if v[0]},
    )
    # semantic missing parts exist where the construction says so, and only there
    assert n_missing[("brute", "alba")][1] == ["b_horn_l", "b_horn_r"] and n_missing[("alba", "brute")][0] == 0
    assert n_missing[("dario", "elin")][1] == ["b_tail"] and n_missing[("elin", "dario")][0] == 0
    assert n_missing[("hound", "tapir")][1] == ["q_tail"] and n_missing[("tapir", "hound")][0] == 0
    assert n_missing[("ram", "pony")][1] == ["q_horn_l", "q_horn_r"]
    assert n_missing[("centaur", "pony")][1] == ["b_arm_l", "b_arm_r", "b_head", "b_torso"]
    assert n_missing[("pony", "centaur")][1] == ["q_head"]
    assert set(n_missing[("centaur", "elin")][1]) == {
        "q_torso",
        "q_frontleg_l",
        "q_frontleg_r",
        "q_hindleg_l",
        "q_hindleg_r",
        "q_tail",
    }
    assert n_missing[("elin", "centaur")][1] == ["b_leg_l", "b_leg_r", "b_torso"]
    same_features = [("alba", "cyra"), ("alba", "elin"), ("hound", "lynx"), ("lynx", "pony")]
    assert all(n_missing[e][0] == 0 and n_missing[e[::-1]][0] == 0 for e in same_features)


def test_correspondences_land_on_the_same_body_part(edge_data):
    """Issue 5: a template vertex lands on the same body part of the other class (a left-front-leg
    vertex on the left front leg). Measured over every directed edge of the template tree on the
    vertex the pipeline rounds to (dominant corner of the image face); the image point itself
    (before rounding) is also labelled by the construction's part fields."""
    rows = []
    totals = Counter()
    for sa, sb, face, weights in edge_data:
        la, names_a = body_part_labels(sa.dataset, sa.name)
        lb, names_b = body_part_labels(sb.dataset, sb.name)
        model_b = build_class(sb.dataset, sb.name)  # the template mesh of b, in metres
        fb = model_b.mesh.faces
        ok = face >= 0
        dominant = fb[face[ok], weights[ok].argmax(axis=1)]
        region_of_a = np.array([semantic_part(n) for n in names_a])
        region_of_b = np.array([semantic_part(n) for n in names_b])
        region_a, region_b = region_of_a[la[ok]], region_of_b[lb[dominant]]
        segment_a, segment_b = np.array(names_a)[la[ok]], np.array(names_b)[lb[dominant]]
        points = np.einsum("nk,nkd->nd", weights[ok], model_b.mesh.vertices[fb[face[ok]]])
        region_point = region_of_b[model_b.body.labels(points)]
        same = region_a == region_b
        rows.append((f"{sa.name}->{sb.name}", round(float(100 * same.mean()), 2)))
        totals["matched"] += ok.sum()
        totals["region"] += same.sum()
        totals["segment"] += (segment_a == segment_b).sum()
        totals["point"] += (region_a == region_point).sum()
        left_front = region_a == "q_frontleg_l"
        totals["left_front"] += left_front.sum()
        totals["left_front_ok"] += (region_b[left_front] == "q_frontleg_l").sum()
        assert same.mean() >= 0.985, rows[-1]
    share = {k: totals[k] / totals["matched"] for k in ("region", "segment", "point")}
    left_front = totals["left_front_ok"] / totals["left_front"]
    print(f"\nbody-part agreement per directed edge (%): {dict(rows)}")
    print(
        f"body-part agreement over all {2 * len(TREE_EDGES)} directed edges, {totals['matched']} matched "
        f"vertices: {100 * share['region']:.2f} % same body part (dominant vertex; image point itself: "
        f"{100 * share['point']:.2f} %), {100 * share['segment']:.2f} % same bone segment, "
        f"left front leg -> left front leg {100 * left_front:.2f} %"
    )
    assert share["region"] >= 0.99  # issue 5: >= 99 %
    assert share["point"] >= 0.995
    assert share["segment"] >= 0.98
    assert left_front >= 0.99


# --- readers of other modules ------------------------------------------------------------------


@pytest.fixture(scope="session")
def annotation_source(collection, tmp_path_factory):
    from becos.sources.annotations import AnnotationSource

    return AnnotationSource(collection / "annotations", cache_dir=tmp_path_factory.mktemp("edge-cache"))


@pytest.fixture(scope="session")
def entries(collection, annotation_source):
    from becos.sources.datasets import DatasetSpec

    return {name: DatasetSpec.load(name).list_shapes(collection / "data", annotation_source) for name in DATASETS}


def test_dataset_registry_lists_the_collection_with_class_held_out_splits(entries):
    from becos.sources.datasets import DatasetSpec, frame_rotation_matrix

    splits_of_class: dict[tuple[str, str], set] = {}
    per_category: dict[str, set] = {}
    for name, ds in DATASETS.items():
        spec = DatasetSpec.load(name)
        assert spec.folder == ds.folder_name and spec.scale == ds.scale
        assert np.allclose(frame_rotation_matrix(spec.rotation_deg), ds.rotation())
        listed = entries[name]
        assert len(listed) == sum(c.dataset == name for c in CLASSES) * POSES
        for e in listed:
            c = SPECS[f"{name}_{e.shape_class}0"]
            assert e.category == c.category and e.template_key == f"{name}_{c.name}"
            splits_of_class.setdefault((name, e.shape_class), set()).add(e.split)
            per_category.setdefault(e.category, set()).add(e.split)
        # within a dataset and category, each split holds its own classes
        for category in ("human", "four-legged"):
            split_sets = [
                {e.shape_class for e in listed if e.category == category and e.split == s}
                for s in ("train", "val", "test")
            ]
            assert all(split_sets) and not (
                split_sets[0] & split_sets[1] or split_sets[0] & split_sets[2] or split_sets[1] & split_sets[2]
            ), (name, category, split_sets)
    assert all(len(s) == 1 for s in splits_of_class.values())  # a class is never split across splits
    assert per_category["human"] == per_category["four-legged"] == {"train", "val", "test"}
    assert per_category["centaur"] == {"train"}
    print("\nsplits:", {f"{d}/{c}": sorted(s)[0] for (d, c), s in sorted(splits_of_class.items())})


def test_annotation_source_resolves_every_edge(collection, annotation_source):
    source = annotation_source
    assert source.graph.number_of_nodes() == len(CLASSES)
    edges = source.edge_sources()
    assert len(edges) == 2 * len(TREE_EDGES) and all(e.kind == "file" for e in edges)
    for e in edges:
        a, b = SPECS[e.source], SPECS[e.target]
        assert source.node_of_key(f"{a.dataset}_{a.name}") == e.source
        assert source.node_template(e.source) == (a.dataset, a.template)
        va, _ = read_off(shape_path(collection, a.dataset, a.template))
        fb = source.default_faces(b.template, b.dataset)
        source.check_edge(e.source, e.target, len(va), len(fb))
        report = source.edge_report(e.source, e.target)
        assert report["zero_weight_rows"] == 0 and report["rows"] == len(va)
    path = source.path("synthy_alba0", "synthy_goat0")
    assert "synthz_centaur0" in path
    assert len(source.chirality_labels("synthz", "centaur0")) == len(
        read_off(shape_path(collection, "synthz", "centaur0"))[0]
    )
    assert not (collection / "annotations" / ".becos-cache").exists()


def test_network_ground_truth_across_datasets(collection, annotation_source, entries):
    """ShapeNetwork ground truth between posed shapes of two datasets: a centaur against a
    four-legged class misses exactly its human upper body; cat-like lynx -> dog-like hound misses
    nothing; matched vertices land on the same body part."""
    from becos.build.network import ShapeNetwork
    from becos.core.mesh import read_mesh

    @cache
    def meshes(dataset, name):
        path = shape_path(collection, dataset, name)
        return read_mesh(path) if dataset in DATASETS and path.is_file() else None

    network = ShapeNetwork(annotation_source, meshes)
    shapes = {(e.dataset, e.name): e for listed in entries.values() for e in listed}
    results = {}
    for (dx, x), (dy, y) in (
        (("synthz", "centaur1"), ("synthy", "hound2")),
        (("synthz", "lynx1"), ("synthy", "hound2")),
        (("synthy", "hound3"), ("synthz", "centaur2")),
    ):
        gt = network.ground_truth(shapes[(dx, x)], shapes[(dy, y)])
        lx, names_x = body_part_labels(dx, x.rstrip("0123456789"))
        ly, names_y = body_part_labels(dy, y.rstrip("0123456789"))
        region_x = np.array([semantic_part(n) for n in names_x])[lx]
        region_y = np.array([semantic_part(n) for n in names_y])[ly]
        target = gt.to_vertex_indices(meshes(dy, y).faces)
        ok = target >= 0
        agreement = float((region_x[ok] == region_y[target[ok]]).mean())
        results[f"{x}->{y}"] = (round(100 * gt.missing_fraction, 2), round(100 * agreement, 2))
        assert agreement >= 0.98, (x, y, agreement)
        if x.startswith("centaur"):
            upper = np.char.startswith(np.array(names_x)[lx].astype(str), "b_")
            assert np.array_equal(~gt.matched, upper)
        elif y.startswith("centaur"):  # X's neck and head, up to rounding where the hops meet
            head = region_x == "q_head"
            assert (~gt.matched[head]).mean() > 0.98 and head[~gt.matched].mean() > 0.98
        else:
            assert gt.missing_fraction == 0.0
    print("\nground truth (missing %, same body part %):", results)
    assert results["centaur1->hound2"][0] > 10.0
