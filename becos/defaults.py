"""The workflow's config schema, ``becos/data/schema.yaml``: the one statement of every config default.

Library code that takes the same options as the workflow (e.g. :class:`becos.build.pairs.PairOptions`) reads
its defaults here (:func:`config_default`) instead of restating them.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any

SCHEMA_PATH = Path(__file__).resolve().parent / "data" / "schema.yaml"
"""The config schema, shipped inside the package (config/README.md documents every key)."""


def config_schema() -> dict:
    """The schema as a new mapping (the caller may change it)."""
    import yaml

    return yaml.safe_load(SCHEMA_PATH.read_text())


@cache
def _defaults() -> dict[str, Any]:
    return {k: v["default"] for k, v in config_schema()["properties"].items() if "default" in v}


def config_defaults() -> dict[str, Any]:
    """The top-level keys' defaults (a copy)."""
    import copy

    return copy.deepcopy(_defaults())


def config_default(key: str) -> Any:
    """The default of the top-level config key ``key`` (KeyError: the schema gives it none)."""
    import copy

    return copy.deepcopy(_defaults()[key])
