"""The Snakemake workflow end to end on a tiny TOSCA configuration (real Snakemake, real data).

The session fixture ``tiny_tosca_run`` (conftest.py) builds all three settings once (8 TOSCA shapes, at most 6
pairs per setting) and every test here reads its results. The incremental-rebuild test makes its own
run (four-legged first, then humans and centaurs).
"""

from __future__ import annotations

import csv
import json
import os
import re
import sys
from pathlib import Path

import numpy as np
import yaml
from snakemake_cmd import snakemake
from tiny_tosca import TINY_SHAPES, tosca_config, write_config_file

REPO = Path(__file__).resolve().parents[1]
SETTINGS = ("full_full", "partial_full", "partial_partial")


def write_config(workdir: Path, becos_code: Path, **overrides) -> Path:
    """``workdir`` with a ``config.yaml`` of :func:`tiny_tosca.tosca_config` and ``overrides``."""
    return write_config_file(workdir, tosca_config(becos_code, **overrides))


def jobs_planned(dry_run_output: str) -> dict[str, int]:
    """Job counts per rule from the 'Job stats' table of a dry run."""
    counts = {}
    for line in dry_run_output.splitlines():
        m = re.fullmatch(r"([a-z_]+)\s+(\d+)", line.strip())
        if m and m.group(1) != "total":
            counts[m.group(1)] = int(m.group(2))
    return counts


def test_every_setting_is_built_and_validated(tiny_tosca_run):
    from becos.products.store import open_benchmark

    for setting in SETTINGS:
        base = tiny_tosca_run / "results" / setting
        validation = json.loads((base / "validation.json").read_text())
        assert validation["valid"] and validation["n_problems"] == 0, validation
        bench = open_benchmark(base / "benchmark.zarr")
        manifest = (base / "manifest.csv").read_text().splitlines()[1:]
        assert 1 <= len(bench) == len(manifest) <= 6
        assert set(bench.table["pair_id"]) == {line.split(",")[0] for line in manifest}
        names = set(bench.table["x_name"]) | set(bench.table["y_name"])
        assert names <= {s.split("/")[1] for s in TINY_SHAPES}
        assert (base / "released").is_dir() and (base / f"pairings_{setting}.pkl").is_file()
        assert (base / "report").is_dir()
        print(
            f"\n{setting}: {len(bench)} pairs {bench.table['split'].value_counts().to_dict()}, "
            f"validation: valid={validation['valid']}, problems={validation['n_problems']}"
        )


def test_store_round_trips_the_pair_records(tiny_tosca_run):
    from becos.build.record import PairRecord
    from becos.products.store import open_benchmark

    for setting in SETTINGS:
        base = tiny_tosca_run / "results" / setting
        bench = open_benchmark(base / "benchmark.zarr")
        for pair_id in bench.table["pair_id"]:
            stored = bench.record(pair_id)
            original = PairRecord.load(base / "pairs" / f"{pair_id}.npz")
            assert stored.meta == original.meta
            assert set(stored.arrays) == set(original.arrays)
            for key, value in original.arrays.items():
                assert stored[key].dtype == value.dtype and stored[key].shape == value.shape, key
                assert np.array_equal(stored[key], value, equal_nan=value.dtype.kind == "f"), key


def test_rerun_of_a_finished_run_does_nothing(tiny_tosca_run):
    result = snakemake(tiny_tosca_run, "-n")
    assert "Nothing to be done" in result.stdout + result.stderr, result.stdout[-2000:]


def test_an_edit_to_a_report_key_reruns_the_reports_not_the_stores(tiny_tosca_run):
    """Issue #15: store_metadata reruns on the keys a store depends on, not on the whole config."""
    planned = jobs_planned(snakemake(tiny_tosca_run, "-n", "--config", "n_renders=1").stdout)
    assert planned.get("report") == 3, planned
    assert not {"store_metadata", "zarr_store", "validate_store", "released_layout"} & set(planned), planned
    planned = jobs_planned(snakemake(tiny_tosca_run, "-n", "--config", "min_overlap=0.15").stdout)
    assert planned.get("store_metadata") == 3 and planned.get("pairs", 0) >= 1, planned  # a key a store records


