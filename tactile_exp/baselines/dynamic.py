"""Chu et al.'s dynamic features: per adjective, 16 discrete HMM chains (BASELINES.md §2).

A chain (EP x sensor) is PCA(97% variance) -> resample each trial to T steps -> k-means into K
symbols -> a discrete HMM with N states, trained on positive trials only; a trial's feature is
its log-likelihood under the chain (not length-normalised, as the authors). The HMM is
`hmmlearn.hmm.CategoricalHMM`'s EM (``fit_categorical_hmm``: same initial draws, updates and
stopping rule, equal to float rounding, tested), vectorised over the sequences, which all have
length T: hmmlearn loops over them in Python, ~90% of a chain's fit time (5x slower).

PCA and linear resampling are both linear, so projecting after resampling equals resampling
after projecting. A trial is therefore reduced once to (row count, mean, scatter) per chain plus
its raw rows resampled to each T of the grid (`SequenceTable`); the per-split PCA is fitted from
pooled moments, never from the raw rows again.

N, T, K are chosen inside the training positives: some positive training objects are held out,
candidates are scored by mean held-out log-likelihood (the authors' criterion), and the chosen
chain is refitted on all training positives. The authors chose on the test positives and refit
on train + test positives, a test-data leak we do not offer (no test trial enters a fit).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from sklearn.cluster import KMeans
from sklearn.exceptions import ConvergenceWarning
from threadpoolctl import threadpool_limits

from tactile_exp import cores
from tactile_exp.baselines.static import PHASES, pool_moments, principal_axes
from tactile_exp.data.layout import Split, TrialData, TrialName
from tactile_exp.models.numba_setup import numba

SENSORS: tuple[str, ...] = ("electrodes", "pac", "pdc", "tac")
CHAINS: tuple[tuple[str, str], ...] = tuple((ep, s) for ep in PHASES for s in SENSORS)
VARIANCE_KEPT = 0.97
HMM_ITER, HMM_TOL = 100, 0.01
PROB_FLOOR = 1e-10  # scoring guard: an unseen transition/emission costs log(1e-10), not -inf
GRIDS: dict[str, dict[str, tuple[int, ...]]] = {
    # small: the values the authors' stored chains mostly ended with (T=20, K=5), N chosen
    "small": {"n_states": (6, 12), "length": (20,), "symbols": (5,)},
    "authors": {"n_states": (12, 15, 18), "length": (20, 25, 30), "symbols": (5, 10, 12)},
}


class DynamicWarning(UserWarning):
    """A chain input was degenerate (empty EP) or its hyperparameters could not be chosen."""


def sensor_rows(trial: TrialData, rows: slice, sensor: str) -> np.ndarray:
    """Raw rows of both fingers side by side: electrodes (n,38), pac (n,44), pdc/tac (n,2)."""
    parts = []
    for f in trial.fingers:
        if sensor == "pac":
            parts.append(f.pac.reshape(trial.n_rows, -1)[rows])
        else:
            parts.append(getattr(f, sensor)[rows].reshape(rows.stop - rows.start, -1))
    return np.hstack(parts).astype(float)


def resample(x: np.ndarray, length: int) -> np.ndarray:
    """(length, d) linear interpolation of each column at positions k*n/length (IDL congrid)."""
    n = len(x)
    pos = np.arange(length) * n / length
    return np.column_stack([np.interp(pos, np.arange(n), col) for col in x.T])


@dataclass
class SequenceTable:
    """Per trial and chain: row moments and the raw rows resampled to each grid length."""

    trials: list[str]
    count: np.ndarray  # (n_trials, 16)
    mean: list[np.ndarray]  # per chain (n_trials, d)
    scatter: list[np.ndarray]  # per chain (n_trials, d, d)
    seqs: dict[int, list[np.ndarray]]  # T -> per chain (n_trials, T, d)

    @classmethod
    def from_trials(cls, trials: Sequence[TrialData], lengths: Sequence[int]) -> SequenceTable:
        count = np.zeros((len(trials), len(CHAINS)))
        mean: list[list[np.ndarray]] = [[] for _ in CHAINS]
        scatter: list[list[np.ndarray]] = [[] for _ in CHAINS]
        seqs: dict[int, list[list[np.ndarray]]] = {T: [[] for _ in CHAINS] for T in lengths}
        for i, trial in enumerate(trials):
            segments = trial.ep_segments()
            for c, (ep, sensor) in enumerate(CHAINS):
                x = sensor_rows(trial, segments[ep], sensor)
                if len(x) == 0:
                    raise ValueError(f"trial {trial.name.name}: EP {ep} has no rows")
                m = x.mean(axis=0)
                count[i, c] = len(x)
                mean[c].append(m)
                scatter[c].append((x - m).T @ (x - m))
                for T in lengths:
                    seqs[T][c].append(resample(x, T))
        return cls(
            [t.name.name for t in trials],
            count,
            [np.array(m) for m in mean],
            [np.array(s) for s in scatter],
            {T: [np.array(s) for s in per] for T, per in seqs.items()},
        )

    def arrays(self) -> dict[str, np.ndarray]:
        out = {"trials": np.array(self.trials), "count": self.count}
        for c in range(len(CHAINS)):
            out[f"mean{c}"], out[f"scatter{c}"] = self.mean[c], self.scatter[c]
            for T, per in self.seqs.items():
                out[f"seq{c}_{T}"] = per[c]
        return out

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray], lengths: Sequence[int]) -> SequenceTable:
        n = range(len(CHAINS))
        return cls(
            [str(t) for t in a["trials"]],
            a["count"],
            [a[f"mean{c}"] for c in n],
            [a[f"scatter{c}"] for c in n],
            {T: [a[f"seq{c}_{T}"] for c in n] for T in lengths},
        )

    @staticmethod
    def keys(lengths: Sequence[int]) -> tuple[str, ...]:
        per = [f"{k}{c}" for c in range(len(CHAINS)) for k in ("mean", "scatter")]
        seq = [f"seq{c}_{T}" for c in range(len(CHAINS)) for T in lengths]
        return ("trials", "count", *per, *seq)

    def index(self, trials: Sequence[str]) -> np.ndarray:
        pos = {t: i for i, t in enumerate(self.trials)}
        unknown = [t for t in trials if t not in pos]
        if unknown:
            raise KeyError(f"dynamic features: unknown trial(s) {unknown[:5]}")
        return np.array([pos[t] for t in trials], dtype=int)


def pca_axes(scatter: np.ndarray, variance: float = VARIANCE_KEPT) -> np.ndarray:
    """(d, k) principal axes keeping ``variance`` of the total, k as sklearn's PCA(0.97)."""
    values = np.clip(np.sort(np.linalg.eigvalsh(scatter))[::-1], 0.0, None)
    total = values.sum()
    k = 1 if total <= 0 else int(np.searchsorted(np.cumsum(values) / total, variance, "right") + 1)
    return principal_axes(scatter, min(k, len(values)))


