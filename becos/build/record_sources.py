"""Record members a pair record file leaves out because the files it was made from give them back exactly.

A file written with :class:`RecordSources` (the workflow's pairs stage) leaves out each member of
:data:`DERIVATIONS` that its remesh files and ground-truth file give back byte for byte, and lists it in
the member ``__derived__`` (JSON): ``sources`` ``{"x" | "y" | "ground_truth": {"path", "sha256"}}`` (paths
relative to the record file's folder, SHA-256 of their bytes, 16 hex digits) and ``arrays`` ``{key:
{"dtype", "shape", "sha256"}}``. Readers (:meth:`becos.build.record.PairRecord.load`, the store writer)
make them again (:func:`derive`) and check both digests: a source changed after the pairs job stops
with an error naming the record and the source, instead of reaching the store.
"""

from __future__ import annotations

import io
import json
import os
from collections import OrderedDict
from collections.abc import Callable, Collection
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from becos.build.placement import place_side
from becos.digests import bytes_digest, content_digest
from becos.errors import InputFileError

DERIVED_MEMBER = "__derived__"
"""Record-file member: JSON of the members left out and the files they come from."""
SOURCE_CACHE_BYTES = 32 * 2**20
"""Bytes of remesh arrays a process keeps between records: the pairs job visits a chunk shape by shape,
so a few dozen files serve it; in the store's order (split, pair id) a cache this size is rarely hit at
full size, where it would otherwise grow the job's memory by what it holds."""
_FIX = (
    "rebuild the pair records: snakemake --forcerun pairs (becos rewrites exactly the records whose "
    "inputs changed), then run snakemake again"
)


@dataclass(frozen=True)
class RecordSources:
    """The files a pair record was made from (None: a side not remeshed, or no ground-truth file), and
    ``digests`` (:func:`becos.digests.bytes_digest`) of those the caller has already hashed (x, y,
    ground_truth), which are then not hashed again."""

    x: Path | None = None
    y: Path | None = None
    ground_truth: Path | None = None
    digests: dict[str, str] = field(default_factory=dict)

    def items(self) -> list[tuple[str, Path]]:
        return [(name, Path(p)) for name, p in (("x", self.x), ("y", self.y), ("ground_truth", self.ground_truth)) if p]


@dataclass(frozen=True)
class Derivation:
    """How one record member is made from a source (``source``: x, y or ground_truth): ``make(source
    arrays, record arrays, meta)``; ``needs``: the record keys it reads."""

    source: str
    needs: tuple[str, ...]
    make: Callable[[dict, dict, dict], np.ndarray]


def _side_derivations(s: str) -> dict[str, Derivation]:
    placement = (f"{s}_full_area", f"{s}_align_rotation", f"{s}_align_translation", f"{s}_random_rotation")
    return {
        f"{s}_faces": Derivation(
            s,
            (f"{s}_full_to_partial", f"{s}_full_face_ids"),
            lambda src, a, m: a[f"{s}_full_to_partial"][src["faces"][a[f"{s}_full_face_ids"]]],
        ),
        f"{s}_vertices": Derivation(
            s,
            (f"{s}_partial_to_full", *placement),
            lambda src, a, m: place_side(src["vertices"][a[f"{s}_partial_to_full"]], a, m, s),
        ),
        f"{s}_full_faces": Derivation(s, (), lambda src, a, m: src["faces"]),
        f"{s}_full_vertices": Derivation(s, placement, lambda src, a, m: place_side(src["vertices"], a, m, s)),
    }


def _map_derivations(name: str, direction: str) -> dict[str, Derivation]:
    return {
        f"{name}_face": Derivation("ground_truth", (), lambda src, a, m: src[f"{direction}_face"]),
        f"{name}_weights": Derivation("ground_truth", (), lambda src, a, m: src[f"{direction}_weights"]),
    }


