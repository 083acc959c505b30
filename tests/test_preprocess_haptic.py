"""Haptic preprocessing (METHOD.md P1-P6) on hand-built trials and a tiny synthetic file."""

from __future__ import annotations

import re

import numpy as np
import pytest
from sklearn.decomposition import PCA

from tactile_exp.data.layout import EPS, PAC_PER_ROW, FingerData, TrialData, TrialName
from tactile_exp.preprocess.haptic import (
    N_SCALAR,
    HapticArrays,
    HapticPreprocessor,
    compute_haptic_arrays,
    downsample_pac,
    load_haptic_arrays,
    resample,
    trial_signals,
)

EP_LEN = 12  # every EP this long, so steps=EP_LEN, offsets=1 reproduces the raw rows exactly
MIXING = np.random.default_rng(99).normal(size=(3, 19))  # electrodes share 3 latent factors
STEMS = [("cork_board_501", 501), ("brick_508", 508), ("loofah_503", 503)]


def make_trial(name: str, seed: int, ep_len: int | tuple[int, ...] = EP_LEN) -> TrialData:
    """A trial with 3 idle rows, then each EP separated by 2 rows of another state."""
    rng = np.random.default_rng(seed)
    lens = (ep_len,) * 4 if isinstance(ep_len, int) else ep_len
    states: list[bytes] = [b"MOVE_ARM_START_POSITION"] * 3
    for state, n in zip(EPS.values(), lens, strict=True):
        states += [state] * n + [b"OPEN_GRIPPER_BY_2CM_FAST"] * 2
    n = len(states)
    fingers = []
    for f in range(2):
        latent = rng.normal(size=(n, 3)) * 40  # electrodes: 3 latent factors + small noise
        electrodes = 3400 + 100 * f + latent @ MIXING + rng.normal(size=(n, 19))
        fingers.append(
            FingerData(
                electrodes=np.rint(electrodes).astype(np.int64),
                pac=rng.integers(2000, 2100, size=n * PAC_PER_ROW),
                pdc=rng.integers(800 - 60 * f, 1200, size=n),
                tac=rng.integers(1990, 2090, size=n),
                tdc=rng.integers(1900, 2000, size=n) + 50 * f,
            )
        )
    return TrialData(TrialName.parse(name), tuple(fingers), np.array(states, dtype="S30"))


class FakeDataset:
    """The part of the PHAC2 reader that preprocessing uses; counts the trials it reads."""

    def __init__(self, trials: list[TrialData], identity: str = "fake-1") -> None:
        self._data = {t.name.name: t for t in trials}
        self.trials = tuple(sorted(t.name for t in trials))
        self._identity = identity
        self.reads = 0

    def iter_trials(self, names=None):
        for t in self.trials if names is None else names:
            self.reads += 1
            yield self._data[t.name]

    def identity(self) -> str:
        return self._identity


def trial_names(n_per_object: int = 3) -> list[str]:
    return [f"{stem}_{t:02d}" for stem, _ in STEMS for t in range(1, n_per_object + 1)]


@pytest.fixture(scope="module")
def dataset() -> FakeDataset:
    return FakeDataset([make_trial(n, seed=i) for i, n in enumerate(trial_names())])


def train_test(ds: FakeDataset) -> tuple[list[str], list[str]]:
    names = [t.name for t in ds.trials]
    return [n for n in names if "_503_" not in n], [n for n in names if "_503_" in n]


# --------------------------------------------------------------------------- pure functions
def test_downsample_pac_methods():
    frames = np.arange(3 * PAC_PER_ROW, dtype=np.int64).reshape(3, PAC_PER_ROW)
    frames[1] = 2000 + np.where(np.arange(PAC_PER_ROW) % 2, 5, -5)  # +-5 square wave
    stream = frames.reshape(-1)
    np.testing.assert_array_equal(downsample_pac(stream, 3), frames[:, 0])
    np.testing.assert_allclose(downsample_pac(stream, 3, "mean"), frames.mean(axis=1))
    rms = downsample_pac(stream, 3, "rms")
    assert rms[1] == pytest.approx(5.0)
    assert rms[0] == pytest.approx(np.arange(PAC_PER_ROW).std())
    with pytest.raises(ValueError, match=r"expected \(44,\)"):
        downsample_pac(stream, 2)
    with pytest.raises(ValueError, match="pac_downsample"):
        downsample_pac(stream, 3, "median")


