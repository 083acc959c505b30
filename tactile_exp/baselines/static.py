"""Chu et al.'s hand-designed static features: 47 numbers per EP, 188 per trial (BASELINES.md §1.2).

Each feature is one small pure function of a baseline-subtracted EP signal. A trial is reduced
once to a `TrialStatic` record: the 23 split-independent numbers per EP, plus the sufficient
statistics of its electrodes (row count, mean, scatter matrix, degree-5 polynomial fit of each
raw electrode column). Because a polynomial least-squares fit is linear in the signal, the
polyfit of any PCA projection follows from those statistics, so the authors' per-trial PCA and
the corrected PCA fitted on training trials are both cheap at split time (`StaticFeatures`).

Authors' quirks, kept by default (``faithful``): the PAC spectrum is cut at 100 Hz, the
electrode PCA is fitted per trial-EP, and the polyfit coefficients are interleaved. Fits are
solved to the optimum of the authors' objectives (exact least squares for the polynomial,
bounded search over the time constant for the exponential) where the authors ran Nelder-Mead
from a fixed start, which stops before convergence on the t^5 terms.

Speed: a trial's linear algebra is small (EPs of ~100-3000 rows), where multi-threaded BLAS
only adds synchronisation (tens of ms per call on a loaded 2-core machine), so `trial_static`
runs with one BLAS thread.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.polynomial import polynomial as npoly
from scipy import optimize, signal

from tactile_exp.data.layout import BASELINE_STATE, EPS, PAC_RATE_HZ, TrialData
from tactile_exp.runtime.blas import one_blas_thread

PHASES: tuple[str, ...] = tuple(EPS)  # squeeze, hold, slow_slide, fast_slide (concat order)
RISE_WINDOW = 50  # Hanning taps for the pdc smoothing
PAC_FIR = signal.firwin(67, [20.0, 700.0], pass_zero=False, fs=PAC_RATE_HZ)  # = the authors' taps
SPECTRUM_WINDOW = signal.get_window("barthann", 50, fftbins=False)
# filtfilt with this FIR: output bin k depends on bins <= k + 2 (taps - 1) (and the start padding)
SMOOTH_MARGIN = 2 * len(SPECTRUM_WINDOW)
AUTHORS_F_MAX = 100.0  # Hz: the authors keep only spectrum bins up to here
POLY_DEGREE = 5
N_ELECTRODE_PCS = 4
N_ELECTRODES = 38  # both fingers side by side
FILL = 0.0  # value of a feature whose EP is too short or degenerate (the flat-signal value)

PAC_NAMES = ("pac_energy", "pac_sc", "pac_sv", "pac_ss", "pac_sk")
FINGER_FEATURES = ("pdc_rise", "pdc_area", "pdc_max", *PAC_NAMES, "tac_area", "tdc_tau")
GRIPPER_NAMES = ("gripper_min", "gripper_mean")
TRANSFORM_NAMES = ("transform_distance",)


class FeatureWarning(UserWarning):
    """A feature could not be computed as defined and was filled (see `FILL`)."""


class TooShort(ValueError):
    """The signal has too few samples (or no energy) for the feature's definition."""


# ------------------------------------------------------------------ one pure function per feature
def pdc_steepest_rise(x: np.ndarray, window: int = RISE_WINDOW) -> float:
    """Max first difference of pdc after normalised Hanning smoothing with mirrored ends."""
    if len(x) < window:
        raise TooShort(f"needs {window} rows for the {window}-tap smoothing, has {len(x)}")
    padded = np.r_[x[window - 1 : 0 : -1], x, x[-1:-window:-1]]
    w = np.hanning(window)
    smooth = np.convolve(w / w.sum(), padded, mode="valid")
    return float(np.max(np.diff(smooth)))


def area(x: np.ndarray) -> float:
    """Trapezoidal integral over the sample index (unit spacing, as the authors)."""
    if len(x) < 1:
        raise TooShort("needs at least 1 row")
    return float(np.trapezoid(x))


