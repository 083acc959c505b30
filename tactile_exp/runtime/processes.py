"""Processes as ``/proc`` shows them (Linux; elsewhere nothing is found and a PID that exists is
taken as running), and the one way to stop child processes.

A run records who runs it (``process_tags``: host, PID and the PID's start time), so a RUNNING
run whose process has ended is told apart from a live one, even after its PID is reused. A
stopped worker is signalled, given time to end its runs, then killed (``stop``): a job's
adjective workers (``runtime.workers``) and a terminated sweep's joblib workers
(``app.sweep``) end the same way.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import time
from collections.abc import Collection
from pathlib import Path

from tactile_exp.runtime import termination

KILLED_WAIT_S = 5.0  # how long ``stop`` waits for killed processes to end
POLL_S = 0.1


def stat_fields(pid: int) -> list[str]:
    """The fields of ``/proc/<pid>/stat`` after the command name; [] where unreadable."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return []


def process_start(pid: int) -> str:
    """The process's start time in clock ticks since boot (/proc), "" where unknown: a PID
    reused by a later process has a different start time."""
    fields = stat_fields(pid)
    return fields[19] if fields else ""


def process_alive(pid: int, started: str = "") -> bool:
    """Whether process ``pid`` (started at ``started``, when given) still runs. A zombie has
    ended: a killed worker that its parent has not reaped yet must not keep its runs RUNNING."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    fields = stat_fields(pid)
    if fields and fields[0] == "Z":
        return False
    return not started or not fields or fields[19] == started


def process_tags() -> dict[str, str]:
    """Who runs this run: stale RUNNING runs are told apart from live ones by these."""
    pid = os.getpid()
    return {"host": socket.gethostname(), "pid": str(pid), "pid_start": process_start(pid)}


def children(pid: int) -> list[int]:
    """Direct child processes of ``pid``."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def is_resource_tracker(pid: int) -> bool:
    """multiprocessing's or loky's resource tracker: it ignores SIGTERM and exits by itself once
    the process that started it is gone, so it is neither signalled nor waited for."""
    try:
        return b"resource_tracker import main" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return False


def stop(pids: Collection[int], grace_s: float) -> list[int]:
    """SIGTERM to each of ``pids`` (each unwinds its job and marks its runs FAILED), SIGKILL to
    those still running after ``grace_s``; returns once all have ended (a zombie has) or
    ``KILLED_WAIT_S`` after the SIGKILL, with the PIDs it had to kill.

    A second SIGTERM to this process does not cut the wait short (``termination.shielded``). It
    never reaps: the processes' parent does (``multiprocessing``, loky), whose bookkeeping an
    ``os.waitpid`` here would break; each process is known by its start time, so a PID reused
    after such a reap is neither waited for nor killed.
    """
    started = {pid: process_start(pid) for pid in pids}

    def running() -> list[int]:
        return [pid for pid, start in started.items() if process_alive(pid, start)]

    for pid in running():
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGTERM)
    with termination.shielded():
        deadline = time.monotonic() + grace_s
        while time.monotonic() < deadline and running():
            time.sleep(POLL_S)
        killed = running()
        for pid in killed:
            with contextlib.suppress(ProcessLookupError):  # ended since it was looked at
                os.kill(pid, signal.SIGKILL)
        deadline = time.monotonic() + KILLED_WAIT_S
        while time.monotonic() < deadline and running():
            time.sleep(POLL_S / 2)
    return killed
