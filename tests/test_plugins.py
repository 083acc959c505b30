"""Components kept outside the package work everywhere a built-in one does: a job, predict, the
MLflow model and the model contract import every ``_module_`` a job's config names; a model
that is YAML only (``model=estimator``, aeon's MiniRocket) runs from a folder outside the
repository through Hydra's ``--config-dir``."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import CONF, TINY_DATA, doc_block
from hydra import compose, initialize_config_dir

from tactile_exp import plugins
from tactile_exp.config import settings_from_config
from tactile_exp.errors import ConfigError
from tactile_exp.experiment import run
from tactile_exp.models import MODELS
from tactile_exp.predict import predict
from tactile_exp.testing import check_model

CENTROID = '''
"""A storable nearest-centroid classifier kept outside the package."""

import numpy as np

from tactile_exp.models.base import Model
from tactile_exp.models.registry import MODELS


@MODELS.register("plugin_centroid")
class Centroid(Model):
    learns_representation = False
    reads = ()
    storable = True

    def __init__(self, *, shrink: float = 0.0) -> None:
        self.shrink = shrink

    def fit(self, train, on_epoch=None):
        X = train.X.reshape(len(train), -1)
        self.input_shape_ = tuple(train.X.shape[1:])
        self.direction_ = X[train.y == 1].mean(0) - (1 - self.shrink) * X[train.y == 0].mean(0)
        return {}

    def decision_function(self, X):
        return np.asarray(X).reshape(len(X), -1) @ self.direction_

    def head(self):
        return type(self)(shrink=self.shrink)

    def state(self):
        return {}, {"direction": self.direction_}

    def restore(self, input_shape, tensors, arrays):
        self.input_shape_ = tuple(input_shape)
        self.direction_ = np.asarray(arrays["direction"])
        return self


class Unregistered(Centroid):
    """A head class nobody registered."""


@MODELS.register("plugin_headless")
class Headless(Centroid):
    def head(self):
        return Unregistered(shrink=self.shrink)
'''

MINIROCKET = doc_block("extending.md", "# aeon's MiniRocket features")  # the page's YAML


@pytest.fixture
def plugin_dir(tmp_path, monkeypatch):
    """A folder outside the repository holding a module (``my_models.centroid``) and a config
    dir with its YAMLs; the module's registrations are forgotten after the test."""
    (tmp_path / "my_models").mkdir()
    (tmp_path / "my_models" / "centroid.py").write_text(CENTROID)
    (tmp_path / "conf" / "model").mkdir(parents=True)
    for name in ("plugin_centroid", "plugin_headless"):
        (tmp_path / "conf" / "model" / f"{name}.yaml").write_text(
            f"name: {name}\n_module_: my_models.centroid\nshrink: 0.0\n"
        )
    (tmp_path / "conf" / "model" / "my_rocket.yaml").write_text(MINIROCKET)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.chdir(tmp_path)
    for module in ("my_models.centroid", "my_models"):  # another test's folder of that name
        monkeypatch.delitem(sys.modules, module, raising=False)
    with MODELS.temporary():
        yield tmp_path
    for module in ("my_models.centroid", "my_models"):
        sys.modules.pop(module, None)


def _settings(config_dir: Path, overrides: list[str], cache_dir: Path, uri: str):
    """A job's settings as ``python -m tactile_exp --config-dir DIR ...`` composes them."""
    base = [
        f"hydra.searchpath=[file://{config_dir}]",
        *TINY_DATA,
        f"cache_dir={cache_dir}",
        f"tracking.uri={uri}",
        "adjectives=[hard]",
    ]
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return settings_from_config(compose("config", overrides=[*base, *overrides]))


def test_every_module_a_config_names_is_found_at_any_depth():
    config = {
        "data": {"name": "synthetic"},
        "modality": {"name": "mine", "_module_": "a.mod", "parts": [{"_module_": "b.mod"}]},
        "model": {"name": "x", "_module_": "c.mod"},
    }
    assert plugins.modules(config) == {
        "modality._module_": "a.mod",
        "modality.parts.0._module_": "b.mod",
        "model._module_": "c.mod",
    }
    with pytest.raises(plugins.PluginError) as err:
        plugins.import_modules({"model": {"_module_": "no_such_package.models"}}, "run abc")
    assert str(err.value).startswith(
        "run abc: model._module_ 'no_such_package.models' cannot be imported (No module named"
    )
    assert "\n" not in str(err.value)


