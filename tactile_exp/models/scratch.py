"""Reusable float32 scratch arrays for the compiled CPU kernels of the haptic ConvNet.

A training step at batch 1000 needs 100-150 MB of activations and gradients. Freshly allocated
memory is page-faulted and zeroed by the OS on its first touch, every step, which cost more than
some kernels themselves (the ConvNet's step in bench/bench_haptic_cnn.py: 73 -> 55 ms with
reuse). ``scratch`` hands out a pooled array only when nothing else references it, so an array
held by a pending backward, a view or a tensor is never handed out twice. One thread per process
(the kernels parallelise inside numba; Hydra's launchers run jobs in processes).

Arrays of 2 MiB and more start on a 2 MiB boundary and ask the kernel for huge pages
(``MADV_HUGEPAGE``; honoured when transparent huge pages are ``always`` or ``madvise``): the
kernels step through time in rows ~4 kB apart, one page each with 4 kB pages, and the batch's
transpose into the layout took 28% less CPU time on huge pages (measured).
"""

from __future__ import annotations

import mmap
import sys

import numpy as np

POOL_BYTES = 512 * 2**20  # ours: a ConvNet training step, both batch sizes of an epoch
HUGE_PAGE = 2 * 2**20
_POOL: list[np.ndarray] = []


def _allocate(shape: tuple[int, ...]) -> np.ndarray:
    """An uninitialised float32 array, on huge pages from ``HUGE_PAGE`` bytes (see above)."""
    count = int(np.prod(shape))
    if 4 * count < HUGE_PAGE or not hasattr(mmap, "MADV_HUGEPAGE"):
        return np.empty(shape, np.float32)
    buffer = mmap.mmap(-1, 4 * count + HUGE_PAGE)  # anonymous, freed with the last view
    buffer.madvise(mmap.MADV_HUGEPAGE)
    offset = -np.frombuffer(buffer, np.uint8).ctypes.data % HUGE_PAGE
    # Built on the buffer directly: a view's ``base`` is then this array (numpy stops at the
    # first base that is not an array), so the pool's reference count sees every view.
    return np.ndarray(shape, np.float32, buffer=buffer, offset=offset)


def _free(i: int) -> bool:
    """Whether nothing but the pool references ``_POOL[i]`` (2: the pool and this argument)."""
    return sys.getrefcount(_POOL[i]) == 2


def scratch(*shape: int) -> np.ndarray:
    """A float32 array of ``shape`` with arbitrary contents, reused from the pool if one is free.

    Free arrays are dropped, oldest first, while a new one would take the pool past
    ``POOL_BYTES``; arrays in use are never dropped (the pool may then exceed it).
    """
    for i in range(len(_POOL)):
        if _POOL[i].shape == shape and _free(i):
            return _POOL[i]
    nbytes = 4 * int(np.prod(shape))
    i = 0
    while i < len(_POOL) and sum(a.nbytes for a in _POOL) + nbytes > POOL_BYTES:
        if _free(i):
            del _POOL[i]
        else:
            i += 1
    arr = _allocate(shape)
    _POOL.append(arr)
    return arr
