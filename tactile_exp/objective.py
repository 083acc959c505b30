"""What a job returns to Hydra: a metric of the held-out validation objects only.

An optimising sweeper (``search=...``) selects on whatever the job returns, so the return value is
computed from the per-adjective validation metrics alone (``validation.fraction`` held-out
training objects, never a test object): the signature admits no test score. The test metrics
stay in MLflow. Every registered metric (``tactile_exp.metrics``) gives two objectives,
``mean_val_<key>`` and ``min_val_<key>`` (``mean_val_auc``, ``min_val_f1``, ...); a job computes
the validation metrics it lists in ``metrics``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping

import numpy as np

from tactile_exp.metrics import METRICS
from tactile_exp.registry import Registry

Validation = Mapping[str, Mapping[str, float]]  # adjective -> metric key -> validation value
OBJECTIVES: Registry[float] = Registry("objective")
# The test objects' names of every registered metric (``mean_<key>``, ``<key>``): named in the
# error when a config asks for one as its objective.
TEST_METRICS = tuple(
    n for k in (METRICS.build(m).key for m in METRICS.names()) for n in (f"mean_{k}", k)
)
# How an objective reduces the adjectives' values: the mean, or the worst adjective's (a
# configuration good for every adjective).
REDUCERS: dict[str, Callable[[list[float]], float]] = {"mean": np.mean, "min": min}


def reduced(reduce: str, key: str, validation: Validation) -> float:
    """The adjectives' validation values of one metric, reduced; NaN when none has one
    (validation.fraction=0, or no held-out object of a class)."""
    values = [v[key] for v in validation.values() if key in v]
    return float(REDUCERS[reduce](values)) if values else np.nan


for _name in METRICS.names():
    for _reduce in REDUCERS:
        _key = METRICS.build(_name).key
        OBJECTIVES.register(f"{_reduce}_val_{_key}")(functools.partial(reduced, _reduce, _key))


def metric_key(name: str) -> str:
    """The metric key objective ``name`` reads (``mean_val_f1`` -> ``f1``)."""
    return name.partition("_val_")[2]


def value(name: str, validation: Validation) -> float:
    """Objective ``name`` of a job's per-adjective validation metrics (NaN when there are none)."""
    return OBJECTIVES[name](validation)
