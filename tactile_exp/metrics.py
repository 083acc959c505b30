"""What a job scores its test units by (E2 and beyond): a registry of metrics of (labels, scores).

Each adjective's run logs every configured metric (``metrics:`` in ``conf/config.yaml``) under
the metric's ``key``, the job's run ``mean_<key>`` over adjectives and ``<key>.<adjective>``, and
the report reads any one of them (``python -m tactile_exp.report --metric NAME``). ``roc_auc`` is
logged as ``auc``, the name every run, the report and the MLflow views had before there were
other metrics. A metric is a function of the test units' 0/1 labels and decision values alone,
so the report's object bootstrap can recompute it on resampled objects (``tactile_exp.stats``).

A new metric is one decorated function (``@register("name")``) in a module imported before the
job's config is checked (the registry is read at lookup, so a test module may add one).
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from sklearn.metrics import roc_auc_score

from tactile_exp.registry import Registry

# Every classifier here ends in a hinge-loss linear layer: a unit is predicted positive when its
# decision value is above 0 (as ``tactile_exp.predict`` and the report's Table III decide).
THRESHOLD = 0.0

Function = Callable[[np.ndarray, np.ndarray], float]  # (0/1 labels, decision values) -> value
# (labels (n,), decision values (n,), unit weights (b, n)) -> the metric under each weighting (b,)
Weighted = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Metric:
    """A registered metric: ``key`` is the name it is logged under, ``label`` the one people
    read; ``needs_both_classes``: undefined unless the labels hold positives and negatives;
    ``weighted`` (optional): the same metric under many integer unit weightings at once."""

    name: str
    key: str
    label: str
    function: Function
    needs_both_classes: bool
    weighted: Weighted | None = None

    def __call__(self, y: np.ndarray, scores: np.ndarray) -> float:
        """The metric of ``scores`` against 0/1 labels ``y``; refuses what it cannot score."""
        y = np.asarray(y)
        scores = np.asarray(scores, dtype=float)
        if self.needs_both_classes and len(np.unique(y)) != 2:
            raise ValueError(
                f"{self.label} needs positives and negatives; labels present: {np.unique(y)}"
            )
        if not np.all(np.isfinite(scores)):
            raise ValueError("scores contain NaN or infinite values")
        return float(self.function(y, scores))

    def replicates(self, y: np.ndarray, scores: np.ndarray, counts: np.ndarray) -> np.ndarray:
        """The metric with each unit taken ``counts[b, unit]`` times, per row ``b`` of counts
        (the report's bootstrap: an object drawn twice counts its units twice)."""
        if self.weighted is not None:
            return self.weighted(np.asarray(y), np.asarray(scores, dtype=float), counts)
        return np.array([self(np.repeat(y, c), np.repeat(scores, c)) for c in counts])


METRICS: Registry[Metric] = Registry("metric")  # entries build a Metric: see ``register``


def register(
    name: str,
    *,
    key: str | None = None,
    label: str | None = None,
    needs_both_classes: bool,
    weighted: Weighted | None = None,
) -> Callable[[Function], Function]:
    """Register ``function(y, scores) -> float`` as metric ``name``, logged as ``key`` (default
    ``name``); two metrics may not share a key (their logged values would overwrite), and a key
    has no dot (the job's run logs ``<key>.<adjective>``). ``weighted`` only makes the report's
    bootstrap faster; without it each replicate's units are repeated and ``function`` called."""

    def add(function: Function) -> Function:
        logged = key or name
        if not re.fullmatch(r"\w+", logged):
            raise ValueError(f"metric {name!r}: key {logged!r}: letters, digits and _ only")
        taken = {METRICS.build(n).key: n for n in METRICS.names()}
        if logged in taken:
            raise ValueError(f"metric {name!r}: key {logged!r} is already metric {taken[logged]!r}")
        factory = functools.partial(
            Metric, name, logged, label or logged, function, needs_both_classes, weighted
        )
        METRICS.register(name)(factory)
        return function

    return add


def compute(names: Sequence[str], y: np.ndarray, scores: np.ndarray) -> dict[str, float]:
    """One adjective's test units scored by each named metric: ``{key: value}``, in order."""
    return {m.key: m(y, scores) for m in map(METRICS.build, names)}


def summary(per_adjective: Mapping[str, Mapping[str, float]]) -> dict[str, float]:
    """A job's metrics from its adjectives' (``{adjective: {key: value}}``): ``mean_<key>``
    over the adjectives and ``<key>.<adjective>`` for each, what the job's run logs."""
    keys = dict.fromkeys(k for values in per_adjective.values() for k in values)
    out = {}
    for key in keys:
        values = {a: v[key] for a, v in per_adjective.items() if key in v}
        out[f"mean_{key}"] = float(np.mean(list(values.values())))
        out.update({f"{key}.{a}": v for a, v in values.items()})
    return out


@register("roc_auc", key="auc", label="AUC", needs_both_classes=True)
def roc_auc(y: np.ndarray, scores: np.ndarray) -> float:
    """ROC AUC (E2): the chance that a positive unit scores above a negative one, ties half."""
    return float(roc_auc_score(y, scores))


def _average_precision_weighted(
    y: np.ndarray, scores: np.ndarray, weights: np.ndarray
) -> np.ndarray:
    """Average precision as scikit-learn's ``average_precision_score`` defines it (sum over
    thresholds of precision times the recall gained, no interpolation), per row of ``weights``:
    units ranked by score once, tied units one threshold, weights summed down the ranking."""
    order = np.argsort(-scores, kind="mergesort")
    ranked, positive = scores[order], (y[order] == 1)
    last = np.r_[np.flatnonzero(ranked[1:] != ranked[:-1]), len(ranked) - 1]  # end of each tie
    ranked_weights = weights[:, order]
    true_positives = np.cumsum(ranked_weights * positive, axis=1)[:, last]
    taken = np.cumsum(ranked_weights, axis=1)[:, last]
    precision = np.divide(true_positives, taken, out=np.zeros(taken.shape), where=taken > 0)
    recall = true_positives / true_positives[:, -1:]
    return np.sum(np.diff(recall, axis=1, prepend=0.0) * precision, axis=1)


@register(
    "average_precision",
    label="average precision",
    needs_both_classes=True,
    weighted=_average_precision_weighted,
)
def average_precision(y: np.ndarray, scores: np.ndarray) -> float:
    """Area under the precision-recall curve (scikit-learn's definition), in numpy: ~20x faster
    than ``average_precision_score``, which the report's bootstrap would call 2000 times."""
    return float(_average_precision_weighted(y, scores, np.ones((1, len(y))))[0])


def _f1_weighted(y: np.ndarray, scores: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """F1 at the decision threshold per row of unit ``weights`` (0 where nothing is positive)."""
    predicted, positive = scores > THRESHOLD, y == 1
    true_positives = weights @ (predicted & positive)
    denominator = 2 * true_positives + weights @ (predicted != positive)
    out = np.zeros(len(weights))
    return np.divide(2 * true_positives, denominator, out=out, where=denominator > 0)


@register("f1", label="F1", needs_both_classes=False, weighted=_f1_weighted)
def f1(y: np.ndarray, scores: np.ndarray) -> float:
    """F1 of the positive class at the decision threshold (a unit is positive when its score
    is > 0), as Chu et al. report it, so their 0.77 stays comparable; 0 when there is nothing
    positive, labelled or predicted (scikit-learn's ``zero_division=0``)."""
    return float(_f1_weighted(y, scores, np.ones((1, len(y))))[0])
