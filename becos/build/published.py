"""The published BeCoS pair lists (``config/pairings_original_<setting>.pkl``) <-> pair manifests.

:func:`import_published` turns a published pickle (three lists ``[train, test, val]`` of shape-dict
pairs) into a manifest in the schema of :mod:`becos.build.sampling` plus the published face targets and
random rotations; :func:`save_cameras` keeps P2P cameras beside it (``cam_pos`` (N, 2, 10, 3) float64,
no pickle); :func:`write_published_pickle` writes a manifest back in the published schema, exactly
round-tripping. Loading uses a restricted unpickler (numpy arrays only). The pickle schema and the
extra columns: docs/design/sampling.md.
"""

from __future__ import annotations

import io
import pickle
import re
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from becos.atomic import save_npz, write_bytes
from becos.build.sampling import (
    JOINER,
    MANIFEST_COLUMNS,
    SETTINGS,
    UNDEFINED,
    find_template_row,
    pair_id_of,
    row_field,
    shape_key,
    sort_manifest,
)
from becos.errors import ConfigError, InputFileError
from becos.seeding import rng_for, stable_hash
from becos.sources.catalog import frame_rotation

PUBLISHED_SPLITS = ("train", "test", "val")
"""Order of the split lists inside a published pickle."""
SHAPE_FIELDS = (
    "name",
    "org_dataset",
    "category",
    "file_path",
    "scale",
    "rot",
    "partial_full_template",
    "partial_full_dataset",
    "desired_n_face_remeshed",
    "random_rot",
)
N_CAMERAS = 10
FACE_TARGET_RANGE = (18000, 20000)
P2P_OVERLAP_HISTOGRAM = (20, 1850, 2391, 2321, 2828, 3163, 3391, 3247, 1715, 2)
"""Overlap histogram of the published P2P benchmark, as printed in the BeCoS paper (SGP 2025;
reference-facts §12): both directions of every pair (``x_overlap`` and ``y_overlap``), counts per
10 % bin ``[k/10, (k+1)/10)``, centres 5 %, 15 %, ..., 95 %; sum 20,928 = 2 × 10,464 pairs
(10,185 train + 137 val + 142 test)."""

_NUMPY_CORE = "numpy._core" if int(np.__version__.split(".")[0]) >= 2 else "numpy.core"
_ALLOWED = {
    ("numpy", "ndarray"),
    ("numpy", "dtype"),
    ("numpy", "array"),
    ("numpy.core.multiarray", "_reconstruct"),
    ("numpy._core.multiarray", "_reconstruct"),
    ("numpy.core.multiarray", "scalar"),
    ("numpy._core.multiarray", "scalar"),
}


class _RestrictedUnpickler(pickle.Unpickler):
    """Unpickler that resolves only numpy array/dtype reconstruction (plus builtin containers)."""

    def find_class(self, module: str, name: str):
        if (module, name) not in _ALLOWED:
            raise pickle.UnpicklingError(f"global {module}.{name} is not allowed in a pair list")
        if module.startswith("numpy.core") or module.startswith("numpy._core"):
            module = _NUMPY_CORE + module.split("core", 1)[1]
        return super().find_class(module, name)


def load_published(path: str | Path) -> list[list[tuple[dict, dict]]]:
    """The raw pair lists ``[train, test, val]`` of a published (or exported) pickle, safely."""
    path = Path(path)
    try:
        data = _RestrictedUnpickler(io.BytesIO(path.read_bytes())).load()
    except FileNotFoundError:
        raise InputFileError(
            path, "file not found", "give the path of config/pairings_original_<setting>.pkl"
        ) from None
    except (pickle.UnpicklingError, EOFError, AttributeError, ImportError) as exc:
        raise InputFileError(
            path,
            f"not a readable pair list ({exc})",
            "use a pair-list pickle from the BeCoS repository or write_published_pickle",
        ) from None
    if not (isinstance(data, list) and len(data) == 3 and all(isinstance(s, list) for s in data)):
        raise InputFileError(
            path,
            "expected a list of 3 lists [train, test, val]",
            "use a pair-list pickle from the BeCoS repository or write_published_pickle",
        )
    return data


