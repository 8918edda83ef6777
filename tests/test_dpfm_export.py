"""The DPFM export read by DPFM's own loading code (issue #34): every item the loader forms from a
finished tiny TOSCA run's three settings gets the ground-truth functional map ``C_gt`` built from the
pair's true correspondences, never one in which a ``-1`` row became a match with shape 1's last vertex.

The loading lines are transcribed from DPFM (github.com/pvnieo/DPFM, MIT licence),
``dpfm/shrec_partial_dataset.py`` ``ShrecPartialDataset.__init__`` / ``__getitem__``, and its
Laplacian eigenbasis from ``dpfm/diffusion_net/geometry.py`` ``compute_operators``, numpy in place of
torch (dense ``P`` in float32 as ``torch.zeros``; numpy's index ``-1`` wraps to the last column as
torch's does).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from becos.products.export import DPFM_NONE_MAPS, write_dpfm

SETTINGS = ("full_full", "partial_full", "partial_partial")
N_FMAP = 30  # ShrecPartialDataset(n_fmap=30), the default DPFM trains with


def dpfm_eigenbasis(verts: np.ndarray, faces: np.ndarray, k_eig: int) -> tuple[np.ndarray, np.ndarray]:
    """diffusion_net ``compute_operators`` (as vendored by DPFM), its eigenbasis part: cotan Laplacian
    and vertex areas of potpourri3d, ``eigsh(L + eps I, k, M, sigma=eps)``. Returns (V, k) eigenvectors
    and the (V,) mass vector (area units of the mesh)."""
    import potpourri3d as pp3d
    import scipy.sparse
    import scipy.sparse.linalg as sla

    eps = 1e-8
    L = pp3d.cotan_laplacian(verts, faces, denom_eps=1e-10)
    massvec_np = pp3d.vertex_areas(verts, faces)
    massvec_np += eps * np.mean(massvec_np)
    L_eigsh = (L + scipy.sparse.identity(L.shape[0]) * eps).tocsc()
    Mmat = scipy.sparse.diags(massvec_np)
    _, evecs_np = sla.eigsh(L_eigsh, k=k_eig, M=Mmat, sigma=eps)
    return evecs_np.astype(np.float32), massvec_np.astype(np.float32)


def dpfm_items(root_dir: Path, name: str = "") -> list[dict]:
    """``ShrecPartialDataset(root_dir, name)`` item by item: ``shape1``/``shape2`` names, ``map21``,
    ``C_gt`` ((n_fmap, n_fmap) float32), ``gt_partiality_mask12`` (over shape 1) and
    ``gt_partiality_mask21`` (over shape 2), plus ``C_true``: ``C_gt`` built from the rows of
    ``map21`` that hold a vertex (no ``-1``), and the two shapes' vertex counts."""
    import potpourri3d as pp3d

    # __init__
    used_shapes = sorted([x.stem for x in (Path(root_dir) / "shapes").iterdir() if name in x.stem])
    corres_path = Path(root_dir) / "maps"
    all_combs = [x.stem for x in corres_path.iterdir() if name in x.stem]
    corres_dict = {}
    for x, y in map(lambda x: (x[: x.rfind("_")], x[x.rfind("_") + 1 :]), all_combs):
        if x in used_shapes and y in used_shapes:
            map_ = np.loadtxt(corres_path / f"{x}_{y}.map", dtype=np.int32).astype(np.int64)
            corres_dict[(used_shapes.index(y), used_shapes.index(x))] = map_
    combinations = list(corres_dict.keys())
    mesh_dirpath = Path(root_dir) / "shapes"
    operators: dict[int, tuple] = {}  # only the shapes some item uses (DPFM computes all of them)

    def shape(idx):
        if idx not in operators:
            verts, faces = pp3d.read_mesh(str(mesh_dirpath / f"{used_shapes[idx]}.off"))
            operators[idx] = (len(verts), *dpfm_eigenbasis(verts, faces, N_FMAP))
        return operators[idx]

    # __getitem__
    items = []
    for idx1, idx2 in combinations:
        (n1, evecs1, _), (n2, evecs2, mass2) = shape(idx1), shape(idx2)
        map21 = corres_dict[(idx1, idx2)]
        evec_1, evec_2 = evecs1[:, :N_FMAP], evecs2[:, :N_FMAP]
        trans_evec2 = evec_2.T @ np.diag(mass2)
        P = np.zeros((evec_2.shape[0], evec_1.shape[0]), dtype=np.float32)
        P[range(evec_2.shape[0]), map21.flatten()] = 1
        C_gt = trans_evec2 @ P @ evec_1
        gt_partiality_mask12 = np.zeros(n1, dtype=np.int64)
        gt_partiality_mask12[map21[map21 != -1]] = 1
        gt_partiality_mask21 = np.zeros(n2, dtype=np.int64)
        gt_partiality_mask21[map21 != -1] = 1
        # the ground truth DPFM means: rows without a counterpart stay zero
        rows = np.flatnonzero(map21 != -1)
        P_true = np.zeros_like(P)
        P_true[rows, map21[rows]] = 1
        C_true = trans_evec2 @ P_true @ evec_1
        items.append(
            {
                "shape1": used_shapes[idx1],
                "shape2": used_shapes[idx2],
                "map21": map21,
                "C_gt": C_gt,
                "C_true": C_true,
                "gt_partiality_mask12": gt_partiality_mask12,
                "gt_partiality_mask21": gt_partiality_mask21,
            }
        )
    return items


