"""Prediction from a finished job's kept models: equal to the logged scores, clear errors."""

from __future__ import annotations

import csv
import io
import shutil
from pathlib import Path

import h5py
import pytest
from mlflow.tracking import MlflowClient

from tactile_exp import store
from tactile_exp.config import settings_from_config
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.experiment import run
from tactile_exp.predict import PredictError, main, predict, read_photographs


@pytest.fixture
def job(tiny_config, mlflow_uri):
    settings = settings_from_config(tiny_config([], "[hard,soft]"))
    result = run(settings)
    data = DATA_SOURCES.build(settings.data.name, **settings.data.params).path
    return result, data


def _logged(uri: str, parent: str) -> dict[str, dict[str, float]]:
    client = MlflowClient(uri)
    exp = client.get_experiment_by_name("tactile_exp")
    runs = client.search_runs([exp.experiment_id], f"tags.mlflow.parentRunId = '{parent}'")
    out = {}
    for child in runs:
        with open(client.download_artifacts(child.info.run_id, "scores.csv")) as f:
            rows = csv.DictReader(io.StringIO(f.read()))
            out[child.data.tags["adjective"]] = {r["unit"]: float(r["score"]) for r in rows}
    return out


def test_predict_equals_the_logged_score_of_held_out_trials(job, mlflow_uri, capsys):
    result, data = job
    logged = _logged(mlflow_uri, result.run_id)
    trials = sorted(logged["hard"])[:2]  # test units of `hard` (one trial each at combine=1)
    got = predict(run_id=result.run_id, tracking_uri=mlflow_uri, data=data, trials=trials)
    assert got.units == trials and got.adjectives == ["hard", "soft"]
    for i, trial in enumerate(trials):
        assert got.scores[i, 0] == pytest.approx(logged["hard"][trial], abs=1e-5)
        assert got.predicted()[i] == [
            a for a, s in zip(got.adjectives, got.scores[i], strict=True) if s > 0
        ]
        if trial in logged["soft"]:
            assert got.scores[i, 1] == pytest.approx(logged["soft"][trial], abs=1e-5)
    args = ["--tracking-uri", mlflow_uri, "--data", str(data), "--format", "csv"]
    assert main([*args, "--trial", trials[0]]) == 0  # newest job: this one
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert float(rows[0]["hard"]) == pytest.approx(logged["hard"][trials[0]], abs=1e-5)


def test_predict_errors_are_clear(job, mlflow_uri, tmp_path, capsys):
    result, data = job
    trial = sorted(_logged(mlflow_uri, result.run_id)["hard"])[0]
    base = ["--tracking-uri", mlflow_uri, "--data", str(data), "--trial", trial]

    def error(argv: list[str]) -> str:
        assert main(argv) == 2
        return capsys.readouterr().err

    assert "unknown run id nope" in error(["nope", *base])
    assert "not photographs" in error(
        [result.run_id, "--tracking-uri", mlflow_uri, "--photos", "x"]
    )

    client = MlflowClient(mlflow_uri)
    exp = client.get_experiment_by_name("tactile_exp")
    running = client.create_run(exp.experiment_id, tags={"run_level": "parent"}).info.run_id
    assert f"run {running} is RUNNING, not FINISHED" in error([running, *base])

    broken = tmp_path / "broken.h5"
    shutil.copy(data, broken)
    with h5py.File(broken, "a") as f:
        del f[trial]["biotacs/finger_0/pdc"]
    message = error([result.run_id, *base[:2], "--data", str(broken), "--trial", trial])
    assert trial in message and "pdc" in message

    child = client.search_runs([exp.experiment_id], f"tags.mlflow.parentRunId = '{result.run_id}'")[
        0
    ]
    head = Path(child.info.artifact_uri.removeprefix("file://"), "head", "weights.pt")
    head.write_bytes(b"garbage")
    message = error([result.run_id, *base])
    assert f"run {child.info.run_id}: artifact head/weights.pt" in message
    assert "Traceback" not in message
    with pytest.raises(store.ArtifactError):
        predict(run_id=result.run_id, tracking_uri=mlflow_uri, data=data, trials=[trial])


def test_photographs_missing_or_not_images(tmp_path):
    with pytest.raises(PredictError, match="no such folder"):
        read_photographs(tmp_path / "none", 32)
    with pytest.raises(PredictError, match="no photographs"):
        read_photographs(tmp_path, 32)
    (tmp_path / "view.jpg").write_text("not an image")
    with pytest.raises(PredictError, match="view.jpg"):
        read_photographs(tmp_path, 32)


@pytest.mark.slow  # prepares photographs and runs the GoogLeNet trunk
def test_predict_from_photographs_equals_the_logged_scores(tiny_config, mlflow_uri, tmp_path):
    small = ["data.views=2", "modality.size=32", "modality.batch_size=64"]
    overrides = ["experiment=table1_k_image_googlenet_1view", *small]
    settings = settings_from_config(tiny_config(overrides, "[hard]"))
    result = run(settings)
    dataset = DATA_SOURCES.build(settings.data.name, **settings.data.params)
    logged = _logged(mlflow_uri, result.run_id)["hard"]
    stem = sorted(logged)[0].rsplit("_v", 1)[0]  # a test object's photographs
    obj = next(t.object_id for t in dataset.trials if t.stem == stem)
    folder = tmp_path / stem
    folder.mkdir()
    for path in dataset.photographs()[obj]:
        shutil.copy(path, folder / path.name)
    got = predict(run_id=result.run_id, tracking_uri=mlflow_uri, photos=folder)
    assert got.units == [f"{stem}_v00", f"{stem}_v01"]
    for unit, score in zip(got.units, got.scores[:, 0], strict=True):
        assert score == pytest.approx(logged[unit], abs=1e-5)
    with pytest.raises(PredictError, match="visual models"):
        predict(run_id=result.run_id, tracking_uri=mlflow_uri, data=dataset.path, trials=[stem])
