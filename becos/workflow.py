"""The workflow's stages as library functions: config -> plan -> the work of one job.

Snakemake (``Snakefile``, ``workflow/rules/*.smk``) only names files; every job runs one ``becos``
sub-command, which calls one function of this module (or of :mod:`becos.store`, :mod:`becos.export`,
:mod:`becos.validate`, :mod:`becos.report`).

Files under ``results`` (config key ``results``)::

    config.json                         the resolved configuration (defaults filled in)
    checks/datasets.json                what the dataset check found
    catalog.csv                         every shape of the enabled datasets (becos.catalog)
    remeshed/<dataset>/<name>/<v>.npz   one remesh variant: mesh + maps to/from the original (.ply beside)
    <setting>/manifest.csv              the pairs of a setting (becos.sampling)
    <setting>/ground_truth/chunk_<k>.json  index of the chunk's ground-truth files <pair_id>.npz
    <setting>/pairs/chunk_<k>.json      index of the chunk's pair records <pair_id>.npz (becos.record)
    <setting>/benchmark.zarr            the store (becos.store), validated into validation.json
    cache/                              parsed meshes and edge files (safe to delete)

Incremental rebuilds. A pair's chunk job is a contiguous range of fixed hash buckets of its id
(:func:`becos.sampling.assign_chunks`; the manifest's ``chunk`` column records the grouping), so
growth adds pairs to chunks and moves one only when the number of chunk jobs doubles; a moved pair
keeps its files (named by pair id; the chunk is not part of any input key). A chunk job reruns when
the manifest or catalog is rewritten or its stage's options change (they are its Snakemake
``params``, :func:`job_options`); a remesh job only when its shape's catalog row or target changes.
Inside a chunk job, a pair's file is rewritten only when the pair's *input key* changed: the digest
of its manifest row (except its chunk), the stage options and the digests of the files
it reads (remesh variants, ground truth). So enabling another dataset recomputes only the new or
re-partnered pairs, and changing ``min_overlap`` recomputes records but no remesh and no ground truth.
"""

from __future__ import annotations

import hashlib
import json
import math
import sys
import time
from collections import OrderedDict
from copy import deepcopy
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from becos.atomic import remove_stale_temporaries, write_text
from becos.errors import ConfigError
from becos.settings import SETTINGS, SPLITS, overlap_range_problem

if TYPE_CHECKING:
    import pandas as pd  # imported where used: write-config, metadata and remesh jobs start without it

SCHEMA_PATH = Path(__file__).resolve().parent / "data" / "schema.yaml"
"""The config schema, shipped inside the package (config/README.md documents every key)."""
GROUND_TRUTH_VERSION = 1
"""Bumped when the ground-truth computation changes, so cached files are recomputed."""
RECORD_VERSION = 2
"""Bumped when pair assembly changes, so cached records are rebuilt."""
STAGE_VERSIONS = {"ground_truth": GROUND_TRUTH_VERSION, "pairs": RECORD_VERSION}
SHAPES_KEPT = 16
"""Shapes (prepared, remeshed, locators, scanners) a chunk job keeps in memory at most; each is dropped
as soon as the chunk's remaining pairs no longer use it (:meth:`ShapeStore.release`)."""
MESHES_KEPT = 12
"""Original meshes a chunk job keeps parsed in memory (:class:`becos.mesh.MeshCache`)."""

STAGE_KEYS: dict[str, tuple[str, ...]] = {
    "catalog": ("data_dir", "annotations", "datasets", "shapes", "template_file"),
    "manifest": (
        "data_dir",
        "annotations",
        "datasets",
        "shapes",
        "template_file",
        "combinations",
        "seed",
        "usage_scale",
        "caps",
        "remesh",
        "remesh_variants",
        "n_chunks",
        "pairs_per_chunk",
        "original_settings",
    ),
    "remesh": ("seed", "remesh", "remesher"),
    "export": ("data_dir",),
    "ground_truth": ("annotations", "template_file", "remesh"),
    "pairs": (
        "one_axis_rotation",
        "up_axis",
        "area_normalised",
        "propagate_annotations",
        "annotations",
        "template_file",
        "original_settings",
        "remesh",
        "remesher",
    ),
}
"""The config keys each stage depends on: a change to one of them reruns that stage (and only it)."""
SETTING_KEYS: dict[str, tuple[str, ...]] = {
    "full_full": (),
    "partial_full": ("camera_distance",),
    "partial_partial": ("camera_distance", "cam_pos_regime", "n_cam_pos", "min_overlap", "max_overlap"),
}
"""Extra keys the ``pairs`` stage depends on, per setting."""


# --------------------------------------------------------------------------------------------------
# configuration


def _schema() -> dict:
    import yaml

    return yaml.safe_load(SCHEMA_PATH.read_text())


def _typed_command_line_values(schema: dict, instance):
    """Nested values given as ``snakemake --config 'exports={zarr: true, ...}'`` arrive as strings
    (Snakemake reads them with YAML's BaseLoader): turn ``"true"``/``"false"`` and numbers into the
    boolean / integer / number the schema asks for, recursively; anything else is left to the schema."""
    kind = schema.get("type")
    if isinstance(instance, dict) and kind == "object":
        props = schema.get("properties", {})
        return {k: _typed_command_line_values(props[k], v) if k in props else v for k, v in instance.items()}
    if isinstance(instance, list) and kind == "array" and isinstance(schema.get("items"), dict):
        return [_typed_command_line_values(schema["items"], v) for v in instance]
    if isinstance(instance, str):
        text = instance.strip()
        if kind == "boolean" and text.lower() in ("true", "false"):
            return text.lower() == "true"
        try:
            if kind == "integer" and text.lstrip("+-").isdigit():
                return int(text)
            if kind == "number":
                return float(text)
        except ValueError:
            pass
    return instance


def _fill_defaults(schema: dict, instance):
    """Fill ``default`` values of object properties, recursively (like Snakemake's ``validate``)."""
    if not isinstance(instance, dict) or schema.get("type") != "object":
        return instance
    for key, sub in schema.get("properties", {}).items():
        if key not in instance and "default" in sub:
            instance[key] = deepcopy(sub["default"])
        if key in instance:
            _fill_defaults(sub, instance[key])
    return instance


def resolve_config(raw: dict) -> dict:
    """Validate ``raw`` against ``becos/data/schema.yaml``, fill defaults, check what a schema cannot.

    Raises:
        ConfigError: one line per problem (:func:`schema_problems`, :func:`check_config`), each
            ``<key>: <what is wrong>. Fix: <fix>`` (unknown key, wrong type, reversed overlap range, ...).
    """
    import jsonschema

    schema = _schema()
    config = _fill_defaults(schema, _typed_command_line_values(schema, deepcopy(dict(raw))))
    if config.get("remesher") == "auto":  # the published targets, rotations and views refer to the reference's remesh
        config["remesher"] = "reference" if config.get("original_settings") else "becos"
    validator = jsonschema.Draft202012Validator(schema)
    errors = sorted(validator.iter_errors(config), key=lambda e: [str(k) for k in e.absolute_path])
    if errors:
        raise ConfigError("\n".join(line for e in errors for line in schema_problems(e)))
    check_config(config)
    return config