def test_snakemake_report_packs_each_settings_report_with_its_caption(tiny_tosca_run, tmp_path):
    import shutil
    import zipfile

    run = tmp_path / "run"  # a copy: Snakemake writes into the folder it reports on
    shutil.copytree(tiny_tosca_run, run, symlinks=True)
    out = tmp_path / "report.zip"
    snakemake(run, "--report", str(out))
    with zipfile.ZipFile(out) as packed:
        names = packed.namelist()
        text = "\n".join(packed.read(n).decode("utf-8", "replace") for n in names if n.endswith((".html", ".js")))
    # one packed copy of the report folder per setting (Snakemake names them by a hash)
    assert sum(n.endswith("/index.html") and "/data/raw/" in n for n in names) == len(SETTINGS), names[:20]
    assert any(n.endswith(".png") and "/renders/" in n for n in names)
    assert "BeCoS benchmark generator" in text  # workflow/report/workflow.rst
    assert "Sample pairs with their ground truth" in text  # workflow/report/index.rst


def test_a_deleted_remesh_output_is_rebuilt(tiny_tosca_run, tmp_path):
    """Issue #21: every remesh output (the .ply nothing else reads included) is a target of the run: a
    shape folder missing one of its files is removed, and its remesh job (one per shape) planned again."""
    import shutil

    run = tmp_path / "run"  # a copy (modification times kept): other tests read the shared run meanwhile
    shutil.copytree(tiny_tosca_run, run, symlinks=True)
    folders = sorted(p for p in (run / "results" / "remeshed").glob("*/*") if p.is_dir())
    ply = sorted(folders[0].glob("*.ply"))[0]
    ply.unlink()
    result = snakemake(run, "-n")
    assert jobs_planned(result.stdout).get("remesh") == 1, result.stdout[-3000:]
    assert f"output: {folders[0].relative_to(run)}\n" in result.stdout, result.stdout[-3000:]
    assert f"{folders[0].relative_to(run)} lacks 1 file(s) its remesh job writes (e.g. {ply.name})" in result.stderr
    assert not folders[0].exists() and all(f.is_dir() for f in folders[1:])  # the other shapes' are kept


def test_a_dry_run_before_any_job_lists_the_first_stages(becos_code, tmp_path):
    """A first ``snakemake -n`` evaluates every job's resources before the dataset check has run."""
    workdir = write_config(tmp_path / "fresh", becos_code, shapes=TINY_SHAPES)
    result = snakemake(workdir, "-n", "--cores", "2")
    planned = jobs_planned(result.stdout)
    assert planned.get("check_datasets") == 1 and planned.get("zarr_store") == 3, planned
    assert not (workdir / "results").exists()


def test_another_working_directory_keeps_the_default_config(tmp_path):
    """``snakemake -d DIR`` reads ``config/config.yaml`` beside the Snakefile, not in DIR (issue #18):
    the resolved config equals the repository's default one, merged under ``--configfile``."""
    from becos.workflow import resolve_config

    default = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    workdir = write_config_file(tmp_path / "elsewhere", {"seed": 7})
    snakemake(workdir, "--cores", "1", "results/config.json")
    resolved = json.loads((workdir / "results" / "config.json").read_text())
    assert resolved == json.loads(json.dumps(resolve_config({**default, "seed": 7})))
    assert resolved["n_chunks"] == default["n_chunks"] and resolved["store_vis"] == default["store_vis"]


def test_one_key_switches_off_every_export(tmp_path):
    """Issue #31, decision 2: ``exports: {enabled: false}`` over the default config (whose released
    layout, pickle and report are on) plans no export job, still the store and its validation; the
    resolved config says every export is off (a dry run: no job runs)."""
    from becos.workflow import resolve_config

    default = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    on = {"released_layout", "published_pairings", "report"}
    assert on <= set(jobs_planned(snakemake(write_config_file(tmp_path / "on", {}), "-n").stdout))
    planned = jobs_planned(snakemake(write_config_file(tmp_path / "off", {"exports": {"enabled": False}}), "-n").stdout)
    assert planned.get("zarr_store") == 3 and planned.get("validate_store") == 3, planned
    exports = {"released_layout", "psmal_layout", "ulrssm_layout", "dpfm_layout", "geodesic_plan", "geodesics"}
    assert not (exports | on) & set(planned), planned
    resolved = resolve_config({**default, "exports": {**default["exports"], "enabled": False, "psmal": True}})
    assert resolved["exports"]["zarr"] is True
    assert not any(v for k, v in resolved["exports"].items() if isinstance(v, bool) and k != "zarr"), resolved
    kept = resolve_config(default)["exports"]  # the default: every export as config/config.yaml says
    assert kept["enabled"] is True and all(kept[k] == v for k, v in default["exports"].items()), kept


