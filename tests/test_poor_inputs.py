"""Clear one-line messages for the POOR cases of issue #21 (each case: the fault, injected into real
files or real calls, and the message that names the file, the problem and the fix)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from becos.errors import BecosError, InputFileError
from becos.record import PairRecord
from becos.store import DamagedStoreError, PairKeyError, open_benchmark, write_store


@pytest.fixture
def store(pair_record_files, tmp_path) -> Path:
    return write_store(pair_record_files["full_full"], tmp_path / "full_full.zarr", setting="full_full",
                       progress=False)


@pytest.mark.parametrize("key", [1.5, True, None, [0]])
def test_a_pair_key_that_is_no_row_nor_pair_id_is_refused(store, key):
    bench = open_benchmark(store)
    with pytest.raises(PairKeyError, match=r"a pair is chosen by its row \(an int\) or its pair_id \(a str\), not") as err:
        bench.record(key)
    assert isinstance(err.value, TypeError) and isinstance(err.value, BecosError)
    assert bench.record(1).pair_id == bench.table["pair_id"][1]          # an int still works


def test_a_store_of_a_newer_format_says_so(store):
    meta = json.loads((store / "zarr.json").read_text())
    meta["attributes"]["becos_store"]["format"] += 1
    (store / "zarr.json").write_text(json.dumps(meta))
    with pytest.raises(InputFileError, match=r"was written by a newer becos: store format 2, this becos reads format 1"
                                             r"\. Fix: upgrade becos"):
        open_benchmark(store)


def test_a_store_rewritten_under_a_reader_is_a_named_error(store, pair_record_files):
    bench = open_benchmark(store)
    first = bench.record(0)
    records = [PairRecord.load(p) for p in pair_record_files["full_full"]]
    folder = store.parent / "one"
    folder.mkdir()
    records[1].save(folder / "only.npz")
    write_store([folder / "only.npz"], store, setting="full_full", progress=False)   # another store, same path
    with pytest.raises(DamagedStoreError, match=r"was rewritten or removed while this reader had it open \(reading "
                                                r"pairs 0:1\)\. Fix: open it again") as err:
        bench.record(0)
    assert err.value.path == store
    with pytest.raises(DamagedStoreError, match="was rewritten or removed"):
        bench.read_metas()
    assert open_benchmark(store).record(0).pair_id == records[1].pair_id != first.pair_id


@pytest.mark.parametrize("argv, message", [
    (["catalog", "--options", "{bad"], "becos catalog: --options: not valid JSON (Expecting property name enclosed "
                                       "in double quotes at line 1 column 2: '{bad'). Fix: pass the JSON"),
    (["catalog", "--options", "[1, 2]"], "becos catalog: --options: a JSON object {...} is needed, not a JSON list"),
    (["catalog", "--options", "{}"], "becos catalog: --options: lacks the key 'annotations' (given keys: []). Fix: "),
    (["remesh", "--options", "{}", "--shape", "{x", "--token", "v0"], "becos remesh: --shape: not valid JSON"),
    (["ground-truth", "--options", '{"results": "RESULTS", "annotations": "x", "template_file": "t"}', "--setting",
      "full_full", "--chunk", "0"], "becos ground-truth: RESULTS/catalog.csv: not found (an input of this stage). "
                                    "Fix: run the stages before `becos ground-truth`"),
], ids=["not_json", "not_an_object", "missing_key", "bad_shape", "missing_input"])
def test_bad_options_of_a_stage_command_are_one_line_errors(argv, message, tmp_path, capsys):
    from becos.cli import main

    results = str(tmp_path / "nothing")
    argv = [a.replace("RESULTS", results) for a in argv] + ["--out", str(tmp_path / "out")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(message.replace("RESULTS", results)), err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
