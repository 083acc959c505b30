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

Buffers from ``MAPPED_FROM`` bytes are private anonymous mappings that start on a 2 MiB boundary
and ask for transparent huge pages (``MADV_HUGEPAGE``; honoured when the kernel's setting is
``always`` or ``madvise``; ``mapped``): the kernels step through time in rows ~4 kB apart, one page
each with 4 kB pages, and a virtual machine's TLB misses cost two page walks. (A shared mapping,
``mmap``'s default, lives in shmem, where huge pages are off by default.) The training set goes
there too (``on_huge_pages``), the ConvNet's per-thread tiles (``convnet_tiles``) and the LSTM's
per-thread chunks (``lstm_kernels``, which keep theirs from call to call). On huge pages the
ConvNet's training step at batch 1000 takes ~0.8x the time, the LSTM's ~0.85-0.9x; ``MAPPED_FROM``
is 256 kB, not 2 MB, because the LSTM's buffers are all under 2 MB (its step a further ~0.94x).
"""

from __future__ import annotations

import mmap
import sys
from collections.abc import Sequence

import numpy as np

POOL_BYTES = 512 * 2**20  # ours: a ConvNet training step, both batch sizes of an epoch
HUGE_PAGE = 2 * 2**20
MAPPED_FROM = HUGE_PAGE // 8  # ours: smaller buffers come from malloc (a mapping takes 2 MB)
HEADROOM = 8  # ours: a new buffer holds 1/8 more than asked (the batch sizes of a job's splits)
_POOL: list[np.ndarray] = []  # flat float32 buffers, oldest first


def mapped(count: int) -> np.ndarray:
    """An uninitialised flat float32 array of ``count`` at the start of a private mapping of its
    own that asks for huge pages (see above; ``np.empty`` where the system has no such hint)."""
    if not hasattr(mmap, "MADV_HUGEPAGE"):
        return np.empty(count, np.float32)
    pages = -(-4 * count // HUGE_PAGE) * HUGE_PAGE  # whole pages: a part page is never huge
    buffer = mmap.mmap(
        -1, pages + HUGE_PAGE, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS
    )  # freed with the last view; the extra page to start the array on a boundary
    buffer.madvise(mmap.MADV_HUGEPAGE)
    offset = -np.frombuffer(buffer, np.uint8).ctypes.data % HUGE_PAGE
    # Built on the mapping directly: a view's ``base`` is then this array (numpy stops at the
    # first base that is not an array), so the pool's reference count sees every view.
    return np.ndarray(count, np.float32, buffer=buffer, offset=offset)


def carved(shapes: Sequence[tuple[int, ...]]) -> list[np.ndarray]:
    """Zeroed C-contiguous float32 arrays of ``shapes``, back to back in one mapping on huge
    pages (``mapped``): a kernel's per-thread arrays, kept from call to call, that it reads and
    writes together."""
    sizes = [int(np.prod(shape)) for shape in shapes]
    block = mapped(sum(sizes))
    block[:] = 0
    parts = np.split(block, np.cumsum(sizes)[:-1])
    return [part.reshape(shape) for part, shape in zip(parts, shapes, strict=True)]


def empty_on_huge_pages(*shape: int) -> np.ndarray:
    """An uninitialised C-contiguous float32 array of ``shape``, on huge pages (``mapped``) from
    ``HUGE_PAGE`` bytes: what a modality writes its instances into, so that a fit trains on them
    in place (``on_huge_pages``) instead of holding a second copy of its training set."""
    count = int(np.prod(shape))
    return (mapped(count) if 4 * count >= HUGE_PAGE else np.empty(count, np.float32)).reshape(shape)


def _in_a_mapping(X: np.ndarray) -> bool:
    """Whether ``X`` is a C-contiguous float32 view of an array built on a mapping (``mapped``'s;
    a file's ``np.memmap`` too, which only costs the huge pages)."""
    root = X
    while isinstance(root.base, np.ndarray):
        root = root.base
    return X.dtype == np.float32 and X.flags.c_contiguous and isinstance(root.base, mmap.mmap)


def on_huge_pages(X: np.ndarray) -> np.ndarray:
    """``X`` as a C-contiguous float32 array on huge pages (``mapped``) from ``HUGE_PAGE`` bytes:
    ``X`` itself when it lies in a mapping already (``empty_on_huge_pages``), else a copy; below
    ``HUGE_PAGE`` bytes as ``np.ascontiguousarray``: a training set whose batches the kernels read
    row by row at random. On 4 kB pages each instance's rows (19 kB at the paper's sizes) cost
    the core TLB misses as well as cache misses."""
    if 4 * X.size < HUGE_PAGE:
        return np.ascontiguousarray(X, dtype=np.float32)
    if _in_a_mapping(X):
        return X
    copy = mapped(X.size).reshape(X.shape)
    copy[...] = X
    return copy


def _allocate(count: int) -> np.ndarray:
    """An uninitialised flat float32 buffer, on huge pages from ``MAPPED_FROM`` bytes (above)."""
    if 4 * count < MAPPED_FROM:
        return np.empty(count, np.float32)
    return mapped(count)


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
