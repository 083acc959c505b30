"""``python -m tactile_exp``: the Hydra entry point (Hydra stays here, at the edge)."""

from __future__ import annotations

import logging
import os
import signal
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig

log = logging.getLogger("tactile_exp")


class Terminated(SystemExit):
    """SIGTERM, unwound like an error so MLflow runs end FAILED, not RUNNING."""


def _terminate(signum: int, frame: object) -> None:
    # SLURM and `kill` send SIGTERM (and a terminated sweep forwards it to its workers).
    raise Terminated(f"terminated by signal {signum}")


@hydra.main(version_base="1.3", config_path="../conf", config_name="config")
def main(cfg: DictConfig) -> float:
    signal.signal(signal.SIGTERM, _terminate)
    from tactile_exp.config import settings_from_config
    from tactile_exp.errors import reported
    from tactile_exp.experiment import run

    hc = HydraConfig.get()
    choices = {k: str(v) for k, v in hc.runtime.choices.items() if not k.startswith("hydra")}
    sweep_id = Path(hc.sweep.dir).name if hc.mode == RunMode.MULTIRUN else ""
    try:
        with reported():
            settings = settings_from_config(cfg, choices, sweep_id, Path(hc.runtime.output_dir))
            return run(settings).mean_auc
    except Terminated:
        if hc.mode != RunMode.MULTIRUN:
            raise
        # A sweep worker (joblib/loky) would survive the exception and take the next job: its
        # runs are marked FAILED by now, so leave at once; the launcher waits for this exit.
        logging.shutdown()
        os._exit(128 + signal.SIGTERM)


if __name__ == "__main__":
    main()
