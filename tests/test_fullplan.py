"""The full published benchmark on a stand-in data root (tests/standin.py): all 8 dataset entries.

The dataset check passes, the registry lists every published shape with its published category,
split and scale, and ``original_settings`` imports exactly the published pair counts.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np
import pytest
from standin import (
    DATASETS,
    PUBLISHED_PAIRS,
    PUBLISHED_SETTINGS,
    PUBLISHED_SHAPES,
    bipyramid,
    build_standin_tree,
    mesh_bytes,
)

from becos.build.published import load_published
from becos.build.sampling import read_manifest
from becos.core.mesh import read_mesh
from becos.sources.catalog import read_catalog
from becos.sources.check import check_datasets
from becos.workflow import resolve_config, write_catalog_stage, write_manifest_stage


@pytest.fixture(scope="module")
def tree(becos_code, tmp_path_factory):
    return build_standin_tree(tmp_path_factory.mktemp("standin"), becos_code)


@pytest.fixture(scope="module")
def catalog_path(tree, tmp_path_factory):
    """The catalog of all 8 entries, written by the catalog job's function."""
    results = tmp_path_factory.mktemp("results")
    config = full_config(tree, results)
    write_catalog_stage(config, results / "catalog.csv")
    return results / "catalog.csv"


def full_config(tree, results, **overrides) -> dict:
    return resolve_config(
        {
            "synthetic": {"enabled": False},
            "data_dir": str(tree.data_dir),
            "annotations": str(tree.annotations),
            "datasets": list(DATASETS),
            "template_file": "templates_all.csv",
            "results": str(results),
            **overrides,
        }
    )


@pytest.mark.parametrize("file_type", ["off", "obj", "ply"])
def test_standin_mesh_is_a_closed_outward_surface_read_back_exactly(file_type, tmp_path):
    vertices, faces = bipyramid(9)
    assert faces.shape == (14, 3)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    directed = {tuple(e) for e in edges.tolist()}
    assert len(directed) == len(edges) and all((b, a) in directed for a, b in directed)  # closed, oriented
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    assert np.einsum("ij,ij->i", a, np.cross(b, c)).sum() > 0  # outward
    path = tmp_path / f"m.{file_type}"
    path.write_bytes(mesh_bytes(vertices, faces, file_type))
    mesh = read_mesh(path)
    np.testing.assert_array_equal(mesh.faces, faces)
    np.testing.assert_allclose(mesh.vertices, vertices, atol=1e-6)


def test_standin_meshes_pass_the_dataset_check(tree):
    assert len(tree.files) == PUBLISHED_SHAPES + 4 and tree.published <= set(tree.files)
    assert tree.template_vertices[("faust", "tr_reg_000")] == 6890
    faust = read_mesh(tree.files[("faust", "tr_reg_000")])  # real template faces (default faces)
    assert (faust.n_vertices, faust.n_faces) == (6890, 13776)
    # stand-ins are not real geometry: no class-template or edge-plausibility comparison (check_geometry)
    report = check_datasets(list(DATASETS), tree.data_dir, tree.annotations, compare_geometry=False)
    assert report["ok"]
    assert all(report[d]["found"] == report[d]["expected"] and not report[d]["bad_meshes"] for d in DATASETS)
    assert report["dt4d_animal"]["meshes_checked"] == 1950 and report["dt4d_human"]["meshes_checked"] == 248
    edges = report["annotations"]["edge_contents"]
    # every edge file whose two templates are published shapes was compared with their mesh counts
    # (the others touch KIDS' template kid00, which no published pair uses)
    assert edges["bad"] == [] and edges["compared_with_meshes"] == 116 and edges["parsed"] == 138


def test_registry_lists_every_published_shape_as_published(tree, catalog_path, becos_code):
    published: dict = defaultdict(set)
    for setting in PUBLISHED_SETTINGS:
        lists = load_published(becos_code / "config" / f"pairings_original_{setting}.pkl")
        for split, pairs in zip(("train", "test", "val"), lists):
            for pair in pairs:
                for s in pair:
                    published[(s["org_dataset"], s["name"])].add((s["category"], split, float(s["scale"])))
    assert len(published) == PUBLISHED_SHAPES
    catalog = read_catalog(catalog_path)
    listed = {
        (d, n): (c, s, sc)
        for d, n, c, s, sc in zip(
            catalog["dataset"], catalog["name"], catalog["category"], catalog["split"], catalog["scale"]
        )
    }
    wrong = {k: (sorted(v), listed.get(k)) for k, v in published.items() if v != {listed.get(k)}}
    assert not wrong, f"{len(wrong)} published shapes listed otherwise, e.g. {list(wrong.items())[:3]}"
    extra = sorted(set(listed) - set(published))
    assert len(extra) == 4 and {d for d, _ in extra} <= {"dt4d_animal", "dt4d_human"}, extra
    print(f"\nDT4D frames of the info files that no published pair uses: {extra}")


@pytest.mark.parametrize("setting", PUBLISHED_SETTINGS)
def test_original_settings_import_the_published_counts(tree, catalog_path, setting):
    results = catalog_path.parent
    config = full_config(tree, results, original_settings=True, setting=list(PUBLISHED_SETTINGS))
    out = results / setting / "manifest.csv"
    write_manifest_stage(config, setting, catalog_path, out)
    manifest = read_manifest(out)
    assert manifest["split"].value_counts().to_dict() == PUBLISHED_PAIRS
    assert manifest["pair_id"].is_unique and (manifest["setting"] == setting).all()
    assert set(manifest["x_dataset"]) | set(manifest["y_dataset"]) == set(DATASETS)


def test_catalog_order_puts_a_name_before_its_extensions():
    # SMAL has cows/cow_alph and cows/cow_alph5: the catalog's sort key must order them, not raise
    from becos.sources.catalog import natural_key

    names = ["cows/cow_alph5", "cows/cow_alph", "cows/cow_alph10", "cows/Cow_alph"]
    assert sorted(names, key=natural_key) == ["cows/Cow_alph", "cows/cow_alph", "cows/cow_alph5", "cows/cow_alph10"]
