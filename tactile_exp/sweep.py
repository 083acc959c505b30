"""The Hydra sweep callback (``hydra.callbacks.prepare_sweep`` in ``conf/config.yaml``).

Kept apart from ``tracking.py`` so that the MLflow layer imports neither Hydra nor the engine.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import signal
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from tactile_exp.tracking import process_alive

if TYPE_CHECKING:
    from tactile_exp.tracking import Tracker

log = logging.getLogger(__name__)

WORKER_GRACE_S = 60.0  # how long a terminated sweep waits for its workers to mark runs FAILED


def _children(pid: int) -> list[int]:
    """Direct child processes of ``pid`` (Linux /proc; none found elsewhere)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def _resource_tracker(pid: int) -> bool:
    """multiprocessing's or loky's resource tracker: it ignores SIGTERM and exits by itself once
    the launcher is gone, so it is neither signalled nor waited for."""
    try:
        return b"resource_tracker import main" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return False


def _gone(pid: int) -> bool:
    """Whether worker ``pid`` has ended; reaps it when it is our child."""
    try:
        waited, _ = os.waitpid(pid, os.WNOHANG)
        if waited == pid:
            return True
    except ChildProcessError:
        pass
    return not process_alive(pid)


def terminate_workers(signum: int, frame: object, *, tracker: Tracker) -> None:
    """SIGTERM to a sweep's launcher: pass it on to the worker processes (each unwinds its job,
    marks its runs FAILED and exits), wait for them, then exit. Without this the launcher died
    alone and its joblib workers went on with parent PID 1.

    A worker can die with its runs still RUNNING: once one worker exits, loky SIGKILLs the others
    (a "broken" pool), maybe mid-unwind or before its next SIGTERM check (``termination.check``);
    and workers past the grace period are killed here. Their runs are closed here instead."""
    workers = [pid for pid in _children(os.getpid()) if not _resource_tracker(pid)]
    log.warning("terminated: stopping %d worker process(es)", len(workers))
    for pid in workers:
        try:
            os.kill(pid, signal.SIGTERM)
        except ProcessLookupError:
            continue
    deadline = time.monotonic() + WORKER_GRACE_S
    while time.monotonic() < deadline and not all(_gone(pid) for pid in workers):
        time.sleep(0.2)
    for pid in workers:
        if not _gone(pid):
            with contextlib.suppress(ProcessLookupError):  # ended since _gone looked
                os.kill(pid, signal.SIGKILL)
    while time.monotonic() < deadline + 5.0 and not all(_gone(pid) for pid in workers):
        time.sleep(0.05)  # ended (a zombie counts), so their runs can be closed
    error = f"Terminated: terminated by signal {signum}; killed before it ended this run"
    closed = tracker.end_runs_of(workers, error=error)
    if closed:
        log.warning("marked FAILED %d run(s) that killed worker(s) left RUNNING", len(closed))
    raise SystemExit(128 + signum)


class PrepareSweep(Callback):
    """Before a multirun launches parallel jobs: create the MLflow experiment, the data and the
    shared preprocessed arrays once, so jobs neither race on the sqlite schema nor repeat work;
    and make SIGTERM to the launcher stop its workers."""

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        from tactile_exp.config import settings_from_config
        from tactile_exp.errors import reported
        from tactile_exp.experiment import load
        from tactile_exp.tracking import Tracker

        with reported():
            settings = settings_from_config(config)
            tracker = Tracker(settings.tracking.uri, settings.tracking.experiment)
            signal.signal(signal.SIGTERM, functools.partial(terminate_workers, tracker=tracker))
            load(settings)
