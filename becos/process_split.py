"""Work of one job split over two processes, for jobs the workflow gives two cores: their work is pure
Python (or one event loop) per process, which threads would serialise on the GIL. :func:`in_second_process`
runs one call beside the caller; :func:`split_over_processes` shares a list of items out with it."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future
from typing import Any


@contextlib.contextmanager
def in_second_process(function: Callable, *args) -> Iterator[Future]:
    """``function(*args)`` in a second (spawned: zarr's event-loop thread does not survive a fork) process
    while the block runs; yields its :class:`~concurrent.futures.Future`, whose ``result()`` returns the
    call's value or raises its exception. Leaving the block, also after an error, waits for the call to end.
    ``function`` (module level), ``args``, the value and the exception must pickle."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        yield pool.submit(function, *args)


def split_over_processes(function: Callable[[list], list], items: Iterable, processes: int = 1) -> list[Any]:
    """``function(items)``: ``function`` maps a list of items to a list of one result each. With
    ``processes`` 2 a second process (:func:`in_second_process`) takes every other item meanwhile, so
    neighbouring items of similar cost are shared out evenly; the results come back in the items' order.

    ``function`` must be picklable (a module-level function, or a ``functools.partial`` of one), and so
    must the items and results; an exception of either process is raised here, once both halves have ended.
    """
    items = list(items)
    if processes < 2 or len(items) < 2:
        return function(items)
    with in_second_process(function, items[0::2]) as theirs:
        ours = function(items[1::2])
        results = theirs.result()
    out: list = [None] * len(items)
    out[0::2], out[1::2] = results, ours
    return out
