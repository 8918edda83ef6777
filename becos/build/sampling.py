"""Pair manifests: which shape pairs a benchmark contains, per setting, chosen so that growth is local.

:func:`sample_pairs` turns the catalog (:mod:`becos.sources.catalog`) into a manifest, one row per matching
instance: ``pair_id, setting, split, category, copy, x_dataset, x_name, y_dataset, y_name, seed,
x_variant, y_variant, chunk``, sorted by split (train, val, test) then ``pair_id``. Every draw is a keyed
hash of what it is for (no global random stream, no dependence on row order), so adding shapes changes
few existing pairs; :func:`assign_chunks` groups pairs into chunk jobs that only split as they grow.
Skipped pairs are counted in ``manifest.attrs['report']``. Anchors, partner choice, pools, centaurs,
per-copy fields, caps and chunks in detail: docs/design/sampling.md.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd

from becos.errors import BecosError, ConfigError
from becos.seeding import stable_hash
from becos.settings import SETTINGS, SPLITS
from becos.sources.catalog import atomic_write_text, sort_catalog

POOL_ORDER = ("human", "four-legged")
JOINER = "centaur"
COMBINATIONS: dict[str, tuple[tuple[str, ...], bool]] = {
    "human": (("human",), False),
    "four-legged": (("four-legged",), False),
    "human_centaur": (("human",), True),
    "four-legged_centaur": (("four-legged",), True),
    "all": (("human", "four-legged"), True),
}
"""combination -> (category pools, centaurs join)."""

MANIFEST_COLUMNS = (
    "pair_id",
    "setting",
    "split",
    "category",
    "copy",
    "x_dataset",
    "x_name",
    "y_dataset",
    "y_name",
    "seed",
    "x_variant",
    "y_variant",
    "chunk",
)
MANIFEST_STRINGS = ("pair_id", "setting", "split", "category", "x_dataset", "x_name", "y_dataset", "y_name")
MANIFEST_INTS = ("copy", "seed", "x_variant", "y_variant", "chunk")
N_BUCKETS = 4096
"""Fixed hash buckets of pair ids (``stable_hash(pair_id) % N_BUCKETS``); chunk jobs are contiguous
bucket ranges, so at most this many chunk jobs (the schema's maximum ``n_chunks``)."""
UNDEFINED = "undefined"

_U64 = np.uint64
_MAX = np.iinfo(np.uint64).max
_BLOCK = 1 << 22  # score-matrix entries per block (32 MB of uint64)


# --------------------------------------------------------------------------------------------
# hashing


def _mix64(x: np.ndarray) -> np.ndarray:
    """SplitMix64 finaliser on a uint64 array (wrapping arithmetic; a bijection of 64-bit words)."""
    x = x ^ (x >> _U64(30))
    x = x * _U64(0xBF58476D1CE4E5B9)
    x = x ^ (x >> _U64(27))
    x = x * _U64(0x94D049BB133111EB)
    return x ^ (x >> _U64(31))


def shape_key(dataset: str, name: str) -> str:
    """The key of a shape in hashes and ids: ``dataset/name``."""
    return f"{dataset}/{name}"


def _anchor_keys(seed: int, setting: str, anchors: list[str], copies: list[int]) -> np.ndarray:
    return np.array([stable_hash(seed, setting, a, c) for a, c in zip(anchors, copies)], dtype=np.uint64)


def _candidate_keys(candidates: list[str]) -> np.ndarray:
    with np.errstate(over="ignore"):
        return _mix64(np.array([stable_hash("candidate", t) for t in candidates], dtype=np.uint64))


def partner_score(seed: int, setting: str, anchor: str, copy: int, candidate: str) -> int:
    """The rendezvous score of ``candidate`` for ``anchor``'s copy (keys as :func:`shape_key`).

    Scalar form of the score matrix used by :func:`sample_pairs` (the partner is the argmin).
    """
    a = _anchor_keys(seed, setting, [anchor], [copy])
    t = _candidate_keys([candidate])
    with np.errstate(over="ignore"):
        return int(_mix64(a ^ t)[0])


def _argmin_partners(row_keys: np.ndarray, col_keys: np.ndarray, allowed) -> np.ndarray:
    """For each row the column of smallest score among allowed ones (-1 if none), in blocks.

    ``allowed(lo, hi)`` returns the (hi - lo, n_cols) boolean mask of allowed candidates.
    """
    n_rows, n_cols = len(row_keys), len(col_keys)
    out = np.full(n_rows, -1, dtype=np.int64)
    if n_cols == 0:
        return out
    step = max(1, _BLOCK // n_cols)
    with np.errstate(over="ignore"):
        for lo in range(0, n_rows, step):
            hi = min(n_rows, lo + step)
            score = _mix64(row_keys[lo:hi, None] ^ col_keys[None, :])
            ok = allowed(lo, hi)
            score[~ok] = _MAX
            best = np.argmin(score, axis=1)
            has = ok[np.arange(hi - lo), best]
            out[lo:hi] = np.where(has, best, -1)
    return out


def pair_id_of(setting: str, x: str, y: str, copy: int) -> str:
    """``pair_id``: 16 hex digits of ``stable_hash(setting, x, y, copy)`` (``x``, ``y`` shape keys)."""
    return f"{stable_hash(setting, x, y, int(copy)):016x}"


# --------------------------------------------------------------------------------------------
# anchors and partners


def n_copies(usage: int, usage_scale: float = 1.0) -> int:
    """Train anchors per shape: ``floor(usage * usage_scale + 0.5)`` (half rounds up)."""
    return int(math.floor(usage * usage_scale + 0.5))


def find_template_row(template_rows, key: str):
    """The template row for ``key`` from a mapping or an object with ``template_row(key)``; None if absent."""
    if template_rows is None:
        return None
    if isinstance(template_rows, Mapping):
        return template_rows.get(key)
    try:
        return template_rows.template_row(key)
    except (LookupError, BecosError):
        return None


def row_field(row, name: str) -> str:
    value = row[name] if isinstance(row, Mapping) else getattr(row, name)
    return str(value).strip()


class _Rows:
    """Accumulates pair copies (anchor key, copy, x, y, split, category)."""

    def __init__(self):
        self.x: list[str] = []
        self.y: list[str] = []
        self.copy: list[int] = []
        self.split: list[str] = []
        self.category: list[str] = []
        self.anchor: list[str] = []

    def add(self, x, y, copy, split, category, anchor):
        self.x.append(x)
        self.y.append(y)
        self.copy.append(copy)
        self.split.append(split)
        self.category.append(category)
        self.anchor.append(anchor)


def _pool_pairs(
    cat: pd.DataFrame,
    *,
    seed: int,
    setting: str,
    pools: tuple[str, ...],
    centaurs: bool,
    usage_scale: float,
    rows: _Rows,
    skipped: Counter,
) -> None:
    """F2F / P2P pairs: rendezvous partners inside each (split, pool)."""
    keys = cat["key"].tolist()
    names = cat["name"].to_numpy(dtype=object)
    for split in SPLITS:
        in_split = cat["split"].to_numpy() == split
        joiners = np.flatnonzero(in_split & (cat["category"].to_numpy() == JOINER)) if centaurs else np.array([], int)
        if centaurs and split != "train":
            if len(joiners):
                skipped["centaur_not_train"] += len(joiners)
            joiners = np.array([], dtype=int)
        for p, pool in enumerate(pools):
            members = np.flatnonzero(in_split & (cat["category"].to_numpy() == pool))
            cols = np.concatenate([members, joiners]).astype(int)
            # anchor copies: members first, then joiners' copies assigned to this pool
            a_idx, a_copy = [], []
            for i in members:
                n = n_copies(int(cat["usage"].iat[i]), usage_scale) if split == "train" else 1
                a_idx.extend([i] * n)
                a_copy.extend(range(n))
            for i in joiners:
                n = n_copies(int(cat["usage"].iat[i]), usage_scale)
                cs = [c for c in range(n) if c % len(pools) == p]
                a_idx.extend([i] * len(cs))
                a_copy.extend(cs)
            if not a_idx:
                continue
            a_idx = np.asarray(a_idx, dtype=int)
            is_joiner_row = np.isin(a_idx, joiners)
            is_joiner_col = np.isin(cols, joiners)
            row_names, col_names = names[a_idx], names[cols]
            row_keys = _anchor_keys(seed, setting, [keys[i] for i in a_idx], a_copy)
            col_keys = _candidate_keys([keys[j] for j in cols])

            def allowed(lo, hi):  # called at once, inside this iteration: the loop variables are this pool's
                ok = row_names[lo:hi, None] != col_names[None, :]  # noqa: B023
                return ok & (is_joiner_row[lo:hi, None] | ~is_joiner_col[None, :])  # noqa: B023

            best = _argmin_partners(row_keys, col_keys, allowed)
            for r, b in enumerate(best):
                if b < 0:
                    skipped[f"no_partner_in_pool:{split}/{pool}"] += 1
                    continue
                x, y = keys[a_idx[r]], keys[cols[b]]
                rows.add(x, y, a_copy[r], split, pool, x)


def _p2f_pairs(
    cat: pd.DataFrame, *, categories: set[str], template_rows, usage_scale: float, rows: _Rows, skipped: Counter
) -> None:
    """P2F pairs: each Y anchors its copies with X = its full template."""
    if template_rows is None:
        raise ConfigError(
            "setting partial_full needs template_rows (the template table: templates_all.csv "
            "or templates_tosca_demo.csv for TOSCA alone)"
        )
    datasets = set(cat["dataset"])
    present = set(cat["key"])
    for i in range(len(cat)):
        category, split = cat["category"].iat[i], cat["split"].iat[i]
        if category not in categories or split not in SPLITS:
            continue
        n = n_copies(int(cat["usage"].iat[i]), usage_scale) if split == "train" else 1
        if n == 0:
            continue
        if category == JOINER and split != "train":
            skipped["centaur_not_train"] += n
            continue
        row = find_template_row(template_rows, cat["template_key"].iat[i])
        if row is None:
            skipped[f"no_template_row:{cat['template_key'].iat[i]}"] += n
            continue
        t_name, t_ds = row_field(row, "partial_full_template"), row_field(row, "partial_full_dataset")
        if UNDEFINED in (t_name, t_ds) or not t_name or t_name == "-":
            skipped["p2f_template_undefined"] += n
            continue
        if t_ds not in datasets:
            skipped[f"p2f_template_dataset_unavailable:{t_ds}"] += n
            continue
        x = shape_key(t_ds, t_name)
        if x not in present:
            skipped[f"p2f_template_shape_missing:{x}"] += n
            continue
        if t_name == cat["name"].iat[i]:
            skipped["p2f_own_template"] += n
            continue
        y = cat["key"].iat[i]
        for c in range(n):
            rows.add(x, y, c, split, category, y)


# --------------------------------------------------------------------------------------------
# public API


def sample_pairs(
    catalog: pd.DataFrame,
    setting: str,
    *,
    seed: int,
    combinations: str = "all",
    template_rows=None,
    n_variants: int = 4,
    n_chunks: int | None = None,
    pairs_per_chunk: int | None = None,
    min_chunks: int | None = None,
    caps: dict | None = None,
    usage_scale: float = 1.0,
) -> pd.DataFrame:
    """The pair manifest of ``setting`` for the shapes of ``catalog`` (rules in the module doc).

    Args:
        catalog: catalog table (:func:`becos.sources.catalog.catalog_table` / ``read_catalog``); row order
            does not matter.
        setting: ``full_full``, ``partial_full`` or ``partial_partial``.
        seed: global seed.
        combinations: ``human``, ``four-legged``, ``human_centaur``, ``four-legged_centaur``, ``all``.
        template_rows: for ``partial_full``: ``{template_key: row}`` with ``row`` a ``TemplateRow``
            (attributes) or a dict with ``partial_full_template`` / ``partial_full_dataset``, or an
            object with ``template_row(key)`` (``becos.sources.annotations.AnnotationSource``).
        n_variants: remesh variants per shape (K); ``x_variant``/``y_variant`` lie in ``[0, K)``.
        n_chunks, pairs_per_chunk, min_chunks: the most chunk jobs, the fewest pairs per chunk job, the
            fewest chunk jobs (:func:`chunk_jobs`; None: the config keys' defaults, :mod:`becos.defaults`).
        caps: optional ``{split: max pairs}``.
        usage_scale: multiplies every dataset's usage count (0.5 ≈ the published pair counts).

    Returns:
        The manifest (columns :data:`MANIFEST_COLUMNS`), sorted by split then ``pair_id``, with
        ``attrs['report']`` (skipped pair copies by reason, pairs per split).
    """
    if setting not in SETTINGS:
        raise ConfigError(f"setting must be one of {SETTINGS}, got {setting!r}")
    if combinations not in COMBINATIONS:
        raise ConfigError(f"combinations must be one of {sorted(COMBINATIONS)}, got {combinations!r}")
    n_chunks, pairs_per_chunk, min_chunks = _chunk_options(n_chunks, pairs_per_chunk, min_chunks)
    if n_variants < 1:
        raise ConfigError(f"n_variants must be >= 1, got {n_variants}")
    if usage_scale < 0:
        raise ConfigError(f"usage_scale must be >= 0, got {usage_scale}")
    pools, centaurs = COMBINATIONS[combinations]
    cat = sort_catalog(
        catalog[["dataset", "name", "category", "split", "template_key", "usage"]].astype(
            {"dataset": str, "name": str, "category": str, "split": str, "template_key": str}
        )
    )
    cat["key"] = [shape_key(d, n) for d, n in zip(cat["dataset"], cat["name"])]
    if cat["key"].duplicated().any():
        raise ConfigError(f"catalog has duplicate shapes: {cat.loc[cat['key'].duplicated(), 'key'].tolist()[:5]}")

    rows, skipped = _Rows(), Counter()
    if setting == "partial_full":
        categories = set(pools) | ({JOINER} if centaurs else set())
        _p2f_pairs(
            cat, categories=categories, template_rows=template_rows, usage_scale=usage_scale, rows=rows, skipped=skipped
        )
    else:
        _pool_pairs(
            cat,
            seed=seed,
            setting=setting,
            pools=pools,
            centaurs=centaurs,
            usage_scale=usage_scale,
            rows=rows,
            skipped=skipped,
        )

    df = _finish(rows, setting=setting, seed=seed, n_variants=n_variants, caps=caps, skipped=skipped)
    df["chunk"] = assign_chunks(
        df["pair_id"], n_chunks=n_chunks, pairs_per_chunk=pairs_per_chunk, min_chunks=min_chunks
    )
    df.attrs["report"]["excluded_shapes"] = int((cat["split"] == "excluded").sum())
    return df


def _finish(rows: _Rows, *, setting, seed, n_variants, caps, skipped: Counter) -> pd.DataFrame:
    """Ids, seeds, variants; caps; stable order (chunks: :func:`assign_chunks`, once the pairs are known)."""
    n = len(rows.x)
    pair_ids = [pair_id_of(setting, x, y, c) for x, y, c in zip(rows.x, rows.y, rows.copy)]
    if len(set(pair_ids)) != n:  # (x, y, copy) is unique by construction; a 64-bit collision is not
        raise BecosError("pair_id collision (64-bit hash); change the setting name or report this")
    seeds = [stable_hash(seed, pid, bits=63) for pid in pair_ids]
    split_x = lambda s: s.split("/", 1)  # noqa: E731  (dataset names contain no '/')
    xs, ys = [split_x(k) for k in rows.x], [split_x(k) for k in rows.y]
    df = pd.DataFrame(
        {
            "pair_id": pair_ids,
            "setting": [setting] * n,
            "split": rows.split,
            "category": rows.category,
            "copy": np.asarray(rows.copy, dtype=np.int64),
            "x_dataset": [d for d, _ in xs],
            "x_name": [m for _, m in xs],
            "y_dataset": [d for d, _ in ys],
            "y_name": [m for _, m in ys],
            "seed": np.asarray(seeds, dtype=np.int64),
            "x_variant": np.asarray([stable_hash(s, "x_variant") % n_variants for s in seeds], dtype=np.int64),
            "y_variant": np.asarray([stable_hash(s, "y_variant") % n_variants for s in seeds], dtype=np.int64),
            "chunk": np.zeros(n, dtype=np.int64),
        },
        columns=list(MANIFEST_COLUMNS),
    )
    if caps:
        rank = np.array([stable_hash(seed, setting, "cap", a, c) for a, c in zip(rows.anchor, rows.copy)], dtype=object)
        keep = np.ones(n, dtype=bool)
        for split, cap in caps.items():
            if split not in SPLITS:
                raise ConfigError(f"caps: unknown split {split!r}; expected {SPLITS}")
            idx = np.flatnonzero(df["split"].to_numpy() == split)
            if cap is not None and len(idx) > int(cap):
                order = sorted(idx, key=lambda i: rank[i])
                keep[order[int(cap) :]] = False
                skipped[f"cap:{split}"] += len(idx) - int(cap)
        df = df[keep]
    df = sort_manifest(df)
    df.attrs["report"] = {
        "skipped": dict(sorted(skipped.items())),
        "n_pairs": {s: int((df["split"] == s).sum()) for s in SPLITS},
    }
    return df


def _chunk_options(n_chunks: int | None, pairs_per_chunk: int | None, min_chunks: int | None) -> tuple[int, int, int]:
    """``n_chunks``, ``pairs_per_chunk`` and ``min_chunks``, the config's defaults for None (:mod:`becos.defaults`);
    raises ConfigError for a value out of range."""
    from becos.defaults import config_default

    given = {"n_chunks": n_chunks, "pairs_per_chunk": pairs_per_chunk, "min_chunks": min_chunks}
    n_chunks, pairs_per_chunk, min_chunks = (config_default(k) if v is None else v for k, v in given.items())
    if not 1 <= n_chunks <= N_BUCKETS or pairs_per_chunk < 1 or min_chunks < 1:
        raise ConfigError(
            f"n_chunks, pairs_per_chunk and min_chunks must be >= 1 (n_chunks <= {N_BUCKETS}), "
            f"got {n_chunks}, {pairs_per_chunk}, {min_chunks}"
        )
    return n_chunks, pairs_per_chunk, min_chunks


MIN_CHUNK_PAIRS = 64
"""The fewest pairs per chunk job that ``min_chunks`` splits a run into (:func:`chunk_jobs`). Measured on
TOSCA F2F with 2 cores, remeshing done: 150 pairs as 2 jobs per stage 28.6-29.5 s, as 1 job 34.1-34.9 s;
450 pairs as 2 jobs 45.0 s, as 1 job 58.5 s (docs/measurements.md)."""


def chunk_jobs(n_pairs: int, n_chunks: int, pairs_per_chunk: int, min_chunks: int = 1) -> int:
    """Chunk jobs per stage for ``n_pairs`` pairs: the largest power of two ``J`` with
    ``J * pairs_per_chunk <= n_pairs`` (so ``pairs_per_chunk`` to twice as many pairs per job), at
    least 1 and at most ``n_chunks``. Powers of two change rarely as a benchmark grows, and a doubling
    splits each job's bucket range in two.

    ``min_chunks`` raises ``J`` to the largest power of two up to ``min_chunks`` that leaves each job
    :data:`MIN_CHUNK_PAIRS` pairs: a run too small for two jobs of ``pairs_per_chunk`` still uses that
    many cores in its chunk stages."""
    jobs = _power_of_two_floor(n_pairs // max(1, pairs_per_chunk))
    least = _power_of_two_floor(min(min_chunks, n_pairs // MIN_CHUNK_PAIRS))
    return max(1, min(max(jobs, least), n_chunks, N_BUCKETS))


def _power_of_two_floor(n: int) -> int:
    """The largest power of two up to ``n`` (1 for ``n`` < 2)."""
    return 1 << max(0, n.bit_length() - 1)


def assign_chunks(pair_ids, *, n_chunks: int, pairs_per_chunk: int, min_chunks: int = 1) -> np.ndarray:
    """``(N,) int64``: the chunk job of each pair id, ``bucket * J // N_BUCKETS`` with ``J``
    :func:`chunk_jobs` of the ``N`` pairs and ``bucket = stable_hash(pair_id) % N_BUCKETS``."""
    pair_ids = list(pair_ids)
    jobs = chunk_jobs(len(pair_ids), n_chunks, pairs_per_chunk, min_chunks)
    buckets = np.fromiter((stable_hash(p) % N_BUCKETS for p in pair_ids), dtype=np.int64, count=len(pair_ids))
    return buckets * jobs // N_BUCKETS


def sort_manifest(df: pd.DataFrame) -> pd.DataFrame:
    """Manifest rows in the stable order: split (train, val, test, then others by name), pair_id."""
    rank = {s: i for i, s in enumerate(SPLITS)}
    keys = [(rank.get(s, len(rank)), s, p) for s, p in zip(df["split"].astype(str), df["pair_id"].astype(str))]
    order = sorted(range(len(keys)), key=keys.__getitem__)
    return df.iloc[order].reset_index(drop=True)


def write_manifest(df: pd.DataFrame, path: str | Path) -> None:
    """Write a manifest as CSV, atomically; identical input gives a byte-identical file.

    The manifest columns come first in their fixed order, extra columns (e.g. of an imported
    published list) follow in the order given.
    """
    missing = [c for c in MANIFEST_COLUMNS if c not in df.columns]
    if missing:
        raise ValueError(f"manifest lacks columns {missing}")
    cols = list(MANIFEST_COLUMNS) + [c for c in df.columns if c not in MANIFEST_COLUMNS]
    out = sort_manifest(df[cols])
    atomic_write_text(path, out.to_csv(index=False, lineterminator="\n"))


def read_manifest(path: str | Path) -> pd.DataFrame:
    """Read a manifest CSV (ids and names stay strings; ints stay int64)."""
    dtypes = {c: str for c in MANIFEST_STRINGS}
    dtypes.update({c: np.int64 for c in MANIFEST_INTS})
    df = pd.read_csv(path, dtype=dtypes, keep_default_na=False)
    for c in df.columns:  # extra columns: numeric where they parse, else strings
        if c not in dtypes and df[c].dtype == object:
            df[c] = df[c].astype(str)
    return df


def appearance_counts(manifest: pd.DataFrame) -> pd.DataFrame:
    """Per shape and split: appearances as X, as Y and in total (``dataset, name, split, as_x, as_y, total``)."""
    x = manifest.groupby(["x_dataset", "x_name", "split"]).size().rename("as_x")
    y = manifest.groupby(["y_dataset", "y_name", "split"]).size().rename("as_y")
    x.index.names = y.index.names = ["dataset", "name", "split"]
    out = pd.concat([x, y], axis=1).fillna(0).astype(np.int64).reset_index()
    out["total"] = out["as_x"] + out["as_y"]
    return out.sort_values(["dataset", "split", "name"]).reset_index(drop=True)


def appearance_summary(manifest: pd.DataFrame, catalog: pd.DataFrame) -> pd.DataFrame:
    """Train appearances per dataset: usage, X count range, total appearances (min, median, mean, max).

    Shapes of the catalog that never appear count as 0.
    """
    counts = appearance_counts(manifest[manifest["split"] == "train"])
    train = catalog[catalog["split"] == "train"][["dataset", "name", "usage"]]
    merged = train.merge(counts.drop(columns="split"), on=["dataset", "name"], how="left").fillna(0)
    g = merged.groupby("dataset")
    return pd.DataFrame(
        {
            "usage": g["usage"].first(),
            "shapes": g.size(),
            "as_x_min": g["as_x"].min().astype(int),
            "as_x_max": g["as_x"].max().astype(int),
            "total_min": g["total"].min().astype(int),
            "total_median": g["total"].median(),
            "total_mean": g["total"].mean(),
            "total_max": g["total"].max().astype(int),
        }
    ).reset_index()
