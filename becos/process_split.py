"""Work of one job split over two processes, for jobs the workflow gives two cores: their work is pure
Python (or one event loop) per process, which threads would serialise on the GIL. :func:`in_second_process`
runs one call beside the caller; :class:`ProcessSplit` shares lists of items out with one second process,
started once for all of them."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future
from typing import Any


def _spawned_pool():
    """A pool of one spawned process (zarr's event-loop thread does not survive a fork)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    return ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"))


@contextlib.contextmanager
def in_second_process(function: Callable, *args) -> Iterator[Future]:
    """``function(*args)`` in a second (spawned) process while the block runs; yields its
    :class:`~concurrent.futures.Future`, whose ``result()`` returns the call's value or raises its
    exception. Leaving the block, also after an error, waits for the call to end.
    ``function`` (module level), ``args``, the value and the exception must pickle."""
    with _spawned_pool() as pool:
        yield pool.submit(function, *args)


class ProcessSplit:
    """Lists of items shared out between this process and, with ``processes`` 2, one second process.

    Used as a context manager: entering it starts the second process and has it import ``warm_up``'s
    modules meanwhile (``warm_up``: module names, e.g. the module of the functions :meth:`map` will get),
    so its start-up overlaps the caller's own work; each :meth:`map` reuses it. Leaving waits for it to end.
    """

    def __init__(self, processes: int = 1, warm_up: tuple[str, ...] = ()):
        self.processes = processes
        self._warm_up = warm_up
        self._pool = None

    def __enter__(self) -> ProcessSplit:
        if self.processes >= 2:
            import importlib

            self._pool = _spawned_pool()
            for module in self._warm_up:
                self._pool.submit(importlib.import_module, module)
        return self

    def __exit__(self, *exc) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def map(self, function: Callable[[list], list], items: Iterable) -> list[Any]:
        """``function(items)``: ``function`` maps a list of items to a list of one result each. With a
        second process, it takes every other item meanwhile, so neighbouring items of similar cost are
        shared out evenly; the results come back in the items' order.

        ``function`` must be picklable (a module-level function, or a ``functools.partial`` of one), and so
        must the items and results; an exception of either process is raised here, once both halves have ended.
        """
        items = list(items)
        if self._pool is None or len(items) < 2:
            return function(items)
        from concurrent.futures import wait

        theirs = self._pool.submit(function, items[0::2])
        try:
            ours = function(items[1::2])
        except BaseException:
            wait([theirs])  # our error is raised once the second half has ended
            raise
        results = theirs.result()
        out: list = [None] * len(items)
        out[0::2], out[1::2] = results, ours
        return out
