"""give_back: freed heap pages leave the process."""

import subprocess
import sys

from tactile_exp.runtime.memory import _malloc_trim

# In a fresh interpreter, whose heap holds nothing else: 2,000 arrays of 100 kB (under glibc's
# mmap threshold, so on the heap) with a small one kept after each, which holds the heap's top:
# freeing the large ones returns little until give_back.
SCRIPT = """
from pathlib import Path
import numpy as np
from tactile_exp.runtime.memory import give_back

def resident_mib():
    return int(Path("/proc/self/statm").read_text().split()[1]) * 4096 / 2**20

kept, freed = [], []
for _ in range(2000):
    freed.append(np.ones(100_000 // 8))
    kept.append(np.ones(4))
held = resident_mib()
del freed
before = resident_mib()
give_back()
print(held, before, resident_mib())
"""


def test_freed_arrays_on_the_heap_are_handed_back():
    assert _malloc_trim() is not None  # Linux with glibc, as CI
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    held, before, after = map(float, out.stdout.split())
    assert held - before < 100  # free() alone returned less than half of the 190 MiB
    assert before - after > 150  # give_back returned most of it