@pytest.mark.job
def test_predict_imports_the_plugin_models_module_in_a_fresh_process(
    plugin_dir, cache_dir, mlflow_uri
):
    """The job's model is registered by a module outside the package; predict, run where that
    module has not been imported, finds it through the job's logged config."""
    with MODELS.temporary():  # what the job registers is forgotten after it, as in a new process
        settings = _settings(plugin_dir / "conf", ["model=plugin_centroid"], cache_dir, mlflow_uri)
        result = run(settings)
    sys.modules.pop("my_models.centroid")
    assert "plugin_centroid" not in MODELS.names()
    logged = result.results["hard"].test
    trials = [str(u) for u in logged.units[:2]]
    got = predict(run_id=result.run_id, tracking_uri=mlflow_uri, trials=trials)
    assert "plugin_centroid" in MODELS.names()
    np.testing.assert_allclose(got.scores[:, 0], logged.scores[:2], rtol=1e-6)


def test_a_plugin_whose_head_is_not_registered_is_refused_before_training(
    plugin_dir, cache_dir, mlflow_uri
):
    with pytest.raises(ConfigError) as err:
        _settings(plugin_dir / "conf", ["model=plugin_headless"], cache_dir, mlflow_uri)
    assert str(err.value) == (
        "model: model=plugin_headless's head() gives a my_models.centroid.Unregistered, which "
        "is not a registered model, so a stored pipeline could not name it; register it "
        "(@MODELS.register) or return a registered model from head()"
    )
    separate = ["model=plugin_headless", "combine_instances=separate"]  # no head: fine
    _settings(plugin_dir / "conf", separate, cache_dir, mlflow_uri)


def test_check_model_runs_the_contract_on_a_plugin(plugin_dir):
    check_model("plugin_centroid", config_dir=plugin_dir / "conf")
    with pytest.raises(ConfigError, match="head\\(\\) gives a my_models.centroid.Unregistered"):
        check_model("plugin_headless", config_dir=plugin_dir / "conf")


@pytest.mark.slow  # ~55 s: a job in a new process and MiniRocket's kernels compiled once
@pytest.mark.job
def test_a_yaml_only_minirocket_model_runs_predicts_deploys_and_keeps_the_contract(
    plugin_dir, cache_dir, mlflow_uri
):
    """From a folder outside the repository: ``python -m tactile_exp --config-dir conf
    model=my_rocket`` runs a job; predict and the logged MLflow model score its test trials
    as the job did; ``check_model`` passes; ONNX export is refused in one line."""
    import mlflow
    import pandas as pd

    from tactile_exp.deploy.mlflow_model import log_job
    from tactile_exp.deploy.onnx_export import export_job
    from tactile_exp.jobs import PredictError, StoredJob

    args = [
        "--config-dir", "conf", "model=my_rocket", *TINY_DATA, f"cache_dir={cache_dir}",
        f"tracking.uri={mlflow_uri}", "adjectives=[hard]", f"hydra.run.dir={plugin_dir / 'run'}",
    ]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[1])}
    done = subprocess.run(
        [sys.executable, "-m", "tactile_exp", *args],
        capture_output=True, text=True, timeout=300, env=env, cwd=plugin_dir,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    client = mlflow.MlflowClient(mlflow_uri)
    experiment = client.get_experiment_by_name("tactile_exp").experiment_id
    (job,) = client.search_runs([experiment], "tags.run_level = 'parent'")
    assert job.data.params["model.transformer._target_"].endswith("MiniRocket")
    assert "schedule.epochs" not in job.data.params  # a model without epochs
    assert job.info.run_name.startswith("my_rocket-concat-c1")
    (child,) = client.search_runs([experiment], f"tags.mlflow.parentRunId = '{job.info.run_id}'")
    auc = child.data.metrics["auc"]
    assert 0.0 <= auc <= 1.0

    logged = StoredJob.open(job.info.run_id, tracking_uri=mlflow_uri).scores(child.info.run_id)
    trials = [u.unit for u in logged[:2]]
    got = predict(run_id=job.info.run_id, tracking_uri=mlflow_uri, trials=trials)
    np.testing.assert_allclose(got.scores[:, 0], [u.score for u in logged[:2]], rtol=1e-5)
    info, _ = log_job(job.info.run_id, tracking_uri=mlflow_uri)
    served = mlflow.pyfunc.load_model(info.model_uri)
    data = got.data.split(" (")[0]
    answer = served.predict(pd.DataFrame({"data": [data] * 2, "trial": trials}))
    np.testing.assert_allclose(answer["hard"], got.scores[:, 0], rtol=1e-6)
    with pytest.raises(PredictError, match="not a torch network"):
        export_job(job.info.run_id, plugin_dir / "onnx", tracking_uri=mlflow_uri)

    check_model("my_rocket", config_dir=plugin_dir / "conf")
