"""Uncertainty of the report's numbers: object bootstrap intervals, paired tests, Holm, Friedman.

What is uncertain is the test set: each adjective's AUC rests on a handful of test objects (the
published split holds ~3 positive and ~4 negative objects per adjective). The bootstrap therefore
resamples test objects (an object's units move together), positives and negatives separately,
all adjectives in every replicate, so an interval is one of the mean over adjectives (Demsar 2006;
Benavoli et al. 2017); intervals are percentile intervals of the replicates. Each class draws n-1
of its n objects (Hall's small-sample correction: drawing n understates the variance of a mean by
(n-1)/n, which at n=3 costs ~5 points of coverage). A class of one object has no interval.

Adjectives share test objects (the published split tests 21 objects across its 24 adjectives;
pooled folds test every object for every adjective), so the draws are joint (``RESAMPLING``): an
object's count in a replicate comes from one uniform number per (seed, object, replicate), shared
by every adjective that tests it, through the multinomial's sequence of conditional binomials.
Each class still draws exactly n-1 of its n objects, as before; what changes is that an object
drawn twice for one adjective tends to be drawn twice for the others, so the interval of a mean
over adjectives carries their covariance (``bench/bench_stats_power.py`` compares the two).

A replicate's draws are a function of (seed, test objects): two configurations tested on the same
objects get the same resampled objects, which is what makes a comparison paired. Evaluations of
several seeds (or splits) are averaged replicate by replicate; what the interval covers is
test-object sampling, not the spread of training seeds.

The numbers are of a `HeldOut`'s ``metric`` (``tactile_exp.metrics``): ROC AUC by default, from
object-pair sums without resampling units; any other metric, a function of the units' labels and
scores, is recomputed on each replicate's units (an object drawn twice counts its units twice).
"""

from __future__ import annotations

import functools
import zlib
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats as sps

from tactile_exp.runtime.blas import one_blas_thread

ALPHA = 0.05
N_BOOT = 2000
SEED = 0
# Ours (the paper tests no equivalence): how much worse, in AUC (0.02 = two AUC points), a
# configuration may be and still count as "as good as" another: ">=" claims are non-inferiority
# tests and "=" claims TOST equivalence tests against this margin.
MARGIN = 0.02
# "joint": an object's draws are shared by every adjective that tests it; "independent": each
# adjective draws its objects on its own (kept to measure against: bench/bench_stats_power.py).
RESAMPLING = "joint"


@dataclass(frozen=True)
class HeldOut:
    """One adjective's held-out units: object, ground truth, decision value (one per unit)."""

    object_id: np.ndarray
    label: np.ndarray
    score: np.ndarray
    metric: str = "roc_auc"  # what `value` and `bootstrap` compute (tactile_exp.metrics)

    @functools.cached_property
    def replicates(self) -> dict[tuple[str, int, int, str], np.ndarray]:
        """Bootstrap values by (adjective, n_boot, seed, resampling), filled by `bootstrap`."""
        return {}

    @functools.cached_property
    def key(self) -> tuple[tuple[int, ...], tuple[int, ...]]:
        """Its positive and negative test objects: what pairs two evaluations."""
        return tuple(
            tuple(np.unique(self.object_id[self.label == label]).tolist()) for label in (1, 0)
        )

    @property
    def too_few(self) -> str:
        """Why no interval exists ("" when one does): a class of fewer than 2 test objects
        cannot be resampled, and a zero-width interval would claim a certainty it lacks."""
        for ids, side in zip(self.key, ("positive", "negative"), strict=True):
            if len(ids) < 2:
                return f"{len(ids)} {side} test object"
        return ""

    @functools.cached_property
    def auc(self) -> float:
        """ROC AUC over units (ties count one half), as metric ``roc_auc`` computes it: the
        sum of ``pairs``' wins, counted per positive unit in the sorted negatives instead of
        over every unit pair (the report takes every adjective's value, bootstraps a few)."""
        negatives = np.sort(self.score[self.label == 0])
        positives = self.score[self.label == 1]
        wins = positives[~np.isnan(positives)]  # a NaN wins no pair, as in ``pairs``
        twice = np.searchsorted(negatives, wins, "left").sum()
        twice += np.searchsorted(negatives, wins, "right").sum()  # + ties once more
        return float(twice * 0.5 / (len(positives) * len(negatives)))

    @functools.cached_property
    def value(self) -> float:
        """The metric of all units: ``auc`` for roc_auc."""
        if self.metric == "roc_auc":
            return self.auc
        from tactile_exp.metrics import METRICS

        return METRICS.build(self.metric)(self.label, self.score)

    @functools.cached_property
    def pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Wins summed per (positive object, negative object), and each object's unit count."""
        sides = []
        for label in (1, 0):
            order = np.flatnonzero(self.label == label)
            order = order[np.argsort(self.object_id[order], kind="stable")]
            ids = self.object_id[order]
            starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
            sides.append(
                (self.score[order], starts, np.diff(np.r_[starts, len(ids)]).astype(float))
            )
        (pos, p_starts, u), (neg, n_starts, v) = sides
        units = (pos[:, None] > neg[None, :]) + 0.5 * (pos[:, None] == neg[None, :])
        wins = np.add.reduceat(np.add.reduceat(units, p_starts, axis=0), n_starts, axis=1)
        return wins, u, v


