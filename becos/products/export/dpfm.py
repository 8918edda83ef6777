"""DPFM style layout (:func:`write_dpfm`): ``shapes/*.off`` + ``maps/<A>_<B>.map`` with ids free of ``_``;
only the directions without a ``-1`` row in ``maps/`` (the rest in ``maps_with_none/``;
``docs/released-layout.md``, section 6).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path

from becos.build.record import PairRecord
from becos.products.export.psmal import write_shapes_and_maps
from becos.products.export.staging import id_field


def dpfm_shape_id(index: int, side: int, dataset: str, name: str) -> str:
    """``<pair index>-<side>-<dataset>-<name>`` with no ``_`` at all (``_``, ``/``, ``\\`` and white
    space become ``-``): DPFM's loader splits a map name ``<A>_<B>`` at its LAST ``_`` and others
    (CP2P loaders) at every ``_``, so an id without ``_`` survives both."""
    return "-".join([str(int(index)), str(int(side)), id_field(dataset), id_field(name)])


DPFM_NONE_MAPS = "maps_with_none"
"""Folder beside ``maps/`` of a DPFM export for the map directions that hold a ``-1`` row."""


def write_dpfm(
    records: Iterable[PairRecord],
    out_dir: str | Path,
    *,
    metadata: Mapping | None = None,
    overwrite: bool = False,
    progress: bool = False,
) -> Path:
    """Write the records DPFM style (``docs/released-layout.md``, section 6): per split
    ``<out>/<split>/shapes/<id>.off`` and, for both directions A -> B of every pair, ``<A>_<B>.map``
    (one line per vertex of A: the 0-based vertex of B, -1 = none), ids :func:`dpfm_shape_id`;
    ``ids.csv`` and ``logs/config.yaml`` as :func:`write_psmal`.

    A direction goes to ``<split>/maps/`` (which DPFM's ``ShrecPartialDataset`` trains on) only when
    every vertex of A has a counterpart, as in DPFM's SHREC'16 maps: its loader sets
    ``P[range(n2), map21] = 1`` and has no "none", so a ``-1`` row would become a match with B's last
    vertex and a wrong ``C_gt``. Directions holding a ``-1`` go to ``<split>/maps_with_none/``
    (:data:`DPFM_NONE_MAPS`, same format), which DPFM does not read; together the two folders hold
    both directions of every pair, and ``<A>_<B>.map != -1`` is A's own overlap mask. The log's
    ``maps`` gives each split's file count per folder (``maps`` = the items DPFM will form)."""
    return write_shapes_and_maps(
        records,
        out_dir,
        dpfm_shape_id,
        "map",
        "write_dpfm",
        "DPFM-style",
        metadata,
        overwrite,
        progress,
        none_maps=DPFM_NONE_MAPS,
    )
