"""Exports of a benchmark in layouts that existing matching code already reads.

Writers, each taking an iterable of :class:`~becos.record.PairRecord` (a store's
``Benchmark.records()``, or records loaded from ``.npz`` files), streaming them one at a time:

- :func:`write_released` -- the folder layout of the released BeCoS benchmark (the reference
  generator's output): ``<out>/<split>/<i>/`` with two OFF meshes, ``corres_*.npy`` and one info
  pickle per shape, as read by DeepShapeMatchingKit's ``BeCoSDataset`` and similar loaders.
- :func:`write_psmal` -- PSMAL (partial SMAL) style: ``<out>/<split>/shapes/<shape id>.off`` and
  ``<out>/<split>/maps/<A>_<B>.vts`` in both directions.
- :func:`write_ulrssm` -- ULRSSM style: one ``off/``, ``corres/*.vts`` (template convention) and
  optional ``dist/*.mat`` root per pair.
- :func:`write_dpfm` -- DPFM style: ``shapes/*.off`` + ``maps/<A>_<B>.map`` with ids free of ``_``;
  only the directions without a ``-1`` row in ``maps/`` (the rest in ``maps_with_none/``).
- :func:`write_geodesic_matrices` -- (V, V) float32 geodesic matrices of every shape, measured on its
  FULL shape, where loaders read them (``geodesic_dist_matrices/<released stem>.npy``, ÷ sqrt-area);
  :func:`write_geodesics` the same for the PSMAL ids (``<out>/<split>/geodesics/<shape id>.npy``).
  Each distinct full mesh is solved once, in parallel processes.

The layouts, every file and key, which loader reads what, and where becos differs from the reference
(the swapped P2P masks) are documented in ``docs/released-layout.md``; this module follows it.

Numbering: pairs are numbered 0..N-1 per split in ascending ``pair_id`` order, whatever order the
records come in. Each export is written into a temporary folder beside ``out`` and renamed into
place at the end, so a reader never sees half an export (geodesics: per ``<split>/geodesics``).

Units and frames: vertices are written exactly as stored in the record (its final frame, dataset
scale unless the record is area-normalised), as shortest round-trip decimal strings, so that parsing
the text gives back the same float64 values.
"""

from __future__ import annotations

import csv
import datetime
import io
import json
import os
import pickle
import re
import shutil
import sys
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from becos.errors import BecosError, DiskFullError, InputFileError
from becos.record import SETTINGS, PairRecord, full_shape

LAYOUT_VERSION = 1
"""Version of the layouts written here (recorded in ``logs/config.yaml``)."""

PICKLE_PROTOCOL = 4
IDS_FILE = "ids.csv"
LOGS_DIR = "logs"
SIDES = (("x", 0), ("y", 1))
_STAGING = ".staging"
_PROGRESS_EVERY = 200
_SPLIT_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")


class ExportError(BecosError):
    """An export cannot be written as asked (existing output, inconsistent or duplicate records)."""


# --------------------------------------------------------------------------------------------------
# file formats


