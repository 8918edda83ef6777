"""Bars on the package's structure (issue #32), fast source scans anyone can rerun.

- The resolved config is read in one place, the options builder (:mod:`becos.workflow.options`): every
  other module receives typed stage options, so no ``config.get(`` or ``config[`` appears elsewhere.
- Defaults live only in ``becos/data/schema.yaml``: the options carry none, and the pairs stage takes
  what a setting does not read from the schema.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

import becos.workflow as bw
from becos.defaults import config_defaults
from becos.errors import ConfigError

PACKAGE = Path(bw.__file__).resolve().parents[1]
OPTIONS_BUILDER = PACKAGE / "workflow" / "options.py"
CONFIG_READ = re.compile(r"\bconfig(\.get\(|\[)")


def test_only_the_options_builder_reads_the_config():
    found = [
        f"{path.relative_to(PACKAGE.parent)}:{number}: {line.strip()}"
        for path in sorted(PACKAGE.rglob("*.py"))
        if path != OPTIONS_BUILDER
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if CONFIG_READ.search(line)
    ]
    assert not found, "read the config through becos.workflow.options instead:\n" + "\n".join(found)
    assert CONFIG_READ.search(OPTIONS_BUILDER.read_text()), "the scan must match what the builder does"


def test_stage_options_carry_no_defaults_and_match_the_schema():
    defaults = config_defaults()
    classes = {*bw.STAGE_OPTIONS.values(), *bw.PAIRS_OPTIONS.values(), bw.SourceOptions, bw.AnnotationOptions}
    for cls in classes:
        for field in dataclasses.fields(cls):
            assert field.default is dataclasses.MISSING and field.default_factory is dataclasses.MISSING, (
                cls.__name__,
                field.name,
            )
            assert field.name in defaults or field.name in ("data_dir", "annotations", "datasets"), field.name
    from becos.build.pairs import PairOptions

    for field in dataclasses.fields(PairOptions):  # the library's pair options default to the config's
        assert field.name == "setting" or field.default == defaults[field.name], field.name
    # what full_full does not read takes the schema's default, not one restated in code
    options = bw.pairs_options(bw.resolve_config(_config(n_cam_pos=3, min_overlap=0.3)), "full_full")
    pair = options.pair_options()
    assert (pair.n_cam_pos, pair.min_overlap, pair.cam_pos_regime) == (
        defaults["n_cam_pos"],
        defaults["min_overlap"],
        defaults["cam_pos_regime"],
    )
    partial = bw.pairs_options(bw.resolve_config(_config(n_cam_pos=3, min_overlap=0.3)), "partial_partial")
    assert (partial.pair_options().n_cam_pos, partial.pair_options().min_overlap) == (3, 0.3)


def test_remesher_auto_is_resolved_once_in_the_resolved_config():
    assert bw.resolve_config(_config())["remesher"] == "becos"
    resolved = bw.resolve_config(_config(original_settings=True, setting="full_full"))
    assert resolved["remesher"] == "reference"
    assert bw.RemeshOptions.of(resolved).remesher == "reference"
    assert not bw.pairs_options(resolved, "full_full").published_views  # P2P only


def _config(**overrides) -> dict:
    return {
        "synthetic": {"enabled": False},
        "data_dir": "data",
        "annotations": "ann",
        "datasets": ["tosca"],
        **overrides,
    }


def test_the_overlap_range_is_checked_where_the_pairs_options_are_built():
    for edit, message in (
        ({"max_overlap": 1.5}, "max_overlap: 1.5 is outside [0, 1]"),
        ({"min_overlap": 0.8, "max_overlap": 0.2}, "min_overlap: 0.8 is above max_overlap 0.2"),
    ):
        with pytest.raises(ConfigError, match=re.escape(message)):
            bw.resolve_config(_config(**edit))
        options = {**bw.resolve_config(_config()), **edit}
        with pytest.raises(ConfigError, match=re.escape(message)):  # a job's options JSON edited by hand
            bw.pairs_options(options, "partial_partial")
        assert bw.pairs_options(options, "full_full").setting == "full_full"  # a setting that reads no range
