"""The options builder: the one place that reads the resolved config (a ``dict``). Each stage gets a frozen
dataclass whose fields are the config keys it depends on (:data:`STAGE_OPTIONS`); the options JSON a rule
passes to its job is that dataclass serialised (:func:`job_options`, Snakemake's rerun trigger), so what
reruns a stage is its dataclass's fields. Also here: ``remesher: auto`` resolved, the checks across keys
(:func:`check_config`), the digest that input keys are made of. Defaults live in ``becos/data/schema.yaml``.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import ClassVar

from becos.settings import SETTINGS

REMESH_VERSION = 3
"""Bumped when becos's remesh changes its output, so cached remeshes are recomputed (2: issue #31, large
inputs decimated directly, the vertex target in two calls, boundary vertices jittered; 3: a patch of
vertices snapped onto another part as a whole is snapped back, TOSCA michael13 variant 0 of seed 42;
a large input with an edge longer than 6 remesh edges is Loop-subdivided first, 32 of 152 TOSCA
remeshes of seed 42)."""
GROUND_TRUTH_VERSION = 1
"""Bumped when the ground-truth computation changes, so cached files are recomputed."""
RECORD_VERSION = 3
"""Bumped when pair assembly changes, so cached records are rebuilt."""


def _read(source, key: str):
    """``key`` of ``source``: a resolved config or a job's options (a mapping), or another options object."""
    return source[key] if isinstance(source, dict) else getattr(source, key)


@dataclass(frozen=True)
class StageOptions:
    """What every job receives: the results folder (config ``results``)."""

    version: ClassVar[int | None] = None
    """The stage's version (:data:`REMESH_VERSION`, ...), part of its options JSON: a bump reruns its jobs."""
    results: str

    @classmethod
    def of(cls, source) -> StageOptions:
        """The options from a resolved config, a job's options JSON (parsed) or another options object
        that has these fields; a missing key raises KeyError (AttributeError for an object)."""
        if type(source) is cls:
            return source
        return cls(**{f.name: _read(source, f.name) for f in fields(cls)})

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """The config keys the stage depends on (its fields)."""
        return tuple(f.name for f in fields(cls))

    def to_json(self) -> str:
        """The options JSON of a job (sorted keys; the stage's ``version`` added when it has one)."""
        value = asdict(self)
        if self.version is not None:
            value["version"] = self.version
        return json.dumps(value, sort_keys=True)

    def key_options(self) -> dict:
        """The fields but ``results`` (where the files go, not what they hold): the part of a pair file's
        input key that the options make."""
        return {k: v for k, v in asdict(self).items() if k != "results"}


@dataclass(frozen=True)
class AnnotationOptions(StageOptions):
    """The annotation folder and its template table (what :func:`becos.workflow.plan.annotation_source` opens)."""

    annotations: str
    template_file: str


@dataclass(frozen=True)
class CheckOptions(StageOptions):
    """The dataset check: where the input data comes from and how it is checked."""

    data_dir: str
    annotations: str
    annotations_archive: dict | None
    synthetic: dict
    datasets: list[str]
    template_file: str
    check_geometry: bool


@dataclass(frozen=True)
class CatalogOptions(StageOptions):
    """The catalog: the enabled datasets' shapes (``shapes``: <dataset>/<name> glob patterns, or None)."""

    data_dir: str
    annotations: str
    datasets: list[str]
    shapes: list[str] | None
    template_file: str


@dataclass(frozen=True)
class ManifestOptions(CatalogOptions):
    """A setting's pair manifest (sampled, or the published lists under ``original_settings``)."""

    combinations: str
    seed: int
    usage_scale: float
    caps: dict
    remesh: bool
    remesh_variants: int
    n_chunks: int
    pairs_per_chunk: int
    min_chunks: int
    original_settings: bool


@dataclass(frozen=True)
class RemeshOptions(StageOptions):
    """One remesh variant of a shape (``remesher``: becos or reference, resolved from ``auto``)."""

    version: ClassVar[int] = REMESH_VERSION
    seed: int
    remesh: bool
    remesher: str
    decimator: str


@dataclass(frozen=True)
class ExportOptions(StageOptions):
    """The published pair lists of a store (the file paths they name are relative to ``data_dir``)."""

    data_dir: str


