"""Freed memory handed back to the system.

glibc's allocator keeps the heap pages that freed arrays and objects leave, for later
allocations: after a job reads every trial of its data file (3.1 GB of int64 arrays for the
default file, read and freed one trial at a time) about 200 MB of freed heap stayed in the
process, and each adjective's pipeline left more. ``give_back`` returns those pages
(``malloc_trim``) where a phase has freed what it will not reuse; it moved the README job's
peak resident memory from 1.62 to 1.52 GB (bench/bench_readme_job.py). Elsewhere than glibc it
does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools


@functools.cache
def _malloc_trim():
    name = ctypes.util.find_library("c")
    trim = getattr(ctypes.CDLL(name), "malloc_trim", None) if name else None
    return trim


def give_back() -> None:
    """Return the freed heap pages of this process to the system (glibc's ``malloc_trim``)."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)
