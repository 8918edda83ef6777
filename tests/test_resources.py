"""Per-rule scheduler resources: the measured table covers every working rule and scales on retries."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from becos.errors import InputFileError
from becos.resources import DEFAULT, RuleResources

REPO = Path(__file__).resolve().parents[1]
TABLE = REPO / "workflow" / "resources.yaml"


class Wildcards:
    setting, chunk = "partial_partial", "0003"


def test_every_rule_asking_for_resources_has_a_measured_entry_or_the_default():
    table = RuleResources.load(TABLE)
    asked = set()
    for smk in (REPO / "workflow" / "rules").glob("*.smk"):
        asked |= set(re.findall(r'RESOURCES\.(?:mem_mb|runtime)\("([a-z_]+)"', smk.read_text()))
    measured = {"remesh", "ground_truth", "pairs", "zarr_store", "validate_store", "released_layout", "report"}
    assert measured <= asked and measured <= set(table.table), sorted(measured - set(table.table))
    for rule in table.table:  # written by benchmarks/resources.py: each entry says what was measured
        line = TABLE.read_text().split(f"\n  {rule}:")[1].splitlines()[0]
        if rule not in measured and "estimate, not measured" in line:
            continue
        assert re.search(r"peak [0-9.]+ MiB, longest [0-9.]+ s", line), line
        assert table.entry(rule)["mem_mb"] >= 1.5 * float(re.search(r"peak ([0-9.]+) MiB", line).group(1))
    for rule in asked - set(table.table):
        assert table.entry(rule) == DEFAULT


def test_retries_ask_for_more_and_chunk_time_grows_with_pairs():
    table = RuleResources({"pairs": {"mem_mb": 700, "runtime": 5, "seconds_per_pair": 6.0}})
    mem, runtime = table.mem_mb("pairs"), table.runtime("pairs", n_pairs=lambda w: 200)
    assert mem(Wildcards, attempt=1) == 700 and mem(Wildcards, attempt=2) == 1400
    assert runtime(Wildcards, attempt=1) == 20 and runtime(Wildcards, attempt=3) == 60  # 200 x 6 s = 20 min
    assert table.runtime("pairs", n_pairs=lambda w: 3)(Wildcards) == 5  # never below the table's
    assert table.mem_mb("unlisted")(Wildcards) == DEFAULT["mem_mb"]
    # a remesh job makes every variant of its shape: its time grows with them (the shipped table's 105 s each)
    remesh = RuleResources.load(TABLE).runtime("remesh", n_variants=lambda w: 5)
    assert remesh(Wildcards) == 9 and remesh(Wildcards, attempt=2) == 18  # 5 x 105 s = 8.75 min
    assert RuleResources.load(TABLE).runtime("remesh", n_variants=lambda w: 2)(Wildcards) == 5


@pytest.mark.parametrize(
    "text, problem",
    [
        ("rules:\n  remesh: {mem_mb: -3, runtime: 5}\n", "mem_mb must be a positive number"),
        ("remesh: 3\n", "KeyError"),
        ("rules: [\n", "YAMLError|ScannerError|ParserError"),
    ],
)
def test_a_broken_table_is_an_error_naming_it(tmp_path, text, problem):
    path = tmp_path / "resources.yaml"
    path.write_text(text)
    with pytest.raises(InputFileError, match=problem) as info:
        RuleResources.load(path)
    assert str(path) in str(info.value) and "benchmarks/resources.py" in str(info.value)
