"""The tiny TOSCA workflow configuration of ``tests/test_workflow.py`` (fixture ``tiny_tosca_run``).

8 TOSCA shapes, caps train 4 / val 1 / test 1, one remesh variant, renders on: every stage of the
workflow runs for all three settings in about a minute on 2 cores. Used by ``tests/test_slurm.py``
to run the same configuration locally and on SLURM; ``tests/test_workflow.py`` builds its
configurations from :func:`tosca_config`.
"""

from __future__ import annotations

from pathlib import Path

import yaml

TINY_SHAPES = ["tosca/cat0", "tosca/cat1", "tosca/dog0", "tosca/dog1", "tosca/horse0", "tosca/horse5",
               "tosca/wolf0", "tosca/centaur0"]


def tosca_config(becos_code: Path, **overrides) -> dict:
    """A TOSCA workflow configuration (keys: ``config/README.md``) for tests: TOSCA only, one remesh
    variant, no renders; ``overrides`` replace top-level keys."""
    config = {
        "synthetic": {"enabled": False},
        "data_dir": str(Path(becos_code) / "data"),
        "annotations": str(becos_code),
        "datasets": ["tosca"],
        "template_file": "templates_tosca_demo.csv",
        "remesh_variants": 1,
        "store_vis": False,
    }
    config.update(overrides)
    return config


def tiny_tosca_config(becos_code: Path, **overrides) -> dict:
    """The configuration dict of the tiny TOSCA run (``becos_code``: the BeCoS code checkout that
    ``../shared/unpack`` prints)."""
    tiny = dict(shapes=list(TINY_SHAPES), caps={"train": 4, "val": 1, "test": 1}, store_vis=True, n_renders=2)
    return tosca_config(becos_code, **{**tiny, **overrides})


def write_tiny_tosca_config(workdir: Path, becos_code: Path, **overrides) -> Path:
    """Write ``workdir/config.yaml`` (creating ``workdir``); returns its path."""
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    path = workdir / "config.yaml"
    path.write_text(yaml.safe_dump(tiny_tosca_config(becos_code, **overrides), sort_keys=False))
    return path
