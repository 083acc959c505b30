"""The objectives a search selects on: every registered metric, on the validation side only."""

from __future__ import annotations

import math

import pytest

from tactile_exp import objective
from tactile_exp.metrics import METRICS

VALIDATION = {"a": {"auc": 0.9, "f1": 0.2}, "b": {"auc": 0.6, "f1": 0.4}, "c": {"f1": 0.9}}


def test_every_registered_metric_gives_a_mean_and_a_min_objective() -> None:
    keys = [METRICS.build(n).key for n in METRICS.names()]
    want = {f"{r}_val_{k}" for r in ("mean", "min") for k in keys}
    assert set(objective.OBJECTIVES.names()) == want
    assert "mean_val_auc" in want and "min_val_f1" in want
    assert not set(objective.TEST_METRICS) & want  # no objective reads a test metric


def test_objectives_reduce_the_adjectives_that_have_the_metric() -> None:
    assert objective.value("mean_val_auc", VALIDATION) == pytest.approx(0.75)
    assert objective.value("min_val_auc", VALIDATION) == pytest.approx(0.6)
    assert objective.value("mean_val_f1", VALIDATION) == pytest.approx(0.5)
    assert objective.value("min_val_f1", VALIDATION) == pytest.approx(0.2)
    assert isinstance(objective.value("min_val_f1", VALIDATION), float)
    assert math.isnan(objective.value("mean_val_average_precision", VALIDATION))
    assert math.isnan(objective.value("min_val_auc", {}))
    assert objective.metric_key("mean_val_average_precision") == "average_precision"
    assert objective.metric_key("min_val_auc") == "auc"
    assert objective.metric_key("mean_val_val_f1") == "val_f1"  # the first "_val_" splits
    assert objective.reduced("min", "f1", VALIDATION) == pytest.approx(0.2)
