"""HMM chains (BASELINES.md §2): resampling, scoring, and no test data in the fit."""

from __future__ import annotations

import warnings

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


def _fit(table, split):
    return dyn.DynamicFeatures("tiny", seed=0).fit(table, split)


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
    assert again.fitted_.dynamic.params_ == first.fitted_.dynamic.params_
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


# ---------------------------------------------------------------- building blocks, direct
def test_sensor_rows_put_both_fingers_side_by_side():
    trial = make_trial("o_101_01", lengths=(30, 40, 30, 20))
    rows = trial.ep_segments()["hold"]
    f0, f1 = trial.fingers
    pdc = dyn.sensor_rows(trial, rows, "pdc")
    np.testing.assert_array_equal(pdc, np.column_stack([f0.pdc[rows], f1.pdc[rows]]))
    assert pdc.dtype == float and pdc.shape == (40, 2)
    electrodes = dyn.sensor_rows(trial, rows, "electrodes")
    np.testing.assert_array_equal(electrodes[:, 19:], f1.electrodes[rows])
    pac = dyn.sensor_rows(trial, rows, "pac")
    np.testing.assert_array_equal(pac[:, :22], f0.pac.reshape(trial.n_rows, 22)[rows])
    assert (electrodes.shape, pac.shape) == ((40, 38), (40, 44))


def test_sequence_table_holds_row_moments_and_round_trips_its_arrays():
    trials = [make_trial(f"o_10{i}_01", lengths=(30, 40, 30, 20), seed=i) for i in (1, 2)]
    table = dyn.SequenceTable.from_trials(trials, (4, 6))
    assert table.trials == ["o_101_01", "o_102_01"]
    c = dyn.CHAINS.index(("hold", "tac"))
    x = dyn.sensor_rows(trials[1], trials[1].ep_segments()["hold"], "tac")
    assert table.count[1, c] == 40
    np.testing.assert_allclose(table.mean[c][1], x.mean(axis=0))
    np.testing.assert_allclose(table.scatter[c][1], (x - x.mean(0)).T @ (x - x.mean(0)))
    np.testing.assert_allclose(table.seqs[6][c][1], dyn.resample(x, 6))
    arrays = table.arrays()
    assert sorted(arrays) == sorted(dyn.SequenceTable.keys((4, 6)))
    again = dyn.SequenceTable.from_arrays(arrays, (4, 6))
    assert again.trials == table.trials
    np.testing.assert_array_equal(again.count, table.count)
    for c in range(len(dyn.CHAINS)):
        np.testing.assert_array_equal(again.mean[c], table.mean[c])
        np.testing.assert_array_equal(again.scatter[c], table.scatter[c])
        for T in (4, 6):
            np.testing.assert_array_equal(again.seqs[T][c], table.seqs[T][c])
    np.testing.assert_array_equal(table.index(["o_102_01", "o_101_01"]), [1, 0])
    with pytest.raises(KeyError, match=r"unknown trial\(s\) \['o_9_01'\]"):
        table.index(["o_101_01", "o_9_01"])


def test_pca_of_constant_rows_keeps_one_axis():
    assert dyn.pca_axes(np.zeros((3, 3))).shape == (3, 1)
    assert dyn.pca_axes(np.diag([50.0, 50.0, 0.0])).shape == (3, 2)


def test_forward_pass_by_hand_and_unseen_symbols_stay_finite():
    start = np.array([1.0, 0.0])
    trans = np.array([[0.5, 0.5], [0.0, 1.0]])
    emit = np.array([[0.5, 0.5], [1.0, 0.0]])
    # P(0, 1) = sum over paths: (s0 -> s0) 0.5*0.5*0.5 + (s0 -> s1) 0.5*0.5*0 = 0.125
    out = dyn.forward_loglik(start, trans, emit, np.array([[0, 1], [0, 0]]))
    np.testing.assert_allclose(out, np.log([0.125, 0.5 * (0.5 * 0.5 + 0.5 * 1.0)]), rtol=1e-8)
    never = dyn.forward_loglik(
        start, np.eye(2), np.array([[1.0, 0.0], [1.0, 0.0]]), np.array([[1]])
    )
    assert np.isfinite(never).all() and never[0] == pytest.approx(np.log(1e-10), rel=1e-3)


