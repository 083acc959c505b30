"""What a job returns to Hydra (issue 28): a metric of the held-out validation objects only.

An optimising sweeper (``search=...``) selects on whatever the job returns, so the return value is
computed from the per-adjective validation AUCs alone (``validation.fraction`` held-out training
objects, never a test object): the signature admits no test score. The test AUC stays in MLflow.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from tactile_exp.registry import Registry

OBJECTIVES: Registry[float] = Registry("objective")
# Metrics of the test objects: named in the error when a config asks for one.
TEST_METRICS = ("mean_auc", "auc")


@OBJECTIVES.register("mean_val_auc")
def mean_val_auc(val_aucs: Mapping[str, float]) -> float:
    """Mean validation AUC over the adjectives whose held-out objects hold both classes."""
    return float(np.mean(list(val_aucs.values()))) if val_aucs else float("nan")


@OBJECTIVES.register("min_val_auc")
def min_val_auc(val_aucs: Mapping[str, float]) -> float:
    """The worst adjective's validation AUC: a configuration good for every adjective."""
    return float(min(val_aucs.values())) if val_aucs else float("nan")


def value(name: str, val_aucs: Mapping[str, float]) -> float:
    """Objective ``name`` of a job's per-adjective validation AUCs (NaN when there are none)."""
    return OBJECTIVES[name](val_aucs)
