"""The baselines' plain code, kept as oracles for their shortcuts (``baselines.shortcuts``).

Each function computes what a shortcut computes the straightforward way: one trial-EP at a time,
one scaler-and-SVM pipeline per (C, draw), each chain scoring the trials asked for. They are not
a runtime path: the tests compare the package's one path with them, and ``plain_paths`` runs
whole rows with them in place (the tests, and ``bench/bench_baselines.py --rows`` for the
before/after figures).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

import numpy as np
from sklearn.exceptions import ConvergenceWarning

from tactile_exp import cores
from tactile_exp.baselines import dynamic, static
from tactile_exp.baselines.static import FILL, N_ELECTRODE_PCS, PHASES, POLY_DEGREE
from tactile_exp.models import linear_svm as svm


def pc_polyfit(poly: np.ndarray, mean: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(k, deg+1) polyfit of each PC series (x - mean) @ axes, from the raw columns' fits."""
    coef = poly @ axes  # a fit is linear in the signal
    coef[0] -= mean @ axes  # the constant term absorbs the centring
    return coef.T


def static_per_trial(
    features: static.StaticFeatures, table: static.StaticTable, trials: Sequence[str]
) -> np.ndarray:
    """``StaticFeatures.transform`` one trial-EP at a time (each its own PCA when per-trial)."""
    out = []
    for i in table.index(trials):
        parts = []
        for e in range(len(PHASES)):
            if features.per_trial_pca:
                mean = table.mean[i, e]
                axes = static.principal_axes(table.scatter[i, e], N_ELECTRODE_PCS)
            else:
                mean, axes = features.axes_[e]  # type: ignore[index]
            coef = pc_polyfit(table.poly[i, e], mean, axes)
            if table.count[i, e] < POLY_DEGREE + 1:  # too short: the fit was filled
                coef = np.full_like(coef, FILL)
            parts += [table.base[i, e], static.order_polyfit(coef, features.interleave)]
        out.append(np.concatenate(parts))
    return np.asarray(out, dtype=float).reshape(len(out), -1)


def held_out_decisions_per_c(
    model: svm.ObjectCVLinearSVM,
    X: np.ndarray,
    y: np.ndarray,
    draws: list[tuple[np.ndarray, np.ndarray]],
) -> list[list[np.ndarray]]:
    """``ObjectCVLinearSVM._held_out_decisions`` with one fresh pipeline per (C, draw)."""
    decisions: list[list[np.ndarray]] = [[] for _ in model.Cs]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        for j, C in enumerate(model.Cs):
            for tr, te in draws:
                pipeline = model._pipeline(C).fit(X[tr], y[tr])
                decisions[j].append(pipeline.decision_function(X[te]))
    return decisions


def chain_scores(
    features: dynamic.DynamicFeatures, table: dynamic.SequenceTable, trials: Sequence[str]
) -> np.ndarray:
    """``DynamicFeatures.transform``: each fitted chain scores just the trials asked for."""
    idx = table.index(trials)
    pairs = zip(features.chains_, features.params_, strict=True)
    return np.column_stack(
        [chain.score(table.seqs[T][c][idx]) for c, (chain, (_, T, _)) in enumerate(pairs)]
    )


@contextmanager
def plain_paths() -> Iterator[None]:
    """Inside the block the baselines compute the plain way: the oracles above in place of the
    shortcuts, and an adjective's chains fitted one after the other (one thread). Not
    thread-safe: a test and bench switch."""
    patched = [
        (static.StaticFeatures, "transform", static_per_trial),
        (svm.ObjectCVLinearSVM, "_held_out_decisions", held_out_decisions_per_c),
        (dynamic.DynamicFeatures, "transform", chain_scores),
        (cores, "threads", lambda tasks: 1),
    ]
    before = [(owner, name, getattr(owner, name)) for owner, name, _ in patched]
    try:
        for owner, name, plain in patched:
            setattr(owner, name, plain)
        yield
    finally:
        for owner, name, original in before:
            setattr(owner, name, original)