def maximum(x: np.ndarray) -> float:
    if len(x) < 1:
        raise TooShort("needs at least 1 row")
    return float(np.max(x))


def pac_spectrum(stream: np.ndarray, f_max: float | None) -> tuple[np.ndarray, np.ndarray]:
    """(freq, smoothed power) of a 2200 Hz PAC stream: FIR, FFT/L, Bartlett-Hann filtfilt.

    ``f_max`` keeps bins up to that frequency (the authors: 100 Hz); ``None`` keeps 0..1100 Hz.
    The full two-sided power spectrum is smoothed, as the authors; because the smoothing is a
    short FIR, only the bins up to the kept ones plus `SMOOTH_MARGIN` are needed (same values),
    and those come from a real FFT (the upper half mirrors the lower).
    """
    min_len = 3 * len(SPECTRUM_WINDOW) + 1  # filtfilt's default padding
    if len(stream) < min_len:
        raise TooShort(f"needs {min_len} PAC samples for the spectrum smoothing, has {len(stream)}")
    filtered = signal.lfilter(PAC_FIR, 1.0, stream)
    filtered -= filtered.mean()
    n = len(filtered)
    freq = PAC_RATE_HZ / 2 * np.linspace(0.0, 1.0, round(n / 2) + 1)
    keep = len(freq) if f_max is None else int(np.searchsorted(freq, f_max, side="right"))
    half = np.abs(np.fft.rfft(filtered) / n) ** 2  # bins 0..n//2; bin n-k equals bin k
    stop = max(keep + SMOOTH_MARGIN, min_len)  # filtfilt needs min_len too
    power = np.concatenate([half, half[1 : n - len(half) + 1][::-1]])[:stop]
    smooth = signal.filtfilt(SPECTRUM_WINDOW / SPECTRUM_WINDOW.sum(), [1.0], power)
    return freq[:keep], smooth[:keep]


def spectral_features(freq: np.ndarray, spectrum: np.ndarray) -> tuple[float, ...]:
    """(energy, centroid, variance, skewness, excess kurtosis), moments weighted by the spectrum."""
    total = spectrum.sum()
    if len(freq) < 2 or not total > 0:
        raise TooShort("spectrum has fewer than 2 bins or no energy")
    energy = np.trapezoid(spectrum, freq)
    sc = (spectrum * freq).sum() / total
    sv = (spectrum * (freq - sc) ** 2).sum() / total
    if not sv > 0:
        raise TooShort("spectrum has no spread")
    ss = (spectrum * (freq - sc) ** 3).sum() / total / sv**1.5
    sk = (spectrum * (freq - sc) ** 4).sum() / total / sv**2 - 3.0
    return float(energy), float(sc), float(sv), float(ss), float(sk)


