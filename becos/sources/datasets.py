"""The dataset registry: one YAML per dataset (``config/datasets/<name>.yaml``) and the shapes it lists.

:meth:`DatasetSpec.list_shapes` turns a data root (the reference's ``data/`` folder) into
:class:`ShapeEntry` rows (name, category, class, template key, split, file); :func:`prepare_shape` loads
one shape in the common frame: y up, metres-like units, centred. For a file's (V, 3) vertices ``V``
(row vectors): ``common = (V * scale - centre) @ frame_rotation``, ``centre = mean(V * scale, axis=0)``,
``frame_rotation`` = Rx @ Ry @ Rz of ``rotation_deg`` (Open3D's xyz convention, applied on the right as
the reference does). The YAML keys, one by one: docs/design/data.md.
"""

from __future__ import annotations

import json
import logging
import re
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import yaml

from becos.core.geometry import surface_area
from becos.core.mesh import MeshCache, TriMesh, read_mesh
from becos.errors import BecosError, ConfigError, InputFileError
from becos.settings import SPLITS
from becos.sources.registry import CONFIG_DIR, available_datasets, registry_dir  # noqa: F401 (CONFIG_DIR re-exported)

if TYPE_CHECKING:
    from becos.sources.annotations import AnnotationSource

log = logging.getLogger(__name__)

CATEGORIES = ("human", "four-legged", "centaur")
EXCLUDED = "excluded"
LAYOUTS = ("flat", "class_folders", "dt4d")
GENERATED = "generated"
"""``expected_count`` of a registry entry whose shapes ``becos synthetic`` writes: counted from its manifest."""
SPLIT_RULES = ("by_class", "by_name", "slices", "template_table")
REQUIRED_KEYS = (
    "name",
    "title",
    "folder",
    "file_type",
    "layout",
    "expected_count",
    "scale",
    "rotation_deg",
    "category",
    "class",
    "template_key",
    "split",
    "usage",
    "source",
)


# --- frames ----------------------------------------------------------------------------------------
def frame_rotation_matrix(rot_deg_xyz) -> np.ndarray:
    """(3, 3) rotation of Open3D ``get_rotation_matrix_from_xyz(radians(rot_deg_xyz))`` = Rx @ Ry @ Rz.

    Apply it to (V, 3) row-vector vertices as ``V @ R`` (the reference's convention). ``[90, 0, 0]``
    sends +z to +y.
    """
    a, b, c = np.radians(np.asarray(rot_deg_xyz, dtype=np.float64).reshape(3))
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    rz = np.array([[cc, -sc, 0], [sc, cc, 0], [0, 0, 1]])
    r = rx @ ry @ rz
    r[np.abs(r) < 1e-15] = 0.0
    return r


def up_vector(axis: str = "y") -> np.ndarray:
    """(3,) unit vector of an up axis name: ``x``, ``y``, ``z``, optionally signed (``-y``, ``+z``)."""
    text = str(axis).strip().lower()
    sign = -1.0 if text.startswith("-") else 1.0
    letter = text.lstrip("+-")
    if letter not in ("x", "y", "z"):
        raise ConfigError(f"up_axis must be x, y or z (optionally with a sign), got {axis!r}")
    out = np.zeros(3)
    out["xyz".index(letter)] = sign
    return out


# --- sorting ---------------------------------------------------------------------------------------
_FIRST_INT_DOT = re.compile(r"(\d+)\.")


def reference_sort_key(file_name: str) -> tuple:
    """Sort key of the reference's file listing, made deterministic.

    The reference sorts files by the first integer followed by ``.`` in the file name (``tr_reg_015.ply``
    -> 15, ``0001.isometry.4.off`` -> 1) and leaves ties in directory order. Here ties are broken by
    the file name (plain string order), which reproduces the reference's realised splits (KIDS: val
    ``0002.isometry.3``-``6``, test ``0002.isometry.7``-``9`` and ``0002.null.0``). Names without such an
    integer sort after the others, by name.
    """
    m = _FIRST_INT_DOT.search(file_name)
    return (0, int(m.group(1)), file_name) if m else (1, 0, file_name)