def test_resample_linear_ramp_is_exact_and_offsets_shift():
    n, steps, offsets = 37, 10, 5
    x = np.stack([np.arange(n) * 2.0 + 7, -np.arange(n) * 0.5], axis=1)
    y = resample(x, steps, offsets)
    assert y.shape == (offsets, steps, 2)
    step = (n - 1) / (steps - 1 + (offsets - 1) / offsets)  # copies jointly span rows 0..n-1
    pos = (np.arange(steps)[None, :] + np.arange(offsets)[:, None] / offsets) * step
    np.testing.assert_allclose(y[..., 0], pos * 2.0 + 7, atol=1e-9)
    np.testing.assert_allclose(y[..., 1], -pos * 0.5, atol=1e-9)
    assert y[0, 0, 0] == 7 and y[-1, -1, 0] == pytest.approx((n - 1) * 2.0 + 7)
    plain = resample(x, steps, 1)[0]
    np.testing.assert_allclose(plain[:, 0], np.linspace(0, n - 1, steps) * 2.0 + 7)


def test_resample_identity_and_upsampling():
    x = np.random.default_rng(0).normal(size=(8, 3))
    np.testing.assert_allclose(resample(x, 8, 1)[0], x)
    up = resample(x, 15, 1)[0]  # doubles the rate: midpoints between rows
    np.testing.assert_allclose(up[1::2], (x[:-1] + x[1:]) / 2)
    with pytest.raises(ValueError, match="non-empty"):
        resample(x[:0], 5)


# --------------------------------------------------------------------------- arrays + fit
def test_shapes(dataset):
    arrays = compute_haptic_arrays(dataset, steps=20, offsets=5)
    assert arrays.signals.shape == (9, 2, 5, 4, 23, 20)
    assert arrays.signals.dtype == np.float32
    np.testing.assert_array_equal(arrays.count, EP_LEN)
    prep = HapticPreprocessor(arrays).fit(train_test(dataset)[0])
    out = prep.transform([dataset.trials[0], "loofah_503_02"])
    assert out.shape == (2, 2, 5, 32, 20) and out.dtype == np.float32
    assert prep.explained_variance_ratio_.shape == (4, 4)
    assert HapticPreprocessor(arrays, n_components=2).fit(["brick_508_01"]).n_channels == 24
    assert not np.array_equal(prep.mean_[0], prep.mean_[1])  # the default: each finger its own
    for k in (1, 19):  # the ends of the allowed range
        assert HapticPreprocessor(arrays, n_components=k).n_channels == 4 * (N_SCALAR + k)


def test_stored_statistics_match_raw_rows(dataset):
    arrays = compute_haptic_arrays(dataset, steps=EP_LEN, offsets=1)
    trial = dataset._data["brick_508_02"]
    i = arrays.index(["brick_508_02"])[0]
    rows = trial.fingers[1].electrodes[trial.segment(EPS["hold"])].astype(float)
    np.testing.assert_allclose(arrays.mean[i, 1, 1, N_SCALAR:], rows.mean(axis=0))
    np.testing.assert_allclose(
        arrays.scatter[i, 1, 1, N_SCALAR:, N_SCALAR:], np.cov(rows.T, ddof=0) * len(rows)
    )
    segments = [trial.segment(state) for state in EPS.values()]
    ep_rows = np.concatenate([trial.fingers[1].electrodes[s] for s in segments]).astype(float)
    np.testing.assert_allclose(arrays.centre[i, 1, N_SCALAR:], ep_rows.mean(axis=0))
    raw = arrays.signals[i, 1, 0, 1, N_SCALAR:].T + arrays.centre[i, 1, N_SCALAR:]
    np.testing.assert_allclose(raw, rows, atol=1e-3)