def _ids(out: Path) -> dict[str, dict]:
    import csv

    with open(out / "ids.csv", encoding="utf-8", newline="") as fh:
        return {row["pair_id"]: row for row in csv.DictReader(fh)}


def _own_mask(out: Path, split: str, a: str, b: str) -> np.ndarray:
    """Shape a's true overlap mask ((V_a,) bool) from the export: ``<a>_<b>.map != -1``, the map in
    ``maps/`` or in ``maps_with_none/`` (docs/released-layout.md section 6)."""
    found = [out / split / folder / f"{a}_{b}.map" for folder in ("maps", DPFM_NONE_MAPS)]
    (path,) = [p for p in found if p.is_file()]
    return np.loadtxt(path, dtype=np.int64) != -1


@pytest.mark.parametrize("setting", SETTINGS)
def test_dpfm_loader_builds_the_true_ground_truth(setting, tiny_tosca_run, tmp_path):
    from becos.products.store import open_benchmark

    bench = open_benchmark(tiny_tosca_run / "results" / setting / "benchmark.zarr")
    records = {r.pair_id: r for r in bench.records()}
    out = write_dpfm(records.values(), tmp_path / "dpfm")
    ids = _ids(out)
    # every direction of every pair: (split, shape2 = the map's first id, shape1 = its second id) -> corr
    directions = {}
    for pair_id, r in records.items():
        row = ids[pair_id]
        directions[(row["split"], row["x_id"], row["y_id"])] = (np.asarray(r["corr_01"]), r, "x", "y")
        directions[(row["split"], row["y_id"], row["x_id"])] = (np.asarray(r["corr_10"]), r, "y", "x")
    representable = {k for k, (corr, *_) in directions.items() if (corr >= 0).all()}

    n_items = n_correct = n_mask12_off = 0
    shares_off = []  # per item: share of shape 1's vertices where mask12 is not shape 1's own overlap
    seen = set()
    for split in sorted({row["split"] for row in ids.values()}):
        for item in dpfm_items(out / split):
            key = (split, item["shape2"], item["shape1"])
            corr, r, s2, s1 = directions[key]
            seen.add(key)
            n_items += 1
            n_correct += bool(np.array_equal(item["C_gt"], item["C_true"]))
            assert np.array_equal(item["map21"], corr)
            # mask21 is shape 2's own overlap mask; mask12 (the image of map21) need not be shape 1's
            assert np.array_equal(item["gt_partiality_mask21"].astype(bool), r[f"{s2}_overlap_mask"])
            true12 = _own_mask(out, split, item["shape1"], item["shape2"])
            assert np.array_equal(true12, r[f"{s1}_overlap_mask"])
            off = item["gt_partiality_mask12"].astype(bool) != true12
            n_mask12_off += bool(off.any())
            shares_off.append(off.mean())
    print(
        f"\n{setting}: {len(records)} pairs, {len(directions)} map directions, DPFM forms {n_items} items, "
        f"C_gt correct on {n_correct} of {n_items}; mask12 != shape 1's own overlap on {n_mask12_off} items"
        + (f" ({min(shares_off):.0%}-{max(shares_off):.0%} of its vertices)" if shares_off else "")
    )
    assert n_correct == n_items, f"{setting}: C_gt wrong on {n_items - n_correct} of {n_items} items"
    assert seen == representable  # every map DPFM can represent reaches it, and no other
    # the directions DPFM cannot represent are kept beside maps/, where DPFM's loader does not look
    splits = {row["split"] for row in ids.values()}
    kept = {(split, *p.stem.split("_")) for split in splits for p in (out / split / DPFM_NONE_MAPS).iterdir()}
    assert kept == set(directions) - representable
    log = yaml.safe_load((out / "logs" / "config.yaml").read_text(encoding="utf-8"))
    assert log["maps"] == {
        split: {"maps": sum(k[0] == split for k in representable), DPFM_NONE_MAPS: sum(k[0] == split for k in kept)}
        for split in splits
    }
