"""Uncertainty of the report's numbers: object bootstrap intervals, paired tests, Holm, Friedman.

What is uncertain is the test set: each adjective's AUC rests on a handful of test objects (the
published split holds ~3 positive and ~4 negative objects per adjective). The bootstrap therefore
resamples test objects (an object's units move together), positives and negatives separately,
all adjectives in every replicate, so an interval is one of the mean over adjectives (Demsar 2006;
Benavoli et al. 2017). Each class draws n-1 of its n objects (Hall's small-sample correction:
drawing n understates the variance of a mean by (n-1)/n, which at n=3 costs ~5 points of
coverage; ``tests/test_stats.py`` checks coverage on simulated PHAC-2-sized data).

A replicate's draws are a function of (seed, adjective, test objects): two configurations tested
on the same objects get the same resampled objects, which is what makes a comparison paired.
Evaluations of several seeds (or splits) are averaged replicate by replicate; what the interval
covers is test-object sampling, not the spread of training seeds.

The numbers are of a `HeldOut`'s ``metric`` (``tactile_exp.metrics``): ROC AUC by default, from
object-pair sums without resampling units; any other metric, a function of the units' labels and
scores, is recomputed on each replicate's units (an object drawn twice counts its units twice).
"""

from __future__ import annotations

import functools
import zlib
from dataclasses import dataclass

import numpy as np
from scipy import stats as sps

ALPHA = 0.05
N_BOOT = 2000
SEED = 0


@dataclass(frozen=True)
class HeldOut:
    """One adjective's held-out units: object, ground truth, decision value (one per unit)."""

    object_id: np.ndarray
    label: np.ndarray
    score: np.ndarray
    metric: str = "roc_auc"  # what `value` and `bootstrap` compute (tactile_exp.metrics)

    @functools.cached_property
    def replicates(self) -> dict[tuple[str, int, int], np.ndarray]:
        """Bootstrap values by (adjective, n_boot, seed), filled by `bootstrap`."""
        return {}

    @functools.cached_property
    def key(self) -> tuple[tuple[int, ...], tuple[int, ...]]:
        """Its positive and negative test objects: what pairs two evaluations."""
        return tuple(
            tuple(np.unique(self.object_id[self.label == label]).tolist()) for label in (1, 0)
        )

    @functools.cached_property
    def auc(self) -> float:
        """ROC AUC over units (ties count one half), as metric ``roc_auc`` computes it."""
        return float(self.pairs[0].sum() / (self.pairs[1].sum() * self.pairs[2].sum()))

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
    estimate: float
    low: float
    high: float

    def __str__(self) -> str:
        return f"{self.estimate:.3f} [{self.low:.3f}, {self.high:.3f}]"


@dataclass(frozen=True)
class Comparison:
    """``a`` minus ``b``: the difference of mean AUC, its paired interval, Wilcoxon's p."""

    a: str
    b: str
    difference: Interval
    p: float  # Wilcoxon signed-rank over the per-adjective differences (two-sided)
    n_adjectives: int
    p_holm: float = float("nan")

    @property
    def verdict(self) -> str:
        """From the Holm-corrected test and the interval together, never the estimate alone."""
        significant = self.p_holm < ALPHA
        if significant and self.difference.low > 0:
            return f"{self.a} beats {self.b}"
        if significant and self.difference.high < 0:
            return f"{self.b} beats {self.a}"
        return "not distinguishable"


@functools.lru_cache(maxsize=256)
def _draws(adjective: str, objects: tuple[int, ...], n_boot: int, seed: int) -> np.ndarray:
    """How often each object is drawn in each replicate (n_boot x objects): n-1 of n, with
    replacement; the same for every evaluation on these objects."""
    n = len(objects)
    tag = zlib.crc32(f"{adjective}:{objects}".encode())
    picks = np.random.default_rng([seed, tag]).integers(0, n, size=(n_boot, max(n - 1, 1)))
    flat = picks + n * np.arange(n_boot)[:, None]
    counts = np.bincount(flat.ravel(), minlength=n_boot * n).reshape(n_boot, n).astype(float)
    counts.flags.writeable = False  # cached: every evaluation on these objects shares it
    return counts


