"""Work of one job split over two processes (:func:`split_over_processes`), for jobs the workflow gives two
cores: their work is pure Python over independent files, which threads would serialise on the GIL."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any


def split_over_processes(function: Callable[[list], list], items: Iterable, processes: int = 1) -> list[Any]:
    """``function(items)``: ``function`` maps a list of items to a list of one result each. With
    ``processes`` 2 a second (spawned) process takes every other item meanwhile, so neighbouring items
    of similar cost are shared out evenly; the results come back in the items' order.

    ``function`` must be picklable (a module-level function, or a ``functools.partial`` of one), and so
    must the items and results; an exception of either process is raised here, once both halves have ended.
    """
    items = list(items)
    if processes < 2 or len(items) < 2:
        return function(items)
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        theirs = pool.submit(function, items[0::2])
        ours = function(items[1::2])
        results = theirs.result()
    out: list = [None] * len(items)
    out[0::2], out[1::2] = results, ours
    return out