def test_candidates_put_the_fallback_first():
    grid = {"n_states": (2, 3), "length": (8, 9), "symbols": (4, 5)}
    cands = dyn._candidates(grid)
    assert cands[0] == (2, 8, 4) and len(set(cands)) == 8
    assert cands[:3] == [(2, 8, 4), (3, 8, 4), (2, 8, 5)]


def test_fitted_features_round_trip_their_arrays_and_score_as_each_chain_alone(tiny_grid):
    from baselines_oracles import chain_scores

    trials, split = _trials()
    table = dyn.SequenceTable.from_trials(trials, (8,))
    with warnings.catch_warnings():
        warnings.simplefilter("error", dyn.DynamicWarning)  # settings chosen: nothing to warn
        model = _fit(table, split)
    assert model.settings() == {
        "grid": TINY_GRID,
        "holdout": 0.2,
        "n_init": 10,
        "seed": 0,
        "hmm": [dyn.HMM_ITER, dyn.HMM_TOL, dyn.VARIANCE_KEPT],
    }
    assert model.feature_names[0] == "dyn/squeeze/electrodes" and len(model.feature_names) == 16
    assert dyn.DynamicFeatures.lengths("tiny") == (8,)
    arrays = model.arrays()
    assert sorted(arrays) == sorted(dyn.DynamicFeatures.KEYS)
    loaded = dyn.DynamicFeatures("tiny").load_arrays(arrays)
    assert loaded.params_ == model.params_ and loaded.fit_trials_ == model.fit_trials_
    chain = loaded.chains_[0]
    assert (chain.n_states, chain.n_symbols) == model.chains_[0].emissionprob_.shape
    names = list(split.test) + list(split.train[:3])
    X = model.transform(table, names)
    np.testing.assert_array_equal(loaded.transform(table, names), X)
    np.testing.assert_allclose(chain_scores(model, table, names), X, rtol=1e-12)
    other = dyn.SequenceTable.from_trials(trials[::-1], (8,))  # another table: scored anew
    np.testing.assert_allclose(model.transform(other, names), X, rtol=1e-12)
    scored = []
    score = model._score
    model._score = lambda table, idx: scored.append(len(idx)) or score(table, idx)
    model.transform(other, names[:2])
    model.transform(other, names[2:])
    assert scored == []  # the table's trials were scored once, by the first transform


def test_no_positive_or_one_positive_object_is_refused_or_warned(tiny_grid):
    trials, split = _trials()
    table = dyn.SequenceTable.from_trials(trials, (8,))
    none = Split("hard", split.train, split.test, {n: 0 for n in split.labels})
    with pytest.raises(ValueError, match="^adjective 'hard': no positive training trial$"):
        _fit(table, none)
    one = {n: int(n.startswith("o_101")) for n in split.labels}
    message = (
        r"^adjective 'hard': fewer than 2 positive training objects; HMM settings not chosen, "
        r"using \(N, T, K\) = \(2, 8, 3\)$"
    )
    with pytest.warns(dyn.DynamicWarning, match=message) as warned:
        model = _fit(table, Split("hard", split.train, split.test, one))
    assert [w.category for w in warned] == [dyn.DynamicWarning]  # no empty scoring either
    assert model.params_ == [(2, 8, 3)] * 16
    assert sorted(model.fit_trials_) == ["o_101_01", "o_101_02"]
    dyn.GRIDS["one"] = {"n_states": (3,), "length": (8,), "symbols": (3,)}
    try:  # a grid of one: nothing to choose, so nothing to warn about
        with warnings.catch_warnings():
            warnings.simplefilter("error", dyn.DynamicWarning)
            alone = dyn.DynamicFeatures("one").fit(table, Split("hard", split.train, (), one))
    finally:
        del dyn.GRIDS["one"]
    assert alone.params_ == [(3, 8, 3)] * 16