def off_text(vertices: np.ndarray, faces: np.ndarray) -> str:
    """OFF text: ``OFF``, ``nV nF 0``, one ``x y z`` line per vertex, one ``3 i j k`` line per face.

    Args:
        vertices: (V, 3) float positions, written as shortest round-trip decimal strings (numpy's
            float64 ``str``), so ``float(token)`` gives back the exact float64 value.
        faces: (F, 3) int 0-based vertex indices.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"OFF needs (V, 3) vertices and (F, 3) faces; got {v.shape} and {f.shape}")
    if not np.isfinite(v).all():
        raise ValueError("OFF vertices must be finite")
    return f"OFF\n{len(v)} {len(f)} 0\n" + _rows_text(v.astype(str)) + _rows_text(f.astype(str), lead="3 ")


def _rows_text(cells: np.ndarray, lead: str = "") -> str:
    """(N, C) strings -> N lines ``<lead>c0 c1 ... c(C-1)``, each ending in a newline (one join over
    an interleaved token array; no per-row Python code)."""
    n, c = cells.shape
    if n == 0:
        return ""
    offset = 1 if lead else 0
    tokens = np.empty((n, offset + 2 * c), dtype=object)
    if lead:
        tokens[:, 0] = lead
    tokens[:, offset::2] = cells
    tokens[:, offset + 1 :: 2] = [" "] * (c - 1) + ["\n"]
    return "".join(tokens.ravel().tolist())


def vts_text(indices: np.ndarray) -> str:
    """One integer per line (PSMAL ``.vts``): 0-based target vertex index, -1 = no counterpart."""
    return _rows_text(np.asarray(indices, dtype=np.int64).reshape(-1, 1).astype(str))


class _PortablePickler(pickle.Pickler):
    """Pickles arrays as ``numpy.ndarray(shape, dtype_str, bytearray)``.

    numpy 2 pickles arrays through ``numpy._core.multiarray._reconstruct``, a module numpy 1.x does
    not have (numpy/numpy#28340); ``numpy.ndarray`` and ``builtins.bytearray`` exist in both, so these
    pickles load under numpy 1.x and 2.x alike (as writable arrays).
    """

    def reducer_override(self, obj):
        if isinstance(obj, np.ndarray):
            if obj.dtype.hasobject or obj.dtype.fields is not None:
                raise TypeError(f"info pickles hold plain numeric arrays only, not dtype {obj.dtype}")
            return np.ndarray, (tuple(int(n) for n in obj.shape), obj.dtype.str, bytearray(obj.tobytes()))
        if isinstance(obj, np.generic):
            raise TypeError(f"numpy scalar {obj!r} in an info pickle: convert it to a Python number first")
        return NotImplemented


def info_pickle_bytes(info: Mapping) -> bytes:
    """A dict of builtins (str, float, int, bool, None) and numpy arrays as a protocol-4 pickle that
    numpy 1.x and 2.x both read (see :class:`_PortablePickler`)."""
    buffer = io.BytesIO()
    _PortablePickler(buffer, protocol=PICKLE_PROTOCOL).dump(dict(info))
    return buffer.getvalue()


def released_stem(name: str) -> str:
    """A shape name as it appears in released file names: ``/`` -> ``_`` (``bear3EP/Attack4009`` ->
    ``bear3EP_Attack4009``), as in the reference."""
    return name.replace("/", "_")


def released_file_stem(side: int, name: str, remesh_variant: int, scanned_in: str | None = None) -> str:
    """``<side>_<name>`` (``/`` -> ``_``), plus ``_v<k>`` for remesh variant k >= 0 and, for a scanned
    shape, ``_scan-<pair_id>``: loaders cache per-shape data by file name, and one name can stand for
    several meshes (remesh variants; every scan is its own mesh). ``0_cat0_v2`` (full),
    ``1_cat3_v0_scan-0123abcd...`` (scanned), ``0_cat0`` (not remeshed, or remeshed to a published face
    target)."""
    stem = f"{int(side)}_{released_stem(name)}"
    if int(remesh_variant) >= 0:
        stem += f"_v{int(remesh_variant)}"
    return stem if scanned_in is None else f"{stem}_scan-{scanned_in}"


def mesh_id(dataset: str, name: str, remesh_variant: int, scanned_in: str | None = None) -> str:
    """The identity of a shape's mesh up to rigid motion: ``<dataset>/<name>``, ``/v<k>`` for remesh
    variant k >= 0, and for a scanned (partial) shape ``/scan/<pair_id>/<x|y>`` (each scan is its own
    mesh). Rotation-invariant data (geodesics, spectra) may be cached by it; vertex positions differ
    per pair (random rotation, alignment) even for one mesh_id."""
    out = f"{dataset}/{name}"
    if int(remesh_variant) >= 0:
        out += f"/v{int(remesh_variant)}"
    return out if scanned_in is None else f"{out}/scan/{scanned_in}"


def psmal_shape_id(index: int, side: int, dataset: str, name: str) -> str:
    """``<pair index>_<side>_<dataset>_<name>``: exactly four ``_``-separated fields, because PSMAL
    loaders split a map file name ``<A>_<B>.vts`` on ``_`` into fields 0-3 (A) and 4-7 (B); ``_``,
    ``/``, ``\\`` and white space inside dataset and name become ``-`` (``tr_reg_000`` ->
    ``tr-reg-000``). The pair index makes ids unique inside a split."""
    return "_".join([str(int(index)), str(int(side)), _id_field(dataset), _id_field(name)])


def _id_field(text: str) -> str:
    return re.sub(r"[_/\\\s]", "-", str(text)) or "-"


# --------------------------------------------------------------------------------------------------
# record -> released info dictionaries


def _f64(a) -> np.ndarray:
    return np.array(a, dtype=np.float64)


def released_infos(record: PairRecord) -> tuple[dict, dict]:
    """The two info dictionaries (shape 0 = X, shape 1 = Y) of the released layout.

    Keys (see ``docs/released-layout.md`` for the full table):

    - always: ``name``, ``org_dataset``, ``scale_per_dataset``, ``surface_area`` (sqrt-area of the
      remeshed full shape at dataset scale), ``surface_area_after_scaling`` (sqrt-area of the full
      shape in the units of the written vertices: ``surface_area``, or 1.0 for an area-normalised
      record), ``random_rotation`` (3, 3), ``align_rotation`` / ``align_translation`` (None for X;
      (3, 3), (3,) for Y, row vectors: ``v @ R + t``), ``pair_id``, ``area_normalised``,
      ``remesh_variant`` (int, -1 = not a variant), ``mesh_id`` (:func:`mesh_id`).
    - every scanned (partial) shape: ``partial2full`` (V,) int64, ``cam_pos`` (3,) camera position,
      ``camera`` (3, 3) rows position / look-at target / up (the record's ``s_camera``: the shape's
      common frame, before alignment and random rotation).
    - every setting, both shapes: ``overlap_mask`` (V,) bool over the shape's OWN vertices and
      ``overlap_percentage`` its mean (the reference swaps these between the two files, and has none
      in F2F, where semantic missing parts also leave vertices without a counterpart).
    - P2P and F2F: ``found_faces_mask_yx`` in X's info = Y's mask, ``found_faces_mask`` in Y's info =
      X's mask (the released convention, which DeepShapeMatchingKit swaps back); P2F: X's info
      ``found_faces_mask`` = X's own mask over full X.
    """
    setting = record.meta["setting"]
    normalised = bool(record.meta.get("area_normalised", False))
    infos = {}
    for s, _ in SIDES:
        meta = record.meta[s]
        sqrt_area = float(record[f"{s}_full_sqrt_area"])
        infos[s] = {
            "name": str(meta["name"]),
            "org_dataset": str(meta["dataset"]),
            "scale_per_dataset": float(record[f"{s}_dataset_scale"]),
            "surface_area": sqrt_area,
            "surface_area_after_scaling": 1.0 if normalised else sqrt_area,
            "random_rotation": _f64(record[f"{s}_random_rotation"]),
            "align_rotation": None if s == "x" else _f64(record["y_align_rotation"]),
            "align_translation": None if s == "x" else _f64(record["y_align_translation"]),
            "pair_id": str(record.pair_id),
            "area_normalised": normalised,
            "remesh_variant": int(record[f"{s}_remesh_variant"]),
        }
    scanned = {"partial_partial": ("x", "y"), "partial_full": ("y",), "full_full": ()}[setting]
    for s, _ in SIDES:
        infos[s]["mesh_id"] = mesh_id(
            infos[s]["org_dataset"],
            infos[s]["name"],
            infos[s]["remesh_variant"],
            f"{record.pair_id}/{s}" if s in scanned else None,
        )
    for s in scanned:
        camera = _f64(record[f"{s}_camera"])
        infos[s]["partial2full"] = np.array(record[f"{s}_partial_to_full"], dtype=np.int64)
        infos[s]["cam_pos"] = camera[0].copy()
        infos[s]["camera"] = camera
    for s, _ in SIDES:
        infos[s]["overlap_mask"] = np.array(record[f"{s}_overlap_mask"], dtype=bool)
        infos[s]["overlap_percentage"] = (
            float(np.mean(infos[s]["overlap_mask"])) if len(infos[s]["overlap_mask"]) else 0.0
        )
    if setting in ("partial_partial", "full_full"):
        infos["x"]["found_faces_mask_yx"] = np.array(record["y_overlap_mask"], dtype=bool)
        infos["y"]["found_faces_mask"] = np.array(record["x_overlap_mask"], dtype=bool)
    elif setting == "partial_full":
        infos["x"]["found_faces_mask"] = np.array(record["x_overlap_mask"], dtype=bool)
    return infos["x"], infos["y"]


def _check_record(record: PairRecord, setting: str | None) -> None:
    pid = record.meta.get("pair_id", "?")
    if setting is not None and record.meta.get("setting") != setting:
        raise ExportError(
            f"pair {pid}: its setting {record.meta.get('setting')!r} differs from the export's "
            f"setting {setting!r}. Fix: export each setting's store on its own"
        )
    split = str(record.meta.get("split", ""))
    if not _SPLIT_NAME.fullmatch(split) or split == LOGS_DIR or split.isdigit():
        raise ExportError(
            f"pair {pid}: split {split!r} cannot be a folder name. Fix: use splits such as train, val, test"
        )
    for s, o, corr in (("x", "y", "corr_01"), ("y", "x", "corr_10")):
        n, n_other = len(record[f"{s}_vertices"]), len(record[f"{o}_vertices"])
        c = record[corr]
        if len(c) != n or (len(c) and (c.min() < -1 or c.max() >= n_other)):
            raise ExportError(
                f"pair {pid}: {corr} has {len(c)} entries in [{c.min() if len(c) else 0}, "
                f"{c.max() if len(c) else 0}] for {n} -> {n_other} vertices. Fix: rebuild the "
                f"pair record"
            )


# --------------------------------------------------------------------------------------------------
# atomic output folders and per-split numbering


def _is_empty_dir(path: Path) -> bool:
    return path.is_dir() and not any(path.iterdir())


def _check_target(out: Path, overwrite: bool) -> None:
    if out.exists() and not out.is_dir():
        raise ExportError(f"{out}: exists and is not a folder. Fix: choose another output path")
    if out.is_dir() and not overwrite and not _is_empty_dir(out):
        raise ExportError(
            f"{out}: folder exists and is not empty. Fix: choose a new output path or pass "
            f"overwrite=True (--force) to replace it"
        )


@contextmanager
def _staged_dir(out: Path, overwrite: bool) -> Iterator[Path]:
    """Yield a temporary folder beside ``out``; on success it replaces ``out``, else it is removed."""
    _check_target(out, overwrite)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.tmp-"))
    try:
        yield tmp
        os.chmod(tmp, 0o755)  # mkdtemp creates 0700; exports are meant to be shared
        _replace_dir(tmp, out, overwrite)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _replace_dir(tmp: Path, out: Path, overwrite: bool) -> None:
    if out.is_dir() and _is_empty_dir(out):
        out.rmdir()
    if out.exists():
        _check_target(out, overwrite)  # appeared meanwhile
        old = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.old-"))
        os.replace(out, old / out.name)
        os.replace(tmp, out)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(tmp, out)


@dataclass(frozen=True)
class _Entry:
    split: str
    pair_id: str
    folder: Path
    x_name: str
    y_name: str
    x_dataset: str
    y_dataset: str


class _Staging:
    """Per-pair scratch folders (numbered in arrival order) and their final per-split numbering."""

    def __init__(self, root: Path, label: str, progress: bool):
        self.root = root / _STAGING
        self.entries: list[_Entry] = []
        self.label = label
        self.progress = progress

    def add(self, record: PairRecord) -> Path:
        folder = self.root / str(len(self.entries))
        folder.mkdir(parents=True)
        m = record.meta
        self.entries.append(
            _Entry(
                str(m["split"]),
                str(m["pair_id"]),
                folder,
                str(m["x"]["name"]),
                str(m["y"]["name"]),
                str(m["x"]["dataset"]),
                str(m["y"]["dataset"]),
            )
        )
        if self.progress and len(self.entries) % _PROGRESS_EVERY == 0:
            print(f"{self.label}: {len(self.entries)} pairs", file=sys.stderr, flush=True)
        return folder

    def by_split(self) -> dict[str, list[_Entry]]:
        """{split: entries in ascending pair_id order} (splits in first-seen order); duplicates raise."""
        out: dict[str, list[_Entry]] = {}
        for e in self.entries:
            out.setdefault(e.split, []).append(e)
        for split, entries in out.items():
            entries.sort(key=lambda e: e.pair_id)
            ids = [e.pair_id for e in entries]
            dup = sorted({a for a, b in zip(ids, ids[1:]) if a == b})
            if dup:
                raise ExportError(f"split {split}: pair ids {dup[:5]} occur more than once. Fix: pass each pair once")
        return out

    def finish(self) -> None:
        if self.progress:
            print(f"{self.label}: {len(self.entries)} pairs done", file=sys.stderr, flush=True)
        shutil.rmtree(self.root, ignore_errors=True)


def _write_ids(path: Path, header: list[str], rows: list[list]) -> None:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    path.write_text(buffer.getvalue(), encoding="utf-8")


def _plain(value):
    """JSON round trip (numpy values and paths as strings) so YAML gets only builtins."""
    return json.loads(json.dumps(value, default=lambda o: o.item() if isinstance(o, np.generic) else str(o)))


def _write_log(
    root: Path,
    writer: str,
    layout: str,
    counts: dict[str, int],
    setting: str | None,
    metadata: Mapping | None,
    maps: Mapping | None = None,
) -> None:
    """``<root>/logs/config.yaml``; ``maps``: optional ``{split: {folder: map files}}`` (DPFM)."""
    import yaml

    from becos import __version__

    log = {
        "written_by": f"becos {__version__} ({writer})",
        "layout": f"{layout} version {LAYOUT_VERSION}, described in docs/released-layout.md of becos",
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "setting": setting,
        "pairs": counts,
        **({"maps": _plain(dict(maps))} if maps is not None else {}),
        "source_metadata": _plain(dict(metadata)) if metadata else None,
    }
    (root / LOGS_DIR).mkdir(exist_ok=True)
    (root / LOGS_DIR / "config.yaml").write_text(
        yaml.safe_dump(log, sort_keys=False, allow_unicode=True), encoding="utf-8"
    )


def _write_annotation_files(folder: Path, record: PairRecord) -> bool:
    labels = {s: np.asarray(record[f"{s}_annotation"], dtype=np.int8) for s, _ in SIDES}
    if not any((a >= 0).any() for a in labels.values()):
        return False
    for s, k in SIDES:
        np.save(folder / f"{k}_annotation.npy", labels[s])
    return True


# --------------------------------------------------------------------------------------------------
# writers


def _place_by_split(staging: _Staging, tmp: Path) -> tuple[list[list], dict[str, int]]:
    """Move the staged pair folders to ``tmp/<split>/<index>`` (store order); returns the id-file rows
    ``[split, index, pair_id, x, y]`` and the pair count per split."""
    rows, counts = [], {}
    for split, entries in staging.by_split().items():
        (tmp / split).mkdir()
        for i, e in enumerate(entries):
            os.replace(e.folder, tmp / split / str(i))
            rows.append([split, i, e.pair_id, e.x_name, e.y_name])
        counts[split] = len(entries)
    staging.finish()
    return rows, counts


def write_released(
    records: Iterable[PairRecord],
    out_dir: str | Path,
    *,
    setting: str,
    metadata: Mapping | None = None,
    overwrite: bool = False,
    progress: bool = False,
) -> Path:
    """Write the records in the released BeCoS folder layout (``docs/released-layout.md``).

    ``<out>/<split>/<i>/`` per pair (``i`` = 0..N-1 in ascending pair_id order within the split) with
    ``0_<x>.off``, ``1_<y>.off``, ``corres_01.npy`` (not for P2F), ``corres_10.npy``,
    ``0_<x>_info.pkl``, ``1_<y>_info.pkl`` and, when any vertex carries a label,
    ``0_annotation.npy`` / ``1_annotation.npy``; ``<out>/ids.csv`` (split, index, pair_id, x, y) and
    ``<out>/logs/config.yaml`` (what wrote it, counts, the source's metadata).

    Name ``out`` after the setting (``.../partial_partial``): DeepShapeMatchingKit's loader infers the
    setting from its data_root path.

    Args:
        records: pair records of ONE setting, in any order (streamed; memory stays one pair).
        out_dir: output folder; must not exist or be empty unless ``overwrite``.
        setting: full_full, partial_full or partial_partial; every record must have it.
        metadata: the source's metadata (e.g. ``Benchmark.metadata``), copied into the log.
        overwrite: replace an existing ``out_dir`` (only once the new export is complete).
        progress: print a line to stderr every 200 pairs.

    Returns:
        ``out_dir`` as a Path.
    """
    if setting not in SETTINGS:
        raise ExportError(f"setting must be one of {SETTINGS}, got {setting!r}")
    out = Path(out_dir)
    with _staged_dir(out, overwrite) as tmp:
        staging = _Staging(tmp, "export-released", progress)
        for record in records:
            _check_record(record, setting)
            _write_released_pair(staging.add(record), record, setting)
        rows, counts = _place_by_split(staging, tmp)
        _write_ids(tmp / IDS_FILE, ["split", "index", "pair_id", "x", "y"], rows)
        _write_log(tmp, "becos.export.write_released", "becos released BeCoS layout", counts, setting, metadata)
    return out


def _write_released_pair(folder: Path, record: PairRecord, setting: str) -> None:
    infos = released_infos(record)
    for (s, k), info in zip(SIDES, infos):
        stem = released_file_stem(
            k, info["name"], info["remesh_variant"], record.pair_id if "partial2full" in info else None
        )
        (folder / f"{stem}.off").write_text(off_text(record[f"{s}_vertices"], record[f"{s}_faces"]), encoding="utf-8")
        (folder / f"{stem}_info.pkl").write_bytes(info_pickle_bytes(info))
    if setting != "partial_full":
        np.save(folder / "corres_01.npy", np.asarray(record["corr_01"], dtype=np.int64))
    np.save(folder / "corres_10.npy", np.asarray(record["corr_10"], dtype=np.int64))
    _write_annotation_files(folder, record)


def write_psmal(
    records: Iterable[PairRecord],
    out_dir: str | Path,
    *,
    metadata: Mapping | None = None,
    overwrite: bool = False,
    progress: bool = False,
) -> Path:
    """Write the records PSMAL style (``docs/released-layout.md``, section PSMAL).

    Per split: ``<out>/<split>/shapes/<id>.off`` for both shapes of every pair and
    ``<out>/<split>/maps/<A>_<B>.vts`` in both directions: one line per vertex of A, the 0-based
    vertex of B or -1 (as PSMAL's own maps, which its loaders read without subtracting 1). Shape ids
    are :func:`psmal_shape_id` ``(pair index, 0|1, dataset, name)``; ``<out>/ids.csv`` maps
    (split, index) to pair_id, names and ids; ``<out>/logs/config.yaml`` as in :func:`write_released`.

    Args: as :func:`write_released` (records of any setting; numbering per split by pair_id).
    """
    return _write_shapes_and_maps(
        records, out_dir, psmal_shape_id, "vts", "write_psmal", "PSMAL-style", metadata, overwrite, progress
    )


def dpfm_shape_id(index: int, side: int, dataset: str, name: str) -> str:
    """``<pair index>-<side>-<dataset>-<name>`` with no ``_`` at all (``_``, ``/``, ``\\`` and white
    space become ``-``): DPFM's loader splits a map name ``<A>_<B>`` at its LAST ``_`` and others
    (CP2P loaders) at every ``_``, so an id without ``_`` survives both."""
    return "-".join([str(int(index)), str(int(side)), _id_field(dataset), _id_field(name)])


DPFM_NONE_MAPS = "maps_with_none"
"""Folder beside ``maps/`` of a DPFM export for the map directions that hold a ``-1`` row."""


def write_dpfm(
    records: Iterable[PairRecord],
    out_dir: str | Path,
    *,
    metadata: Mapping | None = None,
    overwrite: bool = False,
    progress: bool = False,
) -> Path:
    """Write the records DPFM style (``docs/released-layout.md``, section 6): per split
    ``<out>/<split>/shapes/<id>.off`` and, for both directions A -> B of every pair, ``<A>_<B>.map``
    (one line per vertex of A: the 0-based vertex of B, -1 = none), ids :func:`dpfm_shape_id`;
    ``ids.csv`` and ``logs/config.yaml`` as :func:`write_psmal`.

    A direction goes to ``<split>/maps/`` (which DPFM's ``ShrecPartialDataset`` trains on) only when
    every vertex of A has a counterpart, as in DPFM's SHREC'16 maps: its loader sets
    ``P[range(n2), map21] = 1`` and has no "none", so a ``-1`` row would become a match with B's last
    vertex and a wrong ``C_gt``. Directions holding a ``-1`` go to ``<split>/maps_with_none/``
    (:data:`DPFM_NONE_MAPS`, same format), which DPFM does not read; together the two folders hold
    both directions of every pair, and ``<A>_<B>.map != -1`` is A's own overlap mask. The log's
    ``maps`` gives each split's file count per folder (``maps`` = the items DPFM will form)."""
    return _write_shapes_and_maps(
        records,
        out_dir,
        dpfm_shape_id,
        "map",
        "write_dpfm",
        "DPFM-style",
        metadata,
        overwrite,
        progress,
        none_maps=DPFM_NONE_MAPS,
    )


def _write_shapes_and_maps(
    records: Iterable[PairRecord],
    out_dir: str | Path,
    shape_id,
    map_ext: str,
    writer: str,
    layout: str,
    metadata: Mapping | None,
    overwrite: bool,
    progress: bool,
    none_maps: str | None = None,
) -> Path:
    """``<out>/<split>/shapes/<id>.off`` + ``<out>/<split>/maps/<A>_<B>.<map_ext>`` (both directions);
    with ``none_maps``, a direction that holds a ``-1`` goes to ``<out>/<split>/<none_maps>/`` instead
    (both folders are made in every split, empty or not)."""
    out = Path(out_dir)
    with _staged_dir(out, overwrite) as tmp:
        staging = _Staging(tmp, f"export-{map_ext}", progress)
        settings = set()
        for record in records:
            _check_record(record, None)
            settings.add(record.meta["setting"])
            folder = staging.add(record)
            for s, k in SIDES:
                (folder / f"{k}.off").write_text(
                    off_text(record[f"{s}_vertices"], record[f"{s}_faces"]), encoding="utf-8"
                )
            for direction in ("01", "10"):
                corr = np.asarray(record[f"corr_{direction}"], dtype=np.int64)
                kind = "none" if none_maps is not None and (corr < 0).any() else "map"
                (folder / f"{direction}.{kind}").write_text(vts_text(corr), encoding="utf-8")
        rows, counts, map_counts = [], {}, {}
        for split, entries in staging.by_split().items():
            shapes, maps = tmp / split / "shapes", tmp / split / "maps"
            shapes.mkdir(parents=True)
            maps.mkdir()
            folders = {"map": maps}
            if none_maps is not None:
                folders["none"] = tmp / split / none_maps
                folders["none"].mkdir()
            for i, e in enumerate(entries):
                a = shape_id(i, 0, e.x_dataset, e.x_name)
                b = shape_id(i, 1, e.y_dataset, e.y_name)
                os.replace(e.folder / "0.off", shapes / f"{a}.off")
                os.replace(e.folder / "1.off", shapes / f"{b}.off")
                for direction, name in (("01", f"{a}_{b}"), ("10", f"{b}_{a}")):
                    for kind, target in folders.items():
                        if (e.folder / f"{direction}.{kind}").is_file():
                            os.replace(e.folder / f"{direction}.{kind}", target / f"{name}.{map_ext}")
                rows.append([split, i, e.pair_id, e.x_name, e.y_name, a, b])
            counts[split] = len(entries)
            map_counts[split] = {f.name: sum(1 for _ in f.iterdir()) for f in folders.values()}
        staging.finish()
        _write_ids(tmp / IDS_FILE, ["split", "index", "pair_id", "x", "y", "x_id", "y_id"], rows)
        setting = settings.pop() if len(settings) == 1 else None
        _write_log(
            tmp,
            f"becos.export.{writer}",
            f"becos {layout} layout",
            counts,
            setting,
            metadata,
            map_counts if none_maps is not None else None,
        )
    return out


def ulrssm_template_vts(record: PairRecord) -> tuple[str, str]:
    """The two ``corres/<k>.vts`` texts of a pair in ULRSSM's template convention: line t of each file
    is the 1-based vertex of that shape at template point t, so that point t pairs vertex
    ``vts0[t] - 1`` of shape 0 with vertex ``vts1[t] - 1`` of shape 1. The template points are the
    vertices of shape 1 that have a counterpart (record ``corr_10`` != -1, in vertex order): the pair's
    ground truth Y -> X, the direction every setting has (P2F: partial Y -> full X). ULRSSM subtracts 1
    and has no "none" value, hence only matched vertices."""
    corr = np.asarray(record["corr_10"], dtype=np.int64)
    matched = np.flatnonzero(corr >= 0)
    return vts_text(corr[matched] + 1), vts_text(matched + 1)


def write_ulrssm(
    records: Iterable[PairRecord],
    out_dir: str | Path,
    *,
    metadata: Mapping | None = None,
    overwrite: bool = False,
    progress: bool = False,
    geodesics: bool = False,
    method: str = "heat",
    splits=None,
    jobs: int = 1,
    rows=None,
    free_bytes: int | None = None,
) -> Path:
    """Write the records ULRSSM style (``docs/released-layout.md``, section ULRSSM): one data root per
    pair, ``<out>/<split>/<i>/`` with ``off/0.off``, ``off/1.off``, ``corres/0.vts``, ``corres/1.vts``
    (:func:`ulrssm_template_vts`) and, with ``geodesics``, ``dist/0.mat``, ``dist/1.mat``: MATLAB v5
    files, key ``dist``, (V, V) float32 geodesic distances on the full shape divided by its sqrt-area
    (the values of :func:`write_geodesic_matrices`; only for ``splits`` when given).
    ULRSSM's ``PairDataset`` pairs every two shapes of its data root, so one root per pair keeps our
    pairs. ``ids.csv`` and ``logs/config.yaml`` as :func:`write_released`.

    Geodesics (:func:`_write_ulrssm_dist`): each distinct matrix (a full mesh up to rigid motion, or
    one cut of it that a scan keeps) is written ONCE, streamed from its mesh's (R, R) block, and every
    other pair side showing it gets a hard link (a copy only where the file system refuses links,
    reported on stderr and in ``logs/geodesics.json``). The blocks are computed one mesh at a time by
    ``jobs`` processes, or read from ``rows`` (folders of ``becos geodesic-rows``: the workflow's one
    geodesic computation). Before any matrix is written the disk (distinct files × V² × 4 bytes) and
    the peak memory are estimated and printed; an estimate above the free space of the output's file
    system (``free_bytes`` when given, else :func:`shutil.disk_usage`) stops the export
    (:class:`DiskEstimateError`) and leaves ``out`` untouched."""
    out = Path(out_dir)
    with _staged_dir(out, overwrite) as tmp:
        staging = _Staging(tmp, "export-ulrssm", progress)
        settings = set()

        def write_pair(record: PairRecord) -> None:
            settings.add(record.meta["setting"])
            folder = staging.add(record)
            (folder / "off").mkdir()
            (folder / "corres").mkdir()
            for s, k in SIDES:
                (folder / "off" / f"{k}.off").write_text(
                    off_text(record[f"{s}_vertices"], record[f"{s}_faces"]), encoding="utf-8"
                )
            for k, text in enumerate(ulrssm_template_vts(record)):
                (folder / "corres" / f"{k}.vts").write_text(text, encoding="utf-8")

        shapes, meshes, needed, numbers = _geodesic_plan(records, splits if geodesics else [], each=write_pair)
        id_rows, counts = _place_by_split(staging, tmp)
        if geodesics and shapes:
            summary = _write_ulrssm_dist(
                tmp, out, shapes, meshes, needed, numbers, method, jobs, progress, rows, free_bytes
            )
            (tmp / LOGS_DIR).mkdir(exist_ok=True)
            (tmp / LOGS_DIR / "geodesics.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
        _write_ids(tmp / IDS_FILE, ["split", "index", "pair_id", "x", "y"], id_rows)
        setting = settings.pop() if len(settings) == 1 else None
        _write_log(tmp, "becos.export.write_ulrssm", "becos ULRSSM-style layout", counts, setting, metadata)
    return out


class DiskEstimateError(DiskFullError):
    """An export would not fit: its estimated size exceeds the free space of its file system (raised
    before anything is written)."""

    def __init__(self, path: str | Path, problem: str, fix: str):
        InputFileError.__init__(self, path, problem, fix)


# --------------------------------------------------------------------------------------------------
# MATLAB v5 files of one symmetric float32 matrix, streamed (ULRSSM's dist/<k>.mat)

_MI_INT8, _MI_INT32, _MI_UINT32, _MI_SINGLE, _MI_MATRIX = 1, 5, 6, 7, 14
_MX_SINGLE_CLASS = 7
MAT_MAX_VERTICES = 32767
"""Largest V of a (V, V) float32 MAT v5 matrix: its element's byte count is a uint32 (4 V² + 48 < 2³²).
scipy's ``loadmat`` (ULRSSM's reader) cannot read the HDF5-based v7.3 files that would hold more."""
_MAT_TEXT = b"MATLAB 5.0 MAT-file, Platform: posix, Created by: becos (scipy.io.loadmat reads it)"
_WRITE_CHUNK_BYTES = 32 << 20
"""Bytes per buffered write of a matrix (rows of a cut, gathered at a time)."""


def _mat_pad(nbytes: int) -> int:
    return -nbytes % 8


def mat_prefix(n: int, name: str = "dist") -> bytes:
    """The first bytes of a little-endian MAT v5 file holding one real (n, n) float32 matrix ``name``:
    the 128-byte header (fixed text, no date, so the bytes depend on the matrix alone) and the tags of
    the ``miMATRIX`` element (array flags ``mxSINGLE_CLASS``, dimensions (n, n), name, ``miSINGLE``
    data of 4 n² bytes) laid out as ``scipy.io.savemat`` lays them out. The 4 n² data bytes follow in
    column-major order, then zeros up to a multiple of 8 bytes. For a symmetric matrix column-major is
    row-major: the rows of a C-ordered array are written as they are, in as many pieces as wanted."""
    import struct

    if not 0 <= n <= MAT_MAX_VERTICES:
        raise ExportError(
            f"a {n} x {n} float32 matrix does not fit a MATLAB v5 file (at most {MAT_MAX_VERTICES} rows), "
            f"and ULRSSM's scipy.io.loadmat reads no v7.3 file. Fix: leave out --geodesics for shapes this "
            f"large (ULRSSM computes dist itself), or remesh to fewer vertices"
        )
    label = name.encode("ascii")
    if len(label) <= 4:  # small data element: byte count and type in one word, data in the next four bytes
        name_element = struct.pack("<HH", _MI_INT8, len(label)) + label.ljust(4, b"\0")
    else:
        name_element = struct.pack("<II", _MI_INT8, len(label)) + label + b"\0" * _mat_pad(len(label))
    data = 4 * n * n
    body = (
        struct.pack("<IIII", _MI_UINT32, 8, _MX_SINGLE_CLASS, 0)
        + struct.pack("<IIii", _MI_INT32, 8, n, n)
        + name_element
        + struct.pack("<II", _MI_SINGLE, data)
    )
    header = _MAT_TEXT.ljust(116, b" ") + b"\0" * 8 + struct.pack("<H", 0x0100) + b"IM"
    return header + struct.pack("<II", _MI_MATRIX, len(body) + data + _mat_pad(data)) + body


def mat_size(n: int, name: str = "dist") -> int:
    """Bytes of the MAT v5 file of an (n, n) float32 matrix (:func:`mat_prefix`)."""
    data = 4 * n * n
    return len(mat_prefix(n, name)) + data + _mat_pad(data)


def write_symmetric_mat(path: str | Path, n: int, chunks: Iterable[np.ndarray], name: str = "dist") -> int:
    """Write a symmetric (n, n) float32 matrix as the MAT v5 file ``path`` (variable ``name``),
    atomically, from ``chunks``: consecutive (k, n) float32 row blocks whose rows add up to n (the
    matrix is never whole in memory here). Returns the bytes written; ``scipy.io.loadmat(path)[name]``
    gives the matrix back (float32, (n, n))."""
    from becos.atomic import atomic_path

    data = 4 * n * n
    with atomic_path(path, suffix=".tmp.mat") as tmp:
        with open(tmp, "wb") as fh:
            fh.write(mat_prefix(n, name))
            done = 0
            for chunk in chunks:
                chunk = np.ascontiguousarray(chunk, dtype=np.float32)
                if chunk.ndim != 2 or chunk.shape[1] != n:
                    raise ValueError(f"row block of shape {chunk.shape}, expected (k, {n})")
                if chunk.size:
                    fh.write(memoryview(chunk).cast("B"))
                done += chunk.shape[0]
            if done != n:
                raise ValueError(f"{done} rows written, expected {n}")
            fh.write(b"\0" * _mat_pad(data))
    return Path(path).stat().st_size


def _cut_chunks(block: np.ndarray, cut: np.ndarray | None) -> Iterator[np.ndarray]:
    """Row blocks of ``block[np.ix_(cut, cut)]`` (of ``block`` itself when ``cut`` is None), of at most
    :data:`_WRITE_CHUNK_BYTES` each."""
    n = len(block) if cut is None else len(cut)
    step = max(1, _WRITE_CHUNK_BYTES // (4 * max(n, 1)))
    for start in range(0, n, step):
        if cut is None:
            yield block[start : start + step]
        else:
            yield block[cut[start : start + step]][:, cut]


# --------------------------------------------------------------------------------------------------
# per-mesh blocks, one at a time


def _symmetrise_in_place(block: np.ndarray, sqrt_area: float, tile: int = 1024) -> np.ndarray:
    """Turn the (R, R) float32 ``block`` of distance rows between R sources into
    :func:`symmetric_block`'s matrix in place, tile by tile: entry by entry the same float32 operations
    ((d(a, b) + d(b, a)) · 0.5 / sqrt_area, zero diagonal), so the same bytes, with one (R, R) array
    instead of three."""
    n = len(block)
    half, scale = np.float32(0.5), np.float32(sqrt_area)
    for i in range(0, n, tile):
        for j in range(i, n, tile):
            t = block[j : j + tile, i : i + tile].T + block[i : i + tile, j : j + tile]
            t *= half
            t /= scale
            block[i : i + tile, j : j + tile] = t
            block[j : j + tile, i : i + tile] = t.T
    np.fill_diagonal(block, 0.0)
    return block


def _read_npy_block(path: Path, pick: np.ndarray | None, out: np.ndarray) -> np.ndarray:
    """Fill ``out`` with rows and columns ``pick`` (sorted; all when None) of the (R, R) float32 ``.npy``
    file ``path``, by buffered reads of :data:`_WRITE_CHUNK_BYTES` (no memory map: the file's pages do
    not stay in this process's memory)."""
    with open(path, "rb") as fh:
        version = np.lib.format.read_magic(fh)
        reader = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, fortran, dtype = reader(fh)
        if len(shape) != 2 or shape[0] != shape[1] or dtype != np.float32 or fortran:
            raise ExportError(
                f"{path}: a {shape} {dtype} block, expected (R, R) float32. Fix: rerun `becos geodesic-rows`"
            )
        n = shape[0]
        step = max(1, _WRITE_CHUNK_BYTES // (4 * max(n, 1)))
        buffer = np.empty((step, n), dtype=np.float32)
        for start in range(0, n, step):
            rows = min(step, n - start)
            view = out[start : start + rows] if pick is None else buffer[:rows]
            if fh.readinto(memoryview(view).cast("B")) != 4 * rows * n:
                raise ExportError(f"{path}: truncated block. Fix: rerun `becos geodesic-rows`")
            if pick is not None:
                lo, hi = np.searchsorted(pick, [start, start + rows])
                out[lo:hi] = view[pick[lo:hi] - start][:, pick]
    return out


def _mesh_blocks(
    meshes: dict,
    needed: dict,
    scales: Mapping[str, float],
    method: str,
    jobs: int,
    progress: bool,
    rows_folders=None,
    label: str = "geodesics",
) -> Iterator[tuple[str, np.ndarray, np.ndarray]]:
    """Yield ``(key, sources, block)`` for every mesh, ONE at a time, largest first: ``sources`` (R,)
    its sorted needed vertices, ``block`` the (R, R) float32 :func:`symmetric_block` between them
    (symmetrised, divided by ``scales[key]``, the sqrt-area). The caller writes it before asking for
    the next; only one block is in memory.

    Computed: tasks of :func:`_task_rows` source rows, each in a fresh process (``jobs`` at a time,
    also for ``jobs=1``: the solver library keeps memory until its process ends), at most ``jobs``
    tasks submitted and not yet consumed (bounded memory), each task's (rows, V) float32 result cut to
    the block's columns as it arrives; no rows file on disk. From ``rows_folders`` (outputs of
    ``becos geodesic-rows``): each block read (and cut to ``needed``) from its file."""
    import multiprocessing
    import time
    from collections import deque

    order = sorted(meshes, key=lambda k: (-len(needed[k]), k))
    started = time.monotonic()
    if rows_folders is not None:
        from becos.geodesic_jobs import load_rows

        loaded = load_rows(rows_folders)
        for key in order:
            if key not in loaded:
                raise ExportError(
                    f"{', '.join(map(str, rows_folders))}: no geodesic rows of mesh {key}. Fix: plan the rows "
                    f"with this store and the same splits (`becos geodesic-plan`), then rerun `becos geodesic-rows`"
                )
            have, path, scale = loaded[key]
            if not np.isin(needed[key], have).all():
                raise ExportError(
                    f"geodesic rows of mesh {key}: {len(have)} rows, missing some of the {len(needed[key])} this "
                    f"store needs. Fix: rerun `becos geodesic-plan` and `becos geodesic-rows` with this store"
                )
            if abs(scale - scales[key]) > 1e-6 * abs(scale):
                raise ExportError(
                    f"{path}: sqrt-area {scale!r} differs from {scales[key]!r} of this store. Fix: build every "
                    f"setting's store with the same config (area_normalised) and rerun `becos geodesic-plan`"
                )
        for i, key in enumerate(order):
            have, path, _ = loaded[key]
            whole = len(have) == len(needed[key])
            block = np.empty((len(needed[key]),) * 2, dtype=np.float32)
            _read_npy_block(path, None if whole else np.searchsorted(have, needed[key]), block)
            if progress:
                print(
                    f"{label}: read mesh {i + 1}/{len(order)} ({len(block)} rows) from {path.parent}, "
                    f"{time.monotonic() - started:.0f} s",
                    file=sys.stderr,
                    flush=True,
                )
            yield key, needed[key], block
            del block
        return

    from concurrent.futures import ProcessPoolExecutor

    tasks = [
        (key, start, *meshes[key], needed[key][start : start + step], method)
        for key in order
        for step in [_task_rows(len(meshes[key][0]), len(meshes[key][1]))]
        for start in range(0, len(needed[key]), step)
    ]
    total, done = sum(len(needed[k]) for k in order), 0
    # every task in a fresh process (also with jobs=1): the sparse Cholesky solver behind the heat
    # method (cholespy) keeps ~V x 447 x 8 bytes per factorisation that has solved, freed only when its
    # process ends (measured: +67 MB per 9.4k-vertex task; a long-lived process grew to 2 GB)
    pool = ProcessPoolExecutor(
        max_workers=max(1, jobs), mp_context=multiprocessing.get_context("spawn"), max_tasks_per_child=1
    )

    def results() -> Iterator[tuple[str, int, np.ndarray]]:
        pending = deque()
        for task in tasks:
            pending.append(pool.submit(_geodesic_task, task))
            if len(pending) >= max(1, jobs):  # at most `jobs` results in this process: bounded memory
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()

    try:
        block, filled, n_meshes = None, 0, 0
        for key, start, rows in results():
            sources = needed[key]
            if block is None:
                block, filled = np.empty((len(sources), len(sources)), dtype=np.float32), 0
            whole = len(sources) == rows.shape[1] and sources[-1] == len(sources) - 1
            block[start : start + len(rows)] = rows if whole else rows[:, sources]
            filled += len(rows)
            done += len(rows)
            del rows
            if progress:
                print(
                    f"{label} ({method}, {jobs} jobs): {done}/{total} rows of {len(order)} meshes, "
                    f"{time.monotonic() - started:.0f} s",
                    file=sys.stderr,
                    flush=True,
                )
            if filled == len(sources):
                n_meshes += 1
                yield key, sources, _symmetrise_in_place(block, scales[key])
                block = None
    finally:
        pool.shutdown(cancel_futures=True)


# --------------------------------------------------------------------------------------------------
# ULRSSM's dist/<k>.mat: estimate, then each distinct matrix once, links for the rest

_SOLVER_BYTES_PER_VERTEX = 40_000
"""Peak memory of one heat-method task beyond its result, per mesh vertex (factorisations, (V, B) and
(2F, B) solve blocks; measured: 0.34 GB at 9,369 vertices), for :func:`ulrssm_geodesic_estimate`."""
_PROCESS_BYTES = 150 << 20
"""Resident memory of a Python process with numpy, scipy and libigl loaded (a worker or this one)."""


def ulrssm_geodesic_estimate(
    shapes: list[_GeodesicShape], needed: dict, meshes: dict, jobs: int, computed: bool
) -> dict:
    """The ULRSSM geodesics export's cost before it starts: ``files`` distinct matrices (one per full
    mesh, one per distinct cut a scan keeps) for ``sides`` pair sides, ``disk_bytes`` their MAT files
    (Σ 4 n² + headers; links cost nothing), ``memory_bytes`` the peak resident memory of this process
    and its ``jobs`` workers together (the largest (R, R) float32 block, a write chunk, and while
    ``computed``: the tasks in flight, (rows, V) float32 each, plus each worker's solver)."""
    distinct = {(sh.key, len(sh.p2f), sh.p2f.tobytes()) for sh in shapes}
    disk = sum(mat_size(n) for _, n, _ in distinct)
    memory = 0
    for key, sources in needed.items():
        r, v = len(sources), len(meshes[key][0])
        peak = _PROCESS_BYTES + 4 * r * r + _WRITE_CHUNK_BYTES  # this process: the block, a write chunk
        if computed:  # `jobs` results waiting here + one being cut in; per worker: its solve and pickled result
            task = 4 * min(r, _task_rows(v, len(meshes[key][1]))) * v  # one task's (rows, V) float32 result
            workers = max(1, jobs)
            peak += (workers + 1) * task + workers * (_PROCESS_BYTES + _SOLVER_BYTES_PER_VERTEX * v + 2 * task)
        memory = max(memory, peak)
    return {
        "meshes": len(needed),
        "files": len(distinct),
        "sides": len(shapes),
        "disk_bytes": int(disk),
        "memory_bytes": int(memory),
        "largest_mesh_rows": max((len(s) for s in needed.values()), default=0),
    }


def _gb(n: float) -> str:
    return f"{n / 1e9:.2f} GB"


def _write_ulrssm_dist(
    tmp: Path,
    out: Path,
    shapes: list[_GeodesicShape],
    meshes: dict,
    needed: dict,
    numbers: dict,
    method: str,
    jobs: int,
    progress: bool,
    rows_folders=None,
    free_bytes: int | None = None,
) -> dict:
    """Write ``<tmp>/<split>/<i>/dist/<side>.mat`` of every shape (:func:`write_ulrssm`); returns the
    summary written to ``logs/geodesics.json`` (estimate, files, links, copies, bytes, seconds)."""
    import hashlib
    import time

    from becos.atomic import link_or_copy

    started = time.monotonic()
    scales = mesh_sqrt_areas(shapes)
    groups: dict[str, dict[bytes, list[_GeodesicShape]]] = {}
    for sh in shapes:
        digest = hashlib.sha1(np.ascontiguousarray(sh.p2f, dtype=np.int64).tobytes()).digest()
        groups.setdefault(sh.key, {}).setdefault(digest, []).append(sh)
    estimate = ulrssm_geodesic_estimate(shapes, needed, meshes, jobs, rows_folders is None)
    free = int(shutil.disk_usage(tmp).free if free_bytes is None else free_bytes)
    print(
        f"export-ulrssm geodesics: {estimate['files']} distinct dist matrices of {estimate['meshes']} meshes for "
        f"{estimate['sides']} pair sides (the rest hard links): disk {_gb(estimate['disk_bytes'])}, peak memory "
        f"~{_gb(estimate['memory_bytes'])} ({jobs} jobs, largest mesh {estimate['largest_mesh_rows']} vertices); "
        f"free on the output's disk: {_gb(free)}",
        file=sys.stderr,
        flush=True,
    )
    if estimate["disk_bytes"] > free:
        raise DiskEstimateError(
            out,
            f"the ULRSSM geodesic matrices need about {_gb(estimate['disk_bytes'])} ({estimate['files']} distinct "
            f"(V, V) float32 .mat files of {estimate['meshes']} meshes) but its file system has {_gb(free)} "
            f"free; nothing was written",
            "free disk space, choose another --out on a larger disk, or export geodesics of fewer splits "
            "(--splits test)",
        )

    def dist_path(sh: _GeodesicShape) -> Path:
        return tmp / sh.split / str(numbers[(sh.split, sh.pair_id)]) / "dist" / f"{sh.side}.mat"

    written = links = copies = nbytes = 0
    for key, sources, block in _mesh_blocks(
        meshes, needed, scales, method, jobs, progress, rows_folders, "export-ulrssm geodesics"
    ):
        for group in groups[key].values():
            first = group[0]
            cut = np.searchsorted(sources, first.p2f)
            whole = len(cut) == len(sources) and np.array_equal(cut, np.arange(len(sources)))
            path = dist_path(first)
            path.parent.mkdir(exist_ok=True)
            nbytes += write_symmetric_mat(path, len(cut), _cut_chunks(block, None if whole else cut))
            written += 1
            for sh in group[1:]:
                dist_path(sh).parent.mkdir(exist_ok=True)
                if link_or_copy(path, dist_path(sh)):
                    links += 1
                else:
                    copies += 1
                    nbytes += path.stat().st_size
        del block
    if copies:
        print(
            f"export-ulrssm geodesics: {out}: the file system refused hard links; {copies} dist files are "
            f"copies ({_gb(nbytes - estimate['disk_bytes'])} more than estimated)",
            file=sys.stderr,
            flush=True,
        )
    summary = {
        "method": method,
        "estimate": {**estimate, "free_bytes": free},
        "written": written,
        "hard_links": links,
        "copies": copies,
        "bytes": nbytes,
        "seconds": round(time.monotonic() - started, 1),
        "rows_from": [str(p) for p in rows_folders] if rows_folders is not None else None,
    }
    if progress:
        print(f"export-ulrssm geodesics: {json.dumps(summary)}", file=sys.stderr, flush=True)
    return summary


GEODESIC_FOLDER = "geodesic_dist_matrices"
"""Folder of the loaders' geodesic layout (:func:`write_geodesic_matrices`)."""
_GEODESIC_TASK_ROWS = 4096
"""Distance rows per parallel task (one solver set-up each: ~0.3 s against ~5 s of rows at 10k vertices)."""
_GEODESIC_TASK_BYTES = 80 << 20
"""Bytes of one task's (rows, V) float32 result in :func:`_mesh_blocks` (it crosses a process pipe
and waits in memory): ~2,000 rows at 10k vertices, one solver set-up (~0.9 s) per ~15 s of rows."""


def _task_rows(n_vertices: int, n_faces: int) -> int:
    """Source rows per task of :func:`_mesh_blocks` on a mesh of ``n_vertices`` and ``n_faces``: at most
    :data:`_GEODESIC_TASK_ROWS`, and at most :data:`_GEODESIC_TASK_BYTES` of result (at least 256),
    rounded down to a multiple of the heat solver's batch (:func:`becos.geodesics.heat_block_size`), so
    the tasks' rows are bitwise those of one :func:`becos.geodesics.distance_rows` call over all sources
    (``becos geodesic-rows``)."""
    from becos.geodesics import heat_block_size

    rows = int(max(1, min(_GEODESIC_TASK_ROWS, max(256, _GEODESIC_TASK_BYTES // (4 * max(n_vertices, 1))))))
    batch = heat_block_size(n_faces)
    return rows - rows % batch if rows >= batch else rows


@dataclass(frozen=True)
class _GeodesicShape:
    """One shape of one pair whose matrix is to be written."""

    split: str
    pair_id: str
    side: int  # 0 = X, 1 = Y
    dataset: str
    name: str
    stem: str  # released file stem (:func:`released_file_stem`)
    mesh_id: str
    key: str  # the full mesh up to rigid motion (cache key of its rows)
    p2f: np.ndarray  # (V,) its vertices on the full mesh
    sqrt_area: float  # the full shape's sqrt-area in the units of the record's vertices
    setting: str = ""
    vertices: np.ndarray | None = None  # (V, 3) float64 as written (only when the plan keeps arrays)
    faces: np.ndarray | None = None  # (F, 3) int64


def _full_mesh_key(vertices: np.ndarray, faces: np.ndarray, dataset: str, name: str, variant: int) -> str:
    """A file-name-safe key of a full mesh up to rigid motion (:func:`becos.geodesics.shape_key`)."""
    import hashlib

    from becos.geodesics import shape_key
    from becos.mesh import TriMesh

    digest = hashlib.sha1(repr(shape_key(TriMesh(vertices, faces))).encode()).hexdigest()[:16]
    return f"{_id_field(dataset)}_{_id_field(name)}_v{int(variant)}_{digest}"


def _geodesic_plan(
    records: Iterable[PairRecord], splits, each=None, keep_arrays: bool = False
) -> tuple[list[_GeodesicShape], dict, dict, dict]:
    """Shapes to write, unique full meshes ``{key: (vertices, faces)}``, the rows each needs
    ``{key: sorted unique full vertices}`` (the union of its shapes' ``partial_to_full``) and the pair
    numbers ``{(split, pair_id): index}`` of ALL records (ascending pair_id per split, as every export
    numbers pairs; so a split subset keeps the whole export's numbering). Streams the records, calling
    ``each(record)`` on every one (to write other files in the same pass). ``keep_arrays``: each shape
    also keeps its written vertices and faces."""
    keep = None if splits is None else {str(s) for s in splits}
    shapes, meshes, needed, ids = [], {}, {}, {}
    for record in records:
        _check_record(record, None)
        if each is not None:
            each(record)
        ids.setdefault(str(record.meta["split"]), []).append(str(record.pair_id))
        if keep is not None and str(record.meta["split"]) not in keep:
            continue
        infos = released_infos(record)
        normalised = bool(record.meta.get("area_normalised", False))
        for (s, k), info in zip(SIDES, infos):
            vertices, faces = full_shape(record, s)
            key = _full_mesh_key(vertices, faces, info["org_dataset"], info["name"], info["remesh_variant"])
            meshes.setdefault(key, (np.array(vertices, dtype=np.float64), np.array(faces, dtype=np.int64)))
            p2f = np.asarray(record[f"{s}_partial_to_full"], dtype=np.int64)
            needed.setdefault(key, []).append(p2f)
            scanned = "partial2full" in info
            shapes.append(
                _GeodesicShape(
                    str(record.meta["split"]),
                    str(record.pair_id),
                    k,
                    info["org_dataset"],
                    info["name"],
                    released_file_stem(k, info["name"], info["remesh_variant"], record.pair_id if scanned else None),
                    info["mesh_id"],
                    key,
                    p2f,
                    1.0 if normalised else float(record[f"{s}_full_sqrt_area"]),
                    str(record.meta["setting"]),
                    np.asarray(record[f"{s}_vertices"], dtype=np.float64) if keep_arrays else None,
                    np.asarray(record[f"{s}_faces"], dtype=np.int64) if keep_arrays else None,
                )
            )
    numbers = {}
    for split, pair_ids in ids.items():
        pair_ids.sort()
        dup = sorted({a for a, b in zip(pair_ids, pair_ids[1:]) if a == b})
        if dup:
            raise ExportError(f"split {split}: pair ids {dup[:5]} occur more than once. Fix: pass each pair once")
        numbers.update({(split, pid): i for i, pid in enumerate(pair_ids)})
    return shapes, meshes, {key: np.unique(np.concatenate(v)) for key, v in needed.items()}, numbers


def _geodesic_task(args):
    from becos.geodesics import distance_rows

    key, start, vertices, faces, sources, method = args
    return key, start, distance_rows(vertices, faces, sources, method)


def _compute_geodesic_rows(
    meshes: dict, needed: dict, method: str, jobs: int, folder: Path, progress: bool
) -> dict[str, np.ndarray]:
    """``{key: (len(needed[key]), V) float32 memmap}`` of distance rows, computed in tasks of
    :data:`_GEODESIC_TASK_ROWS` rows by ``jobs`` processes (1: in this process), in ``folder``."""
    import time
    from concurrent.futures import ProcessPoolExecutor

    out = {
        key: np.lib.format.open_memmap(
            folder / f"{key}.npy", mode="w+", dtype=np.float32, shape=(len(needed[key]), len(meshes[key][0]))
        )
        for key in meshes
    }
    tasks = [
        (key, start, *meshes[key], needed[key][start : start + _GEODESIC_TASK_ROWS], method)
        for key in sorted(meshes, key=lambda k: -len(needed[k]))
        for start in range(0, len(needed[key]), _GEODESIC_TASK_ROWS)
    ]
    started, done, total = time.monotonic(), 0, sum(len(r) for r in needed.values())
    pool = ProcessPoolExecutor(max_workers=jobs) if jobs > 1 and len(tasks) > 1 else None
    try:
        for key, start, rows in pool.map(_geodesic_task, tasks) if pool else map(_geodesic_task, tasks):
            out[key][start : start + len(rows)] = rows
            done += len(rows)
            if progress:
                print(
                    f"geodesics ({method}, {jobs} jobs): {done}/{total} rows of {len(meshes)} meshes, "
                    f"{time.monotonic() - started:.0f} s",
                    file=sys.stderr,
                    flush=True,
                )
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    return out


def _shape_matrix(shape: _GeodesicShape, rows: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """(V, V) float32 symmetrised matrix of a shape's vertices from its full mesh's rows (float32
    throughout: two (V, V) arrays at a time, no float64 copies of a 10k-vertex matrix)."""
    sub = np.asarray(matrix[np.searchsorted(rows, shape.p2f)], dtype=np.float32)
    if not (len(shape.p2f) == sub.shape[1] and np.array_equal(shape.p2f, np.arange(sub.shape[1]))):
        sub = sub[:, shape.p2f]
    sym = sub.T + sub
    sym *= np.float32(0.5)
    np.fill_diagonal(sym, 0.0)
    return sym


def write_geodesics(
    records: Iterable[PairRecord],
    out_dir: str | Path,
    method: str = "heat",
    *,
    overwrite: bool = False,
    progress: bool = False,
    splits=None,
    jobs: int = 1,
) -> Path:
    """Write ``<out>/<split>/geodesics/<shape id>.npy``: (V, V) float32 geodesic distances of both
    shapes of every pair (units of the record's vertices), with the shape ids of :func:`write_psmal`
    (pass the same records).

    Each distinct full mesh (up to rigid motion: a remesh variant recurring across pairs) is solved
    once, for the union of the vertices its shapes keep, by ``jobs`` processes; ``splits`` limits the
    export to those splits (numbering stays that of the whole split). ``out_dir`` may already hold a
    PSMAL export; each ``<split>/geodesics`` folder appears whole (built aside, renamed in). Existing
    geodesics folders are an error unless ``overwrite``.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ExportError(f"{out}: exists and is not a folder. Fix: choose another output path")
    existing = sorted(p for p in out.glob("*/geodesics") if p.exists()) if out.is_dir() else []
    if existing and not overwrite:
        raise ExportError(
            f"{existing[0]}: geodesic matrices exist already. Fix: pass overwrite=True (--force) "
            f"or write into a new folder"
        )
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out, prefix=".geodesics.tmp-"))
    try:
        shapes, meshes, needed, numbers = _geodesic_plan(records, splits)
        rows = _compute_geodesic_rows(meshes, needed, method, jobs, tmp, progress)
        built = {}
        for sh in shapes:
            target = tmp / sh.split / "geodesics"
            target.mkdir(parents=True, exist_ok=True)
            built[sh.split] = target
            shape_id = psmal_shape_id(numbers[(sh.split, sh.pair_id)], sh.side, sh.dataset, sh.name)
            np.save(target / f"{shape_id}.npy", _shape_matrix(sh, needed[sh.key], rows[sh.key]))
        del rows
        for split, target in built.items():
            final = out / split / "geodesics"
            final.parent.mkdir(exist_ok=True)
            if final.exists():
                if not overwrite:
                    raise ExportError(f"{final}: appeared while writing. Fix: rerun with overwrite=True (--force)")
                old = Path(tempfile.mkdtemp(dir=out, prefix=".geodesics.old-"))
                os.replace(final, old / "geodesics")
                os.replace(target, final)
                shutil.rmtree(old, ignore_errors=True)
            else:
                os.replace(target, final)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out


GEODESIC_LAYOUTS = ("geo-lora", "dsmk")
"""The geodesic layouts :func:`write_geodesic_matrices` can write (``exports.geodesic_layouts``)."""
DSMK_FOLDER = "dsmk"
"""Folder of DeepShapeMatchingKit's geodesic cache layout (:func:`write_geodesic_matrices`)."""


def dsmk_cache_name(vertices: np.ndarray, faces: np.ndarray) -> str:
    """DeepShapeMatchingKit's geodesic cache file name of a shape, ``<sha1>_0.npz``, as its
    ``BeCoSDataset`` (``shape_scale: default``) looks it up: ``utils.cache_util.get_cached_compute`` hashes
    the loaded OFF's vertices as float32 and its faces as int64 (``hash_arrays``: SHA-1 over the raw bytes
    of each array in turn); ``_0`` is the first slot of its collision chain.

    Args:
        vertices: (V, 3) the shape's written vertices (any float dtype; cast to float32 as the loader does).
        faces: (F, 3) its faces.
    """
    import hashlib

    digest = hashlib.sha1()
    digest.update(np.ascontiguousarray(vertices, dtype=np.float32).view(np.uint8))
    digest.update(np.ascontiguousarray(faces, dtype=np.int64).view(np.uint8))
    return f"{digest.hexdigest()}_0.npz"


def _dsmk_reads(setting: str, side: int) -> bool:
    """Whether DeepShapeMatchingKit's BeCoSDataset asks for the geodesics of this shape: only the first
    shape of each pair it forms is given ``dist``; it forms (0, 1) always and (1, 0) for F2F and P2P."""
    return side == 0 or setting in ("partial_partial", "full_full")


def symmetric_block(rows: np.ndarray, sources: np.ndarray, sqrt_area: float) -> np.ndarray:
    """(R, R) float32: the distances between the R ``sources`` of a mesh, from its (R, V) ``rows``
    (row i from vertex ``sources[i]``), symmetrised (the mean of d(a, b) and d(b, a)), zero on the
    diagonal and divided by ``sqrt_area``: the geo-lora matrix of a shape keeping exactly those vertices,
    and, cut to ``[i][:, i]``, of any shape keeping a subset (the same float32 operations entry by entry
    as :func:`_shape_matrix`, so the same bytes)."""
    n = rows.shape[1]
    whole = len(sources) == n and np.array_equal(sources, np.arange(n))
    sub = np.asarray(rows if whole else rows[:, sources], dtype=np.float32)
    sym = sub.T + sub
    del sub
    sym *= np.float32(0.5)
    np.fill_diagonal(sym, 0.0)
    sym /= np.float32(sqrt_area)
    return sym


def mesh_sqrt_areas(shapes: list[_GeodesicShape], known: Mapping | None = None) -> dict[str, float]:
    """``{key: sqrt_area}`` of the full meshes of ``shapes`` (the one normaliser of each mesh's block:
    its first shape's, or ``known``'s), checking that every shape of a mesh agrees to 1e-6."""
    out = dict(known or {})
    for sh in shapes:
        scale = out.setdefault(sh.key, sh.sqrt_area)
        if abs(sh.sqrt_area - scale) > 1e-6 * abs(scale):
            raise ExportError(
                f"shape {sh.name} (pair {sh.pair_id}): sqrt-area {sh.sqrt_area!r} differs from {scale!r} of "
                f"the same full mesh {sh.key}. Fix: build every setting's store with the same config "
                f"(area_normalised) and rerun `becos geodesic-plan`"
            )
    return {sh.key: out[sh.key] for sh in shapes}


def _block_cut(path: Path, cut: np.ndarray, whole: bool) -> np.ndarray:
    """(n, n) float32 in memory: the block file's rows and columns ``cut`` (all of it when ``whole``)."""
    block = np.load(path, mmap_mode="r")
    return np.array(block) if whole else block[np.ix_(cut, cut)]


def _blocks_for(
    shapes: list, meshes: dict, needed: dict, rows_folders, method: str, jobs: int, work: Path, progress: bool
) -> dict[str, tuple[np.ndarray, Path, float]]:
    """``{key: (sorted source vertices, (R, R) block file, sqrt_area)}`` (:func:`symmetric_block`):
    read from ``rows_folders`` (outputs of ``becos geodesic-rows``; they may hold more meshes, and
    rows other stores need) or computed here one mesh at a time (:func:`_mesh_blocks`: no rows file)
    and saved into ``work``."""
    from becos.atomic import save_npy

    if rows_folders is None:
        scales = mesh_sqrt_areas(shapes)
        out = {}
        for key, sources, block in _mesh_blocks(meshes, needed, scales, method, jobs, progress):
            path = work / f"{key}.block.npy"
            save_npy(path, block)
            del block
            out[key] = (sources, path, scales[key])
        return out
    from becos.geodesic_jobs import load_rows

    loaded = load_rows(rows_folders)
    out = {}
    for key in meshes:
        if key not in loaded:
            raise ExportError(
                f"{', '.join(map(str, rows_folders))}: no geodesic rows of mesh {key}. Fix: plan "
                f"the rows with this store and the same splits (`becos geodesic-plan`), then "
                f"rerun `becos geodesic-rows`"
            )
        have, path, scale = loaded[key]
        if not np.isin(needed[key], have).all():
            raise ExportError(
                f"geodesic rows of mesh {key}: {len(have)} rows, missing some of the {len(needed[key])} this "
                f"store needs. Fix: rerun `becos geodesic-plan` and `becos geodesic-rows` with this store"
            )
        out[key] = loaded[key]
    mesh_sqrt_areas(shapes, {key: scale for key, (_, _, scale) in out.items()})  # the store agrees with them
    return out


def write_geodesic_matrices(
    records: Iterable[PairRecord],
    out_dir: str | Path,
    method: str = "heat",
    *,
    splits=None,
    jobs: int = 1,
    metadata: Mapping | None = None,
    overwrite: bool = False,
    progress: bool = False,
    rows=None,
    layouts=GEODESIC_LAYOUTS,
) -> Path:
    """Geodesic matrices in the layouts loaders read (``docs/released-layout.md``, section 3):

    - ``<out>/geodesic_dist_matrices/<stem>.npy``: (V, V) float32 distances between the vertices of the
      released file ``<stem>.off`` (:func:`released_file_stem`; measured on the shape's FULL mesh),
      divided by the full shape's sqrt-area (the released ``surface_area_after_scaling``): the file
      geo-lora's ``BecosDataset`` loads from ``./geodesic_dist_matrices/<off stem>.npy`` instead of
      computing it. ``index.csv`` beside them lists every shape of every pair with its split, pair
      index, pair_id, stem, mesh_id, vertex count, the sqrt-area (multiply to get the record's units)
      and its DeepShapeMatchingKit file.
    - ``<out>/dsmk/<split>/dist/<sha1>_0.npz``: DeepShapeMatchingKit's geodesic cache
      (:func:`dsmk_cache_name`; keys ``verts`` float32, ``faces`` int64, ``result`` (V, V) float32 in
      the units of the written vertices, which its ``BeCoSDataset`` divides by the info file's
      ``surface_area_after_scaling``) of every shape it gives geodesics to; link or copy
      ``dsmk/<split>/dist`` to ``<released export>/<split>/dist``.
    - ``<out>/logs/config.yaml`` as the other exports.

    Each distinct full mesh is solved once for the union of the vertices its shapes keep, by ``jobs``
    processes, or its blocks are read from ``rows`` (folders written by ``becos geodesic-rows``);
    ``splits`` (e.g. ``["test"]``) limits the export to those splits. ``layouts``: which of
    :data:`GEODESIC_LAYOUTS` to write (``index.csv`` is always written).

    Every matrix is written once: a geo-lora file equal to its mesh's block (:func:`symmetric_block`;
    every full shape) is a hard link of the block file (a copy where the file system has no hard
    links), so a full mesh shared by pairs, sides and settings costs its bytes once; other shapes' files
    are cut from the block, in one buffered write each. A DeepShapeMatchingKit file is a zip holding the
    shape's own vertices, so it is written whole for every shape it needs (its ``result``: the block cut
    times the sqrt-area, equal to the unnormalised matrix to float32 round-off).
    """
    from becos.atomic import link_or_copy, save_npy, save_npz

    unknown = sorted(set(layouts) - set(GEODESIC_LAYOUTS))
    if unknown or not layouts:
        raise ExportError(f"geodesic layouts {unknown or '(none)'}: unknown. Fix: choose from {GEODESIC_LAYOUTS}")

    out = Path(out_dir)
    with _staged_dir(out, overwrite) as tmp:
        shapes, meshes, needed, numbers = _geodesic_plan(records, splits, keep_arrays=True)
        work = tmp / ".rows"
        work.mkdir()
        blocks = _blocks_for(shapes, meshes, needed, rows, method, jobs, work, progress)
        folder = tmp / GEODESIC_FOLDER
        folder.mkdir()
        table, written, dsmk_written = [], set(), set()
        for sh in shapes:
            sources, path, scale = blocks[sh.key]
            cut = np.searchsorted(sources, sh.p2f)
            whole = len(cut) == len(sources) and np.array_equal(cut, np.arange(len(sources)))
            matrix = None  # the shape's geo-lora matrix, when read
            if "geo-lora" in layouts and sh.stem not in written:  # one full mesh in several pairs: one file
                written.add(sh.stem)
                if whole:
                    link_or_copy(path, folder / f"{sh.stem}.npy")
                else:
                    matrix = _block_cut(path, cut, whole)
                    save_npy(folder / f"{sh.stem}.npy", matrix)
            dsmk_file = ""
            if "dsmk" in layouts and _dsmk_reads(sh.setting, sh.side):
                dsmk_file = f"{DSMK_FOLDER}/{sh.split}/dist/{dsmk_cache_name(sh.vertices, sh.faces)}"
                if dsmk_file not in dsmk_written:
                    dsmk_written.add(dsmk_file)
                    result = _block_cut(path, cut, whole) if matrix is None else matrix
                    result *= np.float32(scale)  # DSMK divides by the info file's sqrt-area itself
                    (tmp / dsmk_file).parent.mkdir(parents=True, exist_ok=True)
                    save_npz(tmp / dsmk_file, verts=sh.vertices.astype(np.float32), faces=sh.faces, result=result)
                    del result
            del matrix
            table.append(
                [
                    sh.split,
                    numbers[(sh.split, sh.pair_id)],
                    sh.pair_id,
                    sh.side,
                    sh.stem,
                    sh.mesh_id,
                    len(sh.p2f),
                    repr(scale),
                    dsmk_file,
                ]
            )
        shutil.rmtree(work)
        _write_ids(
            folder / "index.csv",
            ["split", "index", "pair_id", "side", "stem", "mesh_id", "n_vertices", "sqrt_area", "dsmk_file"],
            table,
        )
        counts = {split: len({r[2] for r in table if r[0] == split}) for split in dict.fromkeys(r[0] for r in table)}
        _write_log(
            tmp,
            "becos.export.write_geodesic_matrices",
            f"becos geodesic matrices ({method}, divided by sqrt-area; DeepShapeMatchingKit cache)",
            counts,
            None,
            metadata,
        )
    return out
