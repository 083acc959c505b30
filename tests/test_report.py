"""The report from runs logged as jobs log them: grouping, labels, numbers, files, CLI errors."""

import csv
import shutil

import numpy as np
import pytest
from mlflow.tracking import MlflowClient
from PIL import Image

from tactile_exp import report
from tactile_exp.data.layout import ADJECTIVES
from tactile_exp.tracking import Tracker

ROW_A = {"choice.experiment": "table1_a_haptic_static_1trial", "paper.row": "A"}
ROW_A |= {"paper.auc": "77.3", "modality.name": "haptic_features", "model.name": "linear_svm"}
ROW_K = {"choice.experiment": "table1_k_image_googlenet_1view", "paper.row": "K"}
ROW_K |= {"paper.auc": "71.5", "modality.name": "visual", "model.name": "visual_googlenet"}
ROW_I = {"choice.experiment": "table1_i_haptic_cnn_1trial", "paper.row": "I"}
ROW_I |= {"paper.auc": "83.2", "modality.name": "haptic", "model.name": "haptic_cnn"}
# (row_hash, params, seed, overrides, fail?, AUC of each adjective: base + 0.01 * index)
RUNS = [
    ("a", ROW_A, 0, "experiment=table1_a_haptic_static_1trial", False, 0.60),
    ("a", ROW_A, 1, "", False, 0.50),  # superseded by the rerun of seed 1 below
    ("a", ROW_A, 1, "", False, 0.70),
    ("a", ROW_A, 2, "", True, 0.10),  # failed: never counted
    ("k", ROW_K, 0, "split=random data=phac2", False, 0.55),
    ("i-quick", {**ROW_I, "choice.schedule": "quick"}, 0, "", False, 0.65),
    ("i-c10", ROW_I, 0, "combine=10", False, 0.75),  # a stronger variant, not row I
    ("i", ROW_I, 0, "", False, 0.68),
]


def _log(tracker: Tracker, key, row, seed, overrides, fail, base, adjectives=ADJECTIVES):
    params = {"choice.schedule": "paper", "schedule.epochs": "200", "split.name": "published"}
    params |= {"schedule.finetune_epochs": "100", "seed": str(seed)} | row
    tags = {"run_level": "parent", "row_hash": key, "config_hash": f"{key}{seed}"}
    tags |= {"overrides": overrides, "data.identity": "synthetic-abc", "sweep_id": "s1"}
    aucs = {f"auc.{a}": base + 0.01 * i for i, a in enumerate(adjectives)}
    try:
        with tracker.run(f"{params['choice.experiment']}-s{seed}", params, tags) as rid:
            tracker.log_metrics(rid, {"mean_auc": float(np.mean(list(aucs.values()))), **aucs})
            if fail:
                raise RuntimeError("a failed run must not count")
    except RuntimeError:
        pass


@pytest.fixture(scope="module")
def mlflow_uri(mlflow_template, tmp_path_factory):
    """One store for the module: logging the runs is most of these tests' time."""
    path = tmp_path_factory.mktemp("report") / "mlflow.db"
    shutil.copy(mlflow_template, path)
    return f"sqlite:///{path}"


@pytest.fixture(scope="module")
def tracker(mlflow_uri):
    tracker = Tracker(mlflow_uri, "report_test")
    for run in RUNS:
        _log(tracker, *run)
    _log(tracker, "a-1adj", ROW_A, 0, "", False, 0.9, adjectives=["hard"])
    return tracker


def test_groups_count_each_seed_once_and_label_variants(tracker):
    groups = {g.key: g for g in report.collect(tracker)}
    assert set(groups) == {"a", "a-1adj", "k", "i-quick", "i-c10", "i"}
    a = groups["a"]
    assert sorted(a.runs) == [0, 1] and a.at_paper_settings
    mean_a = np.mean(0.01 * np.arange(24))
    assert a.aucs == pytest.approx([0.60 + mean_a, 0.70 + mean_a])  # the rerun of seed 1
    assert groups["k"].at_paper_settings  # split and data overrides keep the paper's method
    assert groups["i-quick"].differences == ("schedule=quick",)
    assert groups["i-c10"].differences == ("combine=10",)
    assert groups["a-1adj"].differences == ("1 adjectives",)
    assert [g.row for g in report.collect(tracker, sweep_id="s1")][:2] == ["A", "A"]


