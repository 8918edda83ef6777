"""The Zarr benchmark store: exact round trip of real pair records, layout, CLI and input errors."""

from __future__ import annotations

import json
import os
import struct
import zipfile
from pathlib import Path

import numpy as np
import pytest

from becos.build.record import SCHEMA_VERSION, PairRecord
from becos.cli import main
from becos.errors import InputFileError
from becos.products.store import TABLE_COLUMNS, count_files, expand_inputs, open_benchmark, write_store

MAX_FILES = 150  # ~2 files per array (zarr.json + one shard) + groups, whatever the pair count


def assert_same_record(got: PairRecord, want: PairRecord) -> None:
    assert got.meta == want.meta
    assert set(got.arrays) == set(want.arrays)
    for key, expected in want.arrays.items():
        value = got.arrays[key]
        assert value.dtype == expected.dtype, key
        assert value.shape == expected.shape, key
        assert np.array_equal(value, expected, equal_nan=expected.dtype.kind == "f"), key


@pytest.fixture(scope="module")
def stores(pair_record_files, tmp_path_factory):
    """{setting: store path} written from the fixture records (train and test pair each)."""
    folder = tmp_path_factory.mktemp("stores")
    metadata = {
        "config_hash": "0123abcd",
        "config": {"seed": 42, "datasets": ["tosca"]},
        "datasets": {"tosca": {"licence": "free for research use"}},
    }
    return {
        setting: write_store(paths, folder / f"{setting}.zarr", setting=setting, metadata=metadata, progress=False)
        for setting, paths in pair_record_files.items()
    }


def test_round_trip_is_exact(stores, pair_record_files):
    for setting, path in stores.items():
        bench = open_benchmark(path)
        records = [PairRecord.load(p) for p in pair_record_files[setting]]
        assert len(bench) == len(records) == 2
        assert bench.setting == setting
        # store order: train before test, whatever the input order
        assert list(bench.table["split"]) == ["train", "test"]
        assert bench.splits() == ["train", "test"]
        for record in records:
            assert_same_record(bench.record(record.pair_id), record)
        row = int(np.flatnonzero(bench.table["pair_id"] == records[1].pair_id)[0])
        assert_same_record(bench.record(row), records[1])
        by_id = {r.pair_id: r for r in records}
        streamed = list(bench.records())
        assert [r.pair_id for r in streamed] == list(bench.table["pair_id"])
        for got in streamed:
            assert_same_record(got, by_id[got.pair_id])
        assert [r.pair_id for r in bench.records("test")] == [r.pair_id for r in records if r.meta["split"] == "test"]
        assert list(bench.records("val")) == []


def test_blocks_split_pairs_but_keep_records_exact(stores, pair_record_files):
    bench = open_benchmark(stores["partial_partial"])
    blocks = list(bench.blocks(max_bytes=1))  # one pair per block
    assert [(b.start, b.stop) for b in blocks] == [(0, 1), (1, 2)]
    by_id = {r.pair_id: r for r in map(PairRecord.load, pair_record_files["partial_partial"])}
    for block in blocks:
        assert_same_record(block.record(0), by_id[block.metas[0]["pair_id"]])
    data, offsets = bench.concatenated("corr_01")
    assert offsets.tolist() == [0, *np.cumsum(bench.table["x_n_vertices"]).tolist()]
    assert len(data) == offsets[-1]