DERIVATIONS: dict[str, Derivation] = {
    **_side_derivations("x"),
    **_side_derivations("y"),
    **_map_derivations("corr_01", "xy"),
    **_map_derivations("corr_10", "yx"),
}
"""Record key -> :class:`Derivation`: the one definition of the members a record file may leave out
(``s`` is x or y; ``R``: the side's remesh file, common frame at dataset scale; ``place``:
:func:`becos.build.placement.place_side`, the pairs stage's own placement):

==================  ==========================================================================
``s_faces``         ``s_full_to_partial[R.faces[s_full_face_ids]]``
``s_vertices``      ``place(R.vertices[s_partial_to_full])``
``s_full_faces``    ``R.faces`` (a partial side; a full side's is empty and kept)
``s_full_vertices`` ``place(R.vertices)`` (likewise)
``corr_01_face``    the ground-truth file's ``xy_face`` (full-to-full; ``corr_10_face``: ``yx_face``)
``corr_01_weights`` its ``xy_weights`` (``corr_10_weights``: ``yx_weights``)
==================  ==========================================================================

A member is left out only where the derivation gives the record's array byte for byte."""


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return (
        a.dtype == b.dtype
        and a.shape == b.shape
        and np.ascontiguousarray(a).tobytes() == np.ascontiguousarray(b).tobytes()
    )


class _SourceCache:
    """Source files' digests, and remesh files' arrays, the most recently used up to
    :data:`SOURCE_CACHE_BYTES` (a ground-truth file serves one pair: parsed each time). Keyed by the file's
    path, size, mtime and inode, so a file replaced on disk is read again; a file whose digest is known
    is parsed without being hashed again."""

    def __init__(self, limit: int = SOURCE_CACHE_BYTES):
        self.limit, self.used = limit, 0
        self.digests: dict[tuple, str] = {}
        self.arrays: OrderedDict[tuple, tuple[dict[str, np.ndarray], int]] = OrderedDict()

    def get(
        self, source: str, path: Path, expected: str | None = None, known: str | None = None
    ) -> tuple[str, dict[str, np.ndarray] | None]:
        """``(digest, arrays)`` of the file of ``source`` (x, y or ground_truth) at ``path``; arrays None
        when its digest is not ``expected`` (then the file is not parsed). ``known``: its digest, already
        taken by the caller."""
        st = path.stat()
        key = (str(path.resolve()), st.st_size, st.st_mtime_ns, st.st_ino)
        if known is not None:
            self.digests.setdefault(key, known)
        if key in self.arrays:
            self.arrays.move_to_end(key)
            return self.digests[key], self.arrays[key][0]
        if key in self.digests:
            sha, file = self.digests[key], path
        else:
            data = path.read_bytes()
            sha, file = bytes_digest(data), io.BytesIO(data)
            self.digests[key] = sha
        if expected is not None and sha != expected:
            return sha, None
        arrays = _read_source(source, file)
        if source != "ground_truth":
            size = sum(a.nbytes for a in arrays.values())
            self.arrays[key] = (arrays, size)
            self.used += size
            while self.used > self.limit and len(self.arrays) > 1:
                _, (_, dropped) = self.arrays.popitem(last=False)
                self.used -= dropped
        return sha, arrays


_SOURCE_MEMBERS = {
    "ground_truth": ("xy_face", "xy_weights", "yx_face", "yx_weights"),  # becos.build.ground_truth_file
    "remesh": ("vertices", "faces"),  # becos.build.remesh.files
}


def _read_source(source: str, file: io.BytesIO | Path) -> dict[str, np.ndarray]:
    """The arrays of a source file (its bytes or its path) that derivations read, as the pairs stage held
    them (:class:`becos.core.surface_map.SurfaceMap` and :class:`becos.core.mesh.TriMesh`: contiguous int64
    indices, float64 values); only these members are read."""
    with np.load(file, allow_pickle=False) as d:
        return {
            key: np.ascontiguousarray(d[key], dtype=np.int64 if key.endswith(("face", "faces")) else np.float64)
            for key in _SOURCE_MEMBERS["ground_truth" if source == "ground_truth" else "remesh"]
        }


