"""Work of one job split over two processes (:func:`map_over_processes`), for jobs the workflow gives two
cores: their work is pure Python over independent files, which threads would serialise on the GIL."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any


def _apply_all(function: Callable, items: list[tuple]) -> list:
    return [function(*item) for item in items]


def map_over_processes(function: Callable, items: Iterable[tuple], processes: int = 1) -> list[Any]:
    """``[function(*item) for item in items]``, in order. With ``processes`` 2 a second (spawned) process
    takes every other item meanwhile, so neighbouring items of similar cost are shared out evenly.

    ``function`` must be a module-level function and its arguments and results picklable; an exception
    of either process is raised here, once both halves have ended.
    """
    items = list(items)
    if processes < 2 or len(items) < 2:
        return _apply_all(function, items)
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        theirs = pool.submit(_apply_all, function, items[0::2])
        ours = _apply_all(function, items[1::2])
        results = theirs.result()
    out: list = [None] * len(items)
    out[0::2], out[1::2] = results, ours
    return out