def test_each_candidate_is_fitted_and_scored_only_when_there_is_a_choice(tiny_grid, monkeypatch):
    trials, split = _trials()
    table = dyn.SequenceTable.from_trials(trials, (8,))
    fits: list[int] = []
    fit = dyn.HMMChain.fit

    def counted(self, *args):
        fits.append(self.n_states)
        return fit(self, *args)

    monkeypatch.setattr(dyn.HMMChain, "fit", counted)
    _fit(table, split)
    assert len(fits) == 16 * (2 + 1)  # per chain: both candidates, then the chosen one refitted
    fits.clear()
    dyn.GRIDS["one"] = {"n_states": (3,), "length": (8,), "symbols": (3,)}
    try:
        dyn.DynamicFeatures("one").fit(table, split)
    finally:
        del dyn.GRIDS["one"]
    assert fits == [3] * 16  # a grid of one: the final chains only


def test_held_out_objects_are_the_holdout_fraction_of_training_positives():
    trials, split = _trials()  # 4 positive training objects: 101-104
    positives = [t for t in split.train if split.labels[t] == 1]

    def held(holdout, seed=0):
        model = dyn.DynamicFeatures(holdout=holdout, seed=seed)
        fit, score = model._selection_sets(split, positives)
        assert sorted(fit + score) == sorted(positives)
        objects = {t.split("_")[1] for t in score}
        assert not objects & {t.split("_")[1] for t in fit}
        return objects

    assert len(held(0.2)) == 1 and len(held(0.5)) == 2 and len(held(0.01)) == 1
    assert {frozenset(held(0.5, seed)) for seed in range(6)} != {frozenset(held(0.5))}
    assert held(0.5, 3) == held(0.5, 3)
    assert all(len(held(0.5, seed)) == 2 for seed in range(20))  # distinct objects
    two = [t for t in positives if t.startswith(("o_101", "o_102"))]  # 2 objects: one is held
    fit, score = dyn.DynamicFeatures()._selection_sets(split, two)
    assert len({t[:5] for t in fit}) == len({t[:5] for t in score}) == 1
    assert dyn.DynamicFeatures()._selection_sets(split, two[:2]) == (two[:2], [])  # 1 object


@pytest.mark.parametrize(
    ("m", "T", "n_states", "n_symbols", "seed"),
    [
        (120, 20, 6, 5, 0),  # runs all 100 iterations
        (120, 20, 12, 5, 3),
        (40, 25, 15, 10, 1),
        (9, 30, 18, 12, 2),  # stops early (tol), more parameters than symbols
        (30, 1, 3, 4, 5),  # length 1: no transitions to count
    ],
)
def test_hmm_em_equals_hmmlearn_categorical_hmm(m, T, n_states, n_symbols, seed):
    """``fit_categorical_hmm`` reproduces hmmlearn's EM (init draws, updates, stopping)."""
    rng = np.random.default_rng(seed)
    regime = np.cumsum(rng.random((m, T)) < 0.2, axis=1) % 3  # sticky hidden regimes
    symbols = (2 * regime + (rng.random((m, T)) < 0.3)) % n_symbols
    reference = hmm.CategoricalHMM(
        n_components=n_states,
        n_features=n_symbols,
        n_iter=dyn.HMM_ITER,
        tol=dyn.HMM_TOL,
        random_state=seed,
        implementation="scaling",
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # hmmlearn: "degenerate solution" on few points
        reference.fit(symbols.reshape(-1, 1), lengths=[T] * m)
    got = dyn.fit_categorical_hmm(symbols, n_states, n_symbols, seed=seed)
    expected = (reference.startprob_, reference.transmat_, reference.emissionprob_)
    for name, ours, theirs in zip(("start", "trans", "emission"), got, expected, strict=True):
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-9, err_msg=name)
    assert reference.monitor_.iter > 1  # EM really moved the parameters


def test_hmm_em_rejects_symbols_outside_the_alphabet():
    with pytest.raises(ValueError, match=r"symbols must lie in \[0, 3\), got 0..3"):
        dyn.fit_categorical_hmm(np.array([[0, 1, 3]]), 2, 3, seed=0)


