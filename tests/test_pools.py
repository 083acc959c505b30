"""The package's own process pools start under any parent (``tactile_exp.pools``)."""

from __future__ import annotations

from tactile_exp import pools


def _square_in_a_pool(method: str, x: int) -> int:
    """In a joblib worker: a pool of this process's own children, started by ``method``."""
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(1, mp_context=pools.start_context(method)) as pool:
        return pool.submit(pow, x, 2).result()


def test_a_joblib_workers_own_pool_starts_its_children():
    """A loky worker's default start method ("loky") is unknown to a fresh child: without
    ``start_context`` every child died before its first task (BrokenProcessPool)."""
    from joblib import Parallel, delayed

    for method in ("spawn", "forkserver"):
        squares = Parallel(n_jobs=2, backend="loky")(
            delayed(_square_in_a_pool)(method, x) for x in (3, 4)
        )
        assert squares == [9, 16]
