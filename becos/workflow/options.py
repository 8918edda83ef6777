"""What a job of each stage depends on: its config keys (:data:`STAGE_KEYS`), the options JSON its rule
passes as a parameter (Snakemake's rerun trigger) and the digest that input keys are made of."""

from __future__ import annotations

import hashlib
import json

REMESH_VERSION = 2
"""Bumped when becos's remesh changes its output, so cached remeshes are recomputed (2: issue #31, large
inputs decimated directly, the vertex target in two calls, boundary vertices jittered)."""
GROUND_TRUTH_VERSION = 1
"""Bumped when the ground-truth computation changes, so cached files are recomputed."""
RECORD_VERSION = 3
"""Bumped when pair assembly changes, so cached records are rebuilt."""
STAGE_VERSIONS = {"remesh": REMESH_VERSION, "ground_truth": GROUND_TRUTH_VERSION, "pairs": RECORD_VERSION}

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
    "remesh": ("seed", "remesh", "remesher", "decimator"),
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
        options["version"] = STAGE_VERSIONS[stage]  # a bump reruns the stage's jobs
    return json.dumps(options, sort_keys=True)
