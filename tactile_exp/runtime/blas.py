"""One BLAS thread for small products, where more threads only add synchronisation.

numpy's and SciPy's BLAS is found once (a lookup costs ~5 ms; limiting it costs ~20 us): the
static features' per-trial solves and the bootstrap's products (replicates x objects) run on one
thread, as two threads on 2 cores spent several times a product's own CPU time waiting.
"""

from __future__ import annotations

import functools
from contextlib import AbstractContextManager

from threadpoolctl import ThreadpoolController


@functools.cache
def _controller() -> ThreadpoolController:
    return ThreadpoolController()


def one_blas_thread() -> AbstractContextManager:
    """A context in which BLAS runs on one thread (the previous count restored after)."""
    return _controller().limit(limits=1, user_api="blas")
