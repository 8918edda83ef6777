"""Reading a store (layout: :mod:`becos.products.store`): :func:`open_benchmark`, :class:`Benchmark`,
:class:`TrainingView`.

:meth:`Benchmark.record`, :meth:`Benchmark.records` and :class:`TrainingView` read the chunk files
directly (:class:`~becos.products.store.chunk_files.ChunkFiles`: per key one ``pread`` and one Blosc
decode per 64 KiB chunk touched);
:meth:`Benchmark.read_block` (``becos validate``, ``compare``) reads through zarr, and any problem falls
back to zarr, which reports it (:meth:`Benchmark.read_rows`). Why a hand-written reader (measured):
docs/design/store.md.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from becos.build.record import (
    RECORD_SCHEMA,
    SCHEMA_VERSION,
    PairRecord,
)
from becos.errors import BecosError, InputFileError
from becos.products.store.chunk_files import ChunkFiles
from becos.products.store.layout import STORE_FORMAT, TABLE_DTYPES, store_order_key

READ_BLOCK_BYTES = 64 << 20
"""Uncompressed bytes read at once by :meth:`Benchmark.blocks` / :meth:`Benchmark.records`."""


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
        widened to the record's dtypes (:func:`becos.build.record.decode_arrays`)."""
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


DRAIN_ROUNDS = 20
"""Most rounds :func:`_drain` waits for tasks started by a failed read (zarr nests its tasks a few deep)."""


async def _drain(tasks, before: set) -> None:
    """After one read of a concurrent batch failed: cancel the batch's other ``tasks`` and wait until
    they, and the tasks zarr started for them since ``before`` (its own ``gather`` leaves a failed
    array's other chunk reads running), have ended, so the error is raised alone.

    Left running, those tasks were destroyed pending at exit (``Task was destroyed but it is
    pending!``, about 60 times) and one of them failed to schedule a thread after interpreter
    shutdown (a ``RuntimeError`` traceback). Tasks started meanwhile by other threads on zarr's loop
    are waited for as well, never cancelled."""
    import asyncio

    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)  # retrieves their exceptions, too
    me = asyncio.current_task()
    for _ in range(DRAIN_ROUNDS):
        started = [t for t in asyncio.all_tasks() - before if t is not me and not t.done()]
        if not started:
            return
        await asyncio.wait(started)


class PairKeyError(BecosError, TypeError):
    """A pair asked for by something that is neither a row index (int) nor a pair_id (str)."""


class DamagedStoreError(InputFileError):
    """A store whose root opens but one of whose arrays, offsets or pair tables is missing or unreadable."""


DAMAGED_STORE_FIX = "re-export the store with `becos export-zarr` (it is damaged or was copied incompletely)"


def _rebuild_fix(store: Path, setting: object) -> str:
    """How to rewrite a store of an older format with this becos: rerun its workflow job, or export the
    setting's pair records again (the workflow's layout: ``results/<setting>/benchmark.zarr`` beside
    ``pairs/chunk_*.json`` and ``metadata.json``, :class:`becos.workflow.layout.Layout`)."""
    setting = setting if isinstance(setting, str) and setting else "<setting>"
    folder = store.parent
    return (
        "rebuild it with this becos: in the run folder, `snakemake --cores 1 --forcerun zarr_store`; or from "
        f"the setting's pair records, `becos export-zarr --setting {setting} --out {store} "
        f"--metadata {folder / 'metadata.json'} {folder / 'pairs'}/chunk_*.json`"
    )


def _checked_store_info(path: Path, attrs: Mapping, fix: str) -> dict:
    """The ``becos_store`` attribute of a store's root ``attrs``, once its store format and record schema
    are the ones this becos reads (an InputFileError saying newer, older or not a store otherwise)."""
    info = attrs.get("becos_store")
    newer = "upgrade becos (pip install -U the becos checkout) to read it, or re-export the store with this becos"
    found = info.get("format") if isinstance(info, dict) else None
    if isinstance(found, int) and not isinstance(found, bool) and found > STORE_FORMAT:
        raise InputFileError(
            path,
            f"was written by a newer becos: store format {found}, this becos reads format {STORE_FORMAT}",
            newer,
        )
    if isinstance(found, int) and not isinstance(found, bool) and 0 < found < STORE_FORMAT:
        raise InputFileError(
            path,
            f"was written by an older becos: store format {found}, this becos reads format {STORE_FORMAT}",
            _rebuild_fix(path, attrs.get("setting")),
        )
    if not isinstance(info, dict) or found != STORE_FORMAT:
        raise InputFileError(path, f"is not a becos benchmark store of format {STORE_FORMAT}", fix)
    schema = attrs.get("schema_version")
    if isinstance(schema, int) and not isinstance(schema, bool) and schema > SCHEMA_VERSION:
        raise InputFileError(
            path,
            f"was written by a newer becos: record schema {schema}, this becos reads {SCHEMA_VERSION}",
            newer,
        )
    if attrs.get("schema_version") != SCHEMA_VERSION:
        raise InputFileError(
            path,
            f"holds record schema {attrs.get('schema_version')}, this becos reads {SCHEMA_VERSION}",
            "re-export the store with this becos version",
        )
    return info


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
        info = _checked_store_info(self.path, attrs, fix)
        self._root = root
        self._files: dict[str, ChunkFiles] | None = None
        self._stamp = self._identity()
        self.metadata = {k: v for k, v in attrs.items() if k != "becos_store"}
        self.setting = attrs["setting"]
        self.layout: dict[str, str | None] = dict(info["layout"])
        self.content_digests: dict[str, str] = dict(info.get("sha256") or {})
        """Node name -> sha256 of its content when written (:class:`ContentDigests`); empty for stores
        written before becos recorded them."""
        frame = self._read_nodes(root)
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

    def _read_nodes(self, root):
        """Open the array nodes, read the offsets and the pair metas' offsets; returns the pairs table as
        read (a missing or damaged node is a :class:`DamagedStoreError` naming it, not a traceback)."""
        import pandas as pd

        node = "arrays"
        try:
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
            return pd.DataFrame(table["rows"], columns=table["columns"])
        except Exception as exc:
            raise DamagedStoreError(
                self.path, f"{node} is missing or unreadable ({type(exc).__name__}: {exc})", DAMAGED_STORE_FIX
            ) from exc

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
        (:class:`~becos.products.store.chunk_files.ChunkFiles`: a few ms per pair where zarr's pipeline
        takes ~65 ms); falls back to :meth:`read_block` (zarr) for a layout it does not read and for any
        problem, which zarr then reports as a :class:`DamagedStoreError`."""
        if self._files is None:
            files = {key: ChunkFiles(self.path / "arrays" / key, a) for key, a in self._arrays.items()}
            files["pairs/meta_json"] = ChunkFiles(self.path / "pairs" / "meta_json", self._meta_json)
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
            before = asyncio.all_tasks()
            tasks = [asyncio.ensure_future(array.async_array.getitem(slice(a, b))) for array, a, b in ranges]
            try:
                return await asyncio.gather(*tasks)
            except BaseException:
                await _drain(tasks, before)
                raise

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
    dict of plain numpy arrays (record keys as in :data:`becos.build.record.RECORD_SCHEMA`, index keys
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
