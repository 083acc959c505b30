"""``python -m tactile_exp``: the Hydra entry point (Hydra stays here, at the edge)."""

from __future__ import annotations

import logging
import os
import signal
import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig

from tactile_exp.runtime import termination

log = logging.getLogger("tactile_exp")


@hydra.main(version_base="1.3", config_path="../conf", config_name="config")
def main(cfg: DictConfig) -> float:
    signal.signal(signal.SIGTERM, termination.handle)
    from tactile_exp.app.sweep import SweepJob
    from tactile_exp.config import settings_from_config
    from tactile_exp.errors import reported
    from tactile_exp.experiment import run
    from tactile_exp.objective import value

    hc = HydraConfig.get()
    choices = {k: str(v) for k, v in hc.runtime.choices.items() if not k.startswith("hydra")}
    # The sweep's folder as configured (multirun/<date>/<time>): its time alone repeats daily.
    sweep_id = str(Path(hc.sweep.dir)) if hc.mode == RunMode.MULTIRUN else ""
    job = SweepJob.of(hc)  # None for a single run
    if job is not None and job.skipped():  # listed invalid before the sweep started
        return float("nan")
    try:
        # A single run's bad value is one error line and exit 2; a sweep job's failure is
        # recorded and kept from Hydra, so that the jobs after it run (tactile_exp.sweep).
        with reported() if job is None else job.recorded():
            settings = settings_from_config(
                cfg, choices, sweep_id, Path(hc.runtime.output_dir), tuple(hc.overrides.task)
            )
            # The configured validation objective, never the test AUC: any sweeper may select on it.
            return value(settings.objective, run(settings).validation)
    except termination.Terminated:
        if hc.mode != RunMode.MULTIRUN:
            raise
        # A sweep worker (joblib/loky) would survive the exception and take the next job: its
        # runs are marked FAILED by now, so leave at once; the launcher waits for this exit.
        logging.shutdown()
        os._exit(128 + signal.SIGTERM)
    return float("nan")  # a sweep job that FAILED


def _refuse_cfg_with_multirun(argv: list[str]) -> None:
    """Hydra answers ``-m ... --cfg job`` with a traceback; say what to run instead."""
    if {"-m", "--multirun"} & set(argv) and any(a in ("-c", "--cfg") for a in argv):
        print(
            "error: --cfg prints one job's config and Hydra refuses it with -m; to compose and "
            "check every job of a sweep without running any, add sweep.on_invalid=check",
            file=sys.stderr,
        )
        sys.exit(2)


if __name__ == "__main__":
    _refuse_cfg_with_multirun(sys.argv[1:])
    main()
