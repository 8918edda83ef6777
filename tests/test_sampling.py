"""Catalog table and pair manifests (becos.sources.catalog, becos.build.sampling) on the TOSCA shapes.

The TOSCA catalog is built from the shipped file names and the facts of ``config/tosca.yaml``
(categories and splits per class, usage 70, scale 0.0095, rot [90, 0, 0]).
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass

import numpy as np
import pandas as pd
import pytest

from becos.build.sampling import (
    MANIFEST_COLUMNS,
    N_BUCKETS,
    appearance_counts,
    appearance_summary,
    assign_chunks,
    chunk_jobs,
    pair_id_of,
    partner_score,
    read_manifest,
    sample_pairs,
    shape_key,
    write_manifest,
)
from becos.defaults import config_default
from becos.seeding import stable_hash
from becos.sources.catalog import catalog_table, natural_key, read_catalog, write_catalog

TOSCA_CLASSES = {  # class -> (category, split), config/tosca.yaml
    "michael": ("human", "train"),
    "david": ("human", "val"),
    "victoria": ("human", "test"),
    "horse": ("four-legged", "train"),
    "wolf": ("four-legged", "train"),
    "dog": ("four-legged", "val"),
    "cat": ("four-legged", "test"),
    "centaur": ("centaur", "train"),
}
RX90 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@dataclass
class Entry:
    """ShapeEntry-like record (the fields of becos.sources.datasets.ShapeEntry)."""

    dataset: str
    name: str
    path: str
    category: str
    shape_class: str
    template_key: str
    split: str
    scale: float
    frame_rotation: np.ndarray
    usage: int


def tosca_entries(tosca_dir) -> list[Entry]:
    out = []
    for f in sorted(tosca_dir.glob("*.off")):
        cls = re.match(r"[a-z]+", f.stem).group(0)
        category, split = TOSCA_CLASSES[cls]
        out.append(Entry("tosca", f.stem, str(f), category, cls, f"tosca_{cls}", split, 0.0095, RX90, 70))
    return out


def template_rows(path) -> dict:
    """First row per key (the reference's lookup rule), as dicts."""
    df = pd.read_csv(path, dtype=str).drop_duplicates("dataset", keep="first")
    return {r["dataset"]: r for r in df.to_dict("records")}


@pytest.fixture(scope="module")
def entries(tosca_dir):
    e = tosca_entries(tosca_dir)
    assert len(e) == 76
    return e


@pytest.fixture(scope="module")
def catalog(entries):
    return catalog_table(entries)


@pytest.fixture(scope="module")
def manifest_all(catalog):
    return sample_pairs(catalog, "full_full", seed=42, combinations="all")


def categories_of(catalog):
    return {shape_key(d, n): c for d, n, c in zip(catalog["dataset"], catalog["name"], catalog["category"])}


# ------------------------------------------------------------------------------------------ catalog


def test_catalog_order_columns_and_round_trip(entries, catalog, tmp_path):
    names = catalog["name"].tolist()
    assert names.index("michael2") < names.index("michael10")
    assert names == sorted(names, key=natural_key)
    assert natural_key("0001.isometry.4") < natural_key("0001.isometry.10")
    # entry order does not matter
    shuffled = [entries[i] for i in np.random.default_rng(0).permutation(len(entries))]
    pd.testing.assert_frame_equal(catalog_table(shuffled), catalog)
    row = catalog[catalog["name"] == "horse0"].iloc[0]
    np.testing.assert_array_equal(row[[f"frame_rotation_{i}" for i in range(9)]].to_numpy(float), RX90.ravel())
    assert (row["category"], row["split"], row["class"], row["template_key"], row["usage"]) == (
        "four-legged",
        "train",
        "horse",
        "tosca_horse",
        70,
    )
    p1, p2 = tmp_path / "a.csv", tmp_path / "b.csv"
    write_catalog(catalog, p1)
    back = read_catalog(p1)
    pd.testing.assert_frame_equal(back, catalog)
    write_catalog(back.iloc[::-1], p2)
    assert p1.read_bytes() == p2.read_bytes()
    with pytest.raises(ValueError, match="duplicate"):
        catalog_table(entries + entries[:1])


# ------------------------------------------------------------------------------------------ pools


def test_pool_rules(catalog, manifest_all):
    m = manifest_all
    cat = categories_of(catalog)
    xc = np.array([cat[shape_key(d, n)] for d, n in zip(m["x_dataset"], m["x_name"])])
    yc = np.array([cat[shape_key(d, n)] for d, n in zip(m["y_dataset"], m["y_name"])])
    centaur = (xc == "centaur") | (yc == "centaur")
    assert (xc[~centaur] == yc[~centaur]).all()  # no cross-category pair without a centaur
    assert (m["category"].to_numpy()[~centaur] == xc[~centaur]).all()
    assert set(m.loc[centaur, "split"]) == {"train"}  # centaur pairs in train only
    assert centaur.sum() > 0
    # a centaur is only a partner of another centaur
    assert not ((yc == "centaur") & (xc != "centaur")).any()
    # centaur pairs land in both pools, partners of the pool's category (or centaurs)
    for pool in ("human", "four-legged"):
        sel = (xc == "centaur") & (m["category"].to_numpy() == pool)
        assert sel.sum() > 0 and set(yc[sel]) <= {pool, "centaur"}
    assert (m["x_name"] != m["y_name"]).all()
    # splits never mix
    splits = dict(zip(catalog["name"], catalog["split"]))
    assert (m["x_name"].map(splits) == m["split"]).all() and (m["y_name"].map(splits) == m["split"]).all()
    assert list(m.columns) == list(MANIFEST_COLUMNS)


@pytest.mark.parametrize("usage_scale", [1.0, 0.5])
def test_anchor_counts_exact(catalog, usage_scale):
    m = sample_pairs(catalog, "partial_partial", seed=7, combinations="all", usage_scale=usage_scale)
    u = int(np.floor(70 * usage_scale + 0.5))
    counts = appearance_counts(m)
    train = catalog[catalog["split"] == "train"]
    as_x = counts.set_index(["name", "split"])["as_x"]
    for name, category in zip(train["name"], train["category"]):
        assert as_x.get((name, "train"), 0) == u, name
    # centaurs: u copies split between the two pools, even copies human, odd copies four-legged
    cent = m[m["x_name"].str.startswith("centaur")]
    assert (cent.loc[cent["category"] == "human", "copy"] % 2 == 0).all()
    assert (cent.loc[cent["category"] == "four-legged", "copy"] % 2 == 1).all()
    for split in ("val", "test"):
        names = catalog.loc[catalog["split"] == split, "name"]
        got = m[m["split"] == split]["x_name"].value_counts()
        assert set(got.index) == set(names) and (got == 1).all()
    # total appearances: u as anchor + partner picks; report the distribution
    summary = appearance_summary(m, catalog)
    row = summary.iloc[0]
    assert row["as_x_min"] == row["as_x_max"] == u
    assert row["total_min"] >= u and row["total_max"] > row["total_mean"] > u
    print(
        f"\nusage_scale={usage_scale}: pairs {m.attrs['report']['n_pairs']}; train appearances per shape "
        f"min {row['total_min']} median {row['total_median']} mean {row['total_mean']:.1f} "
        f"max {row['total_max']}"
    )


def test_partner_is_rendezvous_argmin(catalog, manifest_all):
    """The vectorised argmin equals a brute-force argmin of partner_score (sample of rows)."""
    m = manifest_all
    cat = catalog.set_index("name")
    rows = m.iloc[np.random.default_rng(1).choice(len(m), 60, replace=False)]
    for r in rows.itertuples():
        x = shape_key(r.x_dataset, r.x_name)
        x_is_centaur = cat.at[r.x_name, "category"] == "centaur"
        pool_cats = {r.category, "centaur"} if x_is_centaur else {r.category}
        cands = cat[(cat["split"] == r.split) & cat["category"].isin(pool_cats) & (cat.index != r.x_name)]
        scores = {n: partner_score(42, "full_full", x, r.copy, shape_key("tosca", n)) for n in cands.index}
        assert min(scores, key=scores.get) == r.y_name


def test_determinism_row_order_and_files(catalog, manifest_all, tmp_path):
    shuffled = catalog.sample(frac=1.0, random_state=3)
    again = sample_pairs(shuffled, "full_full", seed=42, combinations="all")
    pd.testing.assert_frame_equal(again, manifest_all)
    other = sample_pairs(catalog, "full_full", seed=43, combinations="all")
    assert (other["y_name"].to_numpy() != manifest_all["y_name"].to_numpy()).mean() > 0.3
    p1, p2 = tmp_path / "m1.csv", tmp_path / "m2.csv"
    write_manifest(manifest_all, p1)
    write_manifest(again.sample(frac=1.0, random_state=5), p2)
    assert p1.read_bytes() == p2.read_bytes()
    back = read_manifest(p1)
    pd.testing.assert_frame_equal(back, manifest_all.reset_index(drop=True), check_like=False)
    # ids and derived fields
    assert manifest_all["pair_id"].str.fullmatch(r"[0-9a-f]{16}").all()
    assert manifest_all["pair_id"].is_unique
    least = config_default("pairs_per_chunk")  # sample_pairs' default chunk options are the config's
    jobs = chunk_jobs(len(manifest_all), config_default("n_chunks"), least, config_default("min_chunks"))
    assert 1 < jobs < 64 and least <= len(manifest_all) / jobs < 2 * least
    assert manifest_all["x_variant"].between(0, 3).all() and manifest_all["chunk"].between(0, jobs - 1).all()
    assert manifest_all["x_variant"].nunique() == 4 and manifest_all["chunk"].nunique() == jobs
    order = list(zip(manifest_all["split"].map({"train": 0, "val": 1, "test": 2}), manifest_all["pair_id"]))
    assert order == sorted(order)


@pytest.mark.parametrize("combination", ["human", "four-legged", "human_centaur", "four-legged_centaur", "all"])
def test_combinations_work_on_tosca(catalog, combination):
    m = sample_pairs(catalog, "full_full", seed=42, combinations=combination, usage_scale=0.2)
    n = m.attrs["report"]["n_pairs"]
    assert n["train"] > 0 and n["val"] > 0 and n["test"] > 0
    pools = {"human", "four-legged"} if combination == "all" else {combination.split("_")[0]}
    assert set(m["category"]) == pools
    has_centaur = m["x_name"].str.startswith("centaur").any()
    assert has_centaur == ("centaur" in combination or combination == "all")


# ------------------------------------------------------------------------------------------ growth


def _by_anchor(m):
    return m.set_index(["x_dataset", "x_name", "copy"])


def test_growth_enabling_other_pools_and_centaurs(catalog):
    four = sample_pairs(catalog, "full_full", seed=42, combinations="four-legged")
    full = sample_pairs(catalog, "full_full", seed=42, combinations="all")
    a, b = _by_anchor(four), _by_anchor(full)
    common = a.index.intersection(b.index)
    assert len(common) == len(a)  # every four-legged anchor copy still exists
    changed = (a.loc[common, "pair_id"] != b.loc[common, "pair_id"]).mean()
    print(
        f"\nfour-legged -> all: {len(a)} four-legged pairs, share changed {changed:.4f}; pairs added {len(b) - len(a)}"
    )
    assert changed <= 0.10
    human = sample_pairs(catalog, "full_full", seed=42, combinations="human")
    human_c = sample_pairs(catalog, "full_full", seed=42, combinations="human_centaur")
    assert set(human["pair_id"]) <= set(human_c["pair_id"])  # centaurs add pairs, change none


def test_growth_new_dataset_changes_about_new_share(entries, catalog):
    zoo = [
        Entry("zoo", f"beast{i}", f"/nowhere/beast{i}.off", "four-legged", "beast", "zoo", "train", 1.0, np.eye(3), 40)
        for i in range(10)
    ]
    grown = catalog_table(entries + zoo)
    old = sample_pairs(catalog, "partial_partial", seed=42, combinations="all")
    new = sample_pairs(grown, "partial_partial", seed=42, combinations="all")
    a, b = _by_anchor(old), _by_anchor(new)
    assert a.index.isin(b.index).all()
    old_fl = a[
        (a["category"] == "four-legged")
        & (a["split"] == "train")
        & ~a.index.get_level_values("x_name").str.startswith("centaur")
    ]
    changed = old_fl["pair_id"] != b.loc[old_fl.index, "pair_id"]
    # each horse/wolf anchor had 10 candidates (11 train four-legged minus itself); 10 are added
    expected = 10 / (10 + 10)
    print(
        f"\nadding 10 four-legged shapes to 11: share of existing four-legged anchors changed "
        f"{changed.mean():.3f} (expected ~{expected:.3f}); new pairs now {len(b) - len(a)}"
    )
    assert abs(changed.mean() - expected) < 0.08
    assert set(b.loc[old_fl.index[changed], "y_dataset"]) == {"zoo"}  # changes only towards new shapes
    unchanged = old_fl.index[~changed]
    pd.testing.assert_frame_equal(a.loc[unchanged], b.loc[unchanged])
    other = a[a["category"] == "human"]
    assert (other["pair_id"] == b.loc[other.index, "pair_id"]).all()  # other pool untouched
    assert (new[new["x_dataset"] == "zoo"].groupby("x_name").size() == 40).all()


def test_caps_keep_smallest_rank_and_are_stable(entries, catalog):
    base = sample_pairs(catalog, "full_full", seed=42, combinations="all")
    c5 = sample_pairs(catalog, "full_full", seed=42, combinations="all", caps={"val": 5, "train": 300})
    c8 = sample_pairs(catalog, "full_full", seed=42, combinations="all", caps={"val": 8, "train": 400})
    assert c5.attrs["report"]["n_pairs"] == {"train": 300, "val": 5, "test": len(base[base["split"] == "test"])}
    assert set(c5["pair_id"]) <= set(c8["pair_id"]) <= set(base["pair_id"])
    assert c5.attrs["report"]["skipped"]["cap:train"] == (base["split"] == "train").sum() - 300
    zoo = [Entry("zoo", f"beast{i}", "-", "four-legged", "beast", "zoo", "train", 1.0, np.eye(3), 4) for i in range(3)]
    grown = sample_pairs(catalog_table(entries + zoo), "full_full", seed=42, combinations="all", caps={"train": 300})
    kept = _by_anchor(c5[c5["split"] == "train"]).index
    still = kept.isin(_by_anchor(grown).index).mean()
    print(f"\ncap 300 train: share of capped anchor copies kept after adding 12 zoo anchors {still:.3f}")
    assert still >= 0.95


# ------------------------------------------------------------------------------------------ P2F


def test_partial_full_with_demo_table(becos_code, catalog):
    rows = template_rows(becos_code / "config" / "templates_tosca_demo.csv")
    m = sample_pairs(catalog, "partial_full", seed=42, combinations="all", template_rows=rows)
    expected_x = {
        n: r["partial_full_template"]
        for n, r in ((n, rows[k]) for n, k in zip(catalog["name"], catalog["template_key"]))
    }
    assert (m["x_name"] == m["y_name"].map(expected_x)).all()
    assert (m["x_name"] != m["y_name"]).all()
    cats = dict(zip(catalog["name"], catalog["category"]))
    assert (m["category"] == m["y_name"].map(cats)).all()
    anchors = m.groupby(["y_name", "split"]).size()
    templates = set(expected_x.values())
    for name, split in zip(catalog["name"], catalog["split"]):
        want = 0 if name in templates else (70 if split == "train" else 1)
        assert anchors.get((name, split), 0) == want, name
    own = sum(70 if s == "train" else 1 for n, s in zip(catalog["name"], catalog["split"]) if n in templates)
    assert m.attrs["report"]["skipped"] == {"p2f_own_template": own}


def test_partial_full_all_table_skips_missing_datasets(becos_code, catalog):
    rows = template_rows(becos_code / "config" / "templates_all.csv")
    m = sample_pairs(catalog, "partial_full", seed=42, combinations="all", template_rows=rows)
    skipped = m.attrs["report"]["skipped"]
    humans = catalog[catalog["category"] == "human"]
    n_humans = sum(70 if s == "train" else 1 for s in humans["split"])
    assert skipped["p2f_template_dataset_unavailable:faust"] == n_humans
    assert "p2f_template_dataset_unavailable:dt4d_animal" in skipped  # dog and cat
    assert set(m["y_name"].str.extract(r"([a-z]+)")[0]) == {"horse", "wolf", "centaur"}
    assert m.attrs["report"]["n_pairs"]["train"] == len(m)


def test_val_centaur_is_reported_not_paired(entries):
    moved = [
        Entry(
            e.dataset,
            e.name,
            e.path,
            e.category,
            e.shape_class,
            e.template_key,
            "val" if e.name == "centaur5" else e.split,
            e.scale,
            e.frame_rotation,
            e.usage,
        )
        for e in entries
    ]
    m = sample_pairs(catalog_table(moved), "full_full", seed=42, combinations="all")
    assert m.attrs["report"]["skipped"]["centaur_not_train"] == 1
    assert not (m["x_name"] == "centaur5").any() and not (m["y_name"] == "centaur5").any()


# ------------------------------------------------------------------------------------------ scale


def test_benchmark_size_pair_counts():
    """~2,500 shapes with the published datasets' usage counts (time printed; speed is measured by
    benchmarks/workflow.py, never asserted in a test)."""
    spec = [
        ("faust", "human", 40, 100),
        ("scape", "human", 40, 71),
        ("kids", "human", 50, 32),
        ("dt4d_human", "human", 10, 248),
        ("tosca", "human", 70, 39),
        ("dt4d_animal", "four-legged", 4, 1950),
        ("smal", "four-legged", 60, 49),
        ("shrec20", "four-legged", 80, 11),
        ("toscaq", "four-legged", 70, 31),
        ("toscac", "centaur", 70, 6),
    ]
    rows = [
        dict(
            dataset=ds,
            name=f"{ds}{i}",
            category=c,
            template_key=ds,
            usage=u,
            split="train" if c == "centaur" or i % 10 < 8 else ("val" if i % 10 == 8 else "test"),
        )
        for ds, c, u, n in spec
        for i in range(n)
    ]
    cat = pd.DataFrame(rows)
    t0 = time.perf_counter()
    m = sample_pairs(cat, "partial_partial", seed=42, combinations="all")
    dt = time.perf_counter() - t0
    half = sample_pairs(cat, "partial_partial", seed=42, combinations="all", usage_scale=0.5)
    print(f"\n{len(cat)} shapes: {len(m)} pairs in {dt:.2f} s (usage_scale 0.5: {len(half)} pairs)")
    expected_train = sum(u * sum(1 for i in range(n) if c == "centaur" or i % 10 < 8) for _, c, u, n in spec)
    assert m.attrs["report"]["n_pairs"]["train"] == expected_train


def test_with_real_dataset_and_annotation_modules(becos_code, catalog, tmp_path):
    """The real becos.sources.datasets / becos.sources.annotations listing."""
    import becos.sources.annotations as annotations
    import becos.sources.datasets as datasets

    source = annotations.AnnotationSource(becos_code, template_table="templates_tosca_demo.csv")
    entries = datasets.DatasetSpec.load("tosca").list_shapes(becos_code / "data", source)
    cat = catalog_table(entries)
    assert len(cat) == 76 and set(cat["split"]) == {"train", "val", "test"}
    pd.testing.assert_frame_equal(cat.drop(columns="file"), catalog.drop(columns="file"), atol=1e-15)
    write_catalog(cat, tmp_path / "catalog.csv")
    pd.testing.assert_frame_equal(read_catalog(tmp_path / "catalog.csv"), cat)
    m = sample_pairs(cat, "partial_full", seed=42, combinations="all", template_rows=source)
    assert len(m) > 0 and (m["x_name"] != m["y_name"]).all()
    f2f = sample_pairs(cat, "full_full", seed=42, combinations="all")
    assert (f2f.groupby(["x_name", "split"]).size().xs("train", level="split") == cat["usage"].iloc[0]).all()


@pytest.mark.parametrize("table", ["templates_tosca_demo.csv", "templates_all.csv"])
def test_partial_full_with_annotation_source(becos_code, catalog, table):
    """becos.sources.annotations.AnnotationSource (object with template_row, or its template_rows() dict)
    gives the same P2F manifest as the plain table rows."""
    import becos.sources.annotations as annotations

    source = annotations.AnnotationSource(becos_code, template_table=table)
    plain = sample_pairs(
        catalog, "partial_full", seed=42, combinations="all", template_rows=template_rows(becos_code / "config" / table)
    )
    via_source = sample_pairs(catalog, "partial_full", seed=42, combinations="all", template_rows=source)
    via_dict = sample_pairs(catalog, "partial_full", seed=42, combinations="all", template_rows=source.template_rows())
    assert len(plain) > 0
    pd.testing.assert_frame_equal(via_source, plain)
    pd.testing.assert_frame_equal(via_dict, plain)
    assert via_source.attrs["report"] == plain.attrs["report"]
    # a key the table lacks is counted, not fatal
    odd = catalog.copy()
    odd.loc[odd["name"] == "wolf0", "template_key"] = "tosca_unicorn"
    m = sample_pairs(odd, "partial_full", seed=42, combinations="all", template_rows=source)
    assert m.attrs["report"]["skipped"]["no_template_row:tosca_unicorn"] == 70


def test_chunk_jobs_follow_the_pair_count_and_growth_moves_no_pair_needlessly():
    """Chunk jobs hold pairs_per_chunk to twice as many pairs, at most n_chunks; growth that keeps the
    job count moves no pair, a doubling splits every job in two (issue 18)."""
    assert [chunk_jobs(n, n_chunks=64, pairs_per_chunk=100) for n in (0, 1, 150, 199, 200, 1334, 10029)] == [
        1,
        1,
        1,
        1,
        2,
        8,
        64,
    ]
    assert chunk_jobs(10**6, n_chunks=100, pairs_per_chunk=100) == 100  # capped by n_chunks
    # min_chunks: at least that many jobs (a power of two) while each keeps MIN_CHUNK_PAIRS pairs
    two = [chunk_jobs(n, n_chunks=64, pairs_per_chunk=300, min_chunks=2) for n in (127, 128, 450, 599, 600, 1200)]
    assert two == [1, 2, 2, 2, 2, 4]
    assert [chunk_jobs(n, n_chunks=64, pairs_per_chunk=300, min_chunks=8) for n in (200, 300, 599)] == [2, 4, 8]
    assert chunk_jobs(900, n_chunks=2, pairs_per_chunk=300, min_chunks=8) == 2  # n_chunks caps it too
    ids = [pair_id_of("full_full", f"d/x{i}", f"d/y{i}", 0) for i in range(1700)]
    small = assign_chunks(ids[:1000], n_chunks=64, pairs_per_chunk=100)
    grown = assign_chunks(ids[:1500], n_chunks=64, pairs_per_chunk=100)
    doubled = assign_chunks(ids, n_chunks=64, pairs_per_chunk=100)
    assert small.max() == grown.max() == 7 and doubled.max() == 15
    assert np.array_equal(grown[:1000], small)  # 8 jobs still: no existing pair moves
    assert np.array_equal(doubled[:1000] // 2, small)  # 16 jobs: job k splits into 2k, 2k + 1
    sizes = np.bincount(small)
    assert sizes.min() > 80 and sizes.max() < 170, sizes  # contiguous bucket ranges: balanced jobs
    buckets = np.array([stable_hash(p) % N_BUCKETS for p in ids[:1000]])
    ranges = [(buckets[small == k].min(), buckets[small == k].max()) for k in range(8)]
    assert all(hi < next_lo for (_, hi), (next_lo, _) in zip(ranges, ranges[1:]))  # contiguous bucket ranges