def natural_key(text: str) -> tuple:
    """``a2 < a10`` ordering (digit runs compared as numbers), then the raw text."""
    parts = re.split(r"(\d+)", text)
    return tuple((0, int(p), "") if i % 2 else (1, 0, p) for i, p in enumerate(parts)), text


# --- entries ---------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ShapeEntry:
    """One shape of a dataset.

    Attributes:
        dataset: dataset name (``tosca``).
        name: name inside the dataset (``cat3``, ``bear3EP/Attack4009``, ``big_cats/lion3``).
        path: the mesh file.
        category: ``human``, ``four-legged`` or ``centaur``.
        shape_class: class (``cat``; DT4D character; FAUST ``subject01``; SMAL ``big_cats``).
        template_key: key of the template table (``tosca_cat``, ``faust``, ``dt4d_animal_bear3EP``).
        split: ``train``, ``val``, ``test`` or ``excluded``.
        scale: factor applied to file coordinates.
        frame_rotation: (3, 3); common-frame vertices = ``(V * scale - centre) @ frame_rotation`` (rows).
        usage: the dataset's train usage count (how many pair slots a train shape anchors).
    """

    dataset: str
    name: str
    path: Path
    category: str
    shape_class: str
    template_key: str
    split: str
    scale: float
    frame_rotation: np.ndarray = field(repr=False)
    usage: int

    @property
    def rot_key(self) -> str:
        """The name with ``/`` -> ``_`` (the reference's key for per-shape rotations and file names)."""
        return self.name.replace("/", "_")


@dataclass(frozen=True, eq=False)
class PreparedShape:
    """A shape in the common frame (y up): scaled, centred on the vertex mean, rotated.

    Attributes:
        entry: the shape.
        mesh: the prepared mesh; vertices (V, 3) = ``(V_file * scale - centre) @ frame_rotation``, faces
            as in the file.
        centre: (3,) vertex mean of the scaled file coordinates (subtracted before rotating).
        area: surface area of ``mesh`` (scaled units squared).
        sqrt_area: ``sqrt(area)``.
    """

    entry: ShapeEntry
    mesh: TriMesh
    centre: np.ndarray
    area: float
    sqrt_area: float


def shape_centre(mesh: TriMesh, scale: float, scaled: np.ndarray | None = None) -> np.ndarray:
    """(3,) :attr:`PreparedShape.centre`: the vertex mean of the file coordinates times ``scale``
    (``scaled``: those coordinates when already computed)."""
    return (mesh.vertices * float(scale) if scaled is None else scaled).mean(axis=0)


def prepare_shape(entry: ShapeEntry, mesh_cache: MeshCache | None = None) -> PreparedShape:
    """Load ``entry``'s mesh (file vertex order) and bring it into the common frame."""
    mesh = mesh_cache.load(entry.path) if mesh_cache is not None else read_mesh(entry.path)
    scaled = mesh.vertices * float(entry.scale)
    centre = shape_centre(mesh, entry.scale, scaled)
    prepared = TriMesh((scaled - centre) @ np.asarray(entry.frame_rotation, dtype=np.float64), mesh.faces)
    area = surface_area(prepared)
    return PreparedShape(entry, prepared, centre, area, float(np.sqrt(area)))


# --- specs -----------------------------------------------------------------------------------------
ARCHIVE_SCHEMES = ("http", "https", "file")
"""URL schemes an archive may be fetched from."""


@dataclass(frozen=True)
class DatasetArchive:
    """A public archive of a dataset that ``becos download-dataset`` fetches (``source.archive`` of its YAML).

    Attributes:
        url: where the archive is (``http``, ``https`` or ``file``); the workflow's ``download_urls``
            replaces it (a mirror).
        sha256: the pinned SHA-256 (64 lowercase hex digits), or None while unknown: the first download
            then records its digest beside the data and warns.
        extract_to: folder below the data root that the archive's members are extracted into (``KIDS``).
        expected: glob, relative to ``extract_to``, that the archive must yield: the dataset ``folder``
            below ``extract_to`` plus ``file_glob`` (KIDS: ``off/*.off``). Derived, not a YAML key, so
            it cannot disagree with the folder the dataset check reads.
    """

    url: str
    sha256: str | None
    extract_to: str
    expected: str


