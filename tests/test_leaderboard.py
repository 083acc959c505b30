"""A data set's leaderboard: ranks, intervals, and paired differences from the baseline."""

import numpy as np
import pytest
from report_fixture import group

from tactile_exp import stats
from tactile_exp.report import configurations, leaderboard
from tactile_exp.report.configurations import Spec
from tactile_exp.report.heldout import Evidence


def _board(baseline=None, **extra):
    made = [
        group("slide", "linear", 0.6),
        group("slide", "haptic_cnn", 2.0),  # planted: far better
        group("slide", "lstm", 0.6, noise="linear"),  # the linear model's scores exactly
        *extra.values(),
    ]
    groups = [g for g, _ in made]
    evidence = {g.key: e for g, e in made}
    names = configurations.names(groups)
    return leaderboard.board("slide", groups, evidence, names, baseline), evidence


def test_the_planted_best_ranks_first_and_beats_the_rest():
    board, evidence = _board()
    first, *rest = board.entries
    assert (first.name, first.rank, board.baseline) == ("model=haptic_cnn", 1.0, "model=haptic_cnn")
    assert board.chosen == "the best by mean"
    assert [e.rank for e in rest] == [2.5, 2.5]  # identical scores share their ranks
    for e in rest:
        assert e.comparison.verdict == "model=haptic_cnn beats " + e.name
        assert e.comparison.difference.high < 0  # this - the baseline
    assert first.value == evidence[first.group.key].interval()
    assert first.value.low < first.value.estimate < first.value.high


def test_a_named_baseline_and_a_configuration_without_scores():
    extra = group("slide", "random", 0.0)
    no_scores = (extra[0], Evidence(missing="run x: no scores.csv for hard"))
    board, evidence = _board(Spec.parse("model=linear"), extra=no_scores)
    assert board.baseline == "model=linear" and board.chosen == "`--baseline model=linear`"
    by_name = {e.name: e for e in board.entries}
    same = by_name["model=lstm"].comparison
    assert same.difference.estimate == 0 and same.verdict == "not distinguishable"
    assert by_name["model=random"].comparison is None
    assert by_name["model=random"].not_compared == "run x: no scores.csv for hard"
    assert by_name["model=random"].value.missing
    rows = leaderboard.rows(board, evidence, "roc_auc")
    assert [r["rank"] for r in rows] == ["1", "2.5", "2.5", "4"]
    assert rows[1]["baseline"] == "model=linear" and rows[0]["verdict"].startswith(
        "model=haptic_cnn beats model=linear (Holm p = "
    )
    md = leaderboard.markdown(board, evidence, "roc_auc")
    assert "| baseline |" in md and "not compared: run x: no scores.csv" in md


def test_holm_covers_the_data_set_comparisons():
    board, _ = _board()
    compared = [e.comparison for e in board.entries if e.comparison]
    raw = [max(c.p, c.p_bootstrap) for c in compared]
    assert [c.p_holm for c in compared] == pytest.approx(stats.holm(raw))


def test_few_labels_say_no_verdict_can_name_a_winner():
    from scipy import stats as sps

    # Wilcoxon's exact two-sided p with every difference of one sign: the floor the note quotes
    for n in (3, 5):
        assert sps.wilcoxon(np.arange(1, n + 1)).pvalue == pytest.approx(2 / 2**n)
        assert f"2/2^{n} = {2 / 2**n:.3g}" in leaderboard.few_labels_note(n)
    assert leaderboard.few_labels_note(6) == ""  # 2/64 < 0.05
