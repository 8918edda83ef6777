"""Exports (released BeCoS folders, PSMAL maps, geodesic matrices) of real TOSCA pair records, read
back by a small loader written from docs/released-layout.md alone (OFF text, .npy, pickles)."""

from __future__ import annotations

import csv
import io
import json
import pickle
import random
from pathlib import Path

import numpy as np
import pytest

from becos.build.record import PairRecord
from becos.products.export import ExportError, write_geodesics, write_psmal, write_released

SETTINGS = ("full_full", "partial_full", "partial_partial")


# --------------------------------------------------------------------------------------------------
# records: the fixture's two pairs per setting plus two copies in "train" whose ids sort before and
# after the fixture's, one of them with annotation labels


def _copy(record: PairRecord, pair_id: str, split: str, **arrays) -> PairRecord:
    meta = json.loads(json.dumps(record.meta))
    meta.update(pair_id=pair_id, split=split)
    return PairRecord({**record.arrays, **arrays}, meta)


@pytest.fixture(scope="module")
def records(pair_record_files) -> dict[str, list[PairRecord]]:
    out = {}
    for setting, paths in pair_record_files.items():
        base = [PairRecord.load(p) for p in paths]
        labels = (np.arange(len(base[0]["x_vertices"])) % 3 - 1).astype(np.int8)  # -1, 0, 1, -1, ...
        extra = [
            _copy(base[1], "a" + base[1].pair_id, "train"),
            _copy(base[0], "z" + base[0].pair_id, "train", x_annotation=labels),
        ]
        out[setting] = base + extra
    return out


def _shuffled(items: list, seed: int = 0) -> list:
    items = list(items)
    random.Random(seed).shuffle(items)
    return items


# --------------------------------------------------------------------------------------------------
# the loader, from docs/released-layout.md only


class _PortableUnpickler(pickle.Unpickler):
    """Accepts only what the doc promises: builtins and numpy.ndarray(shape, dtype, bytearray)."""

    def find_class(self, module, name):
        if (module, name) in {("numpy", "ndarray"), ("builtins", "bytearray")}:
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"info pickle references {module}.{name}")


def read_info(path: Path) -> dict:
    data = path.read_bytes()
    assert data[:2] == b"\x80\x04", "protocol 4"
    return _PortableUnpickler(io.BytesIO(data)).load()


def read_off(path: Path) -> tuple[np.ndarray, np.ndarray]:
    lines = path.read_text(encoding="utf-8").split("\n")
    assert lines[0] == "OFF"
    nv, nf, ne = (int(t) for t in lines[1].split())
    assert ne == 0
    v = np.array([float(t) for t in " ".join(lines[2 : 2 + nv]).split()], dtype=np.float64).reshape(nv, 3)
    f = np.array([int(t) for t in " ".join(lines[2 + nv : 2 + nv + nf]).split()], dtype=np.int64).reshape(nf, 4)
    assert (f[:, 0] == 3).all() and lines[2 + nv + nf :] == [""]
    return v, f[:, 1:]


def read_ids(out: Path) -> list[dict]:
    with open(out / "ids.csv", encoding="utf-8", newline="") as fh:
        return list(csv.DictReader(fh))


def load_released(out: Path) -> dict[tuple[str, int], dict]:
    """{(split, index): pair} of a released export."""
    pairs = {}
    for row in read_ids(out):
        folder = out / row["split"] / row["index"]
        pair = {"row": row}
        for k in (0, 1):
            (off,) = folder.glob(f"{k}_*.off")
            pair[f"off{k}"] = read_off(off)
            pair[f"info{k}"] = read_info(off.with_name(off.stem + "_info.pkl"))
            pair[f"file{k}"] = off.name
            ann = folder / f"{k}_annotation.npy"
            pair[f"ann{k}"] = np.load(ann, allow_pickle=False) if ann.exists() else None
        for name in ("corres_01", "corres_10"):
            path = folder / f"{name}.npy"
            pair[name] = np.load(path, allow_pickle=False) if path.exists() else None
        pairs[(row["split"], int(row["index"]))] = pair
    return pairs


def _check_numbering(out: Path, rows: list[dict], records: list[PairRecord], allowed: set[str]) -> None:
    by_split: dict[str, list[str]] = {}
    for r in records:
        by_split.setdefault(r.meta["split"], []).append(r.pair_id)
    assert {row["split"] for row in rows} == set(by_split)
    assert sorted(p.name for p in out.iterdir()) == sorted(["ids.csv", "logs", *by_split])
    for split, ids in by_split.items():
        split_rows = [row for row in rows if row["split"] == split]
        assert [int(row["index"]) for row in split_rows] == list(range(len(ids)))
        assert [row["pair_id"] for row in split_rows] == sorted(ids)
        # split folders hold nothing but their own entries (some loaders list them as pair folders)
        assert {p.name for p in (out / split).iterdir()} == (allowed or {str(i) for i in range(len(ids))})


# --------------------------------------------------------------------------------------------------
# released layout


