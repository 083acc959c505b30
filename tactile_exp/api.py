"""Fit and score a Table I row from Python (a notebook, a script), with or without MLflow.

    from tactile_exp import api
    settings = api.compose("experiment=table1_i_haptic_cnn_1trial", "adjectives=[hard,soft]")
    results = api.fit(settings)               # no tracking store: models kept in memory
    results["hard"].metrics["auc"], results["hard"].pipeline
    job = api.run(settings)                   # the same job as ``python -m tactile_exp``, in MLflow

``compose`` reads ``conf/`` as the command line does (same overrides); ``fit`` loops
``core.fit_adjective`` over the job's adjectives with a model cache (default ``MemoryCache``:
a second row that shares a model, rows H, I and J or M's ConvNet, finds it there).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from tactile_exp import core
from tactile_exp.cache import MemoryCache, ModelCache
from tactile_exp.config import Settings, settings_from_config

log = logging.getLogger(__name__)

CONF = Path(__file__).resolve().parents[1] / "conf"


def compose(*overrides: str) -> Settings:
    """The checked settings of ``python -m tactile_exp <overrides>`` (Hydra's compose API)."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = hydra_compose("config", overrides=list(overrides))
    return settings_from_config(cfg, overrides=tuple(overrides))


def fit(
    settings: Settings, *, cache: ModelCache | None = None, progress: core.Progress | None = None
) -> dict[str, core.AdjectiveResult]:
    """Every adjective of the job fitted and scored, in order, recording nothing.

    ``cache``: where trained models are found and kept (default: a new ``MemoryCache``);
    ``progress(name)``: an epoch callback per model trained (default: none)."""
    cache = MemoryCache() if cache is None else cache
    dataset, _, splits = core.load(settings)
    results = {}
    for i, (adjective, split) in enumerate(splits.items(), start=1):
        results[adjective] = core.fit_adjective(settings, dataset, split, cache, progress=progress)
        log.info("[%d/%d] %s %s", i, len(splits), adjective, results[adjective].metrics)
    return results


def run(settings: Settings) -> Any:
    """The job recorded in its MLflow store, as ``python -m tactile_exp`` runs it
    (``experiment.JobResult``; imported here so that ``fit`` never loads the tracking layer)."""
    from tactile_exp import experiment

    return experiment.run(settings)
