"""The store's on-disk layout, shared by the writer (:mod:`becos.products.store.write`) and the reader
(:mod:`becos.products.store.read`): format version, split order, chunk file names, the pairs table's columns and
the offsets group of every ragged schema key (see :mod:`becos.products.store` for the layout)."""

from __future__ import annotations

from becos.build.record import RECORD_SCHEMA

STORE_FORMAT = 2
"""2: index keys int32 (:attr:`becos.build.record.Field.stored`), inner chunks of :data:`~becos.products.store.write.CHUNK_BYTES`, LZ4HC
(format 1: int64 indices, 1 MiB chunks, zstd)."""


SPLIT_ORDER = ("train", "val", "test")


CHUNK_KEYS = {"name": "default", "separator": "."}
"""Chunk files named ``c.0.0`` inside each array's folder (no nested folders per dimension)."""


TABLE_COLUMNS = (
    "index",
    "pair_id",
    "split",
    "category",
    "seed",
    "x_dataset",
    "x_name",
    "x_class",
    "x_category",
    "y_dataset",
    "y_name",
    "y_class",
    "y_category",
    "x_n_vertices",
    "y_n_vertices",
    "x_overlap",
    "y_overlap",
    "n_tries",
    "accepted",
)


TABLE_DTYPES = {
    "index": "int64",
    "seed": "int64",
    "x_n_vertices": "int64",
    "y_n_vertices": "int64",
    "x_overlap": "float64",
    "y_overlap": "float64",
    "n_tries": "int64",
    "accepted": "bool",
}


SCHEMA_GROUPS = {key: f.group for key, f in RECORD_SCHEMA.items() if f.group is not None}
"""Record key -> offsets group of the ragged schema keys (:data:`becos.build.record.RECORD_SCHEMA`)."""


def store_order_key(split: str, pair_id: str) -> tuple[int, str, str]:
    """Sort key of store order: split train, val, test, then other splits alphabetically; by pair_id."""
    rank = (SPLIT_ORDER.index(split), "") if split in SPLIT_ORDER else (len(SPLIT_ORDER), str(split))
    return (*rank, str(pair_id))
