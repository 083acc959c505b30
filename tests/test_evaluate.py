"""The job's ROC figure (the metrics themselves: tests/test_metrics.py)."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.metrics import roc_curve

from tactile_exp import evaluate


def test_roc_figure_has_one_panel_per_adjective_with_its_curve_and_auc():
    y = np.array([1, 0, 1, 0, 1, 0])
    scores = np.array([0.5, 0.1, 0.9, 0.5, 0.2, 0.5])
    fig = evaluate.roc_figure({f"adj{i}": (y, scores) for i in range(8)}, "job on data.h5")
    assert tuple(fig.get_size_inches()) == pytest.approx((2.2 * 6, 2.2 * 2))  # 6 per row
    shown = [ax for ax in fig.axes if ax.axison]
    assert len(fig.axes) == 12 and len(shown) == 8
    assert [ax.get_title() for ax in shown] == [f"adj{i} 0.67" for i in range(8)]
    fpr, tpr, _ = roc_curve(y, scores)
    np.testing.assert_array_equal(shown[0].lines[0].get_xydata(), np.column_stack([fpr, tpr]))
    assert fig.get_suptitle() == "job on data.h5"
