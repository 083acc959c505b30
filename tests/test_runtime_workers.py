"""workers=2: adjectives in spawned worker processes give the job that workers=1 gives."""

from __future__ import annotations

import logging
import os

import numpy as np
import pytest
from mlflow.tracking import MlflowClient

from tactile_exp.config import settings_from_config
from tactile_exp.errors import ConfigError
from tactile_exp.experiment import run
from tactile_exp.models import MODELS


def _children(uri: str, config_hash: str) -> list:
    client = MlflowClient(uri)
    exp = client.get_experiment_by_name("tactile_exp")
    query = f"tags.config_hash = '{config_hash}' and tags.run_level = 'child'"
    return client.search_runs([exp.experiment_id], filter_string=query, max_results=100)


def test_two_workers_give_the_same_job_as_one(tiny_config, mlflow_uri, caplog):
    caplog.set_level(logging.INFO)
    base = ["model=linear", "modality=haptic_features", "seed=4", "tracking.skip_finished=false"]
    adjectives = "[hard,soft,smooth]"
    one = run(settings_from_config(tiny_config(base, adjectives=adjectives)))
    two_settings = settings_from_config(tiny_config([*base, "workers=2"], adjectives=adjectives))
    two = run(two_settings)
    assert list(two.results) == ["hard", "soft", "smooth"]  # in the configured order
    for adjective, expected in one.results.items():
        got = two.results[adjective]
        np.testing.assert_array_equal(got.test.units, expected.test.units)
        np.testing.assert_allclose(got.test.scores, expected.test.scores, rtol=1e-4, atol=1e-5)
        assert got.metrics["auc"] == pytest.approx(expected.metrics["auc"], abs=1e-3)
    children = _children(mlflow_uri, two_settings.config_hash)
    mine = [c for c in children if c.data.tags["mlflow.parentRunId"] == two.run_id]
    assert sorted(c.info.run_name for c in mine) == ["adj=hard", "adj=smooth", "adj=soft"]
    assert all(c.info.status == "FINISHED" for c in mine)
    pids = {c.data.tags["pid"] for c in mine}
    assert str(os.getpid()) not in pids and 1 <= len(pids) <= 2  # trained in the workers
    relayed = [r for r in caplog.records if "(worker " in r.getMessage()]
    assert len(relayed) == 3  # the workers' progress lines reach the job's log


FAILING = """
from tactile_exp.models.base import Model
from tactile_exp.models.registry import MODELS


@MODELS.register("cannot_fit")
class CannotFit(Model):
    learns_representation = False

    def __init__(self, *, seed: int = 0) -> None:
        self.seed = seed

    def fit(self, train, on_epoch=None):
        raise RuntimeError("this model cannot be fitted")

    def decision_function(self, X):
        raise AssertionError("never fitted")
"""


@pytest.fixture
def models():
    """MODELS as it is, restored after the test: a model registered in the test stays in it."""
    with MODELS.temporary():
        yield MODELS


def test_a_failing_worker_fails_the_job_and_its_run(
    tiny_config, mlflow_uri, tmp_path, monkeypatch, models
):
    """A model registered by ``_module_`` (imported again in each worker) that raises: the job
    ends with that error, the runs FAILED, none left RUNNING."""
    (tmp_path / "failing_models.py").write_text(FAILING)
    monkeypatch.syspath_prepend(str(tmp_path))  # spawned workers get the job's sys.path
    cfg = tiny_config(
        [
            "modality=haptic_features",
            "combine_instances=separate",
            "workers=2",
            "model=random",
            "+model._module_=failing_models",
            "model.name=cannot_fit",
        ],
        adjectives="[hard,soft,smooth]",
    )
    settings = settings_from_config(cfg)
    with pytest.raises(RuntimeError, match="this model cannot be fitted"):
        run(settings)
    client = MlflowClient(mlflow_uri)
    runs = client.search_runs([client.get_experiment_by_name("tactile_exp").experiment_id])
    status = {r.info.run_name: r.info.status for r in runs}
    assert "RUNNING" not in status.values()
    assert status["adj=hard"] == "FAILED"
    assert status[settings.run_name] == "FAILED"


@pytest.mark.parametrize("value", [0, -1, "two", 1.5, True])
def test_impossible_workers_are_refused(tiny_config, value):
    with pytest.raises(ConfigError, match="workers"):
        settings_from_config(tiny_config([f"workers={value}"]))