@pytest.mark.parametrize("per_finger", [True, False])
def test_normaliser_uses_fitting_trials_only(dataset, per_finger):
    train, test = train_test(dataset)
    arrays = compute_haptic_arrays(dataset, steps=EP_LEN, offsets=1)
    prep = HapticPreprocessor(arrays, per_finger=per_finger).fit(train)
    out = prep.transform(train).reshape(len(train), 2, 4, 8, EP_LEN)[:, :, :, :N_SCALAR]
    if per_finger:  # each finger: mean 0, std 1 per signal over the training EP rows
        stats = out.transpose(1, 3, 0, 2, 4).reshape(2, N_SCALAR, -1)
    else:  # pooled: the statistics hold over both fingers together, not each one
        stats = out.transpose(3, 0, 1, 2, 4).reshape(N_SCALAR, -1)
        assert np.abs(out[:, 1].mean(axis=(0, 1, 3)) - out[:, 0].mean(axis=(0, 1, 3))).max() > 0.1
        np.testing.assert_array_equal(prep.mean_[0], prep.mean_[1])
    np.testing.assert_allclose(stats.mean(axis=-1), 0, atol=1e-4)
    np.testing.assert_allclose(stats.std(axis=-1), 1, atol=1e-4)
    test_out = prep.transform(test)[:, :, :, :N_SCALAR]
    assert np.abs(test_out.mean(axis=(0, 2, 3, 4))).max() > 1e-3  # unseen trials are not centred

    changed = [make_trial(n, seed=i) for i, n in enumerate(trial_names())]
    for t in changed:
        if "_503_" in t.name.name:
            t.fingers[0].pdc[:] += 500
            t.fingers[1].electrodes[:] //= 2
    other = compute_haptic_arrays(FakeDataset(changed), steps=EP_LEN, offsets=1)
    refit = HapticPreprocessor(other, per_finger=per_finger).fit(train)
    np.testing.assert_array_equal(refit.mean_, prep.mean_)
    np.testing.assert_array_equal(refit.components_, prep.components_)
    np.testing.assert_array_equal(refit.transform(train), prep.transform(train))
    assert not np.allclose(refit.transform(test), prep.transform(test))


def test_pca_matches_sklearn_on_normalised_rows(dataset):
    train, _ = train_test(dataset)
    arrays = compute_haptic_arrays(dataset, steps=EP_LEN, offsets=1)
    prep = HapticPreprocessor(arrays).fit(train)
    out = prep.transform(train).reshape(len(train), 2, 4, 8, EP_LEN)
    for e, state in enumerate(EPS.values()):
        rows, pcs = [], []
        for i, name in enumerate(train):
            trial = dataset._data[name]
            for f in range(2):
                raw = trial.fingers[f].electrodes[trial.segment(state)]
                rows.append((raw - prep.mean_[f, N_SCALAR:]) / prep.scale_[f, N_SCALAR:])
                pcs.append(out[i, f, e, N_SCALAR:].T)
        ref = PCA(n_components=4).fit(np.concatenate(rows))
        assert prep.explained_variance_ratio_[e].sum() > 0.95  # 3 latent factors + noise
        np.testing.assert_allclose(
            prep.explained_variance_ratio_[e], ref.explained_variance_ratio_, rtol=1e-6
        )
        np.testing.assert_allclose(prep.explained_variance_[e], ref.explained_variance_, rtol=1e-6)
        largest = np.abs(prep.components_[e]).argmax(axis=1)
        assert np.all(prep.components_[e][np.arange(4), largest] > 0)  # deterministic sign
        signs = np.sign(np.sum(prep.components_[e] * ref.components_, axis=1))
        np.testing.assert_allclose(prep.components_[e], ref.components_ * signs[:, None], atol=1e-8)
        expected = ref.transform(np.concatenate(rows)) * signs
        np.testing.assert_allclose(np.concatenate(pcs), expected, atol=2e-3)


