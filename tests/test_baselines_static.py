"""Static features (BASELINES.md §1.2): each number against a hand-computed value."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from baselines_fixture import make_trial
from baselines_oracles import pc_polyfit
from scipy import signal
from threadpoolctl import threadpool_info, threadpool_limits

from tactile_exp.baselines import static as st
from tactile_exp.data.layout import PAC_RATE_HZ


def test_steepest_rise_of_a_step_is_the_largest_smoothing_weight():
    x = np.r_[np.zeros(100), np.full(100, 3.0)]
    # smoothing a step of height 3 with normalised Hanning weights w/sum(w): each difference
    # is 3 w_k / sum(w); np.hanning(50) sums to 24.5 and peaks at 0.5 - 0.5 cos(2 pi 24 / 49)
    expected = 3 * (0.5 - 0.5 * np.cos(2 * np.pi * 24 / 49)) / 24.5
    assert st.pdc_steepest_rise(x) == pytest.approx(expected, rel=1e-12)


def test_area_and_max_of_a_ramp():
    x = 2.0 * np.arange(11)  # 0, 2, ..., 20 over 10 unit steps: triangle area 10 * 20 / 2
    assert st.area(x) == pytest.approx(100.0)
    assert st.maximum(x) == 20.0


def _tone(freq: float, rows: int = 400) -> np.ndarray:
    t = np.arange(rows * 22) / PAC_RATE_HZ
    return 500 * np.sin(2 * np.pi * freq * t)


@pytest.mark.parametrize("f_max", [st.AUTHORS_F_MAX, None])
def test_spectral_centroid_of_a_50hz_tone(f_max):
    freq, spec = st.pac_spectrum(_tone(50.0), f_max)
    energy, sc, sv, ss, sk = st.spectral_features(freq, spec)
    assert sc == pytest.approx(50.0, abs=1.0)
    assert sv < 100  # the line stays narrow: a spread of under 10 Hz
    assert energy > 0
    assert freq[-1] <= (f_max or PAC_RATE_HZ / 2)


def test_the_100hz_cut_hides_a_300hz_tone():
    full = st.spectral_features(*st.pac_spectrum(_tone(300.0), None))
    cut = st.spectral_features(*st.pac_spectrum(_tone(300.0), st.AUTHORS_F_MAX))
    assert full[1] == pytest.approx(300.0, abs=1.0)
    assert cut[1] < 100.0
    assert cut[0] < 1e-3 * full[0]  # almost no energy left below 100 Hz


def _reference_spectrum(stream: np.ndarray, f_max: float | None) -> tuple[np.ndarray, np.ndarray]:
    """The definition step by step: full complex FFT, filtfilt over all L bins, then the cut."""
    filtered = signal.lfilter(st.PAC_FIR, 1.0, stream)
    filtered = filtered - filtered.mean()
    n = len(filtered)
    power = np.abs(np.fft.fft(filtered) / n) ** 2
    window = st.SPECTRUM_WINDOW / st.SPECTRUM_WINDOW.sum()
    smooth = signal.filtfilt(window, [1.0], power)
    freq = PAC_RATE_HZ / 2 * np.linspace(0.0, 1.0, round(n / 2) + 1)
    keep = len(freq) if f_max is None else int(np.searchsorted(freq, f_max, side="right"))
    return freq[:keep], smooth[:keep]


@pytest.mark.parametrize("length", [151, 152, 3001, 22 * 517])
@pytest.mark.parametrize("f_max", [st.AUTHORS_F_MAX, None])
def test_spectrum_matches_the_full_length_definition(length, f_max):
    stream = np.random.default_rng(length).normal(0.0, 40.0, length).cumsum()
    freq, spec = st.pac_spectrum(stream, f_max)
    ref_freq, ref_spec = _reference_spectrum(stream, f_max)
    np.testing.assert_array_equal(freq, ref_freq)
    np.testing.assert_allclose(spec, ref_spec, rtol=1e-10, atol=1e-12 * ref_spec.max())


def test_exp_fit_sse_is_the_least_squares_residual():
    rng = np.random.default_rng(3)
    t = np.arange(1.0, 301)
    x = 2.0 + 4.0 * np.exp(-t / 25.0) + rng.normal(0.0, 0.1, len(t))
    log_tau = np.log([0.1, 3.0, 25.0, 400.0, 3e5])
    expected = []
    for g in log_tau:
        basis = np.column_stack([np.ones_like(t), np.exp(-t / np.exp(g))])
        coef = np.linalg.lstsq(basis, x, rcond=None)[0]
        expected.append(np.sum((basis @ coef - x) ** 2))
    np.testing.assert_allclose(st.exp_fit_sse(log_tau, t, x), expected, rtol=1e-9)
    assert st.exp_fit_sse(log_tau[2], t, x) == pytest.approx(expected[2], rel=1e-9)


def test_noisy_time_constant_is_the_least_squares_optimum():
    rng = np.random.default_rng(4)
    t = np.arange(1.0, 801)
    x = -1.0 + 6.0 * np.exp(-t / 90.0) + rng.normal(0.0, 0.5, len(t))
    tau = st.tdc_time_constant(x)
    dense = np.linspace(np.log(tau) - 0.05, np.log(tau) + 0.05, 2001)
    best = np.exp(dense[np.argmin(st.exp_fit_sse(dense, t, x))])
    assert tau == pytest.approx(best, rel=1e-4)
    assert tau == pytest.approx(90.0, rel=0.2)


def test_exponential_time_constant():
    t = np.arange(1.0, 501)
    assert st.tdc_time_constant(3.0 - 5.0 * np.exp(-t / 37.0)) == pytest.approx(37.0, rel=1e-4)
    assert st.tdc_time_constant(1.0 + 2.0 * np.exp(-t / 120.0)) == pytest.approx(120.0, rel=1e-4)


def test_polyfit_recovers_a_known_polynomial():
    coef = np.array([4.0, -0.3, 2e-3, -1e-5, 3e-8, -2e-11])
    t = np.arange(1.0, 301)
    y = sum(c * t**k for k, c in enumerate(coef))
    np.testing.assert_allclose(st.polyfit_coefficients(y), coef, rtol=1e-6, atol=1e-12)


def test_pc_polyfit_of_rank_one_electrodes():
    t = np.arange(1.0, 201)
    p = np.array([1.0, 0.5, -0.01, 0, 0, 0])
    signal = p[0] + p[1] * t + p[2] * t**2
    v = np.linspace(-1.0, 2.0, 38)  # the only direction the electrodes move in
    x = 7.0 + signal[:, None] * v[None, :]
    stats = st.electrode_stats(x, "test")
    axes = st.principal_axes(stats.scatter, 4)
    coef = pc_polyfit(stats.poly, stats.mean, axes)  # the oracle of static_matrix's fits
    norm = np.linalg.norm(v)  # PC1 = (x - mean) @ v/|v| = |v| (signal - mean(signal))
    expected = norm * np.r_[p[0] - signal.mean(), p[1:]]
    np.testing.assert_allclose(coef[0], expected, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(coef[1:], 0.0, atol=1e-6)  # no variance left for PCs 2-4


def test_interleaved_polyfit_order():
    coef = np.arange(24.0).reshape(4, 6)  # PC j, coefficient k -> 6 j + k
    assert list(st.order_polyfit(coef, interleave=False)) == list(range(24))
    # blocks (PC1, PC2) = 0..11 and (PC3, PC4) = 12..23, interleaved
    assert list(st.order_polyfit(coef, interleave=True)[:6]) == [0, 12, 1, 13, 2, 14]
    names = st.polyfit_names(interleave=True)
    assert names[:3] == ["pc1_c0", "pc3_c0", "pc1_c1"]


def _vector(trial, **kw) -> tuple[np.ndarray, list[str]]:
    table = st.StaticTable.from_records(["t"], [st.trial_static(trial, **kw)])
    features = st.StaticFeatures()
    return features.transform(table, ["t"])[0], features.feature_names(table)


def test_full_vector_has_188_named_finite_features_invariant_to_offsets():
    x, names = _vector(make_trial())
    assert x.shape == (188,) and len(names) == 188 and np.isfinite(x).all()
    assert names[0] == "squeeze/pdc_rise_f0" and names[47] == "hold/pdc_rise_f0"
    shifted, _ = _vector(make_trial(offset=37.0))  # the baseline removes a constant shift
    np.testing.assert_allclose(shifted, x, rtol=1e-6, atol=1e-6)


def test_short_ep_warns_and_fills_without_nan():
    trial = make_trial(lengths=(120, 200, 100, 5))  # fast slide: 5 rows
    with pytest.warns(st.FeatureWarning, match="fast_slide.*pdc_rise_f0 filled with 0.0"):
        x, names = _vector(trial)
    assert np.isfinite(x).all()
    ep = {n: v for n, v in zip(names, x, strict=True) if n.startswith("fast_slide/")}
    assert ep["fast_slide/pdc_rise_f0"] == st.FILL and ep["fast_slide/pac_sc_f1"] == st.FILL
    assert ep["fast_slide/pc1_c0"] == st.FILL  # 5 rows cannot fit 6 coefficients
    assert ep["fast_slide/pdc_max_f0"] != st.FILL  # features that need few rows are kept


def test_fills_are_collected_instead_of_warned():
    fills: list[str] = []
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        st.trial_static(make_trial(lengths=(120, 200, 100, 5)), fills=fills)
    assert fills and all("fast_slide" in f for f in fills)
    with pytest.warns(st.FeatureWarning, match=r"pdc_rise_f0 x1"):
        st.warn_fills(fills)


def test_missing_gripper_and_transforms_shrink_the_vector():
    with pytest.warns(st.FeatureWarning, match="no gripper channel"):
        x, names = _vector(make_trial(gripper=False))
    assert len(x) == len(names) == 188 - 4 * 2
    assert not any("gripper" in n for n in names)
    with pytest.warns(st.FeatureWarning, match="no gripper or transforms"):
        x, names = _vector(make_trial(gripper=False, translation=False))
    assert len(names) == 188 - 4 * 3


def test_shared_pca_is_fitted_on_training_trials_only():
    records = [st.trial_static(make_trial(seed=s)) for s in range(3)]
    table = st.StaticTable.from_records(["a", "b", "c"], records)
    features = st.StaticFeatures(per_trial_pca=False, interleave=False).fit(table, ["a", "b"])
    before = features.transform(table, ["a", "c"])
    table.scatter[2] *= 50.0  # a non-training trial changes: the fitted axes must not
    table.mean[2] += 3.0
    refit = st.StaticFeatures(per_trial_pca=False, interleave=False).fit(table, ["a", "b"])
    np.testing.assert_array_equal(refit.transform(table, ["a"]), before[:1])
    assert before.shape == (2, 188) and np.isfinite(before).all()
    with pytest.raises(RuntimeError, match="call fit"):
        st.StaticFeatures(per_trial_pca=False).transform(table, ["a"])
    with pytest.raises(KeyError, match="unknown trial"):
        features.transform(table, ["zzz"])


def test_trial_static_restores_the_blas_threads():
    with threadpool_limits(2, user_api="blas"):  # whatever the test process's own count
        before = [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]
        st.trial_static(make_trial())
        after = [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]
    assert after == before and set(before) == {2}
