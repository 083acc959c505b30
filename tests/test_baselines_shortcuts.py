"""The baselines' shortcuts give the plain code's numbers (`tactile_exp.baselines.shortcuts`; the
plain code is the oracles in `tests/baselines_oracles.py`)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from baselines_fixture import make_trial
from baselines_oracles import plain_paths, static_per_trial
from sklearn.metrics import roc_auc_score
from test_baselines_dynamic import TINY_GRID, _generated

from tactile_exp.baselines import dynamic as dyn
from tactile_exp.baselines import features as feat
from tactile_exp.baselines import static as st
from tactile_exp.data.layout import TrialName
from tactile_exp.models.linear_svm import ObjectCVLinearSVM


def _table() -> st.StaticTable:
    """Five trials with different EP lengths, one EP too short for the polyfit (a fill)."""
    lengths = [(120, 200, 100, 60), (90, 150, 80, 40), (60, 70, 50, 5), (100, 100, 100, 100)]
    records, names = [], []
    for i, ep_rows in enumerate([*lengths, lengths[0]]):
        names.append(f"foam_101_{i + 1:02d}")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", st.FeatureWarning)
            records.append(st.trial_static(make_trial(names[-1], ep_rows, seed=i)))
    return st.StaticTable.from_records(names, records)


@pytest.mark.parametrize("per_trial_pca", [True, False])
@pytest.mark.parametrize("interleave", [True, False])
def test_static_matrix_equals_the_per_trial_loop(per_trial_pca, interleave):
    table = _table()
    features = st.StaticFeatures(per_trial_pca=per_trial_pca, interleave=interleave)
    features.fit(table, table.trials[:3])
    order = [table.trials[i] for i in (4, 0, 2, 2)]  # any order, repeats included
    plain = static_per_trial(features, table, order)
    fast = features.transform(table, order)
    np.testing.assert_allclose(fast, plain, rtol=1e-12, atol=1e-12)
    assert fast.shape == (4, 188) and (fast[2:] != 0).any()
    again = features.transform(table, order)  # per-trial: memoised on the table
    np.testing.assert_array_equal(again, fast)
    again[:] = 0.0  # callers get a copy, never the memo itself
    np.testing.assert_array_equal(features.transform(table, order), fast)


def test_principal_axes_of_a_stack_equal_one_at_a_time():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(6, 50, 5))
    scatter = np.einsum("nti,ntj->nij", a, a)
    scatter[0] = np.diag([4.0, 3.0, 0.0, 0.0, 0.0])  # zero loadings keep a positive sign
    stacked = st.principal_axes(scatter, 3)
    for s, axes in zip(scatter, stacked, strict=True):
        np.testing.assert_array_equal(axes, st.principal_axes(s, 3))
        assert (axes[np.argmax(np.abs(axes), axis=0), range(3)] > 0).all()


def _svm_data(n_objects=12, shift=0.8, seed=0):
    rng = np.random.default_rng(seed)
    groups = np.repeat(np.arange(n_objects), 4)
    y = (groups % 3 == 0).astype(int)
    X = rng.normal(size=(len(y), 7)) * rng.uniform(0.1, 50, 7)  # unequal scales: scaler matters
    X[:, 0] += shift * y * X[:, 0].std()
    return X, y, groups


@pytest.mark.parametrize(("n_objects", "p_out"), [(12, 3), (4, 5)])  # (4, 5): leave-1-out
def test_svm_c_search_with_one_scaler_per_draw_equals_the_per_c_pipelines(n_objects, p_out):
    X, y, groups = _svm_data(n_objects)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        with plain_paths():
            plain = ObjectCVLinearSVM(n_draws=6, p_out=p_out, seed=4).fit(X, y, groups)
        fast = ObjectCVLinearSVM(n_draws=6, p_out=p_out, seed=4).fit(X, y, groups)
    assert len(set(plain.cv_scores_)) > 1  # the grid is really compared
    np.testing.assert_array_equal(fast.cv_scores_, plain.cv_scores_)
    assert plain.C_ == fast.C_
    np.testing.assert_array_equal(fast.decision_function(X), plain.decision_function(X))


@pytest.fixture()
def tiny_grid():
    dyn.GRIDS["tiny"] = TINY_GRID
    yield
    del dyn.GRIDS["tiny"]


def test_rows_a_to_f_give_the_plain_codes_c_and_auc(tmp_path, tiny_grid):
    """Each row on a generated file: same features (to float rounding), chosen C and test AUC."""
    data, _, split = _generated(tmp_path)
    rows = [
        dict(features=("static",)),
        dict(features=("dynamic",)),
        dict(features=("static", "dynamic")),
        dict(features=("static", "dynamic"), dynamic_pool="object"),
        dict(features=("static", "dynamic"), faithful=False),
    ]

    def row(settings):
        bf = feat.BaselineFeatures(data, hmm_grid="tiny", cache_dir=tmp_path, **settings)
        bf.fit(split)
        X, X_test = bf.transform(split.train), bf.transform(split.test)
        y = np.array([split.labels[t] for t in split.train])
        groups = np.array([TrialName.parse(t).object_id for t in split.train])
        svm = ObjectCVLinearSVM(Cs=np.logspace(-3, 1, 5), n_draws=8).fit(X, y, groups)
        y_test = [split.labels[t] for t in split.test]
        return X, svm.C_, roc_auc_score(y_test, svm.decision_function(X_test))

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # short generated EPs: static fills
        for settings in rows:
            with plain_paths():
                X0, c0, auc0 = row(settings)
            X1, c1, auc1 = row(settings)
            np.testing.assert_allclose(X1, X0, rtol=1e-10, atol=1e-10)
            assert c1 == c0 and auc1 == pytest.approx(auc0, abs=1e-6)
