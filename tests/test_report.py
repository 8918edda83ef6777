"""Report stage: ground-truth renders of real TOSCA pairs, counts, overlap histogram, report folder, captions."""

from __future__ import annotations

import argparse
import json
import re
import time
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from becos.build.record import PairRecord
from becos.cli.report import configure_parser, run_cli
from becos.products.report import (
    CAPTIONS,
    NO_MATCH_GREY,
    common_vertices,
    overlap_histogram,
    position_colours,
    render_pair,
    select_render_ids,
    table_from_records,
    write_report,
)

REPO = Path(__file__).resolve().parents[1]
SETTINGS = ("full_full", "partial_full", "partial_partial")


@pytest.fixture(scope="module")
def records(pair_record_files) -> dict[str, list[PairRecord]]:
    return {s: [PairRecord.load(p) for p in paths] for s, paths in pair_record_files.items()}


def _image(path: Path) -> np.ndarray:
    return imread(str(path))[..., :3].astype(np.float64)


def _grey_pixels(image: np.ndarray) -> int:
    """Pixels of the (shaded) no-match grey: neutral (r = g = b) and neither white background nor black."""
    spread = image.max(axis=-1) - image.min(axis=-1)
    value = image.max(axis=-1)
    return int(((spread < 0.02) & (value > 0.1) & (value < NO_MATCH_GREY[0] + 0.08)).sum())


@pytest.mark.parametrize("setting", SETTINGS)
def test_render_pair_shows_the_ground_truth(records, setting, tmp_path):
    # the record of the setting with the most Y vertices without counterpart (P2P: some; F2F, P2F: none)
    record = max(records[setting], key=lambda r: int((r["corr_10"] == -1).sum()))
    n_unmatched = int((record["corr_10"] == -1).sum())
    assert (n_unmatched > 0) == (setting == "partial_partial")  # cats are fully matched; scans of Y lie on X

    path = render_pair(record, tmp_path / "pair.png", size=(720, 360))
    image = _image(path)
    assert image.shape == (360, 720, 3)
    drawn = image.min(axis=-1) < 0.97  # not the white background
    assert drawn.mean() > 0.08, f"{setting}: only {drawn.mean():.1%} of the image is drawn"
    colours = np.unique((image[drawn] * 255).round().astype(np.uint8), axis=0)
    assert len(colours) > 500, f"{setting}: only {len(colours)} distinct colours, shading/colours missing"
    # both panels hold a shape
    assert drawn[:, :360].mean() > 0.04 and drawn[:, 360:].mean() > 0.04

    grey = _grey_pixels(image)
    if n_unmatched:
        assert grey > 100, f"{setting}: {n_unmatched} unmatched Y vertices but only {grey} grey pixels"
        assert grey < drawn[:, 360:].sum()  # not the whole of Y
    else:
        assert grey < 10, f"{setting}: fully matched pair shows {grey} grey pixels"


def test_position_colours_are_never_grey(records):
    """The premise of the grey-pixel test: X's colours are saturated everywhere."""
    for setting in SETTINGS:
        colours = position_colours(common_vertices(records[setting][0], "x"))
        assert colours.min() >= 0 and colours.max() <= 1
        assert (colours.max(axis=1) - colours.min(axis=1)).min() > 0.3
        assert np.ptp(colours, axis=0).max() > 0.5  # actually varies over the shape


def test_common_frame_undoes_the_random_rotations(records):
    """After undoing the random rotations Y lies on X (it was aligned onto X), upright in the shared frame."""
    record = records["full_full"][0]
    xc, yc = common_vertices(record, "x"), common_vertices(record, "y")
    corr = record["corr_10"]
    gap_common = np.linalg.norm(yc - xc[corr], axis=1)
    gap_final = np.linalg.norm(record["y_vertices"] - record["x_vertices"][corr], axis=1)
    size = np.ptp(xc, axis=0).max()
    assert np.median(gap_common) < 0.1 * size
    assert np.median(gap_final) > 3 * np.median(gap_common)  # the two random rotations differ
    # the up axis (y) is preserved by the one-axis random rotation: heights agree before and after
    np.testing.assert_allclose(xc[:, 1], record["x_vertices"][:, 1], atol=1e-9)


