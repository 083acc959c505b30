"""Issue 26: a lab's own sensor, added in a temporary folder without touching engine files, runs
end to end: the folder layout (6 channels at 50 Hz, 12 objects, 5 labels), ``modality=signals``
with the linear model and with the haptic ConvNet, MLflow runs, then predict on one object."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from mlflow.tracking import MlflowClient

from tactile_exp.config import settings_from_config
from tactile_exp.data.dataset import Sensor
from tactile_exp.data.folder import write_folder
from tactile_exp.experiment import run
from tactile_exp.predict.__main__ import main as predict_main
from tactile_exp.report.scores import read_scores
from tactile_exp.tracking import Tracker

IMU = Sensor("wrist IMU", ("ax", "ay", "az", "gx", "gy", "gz"), 50.0)
LABELS = ("grippy", "warm", "loud", "sharp", "heavy")  # not PHAC-2's adjectives
N_OBJECTS, N_TRIALS = 12, 3


def write_imu_data(root: Path) -> Path:
    """12 objects, each label positive for 6 of them; label k raises channel k's level, so the
    labels are learnable; trials of 80-120 samples (2 s at 50 Hz, give or take)."""
    rng = np.random.default_rng(26)
    positives = {a: set(rng.permutation(N_OBJECTS)[: N_OBJECTS // 2].tolist()) for a in LABELS}
    labels, trials = {}, {}
    for i in range(N_OBJECTS):
        name = f"thing{i:02d}"
        labels[name] = {a: int(i in positives[a]) for a in LABELS}
        level = np.array([labels[name][a] for a in LABELS] + [0.0])
        trials[name] = [
            level[:, None] + 0.5 * rng.normal(size=(6, int(rng.integers(80, 121))))
            for _ in range(N_TRIALS)
        ]
    return write_folder(root, IMU, labels, trials)


@pytest.mark.slow
@pytest.mark.job
@pytest.mark.parametrize(
    "model", [["model=linear"], ["model=haptic_cnn", "model.groups=6"]], ids=["linear", "cnn"]
)
def test_a_new_sensor_in_the_folder_layout_runs_end_to_end(
    tiny_config, mlflow_uri: str, tmp_path: Path, capsys, model: list[str]
) -> None:
    data = write_imu_data(tmp_path / "imu")
    overrides = ["data=folder", f"data.path={data}", "modality=signals", "split=random", *model]
    settings = settings_from_config(tiny_config(overrides, adjectives="null"))
    result = run(settings)

    client = MlflowClient(mlflow_uri)
    parent = client.get_run(result.run_id)
    assert parent.info.status == "FINISHED"
    assert parent.data.tags["data.labels"] == " ".join(LABELS)
    children = client.search_runs(
        [parent.info.experiment_id], f"tags.mlflow.parentRunId = '{result.run_id}'"
    )
    by_label = {c.data.tags["adjective"]: c for c in children}
    assert sorted(by_label) == sorted(LABELS) and len(children) == len(LABELS)
    assert all(c.info.status == "FINISHED" for c in children)
    for label, child in by_label.items():
        assert parent.data.metrics[f"auc.{label}"] == pytest.approx(
            result.results[label].metrics["auc"]
        )
        assert child.data.metrics["auc"] == pytest.approx(result.results[label].metrics["auc"])

    # predict on one object: each label it is a test object of scores as the job logged it
    tracker = Tracker(mlflow_uri, settings.tracking.experiment)
    logged = {label: read_scores(tracker, c.info.run_id) for label, c in by_label.items()}
    obj = min(u.object_id for units in logged.values() for u in units)
    code = predict_main(
        [result.run_id, "--tracking-uri", mlflow_uri, "--object", str(obj), "--format", "json"]
    )
    assert code == 0
    units = json.loads(capsys.readouterr().out)["units"]
    predicted = {row["unit"]: row["scores"] for row in units}
    assert len(predicted) == N_TRIALS  # combine=1: one unit per trial of the object
    compared = 0
    for label, units in logged.items():
        for unit in units:
            if unit.object_id == obj:
                assert predicted[unit.unit][label] == pytest.approx(unit.score, abs=1e-5)
                compared += 1
    assert compared >= N_TRIALS
