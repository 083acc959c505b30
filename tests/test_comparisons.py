"""The rules that turn the report's numbers into words: what makes a verdict, the family Holm
corrects over, pairing, non-inferiority against the margin, and Fig. 5's rows picked from the
data (a simulation: the family over every candidate row pair keeps false claims at nominal)."""

from __future__ import annotations

import numpy as np
import pytest
from stats_fixture import simulate

from tactile_exp import stats
from tactile_exp.report import comparisons
from tactile_exp.report.heldout import Evidence
from tactile_exp.report.runs import Group, Run


def _group(key: str, row: str = "", modality: str = "haptic", model: str = "m") -> Group:
    run = Run(key, 0, 0, 0.5, {}, "data", "sweep")
    return Group(key, key, key, row, None, "paper", "", "folds", modality, model, 24, (), {}, {},
                 {(0, -1): run})  # fmt: skip


def _cmp(low: float, high: float, p: float, rank: float, eq: tuple = (0.0, 0.0)):
    return stats.Comparison(
        "I", "J", stats.Interval((low + high) / 2, low, high), p, 24, p, p, rank,
        ("hard",), ("soft",), stats.Interval(0.0, *eq),
    )  # fmt: skip


def test_judge_turns_a_verdict_into_a_claims_result() -> None:
    assert comparisons.judge(">", _cmp(0.01, 0.05, 0.001, 5)) == "supported"
    assert comparisons.judge(">", _cmp(-0.05, -0.01, 0.001, -5)) == "contradicted"
    assert comparisons.judge(">", _cmp(0.01, 0.05, 0.2, 5)) == "not distinguishable"
    assert comparisons.judge(">", _cmp(0.01, 0.05, 0.001, -5)) == "mixed"
    assert comparisons.judge(">=", _cmp(0.01, 0.05, 0.001, -5)) == "mixed"
    # ">=": non-inferiority; a non-significant difference alone is no support
    assert comparisons.judge(">=", _cmp(-0.019, 0.05, 0.5, 1)).startswith("supported")
    wide = comparisons.judge(">=", _cmp(-0.08, 0.05, 0.5, 1))
    assert wide == "not distinguishable (the interval allows a loss beyond 0.020)"
    assert comparisons.judge(">=", _cmp(-0.08, 0.05, 0.5, 1), margin=0.1).startswith("supported")
    assert comparisons.judge(">=", _cmp(-0.05, -0.01, 0.001, -5)) == "contradicted"
    assert comparisons.judge(">=", _cmp(0.01, 0.05, 0.001, 5)).startswith("supported")


def test_describe_says_equivalent_only_when_tost_rules_out_the_margin() -> None:
    near = _cmp(-0.03, 0.03, 0.5, 1, eq=(-0.015, 0.012))
    assert "equivalent within +-0.020 (TOST: 90% interval [-0.015, +0.012])" in (
        comparisons.describe(near)
    )
    far = _cmp(-0.03, 0.03, 0.5, 1, eq=(-0.025, 0.012))
    assert comparisons.describe(far).endswith(": not distinguishable")
    won = _cmp(0.01, 0.03, 0.001, 1, eq=(0.012, 0.015))
    assert comparisons.describe(won).endswith(": I beats J")  # a win is not "equivalent"
    text = comparisons.describe(won)
    assert "I - J = +0.020 [+0.010, +0.030] over 24 adjectives (1 higher, 1 lower)" in text
    assert "Wilcoxon p = 0.001, bootstrap p = 0.001, Holm p = 0.001" in text


def _evidence(rng, shifts: dict[str, float], n_adjectives: int = 10) -> dict[str, Evidence]:
    evs = simulate(rng, "folds", tuple(shifts.values()), 0.0, n_adjectives)
    return {k: Evidence([ev]) for k, ev in zip(shifts, evs, strict=True)}