def setting_from_path(path: str | Path) -> str | None:
    """``pairings_original_full_full.pkl`` -> ``full_full`` (None if the name does not tell)."""
    m = re.search(r"(full_full|partial_full|partial_partial)", Path(path).name)
    return m.group(1) if m else None


@dataclass
class PublishedImport:
    """Result of :func:`import_published`: the manifest, P2P cameras by pair_id (or None), counts."""

    manifest: pd.DataFrame
    cameras: dict[str, np.ndarray] | None
    report: dict = field(default_factory=dict)


def _pair_category(x: dict, y: dict) -> str:
    for s in (x, y):
        if s["category"] != JOINER:
            return str(s["category"])
    return JOINER


def import_published(
    path: str | Path,
    *,
    setting: str | None = None,
    seed: int = 42,
    n_variants: int = 4,
    n_chunks: int = 64,
    datasets=None,
) -> PublishedImport:
    """A published pair list as a manifest (schema of :mod:`becos.build.sampling` + extras, module doc).

    Args:
        path: the pickle.
        setting: defaults to the setting named in the file name (or stored in exported pickles).
        seed: global seed for the derived ``seed`` column (published pairs carry none).
        n_variants, n_chunks: as in :func:`becos.build.sampling.sample_pairs`.
        datasets: keep only pairs whose two shapes come from these datasets (e.g. ``{'tosca'}``).
            Counted in ``report['dropped_missing_dataset']``.
    """
    raw = load_published(path)
    setting = setting or setting_from_path(path)
    if setting is None:  # exported pickles carry it
        setting = next((p[0].get("becos", {}).get("setting") for s in raw for p in s if "becos" in p[0]), None)
    if setting not in SETTINGS:
        raise ConfigError(f"{path}: cannot tell the setting; pass setting= one of {SETTINGS}")
    keep = None if datasets is None else {str(d) for d in datasets}
    records, cameras, dropped = [], {}, Counter()
    for split, pairs in zip(PUBLISHED_SPLITS, raw):
        seen = Counter()
        for index, (x, y) in enumerate(pairs):
            xk, yk = shape_key(x["org_dataset"], x["name"]), shape_key(y["org_dataset"], y["name"])
            copy = seen[(xk, yk)]
            seen[(xk, yk)] += 1
            if keep is not None and not {x["org_dataset"], y["org_dataset"]} <= keep:
                dropped[split] += 1
                continue
            rec = _manifest_row(setting, split, index, x, y, copy, seed, n_variants, n_chunks)
            records.append(rec)
            if "cam_pos" in x and "cam_pos" in y:
                cameras[rec["pair_id"]] = np.stack(
                    [np.asarray(x["cam_pos"], np.float64), np.asarray(y["cam_pos"], np.float64)]
                )
    df = pd.DataFrame.from_records(records)
    if df.empty:
        df = pd.DataFrame(columns=list(MANIFEST_COLUMNS))
    for c in ("copy", "seed", "x_variant", "y_variant", "chunk"):
        df[c] = df[c].astype(np.int64)
    if df["pair_id"].duplicated().any():
        raise InputFileError(path, "two pairs share a pair_id", "check the file for duplicated becos metadata")
    df = sort_manifest(df)
    report = {
        "n_pairs": {s: int((df["split"] == s).sum()) for s in PUBLISHED_SPLITS},
        "dropped_missing_dataset": dict(dropped),
    }
    df.attrs["report"] = report
    return PublishedImport(df, cameras or None, report)


