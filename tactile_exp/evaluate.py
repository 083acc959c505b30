"""The per-job ROC figure (E2); the metrics themselves are in ``tactile_exp.metrics``."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from sklearn.metrics import roc_curve

from tactile_exp.metrics import METRICS


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
        ax.set_title(f"{adj} {METRICS.build('roc_auc')(y, s):.2f}", fontsize=8)
        ax.tick_params(labelsize=6)
    fig.suptitle(title, fontsize=10)
    # fixed margins for the small panels: tight_layout measured every label, ~0.5 s a job
    fig.subplots_adjust(
        left=0.3 / fig.get_figwidth(),
        right=1 - 0.1 / fig.get_figwidth(),
        bottom=0.3 / fig.get_figheight(),
        top=1 - 0.55 / fig.get_figheight(),
        wspace=0.3,
        hspace=0.45,
    )
    return fig
