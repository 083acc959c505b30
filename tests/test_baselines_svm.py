"""Leave-objects-out linear SVM (BASELINES.md §1.3) and its `linear_svm` Model adapter."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.metrics import roc_auc_score

from tactile_exp.baselines.svm import LeavePObjectsOut, LinearSVMModel, ObjectCVLinearSVM
from tactile_exp.data.layout import Instances
from tactile_exp.models import MODELS


def _objects_data(n_objects=20, trials=5, shift=1.5, seed=0):
    """Object-level labels (every 3rd object positive); positives shifted along feature 0."""
    rng = np.random.default_rng(seed)
    groups = np.repeat(np.arange(n_objects), trials)
    y = (groups % 3 == 0).astype(int)
    X = rng.normal(size=(len(y), 6))
    X[:, 0] += shift * y
    return X, y, groups


def test_every_draw_holds_out_whole_objects_and_keeps_two_training_classes():
    X, y, groups = _objects_data()
    draws = list(LeavePObjectsOut(p=3, n_draws=25, seed=1).split(X, y, groups))
    assert 0 < len(draws) <= 25
    seen = set()
    for train, test in draws:
        held = set(groups[test])
        assert len(held) == 3 and not held & set(groups[train])
        assert len(train) + len(test) == len(y)
        assert set(y[train]) == {0, 1}
        seen.add(tuple(sorted(held)))
    assert len(seen) == len(draws)  # distinct draws


def test_cv_score_is_roc_auc_of_pooled_held_out_decisions():
    X, y, groups = _objects_data()
    svm = ObjectCVLinearSVM(Cs=[0.01, 1.0], n_draws=8, seed=2)
    scores = svm.cv_scores(X, y, groups)
    held, decisions = [], []
    for train, test in LeavePObjectsOut(3, 8, 2).split(X, y, groups):
        decisions.append(svm._pipeline(1.0).fit(X[train], y[train]).decision_function(X[test]))
        held.append(test)
    expected = roc_auc_score(y[np.concatenate(held)], np.concatenate(decisions))
    assert scores[1] == pytest.approx(expected, abs=1e-12)


def test_fit_on_a_user_matrix_beats_chance_on_separable_data():
    X, y, groups = _objects_data(shift=3.0)
    Xt, yt, _ = _objects_data(shift=3.0, seed=9)
    svm = ObjectCVLinearSVM(n_draws=10).fit(X, y, groups)
    assert svm.C_ in svm.Cs and len(svm.cv_scores_) == len(svm.Cs)
    assert roc_auc_score(yt, svm.decision_function(Xt)) > 0.95


def test_no_usable_draw_falls_back_with_a_warning():
    X, y, groups = _objects_data(n_objects=6)
    y = (groups == 0).astype(int)  # one positive object: a draw holding it out is one-class
    with pytest.warns(UserWarning, match="no draw of held-out objects gives both classes"):
        svm = ObjectCVLinearSVM(Cs=[0.1, 1.0, 10.0], n_draws=5).fit(X, y, groups)
    assert svm.C_ == 1.0 and svm.cv_scores_ is None


def test_bad_input_is_rejected():
    X, y, groups = _objects_data()
    X[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        ObjectCVLinearSVM().fit(X, y, groups)


def test_model_adapter_is_registered_and_heads_are_fresh_copies():
    X, y, groups = _objects_data(shift=3.0)
    model = MODELS.build("linear_svm", Cs=[0.1, 1.0], n_draws=4, seed=3)
    assert isinstance(model, LinearSVMModel) and model.learns_representation is False
    train = Instances(X.astype(np.float32), y, np.array([f"t{i}" for i in range(len(y))]), groups)
    assert model.fit(train) == {}
    assert roc_auc_score(y, model.decision_function(X)) > 0.95
    head = model.head()
    assert head is not model and (head.Cs, head.n_draws, head.seed) == ([0.1, 1.0], 4, 3)
    assert not hasattr(head.svm, "pipeline_")


def test_authors_c_grid_is_selectable_by_name():
    from tactile_exp.baselines.svm import AUTHORS_CS, LinearSVMModel

    assert LinearSVMModel(Cs="authors").svm.Cs == AUTHORS_CS
    with pytest.raises(ValueError, match="'authors'"):
        LinearSVMModel(Cs="author")
