"""Store-level checks of a benchmark store's layout, attributes and pairs table: ``schema``,
``metadata``, ``meta``, ``table``, ``pair_id``, ``split_classes`` and ``centaur`` (the table of
:mod:`becos.products.validate`)."""

from __future__ import annotations

import numpy as np

from becos.build.record import RECORD_SCHEMA, SCHEMA_VERSION
from becos.errors import BecosError
from becos.products.validate.report import MAX_EXAMPLES, Problems
from becos.settings import SETTINGS, SPLITS


def expected_schema() -> dict[str, tuple[str, tuple[int, ...]]]:
    """Record key -> (dtype name, trailing shape) as stored: ragged keys without their leading length,
    stacked keys with their full per-pair shape (from :data:`becos.build.record.RECORD_SCHEMA`)."""
    return {key: (f.disk_dtype, f.shape) for key, f in RECORD_SCHEMA.items()}


def check_schema(bench, problems: list[str]) -> bool:
    """Keys, dtypes, shapes and groups; False if the row-wise checks cannot run."""
    ok = True
    expected = expected_schema()
    missing = sorted(set(expected) - set(bench.layout))
    if missing:
        problems.append(f"schema: the store lacks the record keys {missing}")
        ok = False
    for key, (dtype, trailing) in expected.items():
        if key not in bench.layout:
            continue
        array = bench.array(key)
        group = bench.layout[key]
        want_group = RECORD_SCHEMA[key].group
        if group != want_group:
            problems.append(
                f"schema: {key} is stored in offset group {group}, expected {want_group} "
                "(its lengths disagree with the other arrays of that group)"
            )
            ok = False
        if str(array.dtype) != dtype:
            problems.append(f"schema: {key} has dtype {array.dtype}, expected {dtype}")
            ok = False
        if tuple(array.shape[1:]) != trailing:
            problems.append(f"schema: {key} has rows of shape {tuple(array.shape[1:])}, expected {trailing}")
            ok = False
        if group is not None and array.shape[0] != bench.offsets[group][-1]:
            problems.append(
                f"schema: {key} has {array.shape[0]} rows but offsets '{group}' end at {bench.offsets[group][-1]}"
            )
            ok = False
        if group is None and array.shape[0] != len(bench):
            problems.append(f"schema: {key} has {array.shape[0]} rows for {len(bench)} pairs")
            ok = False
    ids = bench.table["pair_id"].to_numpy().astype(str)
    for group, o in bench.offsets.items():
        if len(o) and o[0] != 0:
            problems.append(f"schema: offsets '{group}' start at {o[0]}, not 0")
            ok = False
        bad = np.flatnonzero(np.diff(o) < 0)
        if len(bad):
            problems.append(
                f"schema: offsets '{group}' decrease (negative row count) in {len(bad)} pair(s), "
                f"e.g. {', '.join(ids[bad[:MAX_EXAMPLES]])}"
            )
            ok = False
    return ok


def split_rule(dataset: str, cache: dict) -> str | None:
    if dataset not in cache:
        from becos.sources.datasets import DatasetSpec

        try:
            cache[dataset] = DatasetSpec.load(dataset).split.get("rule")
        except BecosError:
            cache[dataset] = None
    return cache[dataset]


def check_splits(table, setting: str, problems: Problems) -> None:
    """Class-disjoint splits (``split_classes``) and centaurs in train only (``centaur``)."""
    import pandas as pd

    sides = ["y"] if setting == "partial_full" else ["x", "y"]
    parts = [
        pd.DataFrame(
            {
                "dataset": table[f"{s}_dataset"],
                "class": table[f"{s}_class"],
                "category": table[f"{s}_category"],
                "split": table["split"],
                "pair_id": table["pair_id"],
            }
        )
        for s in sides
    ]
    rows = pd.concat(parts, ignore_index=True)
    rules: dict = {}
    for (dataset, shape_class), group in rows.groupby(["dataset", "class"], sort=True):
        splits = sorted(set(group["split"]), key=lambda v: SPLITS.index(v) if v in SPLITS else len(SPLITS))
        if len(splits) < 2 or split_rule(dataset, rules) in ("slices", "by_name"):
            continue
        examples = [group.loc[group["split"] == sp, "pair_id"].iloc[0] for sp in splits]
        problems.add(
            "split_classes",
            f"class {dataset}/{shape_class} in splits {'+'.join(splits)}",
            sorted(set(group["pair_id"])),
            ", ".join(f"{sp}: {e}" for sp, e in zip(splits, examples)),
        )
    centaurs = rows[(rows["category"] == "centaur") & (rows["split"] != "train")]
    problems.add("centaur", "centaur shape outside train", sorted(set(centaurs["pair_id"])))