CONFIG_DOCS = "config/README.md"
_TYPE_NAMES = {
    "integer": "an integer",
    "number": "a number",
    "string": "a string",
    "boolean": "true or false",
    "array": "a list",
    "object": "a mapping (key: value)",
    "null": "null",
}


def _key(path) -> str:
    """A config key path as the user writes it: ``caps.train``, ``datasets[1]``, ``(top level)``."""
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text or "(top level)"


def _type_of(value) -> str:
    """The JSON-schema type name of a YAML value."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, int):
        return "integer"
    return {float: "number", str: "string", list: "array", dict: "object"}.get(type(value), type(value).__name__)


def _accepts_type(schema: dict, value) -> bool:
    """Whether ``schema``'s ``type`` (if any) admits ``value``."""
    wanted = schema.get("type")
    if wanted is None:
        return True
    wanted = [wanted] if isinstance(wanted, str) else list(wanted)
    kind = _type_of(value)
    return kind in wanted or (kind == "integer" and "number" in wanted)


def schema_problems(error) -> list[str]:
    """One line per problem of a jsonschema ``ValidationError``: ``<key>: <what is wrong>. Fix: <fix>``.

    ``oneOf``/``anyOf`` errors report the branch whose type fits the value (e.g. a bad ``sha256`` inside
    ``annotations_archive``), or the allowed forms when none fits.
    """
    import difflib

    key, value, rule, limit = _key(error.absolute_path), error.instance, error.validator, error.validator_value
    docs = f"see {CONFIG_DOCS}"
    if rule == "additionalProperties":
        known = sorted(error.schema.get("properties", {}))
        lines = []
        for extra in sorted(set(value) - set(known), key=str):
            name = _key([*error.absolute_path, extra])
            close = difflib.get_close_matches(str(extra), known, n=1)
            if close:
                fix = f"did you mean '{close[0]}'? Correct the spelling or remove the key ({docs})"
            elif len(known) <= 12:
                fix = f"remove it; the keys here are {', '.join(known)} ({docs})"
            else:
                fix = f"remove it (every key: {CONFIG_DOCS})"
            lines.append(f"{name}: unknown key. Fix: {fix}")
        return lines
    if rule == "type":
        wanted = [limit] if isinstance(limit, str) else list(limit)
        expected = " or ".join(_TYPE_NAMES.get(t, t) for t in wanted)
        return [
            f"{key}: {value!r} is {_TYPE_NAMES.get(_type_of(value), _type_of(value))}, not {expected}. "
            f"Fix: give {expected} ({docs})"
        ]
    if rule == "enum":
        choices = ", ".join(map(str, limit))
        close = difflib.get_close_matches(str(value), [str(c) for c in limit], n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        return [f"{key}: {value!r} is not an allowed value. Fix: use one of {choices}{hint}"]
    bounds = {
        "minimum": ("below the minimum", ">="),
        "exclusiveMinimum": ("not above", ">"),
        "maximum": ("above the maximum", "<="),
        "exclusiveMaximum": ("not below", "<"),
    }
    if rule in bounds:
        what, op = bounds[rule]
        return [f"{key}: {value!r} is {what} {limit}. Fix: use a value {op} {limit}"]
    if rule == "minItems":
        return [f"{key}: the list has {len(value)} item(s), it needs at least {limit}. Fix: list at least {limit}"]
    if rule == "maxItems":
        return [f"{key}: the list has {len(value)} items, at most {limit} are allowed. Fix: shorten it"]
    if rule == "uniqueItems":
        repeated = sorted({str(v) for v in value if value.count(v) > 1})
        return [f"{key}: lists {', '.join(repeated)} more than once. Fix: list each item once"]
    if rule == "minLength":
        return [f"{key}: is empty. Fix: give a non-empty value ({docs})"]
    if rule == "pattern":
        return [f"{key}: {value!r} does not have the expected form (pattern {limit}). Fix: {docs}"]
    if rule == "required":
        missing = [k for k in limit if k not in value]
        return [f"{_key([*error.absolute_path, k])}: missing. Fix: add it ({docs})" for k in missing]
    if rule in ("oneOf", "anyOf") and error.context:
        branches = error.schema.get(rule, [])
        fitting = [i for i, b in enumerate(branches) if _accepts_type(b, value)]
        if len(fitting) == 1:
            inner = [e for e in error.context if e.relative_schema_path and e.relative_schema_path[0] == fitting[0]]
            lines = [line for e in inner for line in schema_problems(e)]
            if lines:
                return lines
        kinds = [t for b in branches for t in ([b["type"]] if isinstance(b.get("type"), str) else b.get("type", []))]
        forms = " or ".join(_TYPE_NAMES.get(t, t) for t in kinds) or "another form"
        return [f"{key}: {value!r} is {_TYPE_NAMES.get(_type_of(value), _type_of(value))}. Fix: give {forms} ({docs})"]
    message = " ".join(str(error.message).split())
    return [f"{key}: {message}. Fix: {docs}"]


def check_config(config: dict) -> None:
    """Checks across keys, run right after the schema (so a bad config fails before any job).

    Raises:
        ConfigError: one line per problem, ``<key>: <what is wrong>. Fix: <fix>``.
    """
    import difflib

    from becos.datasets import available_datasets

    problems = []
    if config["exports"].get("zarr") is False:
        problems.append(
            "exports.zarr: false is not supported: the Zarr store is always built (validation, the report "
            "and every other export read it). Fix: remove exports.zarr from the configuration"
        )
    overlap = overlap_range_problem(config["min_overlap"], config["max_overlap"])
    if overlap:
        problems.append(overlap)
    known = sorted(available_datasets())
    for name in config["datasets"]:
        if name not in known:
            close = difflib.get_close_matches(name, known, n=1)
            hint = f"did you mean '{close[0]}'? " if close else ""
            problems.append(
                f"datasets: '{name}' is not in the registry (config/datasets/*.yaml). "
                f"Fix: {hint}use one of {', '.join(known)}"
            )
    if config.get("download") or config.get("download_urls"):
        from becos.download import download_config_problems

        problems += download_config_problems(config)
    if config.get("original_settings") and "partial_full" in settings_of(config):
        problems.append(
            "original_settings: the reference publishes no partial_full pair list. "
            "Fix: use setting full_full / partial_partial or original_settings: false"
        )
    synthetic = config.get("synthetic") or {}
    if synthetic.get("enabled"):
        out = Path(synthetic.get("out", "resources/synthetic"))
        for key, expected in (("data_dir", out / "data"), ("annotations", out / "annotations")):
            if Path(config[key]) != expected:
                problems.append(
                    f"{key}: {config[key]!r}, but the synthetic collection is generated into "
                    f"{str(expected)!r}. Fix: set {key}: {expected} (or synthetic.enabled: false)"
                )
    results = Path(config.get("results", "results"))
    if results.exists() and not results.is_dir():
        problems.append(
            f"results: {str(results)!r} ({results.absolute()}) is a file, not a folder. "
            "Fix: set results to a folder path, or move the file away"
        )
    if problems:
        raise ConfigError("\n".join(" ".join(p.split()) for p in problems))  # one line per problem


def settings_of(config: dict) -> list[str]:
    """The configured settings as a list, in the canonical order."""
    value = config.get("setting", list(SETTINGS))
    wanted = {value} if isinstance(value, str) else set(value)
    return [s for s in SETTINGS if s in wanted]


def digest(value) -> str:
    """16 hex digits of SHA-256 of a JSON-able value (sorted keys): stable across runs and machines."""
    text = json.dumps(value, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def stage_options(config: dict, stage: str, setting: str | None = None) -> dict:
    """The part of ``config`` that ``stage`` (of ``setting``) depends on (:data:`STAGE_KEYS`,
    :data:`SETTING_KEYS`)."""
    keys = STAGE_KEYS[stage] + (SETTING_KEYS[setting] if stage == "pairs" and setting else ())
    return {k: config.get(k) for k in keys}


def job_options(config: dict, stage: str, setting: str | None = None) -> str:
    """The JSON a job of ``stage`` receives (its :func:`stage_options` + ``results``).

    Rules pass it as a parameter, so Snakemake reruns a job exactly when one of these values changes.
    """
    options = stage_options(config, stage, setting)
    options["results"] = config.get("results", "results")
    if stage in STAGE_VERSIONS:
        options["version"] = STAGE_VERSIONS[stage]  # a bump reruns the stage's chunk jobs
    return json.dumps(options, sort_keys=True)


def load_config(path: str | Path) -> dict:
    """Read a config (JSON or YAML) and resolve it (:func:`resolve_config`)."""
    return resolve_config(read_config_file(path))


def read_config_file(path: str | Path) -> dict:
    """The mapping in a YAML (or JSON) config file, unresolved.

    Raises:
        ConfigError: ``<file>: <problem>. Fix: <fix>`` when the file is missing, is not valid YAML (with
            its line and column) or does not hold a mapping.
    """
    import yaml

    path = Path(path)
    if not path.is_file():
        what = "is a folder" if path.is_dir() else "not found"
        raise ConfigError(
            f"{path}: config file {what} ({path.absolute()}). Fix: check the path given to "
            "--configfile (keys: config/README.md; an example: config/tosca.yaml)"
        )
    try:
        value = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        mark, start = getattr(exc, "problem_mark", None), getattr(exc, "context_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
        problem = " ".join(str(getattr(exc, "problem", None) or exc).split())
        if start is not None and getattr(exc, "context", None):
            problem += f"; {exc.context} at line {start.line + 1}, column {start.column + 1}"
        raise ConfigError(
            f"{path}: {where}not valid YAML ({problem}). Fix: correct the YAML syntax there "
            "(e.g. a missing ']' or ':', tabs used for indentation)"
        ) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot be read ({exc}). Fix: check the file's permissions and encoding") from None
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise ConfigError(
            f"{path}: holds {type(value).__name__}, not a mapping of config keys. "
            "Fix: write one `key: value` per line (config/README.md)"
        )
    return value


def check_config_files(argv: list[str]) -> list[str]:
    """Problems (one line each) of the ``--configfile``/``--configfiles`` files named in a Snakemake
    command line: missing, not YAML, not a mapping. Snakemake itself reports these with a traceback or
    without file and line, before the workflow is read (the default workflow profile calls this)."""
    files, taking = [], False
    for arg in argv:
        name, eq, value = arg.partition("=")
        if name in ("--configfile", "--configfiles"):
            taking = not eq  # `--configfile a.yaml b.yaml` (nargs +) or `--configfile=a.yaml`
            if eq:
                files.append(value)
        elif taking and not arg.startswith("-"):
            files.append(arg)
        else:
            taking = False
    problems = []
    for name in files:
        try:
            read_config_file(name)
        except ConfigError as exc:
            problems.append(str(exc))
    return problems


# --------------------------------------------------------------------------------------------------
# layout


@dataclass(frozen=True)
class Layout:
    """Where every artefact of a run lives (relative to the working directory unless absolute)."""

    results: Path

    @classmethod
    def of(cls, config: dict) -> Layout:
        return cls(Path(config.get("results", "results")))

    @property
    def config(self) -> Path:
        return self.results / "config.json"

    @property
    def checks(self) -> Path:
        return self.results / "checks" / "datasets.json"

    def downloaded(self, dataset: str) -> Path:
        """Stamp of a dataset's download (``becos download-dataset --out``)."""
        return self.results / "downloads" / f"{dataset}.json"

    @property
    def catalog(self) -> Path:
        return self.results / "catalog.csv"

    @property
    def cache(self) -> Path:
        return self.results / "cache"

    def manifest(self, setting: str) -> Path:
        return self.results / setting / "manifest.csv"

    def remeshed(self, dataset: str, name: str, token: str) -> Path:
        return self.results / "remeshed" / dataset / name / f"{token}.npz"

    def ground_truth_index(self, setting: str, chunk: int) -> Path:
        return self.results / setting / "ground_truth" / f"chunk_{chunk:04d}.json"

    def ground_truth(self, setting: str, pair_id: str) -> Path:
        return self.results / setting / "ground_truth" / f"{pair_id}.npz"

    def pairs_index(self, setting: str, chunk: int) -> Path:
        return self.results / setting / "pairs" / f"chunk_{chunk:04d}.json"

    def record(self, setting: str, pair_id: str) -> Path:
        return self.results / setting / "pairs" / f"{pair_id}.npz"


def remesh_token(row, side: str, remesh: bool) -> str:
    """The remesh file a pair side uses: ``v<k>`` (variant k), ``f<n>`` (published face target n) or
    ``original`` (no remeshing)."""
    if not remesh:
        return "original"
    target = row.get(f"{side}_face_target") if hasattr(row, "get") else None
    if target is not None and not math.isnan(float(target)) and int(target) > 0:
        return f"f{int(target)}"
    return f"v{int(row[f'{side}_variant'])}"


# --------------------------------------------------------------------------------------------------
# the plan: everything Snakemake needs to know to build the job graph


def annotation_source(config: dict):
    from becos.annotations import AnnotationSource

    return AnnotationSource(
        config["annotations"],
        cache_dir=Layout.of(config).cache / "annotations",
        template_table=config.get("template_file", "templates_all.csv"),
    )


def build_catalog(config: dict, annotations=None) -> pd.DataFrame:
    """The catalog of every enabled dataset's shapes (:mod:`becos.catalog`)."""
    from becos.catalog import catalog_table
    from becos.datasets import DatasetSpec

    annotations = annotations or annotation_source(config)
    entries = []
    for name in config["datasets"]:
        entries.extend(DatasetSpec.load(name).list_shapes(config["data_dir"], annotations))
    patterns = config.get("shapes")
    if patterns:
        from fnmatch import fnmatchcase

        entries = [e for e in entries if any(fnmatchcase(f"{e.dataset}/{e.name}", p) for p in patterns)]
        if not entries:
            raise ConfigError(
                f"shapes: no shape of datasets {config['datasets']} matches {patterns}. Fix: give "
                "<dataset>/<name> patterns of shapes in those datasets (globs allowed, e.g. tosca/cat*), "
                "or add their dataset to `datasets`"
            )
    return catalog_table(entries)


def build_manifest(config: dict, setting: str, catalog: pd.DataFrame, annotations=None) -> pd.DataFrame:
    """The pair manifest of ``setting`` (:mod:`becos.sampling`, or the published lists)."""
    import pandas as pd

    from becos.sampling import assign_chunks, sample_pairs

    if config.get("original_settings"):
        from becos.published import import_published

        path = Path(config["annotations"]) / "config" / f"pairings_original_{setting}.pkl"
        imported = import_published(
            path,
            setting=setting,
            seed=config["seed"],
            n_variants=config["remesh_variants"],
            n_chunks=config["n_chunks"],
            datasets=config["datasets"],
        )
        manifest = imported.manifest
        if imported.cameras:  # P2P: the published cameras travel with their pair (x_cam_pos_0..29, y_...)
            cams = np.stack([imported.cameras[p] for p in manifest["pair_id"]]).reshape(len(manifest), 2, -1)
            columns = {
                f"{side}_cam_pos_{i}": cams[:, s, i] for s, side in enumerate("xy") for i in range(cams.shape[2])
            }
            manifest = pd.concat([manifest, pd.DataFrame(columns, index=manifest.index)], axis=1)
            manifest.attrs = imported.manifest.attrs
        manifest = _restrict_published(manifest, catalog, config, setting)
        manifest["chunk"] = assign_chunks(
            manifest["pair_id"], n_chunks=config["n_chunks"], pairs_per_chunk=config["pairs_per_chunk"]
        )
        return manifest
    annotations = annotations or annotation_source(config)
    caps = {k: v for k, v in (config.get("caps") or {}).items() if v is not None}
    return sample_pairs(
        catalog,
        setting,
        seed=config["seed"],
        combinations=config["combinations"],
        template_rows=annotations,
        n_variants=config["remesh_variants"],
        n_chunks=config["n_chunks"],
        pairs_per_chunk=config["pairs_per_chunk"],
        caps=caps or None,
        usage_scale=config["usage_scale"],
    )


def _restrict_published(manifest: pd.DataFrame, catalog: pd.DataFrame, config: dict, setting: str) -> pd.DataFrame:
    """Published pairs whose two shapes are in the catalog (``shapes`` filter), then the per-split caps
    (pairs ranked by a keyed hash of their id, as for sampled pairs)."""
    from becos.sampling import sort_manifest
    from becos.seeding import stable_hash

    known = set(zip(catalog["dataset"], catalog["name"]))
    keep = [
        (xd, xn) in known and (yd, yn) in known
        for xd, xn, yd, yn in zip(manifest["x_dataset"], manifest["x_name"], manifest["y_dataset"], manifest["y_name"])
    ]
    out = manifest[np.asarray(keep, dtype=bool)]
    for split, cap in (config.get("caps") or {}).items():
        rows = out[out["split"] == split]
        if cap is not None and len(rows) > cap:
            rank = sorted(rows["pair_id"], key=lambda p: stable_hash(config["seed"], setting, "cap", p))
            out = out[(out["split"] != split) | out["pair_id"].isin(rank[:cap])]
    report = dict(manifest.attrs.get("report", {}))
    report["n_pairs"] = {s: int((out["split"] == s).sum()) for s in SPLITS}
    out = sort_manifest(out)
    out.attrs["report"] = report
    return out


@dataclass
class Plan:
    """The catalog and manifests of a config, and the jobs they imply.

    Computed in the Snakemake process (after the dataset check) and again, identically, by the jobs
    that write the catalog and manifests.
    """

    config: dict
    catalog: pd.DataFrame
    manifests: dict[str, pd.DataFrame]
    layout: Layout = field(init=False)
    _chunk_inputs: dict[tuple[str, int], list[str]] = field(init=False, default_factory=dict, repr=False)

    def __post_init__(self):
        self.layout = Layout.of(self.config)

    @classmethod
    def build(cls, config: dict) -> Plan:
        annotations = annotation_source(config)
        catalog = build_catalog(config, annotations)
        manifests = {s: build_manifest(config, s, catalog, annotations) for s in settings_of(config)}
        return cls(config, catalog, manifests)

    @cached_property
    def files(self) -> dict[tuple[str, str], str]:
        return {(d, n): f for d, n, f in zip(self.catalog["dataset"], self.catalog["name"], self.catalog["file"])}

    def _side_files(self, rows: pd.DataFrame) -> list[tuple[str, str, str]]:
        remesh = bool(self.config.get("remesh", True))
        out = set()
        for row in rows.to_dict("records"):
            for side in ("x", "y"):
                out.add((row[f"{side}_dataset"], row[f"{side}_name"], remesh_token(row, side, remesh)))
        return sorted(out)

    @cached_property
    def remesh_jobs(self) -> list[tuple[str, str, str]]:
        """Every (dataset, name, token) some pair uses, remeshing only (not ``original``)."""
        if not self.config.get("remesh", True):
            return []
        jobs = set()
        for manifest in self.manifests.values():
            jobs.update(self._side_files(manifest))
        return sorted(jobs)

    @cached_property
    def _chunk_groups(self) -> dict[str, dict[int, pd.DataFrame]]:
        """``{setting: {chunk: rows}}``, split once (Snakemake asks per chunk job, several times)."""
        return {s: {int(c): rows for c, rows in m.groupby("chunk", sort=True)} for s, m in self.manifests.items()}

    def chunks(self, setting: str) -> list[int]:
        return list(self._chunk_groups[setting])

    def chunk_rows(self, setting: str, chunk: int) -> pd.DataFrame:
        rows = self._chunk_groups[setting].get(int(chunk))
        return self.manifests[setting].iloc[:0] if rows is None else rows

    def chunk_inputs(self, setting: str, chunk: int) -> list[str]:
        """Remesh files the chunk reads (none without remeshing); computed once per chunk."""
        if not self.config.get("remesh", True):
            return []
        key = (setting, int(chunk))
        if key not in self._chunk_inputs:
            rows = self.chunk_rows(setting, chunk)
            self._chunk_inputs[key] = [str(self.layout.remeshed(*k)) for k in self._side_files(rows)]
        return list(self._chunk_inputs[key])

    @cached_property
    def _catalog_rows(self) -> dict[tuple[str, str], dict]:
        return {(r["dataset"], r["name"]): r for r in self.catalog.to_dict("records")}

    def shape_json(self, dataset: str, name: str) -> str:
        """A shape's catalog row as JSON (the remesh job's description of its shape)."""
        return json.dumps(self._catalog_rows[(dataset, name)], sort_keys=True)

    def remesh_target(self, dataset: str, name: str, token: str) -> dict:
        return remesh_target(self.config, dataset, name, token)

    @cached_property
    def _annotations(self):
        return annotation_source(self.config)

    def chunk_edge_files(self, setting: str, chunk: int) -> list[str]:
        """The annotation folder's edge files the chunk's ground truth reads (both directions), so that
        editing or restoring one reruns the chunk (:func:`edge_files_between`)."""
        keys = self._catalog_rows
        rows = self.chunk_rows(setting, chunk)
        pairs = {
            (keys[(xd, xn)]["template_key"], keys[(yd, yn)]["template_key"])
            for xd, xn, yd, yn in zip(rows["x_dataset"], rows["x_name"], rows["y_dataset"], rows["y_name"])
        }
        return sorted({str(p) for kx, ky in pairs for p in edge_files_between(self._annotations, kx, ky)})


def remesh_target(config: dict, dataset: str, name: str, token: str) -> dict:
    """Arguments of :func:`becos.remesh.remesh` for a token."""
    from becos.remesh import variant_target_vertices

    if token.startswith("f"):
        return {"target_faces": int(token[1:])}
    return {"target_vertices": int(variant_target_vertices(config["seed"], dataset, name, int(token[1:])))}


def edge_files_between(annotations, x_key: str, y_key: str) -> list[Path]:
    """Edge files on the network path between the templates of template keys ``x_key`` and ``y_key``,
    both directions (the ground truth both ways reads them); identity edges have none."""
    nodes = annotations.path(annotations.node_of_key(x_key), annotations.node_of_key(y_key))
    out = []
    for a, b in zip(nodes, nodes[1:]):
        for u, v in ((a, b), (b, a)):
            source = annotations.edge_source(u, v)
            if source.kind == "file":
                out.append(Path(source.path))
    return out


# --------------------------------------------------------------------------------------------------
# shapes as the jobs see them


def _entry(row) -> object:
    from becos.catalog import frame_rotation
    from becos.datasets import ShapeEntry

    return ShapeEntry(
        dataset=row["dataset"],
        name=row["name"],
        path=Path(row["file"]),
        category=row["category"],
        shape_class=row["class"],
        template_key=row["template_key"],
        split=row["split"],
        scale=float(row["scale"]),
        frame_rotation=frame_rotation(row),
        usage=int(row["usage"]),
    )


class _Recent(OrderedDict):
    """A dict that keeps only its ``size`` most recently used entries."""

    def __init__(self, size: int, on_drop=None):
        super().__init__()
        self.size = size
        self.on_drop = on_drop  # called with each value pushed out (not with values popped by the caller)

    def get_or_make(self, key, make):
        if key in self:
            self.move_to_end(key)
            return self[key]
        value = self[key] = make()
        while len(self) > self.size:
            _, dropped = self.popitem(last=False)
            if self.on_drop is not None:
                self.on_drop(dropped)
        return value


ShapeKey = tuple[str, str, str]
"""``(dataset, name, token)``: one pair side's shape as a chunk job loads it."""


def pair_shape_keys(row: dict, remesh: bool) -> tuple[ShapeKey, ShapeKey]:
    """The shapes of a manifest row's two sides."""
    return (
        (row["x_dataset"], row["x_name"], remesh_token(row, "x", remesh)),
        (row["y_dataset"], row["y_name"], remesh_token(row, "y", remesh)),
    )


def visit_order(records: list[dict], remesh: bool) -> tuple[list[dict], list[list[ShapeKey]]]:
    """The order a chunk job computes its pairs in, and per pair the shapes it uses for the last time.

    Pairs are sorted by their smaller then larger shape key (then id), so a shape's pairs come close
    together; a shape is released after its last pair (:meth:`ShapeStore.release`), which keeps a
    chunk's working set small without reloading shapes. The order changes no output: every pair's
    files depend on that pair alone, and the chunk's index is sorted by pair id.
    """

    def sort_key(row):
        a, b = pair_shape_keys(row, remesh)
        return (min(a, b), max(a, b), row["pair_id"])

    ordered = sorted(records, key=sort_key)
    last_use: dict[ShapeKey, int] = {}
    for i, row in enumerate(ordered):
        for key in pair_shape_keys(row, remesh):
            last_use[key] = i
    done: list[list[ShapeKey]] = [[] for _ in ordered]
    for key, i in last_use.items():
        done[i].append(key)
    return ordered, done


class ShapeStore:
    """The shapes of one job: catalog entries, parsed meshes, prepared meshes, remesh variants and the
    per-shape structures built on them (closest-point locators, Embree scanners).

    A chunk job releases a shape after the last of its pairs that uses it (:func:`visit_order`,
    :meth:`release`) and keeps at most :data:`SHAPES_KEPT` shapes (least recently used dropped first):
    each shape is loaded and its structures built about once per chunk, and the job's memory does not
    grow with the number of pairs in a chunk.
    """

    def __init__(self, config: dict, catalog: pd.DataFrame | list[dict]):
        """``catalog``: the catalog table, or some of its rows as dicts."""
        from becos.mesh import MeshCache

        self.config = config
        self.layout = Layout.of(config)
        rows = catalog if isinstance(catalog, list) else catalog.to_dict("records")
        self.entries = {(r["dataset"], r["name"]): _entry(r) for r in rows}
        self.mesh_cache = MeshCache(self.layout.cache / "meshes", max_in_memory=MESHES_KEPT)
        self._prepared = _Recent(SHAPES_KEPT)
        self._remeshed = _Recent(SHAPES_KEPT, on_drop=self._forget_remeshed)
        self._scanners = _Recent(SHAPES_KEPT)
        self._instances = _Recent(SHAPES_KEPT)
        self._centres: dict[tuple[str, str], np.ndarray] = {}
        self._digests: dict[Path, str] = {}
        self._network = None

    def _forget_remeshed(self, remeshed) -> None:
        """Drop what the network built on a remesh variant's mesh (its closest-point locator)."""
        if self._network is not None:
            self._network.forget(remeshed.mesh)

    def release(self, keys: list[ShapeKey]) -> None:
        """Drop shapes no later pair of the chunk uses (their remesh, locator, scanner, prepared mesh)."""
        for dataset, name, token in keys:
            remeshed = self._remeshed.pop((dataset, name, token), None)
            if remeshed is not None:
                self._forget_remeshed(remeshed)
            self._scanners.pop((dataset, name, token), None)
            self._instances.pop((dataset, name, token), None)
            if not any(k[:2] == (dataset, name) for k in self._remeshed):
                self._prepared.pop((dataset, name), None)

    def scanner(self, dataset: str, name: str, token: str, mesh):
        """The :class:`becos.partiality.Scanner` of a pair side's ``mesh`` (built once while kept)."""
        from becos.partiality import Scanner

        return self._scanners.get_or_make((dataset, name, token), lambda: Scanner(mesh))

    def centre(self, dataset: str, name: str) -> np.ndarray:
        """(3,) the shape's centre in scaled file coordinates (:attr:`becos.datasets.PreparedShape.centre`),
        without preparing the whole mesh."""
        from becos.datasets import shape_centre

        key = (dataset, name)
        if key in self._prepared:
            return self._prepared[key].centre
        if key not in self._centres:
            entry = self.entry(dataset, name)
            self._centres[key] = shape_centre(self.mesh_cache.load(entry.path), entry.scale)
        return self._centres[key]

    def entry(self, dataset: str, name: str):
        try:
            return self.entries[(dataset, name)]
        except KeyError:
            raise ConfigError(
                f"shape {dataset}/{name} is not in the catalog; was the dataset disabled? "
                f"Re-run the workflow so the catalog and manifests are rebuilt"
            ) from None

    def mesh(self, dataset: str, name: str):
        """The original mesh of a catalogued shape, or None (the network then uses default faces)."""
        entry = self.entries.get((dataset, name))
        return None if entry is None else self.mesh_cache.load(entry.path)

    def prepared(self, dataset: str, name: str):
        from becos.datasets import prepare_shape

        return self._prepared.get_or_make(
            (dataset, name), lambda: prepare_shape(self.entry(dataset, name), self.mesh_cache)
        )

    def remeshed(self, dataset: str, name: str, token: str):
        """The remesh variant (:class:`becos.remesh.Remeshed`), or None for ``original``."""
        from becos.remesh import load_remeshed

        if token == "original":
            return None
        return self._remeshed.get_or_make(
            (dataset, name, token), lambda: load_remeshed(self.layout.remeshed(dataset, name, token))
        )

    def file_digest(self, path: Path) -> str:
        path = Path(path)
        if path not in self._digests:
            self._digests[path] = hashlib.sha256(path.read_bytes()).hexdigest()[:16]
        return self._digests[path]

    def source_digest(self, dataset: str, name: str, token: str) -> str:
        """Digest of the file a pair side is built from (remesh variant, or the original mesh)."""
        if token == "original":
            return self.file_digest(self.entry(dataset, name).path)
        return self.file_digest(self.layout.remeshed(dataset, name, token))

    def edge_digests(self, x, y) -> list[str]:
        """Digests of the edge files the ground truth between entries ``x`` and ``y`` reads (both ways),
        for its input key. Each file is checked once per job for geometric plausibility where its
        target template's mesh is available (:func:`becos.check.edge_plausibility`), since a file
        changed after the dataset check is only seen here."""
        from becos.check import edge_plausibility, require_plausible_edge

        annotations = self.network.annotations
        out = []
        nodes = annotations.path(annotations.node_of_key(x.template_key), annotations.node_of_key(y.template_key))
        for a, b in zip(nodes, nodes[1:]):
            for u, v in ((a, b), (b, a)):
                source = annotations.edge_source(u, v)
                if source.kind != "file":
                    out.append("identity")
                    continue
                key = Path(source.path)
                if key not in self._digests:
                    target = self.mesh(*annotations.node_template(v))
                    if target is not None:
                        source_mesh = self.mesh(*annotations.node_template(u))
                        edge = annotations.edge_map(u, v)
                        if not len(edge) or edge.face.max() < target.n_faces:  # else ground_truth names it
                            faces = (
                                source_mesh.faces
                                if source_mesh is not None
                                else annotations.default_faces(*annotations.node_template(u)[::-1])
                            )
                            stats = edge_plausibility(
                                edge,
                                target.vertices,
                                target.faces,
                                faces,
                                None if source_mesh is None else source_mesh.vertices,
                            )
                            require_plausible_edge(key, u, v, stats)
                out.append(self.file_digest(key))
        return out

    @property
    def network(self):
        from becos.network import ShapeNetwork

        if self._network is None:
            self._network = ShapeNetwork(annotation_source(self.config), self.mesh)
        return self._network

    def instance(self, dataset: str, name: str, token: str):
        """A :class:`becos.pairs.ShapeInstance` (common frame, dataset scale; remeshed unless ``original``),
        the same object while the shape is kept (so its surface area is computed once)."""
        return self._instances.get_or_make((dataset, name, token), lambda: self._make_instance(dataset, name, token))

    def _make_instance(self, dataset: str, name: str, token: str):
        from becos.pairs import ShapeInstance

        entry, remeshed = self.entry(dataset, name), self.remeshed(dataset, name, token)
        if remeshed is None:
            prepared = self.prepared(dataset, name)
            mesh, centre = prepared.mesh, prepared.centre
        else:  # the prepared mesh itself is not needed, only its centre
            mesh, centre = remeshed.mesh, self.centre(dataset, name)
        variant = int(token[1:]) if token.startswith("v") else -1
        return ShapeInstance(
            entry.dataset,
            entry.name,
            entry.category,
            entry.shape_class,
            mesh,
            entry.scale,
            entry.frame_rotation,
            centre,
            variant,
        )


# --------------------------------------------------------------------------------------------------
# stage functions (one per job kind)


def _log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def write_catalog_stage(config: dict, out: Path) -> pd.DataFrame:
    from becos.catalog import write_catalog

    catalog = build_catalog(config)
    write_catalog(catalog, out)
    counts = catalog.groupby(["dataset", "split"]).size().to_dict()
    _log(f"catalog: {len(catalog)} shapes -> {out}; per dataset/split: {counts}")
    return catalog


def write_manifest_stage(config: dict, setting: str, catalog_path: Path, out: Path) -> pd.DataFrame:
    from becos.catalog import read_catalog
    from becos.sampling import write_manifest

    manifest = build_manifest(config, setting, read_catalog(catalog_path))
    write_manifest(manifest, out)
    report = manifest.attrs.get("report", {})
    _log(f"manifest {setting}: {len(manifest)} pairs -> {out}; {json.dumps(report, sort_keys=True)}")
    return manifest


def remesh_stage(config: dict, shape_row: dict, token: str, out: Path, ply: Path | None = None) -> None:
    """Remesh one shape variant (prepared, common-frame mesh) and write the maps (+ a PLY to look at).

    ``shape_row`` is the shape's catalog row (:mod:`becos.catalog` columns). With ``remesher:
    reference`` the reference's remesh of the file coordinates (:mod:`becos.reference_remesh`; a vertex
    target n becomes the face target 2n).
    """
    from becos.remesh import remesh_with_stats, save_remeshed, write_ply

    cpu = {"job_start": time.process_time()}  # CPU seconds by step, logged for benchmarks/remesh.py
    dataset, name = shape_row["dataset"], shape_row["name"]
    shapes = ShapeStore(config, [shape_row])
    target = remesh_target(config, dataset, name, token)
    lap = time.process_time()
    shapes.mesh(dataset, name)
    cpu["load"], lap = time.process_time() - lap, time.process_time()
    prepared = shapes.prepared(dataset, name)
    cpu["prepare"], lap = time.process_time() - lap, time.process_time()
    start = time.perf_counter()
    if config.get("remesher") == "reference":
        from becos.reference_remesh import remesh_like_reference

        faces = target.get("target_faces") or 2 * int(target["target_vertices"])
        result, _ = remesh_like_reference(shapes.mesh(dataset, name), prepared, faces, source=prepared.entry.path)
        cpu["remesh"] = time.process_time() - lap
    else:
        result, stats = remesh_with_stats(prepared.mesh, **target, source=prepared.entry.path)
        cpu.update(stats["cpu_seconds"])
    lap = time.process_time()
    _remove_killed_writes([Path(p) for p in (out, ply) if p is not None])
    save_remeshed(Path(out), result)
    if ply is not None:
        write_ply(Path(ply), result.mesh)
    cpu["save"] = time.process_time() - lap
    _log(f"remesh cpu seconds: {json.dumps({k: round(v, 4) for k, v in cpu.items()})}")
    _log(
        f"remesh {dataset}/{name} {token} ({config.get('remesher', 'becos')}): {prepared.mesh.n_vertices} -> "
        f"{result.mesh.n_vertices} vertices ({target}) in {time.perf_counter() - start:.1f} s"
    )


def _stored_key(path: Path, member: str) -> str | None:
    """The input key stored in an .npz (None if absent or unreadable)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            value = str(data[member]) if member in data.files else None
    except Exception:
        return None
    if value is not None and member == "__meta__":
        return json.loads(value).get("input_key")
    return value


def _chunk_rows(config: dict, setting: str, chunk: int) -> pd.DataFrame:
    from becos.sampling import read_manifest

    manifest = read_manifest(Layout.of(config).manifest(setting))
    return manifest[manifest["chunk"] == int(chunk)]


def _progress(stage: str, setting: str, chunk: int, entries: list[dict], n_rows: int, started: float) -> None:
    """A progress line every 10 pairs and at the end of a chunk."""
    done = len(entries)
    if done % 10 == 0 or done == n_rows:
        _log(
            f"{stage} {setting} chunk {chunk}: {done}/{n_rows} pairs ({sum(e['computed'] for e in entries)} "
            f"computed, the rest up to date) {time.perf_counter() - started:.1f} s"
        )


def _remove_killed_writes(paths: list[Path]) -> None:
    """Before a job writes ``paths``: remove the temporary files a killed run of it left beside them."""
    for folder in {p.parent for p in paths}:
        n = remove_stale_temporaries(folder, [p.name for p in paths if p.parent == folder])
        if n:
            _log(f"removed {n} temporary file(s) left in {folder} by an interrupted run")


def _write_index(path: Path, setting: str, chunk: int, entries: list[dict], started: float) -> dict:
    """Write a chunk's index (pairs, their files, input keys and digests); return its counts.

    The index holds content only, so a resumed or re-ordered run writes the same bytes; what was
    computed or reused and how long it took go to the job's log."""
    computed = sum(e["computed"] for e in entries)
    index = {
        "setting": setting,
        "chunk": int(chunk),
        "n_pairs": len(entries),
        "pairs": sorted(({k: v for k, v in e.items() if k != "computed"} for e in entries), key=lambda e: e["pair_id"]),
    }
    write_text(path, json.dumps(index, indent=1) + "\n")
    _log(
        f"chunk {chunk} of {setting}: {len(entries)} pairs, {computed} computed, {len(entries) - computed} "
        f"reused, {time.perf_counter() - started:.1f} s"
    )
    return {"n": len(entries), "computed": computed}


def ground_truth_stage(config: dict, setting: str, chunk: int, out_index: Path) -> dict:
    """Ground truth both ways for every pair of a chunk; files already up to date are kept."""
    from becos.atomic import save_npz
    from becos.catalog import read_catalog

    started = time.perf_counter()
    layout = Layout.of(config)
    remesh = bool(config.get("remesh", True))
    shapes = ShapeStore(config, read_catalog(layout.catalog))
    rows = _chunk_rows(config, setting, chunk)
    _remove_killed_writes([*(layout.ground_truth(setting, pid) for pid in rows["pair_id"]), Path(out_index)])
    entries = []
    ordered, last_used = visit_order(rows.to_dict("records"), remesh)
    for row, done in zip(ordered, last_used):
        tx, ty = remesh_token(row, "x", remesh), remesh_token(row, "y", remesh)
        key = digest(
            {
                "version": GROUND_TRUTH_VERSION,
                "x": [row["x_dataset"], row["x_name"], tx],
                "y": [row["y_dataset"], row["y_name"], ty],
                "sources": [
                    shapes.source_digest(row["x_dataset"], row["x_name"], tx),
                    shapes.source_digest(row["y_dataset"], row["y_name"], ty),
                ],
                "edges": shapes.edge_digests(
                    shapes.entry(row["x_dataset"], row["x_name"]), shapes.entry(row["y_dataset"], row["y_name"])
                ),
                "options": stage_options(config, "ground_truth"),
            }
        )
        path = layout.ground_truth(setting, row["pair_id"])
        computed = _stored_key(path, "input_key") != key
        if computed:
            x, y = shapes.entry(row["x_dataset"], row["x_name"]), shapes.entry(row["y_dataset"], row["y_name"])
            rx, ry = shapes.remeshed(x.dataset, x.name, tx), shapes.remeshed(y.dataset, y.name, ty)
            gt_xy = shapes.network.ground_truth(x, y, x_remesh=rx, y_remesh=ry)
            gt_yx = shapes.network.ground_truth(y, x, x_remesh=ry, y_remesh=rx)
            save_npz(
                path,
                compressed=True,
                input_key=np.array(key),
                xy_face=_narrow(gt_xy.face),
                xy_weights=gt_xy.weights,
                xy_distance=gt_xy.distance,
                yx_face=_narrow(gt_yx.face),
                yx_weights=gt_yx.weights,
                yx_distance=gt_yx.distance,
            )
        entries.append(
            {
                "pair_id": row["pair_id"],
                "path": str(path),
                "input_key": key,
                "computed": computed,
                "digest": shapes.file_digest(path),
            }
        )
        shapes.release(done)
        _progress("ground truth", setting, chunk, entries, len(rows), started)
    return _write_index(Path(out_index), setting, chunk, entries, started)


def _narrow(face: np.ndarray) -> np.ndarray:
    """Face indices as int32 on disk when they fit (:class:`SurfaceMap` widens them on load)."""
    return face.astype(np.int32) if len(face) and face.max() <= np.iinfo(np.int32).max else face


def load_ground_truth(path: Path):
    """``(gt_xy, gt_yx)`` :class:`becos.surface_map.SurfaceMap` from a ground-truth file (a .npz,
    :func:`becos.atomic.save_npz` compressed:
    ``input_key``, ``xy_face`` (V_x,) int32, ``xy_weights`` (V_x, 3), ``xy_distance`` (V_x,), the same
    for ``yx``; files of older becos hold int64 faces, uncompressed)."""
    from becos.surface_map import SurfaceMap

    with np.load(path, allow_pickle=False) as d:
        return (
            SurfaceMap(d["xy_face"], d["xy_weights"], d["xy_distance"]),
            SurfaceMap(d["yx_face"], d["yx_weights"], d["yx_distance"]),
        )


def pair_options(config: dict, setting: str):
    from becos.pairs import PairOptions

    fields = {k: config[k] for k in PairOptions.__dataclass_fields__ if k in config and k != "setting"}
    return PairOptions(setting=setting, **fields)  # keys a setting does not use keep their defaults


def pairs_stage(config: dict, setting: str, chunk: int, gt_index: Path, out_index: Path) -> dict:
    """Pair records (partiality, alignment, rotation, annotations) for every pair of a chunk."""
    from becos.catalog import read_catalog
    from becos.pairs import build_pair
    from becos.record import is_intact

    started = time.perf_counter()
    layout = Layout.of(config)
    remesh = bool(config.get("remesh", True))
    shapes = ShapeStore(config, read_catalog(layout.catalog))
    options = pair_options(config, setting)
    gt_files = {e["pair_id"]: e for e in json.loads(Path(gt_index).read_text())["pairs"]}
    rows = _chunk_rows(config, setting, chunk)
    _remove_killed_writes([*(layout.record(setting, pid) for pid in rows["pair_id"]), Path(out_index)])
    labels = _labeller(config, shapes) if config.get("propagate_annotations", True) else None
    entries = []
    ordered, last_used = visit_order(rows.to_dict("records"), remesh)
    for row, done in zip(ordered, last_used):
        tx, ty = remesh_token(row, "x", remesh), remesh_token(row, "y", remesh)
        gt = gt_files.get(row["pair_id"])
        if gt is None:
            raise ConfigError(
                f"{gt_index}: no ground truth for pair {row['pair_id']}; re-run the workflow "
                "(the ground-truth index is older than the manifest)"
            )
        key = digest(
            {
                "version": RECORD_VERSION,
                "row": {k: row[k] for k in sorted(row) if k != "chunk"},
                "options": stage_options(config, "pairs", setting),
                "ground_truth": gt["digest"],
                "sources": [
                    shapes.source_digest(row["x_dataset"], row["x_name"], tx),
                    shapes.source_digest(row["y_dataset"], row["y_name"], ty),
                ],
            }
        )
        path = layout.record(setting, row["pair_id"])
        computed = _stored_key(path, "__meta__") != key
        if not computed and not is_intact(path):
            _log(
                f"{path}: its content no longer matches the digest becos recorded when writing it (edited or "
                f"replaced by hand?); rebuilding it"
            )
            computed = True
        if computed:
            x = shapes.instance(row["x_dataset"], row["x_name"], tx)
            y = shapes.instance(row["y_dataset"], row["y_name"], ty)
            gt_xy, gt_yx = load_ground_truth(Path(gt["path"]))
            pair_scanners = (None, None)
            if setting != "full_full":
                pair_scanners = tuple(shapes.scanner(s.dataset, s.name, t, s.mesh) for s, t in ((x, tx), (y, ty)))
            record = build_pair(
                x,
                y,
                gt_xy,
                gt_yx,
                pair_id=row["pair_id"],
                seed=int(row["seed"]),
                split=row["split"],
                options=options,
                scanners=pair_scanners,
                rotations=_published_rotations(row),
                published_views=_published_views(config, row, options),
            )
            if labels is not None:
                for side, s, t in (("x", x, tx), ("y", y, ty)):
                    full = labels(s.dataset, s.name, t)
                    if full is not None:
                        record.arrays[f"{side}_annotation"] = full[record[f"{side}_partial_to_full"]]
            record.meta.update(
                input_key=key, category=row["category"], copy=int(row["copy"]), x_token=tx, y_token=ty
            )  # no chunk: regrouping keeps the record
            record.save(path)
        entries.append(
            {
                "pair_id": row["pair_id"],
                "path": str(path),
                "input_key": key,
                "computed": computed,
                "split": row["split"],
                "digest": shapes.file_digest(path),
            }
        )
        shapes.release(done)
        _progress("pairs", setting, chunk, entries, len(rows), started)
    return _write_index(Path(out_index), setting, chunk, entries, started)


def _published_views(config: dict, row: dict, options):
    """``original_settings`` P2P with the reference remesh: the views of the pair's published cameras
    (:func:`becos.reference_views.published_scan`), else None (the pairs stage draws cameras)."""
    if (
        options.setting != "partial_partial"
        or not config.get("original_settings")
        or config.get("remesher") != "reference"
        or "x_cam_pos_0" not in row
    ):
        return None
    from becos.reference_views import published_scan

    n = sum(1 for k in row if k.startswith("x_cam_pos_"))
    cameras = np.array([[row[f"{side}_cam_pos_{i}"] for i in range(n)] for side in "xy"], dtype=np.float64).reshape(
        2, -1, 3
    )
    return lambda x, y, gt_xy, gt_yx: published_scan(
        x,
        y,
        gt_xy,
        gt_yx,
        config["annotations"],
        row["x_name"],
        row["y_name"],
        cameras,
        options.n_cam_pos,
        options.min_overlap,
        options.max_overlap,
    )


def _published_rotations(row: dict):
    """The published lists' random rotations of a pair (``original_settings``), else None."""
    if "x_random_rot_0" not in row or math.isnan(float(row["x_random_rot_0"])):
        return None
    return tuple(
        np.array([row[f"{side}_random_rot_{i}"] for i in range(9)], dtype=np.float64).reshape(3, 3)
        for side in ("x", "y")
    )


def _labeller(config: dict, shapes: ShapeStore):
    """``labels(dataset, name, token) -> (V,) int8 or None``: propagated left/right labels of a full shape."""
    from becos.propagation import labels_for_instance

    cache: dict = {}

    def labels(dataset: str, name: str, token: str):
        key = (dataset, name, token)
        if key not in cache:
            cache[key] = labels_for_instance(
                shapes.network, shapes.entry(dataset, name), remesh=shapes.remeshed(dataset, name, token)
            )
        return cache[key]

    return labels


def store_metadata(config: dict, setting: str) -> dict:
    """Metadata for a setting's store: config and its digest, datasets with licence and citation."""
    from becos.datasets import DatasetSpec

    datasets = {}
    for name in config["datasets"]:
        spec = DatasetSpec.load(name)
        datasets[name] = {"title": spec.title, **{k: spec.source.get(k) for k in ("url", "licence", "citation")}}
    return {
        "setting": setting,
        "config": config,
        "config_hash": digest(config),
        "datasets": datasets,
        "generator": "becos workflow",
        "follows_published_lists": published_parts(config, setting),
    }


def published_parts(config: dict, setting: str) -> dict[str, bool | None]:
    """Per part of a setting's benchmark, whether it follows the published pair lists (None: the
    setting has no such part). P2P views follow them with the reference remesh (their triangle ids
    index its faces; :mod:`becos.reference_views`); P2F has no published list."""
    original = bool(config.get("original_settings"))
    remesh = bool(config.get("remesh", True))
    reference = original and remesh and config.get("remesher") == "reference"
    return {
        "pairs": original,
        "rotations": original,
        "face_targets": original and remesh,
        "remesh": reference,
        "views": None if setting == "full_full" else (reference and setting == "partial_partial"),
    }


def export_pairings_stage(config: dict, setting: str, out: Path, store: Path) -> None:
    """The manifest in the published pickle schema (share a benchmark as pair lists + code), with the
    random rotations, cameras and face counts the store's records actually used (docs/released-layout.md,
    section "Published pair lists")."""
    from becos.catalog import read_catalog
    from becos.published import store_pair_facts, write_published_pickle
    from becos.sampling import read_manifest
    from becos.store import open_benchmark

    layout = Layout.of(config)
    facts = store_pair_facts(open_benchmark(store))
    write_published_pickle(
        read_manifest(layout.manifest(setting)),
        out,
        read_catalog(layout.catalog),
        random_rotations=facts["random_rotations"],
        cameras=facts["cameras"],
        pair_face_targets=facts["face_targets"],
        data_root=config.get("data_dir"),
    )