@pytest.mark.parametrize("setting", SETTINGS)
def test_released_round_trip(setting, records, tmp_path):
    recs = records[setting]
    out = write_released(_shuffled(recs), tmp_path / "BeCoS" / setting, setting=setting)
    assert out == tmp_path / "BeCoS" / setting
    assert [p.name for p in (tmp_path / "BeCoS").iterdir()] == [setting]  # no temp folder left
    rows = read_ids(out)
    _check_numbering(out, rows, recs, set())
    log = (out / "logs" / "config.yaml").read_text()
    assert "becos.products.export.write_released" in log and f"setting: {setting}" in log

    by_id = {r.pair_id: r for r in recs}
    for (split, index), pair in load_released(out).items():
        r = by_id[pair["row"]["pair_id"]]
        assert r.meta["split"] == split
        assert pair["row"]["x"] == r.meta["x"]["name"] and pair["row"]["y"] == r.meta["y"]["name"]
        variants = int(r["x_remesh_variant"]), int(r["y_remesh_variant"])
        assert variants == (0, 0)  # remesh variant 0 of cat0 and cat3: "_v0" in the file names
        scanned = {"full_full": (), "partial_full": ("y",), "partial_partial": ("x", "y")}[setting]
        for k, s in ((0, "x"), (1, "y")):  # each scan is its own mesh: the pair id in its file name
            scan = f"_scan-{r.pair_id}" if s in scanned else ""
            assert pair[f"file{k}"] == f"{k}_{r.meta[s]['name']}_v0{scan}.off"
        for k, s in ((0, "x"), (1, "y")):
            v, f = pair[f"off{k}"]
            assert v.dtype == np.float64 and np.array_equal(v, r[f"{s}_vertices"])  # exact
            assert np.array_equal(f, r[f"{s}_faces"])
        assert pair["corres_10"].dtype == np.int64 and np.array_equal(pair["corres_10"], r["corr_10"])
        if setting == "partial_full":
            assert pair["corres_01"] is None
        else:
            assert pair["corres_01"].dtype == np.int64 and np.array_equal(pair["corres_01"], r["corr_01"])

        i0, i1 = pair["info0"], pair["info1"]
        for info, s in ((i0, "x"), (i1, "y")):
            assert info["name"] == r.meta[s]["name"] and info["org_dataset"] == r.meta[s]["dataset"]
            assert info["scale_per_dataset"] == r[f"{s}_dataset_scale"]
            assert info["surface_area"] == info["surface_area_after_scaling"] == r[f"{s}_full_sqrt_area"]
            assert type(info["surface_area"]) is float and info["pair_id"] == r.pair_id
            assert np.array_equal(info["random_rotation"], r[f"{s}_random_rotation"])
            assert info["random_rotation"].flags.writeable
            assert info["remesh_variant"] == 0 and info["mesh_id"].startswith(f"tosca/{info['name']}/v0")
        assert i0["align_rotation"] is None and i0["align_translation"] is None
        assert np.array_equal(i1["align_rotation"], r["y_align_rotation"])
        assert np.array_equal(i1["align_translation"], r["y_align_translation"])

        scanned = {"full_full": (), "partial_full": ("y",), "partial_partial": ("x", "y")}[setting]
        for info, s in ((i0, "x"), (i1, "y")):
            if s in scanned:
                assert info["partial2full"].dtype == np.int64
                assert np.array_equal(info["partial2full"], r[f"{s}_partial_to_full"])
                assert np.array_equal(info["cam_pos"], r[f"{s}_camera"][0]) and info["cam_pos"].shape == (3,)
            else:
                assert "partial2full" not in info and "cam_pos" not in info
            # every setting: each shape's OWN mask under the reference's key (the reference swaps them in
            # P2P and has none in F2F)
            assert info["overlap_mask"].dtype == bool and np.array_equal(info["overlap_mask"], r[f"{s}_overlap_mask"])
            assert len(info["overlap_mask"]) == len(r[f"{s}_vertices"])
            assert info["overlap_percentage"] == pytest.approx(info["overlap_mask"].mean())
            assert info["mesh_id"].endswith(f"/scan/{r.pair_id}/{s}") == (s in scanned)
        if setting in ("partial_partial", "full_full"):  # released placement: the other shape's mask
            assert np.array_equal(i0["found_faces_mask_yx"], r["y_overlap_mask"]) and "found_faces_mask" not in i0
            assert np.array_equal(i1["found_faces_mask"], r["x_overlap_mask"]) and "found_faces_mask_yx" not in i1
        if setting == "partial_full":
            assert np.array_equal(i0["found_faces_mask"], r["x_overlap_mask"])
            assert len(i0["found_faces_mask"]) == len(r["x_vertices"]) == len(r["x_partial_to_full"])

        labelled = pair["row"]["pair_id"].startswith("z")
        assert (pair["ann0"] is not None) == labelled and (pair["ann1"] is not None) == labelled
        if labelled:
            assert pair["ann0"].dtype == np.int8 and np.array_equal(pair["ann0"], r["x_annotation"])
            assert np.array_equal(pair["ann1"], np.full(len(r["y_vertices"]), -1, np.int8))


