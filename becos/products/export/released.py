"""The released BeCoS folder layout (:func:`write_released`): ``<out>/<split>/<i>/`` with two OFF meshes,
``corres_*.npy`` and one info pickle per shape, as read by DeepShapeMatchingKit's ``BeCoSDataset`` and
similar loaders; also the released file stems and mesh ids the geodesic layouts name files by.

The layout, every file and key, and where becos differs from the reference (the swapped P2P masks) are
documented in ``docs/released-layout.md``.
"""

from __future__ import annotations

import io
import pickle
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from becos.build.record import SETTINGS, PairRecord
from becos.core.formats.write import off_text
from becos.products.export.staging import (
    IDS_FILE,
    SIDES,
    ExportError,
    Staging,
    check_record,
    place_by_split,
    staged_dir,
    write_ids,
    write_log,
)

PICKLE_PROTOCOL = 4


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


def _write_annotation_files(folder: Path, record: PairRecord) -> bool:
    labels = {s: np.asarray(record[f"{s}_annotation"], dtype=np.int8) for s, _ in SIDES}
    if not any((a >= 0).any() for a in labels.values()):
        return False
    for s, k in SIDES:
        np.save(folder / f"{k}_annotation.npy", labels[s])
    return True


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
    with staged_dir(out, overwrite) as tmp:
        staging = Staging(tmp, "export-released", progress)
        for record in records:
            check_record(record, setting)
            _write_released_pair(staging.add(record), record, setting)
        rows, counts = place_by_split(staging, tmp)
        write_ids(tmp / IDS_FILE, ["split", "index", "pair_id", "x", "y"], rows)
        write_log(tmp, "becos.products.export.write_released", "becos released BeCoS layout", counts, setting, metadata)
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
