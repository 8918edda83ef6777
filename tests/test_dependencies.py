"""One list of dependencies: ``pyproject.toml`` is the one pip reads; the conda files ``environment.yml``
and ``workflow/envs/becos.yaml`` must name the same packages with the same version ranges (issue #32,
item 4: the rule environment had lost ``cholespy``, which the geodesics import)."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]


def _requirement(text: str) -> tuple[str, str]:
    """(normalised name, version range) of a requirement line such as ``zarr>=3.0``."""
    match = re.fullmatch(r"\s*([A-Za-z0-9_.\-]+)\s*(.*?)\s*", text)
    assert match, text
    return re.sub(r"[-_.]+", "-", match[1]).lower(), match[2].replace(" ", "")


def _conda_requirements(path: Path) -> dict[str, str]:
    """The packages of a conda environment file (conda and pip sections; ``pip`` itself and ``-e .`` left out)."""
    out: dict[str, str] = {}
    for entry in yaml.safe_load(path.read_text(encoding="utf-8"))["dependencies"]:
        lines = entry["pip"] if isinstance(entry, dict) else [entry]
        for line in lines:
            if line == "pip" or line.startswith("-e"):
                continue
            name, spec = _requirement(line)
            assert name not in out, f"{path.name}: {name} listed twice"
            out[name] = spec
    return out


def _pyproject() -> tuple[dict[str, str], dict[str, str], str]:
    project = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    core = dict(_requirement(r) for r in project["dependencies"])
    test = dict(_requirement(r) for r in project["optional-dependencies"]["test"])
    return core, test, project["requires-python"]


def test_the_rule_environment_names_exactly_the_packages_pip_installs():
    core, _, python = _pyproject()
    conda = _conda_requirements(REPO / "workflow" / "envs" / "becos.yaml")
    assert conda.pop("python") == python
    assert conda == core


def test_the_conda_environment_names_the_packages_pip_installs_and_test_tools_of_the_test_extra():
    core, test, python = _pyproject()
    conda = _conda_requirements(REPO / "environment.yml")
    assert conda.pop("python") == python
    missing = {name: spec for name, spec in core.items() if conda.get(name) != spec}
    assert not missing, f"environment.yml lacks or differs from pyproject.toml: {missing}"
    extra = {name: spec for name, spec in conda.items() if name not in core and test.get(name) != spec}
    assert not extra, f"environment.yml names what pyproject.toml does not (nor its test extra): {extra}"