def test_claims_are_paired_holm_corrected_over_those_compared_and_judged() -> None:
    rng = np.random.default_rng(11)
    rows = {"I": 0.08, "A": 0.0, "G": 0.08, "J": 0.079}
    evidence = _evidence(rng, rows)
    groups = [_group(r, r) for r in rows]
    lines = {c.claim: c for c in comparisons.claims(groups, evidence)}
    assert [c.claim for c in comparisons.claims(groups, evidence)] == [
        f"{c.better} {c.relation} {c.worse}" for c in comparisons.CLAIMS
    ]
    assert lines["I > A"].result == "supported"
    assert [line.says for line in lines.values()] == [c.says for c in comparisons.CLAIMS]
    assert lines["I > G"].result == "not distinguishable"
    assert lines["I > H"] == comparisons.ClaimLine(
        "I > H", "combining instances beats scoring each alone", "not run", "row H not run"
    )
    wide = {c.claim: c for c in comparisons.claims(groups, evidence, margin=0.5)}
    assert wide["I >= J"].result == "supported (not worse by 0.500 or more)"
    assert ": equivalent within +-0.500 (TOST: 90% interval [" in wide["I >= J"].detail
    assert lines["L > K"].detail == "row L and K not run"
    # Holm's family is the three claims compared (I > A, I > G, I >= J), nothing else.
    compared = [
        stats.compare(a, evidence[a].evaluations, b, evidence[b].evaluations)
        for a, b in (("I", "A"), ("I", "G"), ("I", "J"))
    ]
    for line, cmp in zip(("I > A", "I > G", "I >= J"), stats.with_holm(compared), strict=True):
        assert f"Holm p = {cmp.p_holm:.3g}:" in lines[line].detail
        assert lines[line].result == comparisons.judge(line.split()[1], cmp)
        assert lines[line].detail == comparisons.describe(cmp)
    # Another split for A: not compared paired, and the line says why.
    moved = {
        adj: stats.HeldOut(h.object_id + 1000, h.label, h.score)
        for adj, h in evidence["A"].evaluations[0].items()
    }
    lines = {c.claim: c for c in comparisons.claims(groups, evidence | {"A": Evidence([moved])})}
    assert lines["I > A"].result == "not compared"
    assert lines["I > A"].detail.startswith("not paired: different test objects")
    assert lines["I > A"].says == "deep (ConvNet) beats hand-designed features"
    lines = {c.claim: c for c in comparisons.claims(groups, evidence | {"A": Evidence([], "x")})}
    assert lines["I > A"] == comparisons.ClaimLine(
        "I > A", "deep (ConvNet) beats hand-designed features", "not compared", "x"
    )


def test_selection_family_counts_the_candidate_row_pairs() -> None:
    haptic = [_group(f"h{i}") for i in range(3)] + [_group("r", model="random")]
    visual = [_group(f"v{i}", modality="visual") for i in range(2)]
    assert comparisons.selection_family(haptic + visual) == 6
    paper = [_group("I", "I"), *haptic, *visual]  # the paper's settings are preferred
    assert comparisons.selection_family(paper) == 2
    assert comparisons.selection_family([]) == 1
    # Multimodal rows are neither: not candidates for either side.
    assert comparisons.selection_family([*haptic, *visual, _group("M", "M", "multimodal")]) == 6


@pytest.mark.simulation
def test_best_of_rows_no_longer_inflates_fig5_claims() -> None:
    """Three haptic and three visual rows, all alike in the population; the best of each by
    test mean AUC (as Fig. 5 picks them) compared on Fig. 5's adjectives. Over the family of
    every candidate pair the rate of data sets with any claim stays at or below 0.05."""
    rng = np.random.default_rng(41)
    n_sets, found = 150, {1: 0, 9: 0}
    names = ["h0", "h1", "h2", "v0", "v1", "v2"]
    groups = [_group(n, modality="visual" if n[0] == "v" else "haptic") for n in names]
    assert comparisons.selection_family(groups) == 9
    for _ in range(n_sets):
        evidence = _evidence(rng, dict.fromkeys(names, 0.0), 24)
        mean = {n: np.mean([h.value for h in evidence[n].evaluations[0].values()]) for n in names}
        haptic = max(groups[:3], key=lambda g: mean[g.key])
        visual = max(groups[3:], key=lambda g: mean[g.key])
        for candidates in found:
            lines = comparisons.by_modality(haptic, visual, evidence, candidates)
            found[candidates] += any(c.result != "not distinguishable" for c in lines)
    assert found[9] / n_sets <= 0.05, found
    assert found[1] >= found[9], found


