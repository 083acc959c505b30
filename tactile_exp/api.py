"""Fit and score a Table I row from Python (a notebook, a script), with or without MLflow.

    from tactile_exp import api
    settings = api.compose("experiment=table1_i_haptic_cnn_1trial", "adjectives=[hard,soft]")
    results = api.fit(settings)               # no tracking store: models kept in memory
    results["hard"].metrics["auc"], results["hard"].pipeline
    job = api.run(settings)                   # the same job as ``python -m tactile_exp``, in MLflow

``compose`` reads ``conf/`` as the command line does (same overrides); ``fit`` loops
``core.fit_adjective`` over the job's adjectives with a model cache (default ``MemoryCache``:
a second row that shares a model, rows H, I and J or M's ConvNet, finds it there) and hands
each result to a ``Recorder`` when given one: another tracker than MLflow (a file, a database)
is a class with its two methods.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol

from tactile_exp import core
from tactile_exp.cache import MemoryCache, ModelCache
from tactile_exp.config import Settings, settings_from_config

log = logging.getLogger(__name__)

CONF = Path(__file__).resolve().parents[1] / "conf"


class Recorder(Protocol):
    """What ``fit`` tells a tracker: each adjective's result as it is scored, then the job's."""

    def adjective(self, settings: Settings, result: core.AdjectiveResult) -> None: ...

    def job(self, settings: Settings, results: Mapping[str, core.AdjectiveResult]) -> None: ...


def compose(*overrides: str) -> Settings:
    """The checked settings of ``python -m tactile_exp <overrides>`` (Hydra's compose API)."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = hydra_compose("config", overrides=list(overrides))
    return settings_from_config(cfg, overrides=tuple(overrides))


def fit(
    settings: Settings,
    *,
    cache: ModelCache | None = None,
    progress: core.Progress | None = None,
    recorder: Recorder | None = None,
) -> dict[str, core.AdjectiveResult]:
    """Every adjective of the job fitted and scored, in order.

    ``cache``: where trained models are found and kept (default: a new ``MemoryCache``);
    ``progress(name)``: an epoch callback per model trained (default: none); ``recorder``: what
    records the results (default: nothing is recorded)."""
    cache = MemoryCache() if cache is None else cache
    if settings.split_note:  # what split=declared chose, as a job says it
        log.info("split: %s", settings.split_note)
    dataset, _, splits = core.load(settings)
    results = {}
    for i, (adjective, split) in enumerate(splits.items(), start=1):
        results[adjective] = core.fit_adjective(settings, dataset, split, cache, progress=progress)
        log.info("[%d/%d] %s %s", i, len(splits), adjective, results[adjective].metrics)
        if recorder is not None:
            recorder.adjective(settings, results[adjective])
    if recorder is not None:
        recorder.job(settings, results)
    return results


def run(settings: Settings) -> Any:
    """The job recorded in its MLflow store, as ``python -m tactile_exp`` runs it
    (``experiment.JobResult``; imported here so that ``fit`` never loads the tracking layer)."""
    from tactile_exp import experiment

    return experiment.run(settings)
