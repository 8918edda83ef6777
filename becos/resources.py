"""Per-rule scheduler resources (memory in MiB, run time in minutes) from measured peaks.

``workflow/resources.yaml`` holds per rule ``mem_mb`` and ``runtime`` from the peaks ``benchmarks/resources.py``
measured on a real run (with margins), for chunk rules ``seconds_per_pair``: their run time grows with
the chunk's pairs, their memory does not (at most :data:`becos.workflow.shapes.SHAPES_KEPT` shapes
loaded), and for the remesh rule ``seconds_per_variant``: a job remeshes every variant of its shape, one
after the other. A rule missing from the file gets :data:`DEFAULT`. Snakemake calls the functions returned here
with the job's wildcards and ``attempt`` (1, 2, ... when a profile sets ``retries``), so a retried job,
killed for exceeding its request, asks for ``attempt`` times the memory and time.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import yaml

from becos.errors import InputFileError

DEFAULT = {"mem_mb": 2000, "runtime": 30}
"""Resources of a rule the table does not list."""

THREADS = {"validate_store": 2, "zarr_store": 2, "check_datasets": 2}
"""Cores of the rules whose job splits its work (Snakemake gives a job at most ``--cores``); the others
use one. ``becos validate --threads 2`` on a 1,000-pair TOSCA store: 13.6 -> 10.1 s wall; ``becos
export-zarr --processes 2`` (a second process fills half of the arrays) and ``becos check --processes 2``:
see docs/measurements.md."""


class RuleResources:
    """The resource table, handing Snakemake ``resources:`` callables per rule."""

    def __init__(self, table: dict[str, dict]):
        self.table = table

    @classmethod
    def load(cls, path: str | Path) -> RuleResources:
        path = Path(path)
        try:
            raw = yaml.safe_load(path.read_text()) or {}
            table = raw["rules"]
            for rule, entry in table.items():
                for key in ("mem_mb", "runtime"):
                    if not (isinstance(entry.get(key), (int, float)) and entry[key] > 0):
                        raise ValueError(f"rule {rule}: {key} must be a positive number, got {entry.get(key)!r}")
        except FileNotFoundError:
            raise InputFileError(
                path,
                "the resource table is missing",
                "restore workflow/resources.yaml from the repository or regenerate it with "
                "`python benchmarks/resources.py --write`",
            ) from None
        except (yaml.YAMLError, KeyError, TypeError, AttributeError, ValueError) as exc:
            raise InputFileError(
                path,
                f"not a valid resource table ({type(exc).__name__}: {exc})",
                "each entry under `rules:` needs positive mem_mb (MiB) and runtime (minutes); "
                "regenerate it with `python benchmarks/resources.py --write`",
            ) from None
        return cls(table)

    def entry(self, rule: str) -> dict:
        return {**DEFAULT, **self.table.get(rule, {})}

    def threads(self, rule: str) -> int:
        """Cores a job of ``rule`` uses (:data:`THREADS`, else 1)."""
        return THREADS.get(rule, 1)

    def mem_mb(self, rule: str) -> Callable[..., int]:
        """``mem_mb`` of ``rule`` (MiB), times the attempt."""
        base = int(self.entry(rule)["mem_mb"])

        def mem_mb(wildcards, attempt: int = 1) -> int:
            return base * attempt

        return mem_mb

    def runtime(
        self,
        rule: str,
        n_pairs: Callable[[object], int] | None = None,
        n_variants: Callable[[object], int] | None = None,
    ) -> Callable[..., int]:
        """``runtime`` of ``rule`` (minutes), times the attempt. For a chunk rule give ``n_pairs``
        (wildcards -> pairs in the job's chunk): then it is the larger of the table's runtime and
        ``seconds_per_pair`` × pairs. For the remesh rule give ``n_variants`` (wildcards -> variants the
        job writes): then it is the larger of the table's runtime and ``seconds_per_variant`` × variants."""
        entry = self.entry(rule)
        base = int(entry["runtime"])
        per_pair, per_variant = float(entry.get("seconds_per_pair", 0.0)), float(entry.get("seconds_per_variant", 0.0))

        def runtime(wildcards, attempt: int = 1) -> int:
            minutes = base
            if n_pairs is not None and per_pair > 0:
                minutes = max(minutes, math.ceil(per_pair * n_pairs(wildcards) / 60))
            if n_variants is not None and per_variant > 0:
                minutes = max(minutes, math.ceil(per_variant * n_variants(wildcards) / 60))
            return minutes * attempt

        return runtime
