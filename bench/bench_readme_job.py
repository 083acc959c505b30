"""The README's job (``experiment=quick_table1_i``) from fresh caches, phase by phase.

Target: under 90 s from a fresh clone after install, data generation included. Each phase runs
in a child process, in order, with empty cache folders (``$TACTILE_EXP_CACHE``, numba's cache
under it) and MLflow store, as on a fresh clone:

1. generation: the embedded default synthetic data set alone (``synthetic.default_file``);
2. job, first run: the job with the data ready and numba's cache empty: it compiles its kernels
   in a background process while it preprocesses the signals (cached after);
3. job, again: the same job into a fresh MLflow store (kernels and preprocessed signals cached);
4. compile alone: the kernels the job runs (each module's ``warm_up``) into another empty numba
   cache, what phase 2 overlaps with its preprocessing.

Phases 1 + 2 are what a fresh clone pays. Wall and CPU seconds (children's user + system:
both cores busy shows as CPU > wall; the generation's workers, children of a fork server, are
not counted; the job's compile process is, the job waits for it) and the load average after each
phase are printed; other work on the machine slows every phase, so read them with the load.

Run: ``.venv/bin/python bench/bench_readme_job.py [--json bench/results/bench_readme_job.json]``
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = 90.0
GENERATE = (
    "from tactile_exp.data.phac2 import default_cache_dir\n"
    "from tactile_exp.data.synthetic import default_file\n"
    "default_file(default_cache_dir())\n"
)
COMPILE = (
    "from tactile_exp.models import convnet_tiles, grouped_conv_numba, linear_sgd\n"
    "linear_sgd.warm_up()\n"
    "grouped_conv_numba.warm_up()\n"
    "convnet_tiles.warm_up()\n"
)
JOB = ["-m", "tactile_exp", "experiment=quick_table1_i"]


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def phase(name: str, args: list[str], env: dict[str, str], cwd: Path) -> tuple[float, float]:
    """Wall and CPU seconds of ``python args`` in a child; its output goes to ``cwd/name.log``."""
    start, start_cpu = time.perf_counter(), _children_cpu()
    with open(cwd / f"{name}.log", "w") as log:
        subprocess.run(
            [sys.executable, *args], env=env, cwd=cwd, stdout=log, stderr=log, check=True
        )
    wall, cpu = time.perf_counter() - start, _children_cpu() - start_cpu
    print(f"{name:28s} {wall:7.1f} s wall {cpu:7.1f} s CPU   load {os.getloadavg()[0]:.1f}")
    return wall, cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args()
    root = Path(__file__).resolve().parent.parent
    figures: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="bench-readme-job-") as tmp:
        folder = Path(tmp)
        env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
        env["TACTILE_EXP_CACHE"] = str(folder / "cache")
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(root), env.get("PYTHONPATH")]))
        env["MLFLOW_TRACKING_URI"] = f"sqlite:///{folder / 'mlflow.db'}"
        outputs = f"hydra.run.dir={folder / 'outputs'}"
        phases = {
            "generation": ["-c", GENERATE],
            "job, first run": [*JOB, outputs],
        }
        for name, argv in phases.items():
            figures[f"{name}, s"], figures[f"{name}, CPU s"] = phase(name, argv, env, folder)
        del figures["generation, CPU s"]  # its workers' time is not counted (docstring)
        env["MLFLOW_TRACKING_URI"] = f"sqlite:///{folder / 'mlflow-again.db'}"
        figures["job, again, s"], figures["job, again, CPU s"] = phase(
            "job, again", [*JOB, outputs], env, folder
        )
        env["NUMBA_CACHE_DIR"] = str(folder / "numba-alone")
        figures["compile alone, s"], figures["compile alone, CPU s"] = phase(
            "compile alone", ["-c", COMPILE], env, folder
        )
    fresh = sum(figures[f"{name}, s"] for name in phases)
    figures["fresh clone (generation + first run), s"] = fresh
    figures = {k: round(v, 1) for k, v in figures.items()}
    print(f"fresh clone: {fresh:.1f} s (target {TARGET_S:.0f} s)")
    if args.json:
        sys.path.insert(0, str(Path(__file__).parent))
        from record import write

        notes = (
            "phases in order from empty caches, each in a child process; CPU s: the children's "
            "user + system time; load average at the end in machine"
        )
        write(args.json, "bench_readme_job", figures, notes)


if __name__ == "__main__":
    main()