Evaluation = dict[str, HeldOut]  # adjective -> its test units, one seed (a seed's folds pooled)


@dataclass(frozen=True)
class Interval:
    """A percentile interval; ``missing`` says why there is none (then ``low``/``high`` are NaN).
    The estimate is the value on every object, which a percentile interval need not contain."""

    estimate: float
    low: float
    high: float
    missing: str = ""

    def __str__(self) -> str:
        if self.missing:
            return f"{self.estimate:.3f} (no interval: {self.missing})"
        return f"{self.estimate:.3f} [{self.low:.3f}, {self.high:.3f}]"


def no_interval(estimate: float, why: str) -> Interval:
    return Interval(estimate, np.nan, np.nan, why)


@dataclass(frozen=True)
class Comparison:
    """``a`` minus ``b``: the difference of mean AUC, its paired interval, Wilcoxon's test.

    Wilcoxon's test takes the adjectives as independent, which shared test objects are not; the
    paired bootstrap draws shared objects jointly. A comparison is significant only when both
    tests are (an intersection-union test: its p is the larger of the two), after Holm."""

    a: str
    b: str
    difference: Interval
    p: float  # Wilcoxon signed-rank over the per-adjective differences (two-sided)
    n_adjectives: int
    p_holm: float = float("nan")  # Holm over the family of max(p, p_bootstrap)
    p_bootstrap: float = 0.0  # the paired bootstrap's two-sided p (its replicates' side of 0)
    signed_rank: float = 0.0  # W+ - W-: > 0 when the ranked differences favour ``a``
    a_better: tuple[str, ...] = ()  # adjectives where a's value is higher
    b_better: tuple[str, ...] = ()
    equivalence: Interval | None = None  # the 1 - 2 ALPHA interval: TOST's two one-sided tests

    @property
    def verdict(self) -> str:
        """A winner only when the Holm-corrected test, the interval and the direction of the
        signed-rank statistic all agree; "mixed" when the interval and the ranks point opposite
        ways; never from the estimate alone."""
        d = self.difference
        side = 1 if d.low > 0 else -1 if d.high < 0 else 0
        ranks = int(np.sign(self.signed_rank))
        if side and ranks and side != ranks:
            return (
                f"mixed: {self.a} better on {_listed(self.a_better)}, "
                f"{self.b} better on {_listed(self.b_better)}"
            )
        if self.p_holm < ALPHA and side == ranks == 1:
            return f"{self.a} beats {self.b}"
        if self.p_holm < ALPHA and side == ranks == -1:
            return f"{self.b} beats {self.a}"
        return "not distinguishable"

    def non_inferior(self, margin: float = MARGIN) -> bool:
        """``a`` is at most ``margin`` worse than ``b``: the interval's lower end clears -margin."""
        return self.difference.low > -margin

    def equivalent(self, margin: float = MARGIN) -> bool:
        """TOST: both one-sided tests at ALPHA reject a difference beyond the margin, i.e. the
        1 - 2 ALPHA interval lies inside (-margin, margin)."""
        e = self.equivalence
        return e is not None and -margin < e.low and e.high < margin


def _listed(adjectives: tuple[str, ...]) -> str:
    return f"{len(adjectives)} ({', '.join(adjectives)})" if adjectives else "0"