def _dsmk_masks(info_x: dict, info_y: dict, setting: str, n_x: int, n_y: int) -> tuple[np.ndarray, np.ndarray]:
    """The partiality-mask lines of DeepShapeMatchingKit's BeCoSDataset.__getitem__ (numpy port)."""
    if setting == "partial_partial":
        if "found_faces_mask_yx" in info_x:
            mask_x, mask_y = info_x["found_faces_mask_yx"].astype(int), info_y["found_faces_mask"].astype(int)
        else:
            mask_x, mask_y = info_x["found_faces_mask"].astype(int), info_y["found_faces_mask_yx"].astype(int)
        return mask_y, mask_x  # "somehow the mask live on the other side, we need to swap them"
    if setting == "partial_full":
        return info_x["found_faces_mask"].astype(int), np.ones(n_y)
    return np.ones(n_x), np.ones(n_y)


@pytest.mark.parametrize("setting", SETTINGS)
def test_released_layout_reads_like_deepshapematchingkit(setting, records, tmp_path):
    """Replays DeepShapeMatchingKit's BeCoSDataset file logic: pairs (0, 1) with corres_10 and, for F2F and
    P2P, (1, 0) with corres_01; masks via its key dance must give each shape its own mask."""
    import trimesh

    r = records[setting][0]
    out = write_released([r], tmp_path / "BeCoS" / setting / "x", setting=setting)
    data_root = out / r.meta["split"]
    folders = [p for p in data_root.glob("*") if p.name.isdigit()]
    highest = max(int(p.name) for p in folders)
    assert highest == 0
    folder = data_root / "0"
    off0, off1 = sorted(folder.glob("0_*.off"))[0], sorted(folder.glob("1_*.off"))[0]
    directions = [(off0, off1, "corres_10.npy", "x", "y")]
    if setting in ("partial_partial", "full_full"):
        directions.append((off1, off0, "corres_01.npy", "y", "x"))
    for off_x, off_y, corr_file, sx, sy in directions:
        info_x = pickle.loads(Path(str(off_x).replace(".off", "_info.pkl")).read_bytes())
        info_y = pickle.loads(Path(str(off_y).replace(".off", "_info.pkl")).read_bytes())
        mesh_x = trimesh.load(off_x, process=False, maintain_order=True)
        mesh_y = trimesh.load(off_y, process=False, maintain_order=True)
        assert np.array_equal(mesh_x.vertices, r[f"{sx}_vertices"]) and np.array_equal(mesh_x.faces, r[f"{sx}_faces"])
        corr = np.load(folder / corr_file)
        valid = corr != -1
        assert len(corr) == len(mesh_y.vertices) and corr[valid].max() < len(mesh_x.vertices)
        assert np.array_equal(valid, r[f"{sy}_overlap_mask"])  # corr_y = arange(len(corr))[valid]
        # "normalized" scale: vertices / surface_area_after_scaling -> the FULL shape has unit area
        unit = np.sqrt(mesh_x.area_faces.sum()) / info_x["surface_area_after_scaling"]
        if len(mesh_x.vertices) == len(r[f"{sx}_partial_to_full"]) and not len(r[f"{sx}_full_faces"]):
            assert unit == pytest.approx(1.0, rel=1e-9)
        else:
            assert 0.2 < unit < 1.0
        mask_x, mask_y = _dsmk_masks(info_x, info_y, setting, len(mesh_x.vertices), len(mesh_y.vertices))
        assert len(mask_x) == len(mesh_x.vertices) and len(mask_y) == len(mesh_y.vertices)
        if setting != "full_full":
            assert np.array_equal(mask_x.astype(bool), r[f"{sx}_overlap_mask"])
        if setting == "partial_partial":
            assert np.array_equal(mask_y.astype(bool), r[f"{sy}_overlap_mask"])


def test_released_refuses_and_replaces_existing_output(records, tmp_path):
    recs = records["full_full"]
    out = tmp_path / "full_full"
    out.mkdir()
    (out / "keep.txt").write_text("old")
    with pytest.raises(ExportError, match="not empty"):
        write_released(recs, out, setting="full_full")
    assert (out / "keep.txt").exists()
    write_released(recs[:1], out, setting="full_full", overwrite=True)
    assert not (out / "keep.txt").exists() and len(read_ids(out)) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["full_full"]  # no temp or old folders left
    with pytest.raises(ExportError, match="setting 'partial_full'"):
        write_released(records["partial_full"], tmp_path / "mixed", setting="full_full")
    with pytest.raises(ExportError, match="more than once"):
        write_released([recs[0], recs[0]], tmp_path / "dup", setting="full_full")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["full_full"]


# --------------------------------------------------------------------------------------------------
# PSMAL layout


def read_vts(path: Path) -> np.ndarray:
    text = path.read_text(encoding="utf-8")
    assert text.endswith("\n")
    return np.array([int(t) for t in text.split("\n")[:-1]], dtype=np.int64)