@dataclass(frozen=True)
class GroundTruthOptions(StageOptions):
    """A chunk's ground truth (``remesh`` false: the pairs' original meshes)."""

    version: ClassVar[int] = GROUND_TRUTH_VERSION
    annotations: str
    template_file: str
    remesh: bool


@dataclass(frozen=True)
class PairsOptions(StageOptions):
    """A chunk's pair records, ``full_full`` (the subclasses add the keys a partial setting reads)."""

    version: ClassVar[int] = RECORD_VERSION
    setting: ClassVar[str] = "full_full"
    one_axis_rotation: bool
    up_axis: str
    area_normalised: bool
    propagate_annotations: bool
    annotations: str
    template_file: str
    original_settings: bool
    remesh: bool
    remesher: str

    @property
    def published_views(self) -> bool:
        """Whether the views come from the published cameras (``original_settings`` P2P with the reference
        remesh: the shipped triangle ids index its faces)."""
        return self.setting == "partial_partial" and self.original_settings and self.remesher == "reference"

    def pair_options(self):
        """:class:`becos.build.pairs.PairOptions` of the setting; a key the setting does not read takes its
        default (the schema's)."""
        from becos.build.pairs import PairOptions

        names = [f.name for f in fields(PairOptions) if f.name != "setting" and hasattr(self, f.name)]
        return PairOptions(setting=self.setting, **{k: getattr(self, k) for k in names})


@dataclass(frozen=True)
class PartialFullPairsOptions(PairsOptions):
    setting: ClassVar[str] = "partial_full"
    camera_distance: float


@dataclass(frozen=True)
class PartialPartialPairsOptions(PartialFullPairsOptions):
    setting: ClassVar[str] = "partial_partial"
    cam_pos_regime: str
    n_cam_pos: int
    min_overlap: float
    max_overlap: float

    def __post_init__(self):
        from becos.errors import ConfigError
        from becos.settings import overlap_range_problem

        problem = overlap_range_problem(self.min_overlap, self.max_overlap)  # the one check of the range
        if problem:
            raise ConfigError(problem)


PAIRS_OPTIONS: dict[str, type[PairsOptions]] = {
    cls.setting: cls for cls in (PairsOptions, PartialFullPairsOptions, PartialPartialPairsOptions)
}
"""The pairs stage's options per setting."""

STAGE_OPTIONS: dict[str, type[StageOptions]] = {
    "check": CheckOptions,
    "catalog": CatalogOptions,
    "manifest": ManifestOptions,
    "remesh": RemeshOptions,
    "export": ExportOptions,
    "ground_truth": GroundTruthOptions,
    "pairs": PartialPartialPairsOptions,
}
"""Each stage's options (``pairs``: of the setting that reads the most keys; :data:`PAIRS_OPTIONS`)."""

STORE_STAGES = ("check", "catalog", "manifest", "remesh", "ground_truth", "pairs")
"""The stages whose output a store holds: a change to one of their keys rewrites the store's metadata (the
rest, e.g. ``n_renders`` or ``exports``, says what is built from a store, or how the data arrived)."""


@dataclass(frozen=True)
class SourceOptions:
    """Where the input files of a run come from: the dataset folders, the annotation folder and what the
    run itself writes into them (synthetic collection, fetched annotations, downloads)."""

    data_dir: str
    annotations: str
    annotations_archive: dict | None
    synthetic: dict
    datasets: list[str]
    download: list[str]
    original_settings: bool

    @classmethod
    def of(cls, config) -> SourceOptions:
        return cls(**{f.name: _read(config, f.name) for f in fields(cls)})


def stage_options(config, stage: str, setting: str | None = None) -> StageOptions:
    """The options of ``stage`` (of ``setting`` for ``pairs``) from a resolved config or a job's options."""
    cls = PAIRS_OPTIONS[setting or "full_full"] if stage == "pairs" else STAGE_OPTIONS[stage]
    return cls.of(config)


def pairs_options(config, setting: str) -> PairsOptions:
    """The pairs stage's options of ``setting``."""
    return PAIRS_OPTIONS[setting].of(config)


def job_options(config, stage: str, setting: str | None = None) -> str:
    """The JSON a job of ``stage`` receives (:meth:`StageOptions.to_json`).

    Rules pass it as a parameter, so Snakemake reruns a job exactly when one of these values changes.
    """
    return stage_options(config, stage, setting).to_json()


