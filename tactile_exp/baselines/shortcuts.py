"""One switch for the baselines' shortcuts, so the plain path stays runnable and measurable.

On (the default), work that gives the same numbers is done once: the authors' per-trial static
features of every trial in one batched eigendecomposition per table (split-independent, so shared
by rows A, B, E, F and all adjectives), one standardisation per CV draw for every C of the SVM
grid (the draws on threads, one per core), every trial's HMM log-likelihoods once per fitted
chains (shared by rows C-F), and an adjective's 16 chains fitted on threads (each as it would be
alone). Off: the original per-trial and per-(C, draw) code, one chain after the other, the
reference that tests and ``bench/bench_baselines.py --rows`` compare the shortcuts with.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

_STATE = {"on": True}


def enabled() -> bool:
    return _STATE["on"]


@contextmanager
def disabled() -> Iterator[None]:
    """Run the plain path inside the block (not thread-safe: a test and bench switch)."""
    before = _STATE["on"]
    _STATE["on"] = False
    try:
        yield
    finally:
        _STATE["on"] = before


def threads(tasks: int) -> int:
    """Threads for ``tasks`` independent single-threaded tasks: one per core, at most one each."""
    return max(1, min(os.cpu_count() or 1, tasks))