def _counts(uniforms: np.ndarray) -> np.ndarray:
    """n-1 draws with replacement among n objects, as counts (n_boot x n), by the multinomial's
    conditional binomials: object i's count is the inverse binomial CDF of its own uniform, with
    the draws not yet given and probability 1 / (objects left); the last takes the rest."""
    n_boot, n = uniforms.shape
    left = np.full(n_boot, max(n - 1, 1))
    counts = np.zeros((n_boot, n))
    for i in range(n - 1):
        p = 1.0 / (n - i)
        u = uniforms[:, i]
        count = np.zeros(n_boot)
        pmf = (1 - p) ** left
        cdf = pmf.copy()
        active = np.flatnonzero(u > cdf)  # none where no draws are left: there cdf is 1
        while active.size:  # the inverse CDF, stepping only the replicates not yet placed
            c = count[active]
            pmf[active] *= (left[active] - c) / (c + 1) * p / (1 - p)
            count[active] = c + 1
            cdf[active] += pmf[active]
            active = active[(u[active] > cdf[active]) & (count[active] < left[active])]
        counts[:, i] = count
        left = left - count
    counts[:, n - 1] = left
    return counts


@functools.lru_cache(maxsize=4096)
def _uniforms(object_id: int, n_boot: int, seed: int) -> np.ndarray:
    """The object's uniform number in each replicate: shared by every adjective testing it."""
    return np.random.default_rng([seed, 1, int(object_id)]).random(n_boot)


@functools.lru_cache(maxsize=256)
def _draws(
    adjective: str, objects: tuple[int, ...], n_boot: int, seed: int, resampling: str
) -> np.ndarray:
    """How often each object is drawn in each replicate (n_boot x objects): n-1 of n, with
    replacement; the same for every evaluation on these objects."""
    n = len(objects)
    if resampling == "joint":
        counts = _counts(np.column_stack([_uniforms(o, n_boot, seed) for o in objects]))
    elif resampling == "independent":
        tag = zlib.crc32(f"{adjective}:{objects}".encode())
        picks = np.random.default_rng([seed, tag]).integers(0, n, size=(n_boot, max(n - 1, 1)))
        flat = picks + n * np.arange(n_boot)[:, None]
        counts = np.bincount(flat.ravel(), minlength=n_boot * n).reshape(n_boot, n)
        counts = counts.astype(float)
    else:
        raise ValueError(f"resampling: expected joint or independent, got {resampling!r}")
    counts.flags.writeable = False  # cached: every evaluation on these objects shares it
    return counts


def bootstrap(test: HeldOut, adjective: str, n_boot: int = N_BOOT, seed: int = SEED) -> np.ndarray:
    """The adjective's metric in each bootstrap replicate (n_boot,); kept on ``test``, since a
    configuration enters several comparisons."""
    kept = test.replicates.get((adjective, n_boot, seed, RESAMPLING))
    if kept is None:
        pos_ids, neg_ids = test.key
        cp = _draws(f"{adjective}+", pos_ids, n_boot, seed, RESAMPLING)
        cn = _draws(f"{adjective}-", neg_ids, n_boot, seed, RESAMPLING)
        if test.metric == "roc_auc":
            wins, u, v = test.pairs
            with one_blas_thread():  # small products (runtime/blas.py)
                kept = np.sum((cp @ wins) * cn, axis=1) / ((cp @ u) * (cn @ v))
        else:
            kept = _resampled(test, cp, cn)
        test.replicates[(adjective, n_boot, seed, RESAMPLING)] = kept
    return kept


def _resampled(test: HeldOut, cp: np.ndarray, cn: np.ndarray) -> np.ndarray:
    """``test.metric`` on each replicate's units: each unit as often as its object is drawn."""
    from tactile_exp.metrics import METRICS

    pos_ids, neg_ids = test.key
    counts = np.empty((len(cp), len(test.label)), dtype=int)
    for label, ids, drawn in ((1, pos_ids, cp), (0, neg_ids, cn)):
        units = test.label == label
        counts[:, units] = drawn[:, np.searchsorted(ids, test.object_id[units])]
    return METRICS.build(test.metric).replicates(test.label, test.score, counts)


def bootstrap_mean(
    evaluations: list[Evaluation], n_boot: int = N_BOOT, seed: int = SEED
) -> tuple[float, np.ndarray]:
    """The mean over adjectives (then over evaluations) and its bootstrap replicates."""
    estimates, replicates = [], []
    for ev in evaluations:
        estimates.append(np.mean([t.value for t in ev.values()]))
        boots = [bootstrap(t, a, n_boot, seed) for a, t in sorted(ev.items())]
        replicates.append(np.mean(boots, axis=0))
    return float(np.mean(estimates)), np.mean(replicates, axis=0)


