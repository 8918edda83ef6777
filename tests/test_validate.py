"""Store validation: real stores validate clean; every check of :mod:`becos.products.validate` catches a store
corrupted in exactly one way (one case per check, :data:`CORRUPTIONS`), with a message naming the
check, what is wrong, how many pairs and an example pair; damaged stores are reported, never a
traceback."""

from __future__ import annotations

import json
import re
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import zarr

from becos.build.record import PairRecord
from becos.cli import main
from becos.products.store import TABLE_COLUMNS, open_benchmark, table_row, write_pairs, write_store
from becos.products.validate import validate, validate_store

CHECKS = (
    "checksum",
    "schema",
    "metadata",
    "meta",
    "table",
    "pair_id",
    "index_range",
    "unmatched",
    "weights",
    "corr_face",
    "overlap",
    "index_maps",
    "full_shape",
    "setting",
    "face_map",
    "vertex_map",
    "connectivity",
    "rotation",
    "alignment",
    "camera",
    "scalars",
    "finite",
    "split_classes",
    "centaur",
)
"""Every check in docs/design/validate.md's table of becos.products.validate (``store``: test_damaged_store_is_reported)."""


@pytest.fixture(scope="module")
def clean_stores(pair_record_files, tmp_path_factory):
    """{setting: store} of the fixture records, relabelled into one split.

    The fixture puts cat0 -> cat3 in train *and* test, which breaks class hold-out (the check
    ``split_classes`` must catch exactly that, see below); TOSCA holds cats out for test.
    """
    folder = tmp_path_factory.mktemp("clean")
    out = {}
    for setting, paths in pair_record_files.items():
        relabelled = []
        for p in paths:
            record = PairRecord.load(p)
            record.meta["split"] = "test"
            relabelled.append(folder / setting / p.name)
            record.save(relabelled[-1])
        out[setting] = write_store(relabelled, folder / f"{setting}.zarr", setting=setting, progress=False)
    return out


@pytest.fixture()
def p2p_copy(clean_stores, tmp_path):
    """A writable copy of the clean partial_partial store."""
    path = tmp_path / "corrupt.zarr"
    shutil.copytree(clean_stores["partial_partial"], path)
    return path


# --------------------------------------------------------------------------------------------------
# helpers that corrupt a store copy in place


def _array(store, key):
    return zarr.open_array(str(store / "arrays" / key), mode="r+")


def _rows(bench, key, pair):
    """Global rows ``start, stop`` of one pair in a ragged array."""
    o = bench.offsets[bench.layout[key]]
    return int(o[pair]), int(o[pair + 1])


def _set_attrs(store, **attrs):
    zarr.open_group(str(store), mode="r+").attrs.update(attrs)


def _rewrite_pairs(store, edit_metas=None, edit_rows=None):
    """Rewrite the metas and the table (table rows derived from the edited metas, then ``edit_rows``)."""
    bench = open_benchmark(store)
    metas = bench.read_metas()
    if edit_metas is not None:
        edit_metas(metas)
    t = bench.table
    rows = [
        table_row(i, m, t["x_n_vertices"][i], t["y_n_vertices"][i], t["x_overlap"][i], t["y_overlap"][i])
        for i, m in enumerate(metas)
    ]
    if edit_rows is not None:
        edit_rows(rows)
    write_pairs(zarr.open_group(str(store), mode="r+"), metas, rows)


def _col(name):
    return TABLE_COLUMNS.index(name)


def _reseal(store):
    """Record the sha256 of the store's current content, as a writer that wrote these (wrong) values would.

    The corruptions below stand for a buggy writer, caught by the invariant they break; ``checksum``
    stands for damage after writing (a deleted chunk file), caught by the digests alone."""
    from becos.products.store import ContentDigests

    root = zarr.open_group(str(store), mode="r+")
    info = dict(root.attrs["becos_store"])
    nodes = {node: root[node][:] for node in info["sha256"] if node in root}
    digests = ContentDigests({node: data.dtype for node, data in nodes.items()})
    for node, data in nodes.items():
        digests.update(node, data)
    root.attrs.update(becos_store={**info, "sha256": digests.hexdigests()})


def c_checksum(store, bench):
    """A deleted chunk file: Zarr reads it back as zeros, which are valid annotation labels."""
    files = list((store / "arrays" / "y_annotation").glob("c.*"))
    assert files and np.any(bench.concatenated("y_annotation")[0] != 0)
    for f in files:
        f.unlink()