def test_transform_writes_into_a_given_array_of_its_shape_only(dataset):
    """The haptic modality hands ``transform`` its instances' array (on huge pages, where a fit
    trains on them in place): the same values as a new array, any other array refused."""
    arrays = compute_haptic_arrays(dataset, steps=20, offsets=5)
    prep = HapticPreprocessor(arrays).fit(train_test(dataset)[0])
    names = [dataset.trials[0], "loofah_503_02"]
    given = np.full((2, 2, 5, 4, 8, 20), np.nan, np.float32)
    out = prep.transform(names, given)
    assert np.shares_memory(out, given)
    np.testing.assert_array_equal(out, prep.transform(names))
    for bad in (given[:1], given.astype(np.float64), given[:, :, :, :, :, ::-1]):
        with pytest.raises(ValueError, match="out must be C-contiguous float32"):
            prep.transform(names, bad)


def test_transform_commutes_with_resampling(dataset):
    """Normalising after resampling (our fast path) equals resampling normalised rows."""
    lens = (30, 55, 17, 9)
    trials = [make_trial(n, seed=i, ep_len=lens) for i, n in enumerate(trial_names(2))]
    ds = FakeDataset(trials)
    arrays = compute_haptic_arrays(ds, steps=16, offsets=3)
    prep = HapticPreprocessor(arrays, n_components=3).fit([t.name for t in ds.trials[:4]])
    trial = trials[-1]
    out = prep.transform([trial.name.name])[0].reshape(2, 3, 4, 7, 16)
    for e, state in enumerate(EPS.values()):
        raw = trial.fingers[1].electrodes[trial.segment(state)]
        z = (raw - prep.mean_[1, N_SCALAR:]) / prep.scale_[1, N_SCALAR:] - prep.pca_mean_[e]
        expected = resample(z @ prep.components_[e].T, 16, 3)  # (3, 16, 3)
        np.testing.assert_allclose(out[1, :, e, N_SCALAR:], expected.transpose(0, 2, 1), atol=2e-3)


# --------------------------------------------------------------------------- cache + settings
def test_cache_reuses_arrays_without_reading(tmp_path):
    ds = FakeDataset([make_trial(n, seed=i) for i, n in enumerate(trial_names(2))])
    first = load_haptic_arrays(ds, steps=10, offsets=2, cache_dir=tmp_path)
    assert ds.reads == 6
    second = load_haptic_arrays(ds, steps=10, offsets=2, cache_dir=tmp_path)
    assert ds.reads == 6  # served from the cache
    assert second.trials == first.trials
    for key in ("signals", "centre", "count", "mean", "scatter"):
        np.testing.assert_array_equal(getattr(second, key), getattr(first, key))
    fresh = compute_haptic_arrays(ds, steps=10, offsets=2)
    np.testing.assert_array_equal(second.signals, fresh.signals)
    load_haptic_arrays(ds, steps=10, offsets=2, pac_downsample="rms", cache_dir=tmp_path)
    assert ds.reads == 18  # other settings, other entry
    assert sorted(p.suffix for p in tmp_path.iterdir()) == [".npz", ".npz"]  # no temp files left


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"steps": 1}, "steps must be an integer >= 2"),
        ({"offsets": 0}, "offsets must be an integer >= 1"),
        ({"pac_downsample": "fft"}, "pac_downsample must be one of"),
    ],
)
def test_bad_settings_raise(tmp_path, kwargs, message):
    with pytest.raises(ValueError, match=message):
        load_haptic_arrays(FakeDataset([]), cache_dir=tmp_path, **kwargs)


def test_bad_preprocessor_use_raises(dataset):
    arrays = compute_haptic_arrays(dataset, steps=5, offsets=1)
    for k in (0, 20):
        with pytest.raises(ValueError, match="n_components must be an integer in 1..19"):
            HapticPreprocessor(arrays, n_components=k)
    prep = HapticPreprocessor(arrays)
    with pytest.raises(RuntimeError, match="^HapticPreprocessor.transform called before fit$"):
        prep.transform(["brick_508_01"])
    with pytest.raises(
        KeyError, match=r"trials not in the haptic arrays: \['no_such_trial_999_01'\]"
    ):
        prep.fit(["brick_508_01", "no_such_trial_999_01"])
    unknown = [f"ghost_999_{t:02d}" for t in range(1, 7)]
    with pytest.raises(KeyError, match=re.escape(f"{unknown[:5]} (6 total)")):
        arrays.index(unknown)
    with pytest.raises(ValueError, match="^HapticPreprocessor.fit needs at least one trial$"):
        prep.fit([])