@pytest.mark.parametrize("setting", SETTINGS)
def test_psmal_round_trip(setting, records, tmp_path):
    recs = records[setting]
    out = write_psmal(_shuffled(recs, 1), tmp_path / "psmal")
    rows = read_ids(out)
    _check_numbering(out, rows, recs, {"shapes", "maps"})
    by_id = {r.pair_id: r for r in recs}
    for row in rows:
        r = by_id[row["pair_id"]]
        root = out / row["split"]
        a, b = row["x_id"], row["y_id"]
        assert a.split("_")[:2] == [row["index"], "0"] and b.split("_")[:2] == [row["index"], "1"]
        for shape_id, s in ((a, "x"), (b, "y")):
            assert len(shape_id.split("_")) == 4
            v, f = read_off(root / "shapes" / f"{shape_id}.off")
            assert np.array_equal(v, r[f"{s}_vertices"]) and np.array_equal(f, r[f"{s}_faces"])
        assert np.array_equal(read_vts(root / "maps" / f"{a}_{b}.vts"), r["corr_01"])
        assert np.array_equal(read_vts(root / "maps" / f"{b}_{a}.vts"), r["corr_10"])
    # PSMAL loaders: every map is one pair, shapes = first four and next four "_" fields of its name
    for split in {row["split"] for row in rows}:
        maps = sorted((out / split / "maps").glob("*.vts"))
        n = sum(row["split"] == split for row in rows)
        assert len(maps) == 2 * n and len(list((out / split / "shapes").glob("*.off"))) == 2 * n
        for m in maps:
            parts = m.name[:-4].split("_")
            assert len(parts) == 8
            first, second = "_".join(parts[:4]), "_".join(parts[4:8])
            corr = np.loadtxt(m, dtype=np.int32)  # as the loaders read it (0-based, -1 = none)
            n_first = len(read_off(out / split / "shapes" / f"{first}.off")[0])
            n_second = len(read_off(out / split / "shapes" / f"{second}.off")[0])
            assert len(corr) == n_first and corr.min() >= -1 and corr.max() < n_second


# --------------------------------------------------------------------------------------------------
# geodesics (small pair: two scanned spheres) and the command line


@pytest.fixture(scope="module")
def small_record() -> PairRecord:
    import trimesh

    from becos.build.pairs import PairOptions, ShapeInstance, build_pair
    from becos.core.mesh import TriMesh
    from becos.core.surface_map import SurfaceMap

    sphere = trimesh.creation.icosphere(subdivisions=3)
    v, f = np.asarray(sphere.vertices) * 0.5, np.asarray(sphere.faces)
    x = ShapeInstance("synthetic", "ball", "blob", "ball", TriMesh(v, f))
    y = ShapeInstance("synthetic", "egg_1", "blob", "egg", TriMesh(v * [1.2, 1.0, 0.9], f))
    gt = SurfaceMap.identity(f, len(v))
    record = build_pair(
        x, y, gt, gt, pair_id="small", seed=3, split="test", options=PairOptions(setting="partial_partial")
    )
    assert len(record["x_vertices"]) < len(v) and len(record["y_vertices"]) < len(v)
    return record


