"""The benchmark store: one Zarr (format 3) store per setting holding every pair record of that setting.

Row ``i`` of every array is pair ``i`` in store order (split train, val, test, then others; by
``pair_id`` inside a split): ``arrays/<key>`` per record key (ragged keys concatenated along axis 0 with
``offsets/<group>`` (N + 1,) row ranges; per-pair keys stacked (N, ...)), ``pairs/`` the metas and the
pairs table; root attributes are the metadata. Any :class:`~becos.build.record.PairRecord` round-trips
exactly. Modules: ``layout``, ``npz``, ``chunk_files``, ``write`` (:func:`write_store`), ``read``
(:func:`open_benchmark`, :class:`TrainingView`), ``geodesics`` (:class:`GeodesicView`); every name
importable from here. The layout, offset groups, files and metadata in detail: docs/design/store.md.
"""

from __future__ import annotations

from becos.products.store.geodesics import GeodesicView
from becos.products.store.layout import (
    CHUNK_KEYS,
    SCHEMA_GROUPS,
    SPLIT_ORDER,
    STORE_FORMAT,
    TABLE_COLUMNS,
    TABLE_DTYPES,
    store_order_key,
)
from becos.products.store.npz import (
    expand_inputs,
    index_setting,
    read_record_index,
)
from becos.products.store.read import (
    DAMAGED_STORE_FIX,
    READ_BLOCK_BYTES,
    Benchmark,
    Block,
    DamagedStoreError,
    PairKeyError,
    TrainingView,
    count_files,
    open_benchmark,
)
from becos.products.store.write import (
    CHUNK_BYTES,
    SHARD_BYTES,
    STACKED_CHUNK_BYTES,
    VERSION_PACKAGES,
    ContentDigests,
    check_out_folder,
    disk_dtype,
    is_becos_store,
    table_row,
    write_pairs,
    write_store,
)

__all__ = [
    "Benchmark",
    "Block",
    "CHUNK_BYTES",
    "CHUNK_KEYS",
    "ContentDigests",
    "DAMAGED_STORE_FIX",
    "DamagedStoreError",
    "GeodesicView",
    "PairKeyError",
    "READ_BLOCK_BYTES",
    "SCHEMA_GROUPS",
    "SHARD_BYTES",
    "SPLIT_ORDER",
    "STACKED_CHUNK_BYTES",
    "STORE_FORMAT",
    "TABLE_COLUMNS",
    "TABLE_DTYPES",
    "TrainingView",
    "VERSION_PACKAGES",
    "check_out_folder",
    "count_files",
    "disk_dtype",
    "expand_inputs",
    "index_setting",
    "is_becos_store",
    "open_benchmark",
    "read_record_index",
    "store_order_key",
    "table_row",
    "write_pairs",
    "write_store",
]
