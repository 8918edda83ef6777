"""``store``: open a store for validation without a traceback, and name what is missing or unreadable
(nodes whose metadata is absent or broken, chunks that do not decode, and the pairs they hold)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from becos.products.store import DAMAGED_STORE_FIX as STORE_FIX
from becos.products.validate.report import MAX_EXAMPLES


def node_problem(path: Path, node: str) -> str | None:
    """Why the Zarr node ``node`` (e.g. ``arrays/x_faces``) of a store cannot be opened, else None."""
    meta = path / node / "zarr.json"
    if not meta.is_file():
        return "missing"
    try:
        info = json.loads(meta.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        return f"has unreadable metadata ({node}/zarr.json: {exc})"
    if not isinstance(info, dict) or info.get("node_type") != "array":
        return f"is not a Zarr array ({node}/zarr.json)"
    return None


def diagnose(path: Path, exc: Exception) -> list[str]:
    """Readable ``store`` problems of a store that exists but does not open (missing or damaged nodes)."""
    try:
        attrs = json.loads((path / "zarr.json").read_text(encoding="utf-8")).get("attributes", {})
        layout = dict(attrs["becos_store"]["layout"])
    except Exception:  # root metadata unreadable: nothing more specific to say
        layout = {}
    nodes = [f"arrays/{k}" for k in layout]
    nodes += [f"offsets/{g}" for g in sorted({g for g in layout.values() if g is not None})]
    nodes += ["pairs/meta_json", "pairs/meta_offsets", "pairs/table_json"]
    found: dict[str, list[str]] = {}
    for node in nodes:
        problem = node_problem(path, node)
        if problem is not None:
            found.setdefault(problem if problem == "missing" else "unreadable", []).append(
                node if problem == "missing" else f"{node} {problem}"
            )
    out = []
    if "missing" in found:
        names = found["missing"]
        out.append(
            f"store: {path}: {len(names)} of its arrays missing: {', '.join(names[:8])}"
            f"{' ...' if len(names) > 8 else ''}. Fix: {STORE_FIX}"
        )
    if "unreadable" in found:
        out.append(f"store: {path}: {'; '.join(found['unreadable'][:4])}. Fix: {STORE_FIX}")
    if not out:
        out.append(f"store: {path}: cannot be opened ({type(exc).__name__}: {exc}). Fix: {STORE_FIX}")
    return out


def open_for_validation(path: str | Path):
    """``(Benchmark, [])`` or ``(None, [store problem])``: never raises for a missing or damaged store."""
    from becos.errors import InputFileError
    from becos.products.store import DamagedStoreError, open_benchmark

    path = Path(path)
    fix = "give a store folder (*.zarr) written by `becos export-zarr`"
    if not path.exists():
        return None, [f"store: {path}: not found. Fix: check the path; {fix}"]
    if not path.is_dir():
        return None, [f"store: {path}: is a file, not a store folder. Fix: {fix}"]
    try:
        return open_benchmark(path), []
    except DamagedStoreError as exc:  # name every missing or unreadable node, not just the first
        return None, diagnose(path, exc.__cause__)
    except InputFileError as exc:
        return None, [f"store: {exc}"]
    except Exception as exc:  # zarr raises KeyError, JSONDecodeError ... for damaged stores
        return None, diagnose(path, exc)


def unreadable_rows(bench, start: int, stop: int, exc: Exception, ids: np.ndarray) -> str:
    """The ``store`` problem of rows ``start:stop`` that failed to read: which arrays fail, why, and for
    which pairs (each failing array re-read pair by pair)."""

    def rows_of(key: str, i: int, j: int) -> tuple[int, int]:
        group = bench.layout[key]
        return (i, j) if group is None else (int(bench.offsets[group][i]), int(bench.offsets[group][j]))

    failing, bad = [], np.zeros(stop - start, dtype=bool)
    for key in bench.layout:
        try:
            bench.array(key)[slice(*rows_of(key, start, stop))]
        except Exception as err:
            failing.append(f"arrays/{key} ({type(err).__name__}: {err})")
            for i in range(start, stop):
                try:
                    bench.array(key)[slice(*rows_of(key, i, i + 1))]
                except Exception:
                    bad[i - start] = True
    if not failing:
        failing.append(f"pairs/meta_json ({type(exc).__name__}: {exc})")
    if not bad.any():
        bad[:] = True
    pairs = ids[start:stop][bad]
    return (
        f"store: {bench.path}: chunks of {'; '.join(failing[:4])}{' ...' if len(failing) > 4 else ''} cannot "
        f"be read, in {len(pairs)} pair(s), e.g. {', '.join(pairs[:MAX_EXAMPLES])}. Fix: {STORE_FIX}"
    )