def test_render_of_a_10k_vertex_pair(records, tmp_path):
    record = records["full_full"][0]
    n_faces = len(record["x_faces"]) + len(record["y_faces"])
    render_pair(record, tmp_path / "warm.png")  # imports, font cache
    start = time.perf_counter()
    render_pair(record, tmp_path / "pair.png")
    seconds = time.perf_counter() - start
    print(
        f"render of {len(record['x_vertices'])} + {len(record['y_vertices'])} vertices, {n_faces} faces: "
        f"{seconds:.2f} s"
    )  # speed: printed, not asserted
    assert (tmp_path / "pair.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_write_report_counts_histogram_renders(records, tmp_path):
    all_records = [r for s in SETTINGS for r in records[s]]
    table = table_from_records(all_records)
    assert list(table["split"]) == ["train"] * 3 + ["test"] * 3  # store order

    out = tmp_path / "report"
    summary = write_report(iter(all_records), table, out, n_renders=3, metadata={"config_hash": "abc123"})

    # counts
    assert summary["n_pairs"] == 6 and summary["splits"] == ["train", "test"]
    assert summary["counts"]["split"]["train"]["total"] == 3
    assert summary["counts"]["split"]["test"]["total"] == 3
    assert summary["counts"]["category"] == {"four-legged": {"train": 3, "test": 3, "total": 6}}
    assert summary["counts"]["dataset_pair"]["tosca/tosca"]["total"] == 6
    assert summary["setting"] == "mixed" and summary["n_distinct_shapes"] == 2
    counts_csv = (out / "counts.csv").read_text().splitlines()
    assert counts_csv[0] == "group,value,train,test,total"
    assert "split,train,3,0,3" in counts_csv and "x_dataset,tosca,3,3,6" in counts_csv

    # histogram: both directions of every pair, each in the bin of its overlap
    hist = summary["overlap_histogram"]
    assert hist["n_directions"] == sum(hist["total"]) == 12
    for direction in ("x", "y"):
        values = np.array([float(r[f"{direction}_overlap"]) for r in all_records])
        expected = np.bincount(np.minimum((values * 10).astype(int), 9), minlength=10)
        assert hist[direction] == expected.tolist()
    assert hist["total"][9] == 2 + 2 + 2  # F2F both ways, P2F y_overlap = 1.0
    rows = (out / "overlap_histogram.csv").read_text().splitlines()
    assert len(rows) == 11 and sum(int(r.split(",")[-1]) for r in rows[1:]) == 12

    # renders: round robin over the splits, smallest pair ids first
    chosen = [r["pair_id"] for r in summary["renders"]]
    assert chosen == ["ff00000000000000", "ff00000000000001", "pf00000000000000"]
    for entry in summary["renders"]:
        assert _image(out / entry["file"]).shape == (450, 900, 3)
    assert summary["missing_renders"] == []

    # summary.json is what was returned; index.html links only to files that exist (relative links)
    assert json.loads((out / "summary.json").read_text()) == summary
    assert summary["metadata"] == {"config_hash": "abc123"}
    page = (out / "index.html").read_text()
    links = re.findall(r'(?:src|href)="([^"]+)"', page)
    assert "overlap_histogram.png" in links and "renders/pf00000000000000.png" in links
    for link in links:
        assert not link.startswith(("/", "http")) and (out / link).is_file(), link
    assert "abc123" in page
    # not a P2P report: no published histogram beside it (table, page, plot)
    assert summary["published_overlap_histogram"] is None and "published" not in rows[0]
    assert "Beside the published" not in page
    assert _published_grey_pixels(out / "overlap_histogram.png") < 1000  # anti-aliased text only


def _published_grey_pixels(path: Path) -> int:
    """Pixels of the published histogram's bar colour (#8c8c8c) in a histogram PNG."""
    image = _image(path)
    return int((np.abs(image - 0x8C / 255).max(axis=-1) < 0.01).sum())


def test_write_report_single_setting_and_missing_records(records, tmp_path):
    p2p = records["partial_partial"]
    table = table_from_records(p2p)
    # only the test record is passed: the train one is reported missing, not rendered
    summary = write_report([p2p[1]], table, tmp_path, n_renders=8)
    assert summary["setting"] == "partial_partial"
    assert summary["overlap_histogram"]["n_directions"] == sum(summary["overlap_histogram"]["total"]) == 4
    # P2P: the published histogram beside ours, both as shares
    published = summary["published_overlap_histogram"]
    assert published["published_count"] == [20, 1850, 2391, 2321, 2828, 3163, 3391, 3247, 1715, 2]
    assert published["n_published_directions"] == 20928 and published["n_directions"] == 4
    assert published["bin_centre_percent"] == list(range(5, 100, 10))
    assert published["count"] == summary["overlap_histogram"]["total"]
    np.testing.assert_allclose(published["share"], np.array(published["count"]) / 4)
    np.testing.assert_allclose(sum(published["published_share"]), 1.0)
    assert published["published_share"][6] == pytest.approx(3391 / 20928)
    expected_tv = 0.5 * np.abs(np.array(published["share"]) - np.array(published["published_share"])).sum()
    assert published["total_variation"] == pytest.approx(expected_tv) and 0 < expected_tv <= 1
    rows = (tmp_path / "overlap_histogram.csv").read_text().splitlines()
    assert rows[0].endswith(",total,share,published_count,published_share")
    assert rows[7].split(",")[-2:] == ["3391", str(round(3391 / 20928, 6))]
    page = (tmp_path / "index.html").read_text()
    assert "Beside the published BeCoS P2P histogram" in page and "3,391" in page and "16.2 %" in page
    assert f"{expected_tv:.3f}" in page
    assert _published_grey_pixels(tmp_path / "overlap_histogram.png") > 5000  # the published bars
    assert [r["pair_id"] for r in summary["renders"]] == [p2p[1].pair_id]
    assert summary["missing_renders"] == [p2p[0].pair_id]
    assert sorted(p.name for p in (tmp_path / "renders").iterdir()) == [f"{p2p[1].pair_id}.png"]
    assert abs(summary["overlap"]["x"]["mean"] - np.mean([float(r["x_overlap"]) for r in p2p])) < 1e-12


def test_select_render_ids_and_bad_tables(records):
    import pandas as pd

    table = pd.DataFrame({"pair_id": ["b", "a", "d", "c", "e"], "split": ["test", "test", "train", "val", "train"]})
    assert select_render_ids(table, 4) == ["d", "c", "a", "e"]
    assert select_render_ids(table, 10) == ["d", "c", "a", "e", "b"]
    assert select_render_ids(table, 0) == []

    good = table_from_records(records["full_full"])
    with pytest.raises(ValueError, match="x_overlap"):
        write_report([], good.drop(columns="x_overlap"), "/nonexistent/never-written")
    broken = good.assign(y_overlap=[0.5, 1.5])
    with pytest.raises(ValueError, match="outside"):
        overlap_histogram(broken)
    edges = good.assign(x_overlap=[0.3, 0.1], y_overlap=[1.0, 0.0])
    hist = overlap_histogram(edges)
    assert hist["x"][3] == 1 and hist["x"][1] == 1 and hist["y"][9] == 1 and hist["y"][0] == 1


def test_captions_exist_and_are_valid_rst():
    from docutils.core import publish_parts

    folder = REPO / "workflow" / "report"
    names = {"workflow.rst", *CAPTIONS.values()}
    assert names <= {p.name for p in folder.glob("*.rst")}
    for name in names:
        text = (folder / name).read_text(encoding="utf-8")
        assert "{{" not in text and "{%" not in text  # Snakemake renders captions with Jinja2
        # halt_level 2: any docutils warning is an error
        body = publish_parts(text, writer="html", settings_overrides={"halt_level": 2, "report_level": 5})["body"]
        assert len(body) > 100, name


def test_cli_arguments_and_missing_store(tmp_path):
    from becos.errors import InputFileError

    parser = argparse.ArgumentParser()
    configure_parser(parser)
    args = parser.parse_args([str(tmp_path / "absent.zarr"), str(tmp_path / "out"), "--renders", "3"])
    assert args.renders == 3 and args.store == tmp_path / "absent.zarr"
    assert parser.parse_args(["s", "o"]).renders == 8
    with pytest.raises(InputFileError, match="absent.zarr.*not found"):
        run_cli(args)


def test_cli_on_a_store(pair_record_files, tmp_path, capsys):
    import becos.products.store as store
    from becos.cli import main

    path = store.write_store(
        pair_record_files["partial_partial"], tmp_path / "p2p.zarr", setting="partial_partial", progress=False
    )
    assert main(["report", str(path), str(tmp_path / "out"), "--renders", "1"]) == 0
    printed = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert printed["n_pairs"] == 2 and printed["renders"] == 1 and printed["overlap_directions"] == 4
    assert 0 < printed["published_overlap_total_variation"] <= 1
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["setting"] == "partial_partial"
    assert (tmp_path / "out" / summary["renders"][0]["file"]).is_file()