def c_schema(store, bench):
    root = zarr.open_group(str(store), mode="r+")
    data = root["arrays/x_annotation"][:]
    del root["arrays/x_annotation"]
    root["arrays"].create_array("x_annotation", data=data.astype(np.int32))


def c_metadata(store, bench):
    _set_attrs(store, n_pairs=3)


def c_meta(store, bench):
    _rewrite_pairs(store, lambda metas: metas[1].update(setting="partial_full"))
    return 1


def c_table(store, bench):
    def edit(rows):
        rows[1][_col("x_n_vertices")] += 1

    _rewrite_pairs(store, edit_rows=edit)
    return 1


def c_pair_id(store, bench):
    def edit(metas):
        metas[1]["pair_id"] = metas[0]["pair_id"]

    _rewrite_pairs(store, edit)
    return 0


def c_index_range(store, bench):
    row = _rows(bench, "corr_01", 1)[0] + 5  # pair 1, X vertex 5
    _array(store, "corr_01")[row] = bench.table["y_n_vertices"][1] + 7
    return 1


def c_unmatched(store, bench):
    a, b = _rows(bench, "y_overlap_mask", 0)
    mask = np.asarray(bench.array("y_overlap_mask")[a:b])
    _array(store, "corr_10")[a + int(np.flatnonzero(mask)[3])] = -1  # a matched Y vertex of pair 0
    return 0


def _matched_row(bench, pair, side="x"):
    """Global row of a matched vertex of ``pair`` whose largest weight is clearly the largest."""
    corr = "corr_01" if side == "x" else "corr_10"
    a, b = _rows(bench, corr, pair)
    w = np.asarray(bench.array(f"{corr}_weights")[a:b])
    top = np.sort(w, axis=1)
    return a + int(np.flatnonzero((np.asarray(bench.array(corr)[a:b]) >= 0) & (top[:, 2] > top[:, 1] + 0.1))[7])


def c_weights(store, bench):
    row = _matched_row(bench, 1)
    weights = _array(store, "corr_01_weights")
    weights[row] = weights[row] * 0.9  # same largest corner, sum 0.9
    return 1


def c_corr_face(store, bench):
    row = _matched_row(bench, 1)
    face = int(bench.array("corr_01_face")[row])
    corners = np.asarray(bench.array("y_faces")[_rows(bench, "y_faces", 1)[0] + face])
    weights = np.asarray(bench.array("corr_01_weights")[row])
    at = np.asarray(bench.array("y_vertices")[_rows(bench, "y_vertices", 1)[0] + corners])
    farthest = np.linalg.norm(at - weights @ at, axis=1).argmax()
    _array(store, "corr_01")[row] = corners[farthest]  # a corner, not the nearest vertex
    return 1


def c_overlap(store, bench):
    _array(store, "x_overlap")[1] = 0.95  # mask mean 0.69, accepted range [0.1, 0.9]

    def edit(rows):
        rows[1][_col("x_overlap")] = 0.95  # the table agrees with the array

    _rewrite_pairs(store, edit_rows=edit)
    return 1


def c_index_maps(store, bench):
    a, b = _rows(bench, "x_full_to_partial", 1)
    ftp = np.asarray(bench.array("x_full_to_partial")[a:b])
    _array(store, "x_full_to_partial")[a + int(np.flatnonzero(ftp < 0)[0])] = 0  # a dropped vertex "kept"
    return 1


def c_full_shape(store, bench):
    a, _ = _rows(bench, "y_full_face_ids", 1)
    _array(store, "y_full_face_ids")[a + 3] = 4  # full shape: face 3 must come from face 3
    return 1


def c_setting(store, bench):
    """A partial_full store labelled full_full (root attribute and metas): its Y shapes are partial."""
    _set_attrs(store, setting="full_full")
    _rewrite_pairs(store, lambda metas: [m.update(setting="full_full") for m in metas])
    return 0


def c_face_map(store, bench):
    f0, _ = _rows(bench, "y_full_face_ids", 0)
    full_face = int(bench.array("y_full_face_ids")[f0]) + _rows(bench, "y_full_faces", 0)[0]
    faces = _array(store, "y_full_faces")
    corners = faces[full_face]
    corners[0] = corners[0] + 1 if corners[0] > 0 else 1
    faces[full_face] = corners
    return 0


