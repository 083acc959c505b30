"""give_back: freed heap pages leave the process."""

from pathlib import Path

import numpy as np

from tactile_exp.runtime.memory import _malloc_trim, give_back


def _resident_mb() -> float:
    return int(Path("/proc/self/statm").read_text().split()[1]) * 4096 / 2**20


def test_freed_arrays_on_the_heap_are_handed_back():
    """Arrays under glibc's mmap threshold come from the heap; small ones kept between them hold
    its top, so freeing the large ones returns little until ``give_back``."""
    assert _malloc_trim() is not None  # Linux with glibc, as CI
    kept, freed = [], []
    for _ in range(2000):
        freed.append(np.ones(100_000 // 8))  # 100 kB each, 190 MiB in all
        kept.append(np.ones(4))
    del freed
    before = _resident_mb()
    give_back()
    after = _resident_mb()
    assert before - after > 80  # give_back returned at least ~half of the 190 MiB
    assert len(kept) == 2000