def forward_loglik(
    startprob: np.ndarray, transmat: np.ndarray, emission: np.ndarray, symbols: np.ndarray
) -> np.ndarray:
    """(m,) log P(sequence) of m equal-length symbol sequences (m, T), scaled forward pass."""
    start, trans, emit = (
        np.maximum(p, PROB_FLOOR) / np.maximum(p, PROB_FLOOR).sum(axis=-1, keepdims=True)
        for p in (startprob, transmat, emission)
    )
    alpha = start * emit[:, symbols[:, 0]].T
    loglik = np.zeros(len(symbols))
    for t in range(symbols.shape[1]):
        if t:
            alpha = (alpha @ trans) * emit[:, symbols[:, t]].T
        scale = alpha.sum(axis=1)
        loglik += np.log(scale)
        alpha /= scale[:, None]
    return loglik


def fit_categorical_hmm(
    symbols: np.ndarray,
    n_states: int,
    n_symbols: int,
    *,
    seed: int,
    n_iter: int = HMM_ITER,
    tol: float = HMM_TOL,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(startprob, transmat, emissionprob) by EM on m equal-length symbol sequences (m, T).

    hmmlearn 0.3's ``CategoricalHMM(n_states, n_features=n_symbols, random_state=seed,
    implementation="scaling")`` step for step: Dirichlet(1/N) start and transition rows and
    uniform-random emission rows from ``RandomState(seed)``, scaled forward-backward, priors of
    1 (plain maximum likelihood), stop after the M-step of the iteration whose log-likelihood
    gained less than ``tol``.
    """
    m, T = symbols.shape
    if symbols.min() < 0 or symbols.max() >= n_symbols:
        raise ValueError(
            f"symbols must lie in [0, {n_symbols}), got {symbols.min()}..{symbols.max()}"
        )
    alpha = np.full(n_states, 1.0 / n_states)
    draws = np.random.RandomState(seed)
    start, trans = draws.dirichlet(alpha), draws.dirichlet(alpha, size=n_states)
    emit = np.random.RandomState(seed).rand(n_states, n_symbols)  # hmmlearn draws it afresh
    emit /= emit.sum(axis=1, keepdims=True)
    previous = -np.inf
    for _ in range(n_iter):
        loglik, start_counts, xi, emit_counts = _expected_counts(symbols, start, trans, emit)
        if loglik == -np.inf:
            raise ValueError("HMM forward pass underflowed: a sequence has probability 0")
        start = _normalised(np.where(start == 0, 0.0, start_counts))
        trans = _normalised(np.where(trans == 0, 0.0, xi * trans))
        emit = _normalised(emit_counts)
        if loglik - previous < tol:
            break
        previous = loglik
    return start, trans, emit


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _expected_counts(symbols, start, trans, emit):  # pragma: no cover (compiled)
    """The E-step over all sequences, compiled: (log-likelihood, expected start counts (N,),
    transition sums (N, N) still to be multiplied by ``trans``, emission counts (N, K)).

    Per sequence: hmmlearn's scaled forward-backward, the posteriors normalised per frame.
    A log-likelihood of -inf means a sequence had probability 0 (the forward pass underflowed).
    Compiled, one sequence at a time: numpy's version looped over time in Python on (m, N)
    slices, and that loop was most of a chain's fit.
    """
    m, T = symbols.shape
    N, K = emit.shape
    fwd, bwd, scale = np.empty((T, N)), np.empty((T, N)), np.empty(T)
    a, post = np.empty(N), np.empty(N)
    start_counts, xi, emit_counts = np.zeros(N), np.zeros((N, N)), np.zeros((N, K))
    loglik = 0.0
    for s in range(m):
        seq = symbols[s]
        for t in range(T):
            for j in range(N):
                if t == 0:
                    a[j] = start[j] * emit[j, seq[0]]
                else:
                    acc = 0.0
                    for i in range(N):
                        acc += fwd[t - 1, i] * trans[i, j]
                    a[j] = acc * emit[j, seq[t]]
            total = a.sum()
            if total == 0.0:
                return -np.inf, start_counts, xi, emit_counts
            scale[t] = 1.0 / total
            for j in range(N):
                fwd[t, j] = a[j] * scale[t]
            loglik -= np.log(scale[t])
        for j in range(N):
            bwd[T - 1, j] = scale[T - 1]
        for t in range(T - 2, -1, -1):
            for j in range(N):
                a[j] = emit[j, seq[t + 1]] * bwd[t + 1, j]  # "ahead" at t + 1
            for i in range(N):
                acc = 0.0
                for j in range(N):
                    acc += a[j] * trans[i, j]
                    xi[i, j] += fwd[t, i] * a[j]
                bwd[t, i] = acc * scale[t]
        for t in range(T):
            for j in range(N):
                post[j] = fwd[t, j] * bwd[t, j]
            total = post.sum()
            for j in range(N):
                p = post[j] / total
                emit_counts[j, seq[t]] += p
                if t == 0:
                    start_counts[j] += p
    return loglik, start_counts, xi, emit_counts


def _normalised(p: np.ndarray) -> np.ndarray:
    """Rows (or the vector) scaled to sum 1; an all-zero row stays zero (hmmlearn's normalize)."""
    total = p.sum(axis=-1, keepdims=True)
    return p / np.where(total == 0, 1.0, total)


class HMMChain:
    """One chain: PCA(97%) -> k-means(K) symbols -> discrete HMM(N), on resampled sequences."""

    STATE = ("mean", "axes", "centers", "startprob", "transmat", "emissionprob")

    def __init__(self, n_states: int, n_symbols: int, seed: int = 0, n_init: int = 10) -> None:
        self.n_states = n_states
        self.n_symbols = n_symbols
        self.seed = seed
        self.n_init = n_init

    def fit(
        self, count: np.ndarray, mean: np.ndarray, scatter: np.ndarray, seqs: np.ndarray
    ) -> HMMChain:
        """count (m,), mean (m,d), scatter (m,d,d): the fit trials' raw rows; seqs (m,T,d)."""
        self.mean_, pooled = pool_moments(count, mean, scatter)
        self.axes_ = pca_axes(pooled)
        points = self._project(seqs).reshape(-1, self.axes_.shape[1])
        with warnings.catch_warnings(), threadpool_limits(1):  # threads only add overhead here
            _quiet_kmeans()
            kmeans = KMeans(self.n_symbols, n_init=self.n_init, random_state=self.seed)
            labels = kmeans.fit_predict(points)
        self.centers_ = kmeans.cluster_centers_
        self.startprob_, self.transmat_, self.emissionprob_ = fit_categorical_hmm(
            labels.reshape(seqs.shape[:2]), self.n_states, self.n_symbols, seed=self.seed
        )
        return self

    def arrays(self, prefix: str) -> dict[str, np.ndarray]:
        """What scoring needs, as named float arrays (for the on-disk chain cache)."""
        return {prefix + name: getattr(self, name + "_") for name in self.STATE}

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray], prefix: str) -> HMMChain:
        """A fitted chain from ``arrays``' output (scores exactly as the chain that wrote it)."""
        emission = a[prefix + "emissionprob"]
        chain = cls(*emission.shape)
        for name in cls.STATE:
            setattr(chain, name + "_", a[prefix + name])
        return chain

    def _project(self, seqs: np.ndarray) -> np.ndarray:
        return (seqs - self.mean_) @ self.axes_

    def symbols(self, seqs: np.ndarray) -> np.ndarray:
        """(m, T) nearest-centroid symbols."""
        z = self._project(seqs)
        d = ((z[:, :, None, :] - self.centers_[None, None]) ** 2).sum(axis=-1)
        return np.argmin(d, axis=-1)

    def score(self, seqs: np.ndarray) -> np.ndarray:
        """(m,) log-likelihood of each resampled sequence."""
        return forward_loglik(
            self.startprob_, self.transmat_, self.emissionprob_, self.symbols(seqs)
        )


