"""PSMAL (partial SMAL) style layout (:func:`write_psmal`): ``<out>/<split>/shapes/<shape id>.off`` and
``<out>/<split>/maps/<A>_<B>.vts`` in both directions; :func:`write_shapes_and_maps` also writes the
DPFM layout (``docs/released-layout.md``).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from becos.build.record import PairRecord
from becos.core.formats.write import off_text, vts_text
from becos.products.export.staging import (
    IDS_FILE,
    SIDES,
    Staging,
    check_record,
    id_field,
    staged_dir,
    write_ids,
    write_log,
)


def psmal_shape_id(index: int, side: int, dataset: str, name: str) -> str:
    """``<pair index>_<side>_<dataset>_<name>``: exactly four ``_``-separated fields, because PSMAL
    loaders split a map file name ``<A>_<B>.vts`` on ``_`` into fields 0-3 (A) and 4-7 (B); ``_``,
    ``/``, ``\\`` and white space inside dataset and name become ``-`` (``tr_reg_000`` ->
    ``tr-reg-000``). The pair index makes ids unique inside a split."""
    return "_".join([str(int(index)), str(int(side)), id_field(dataset), id_field(name)])


def write_psmal(
    records: Iterable[PairRecord],
    out_dir: str | Path,
    *,
    metadata: Mapping | None = None,
    overwrite: bool = False,
    progress: bool = False,
) -> Path:
    """Write the records PSMAL style (``docs/released-layout.md``, section PSMAL).

    Per split: ``<out>/<split>/shapes/<id>.off`` for both shapes of every pair and
    ``<out>/<split>/maps/<A>_<B>.vts`` in both directions: one line per vertex of A, the 0-based
    vertex of B or -1 (as PSMAL's own maps, which its loaders read without subtracting 1). Shape ids
    are :func:`psmal_shape_id` ``(pair index, 0|1, dataset, name)``; ``<out>/ids.csv`` maps
    (split, index) to pair_id, names and ids; ``<out>/logs/config.yaml`` as in :func:`write_released`.

    Args: as :func:`write_released` (records of any setting; numbering per split by pair_id).
    """
    return write_shapes_and_maps(
        records, out_dir, psmal_shape_id, "vts", "write_psmal", "PSMAL-style", metadata, overwrite, progress
    )


def write_shapes_and_maps(
    records: Iterable[PairRecord],
    out_dir: str | Path,
    shape_id,
    map_ext: str,
    writer: str,
    layout: str,
    metadata: Mapping | None,
    overwrite: bool,
    progress: bool,
    none_maps: str | None = None,
) -> Path:
    """``<out>/<split>/shapes/<id>.off`` + ``<out>/<split>/maps/<A>_<B>.<map_ext>`` (both directions);
    with ``none_maps``, a direction that holds a ``-1`` goes to ``<out>/<split>/<none_maps>/`` instead
    (both folders are made in every split, empty or not)."""
    out = Path(out_dir)
    with staged_dir(out, overwrite) as tmp:
        staging = Staging(tmp, f"export-{map_ext}", progress)
        settings = set()
        for record in records:
            check_record(record, None)
            settings.add(record.meta["setting"])
            folder = staging.add(record)
            for s, k in SIDES:
                (folder / f"{k}.off").write_text(
                    off_text(record[f"{s}_vertices"], record[f"{s}_faces"]), encoding="utf-8"
                )
            for direction in ("01", "10"):
                corr = np.asarray(record[f"corr_{direction}"], dtype=np.int64)
                kind = "none" if none_maps is not None and (corr < 0).any() else "map"
                (folder / f"{direction}.{kind}").write_text(vts_text(corr), encoding="utf-8")
        rows, counts, map_counts = [], {}, {}
        for split, entries in staging.by_split().items():
            shapes, maps = tmp / split / "shapes", tmp / split / "maps"
            shapes.mkdir(parents=True)
            maps.mkdir()
            folders = {"map": maps}
            if none_maps is not None:
                folders["none"] = tmp / split / none_maps
                folders["none"].mkdir()
            for i, e in enumerate(entries):
                a = shape_id(i, 0, e.x_dataset, e.x_name)
                b = shape_id(i, 1, e.y_dataset, e.y_name)
                os.replace(e.folder / "0.off", shapes / f"{a}.off")
                os.replace(e.folder / "1.off", shapes / f"{b}.off")
                for direction, name in (("01", f"{a}_{b}"), ("10", f"{b}_{a}")):
                    for kind, target in folders.items():
                        if (e.folder / f"{direction}.{kind}").is_file():
                            os.replace(e.folder / f"{direction}.{kind}", target / f"{name}.{map_ext}")
                rows.append([split, i, e.pair_id, e.x_name, e.y_name, a, b])
            counts[split] = len(entries)
            map_counts[split] = {f.name: sum(1 for _ in f.iterdir()) for f in folders.values()}
        staging.finish()
        write_ids(tmp / IDS_FILE, ["split", "index", "pair_id", "x", "y", "x_id", "y_id"], rows)
        setting = settings.pop() if len(settings) == 1 else None
        write_log(
            tmp,
            f"becos.products.export.{writer}",
            f"becos {layout} layout",
            counts,
            setting,
            metadata,
            map_counts if none_maps is not None else None,
        )
    return out
