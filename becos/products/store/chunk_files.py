"""A store array's chunk files read and written straight, beside zarr's own pipeline: :class:`ChunkFiles`
(rows read with one ``pread`` and one Blosc decode per inner chunk touched; whole shards written as zarr
writes them, byte for byte). Why, measured: docs/design/store.md."""

from __future__ import annotations

import math
import os
import struct
from pathlib import Path

import numpy as np

EMPTY_CHUNK = 2**64 - 1
"""A shard index's (offset, nbytes) of an inner chunk that holds nothing (read as the fill value)."""


class ChunkFiles:
    """Rows of one store array, straight from and to its chunk files.

    :meth:`read` gives rows ``a:b``: one ``pread`` and one Blosc decode per inner chunk touched, shard
    indexes read once and kept. Zarr's own read path costs ~1.4 ms of CPU per array and read (its
    asyncio pipeline), ~65 ms for the ~50 arrays of one record; this reads a record in a few ms
    (``benchmarks/store.py``). :meth:`write` writes whole shards (each inner chunk Blosc-encoded, then
    the shard index and its crc32c), the bytes zarr writes for them in about half zarr's CPU time.

    Both handle exactly what :func:`~becos.products.store.write.write_store` creates (chunks along axis 0,
    codecs bytes + Blosc, optionally sharded with the index at the end); :attr:`usable` (reading) and
    :attr:`writable` are False for anything else, and the caller goes through zarr. A read problem raises
    ``ValueError``/``OSError`` (the caller then re-reads through zarr, which reports it as before)."""

    def __init__(self, folder: Path, array):
        from zarr.codecs import BloscCodec, BytesCodec, Crc32cCodec, ShardingCodec

        meta = array.metadata
        self.folder = Path(folder)
        self.dtype = np.dtype(array.dtype)
        self.shape = tuple(meta.shape)
        self.row_shape = self.shape[1:]
        self.outer = int(meta.chunk_grid.chunk_shape[0])
        self.sep = getattr(meta.chunk_key_encoding, "separator", "/")
        self.fill_value = meta.fill_value
        codecs = list(meta.codecs)
        self.inner, self.per_shard = self.outer, 0
        index_ok = True
        if len(codecs) == 1 and isinstance(codecs[0], ShardingCodec):
            shard = codecs[0]
            end = str(getattr(shard.index_location, "value", shard.index_location)) == "end"
            self.inner = int(shard.chunk_shape[0])
            self.per_shard = self.outer // self.inner
            codecs = list(shard.codecs) if end and tuple(shard.chunk_shape[1:]) == self.row_shape else []
            index = list(shard.index_codecs)
            index_ok = (
                len(index) == 2
                and isinstance(index[0], BytesCodec)
                and str(getattr(index[0].endian, "value", index[0].endian)) == "little"
                and isinstance(index[1], Crc32cCodec)
            )
        self.usable = (
            len(codecs) == 2
            and isinstance(codecs[0], BytesCodec)
            and isinstance(codecs[1], BloscCodec)
            and tuple(meta.chunk_grid.chunk_shape[1:]) == self.row_shape
            and self.dtype.isnative
            and meta.dimension_names is None
            and self.sep in (".", "/")
            and getattr(meta.chunk_key_encoding, "name", "") == "default"
        )
        self.writable = (
            self.usable
            and index_ok
            and self.sep == "."  # write_store's flat chunk files: no folders to make
            and self.outer % self.inner == 0
            and (np.little_endian or self.dtype.itemsize == 1)
            and str(getattr(codecs[0].endian, "value", codecs[0].endian)) in ("little", "None")
            and array.config.write_empty_chunks  # zarr would leave all-fill chunks out
            and array.config.order == "C"
        )
        self._encoder = _blosc_encoder(codecs[1]) if self.writable else None
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
        """Rows ``a:b`` as a new array."""
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
                    if offset == EMPTY_CHUNK:
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

    def write(self, start: int, data: np.ndarray) -> None:
        """Rows ``start : start + len(data)`` into a new array's files, whole chunk files at a time:
        ``start`` is the first row of a chunk file (a shard, or a chunk when unsharded) and the rows end
        at the end of one, or at the array's end (the last inner chunk is padded with the fill value, the
        inner chunks past the end are left empty, as zarr leaves them). Only where :attr:`writable`."""
        if not self.writable:
            raise ValueError(f"{self.folder}: not a layout ChunkFiles writes")
        stop = start + len(data)
        if start % self.outer or (stop % self.outer and stop != self.shape[0]) or stop > self.shape[0]:
            raise ValueError(f"{self.folder}: rows {start}:{stop} are not whole chunk files")
        data = np.ascontiguousarray(data, dtype=self.dtype)
        encoder = self._encoder
        for first in range(start, stop, self.outer):
            block = data[first - start : first - start + self.outer]
            chunks = [block[i : i + self.inner] for i in range(0, len(block), self.inner)]
            if len(chunks[-1]) < self.inner:
                padded = np.full((self.inner, *self.row_shape), self.fill_value, dtype=self.dtype)
                padded[: len(chunks[-1])] = chunks[-1]
                chunks[-1] = padded
            encoded = [encoder.encode(chunk) for chunk in chunks]
            if self.per_shard:
                sizes = np.array([len(e) for e in encoded], dtype="<u8")
                index = np.full((self.per_shard, 2), EMPTY_CHUNK, dtype="<u8")
                index[: len(encoded), 0] = np.cumsum(sizes) - sizes  # each chunk's start in the file
                index[: len(encoded), 1] = sizes
                encoded.append(index.tobytes() + struct.pack("<I", _crc32c(index.tobytes())))
            self._file(first // self.outer).write_bytes(b"".join(encoded))


def _blosc_encoder(codec):
    """The numcodecs ``Blosc`` that zarr encodes with for the store array's ``BloscCodec``."""
    from numcodecs import Blosc

    shuffle = {"noshuffle": Blosc.NOSHUFFLE, "shuffle": Blosc.SHUFFLE, "bitshuffle": Blosc.BITSHUFFLE}
    return Blosc(
        cname=str(getattr(codec.cname, "value", codec.cname)),
        clevel=int(codec.clevel),
        shuffle=shuffle[str(getattr(codec.shuffle, "value", codec.shuffle))],
        blocksize=int(codec.blocksize),
        typesize=int(codec.typesize),
    )


def _crc32c(data: bytes) -> int:
    import google_crc32c  # zarr's own checksum of shard indexes

    return int(google_crc32c.value(data))
