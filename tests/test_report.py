import csv

import numpy as np
import pytest

from tactile_exp import report
from tactile_exp.tracking import Tracker


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
    assert all(p.exists() for p in paths)
    with open(tmp_path / "out" / "per_adjective.csv") as f:
        rows = {r["method"]: r for r in csv.DictReader(f)}
    assert float(rows["table1_a_haptic_static_1trial"]["hard"]) == pytest.approx(0.7)
    assert rows["table1_a_haptic_static_1trial"]["thin"] == ""
    assert np.isclose(float(rows["haptic_cnn-concat-c10"]["soft"]), 0.7)