def percentile(estimate: float, replicates: np.ndarray, level: float = 1 - ALPHA) -> Interval:
    low, high = np.quantile(replicates, [(1 - level) / 2, (1 + level) / 2])
    return Interval(estimate, float(low), float(high))


def mean_interval(
    evaluations: list[Evaluation], n_boot: int = N_BOOT, seed: int = SEED
) -> Interval:
    """Mean AUC over adjectives (and evaluations) with its 95% object-bootstrap interval."""
    return percentile(*bootstrap_mean(evaluations, n_boot, seed))


def adjective_intervals(
    evaluations: list[Evaluation], n_boot: int = N_BOOT, seed: int = SEED
) -> dict[str, Interval]:
    """Each adjective's AUC (mean over evaluations) with its interval: Fig. 5's error bars; none
    where a class has fewer than 2 test objects."""
    out = {}
    for a in sorted({a for ev in evaluations for a in ev}):
        tests = [ev[a] for ev in evaluations if a in ev]
        estimate = float(np.mean([t.value for t in tests]))
        why = [t.too_few for t in tests if t.too_few]
        if why:
            out[a] = no_interval(estimate, why[0])
            continue
        boots = np.mean([bootstrap(t, a, n_boot, seed) for t in tests], axis=0)
        out[a] = percentile(estimate, boots)
    return out


def unpaired_reason(a: list[Evaluation], b: list[Evaluation]) -> str | None:
    """Why two configurations cannot be compared paired, or None when they can: the same
    adjectives, and per adjective the same test objects in the same number of evaluations."""
    if len(a) != len(b):
        return f"{len(a)} vs {len(b)} seeds/splits"
    if len({frozenset(ev) for ev in (*a, *b)}) > 1:
        return "different adjectives"
    for ea, eb in zip(a, b, strict=True):
        for adj, test in ea.items():
            if test.key != eb[adj].key:
                return f"different test objects ({adj}: another split rule, seed or fold)"
    return None


def compare(
    name_a: str,
    a: list[Evaluation],
    name_b: str,
    b: list[Evaluation],
    n_boot: int = N_BOOT,
    seed: int = SEED,
) -> Comparison:
    """Paired: the difference of mean AUC with its paired-bootstrap interval (the same objects
    drawn for both) and Wilcoxon's signed-rank test over the per-adjective differences."""
    reason = unpaired_reason(a, b)
    if reason is not None:
        raise ValueError(f"{name_a} vs {name_b}: not on the same test objects ({reason})")
    est_a, boot_a = bootstrap_mean(a, n_boot, seed)
    est_b, boot_b = bootstrap_mean(b, n_boot, seed)
    by_adjective = {j: _difference(a, b, j) for j in sorted(a[0])}
    diffs = np.array(list(by_adjective.values()))
    return Comparison(
        name_a,
        name_b,
        percentile(est_a - est_b, boot_a - boot_b),
        wilcoxon_p(diffs),
        len(diffs),
        p_bootstrap=bootstrap_p(boot_a - boot_b),
        signed_rank=signed_rank(diffs),
        a_better=tuple(j for j, d in by_adjective.items() if d > 0),
        b_better=tuple(j for j, d in by_adjective.items() if d < 0),
        equivalence=percentile(est_a - est_b, boot_a - boot_b, 1 - 2 * ALPHA),
    )


def adjective_difference(
    a: list[Evaluation], b: list[Evaluation], adjective: str, level: float = 1 - ALPHA
) -> Interval:
    """One adjective's AUC difference ``a - b`` with its paired-bootstrap interval (one
    adjective has no Wilcoxon test; choose ``level`` for the family, e.g. Bonferroni)."""
    pairs = list(zip(a, b, strict=True)) if len(a) == len(b) else []
    if not pairs or any(x[adjective].key != y[adjective].key for x, y in pairs):
        raise ValueError(f"not on the same test objects ({adjective})")
    estimate = _difference(a, b, adjective)
    why = [x[adjective].too_few for x in a if x[adjective].too_few]
    if why:
        return no_interval(estimate, why[0])
    boots = [
        bootstrap(x[adjective], adjective) - bootstrap(y[adjective], adjective) for x, y in pairs
    ]
    return percentile(estimate, np.mean(boots, axis=0), level)


