"""Declared comparisons: verdicts on each data set, per-label differences, the test across
data sets, and the numbers against an independent recomputation with numpy and scipy."""

import csv

import numpy as np
import pytest
from report_fixture import LABELS, group
from scipy import stats as sps
from sklearn.metrics import roc_auc_score

from tactile_exp import stats
from tactile_exp.report import configurations, declared
from tactile_exp.report.configurations import SpecError

CNN_BEATS_LINEAR = declared.Declared.parse("model=haptic_cnn > model=linear")


def _datasets():
    made = [
        group("slide", "linear", 0.6),
        group("slide", "haptic_cnn", 2.0),  # planted better here
        group("flat", "linear", 0.8),
        group("flat", "haptic_cnn", 0.8, noise="linear"),  # identical in effect here
        group("grasp", "linear", 0.8),  # the ConvNet did not run on grasp
    ]
    groups = [g for g, _ in made]
    evidence = {g.key: e for g, e in made}
    return configurations.by_dataset(groups), evidence, configurations.names(groups)


def test_parse_reads_both_relations_and_refuses_anything_else():
    d = declared.Declared.parse("model=a model.x=1 >= model=b")
    assert (d.better.items, d.relation, d.worse.items) == (
        (("model", "a"), ("model.x", "1")),
        ">=",
        (("model", "b"),),
    )
    assert CNN_BEATS_LINEAR.relation == ">"
    with pytest.raises(SpecError, match="expected 'A > B' or 'A >= B'"):
        declared.Declared.parse("model=a < model=b")


def test_verdicts_per_data_set():
    datasets, evidence, names = _datasets()
    found = declared.outcomes([CNN_BEATS_LINEAR], datasets, evidence, names)
    by_data = {o.dataset: o for o in found}
    assert by_data["slide"].result == "supported"
    assert by_data["flat"].result == "not distinguishable"
    assert "equivalent within +-0.020" in by_data["flat"].detail  # every difference is 0
    assert by_data["grasp"].result == "not run"
    assert by_data["grasp"].detail == "model=haptic_cnn did not run here"
    slide = by_data["slide"]
    assert list(slide.labels) == sorted(LABELS) and slide.level == pytest.approx(1 - 0.05 / 8)
    assert all(iv.estimate > 0 and iv.low <= iv.high for iv in slide.labels.values())
    # At the Bonferroni level one label alone needs a large difference: some clear zero.
    sides = {r["label"]: r["result"] for r in declared.rows([slide]) if r["label"]}
    assert "a higher" in sides.values() and "not distinguishable" in sides.values()
    rows = declared.rows(found)
    assert [r["label"] for r in rows if r["dataset"] == "slide"] == ["", *sorted(LABELS)]
    # Holm over the compared outcomes of every declared comparison (two here).
    compared = [o.comparison for o in found if o.comparison]
    assert [c.p_holm for c in compared] == pytest.approx(
        stats.holm([max(c.p, c.p_bootstrap) for c in compared])
    )


def test_as_good_as_needs_the_interval_to_rule_out_the_margin():
    datasets, evidence, names = _datasets()
    worse = declared.Declared.parse("model=linear >= model=haptic_cnn")
    found = {o.dataset: o for o in declared.outcomes([worse], datasets, evidence, names)}
    assert found["slide"].result == "contradicted"
    assert found["flat"].result == "supported (not worse by 0.020 or more)"


def test_a_spec_that_names_nothing_is_one_line():
    datasets, evidence, names = _datasets()
    nothing = declared.Declared.parse("model=lstm > model=linear")
    with pytest.raises(SpecError) as err:
        declared.outcomes([nothing], datasets, evidence, names)
    line = str(err.value)
    assert "'model=lstm' names no configuration on any data set" in line and "\n" not in line
    assert "model=haptic_cnn; model=linear" in line


def test_across_data_sets_is_wilcoxon_over_their_differences():
    datasets, evidence, names = _datasets()
    (result,) = declared.across([CNN_BEATS_LINEAR], datasets, evidence, names)
    assert set(result.differences) == {"slide", "flat"}  # grasp lacks the ConvNet
    assert result.differences["flat"] == 0
    assert result.p == pytest.approx(sps.wilcoxon([result.differences["slide"]]).pvalue)
    assert "higher on 1 of 2 data sets" in result.describe() and "cannot fall below" in (
        result.describe()
    )


