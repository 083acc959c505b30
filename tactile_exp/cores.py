"""How many cores this process may use: the one rule for every thread pool of the package.

A worker process of a job (``runtime.workers``) gets its share of the cores (``share``), so
the thread pools it opens (the SVM grid, the HMM chains) never oversubscribe the machine.
"""

from __future__ import annotations

import os

_share: dict[str, int] = {}  # set once in a worker process: its cores


def cores() -> int:
    """The cores this process may run on (its CPU affinity; a worker's share when set)."""
    if "cores" in _share:
        return _share["cores"]
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def share(n: int) -> None:
    """This process runs on ``n`` of the machine's cores (a job's worker process)."""
    _share["cores"] = max(1, n)


def threads(tasks: int) -> int:
    """Threads for ``tasks`` independent single-threaded tasks: one per core, at most one each."""
    return max(1, min(cores(), tasks))
