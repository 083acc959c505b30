"""What `mlflow ui` shows of a job: experiment kind, source tags, dataset input, row grouping."""

import subprocess
from pathlib import Path

from mlflow.tracking import MlflowClient

from tactile_exp.config import settings_from_config
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.experiment import run
from tactile_exp.tracking import EXPERIMENT_TAGS, Tracker, git_commit

ROOT = Path(__file__).resolve().parents[1]
FAST = ["model=random", "combine_instances=separate"]


def test_job_runs_carry_ui_tags_and_the_data_file_as_input(tiny_config, mlflow_uri):
    settings = settings_from_config(tiny_config([*FAST, "seed=41"], adjectives="[hard]"))
    run(settings)
    client = MlflowClient(mlflow_uri)
    experiment = client.get_experiment_by_name("tactile_exp")
    assert experiment.tags["mlflow.experimentKind"] == "custom_model_development"
    runs = client.search_runs([experiment.experiment_id])
    parent = next(r for r in runs if r.data.tags["run_level"] == "parent")
    child = next(r for r in runs if r.data.tags["run_level"] == "child")
    head = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    for r in (parent, child):
        assert r.data.tags["mlflow.source.name"] == "python -m tactile_exp"
        assert r.data.tags.get("mlflow.source.git.commit") == (head or None)
    dataset = DATA_SOURCES.build(settings.data.name, **settings.data.params)
    inputs = parent.inputs.dataset_inputs
    assert [(i.dataset.name, i.dataset.digest) for i in inputs] == [
        (dataset.path.stem, dataset.digest())
    ]
    assert f"{inputs[0].dataset.name}-{inputs[0].dataset.digest}" == dataset.identity()
    assert parent.data.tags["data.identity"] == dataset.identity()
    assert parent.data.tags["row_hash"] == settings.row_hash


def test_existing_experiment_gets_the_kind_tag(mlflow_uri):
    client = MlflowClient(mlflow_uri)
    created = client.create_experiment("older")
    assert "mlflow.experimentKind" not in client.get_experiment(created).tags
    assert Tracker(mlflow_uri, "older").experiment_id == created
    assert (
        client.get_experiment(created).tags["mlflow.experimentKind"]
        == (EXPERIMENT_TAGS["mlflow.experimentKind"])
    )


def test_no_commit_outside_a_checkout(tmp_path):
    assert git_commit(tmp_path) is None  # no pyproject.toml: an installed package
    (tmp_path / "pyproject.toml").write_text("")
    assert git_commit(tmp_path) is None  # a source tree that is not a git checkout


def test_row_hash_ignores_only_the_seed(tiny_config):
    base = settings_from_config(tiny_config(["seed=0"]))
    other_seed = settings_from_config(tiny_config(["seed=1"]))
    assert other_seed.row_hash == base.row_hash and other_seed.config_hash != base.config_hash
    for change in (["schedule=quick"], ["split=random"], ["combine_instances=mean"]):
        assert settings_from_config(tiny_config(["seed=0", *change])).row_hash != base.row_hash
    fewer = settings_from_config(tiny_config(["seed=0"], adjectives="[hard]"))
    assert fewer.row_hash != base.row_hash
