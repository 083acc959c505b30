"""Leave-objects-out linear SVM (BASELINES.md §1.3) and its `linear_svm` Model adapter."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from sklearn.metrics import roc_auc_score
from sklearn.svm import LinearSVC

from tactile_exp.data.layout import Instances
from tactile_exp.models import MODELS
from tactile_exp.models.linear_svm import (
    LeavePObjectsOut,
    LinearSVMModel,
    ObjectCVLinearSVM,
    SquaredHingeSVM,
)


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
    from tactile_exp.models.linear_svm import AUTHORS_CS, LinearSVMModel

    assert LinearSVMModel(Cs="authors").svm.Cs == AUTHORS_CS
    with pytest.raises(ValueError, match="'authors'"):
        LinearSVMModel(Cs="author")


def test_draws_need_more_objects_than_they_hold_out_and_follow_the_seed():
    X, y, groups = _objects_data(n_objects=3)
    with pytest.raises(ValueError, match="^leave-3-objects-out needs more than 3 objects$"):
        list(LeavePObjectsOut(p=3).split(X, y, groups))
    X, _, groups = _objects_data(n_objects=12)
    y = np.isin(groups, [0, 3]).astype(int)

    def held(seed, n_draws=6):
        draws = LeavePObjectsOut(p=2, n_draws=n_draws, seed=seed).split(X, y, groups)
        return [tuple(np.unique(groups[test])) for _, test in draws]

    assert len(held(0)) == 6 and held(0) == held(0) and held(0) != held(1)
    assert len(held(0, n_draws=66)) == 66 - 1  # every pair but {0, 3} (one-class training set)


def test_small_training_sets_hold_out_fewer_objects_with_a_warning():
    """4 objects, 2 per class: no leave-3-out draw keeps both classes in training, so C is scored
    by leave-2-objects-out, exactly as a hand-made leave-2-out gives it."""
    X, y, groups = _objects_data(n_objects=4, shift=0.5)
    y = (groups < 2).astype(int)
    svm = ObjectCVLinearSVM(Cs=[0.01, 1.0], n_draws=5, p_out=4)
    with pytest.warns(UserWarning) as warned:
        scores = svm.cv_scores(X, y, groups)
    assert [str(w.message) for w in warned] == [
        "only 4 training objects: C chosen by leave-2-objects-out instead of leave-4-objects-out"
    ]
    held, decisions = [], []
    for train, test in LeavePObjectsOut(2, 5, 0).split(X, y, groups):
        decisions.append(svm._pipeline(1.0).fit(X[train], y[train]).decision_function(X[test]))
        held.append(test)
    assert len(held) >= 2 and all(len(np.unique(groups[test])) == 2 for test in held)
    expected = roc_auc_score(y[np.concatenate(held)], np.concatenate(decisions))
    assert scores[1] == pytest.approx(expected, abs=1e-12)
    one = groups == 0
    assert svm.cv_scores(X[one], y[one], groups[one]) is None  # nothing to hold out


def test_c_is_the_grid_value_with_the_best_held_out_auc():
    X, y, groups = _objects_data(shift=0.7, seed=4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a grid to choose from and usable draws: no warning
        svm = ObjectCVLinearSVM(Cs=[10.0, 1.0, 1e-2, 1e-4], n_draws=10, seed=1).fit(X, y, groups)
        pair = ObjectCVLinearSVM(Cs=[10.0, 1e-4], n_draws=10, seed=1).fit(X, y, groups)
        single = ObjectCVLinearSVM(Cs=[0.5]).fit(X, y, groups)  # nothing to choose: no CV
    best = int(np.argmax(svm.cv_scores_))
    assert len(set(svm.cv_scores_)) > 1 and best > 0  # the best is not simply the first
    assert svm.Cs[best] == svm.C_
    refit = svm._pipeline(svm.C_).fit(X, y)
    np.testing.assert_allclose(svm.decision_function(X), refit.decision_function(X))
    assert len(pair.cv_scores_) == 2 and pair.C_ == 1e-4
    assert single.C_ == 0.5 and single.cv_scores_ is None


def test_float32_features_give_the_float64_numbers():
    """Instances hold float32: the SVM standardises and scores in float64 all the same."""
    X, y, groups = _objects_data(shift=0.7)
    X = X.astype(np.float32)
    wide = ObjectCVLinearSVM(Cs=[0.1, 1.0], n_draws=4).fit(X.astype(np.float64), y, groups)
    narrow = ObjectCVLinearSVM(Cs=[0.1, 1.0], n_draws=4).fit(X, y, groups)
    np.testing.assert_array_equal(narrow.decision_function(X), wide.decision_function(X))
    np.testing.assert_array_equal(
        narrow.decision_function(X), wide.decision_function(X.astype(np.float64))
    )


def test_one_scaler_per_draw_gives_the_per_c_pipelines_scores():
    from baselines_oracles import plain_paths

    X, y, groups = _objects_data(shift=0.7)
    svm = ObjectCVLinearSVM(Cs=[0.01, 1.0, 10.0], n_draws=6, seed=3)
    fast = svm.cv_scores(X, y, groups)
    with plain_paths():
        plain = svm.cv_scores(X, y, groups)
    np.testing.assert_allclose(plain, fast, rtol=1e-9)


def test_middle_c_of_an_even_grid_and_exact_input_messages():
    X, y, groups = _objects_data(n_objects=6)
    y = (groups == 0).astype(int)
    with pytest.warns(
        UserWarning, match="^no draw of held-out objects gives both classes; middle "
    ):
        svm = ObjectCVLinearSVM(Cs=[0.1, 1.0, 10.0, 100.0], n_draws=5).fit(X, y, groups)
    assert svm.C_ == 10.0
    with pytest.warns(UserWarning, match="middle C=1$"):
        pair = ObjectCVLinearSVM(Cs=[0.1, 1.0], n_draws=5).fit(X, y, groups)
    assert pair.C_ == 1.0
    X[3, 2] = np.inf
    with pytest.raises(ValueError, match=r"^ObjectCVLinearSVM.fit: X has NaN or infinite values$"):
        ObjectCVLinearSVM().fit(X, y, groups)
    X[3, 2] = 0.0
    with pytest.raises(ValueError, match=r"^ObjectCVLinearSVM.fit: y needs both classes$"):
        ObjectCVLinearSVM().fit(X, np.zeros_like(y), groups)


def test_stored_svm_restores_exactly_and_rejects_wrong_shapes():
    X, y, groups = _objects_data(shift=3.0)
    train = Instances(X.reshape(-1, 2, 3), y, np.array([f"t{i}" for i in range(len(y))]), groups)
    fitted = LinearSVMModel(Cs=[0.1, 1.0], n_draws=4)
    fitted.fit(train)
    tensors, arrays = fitted.state()
    assert tensors == {} and float(arrays["C"]) == fitted.svm.C_
    restored = LinearSVMModel(Cs=[0.1, 1.0], n_draws=4).restore((2, 3), tensors, arrays)
    assert restored.input_shape_ == (2, 3) and restored.svm.C_ == fitted.svm.C_
    np.testing.assert_array_equal(
        restored.decision_function(train.X), fitted.decision_function(train.X)
    )
    for key, bad, message in [
        ("mean", np.zeros(5), r"^mean: shape \(5,\), expected \(6,\)$"),
        ("scale", np.zeros((6, 1)), r"^scale: shape \(6, 1\), expected \(6,\)$"),
        ("coef", np.zeros((6,)), r"^coef: shape \(6,\), expected \(1, 6\)$"),
        ("intercept", np.zeros(2), r"^intercept: shape \(2,\), expected \(1,\)$"),
    ]:
        with pytest.raises(ValueError, match=message):
            LinearSVMModel().restore((2, 3), {}, arrays | {key: bad})


def test_c_grid_settings():
    from tactile_exp.models.linear_svm import DEFAULT_CS

    defaults = {"Cs": None, "n_draws": 20, "p_out": 3, "seed": 0, "solver": "newton"}
    assert LinearSVMModel().get_params() == defaults
    assert LinearSVMModel().svm.Cs == DEFAULT_CS
    assert LinearSVMModel(Cs=[2, 3]).svm.Cs == (2.0, 3.0)
    model = LinearSVMModel(Cs=[2], n_draws=7, p_out=2, seed=5)
    assert (model.svm.n_draws, model.svm.p_out, model.svm.seed) == (7, 2, 5)
    with pytest.raises(
        ValueError, match=r"^Cs must be a list of numbers, null or 'authors', got 'x'$"
    ):
        LinearSVMModel(Cs="x")
    assert isinstance(LinearSVMModel(solver="liblinear").svm._svc(1.0), LinearSVC)
    with pytest.raises(ValueError, match=r"^solver must be one of newton, liblinear, got 'x'$"):
        LinearSVMModel(solver="x")


@pytest.mark.parametrize(
    ("n", "d", "shift", "C"),
    [(200, 10, 1.0, 1.0), (60, 150, 3.0, 10.0), (500, 50, 5.0, 100.0), (300, 20, 0.3, 1e-3)],
)
def test_newton_svm_is_the_optimum_liblinear_approaches(n, d, shift, C):
    """Overlapping, more features than rows, nearly hard margin, tiny C; 20% positives: the
    balanced weights matter. Against liblinear run to a 1e-12 tolerance, which takes 7-1,400
    iterations where the Newton solver takes 1-50 steps."""
    rng = np.random.default_rng(d)
    y = (rng.random(n) < 0.2).astype(int)
    X = rng.normal(size=(n, d))
    X[:, 0] += shift * y
    ours = SquaredHingeSVM(C).fit(X, y)
    tight = LinearSVC(C=C, dual=False, class_weight="balanced", tol=1e-12, max_iter=10**6)
    tight.fit(X, y)
    np.testing.assert_allclose(ours.coef_, tight.coef_, atol=1e-7)
    np.testing.assert_allclose(ours.intercept_, tight.intercept_, atol=1e-7)
    np.testing.assert_allclose(ours.decision_function(X), tight.decision_function(X), atol=1e-6)
    assert ours.n_iter_ <= 60


def test_liblinear_as_linearsvc_runs_it_stops_short_where_newton_does_not():
    """Why Newton is the default: near hard margin liblinear stops at its iteration cap."""
    rng = np.random.default_rng(1)
    y = (rng.random(60) < 0.2).astype(int)
    X = rng.normal(size=(60, 150))
    X[:, 0] += 3.0 * y
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        capped = LinearSVC(C=10.0, dual=False, class_weight="balanced", max_iter=50).fit(X, y)
    ours = SquaredHingeSVM(10.0).fit(X, y)
    assert capped.n_iter_ == 50 and ours.n_iter_ < 10
    assert np.abs(capped.coef_ - ours.coef_).max() > 1e-4


def test_defaults_are_the_authors_protocol_and_classes_are_balanced():
    """Leave 3 objects out, 20 draws, seed 0; a rare adjective's positives are not outvoted."""
    draws = LeavePObjectsOut()
    assert (draws.p, draws.n_draws, draws.seed) == (3, 20, 0)
    svm = ObjectCVLinearSVM()
    assert (svm.n_draws, svm.p_out, svm.seed) == (20, 3, 0)
    X, y, groups = _objects_data(shift=1.0)
    y = (groups % 10 == 0).astype(int)  # 2 positive objects of 20
    X[:, 0] += y
    fitted = ObjectCVLinearSVM(Cs=[1e-2]).fit(X, y, groups)
    decisions = fitted.decision_function(X)
    assert (decisions[y == 1] > 0).mean() >= 0.5  # unweighted: every trial scores negative