def test_bad_trial_raises_naming_it():
    trial = make_trial("brick_508_01", seed=0)
    trial.fingers[1].tdc = trial.fingers[1].tdc[:-1]
    with pytest.raises(ValueError, match="brick_508_01 finger_1/tdc"):
        compute_haptic_arrays(FakeDataset([trial]), steps=5, offsets=1)


# --------------------------------------------------------------------------- synthetic file
@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    from tactile_exp.data.phac2 import PHAC2
    from tactile_exp.data.synthetic import SyntheticSpec, generate

    spec = SyntheticSpec(
        object_ids=(101, 508, 703), trials=2, duration_scale=0.1, views=1,
        image_width=96, image_height=64,
    )  # fmt: skip
    return PHAC2(generate(tmp_path_factory.mktemp("synthetic") / "phac2.h5", spec))


def test_synthetic_file_end_to_end(synthetic, tmp_path):
    arrays = load_haptic_arrays(synthetic, steps=30, offsets=5, cache_dir=tmp_path)
    names = [t.name for t in synthetic.trials]
    assert arrays.trials == tuple(names)
    trial = synthetic.read_trial(names[0])
    lengths = [s.stop - s.start for s in trial.ep_segments().values()]
    np.testing.assert_array_equal(arrays.count[0], lengths)
    again = load_haptic_arrays(synthetic, steps=30, offsets=5, cache_dir=tmp_path)
    np.testing.assert_array_equal(again.signals, arrays.signals)

    train = [n for n in names if "_703_" not in n]
    prep = HapticPreprocessor(arrays).fit(train)
    out = prep.transform(names)
    assert out.shape == (6, 2, 5, 32, 30) and np.isfinite(out).all()
    assert np.all(prep.explained_variance_ratio_.sum(axis=1) > 0.5)
    # EP-major channels: PDC is channel 1 of each EP's 8. The generator presses hardest in the
    # squeeze, holds at 50 %, slides at 20 % and 10 % of that travel (PHAC2_FORMAT.md §5).
    pdc = out.reshape(6, 2, 5, 4, 8, 30)[:, :, :, :, 1]  # (trial, finger, copy, EP, step)
    plateau = pdc.mean(axis=(2, 4))
    assert np.all(np.diff(plateau[..., 1:], axis=-1) < 0)  # hold > slow slide > fast slide
    assert np.all(pdc[:, :, :, 0].max(axis=(2, 3)) > plateau[..., 1])  # squeeze peak > hold


def test_short_dataset_raises():
    class Short(FakeDataset):
        def iter_trials(self, names=None):
            yield from list(super().iter_trials(names))[:-1]

    trials = [make_trial(n, seed=i) for i, n in enumerate(trial_names(1))]
    with pytest.raises(ValueError, match="yielded 2 trials, expected 3"):
        compute_haptic_arrays(Short(trials), steps=5, offsets=1)


def test_state_restores_the_fitted_preprocessing_and_rejects_bad_state(dataset):
    arrays = compute_haptic_arrays(dataset, steps=6, offsets=2)
    train, test = train_test(dataset)
    fitted = HapticPreprocessor(arrays, n_components=3).fit(train)
    state = fitted.state()
    assert sorted(state) == sorted(HapticPreprocessor.STATE)
    np.testing.assert_array_equal(state["mean"], fitted.mean_)
    np.testing.assert_array_equal(state["scale"], fitted.scale_)
    np.testing.assert_array_equal(state["components"], fitted.components_)
    np.testing.assert_array_equal(state["pca_mean"], fitted.pca_mean_)
    restored = HapticPreprocessor(arrays, n_components=3).restore(state)
    np.testing.assert_array_equal(restored.transform(test), fitted.transform(test))
    for name in ("mean", "scale", "components", "pca_mean"):
        np.testing.assert_array_equal(getattr(restored, f"{name}_"), state[name])
    for name in HapticPreprocessor.STATE:
        partial = {k: v for k, v in state.items() if k != name}
        with pytest.raises(ValueError, match=f"^haptic preprocessing state lacks '{name}'$"):
            HapticPreprocessor(arrays, n_components=3).restore(partial)
    four = HapticPreprocessor(arrays, n_components=4)  # expects 4 + 4 channels per EP
    message = r"^haptic preprocessing 'weight' has shape \(2, 4, 7, 23\), expected \(2, 4, 8, 23\) "
    with pytest.raises(ValueError, match=message + "for 4 electrode PCs$"):
        four.restore(state)
    message = r"^haptic preprocessing 'bias' has shape \(2, 4, 7\), expected \(2, 4, 8\) for 4 "
    with pytest.raises(ValueError, match=message):
        four.restore(state | {"weight": np.zeros((2, 4, 8, 23))})