def c_vertex_map(store, bench):
    kept = int(bench.array("y_partial_to_full")[_rows(bench, "y_partial_to_full", 1)[0] + 10])
    row = _rows(bench, "y_full_vertices", 1)[0] + kept
    vertices = _array(store, "y_full_vertices")
    vertices[row] = vertices[row] + 1e-3
    return 1


def c_connectivity(store, bench):
    """Pair 0's X: the only face of a boundary 'ear' vertex replaced by a copy of another face (with its
    full face id, so the face map stays right): the ear vertex is on no face any more. The ear face is
    one that no point of Y's ground truth lies on (``corr_10_face``), so only this check can fail."""
    f0, f1 = _rows(bench, "x_faces", 0)
    faces = np.asarray(bench.array("x_faces")[f0:f1])
    uses = np.bincount(faces.ravel())
    c0, c1 = _rows(bench, "corr_10_face", 0)
    held = np.asarray(bench.array("corr_10_face")[c0:c1])
    ears = np.flatnonzero((uses[faces] == 1).any(axis=1))
    ear_face = int(ears[~np.isin(ears, held)][0])
    other = (ear_face + 1) % len(faces)
    for key in ("x_faces", "x_full_face_ids"):
        arr = _array(store, key)
        arr[f0 + ear_face] = arr[f0 + other]
    return 0


def c_rotation(store, bench):
    rotation = _array(store, "y_random_rotation")
    rotation[1] = rotation[1] * 1.01
    return 1


def c_alignment(store, bench):
    quarter_turn = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # a rotation, det +1
    _array(store, "x_align_rotation")[0] = quarter_turn
    return 0


def c_camera(store, bench):
    _array(store, "x_camera")[1] = np.eye(3)  # a camera for a full_full shape
    return 1


def c_scalars(store, bench):
    sqrt_area = _array(store, "x_full_sqrt_area")
    sqrt_area[1] = sqrt_area[1] * 1.1
    return 1


def c_finite(store, bench):
    row = _rows(bench, "x_vertices", 0)[0] + 42
    vertices = _array(store, "x_vertices")
    vertices[row] = np.array([np.nan, 0.0, 0.0])
    return 0


def c_split_classes(store, bench):
    """Pair 0 moved to train (meta, table and the root ``splits`` agree): class cat in train and test."""
    _rewrite_pairs(store, lambda metas: metas[0].update(split="train"))
    _set_attrs(store, splits={"train": 1, "test": 1})
    return 0


def c_centaur(store, bench):
    _rewrite_pairs(store, lambda metas: metas[1]["y"].update(category="centaur"))
    return 1


@dataclass(frozen=True)
class Corruption:
    check: str
    setting: str
    corrupt: Callable  # (store, bench) -> row of the example pair, or None (store-level)
    message: str  # expected in the check's problem
    n_pairs: int = 1


CORRUPTIONS = (
    Corruption(
        "checksum",
        "full_full",
        c_checksum,
        "checksum: arrays/y_annotation content differs from the sha256 recorded when the store was written; "
        "chunk files absent (Zarr reads them as zeros): c.0",
    ),
    Corruption("schema", "full_full", c_schema, "schema: x_annotation has dtype int32, expected int8"),
    Corruption("metadata", "full_full", c_metadata, "metadata: n_pairs says 3 but the table has 2 rows"),
    Corruption("meta", "partial_partial", c_meta, "meta: meta setting differs from the store's (partial_partial)"),
    Corruption("table", "partial_partial", c_table, "table: table x_n_vertices differs from the arrays"),
    Corruption("pair_id", "partial_partial", c_pair_id, "pair_id: duplicate pair id"),
    Corruption("index_range", "partial_partial", c_index_range, "index_range: corr_01 outside [-1, V_y)"),
    Corruption("unmatched", "partial_partial", c_unmatched, "unmatched: corr_10 >= 0 differs from y_overlap_mask"),
    Corruption(
        "weights", "partial_partial", c_weights, "weights: corr_01_weights negative, non-finite or not summing to 1"
    ),
    Corruption(
        "corr_face",
        "partial_partial",
        c_corr_face,
        "corr_face: corr_01 is not the vertex nearest its point along the surface",
    ),
    Corruption("overlap", "partial_partial", c_overlap, "overlap: x_overlap differs from the mean of x_overlap_mask"),
    Corruption(
        "index_maps",
        "partial_partial",
        c_index_maps,
        "index_maps: x_full_to_partial keeps a different number of vertices than V_x",
    ),
    Corruption(
        "full_shape",
        "full_full",
        c_full_shape,
        "full_shape: full y shape does not keep every face and vertex (identity maps)",
    ),
    Corruption("setting", "partial_full", c_setting, "setting: y is partial in a full_full store", n_pairs=2),
    Corruption(
        "face_map",
        "partial_partial",
        c_face_map,
        "face_map: y_partial_to_full[y_faces] != y_full_faces[y_full_face_ids]",
    ),
    Corruption(
        "vertex_map", "partial_partial", c_vertex_map, "vertex_map: y_vertices != y_full_vertices[y_partial_to_full]"
    ),
    Corruption(
        "connectivity", "partial_partial", c_connectivity, "connectivity: partial x shape has vertices on no face"
    ),
    Corruption("rotation", "partial_partial", c_rotation, "rotation: y_random_rotation not orthonormal with det +1"),
    Corruption(
        "alignment",
        "partial_partial",
        c_alignment,
        "alignment: x_align_rotation / x_align_translation not the identity",
    ),
    Corruption("camera", "full_full", c_camera, "camera: x_camera not NaN though a full_full store keeps x full"),
    Corruption(
        "scalars",
        "partial_partial",
        c_scalars,
        "scalars: x_full_area / x_full_sqrt_area / x_dataset_scale inconsistent",
    ),
    Corruption("finite", "full_full", c_finite, "finite: x_vertices not finite"),
    Corruption(
        "split_classes", "full_full", c_split_classes, "split_classes: class tosca/cat in splits train+test", n_pairs=2
    ),
    Corruption("centaur", "full_full", c_centaur, "centaur: centaur shape outside train"),
)


