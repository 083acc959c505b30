"""A job's held-out results as its child runs logged them: per adjective, ``scores.csv``.

``scores.csv`` has one line per test unit (a trial, a group of trials, an object's views, or one
instance): ``unit`` (the unit's first trial, or the object's name for visual units), ``object_id``,
``label`` (ground truth, 0/1) and ``score`` (the decision value). Every classifier the jobs train
ends in a hinge-loss linear layer, so an adjective is predicted when its score is > 0
(``THRESHOLD``, as ``tactile_exp.predict`` decides).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

from tactile_exp.metrics import THRESHOLD
from tactile_exp.tracking import Tracker

SCORES_FILE = "scores.csv"


class ReportError(RuntimeError):
    """A run the report needs is incomplete or does not fit; the message says which and why."""


@dataclass(frozen=True)
class UnitScore:
    unit: str
    object_id: int
    label: int
    score: float

    @property
    def predicted(self) -> bool:
        return self.score > THRESHOLD


def read_scores(tracker: Tracker, child_id: str) -> list[UnitScore]:
    """The test units of one child run, as its ``scores.csv`` lists them."""
    from mlflow.exceptions import MlflowException

    try:
        path = Path(tracker.client.download_artifacts(child_id, SCORES_FILE))
        with open(path, newline="") as f:
            return [
                UnitScore(r["unit"], int(r["object_id"]), int(float(r["label"])), float(r["score"]))
                for r in csv.DictReader(f)
            ]
    except (OSError, KeyError, ValueError, MlflowException) as err:
        raise ReportError(f"run {child_id}: artifact {SCORES_FILE} unreadable ({err})") from None