def test_a_constant_signal_is_normalised_to_zero():
    trials = [make_trial(n, seed=i) for i, n in enumerate(trial_names(1))]
    for t in trials:
        for f in t.fingers:
            f.tac[:] = 2000
    arrays = compute_haptic_arrays(FakeDataset(trials), steps=5, offsets=1)
    prep = HapticPreprocessor(arrays).fit([t.name.name for t in trials])
    np.testing.assert_array_equal(prep.scale_[:, 2], 1.0)  # TAC: no division by zero
    out = prep.transform([t.name.name for t in trials]).reshape(3, 2, 1, 4, 8, 5)
    np.testing.assert_allclose(out[..., 2, :], 0.0, atol=1e-4)
    assert np.isfinite(out).all()


def test_defaults_are_the_papers_150_steps_and_5_offsets(dataset, tmp_path, monkeypatch):
    from tactile_exp.preprocess import haptic

    few = FakeDataset([dataset._data[n.name] for n in dataset.trials[:2]])
    assert compute_haptic_arrays(few).signals.shape[1:] == (2, 5, 4, 23, 150)
    monkeypatch.setattr(haptic, "default_cache_dir", lambda: tmp_path)
    assert load_haptic_arrays(few).signals.shape[1:] == (2, 5, 4, 23, 150)
    assert len(list(tmp_path.glob("haptic-*.npz"))) == 1  # in the reader's cache dir


def test_cache_entries_differ_by_offsets_and_pac_method(dataset, tmp_path):
    few = FakeDataset([dataset._data[n.name] for n in dataset.trials[:2]])
    for offsets in (1, 2):
        for method in ("subsample", "mean"):
            got = load_haptic_arrays(few, 5, offsets, method, cache_dir=tmp_path)
            want = compute_haptic_arrays(few, 5, offsets, method)
            np.testing.assert_array_equal(got.signals, want.signals)
            again = load_haptic_arrays(few, 5, offsets, method, cache_dir=tmp_path)
            np.testing.assert_array_equal(again.signals, want.signals)
    assert len(list(tmp_path.glob("haptic-*.npz"))) == 4
    trial = few._data[few.trials[0].name]
    mean_pac = downsample_pac(trial.fingers[0].pac, trial.n_rows, "mean")
    hold = trial.segment(EPS["hold"])
    got = compute_haptic_arrays(few, EP_LEN, 1, "mean")
    raw = got.signals[0, 0, 0, 1, 0] + got.centre[0, 0, 0]
    np.testing.assert_allclose(raw, mean_pac[hold], rtol=1e-6)


def test_progress_is_reported_for_large_data_sets(capsys):
    trials = [make_trial(f"brick_508_{t:02d}", seed=t, ep_len=3) for t in range(1, 22)]
    compute_haptic_arrays(FakeDataset(trials), steps=2, offsets=1)
    out, err = capsys.readouterr()
    lines = [f"haptic preprocessing: {k}/21 trials" for k in (*range(2, 21, 2), 21)]
    assert out == "" and err.splitlines() == lines
    compute_haptic_arrays(FakeDataset(trials[:19]), steps=2, offsets=1)
    assert capsys.readouterr() == ("", "")  # small data sets: silent
    empty = compute_haptic_arrays(FakeDataset([]), steps=2, offsets=1)
    assert empty.trials == () and empty.signals.shape == (0, 2, 1, 4, 23, 2)