def _manifest_row(
    setting: str, split: str, index: int, x: dict, y: dict, copy: int, seed, n_variants, n_chunks
) -> dict:
    """The manifest row of the published pair ``(x, y)``, the ``index``-th of ``split`` and the ``copy``-th
    of its shapes: ids, seed, variants and chunk from the becos metadata of an exported pickle, else
    derived (arguments as :func:`import_published`), and the published face targets and rotations."""
    xk, yk = shape_key(x["org_dataset"], x["name"]), shape_key(y["org_dataset"], y["name"])
    meta = x.get("becos")
    if meta is not None:
        pid, pseed, copy, chunk = meta["pair_id"], int(meta["seed"]), int(meta["copy"]), int(meta["chunk"])
        category, xv, yv = meta["category"], int(meta["variant"]), int(y["becos"]["variant"])
    else:
        pid = pair_id_of(setting, xk, yk, copy)
        pseed = stable_hash(seed, pid, bits=63)
        chunk = stable_hash(pid) % n_chunks
        category = _pair_category(x, y)
        xv, yv = stable_hash(pseed, "x_variant") % n_variants, stable_hash(pseed, "y_variant") % n_variants
    rec = {
        "pair_id": pid,
        "setting": setting,
        "split": split,
        "category": category,
        "copy": copy,
        "x_dataset": x["org_dataset"],
        "x_name": x["name"],
        "y_dataset": y["org_dataset"],
        "y_name": y["name"],
        "seed": pseed,
        "x_variant": xv,
        "y_variant": yv,
        "chunk": chunk,
        "published_index": index,
        "x_category": x["category"],
        "y_category": y["category"],
        "x_face_target": int(x["desired_n_face_remeshed"]),
        "y_face_target": int(y["desired_n_face_remeshed"]),
    }
    for side, s in (("x", x), ("y", y)):
        rot = np.asarray(s["random_rot"], dtype=np.float64).reshape(9)
        rec.update({f"{side}_random_rot_{i}": float(v) for i, v in enumerate(rot)})
    return rec


def published_shapes(manifest: pd.DataFrame) -> pd.DataFrame:
    """The distinct shapes of a manifest (``dataset, name``), sorted."""
    x = manifest[["x_dataset", "x_name"]].set_axis(["dataset", "name"], axis=1)
    y = manifest[["y_dataset", "y_name"]].set_axis(["dataset", "name"], axis=1)
    return pd.concat([x, y]).drop_duplicates().sort_values(["dataset", "name"]).reset_index(drop=True)


# --------------------------------------------------------------------------------------------
# cameras side file


def save_cameras(path: str | Path, cameras: Mapping[str, np.ndarray]) -> None:
    """Write ``{pair_id: (2, 10, 3)}`` cameras as one ``.npz`` (``pair_id``, ``cam_pos``), atomically."""
    path = Path(path)
    ids = sorted(cameras)
    cam = np.stack([np.asarray(cameras[i], dtype=np.float64) for i in ids]) if ids else np.zeros((0, 2, N_CAMERAS, 3))
    save_npz(path, compressed=True, pair_id=np.array(ids, dtype="U16"), cam_pos=cam)


def load_cameras(path: str | Path) -> dict[str, np.ndarray]:
    """Read a cameras ``.npz`` written by :func:`save_cameras`."""
    with np.load(path, allow_pickle=False) as data:
        return {str(i): c for i, c in zip(data["pair_id"], data["cam_pos"])}


# --------------------------------------------------------------------------------------------
# export


def rotation_to_xyz_degrees(rotation: np.ndarray) -> list:
    """Angles ``[a, b, c]`` (degrees) with ``rotation = Rx(a) @ Ry(b) @ Rz(c)`` — the reference's
    ``rot`` (Open3D ``get_rotation_matrix_from_xyz``). Rounded to 1e-6; whole numbers as ints."""
    from scipy.spatial.transform import Rotation

    angles = Rotation.from_matrix(np.asarray(rotation, dtype=np.float64)).as_euler("XYZ", degrees=True)
    out = []
    for a in np.round(angles, 6) + 0.0:
        out.append(int(a) if float(a).is_integer() else float(a))
    return out


