"""The benchmark across data sets: cells, ranks over complete blocks, Friedman, the missing."""

import numpy as np
import pytest
from report_fixture import group
from scipy import stats as sps

from tactile_exp.report import benchmark, configurations, leaderboard

QUALITY = {  # data set -> model -> score separation
    "slip": {"linear": 1.2, "haptic_cnn": 0.4, "lstm": 0.8},
    "slide": {"linear": 0.5, "haptic_cnn": 2.0, "lstm": 0.9},
    "grasp": {"linear": 1.5, "haptic_cnn": 0.3, "lstm": 0.7, "random": 0.0},
}


def _bench(made):
    """The benchmark of (group, evidence) pairs, a leaderboard per data set."""
    groups = [g for g, _ in made]
    evidence = {g.key: e for g, e in made}
    names = configurations.names(groups)
    boards = [
        leaderboard.board(d, gs, evidence, names)
        for d, gs in configurations.by_dataset(groups).items()
    ]
    return benchmark.benchmark(boards)


def _quality_bench():
    return _bench([group(d, m, q) for d, models in QUALITY.items() for m, q in models.items()])


def test_ranks_and_friedman_are_over_the_configurations_on_every_data_set():
    bench = _quality_bench()
    assert bench.datasets == ("grasp", "slide", "slip")
    assert bench.missing == {"model=random": ("slide", "slip")}
    assert bench.configurations[-1] == "model=random" and "model=random" not in bench.mean_ranks
    complete = ["model=haptic_cnn", "model=linear", "model=lstm"]
    values = np.array([[bench.cells[n, d].estimate for d in bench.datasets] for n in complete])
    expected = sps.rankdata(-values, axis=0).mean(axis=1)
    assert [bench.mean_ranks[n] for n in complete] == pytest.approx(expected)
    f = bench.friedman
    assert f.n_adjectives == 3 and sorted(f.names) == complete
    assert f.statistic == pytest.approx(sps.friedmanchisquare(*values).statistic)
    assert list(bench.configurations[:3]) == sorted(complete, key=lambda n: bench.mean_ranks[n])


def test_the_tables_list_the_missing_and_never_rank_them():
    bench = _quality_bench()
    rows = benchmark.rows(bench, "roc_auc")
    random = next(r for r in rows if r["configuration"] == "model=random")
    assert random["mean_rank"] == "" and random["slide"] == "" and random["grasp"]
    assert random["missing_on"] == "slide slip"
    md = benchmark.markdown(bench, "roc_auc")
    assert "| `model=random` |" in md and "not ranked" in md and "not run" in md
    assert "Not ranked (missing on a data set): `model=random` (not on slide, slip)" in md
    assert "Friedman over 3 data sets and 3 configurations" in md


def test_two_complete_configurations_get_ranks_and_no_friedman():
    bench = _bench(
        [group(d, m, q) for d in ("a", "b") for m, q in (("linear", 1.0), ("lstm", 0.5))]
    )
    assert bench.friedman is None and "Friedman's test needs 3" in bench.why_not
    assert bench.mean_ranks == {"model=linear": 1.0, "model=lstm": 2.0}