def _draws(objects: np.ndarray, n_boot: int = stats.N_BOOT) -> np.ndarray:
    """n-1 of n objects with replacement per replicate, from each object's own uniforms
    (default_rng([0, 1, object]), shared by every label), by the multinomial's conditional
    binomials inverted with scipy."""
    u = np.column_stack([np.random.default_rng([0, 1, int(o)]).random(n_boot) for o in objects])
    n = len(objects)
    left = np.full(n_boot, n - 1.0)
    counts = np.zeros((n_boot, n))
    for i in range(n - 1):
        counts[:, i] = sps.binom.ppf(u[:, i], left, 1 / (n - i))
        left -= counts[:, i]
    counts[:, -1] = left
    return counts


def _weighted_aucs(label, score, weight):
    """ROC AUC of units weighted per replicate (n_boot x units), ties counting one half."""
    pos, neg = label == 1, label == 0
    wins = (score[pos][:, None] > score[neg][None, :]) + 0.5 * (
        score[pos][:, None] == score[neg][None, :]
    )
    wp, wn = weight[:, pos], weight[:, neg]
    return np.einsum("bp,pn,bn->b", wp, wins, wn) / (wp.sum(1) * wn.sum(1))


def test_one_comparison_equals_an_independent_recomputation(tmp_path):
    """The slide data set's comparison from the scores as plain files: sklearn's AUCs,
    scipy's Wilcoxon and the paired bootstrap written out again with numpy."""
    datasets, evidence, names = _datasets()
    found = declared.outcomes([CNN_BEATS_LINEAR], datasets, evidence, names)
    slide = next(o for o in found if o.dataset == "slide")
    files = {}
    for g in datasets["slide"]:
        path = tmp_path / f"{g.model}.csv"
        with open(path, "w") as f:
            f.write("label_name,object_id,label,score\n")
            for name, held in evidence[g.key].evaluations[0].items():
                for o, y, s in zip(held.object_id, held.label, held.score, strict=True):
                    f.write(f"{name},{o},{y},{float(s)!r}\n")
        files[g.model] = path
    tables = {m: list(csv.DictReader(p.read_text().splitlines())) for m, p in files.items()}
    differences, boot = [], []
    for name in LABELS:
        per_model = {}
        for m, t in tables.items():
            rows = [r for r in t if r["label_name"] == name]
            obj = np.array([int(r["object_id"]) for r in rows])
            y = np.array([int(r["label"]) for r in rows])
            s = np.array([float(r["score"]) for r in rows])
            weight = np.zeros((stats.N_BOOT, len(obj)))
            for side in (1, 0):
                ids = np.unique(obj[y == side])
                drawn = _draws(ids)
                for k, o in enumerate(ids):
                    weight[:, obj == o] = drawn[:, [k]]
            per_model[m] = (roc_auc_score(y, s), _weighted_aucs(y, s, weight))
            assert _weighted_aucs(y, s, weight[:1])[0] == pytest.approx(
                roc_auc_score(y, s, sample_weight=weight[0])
            )
        differences.append(per_model["haptic_cnn"][0] - per_model["linear"][0])
        boot.append(per_model["haptic_cnn"][1] - per_model["linear"][1])
    replicates = np.mean(boot, axis=0)
    low, high = np.quantile(replicates, [0.025, 0.975])
    cmp = slide.comparison
    assert cmp.difference.estimate == pytest.approx(np.mean(differences), abs=1e-12)
    assert (cmp.difference.low, cmp.difference.high) == pytest.approx((low, high), abs=1e-9)
    assert cmp.p == pytest.approx(sps.wilcoxon(differences).pvalue, rel=1e-12)
    side = min(np.sum(replicates <= 0), np.sum(replicates >= 0))
    assert cmp.p_bootstrap == pytest.approx(min(1.0, 2 * (side + 1) / (stats.N_BOOT + 1)))
