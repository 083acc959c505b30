"""Where the README job's resident memory goes: the libraries it imports, the haptic arrays, and
the freed heap that reading the data file leaves (handed back by ``runtime.memory.give_back``).

In one fresh process: the resident memory (``/proc/self/statm``) after importing each library
the job imports, in the job's order of weight (torch, numba, MLflow, scikit-learn and SciPy,
OpenCV and h5py, matplotlib, then the package's job modules); then after the first (uncached)
load of the default file's haptic arrays into a temporary cache, before and after
``give_back``, with the arrays' own size. The job's peak itself: bench/bench_readme_job.py.

Run: ``.venv/bin/python bench/bench_job_memory.py [--data-dir DIR] [--json OUT]``
(the default synthetic file is generated under DIR on first use, as the job does).
"""

from __future__ import annotations

import argparse
import importlib
import sys
import tempfile
from pathlib import Path

IMPORTS = {  # what the job imports, heaviest first; each line's figure is what it added
    "torch": ["torch"],
    "numba": ["numba"],
    "MLflow": ["mlflow"],
    "scikit-learn and SciPy": ["sklearn.linear_model", "scipy.signal"],
    "OpenCV and h5py": ["cv2", "h5py"],
    "matplotlib": ["matplotlib.pyplot"],
    "tactile_exp's job modules": ["tactile_exp.experiment", "tactile_exp.models.haptic_cnn"],
}


def resident_mb() -> float:
    pages = int(Path("/proc/self/statm").read_text().split()[1])
    return pages * 4096 / 2**20


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", type=Path, default=None)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    figures: dict[str, float] = {}
    start = last = resident_mb()
    print(f"{'interpreter':40s} {start:7.0f} MB")
    for name, modules in IMPORTS.items():
        for module in modules:
            importlib.import_module(module)
        now = resident_mb()
        figures[f"import {name}, MB"] = round(now - last, 1)
        print(f"{'+ ' + name:40s} {now - last:+7.0f} MB")
        last = now
    figures["after the imports, MB"] = round(last, 1)
    print(f"{'after the imports':40s} {last:7.0f} MB")

    from tactile_exp.data.phac2 import PHAC2, default_cache_dir
    from tactile_exp.data.synthetic import default_file
    from tactile_exp.preprocess.haptic import load_haptic_arrays
    from tactile_exp.runtime.memory import give_back

    dataset = PHAC2(default_file(args.data_dir or default_cache_dir()))
    before = resident_mb()
    with tempfile.TemporaryDirectory() as tmp:
        arrays = load_haptic_arrays(dataset, cache_dir=Path(tmp))
    held = sum(a.nbytes for a in vars(arrays).values() if hasattr(a, "nbytes")) / 2**20
    loaded = resident_mb()
    give_back()
    after = resident_mb()
    rows = {
        "haptic arrays held, MB": held,
        "resident growth of the first load, MB": loaded - before,
        "freed heap handed back by give_back, MB": loaded - after,
        "after the load and give_back, MB": after,
    }
    for name, value in rows.items():
        figures[name] = round(value, 1)
        print(f"{name:40s} {value:7.0f}")
    if args.json:
        sys.path.insert(0, str(Path(__file__).parent))
        from record import write

        notes = "one process; resident memory from /proc/self/statm after each step"
        write(args.json, "bench_job_memory", figures, notes)


if __name__ == "__main__":
    main()