def exp_fit_sse(log_tau: np.ndarray | float, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Residual sum of squares of the least-squares a + b exp(-t/tau), for each tau = e^log_tau.

    Given tau the fit is the projection of x on span{1, e}: with centred e_c and x_c, b is
    <e_c, x_c>/<e_c, e_c> and the residual is x_c - b e_c (a closed form, vectorised over tau).
    """
    e = np.exp(-t / np.exp(np.asarray(log_tau, dtype=float))[..., None])
    e -= e.mean(axis=-1, keepdims=True)
    xc = x - x.mean()
    norm = np.einsum("...n,...n->...", e, e)
    b = np.divide(e @ xc, norm, out=np.zeros_like(norm), where=norm > 0)
    r = xc - b[..., None] * e
    return np.einsum("...n,...n->...", r, r)


def tdc_time_constant(x: np.ndarray) -> float:
    """tau of the least-squares fit x(t) ~ a + b exp(-t/tau), t = 1..n samples (only tau is kept).

    a and b are linear given tau, so tau is found by a log grid plus bounded Brent refinement on
    [0.1, 1000 n] samples: the authors' objective, without Nelder-Mead's dependence on its start.
    """
    n = len(x)
    if n < 4:
        raise TooShort(f"needs 4 rows for a 3-parameter fit, has {n}")
    t = np.arange(1.0, n + 1)
    grid = np.linspace(np.log(0.1), np.log(1000.0 * n), 41)
    sse = exp_fit_sse(grid, t, x)
    i = int(np.argmin(sse))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    best = optimize.minimize_scalar(
        lambda g: float(exp_fit_sse(g, t, x)), bounds=(lo, hi), method="bounded"
    )
    return float(np.exp(best.x if best.fun <= sse[i] else grid[i]))


def gripper_stats(position: np.ndarray) -> tuple[float, float]:
    """(min, mean) gripper aperture over the EP."""
    if len(position) < 1:
        raise TooShort("needs at least 1 row")
    return float(np.min(position)), float(np.mean(position))


def hand_descent(translation: np.ndarray) -> float:
    """z at the EP's first row minus min z over the EP: how far the hand went down."""
    if len(translation) < 1:
        raise TooShort("needs at least 1 row")
    z = translation[:, 2]
    return float(z[0] - z.min())


def polyfit_coefficients(y: np.ndarray, degree: int = POLY_DEGREE) -> np.ndarray:
    """Least-squares coefficients c0..c_deg of y(t) ~ sum c_k t^k, t = 1..n; y (n,) or (n, d)."""
    if len(y) < degree + 1:
        raise TooShort(f"needs {degree + 1} rows for a degree-{degree} fit, has {len(y)}")
    return npoly.polyfit(np.arange(1.0, len(y) + 1), y, degree)


def principal_axes(scatter: np.ndarray, k: int) -> np.ndarray:
    """(..., d, k) top-k eigenvectors of (a stack of) scatter matrices, each signed so its
    largest loading is > 0."""
    values, vectors = np.linalg.eigh(scatter)
    order = np.argsort(values, axis=-1)[..., ::-1][..., :k]
    axes = np.take_along_axis(vectors, order[..., None, :], axis=-1)
    top = np.argmax(np.abs(axes), axis=-2)[..., None, :]
    signs = np.take_along_axis(axes, top, axis=-2)
    return axes * np.where(signs == 0, 1.0, np.sign(signs))


def pool_moments(
    count: np.ndarray, mean: np.ndarray, scatter: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and centred scatter of the union of row sets given their (count, mean, scatter)."""
    total = max(float(count.sum()), 1.0)
    pooled = (count[:, None] * mean).sum(axis=0) / total
    dev = mean - pooled
    return pooled, scatter.sum(axis=0) + np.einsum("n,ni,nj->ij", count, dev, dev)


def order_polyfit(coef: np.ndarray, interleave: bool) -> np.ndarray:
    """Flatten (4, 6) PC coefficients: plain PC1..PC4, or the authors' two interleaved 12-blocks."""
    if not interleave:
        return coef.reshape(-1)
    blocks = coef.reshape(2, -1)  # (PC1, PC2) and (PC3, PC4)
    return blocks.T.reshape(-1)


def polyfit_names(interleave: bool) -> list[str]:
    grid = np.array(
        [[f"pc{j + 1}_c{k}" for k in range(POLY_DEGREE + 1)] for j in range(N_ELECTRODE_PCS)]
    )
    return list(order_polyfit(grid, interleave))


# ------------------------------------------------------------------ one trial
@dataclass
class ElectrodeStats:
    """What the electrode polyfit needs of one trial-EP, whatever PCA is applied later."""

    count: int
    mean: np.ndarray  # (38,)
    scatter: np.ndarray  # (38, 38) centred sum of outer products
    poly: np.ndarray  # (6, 38) polyfit of each baseline-subtracted column


@dataclass
class TrialStatic:
    """Split-independent static numbers of one trial."""

    names: list[str]  # per-EP names of ``base`` columns
    base: np.ndarray  # (4, len(names))
    electrodes: list[ElectrodeStats]  # one per EP


def _report(note: str, fills: list[str] | None) -> None:
    if fills is None:
        warnings.warn(note, FeatureWarning, 4)
    else:
        fills.append(note)


def _guarded(
    values: dict[str, float], names: Sequence[str], fn, where: str, fills: list[str] | None
) -> None:
    """Store fn()'s numbers under ``names``; on TooShort or non-finite output fill and report.

    A fill is a warning, or a line appended to ``fills`` when the caller summarises many trials.
    """
    try:
        out = fn()
        out = out if isinstance(out, tuple) else (float(out),)
        if not np.all(np.isfinite(out)):
            raise TooShort("non-finite result")
    except TooShort as e:
        _report(f"{where}: {'/'.join(names)} filled with {FILL}: {e}", fills)
        out = (FILL,) * len(names)
    values.update(zip(names, out, strict=True))


def warn_fills(fills: Sequence[str]) -> None:
    """One warning summarising the fills of many trials (count per feature, first example)."""
    if not fills:
        return
    per: dict[str, int] = {}
    for note in fills:
        feature = note.split(": ")[1].split(" filled")[0]
        per[feature] = per.get(feature, 0) + 1
    counts = ", ".join(f"{k} x{v}" for k, v in sorted(per.items()))
    warnings.warn(
        f"{len(fills)} static feature value(s) filled with {FILL} (EP too short or degenerate): "
        f"{counts}; e.g. {fills[0]}",
        FeatureWarning,
        2,
    )


def electrode_stats(x: np.ndarray, where: str, fills: list[str] | None = None) -> ElectrodeStats:
    count = len(x)
    mean = x.mean(axis=0) if count else np.zeros(x.shape[1])
    centred = x - mean
    try:
        poly = polyfit_coefficients(x)
    except TooShort as e:
        _report(f"{where}: electrode_polyfit filled with {FILL}: {e}", fills)
        poly = np.full((POLY_DEGREE + 1, x.shape[1]), FILL)
    return ElectrodeStats(count, mean, centred.T @ centred, poly)


def trial_static(
    trial: TrialData, f_max: float | None = AUTHORS_F_MAX, fills: list[str] | None = None
) -> TrialStatic:
    """The 23 base numbers per EP (gripper/transform ones only when present) and electrode stats.

    Short EPs give `FILL` values, reported as warnings or appended to ``fills``. Signals are
    baseline-subtracted with the mean of the trial's MOVE_ARM_START_POSITION rows (gripper
    and transform signals are not, as the authors).
    """
    with one_blas_thread():  # see the module docstring
        rest = trial.segment(BASELINE_STATE)
        fingers = []
        for f in trial.fingers:
            pac = f.pac.reshape(trial.n_rows, -1).astype(float)
            fingers.append(
                {
                    "pdc": f.pdc - f.pdc[rest].mean(),
                    "pac": pac - pac[rest].mean(axis=0),
                    "tac": f.tac - f.tac[rest].mean(),
                    "tdc": f.tdc - f.tdc[rest].mean(),
                }
            )
        electrodes = np.hstack([f.electrodes for f in trial.fingers]).astype(float)
        electrodes -= electrodes[rest].mean(axis=0)
        grip = trial.gripper.get("joint_position")
        names: list[str] | None = None
        rows, stats = [], []
        for ep, rows_slice in trial.ep_segments().items():
            where = f"trial {trial.name.name}, EP {ep} ({rows_slice.stop - rows_slice.start} rows)"
            values: dict[str, float] = {}
            for i, fd in enumerate(fingers):
                pdc, tac, tdc = fd["pdc"][rows_slice], fd["tac"][rows_slice], fd["tdc"][rows_slice]
                stream = fd["pac"][rows_slice].reshape(-1)
                f = f"_f{i}"
                _guarded(values, ["pdc_rise" + f], lambda x=pdc: pdc_steepest_rise(x), where, fills)
                _guarded(values, ["pdc_area" + f], lambda x=pdc: area(x), where, fills)
                _guarded(values, ["pdc_max" + f], lambda x=pdc: maximum(x), where, fills)
                _guarded(
                    values,
                    [n + f for n in PAC_NAMES],
                    lambda s=stream: spectral_features(*pac_spectrum(s, f_max)),
                    where,
                    fills,
                )
                _guarded(values, ["tac_area" + f], lambda x=tac: area(x), where, fills)
                _guarded(values, ["tdc_tau" + f], lambda x=tdc: tdc_time_constant(x), where, fills)
            if grip is not None:
                g = grip[rows_slice]
                _guarded(values, GRIPPER_NAMES, lambda g=g: gripper_stats(g), where, fills)
            if trial.translation is not None:
                tr = trial.translation[rows_slice]
                _guarded(values, TRANSFORM_NAMES, lambda x=tr: hand_descent(x), where, fills)
            order = [f"{n}_f{i}" for n in FINGER_FEATURES for i in (0, 1)]
            order += [n for n in (*GRIPPER_NAMES, *TRANSFORM_NAMES) if n in values]
            names = order
            rows.append([values[n] for n in order])
            stats.append(electrode_stats(electrodes[rows_slice], where, fills))
        absent = {"gripper": grip is None, "transforms": trial.translation is None}
        missing = [label for label, gone in absent.items() if gone]
        if missing and fills is None:
            warnings.warn(
                f"trial {trial.name.name}: no {' or '.join(missing)} channel; "
                f"those static features are left out",
                FeatureWarning,
                2,
            )
        return TrialStatic(names or [], np.asarray(rows, dtype=float), stats)


# ------------------------------------------------------------------ the data set and a split
@dataclass
class StaticTable:
    """Static records of many trials as arrays (what the disk cache stores)."""

    trials: list[str]
    names: list[str]  # per-EP base names common to all trials
    base: np.ndarray  # (n, 4, B)
    count: np.ndarray  # (n, 4)
    mean: np.ndarray  # (n, 4, 38)
    scatter: np.ndarray  # (n, 4, 38, 38)
    poly: np.ndarray  # (n, 4, 6, 38)
    # split-independent results derived from the (never mutated) arrays, computed once
    derived: dict[str, np.ndarray] = field(default_factory=dict, repr=False, compare=False)

    KEYS = ("trials", "names", "base", "count", "mean", "scatter", "poly")

    @classmethod
    def from_records(cls, trials: Sequence[str], records: Sequence[TrialStatic]) -> StaticTable:
        """Stack records; base features absent in some trial are dropped with a warning."""
        common = [n for n in records[0].names if all(n in r.names for r in records)]
        dropped = sorted({n for r in records for n in r.names} - set(common))
        if dropped:
            warnings.warn(
                f"static features {dropped} are missing in some trials and left out",
                FeatureWarning,
                2,
            )
        base = np.stack([r.base[:, [r.names.index(n) for n in common]] for r in records])

        def field(name: str) -> np.ndarray:
            return np.array([[getattr(s, name) for s in r.electrodes] for r in records])

        return cls(
            list(trials),
            common,
            base,
            field("count"),
            field("mean"),
            field("scatter"),
            field("poly"),
        )

    def arrays(self) -> dict[str, np.ndarray]:
        return {
            "trials": np.array(self.trials),
            "names": np.array(self.names),
            **{k: getattr(self, k) for k in ("base", "count", "mean", "scatter", "poly")},
        }

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray]) -> StaticTable:
        return cls(
            [str(t) for t in a["trials"]],
            [str(n) for n in a["names"]],
            *(a[k] for k in ("base", "count", "mean", "scatter", "poly")),
        )

    def index(self, trials: Sequence[str]) -> np.ndarray:
        pos = {t: i for i, t in enumerate(self.trials)}
        unknown = [t for t in trials if t not in pos]
        if unknown:
            raise KeyError(f"static features: unknown trial(s) {unknown[:5]}")
        return np.array([pos[t] for t in trials], dtype=int)