_CACHE = _SourceCache()


def leave_out(arrays: dict[str, np.ndarray], meta: dict, sources: RecordSources, folder: Path) -> dict:
    """The ``__derived__`` description of the members of ``arrays`` that ``sources`` give back byte for
    byte (to be left out of the record file written into ``folder``); ``{}`` when none."""
    loaded = {name: (path, *_CACHE.get(name, path, known=sources.digests.get(name))) for name, path in sources.items()}
    left_out = {}
    for key, d in DERIVATIONS.items():
        if d.source not in loaded or key not in arrays or arrays[key].size == 0:  # an empty member costs nothing
            continue
        try:
            made = d.make(loaded[d.source][2], arrays, meta)
        except (IndexError, KeyError, ValueError):  # a source that does not fit the record: keep the member
            continue
        if _same(made, arrays[key]):
            value = arrays[key]
            left_out[key] = {
                "dtype": value.dtype.str,
                "shape": list(value.shape),
                "sha256": content_digest({key: value}, {}),
            }
    if not left_out:
        return {}
    used = {DERIVATIONS[key].source for key in left_out}
    return {
        "sources": {
            name: {"path": os.path.relpath(os.path.abspath(path), os.path.abspath(folder)), "sha256": sha}
            for name, (path, sha, _) in loaded.items()
            if name in used
        },
        "arrays": left_out,
    }


def derived_shapes(derived: dict) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """``{key: (shape, dtype)}`` of the members a ``__derived__`` description lists."""
    return {key: (tuple(spec["shape"]), np.dtype(spec["dtype"])) for key, spec in derived.get("arrays", {}).items()}


def needed_keys(derived: dict, keys: Collection[str]) -> set[str]:
    """The record keys the derivation of ``keys`` (those of them ``derived`` lists) reads."""
    listed = derived.get("arrays", {})
    return {need for key in keys if key in listed for need in DERIVATIONS[key].needs}


def derive(record_path: Path, derived: dict, arrays: dict, meta: dict, keys: Collection[str] | None = None) -> dict:
    """The left-out members (``keys`` of them; None: all) of the record file ``record_path``, from its
    sources and its other members ``arrays`` (decoded) and ``meta``. Each source's digest and each made
    array's digest must be what the pairs stage recorded.

    Raises:
        InputFileError: naming the record file, the source and what differs.
    """
    listed = derived.get("arrays", {})
    wanted = [key for key in listed if keys is None or key in keys]
    folder = Path(record_path).parent
    out, loaded = {}, {}
    for key in wanted:
        d = DERIVATIONS.get(key)
        source = derived.get("sources", {}).get(d.source) if d is not None else None
        if source is None:
            raise InputFileError(record_path, f"lists the left-out member {key!r} without its source", _FIX)
        if d.source not in loaded:
            path = Path(os.path.normpath(folder / source["path"]))
            what = "ground-truth file" if d.source == "ground_truth" else f"remesh file of shape {d.source}"
            if not path.is_file():
                raise InputFileError(
                    record_path, f"its {what} {path} is missing (the record leaves out members it gives)", _FIX
                )
            sha, arrays_of_source = _CACHE.get(d.source, path, expected=source["sha256"])  # same bytes: they parse
            if arrays_of_source is None:
                raise InputFileError(
                    record_path,
                    f"its {what} {path} has changed since the record was written (digest {sha}, the record was "
                    f"made from {source['sha256']})",
                    _FIX,
                )
            loaded[d.source] = arrays_of_source
        value = d.make(loaded[d.source], arrays, meta)
        spec = listed[key]
        if content_digest({key: value}, {}) != spec["sha256"] or value.dtype != np.dtype(spec["dtype"]):
            raise InputFileError(
                record_path,
                f"its member {key!r}, made again from its sources, is not the array the pairs job left out",
                _FIX,
            )
        out[key] = value
    return out


def read_derived(member: np.ndarray) -> dict:
    """The ``__derived__`` member's JSON."""
    return json.loads(str(member))
