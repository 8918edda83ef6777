"""What every export shares: its folder built aside and renamed into place, per-split numbering, ids and logs.

Each export is written into a temporary folder beside ``out`` and renamed into place at the end, so a
reader never sees half an export. Pairs are numbered 0..N-1 per split in ascending ``pair_id`` order,
whatever order the records come in. ``ids.csv`` maps the numbers to pair ids, ``logs/config.yaml``
records what wrote the export.
"""

from __future__ import annotations

import csv
import datetime
import io
import json
import os
import re
import shutil
import sys
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from becos.atomic import atomic_folder
from becos.build.record import PairRecord
from becos.errors import BecosError, DiskFullError, InputFileError

LAYOUT_VERSION = 1
"""Version of the layouts written here (recorded in ``logs/config.yaml``)."""


IDS_FILE = "ids.csv"


LOGS_DIR = "logs"


SIDES = (("x", 0), ("y", 1))


_STAGING = ".staging"


_PROGRESS_EVERY = 200


_SPLIT_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")


class ExportError(BecosError):
    """An export cannot be written as asked (existing output, inconsistent or duplicate records)."""


def id_field(text: str) -> str:
    return re.sub(r"[_/\\\s]", "-", str(text)) or "-"


def check_record(record: PairRecord, setting: str | None) -> None:
    pid = record.meta.get("pair_id", "?")
    if setting is not None and record.meta.get("setting") != setting:
        raise ExportError(
            f"pair {pid}: its setting {record.meta.get('setting')!r} differs from the export's "
            f"setting {setting!r}. Fix: export each setting's store on its own"
        )
    split = str(record.meta.get("split", ""))
    if not _SPLIT_NAME.fullmatch(split) or split == LOGS_DIR or split.isdigit():
        raise ExportError(
            f"pair {pid}: split {split!r} cannot be a folder name. Fix: use splits such as train, val, test"
        )
    for s, o, corr in (("x", "y", "corr_01"), ("y", "x", "corr_10")):
        n, n_other = len(record[f"{s}_vertices"]), len(record[f"{o}_vertices"])
        c = record[corr]
        if len(c) != n or (len(c) and (c.min() < -1 or c.max() >= n_other)):
            raise ExportError(
                f"pair {pid}: {corr} has {len(c)} entries in [{c.min() if len(c) else 0}, "
                f"{c.max() if len(c) else 0}] for {n} -> {n_other} vertices. Fix: rebuild the "
                f"pair record"
            )


def _is_empty_dir(path: Path) -> bool:
    return path.is_dir() and not any(path.iterdir())


def _check_target(out: Path, overwrite: bool) -> None:
    if out.exists() and not out.is_dir():
        raise ExportError(f"{out}: exists and is not a folder. Fix: choose another output path")
    if out.is_dir() and not overwrite and not _is_empty_dir(out):
        raise ExportError(
            f"{out}: folder exists and is not empty. Fix: choose a new output path or pass "
            f"overwrite=True (--force) to replace it"
        )


@contextmanager
def staged_dir(out: Path, overwrite: bool) -> Iterator[Path]:
    """Yield a temporary folder beside ``out``; on success it replaces ``out``, else it is removed
    (:func:`becos.atomic.atomic_folder`)."""
    _check_target(out, overwrite)
    with atomic_folder(out) as tmp:
        yield tmp
        _check_target(out, overwrite)  # appeared meanwhile


@dataclass(frozen=True)
class _Entry:
    split: str
    pair_id: str
    folder: Path
    x_name: str
    y_name: str
    x_dataset: str
    y_dataset: str