def test_fig5_line_says_how_its_rows_were_picked_and_when_there_is_no_interval() -> None:
    rng = np.random.default_rng(12)
    evidence = _evidence(rng, {"h": 0.0, "v": 0.0}, 24)
    h, v = _group("h"), _group("v", modality="visual")
    line = comparisons.by_modality(h, v, evidence, 6)[0]
    assert line.claim == "thick: better by sight"
    assert "(99.79% interval: Bonferroni over 4 adjectives x 6 candidate row pair(s)" in line.detail
    one = {"thick": stats.HeldOut(np.arange(4), np.array([1, 0, 0, 0]), np.arange(4.0))}
    lines = comparisons.by_modality(h, v, {"h": Evidence([one]), "v": Evidence([one])})
    assert lines[0] == comparisons.ClaimLine(
        "thick: better by sight", "Fig. 5", "not distinguishable",
        "v - h = +0.000 (no interval: 1 positive test object)",
    )  # fmt: skip
    assert lines[1].result == "not run"  # thin is not among these rows' adjectives
    assert comparisons.by_modality(None, v, evidence)[0].result == "not run"


@pytest.mark.parametrize("relation", [">", ">="])
def test_every_claim_relation_is_judged(relation: str) -> None:
    assert {c.relation for c in comparisons.CLAIMS} == {">", ">="}
    assert comparisons.judge(relation, _cmp(-0.05, -0.01, 0.001, -5)) == "contradicted"


def _swept(key: str, sweep: str = "s", **overrides: str) -> Group:
    run = Run(key, 0, 0, 0.5, {}, "data", sweep)
    return Group(key, key, "haptic_cnn", "", None, "paper", "", "folds", "haptic", "m", 24,
                 (), {}, dict(overrides), {(0, -1): run})  # fmt: skip


def test_ablation_names_configurations_by_what_differs_and_pairs_each_axis() -> None:
    rng = np.random.default_rng(13)
    shifts = {"c1h": 0.0, "c10h": 0.1, "c1l": 0.0, "c10l": 0.1, "lone": 0.0, "row": 0.0}
    evidence = _evidence(rng, shifts)
    groups = [
        _swept("c1h", combine="1", loss="hinge", seed="0", **{"split.fold": "0"}),
        _swept("c10h", combine="10", loss="hinge", seed="1"),
        _swept("c1l", combine="1", loss="logistic"),
        _swept("c10l", combine="10", loss="logistic", **{"hydra.job": "x"}),
        _swept("lone", sweep="other", combine="5"),
        _group("row", "I"),  # a Table I row: not in the ablation
    ]
    view = comparisons.ablation(groups, evidence)
    assert view.axes == {"combine": ["1", "10"], "loss": ["hinge", "logistic"]}
    assert view.configs[("10", "hinge")].key == "c10h" and len(view.configs) == 4
    assert view.name(("10", "hinge")) == "combine=10 loss=hinge"
    (combine, c_cmp, c_n), (loss, l_cmp, l_n) = view.effects
    assert (combine, c_cmp.a, c_cmp.b, c_n) == ("combine", "combine=10", "combine=1", 2)
    assert (loss, l_cmp.a, l_cmp.b, l_n) == ("loss", "loss=logistic", "loss=hinge", 2)
    # combinations pooled: combine=10 over both losses against combine=1 over both
    pooled = stats.compare(
        "combine=10", [evidence["c10h"].evaluations[0], evidence["c10l"].evaluations[0]],
        "combine=1", [evidence["c1h"].evaluations[0], evidence["c1l"].evaluations[0]],
    )  # fmt: skip
    holm = stats.with_holm([pooled, l_cmp])
    assert c_cmp.difference == pooled.difference and c_cmp.p_holm == holm[0].p_holm
    assert c_cmp.verdict == "combine=10 beats combine=1"
    assert view.unpaired == []
    # Levels in numeric order; a level pair with no paired combination is listed, with why.
    moved = {j: stats.HeldOut(h.object_id + 500, h.label, h.score)
             for j, h in evidence["c10l"].evaluations[0].items()}  # fmt: skip
    three = [*groups[:4], _swept("c2h", combine="2", loss="hinge")]
    evidence3 = evidence | {"c2h": Evidence([moved])}
    view = comparisons.ablation(three, evidence3)
    assert view.axes["combine"] == ["1", "2", "10"]
    assert ("combine", "combine=2 vs combine=1", "not paired: different test objects (absorbent:"
            " another split rule, seed or fold)") in view.unpaired  # fmt: skip
    assert ("combine", "combine=10 vs combine=2", "not paired: different test objects (absorbent:"
            " another split rule, seed or fold)") in view.unpaired  # fmt: skip
    missing = ("combine", "combine=2 vs combine=1", "no combination of the other axes has both")
    assert missing not in view.unpaired
    assert comparisons.ablation(groups[4:], evidence) is None  # no sweep of two
    alike = [_swept("x1", a="1"), _swept("x2", a="1")]
    assert comparisons.ablation(alike, _evidence(rng, {"x1": 0.0, "x2": 0.0})) is None
    assert comparisons._level_key("10") < comparisons._level_key("9x")


