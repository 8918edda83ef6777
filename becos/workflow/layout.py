"""Where every artefact of a run lives under ``results`` (:class:`Layout`), and which remesh file a pair side
uses (:func:`remesh_token`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path


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
