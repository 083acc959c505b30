"""A job's adjectives side by side in worker processes (``workers`` > 1; ours, not the paper's).

On 2 cores, a ConvNet job with two single-threaded workers takes ~0.91 of the time it takes in
one process on two threads (``bench/bench_workers.py``: row I cut to 6 adjectives x 120 epochs,
2026-11-27). Each worker runs whole adjectives, its own MLflow
runs included; the job's process only hands out adjectives and collects their results.

Workers are spawned (never forked: torch and numba hold threads), take ``cores // workers``
threads each, send their log records through the job's handlers, and end with the job: an error
or SIGTERM in the job sends SIGTERM to the workers (their runs end FAILED), and a job killed
outright takes its workers with it (Linux: the parent-death signal).
"""

from __future__ import annotations

import concurrent.futures
import ctypes
import logging
import logging.handlers
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from types import TracebackType
from typing import Any

from tactile_exp import cores, pools
from tactile_exp.runtime import processes, termination

log = logging.getLogger(__name__)

GRACE_S = 30.0  # how long stopped workers get to end their runs before SIGKILL
_PR_SET_PDEATHSIG = 1  # prctl(2)
ORPHAN_POLL_S = 1.0  # how often a worker looks whether its job is still its parent


class Pool:
    """``workers`` spawned processes, each set up once by ``init(*initargs)``; ``map`` yields
    results in order. Leaving the block on an error stops the workers (``pids`` lists them, so
    the caller can close any run a killed worker left RUNNING)."""

    def __init__(
        self, workers: int, *, init: Callable[..., None], initargs: tuple[Any, ...]
    ) -> None:
        context = pools.start_context("spawn")
        records = context.Queue()
        self._listener = logging.handlers.QueueListener(records, _Relay())
        threads = max(1, cores.cores() // workers)
        self._executor = concurrent.futures.ProcessPoolExecutor(
            max_workers=workers,
            mp_context=context,
            initializer=_start,
            initargs=(records, logging.getLogger().getEffectiveLevel(), threads, init, initargs),
        )
        self.pids: set[int] = set()

    def __enter__(self) -> Pool:
        self._listener.start()
        return self

    def map(self, fn: Callable[..., Any], calls: Iterable[tuple[Any, ...]]) -> Iterator[Any]:
        futures = [self._executor.submit(_call, fn, *args) for args in calls]
        self.pids.update(p.pid for p in multiprocessing.active_children() if p.pid is not None)
        for future in futures:
            yield future.result()

    def __exit__(
        self,
        kind: type[BaseException] | None,
        err: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        try:
            if err is None:
                self._executor.shutdown(wait=True)
                return
            self._stop()
        finally:
            self._listener.stop()

    def _stop(self) -> None:
        """SIGTERM to every worker, SIGKILL to those still there after ``GRACE_S``."""
        self._executor.shutdown(wait=False, cancel_futures=True)
        processes.stop(self.pids, GRACE_S)
        multiprocessing.active_children()  # reaps the ended workers


class _Relay(logging.Handler):
    """A worker's record, handled by the job's logger of the same name (level, handlers)."""

    def emit(self, record: logging.LogRecord) -> None:
        logging.getLogger(record.name).handle(record)


_job = {"pid": 0}  # in a worker: the job's PID


def _call(fn: Callable[..., Any], *args: Any) -> Any:
    """``fn(*args)``, unless this worker was stopped: an adjective already queued to it must not
    start once its job is ending."""
    termination.check()
    try:
        return fn(*args)
    finally:
        signum = termination.received()
        if signum and os.getppid() != _job["pid"]:
            os._exit(128 + signum)  # the job is gone (killed): its runs are ended


def _watch_job(job_pid: int) -> None:
    """SIGTERM to this worker once its job is gone, then exit if it has not: the parent-death
    signal alone once left a worker of a SIGKILLed job running, idle between adjectives."""
    while os.getppid() == job_pid:
        time.sleep(ORPHAN_POLL_S)
    os.kill(os.getpid(), signal.SIGTERM)  # the main thread ends its runs FAILED and exits
    time.sleep(GRACE_S)
    os._exit(128 + signal.SIGTERM)


def _start(
    records: Any,
    level: int,
    threads: int,
    init: Callable[..., None],
    initargs: tuple[Any, ...],
) -> None:
    """A worker's setup: signals, logging through the job, threads, then ``init``."""
    signal.signal(signal.SIGTERM, termination.handle)
    _job["pid"] = os.getppid()
    if sys.platform == "linux":  # SIGTERM when the job dies, even by SIGKILL
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    threading.Thread(target=_watch_job, args=(_job["pid"],), daemon=True).start()
    root = logging.getLogger()
    root.handlers[:] = [logging.handlers.QueueHandler(records)]
    root.setLevel(level)
    import torch

    from tactile_exp.models.numba_setup import numba

    cores.share(threads)
    torch.set_num_threads(threads)
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    init(*initargs)