def test_a_bad_config_fails_before_any_job(becos_code, tmp_path):
    cases = {
        "unknown key": {"min_overlapp": 0.2},
        "wrong type": {"n_cam_pos": "ten"},
        "reversed overlap range": {"min_overlap": 0.8, "max_overlap": 0.2},
    }
    for what, override in cases.items():
        workdir = write_config(tmp_path / what.replace(" ", "-"), becos_code, **override)
        result = snakemake(workdir, "--cores", "1", check=False)
        text = result.stdout + result.stderr
        assert result.returncode != 0, what
        key = next(iter(override))
        assert key in text, (what, text[-1500:])
        assert not (workdir / "results").exists() and not (workdir / "logs").exists(), what


def test_pairs_chunks_are_fixed_by_the_pair_id(tiny_tosca_run):
    """A pair's chunk job is its fixed hash bucket's range (becos.build.sampling.assign_chunks)."""
    from becos.build.sampling import N_BUCKETS, chunk_jobs, read_manifest
    from becos.seeding import stable_hash

    config = json.loads((tiny_tosca_run / "results" / "config.json").read_text())
    manifest = read_manifest(tiny_tosca_run / "results" / "partial_partial" / "manifest.csv")
    jobs = chunk_jobs(len(manifest), config["n_chunks"], config["pairs_per_chunk"], config["min_chunks"])
    buckets = [stable_hash(p) % N_BUCKETS for p in manifest["pair_id"]]
    assert all(b * jobs // N_BUCKETS == c for b, c in zip(buckets, manifest["chunk"]))
    indices = sorted((tiny_tosca_run / "results" / "partial_partial" / "pairs").glob("chunk_*.json"))
    assert len(indices) == manifest["chunk"].nunique()  # one job per non-empty chunk, not per pair


def test_visit_order_releases_each_shape_after_its_last_pair():
    """A chunk job visits every pair once and releases each shape exactly once, after its last pair."""
    from becos.workflow import pair_shape_keys, visit_order

    names = ["cat0", "cat1", "dog0", "dog1", "horse0"]
    rows = [
        {
            "pair_id": f"p{i:02d}",
            "x_dataset": "tosca",
            "x_name": names[i % 5],
            "x_variant": i % 2,
            "y_dataset": "tosca",
            "y_name": names[(3 * i + 1) % 5],
            "y_variant": 0,
        }
        for i in range(20)
    ]
    ordered, released = visit_order(rows, remesh=True)
    assert sorted(r["pair_id"] for r in ordered) == [r["pair_id"] for r in rows]
    flat = [key for keys in released for key in keys]
    used = {key for row in rows for key in pair_shape_keys(row, True)}
    assert sorted(flat) == sorted(used)  # each shape released once
    for i, keys in enumerate(released):
        later = {key for row in ordered[i + 1 :] for key in pair_shape_keys(row, True)}
        assert set(keys) <= set(pair_shape_keys(ordered[i], True)) and not set(keys) & later


def test_chunk_files_do_not_depend_on_the_shapes_a_job_keeps(tiny_tosca_run, tmp_path, monkeypatch):
    """Ground truth and pair records of a chunk come out byte-identical when its job keeps one shape
    at a time (every remesh, locator and scanner rebuilt per pair) instead of reusing them."""
    import shutil

    import becos.build.network
    import becos.workflow as bw

    monkeypatch.setattr(bw.shapes, "SHAPES_KEPT", 1)  # read where ShapeStore is defined
    monkeypatch.setattr(becos.build.network.ShapeNetwork, "MESHES_KEPT", 1)
    source = tiny_tosca_run / "results"
    results = tmp_path / "results"
    shutil.copytree(source, results, ignore=shutil.ignore_patterns("*.zarr", "released", "report", "psmal"))
    config = {**json.loads((source / "config.json").read_text()), "results": str(results)}
    for setting in ("partial_partial",):  # both sides scanned: every per-shape structure is used
        for index in sorted((results / setting / "ground_truth").glob("chunk_*.json")):
            chunk = int(index.stem.split("_")[1])
            gt_index, pairs_index = index, results / setting / "pairs" / index.name
            files = [Path(e["path"]).name for i in (gt_index, pairs_index) for e in json.loads(i.read_text())["pairs"]]
            for name in files:
                (results / setting / "ground_truth" / name).unlink(missing_ok=True)
                (results / setting / "pairs" / name).unlink(missing_ok=True)
            layout = bw.Layout.of(config)  # the paths the chunk's rules pass, the list file's moved to the copy
            listed = json.loads(layout.remesh_files(setting).read_text())
            moved = {c: [[*e[:3], str(layout.remeshed(*e[:3]))] for e in rows] for c, rows in listed.items()}
            remesh_files = tmp_path / "remesh_files.json"
            remesh_files.write_text(json.dumps(moved))
            inputs = {"manifest": layout.manifest(setting), "catalog": layout.catalog, "remesh_files": remesh_files}
            assert bw.ground_truth_stage(config, setting, chunk, gt_index, **inputs)["computed"] > 0
            assert bw.pairs_stage(config, setting, chunk, gt_index, pairs_index, **inputs)["computed"] > 0
            for kind, ix in (("ground_truth", gt_index), ("pairs", pairs_index)):
                for entry in json.loads(ix.read_text())["pairs"]:
                    name = Path(entry["path"]).name
                    assert (results / setting / kind / name).read_bytes() == (
                        source / setting / kind / name
                    ).read_bytes()
                original = json.loads((source / setting / kind / ix.name).read_text())["pairs"]
                assert [{k: v for k, v in e.items() if k != "path"} for e in json.loads(ix.read_text())["pairs"]] == [
                    {k: v for k, v in e.items() if k != "path"} for e in original
                ]


def test_incremental_rebuild(becos_code, tmp_path):
    """Four-legged only, then humans and centaurs; then only min_overlap changes."""
    shapes = [
        "tosca/cat0",
        "tosca/cat1",
        "tosca/dog0",
        "tosca/dog1",
        "tosca/horse0",
        "tosca/horse5",
        "tosca/wolf0",
        "tosca/wolf1",
        "tosca/michael0",
        "tosca/michael1",
        "tosca/david0",
        "tosca/david1",
        "tosca/centaur0",
        "tosca/centaur1",
    ]
    common = dict(
        shapes=shapes,
        setting="partial_partial",
        usage_scale=0.05,
        exports={"released": False, "published_pickle": False, "report": False},
    )
    workdir = write_config(tmp_path / "run", becos_code, combinations="four-legged", **common)
    snakemake(workdir, "--cores", "2")
    pairs_dir = workdir / "results" / "partial_partial" / "pairs"
    before = {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in pairs_dir.glob("*.npz")}
    # the remesh jobs' outputs: one folder per shape
    remeshed_before = {str(p.parent.relative_to(workdir)) for p in (workdir / "results" / "remeshed").rglob("*.npz")}
    assert before and remeshed_before

    write_config(workdir, becos_code, combinations="all", **common)
    dry = snakemake(workdir, "-n", "--cores", "2").stdout
    planned_remesh = set(re.findall(r"output: (results/remeshed/\S+)\n", dry))
    assert planned_remesh and not planned_remesh & remeshed_before  # new shapes only
    snakemake(workdir, "--cores", "2")
    after = {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in pairs_dir.glob("*.npz")}
    changed = [n for n in before if after.get(n) != before[n]]
    assert len(after) > len(before)
    assert len(changed) <= 0.1 * len(before), changed
    print(
        f"\nincremental: {len(before)} pairs -> {len(after)}; existing pair files changed: {len(changed)}; "
        f"remesh jobs planned: {sorted(planned_remesh)} (already remeshed: {sorted(remeshed_before)})"
    )

    write_config(workdir, becos_code, combinations="all", min_overlap=0.15, **common)
    planned = jobs_planned(snakemake(workdir, "-n", "--cores", "2").stdout)
    assert planned.get("pairs", 0) >= 1
    assert "remesh" not in planned and "ground_truth" not in planned, planned
    print(f"min_overlap 0.1 -> 0.15 plans: {planned}")

    # regrouping the pairs into more chunk jobs reruns the chunk jobs but recomputes no pair (issue 18)
    setting_dir = workdir / "results" / "partial_partial"
    files = {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in setting_dir.glob("*/*.npz")}
    jobs_before = len(list(setting_dir.glob("pairs/chunk_*.json")))
    write_config(workdir, becos_code, combinations="all", pairs_per_chunk=4, **common)
    snakemake(workdir, "--cores", "2", "--until", "pairs")
    indices = sorted(setting_dir.glob("pairs/chunk_*.json"))
    regrouped = {json.loads(i.read_text())["chunk"] for i in indices}
    assert jobs_before == 1 and len(regrouped) > 1, (jobs_before, regrouped)
    assert {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in setting_dir.glob("*/*.npz")} == files
    logs = [*(workdir / "logs" / "ground_truth").rglob("*.log"), *(workdir / "logs" / "pairs").rglob("*.log")]
    assert len(logs) == 2 * len(regrouped) and all(", 0 computed," in log.read_text() for log in logs), logs
    print(f"regrouped {len(files)} pair and ground-truth files from 1 into {len(regrouped)} chunk jobs: none rewritten")


def test_original_settings_plan_uses_the_published_pairs(becos_code, tmp_path):
    from becos import workflow as bw

    config = bw.resolve_config(
        yaml.safe_load(
            write_config(
                tmp_path,
                becos_code,
                original_settings=True,
                setting="partial_partial",
                caps={"train": 3, "val": 1, "test": 1},
            )
            .joinpath("config.yaml")
            .read_text()
        )
    )
    config["results"] = str(tmp_path / "results")
    plan = bw.Plan.build(config)
    manifest = plan.manifests["partial_partial"]
    counts = manifest["split"].value_counts().to_dict()
    assert counts["train"] == 3 and counts.get("val", 0) <= 1 and counts.get("test", 0) <= 1
    assert set(manifest["x_dataset"]) == set(manifest["y_dataset"]) == {"tosca"}
    # published face targets become remesh tokens; published rotations travel with the pair
    assert plan.remesh_jobs and all(re.fullmatch(r"f\d+", t) for _, _, t in plan.remesh_variants)
    rotations = bw.pair_published_rotations(manifest.iloc[0].to_dict())
    for r in rotations:
        assert np.allclose(r @ r.T, np.eye(3), atol=1e-6)


def test_released_export_of_the_workflow_loads_with_the_documented_layout(tiny_tosca_run):
    """The workflow's released-layout export, read by the loader written to docs/released-layout.md."""
    from test_export import load_released

    from becos.products.store import open_benchmark

    for setting in SETTINGS:
        base = tiny_tosca_run / "results" / setting
        bench = open_benchmark(base / "benchmark.zarr")
        pairs = load_released(base / "released")
        assert len(pairs) == len(bench)
        for (split, index), pair in pairs.items():
            record = bench.record(pair["row"]["pair_id"])
            assert record.meta["split"] == split
            for k, side in ((0, "x"), (1, "y")):
                vertices, faces = pair[f"off{k}"]
                assert np.array_equal(vertices, record[f"{side}_vertices"])
                assert np.array_equal(faces, record[f"{side}_faces"])
            assert np.array_equal(pair["corres_10"], record["corr_10"])
            if setting != "partial_full":
                assert np.array_equal(pair["corres_01"], record["corr_01"])
            if pair["ann1"] is not None:  # left/right labels propagated by the workflow
                assert np.array_equal(pair["ann1"], record["y_annotation"])


def test_every_same_class_pair_is_within_the_ground_truth_bound(tiny_tosca_run):
    """Issue #20: the final vertex maps (``corr_01`` and ``corr_10``) of EVERY same-class pair of the
    run, all three settings, against the exact truth (each remeshed vertex's ``to_original`` point
    carried by vertex identity; ``benchmarks/gt_error.py``, which prints the full table of a large
    run): max <= 0.04 x sqrt(area) on every pair, means within 5 % of the best possible vertex map."""
    sys.path.insert(0, str(REPO / "benchmarks"))
    import gt_error

    run = gt_error.Run(tiny_tosca_run / "results")
    results = [r for setting in SETTINGS for r in gt_error.audit_setting(run, setting)]
    assert {r.setting for r in results} == set(SETTINGS), "a setting of the tiny run has no same-class pair"
    print("\n" + gt_error.distribution_table(results).to_string(index=False, float_format=lambda v: f"{v:.4f}"))
    for r in results:
        s = r.summary()
        assert s["n"] > 0, s
        assert s["max"] <= gt_error.BOUND, s
        # along-surface rounding: at most 1.023 per pair (nearest corner in 3D: 1.02-1.06; largest weight: 1.10-1.19)
        assert s["mean"] <= 1.05 * s["best_mean"], s
    remeshes = gt_error.audit_remeshes(run)  # the truth's own source: no vertex snapped onto another part
    assert len(remeshes) > 0
    assert (remeshes["longest_edge_in_poses"] <= gt_error.STRETCH_BOUND).all(), remeshes.head()


def test_gt_error_names_a_store_the_run_lacks(tiny_tosca_run, capsys):
    """``benchmarks/gt_error.py`` audits the settings whose store a run has; a setting asked for
    without a store ends in one line naming its path (it once tracebacked after auditing the others)."""
    sys.path.insert(0, str(REPO / "benchmarks"))
    import gt_error

    results = tiny_tosca_run / "results"
    assert gt_error.main([str(results), "--settings", "full_full,partial_partial_x"]) == 2
    err = capsys.readouterr().err
    assert str(results / "partial_partial_x" / "benchmark.zarr") in err and "Traceback" not in err


def _tree(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` by relative path, but ``logs/config.yaml`` (it quotes its creation time) and
    Snakemake's ``.snakemake_timestamp`` of a directory output."""
    return {
        str(p.relative_to(root)): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.relative_to(root) not in (Path("logs", "config.yaml"), Path(".snakemake_timestamp"))
    }


def test_ulrssm_and_dpfm_exports_are_rules_with_cached_outputs(tiny_tosca_run, tmp_path):
    """Issue #34: ``--config 'exports={ulrssm: true, dpfm: true}'`` is accepted; on a finished run it adds
    the two layouts per setting (rules ulrssm_layout, dpfm_layout; no store nor other export reruns), each the
    same files as ``becos export-ulrssm`` / ``export-dpfm`` write from the store (ULRSSM without
    ``dist/``), and a second call does nothing."""
    import shutil

    from becos.products.export import DPFM_NONE_MAPS, IDS_FILE, write_dpfm, write_ulrssm
    from becos.products.store import open_benchmark

    run = tmp_path / "run"  # a copy (modification times kept): other tests read the shared run meanwhile
    shutil.copytree(tiny_tosca_run, run, symlinks=True)
    exports = ("--config", "exports={ulrssm: true, dpfm: true}")
    dry = snakemake(run, "-n", *exports).stdout
    # results/config.json records the whole config, so it is written again; no store nor other export is
    planned = {"ulrssm_layout": 3, "dpfm_layout": 3, "resolved_config": 1, "all": 1}
    assert jobs_planned(dry) == planned, dry[-3000:]
    snakemake(run, "--cores", "2", *exports)
    for setting in SETTINGS:
        base = run / "results" / setting
        bench = open_benchmark(base / "benchmark.zarr")
        ulrssm, dpfm = base / "ulrssm", base / "dpfm"
        for out in (ulrssm, dpfm):
            with open(out / IDS_FILE, encoding="utf-8", newline="") as fh:
                assert sorted(r["pair_id"] for r in csv.DictReader(fh)) == sorted(bench.table["pair_id"])
            assert (out / "logs" / "config.yaml").is_file()
        roots = sorted(p.parent for p in ulrssm.glob("*/*/off"))
        assert len(roots) == len(bench)
        for root in roots:  # one ULRSSM data_root per pair, without dist/
            assert sorted(str(p.relative_to(root)) for p in root.rglob("*")) == [
                "corres",
                "corres/0.vts",
                "corres/1.vts",
                "off",
                "off/0.off",
                "off/1.off",
            ]
        # each pair's two directions are in maps/ (what DPFM reads) or maps_with_none/ (a P2P export's maps/
        # stays empty: docs/released-layout.md section 6)
        maps = list(dpfm.glob("*/maps/*.map")) + list(dpfm.glob(f"*/{DPFM_NONE_MAPS}/*.map"))
        assert list(dpfm.glob("*/shapes/*.off")) and len(maps) == 2 * len(bench)
        by_hand = tmp_path / "by_hand" / setting
        write_ulrssm(bench.records(), by_hand / "ulrssm", metadata=bench.metadata)
        write_dpfm(bench.records(), by_hand / "dpfm", metadata=bench.metadata)
        assert _tree(ulrssm) == _tree(by_hand / "ulrssm")
        assert _tree(dpfm) == _tree(by_hand / "dpfm")
    again = snakemake(run, "--cores", "2", *exports)
    assert "Nothing to be done" in again.stdout + again.stderr, again.stdout[-2000:]


def test_each_job_opens_only_what_its_rule_declares(tiny_tosca_reference, becos_code):
    """Every `becos` job of the tiny run recorded what it opened (BECOS_AUDIT_OPENS, becos.cli.audit); under
    the working directory and the BeCoS code folder (data and annotations), each path is one its rule
    declares (tests/opened_paths.py says what counts as declared)."""
    from opened_paths import recorded_jobs, undeclared_opens

    run, opened = tiny_tosca_reference.workdir, tiny_tosca_reference.opened
    records = sorted(opened.glob("*.json"))
    assert len(records) == len(recorded_jobs(run)), "one audit record per becos job of the run"
    remesh_reads = [
        path
        for record in records
        if record.name.startswith("ground-truth-")
        for event, path, _ in json.loads(record.read_text())["opened"]
        if event == "open" and "/results/remeshed/" in path
    ]
    assert remesh_reads, "the audit sees the ground-truth jobs open their remesh files"
    problems = undeclared_opens(run, opened, [becos_code])
    assert not problems, f"{len(problems)} undeclared opens:\n" + "\n".join(problems[:60])


def test_copies_of_a_pair_share_one_ground_truth_file(tiny_tosca_run):
    """Copies of a pair in a chunk (same shapes, same order: the same input key) get one ground-truth
    file, its other names hard links to it, so its bytes are on disk once; the index lists each name
    with the same digest."""
    shared = 0
    for index in sorted((tiny_tosca_run / "results").glob("*/ground_truth/chunk_*.json")):
        by_key: dict[str, list[dict]] = {}
        for entry in json.loads(index.read_text())["pairs"]:
            by_key.setdefault(entry["input_key"], []).append(entry)
        for entries in by_key.values():
            files = {(st.st_dev, st.st_ino) for st in (os.stat(tiny_tosca_run / e["path"]) for e in entries)}
            assert len(files) == 1, [e["pair_id"] for e in entries]
            assert len({e["digest"] for e in entries}) == 1
            shared += len(entries) - 1
    assert shared > 0  # the tiny run draws its pairs from a few shapes: every setting has copies


def test_catalog_and_manifests_start_before_the_last_remesh_job(tiny_tosca_run):
    """The catalog and manifest jobs take under a second and every ground-truth job waits for them: with
    ``priority: 1`` they start as soon as they can, not after the remesh jobs (in the order jobs start in
    the run's Snakemake log)."""
    log = sorted((tiny_tosca_run / ".snakemake" / "log").glob("*.snakemake.log"))[0].read_text()
    started = re.findall(r"^(?:local)?rule (\w+):$", log, flags=re.M)
    last_remesh = max(i for i, rule in enumerate(started) if rule == "remesh")
    for rule in ("catalog", "manifest"):
        assert rule in started and max(i for i, r in enumerate(started) if r == rule) < last_remesh, started
