"""The Hydra sweep callback (``hydra.callbacks.prepare_sweep`` in ``conf/config.yaml``).

Kept apart from ``tracking.py`` so that the MLflow layer imports neither Hydra nor the engine.
"""

from __future__ import annotations

from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig


class PrepareSweep(Callback):
    """Before a multirun launches parallel jobs: create the MLflow experiment, the data and the
    shared preprocessed arrays once, so jobs neither race on the sqlite schema nor repeat work."""

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        from tactile_exp.config import settings_from_config
        from tactile_exp.experiment import load
        from tactile_exp.tracking import Tracker

        settings = settings_from_config(config)
        Tracker(settings.tracking.uri, settings.tracking.experiment)
        load(settings)
