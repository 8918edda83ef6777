"""The benchmark store: one Zarr (format 3) store per setting holding every pair record of that setting.

Modules: :mod:`becos.store.layout` (what writer and reader share: format, order, table columns,
offsets groups), :mod:`becos.store.npz` (the pair record .npz files and their index files),
:mod:`becos.store.write` (:func:`write_store`), :mod:`becos.store.read` (:func:`open_benchmark`,
:class:`Benchmark`, :class:`TrainingView`), :mod:`becos.store.geodesics` (:class:`GeodesicView`: geodesic
distances of the pairs on demand); every name is importable from ``becos.store``.

Layout (one global table of pairs in *store order*: split train, val, test, then other splits
alphabetically; inside a split by ``pair_id``; row ``i`` of every array below is pair ``i``)::

    <store>/zarr.json               root group; attributes = metadata (see below)
    <store>/arrays/<key>            one array per record key (``x_vertices``, ``corr_01`` ...):
                                    "ragged" keys are the pairs' arrays concatenated along axis 0,
                                    "stacked" keys (scalars, (3,), (3, 3)) are stacked as (N, ...)
    <store>/offsets/<group>         int64 (N + 1,): rows of pair i of every ragged key of the group
                                    are ``offsets[i]:offsets[i + 1]``
    <store>/pairs/meta_json         uint8: every pair's ``meta`` as UTF-8 JSON, concatenated
    <store>/pairs/meta_offsets      int64 (N + 1,): byte ranges of ``meta_json``
    <store>/pairs/table_json        uint8: the pairs table (``Benchmark.table``) as UTF-8 JSON
                                    ``{"columns": [...], "rows": [[...], ...]}``

Offset groups (per side ``s`` in x, y; ``o`` the other side, ``corr_so`` = ``corr_01`` for x):

=====================  ======================================================================
``s_vertex``           s_vertices, s_partial_to_full, s_overlap_mask, s_annotation, corr_so,
                       corr_so_face, corr_so_weights  (V_s rows)
``s_face``             s_faces, s_full_face_ids  (F_s rows)
``s_full_vertex``      s_full_vertices  (V_full rows, 0 for a full shape)
``s_full_to_partial``  s_full_to_partial  (V_full rows, also for a full shape)
``s_full_face``        s_full_faces  (F_full rows, 0 for a full shape)
=====================  ======================================================================

A key whose lengths disagree with its group's gets an offsets array of its own (named after the
key); keys outside the schema are stored as well (stacked when every pair has the same shape,
else ragged with their own offsets), so any :class:`~becos.record.PairRecord` round-trips exactly:
same keys, dtypes, shapes and values (NaN included) and the same ``meta``. The layout actually
used is recorded in the root attribute ``becos_store.layout`` (key -> group, or null = stacked).

Files: arrays are sharded (``SHARD_BYTES`` per shard file, inner chunks of ``CHUNK_BYTES`` for
ragged keys and ``STACKED_CHUNK_BYTES`` for per-pair keys, Blosc LZ4HC with byte shuffle, chunk files
named ``c.<i>.<j>``), so a store holds about two files per array (``zarr.json`` + one shard) until an
array outgrows a shard, instead of one file per pair and key. Index keys are stored int32
(:attr:`becos.record.Field.stored`) and widened back on read (store format 2; format 1 held them
int64 in 1 MiB chunks).

Reading: :meth:`Benchmark.record`, :meth:`Benchmark.records` and :class:`TrainingView` read the chunk
files directly (:class:`_ChunkFiles`: per key one ``pread`` and one Blosc decode per 64 KiB chunk
touched), about as fast as ``np.load`` of the pair's own .npz (``benchmarks/store.py``);
:meth:`Benchmark.read_block` (``becos validate``, ``compare``) reads through zarr.

Root attributes (``Benchmark.metadata``): the caller's metadata (``config_hash``, ``config``,
``datasets`` with licence and citation ...) plus ``schema_version`` (:data:`becos.record.SCHEMA_VERSION`),
``setting``, ``n_pairs``, ``splits`` (pairs per split), ``created`` (ISO 8601, UTC) and
``versions`` (python, becos, numpy, zarr, trimesh, pymeshlab, embreex, snakemake where installed);
``becos_store`` holds the store format, the layout and ``sha256``: the digest of every array's and
offsets array's content (:class:`ContentDigests`), taken from the data as it was written, so that
``becos validate`` notices a chunk file deleted (Zarr reads it back as zeros), truncated or edited
after the store was written.

Writing (:func:`write_store`) streams: one pass over the .npz headers and metas (shapes, dtypes,
order), then one pass over the records, buffering at most one shard per array, into a hidden
temporary folder beside ``out`` that replaces ``out`` when complete. Command line::

    becos export-zarr --setting partial_partial --out results/partial_partial/benchmark.zarr \\
        [--metadata metadata.json] results/partial_partial/pairs/chunk_*.json

``--out`` may be new, an empty folder or a becos store (replaced: the workflow rewrites its stores);
any other folder is refused unless ``--force`` is given, and never replaced while an input (a
record, an index file, the metadata file) lies inside it (:func:`check_out_folder`).
"""

from __future__ import annotations

from becos.store.geodesics import GeodesicView
from becos.store.layout import (
    CHUNK_KEYS,
    SCHEMA_GROUPS,
    SPLIT_ORDER,
    STORE_FORMAT,
    TABLE_COLUMNS,
    TABLE_DTYPES,
    store_order_key,
)
from becos.store.npz import (
    expand_inputs,
    index_setting,
    read_record_index,
)
from becos.store.read import (
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
from becos.store.write import (
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
