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


# ---------------------------------------------------------------- Tracker, direct
def test_flatten_dots_nested_keys_and_truncates_long_values():
    from tactile_exp.tracking import MAX_PARAM_LENGTH, flatten

    nested = {"a": {"b": 1, "c": {"d": [1, 2]}}, "e": "x" * (MAX_PARAM_LENGTH + 5)}
    assert flatten(nested) == {"a.b": "1", "a.c.d": "[1, 2]", "e": "x" * MAX_PARAM_LENGTH}
    assert flatten({"k": None}, "p.") == {"p.k": "None"}


def test_run_ends_finished_failed_or_killed_with_the_error_and_every_param(mlflow_uri):
    import pytest

    tracker = Tracker(mlflow_uri, "runs")
    params = {f"p{i}": str(i) for i in range(250)}  # more than one batch of 100
    with tracker.run("ok", params, {"level": "x"}) as ok:
        tracker.log_curves(ok, {"loss": [3.0, 2.0, 1.0]}, start=5)
        tracker.log_metrics(ok, {"auc": 0.75}, step=2)
    with pytest.raises(ValueError), tracker.run("bad", {}, {}, parent_id=ok):
        raise ValueError("boom")
    with pytest.raises(KeyboardInterrupt), tracker.run("stop", {}, {}):
        raise KeyboardInterrupt
    client = MlflowClient(mlflow_uri)
    runs = {r.info.run_name: r for r in client.search_runs([tracker.experiment_id])}
    assert runs["ok"].info.status == "FINISHED" and runs["ok"].data.params == params
    assert runs["ok"].data.tags["level"] == "x" and "error" not in runs["ok"].data.tags
    history = client.get_metric_history(ok, "loss")
    assert sorted((m.step, m.value) for m in history) == [(5, 3.0), (6, 2.0), (7, 1.0)]
    assert [(m.step, m.value) for m in client.get_metric_history(ok, "auc")] == [(2, 0.75)]
    assert runs["bad"].info.status == "FAILED"
    assert runs["bad"].data.tags["error"] == "ValueError: boom"
    assert runs["bad"].data.tags["mlflow.parentRunId"] == ok
    assert runs["stop"].info.status == "KILLED"
    assert runs["stop"].data.tags["error"].startswith("KeyboardInterrupt")


def test_curves_longer_than_a_batch_are_logged_whole(mlflow_uri, monkeypatch):
    from tactile_exp import tracking

    monkeypatch.setattr(tracking, "MAX_BATCH", 4)
    tracker = Tracker(mlflow_uri, "curves")
    with tracker.run("r", {}, {}) as run_id:
        tracker.log_curves(run_id, {"a": [float(i) for i in range(7)], "b": [1.0, 2.0]})
    client = MlflowClient(mlflow_uri)
    assert sorted(m.step for m in client.get_metric_history(run_id, "a")) == list(range(7))
    assert len(client.get_metric_history(run_id, "b")) == 2


def test_stale_running_runs_of_dead_processes_are_killed_live_ones_kept(mlflow_uri):
    import os
    import socket

    tracker = Tracker(mlflow_uri, "stale")
    host = socket.gethostname()
    dead = subprocess.Popen(["true"])
    dead.wait()
    me = str(os.getpid())

    def make(name, **tags):
        base = {"config_hash": "h1", "run_level": "parent"}
        return tracker.client.create_run(tracker.experiment_id, run_name=name, tags=base | tags)

    gone = make("gone", host=host, pid=str(dead.pid), pid_start="")
    alive = make("alive", host=host, pid=me, pid_start="")
    reused_pid = make("reused", host=host, pid=me, pid_start="1")  # same pid, other process
    elsewhere = make("elsewhere", host=host + "-other", pid=str(dead.pid))
    no_pid = make("no_pid", host=host)
    other_hash = make("other", host=host, pid=str(dead.pid), config_hash="h2")
    ended = tracker.end_stale_runs("h1")
    assert sorted(ended) == sorted([gone.info.run_id, reused_pid.info.run_id])
    client = MlflowClient(mlflow_uri)
    status = {r: client.get_run(r.info.run_id).info.status for r in (gone, reused_pid)}
    assert set(status.values()) == {"KILLED"}
    error = client.get_run(gone.info.run_id).data.tags["error"]
    assert error == f"stale: process {dead.pid} on {host} ended without closing this run"
    for r in (alive, elsewhere, no_pid, other_hash):
        assert client.get_run(r.info.run_id).info.status == "RUNNING"
    assert tracker.finished_run("h1", data_identity="any") is None  # RUNNING or KILLED: rerun


def test_reading_a_missing_experiment_names_the_ones_there(mlflow_uri):
    import pytest

    from tactile_exp.tracking import ExperimentNotFound

    Tracker(mlflow_uri, "present")
    with pytest.raises(ExperimentNotFound, match=r"no MLflow experiment 'absent' in .*present"):
        Tracker(mlflow_uri, "absent", create=False)
    assert Tracker(mlflow_uri, "present", create=False).experiment_id


def test_unreachable_server_is_reported_before_any_work():
    import pytest

    from tactile_exp.tracking import TrackingError, check_server

    with pytest.raises(TrackingError, match=r"^tracking.uri: no MLflow server answers at http"):
        check_server("http://127.0.0.1:9/", timeout=1.0)