class StaticFeatures:
    """The 4 x 47 static vector of trials; ``fit`` matters only when the PCA is shared.

    per_trial_pca=True (the authors): a new electrode PCA(4) for every trial-EP.
    per_trial_pca=False: one PCA(4) per EP fitted on the training trials' electrode rows.
    """

    def __init__(self, per_trial_pca: bool = True, interleave: bool = True) -> None:
        self.per_trial_pca = per_trial_pca
        self.interleave = interleave
        self.axes_: list[tuple[np.ndarray, np.ndarray]] | None = None  # per EP: (mean, axes)

    def fit(self, table: StaticTable, train: Sequence[str]) -> StaticFeatures:
        idx = table.index(train)
        self.axes_ = []
        for e in range(len(PHASES)):
            moments = table.count[idx, e], table.mean[idx, e], table.scatter[idx, e]
            mean, scatter = pool_moments(*moments)
            self.axes_.append((mean, principal_axes(scatter, N_ELECTRODE_PCS)))
        return self

    def arrays(self) -> dict[str, np.ndarray]:
        """The fitted per-EP PCA (mean, axes) as named arrays (kept with a stored model)."""
        out = {}
        for e, (mean, axes) in enumerate(self.axes_ or []):
            out[f"mean{e}"], out[f"axes{e}"] = mean, axes
        return out

    def load_arrays(self, a: dict[str, np.ndarray]) -> StaticFeatures:
        """Restore the fitted PCA saved by ``arrays`` (in place of ``fit``)."""
        self.axes_ = [(a[f"mean{e}"], a[f"axes{e}"]) for e in range(len(PHASES))]
        return self

    def feature_names(self, table: StaticTable) -> list[str]:
        per_ep = [*table.names, *polyfit_names(self.interleave)]
        return [f"{ep}/{n}" for ep in PHASES for n in per_ep]

    def transform(self, table: StaticTable, trials: Sequence[str]) -> np.ndarray:
        if not self.per_trial_pca and self.axes_ is None:
            raise RuntimeError("StaticFeatures(per_trial_pca=False): call fit before transform")
        idx = table.index(trials)
        if not self.per_trial_pca:
            return static_matrix(table, idx, self.interleave, self.axes_)
        key = f"per_trial_pca/interleave={self.interleave}"  # the same for every split
        if key not in table.derived:
            every = np.arange(len(table.trials))
            table.derived[key] = static_matrix(table, every, self.interleave)
        return table.derived[key][idx]


