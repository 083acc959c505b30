"""HMM chains (BASELINES.md §2): resampling, scoring, and no test data in the fit."""

from __future__ import annotations

import numpy as np
import pytest
from baselines_fixture import make_trial
from hmmlearn import hmm

from tactile_exp.baselines import dynamic as dyn
from tactile_exp.data.layout import Split

TINY_GRID = {"n_states": (2, 3), "length": (8,), "symbols": (3,)}


def test_resample_takes_linear_positions_k_n_over_t():
    x = np.column_stack([np.arange(10.0), 5 * np.arange(10.0)])
    out = dyn.resample(x, 4)  # positions 0, 2.5, 5, 7.5
    np.testing.assert_allclose(out[:, 0], [0, 2.5, 5, 7.5])
    np.testing.assert_allclose(out[:, 1], 5 * out[:, 0])


def test_pca_keeps_97_percent_of_the_variance():
    assert dyn.pca_axes(np.diag([90.0, 6.0, 3.0, 1.0])).shape == (4, 3)  # 96 < 97 <= 99
    assert dyn.pca_axes(np.diag([90.0, 8.0, 1.5, 0.5])).shape == (4, 2)  # 97 <= 98
    assert dyn.pca_axes(np.diag([99.0, 0.5, 0.5])).shape == (3, 1)


def test_vectorised_forward_pass_equals_hmmlearn_score():
    rng = np.random.default_rng(0)
    seqs = np.cumsum(rng.normal(size=(30, 12, 3)), axis=1)
    m = seqs.reshape(-1, 3).mean(axis=0)
    scatter = np.stack([(s - m).T @ (s - m) for s in seqs])
    chain = dyn.HMMChain(3, 4).fit(np.full(30, 12.0), np.tile(m, (30, 1)), scatter, seqs)
    symbols = chain.symbols(seqs)
    reference = hmm.CategoricalHMM(n_components=3, n_features=4)
    reference.startprob_, reference.transmat_ = chain.startprob_, chain.transmat_
    reference.emissionprob_ = chain.emissionprob_
    expected = [reference.score(s.reshape(-1, 1)) for s in symbols]
    np.testing.assert_allclose(chain.score(seqs), expected, rtol=1e-8)


def _trials():
    """Objects 101-104 positive (train), 105 positive (test); 201-203 negative."""
    names = [f"o_{o}_{t:02d}" for o in (101, 102, 103, 104, 105, 201, 202, 203) for t in (1, 2)]
    trials = [make_trial(n, lengths=(30, 40, 30, 20), seed=i) for i, n in enumerate(names)]
    for t in trials:  # positives ramp up in every channel: learnable dynamics
        if t.name.object_id < 200:
            ramp = np.linspace(0, 800, t.n_rows).astype(np.int64)
            for f in t.fingers:
                f.pdc += ramp
                f.electrodes += ramp[:, None]
    labels = {t.name.name: int(t.name.object_id < 200) for t in trials}
    test = [n for n in labels if n.startswith(("o_105", "o_203"))]
    split = Split("hard", tuple(n for n in labels if n not in test), tuple(test), labels)
    return trials, split


def _fit(table, split, leak=False):
    return dyn.DynamicFeatures("tiny", leak_test_positives=leak, seed=0).fit(table, split)


def _params(model):
    return [np.concatenate([c.centers_.ravel(), c.emissionprob_.ravel()]) for c in model.chains_]


@pytest.fixture(scope="module")
def tiny_grid():
    dyn.GRIDS["tiny"] = TINY_GRID
    yield
    del dyn.GRIDS["tiny"]


def test_chains_see_training_positives_only(tiny_grid):
    trials, split = _trials()
    table = dyn.SequenceTable.from_trials(trials, (8,))
    model = _fit(table, split)
    assert sorted(model.fit_trials_) == sorted(n for n in split.train if split.labels[n] == 1)
    before = _params(model)
    X = model.transform(table, list(split.test))
    assert X.shape == (4, 16) and np.isfinite(X).all()
    # make every test trial and every training negative wildly different: nothing may change
    hidden = table.index([n for n in split.labels if n in split.test or not split.labels[n]])
    for c in range(len(dyn.CHAINS)):
        table.mean[c][hidden] *= 9.0
        table.scatter[c][hidden] *= 50.0
        table.seqs[8][c][hidden] = -table.seqs[8][c][hidden] * 7.0
    after = _params(_fit(table, split))
    for b, a in zip(before, after, strict=True):
        np.testing.assert_array_equal(a, b)


def test_leaky_flag_fits_on_test_positives_too(tiny_grid):
    trials, split = _trials()
    table = dyn.SequenceTable.from_trials(trials, (8,))
    model = _fit(table, split, leak=True)
    test_pos = [n for n in split.test if split.labels[n]]
    assert set(test_pos) <= set(model.fit_trials_)
    before = _params(model)
    i = table.index(test_pos)
    for c in range(len(dyn.CHAINS)):
        table.seqs[8][c][i] = -table.seqs[8][c][i] * 7.0
    after = _params(_fit(table, split, leak=True))
    assert any(not np.array_equal(a, b) for a, b in zip(before, after, strict=True))


