"""Pair record files (``.npz`` of :class:`becos.build.record.PairRecord`) as the store writer reads them: keys,
shapes and dtypes from the zip's ``.npy`` headers without loading the arrays (:func:`read_npz`), and
the index files that list a chunk's records (:func:`read_record_index`, :func:`expand_inputs`)."""

from __future__ import annotations

import ast
import hashlib
import io
import json
import math
import re
import struct
import zipfile
import zlib
from collections.abc import Collection, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from becos.build.record import (
    IDENTITY_MEMBER,
    RECORD_KEYS,
    RECORD_SCHEMA,
    SCHEMA_VERSION,
    decode_arrays,
)
from becos.build.record_sources import DERIVED_MEMBER, derive, derived_shapes, needed_keys, read_derived
from becos.errors import InputFileError


@dataclass
class RecordInfo:
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


def _data_offset(fh, info: zipfile.ZipInfo) -> int:
    """File offset of a zip member's (possibly compressed) bytes, past its local header."""
    fh.seek(info.header_offset)
    local = _LOCAL_HEADER.unpack(fh.read(_LOCAL_HEADER.size))
    if local[0] != b"PK\x03\x04":
        raise ValueError(f"bad zip member header of {info.filename}")
    return info.header_offset + _LOCAL_HEADER.size + local[9] + local[10]


def _inflate(fh, info: zipfile.ZipInfo) -> io.BytesIO:
    """A deflated member's bytes, inflated in one call rather than through zipfile's stream of small
    reads, and checked against the zip's size and CRC as zipfile checks them."""
    fh.seek(_data_offset(fh, info))
    try:
        data = zlib.decompress(fh.read(info.compress_size), -zlib.MAX_WBITS, info.file_size)
    except zlib.error as exc:
        raise ValueError(f"member {info.filename} cannot be inflated ({exc})") from exc
    if len(data) != info.file_size or zlib.crc32(data) != info.CRC:
        raise ValueError(f"member {info.filename} is damaged (size or CRC differs from the zip's record)")
    return io.BytesIO(data)


def read_npz(
    path: Path, load: bool, keys: Collection[str] | None = None
) -> tuple[dict, dict[str, tuple[tuple[int, ...], np.dtype]], dict]:
    """``(meta, {key: (shape, dtype)}, {key: array})`` of a record .npz (arrays only when ``load``), as
    :meth:`PairRecord.load` gives them (:func:`becos.build.record.decode_arrays`: widened, identity maps derived).
    ``keys``: load only these arrays (None: all); the shapes are those of every array either way.

    Uncompressed members (``np.savez``, what :meth:`PairRecord.save` writes for float arrays) are
    read straight from the file at their offset: no zip CRC pass, one copy. Deflated ones are inflated
    whole when loaded (:func:`_inflate`), else only their header is read through the zip stream.
    """
    shapes, arrays, meta, identity, derived = {}, {}, None, {}, {}
    special_members = ("__meta__", IDENTITY_MEMBER, DERIVED_MEMBER)
    reading = None if keys is None else set(keys)  # the keys whose data is read: ``keys`` and what they derive from
    with open(path, "rb") as fh, zipfile.ZipFile(fh) as z:
        members = sorted(z.infolist(), key=lambda i: i.filename[:-4] not in special_members)  # the JSON ones first
        for info in members:
            if not info.filename.endswith(".npy"):
                continue
            key = info.filename[:-4]
            special = key in special_members
            wanted = special or (load and (reading is None or key in reading))  # its data is read, not only its header
            stored = info.compress_type == zipfile.ZIP_STORED
            if stored:
                fh.seek(_data_offset(fh, info))
                src = fh
            elif info.compress_type == zipfile.ZIP_DEFLATED and wanted:
                src = _inflate(fh, info)
            else:
                src = z.open(info)
            try:
                shape, dtype, fortran = _npy_header(src)
                if not special:
                    shapes[key] = (shape, dtype)
                if not wanted:
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
            elif key == DERIVED_MEMBER:
                derived = read_derived(data)
                if reading is not None:
                    reading |= needed_keys(derived, reading)
            else:
                arrays[key] = data
    for key, n in identity.items():  # the record's own dtypes and shapes (decode_arrays)
        shapes[key] = ((int(n),), np.dtype(RECORD_SCHEMA[key].dtype))
    for key, (shape, dtype) in shapes.items():
        f = RECORD_SCHEMA.get(key)
        if f is not None and f.stored is not None and dtype == np.dtype(f.stored):
            shapes[key] = (shape, np.dtype(f.dtype))
    shapes.update(derived_shapes(derived))
    if not load:
        return meta, shapes, arrays
    if reading is not None:
        identity = {key: n for key, n in identity.items() if key in reading}
    decoded = decode_arrays(arrays, identity)
    if derived:
        decoded.update(derive(path, derived, decoded, meta, keys))
    return meta, shapes, decoded if keys is None else {key: v for key, v in decoded.items() if key in keys}


def scan_record(path: Path) -> RecordInfo:
    """Meta and the (shape, dtype) of every array of a record .npz, reading only the .npy headers."""
    fix = "give pair records written by becos (PairRecord.save, the workflow's pairs stage)"
    if not path.is_file():
        raise InputFileError(
            path,
            "pair record not found",
            "check the path (index paths are relative to the current directory) or re-run the pairs stage",
        )
    try:
        meta, shapes, _ = read_npz(path, load=False)
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
    return RecordInfo(path, meta, shapes)


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
