"""ROC AUC per adjective (ties count one half), its refusals, the job's mean and the ROC figure."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.metrics import roc_curve

from tactile_exp import evaluate


# moved from test_behaviour.py / test_reliability.py (issue 26)
def test_auc_counts_ties_as_half_against_a_hand_computed_value():
    # positives 0.5, 0.9, 0.2 against negatives 0.1, 0.5, 0.5:
    # 0.5 beats 0.1 and ties twice (1 + 0.5 + 0.5), 0.9 beats all 3, 0.2 beats 0.1 -> 6 / 9
    y = np.array([1, 0, 1, 0, 1, 0])
    scores = np.array([0.5, 0.1, 0.9, 0.5, 0.2, 0.5])
    assert evaluate.auc(y, scores) == pytest.approx(6 / 9, abs=1e-12)
    assert evaluate.auc(y, np.zeros(6)) == 0.5  # all tied: chance, not 0 or 1
    assert evaluate.auc(y == 1, -scores) == pytest.approx(3 / 9, abs=1e-12)


@pytest.mark.parametrize(
    "y,scores,message",
    [
        ([1, 1, 1], [0.1, 0.2, 0.3], r"^AUC needs positives and negatives; labels present: \[1\]$"),
        ([0, 0], [0.1, 0.2], r"^AUC needs positives and negatives; labels present: \[0\]$"),
        ([0, 1, 1], [0.1, np.nan, 0.3], "^scores contain NaN or infinite values$"),
        ([0, 1, 1], [0.1, np.inf, 0.3], "^scores contain NaN or infinite values$"),
    ],
)
def test_auc_rejects_one_class_and_non_finite_scores(y, scores, message):
    with pytest.raises(ValueError, match=message):
        evaluate.auc(np.array(y), np.array(scores))


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


def test_mean_auc_is_the_plain_mean():
    assert evaluate.mean_auc({"a": 0.5, "b": 1.0, "c": 0.6}) == pytest.approx(0.7)
