""":func:`validate`: every check of the :mod:`becos.products.validate` table on one store, in order: the store
opens (``store``), root attributes and table order, the schema, then block by block the row-wise checks
(:class:`~becos.products.validate.block.BlockChecker`), the metas and the content digests, and last the
checks over all pairs (``checksum``, ``pair_id``, ``split_classes``, ``centaur``)."""

from __future__ import annotations

import sys
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from becos.products.validate.block import BlockChecker, EdgeNeighbourCache
from becos.products.validate.content import check_digests, digests_to_check
from becos.products.validate.opening import open_for_validation, unreadable_rows
from becos.products.validate.report import Problems, ValidationReport
from becos.products.validate.tables import (
    check_metadata,
    check_metas,
    check_order,
    check_pair_ids,
    check_schema,
    check_splits,
)

VALIDATE_BLOCK_BYTES = 16 << 20
"""Uncompressed bytes checked at once (the checks make several temporaries per block, so the
block size sets the validator's memory, independent of the store's size)."""


def validate(
    path: str | Path, progress: bool = False, threads: int = 1, block_bytes: int = VALIDATE_BLOCK_BYTES
) -> ValidationReport:
    """Run every check on a store; see docs/design/validate.md. Never raises for a bad store: a store that
    is missing or does not open gives one ``store`` problem. ``threads`` > 1 checks that many blocks at
    once (numpy releases the GIL in the checks' array work); the report is the same for any ``threads``.
    ``block_bytes``: uncompressed bytes of pairs checked as one block (at least one pair)."""
    started = time.perf_counter()
    path = Path(path)
    bench, problems = open_for_validation(path)
    if bench is None:
        return ValidationReport(path, problems, seconds=time.perf_counter() - started)
    found = Problems()
    table = bench.table
    n = len(bench)
    ids = table["pair_id"].to_numpy().astype(str)
    check_metadata(bench, problems)
    if list(table["index"]) != list(range(n)):
        problems.append("table: the index column is not 0..N-1")
    check_order(table, problems)

    if check_schema(bench, problems):
        check_blocks(bench, ids, problems, found, started if progress else None, threads, block_bytes)
    else:  # the arrays cannot be trusted: check the metas and the table only
        check_metas_only(bench, ids, problems, found)
    check_pair_ids(ids, found)
    check_splits(table, bench.setting, found)
    problems.extend(found.messages())
    splits = {str(k): int(v) for k, v in table["split"].value_counts().items()}
    return ValidationReport(path, problems, n, bench.setting, splits, time.perf_counter() - started)


def check_metas_only(bench, ids: np.ndarray, problems: list[str], found: Problems) -> None:
    """The ``meta`` and ``table`` checks of a store whose arrays fail ``schema`` (``ids``: (N,) str)."""
    from becos.products.store import Block

    n = len(bench)
    try:
        metas = bench.read_metas()
    except Exception as exc:
        problems.append(unreadable_rows(bench, 0, n, exc, ids))
    else:
        check_metas(Block(0, n, {}, {}, bench.layout, metas), bench.setting, bench.table, found)


def check_blocks(
    bench,
    ids: np.ndarray,
    problems: list[str],
    found: Problems,
    started: float | None,
    threads: int = 1,
    block_bytes: int = VALIDATE_BLOCK_BYTES,
) -> None:
    """Row-wise checks and metas block by block, then ``checksum`` if every block read
    (``ids``: (N,) str; ``started``: :func:`time.perf_counter` of the run to print progress about
    every 10 % on stderr, None for none). This thread reads the blocks in order and feeds the digests;
    ``threads`` workers check them, each into its own :class:`Problems`, merged in block order so the
    messages are those of one thread."""
    n = len(bench)
    reported = 0
    digests = digests_to_check(bench)
    neighbours = EdgeNeighbourCache()  # the blocks share the store's remeshes

    def check(block) -> Problems:
        block_found = Problems()
        BlockChecker(block, bench.setting, ids[block.start : block.stop], block_found, neighbours).run()
        check_metas(block, bench.setting, bench.table, block_found)
        return block_found

    def merge_oldest() -> None:
        nonlocal reported
        stop, future = pending.popleft()
        found.merge(future.result())
        if started is not None and (10 * stop // n > reported or stop == n):  # about every 10 %
            reported = 10 * stop // n
            print(
                f"validate: {stop}/{n} pairs checked ({time.perf_counter() - started:.1f} s)",
                file=sys.stderr,
                flush=True,
            )

    workers = max(1, threads)
    pending: deque = deque()
    with ThreadPoolExecutor(workers) as pool:
        for start, stop in bench.block_ranges(max_bytes=block_bytes):
            try:  # straight from the chunk files; any problem is read again, and reported, through zarr
                block = bench.read_rows(start, stop)
            except Exception as exc:  # a damaged chunk: name it, check the other blocks
                problems.append(unreadable_rows(bench, start, stop, exc, ids))
                digests = None
                continue
            if digests is not None:  # before the checks see the block
                for key in bench.layout:
                    digests.update(f"arrays/{key}", block.arrays[key])
            pending.append((stop, pool.submit(check, block)))
            while len(pending) > workers:  # bounds the blocks held in memory
                merge_oldest()
        while pending:
            merge_oldest()
    if digests is not None:
        check_digests(bench, digests, problems)


def validate_store(path: str | Path) -> list[str]:
    """Human-readable problems of a benchmark store; empty = valid (checks: docs/design/validate.md)."""
    return validate(path).problems
