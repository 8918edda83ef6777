"""Snakemake's scheduler with becos's fix: at most one re-evaluation timer pending (becos.workflow.scheduling)."""

import threading

from snakemake.scheduling.job_scheduler import JobScheduler

from becos.workflow.scheduling import SNAKEMAKE_METHOD, one_pending_reevaluation


def releases(semaphore: threading.Semaphore) -> int:
    count = 0
    while semaphore.acquire(blocking=False):
        count += 1
    return count


def test_many_rounds_asking_for_a_reevaluation_start_one_timer():
    # Snakemake's own method starts a timer per call: 20 rounds waiting for a core would become 20
    # chains of rounds. The installed Snakemake must have the method, or the workflow's fix is void.
    assert one_pending_reevaluation()
    assert one_pending_reevaluation()  # a second call keeps the first patch
    scheduler = object.__new__(JobScheduler)  # the real class; the timer uses only its semaphore
    scheduler._open_jobs = threading.Semaphore(0)
    threads = threading.active_count()
    for _ in range(20):
        getattr(JobScheduler, SNAKEMAKE_METHOD)(scheduler, 0.2)
    assert threading.active_count() == threads + 1
    pending = scheduler._pending_reevaluation
    assert pending.daemon  # a pending timer does not hold Snakemake at exit
    pending.join(5)
    assert releases(scheduler._open_jobs) == 1
    # once it has fired, the next round that asks starts a timer again
    getattr(JobScheduler, SNAKEMAKE_METHOD)(scheduler, 0.2)
    scheduler._pending_reevaluation.join(5)
    assert releases(scheduler._open_jobs) == 1