class Staging:
    """Per-pair scratch folders (numbered in arrival order) and their final per-split numbering."""

    def __init__(self, root: Path, label: str, progress: bool):
        self.root = root / _STAGING
        self.entries: list[_Entry] = []
        self.label = label
        self.progress = progress

    def add(self, record: PairRecord) -> Path:
        folder = self.root / str(len(self.entries))
        folder.mkdir(parents=True)
        m = record.meta
        self.entries.append(
            _Entry(
                str(m["split"]),
                str(m["pair_id"]),
                folder,
                str(m["x"]["name"]),
                str(m["y"]["name"]),
                str(m["x"]["dataset"]),
                str(m["y"]["dataset"]),
            )
        )
        if self.progress and len(self.entries) % _PROGRESS_EVERY == 0:
            print(f"{self.label}: {len(self.entries)} pairs", file=sys.stderr, flush=True)
        return folder

    def by_split(self) -> dict[str, list[_Entry]]:
        """{split: entries in ascending pair_id order} (splits in first-seen order); duplicates raise."""
        out: dict[str, list[_Entry]] = {}
        for e in self.entries:
            out.setdefault(e.split, []).append(e)
        for split, entries in out.items():
            entries.sort(key=lambda e: e.pair_id)
            ids = [e.pair_id for e in entries]
            dup = sorted({a for a, b in zip(ids, ids[1:]) if a == b})
            if dup:
                raise ExportError(f"split {split}: pair ids {dup[:5]} occur more than once. Fix: pass each pair once")
        return out

    def finish(self) -> None:
        if self.progress:
            print(f"{self.label}: {len(self.entries)} pairs done", file=sys.stderr, flush=True)
        shutil.rmtree(self.root, ignore_errors=True)


def write_ids(path: Path, header: list[str], rows: list[list]) -> None:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    path.write_text(buffer.getvalue(), encoding="utf-8")


def _plain(value):
    """JSON round trip (numpy values and paths as strings) so YAML gets only builtins."""
    return json.loads(json.dumps(value, default=lambda o: o.item() if isinstance(o, np.generic) else str(o)))


def write_log(
    root: Path,
    writer: str,
    layout: str,
    counts: dict[str, int],
    setting: str | None,
    metadata: Mapping | None,
    maps: Mapping | None = None,
) -> None:
    """``<root>/logs/config.yaml``; ``maps``: optional ``{split: {folder: map files}}`` (DPFM)."""
    import yaml

    from becos import __version__

    log = {
        "written_by": f"becos {__version__} ({writer})",
        "layout": f"{layout} version {LAYOUT_VERSION}, described in docs/released-layout.md of becos",
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "setting": setting,
        "pairs": counts,
        **({"maps": _plain(dict(maps))} if maps is not None else {}),
        "source_metadata": _plain(dict(metadata)) if metadata else None,
    }
    (root / LOGS_DIR).mkdir(exist_ok=True)
    (root / LOGS_DIR / "config.yaml").write_text(
        yaml.safe_dump(log, sort_keys=False, allow_unicode=True), encoding="utf-8"
    )


def place_by_split(staging: Staging, tmp: Path) -> tuple[list[list], dict[str, int]]:
    """Move the staged pair folders to ``tmp/<split>/<index>`` (store order); returns the id-file rows
    ``[split, index, pair_id, x, y]`` and the pair count per split."""
    rows, counts = [], {}
    for split, entries in staging.by_split().items():
        (tmp / split).mkdir()
        for i, e in enumerate(entries):
            os.replace(e.folder, tmp / split / str(i))
            rows.append([split, i, e.pair_id, e.x_name, e.y_name])
        counts[split] = len(entries)
    staging.finish()
    return rows, counts


class DiskEstimateError(DiskFullError):
    """An export would not fit: its estimated size exceeds the free space of its file system (raised
    before anything is written)."""

    def __init__(self, path: str | Path, problem: str, fix: str):
        InputFileError.__init__(self, path, problem, fix)


def gigabytes(n: float) -> str:
    """``n`` bytes as text in GB (10⁹ bytes), two decimals."""
    return f"{n / 1e9:.2f} GB"


def free_space(folder: Path, free_bytes: int | None = None) -> int:
    """Free bytes on ``folder``'s file system (``free_bytes`` instead, when given: tests)."""
    return int(shutil.disk_usage(folder).free if free_bytes is None else free_bytes)


def require_room(out: Path, need: int, free: int, what: str, fix: str, detail: str = "") -> None:
    """Raise :class:`DiskEstimateError` naming ``out`` when ``need`` bytes (the estimate of ``what``,
    ``detail`` in brackets) exceed ``free``; an export calls it before writing anything."""
    if need > free:
        detail = f" ({detail})" if detail else ""
        raise DiskEstimateError(
            out,
            f"{what} need about {gigabytes(need)}{detail} but its file system has {gigabytes(free)} free; "
            "nothing was written",
            fix,
        )