def static_matrix(
    table: StaticTable,
    idx: np.ndarray,
    interleave: bool,
    shared: list[tuple[np.ndarray, np.ndarray]] | None = None,
) -> np.ndarray:
    """(len(idx), 4 x 47) static vectors of table rows ``idx``, all trials at once.

    ``shared``: per EP the (mean, axes) of a PCA fitted on training trials; None: each trial-EP's
    own PCA (the authors'), from one batched eigendecomposition on one BLAS thread (threads only
    add overhead on 38 x 38 matrices: ~7x slower on the loaded 2-core machine).
    """
    n, parts = len(idx), []
    with one_blas_thread():
        for e in range(len(PHASES)):
            if shared is None:
                mean = table.mean[idx, e][:, None, :]  # (n, 1, 38)
                axes = principal_axes(table.scatter[idx, e], N_ELECTRODE_PCS)  # (n, 38, 4)
            else:
                mean, axes = shared[e]
            coef = table.poly[idx, e] @ axes  # (n, 6, 4): a fit is linear in the signal
            coef[:, 0] -= (mean @ axes).reshape(-1, N_ELECTRODE_PCS)  # the centring
            coef[table.count[idx, e] < POLY_DEGREE + 1] = FILL  # too short: the fit was filled
            coef = coef.transpose(0, 2, 1)  # (n, PC, degree)
            if interleave:  # as `order_polyfit`: (PC1, PC2) and (PC3, PC4) blocks interleaved
                coef = coef.reshape(n, 2, -1).transpose(0, 2, 1)
            parts += [table.base[idx, e], coef.reshape(n, -1)]
    return np.concatenate(parts, axis=1).astype(float)
