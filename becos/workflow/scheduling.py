"""At most one pending re-evaluation timer in Snakemake's job scheduler (snakemake/snakemake#3744).

Snakemake's job rate limiter (``--max-jobs-per-timespan``, on by default: 100/1s) makes every round that
leaves ready jobs waiting start a timer for another round one timespan later, which starts another. Each
finished job starts such a chain, ended only when no job is ready: while jobs wait for a core, the rounds
per second grow with the jobs finished, and each resets the ready jobs' params and stats the inputs of
up to ``scheduler-subsample`` of them, so Snakemake's own CPU grew with the square of the job count
(``benchmarks/scheduler.py --job-seconds``; docs/scale.md, Defects). :func:`one_pending_reevaluation`
starts no timer while one is pending: a round still follows within one timespan of every round asking.
"""

from __future__ import annotations

import threading

SNAKEMAKE_METHOD = "_schedule_reevalutation"
"""The scheduler's method that starts the timer (Snakemake's spelling)."""


def one_pending_reevaluation() -> bool:
    """Patch :class:`snakemake.scheduling.job_scheduler.JobScheduler` so that each scheduler has at most one
    re-evaluation timer pending (a daemon thread: it does not hold the process at exit). True when the
    installed Snakemake has the method (patched now or before); False leaves Snakemake as it is."""
    from snakemake.scheduling import job_scheduler

    scheduler = getattr(job_scheduler, "JobScheduler", None)
    original = getattr(scheduler, SNAKEMAKE_METHOD, None)
    if original is None:
        return False
    if getattr(original, "one_pending", False):
        return True
    lock = threading.Lock()

    def schedule_reevaluation(self, delay) -> None:
        with lock:
            if getattr(self, "_pending_reevaluation", None) is not None:
                return  # the pending timer starts a round within one timespan

            def reevaluate() -> None:
                with lock:
                    self._pending_reevaluation = None
                self._open_jobs.release()

            timer = threading.Timer(delay, reevaluate)
            timer.daemon = True
            self._pending_reevaluation = timer
        timer.start()

    schedule_reevaluation.one_pending = True
    setattr(scheduler, SNAKEMAKE_METHOD, schedule_reevaluation)
    return True
