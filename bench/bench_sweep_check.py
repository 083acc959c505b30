"""Bench: what checking every job's config costs a sweep before its first job.

Composes the multirun config of ``python -m tactile_exp -m <overrides>`` (default: the Table I
grid over three seeds, 45 jobs) and times ``tactile_exp.app.sweep.check_jobs`` on it, then the
same jobs step by step: composing each job's config, ``settings_from_config`` (values, components,
models built once) and ``experiment.open_data`` (the data file, ``combine``, every adjective's
split). Nothing is trained or tracked. Prints the seconds of each, in total and per job.

    .venv/bin/python bench/bench_sweep_check.py
    .venv/bin/python bench/bench_sweep_check.py model=haptic_cnn,linear modality=visual,haptic
"""

from __future__ import annotations

import contextlib
import sys
import tempfile
import time
import warnings
from pathlib import Path

from hydra import initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.types import RunMode

from tactile_exp.app import sweep
from tactile_exp.config import settings_from_config
from tactile_exp.experiment import open_data

CONF = Path(__file__).resolve().parents[1] / "conf"


def main(overrides: list[str]) -> None:
    warnings.simplefilter("ignore")  # the splits' fallbacks, once per job
    with (
        tempfile.TemporaryDirectory() as folder,
        initialize_config_dir(config_dir=str(CONF), version_base="1.3"),
    ):
        hydra = GlobalHydra.instance().hydra
        assert hydra is not None
        config = hydra.compose_config(
            "config",
            [*overrides, f"hydra.sweep.dir={folder}"],
            run_mode=RunMode.MULTIRUN,
            with_log_configuration=False,
        )
        jobs = sweep.sweep_jobs(config)
        assert jobs is not None, "the basic sweeper's grid only"
        start = time.perf_counter()
        valid, invalid, _ = sweep.check_jobs(config, jobs)
        total = time.perf_counter() - start
        print(
            f"{' '.join(overrides)}: {len(jobs)} jobs, {len(valid)} valid, {len(invalid)} invalid"
        )
        print(f"check_jobs: {total:.1f} s ({total / len(jobs):.2f} s per job)")
        steps = {"compose": 0.0, "settings_from_config": 0.0, "open_data": 0.0}
        loader = GlobalHydra.instance().config_loader()
        for job in jobs:
            t0 = time.perf_counter()
            composed = loader.load_sweep_config(config, list(job))
            t1 = time.perf_counter()
            try:
                settings = settings_from_config(composed)
            except Exception:  # an invalid cell
                settings = None
            t2 = time.perf_counter()
            if settings is not None:
                with contextlib.suppress(Exception):  # an invalid cell
                    open_data(settings)
            t3 = time.perf_counter()
            steps["compose"] += t1 - t0
            steps["settings_from_config"] += t2 - t1
            steps["open_data"] += t3 - t2
        for step, seconds in steps.items():
            print(f"  {step}: {seconds:.1f} s ({seconds / len(jobs):.2f} s per job)")


if __name__ == "__main__":
    main(sys.argv[1:] or ["sweep=table1", "seed=0,1,2"])
