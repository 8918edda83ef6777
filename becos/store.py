"""The benchmark store: one Zarr (format 3) store per setting holding every pair record of that setting.

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
"""

from __future__ import annotations

import ast
import errno
import hashlib
import json
import math
import os
import re
import shutil
import struct
import sys
import tempfile
import time
import zipfile
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from becos.atomic import remove_stale_temporaries
from becos.errors import BecosError, DiskFullError, InputFileError
from becos.record import (
    IDENTITY_MEMBER,
    RECORD_KEYS,
    RECORD_SCHEMA,
    SCHEMA_VERSION,
    SETTINGS,
    PairRecord,
    decode_arrays,
)

STORE_FORMAT = 2
"""2: index keys int32 (:attr:`becos.record.Field.stored`), inner chunks of :data:`CHUNK_BYTES`, LZ4HC
(format 1: int64 indices, 1 MiB chunks, zstd)."""
SPLIT_ORDER = ("train", "val", "test")
CHUNK_BYTES = 64 << 10
"""Uncompressed bytes per inner chunk (the unit a partial read decodes): 64 KiB, so reading one pair
(~2 MB of arrays over ~50 keys) decodes little beyond its own rows."""
STACKED_CHUNK_BYTES = 4 << 10
"""Inner chunk of the per-pair (stacked) keys: one pair's row is 8-72 bytes, so reading a pair
decodes 4 KiB per key, not 64."""
SHARD_BYTES = 4 << 20
"""Uncompressed bytes per shard file (also the most :func:`write_store` buffers per array, so the
writer's memory stays flat as stores grow: ~40 arrays x 4 MiB)."""
CHUNK_KEYS = {"name": "default", "separator": "."}
"""Chunk files named ``c.0.0`` inside each array's folder (no nested folders per dimension)."""
READ_BLOCK_BYTES = 64 << 20
"""Uncompressed bytes read at once by :meth:`Benchmark.blocks` / :meth:`Benchmark.records`."""
VERSION_PACKAGES = ("becos", "numpy", "zarr", "trimesh", "pymeshlab", "embreex", "snakemake")
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
"""Record key -> offsets group of the ragged schema keys (:data:`becos.record.RECORD_SCHEMA`)."""


# --------------------------------------------------------------------------------------------------
# reading record files


@dataclass
class _RecordInfo:
    path: Path
    meta: dict
    shapes: dict[str, tuple[tuple[int, ...], np.dtype]]


_LOCAL_HEADER = struct.Struct("<4sHHHHHIIIHH")
_NPY_HEADER = re.compile(r"""^\{'descr': '([^']+)', 'fortran_order': (True|False), 'shape': \(([0-9, ]*)\), \}\s*$""")


def _npy_header(fh) -> tuple[tuple[int, ...], np.dtype, bool]:
    """(shape, dtype, fortran_order) of the .npy stream at ``fh``'s position; leaves it at the data."""
    version = np.lib.format.read_magic(fh)
    size = struct.unpack("<H" if version == (1, 0) else "<I", fh.read(2 if version == (1, 0) else 4))[0]
    text = fh.read(size).decode("latin1" if version < (3, 0) else "utf-8")
    m = _NPY_HEADER.match(text)
    if m is not None:  # numpy's own layout: parse without ast (10x faster)
        shape = tuple(int(v) for v in m.group(3).replace(" ", "").split(",") if v)
        dtype, fortran = np.dtype(m.group(1)), m.group(2) == "True"
    else:
        header = ast.literal_eval(text)
        shape = tuple(header["shape"])
        dtype, fortran = np.lib.format.descr_to_dtype(header["descr"]), bool(header["fortran_order"])
    if dtype.hasobject:
        raise ValueError("holds Python objects (pickles), which becos never writes")
    return shape, dtype, fortran


def _read_npz(path: Path, load: bool) -> tuple[dict, dict[str, tuple[tuple[int, ...], np.dtype]], dict]:
    """``(meta, {key: (shape, dtype)}, {key: array})`` of a record .npz (arrays only when ``load``), as
    :meth:`PairRecord.load` gives them (:func:`becos.record.decode_arrays`: widened, identity maps derived).

    Uncompressed members (``np.savez``, what :meth:`PairRecord.save` writes) are read straight from
    the file at their offset: no zip CRC pass, one copy; compressed ones through the zip stream.
    """
    shapes, arrays, meta, identity = {}, {}, None, {}
    with open(path, "rb") as fh, zipfile.ZipFile(fh) as z:
        for info in z.infolist():
            if not info.filename.endswith(".npy"):
                continue
            key = info.filename[:-4]
            stored = info.compress_type == zipfile.ZIP_STORED
            if stored:
                fh.seek(info.header_offset)
                local = _LOCAL_HEADER.unpack(fh.read(_LOCAL_HEADER.size))
                if local[0] != b"PK\x03\x04":
                    raise ValueError(f"bad zip member header of {info.filename}")
                fh.seek(info.header_offset + _LOCAL_HEADER.size + local[9] + local[10])
                src = fh
            else:
                src = z.open(info)
            try:
                shape, dtype, fortran = _npy_header(src)
                special = key in ("__meta__", IDENTITY_MEMBER)
                if not special:
                    shapes[key] = (shape, dtype)
                if not special and not load:
                    continue
                count = math.prod(shape)
                if stored:
                    data = np.fromfile(fh, dtype=dtype, count=count)
                else:
                    data = np.frombuffer(src.read(count * dtype.itemsize), dtype=dtype).copy()
                if len(data) != count:
                    raise ValueError(f"member {info.filename} is truncated")
                data = data.reshape(shape, order="F" if fortran else "C")
            finally:
                if not stored:
                    src.close()
            if key == "__meta__":
                meta = json.loads(str(data))
            elif key == IDENTITY_MEMBER:
                identity = json.loads(str(data))
            else:
                arrays[key] = data
    for key, n in identity.items():  # the record's own dtypes and shapes (decode_arrays)
        shapes[key] = ((int(n),), np.dtype(RECORD_SCHEMA[key].dtype))
    for key, (shape, dtype) in shapes.items():
        f = RECORD_SCHEMA.get(key)
        if f is not None and f.stored is not None and dtype == np.dtype(f.stored):
            shapes[key] = (shape, np.dtype(f.dtype))
    return meta, shapes, decode_arrays(arrays, identity) if load else arrays