def check_order(table, problems: list[str]) -> None:
    """``table``: rows in store order (:func:`becos.products.store.store_order_key`)."""
    from becos.products.store import store_order_key

    keys = [store_order_key(split, pid) for split, pid in zip(table["split"], table["pair_id"])]
    late = [i for i in range(1, len(keys)) if keys[i] < keys[i - 1]]
    if late:
        i = late[0]
        problems.append(
            f"table: {len(late)} row(s) out of store order (split train, val, test, then pair_id), "
            f"first at row {i}: {table['pair_id'][i]} ({table['split'][i]}) after "
            f"{table['pair_id'][i - 1]} ({table['split'][i - 1]})"
        )


def check_metadata(bench, problems: list[str]) -> None:
    """Root attributes (``metadata``)."""
    meta, n, table = bench.metadata, len(bench), bench.table
    if meta.get("schema_version") != SCHEMA_VERSION:
        problems.append(f"metadata: schema_version {meta.get('schema_version')}, expected {SCHEMA_VERSION}")
    if bench.setting not in SETTINGS:
        problems.append(f"metadata: setting {bench.setting!r} is not one of {SETTINGS}")
    if meta.get("n_pairs", n) != n:
        problems.append(f"metadata: n_pairs says {meta.get('n_pairs')} but the table has {n} rows")
    splits = {str(k): int(v) for k, v in table["split"].value_counts().items()}
    if "splits" in meta and meta["splits"] != splits:
        problems.append(f"metadata: splits says {meta['splits']} but the table has {splits}")
    versions = meta.get("versions")
    if not isinstance(versions, dict) or not {"python", "numpy", "zarr"} <= set(versions):
        problems.append(
            f"metadata: versions is {versions!r}, not a {{package: version}} mapping with at least "
            "python, numpy and zarr (the store does not say which libraries built it)"
        )


ARRAY_COLUMNS = ("index", "x_n_vertices", "y_n_vertices", "x_overlap", "y_overlap")
"""Store table columns that follow from the arrays (checked against them), not from a pair's meta."""


def check_metas(block, setting: str, table, found: Problems) -> None:
    from becos.products.store import TABLE_COLUMNS, table_row

    rows = table.iloc[block.start : block.stop]
    ids = rows["pair_id"].to_numpy().astype(str)
    metas = block.metas
    bad = np.array([m.get("setting", setting) != setting for m in metas])
    found.add("meta", f"meta setting differs from the store's ({setting})", ids[bad])
    bad = np.array([m.get("split") not in SPLITS for m in metas])
    found.add("meta", "meta split is not train/val/test", ids[bad])
    bad = np.array([m.get("schema_version", SCHEMA_VERSION) != SCHEMA_VERSION for m in metas])
    found.add("meta", f"meta schema_version is not {SCHEMA_VERSION}", ids[bad])
    expected, unreadable = [], np.zeros(len(metas), dtype=bool)
    for i, m in enumerate(metas):
        try:
            expected.append(table_row(block.start + i, {"pair_id": None, **m}, 0, 0, 0.0, 0.0))
        except (TypeError, ValueError, AttributeError):
            unreadable[i] = True
            expected.append([None] * len(TABLE_COLUMNS))
    found.add("meta", "meta seed/n_tries not integers or x/y not objects", ids[unreadable])
    for j, column in enumerate(TABLE_COLUMNS):
        if column in ARRAY_COLUMNS:
            continue
        want = [row[j] for row in expected]
        have = rows[column].tolist()
        bad = np.array([w != h for w, h in zip(want, have)]) & ~unreadable
        found.add("table", f"table {column} differs from the pair meta", ids[bad])
    for s in ("x", "y"):
        group = f"{s}_vertex"
        if group in block.offsets:
            found.add(
                "table",
                f"table {s}_n_vertices differs from the arrays",
                ids[block.counts(group) != rows[f"{s}_n_vertices"].to_numpy()],
            )
        if f"{s}_overlap" in block.arrays and block.arrays[f"{s}_overlap"].shape == (len(block),):
            stored = block.arrays[f"{s}_overlap"]
            found.add(
                "table",
                f"table {s}_overlap differs from the arrays",
                ids[~(np.abs(stored - rows[f"{s}_overlap"].to_numpy()) <= 1e-12)],
            )


def check_pair_ids(ids: np.ndarray, found: Problems) -> None:
    """``pair_id``: every id once (``ids``: (N,) str, the table's pair ids)."""
    values, counts = np.unique(ids, return_counts=True)
    dup = values[counts > 1]
    if len(dup):
        found.add("pair_id", "duplicate pair id", dup, f"{int(counts[counts > 1].sum())} rows share {len(dup)} id(s)")
