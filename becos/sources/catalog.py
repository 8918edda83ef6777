"""The shape catalog: one table row per shape a benchmark may use, written as a stable CSV.

The flat, reviewable form of the dataset listing (:mod:`becos.sources.datasets`): everything the pair sampler
(:mod:`becos.build.sampling`) needs about a shape, nothing geometric. Columns :data:`COLUMNS`: dataset, name,
category, class, split, file, template_key, scale, ``frame_rotation_0-8`` (the (3, 3) frame rotation,
row-major, for row vectors ``V @ R``) and usage. Rows sort by dataset, then a natural sort of the name,
then the raw name, so file-system order never leaks in. Each column's meaning: docs/design/sampling.md.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from becos.atomic import write_text
from becos.settings import SPLITS as BENCHMARK_SPLITS

if TYPE_CHECKING:
    import pandas as pd  # imported where used: a remesh job reads one catalog row and needs no pandas

ROTATION_COLUMNS = tuple(f"frame_rotation_{i}" for i in range(9))
COLUMNS = ("dataset", "name", "category", "class", "split", "file", "template_key", "scale", *ROTATION_COLUMNS, "usage")
STRING_COLUMNS = ("dataset", "name", "category", "class", "split", "file", "template_key")
CATEGORIES = ("human", "four-legged", "centaur")
SPLITS = (*BENCHMARK_SPLITS, "excluded")
"""A catalog row's split: a benchmark split, or ``excluded`` (a shape no pair uses)."""


def natural_key(text: str) -> tuple:
    """Sort key that orders digit runs by value: ``a2 < a10``, ``0001.isometry.4 < 0001.isometry.10``.

    ``re.split`` with a capturing group alternates text (even positions) and digits (odd positions),
    so the key compares like with like at every position; a name that is a prefix of another sorts
    first (SMAL ``cow_alph`` < ``cow_alph5``); the raw text breaks remaining ties (``a01`` vs ``a1``).
    """
    parts = re.split(r"(\d+)", str(text))
    return tuple(int(p) if i % 2 else p.lower() for i, p in enumerate(parts)), str(text)


def sort_catalog(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` in the catalog's stable order (dataset, natural name order), with a fresh index."""
    keys = [(d, natural_key(n)) for d, n in zip(df["dataset"].astype(str), df["name"].astype(str))]
    order = sorted(range(len(keys)), key=keys.__getitem__)
    return df.iloc[order].reset_index(drop=True)


def _entry_row(entry) -> dict:
    """One catalog row from a ``ShapeEntry``-like object (attribute access)."""
    rotation = np.asarray(entry.frame_rotation, dtype=np.float64)
    if rotation.shape != (3, 3):
        raise ValueError(f"{entry.dataset}/{entry.name}: frame_rotation must be (3, 3), got {rotation.shape}")
    row = {
        "dataset": str(entry.dataset),
        "name": str(entry.name),
        "category": str(entry.category),
        "class": str(entry.shape_class),
        "split": str(entry.split),
        "file": str(entry.path),
        "template_key": str(entry.template_key),
        "scale": float(entry.scale),
        "usage": int(entry.usage),
    }
    row.update(zip(ROTATION_COLUMNS, rotation.ravel().tolist()))
    return row


def catalog_table(entries: Iterable) -> pd.DataFrame:
    """The catalog of ``entries`` (``becos.sources.datasets.ShapeEntry`` or any object with its attributes).

    Raises ``ValueError`` on a duplicate ``(dataset, name)``, an unknown category or split.
    """
    import pandas as pd

    rows = [_entry_row(e) for e in entries]
    df = pd.DataFrame(rows, columns=list(COLUMNS))
    _validate(df)
    return sort_catalog(df)


def _validate(df: pd.DataFrame) -> None:
    missing = [c for c in COLUMNS if c not in df.columns]
    if missing:
        raise ValueError(f"catalog lacks columns {missing}")
    dup = df.duplicated(["dataset", "name"])
    if dup.any():
        first = df.loc[dup, ["dataset", "name"]].iloc[0].tolist()
        raise ValueError(f"catalog has duplicate shape {first[0]}/{first[1]}")
    bad = sorted(set(df["category"]) - set(CATEGORIES))
    if bad:
        raise ValueError(f"unknown categories {bad}; expected {CATEGORIES}")
    bad = sorted(set(df["split"]) - set(SPLITS))
    if bad:
        raise ValueError(f"unknown splits {bad}; expected {SPLITS}")


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (see :mod:`becos.atomic`)."""
    write_text(path, text)


def write_catalog(df: pd.DataFrame, path: str | Path) -> None:
    """Write the catalog as CSV (atomic; stable row order; floats in shortest round-trip form)."""
    _validate(df)
    out = sort_catalog(df[list(COLUMNS)])
    atomic_write_text(path, out.to_csv(index=False, lineterminator="\n"))


def read_catalog(path: str | Path) -> pd.DataFrame:
    """Read a catalog CSV written by :func:`write_catalog` (strings stay strings: ``0001`` is not 1)."""
    import pandas as pd

    dtypes = {c: str for c in STRING_COLUMNS}
    dtypes.update({c: np.float64 for c in ("scale", *ROTATION_COLUMNS)})
    dtypes["usage"] = np.int64
    df = pd.read_csv(path, dtype=dtypes, keep_default_na=False)
    _validate(df)
    return sort_catalog(df[list(COLUMNS)])


def frame_rotation(row) -> np.ndarray:
    """The (3, 3) frame rotation of one catalog row (a Series or mapping)."""
    return np.array([row[c] for c in ROTATION_COLUMNS], dtype=np.float64).reshape(3, 3)