def _scan_record(path: Path) -> _RecordInfo:
    """Meta and the (shape, dtype) of every array of a record .npz, reading only the .npy headers."""
    fix = "give pair records written by becos (PairRecord.save, the workflow's pairs stage)"
    if not path.is_file():
        raise InputFileError(
            path,
            "pair record not found",
            "check the path (index paths are relative to the current directory) or re-run the pairs stage",
        )
    try:
        meta, shapes, _ = _read_npz(path, load=False)
    except (zipfile.BadZipFile, ValueError, OSError, KeyError, SyntaxError, struct.error, TypeError) as exc:
        raise InputFileError(path, f"is not a readable pair record .npz ({exc})", fix) from exc
    if meta is None:
        raise InputFileError(path, "holds no __meta__ entry, so it is not a pair record", fix)
    missing = [k for k in RECORD_KEYS if k not in shapes]
    if missing:
        raise InputFileError(path, f"lacks the record keys {missing}", fix)
    if not isinstance(meta.get("pair_id"), str) or not meta["pair_id"]:
        raise InputFileError(path, "its meta has no pair_id", fix)
    if meta.get("schema_version", SCHEMA_VERSION) != SCHEMA_VERSION:
        raise InputFileError(
            path,
            f"has record schema version {meta.get('schema_version')}, this becos writes "
            f"stores of version {SCHEMA_VERSION}",
            "rebuild the pair records with this becos",
        )
    return _RecordInfo(path, meta, shapes)


def read_record_index(path: str | Path) -> list[Path]:
    """Record paths listed by an index file.

    Accepted: the workflow's chunk index (JSON ``{"setting", "chunk", "pairs": [{"pair_id", "path"}, ...]}``),
    a JSON list of paths or of such entries, or text with one path per line (blank lines and ``#``
    comments skipped). Relative paths are taken from the current directory, or else from the index
    file's folder when only that exists.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(
            path,
            f"cannot be read as a record index ({exc})",
            "give record .npz files or a chunk index written by `becos pairs`",
        ) from exc
    stripped = text.lstrip()
    if stripped.startswith(("{", "[")):
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputFileError(path, f"is not valid JSON ({exc})", "fix or regenerate the index") from exc
        entries = data.get("pairs") if isinstance(data, dict) else data
        if not isinstance(entries, list):
            raise InputFileError(path, "is JSON without a 'pairs' list", "give a chunk index written by `becos pairs`")
        raw = []
        for entry in entries:
            value = entry.get("path") if isinstance(entry, dict) else entry
            if not isinstance(value, str):
                raise InputFileError(
                    path, f"entry {entry!r} names no record path", "each entry needs a 'path' (or be a path string)"
                )
            raw.append((value, entry.get("digest") if isinstance(entry, dict) else None))
    else:
        raw = [(line.strip(), None) for line in text.splitlines() if line.strip() and not line.strip().startswith("#")]
    out = []
    for value, recorded in raw:
        p = Path(value)
        if not p.is_absolute() and not p.exists() and (path.parent / p).exists():
            p = path.parent / p
        if recorded is not None and p.is_file():
            found = hashlib.sha256(p.read_bytes()).hexdigest()[: len(recorded)]
            if found != recorded:
                raise InputFileError(
                    p,
                    f"is not the file the pairs job wrote: its digest is {found}, {path} "
                    f"records {recorded} (edited or replaced after the job)",
                    "rebuild it: snakemake --forcerun pairs (becos rebuilds every record whose "
                    "content changed), then write the store again",
                )
        out.append(p)
    return out


def index_setting(path: str | Path) -> str | None:
    """The ``setting`` a JSON chunk index declares, else None."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return data.get("setting") if isinstance(data, dict) else None


# --------------------------------------------------------------------------------------------------
# writing


def store_order_key(split: str, pair_id: str) -> tuple[int, str, str]:
    """Sort key of store order: split train, val, test, then other splits alphabetically; by pair_id."""
    rank = (SPLIT_ORDER.index(split), "") if split in SPLIT_ORDER else (len(SPLIT_ORDER), str(split))
    return (*rank, str(pair_id))


def _plan_layout(infos: list[_RecordInfo]) -> tuple[dict[str, str | None], dict[str, np.ndarray]]:
    """Key -> group (None = stacked) and group -> per-pair lengths (N,) int64."""
    first = infos[0]
    keys = list(first.shapes)
    for info in infos[1:]:
        if set(info.shapes) != set(keys):
            diff = sorted(set(info.shapes) ^ set(keys))
            raise InputFileError(
                info.path,
                f"has a different set of arrays than {first.path} (differing: {diff})",
                "export records built by one becos version and setting together",
            )
    layout: dict[str, str | None] = {}
    lengths: dict[str, np.ndarray] = {}
    order = [k for k in SCHEMA_GROUPS if k in first.shapes] + sorted(k for k in keys if k not in SCHEMA_GROUPS)
    for key in order:
        shapes = [info.shapes[key][0] for info in infos]
        dtypes = {info.shapes[key][1] for info in infos}
        if len(dtypes) > 1:
            bad = next(info for info in infos if info.shapes[key][1] != first.shapes[key][1])
            raise InputFileError(
                bad.path,
                f"'{key}' has dtype {bad.shapes[key][1]} but {first.path} has {first.shapes[key][1]}",
                "rebuild the records with one becos version",
            )
        same_shape = all(s == shapes[0] for s in shapes)
        if key not in SCHEMA_GROUPS and same_shape:
            layout[key] = None
            continue
        if len(shapes[0]) == 0 or any(s[1:] != shapes[0][1:] for s in shapes):
            bad = next((info for info in infos if info.shapes[key][0][1:] != shapes[0][1:]), first)
            raise InputFileError(
                bad.path,
                f"'{key}' has shape {bad.shapes[key][0]}, which cannot be concatenated with {first.path}'s {shapes[0]}",
                "rebuild the records with one becos version",
            )
        n = np.array([s[0] for s in shapes], dtype=np.int64)
        group = SCHEMA_GROUPS.get(key, key)
        if group in lengths and not np.array_equal(lengths[group], n):
            group = key  # disagrees with its group: offsets of its own
        lengths.setdefault(group, n)
        layout[key] = group
    return layout, lengths


def disk_dtype(key: str, dtype: np.dtype) -> np.dtype:
    """The store's dtype of a record key of ``dtype``: the schema's narrower ``stored`` dtype for its
    index keys (:class:`becos.record.Field`), else ``dtype``."""
    f = RECORD_SCHEMA.get(key)
    if f is not None and f.stored is not None and np.dtype(dtype) == np.dtype(f.dtype):
        return np.dtype(f.stored)
    return np.dtype(dtype)