def test_unknown_grid_is_rejected():
    with pytest.raises(KeyError, match="unknown HMM grid 'huge'"):
        dyn.DynamicFeatures("huge")


def _generated(folder):
    """A tiny generated file and a 'soft' split of it (objects 105 and 206 held out)."""
    from tactile_exp.data.phac2 import PHAC2
    from tactile_exp.data.synthetic import SyntheticSpec, generate

    spec = SyntheticSpec(
        object_ids=(101, 103, 104, 105, 201, 202, 206), trials=2, duration_scale=0.1, views=0
    )
    data = PHAC2(generate(folder / "tiny.h5", spec))
    names = [t.name for t in data.trials]
    labels = {n: int(n.split("_")[-2].startswith("1")) for n in names}
    test = tuple(n for n in names if "_105_" in n or "_206_" in n)
    return data, names, Split("soft", tuple(n for n in names if n not in test), test, labels)


def test_feature_builder_on_a_generated_file(tmp_path, tiny_grid, monkeypatch):
    from tactile_exp.baselines import features as feat

    data, names, split = _generated(tmp_path)
    labels = split.labels
    kwargs = dict(features=("static", "dynamic"), faithful=False, dynamic_pool="object")
    with pytest.warns(UserWarning):  # the short synthetic EPs fill some static features
        bf = feat.BaselineFeatures(data, hmm_grid="tiny", cache_dir=tmp_path, **kwargs).fit(split)
    X = bf.transform(names)
    assert X.shape == (len(names), 188 + 16) == (len(names), len(bf.feature_names))
    assert np.isfinite(X).all()
    dyn_block = X[:, 188:]  # pooled per object within one side: both trials share the vector
    np.testing.assert_array_equal(dyn_block[0], dyn_block[1])
    assert not np.array_equal(dyn_block[0], dyn_block[2])
    assert len(list(tmp_path.glob("baseline_*.npz"))) == 3  # static, sequences, soft's chains
    feat._MEMO.clear()  # a new process: the disk cache answers, the file is not read again
    monkeypatch.setattr(data, "iter_trials", None)
    again = feat.BaselineFeatures(data, hmm_grid="tiny", cache_dir=tmp_path, **kwargs).fit(split)
    np.testing.assert_array_equal(again.transform(names), X)
    with pytest.raises(ValueError, match="neither side"):
        feat.BaselineFeatures(data, hmm_grid="tiny", **kwargs).fit(
            Split("soft", split.train[:-2], split.test, labels)
        ).transform(names)


def test_fitted_chains_are_cached_per_data_split_settings_and_seed(
    tmp_path, tiny_grid, monkeypatch
):
    from tactile_exp.baselines import features as feat

    data, names, split = _generated(tmp_path)
    cache = tmp_path / "cache"

    def features(**kw):
        settings = dict(features=("dynamic",), hmm_grid="tiny", cache_dir=cache, seed=0) | kw
        return feat.BaselineFeatures(data, **settings)

    first = features().fit(split)  # row C fits the chains
    X = first.transform(names)
    assert len(list(cache.glob("baseline_hmm_soft_*.npz"))) == 1

    def refit(*args, **kwargs):
        raise AssertionError("chains refitted")

    monkeypatch.setattr(dyn.DynamicFeatures, "fit", refit)
    feat._MEMO.clear()  # another job: only the disk cache remembers
    again = features().fit(split)  # a hit: loaded, not refitted, bit-identical features
    np.testing.assert_array_equal(again.transform(names), X)
    assert again.dynamic_.params_ == first.dynamic_.params_
    pooled = features(dynamic_pool="object").fit(split).transform(names)  # row D/F's chains too
    assert not np.array_equal(pooled, X) and np.isfinite(pooled).all()

    moved = split.train[-1]  # one training trial moved to the test side
    other_split = Split("soft", split.train[:-1], (*split.test, moved), split.labels)
    flipped = Split(
        "soft", split.train, split.test, split.labels | {moved: 1 - split.labels[moved]}
    )
    dyn.GRIDS["tiny2"] = {**TINY_GRID, "n_states": (3,)}
    try:
        misses = [
            (features(), other_split),
            (features(), flipped),
            (features(seed=1), split),
            (features(leak_test_positives=True), split),
            (features(hmm_grid="tiny2"), split),
        ]
        for model, changed in misses:
            with pytest.raises(AssertionError, match="refitted"):
                model.fit(changed)
        monkeypatch.setattr(data, "identity", lambda: "another-file")
        with pytest.raises(AssertionError, match="refitted"):
            features().fit(split)
    finally:
        del dyn.GRIDS["tiny2"]