def test_every_check_has_a_corruption():
    page = (Path(__file__).resolve().parents[1] / "docs" / "design" / "validate.md").read_text()
    section = page.split("## `becos.products.validate`")[1].split("\n## ")[0]
    documented = re.findall(r"^``(\w+)``", section, flags=re.MULTILINE)
    assert set(documented) == set(CHECKS) | {"store"}
    assert [c.check for c in CORRUPTIONS] == list(CHECKS)


# --------------------------------------------------------------------------------------------------
# tests


def test_clean_stores_validate(clean_stores):
    for setting, path in clean_stores.items():
        report = validate(path)
        assert report.problems == [], (setting, report.problems)
        assert report.n_pairs == 2 and report.splits == {"test": 2} and report.setting == setting


@pytest.mark.parametrize("case", CORRUPTIONS, ids=[c.check for c in CORRUPTIONS])
def test_corruption_is_caught(case, clean_stores, tmp_path):
    """One corruption, one failing check, a message with the check, the problem, the pair count and an
    example pair id (store-level checks name the array or attribute instead)."""
    store = tmp_path / "corrupt.zarr"
    shutil.copytree(clean_stores[case.setting], store)
    bench = open_benchmark(store)
    example = case.corrupt(store, bench)
    if case.check != "checksum":
        _reseal(store)
    problems = validate_store(store)
    assert problems, "the corruption went unnoticed"
    # one block per pair, checked by two threads: the same report
    assert validate(store, threads=2, block_bytes=1).problems == problems
    assert {p.split(":")[0] for p in problems} == {case.check}, problems
    hit = next((p for p in problems if p.startswith(case.message)), None)
    assert hit is not None, problems
    if example is not None:
        assert f" in {case.n_pairs} pair(s), e.g. {bench.table['pair_id'][example]}" in hit, hit
    print(f"\n{case.check}: {case.corrupt.__name__} -> {hit}")


