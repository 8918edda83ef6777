"""Shared fixtures: the reference data laid out by ``../shared/unpack`` (TOSCA meshes, annotations)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"


@pytest.fixture(scope="session")
def becos_code() -> Path:
    """The BeCoS reference checkout (annotation files + TOSCA meshes), unpacked once per machine."""
    unpack = SHARED / "unpack"
    if not unpack.exists():
        pytest.skip(f"{unpack} not found: the real-data tests need ../shared beside the repository")
    out = subprocess.run([str(unpack)], check=True, capture_output=True, text=True).stdout.strip()
    return Path(out.splitlines()[-1])


@pytest.fixture(scope="session")
def tosca_dir(becos_code: Path) -> Path:
    return becos_code / "data" / "tosca-off"


@pytest.fixture(scope="session")
def mesh_cache(tmp_path_factory):
    """One parsed-mesh cache for the whole test session."""
    from becos.mesh import MeshCache

    return MeshCache(tmp_path_factory.mktemp("mesh-cache"))