def store_keys(config: dict) -> str:
    """The store metadata's rerun trigger: the keys of the :data:`STORE_STAGES` (every setting), as JSON."""
    keys = {"results", *(k for s in STORE_STAGES for k in STAGE_OPTIONS[s].keys())}
    return json.dumps({k: config[k] for k in sorted(keys)}, sort_keys=True)


def results_of(source) -> Path:
    """The results folder of a config, a job's options or an options object."""
    return Path(_read(source, "results"))


def settings_of(config) -> list[str]:
    """The configured settings (config ``setting``: one or a list) as a list, in the canonical order."""
    value = _read(config, "setting")
    wanted = {value} if isinstance(value, str) else set(value)
    return [s for s in SETTINGS if s in wanted]


def digest(value) -> str:
    """16 hex digits of SHA-256 of a JSON-able value (sorted keys): stable across runs and machines."""
    text = json.dumps(value, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def resolve_remesher(config: dict) -> None:
    """``remesher: auto`` made ``reference`` under ``original_settings`` (the published targets, rotations
    and views refer to the reference's remesh), else ``becos``; in place, before the schema check."""
    if config.get("remesher") == "auto":
        config["remesher"] = "reference" if config.get("original_settings") else "becos"


def switch_off_exports(config: dict, schema: dict) -> None:
    """``exports.enabled: false``: every on/off export key of the schema (all but ``enabled`` and ``zarr``,
    the store, which is always built) set to false in ``config``, in place, so the resolved config says
    what is built."""
    exports = config["exports"]
    if exports["enabled"]:
        return
    for key, spec in schema["properties"]["exports"]["properties"].items():
        if spec.get("type") == "boolean" and key not in ("enabled", "zarr"):
            exports[key] = False


def check_config(config: dict) -> None:
    """Checks across keys, run right after the schema (so a bad config fails before any job).

    Raises:
        ConfigError: one line per problem, ``<key>: <what is wrong>. Fix: <fix>``.
    """
    from becos.errors import ConfigError

    problems = []
    if config["exports"].get("zarr") is False:
        problems.append(
            "exports.zarr: false is not supported: the Zarr store is always built (validation, the report "
            "and every other export read it). Fix: remove exports.zarr from the configuration"
        )
    try:  # the overlap range, checked where the pairs stage's options are built
        pairs_options(config, "partial_partial")
    except ConfigError as exc:
        problems.append(str(exc))
    problems += _dataset_problems(config)
    if config["original_settings"] and "partial_full" in settings_of(config):
        problems.append(
            "original_settings: the reference publishes no partial_full pair list. "
            "Fix: use setting full_full / partial_partial or original_settings: false"
        )
    problems += _synthetic_problems(config)
    results = results_of(config)
    if results.exists() and not results.is_dir():
        problems.append(
            f"results: {str(results)!r} ({results.absolute()}) is a file, not a folder. "
            "Fix: set results to a folder path, or move the file away"
        )
    if problems:
        raise ConfigError("\n".join(" ".join(p.split()) for p in problems))  # one line per problem


def _dataset_problems(config: dict) -> list[str]:
    """Datasets not in the registry; bad ``download`` / ``download_urls`` entries."""
    import difflib

    from becos.sources.datasets import available_datasets

    problems = []
    known = sorted(available_datasets())
    for name in config["datasets"]:
        if name not in known:
            close = difflib.get_close_matches(name, known, n=1)
            hint = f"did you mean '{close[0]}'? " if close else ""
            problems.append(
                f"datasets: '{name}' is not in the registry (config/datasets/*.yaml). "
                f"Fix: {hint}use one of {', '.join(known)}"
            )
    if config["download"] or config["download_urls"]:
        from becos.sources.download import download_config_problems

        problems += download_config_problems(config["download"], config["download_urls"], config["datasets"])
    return problems


def _synthetic_problems(config: dict) -> list[str]:
    """``data_dir`` / ``annotations`` that are not where the synthetic collection is generated."""
    synthetic = config["synthetic"]
    if not synthetic["enabled"]:
        return []
    out, problems = Path(synthetic["out"]), []
    for key, expected in (("data_dir", out / "data"), ("annotations", out / "annotations")):
        if Path(config[key]) != expected:
            problems.append(
                f"{key}: {config[key]!r}, but the synthetic collection is generated into "
                f"{str(expected)!r}. Fix: set {key}: {expected} (or synthetic.enabled: false)"
            )
    return problems