def test_ablation_edges_missing_partners_defaults_and_runs_without_scores() -> None:
    assert comparisons.ablation([], {}) is None
    rng = np.random.default_rng(15)
    evidence = _evidence(rng, dict.fromkeys(("p1", "p2", "p3", "p4"), 0.0))
    evidence["broken"] = Evidence([], "no scores")
    groups = [
        _swept("p1", lr="0.1", loss="a"),
        _swept("p2", lr="0.2", loss="b"),
        _swept("p3", lr="0.2", loss="a"),
        _swept("p4", lr="0.3", loss="b"),
        _swept("broken", lr="0.5", loss="a"),  # no scores: not a configuration of the sweep
    ]
    view = comparisons.ablation(groups, evidence)
    assert view.axes == {"loss": ["a", "b"], "lr": ["0.1", "0.2", "0.3"]}
    # Each pair of levels pairs the configurations alike on the other axes, where there are any.
    assert [(axis, c.a, c.b, n) for axis, c, n in view.effects] == [
        ("loss", "loss=b", "loss=a", 1),
        ("lr", "lr=0.2", "lr=0.1", 1),
        ("lr", "lr=0.3", "lr=0.2", 1),
    ]
    none = "no combination of the other axes has both"
    assert view.unpaired == [("lr", "lr=0.3 vs lr=0.1", none)]
    # A sweep of two, one without the override: its level is the default, named empty.
    two = [_swept("d1", sweep="t", lr="0.1"), _swept("d2", sweep="t")]
    view = comparisons.ablation(two, _evidence(rng, {"d1": 0.0, "d2": 0.0}))
    assert view.axes == {"lr": ["0.1", ""]} and view.configs[("",)].key == "d2"
    assert [(c.a, c.b, n) for _, c, n in view.effects] == [("lr=", "lr=0.1", 1)]


def test_friedman_ranks_the_largest_set_on_the_same_objects() -> None:
    rng = np.random.default_rng(14)
    evidence = _evidence(rng, {"A": 0.0, "I": 0.1, "G": 0.05})
    other = simulate(rng, "published", (0.0,))[0]
    evidence["K"] = Evidence([other])
    evidence["X"] = Evidence([], "no scores")
    groups = [_group(r, r) for r in ("A", "I", "G", "K", "X")]
    assert [g.key for g in comparisons.friedman_set(groups, evidence)] == ["A", "I", "G"]
    result = comparisons.friedman(groups, evidence)
    adjectives = sorted(evidence["A"].evaluations[0])
    aucs = np.array([[evidence[r].evaluations[0][j].value for j in adjectives] for r in "AIG"])
    want = stats.friedman(["A", "I", "G"], aucs)
    assert result.names == ("A", "I", "G") and result.statistic == pytest.approx(want.statistic)
    assert result.mean_ranks == pytest.approx(want.mean_ranks)
    assert comparisons.friedman(groups[:2] + groups[3:], evidence) is None
    assert comparisons.friedman_set(groups[:2], evidence) == []
    assert comparisons.friedman_set([], {}) == [] and comparisons.friedman([], {}) is None


def test_labels_name_rows_variants_and_methods() -> None:
    assert comparisons.label(_group("I", "I")) == "I"
    varied = _group("I", "I")
    varied.differences = ("schedule=quick",)
    assert comparisons.label(varied) == "(I)"
    assert comparisons.label(_group("k")) == "k"