def test_table_numbers_and_labels(tracker):
    rows = report.table1(report.collect(tracker))
    a = next(r for r in rows if r["seeds"] == "0 1")
    mean_a = 0.65 + np.mean(0.01 * np.arange(24))
    assert float(a["mean_auc"]) == pytest.approx(mean_a, abs=1e-6)
    assert float(a["std_auc"]) == pytest.approx(np.std([0.6, 0.7], ddof=1), abs=1e-6)
    assert (a["row"], a["paper_auc"], a["adjectives"], a["data"]) == (
        "A",
        "0.773",
        "24",
        "synthetic-abc",
    )
    assert len(a["run_ids"].split()) == 2
    md = report.table1_markdown(rows)
    quick = next(line for line in md.splitlines() if "schedule=quick" in line)
    assert quick.startswith("| (I) |") and "83.2" in quick
    assert md.count("| I | `table1_i_haptic_cnn_1trial` | paper |") == 1


def test_written_files_read_back(tracker, tmp_path):
    groups = report.collect(tracker)
    paths = report.write(groups, tmp_path / "out", "test")
    assert [p.name for p in paths] == [
        "table1.md",
        "table1.csv",
        "per_adjective.csv",
        "fig5_per_adjective.png",
        "index.md",
    ]
    with open(tmp_path / "out" / "table1.csv") as f:
        assert list(csv.DictReader(f)) == report.table1(groups)
    with open(tmp_path / "out" / "per_adjective.csv") as f:
        lines = {r["row_hash"]: r for r in csv.DictReader(f)}
    assert float(lines["a"]["metallic"]) == pytest.approx(
        0.65 + 0.01 * ADJECTIVES.index("metallic")
    )
    assert lines["a-1adj"]["thin"] == ""
    with Image.open(tmp_path / "out" / "fig5_per_adjective.png") as image:
        assert image.size == (1200, 450)
        assert np.asarray(image.convert("L")).std() > 10  # drawn, not blank
    # Fig. 5 takes row I at the paper's settings, not its stronger combine=10 variant.
    assert report.best(groups, report.HAPTIC).key == "i"
    assert report.best(groups, ("visual",)).key == "k"
    index = (tmp_path / "out" / "index.md").read_text()
    assert "![Fig. 5](fig5_per_adjective.png)" in index and "`table1_i_haptic_cnn_1trial`" in index


def test_cli_logs_a_report_run(tracker, mlflow_uri, tmp_path, capsys):
    report.main(["--tracking-uri", mlflow_uri, "--experiment", "report_test"] + [
        "--sweep-id", "s1", "--out", str(tmp_path / "r")])  # fmt: skip
    client = MlflowClient(mlflow_uri)
    runs = client.search_runs([tracker.experiment_id], "tags.run_level = 'report'")
    assert [r.info.run_name for r in runs] == ["report"]
    listed = {a.path for a in client.list_artifacts(runs[0].info.run_id, "report")}
    assert "report/table1.csv" in listed and "report/index.md" in listed
    assert runs[0].data.tags["mlflow.source.name"] == "python -m tactile_exp.report"
    assert "table1_a_haptic_static_1trial" in capsys.readouterr().out


def test_cli_names_what_is_missing(tracker, mlflow_uri, tmp_path):
    out = ["--tracking-uri", mlflow_uri, "--out", str(tmp_path / "r")]
    with pytest.raises(SystemExit, match="no MLflow experiment 'nope'.*report_test"):
        report.main([*out, "--experiment", "nope"])
    with pytest.raises(SystemExit, match="no FINISHED job runs .* sweep_id 'zzz'"):
        report.main([*out, "--experiment", "report_test", "--sweep-id", "zzz"])
    assert not (tmp_path / "r").exists()