def test_trials_out_of_order_or_extra_are_an_error():
    trials = [make_trial(n, seed=i) for i, n in enumerate(trial_names(1))]

    class Reordered(FakeDataset):
        def iter_trials(self, names=None):
            yield from reversed(list(super().iter_trials(names)))

    class Extra(FakeDataset):
        def iter_trials(self, names=None):
            yield from super().iter_trials(names)
            yield trials[0]

    names = sorted(t.name.name for t in trials)
    first, last = names[0], names[-1]
    with pytest.raises(ValueError, match=f"^dataset yielded trial {last}, expected {first}$"):
        compute_haptic_arrays(Reordered(trials), steps=2, offsets=1)
    with pytest.raises(
        ValueError, match=f"^dataset yielded trial {trials[0].name.name}, expected no more trials$"
    ):
        compute_haptic_arrays(Extra(trials), steps=2, offsets=1)


def test_wrong_shapes_name_the_array_or_signal():
    trial = make_trial("brick_508_01", seed=0)
    n = trial.n_rows
    trial.fingers[0].electrodes = trial.fingers[0].electrodes[:, :18]
    with pytest.raises(
        ValueError, match=rf"finger_0/electrodes: shape \({n}, 18\), expected {n} rows x 19$"
    ):
        compute_haptic_arrays(FakeDataset([trial]), steps=5, offsets=1)
    trial = make_trial("brick_508_01", seed=0)
    trial.fingers[1].pdc = trial.fingers[1].pdc[:-1]
    with pytest.raises(ValueError, match=rf"finger_1/pdc: shape \({n - 1},\), expected {n} rows$"):
        compute_haptic_arrays(FakeDataset([trial]), steps=5, offsets=1)
    good = compute_haptic_arrays(FakeDataset([make_trial("brick_508_01", seed=0)]), 5, 1)
    with pytest.raises(
        ValueError, match=r"^HapticArrays.count: shape \(1, 3\), expected \(1, 4\)$"
    ):
        HapticArrays(
            good.trials, good.signals, good.centre, good.count[:, :3], good.mean, good.scatter
        )


def test_resample_of_a_single_row_repeats_it():
    assert resample(np.ones((4, 2)), 3).shape == (1, 3, 2)  # one copy by default
    out = resample(np.array([[1.0, 2.0]]), 3, 2)
    np.testing.assert_array_equal(out, np.broadcast_to([1.0, 2.0], (2, 3, 2)))


def test_trial_signals_default_to_subsampled_pac():
    trial = make_trial("brick_508_01", seed=0)
    x = trial_signals(trial)
    np.testing.assert_array_equal(x[1, :, 0], trial.fingers[1].pac[::PAC_PER_ROW])
    np.testing.assert_array_equal(x[0, :, 1], trial.fingers[0].pdc)


def _tiny_file(path, seed: int):
    from tactile_exp.data.synthetic import SyntheticSpec, generate

    spec = SyntheticSpec(seed=seed, object_ids=(101, 201), trials=1, duration_scale=0.05, views=0)
    return generate(path, spec)


def test_haptic_cache_is_invalidated_by_a_changed_data_file(tmp_path):
    import shutil

    from tactile_exp.data.phac2 import PHAC2

    path, cache = tmp_path / "data.h5", tmp_path / "cache"
    first = load_haptic_arrays(PHAC2(_tiny_file(path, 0)), steps=8, offsets=1, cache_dir=cache)
    other = tmp_path / "other.h5"
    _tiny_file(other, 1)
    shutil.copyfile(other, path)  # same name, new content
    again = load_haptic_arrays(PHAC2(path), steps=8, offsets=1, cache_dir=cache)
    fresh = compute_haptic_arrays(PHAC2(path), steps=8, offsets=1)
    np.testing.assert_array_equal(again.signals, fresh.signals)
    assert not np.array_equal(again.signals, first.signals)
    coarser = load_haptic_arrays(PHAC2(path), steps=6, offsets=1, cache_dir=cache)
    assert coarser.steps == 6  # changed settings: a new entry, not the steps=8 one
    assert len(list(cache.glob("haptic-*.npz"))) == 3