def test_layout_table_and_metadata(stores, pair_record_files):
    bench = open_benchmark(stores["partial_full"])
    records = {r.pair_id: r for r in map(PairRecord.load, pair_record_files["partial_full"])}
    assert bench.layout["x_vertices"] == bench.layout["corr_01"] == "x_vertex"
    assert bench.layout["y_faces"] == bench.layout["y_full_face_ids"] == "y_face"
    assert bench.layout["y_random_rotation"] is None  # stacked (N, 3, 3)
    assert bench.array("y_random_rotation").shape == (2, 3, 3)
    assert bench.array("x_vertices").shape[0] == sum(len(r["x_vertices"]) for r in records.values())
    table = bench.table
    assert list(table.columns) == list(TABLE_COLUMNS)  # the stored table holds the layout's columns, in order
    for row in table.itertuples():
        record = records[row.pair_id]
        assert row.index == row.Index
        assert (row.x_name, row.y_name, row.x_class, row.y_dataset) == ("cat0", "cat3", "cat", "tosca")
        assert row.seed == record.meta["seed"] and row.split == record.meta["split"]
        assert row.y_n_vertices == len(record["y_vertices"]) and row.y_overlap == float(record["y_overlap"])
        assert row.category == "four-legged"
    assert table["seed"].dtype == np.int64 and table["accepted"].dtype == bool
    meta = bench.metadata
    assert meta["schema_version"] == SCHEMA_VERSION and meta["setting"] == "partial_full"
    assert meta["config_hash"] == "0123abcd" and meta["config"]["seed"] == 42
    assert meta["datasets"]["tosca"]["licence"] == "free for research use"
    assert {"becos", "numpy", "zarr", "trimesh"} <= set(meta["versions"])
    assert meta["n_pairs"] == 2 and meta["splits"] == {"train": 1, "test": 1}
    assert "created" in meta and "becos_store" not in meta


def test_few_files(stores):
    for path in stores.values():
        n = count_files(path)
        assert 40 < n <= MAX_FILES, n  # one zarr.json per array at least; never one file per pair and key


