"""Time and peak memory of haptic and visual preprocessing on the full default synthetic file.

Measures, in one run: every BioTac array of the file read through h5py's gzip filter and through
``deflate.read_array`` (ISA-L), CPU seconds, alternating twice; the haptic arrays' first
(uncached) and cached load, the engine's 24 x
(fit on an adjective's training trials + transform of its train and test trials), and the visual
arrays' first and cached load. Targets: cached preprocessing under 5 s, peak memory under 2 GB.

    PYTHONPATH=. .venv/bin/python bench/bench_preprocess.py [--data-dir DIR]

The synthetic data is generated once under DIR (default: the reader's cache dir) and timed
separately; the preprocessed caches go to a fresh temporary folder so "first run" is one.
"""

from __future__ import annotations

import argparse
import gc
import os
import resource
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from tactile_exp.data.deflate import read_array
from tactile_exp.data.layout import ADJECTIVES, Split
from tactile_exp.data.phac2 import PHAC2, default_cache_dir
from tactile_exp.data.splits import make_split
from tactile_exp.data.synthetic import default_file
from tactile_exp.preprocess.haptic import HapticArrays, HapticPreprocessor, load_haptic_arrays
from tactile_exp.preprocess.visual import load_visual_arrays

TARGET_CACHED_S = 5.0
TARGET_PEAK_GB = 2.0
PAGE = os.sysconf("SC_PAGE_SIZE")


def _rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * PAGE


def measure(label: str, fn: Callable[[], Any]) -> tuple[Any, float, float]:
    """Run ``fn``; print and return (result, seconds, peak RSS growth in GB).

    Memory: a thread samples the resident set every 5 ms (no allocation hooks, so timings stay
    honest); the figure is the peak during ``fn`` minus the resident set before it.
    """
    gc.collect()
    before = peak = _rss_bytes()
    done = threading.Event()

    def sample() -> None:
        nonlocal peak
        while not done.wait(0.005):
            peak = max(peak, _rss_bytes())

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    start = time.perf_counter()
    result = fn()
    seconds = time.perf_counter() - start
    done.set()
    sampler.join()
    grown_gb = (max(peak, _rss_bytes()) - before) / 2**30
    print(f"{label:<44s} {seconds:8.2f} s   peak +{grown_gb:6.3f} GB", flush=True)
    return result, seconds, grown_gb


def read_biotacs(dataset: PHAC2, read: Callable[[h5py.Dataset], np.ndarray]) -> float:
    """CPU seconds to read every BioTac array of ``dataset``'s file with ``read``."""
    with h5py.File(dataset.path, "r") as f:
        arrays: list[h5py.Dataset] = []
        f.visititems(lambda name, node: arrays.append(node) if "/biotacs/" in f"/{name}" else None)
        arrays = [a for a in arrays if isinstance(a, h5py.Dataset)]
        start = time.process_time()
        for array in arrays:
            read(array)
        return time.process_time() - start


def engine_loop(splits: list[Split], arrays: HapticArrays) -> int:
    """What one job does: fit and transform once per adjective."""
    instances = 0
    for split in splits:
        pre = HapticPreprocessor(arrays).fit(split.train)
        instances += len(pre.transform(split.train)) + len(pre.transform(split.test))
    return instances


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", type=Path, default=default_cache_dir())
    args = parser.parse_args()

    path, gen_s, _ = measure(
        "synthetic file (generated or found)", lambda: default_file(args.data_dir)
    )
    dataset = PHAC2(path)
    print(
        f"data: {path} ({len(dataset.trials)} trials, "
        f"{sum(map(len, dataset.photographs().values()))} photographs)"
    )
    for _ in range(2):  # alternating: the machine's speed moves
        h5py_s = read_biotacs(dataset, lambda ds: ds[()])
        isal_s = read_biotacs(dataset, read_array)
        print(
            f"BioTac arrays read, CPU s: h5py's gzip filter {h5py_s:.2f}, "
            f"ISA-L (deflate.read_array) {isal_s:.2f} ({h5py_s / isal_s:.1f}x)"
        )
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp)
        _, h_first, h_first_mem = measure(
            "haptic arrays, first run", lambda: load_haptic_arrays(dataset, cache_dir=cache)
        )
        arrays, h_cached, h_cached_mem = measure(
            "haptic arrays, cached", lambda: load_haptic_arrays(dataset, cache_dir=cache)
        )
        splits, _, _ = measure(
            "24 published splits (engine's job, not timed below)",
            lambda: [make_split(dataset, a) for a in ADJECTIVES],
        )
        n, loop_s, loop_mem = measure(
            "24 x (fit + transform train and test)", lambda: engine_loop(splits, arrays)
        )
        print(f"  {n} trials transformed, {loop_s / 24 * 1000:.0f} ms per adjective")
        _, v_first, v_first_mem = measure(
            "visual arrays, first run", lambda: load_visual_arrays(dataset, cache_dir=cache)
        )
        _, v_cached, v_cached_mem = measure(
            "visual arrays, cached", lambda: load_visual_arrays(dataset, cache_dir=cache)
        )
    maxrss_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    cached_total = h_cached + loop_s + v_cached
    peak = max(h_first_mem, h_cached_mem, loop_mem, v_first_mem, v_cached_mem)
    print()
    print(f"haptic cached / first run: {h_cached / h_first:.3f} ({h_first / h_cached:.0f}x faster)")
    print(f"visual cached / first run: {v_cached / v_first:.3f} ({v_first / v_cached:.0f}x faster)")
    print(
        f"cached preprocessing of a job (haptic load + 24 fits + visual load): "
        f"{cached_total:.2f} s (target < {TARGET_CACHED_S:.0f} s: "
        f"{'met' if cached_total < TARGET_CACHED_S else 'MISSED'})"
    )
    print(
        f"largest memory growth of one step {peak:.3f} GB, process max RSS {maxrss_gb:.3f} GB "
        f"(target < {TARGET_PEAK_GB:.0f} GB: {'met' if maxrss_gb < TARGET_PEAK_GB else 'MISSED'})"
    )
    print(f"(synthetic data step took {gen_s:.1f} s; not part of preprocessing)")


if __name__ == "__main__":
    main()