def _clear(perfect: bool, first: int) -> stats.HeldOut:
    """20 positive and 20 negative objects: AUC 1 (perfect) or 0.5 (interleaved)."""
    pos = np.arange(20.0) + (100 if perfect else 0)
    score = np.r_[pos, np.arange(20.0)]
    return stats.HeldOut(first + np.arange(40), (np.arange(40) < 20).astype(int), score)


def test_fig5_lines_for_every_case_at_the_family_level() -> None:
    haptic = _group("h")
    visual = _group("L", "L", modality="visual")
    visual.method = "visual_cnn"  # a row is named by its letter, a configuration by its method
    hv = {"thick": (False, True), "thin": (True, False), "squishy": (True, True)}
    ev_h = {a: _clear(h, 100 * i) for i, (a, (h, _)) in enumerate(hv.items())}
    ev_v = {a: _clear(v, 100 * i) for i, (a, (_, v)) in enumerate(hv.items())}
    evidence = {"h": Evidence([ev_h]), "L": Evidence([ev_v])}
    lines = comparisons.by_modality(haptic, visual, evidence, 3)
    level = 1 - 0.05 / 12
    rest = "(99.58% interval: Bonferroni over 4 adjectives x 3 candidate row pair(s), the rows "
    rest += "picked by test mean AUC)"
    want = []
    for adjective, result in (("thick", "supported"), ("thin", "contradicted")):
        iv = stats.adjective_difference([ev_v], [ev_h], adjective, level)
        numbers = f"L - h = {iv.estimate:+.3f} [{iv.low:+.3f}, {iv.high:+.3f}] {rest}"
        says = "sight" if adjective in ("thick", "thin") else "touch"
        want.append(
            comparisons.ClaimLine(f"{adjective}: better by {says}", "Fig. 5", result, numbers)
        )
    assert lines[:2] == want
    assert lines[0].detail.startswith("L - h = +0.500 [+0.")
    assert lines[2] == comparisons.ClaimLine(
        "squishy: better by touch", "Fig. 5", "not distinguishable",
        f"L - h = +0.000 [+0.000, +0.000] {rest}",
    )  # fmt: skip
    assert lines[3] == comparisons.ClaimLine(
        "absorbent: better by touch", "Fig. 5", "not run",
        "absorbent not among both rows' adjectives",
    )  # fmt: skip
    assert len(lines) == 4
    # haptic better on squishy: supported; no rows, no scores, other objects: said so
    squishy = {"squishy": _clear(True, 0)}
    flat = {"squishy": _clear(False, 0)}
    line = comparisons.by_modality(
        haptic, visual, {"h": Evidence([squishy]), "L": Evidence([flat])}
    )
    assert line[2].result == "supported" and "(98.75% interval" in line[2].detail
    none = comparisons.ClaimLine("thick: better by sight", "Fig. 5", "not run",
                                 "needs a haptic and a visual row")  # fmt: skip
    assert comparisons.by_modality(haptic, None, evidence) == [
        comparisons.ClaimLine(f"{a}: better by {'sight' if s == 'visual' else 'touch'}", "Fig. 5",
                              "not run", "needs a haptic and a visual row")
        for a, s in comparisons.BY_MODALITY
    ]  # fmt: skip
    assert none in comparisons.by_modality(haptic, None, evidence)
    missing = {"h": Evidence([], "no scores.csv"), "L": evidence["L"]}
    assert comparisons.by_modality(haptic, visual, missing)[0] == comparisons.ClaimLine(
        "thick: better by sight", "Fig. 5", "not run", "no scores.csv"
    )
    missing = {"h": evidence["h"], "L": Evidence([], "no L scores")}
    assert comparisons.by_modality(haptic, visual, missing)[1].detail == "no L scores"
    moved = {a: stats.HeldOut(h.object_id + 1, h.label, h.score) for a, h in ev_v.items()}
    other = comparisons.by_modality(haptic, visual, {"h": Evidence([ev_h]), "L": Evidence([moved])})
    assert other[0] == comparisons.ClaimLine(
        "thick: better by sight", "Fig. 5", "not compared", "not on the same test objects (thick)"
    )
    assert [line.result for line in other] == ["not compared"] * 3 + ["not run"]