def _difference(a: list[Evaluation], b: list[Evaluation], adjective: str) -> float:
    """The adjective's ``a - b``, averaged over the paired evaluations."""
    return float(
        np.mean([x[adjective].value - y[adjective].value for x, y in zip(a, b, strict=True)])
    )


def wilcoxon_p(differences: np.ndarray) -> float:
    """scipy's two-sided Wilcoxon signed-rank p-value over the non-zero differences (Wilcoxon's
    rule: a zero difference is dropped, so n counts the others); 1 when every one is zero."""
    nonzero = differences[differences != 0]
    if not len(nonzero):
        return 1.0
    return float(sps.wilcoxon(nonzero).pvalue)


def signed_rank(differences: np.ndarray) -> float:
    """W+ - W-: the ranks of |d| (ties averaged, zeros dropped) summed with d's signs: which
    way the signed-rank test points, whatever the mean says."""
    nonzero = differences[differences != 0]
    return float(np.sum(np.sign(nonzero) * sps.rankdata(np.abs(nonzero))))


def bootstrap_p(replicates: np.ndarray) -> float:
    """Two-sided p of "no difference" from paired-bootstrap replicates: twice the share on the
    smaller side of 0 (a replicate at 0 counts on both), never 0 ((k + 1) / (n + 1))."""
    side = min(np.sum(replicates <= 0), np.sum(replicates >= 0))
    return float(min(1.0, 2 * (side + 1) / (len(replicates) + 1)))


def holm(pvalues: list[float]) -> list[float]:
    """Holm's step-down adjusted p-values (family-wise error), in the input's order."""
    p = np.asarray(pvalues)
    order = np.argsort(p)
    scaled = np.maximum.accumulate((len(p) - np.arange(len(p))) * p[order])
    out = np.empty_like(p)
    out[order] = np.minimum(scaled, 1.0)
    return out.tolist()


def with_holm(comparisons: list[Comparison]) -> list[Comparison]:
    """The family's comparisons with their Holm-corrected p-values filled in: Holm over each
    comparison's larger p of Wilcoxon's and the bootstrap's."""
    adjusted = holm([max(c.p, c.p_bootstrap) for c in comparisons])
    return [replace(c, p_holm=q) for c, q in zip(comparisons, adjusted, strict=True)]


@dataclass(frozen=True)
class Friedman:
    """Configurations ranked on each adjective (1 = best); Nemenyi's critical difference."""

    names: tuple[str, ...]
    mean_ranks: np.ndarray
    statistic: float  # Friedman's chi-square
    p: float
    critical_difference: float
    n_adjectives: int
    f_statistic: float  # Iman and Davenport's F, less conservative (Demsar 2006, eq. 4)
    f_p: float


def iman_davenport(chi2: float, k: int, n: int) -> tuple[float, float]:
    """Iman-Davenport's F of Friedman's chi-square over k configurations and n adjectives, with
    its p-value on (k-1, (k-1)(n-1)) degrees of freedom."""
    if chi2 >= n * (k - 1):  # every adjective ranks the configurations alike
        return np.inf, 0.0
    f = (n - 1) * chi2 / (n * (k - 1) - chi2)
    return float(f), float(sps.f.sf(f, k - 1, (k - 1) * (n - 1)))


def friedman(names: list[str], aucs: np.ndarray, alpha: float = ALPHA) -> Friedman:
    """Friedman's test over configurations (rows) x adjectives (columns), scipy's statistic,
    Iman-Davenport's F, and the Nemenyi critical difference of mean ranks (Demsar 2006, eq. 5)."""
    k, n = aucs.shape
    if k < 3:
        raise ValueError(f"Friedman's test needs at least 3 configurations, got {k}")
    ranks = sps.rankdata(-aucs, axis=0)
    result = sps.friedmanchisquare(*aucs)
    q = sps.studentized_range.ppf(1 - alpha, k, np.inf) / np.sqrt(2)
    cd = float(q * np.sqrt(k * (k + 1) / (6 * n)))
    f, f_p = iman_davenport(float(result.statistic), k, n)
    return Friedman(
        tuple(names),
        ranks.mean(axis=1),
        float(result.statistic),
        float(result.pvalue),
        cd,
        n,
        f,
        f_p,
    )
