"""A finished job as an MLflow pyfunc model: predict's scores through ``pyfunc.load_model`` and
through ``mlflow models serve``; the registered version's tags; predict's artifact errors."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from mlflow.tracking import MlflowClient

from tactile_exp import artifacts
from tactile_exp.config import settings_from_config
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.deploy.__main__ import main
from tactile_exp.deploy.mlflow_model import log_job
from tactile_exp.experiment import run
from tactile_exp.predict import predict


@pytest.fixture
def registered(tiny_config, mlflow_uri, capsys):
    """A row I job on one adjective, logged and registered as ``touch`` version 1."""
    settings = settings_from_config(
        tiny_config(["experiment=table1_i_haptic_cnn_1trial"], "[hard]")
    )
    job = run(settings).run_id
    dataset = DATA_SOURCES.build(settings.data.name, **settings.data.params)
    capsys.readouterr()
    assert main(["--tracking-uri", mlflow_uri, "log", job, "--register", "touch"]) == 0
    out = capsys.readouterr().out
    assert "registered models:/touch/1" in out
    obj = dataset.trials[0].object_id
    trials = sorted(t.name for t in dataset.trials if t.object_id == obj)
    return job, dataset.path, trials


def _request(data: Path, trials: list[str]) -> pd.DataFrame:
    return pd.DataFrame({"data": [str(data)] * len(trials), "trial": trials})


@pytest.mark.job
def test_logged_model_scores_as_predict_and_its_version_is_tagged(registered, mlflow_uri):
    import mlflow

    job, data, trials = registered
    mlflow.set_tracking_uri(mlflow_uri)
    model = mlflow.pyfunc.load_model("models:/touch/1")
    got = model.predict(_request(data, trials))
    expected = predict(run_id=job, tracking_uri=mlflow_uri, data=data, trials=trials)
    assert list(got.columns) == ["unit", "hard", "predicted"]
    assert got["unit"].tolist() == expected.units == trials
    np.testing.assert_allclose(got["hard"], expected.scores[:, 0], atol=1e-6)
    assert got["predicted"].tolist() == [" ".join(p) for p in expected.predicted()]

    client = MlflowClient(mlflow_uri)
    version = client.get_model_version("touch", "1")
    parent = client.get_run(job)
    assert parent.info.status == "FINISHED"  # the job's run, which holds the model, as it was
    assert version.tags["row"] == "I" and version.tags["experiment"] == "tactile_exp"
    assert version.tags["data.identity"] == parent.data.tags["data.identity"]
    assert float(version.tags["mean_auc"]) == pytest.approx(parent.data.metrics["mean_auc"], 1e-4)
    info = mlflow.models.get_model_info("models:/touch/1")
    assert [c.name for c in info.signature.inputs] == ["data", "trial", "photos"]
    assert [c.name for c in info.signature.outputs] == ["unit", "hard", "predicted"]
    local = Path(mlflow.artifacts.download_artifacts("models:/touch/1"))
    assert not list(local.rglob("*.pkl")) and (local / "input_example.json").is_file()


@pytest.mark.job
def test_a_corrupt_artifact_is_predicts_error(registered, mlflow_uri):
    import mlflow

    job, data, trials = registered
    mlflow.set_tracking_uri(mlflow_uri)
    local = Path(mlflow.artifacts.download_artifacts("models:/touch/1"))
    (head,) = local.rglob("head/weights.pt")
    head.write_bytes(b"garbage")
    with pytest.raises(artifacts.ArtifactError) as logged:  # when loaded, before any request
        mlflow.pyfunc.load_model(str(local))
    child = head.parent.parent.name
    assert str(logged.value).startswith(f"run {child}: artifact head/weights.pt is not a readable")
    client = MlflowClient(mlflow_uri)
    original = Path(client.get_run(child).info.artifact_uri.removeprefix("file://"), "head")
    (original / "weights.pt").write_bytes(b"garbage")
    with pytest.raises(artifacts.ArtifactError) as direct:
        predict(run_id=job, tracking_uri=mlflow_uri, data=data, trials=trials)
    assert str(direct.value) == str(logged.value)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
@pytest.mark.job
def test_served_model_answers_with_predicts_scores(registered, mlflow_uri, tmp_path):
    job, data, trials = registered
    port = _free_port()
    env = {**os.environ, "MLFLOW_TRACKING_URI": mlflow_uri, "MLFLOW_REGISTRY_URI": mlflow_uri}
    # the server runs `uvicorn` from PATH: the environment's scripts, as in an activated venv
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    command = [sys.executable, "-m", "mlflow", "models", "serve", "-m", "models:/touch/1"]
    command += ["--env-manager", "local", "--host", "127.0.0.1", "--port", str(port)]
    log = (tmp_path / "serve.log").open("w")
    server = subprocess.Popen(
        command, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
    )
    try:
        body = {"dataframe_split": _request(data, trials).to_dict(orient="split")}
        request = urllib.request.Request(
            f"http://127.0.0.1:{port}/invocations",
            data=json.dumps(body).encode(),
            headers={"Content-Type": "application/json"},
        )
        deadline = time.monotonic() + 60
        while True:
            try:
                with urllib.request.urlopen(request, timeout=30) as response:
                    answer = json.loads(response.read())
                break
            except (ConnectionError, urllib.error.URLError):
                if time.monotonic() > deadline or server.poll() is not None:
                    raise AssertionError((tmp_path / "serve.log").read_text()[-2000:]) from None
                time.sleep(0.5)
    finally:
        os.killpg(server.pid, signal.SIGTERM)  # mlflow and the uvicorn it starts
        server.wait(timeout=30)
        log.close()
    expected = predict(run_id=job, tracking_uri=mlflow_uri, data=data, trials=trials)
    rows = answer["predictions"]
    assert [r["unit"] for r in rows] == expected.units
    np.testing.assert_allclose([r["hard"] for r in rows], expected.scores[:, 0], atol=1e-6)


@pytest.mark.slow  # a multimodal job: trains the ConvNet part and prepares photographs
@pytest.mark.job
def test_multimodal_model_takes_trials_and_photographs(tiny_config, mlflow_uri, tmp_path):
    import mlflow

    small = ["modality.visual.size=32", "modality.visual.batch_size=128"]
    overrides = ["experiment=table1_m_multimodal_i_l", *small]
    settings = settings_from_config(tiny_config(overrides, "[hard]"))
    job = run(settings).run_id
    dataset = DATA_SOURCES.build(settings.data.name, **settings.data.params)
    info, version = log_job(job, tracking_uri=mlflow_uri)
    assert version is None
    obj, paths = next(iter(dataset.photographs().items()))
    folder = tmp_path / "photos"
    folder.mkdir()
    for path in paths:
        shutil.copy(path, folder / path.name)
    trials = sorted(t.name for t in dataset.trials if t.object_id == obj)
    request = _request(dataset.path, trials).assign(photos=str(folder))
    got = mlflow.pyfunc.load_model(info.model_uri).predict(request)
    expected = predict(
        run_id=job, tracking_uri=mlflow_uri, data=dataset.path, trials=trials, photos=folder
    )
    assert got["unit"].tolist() == expected.units
    np.testing.assert_allclose(got["hard"], expected.scores[:, 0], atol=1e-6)
    local = Path(mlflow.artifacts.download_artifacts(info.model_uri))
    example = json.loads((local / "input_example.json").read_text())
    assert example["columns"] == ["data", "trial", "photos"]
    assert example["data"][0][2].startswith("photos/")
