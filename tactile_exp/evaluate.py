"""ROC AUC per adjective (E2) and the per-job summary."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from sklearn.metrics import roc_auc_score, roc_curve


def auc(y: np.ndarray, scores: np.ndarray) -> float:
    """ROC AUC of ``scores`` against 0/1 labels; needs both classes."""
    y = np.asarray(y)
    scores = np.asarray(scores, dtype=float)
    if len(np.unique(y)) != 2:
        raise ValueError(f"AUC needs positives and negatives; labels present: {np.unique(y)}")
    if not np.all(np.isfinite(scores)):
        raise ValueError("scores contain NaN or infinite values")
    return float(roc_auc_score(y, scores))


def mean_auc(aucs: Mapping[str, float]) -> float:
    return float(np.mean(list(aucs.values())))


def roc_figure(curves: Mapping[str, tuple[np.ndarray, np.ndarray]], title: str):
    """One small ROC panel per adjective: what the AUC table hides (few test objects)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(curves)
    cols = min(6, n)
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(2.2 * cols, 2.2 * rows), squeeze=False)
    for ax in axes.flat[n:]:
        ax.axis("off")
    for ax, (adj, (y, s)) in zip(axes.flat, curves.items(), strict=False):
        fpr, tpr, _ = roc_curve(y, s)
        ax.plot(fpr, tpr, lw=1.5)
        ax.plot([0, 1], [0, 1], "k:", lw=0.8)
        ax.set_title(f"{adj} {auc(y, s):.2f}", fontsize=8)
        ax.tick_params(labelsize=6)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig
