"""Known answers for the report's statistics: scipy's values, Demsar's table, and coverage,
false-positive rate and power on 400 simulated data sets at PHAC-2's sizes (stats_fixture)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats as sps
from sklearn.metrics import roc_auc_score
from stats_fixture import population_mean, simulate

from tactile_exp import stats

N_SETS = 400
N_BOOT = 1000


def _known_answers(protocol: str, n_sets: int = N_SETS) -> dict[str, float]:
    """Coverage of the mean's interval, family-wise false positives of three identical
    configurations (Holm over their three comparisons), and power for a difference of 0.10."""
    rng = np.random.default_rng(27)
    covered = false_family = detected = 0
    for i in range(n_sets):
        a, b, c, better = simulate(rng, protocol, (0.0, 0.0, 0.0, 0.10))
        iv = stats.mean_interval([a], N_BOOT, seed=i)
        covered += iv.low <= population_mean() <= iv.high
        family = stats.with_holm(
            [
                stats.compare(x, [ex], y, [ey], N_BOOT, i)
                for x, ex, y, ey in (("a", a, "b", b), ("a", a, "c", c), ("b", b, "c", c))
            ]
        )
        false_family += any(cmp.verdict != "not distinguishable" for cmp in family)
        if protocol != "published":  # the published split's power: bench/bench_stats_power.py
            power = stats.with_holm([stats.compare("better", [better], "a", [a], N_BOOT, i)])
            detected += power[0].verdict == "better beats a"
    return {"coverage": covered / n_sets, "fwer": false_family / n_sets, "power": detected / n_sets}


def test_published_split_interval_covers_and_holm_keeps_false_positives_down() -> None:
    found = _known_answers("published")
    assert 0.92 <= found["coverage"] <= 0.975, found
    assert found["fwer"] <= 0.06, found


@pytest.mark.slow
def test_five_folds_cover_keep_false_positives_down_and_detect_a_tenth() -> None:
    found = _known_answers("folds")
    assert 0.92 <= found["coverage"] <= 0.975, found
    assert found["fwer"] <= 0.06, found
    assert found["power"] >= 0.80, found


def test_auc_equals_sklearn_with_ties_and_units_per_object() -> None:
    rng = np.random.default_rng(0)
    obj = np.repeat(np.arange(9), 4)
    label = (obj < 4).astype(int)
    score = np.round(rng.normal(label, 1.0), 1)  # rounded: ties between units
    held = stats.HeldOut(obj, label, score)
    assert held.auc == pytest.approx(roc_auc_score(label, score), abs=1e-12)
    assert held.key == ((0, 1, 2, 3), (4, 5, 6, 7, 8))


def test_bootstrap_moves_objects_not_units_and_pairs_by_objects() -> None:
    # Two objects per class, every unit of an object scored alike: any object resample gives
    # an AUC of 0, 0.5 or 1 over whole objects, never a unit-level in-between value.
    obj = np.repeat(np.arange(4), 5)
    label = (obj < 2).astype(int)
    score = np.array([3.0, 0.0, 1.0, 2.0])[obj]  # positives 0 (3.0), 1 (0.0); negatives 2, 3
    boots = stats.bootstrap(stats.HeldOut(obj, label, score), "hard", 500, 0)
    # n-1 = 1 object per class: AUC is 1 (object 0 drawn) or 0 (object 1 drawn)
    assert set(np.unique(boots)) == {0.0, 1.0}
    shifted = stats.HeldOut(obj, label, score + 0.0)
    again = stats.bootstrap(shifted, "hard", 500, 0)
    assert np.array_equal(boots, again)  # the same objects: the same draws (paired)


def test_wilcoxon_equals_scipy_and_holm_equals_the_step_down_rule() -> None:
    d = np.random.default_rng(3).normal(0.02, 0.05, 24)
    assert stats.wilcoxon_p(d) == pytest.approx(sps.wilcoxon(d).pvalue, rel=1e-12)
    assert stats.wilcoxon_p(np.zeros(24)) == 1.0
    # Holm by hand: sorted 0.01, 0.03, 0.04 -> 3*0.01, max(2*0.03, .03), max(1*0.04, .06)
    assert stats.holm([0.04, 0.01, 0.03]) == pytest.approx([0.06, 0.03, 0.06])
    assert stats.holm([0.5, 0.9]) == pytest.approx([1.0, 1.0])


def test_verdict_needs_holm_and_the_interval_and_names_the_winner() -> None:
    def cmp(low: float, high: float, p: float) -> stats.Comparison:
        return stats.Comparison("I", "A", stats.Interval((low + high) / 2, low, high), p, 24, p)

    assert cmp(0.01, 0.09, 0.01).verdict == "I beats A"
    assert cmp(-0.09, -0.01, 0.01).verdict == "A beats I"
    assert cmp(0.01, 0.09, 0.20).verdict == "not distinguishable"  # point estimate alone: no
    assert cmp(-0.01, 0.09, 0.01).verdict == "not distinguishable"


def test_unpaired_configurations_are_refused_with_the_reason() -> None:
    rng = np.random.default_rng(1)
    (a,) = simulate(rng, "published", (0.0,))
    moved = {k: stats.HeldOut(v.object_id + 100, v.label, v.score) for k, v in a.items()}
    assert "different test objects" in stats.unpaired_reason([a], [moved])
    assert stats.unpaired_reason([a], [a, a]) == "1 vs 2 seeds/splits"
    with pytest.raises(ValueError, match="not on the same test objects"):
        stats.compare("x", [a], "y", [moved])


def test_friedman_equals_scipy_and_nemenyi_cd_equals_demsars_table() -> None:
    aucs = np.random.default_rng(2).uniform(0.6, 0.9, (4, 24))
    aucs[0] += 0.05
    f = stats.friedman(["a", "b", "c", "d"], aucs)
    want = sps.friedmanchisquare(*aucs)
    assert (f.statistic, f.p) == pytest.approx((want.statistic, want.pvalue))
    assert f.mean_ranks.sum() == pytest.approx(4 * 5 / 2)  # ranks 1..4 on each adjective
    # Demsar (2006) Table 5a: q_0.05 = 2.569 for k = 4; CD = q sqrt(k(k+1) / 6N)
    assert f.critical_difference == pytest.approx(2.569 * np.sqrt(20 / (6 * 24)), abs=2e-3)
    with pytest.raises(ValueError, match="at least 3 configurations"):
        stats.friedman(["a", "b"], aucs[:2])


def test_one_adjective_difference_is_paired_and_refuses_other_objects() -> None:
    rng = np.random.default_rng(4)
    a, b = simulate(rng, "published", (0.0, 0.0))
    same = stats.adjective_difference([a], [a], "hard")
    assert (same.estimate, same.low, same.high) == (0.0, 0.0, 0.0)  # the same draws for both
    iv = stats.adjective_difference([a], [b], "hard", level=0.99)
    assert iv.estimate == pytest.approx(a["hard"].auc - b["hard"].auc)
    assert iv.low <= iv.estimate <= iv.high
    moved = {"hard": stats.HeldOut(a["hard"].object_id + 1, a["hard"].label, a["hard"].score)}
    with pytest.raises(ValueError, match="not on the same test objects"):
        stats.adjective_difference([a], [moved], "hard")
