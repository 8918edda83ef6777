"""Where the dataset registry lives (one YAML per dataset) and which datasets it names.

A leaf module (no becos imports): :mod:`becos.sources.annotations` asks it for the dataset names without
importing :mod:`becos.sources.datasets`, which reads the YAMLs and takes an annotation folder as input.
"""

from __future__ import annotations

import os
from pathlib import Path

CONFIG_DIR = Path(__file__).resolve().parents[1] / "data" / "datasets"
"""Default folder of the dataset YAMLs, shipped inside the package (``config/datasets`` in a checkout is a
link to it); override with ``config_dir`` or ``$BECOS_DATASETS_DIR``."""


def registry_dir(config_dir: Path | str | None = None) -> Path:
    """The registry folder: ``config_dir`` if given, else ``$BECOS_DATASETS_DIR``, else :data:`CONFIG_DIR`."""
    if config_dir is not None:
        return Path(config_dir)
    env = os.environ.get("BECOS_DATASETS_DIR")
    return Path(env) if env else CONFIG_DIR


def available_datasets(config_dir: Path | str | None = None) -> list[str]:
    """Names of the dataset YAMLs in the registry folder, sorted."""
    return sorted(p.stem for p in registry_dir(config_dir).glob("*.yaml"))
