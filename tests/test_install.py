"""A non-editable install works: the wheel ships the config schema and the dataset registry.

The wheel is built from a copy of the package (``pip wheel --no-deps --no-build-isolation``: offline, no build
folder in the checkout) and installed with ``--no-deps`` into a fresh venv outside the repository; that venv
sees the test venv's site-packages through a ``.pth`` line (for numpy, jsonschema, ...) but not its editable
becos, so the commands below run the installed copy.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
from importlib.metadata import version
from pathlib import Path

import pytest

from becos.workflow import resolve_config

REPO = Path(__file__).resolve().parents[1]

OPTIONS = {"synthetic": {"enabled": False}, "data_dir": "d", "annotations": "a", "datasets": ["tosca"]}


def _can_build_wheels() -> bool:
    """setuptools >= 70.1 builds wheels itself; older ones need the ``wheel`` package."""
    try:
        major, minor = (int(v) for v in version("setuptools").split(".")[:2])
    except Exception:
        return False
    if (major, minor) >= (70, 1):
        return True
    try:
        version("wheel")
        return major >= 68
    except Exception:
        return False


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """A fresh venv (outside the repository) with becos installed from its wheel; returns the venv folder."""
    if not _can_build_wheels():
        pytest.skip("building the wheel offline needs setuptools>=70.1 in the test venv (pip install -e '.[test]')")
    tmp = tmp_path_factory.mktemp("install")
    source = tmp / "source"
    source.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO / name, source / name)
    shutil.copytree(REPO / "becos", source / "becos", ignore=shutil.ignore_patterns("__pycache__"))
    run = dict(check=True, capture_output=True, text=True, env=_clean_env())
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "-q",
            "--no-deps",
            "--no-build-isolation",
            "-w",
            str(tmp / "wheels"),
            str(source),
        ],
        cwd=tmp,
        **run,
    )
    wheel = next((tmp / "wheels").glob("becos-*.whl"))
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], **run)
    python = venv / "bin" / "python"
    site = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], **run
    ).stdout.strip()
    # the dependencies come from the test venv; a plain path line does not run that venv's own .pth files,
    # so its editable becos stays invisible
    (Path(site) / "test-venv-dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "-q", "--no-deps", "--no-index", str(wheel)],
        **run,
    )
    return venv


def _clean_env() -> dict:
    """The environment without PYTHONPATH (the tests run with the checkout on it)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "BECOS_DATASETS_DIR")}
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    return env


def _becos(venv: Path, cwd: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(venv / "bin" / "becos"), *args], cwd=cwd, capture_output=True, text=True, env=_clean_env(), timeout=120
    )


def test_the_installed_wheel_runs_outside_the_repository(installed, tmp_path):
    where = subprocess.run(
        [
            str(installed / "bin" / "python"),
            "-c",
            "import becos.workflow as w, becos.sources.datasets as d; print(w.SCHEMA_PATH); print(d.CONFIG_DIR)",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env=_clean_env(),
        check=True,
    )
    schema, registry = (Path(line) for line in where.stdout.split())
    assert schema.is_file() and installed in schema.parents, where.stdout
    assert (registry / "tosca.yaml").is_file() and installed in registry.parents, where.stdout

    helped = _becos(installed, tmp_path, "--help")
    assert helped.returncode == 0, helped.stderr
    assert "write-config" in helped.stdout

    written = _becos(installed, tmp_path, "write-config", "--options", json.dumps(OPTIONS), "--out", "config.json")
    assert written.returncode == 0, written.stderr
    # the same resolved config (schema defaults, registry check) as the checkout gives
    assert json.loads((tmp_path / "config.json").read_text()) == resolve_config(dict(OPTIONS))

    wrong = _becos(
        installed,
        tmp_path,
        "write-config",
        "--options",
        json.dumps({**OPTIONS, "datasets": ["toska"]}),
        "--out",
        "bad.json",
    )
    assert wrong.returncode == 2 and "did you mean 'tosca'" in wrong.stderr, wrong.stderr
    assert "Traceback" not in wrong.stderr