def test_a_store_of_an_older_becos_validates_with_its_own_rounding(clean_stores, tmp_path):
    """Records of an older becos validate by the rounding they were written with: without meta
    ``vertex_rounding`` (before issue #20) the largest-weight corner, with ``nearest_corner`` the corner
    nearest in 3D. Today's rounding in a record that says neither is reported as not its rounding."""
    from becos.build.record import NEAREST_CORNER_VERTEX_MAP_ROUNDING

    def older(store, pick, edit_metas):
        shutil.copytree(clean_stores["partial_partial"], store)
        bench = open_benchmark(store)
        differ = 0
        for corr, o in (("corr_01", "y"), ("corr_10", "x")):
            values, faces, weights = (np.asarray(bench.array(k)[:]) for k in (corr, f"{corr}_face", f"{corr}_weights"))
            for pair in range(len(bench)):
                start, stop = _rows(bench, corr, pair)
                f0 = _rows(bench, f"{o}_faces", pair)[0]
                v0 = _rows(bench, f"{o}_vertices", pair)[0]
                rows = np.arange(start, stop)[faces[start:stop] >= 0]
                corners = np.asarray(bench.array(f"{o}_faces")[:])[f0 + faces[rows]]
                at = np.asarray(bench.array(f"{o}_vertices")[:])[v0 + corners]
                chosen = corners[np.arange(len(rows)), pick(weights[rows], at)]
                differ += int((chosen != values[rows]).sum())
                values[rows] = chosen
            _array(store, corr)[:] = values
        _rewrite_pairs(store, edit_metas=edit_metas)
        _reseal(store)
        return differ

    largest = lambda w, at: w.argmax(axis=1)  # noqa: E731
    nearest = lambda w, at: np.linalg.norm(at - np.einsum("nk,nkd->nd", w, at)[:, None], axis=2).argmin(axis=1)  # noqa: E731
    unlabelled = lambda metas: [m.pop("vertex_rounding") for m in metas]  # noqa: E731
    nearest_corner = lambda metas: [m.update(vertex_rounding=NEAREST_CORNER_VERTEX_MAP_ROUNDING) for m in metas]  # noqa: E731
    differ = older(tmp_path / "largest.zarr", largest, unlabelled)
    assert differ > 0 and validate_store(tmp_path / "largest.zarr") == []  # the two roundings differ on these remeshes
    differ_corner = older(tmp_path / "corner.zarr", nearest, nearest_corner)
    assert differ_corner > 0 and validate_store(tmp_path / "corner.zarr") == []

    # today's rounding in records that do not say so
    for name, edit, message in (
        ("mislabelled.zarr", unlabelled, "is not the largest-weight corner"),
        ("mislabelled-corner.zarr", nearest_corner, "vertex_rounding nearest_corner"),
    ):
        store = tmp_path / name
        shutil.copytree(clean_stores["partial_partial"], store)
        _rewrite_pairs(store, edit_metas=edit)
        _reseal(store)
        problems = validate_store(store)
        assert problems and all(p.startswith("corr_face: corr_") and message in p for p in problems), problems
    print(
        f"\n{differ} vertices (largest weight) and {differ_corner} (nearest corner) round differently from today's "
        f"rule; older stores clean; mislabelled store: {problems[0]}"
    )


def test_class_in_train_and_test(pair_record_files, tmp_path):
    """The fixture's own split labels (cat in train and test) break class hold-out."""
    path = write_store(pair_record_files["full_full"], tmp_path / "ff.zarr", setting="full_full", progress=False)
    problems = validate_store(path)
    assert len(problems) == 1, problems
    assert problems[0].startswith("split_classes: class tosca/cat in splits train+test")


def test_reflection_is_not_a_rotation(p2p_copy):
    rotation = _array(p2p_copy, "x_frame_rotation")
    rotation[0] = rotation[0] @ np.diag([1.0, 1.0, -1.0])  # orthonormal, det -1
    _reseal(p2p_copy)
    problems = validate_store(p2p_copy)
    assert len(problems) == 1 and problems[0].startswith("rotation: x_frame_rotation not orthonormal"), problems