def _chunking(
    n_rows: int, row_shape: tuple[int, ...], itemsize: int, chunk_bytes: int = CHUNK_BYTES
) -> tuple[tuple, tuple | None]:
    """(chunks, shards or None) along axis 0 for an array of ``n_rows`` rows of ``row_shape``."""
    row_bytes = max(1, math.prod(row_shape)) * itemsize
    chunk_rows = int(min(max(1, chunk_bytes // row_bytes), max(1, n_rows)))
    n_chunks = max(1, math.ceil(n_rows / chunk_rows))
    per_shard = int(min(max(1, SHARD_BYTES // (chunk_rows * row_bytes)), n_chunks))
    chunks = (chunk_rows, *row_shape)
    if per_shard <= 1 and n_chunks == 1:
        return chunks, None
    return chunks, (chunk_rows * per_shard, *row_shape)


class ContentDigests:
    """sha256 of each array's content: its rows in store order, as the C-order bytes of its dtype.

    Keys are store node names (``arrays/x_vertices``, ``offsets/x_vertex``); feed the rows of each
    array in order, in any number of pieces (the digest of the whole array does not depend on how
    it is cut)."""

    def __init__(self, dtypes: Mapping[str, np.dtype]):
        self.dtypes = {key: np.dtype(dtype) for key, dtype in dtypes.items()}
        self._hashes = {key: hashlib.sha256() for key in self.dtypes}

    def update(self, key: str, rows: np.ndarray) -> None:
        data = np.ascontiguousarray(rows, dtype=self.dtypes[key])
        self._hashes[key].update(data.reshape(-1).view(np.uint8))

    def hexdigests(self) -> dict[str, str]:
        return {key: h.hexdigest() for key, h in self._hashes.items()}


class _Writer:
    """Writes array regions in one background thread (compression overlaps reading the next records);
    at most ``max_pending`` bytes wait in the queue."""

    def __init__(self, max_pending: int = 2 * SHARD_BYTES):
        from concurrent.futures import ThreadPoolExecutor

        self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="becos-store")
        self.pending: list = []
        self.max_pending = max_pending

    def submit(self, array, start: int, data: np.ndarray) -> None:
        def job():
            array[start : start + len(data)] = data

        self.pending.append((self.pool.submit(job), data.nbytes))
        while sum(n for _, n in self.pending) > self.max_pending:
            self.pending.pop(0)[0].result()
        still = []
        for future, nbytes in self.pending:
            if future.done():
                future.result()  # re-raises a failed write now
            else:
                still.append((future, nbytes))
        self.pending = still

    def finish(self, failed: bool = False) -> None:
        """Wait for every write (re-raising the first failure); after ``failed``, drop queued ones."""
        try:
            if not failed:
                for future, _ in self.pending:
                    future.result()
        finally:
            self.pool.shutdown(wait=True, cancel_futures=True)
            self.pending = []


class _Sink:
    """Buffers rows of one array and hands them to the writer a whole number of shards at a time."""

    def __init__(self, array, shard_rows: int, writer: _Writer, digests: ContentDigests, node: str):
        self.array, self.shard_rows, self.writer = array, max(1, shard_rows), writer
        self.digests, self.node = digests, node
        self.parts: list[np.ndarray] = []
        self.buffered = 0
        self.pos = 0

    def add(self, rows: np.ndarray) -> None:
        self.digests.update(self.node, rows)
        if len(rows):
            self.parts.append(rows)
            self.buffered += len(rows)
        if self.buffered >= self.shard_rows:
            self._write(final=False)

    def _write(self, final: bool) -> None:
        if not self.buffered:
            return
        data = self.parts[0] if len(self.parts) == 1 else np.concatenate(self.parts)
        n = len(data) if final else (len(data) // self.shard_rows) * self.shard_rows
        self.writer.submit(self.array, self.pos, data[:n])
        self.pos += n
        rest = data[n:]
        self.parts = [rest] if len(rest) else []
        self.buffered = len(rest)

    def close(self) -> None:
        self._write(final=True)
        if self.pos != self.array.shape[0]:
            raise RuntimeError(f"store array {self.array.name}: wrote {self.pos} of {self.array.shape[0]} rows")


def _versions() -> dict[str, str]:
    from importlib import metadata as importlib_metadata

    out = {"python": sys.version.split()[0]}
    for name in VERSION_PACKAGES:
        try:
            out[name] = importlib_metadata.version(name)
        except importlib_metadata.PackageNotFoundError:
            continue
    return out


def _pair_category(meta: dict) -> str:
    """The pair's category pool: meta ``category`` (workflow records), else derived from the shapes."""
    if meta.get("category"):
        return str(meta["category"])
    cx, cy = (meta.get(s, {}).get("category", "") for s in ("x", "y"))
    if meta.get("setting") == "partial_full":
        return cy
    if cx == cy or cy == "centaur":
        return cx
    return cy if cx == "centaur" else f"{cx}_{cy}"


def table_row(index: int, meta: dict, x_n_vertices: int, y_n_vertices: int, x_overlap: float, y_overlap: float) -> list:
    """One row of the pairs table (:data:`TABLE_COLUMNS`) from a pair's meta and sizes."""
    x, y = meta.get("x", {}), meta.get("y", {})
    return [
        int(index),
        meta["pair_id"],
        meta.get("split", ""),
        _pair_category(meta),
        int(meta.get("seed", -1)),
        x.get("dataset", ""),
        x.get("name", ""),
        x.get("class", ""),
        x.get("category", ""),
        y.get("dataset", ""),
        y.get("name", ""),
        y.get("class", ""),
        y.get("category", ""),
        int(x_n_vertices),
        int(y_n_vertices),
        float(x_overlap),
        float(y_overlap),
        int(meta.get("n_tries", 0)),
        bool(meta.get("accepted", True)),
    ]


def _json_bytes(value) -> np.ndarray:
    return np.frombuffer(json.dumps(value, sort_keys=True, allow_nan=True).encode("utf-8"), dtype=np.uint8)


def _bytes_array(group, name: str, data: np.ndarray) -> None:
    chunks, shards = _chunking(len(data), (), 1)
    array = group.create_array(
        name,
        shape=data.shape,
        dtype=np.uint8,
        chunks=chunks,
        shards=shards,
        compressors=_compressors(),
        fill_value=0,
        chunk_key_encoding=CHUNK_KEYS,
    )
    if len(data):
        array[:] = data


def _compressors():
    """Blosc LZ4HC level 1 with byte shuffle. On TOSCA pair records it is as small as Blosc zstd level 1
    (1.054 vs 1.040 MB per F2F pair), faster to write (3.9 vs 5.6 ms CPU per pair) and decodes 6x
    faster (0.31 vs 1.8 ms), which is most of what reading a pair costs; shuffled small integers and
    masks compress well, float coordinates little with any codec."""
    from zarr.codecs import BloscCodec

    return [BloscCodec(cname="lz4hc", clevel=1, shuffle="shuffle")]


def write_pairs(root, metas: list[dict], table_rows: list[list]) -> None:
    """(Re)write the ``pairs`` group (metas and table) of an open, writable store group."""
    pairs = root.require_group("pairs")
    blobs = [json.dumps(m, sort_keys=True, allow_nan=True).encode("utf-8") for m in metas]
    offsets = np.zeros(len(blobs) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum([len(b) for b in blobs])
    for name in ("meta_json", "meta_offsets", "table_json"):
        if name in pairs:
            del pairs[name]
    _bytes_array(pairs, "meta_json", np.frombuffer(b"".join(blobs), dtype=np.uint8))
    pairs.create_array(
        "meta_offsets",
        data=offsets,
        chunks=(max(1, len(offsets)),),
        compressors=_compressors(),
        chunk_key_encoding=CHUNK_KEYS,
    )
    _bytes_array(pairs, "table_json", _json_bytes({"columns": list(TABLE_COLUMNS), "rows": table_rows}))


def _progress(message: str) -> None:
    print(f"export-zarr: {message}", file=sys.stderr, flush=True)


def _add_record(info: _RecordInfo, sinks: dict, layout: dict, metas: list, rows: list, index: int) -> None:
    try:
        meta, _, arrays = _read_npz(info.path, load=True)
    except (zipfile.BadZipFile, ValueError, OSError, KeyError, SyntaxError, struct.error, TypeError) as exc:
        raise InputFileError(
            info.path, f"is not a readable pair record .npz ({exc})", "re-run the pairs stage for this pair"
        ) from exc
    record = PairRecord(arrays, meta)
    for key, sink in sinks.items():
        value = record.arrays[key]
        if value.shape != info.shapes[key][0] or value.dtype != info.shapes[key][1]:
            raise InputFileError(
                info.path, "changed while the store was written", "re-run export-zarr once the pairs stage is done"
            )
        disk = sink.array.dtype
        if value.dtype != disk:  # an index key stored narrower: every value must fit
            if value.size and (value.min() < np.iinfo(disk).min or value.max() > np.iinfo(disk).max):
                raise InputFileError(
                    info.path,
                    f"'{key}' holds values outside {disk}, the store's dtype of this index key",
                    "rebuild the pair record with becos",
                )
            value = value.astype(disk)
        sink.add(value[None] if layout[key] is None else value)
    metas.append(record.meta)
    rows.append(
        table_row(
            index,
            record.meta,
            len(record["x_vertices"]),
            len(record["y_vertices"]),
            record["x_overlap"],
            record["y_overlap"],
        )
    )


def write_store(
    record_paths: Iterable[str | Path],
    out: str | Path,
    *,
    setting: str,
    metadata: Mapping | None = None,
    progress: bool = True,
) -> Path:
    """One Zarr v3 store per setting: every PairRecord concatenated per key (+ offsets), a pairs table,
    metadata. Written to a temp dir then renamed (atomic).

    Args:
        record_paths: pair record .npz files (:meth:`becos.record.PairRecord.save`), any order; each
            pair_id once, every record of ``setting`` and of this schema version.
        out: the store folder (``*.zarr``); an existing store there is replaced.
        setting: full_full | partial_full | partial_partial.
        metadata: JSON-able extra root attributes (``config_hash``, ``config``, ``datasets`` ...);
            a ``setting`` in it must equal ``setting``.
        progress: print progress to stderr (about every 10 % for 50 records or more).

    Returns:
        ``out`` as a Path. Raises :class:`InputFileError` naming the offending record file.
    """
    import zarr

    out = Path(out)
    if setting not in SETTINGS:
        raise BecosError(f"setting must be one of {SETTINGS}, got {setting!r}")
    metadata = json.loads(json.dumps(dict(metadata or {}), default=str))
    if metadata.get("setting", setting) != setting:
        raise BecosError(
            f"the store metadata says setting {metadata['setting']!r} but --setting is {setting!r}. "
            "Fix: pass the metadata file of the same setting"
        )
    started = time.perf_counter()
    paths = [Path(p) for p in record_paths]
    if not paths:
        raise BecosError(f"{out}: no pair records given. Fix: pass record .npz files or chunk index files")
    infos = []
    seen: dict[str, Path] = {}
    for path in paths:
        info = _scan_record(path)
        pid = info.meta["pair_id"]
        if pid in seen:
            raise InputFileError(path, f"pair {pid} is also in {seen[pid]}", "give each record once")
        seen[pid] = path
        if info.meta.get("setting", setting) != setting:
            raise InputFileError(
                path,
                f"is a {info.meta.get('setting')} record, not {setting}",
                f"export only the records of {setting} into this store",
            )
        infos.append(info)
    infos.sort(key=lambda i: store_order_key(i.meta.get("split", ""), i.meta["pair_id"]))
    layout, lengths = _plan_layout(infos)
    n = len(infos)
    if progress and n >= 50:
        _progress(f"{n} records scanned in {time.perf_counter() - started:.1f} s")

    out.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(out.parent, [out.name])  # one job writes a store: these are a killed write's
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp"))
    try:
        root = zarr.open_group(str(tmp), mode="w", zarr_format=3)
        arrays, offsets_group = root.create_group("arrays"), root.create_group("offsets")
        first = infos[0].shapes
        disk = {key: disk_dtype(key, first[key][1]) for key in layout}
        digests = ContentDigests(
            {**{f"arrays/{key}": disk[key] for key in layout}, **{f"offsets/{group}": np.int64 for group in lengths}}
        )
        for group, n_rows in lengths.items():
            offsets = np.zeros(n + 1, dtype=np.int64)
            offsets[1:] = np.cumsum(n_rows)
            offsets_group.create_array(
                group, data=offsets, chunks=(n + 1,), compressors=_compressors(), chunk_key_encoding=CHUNK_KEYS
            )
            digests.update(f"offsets/{group}", offsets)
        sinks = {}
        writer = _Writer()
        for key, group in layout.items():
            shape, dtype = first[key][0], disk[key]
            total = n if group is None else int(lengths[group].sum())
            row_shape = shape if group is None else shape[1:]
            chunks, shards = _chunking(
                total, row_shape, dtype.itemsize, CHUNK_BYTES if group is not None else STACKED_CHUNK_BYTES
            )
            array = arrays.create_array(
                key,
                shape=(total, *row_shape),
                dtype=dtype,
                chunks=chunks,
                shards=shards,
                compressors=_compressors(),
                fill_value=np.zeros((), dtype).item(),
                chunk_key_encoding=CHUNK_KEYS,
                # every chunk file exists, even all-zero ones: an absent file is damage
                config={"write_empty_chunks": True},
            )
            sinks[key] = _Sink(array, (shards or chunks)[0], writer, digests, f"arrays/{key}")
        metas, rows = [], []
        step = max(1, math.ceil(n / 10))
        try:
            for i, info in enumerate(infos):
                _add_record(info, sinks, layout, metas, rows, i)
                if progress and n >= 50 and ((i + 1) % step == 0 or i + 1 == n):
                    _progress(f"{i + 1}/{n} records read ({time.perf_counter() - started:.1f} s)")
            for sink in sinks.values():
                sink.close()
        except BaseException:
            writer.finish(failed=True)
            raise
        writer.finish()
        write_pairs(root, metas, rows)
        splits: dict[str, int] = {}
        for m in metas:
            splits[m.get("split", "")] = splits.get(m.get("split", ""), 0) + 1
        attrs = dict(metadata)
        attrs.update(
            schema_version=SCHEMA_VERSION,
            setting=setting,
            n_pairs=n,
            splits=splits,
            created=datetime.now(UTC).isoformat(timespec="seconds"),
            versions=_versions(),
            becos_store={"format": STORE_FORMAT, "layout": layout, "sha256": digests.hexdigests()},
        )
        root.attrs.update(attrs)
        os.chmod(tmp, 0o755)
        _replace_dir(tmp, out)
    except BaseException as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        full = exc if isinstance(exc, OSError) else exc.__cause__ or exc.__context__
        if isinstance(full, OSError) and full.errno in (errno.ENOSPC, errno.EDQUOT):
            raise DiskFullError(out, full) from exc
        raise
    if progress:
        _progress(f"{n} pairs -> {out} ({time.perf_counter() - started:.1f} s)")
    return out


def _replace_dir(tmp: Path, out: Path) -> None:
    """Move the finished ``tmp`` folder to ``out``; an old ``out`` is moved aside first, then deleted."""
    old = None
    if out.exists() or out.is_symlink():
        old = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".old"))
        os.replace(out, old / "store")
    os.replace(tmp, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


# --------------------------------------------------------------------------------------------------
# reading


@dataclass
class Block:
    """Consecutive pairs ``start:stop`` of a store read at once.

    Attributes:
        start, stop: store rows.
        arrays: key -> the block's rows of that key (ragged keys concatenated over the block's
            pairs, stacked keys (stop - start, ...)).
        offsets: group -> (stop - start + 1,) int64 offsets into ``arrays`` (starting at 0).
        layout: key -> group, None for stacked keys.
        metas: the pairs' meta dicts.
    """

    start: int
    stop: int
    arrays: dict[str, np.ndarray]
    offsets: dict[str, np.ndarray]
    layout: dict[str, str | None]
    metas: list[dict]

    def __len__(self) -> int:
        return self.stop - self.start

    def counts(self, group: str) -> np.ndarray:
        """(n,) rows per pair of a ragged group."""
        return np.diff(self.offsets[group])

    def record(self, i: int) -> PairRecord:
        """The ``i``-th pair of the block (0-based within the block), arrays copied and index keys
        widened to the record's dtypes (:func:`becos.record.decode_arrays`)."""
        arrays = {}
        for key, group in self.layout.items():
            data = self.arrays[key]
            if group is None:
                value = data[i, ...]
            else:
                o = self.offsets[group]
                value = data[o[i] : o[i + 1]]
            f = RECORD_SCHEMA.get(key)
            wide = f is not None and f.stored is not None and value.dtype == np.dtype(f.stored)
            arrays[key] = value.astype(f.dtype) if wide else value.copy()
        return PairRecord(arrays, self.metas[i])


class _ChunkFiles:
    """Rows ``a:b`` of one store array read straight from its chunk files: one ``pread`` and one Blosc
    decode per inner chunk touched, shard indexes read once and kept.

    Zarr's own read path costs ~1.4 ms of CPU per array and read (its asyncio pipeline), ~65 ms for
    the ~50 arrays of one record; this reads a record in a few ms (``benchmarks/store.py``). It reads
    exactly what :func:`write_store` writes (chunks along axis 0, codecs bytes + Blosc, optionally
    sharded with the index at the end); :attr:`usable` is False for anything else, and the caller then
    reads through zarr. Any problem raises ``ValueError``/``OSError`` (the caller then re-reads through
    zarr, which reports it as before)."""

    def __init__(self, folder: Path, array):
        from zarr.codecs import BloscCodec, BytesCodec, ShardingCodec

        meta = array.metadata
        self.folder = folder
        self.dtype = np.dtype(array.dtype)
        self.shape = tuple(meta.shape)
        self.row_shape = self.shape[1:]
        self.outer = int(meta.chunk_grid.chunk_shape[0])
        self.sep = getattr(meta.chunk_key_encoding, "separator", "/")
        codecs = list(meta.codecs)
        self.inner, self.per_shard = self.outer, 0
        if len(codecs) == 1 and isinstance(codecs[0], ShardingCodec):
            shard = codecs[0]
            end = str(getattr(shard.index_location, "value", shard.index_location)) == "end"
            self.inner = int(shard.chunk_shape[0])
            self.per_shard = self.outer // self.inner
            codecs = list(shard.codecs) if end and tuple(shard.chunk_shape[1:]) == self.row_shape else []
        self.usable = (
            len(codecs) == 2
            and isinstance(codecs[0], BytesCodec)
            and isinstance(codecs[1], BloscCodec)
            and tuple(meta.chunk_grid.chunk_shape[1:]) == self.row_shape
            and self.dtype.isnative
            and meta.dimension_names is None
            and self.sep in (".", "/")
        )
        self.chunk_key = getattr(meta.chunk_key_encoding, "name", "")
        self.usable = self.usable and self.chunk_key == "default"
        self._index: dict[int, np.ndarray] = {}

    def _file(self, k: int) -> Path:
        return self.folder / self.sep.join(["c", str(k), *("0" * len(self.row_shape))])

    def _shard_index(self, fd: int, shard: int) -> np.ndarray:
        index = self._index.get(shard)
        if index is None:
            size = os.fstat(fd).st_size
            n = 16 * self.per_shard + 4  # (offset, nbytes) uint64 per chunk + crc32c
            raw = os.pread(fd, n, size - n)
            if size < n or len(raw) != n:
                raise ValueError("shard index truncated")
            index = np.frombuffer(raw[:-4], dtype="<u8").reshape(self.per_shard, 2)
            self._index[shard] = index
        return index

    def read(self, a: int, b: int) -> np.ndarray:
        from numcodecs.blosc import decompress

        out = np.empty((b - a, *self.row_shape), dtype=self.dtype)
        if b <= a:
            return out
        row_items = math.prod(self.row_shape)
        c = self.inner
        fds: dict[int, int] = {}
        try:
            for k in range(a // c, (b - 1) // c + 1):
                file_k = k // self.per_shard if self.per_shard else k
                fd = fds.get(file_k)
                if fd is None:
                    fd = fds[file_k] = os.open(self._file(file_k), os.O_RDONLY)
                if self.per_shard:
                    offset, nbytes = (int(v) for v in self._shard_index(fd, file_k)[k % self.per_shard])
                    if offset == 2**64 - 1:
                        raise ValueError("inner chunk absent")
                    raw = os.pread(fd, nbytes, offset)
                    if len(raw) != nbytes:
                        raise ValueError("inner chunk truncated")
                else:
                    raw = os.pread(fd, os.fstat(fd).st_size, 0)
                lo, hi = max(a, k * c), min(b, (k + 1) * c, self.shape[0])
                rows = min(c, self.shape[0] - k * c) if not self.per_shard else c
                if lo == k * c and hi == (k + 1) * c:  # the whole chunk: decode in place
                    decompress(raw, out[lo - a : hi - a])
                    continue
                data = np.frombuffer(decompress(raw), dtype=self.dtype)
                if data.size < rows * row_items:
                    raise ValueError("chunk decodes to too few bytes")
                data = data[: c * row_items].reshape(-1, *self.row_shape)
                out[lo - a : hi - a] = data[lo - k * c : hi - k * c]
        finally:
            for fd in fds.values():
                os.close(fd)
        return out


class PairKeyError(BecosError, TypeError):
    """A pair asked for by something that is neither a row index (int) nor a pair_id (str)."""


class DamagedStoreError(InputFileError):
    """A store whose root opens but one of whose arrays, offsets or pair tables is missing or unreadable."""


DAMAGED_STORE_FIX = "re-export the store with `becos export-zarr` (it is damaged or was copied incompletely)"


class Benchmark:
    """A benchmark store opened for reading (:func:`open_benchmark`).

    Attributes:
        path: the store folder.
        setting: full_full | partial_full | partial_partial.
        metadata: root attributes (schema_version, setting, config_hash, config, versions, datasets,
            created ...), without the internal ``becos_store`` layout.
        table: pandas DataFrame, one row per pair in store order (:data:`TABLE_COLUMNS`).
    """

    def __init__(self, path: str | Path):
        import pandas as pd
        import zarr

        self.path = Path(path)
        fix = "give a store written by `becos export-zarr` (a folder with zarr.json)"
        if not (self.path / "zarr.json").is_file():
            raise InputFileError(self.path, "is not a Zarr v3 store", fix)
        try:
            root = zarr.open_group(str(self.path), mode="r", zarr_format=3)
            attrs = dict(root.attrs)
        except Exception as exc:  # zarr raises several types for unreadable metadata
            raise InputFileError(self.path, f"cannot be opened as a Zarr store ({exc})", fix) from exc
        info = attrs.get("becos_store")
        newer = "upgrade becos (pip install -U the becos checkout) to read it, or re-export the store with this becos"
        found = info.get("format") if isinstance(info, dict) else None
        if isinstance(found, int) and not isinstance(found, bool) and found > STORE_FORMAT:
            raise InputFileError(
                self.path,
                f"was written by a newer becos: store format {found}, this becos reads format {STORE_FORMAT}",
                newer,
            )
        if not isinstance(info, dict) or found != STORE_FORMAT:
            raise InputFileError(self.path, f"is not a becos benchmark store of format {STORE_FORMAT}", fix)
        schema = attrs.get("schema_version")
        if isinstance(schema, int) and not isinstance(schema, bool) and schema > SCHEMA_VERSION:
            raise InputFileError(
                self.path,
                f"was written by a newer becos: record schema {schema}, this becos reads {SCHEMA_VERSION}",
                newer,
            )
        if attrs.get("schema_version") != SCHEMA_VERSION:
            raise InputFileError(
                self.path,
                f"holds record schema {attrs.get('schema_version')}, this becos reads {SCHEMA_VERSION}",
                "re-export the store with this becos version",
            )
        self._root = root
        self._files: dict[str, _ChunkFiles] | None = None
        self._stamp = self._identity()
        self.metadata = {k: v for k, v in attrs.items() if k != "becos_store"}
        self.setting = attrs["setting"]
        self.layout: dict[str, str | None] = dict(info["layout"])
        self.content_digests: dict[str, str] = dict(info.get("sha256") or {})
        """Node name -> sha256 of its content when written (:class:`ContentDigests`); empty for stores
        written before becos recorded them."""
        node = "arrays"
        try:  # a missing or damaged node is a damaged store, not a traceback
            self._arrays = {}
            for key in self.layout:
                node = f"arrays/{key}"
                self._arrays[key] = root[node]
            self.offsets = {}
            for g in sorted({g for g in self.layout.values() if g is not None}):
                node = f"offsets/{g}"
                self.offsets[g] = np.asarray(root[node][:])
            node = "pairs/meta_offsets"
            self._meta_offsets = np.asarray(root[node][:])
            node = "pairs/meta_json"
            self._meta_json = root[node]
            node = "pairs/table_json"
            table = json.loads(bytes(np.asarray(root[node][:])).decode("utf-8"))
            frame = pd.DataFrame(table["rows"], columns=table["columns"])
        except Exception as exc:
            raise DamagedStoreError(
                self.path, f"{node} is missing or unreadable ({type(exc).__name__}: {exc})", DAMAGED_STORE_FIX
            ) from exc
        self.table = frame.astype({k: v for k, v in TABLE_DTYPES.items() if k in frame.columns})
        self._row_of = {pid: i for i, pid in enumerate(self.table["pair_id"])}
        n = len(self.table)
        for name, o in [*self.offsets.items(), ("meta_offsets", self._meta_offsets)]:
            if len(o) != n + 1:
                raise InputFileError(
                    self.path,
                    f"offsets '{name}' have {len(o)} entries for {n} pairs",
                    "re-export the store (it is damaged)",
                )

    def __repr__(self) -> str:
        return f"Benchmark({str(self.path)!r}, setting={self.setting!r}, pairs={len(self)})"

    def _identity(self) -> tuple[int, int, int]:
        """(inode, size, mtime) of the store's root metadata: :func:`write_store` replaces the whole
        folder, so a rewrite changes it."""
        try:
            st = (self.path / "zarr.json").stat()
        except OSError:
            return (-1, -1, -1)
        return (st.st_ino, st.st_size, st.st_mtime_ns)

    def _check_unchanged(self, what: str) -> None:
        """Raise :class:`DamagedStoreError` when the store was rewritten (or removed) since it was opened:
        its offsets no longer fit the files, so a read would return another pair's bytes."""
        if self._identity() != self._stamp:
            raise DamagedStoreError(
                self.path,
                f"was rewritten or removed while this reader had it open (reading {what})",
                "open it again (open_benchmark) once the writer has finished",
            )

    def __len__(self) -> int:
        return len(self.table)

    def __iter__(self) -> Iterator[PairRecord]:
        return self.records()

    def splits(self) -> list[str]:
        """Splits present, in store order (train, val, test first)."""
        return sorted(set(self.table["split"]), key=lambda split: store_order_key(split, ""))

    def row(self, key: int | str) -> int:
        """Store row of a row index or pair_id (KeyError/IndexError if absent; :class:`PairKeyError`, a
        TypeError, for anything else, e.g. ``1.5`` or ``True``)."""
        if isinstance(key, str):
            if key not in self._row_of:
                raise KeyError(f"{self.path}: no pair {key!r}")
            return self._row_of[key]
        if isinstance(key, (bool, np.bool_)) or not isinstance(key, (int, np.integer)):
            raise PairKeyError(
                f"{self.path}: a pair is chosen by its row (an int) or its pair_id (a str), not "
                f"{key!r} ({type(key).__name__}). Fix: pass an integer row, e.g. "
                f"bench.record(0), or a pair_id from bench.table['pair_id']"
            )
        i = int(key)
        if not -len(self) <= i < len(self):
            raise IndexError(f"{self.path}: row {i} out of range for {len(self)} pairs")
        return i % len(self)

    def record(self, key: int | str) -> PairRecord:
        """The pair at a row index or with a pair_id: exact round trip of every array and the meta."""
        i = self.row(key)
        return self.read_rows(i, i + 1).record(0)

    def read_rows(self, start: int, stop: int) -> Block:
        """Pairs ``start:stop`` as one :class:`Block`, read straight from the chunk files
        (:class:`_ChunkFiles`: a few ms per pair where zarr's pipeline takes ~65 ms); falls back to
        :meth:`read_block` (zarr) for a layout it does not read and for any problem, which zarr then
        reports as a :class:`DamagedStoreError`."""
        if self._files is None:
            files = {key: _ChunkFiles(self.path / "arrays" / key, a) for key, a in self._arrays.items()}
            files["pairs/meta_json"] = _ChunkFiles(self.path / "pairs" / "meta_json", self._meta_json)
            self._files = files if all(f.usable for f in files.values()) else {}
        if not self._files:
            return self.read_block(start, stop)
        self._check_unchanged(f"pairs {start}:{stop}")
        try:
            arrays = {}
            for key, group in self.layout.items():
                a, b = (start, stop) if group is None else (self.offsets[group][start], self.offsets[group][stop])
                arrays[key] = self._files[key].read(int(a), int(b))
            mo = self._meta_offsets
            blob = self._files["pairs/meta_json"].read(int(mo[start]), int(mo[stop])).tobytes()
            metas = [
                json.loads(blob[o0:o1].decode("utf-8"))
                for o0, o1 in zip(mo[start:stop] - mo[start], mo[start + 1 : stop + 1] - mo[start])
            ]
        except Exception:  # noqa: BLE001 - zarr re-reads it and reports the problem as before
            self._files = None
            return self.read_block(start, stop)
        self._check_unchanged(f"pairs {start}:{stop}")
        offsets = {g: o[start : stop + 1] - o[start] for g, o in self.offsets.items()}
        return Block(start, stop, arrays, offsets, self.layout, metas)

    def records(self, split: str | None = None) -> Iterator[PairRecord]:
        """Every pair (or those of one split) in table order, read a block at a time."""
        for block in self.blocks(split):
            for i in range(len(block)):
                yield block.record(i)

    def array(self, key: str):
        """The zarr array of one key (ragged: all pairs' rows concatenated; stacked: (N, ...))."""
        return self._arrays[key]

    def concatenated(self, key: str) -> tuple[np.ndarray, np.ndarray | None]:
        """All pairs' rows of one key at once: ``(data, offsets)`` for ragged keys ((N + 1,) offsets),
        ``(stacked (N, ...), None)`` for stacked keys."""
        group = self.layout[key]
        return np.asarray(self._arrays[key][:]), (None if group is None else self.offsets[group])

    def pair_bytes(self) -> np.ndarray:
        """(N,) uncompressed bytes of each pair's arrays."""
        total = np.zeros(len(self), dtype=np.int64)
        for key, group in self.layout.items():
            a = self._arrays[key]
            row_bytes = math.prod(a.shape[1:]) * a.dtype.itemsize
            total += row_bytes if group is None else np.diff(self.offsets[group]) * row_bytes
        return total

    def block_ranges(self, split: str | None = None, max_bytes: int = READ_BLOCK_BYTES) -> list[tuple[int, int]]:
        """Row ranges ``(start, stop)`` of consecutive pairs (of one split, or all) holding about
        ``max_bytes`` of arrays each (at least one pair)."""
        rows = np.arange(len(self)) if split is None else np.flatnonzero(self.table["split"].to_numpy() == split)
        if not len(rows):
            return []
        size = self.pair_bytes()
        out = []
        for run in np.split(rows, np.flatnonzero(np.diff(rows) != 1) + 1):
            start = int(run[0])
            acc = 0
            for i in run:
                if acc and acc + size[i] > max_bytes:
                    out.append((start, int(i)))
                    start, acc = int(i), 0
                acc += int(size[i])
            out.append((start, int(run[-1]) + 1))
        return out

    def blocks(self, split: str | None = None, max_bytes: int = READ_BLOCK_BYTES) -> Iterator[Block]:
        """Consecutive pairs (of one split, or all) in blocks of about ``max_bytes`` of arrays."""
        for start, stop in self.block_ranges(split, max_bytes):
            yield self.read_rows(start, stop)

    def read_block(self, start: int, stop: int) -> Block:
        """Pairs ``start:stop`` (store rows) as one :class:`Block`."""
        import asyncio

        from zarr.core.sync import sync

        keys = list(self.layout)
        ranges = []
        for key in keys:
            group = self.layout[key]
            a, b = (start, stop) if group is None else (self.offsets[group][start], self.offsets[group][stop])
            ranges.append((self._arrays[key], int(a), int(b)))
        mo = self._meta_offsets
        ranges.append((self._meta_json, int(mo[start]), int(mo[stop])))

        async def read_all():  # every array's slice concurrently: one round trip, not one per key
            return await asyncio.gather(*(array.async_array.getitem(slice(a, b)) for array, a, b in ranges))

        self._check_unchanged(f"pairs {start}:{stop}")
        try:
            values = sync(read_all())
        except Exception as exc:  # a chunk that does not decode: zarr and the codecs raise several types
            self._check_unchanged(f"pairs {start}:{stop}")
            raise DamagedStoreError(
                self.path, f"pairs {start}:{stop} cannot be read ({type(exc).__name__}: {exc})", DAMAGED_STORE_FIX
            ) from exc
        self._check_unchanged(f"pairs {start}:{stop}")
        arrays = {key: np.asarray(v) for key, v in zip(keys, values)}
        offsets = {g: o[start : stop + 1] - o[start] for g, o in self.offsets.items()}
        blob = bytes(np.asarray(values[-1]))
        local = mo[start : stop + 1] - mo[start]
        metas = self._decode_metas(blob, local, f"pairs {start}:{stop}")
        return Block(start, stop, arrays, offsets, self.layout, metas)

    def _decode_metas(self, blob: bytes, offsets: np.ndarray, what: str) -> list[dict]:
        try:
            return [json.loads(blob[offsets[i] : offsets[i + 1]].decode("utf-8")) for i in range(len(offsets) - 1)]
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            self._check_unchanged(what)
            raise DamagedStoreError(
                self.path, f"the metadata of {what} does not decode ({exc})", DAMAGED_STORE_FIX
            ) from exc

    def read_metas(self) -> list[dict]:
        """Every pair's meta, in store order."""
        self._check_unchanged("the pair metadata")
        blob = bytes(np.asarray(self._meta_json[:]))
        self._check_unchanged("the pair metadata")
        return self._decode_metas(blob, self._meta_offsets, "the pair metadata")


class TrainingView:
    """The pairs of a store (or of one split) for a training loop: ``len(view)`` and ``view[i]`` -> a
    dict of plain numpy arrays (record keys as in :data:`becos.record.RECORD_SCHEMA`, index keys
    int64, plus ``row``: the pair's store row). Needs no torch; a ``torch.utils.data.Dataset`` can
    wrap it as is.

    Safe in ``DataLoader`` worker processes, forked or spawned: the store is opened lazily in each
    process (again after a fork), and pickling the view carries only the path, split, keys and rows,
    never an open store. Reads go through :meth:`Benchmark.read_rows` (a few ms per pair).

    Args:
        path: the store folder.
        split: only the pairs of this split (train, val, test ...), in store order; None: all.
        keys: record keys to return (default: all).
    """

    def __init__(self, path: str | Path, split: str | None = None, keys: Iterable[str] | None = None):
        self.path, self.split = Path(path), split
        bench = Benchmark(self.path)
        unknown = sorted(set(keys or ()) - set(bench.layout))
        if unknown:
            raise BecosError(f"{self.path}: no record keys {unknown}. Fix: choose keys from {sorted(bench.layout)}")
        self.keys = tuple(keys) if keys is not None else tuple(bench.layout)
        table_split = bench.table["split"].to_numpy()
        self.rows = np.arange(len(bench)) if split is None else np.flatnonzero(table_split == split)
        self._bench, self._pid = bench, os.getpid()

    def __getstate__(self) -> dict:
        return {**self.__dict__, "_bench": None, "_pid": None}

    def __len__(self) -> int:
        return len(self.rows)

    def benchmark(self) -> Benchmark:
        """This process's open store (opened on first use, and again in a forked child)."""
        if self._bench is None or self._pid != os.getpid():
            self._bench, self._pid = Benchmark(self.path), os.getpid()
        return self._bench

    def __getitem__(self, i: int) -> dict[str, np.ndarray]:
        if isinstance(i, (bool, np.bool_)) or not isinstance(i, (int, np.integer)):
            raise PairKeyError(f"{self.path}: a training view is indexed by an int, not {i!r}")
        if not -len(self) <= i < len(self):
            raise IndexError(f"{self.path}: item {i} out of range for {len(self)} pairs")
        row = int(self.rows[i])
        record = self.benchmark().read_rows(row, row + 1).record(0)
        return {**{k: record.arrays[k] for k in self.keys}, "row": np.int64(row)}


def open_benchmark(path: str | Path) -> Benchmark:
    """Open a store written by :func:`write_store` (read-only)."""
    return Benchmark(path)


def count_files(path: str | Path) -> int:
    """Number of files below a store folder."""
    return sum(len(files) for _, _, files in os.walk(path))


def expand_inputs(inputs: Iterable[str | Path], setting: str | None = None) -> list[Path]:
    """Record paths from a mix of record .npz files and index files (:func:`read_record_index`)."""
    out = []
    for path in map(Path, inputs):
        if path.suffix == ".npz":
            out.append(path)
            continue
        if not path.is_file():
            raise InputFileError(path, "not found", "pass existing record .npz files or index files")
        declared = index_setting(path)
        if setting is not None and declared is not None and declared != setting:
            raise InputFileError(
                path,
                f"is an index of {declared} records, not {setting}",
                "pass the indexes of the setting being exported",
            )
        out.extend(read_record_index(path))
    return out
