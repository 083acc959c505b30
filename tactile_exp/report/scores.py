"""A job's held-out results as its child runs logged them: per adjective, ``scores.csv``.

``scores.csv`` has one line per test unit (a trial, a group of trials, an object's views, or one
instance): ``unit`` (the unit's first trial, or the object's name for visual units), ``object_id``,
``label`` (ground truth, 0/1) and ``score`` (the decision value). Every classifier the jobs train
ends in a hinge-loss linear layer, so an adjective is predicted when its score is > 0
(``THRESHOLD``, as ``tactile_exp.predict`` decides).
"""

from __future__ import annotations

from tactile_exp import scores_file
from tactile_exp.scores_file import UnitScore
from tactile_exp.tracking import Tracker

SCORES_FILE = scores_file.NAME


class ReportError(RuntimeError):
    """A run the report needs is incomplete or does not fit; the message says which and why."""


def read_scores(tracker: Tracker, child_id: str) -> list[UnitScore]:
    """The test units of one child run, as its ``scores.csv`` lists them."""
    from mlflow.exceptions import MlflowException

    try:
        return scores_file.read(tracker.download(child_id, SCORES_FILE).read_text())
    except (OSError, KeyError, ValueError, MlflowException) as err:
        raise ReportError(f"run {child_id}: artifact {SCORES_FILE} unreadable ({err})") from None
