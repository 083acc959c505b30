"""The README's job (``experiment=quick_table1_i``) from fresh caches, phase by phase.

Target: under 45 s from a fresh clone after install, data generation included. Each phase runs
in a child process, in order, with empty cache folders (``$TACTILE_EXP_CACHE``, numba's cache
under it) and MLflow store, as on a fresh clone:

1. fresh clone: the job from empty caches. It starts compiling its kernels in a background
   process (``compile_ahead``), then generates the embedded default data set (one worker per
   core), creates its MLflow store and preprocesses the signals beside that compile, then
   trains; its log's ``phases:`` line says what each phase took;
2. job, again: the same job into a fresh MLflow store (data, kernels and preprocessed signals
   cached);
3. generation alone: the default data set into another empty cache folder
   (``synthetic.default_file``), what phase 1 generates;
4. compile alone: the kernels the job runs (its model's ``kernels()``, each module's
   ``warm_up``) into another empty numba cache, what phase 1 compiles.

Wall and CPU seconds (children's user + system: both cores busy shows as CPU > wall; the
generation's workers, children of a fork server, are not counted; the job's compile process is,
the job waits for it), the peak resident memory of the phase's process (``wait4``'s
``ru_maxrss``: the largest of it and the processes it waited for, the job's compile process
among them) and the load average after each phase are printed; other work on the machine slows
every phase, so read them with the load.

With ``--before REV`` the phases run for the package at git revision ``REV`` too (exported under
the cache folder with its ``conf/``, as bench_roofline does), each from its own empty caches,
before and now alternating phase by phase: a before/after in one run.

Run: ``.venv/bin/python bench/bench_readme_job.py [--before REV]
[--json bench/results/bench_readme_job.json]``
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from revision import package_at

TARGET_S = 45.0
GENERATE = (
    "from tactile_exp.data.phac2 import default_cache_dir\n"
    "from tactile_exp.data.synthetic import default_file\n"
    "default_file(default_cache_dir())\n"
)
COMPILE = (  # the job's model's kernel modules (row I: the haptic ConvNet), as its compile ahead
    "from tactile_exp.models import MODELS\n"
    "for module in MODELS.build('haptic_cnn').kernels():\n"
    "    __import__(module, fromlist=['warm_up']).warm_up()\n"
)
JOB = ["-m", "tactile_exp", "experiment=quick_table1_i"]
ROOT = Path(__file__).resolve().parent.parent


def phase(name: str, args: list[str], env: dict[str, str], cwd: Path) -> tuple[float, ...]:
    """Wall and CPU seconds and peak resident MB of ``python args`` in a child; its output goes
    to ``cwd/name.log``."""
    start = time.perf_counter()
    with open(cwd / f"{name}.log", "w") as log:
        child = subprocess.Popen([sys.executable, *args], env=env, cwd=cwd, stdout=log, stderr=log)
        _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode:
        raise subprocess.CalledProcessError(child.returncode, args)
    wall, cpu = time.perf_counter() - start, usage.ru_utime + usage.ru_stime
    peak = usage.ru_maxrss / 1024  # kB on Linux
    print(
        f"{name:36s} {wall:7.1f} s wall {cpu:7.1f} s CPU {peak:7.0f} MB peak   "
        f"load {os.getloadavg()[0]:.1f}"
    )
    return wall, cpu, peak


def package(rev: str | None) -> Path:
    """The folder holding ``tactile_exp`` and ``conf/`` at ``rev`` (None: this checkout)."""
    if rev is None:
        return ROOT
    return package_at(rev)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default=None, help="also run the package at this git rev")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args()
    tags = {"": None} if args.before is None else {"": None, " (before)": args.before}
    figures: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="bench-readme-job-") as tmp:
        envs, folders = {}, {}
        for tag, rev in tags.items():
            folder = folders[tag] = Path(tmp) / ("before" if tag else "now")
            folder.mkdir()
            env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
            env["TACTILE_EXP_CACHE"] = str(folder / "cache")
            env["PYTHONPATH"] = str(package(rev))
            env["MLFLOW_TRACKING_URI"] = f"sqlite:///{folder / 'mlflow.db'}"
            envs[tag] = env
        steps = [
            ("fresh clone", JOB, "mlflow.db"),
            ("job, again", JOB, "mlflow-again.db"),
            ("generation alone", ["-c", GENERATE], "cache-alone"),
            ("compile alone", ["-c", COMPILE], "numba-alone"),
        ]
        for name, argv, store in steps:
            for tag in tags:
                folder, env = folders[tag], dict(envs[tag])
                if name in ("fresh clone", "job, again"):
                    env["MLFLOW_TRACKING_URI"] = f"sqlite:///{folder / store}"
                    argv = [*JOB, f"hydra.run.dir={folder / 'outputs'}"]
                elif name == "generation alone":
                    env["TACTILE_EXP_CACHE"] = str(folder / store)
                else:
                    env["NUMBA_CACHE_DIR"] = str(folder / store)
                wall, cpu, peak = phase(name + tag, argv, env, folder)
                figures[f"{name}, s{tag}"] = wall
                if name != "generation alone":  # its workers' time is not counted (docstring)
                    figures[f"{name}, CPU s{tag}"] = cpu
                figures[f"{name}, peak resident MB{tag}"] = peak
        for tag in tags:
            job_log = (folders[tag] / f"fresh clone{tag}.log").read_text()
            phases = [line for line in job_log.splitlines() if "phases:" in line]
            if phases:
                print(f"the fresh clone's log{tag}: {phases[-1].split(' - ', 1)[-1]}")
    for tag in tags:
        fresh = figures[f"fresh clone, s{tag}"]
        print(f"fresh clone{tag}: {fresh:.1f} s (target {TARGET_S:.0f} s)")
    figures = {k: round(v, 1) for k, v in figures.items()}
    if args.json:
        sys.path.insert(0, str(Path(__file__).parent))
        from record import write

        notes = (
            "phases in order from empty caches, each in a child process; CPU s: the children's "
            "user + system time; peak resident MB: the phase's process or the largest it "
            "waited for (wait4's ru_maxrss); "
            "load average at the end in machine"
        )
        if args.before is not None:
            notes += f"; (before) = the package at --before {args.before}, phases alternating"
        write(args.json, "bench_readme_job", figures, notes)


if __name__ == "__main__":
    main()
