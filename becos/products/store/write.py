"""Writing a store (:func:`write_store`; layout: :mod:`becos.products.store`).

Streams: one pass over the .npz headers and metas (shapes, dtypes, order), then one pass over the
records, buffering at most one shard per array (:data:`SHARD_BYTES`, inner chunks of
:data:`CHUNK_BYTES` for ragged keys and :data:`STACKED_CHUNK_BYTES` for per-pair keys, Blosc LZ4HC
with byte shuffle; the shards written straight to the files: :class:`ChunkFiles`), into a hidden
temporary folder beside ``out`` that replaces ``out`` when complete. With ``processes=2`` a second
process fills about half of the arrays (whole arrays: every shard still has one writer) while the
first fills the rest and the pairs table; the store is the same.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import math
import os
import shutil
import struct
import sys
import tempfile
import time
import zipfile
from collections.abc import Callable, Collection, Iterable, Mapping
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from becos.atomic import remove_stale_temporaries
from becos.build.record import (
    RECORD_SCHEMA,
    SCHEMA_VERSION,
    SETTINGS,
)
from becos.errors import BecosError, DiskFullError, InputFileError
from becos.products.store.chunk_files import ChunkFiles
from becos.products.store.layout import CHUNK_KEYS, SCHEMA_GROUPS, STORE_FORMAT, TABLE_COLUMNS, store_order_key
from becos.products.store.npz import RecordInfo, read_npz, scan_record

CHUNK_BYTES = 64 << 10
"""Uncompressed bytes per inner chunk (the unit a partial read decodes): 64 KiB, so reading one pair
(~2 MB of arrays over ~50 keys) decodes little beyond its own rows."""


STACKED_CHUNK_BYTES = 4 << 10
"""Inner chunk of the per-pair (stacked) keys: one pair's row is 8-72 bytes, so reading a pair
decodes 4 KiB per key, not 64."""


SHARD_BYTES = 4 << 20
"""Uncompressed bytes per shard file (also the most :func:`write_store` buffers per array, so the
writer's memory stays flat as stores grow: ~40 arrays x 4 MiB)."""


ARRAY_CONFIG = {"write_empty_chunks": True}
"""How the writer opens every array: each chunk is stored, all-zero ones too, so an absent chunk is damage."""


SECOND_PROCESS_BYTES = 256 << 20
"""Uncompressed array bytes above which ``processes=2`` uses its second process: below, its start-up
(~0.5 CPU-s of imports) costs more than it saves. The writing process is the bottleneck of a large
store (zarr's encoding of ~25,000 inner chunks per 1,000 TOSCA pairs, one event loop per process)."""


VERSION_PACKAGES = ("becos", "numpy", "zarr", "trimesh", "pymeshlab", "embreex", "snakemake")


def _plan_layout(infos: list[RecordInfo]) -> tuple[dict[str, str | None], dict[str, np.ndarray]]:
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
    index keys (:class:`becos.build.record.Field`), else ``dtype``."""
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
        self._done: dict[str, str] = {}

    def update(self, key: str, rows: np.ndarray) -> None:
        data = np.ascontiguousarray(rows, dtype=self.dtypes[key])
        self._hashes[key].update(data.reshape(-1).view(np.uint8))

    def hexdigests(self) -> dict[str, str]:
        return {key: self._done.get(key) or h.hexdigest() for key, h in self._hashes.items()}

    def merge(self, done: Mapping[str, str]) -> None:
        """Take the finished digests of keys fed elsewhere (the store writer's second process)."""
        unknown = set(done) - set(self._hashes)
        if unknown:
            raise KeyError(f"digests of unknown store nodes: {sorted(unknown)}")
        self._done.update(done)


class _Writer:
    """Writes array regions in one background thread (compression overlaps reading the next records);
    at most ``max_pending`` bytes wait in the queue."""

    def __init__(self, max_pending: int = 2 * SHARD_BYTES):
        from concurrent.futures import ThreadPoolExecutor

        self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="becos-store")
        self.pending: list = []
        self.max_pending = max_pending

    def submit(self, write: Callable[[int, np.ndarray], None], start: int, data: np.ndarray) -> None:
        """Run ``write(start, data)`` in the background thread."""
        self.pending.append((self.pool.submit(write, start, data), data.nbytes))
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
    """Buffers rows of one array and hands them to the writer a whole number of shards at a time, written
    straight to the array's files in ``folder`` (:class:`ChunkFiles`; through zarr for a layout it does
    not write)."""

    def __init__(self, array, folder: Path, writer: _Writer, digests: ContentDigests, node: str):
        self.array, self.shard_rows, self.writer = array, max(1, _shard_rows(array)), writer
        self.digests, self.node = digests, node
        files = ChunkFiles(folder, array)
        self.write = files.write if files.writable else self._write_through_zarr
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
        self.writer.submit(self.write, self.pos, data[:n])
        self.pos += n
        rest = data[n:]
        self.parts = [rest] if len(rest) else []
        self.buffered = len(rest)

    def _write_through_zarr(self, start: int, data: np.ndarray) -> None:
        self.array[start : start + len(data)] = data

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


_CHANGED_FIX = "re-run export-zarr once the pairs stage is done"


def _read_record(info: RecordInfo, keys: Collection[str] | None = None) -> tuple[dict, dict]:
    """``(meta, arrays)`` of a record (only ``keys``' arrays when given; :func:`read_npz`)."""
    try:
        meta, _, arrays = read_npz(info.path, load=True, keys=keys)
    except (zipfile.BadZipFile, ValueError, OSError, KeyError, SyntaxError, struct.error, TypeError) as exc:
        raise InputFileError(
            info.path, f"is not a readable pair record .npz ({exc})", "re-run the pairs stage for this pair"
        ) from exc
    if meta is None:
        raise InputFileError(info.path, "changed while the store was written", _CHANGED_FIX)
    meta.setdefault("schema_version", SCHEMA_VERSION)  # as PairRecord gives it
    return meta, arrays


def _add_arrays(info: RecordInfo, arrays: dict, sinks: dict, layout: dict) -> None:
    """A record's rows of each sink's key, as the store keeps them (index keys narrowed, checked)."""
    for key, sink in sinks.items():
        value = arrays.get(key)
        if value is None or value.shape != info.shapes[key][0] or value.dtype != info.shapes[key][1]:
            raise InputFileError(info.path, "changed while the store was written", _CHANGED_FIX)
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


def _add_record(
    info: RecordInfo, sinks: dict, layout: dict, metas: list, rows: list, index: int, keys: Collection[str] | None
) -> None:
    """A record's rows into ``sinks``, its meta and table row into ``metas`` and ``rows``; ``keys``: the
    arrays to read (None: all of them, which the sinks then are)."""
    meta, arrays = _read_record(info, None if keys is None else {*keys, "x_overlap", "y_overlap"})
    _add_arrays(info, arrays, sinks, layout)
    if "x_overlap" not in arrays or "y_overlap" not in arrays:
        raise InputFileError(info.path, "changed while the store was written", _CHANGED_FIX)
    metas.append(meta)
    rows.append(
        table_row(
            index,
            meta,
            info.shapes["x_vertices"][0][0],
            info.shapes["y_vertices"][0][0],
            arrays["x_overlap"],
            arrays["y_overlap"],
        )
    )


def is_becos_store(folder: str | Path) -> bool:
    """True when ``folder`` holds a becos store's root metadata: a ``zarr.json`` whose attributes carry
    ``becos_store`` (any store format, damaged arrays or not). :func:`write_store` replaces such a
    folder without asking, since rewriting its store is what the workflow does."""
    try:
        meta = json.loads((Path(folder) / "zarr.json").read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    attrs = meta.get("attributes") if isinstance(meta, dict) else None
    return isinstance(attrs, dict) and isinstance(attrs.get("becos_store"), dict)


def _listing(folder: Path, limit: int = 5) -> str:
    """The first ``limit`` entries of a folder (folders with a trailing ``/``) and how many there are."""
    names = sorted(e.name + ("/" if e.is_dir() else "") for e in os.scandir(folder))
    shown = ", ".join(names[:limit]) + (", ..." if len(names) > limit else "")
    return f"{shown} ({len(names)} entries)" if len(names) > limit else shown


def check_out_folder(out: str | Path, inputs: Iterable[str | Path], *, overwrite: bool = False) -> None:
    """Refuse an ``out`` that :func:`write_store` must not replace, before anything is written.

    ``out`` may be absent, an empty folder or a becos store (:func:`is_becos_store`, replaced as
    the workflow does); anything else only with ``overwrite``, since replacing it deletes what it
    holds. Never when one of ``inputs`` (records, index files, metadata) lies inside ``out``, with
    or without ``overwrite``: the export would delete its own inputs.

    Raises:
        InputFileError: naming ``out``, what it holds and the fix.
    """
    out = Path(out)
    if not (out.exists() or out.is_symlink()):
        return
    homes = {Path(os.path.abspath(out)), out.resolve()}
    inside = []
    for path in dict.fromkeys(map(Path, inputs)):  # the path as given (a link inside out) and its target
        if any(p.is_relative_to(h) for p in (Path(os.path.abspath(path)), path.resolve()) for h in homes):
            inside.append(path)
    store, is_dir = is_becos_store(out), out.is_dir() and not out.is_symlink()
    empty = is_dir and next(os.scandir(out), None) is None
    elsewhere = "choose another --out (a new or empty folder, or a becos store)"
    if inside and (overwrite or store):
        more = f" and {len(inside) - 1} more" if len(inside) > 1 else ""
        raise InputFileError(
            out,
            f"holds inputs of this export ({inside[0]}{more}): replacing the folder would delete them",
            f"{elsewhere}, or move the inputs out of it first",
        )
    if store or empty or overwrite:
        return
    held = f"a folder holding {_listing(out)}" if is_dir else "a file or link"
    if inside:
        held += f" (among them inputs of this export: {inside[0]})"
        fix = f"{elsewhere}; --force replaces such a folder, deleting what it holds, once no input lies inside it"
    else:
        fix = f"{elsewhere}, or pass --force to replace it, deleting what it holds"
    raise InputFileError(
        out, f"is not a becos store but {held}, and export-zarr replaces the --out folder as a whole", fix
    )


def write_store(
    record_paths: Iterable[str | Path],
    out: str | Path,
    *,
    setting: str,
    metadata: Mapping | None = None,
    progress: bool = True,
    overwrite: bool = False,
    protect: Iterable[str | Path] = (),
    processes: int = 1,
) -> Path:
    """One Zarr v3 store per setting: every PairRecord concatenated per key (+ offsets), a pairs table,
    metadata. Written to a temp dir then renamed (atomic).

    Args:
        record_paths: pair record .npz files (:meth:`becos.build.record.PairRecord.save`), any order; each
            pair_id once, every record of ``setting`` and of this schema version.
        out: the store folder (``*.zarr``); an existing becos store or empty folder there is replaced,
            anything else only with ``overwrite`` (:func:`check_out_folder`).
        setting: full_full | partial_full | partial_partial.
        metadata: JSON-able extra root attributes (``config_hash``, ``config``, ``datasets`` ...);
            a ``setting`` in it must equal ``setting``.
        progress: print progress to stderr (about every 10 % for 50 records or more).
        overwrite: replace an ``out`` that is not a becos store (deleting what it holds).
        protect: further input files (index files, metadata) that ``out`` must not hold, besides
            ``record_paths``.
        processes: 2 lets a second process fill about half of the arrays of a store of more than
            :data:`SECOND_PROCESS_BYTES` (each array has one writer); the same store as with 1.

    Returns:
        ``out`` as a Path. Raises :class:`InputFileError` naming the offending record file.
    """
    out = Path(out)
    metadata = _store_metadata(metadata, setting)
    started = time.perf_counter()
    paths = [Path(p) for p in record_paths]
    if not paths:
        raise BecosError(f"{out}: no pair records given. Fix: pass record .npz files or chunk index files")
    check_out_folder(out, [*protect, *paths], overwrite=overwrite)  # the files named first
    infos = _scan_records(paths, setting)
    layout, lengths = _plan_layout(infos)
    n = len(infos)
    if progress and n >= 50:
        _progress(f"{n} records scanned in {time.perf_counter() - started:.1f} s")

    out.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(out.parent, [out.name])  # one job writes a store: these are a killed write's
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp"))
    try:
        _fill_store(tmp, infos, layout, lengths, setting, metadata, progress, started, processes)
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


def _store_metadata(metadata: Mapping | None, setting: str) -> dict:
    """``metadata`` as JSON would give it back, checked against ``setting``."""
    if setting not in SETTINGS:
        raise BecosError(f"setting must be one of {SETTINGS}, got {setting!r}")
    metadata = json.loads(json.dumps(dict(metadata or {}), default=str))
    if metadata.get("setting", setting) != setting:
        raise BecosError(
            f"the store metadata says setting {metadata['setting']!r} but --setting is {setting!r}. "
            "Fix: pass the metadata file of the same setting"
        )
    return metadata


def _scan_records(paths: list[Path], setting: str) -> list:
    """:func:`scan_record` of each file, in store order; each pair once, each of ``setting``."""
    infos = []
    seen: dict[str, Path] = {}
    for path in paths:
        info = scan_record(path)
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
    return infos


def _fill_store(
    tmp: Path, infos: list, layout: dict, lengths: dict, setting, metadata, progress, started, processes: int = 1
) -> None:
    """Write the store of ``infos`` (in that order) into the new folder ``tmp``: offsets, arrays, pairs
    table and root attributes (``metadata`` plus what the store is); ``processes`` 2: a second process
    fills about half of the arrays (:func:`_second_process_keys`)."""
    import zarr

    n = len(infos)
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
    created = {
        key: _create_array(arrays, key, group, first[key][0], disk[key], n, lengths) for key, group in layout.items()
    }
    other = _second_process_keys(created, processes)
    writer = _Writer()
    sinks = {
        key: _Sink(array, tmp / "arrays" / key, writer, digests, f"arrays/{key}")
        for key, array in created.items()
        if key not in other
    }
    from becos.process_split import in_second_process

    beside = in_second_process(_fill_keys, str(tmp), infos, other, layout) if other else contextlib.nullcontext()
    with beside as theirs:
        metas, rows = _copy_records(infos, sinks, layout, writer, progress, started, None if not other else list(sinks))
        if theirs is not None:
            digests.merge(theirs.result())
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


def _create_array(arrays, key: str, group, shape, dtype, n: int, lengths: dict):
    """The array ``key`` of the store, empty (every pair's rows; ``group`` None: one stacked row per pair,
    of ``shape``)."""
    total = n if group is None else int(lengths[group].sum())
    row_shape = shape if group is None else shape[1:]
    chunks, shards = _chunking(
        total, row_shape, dtype.itemsize, CHUNK_BYTES if group is not None else STACKED_CHUNK_BYTES
    )
    return arrays.create_array(
        key,
        shape=(total, *row_shape),
        dtype=dtype,
        chunks=chunks,
        shards=shards,
        compressors=_compressors(),
        fill_value=np.zeros((), dtype).item(),
        chunk_key_encoding=CHUNK_KEYS,
        config=ARRAY_CONFIG,
    )


def _shard_rows(array) -> int:
    """Rows of one shard of a store array (of one chunk when it has no shards): the unit a sink writes."""
    return (array.shards or array.chunks)[0]


@contextlib.contextmanager
def _filling(sinks: dict, writer: _Writer):
    """Around feeding ``sinks``: closes them and waits for ``writer``'s writes after the block; after an
    error, drops the writes still queued."""
    try:
        yield
        for sink in sinks.values():
            sink.close()
    except BaseException:
        writer.finish(failed=True)
        raise
    writer.finish()


def _second_process_keys(arrays: Mapping[str, object], processes: int) -> list[str]:
    """The keys a second process fills: about half of the bytes, the largest arrays dealt alternately
    to the lighter side (in a fixed order); none for one process or a small store."""
    nbytes = {key: int(np.prod(a.shape)) * a.dtype.itemsize for key, a in arrays.items()}
    if processes < 2 or sum(nbytes.values()) <= SECOND_PROCESS_BYTES:
        return []
    sides: tuple[list[str], list[str]] = ([], [])
    load = [0, 0]
    for key in sorted(nbytes, key=lambda k: (-nbytes[k], k)):
        side = 0 if load[0] <= load[1] else 1
        sides[side].append(key)
        load[side] += nbytes[key]
    return sides[1]


def _fill_keys(tmp: str, infos: list, keys: list[str], layout: dict) -> dict[str, str]:
    """The second process's part of :func:`_fill_store`: the arrays ``keys`` of the store being written
    in ``tmp`` (created empty by the first), from every record; returns their content digests."""
    import zarr

    group = zarr.open_group(str(Path(tmp) / "arrays"), mode="r+")
    arrays = {key: group[key].with_config(ARRAY_CONFIG) for key in keys}  # the config is not stored
    digests = ContentDigests({f"arrays/{key}": a.dtype for key, a in arrays.items()})
    writer = _Writer()
    sinks = {key: _Sink(a, Path(tmp) / "arrays" / key, writer, digests, f"arrays/{key}") for key, a in arrays.items()}
    with _filling(sinks, writer):
        for info in infos:
            _add_arrays(info, _read_record(info, keys)[1], sinks, layout)
    return digests.hexdigests()


def _copy_records(
    infos: list, sinks: dict, layout: dict, writer, progress, started, keys: list[str] | None = None
) -> tuple[list, list]:
    """Every record's arrays into ``sinks`` (closed, and ``writer`` finished, at the end); returns the
    pair metas and table rows. ``keys``: the arrays to read (the sinks'; None: every array)."""
    n = len(infos)
    metas, rows = [], []
    step = max(1, math.ceil(n / 10))
    with _filling(sinks, writer):
        for i, info in enumerate(infos):
            _add_record(info, sinks, layout, metas, rows, i, keys)
            if progress and n >= 50 and ((i + 1) % step == 0 or i + 1 == n):
                _progress(f"{i + 1}/{n} records read ({time.perf_counter() - started:.1f} s)")
    return metas, rows


def _replace_dir(tmp: Path, out: Path) -> None:
    """Move the finished ``tmp`` folder to ``out``; an old ``out`` is moved aside first, then deleted."""
    old = None
    if out.exists() or out.is_symlink():
        old = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".old"))
        os.replace(out, old / "store")
    os.replace(tmp, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