def _quiet_kmeans() -> None:
    """Too few distinct points for K symbols: k-means still labels them, so no warning."""
    warnings.filterwarnings("ignore", "Number of distinct clusters", ConvergenceWarning)


def _candidates(grid: dict[str, tuple[int, ...]]) -> list[tuple[int, int, int]]:
    """(N, T, K) triples; the first is the fallback when nothing can be held out."""
    return [(n, t, k) for t in grid["length"] for k in grid["symbols"] for n in grid["n_states"]]


class DynamicFeatures:
    """Per adjective: 16 chains fitted on training positives; features = 16 log-likelihoods."""

    def __init__(
        self,
        grid: str = "small",
        holdout: float = 0.2,
        n_init: int = 10,
        seed: int = 0,
    ) -> None:
        if grid not in GRIDS:
            raise KeyError(f"unknown HMM grid {grid!r}; known grids: {', '.join(GRIDS)}")
        self.grid = grid
        self.holdout = holdout
        self.n_init = n_init
        self.seed = seed
        self._scored: tuple[SequenceTable, np.ndarray] | None = None  # see `transform`

    def settings(self) -> dict[str, object]:
        """Everything besides the data and the split that the fitted chains depend on."""
        return {
            "grid": GRIDS[self.grid],
            "holdout": self.holdout,
            "n_init": self.n_init,
            "seed": self.seed,
            "hmm": [HMM_ITER, HMM_TOL, VARIANCE_KEPT],
        }

    KEYS: tuple[str, ...] = (
        "params",
        "fit_trials",
        *(f"chain{c}_{name}" for c in range(len(CHAINS)) for name in HMMChain.STATE),
    )

    def arrays(self) -> dict[str, np.ndarray]:
        """The fitted chains as named arrays (strings and floats only: loads without pickle)."""
        out = {"params": np.array(self.params_), "fit_trials": np.array(self.fit_trials_)}
        for c, chain in enumerate(self.chains_):
            out |= chain.arrays(f"chain{c}_")
        return out

    def load_arrays(self, a: dict[str, np.ndarray]) -> DynamicFeatures:
        """Restore the fitted state saved by ``arrays`` (in place of ``fit``)."""
        self.params_ = [tuple(int(v) for v in row) for row in a["params"]]
        self.fit_trials_ = [str(t) for t in a["fit_trials"]]
        self.chains_ = [HMMChain.from_arrays(a, f"chain{c}_") for c in range(len(CHAINS))]
        return self

    @staticmethod
    def lengths(grid: str) -> tuple[int, ...]:
        return GRIDS[grid]["length"]

    @property
    def feature_names(self) -> list[str]:
        return [f"dyn/{ep}/{sensor}" for ep, sensor in CHAINS]

    def _chain(self, table: SequenceTable, c: int, idx: np.ndarray, cand) -> HMMChain:
        n, T, k = cand
        chain = HMMChain(n, k, self.seed, self.n_init)
        return chain.fit(
            table.count[idx, c], table.mean[c][idx], table.scatter[c][idx], table.seqs[T][c][idx]
        )

    def _selection_sets(self, split: Split, positives: list[str]) -> tuple[list[str], list[str]]:
        """(fit trials, scoring trials) for choosing N, T, K; scoring empty = no choice."""
        objects = sorted({TrialName.parse(t).object_id for t in positives})  # type: ignore[union-attr]
        if len(objects) < 2:
            return positives, []
        rng = np.random.default_rng(self.seed)
        n_hold = max(1, round(self.holdout * len(objects)))
        held = set(rng.choice(objects, n_hold, replace=False).tolist())
        is_held = [TrialName.parse(t).object_id in held for t in positives]  # type: ignore[union-attr]
        return (
            [t for t, h in zip(positives, is_held, strict=True) if not h],
            [t for t, h in zip(positives, is_held, strict=True) if h],
        )

    def fit(self, table: SequenceTable, split: Split) -> DynamicFeatures:
        """Fit the 16 chains of ``split.adjective`` on its training positives only."""
        positives = [t for t in split.train if split.labels[t] == 1]
        if not positives:
            raise ValueError(f"adjective {split.adjective!r}: no positive training trial")
        fit_set, score_set = self._selection_sets(split, positives)
        final = positives
        candidates = _candidates(GRIDS[self.grid])
        if not score_set and len(candidates) > 1:
            warnings.warn(
                f"adjective {split.adjective!r}: fewer than 2 positive training objects; "
                f"HMM settings not chosen, using (N, T, K) = {candidates[0]}",
                DynamicWarning,
                2,
            )
        self.fit_trials_ = final
        fit_idx, score_idx, final_idx = map(table.index, (fit_set, score_set, final))

        def fit_chain(c: int) -> tuple[tuple[int, int, int], HMMChain]:
            best = candidates[0]
            if len(score_idx) and len(candidates) > 1:
                scores = []
                for cand in candidates:
                    chain = self._chain(table, c, fit_idx, cand)
                    scores.append(chain.score(table.seqs[cand[1]][c][score_idx]).mean())
                best = candidates[int(np.argmax(scores))]
            return best, self._chain(table, c, final_idx, best)

        # Each chain's fit is single-threaded (k-means under a 1-thread limit, the E-step
        # compiled without the GIL): the 16 chains run on threads, one per core. The outer
        # limit holds the BLAS and OpenMP pools at 1 thread however the chains' own limits
        # interleave, so every chain computes what it computes alone.
        # Likewise the outer filter: warnings filters are process-wide in Python 3.11, and
        # each chain's own catch_warnings restores what it saw when it entered.
        with warnings.catch_warnings(), threadpool_limits(1):
            _quiet_kmeans()
            with ThreadPoolExecutor(cores.threads(len(CHAINS))) as pool:
                fitted = list(pool.map(fit_chain, range(len(CHAINS))))
        self.params_ = [best for best, _ in fitted]
        self.chains_ = [chain for _, chain in fitted]
        return self

    def transform(self, table: SequenceTable, trials: Sequence[str]) -> np.ndarray:
        """(n, 16) log-likelihoods; every trial of ``table`` is scored once per fitted chains and
        indexed after (rows C-F and the object pooling of row F share it; see `shortcuts`)."""
        idx = table.index(trials)
        if self._scored is None or self._scored[0] is not table:
            self._scored = (table, self._score(table, np.arange(len(table.trials))))
        return self._scored[1][idx]

    def _score(self, table: SequenceTable, idx: np.ndarray) -> np.ndarray:
        cols = [
            chain.score(table.seqs[T][c][idx])
            for c, (chain, (_, T, _)) in enumerate(zip(self.chains_, self.params_, strict=True))
        ]
        return np.column_stack(cols)