def test_partial_split_into_two_components(p2p_copy):
    bench = open_benchmark(p2p_copy)
    f0, f1 = _rows(bench, "x_faces", 0)
    local = np.asarray(bench.array("x_faces")[f0:f1])
    # re-point one face at three vertices of faces far apart: it shares no edge with any other face
    far = local[[0, len(local) // 2, len(local) - 1], [0, 1, 2]]
    _array(p2p_copy, "x_faces")[f0 + len(local) // 3] = far
    _reseal(p2p_copy)
    problems = validate_store(p2p_copy)
    assert any(p.startswith("connectivity: partial x shape is not one edge-connected component") for p in problems)
    assert any(p.startswith("face_map:") for p in problems)  # the face no longer matches its full face


def test_partial_to_full_not_increasing(p2p_copy):
    bench = open_benchmark(p2p_copy)
    start, _ = _rows(bench, "y_partial_to_full", 0)
    ptf = _array(p2p_copy, "y_partial_to_full")
    ptf[start + 1] = ptf[start + 0]
    _reseal(p2p_copy)
    text = "\n".join(p for p in validate_store(p2p_copy) if p.startswith("index_maps:"))
    assert "y_partial_to_full not strictly increasing" in text and "is not the identity" in text


def test_pairs_out_of_store_order(clean_stores, tmp_path):
    store = tmp_path / "ff.zarr"
    shutil.copytree(clean_stores["full_full"], store)
    first, second = open_benchmark(store).table["pair_id"][:2]

    def swap(metas):
        metas[0]["pair_id"], metas[1]["pair_id"] = second, first

    _rewrite_pairs(store, swap)
    problems = validate_store(store)
    assert problems == [
        f"table: 1 row(s) out of store order (split train, val, test, then pair_id), first at row 1: "
        f"{first} (test) after {second} (test)"
    ], problems


def test_decreasing_offsets_name_the_pair(clean_stores, tmp_path):
    store = tmp_path / "ff.zarr"
    shutil.copytree(clean_stores["full_full"], store)
    offsets = zarr.open_array(str(store / "offsets" / "x_face"), mode="r+")
    offsets[1] = offsets[2] + 5  # pair 0 too long, pair 1 negative
    problems = validate_store(store)
    pair_1 = open_benchmark(store).table["pair_id"][1]
    assert f"schema: offsets 'x_face' decrease (negative row count) in 1 pair(s), e.g. {pair_1}" in problems


# --------------------------------------------------------------------------------------------------
# stores that do not open or read: one readable ``store`` problem, never a traceback


def _damage(kind, store):
    if kind == "missing":
        shutil.rmtree(store)
    elif kind == "a file":
        shutil.rmtree(store)
        store.write_text("not a store\n")
    elif kind == "no zarr.json":
        (store / "zarr.json").unlink()
    elif kind == "root zarr.json garbage":
        (store / "zarr.json").write_text("{garbage")
    elif kind == "missing array":
        shutil.rmtree(store / "arrays" / "x_faces")
    elif kind == "missing offsets":
        shutil.rmtree(store / "offsets" / "x_vertex")
    elif kind == "missing table":
        shutil.rmtree(store / "pairs" / "table_json")
    elif kind == "array zarr.json garbage":
        (store / "arrays" / "corr_01" / "zarr.json").write_text("{garbage")
    elif kind == "truncated chunk":
        chunk = next((store / "arrays" / "x_vertices").glob("c.*"))
        chunk.write_bytes(chunk.read_bytes()[:50])


DAMAGES = {
    "missing": "not found. Fix: check the path",
    "a file": "is a file, not a store folder",
    "no zarr.json": "is not a Zarr v3 store",
    "root zarr.json garbage": "cannot be opened as a Zarr store",
    "missing array": "1 of its arrays missing: arrays/x_faces. Fix: re-export the store",
    "missing offsets": "1 of its arrays missing: offsets/x_vertex. Fix: re-export the store",
    "missing table": "1 of its arrays missing: pairs/table_json. Fix: re-export the store",
    "array zarr.json garbage": "arrays/corr_01 has unreadable metadata (arrays/corr_01/zarr.json",
    # x_vertices is sharded (64 KiB inner chunks): the truncated file loses its shard index
    "truncated chunk": "chunks of arrays/x_vertices (ValueError: Stored and computed checksum do not match",
}


@pytest.mark.parametrize("kind", list(DAMAGES))
def test_damaged_store_is_reported(kind, clean_stores, tmp_path, capsys):
    store = tmp_path / "damaged.zarr"
    shutil.copytree(clean_stores["full_full"], store)
    _damage(kind, store)
    problems = validate_store(store)
    assert len(problems) == 1 and problems[0].startswith(f"store: {store}: "), problems
    assert DAMAGES[kind] in problems[0] and "Fix:" in problems[0], problems[0]
    if kind == "truncated chunk":  # the pairs in the damaged chunk
        assert " in 2 pair(s), e.g. ff00000000000000, ff00000000000001" in problems[0]
    capsys.readouterr()
    assert main(["validate", str(store)]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and f"becos validate: {problems[0]}" in err


def test_cli_exit_status_and_json(clean_stores, p2p_copy, tmp_path, capsys):
    out = tmp_path / "validation.json"
    assert main(["validate", str(clean_stores["full_full"]), "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["valid"] is True and report["problems"] == [] and report["n_pairs"] == 2
    assert "comparison" not in report
    _array(p2p_copy, "x_random_rotation")[0] = np.zeros((3, 3))
    _reseal(p2p_copy)
    capsys.readouterr()
    assert main(["validate", str(p2p_copy), "--json", str(out)]) == 1
    err = capsys.readouterr().err
    assert "becos validate: rotation: x_random_rotation" in err
    assert json.loads(out.read_text())["problems"][0].startswith("rotation:")