def bootstrap(test: HeldOut, adjective: str, n_boot: int = N_BOOT, seed: int = SEED) -> np.ndarray:
    """The adjective's metric in each bootstrap replicate (n_boot,); kept on ``test``, since a
    configuration enters several comparisons."""
    kept = test.replicates.get((adjective, n_boot, seed))
    if kept is None:
        pos_ids, neg_ids = test.key
        cp = _draws(f"{adjective}+", pos_ids, n_boot, seed)
        cn = _draws(f"{adjective}-", neg_ids, n_boot, seed)
        if test.metric == "roc_auc":
            wins, u, v = test.pairs
            kept = np.einsum("bi,bi->b", cp @ wins, cn) / ((cp @ u) * (cn @ v))
        else:
            kept = _resampled(test, cp, cn)
        test.replicates[(adjective, n_boot, seed)] = kept
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
    """Each adjective's AUC (mean over evaluations) with its interval: Fig. 5's error bars."""
    out = {}
    for a in sorted({a for ev in evaluations for a in ev}):
        tests = [ev[a] for ev in evaluations if a in ev]
        boots = np.mean([bootstrap(t, a, n_boot, seed) for t in tests], axis=0)
        out[a] = percentile(float(np.mean([t.value for t in tests])), boots)
    return out


def unpaired_reason(a: list[Evaluation], b: list[Evaluation]) -> str | None:
    """Why two configurations cannot be compared paired, or None when they can: the same
    adjectives, and per adjective the same test objects in the same number of evaluations."""
    if len(a) != len(b):
        return f"{len(a)} vs {len(b)} seeds/splits"
    adjectives = [set(ev) for ev in (*a, *b)]
    if any(s != adjectives[0] for s in adjectives):
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
    adjectives = sorted(a[0])
    diffs = [
        np.mean([ea[j].value - eb[j].value for ea, eb in zip(a, b, strict=True)])
        for j in adjectives
    ]
    return Comparison(
        name_a,
        name_b,
        percentile(est_a - est_b, boot_a - boot_b),
        wilcoxon_p(np.array(diffs)),
        len(adjectives),
    )


def adjective_difference(
    a: list[Evaluation], b: list[Evaluation], adjective: str, level: float = 1 - ALPHA
) -> Interval:
    """One adjective's AUC difference ``a - b`` with its paired-bootstrap interval (one
    adjective has no Wilcoxon test; choose ``level`` for the family, e.g. Bonferroni)."""
    pairs = list(zip(a, b, strict=True)) if len(a) == len(b) else []
    if not pairs or any(x[adjective].key != y[adjective].key for x, y in pairs):
        raise ValueError(f"not on the same test objects ({adjective})")
    boots = [
        bootstrap(x[adjective], adjective) - bootstrap(y[adjective], adjective) for x, y in pairs
    ]
    estimate = float(np.mean([x[adjective].value - y[adjective].value for x, y in pairs]))
    return percentile(estimate, np.mean(boots, axis=0), level)


def wilcoxon_p(differences: np.ndarray) -> float:
    """scipy's two-sided Wilcoxon signed-rank p-value; 1 when every difference is zero."""
    if not np.any(differences != 0):
        return 1.0
    return float(sps.wilcoxon(differences).pvalue)


def holm(pvalues: list[float]) -> list[float]:
    """Holm's step-down adjusted p-values (family-wise error), in the input's order."""
    p = np.asarray(pvalues, dtype=float)
    order = np.argsort(p)
    scaled = np.maximum.accumulate((len(p) - np.arange(len(p))) * p[order])
    out = np.empty_like(p)
    out[order] = np.minimum(scaled, 1.0)
    return out.tolist()


def with_holm(comparisons: list[Comparison]) -> list[Comparison]:
    """The family's comparisons with their Holm-corrected p-values filled in."""
    adjusted = holm([c.p for c in comparisons])
    return [
        Comparison(c.a, c.b, c.difference, c.p, c.n_adjectives, q)
        for c, q in zip(comparisons, adjusted, strict=True)
    ]


@dataclass(frozen=True)
class Friedman:
    """Configurations ranked on each adjective (1 = best); Nemenyi's critical difference."""

    names: tuple[str, ...]
    mean_ranks: np.ndarray
    statistic: float
    p: float
    critical_difference: float
    n_adjectives: int


def friedman(names: list[str], aucs: np.ndarray, alpha: float = ALPHA) -> Friedman:
    """Friedman's test over configurations (rows) x adjectives (columns), scipy's statistic,
    and the Nemenyi critical difference of mean ranks (Demsar 2006, eq. 5)."""
    k, n = aucs.shape
    if k < 3:
        raise ValueError(f"Friedman's test needs at least 3 configurations, got {k}")
    ranks = sps.rankdata(-aucs, axis=0)
    result = sps.friedmanchisquare(*aucs)
    q = sps.studentized_range.ppf(1 - alpha, k, np.inf) / np.sqrt(2)
    cd = float(q * np.sqrt(k * (k + 1) / (6 * n)))
    return Friedman(
        tuple(names), ranks.mean(axis=1), float(result.statistic), float(result.pvalue), cd, n
    )
