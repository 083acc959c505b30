"""Reusable float32 scratch arrays for the compiled CPU kernels of the haptic ConvNet and LSTM.

A training step at batch 1000 needs 100-150 MB of activations and gradients. Freshly allocated
memory is page-faulted and zeroed by the OS on its first touch, every step, which cost more than
some kernels themselves (the ConvNet's step in bench/bench_haptic_cnn.py: 73 -> 55 ms with
reuse). ``scratch`` hands out a view of a pooled buffer only when nothing else references the
buffer, so memory held by a pending backward, a view or a tensor is never handed out twice. A
buffer serves any shape that fits in it (the front of the buffer, contiguous), and new ones get
``HEADROOM`` to spare: the batch sizes of a job differ from adjective to adjective (each has its
own split), and exact shapes made every adjective fault in a new set of arrays. One thread per
process (the kernels parallelise inside numba; Hydra's launchers run jobs in processes).

Buffers of 2 MiB and more are private anonymous mappings that start on a 2 MiB boundary and ask
for transparent huge pages (``MADV_HUGEPAGE``; honoured when the kernel's setting is ``always``
or ``madvise``): the kernels step through time in rows ~4 kB apart, one page each with 4 kB
pages. (A shared mapping, ``mmap``'s default, lives in shmem, where huge pages are off by default.)
"""

from __future__ import annotations

import mmap
import sys

import numpy as np

POOL_BYTES = 512 * 2**20  # ours: a ConvNet training step, both batch sizes of an epoch
HUGE_PAGE = 2 * 2**20
HEADROOM = 8  # ours: a new buffer holds 1/8 more than asked (the batch sizes of a job's splits)
_POOL: list[np.ndarray] = []  # flat float32 buffers, oldest first


def _allocate(count: int) -> np.ndarray:
    """An uninitialised flat float32 buffer, on huge pages from ``HUGE_PAGE`` bytes (see above)."""
    if 4 * count < HUGE_PAGE or not hasattr(mmap, "MADV_HUGEPAGE"):
        return np.empty(count, np.float32)
    buffer = mmap.mmap(
        -1, 4 * count + HUGE_PAGE, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS
    )  # freed with the last view
    buffer.madvise(mmap.MADV_HUGEPAGE)
    offset = -np.frombuffer(buffer, np.uint8).ctypes.data % HUGE_PAGE
    # Built on the mapping directly: a view's ``base`` is then this array (numpy stops at the
    # first base that is not an array), so the pool's reference count sees every view.
    return np.ndarray(count, np.float32, buffer=buffer, offset=offset)


def _free(i: int) -> bool:
    """Whether nothing but the pool references ``_POOL[i]`` (2: the pool and this argument)."""
    return sys.getrefcount(_POOL[i]) == 2


def scratch(*shape: int) -> np.ndarray:
    """A C-contiguous float32 array of ``shape`` with arbitrary contents: the front of the
    smallest free pooled buffer it fits in, else of a new buffer.

    Free buffers are dropped, oldest first, while a new one would take the pool past
    ``POOL_BYTES``; buffers in use are never dropped (the pool may then exceed it).
    """
    count = int(np.prod(shape))
    fits = [i for i in range(len(_POOL)) if _POOL[i].size >= count and _free(i)]
    if fits:
        return _POOL[min(fits, key=lambda i: _POOL[i].size)][:count].reshape(shape)
    capacity = count + count // HEADROOM
    i = 0
    while i < len(_POOL) and sum(a.nbytes for a in _POOL) + 4 * capacity > POOL_BYTES:
        if _free(i):
            del _POOL[i]
        else:
            i += 1
    _POOL.append(_allocate(capacity))
    return _POOL[-1][:count].reshape(shape)
