"""Where every artefact of a run lives under ``results`` (:class:`Layout`), and which remesh file a pair side
uses (:func:`remesh_token`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Layout:
    """Where every artefact of a run lives (relative to the working directory unless absolute).

    The one statement of every path the rules name: a rule's output is ``LAYOUT.<member>(...)`` with
    wildcards as arguments (``LAYOUT.store("{setting}")``), its input the same member, so a file's name
    is written once; the Python side (:class:`becos.workflow.plan.Plan`, tests) asks the same members
    with values. A per-setting member takes a setting or ``"{setting}"``; a chunk an int (written as 4
    digits) or ``"{chunk}"``.
    """

    results: Path

    @classmethod
    def of(cls, config) -> Layout:
        """The layout of a resolved config, a job's options or an options object (their ``results``)."""
        from becos.workflow.options import results_of

        return cls(results_of(config))

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
        """The Snakemake process's parsed edge files and input digests (safe to delete; no job reads it: a
        job parses the files its rule passes)."""
        return self.results / "cache"

    @property
    def input_digests(self) -> Path:
        """Content digests of the input files, cached on their status (:class:`becos.workflow.digests.DigestCache`;
        safe to delete)."""
        return self.cache / "input_digests.json"

    def manifest(self, setting: str) -> Path:
        return self.results / setting / "manifest.csv"

    def remesh_files(self, setting: str) -> Path:
        """The remesh files each chunk job of a setting reads, by chunk (written with the manifest)."""
        return self.results / setting / "remesh_files.json"

    @property
    def remeshed_root(self) -> Path:
        """The folder of every remesh variant (:func:`remeshed_file`)."""
        return self.results / "remeshed"

    def remeshed_folder(self, dataset: str, name: str) -> Path:
        """A shape's remesh variants (one remesh job writes the folder: :func:`variant_file`)."""
        return self.remeshed_root / dataset / name

    def remeshed(self, dataset: str, name: str, token: str) -> Path:
        return remeshed_file(self.remeshed_root, dataset, name, token)

    def remeshed_ply(self, dataset: str, name: str, token: str) -> Path:
        """The remesh variant as PLY, beside its .npz (to look at; no job reads it)."""
        return self.remeshed(dataset, name, token).with_suffix(".ply")

    def ground_truth_folder(self, setting: str) -> Path:
        """A setting's ground-truth files ``<pair_id>.npz`` and their chunk indices."""
        return self.results / setting / "ground_truth"

    def ground_truth_index(self, setting: str, chunk: int | str) -> Path:
        return self.ground_truth_folder(setting) / _chunk_index_name(chunk)

    def ground_truth(self, setting: str, pair_id: str) -> Path:
        return pair_file(self.ground_truth_folder(setting), pair_id)

    def pairs_folder(self, setting: str) -> Path:
        """A setting's pair records ``<pair_id>.npz`` (:mod:`becos.build.record`) and their chunk indices."""
        return self.results / setting / "pairs"

    def pairs_index(self, setting: str, chunk: int | str) -> Path:
        return self.pairs_folder(setting) / _chunk_index_name(chunk)

    def record(self, setting: str, pair_id: str) -> Path:
        return pair_file(self.pairs_folder(setting), pair_id)

    def metadata(self, setting: str) -> Path:
        """What a setting's store records about its making (``becos metadata``)."""
        return self.results / setting / "metadata.json"

    def store(self, setting: str) -> Path:
        """A setting's Zarr store (:mod:`becos.products.store`)."""
        return self.results / setting / "benchmark.zarr"

    def validation(self, setting: str) -> Path:
        return self.results / setting / "validation.json"

    def released(self, setting: str) -> Path:
        return self.results / setting / "released"

    def psmal(self, setting: str) -> Path:
        return self.results / setting / "psmal"

    def ulrssm(self, setting: str) -> Path:
        """ULRSSM-style layout (``becos export-ulrssm``; without ``dist/``)."""
        return self.results / setting / "ulrssm"

    def dpfm(self, setting: str) -> Path:
        """DPFM-style layout (``becos export-dpfm``)."""
        return self.results / setting / "dpfm"

    def geodesics(self, setting: str) -> Path:
        return self.results / setting / "geodesics"

    @property
    def geodesic_plan(self) -> Path:
        """The geodesic plan over every setting's store (temporary)."""
        return self.results / "geodesics" / "plan"

    def geodesic_rows(self, part: int | str) -> Path:
        return self.results / "geodesics" / "rows" / f"part_{part}"

    def published_pickle(self, setting: str) -> Path:
        return self.results / setting / f"pairings_{setting}.pkl"

    def report(self, setting: str) -> Path:
        return self.results / setting / "report"

    def predictions(self, setting: str, baseline: str) -> Path:
        return self.results / setting / "predictions" / baseline

    def evaluation(self, setting: str) -> Path:
        """The folder ``becos evaluate`` writes ``summary.csv``, ``pck.png`` and ``per_pair.csv`` into."""
        return self.results / setting / "evaluation"


def _chunk_index_name(chunk: int | str) -> str:
    """``chunk_0007.json`` for chunk 7; a wildcard pattern (``"{chunk}"``) is kept as it is."""
    return f"chunk_{chunk}.json" if isinstance(chunk, str) else f"chunk_{chunk:04d}.json"


def remeshed_file(root: str | Path, dataset: str, name: str, token: str) -> Path:
    """A remesh variant's .npz under the remesh folder ``root`` (:attr:`Layout.remeshed_root`)."""
    return variant_file(Path(root) / dataset / name, token)


def variant_file(folder: str | Path, token: str) -> Path:
    """The .npz of the remesh variant ``token`` in its shape's folder (:meth:`Layout.remeshed_folder`);
    its PLY is the same path with the suffix ``.ply``."""
    return Path(folder) / f"{token}.npz"


def centre_file(folder: str | Path) -> Path:
    """The shape's centre in its remesh folder (:meth:`Layout.remeshed_folder`): (3,) float64, the
    :attr:`becos.sources.datasets.PreparedShape.centre` its remesh job computed, which the chunk jobs read
    instead of parsing the original mesh for it. Folders of remesh jobs before it have none."""
    return Path(folder) / "centre.npy"


def pair_file(folder: str | Path, pair_id: str) -> Path:
    """A pair's file in a chunk stage's folder, beside the chunk indices (ground truth or record)."""
    return Path(folder) / f"{pair_id}.npz"


def remesh_token(row, side: str, remesh: bool) -> str:
    """The remesh file a pair side uses: ``v<k>`` (variant k), ``f<n>`` (published face target n) or
    ``original`` (no remeshing)."""
    if not remesh:
        return "original"
    target = row.get(f"{side}_face_target") if hasattr(row, "get") else None
    if target is not None and not math.isnan(float(target)) and int(target) > 0:
        return f"f{int(target)}"
    return f"v{int(row[f'{side}_variant'])}"