def test_svm_cross_validation_never_splits_an_object(monkeypatch):
    """C is chosen on folds that hold out whole objects (groups = the instances' object ids)."""
    rng = np.random.default_rng(0)
    objects = np.repeat(np.arange(12), 5)
    y = (objects % 2).astype(np.int64)
    X = rng.normal(size=(60, 4)) + y[:, None] * 0.7 + objects[:, None] * 0.05
    trials = np.array([f"o_{o}_{i}" for i, o in enumerate(objects)], dtype=object)
    folds = []
    split = LeavePObjectsOut.split

    def spy(self, X, y, groups):
        for tr, te in split(self, X, y, groups):
            folds.append((tr, te))
            yield tr, te

    monkeypatch.setattr(LeavePObjectsOut, "split", spy)
    model = MODELS.build("linear_svm", n_draws=8, p_out=3)
    model.fit(Instances(X, y, trials, objects))
    assert folds
    for tr, te in folds:
        assert len(set(objects[te])) == 3 and not set(objects[tr]) & set(objects[te])
        assert set(y[tr]) == {0, 1}
    cv = model.svm.cv_scores_
    assert model.svm.Cs[int(np.argmax(cv))] == model.svm.C_


def test_svm_on_few_objects_holds_out_fewer_objects_and_still_chooses_c():
    """A lab's small file: with 4 objects (2 per class) no leave-3-out draw keeps both classes
    in training, so C is chosen by leave-2-out (a CV score per C), with a warning; 5 objects
    (3 + 2) still allow the default leave-3-out, silently; 3 objects allow no CV at all."""
    rng = np.random.default_rng(0)
    groups = np.repeat([1, 2, 3, 4, 5], 6)
    y = (groups <= 3).astype(int)
    X = rng.normal(size=(30, 4)) + y[:, None]
    four = groups >= 2
    svm = ObjectCVLinearSVM(n_draws=20)
    with pytest.warns(UserWarning, match="only 4 training objects: C chosen by leave-2-objects"):
        svm.fit(X[four], y[four], groups[four])
    assert svm.cv_scores_ is not None and len(svm.cv_scores_) == len(svm.Cs)
    assert svm.Cs[int(np.argmax(svm.cv_scores_))] == svm.C_
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # 5 objects: leave-3-out works, nothing to warn about
        assert ObjectCVLinearSVM(n_draws=20).cv_scores(X, y, groups) is not None
    three = groups >= 3  # 1 positive object, 2 negative: no draw scores C
    with pytest.warns(UserWarning, match="middle C"):
        svm.fit(X[three], y[three], groups[three])
    assert svm.cv_scores_ is None and svm.Cs[len(svm.Cs) // 2] == svm.C_