def test_cli_reads_chunk_index_and_replaces_store(pair_record_files, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    paths = pair_record_files["partial_partial"]
    (tmp_path / "records").mkdir()
    entries = []
    for p in paths:  # the workflow writes paths relative to the working directory
        os.symlink(p, tmp_path / "records" / p.name)
        entries.append({"pair_id": p.stem, "path": f"records/{p.name}", "computed": True})
    (tmp_path / "chunk_0000.json").write_text(json.dumps({"setting": "partial_partial", "chunk": 0, "pairs": entries}))
    (tmp_path / "meta.json").write_text(json.dumps({"config_hash": "feed", "setting": "partial_partial"}))
    args = [
        "export-zarr",
        "--setting",
        "partial_partial",
        "--out",
        "out/bench.zarr",
        "--metadata",
        "meta.json",
        "chunk_0000.json",
    ]
    assert main(args) == 0
    first = json.loads(capsys.readouterr().out)
    assert first["n_pairs"] == 2 and first["n_files"] <= MAX_FILES
    # a second export replaces the first; a text index with one path per line works too
    (tmp_path / "list.txt").write_text(f"# records\n{paths[0]}\n\n")
    assert main(args[:-1] + ["list.txt"]) == 0
    bench = open_benchmark(tmp_path / "out" / "bench.zarr")
    assert list(bench.table["pair_id"]) == [paths[0].stem]
    assert bench.metadata["config_hash"] == "feed"
    assert sorted(os.listdir(tmp_path / "out")) == ["bench.zarr"]  # no temporary folders left
    assert expand_inputs(["chunk_0000.json"]) == [
        p.relative_to(tmp_path) for p in [tmp_path / "records" / q.name for q in paths]
    ]


def _flip_a_byte(path: Path, info: zipfile.ZipInfo) -> None:
    """Invert one byte in the middle of the zip member ``info``'s stored (compressed) bytes in ``path``."""
    with open(path, "r+b") as fh:
        fh.seek(info.header_offset + 26)
        name_len, extra_len = struct.unpack("<HH", fh.read(4))
        fh.seek(info.header_offset + 30 + name_len + extra_len + info.compress_size // 2)
        byte = fh.read(1)
        fh.seek(-1, os.SEEK_CUR)
        fh.write(bytes([byte[0] ^ 0xFF]))


def test_bad_inputs_name_the_file(pair_record_files, tmp_path, capsys):
    pp, ff = pair_record_files["partial_partial"], pair_record_files["full_full"]
    with pytest.raises(InputFileError, match=ff[0].name + ".*not partial_partial"):
        write_store([pp[0], ff[0]], tmp_path / "a.zarr", setting="partial_partial", progress=False)
    with pytest.raises(InputFileError, match="also in"):
        write_store([pp[0], pp[0]], tmp_path / "a.zarr", setting="partial_partial", progress=False)
    broken = tmp_path / "broken.npz"
    broken.write_bytes(b"not a zip file")
    with pytest.raises(InputFileError, match="broken.npz.*not a readable pair record"):
        write_store([pp[0], broken], tmp_path / "a.zarr", setting="partial_partial", progress=False)
    assert not (tmp_path / "a.zarr").exists()
    # a flipped byte inside a deflated member (the faces): caught by the inflate or the zip's CRC
    damaged = tmp_path / "damaged.npz"
    damaged.write_bytes(pp[1].read_bytes())
    with zipfile.ZipFile(damaged) as z:
        info = z.getinfo("x_faces.npy")
    assert info.compress_type == zipfile.ZIP_DEFLATED
    _flip_a_byte(damaged, info)
    with pytest.raises(InputFileError, match="damaged.npz.*not a readable pair record.*x_faces"):
        write_store([pp[0], damaged], tmp_path / "a.zarr", setting="partial_partial", progress=False)
    assert not (tmp_path / "a.zarr").exists()
    index = tmp_path / "chunk.json"
    index.write_text(json.dumps({"setting": "full_full", "pairs": [{"path": str(ff[0])}]}))
    assert main(["export-zarr", "--setting", "partial_partial", "--out", str(tmp_path / "b.zarr"), str(index)]) == 2
    assert "chunk.json" in capsys.readouterr().err
    with pytest.raises(InputFileError, match="not a Zarr v3 store"):
        open_benchmark(tmp_path)


def test_compressed_and_fortran_records_round_trip(pair_record_files, tmp_path):
    """Records saved with savez_compressed (read through numpy) and Fortran-ordered arrays."""
    from becos.atomic import save_npz

    record = PairRecord.load(pair_record_files["partial_full"][0])
    arrays = dict(record.arrays, y_vertices=np.asfortranarray(record["y_vertices"]))
    compressed = tmp_path / "compressed.npz"
    save_npz(compressed, compressed=True, __meta__=np.array(json.dumps(record.meta)), **arrays)
    plain = PairRecord.load(pair_record_files["partial_full"][1])
    plain.arrays["x_faces"] = np.asfortranarray(plain["x_faces"])
    plain.save(tmp_path / "fortran.npz")
    path = write_store(
        [compressed, tmp_path / "fortran.npz"], tmp_path / "s.zarr", setting="partial_full", progress=False
    )
    bench = open_benchmark(path)
    assert_same_record(bench.record(record.pair_id), record)
    assert_same_record(bench.record(plain.pair_id), plain)


def test_a_killed_writes_folder_is_removed_but_not_a_sibling_stores(pair_record_files, tmp_path):
    """Writing ``s.zarr`` removes ``.s.zarr.<random>.tmp`` (a killed write of it), never the temporary
    folder of ``s.zarr.v2`` being written beside it."""
    killed, sibling = tmp_path / ".s.zarr.k1ll3d_x.tmp", tmp_path / ".s.zarr.v2.abcd1234.tmp"
    for folder in (killed, sibling):
        (folder / "arrays").mkdir(parents=True)
    write_store(pair_record_files["full_full"], tmp_path / "s.zarr", setting="full_full", progress=False)
    assert not killed.exists() and sibling.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == [sibling.name, "s.zarr"]


def _read_in_child(view, queue) -> None:
    queue.put(view[1])


@pytest.mark.parametrize("method", ["fork", "spawn"])
def test_training_view_in_worker_processes(stores, pair_record_files, method):
    """len()/[i] give plain numpy arrays equal to the records; the view pickles without an open store and
    reads in forked children (after the parent has read: the inherited store is reopened) and spawned ones."""
    import multiprocessing
    import operator
    import pickle

    from becos.products.store import TrainingView

    view = TrainingView(stores["partial_partial"], keys=["x_vertices", "corr_01", "y_faces"])
    assert len(view) == 2 and len(TrainingView(stores["partial_partial"], split="test")) == 1
    by_id = {r.pair_id: r for r in map(PairRecord.load, pair_record_files["partial_partial"])}
    first = view[0]
    assert set(first) == {"x_vertices", "corr_01", "y_faces", "row"}
    want = by_id[open_benchmark(stores["partial_partial"]).table["pair_id"][0]]
    for key in ("x_vertices", "corr_01", "y_faces"):
        assert type(first[key]) is np.ndarray and first[key].dtype == want[key].dtype
        assert np.array_equal(first[key], want[key])
    assert view[-1]["row"] == 1
    with pytest.raises(IndexError):
        view[2]
    state = pickle.dumps(view)
    assert pickle.loads(state)._bench is None and len(state) < 2000
    context = multiprocessing.get_context(method)
    with context.Pool(2) as pool:
        got = pool.starmap(operator.getitem, [(view, i) for i in (0, 1, 0, 1)])
    if method == "fork":  # the child inherits the parent's open store itself (not pickled)
        queue = context.Queue()
        child = context.Process(target=_read_in_child, args=(view, queue))
        child.start()
        got.append(queue.get(timeout=60))
        child.join(timeout=60)
        assert child.exitcode == 0
    for d in got:
        row = int(d["row"])
        record = by_id[open_benchmark(stores["partial_partial"]).table["pair_id"][row]]
        assert np.array_equal(d["x_vertices"], record["x_vertices"]) and d["corr_01"].dtype == np.int64
        assert np.array_equal(d["corr_01"], record["corr_01"])


def test_record_files_hold_int32_indices_and_no_identity_maps(pair_record_files, tmp_path):
    """A full shape's identity maps are left out of the file and derived on load; index keys are int32
    on disk and int64 again after loading; values, dtypes and shapes round-trip exactly."""
    from becos.build.record import IDENTITY_MEMBER, RECORD_SCHEMA, encode_arrays

    record = PairRecord.load(pair_record_files["partial_full"][0])  # X full, Y partial
    path = tmp_path / "r.npz"
    record.save(path)
    with np.load(path) as data:
        on_disk = {k: data[k] for k in data.files}
    identity = json.loads(str(on_disk[IDENTITY_MEMBER]))
    assert set(identity) == {"x_partial_to_full", "x_full_to_partial", "x_full_face_ids"}
    assert identity["x_full_face_ids"] == len(record["x_faces"]) and not set(identity) & set(on_disk)
    assert on_disk["y_partial_to_full"].dtype == np.int32 and on_disk["corr_10"].dtype == np.int32
    assert on_disk["y_vertices"].dtype == np.float64 and on_disk["x_annotation"].dtype == np.int8
    assert assert_same_record(PairRecord.load(path), record) is None
    wide = dict(record.arrays, corr_01=record["corr_01"] + (1 << 40))  # does not fit int32: kept int64
    assert encode_arrays(wide)[0]["corr_01"].dtype == np.int64
    # the one schema table drives the store layout and the validator's expectations
    from becos.products.store import SCHEMA_GROUPS
    from becos.products.validate import expected_schema

    assert expected_schema()["x_faces"] == ("int32", (3,)) and SCHEMA_GROUPS["corr_10_face"] == "y_vertex"
    assert set(expected_schema()) == set(RECORD_SCHEMA) == set(record.arrays)
    import becos.build.record

    assert all(f"s_{k}" in becos.build.record.__doc__ for k in becos.build.record.SHAPE_KEYS)


def test_direct_reads_equal_zarr_reads_and_damage_is_named(stores, pair_record_files, tmp_path, monkeypatch):
    """record(i) reads the chunk files itself; it returns what zarr's read_block returns, and a damaged
    chunk file ends in DamagedStoreError (through zarr), never in another pair's or garbage values."""
    import shutil

    from becos.products.store import DamagedStoreError

    bench = open_benchmark(stores["partial_partial"])
    for i in range(len(bench)):
        assert_same_record(bench.record(i), bench.read_block(i, i + 1).record(0))
    assert bench._files, "the direct reader was not used"
    assert bench.record(1).arrays["x_faces"].dtype == np.int64
    import becos.products.store.write

    monkeypatch.setattr(becos.products.store.write, "CHUNK_BYTES", 4096)  # many chunks over several shards per array
    monkeypatch.setattr(becos.products.store.write, "SHARD_BYTES", 32768)
    small = open_benchmark(
        write_store(
            pair_record_files["partial_partial"], tmp_path / "small.zarr", setting="partial_partial", progress=False
        )
    )
    assert len(list((tmp_path / "small.zarr" / "arrays" / "x_vertices").glob("c.*"))) > 2
    whole = small.read_block(0, 2)
    for i, got in enumerate(small.records()):  # whole chunks decoded in place
        assert_same_record(got, whole.record(i))
        assert_same_record(small.record(i), whole.record(i))
    damaged = tmp_path / "damaged.zarr"
    shutil.copytree(stores["partial_partial"], damaged)
    chunk = next((damaged / "arrays" / "x_vertices").glob("c.*"))
    chunk.write_bytes(chunk.read_bytes()[:50])
    with pytest.raises(DamagedStoreError, match="arrays/x_vertices|cannot be read"):
        open_benchmark(damaged).record(0)


def test_export_refuses_a_folder_that_is_not_a_store_and_never_deletes_its_inputs(pair_record_files, tmp_path, capsys):
    """BAD 7 of issue #29: ``--out`` on a folder that is not a becos store (a notes.txt and the input
    records inside) is refused, also with ``--force`` while the inputs lie inside it; with
    ``--force`` and only other files inside, the folder is replaced; an empty folder is used."""
    import shutil

    out = tmp_path / "work"
    (out / "records").mkdir(parents=True)
    (out / "notes.txt").write_text("my notes\n")
    entries = []
    for p in pair_record_files["partial_partial"]:
        shutil.copy(p, out / "records" / p.name)
        entries.append({"pair_id": p.stem, "path": str(out / "records" / p.name), "computed": True})
    index = out / "chunk_0000.json"
    index.write_text(json.dumps({"setting": "partial_partial", "chunk": 0, "pairs": entries}))
    before = sorted(str(p.relative_to(out)) for p in out.rglob("*"))
    args = ["export-zarr", "--setting", "partial_partial", "--out", str(out), str(index)]

    assert main(args) != 0, "export-zarr replaced a folder that is not a store (and the inputs in it)"
    err = capsys.readouterr().err
    assert str(out) in err and "not a becos store" in err and "notes.txt" in err and "--force" in err, err
    assert "Traceback" not in err
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*")) == before

    assert main([*args, "--force"]) != 0, "--force deleted the export's own inputs"
    err = capsys.readouterr().err
    assert str(out) in err and "chunk_0000.json" in err and "inputs" in err, err
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*")) == before

    # inputs elsewhere, only notes.txt left: --force replaces the folder with the store
    moved = tmp_path / "records"
    shutil.move(out / "records", moved)
    index.unlink()
    records = sorted(str(p) for p in moved.glob("*.npz"))
    plain = ["export-zarr", "--setting", "partial_partial", "--out", str(out), *records]
    assert main(plain) != 0 and (out / "notes.txt").exists()
    capsys.readouterr()
    assert main([*plain, "--force"]) == 0
    assert not (out / "notes.txt").exists() and len(open_benchmark(out)) == 2
    assert main(plain) == 0  # a becos store is replaced without --force (the workflow rewrites stores)

    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["export-zarr", "--setting", "partial_partial", "--out", str(empty), *records]) == 0
    assert len(open_benchmark(empty)) == 2


def test_a_truncated_chunk_raises_one_damaged_store_error_and_no_pending_task_noise(stores, tmp_path):
    """POOR of issue #29: reading a store with truncated chunks raised DamagedStoreError, then printed
    dozens of ``Task was destroyed but it is pending!`` and RuntimeError tracebacks at exit (zarr's
    reads of the other arrays and chunks left running). They are cancelled or awaited before the error."""
    import shutil
    import subprocess
    import sys

    damaged = tmp_path / "damaged.zarr"
    shutil.copytree(stores["partial_partial"], damaged)
    for key in ("y_faces", "x_overlap_mask", "corr_01"):  # half of a chunk file: many reads still running
        chunk = sorted((damaged / "arrays" / key).glob("c.*"))[0]
        chunk.write_bytes(chunk.read_bytes()[: chunk.stat().st_size // 2])
    script = (
        "import sys\n"
        "from becos.products.store import DamagedStoreError, open_benchmark\n"
        "try:\n"
        "    open_benchmark(sys.argv[1]).record(0)\n"
        "except DamagedStoreError as exc:\n"
        "    print('caught:', exc)\n"
    )
    done = subprocess.run([sys.executable, "-c", script, str(damaged)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.count("caught:") == 1 and "damaged.zarr: pairs 0:1 cannot be read" in done.stdout, done.stdout
    err = done.stderr
    assert "Task was destroyed" not in err and "RuntimeError" not in err and "Traceback" not in err, err[:3000]


def test_a_store_of_an_older_format_says_so_and_how_to_rebuild_it(stores, pair_record_files, tmp_path):
    """POOR of issue #29: a format 1 store (an older becos) was "not a becos benchmark store of
    format 2"; the message says it is older and names the commands that rebuild it. export-zarr
    replaces it like any becos store."""
    import shutil

    old = tmp_path / "partial_partial" / "benchmark.zarr"
    shutil.copytree(stores["partial_partial"], old)
    meta = json.loads((old / "zarr.json").read_text())
    meta["attributes"]["becos_store"]["format"] = 1
    (old / "zarr.json").write_text(json.dumps(meta))
    with pytest.raises(InputFileError) as caught:
        open_benchmark(old)
    message = str(caught.value)
    assert message.startswith(f"{old}: was written by an older becos: store format 1, this becos reads format 2")
    assert "snakemake --cores 1 --forcerun zarr_store" in message
    pairs = tmp_path / "partial_partial" / "pairs"
    assert f"becos export-zarr --setting partial_partial --out {old} " in message and f"{pairs}/chunk_*.json" in message
    write_store(pair_record_files["partial_partial"], old, setting="partial_partial", progress=False)
    assert len(open_benchmark(old)) == 2


def _tree_bytes(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _same_store_but_created(one: Path, two: Path) -> dict:
    """Asserts two stores are the same file for file but the root's creation time; gives one's root metadata."""
    a, b = _tree_bytes(one), _tree_bytes(two)
    assert a.keys() == b.keys() and len(a) > 40
    assert {k for k in a if a[k] != b[k]} <= {"zarr.json"}
    meta_a, meta_b = (json.loads(t["zarr.json"]) for t in (a, b))
    meta_a["attributes"].pop("created"), meta_b["attributes"].pop("created")
    assert meta_a == meta_b
    return meta_a


def test_a_second_process_writes_the_same_store(pair_record_files, tmp_path, monkeypatch):
    """processes=2 (a second process fills half of the arrays) gives the store processes=1 gives, file for
    file but the root's creation time; an error of a record in the second process's arrays ends in the
    same InputFileError naming the record."""
    from becos.products.store import write

    monkeypatch.setattr(write, "SECOND_PROCESS_BYTES", 0)  # the test records are small
    records = pair_record_files["partial_partial"]
    one = write_store(records, tmp_path / "one.zarr", setting="partial_partial", progress=False)
    two = write_store(records, tmp_path / "two.zarr", setting="partial_partial", progress=False, processes=2)
    meta_a = _same_store_but_created(one, two)

    import zarr

    arrays = zarr.open_group(str(one / "arrays"), mode="r")
    layout = meta_a["attributes"]["becos_store"]["layout"]
    second = write._second_process_keys({k: arrays[k] for k in layout}, 2)
    assert second and set(second) < set(layout)  # both processes had arrays to fill
    damaged = tmp_path / "damaged.npz"
    damaged.write_bytes(records[1].read_bytes())
    with zipfile.ZipFile(damaged) as z:
        deflated = [i for i in z.infolist() if i.filename[:-4] in second and i.compress_type == zipfile.ZIP_DEFLATED]
    assert deflated, second
    info = deflated[0]
    _flip_a_byte(damaged, info)
    with pytest.raises(InputFileError, match=f"damaged.npz.*not a readable pair record.*{info.filename}"):
        write_store(
            [records[0], damaged], tmp_path / "bad.zarr", setting="partial_partial", progress=False, processes=2
        )
    assert not (tmp_path / "bad.zarr").exists()


def test_direct_writes_are_the_bytes_zarr_writes(pair_record_files, tmp_path, monkeypatch):
    """The store writer writes its arrays' shards straight to the files (ChunkFiles.write); the store is the
    one zarr writes, file for file but the root's creation time."""
    from becos.products.store import write
    from becos.products.store.chunk_files import ChunkFiles

    records = pair_record_files["partial_partial"]
    calls = []
    monkeypatch.setattr(
        ChunkFiles, "write", lambda self, start, data, _w=ChunkFiles.write: (calls.append(1), _w(self, start, data))
    )
    direct = write_store(records, tmp_path / "direct.zarr", setting="partial_partial", progress=False)
    assert len(calls) > 40  # every array went the direct way

    class ThroughZarr(ChunkFiles):
        writable = property(lambda self: False, lambda self, value: None)

    monkeypatch.setattr(write, "ChunkFiles", ThroughZarr)
    direct_calls = len(calls)
    through_zarr = write_store(records, tmp_path / "zarr.zarr", setting="partial_partial", progress=False)
    assert len(calls) == direct_calls
    _same_store_but_created(direct, through_zarr)


@pytest.mark.parametrize(
    ("shape", "dtype"),
    [((3 * 174720 + 1000, 3), "float64"), ((400_000,), "int32"), ((70_000,), "uint8"), ((5, 3, 3), "float64")],
)
def test_chunk_files_write_what_zarr_writes(tmp_path, shape, dtype):
    """ChunkFiles.write of whole shards (the last one partial, its last inner chunk padded) gives zarr's
    bytes for each chunk file of a store array (sharded or one chunk), read back equal through zarr; rows
    that do not start a chunk file are refused."""
    import zarr

    from becos.products.store.chunk_files import ChunkFiles
    from becos.products.store.layout import CHUNK_KEYS
    from becos.products.store.write import ARRAY_CONFIG, CHUNK_BYTES, _chunking, _compressors

    data = (
        np.random.default_rng(7).normal(size=shape).astype(dtype)
        if dtype != "uint8"
        else (np.random.default_rng(7).integers(0, 4, size=shape).astype(dtype))
    )
    chunks, shards = _chunking(shape[0], shape[1:], data.dtype.itemsize, CHUNK_BYTES)
    group = zarr.open_group(str(tmp_path / "g"), mode="w", zarr_format=3)

    def array(name, separator="."):
        return group.create_array(
            name,
            shape=shape,
            dtype=dtype,
            chunks=chunks,
            shards=shards,
            compressors=_compressors(),
            fill_value=0,
            chunk_key_encoding={**CHUNK_KEYS, "separator": separator},
            config=ARRAY_CONFIG,
        )

    arrays = [array("zarr"), array("direct")]
    files = ChunkFiles(tmp_path / "g" / "direct", arrays[1])
    assert files.writable and files.usable
    assert not ChunkFiles(tmp_path / "g" / "direct", arrays[1].with_config({"write_empty_chunks": False})).writable
    nested = ChunkFiles(tmp_path / "g" / "nested", array("nested", separator="/"))
    assert nested.usable and not nested.writable  # read, but written through zarr (folders per dimension)
    step = (shards or chunks)[0]
    for start in range(0, shape[0], step):
        arrays[0][start : start + step] = data[start : start + step]
        files.write(start, data[start : start + step])
    written = sorted(p.name for p in (tmp_path / "g" / "zarr").iterdir())
    assert written == sorted(p.name for p in (tmp_path / "g" / "direct").iterdir())
    assert (len(written) - 1 > 1) == (shards is not None and shape[0] > shards[0])
    for name in written:
        if name != "zarr.json":
            assert (tmp_path / "g" / "direct" / name).read_bytes() == (tmp_path / "g" / "zarr" / name).read_bytes(), (
                name
            )
    assert np.array_equal(zarr.open_array(str(tmp_path / "g" / "direct"), mode="r")[:], data)
    assert np.array_equal(files.read(0, shape[0]), data)
    if shape[0] > step:
        with pytest.raises(ValueError, match="not whole chunk files"):
            files.write(1, data[1:step])
