import csv
import os

import matplotlib
import numpy as np
import pytest

from tactile_exp import report
from tactile_exp.tracking import Tracker

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


@pytest.fixture()
def tracker(tmp_path):
    tracker = Tracker(f"sqlite:///{tmp_path / 'm.db'}", "report_test")
    runs = [  # (name, experiment choice, status, {adjective: auc})
        ("table1_a_haptic_static_1trial-s0", "table1_a_haptic_static_1trial", "ok", (0.6, 0.8)),
        ("table1_a_haptic_static_1trial-s1", "table1_a_haptic_static_1trial", "ok", (0.8, 1.0)),
        ("haptic_cnn-concat-c10-s0", "None", "ok", (0.7, 0.7)),
        ("haptic_cnn-concat-c10-s1", "None", "fail", (0.1, 0.1)),
    ]
    for name, experiment, status, (hard, soft) in runs:
        try:
            params = {"choice.experiment": experiment, "paper.auc": "None"}
            if experiment.startswith("table1_a"):
                params["paper.auc"] = "77.3"  # logged from the experiment file's paper node
            with tracker.run(name, params, {"run_level": "parent"}) as rid:
                tracker.log_metrics(
                    rid, {"mean_auc": (hard + soft) / 2, "auc.hard": hard, "auc.soft": soft}
                )
                if status == "fail":
                    raise RuntimeError("a failed run must not count")
        except RuntimeError:
            pass
    return tracker


def test_table1_groups_seeds_and_skips_failed_runs(tracker, tmp_path):
    methods = report.collect(tracker)
    assert sorted(methods) == ["haptic_cnn-concat-c10", "table1_a_haptic_static_1trial"]
    rows = {r["method"]: r for r in report.table1(methods)}
    a = rows["table1_a_haptic_static_1trial"]
    assert (a["row"], a["runs"], a["mean AUC %"], a["paper (real PHAC-2)"]) == (
        "A",
        "2",
        "80.0",
        "77.3",
    )
    assert a["std over runs"] == "10.0"
    assert rows["haptic_cnn-concat-c10"]["runs"] == "1"


def test_written_files(tracker, tmp_path):
    paths = report.write(report.collect(tracker), tmp_path / "out")
    names = ["table1.md", "table1.csv", "per_adjective.csv", "per_adjective.png"]
    assert [p.name for p in paths] == names
    assert sorted(os.listdir(tmp_path / "out")) == sorted(names)
    with open(tmp_path / "out" / "table1.csv") as f:
        table = {r["method"]: r for r in csv.DictReader(f)}
    assert table["table1_a_haptic_static_1trial"]["mean AUC %"] == "80.0"
    cnn = table["haptic_cnn-concat-c10"]
    assert (cnn["runs"], cnn["row"], cnn["std over runs"]) == ("1", "", "")
    md = (tmp_path / "out" / "table1.md").read_text().splitlines()
    assert len(md) == 2 + len(table)
    assert "| A | table1_a_haptic_static_1trial | 2 | 80.0 | 10.0 | 77.3 |" in md
    image = plt.imread(tmp_path / "out" / "per_adjective.png")
    assert image.shape[:2] == (576, 1440)  # figsize (12, 4.5 + 0.15 x 2 methods) at 120 dpi
    assert image[..., :3].std() > 0.05  # bars drawn, not a blank canvas
    with open(tmp_path / "out" / "per_adjective.csv") as f:
        rows = {r["method"]: r for r in csv.DictReader(f)}
    assert float(rows["table1_a_haptic_static_1trial"]["hard"]) == pytest.approx(0.7)
    assert rows["table1_a_haptic_static_1trial"]["thin"] == ""
    assert np.isclose(float(rows["haptic_cnn-concat-c10"]["soft"]), 0.7)
