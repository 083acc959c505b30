"""The metrics registry: values against scikit-learn and hand counts, and a metric added in this
module reaching every child run and the report without touching an engine file."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from mlflow.tracking import MlflowClient
from sklearn.metrics import average_precision_score, f1_score, roc_auc_score

from tactile_exp import metrics, stats
from tactile_exp.config import settings_from_config
from tactile_exp.experiment import run
from tactile_exp.metrics import METRICS


def _cases(n: int = 60):
    """Random labelled score vectors with many ties (scores rounded), some exactly at 0."""
    rng = np.random.default_rng(0)
    for _ in range(n):
        size = int(rng.integers(2, 40))
        y = rng.integers(0, 2, size)
        if len(np.unique(y)) == 2:
            yield y, np.round(rng.normal(size=size), 1)


def test_roc_auc_average_precision_and_f1_equal_scikit_learn():
    cases = list(_cases())
    assert len(cases) > 40
    for y, s in cases:
        assert METRICS.build("roc_auc")(y, s) == pytest.approx(roc_auc_score(y, s), abs=1e-12)
        ap = METRICS.build("average_precision")(y, s)
        assert ap == pytest.approx(average_precision_score(y, s), abs=1e-12)
        assert METRICS.build("f1")(y, s) == pytest.approx(f1_score(y, s > 0), abs=1e-12)


def test_roc_auc_counts_ties_as_half_against_a_hand_computed_value():
    # positives 0.5, 0.9, 0.2 against negatives 0.1, 0.5, 0.5:
    # 0.5 beats 0.1 and ties twice (1 + 0.5 + 0.5), 0.9 beats all 3, 0.2 beats 0.1 -> 6 / 9
    auc = METRICS.build("roc_auc")
    y = np.array([1, 0, 1, 0, 1, 0])
    scores = np.array([0.5, 0.1, 0.9, 0.5, 0.2, 0.5])
    assert auc(y, scores) == pytest.approx(6 / 9, abs=1e-12)
    assert auc(y, np.zeros(6)) == 0.5  # all tied: chance, not 0 or 1
    assert auc(y == 1, -scores) == pytest.approx(3 / 9, abs=1e-12)


def test_f1_is_at_the_decision_threshold_counted_by_hand():
    f1 = METRICS.build("f1")
    # predicted (score > 0): units 0, 2, 3; a score of exactly 0 is negative (unit 4).
    y = np.array([1, 1, 0, 1, 1, 0])
    scores = np.array([0.7, -0.2, 0.1, 2.0, 0.0, -1.0])
    tp, fp, fn = 2, 1, 2  # units 0 and 3; unit 2; units 1 and 4
    assert f1(y, scores) == pytest.approx(2 * tp / (2 * tp + fp + fn), abs=1e-12)  # 4/7
    # Shifting every score by a constant moves the threshold, which AUC would not notice.
    assert f1(y, scores + 0.5) == pytest.approx(2 * 4 / (2 * 4 + 1 + 0))  # unit 2 still wrong
    # Nothing positive, labelled or predicted: 0, as scikit-learn's zero_division=0.
    none = np.zeros(3, dtype=int)
    assert f1(none, -np.ones(3)) == f1_score(none, np.zeros(3), zero_division=0) == 0.0
    assert f1(none, np.ones(3)) == 0.0  # only false positives


def test_average_precision_by_hand():
    # ranked 0.9 (+), 0.8 (-), 0.4 (+), 0.1 (-): precision 1 at recall 1/2, 2/3 at recall 1.
    y, scores = np.array([1, 0, 1, 0]), np.array([0.9, 0.8, 0.4, 0.1])
    assert METRICS.build("average_precision")(y, scores) == pytest.approx(0.5 * 1 + 0.5 * 2 / 3)


@pytest.mark.parametrize(
    "name,y,scores,message",
    [
        ("roc_auc", [1, 1, 1], [0.1, 0.2, 0.3], r"^AUC needs positives and negatives; labels "),
        ("roc_auc", [0, 0], [0.1, 0.2], r"^AUC needs positives and negatives; labels present: \[0"),
        ("average_precision", [0, 0], [0.1, 0.2], "^average precision needs positives and "),
        ("roc_auc", [0, 1, 1], [0.1, np.nan, 0.3], "^scores contain NaN or infinite values$"),
        ("f1", [0, 1, 1], [0.1, np.inf, 0.3], "^scores contain NaN or infinite values$"),
    ],
)
def test_a_metric_refuses_what_it_cannot_score(name, y, scores, message):
    with pytest.raises(ValueError, match=message):
        METRICS.build(name)(np.array(y), np.array(scores))


def test_roc_auc_is_logged_as_auc_and_the_others_by_name():
    keys = {name: METRICS.build(name).key for name in ("roc_auc", "average_precision", "f1")}
    assert keys == {"roc_auc": "auc", "average_precision": "average_precision", "f1": "f1"}
    assert (
        METRICS.build("roc_auc").needs_both_classes and not METRICS.build("f1").needs_both_classes
    )
    y, s = np.array([0, 1, 1, 0]), np.array([-1.0, 2.0, 0.5, 0.7])
    assert list(metrics.compute(["f1", "roc_auc"], y, s)) == ["f1", "auc"]  # in order


def test_summary_is_the_mean_over_adjectives_and_each_adjectives_value():
    got = metrics.summary({"hard": {"auc": 0.5, "f1": 0.2}, "soft": {"auc": 1.0, "f1": 0.4}})
    assert got == pytest.approx(
        {"mean_auc": 0.75, "auc.hard": 0.5, "auc.soft": 1.0}
        | {"mean_f1": 0.3, "f1.hard": 0.2, "f1.soft": 0.4}
    )


@pytest.fixture
def registry():
    """METRICS as it is, restored after the test: what a test registers stays in the test."""
    with METRICS.temporary():
        yield METRICS


def test_two_metrics_may_not_share_a_key(registry):
    with pytest.raises(ValueError, match="key 'auc' is already metric 'roc_auc'"):
        metrics.register("another_auc", key="auc", needs_both_classes=True)(roc_auc_score)
    with pytest.raises(ValueError, match="key 'a.b': letters, digits and _ only"):
        metrics.register("dotted", key="a.b", needs_both_classes=True)(roc_auc_score)


@pytest.mark.parametrize("name", ["roc_auc", "average_precision", "f1"])
def test_bootstrap_of_a_registered_metric_recomputes_it_on_the_resampled_units(registry, name):
    """Known answer: a metric registered again without its fast path goes through the generic
    one (units repeated as often as their object is drawn) and must give the same replicates
    as ROC AUC's pair sums and the other metrics' weighted forms."""
    shipped = METRICS.build(name)
    plain = f"{name}_again"
    metrics.register(plain, needs_both_classes=shipped.needs_both_classes)(shipped.function)
    rng = np.random.default_rng(3)
    obj = np.repeat(np.arange(7), 3)
    label = (obj < 3).astype(int)
    score = np.round(label - 0.5 + rng.normal(size=len(obj)), 1)
    fast = stats.bootstrap(stats.HeldOut(obj, label, score, name), "hard", 300, 0)
    generic = stats.bootstrap(stats.HeldOut(obj, label, score, plain), "hard", 300, 0)
    np.testing.assert_allclose(generic, fast, atol=1e-12)
    assert fast.std() > 0.01  # the replicates differ: the draws are really compared


def test_weighted_forms_equal_scikit_learn_with_sample_weights():
    rng = np.random.default_rng(5)
    for y, s in list(_cases())[:20]:
        w = rng.integers(0, 3, size=(4, len(y)))
        w[:, np.flatnonzero(y == 1)[0]] += 1  # a positive in every weighting
        ap = METRICS.build("average_precision").replicates(y, s, w)
        f1 = METRICS.build("f1").replicates(y, s, w)
        for row, weights in enumerate(w):
            expected = average_precision_score(y, s, sample_weight=weights)
            assert ap[row] == pytest.approx(expected, abs=1e-12)
            assert f1[row] == pytest.approx(f1_score(y, s > 0, sample_weight=weights), abs=1e-12)


def _csv(path: Path) -> list[dict[str, str]]:
    return list(csv.DictReader(path.read_text().splitlines()))


def balanced_accuracy(y: np.ndarray, scores: np.ndarray) -> float:
    """The mean of the true positive and true negative rates at the decision threshold."""
    predicted = scores > 0
    return float((np.mean(predicted[y == 1]) + np.mean(~predicted[y == 0])) / 2)


@pytest.mark.slow
@pytest.mark.job
def test_a_metric_registered_here_reaches_every_child_run_and_the_report(
    registry, tiny_config, mlflow_uri, tmp_path
):
    metrics.register("balanced_accuracy", label="balanced accuracy", needs_both_classes=True)(
        balanced_accuracy
    )
    overrides = ["experiment=table1_a_haptic_static_1trial", "model=linear"]
    overrides += ["metrics=[roc_auc,balanced_accuracy]"]
    settings = settings_from_config(tiny_config(overrides, adjectives="[hard,soft]"))
    assert settings.metrics == ("roc_auc", "balanced_accuracy")
    job = run(settings)
    client = MlflowClient(mlflow_uri)
    children = client.search_runs(
        [client.get_experiment_by_name("tactile_exp").experiment_id],
        f"tags.mlflow.parentRunId = '{job.run_id}' and tags.run_level = 'child'",
    )
    assert len(children) == 2
    logged = {}
    for child in children:
        path = client.download_artifacts(child.info.run_id, "scores.csv", str(tmp_path))
        rows = _csv(Path(path))
        y = np.array([int(float(r["label"])) for r in rows])
        s = np.array([float(r["score"]) for r in rows])
        adjective = child.data.tags["adjective"]
        logged[adjective] = child.data.metrics["balanced_accuracy"]
        assert logged[adjective] == pytest.approx(balanced_accuracy(y, s), abs=1e-12)
        assert child.data.metrics["auc"] == pytest.approx(roc_auc_score(y, s), abs=1e-12)
        assert "f1" not in child.data.metrics  # only what the config lists
        assert job.results[adjective].metrics["balanced_accuracy"] == logged[adjective]
    parent = client.get_run(job.run_id).data.metrics
    assert parent["mean_balanced_accuracy"] == pytest.approx(np.mean(list(logged.values())))
    assert {a: parent[f"balanced_accuracy.{a}"] for a in logged} == pytest.approx(logged)

    from tactile_exp.report import cli

    out = tmp_path / "report"
    cli.main(["--tracking-uri", mlflow_uri, "--out", str(out), "--metric", "balanced_accuracy"])
    (row,) = _csv(out / "table1.csv")
    mean = float(row["mean_balanced_accuracy"])
    assert mean == pytest.approx(parent["mean_balanced_accuracy"], abs=1e-6)
    low, high = (
        float(row["mean_balanced_accuracy_ci_low"]),
        float(row["mean_balanced_accuracy_ci_high"]),
    )
    assert low <= mean <= high and low < high  # recomputed on resampled objects
    assert row["paper_auc"] == ""  # the paper's figures are ROC AUC
    (per_adjective,) = _csv(out / "per_adjective.csv")
    assert {a: float(per_adjective[a]) for a in logged} == pytest.approx(logged, abs=1e-6)
    intervals = _csv(out / "per_adjective_intervals.csv")
    assert {r["adjective"]: float(r["balanced_accuracy"]) for r in intervals} == pytest.approx(
        logged, abs=1e-6
    )
    index = (out / "index.md").read_text()
    assert "**Metric: balanced accuracy** (`--metric balanced_accuracy`" in index
    assert "| mean balanced accuracy % [95% CI] |" in (out / "table1.md").read_text()

    # The default report of the same runs is ROC AUC's, as before.
    cli.main(["--tracking-uri", mlflow_uri, "--out", str(tmp_path / "auc")])
    (row,) = _csv(tmp_path / "auc" / "table1.csv")
    assert float(row["mean_auc"]) == pytest.approx(job.means["mean_auc"], abs=1e-6)
    assert row["paper_auc"] == "0.773"
