"""How the package's own process pools start (the synthetic generator's workers, a job's
adjective workers), in any parent process, a launcher's worker included."""

from __future__ import annotations

import multiprocessing
import multiprocessing.context


def start_context(method: str) -> multiprocessing.context.BaseContext:
    """multiprocessing's ``method`` context ("spawn" or "forkserver") for this process's own pool.

    A spawned or forkserver child first sets its parent's default start method; in a joblib
    (loky) worker that is "loky", which a fresh child does not know, and every child died before
    its first task (the synthetic generator's pool under ``hydra/launcher=joblib``). There the
    default becomes ``method``: the worker itself starts no other processes.
    """
    if multiprocessing.get_start_method(allow_none=True) not in (
        None,
        *multiprocessing.get_all_start_methods(),
    ):
        multiprocessing.set_start_method(method, force=True)
    return multiprocessing.get_context(method)