def y_rotation(theta: float) -> np.ndarray:
    """Rotation about +y by ``theta`` radians, in the reference's row-vector convention (``V @ R``)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


def default_face_target(dataset: str, name: str, variant: int) -> int:
    """A face target in [18000, 20000] keyed by shape and remesh variant (for exported pickles)."""
    lo, hi = FACE_TARGET_RANGE
    return lo + stable_hash("face_target", dataset, name, int(variant)) % (hi - lo + 1)


def _default_random_rotations(pair_seed: int) -> np.ndarray:
    rng = rng_for(pair_seed, "random_rotation")
    return np.stack([y_rotation(t) for t in rng.uniform(0.0, 2 * np.pi, size=2)])


def _default_cameras(pair_seed: int, regime: str = "high") -> np.ndarray:
    """(2, 10, 3) unit camera directions: try k from ``draw_camera_pair(rng_for(pair seed, 'cameras', k))``."""
    from becos.build.cameras import draw_camera_pair

    out = np.empty((2, N_CAMERAS, 3))
    for k in range(N_CAMERAS):
        cx, cy = draw_camera_pair(rng_for(pair_seed, "cameras", k), regime)
        out[0, k], out[1, k] = cx.position, cy.position
    return out / np.linalg.norm(out, axis=2, keepdims=True)


class _PortablePickler(pickle.Pickler):
    """Pickles ndarrays as ``numpy.array(nested list, dtype)``: loadable by numpy 1.x and 2.x."""

    def reducer_override(self, obj):
        if type(obj) is np.ndarray:
            return np.array, (obj.tolist(), obj.dtype.str)
        return NotImplemented


def write_published_pickle(
    manifest: pd.DataFrame,
    path: str | Path,
    catalog: pd.DataFrame,
    *,
    template_rows=None,
    face_targets: Callable[[str, str, int], int] | None = None,
    random_rotations: Mapping[str, np.ndarray] | None = None,
    cameras: Mapping[str, np.ndarray] | None = None,
    regime: str = "high",
    pair_face_targets: Mapping[str, tuple[int, int]] | None = None,
    data_root: str | Path | None = None,
) -> None:
    """Write ``manifest`` as a pair list in the published pickle schema (atomic, protocol 4).

    Args:
        manifest: a manifest of one setting.
        catalog: the catalog of its shapes (file path, scale, frame rotation, category, template key).
        template_rows: as in :func:`becos.build.sampling.sample_pairs`; fills ``partial_full_template`` /
            ``partial_full_dataset`` (``undefined`` when absent).
        face_targets: ``(dataset, name, variant) -> int`` for ``desired_n_face_remeshed``
            (default :func:`default_face_target` of the pair's variant).
        random_rotations: ``{pair_id: (2, 3, 3)}`` (x, y), row-vector convention; default: a y-axis
            rotation per shape from ``rng_for(pair seed, 'random_rotation')``.
        cameras: ``{pair_id: (2, 10, 3)}`` for partial settings (written as ``cam_pos``); default:
            unit directions of ``draw_camera_pair(rng_for(pair seed, 'cameras', k), regime)``.
            Pass the rotations/cameras your records used when the pickle must describe them
            (:func:`store_pair_facts` reads them from a benchmark store).
        pair_face_targets: ``{pair_id: (x faces, y faces)}``; overrides ``face_targets`` (e.g. the
            face counts of the remeshed shapes a store's records were built from).
        data_root: the data root the catalog's files lie in (config ``data_dir``): ``file_path`` is then
            written as the reference writes it, ``data/<path below the data root>`` (the reference
            reads ``f"{data_dir}/{file_path[4:]}"``); without it, the catalog's ``file`` as is.

    ``rot`` is written as the three angles of the catalog's frame rotation. Shapes missing from the
    catalog, or pairs missing from ``random_rotations`` / ``cameras`` / ``pair_face_targets``, raise
    ``ConfigError``; a catalog file outside ``data_root`` too.
    """
    settings = set(manifest["setting"])
    if len(settings) > 1:
        raise ConfigError(f"a pair list holds one setting; manifest has {sorted(settings)}")
    partial = bool(settings & {"partial_full", "partial_partial"})
    entries = _PublishedShapes(catalog, template_rows, face_targets or default_face_target, data_root)
    lists: dict[str, list] = {s: [] for s in PUBLISHED_SPLITS}
    for row in sort_manifest(manifest).to_dict("records"):
        if row["split"] not in lists:
            raise ConfigError(f"pair {row['pair_id']}: split {row['split']!r} has no place in a pair list")
        pid = row["pair_id"]
        rot = (
            np.asarray(_lookup(random_rotations, pid, "random rotations"))
            if random_rotations is not None
            else _default_random_rotations(int(row["seed"]))
        )
        cam = None
        if partial:
            cam = (
                np.asarray(_lookup(cameras, pid, "cameras"))
                if cameras is not None
                else _default_cameras(int(row["seed"]), regime)
            )
        faces = (None, None) if pair_face_targets is None else _lookup(pair_face_targets, pid, "face targets")
        lists[row["split"]].append(
            (
                entries.shape_dict("x", row, rot[0], None if cam is None else cam[0], faces[0]),
                entries.shape_dict("y", row, rot[1], None if cam is None else cam[1], faces[1]),
            )
        )
    buf = io.BytesIO()
    _PortablePickler(buf, protocol=4).dump([lists[s] for s in PUBLISHED_SPLITS])
    write_bytes(path, buf.getvalue())


def _lookup(table: Mapping, pid: str, what: str):
    """``table[pid]``, or ConfigError naming the pair and what is missing for it."""
    if pid not in table:
        raise ConfigError(
            f"pair {pid}: no {what} given for it (the store lacks the pair?). Fix: write the "
            f"pair list from the store built from this manifest"
        )
    return table[pid]


class _PublishedShapes:
    """The shape dicts of a published pair list, from the catalog (frame rotations converted once per
    shape) and the template rows; arguments as in :func:`write_published_pickle`."""

    def __init__(self, catalog: pd.DataFrame, template_rows, face_targets, data_root):
        self.shapes = {shape_key(r["dataset"], r["name"]): r for r in catalog.to_dict("records")}
        self.template_rows, self.face_targets = template_rows, face_targets
        self.root = None if data_root is None else Path(data_root).resolve()
        self.rot_cache: dict[str, list] = {}

    def file_path(self, entry: dict) -> str:
        """``file_path`` as the reference writes it: ``data/<path below the data root>`` (the catalog's
        file as is without a data root)."""
        if self.root is None:
            return str(entry["file"])
        try:
            below = Path(entry["file"]).resolve().relative_to(self.root)
        except ValueError:
            raise ConfigError(
                f"{entry['file']}: shape {entry['dataset']}/{entry['name']} lies outside the data "
                f"root {self.root}. Fix: pass the data_dir the catalog was built from"
            ) from None
        return f"data/{below.as_posix()}"

    def shape_dict(self, side: str, row: dict, rot: np.ndarray, cam: np.ndarray | None, faces: int | None) -> dict:
        """The dict of shape ``side`` (``x``/``y``) of manifest ``row``: (3, 3) ``rot`` its random
        rotation, (10, 3) ``cam`` its cameras (partial settings), ``faces`` its face target (None: from
        ``face_targets``)."""
        key = shape_key(row[f"{side}_dataset"], row[f"{side}_name"])
        entry = self.shapes.get(key)
        if entry is None:
            raise ConfigError(f"shape {key} of pair {row['pair_id']} is not in the catalog")
        if key not in self.rot_cache:
            self.rot_cache[key] = rotation_to_xyz_degrees(frame_rotation(entry))
        trow = find_template_row(self.template_rows, str(entry["template_key"]))
        d = {
            "name": str(row[f"{side}_name"]),
            "org_dataset": str(row[f"{side}_dataset"]),
            "category": str(entry["category"]),
            "file_path": self.file_path(entry),
            "scale": float(entry["scale"]),
            "rot": list(self.rot_cache[key]),
            "partial_full_template": row_field(trow, "partial_full_template") if trow is not None else UNDEFINED,
            "partial_full_dataset": row_field(trow, "partial_full_dataset") if trow is not None else UNDEFINED,
            "desired_n_face_remeshed": int(faces)
            if faces is not None
            else int(self.face_targets(row[f"{side}_dataset"], row[f"{side}_name"], int(row[f"{side}_variant"]))),
            "random_rot": np.array(rot, dtype=np.float64),
            "becos": {
                "pair_id": str(row["pair_id"]),
                "setting": str(row["setting"]),
                "category": str(row["category"]),
                "copy": int(row["copy"]),
                "seed": int(row["seed"]),
                "variant": int(row[f"{side}_variant"]),
                "chunk": int(row["chunk"]),
            },
        }
        if cam is not None:
            d["cam_pos"] = np.array(cam, dtype=np.float64)
        return d


def store_pair_facts(bench) -> dict[str, dict[str, np.ndarray]]:
    """What a benchmark store's records actually used, per ``pair_id``, for :func:`write_published_pickle`.

    Returns ``{"random_rotations": {pid: (2, 3, 3)}, "cameras": {pid: (2, 10, 3)},
    "face_targets": {pid: (x, y)}}``:

    - random rotations: the records' ``x/y_random_rotation`` (row vectors, applied last), as the
      reference's ``random_rot``;
    - cameras: per shape, the unit direction from the look-at target to the camera that cut it
      (record ``camera`` row 0 - row 1), in the pair's shared frame (Y's turned by its alignment
      rotation, as the reference casts Y after aligning it to X), repeated in all :data:`N_CAMERAS`
      tries, so that the reference's first try (and any later one) uses the camera becos used; a full
      shape (no camera: P2F's X) gets NaN rows;
    - face targets: ``f<n>`` remesh tokens give n (the published target the remesh aimed at); other
      shapes the face count of the full remeshed shape the record was cut from.

    Only the small stacked arrays and the metas are read (not the meshes).

    Args:
        bench: an open :class:`becos.products.store.Benchmark`.
    """
    ids = list(bench.table["pair_id"])
    metas = bench.read_metas()
    out: dict[str, dict] = {"random_rotations": {}, "cameras": {}, "face_targets": {}}
    rot = {s: bench.concatenated(f"{s}_random_rotation")[0] for s in ("x", "y")}
    cam = {s: bench.concatenated(f"{s}_camera")[0] for s in ("x", "y")}
    align = {s: bench.concatenated(f"{s}_align_rotation")[0] for s in ("x", "y")}
    faces = {}
    for s in ("x", "y"):
        counts = {}
        for key in (f"{s}_faces", f"{s}_full_faces"):
            group = bench.layout[key]
            counts[key] = np.diff(bench.offsets[group]) if group is not None else np.full(len(ids), 0)
        faces[s] = np.where(counts[f"{s}_full_faces"] > 0, counts[f"{s}_full_faces"], counts[f"{s}_faces"])
    for i, pid in enumerate(ids):
        out["random_rotations"][pid] = np.stack([rot["x"][i], rot["y"][i]]).astype(np.float64)
        directions = []
        for s in ("x", "y"):
            c = np.asarray(cam[s][i], dtype=np.float64)
            d = c[0] - c[1]
            d = d @ np.asarray(align[s][i], dtype=np.float64)  # common frame -> shared (aligned) frame
            d = d / np.linalg.norm(d) if np.isfinite(d).all() and np.linalg.norm(d) > 0 else np.full(3, np.nan)
            directions.append(np.tile(d, (N_CAMERAS, 1)))
        out["cameras"][pid] = np.stack(directions)
        targets = []
        for s in ("x", "y"):
            token = str(metas[i].get(f"{s}_token", ""))
            targets.append(int(token[1:]) if re.fullmatch(r"f\d+", token) else int(faces[s][i]))
        out["face_targets"][pid] = tuple(targets)
    return out
