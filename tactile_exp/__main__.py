"""``python -m tactile_exp``: the Hydra entry point (Hydra stays here, at the edge)."""

from __future__ import annotations

import logging
import signal
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig

log = logging.getLogger("tactile_exp")


def _terminate(signum: int, frame: object) -> None:
    # SLURM and `kill` send SIGTERM: unwind like an error so MLflow runs end FAILED, not RUNNING.
    raise SystemExit(f"terminated by signal {signum}")


@hydra.main(version_base="1.3", config_path="../conf", config_name="config")
def main(cfg: DictConfig) -> float:
    signal.signal(signal.SIGTERM, _terminate)
    from tactile_exp.config import settings_from_config
    from tactile_exp.experiment import run

    hc = HydraConfig.get()
    choices = {k: str(v) for k, v in hc.runtime.choices.items() if not k.startswith("hydra")}
    sweep_id = Path(hc.sweep.dir).name if hc.mode == RunMode.MULTIRUN else ""
    settings = settings_from_config(
        cfg, choices, sweep_id, Path(hc.runtime.output_dir), tuple(hc.overrides.task)
    )
    return run(settings).mean_auc


if __name__ == "__main__":
    main()