def _edge_dijkstra(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    from scipy.sparse.csgraph import dijkstra

    from becos.core.geodesics import edge_graph
    from becos.core.mesh import TriMesh

    return dijkstra(edge_graph(TriMesh(vertices, faces)), directed=False)


def test_geodesics_on_full_shape(small_record, tmp_path):
    r = small_record
    out = write_psmal([r], tmp_path / "psmal")
    write_geodesics([r], out, "dijkstra")
    with pytest.raises(ExportError, match="exist already"):
        write_geodesics([r], out, "heat")
    write_geodesics([r], out, "heat", overwrite=True)
    (row,) = read_ids(out)
    assert sorted(p.name for p in out.iterdir()) == ["ids.csv", "logs", "test"]
    assert {p.name for p in (out / "test").iterdir()} == {"shapes", "maps", "geodesics"}
    heat = {s: np.load(out / "test" / "geodesics" / f"{row[f'{s}_id']}.npy") for s in ("x", "y")}
    dijkstra_out = tmp_path / "dijkstra"
    write_geodesics([r], dijkstra_out, "dijkstra")
    edge = {s: np.load(dijkstra_out / "test" / "geodesics" / f"{row[f'{s}_id']}.npy") for s in ("x", "y")}
    for s in ("x", "y"):
        d, e = heat[s], edge[s]
        n = len(r[f"{s}_vertices"])
        assert d.dtype == np.float32 and d.shape == (n, n) and e.shape == (n, n)
        assert np.array_equal(d, d.T) and not np.diag(d).any()
        full = _edge_dijkstra(r[f"{s}_full_vertices"], r[f"{s}_full_faces"])
        p2f = r[f"{s}_partial_to_full"]
        assert np.allclose(e, full[np.ix_(p2f, p2f)], rtol=1e-6)  # measured on the FULL shape
        on_cut = _edge_dijkstra(r[f"{s}_vertices"], r[f"{s}_faces"])
        assert (e <= on_cut * (1 + 1e-6)).all()  # a cut can only lengthen paths
        vertices = r[f"{s}_vertices"]
        euclid = np.linalg.norm(vertices[:, None] - vertices[None], axis=2)
        far = euclid > 0.1
        assert (d[far] >= 0.85 * euclid[far]).all()  # heat is approximate on this coarse mesh
        assert 1.0 < np.median(e[far] / d[far]) < 1.2  # edge paths are a little longer than surface geodesics
    # X is a sphere of radius 0.5 about the origin: exact geodesics are great-circle arcs
    unit = r["x_vertices"] / np.linalg.norm(r["x_vertices"], axis=1, keepdims=True)
    arc = 0.5 * np.arccos(np.clip(unit @ unit.T, -1.0, 1.0))
    far = arc > 0.1
    ratio = heat["x"][far] / arc[far]
    assert abs(np.median(ratio) - 1.0) < 0.03 and np.abs(ratio - 1.0).max() < 0.1
    assert 1.0 < np.median(edge["x"][far] / arc[far]) < 1.15


def test_cli_exports_a_store(records, pair_record_files, small_record, tmp_path, capsys):
    import becos.products.store as store
    from becos.cli import main

    setting = "partial_partial"
    store_path = store.write_store(pair_record_files[setting], tmp_path / "pp.zarr", setting=setting, progress=False)
    out = tmp_path / "BeCoS" / setting
    assert main(["export-released", str(store_path), str(out)]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["pairs"] == {"train": 1, "test": 1} and result["setting"] == setting
    direct = write_released(
        [PairRecord.load(p) for p in pair_record_files[setting]], tmp_path / "direct", setting=setting
    )
    files = sorted(p.relative_to(direct) for p in direct.rglob("*") if p.is_file() and p.parent.name != "logs")
    assert files == sorted(p.relative_to(out) for p in out.rglob("*") if p.is_file() and p.parent.name != "logs")
    assert all((direct / f).read_bytes() == (out / f).read_bytes() for f in files)
    assert main(["export-released", str(store_path), str(out)]) == 2  # exists: refused with a message
    assert "Fix:" in capsys.readouterr().err
    assert main(["export-released", str(store_path), str(out), "--force"]) == 0

    small_npz = tmp_path / "small.npz"
    small_record.save(small_npz)
    small_store = store.write_store([small_npz], tmp_path / "small.zarr", setting=setting, progress=False)
    capsys.readouterr()
    assert main(["export-psmal", str(small_store), str(tmp_path / "psmal"), "--geodesics"]) == 0
    assert json.loads(capsys.readouterr().out)["geodesics"] == "heat"
    (row,) = read_ids(tmp_path / "psmal")
    d = np.load(tmp_path / "psmal" / "test" / "geodesics" / f"{row['y_id']}.npy")
    assert d.shape == (len(small_record["y_vertices"]),) * 2
    assert main(["export-geodesics", str(small_store), str(tmp_path / "geo"), "--splits", "train"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["matrices"] == 0 and result["splits"] == ["train"]  # the small pair is in "test"
    assert main(["export-geodesics", str(small_store), str(tmp_path / "geo"), "--force", "--jobs", "2"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["matrices"] == 2 and result["bytes"] > 4 * len(small_record["y_vertices"]) ** 2
    assert main(["export-geodesics", str(small_store), str(tmp_path / "geo2"), "--jobs", "0"]) == 2


# --------------------------------------------------------------------------------------------------
# one name, several remesh variants; F2F masks (semantic missing parts)


def _ball_records(setting: str) -> list[PairRecord]:
    """ "ball" remeshed twice (variant 0: 162 vertices, variant 1: 642) paired with "egg"; egg vertices
    with y > 0.25 are a semantic missing part (no counterpart on the ball). Pairs ball0a, ball0b
    (variant 0, two seeds) and ball1 (variant 1)."""
    import trimesh
    from scipy.spatial import cKDTree

    from becos.build.pairs import PairOptions, ShapeInstance, build_pair
    from becos.core.mesh import TriMesh
    from becos.core.surface_map import SurfaceMap

    coarse, fine = trimesh.creation.icosphere(subdivisions=2), trimesh.creation.icosphere(subdivisions=3)
    fv, ff = np.asarray(fine.vertices), np.asarray(fine.faces)
    egg = ShapeInstance("synthetic", "egg", "blob", "egg", TriMesh(fv * [0.6, 0.5, 0.45], ff), remesh_variant=0)
    out = []
    for pair_id, variant, sphere, seed in (("ball0a", 0, coarse, 1), ("ball0b", 0, coarse, 2), ("ball1", 1, fine, 3)):
        v, f = np.asarray(sphere.vertices), np.asarray(sphere.faces)
        assert np.allclose(v, fv[: len(v)])  # icosphere levels share their first vertices
        ball = ShapeInstance("synthetic", "ball", "blob", "ball", TriMesh(v * 0.5, f), remesh_variant=variant)
        from_egg = cKDTree(v).query(fv)[1]
        from_egg[fv[:, 1] > 0.5] = -1  # the missing part
        gt_xy = SurfaceMap.from_vertex_indices(np.arange(len(v)), ff)
        gt_yx = SurfaceMap.from_vertex_indices(from_egg, f)
        out.append(
            build_pair(
                ball, egg, gt_xy, gt_yx, pair_id=pair_id, seed=seed, split="test", options=PairOptions(setting=setting)
            )
        )
    return out


def _distances(vertices: np.ndarray) -> np.ndarray:
    """A rotation-invariant per-shape quantity (stands in for a geodesic matrix)."""
    return np.linalg.norm(vertices[:, None] - vertices[None], axis=2)


@pytest.mark.parametrize("setting", ["full_full", "partial_full"])
def test_name_keyed_cache_and_f2f_masks(setting, tmp_path):
    """A loader that caches a per-shape matrix under the OFF file's stem (as geo-lora caches geodesics
    under ``<off stem>.npy``) gets each variant's own mesh; masks are read where DSMK would assume ones."""
    import trimesh

    recs = _ball_records(setting)
    out = write_released(recs, tmp_path / setting, setting=setting)
    cache: dict[str, np.ndarray] = {}
    hits = 0
    by_name: dict[str, int] = {}
    for row in read_ids(out):
        folder = out / row["split"] / row["index"]
        offs = sorted(folder.glob("*.off"))
        for k, off in enumerate(offs):
            vertices = np.asarray(trimesh.load(off, process=False, maintain_order=True).vertices)
            info = read_info(off.with_name(off.stem + "_info.pkl"))
            if off.stem in cache:
                hits += 1
                # a cache hit must be the same mesh (up to the pair's rigid motion)
                np.testing.assert_allclose(cache[off.stem], _distances(vertices), atol=1e-9)
            else:
                cache[off.stem] = _distances(vertices)
            by_name.setdefault(info["name"], len(vertices))
            if k == 0:  # the ball: one name, two meshes, told apart by file name and info
                assert info["name"] == "ball" and off.stem == f"0_ball_v{info['remesh_variant']}"
                assert info["mesh_id"] == f"synthetic/ball/v{info['remesh_variant']}"
        # masks: both shapes carry their own; where corres is -1 the mask is 0 (not the all-ones default)
        mask_egg = read_info(offs[1].with_name(offs[1].stem + "_info.pkl"))["overlap_mask"]
        corr = np.load(folder / "corres_10.npy")
        assert np.array_equal(mask_egg, corr != -1) and 0 < (~mask_egg).sum() < len(mask_egg)
    eggs = ["1_egg_v0"] if setting == "full_full" else [f"1_egg_v0_scan-{r.pair_id}" for r in recs]
    assert sorted(cache) == sorted(["0_ball_v0", "0_ball_v1", *eggs])
    assert hits == (3 if setting == "full_full" else 1)  # ball v0 again (+ the full egg twice in F2F)
    # keyed by name alone, the cache would have served ball v0's 162 vertices to ball v1 (642)
    assert by_name["ball"] == 162 and len(cache["0_ball_v1"]) == 642


def geolora_cached_geodesics_path(full_file: str) -> str:
    """Where geo-lora's ``BecosDataset`` (P2F mode) loads a full shape's geodesic matrix instead of
    computing it: ``./geodesic_dist_matrices/<OFF file name before ".off">.npy``, relative to the
    working folder, for the first ``.off`` of the sorted pair folder (geo-lora ``utils/shape_dataset.py``,
    ``BaseDataset.get_geodesic_distmat`` with ``loading=True``; licence not stated in our index). The
    matrix it computes otherwise is divided by the shape's sqrt-area (``normalize=True``)."""
    return "./geodesic_dist_matrices/" + full_file.split(".off")[0] + ".npy"


def test_geodesic_matrices_where_loaders_read_them(tmp_path, monkeypatch):
    import trimesh

    from becos.products.export import GEODESIC_FOLDER, write_geodesic_matrices

    recs = _ball_records("partial_full")
    recs[2] = _copy(recs[2], recs[2].pair_id, "train")  # ball v1 in train: left out by splits=["test"]
    released = write_released(recs, tmp_path / "BeCoS" / "partial_full", setting="partial_full")
    out = write_geodesic_matrices(recs, tmp_path / "geodesics", splits=["test"], jobs=2)
    with open(out / GEODESIC_FOLDER / "index.csv", encoding="utf-8", newline="") as fh:
        index = list(csv.DictReader(fh))
    assert {row["split"] for row in index} == {"test"} and len(index) == 4  # 2 test pairs x 2 shapes
    files = sorted(p.name for p in (out / GEODESIC_FOLDER).glob("*.npy"))
    assert len(files) == 3  # ball v0 once (two pairs), two scans of the egg
    monkeypatch.chdir(out)  # geo-lora reads ./geodesic_dist_matrices relative to its working folder
    by_id = {r.pair_id: r for r in recs}
    for row in read_ids(released):
        if row["split"] != "test":
            continue
        r = by_id[row["pair_id"]]
        folder = released / row["split"] / row["index"]
        offs = sorted(p.name for p in folder.glob("*.off"))
        for k, (s, off) in enumerate(zip(("x", "y"), offs)):
            d = np.load(geolora_cached_geodesics_path(off))
            info = read_info(folder / off.replace(".off", "_info.pkl"))
            vertices = np.asarray(trimesh.load(folder / off, process=False, maintain_order=True).vertices)
            assert d.dtype == np.float32 and d.shape == (len(vertices),) * 2
            assert np.array_equal(d, d.T) and not np.diag(d).any()
            (entry,) = [e for e in index if e["pair_id"] == r.pair_id and e["side"] == str(k)]
            assert (
                float(entry["sqrt_area"]) == info["surface_area_after_scaling"] and entry["mesh_id"] == info["mesh_id"]
            )
            if s == "x":  # the ball: a sphere of radius 0.5, geodesics are great-circle arcs
                unit = vertices / np.linalg.norm(vertices, axis=1, keepdims=True)
                arc = 0.5 * np.arccos(np.clip(unit @ unit.T, -1, 1)) / info["surface_area_after_scaling"]
                far = arc > 0.05
                assert abs(np.median(d[far] / arc[far]) - 1) < 0.05
            else:  # a scan: distances on the FULL egg between its kept vertices
                p2f = info["partial2full"]
                full = _edge_dijkstra(r["y_full_vertices"], r["y_full_faces"])[np.ix_(p2f, p2f)]
                ratio = full[d > 0.05] / (d[d > 0.05] * info["surface_area_after_scaling"])
                assert 1.0 < np.median(ratio) < 1.2  # edge paths a little longer than surface geodesics


# --------------------------------------------------------------------------------------------------
# ULRSSM and DPFM layouts, read with the loaders' own parsing logic (numpy in place of torch)


def ulrssm_sort_list(paths: list[str]) -> list[str]:
    """ULRSSM ``datasets/shape_dataset.py`` ``sort_list`` (MIT licence): sort by the first integer that
    is followed by a ``.`` in the path, or lexicographically when some path has none."""
    import re

    try:
        return sorted(paths, key=lambda x: int(re.search(r"\d+(?=\.)", x).group()))
    except AttributeError:
        return sorted(paths)


def ulrssm_pair(data_root: Path, first: int, second: int, with_dist: bool) -> dict:
    """ULRSSM ``SingleShapeDataset._init_data`` / ``__getitem__`` file logic for two shapes of a root:
    ``off/*.off``, ``corres/*.vts`` (``np.loadtxt(..., dtype=np.int32) - 1``), ``dist/*.mat`` (key
    ``dist``), each list sorted by ``sort_list``; a pair's ground truth is the template pairing
    ``first['corr'][t] <-> second['corr'][t]``."""
    import glob

    import scipy.io
    import trimesh

    offs = ulrssm_sort_list(glob.glob(f"{data_root / 'off'}/*.off"))
    corrs = ulrssm_sort_list(glob.glob(f"{data_root / 'corres'}/*.vts"))
    dists = ulrssm_sort_list(glob.glob(f"{data_root / 'dist'}/*.mat")) if with_dist else []
    assert len(offs) == len(corrs) and (not with_dist or len(dists) == len(offs))
    items = []
    for i in (first, second):
        mesh = trimesh.load(offs[i], process=False, maintain_order=True)
        item = {
            "name": Path(offs[i]).stem,
            "verts": np.asarray(mesh.vertices, np.float32),
            "corr": np.loadtxt(corrs[i], dtype=np.int32) - 1,
        }
        if with_dist:
            item["dist"] = scipy.io.loadmat(dists[i])["dist"].astype(np.float32)
        items.append(item)
    return {"first": items[0], "second": items[1]}


@pytest.mark.parametrize("setting", SETTINGS)
def test_ulrssm_layout_reads_like_ulrssm(setting, records, tmp_path):
    from becos.products.export import write_ulrssm

    recs = records[setting][:2]  # a train and a test pair (the OFF text of 9k-vertex shapes dominates)
    out = write_ulrssm(_shuffled(recs, 2), tmp_path / "ulrssm")
    by_id = {r.pair_id: r for r in recs}
    rows = read_ids(out)
    _check_numbering(out, rows, recs, set())
    for row in rows:
        r = by_id[row["pair_id"]]
        root = out / row["split"] / row["index"]
        pair = ulrssm_pair(root, 0, 1, with_dist=False)
        first, second = pair["first"], pair["second"]
        assert np.array_equal(first["verts"], r["x_vertices"].astype(np.float32))
        assert np.array_equal(second["verts"], r["y_vertices"].astype(np.float32))
        x_of_t, y_of_t = first["corr"], second["corr"]
        assert len(x_of_t) == len(y_of_t) == int((r["corr_10"] >= 0).sum())  # one template point per matched Y vertex
        assert x_of_t.min() >= 0 and y_of_t.min() >= 0  # never the -1 ULRSSM cannot express
        assert np.array_equal(r["corr_10"][y_of_t], x_of_t)  # the ground truth Y -> X exactly
        back = ulrssm_pair(root, 1, 0, with_dist=False)  # the reversed pair: same points
        assert np.array_equal(back["first"]["corr"], y_of_t)


def dpfm_pairs(data_root: Path, name: str = "") -> dict:
    """DPFM ``shrec_partial_dataset.py`` ``ShrecPartialDataset.__init__`` / ``__getitem__`` file logic
    (MIT licence): shapes = sorted ``shapes/*`` stems containing ``name``; each ``maps/<x>_<y>.map``
    (split at the LAST ``_``) whose two ids are shapes is the pair (shape1 = y, shape2 = x) with
    ``map21 = loadtxt(int32)`` (one entry per vertex of x); partiality masks from it."""
    import trimesh

    used = sorted(p.stem for p in (data_root / "shapes").iterdir() if name in p.stem)
    pairs = {}
    for stem in (p.stem for p in (data_root / "maps").iterdir() if name in p.stem):
        x, y = stem[: stem.rfind("_")], stem[stem.rfind("_") + 1 :]
        if x in used and y in used:
            map21 = np.loadtxt(data_root / "maps" / f"{x}_{y}.map", dtype=np.int32)
            n1 = len(trimesh.load(data_root / "shapes" / f"{y}.off", process=False).vertices)
            mask12 = np.zeros(n1, dtype=np.int64)
            mask12[map21[map21 != -1]] = 1
            pairs[(x, y)] = {"map21": map21, "mask21": (map21 != -1).astype(np.int64), "mask12": mask12}
    return pairs


@pytest.mark.parametrize("setting", SETTINGS)
def test_dpfm_layout_reads_like_dpfm(setting, records, tmp_path):
    from becos.products.export import DPFM_NONE_MAPS, write_dpfm

    recs = records[setting][:2]
    out = write_dpfm(_shuffled(recs, 3), tmp_path / "dpfm")
    rows = read_ids(out)
    _check_numbering(out, rows, recs, {"shapes", "maps", DPFM_NONE_MAPS})
    by_id = {r.pair_id: r for r in recs}
    for split in {row["split"] for row in rows}:
        pairs = dpfm_pairs(out / split)
        # the directions with a -1 row, read the same way from the folder DPFM does not train on
        (out / split / "maps").rename(out / split / "representable")
        (out / split / DPFM_NONE_MAPS).rename(out / split / "maps")
        unrepresentable = dpfm_pairs(out / split)
        split_rows = [row for row in rows if row["split"] == split]
        # both directions of every pair survive the id parsing, each in one of the two folders
        assert len(pairs) + len(unrepresentable) == 2 * len(split_rows)
        for row in split_rows:
            r = by_id[row["pair_id"]]
            assert "_" not in row["x_id"] + row["y_id"]
            for (x, y), corr, mask_x, mask_y in (
                ((row["x_id"], row["y_id"]), r["corr_01"], "x", "y"),
                ((row["y_id"], row["x_id"]), r["corr_10"], "y", "x"),
            ):
                got = pairs[(x, y)] if (corr >= 0).all() else unrepresentable[(x, y)]
                assert ((x, y) in pairs) == (corr >= 0).all()  # DPFM trains only on maps without -1
                assert np.array_equal(got["map21"], corr)
                assert np.array_equal(got["mask21"].astype(bool), r[f"{mask_x}_overlap_mask"])
                hit = np.zeros(len(r[f"{mask_y}_vertices"]), bool)
                hit[corr[corr >= 0]] = True
                assert np.array_equal(got["mask12"].astype(bool), hit)


def test_ulrssm_dist_matches_the_geodesic_export(small_record, tmp_path):
    from becos.products.export import GEODESIC_FOLDER, write_geodesic_matrices, write_ulrssm

    recs = [small_record, *_ball_records("partial_full")[:1]]
    recs[1] = _copy(recs[1], recs[1].pair_id, "test")
    out = write_ulrssm(recs, tmp_path / "ulrssm", geodesics=True, splits=["test"], jobs=1)
    geo = write_geodesic_matrices(recs, tmp_path / "geo")
    with open(geo / GEODESIC_FOLDER / "index.csv", encoding="utf-8", newline="") as fh:
        index = {(row["pair_id"], int(row["side"])): row["stem"] for row in csv.DictReader(fh)}
    for row in read_ids(out):
        pair = ulrssm_pair(out / row["split"] / row["index"], 0, 1, with_dist=True)
        for k, item in enumerate((pair["first"], pair["second"])):
            d = item["dist"]
            assert d.shape == (len(item["verts"]),) * 2 and d.dtype == np.float32
            assert np.array_equal(d, np.load(geo / GEODESIC_FOLDER / f"{index[(row['pair_id'], k)]}.npy"))


def test_nested_export_keys_on_the_snakemake_command_line():
    """``--config 'exports={...}'``: Snakemake hands nested values over as strings; they are typed by
    the schema instead of failing with "'true' is not of type 'boolean'"."""
    from snakemake.cli import parse_config

    from becos.errors import ConfigError
    from becos.workflow import resolve_config

    base = {"data_dir": "d", "annotations": "a", "datasets": ["tosca"]}
    given = parse_config(["exports={zarr: true, psmal: True, geodesics: false, geodesic_splits: [test, val]}"])
    assert given["exports"]["psmal"] == "True"  # what Snakemake passes on
    exports = resolve_config({**base, **given})["exports"]
    assert exports["zarr"] is True and exports["psmal"] is True and exports["geodesics"] is False
    assert exports["geodesic_splits"] == ["test", "val"] and exports["released"] is True  # defaults kept
    with pytest.raises(ConfigError, match=r"exports\.psmal"):
        resolve_config({**base, **parse_config(["exports={psmal: maybe}"])})
    # issue #34: the ULRSSM and DPFM layouts are workflow exports too (rules ulrssm_layout, dpfm_layout)
    exports = resolve_config({**base, **parse_config(["exports={ulrssm: true, dpfm: true}"])})["exports"]
    assert exports["ulrssm"] is True and exports["dpfm"] is True and exports["psmal"] is False
    assert resolve_config(base)["exports"]["ulrssm"] is False and resolve_config(base)["exports"]["dpfm"] is False