@pytest.fixture
def small_grid(monkeypatch):
    """A grid of 4 candidates, registered for one test (the real "small" grid is left alone)."""
    monkeypatch.setitem(
        dyn.GRIDS, "selection", {"n_states": (2, 4), "length": (6, 10), "symbols": (3,)}
    )
    return "selection"


def _hmm_data():
    """Positives 101-105 (105 in test) ramp up in every channel; negatives 201-203."""
    objects = (101, 102, 103, 104, 105, 201, 202, 203)
    names = [f"o_{o}_{t:02d}" for o in objects for t in (1, 2)]
    trials = [make_trial(n, lengths=(30, 40, 30, 20), seed=i) for i, n in enumerate(names)]
    for t in trials:
        if t.name.object_id < 200:
            ramp = np.linspace(0, 800 * (t.name.object_id % 3 + 1), t.n_rows).astype(np.int64)
            for f in t.fingers:
                f.pdc += ramp
                f.electrodes += ramp[:, None]
    labels = {n: int(n.split("_")[1] < "200") for n in names}
    test = tuple(n for n in names if "_105_" in n or "_203_" in n)
    return trials, Split("hard", tuple(n for n in names if n not in test), test, labels)


def _rows(table_seqs: np.ndarray, seqs: np.ndarray) -> list[int]:
    return [int(np.flatnonzero((table_seqs == s).all(axis=(1, 2)))[0]) for s in seqs]


def test_hmm_settings_are_chosen_by_held_out_likelihood(small_grid, monkeypatch):
    """Each chain's (N, T, K) maximises the mean log-likelihood of held-out training positives:
    whole objects, never in the candidates' fit, never a test or negative trial."""
    from collections import defaultdict

    trials, split = _hmm_data()
    lengths = dyn.GRIDS[small_grid]["length"]
    table = dyn.SequenceTable.from_trials(trials, lengths)
    fitted: dict[int, list] = defaultdict(list)
    scored: dict[int, list] = defaultdict(list)
    fit, score = dyn.HMMChain.fit, dyn.HMMChain.score

    def chain_of(seqs) -> int:
        """The chain whose sequences these are: the one table column holding every row."""
        found = [
            c
            for c in range(len(dyn.CHAINS))
            if table.seqs[seqs.shape[1]][c].shape[1:] == seqs.shape[1:]
            and all((table.seqs[seqs.shape[1]][c] == s).all(axis=(1, 2)).any() for s in seqs)
        ]
        assert len(found) == 1
        return found[0]

    def fit_spy(self, count, mean, scatter, seqs):
        fitted[chain_of(seqs)].append(seqs)
        return fit(self, count, mean, scatter, seqs)

    def score_spy(self, seqs):
        out = score(self, seqs)
        key = (self.n_states, seqs.shape[1], self.n_symbols)
        scored[chain_of(seqs)].append((key, seqs, out.mean()))
        return out

    monkeypatch.setattr(dyn.HMMChain, "fit", fit_spy)
    monkeypatch.setattr(dyn.HMMChain, "score", score_spy)
    model = dyn.DynamicFeatures(small_grid, seed=0).fit(table, split)

    n_cand = 4
    assert sorted(scored) == list(range(len(dyn.CHAINS)))
    chosen = []
    for c in range(len(dyn.CHAINS)):
        calls = scored[c]
        assert len(calls) == n_cand and len(fitted[c]) == n_cand + 1
        best = max(calls, key=lambda call: call[2])[0]
        assert model.params_[c] == best
        chosen.append(best)
        for j, ((_, T, _), seqs, _) in enumerate(calls):
            held = {table.trials[i] for i in _rows(table.seqs[T][c], seqs)}
            fit_rows = fitted[c][j]  # each candidate's fit, then the final refit
            fit_set = {table.trials[i] for i in _rows(table.seqs[T][c], fit_rows)}
            assert held and not held & fit_set
            assert held <= {t for t in split.train if split.labels[t] == 1}
            objects = {t.split("_")[1] for t in held}
            assert {t for t in split.train if t.split("_")[1] in objects} == held
    assert len(set(chosen)) > 1  # the likelihood picked different settings for different chains
