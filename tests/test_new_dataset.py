"""A lab's own sensor, added in a temporary folder without touching engine files, runs
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


def write_lab_data(root: Path, channels: int, sensor: str, labels_style: str) -> Path:
    """5 objects x 3 trials of ``channels`` channels at 100 Hz; labels ``hard`` (+2/-3),
    ``soft`` (+3/-2) and ``sticky`` (one positive object), written as a lab's tools write them:
    ``pandas`` (index column, 1.0/0.0), ``excel`` (UTF-8 BOM, ``;``, TRUE/FALSE)."""
    import pandas as pd

    rng = np.random.default_rng(channels)
    names = [f"obj{i}" for i in range(5)]
    table = {
        "hard": [1, 1, 0, 0, 0],
        "soft": [0, 0, 1, 1, 1],
        "sticky": [1, 0, 0, 0, 0],
    }
    trials = {
        o: [table["hard"][i] + rng.normal(size=(channels, 60)) for _ in range(3)]
        for i, o in enumerate(names)
    }
    labels = {o: {a: v[i] for a, v in table.items()} for i, o in enumerate(names)}
    chans = tuple(f"ch{k:02d}" for k in range(channels))
    root = write_folder(root, Sensor(sensor, chans, 100.0), labels, trials)
    frame = pd.DataFrame({"object": names, **{a: np.array(v, float) for a, v in table.items()}})
    if labels_style == "pandas":
        frame.to_csv(root / "labels.csv")  # index column, 1.0 and 0.0
    else:
        rows = [";".join(["object", *table])]
        rows += [";".join([o, *("TRUE" if v[i] else "FALSE" for v in table.values())])
                 for i, o in enumerate(names)]  # fmt: skip
        (root / "labels.csv").write_bytes(("\ufeff" + "\r\n".join(rows) + "\r\n").encode())
    return root


MODALITY_NAMES = ("haptic", "haptic_features", "multimodal", "signals", "visual")
MODEL_NAMES = (
    "estimator",
    "haptic_cnn",
    "haptic_lstm",
    "linear",
    "linear_svm",
    "random",
    "visual_googlenet",
)


@pytest.mark.slow
@pytest.mark.job
@pytest.mark.parametrize(
    "channels,sensor,labels_style",
    [(48, "BioTac (2 fingers)", "pandas"), (3, "glove", "excel")],
    ids=["48ch-phac2-name-pandas", "3ch-excel-bom"],
)
def test_every_modality_and_model_runs_or_is_refused_before_any_run(
    tiny_config, mlflow_uri: str, tmp_path: Path, capsys, channels, sensor, labels_style
) -> None:
    """Each registered modality x model pair on a lab's folder data set: it runs to FINISHED, or
    it stops with one error line before any run exists; never a traceback or a FAILED run."""
    from tactile_exp.errors import EXIT_USER_ERROR, reported
    from tactile_exp.modalities import MODALITIES
    from tactile_exp.models.registry import MODELS

    assert set(MODALITY_NAMES) == set(MODALITIES.names())  # a new one joins this test
    assert set(MODEL_NAMES) == set(MODELS.names())
    data = write_lab_data(tmp_path / "lab", channels, sensor, labels_style)
    client = MlflowClient(mlflow_uri)
    outcomes = {}
    for modality in MODALITY_NAMES:
        for model in MODEL_NAMES:
            before = len(_all_runs(client))
            overrides = [
                "data=folder", f"data.path={data}", f"modality={modality}", f"model={model}",
                "split=random",
            ]  # fmt: skip
            with pytest.raises(SystemExit) as done, reported():
                run(settings_from_config(tiny_config(overrides, adjectives="null")))
                raise SystemExit(0)
            errors = capsys.readouterr().err.splitlines()
            refused = [e for e in errors if e.startswith("error:")]
            assert not any("Traceback" in e for e in errors), (modality, model)
            if done.value.code == EXIT_USER_ERROR:
                assert len(refused) == 1, (modality, model, refused)
                assert len(_all_runs(client)) == before, (modality, model)  # before any run
                outcomes[modality, model] = refused[0]
            else:
                assert done.value.code == 0 and not refused, (modality, model, refused)
                outcomes[modality, model] = "ran"
    assert {r.info.status for r in _all_runs(client)} == {"FINISHED"}
    ran = sorted(pair for pair, outcome in outcomes.items() if outcome == "ran")
    ran_models = ("estimator", "haptic_lstm", "linear", "linear_svm", "random")
    assert ran == [("signals", m) for m in ran_models]
    for modality in ("haptic", "haptic_features", "multimodal"):  # PHAC-2's layout, by declaration
        assert outcomes[modality, "linear"].startswith(
            f"error: modality: modality={modality} needs trials in the phac2-biotac layout"
        )
        assert outcomes[modality, "linear"].endswith("modality=signals would fit")
    assert outcomes["visual", "linear"].startswith("error: modality: modality=visual needs photo")
    assert outcomes["signals", "haptic_cnn"] == (
        f"error: model.groups: groups=32 does not divide the {channels} channels of each "
        "instance; model.groups=channels (one group per channel, as M1 has one per signal; "
        f"ours) or a divisor of {channels} (modality=signals on {data})"
    )
    assert outcomes["signals", "visual_googlenet"].startswith(
        "error: modality: model=visual_googlenet takes feature vectors, modality=signals gives"
    )
    # sticky's one positive object is split by trial: flagged on every job that ran
    parents = [r for r in _all_runs(client) if r.data.tags.get("run_level") == "parent"]
    assert len(parents) == len(ran_models)
    assert all(r.data.tags["labels.seen_object"] == "sticky" for r in parents)
    assert all(r.data.tags["data.labels"] == "hard soft sticky" for r in parents)


def _all_runs(client: MlflowClient) -> list:
    return client.search_runs([e.experiment_id for e in client.search_experiments()])


@pytest.mark.job
def test_the_default_job_on_a_folder_data_set_runs_its_declared_folds(
    tiny_config, mlflow_uri: str, tmp_path: Path, caplog
) -> None:
    """No split= on the command line: the job runs object-grouped folds with the K its labels
    allow, says so once and tags its run; it is the job split=folds split.folds=K names."""
    import logging

    data = write_imu_data(tmp_path / "imu")  # each label positive for 6 of 12 objects: K=5
    overrides = ["data=folder", f"data.path={data}", "modality=signals", "model=linear"]
    settings = settings_from_config(
        tiny_config(overrides, adjectives="[grippy,warm]"), overrides=tuple(overrides)
    )
    with caplog.at_level(logging.INFO, logger="tactile_exp.experiment"):
        result = run(settings)
    said = [r.getMessage() for r in caplog.records if r.getMessage().startswith("split: ")]
    assert said == ["split: folds K=5 (every label has at least 5 positive and 5 negative objects)"]
    parent = MlflowClient(mlflow_uri).get_run(result.run_id)
    assert parent.data.tags["split.resolved"] == said[0].removeprefix("split: ")
    assert parent.info.run_name.endswith("-folds-folds=5-s0")
    # fold 0 of 5 over 6 positive and 6 negative objects: 2 positives dealt to it, then the
    # negatives start at fold 1 and give it 1
    assert {a: r.sizes["n_test_objects"] for a, r in result.results.items()} == {
        "grippy": 3,
        "warm": 3,
    }