@dataclass(frozen=True)
class _Rule:
    pattern: re.Pattern
    value: str


class DatasetSpec:
    """A parsed dataset YAML (the keys: docs/design/data.md).

    Attributes:
        path: the YAML file; ``raw``: its content; plus ``name``, ``folder``, ``file_type``, ``layout``,
        ``expected_count``, ``scale``, ``rotation_deg``, ``usage``, ``excluded``, ``split``, ``source``,
        ``archive`` (:class:`DatasetArchive`, None when the dataset cannot be downloaded automatically).
    """

    def __init__(self, raw: dict, path: Path):
        self.path = path
        self.raw = raw
        missing = [k for k in REQUIRED_KEYS if k not in raw]
        if missing:
            self._fail(f"lacks keys {missing}", "add them (see becos.sources.datasets for the schema)")
        self.name = str(raw["name"])
        self.title = str(raw["title"])
        self.folder = str(raw["folder"]).strip("/")
        self.file_type = str(raw["file_type"]).lower().lstrip(".")
        self.layout = str(raw["layout"])
        if self.layout not in LAYOUTS:
            self._fail(f"layout '{self.layout}' is unknown", f"use one of {LAYOUTS}")
        self.file_glob = str(raw.get("file_glob") or f"*.{self.file_type}")
        self.info_file = raw.get("info_file")
        if self.layout == "dt4d" and not self.info_file:
            self._fail("layout dt4d needs info_file", "name the annotation folder's data/info_dt4d_*.json")
        self.generated = raw["expected_count"] == GENERATED
        if self.generated and raw.get("expected_per_class"):
            self._fail("has expected_per_class with expected_count: generated", "remove expected_per_class")
        self.expected_count = None if self.generated else int(raw["expected_count"])
        self.expected_per_class = {str(k): int(v) for k, v in (raw.get("expected_per_class") or {}).items()}
        self.scale = float(raw["scale"])
        if not self.scale > 0:
            self._fail(f"scale must be positive, got {self.scale}", "set the dataset's unit scale")
        rot = raw["rotation_deg"]
        if not (isinstance(rot, (list, tuple)) and len(rot) == 3):
            self._fail(f"rotation_deg must be [rx, ry, rz] in degrees, got {rot!r}", "give three angles")
        self.rotation_deg = tuple(float(v) for v in rot)
        self.rotation_per_shape = raw.get("rotation_per_shape") or None
        self.category_rules = self._rules("category")
        for rule in self.category_rules:
            if rule.value not in CATEGORIES:
                self._fail(f"category value '{rule.value}' is unknown", f"use one of {CATEGORIES}")
        self.class_rules = self._rules("class")
        self.template_key_format = str(raw["template_key"])
        self.split = dict(raw["split"])
        rule = self.split.get("rule")
        if rule not in SPLIT_RULES:
            self._fail(f"split rule '{rule}' is unknown", f"use one of {SPLIT_RULES}")
        if rule == "slices" and self.split.get("order") != "reference_numeric":
            self._fail("split rule 'slices' needs order: reference_numeric", "set split.order")
        self.excluded = tuple(str(n) for n in (raw.get("excluded") or ()))
        self.usage = int(raw["usage"])
        self.source = dict(raw["source"])
        self.archive = self._archive(self.source.get("archive"))

    def __repr__(self) -> str:
        return f"DatasetSpec({self.name!r}, {str(self.path)!r})"

    def _fail(self, problem: str, fix: str):
        raise InputFileError(self.path, problem, fix)

    def _archive(self, raw) -> DatasetArchive | None:
        """``source.archive`` parsed and checked (None: the dataset cannot be downloaded automatically)."""
        if raw is None:
            return None
        fix = "write source.archive as {url: ..., sha256: <64 hex digits or null>, extract_to: <folder>}"
        if not isinstance(raw, dict) or set(raw) != {"url", "sha256", "extract_to"}:
            self._fail(f"source.archive must have exactly the keys url, sha256, extract_to, got {raw!r}", fix)
        url = str(raw["url"]).strip()
        if url.split("://", 1)[0].lower() not in ARCHIVE_SCHEMES or "://" not in url:
            self._fail(f"source.archive.url {url!r} is not an http(s):// or file:// URL", "give the full URL")
        sha256 = raw["sha256"]
        if sha256 is not None:
            sha256 = str(sha256).strip().lower()
            if not re.fullmatch(r"[0-9a-f]{64}", sha256):
                self._fail(
                    f"source.archive.sha256 {raw['sha256']!r} is not 64 hex digits",
                    "pin the archive's digest (sha256sum ARCHIVE) or write null while it is unknown",
                )
        extract_to = str(raw["extract_to"]).strip("/")
        parts = extract_to.split("/")
        if not extract_to or ".." in parts or "" in parts:
            self._fail(
                f"source.archive.extract_to {raw['extract_to']!r} is not a folder below the data root",
                "name a relative folder without '..' (e.g. KIDS)",
            )
        if self.folder != extract_to and not self.folder.startswith(extract_to + "/"):
            self._fail(
                f"the dataset folder '{self.folder}' is not inside source.archive.extract_to '{extract_to}'",
                "extract the archive into a folder that holds the dataset folder",
            )
        inner = self.folder[len(extract_to) :].strip("/")
        expected = f"{inner}/{self.file_glob}" if inner else self.file_glob
        return DatasetArchive(url=url, sha256=sha256, extract_to=extract_to, expected=expected)

    def _rules(self, key: str) -> list[_Rule]:
        value = self.raw[key]
        items = value if isinstance(value, list) else [value]
        rules = []
        for item in items:
            if not isinstance(item, dict) or "match" not in item or "value" not in item:
                self._fail(
                    f"'{key}' rules must be {{match: regex, value: text}} items, got {item!r}",
                    "write each rule as a mapping with match and value",
                )
            try:
                rules.append(_Rule(re.compile(str(item["match"]), re.IGNORECASE), str(item["value"])))
            except re.error as exc:
                self._fail(f"'{key}' pattern {item['match']!r} is not a regular expression ({exc})", "fix the regex")
        return rules

    @classmethod
    def load(cls, name: str, config_dir: Path | None = None) -> DatasetSpec:
        """The spec ``<config_dir>/<name>.yaml`` (default: the repository's ``config/datasets``)."""
        folder = registry_dir(config_dir)
        path = folder / f"{name}.yaml"
        if not path.is_file():
            raise ConfigError(
                f"no dataset '{name}' in {folder} (available: {available_datasets(folder)}). "
                f"Fix: use one of those names or add {path}"
            )
        try:
            raw = yaml.safe_load(path.read_text(encoding="utf-8"))
        except yaml.YAMLError as exc:
            raise InputFileError(path, f"is not valid YAML ({exc})", "fix the syntax") from exc
        if not isinstance(raw, dict):
            raise InputFileError(path, "must hold a mapping of keys", "see becos.sources.datasets for the schema")
        spec = cls(raw, path)
        if spec.name != name:
            raise InputFileError(path, f"says name '{spec.name}' but is named {name}.yaml", "make them agree")
        return spec

    # --- name rules -----------------------------------------------------------------------------
    def _apply(self, rules: list[_Rule], name: str, what: str) -> str:
        for rule in rules:
            m = rule.pattern.search(name)
            if m:
                return rule.value.format(*([m.group(0)] + [g or "" for g in m.groups()]), name=name)
        raise BecosError(
            f"{self.path}: no {what} rule matches shape name '{name}'. Fix: check the name "
            f"(dataset {self.name}) or add a rule"
        )

    def category_of(self, name: str) -> str:
        """``human``, ``four-legged`` or ``centaur``."""
        return self._apply(self.category_rules, name, "category")

    def class_of(self, name: str) -> str:
        return self._apply(self.class_rules, name, "class")

    def template_key_of(self, name: str) -> str:
        """Key of the template table (reference facts §3.2, "key per shape")."""
        return self.template_key_format.format(name=name, **{"class": self.class_of(name)})

    def split_of(self, name: str, annotations: AnnotationSource | None = None) -> str:
        """Split of one shape for rules that depend on the name alone (by_class, by_name, template_table).

        Slices depend on the whole listing: use :meth:`assign_splits`.
        """
        if name in self.excluded:
            return EXCLUDED
        rule = self.split["rule"]
        if rule == "slices":
            raise BecosError(
                f"{self.path}: split of '{name}' depends on the whole file list (count-based "
                f"slices). Fix: use DatasetSpec.assign_splits(names)"
            )
        if rule == "template_table":
            if annotations is None:
                raise ConfigError(
                    f"{self.path}: the split of dataset {self.name} comes from the template table's "
                    f"split column. Fix: pass an AnnotationSource"
                )
            key = self.template_key_of(name)
            split = annotations.template_row(key).split
            if split not in SPLITS:
                raise InputFileError(
                    annotations.template_table_path,
                    f"row '{key}' has split '{split}'",
                    "give DT4D rows train, val or test",
                )
            return split
        value = self.class_of(name) if rule == "by_class" else name
        hits = [s for s in SPLITS if value in [str(v) for v in (self.split.get(s) or ())]]
        if len(hits) != 1:
            raise BecosError(
                f"{self.path}: {'class' if rule == 'by_class' else 'shape'} '{value}' (shape '{name}') "
                f"is in {len(hits)} of the split lists {SPLITS}. Fix: list it in exactly one "
                f"(or under excluded)"
            )
        return hits[0]

    def assign_splits(self, names: list[str], annotations: AnnotationSource | None = None) -> dict[str, str]:
        """Name -> split for a whole listing.

        ``slices``: the used names in :func:`reference_sort_key` order (of ``<name>.<file_type>``), the
        first ``train`` to train, the next ``val`` to val, the next ``test`` to test; counts must add up.
        """
        used = [n for n in names if n not in self.excluded]
        out = {n: EXCLUDED for n in names if n in self.excluded}
        if self.split["rule"] != "slices":
            out.update({n: self.split_of(n, annotations) for n in used})
            return out
        counts = [int(self.split[s]) for s in SPLITS]
        if sum(counts) != len(used):
            raise BecosError(
                f"{self.path}: the split slices {dict(zip(SPLITS, counts))} cover {sum(counts)} shapes "
                f"but {len(used)} are listed. Fix: check the dataset download is complete"
            )
        ordered = sorted(used, key=lambda n: reference_sort_key(f"{n}.{self.file_type}"))
        start = 0
        for split, n in zip(SPLITS, counts):
            out.update({name: split for name in ordered[start : start + n]})
            start += n
        return out

    # --- frames ---------------------------------------------------------------------------------
    def _shape_rotations(self, annotations: AnnotationSource | None) -> tuple[dict[str, list], list]:
        spec = self.rotation_per_shape
        default = list(spec.get("default", [0, 0, 0]))
        if "values" in spec:
            return dict(spec["values"]), default
        ref = spec.get("from_reference")
        if not ref:
            self._fail("rotation_per_shape needs 'values' or 'from_reference'", "give one of them")
        if annotations is None:
            raise ConfigError(
                f"{self.path}: dataset {self.name} has one frame rotation per shape, read from the "
                f"BeCoS annotation folder's {ref}. Fix: pass an AnnotationSource of that folder"
            )
        path = Path(annotations.root) / ref
        if not path.is_file():
            raise InputFileError(
                path,
                f"per-shape frame rotations of dataset {self.name} not found",
                f"copy the reference checkout's {ref} there, or put the dict under "
                f"rotation_per_shape.values in {self.path}",
            )
        try:
            values = (yaml.safe_load(path.read_text(encoding="utf-8")) or {}).get(spec.get("key", "rot"))
        except yaml.YAMLError as exc:
            raise InputFileError(path, f"is not valid YAML ({exc})", "restore the reference's file") from exc
        if not isinstance(values, dict):
            raise InputFileError(
                path, f"key '{spec.get('key', 'rot')}' does not hold a per-shape dict", "restore the reference's file"
            )
        return values, default

    def rotation_of(self, name: str, annotations: AnnotationSource | None = None) -> np.ndarray:
        """(3, 3) frame rotation of a shape (per-shape dict where the dataset has one)."""
        if not self.rotation_per_shape:
            return frame_rotation_matrix(self.rotation_deg)
        values, default = self._shape_rotations(annotations)
        rot = values.get(name.replace("/", "_"))
        if rot is None:
            log.warning("%s: no per-shape rotation for '%s'; using %s (reference behaviour)", self.path, name, default)
            rot = default
        return frame_rotation_matrix(rot)

    # --- listing --------------------------------------------------------------------------------
    def download_help(self) -> str:
        """Where to get the dataset, for error messages."""
        s = self.source
        parts = [f"{self.title}: {s.get('instructions', '').strip()}"]
        if s.get("url"):
            parts.append(f"URL: {s['url']}")
        if s.get("licence"):
            parts.append(f"licence: {s['licence']}")
        if s.get("citation"):
            parts.append(f"cite: {s['citation']}")
        return " | ".join(parts)

    def info_file_candidates(self, annotations_root: str | Path | None, data_root: str | Path) -> list[Path]:
        """Where a ``dt4d`` dataset's ``info_file`` is looked for, in order: the annotation folder's
        ``data/``, then the data root."""
        return ([Path(annotations_root) / "data" / self.info_file] if annotations_root is not None else []) + [
            Path(data_root) / self.info_file
        ]

    def _dt4d_names(self, annotations: AnnotationSource | None, data_root: Path) -> tuple[list[str], Path]:
        candidates = self.info_file_candidates(annotations.root if annotations is not None else None, data_root)
        path = next((p for p in candidates if p.is_file()), None)
        if path is None:
            raise InputFileError(
                candidates[0],
                f"the DT4D class/frame list of {self.name} is missing",
                "use the BeCoS annotation folder (it ships data/info_dt4d_*.json)",
            )
        try:
            info = json.loads(path.read_text(encoding="utf-8"))
            names = [
                f"{cls}/{action}{int(frame):03d}"
                for cls, actions in info.items()
                for action, frames in actions.items()
                for frame in frames
            ]
        except (ValueError, AttributeError, TypeError) as exc:
            raise InputFileError(
                path,
                f"is not a {{class: {{action: [frame ids]}}}} JSON ({exc})",
                "restore the annotation folder's file",
            ) from exc
        return names, path

    @property
    def mesh_glob(self) -> str:
        """The glob of the dataset's mesh files below its folder: ``file_glob`` (layout flat), else
        ``*/<file_glob>`` (one folder per class: class_folders, dt4d). It matches entries of any kind
        (folders, named pipes, ...): :meth:`list_names` keeps the regular files."""
        return self.file_glob if self.layout == "flat" else f"*/{self.file_glob}"

    def name_of(self, path: str | Path) -> str:
        """The shape name of a mesh file found by :attr:`mesh_glob` (``wolf1``, ``<class>/<stem>``)."""
        path = Path(path)
        return path.stem if self.layout == "flat" else f"{path.parent.name}/{path.stem}"

    def list_names(self, data_root: str | Path, annotations: AnnotationSource | None = None) -> list[str]:
        """Shape names found below ``data_root`` (excluded ones included), in natural order.

        Raises:
            InputFileError: the dataset folder is missing (message carries the download instructions),
                or (DT4D) files listed in the info JSON are missing.
        """
        folder = Path(data_root) / self.folder
        if not folder.is_dir():
            raise InputFileError(
                folder,
                f"dataset folder of {self.name} not found",
                f"download it and place it there. {self.download_help()}",
            )
        if self.layout in ("flat", "class_folders"):
            names = [self.name_of(p) for p in folder.glob(self.mesh_glob) if p.is_file()]
        else:
            names, info_path = self._dt4d_names(annotations, Path(data_root))
            missing = [n for n in names if not (folder / f"{n}.{self.file_type}").is_file()]
            if missing:
                raise InputFileError(
                    folder,
                    f"{len(missing)} of the {len(names)} shapes listed in {info_path} are "
                    f"missing (e.g. {missing[0]}.{self.file_type})",
                    f"put the full DeformingThings4D download in "
                    f"{Path(data_root) / 'DeformingThings4D'} and run the workflow (or "
                    f"`becos prepare-dt4d`), which writes them. {self.download_help()}",
                )
        return sorted(names, key=natural_key)

    def expected_counts(self, data_root: str | Path) -> tuple[int, dict[str, int]]:
        """The used shapes expected below ``data_root``: (total, ``{class: count}``, empty if the registry
        has none). ``expected_count: generated``: the files of this dataset's folder that the collection's
        manifest lists (``<data_root>/../synthetic.json``, :mod:`becos.sources.synthetic`), per class.

        Raises:
            InputFileError: a generated dataset whose manifest is missing or unreadable.
        """
        if not self.generated:
            return self.expected_count, dict(self.expected_per_class)
        from becos.sources.synthetic.collection import MANIFEST

        path = Path(data_root).parent / MANIFEST
        fix = "generate the collection with `becos synthetic OUT` and use OUT/data as data_dir (synthetic.enabled)"
        try:
            listed = json.loads(path.read_text(encoding="utf-8"))["files"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise InputFileError(
                path,
                f"is missing or not a synthetic collection manifest ({exc}); {self.name} counts its shapes there",
                fix,
            ) from exc
        prefix, suffix = f"data/{self.folder}/", f".{self.file_type}"
        names = [self.name_of(f) for f in listed if f.startswith(prefix) and f.endswith(suffix)]
        per_class = Counter(self.class_of(n) for n in names if n not in self.excluded)
        return sum(per_class.values()), dict(sorted(per_class.items()))

    def list_shapes(self, data_root: str | Path, annotations: AnnotationSource | None = None) -> list[ShapeEntry]:
        """Every shape of the dataset below ``data_root`` as :class:`ShapeEntry` (natural name order).

        Excluded shapes that are present are listed with split ``excluded``. Counts are checked against
        ``expected_count`` (used shapes) and ``expected_per_class``.

        Raises:
            InputFileError: missing folder (with download instructions) or wrong counts.
        """
        data_root = Path(data_root)
        folder = data_root / self.folder
        names = self.list_names(data_root, annotations)
        used = [n for n in names if n not in self.excluded]
        expected_count, expected_per_class = self.expected_counts(data_root)
        if len(used) != expected_count:
            raise InputFileError(
                folder,
                f"found {len(used)} {self.name} shapes ({self.file_glob}), expected {expected_count}",
                f"complete or re-extract the download. {self.download_help()}",
            )
        if expected_per_class:
            counts: dict[str, int] = {}
            for n in used:
                counts[self.class_of(n)] = counts.get(self.class_of(n), 0) + 1
            if counts != expected_per_class:
                diff = {
                    c: (counts.get(c, 0), expected_per_class.get(c, 0))
                    for c in set(counts) | set(expected_per_class)
                    if counts.get(c, 0) != expected_per_class.get(c, 0)
                }
                raise InputFileError(
                    folder,
                    f"shapes per class (found, expected) differ: {diff}",
                    f"complete or re-extract the download. {self.download_help()}",
                )
        if self.split["rule"] == "by_name":
            listed = {str(v) for s in SPLITS for v in (self.split.get(s) or ())}
            absent = sorted(listed - set(used))
            if absent:
                raise InputFileError(
                    folder,
                    f"shapes named in the split lists are missing: {absent}",
                    f"complete the download. {self.download_help()}",
                )
        splits = self.assign_splits(names, annotations)
        rotations = None
        if self.rotation_per_shape:
            rotations = self._shape_rotations(annotations)
        fixed = frame_rotation_matrix(self.rotation_deg)
        entries = []
        for n in names:
            if rotations is not None:
                values, default = rotations
                rot = values.get(n.replace("/", "_"))
                if rot is None:
                    log.warning(
                        "%s: no per-shape rotation for '%s'; using %s (reference behaviour)", self.path, n, default
                    )
                    rot = default
                rotation = frame_rotation_matrix(rot)
            else:
                rotation = fixed.copy()
            entries.append(
                ShapeEntry(
                    dataset=self.name,
                    name=n,
                    path=folder / f"{n}.{self.file_type}",
                    category=self.category_of(n),
                    shape_class=self.class_of(n),
                    template_key=self.template_key_of(n),
                    split=splits[n],
                    scale=self.scale,
                    frame_rotation=rotation,
                    usage=self.usage,
                )
            )
        return entries


def load_all(config_dir: Path | str | None = None) -> dict[str, DatasetSpec]:
    """Every registered dataset spec by name."""
    return {name: DatasetSpec.load(name, config_dir) for name in available_datasets(config_dir)}
