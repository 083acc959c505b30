"""What `mlflow ui` shows of a job: experiment kind, source tags, dataset input, row grouping."""

import json
import logging
import os
import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import TINY_DATA
from mlflow.tracking import MlflowClient
from mlflow_ui_fixture import CHROMIUM, mlflow_ui, page

from tactile_exp.config import settings_from_config
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.experiment import run
from tactile_exp.tracking import (
    EXPERIMENT_TAGS,
    SHARED_VIEW_TAG,
    UI_DEFAULT,
    Tracker,
    git_commit,
)

ROOT = Path(__file__).resolve().parents[1]
FAST = ["model=random", "combine_instances=separate"]


@pytest.mark.job
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


def test_new_and_existing_experiments_get_the_kind_tag(mlflow_uri):
    client = MlflowClient(mlflow_uri)
    fresh = Tracker(mlflow_uri, "fresh").experiment_id
    assert client.get_experiment(fresh).tags["mlflow.experimentKind"] == "custom_model_development"
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
        tracker.log_metrics(ok, {"mean_auc": 0.5})
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
    assert [(m.step, m.value) for m in client.get_metric_history(ok, "mean_auc")] == [(0, 0.5)]
    assert runs["bad"].info.status == "FAILED"
    assert runs["bad"].data.tags["error"] == "ValueError: boom"
    assert runs["bad"].data.tags["mlflow.parentRunId"] == ok
    assert runs["stop"].info.status == "KILLED"
    assert runs["stop"].data.tags["error"].startswith("KeyboardInterrupt")


def test_a_sigterm_wrapped_in_another_error_ends_the_run_as_the_signal(mlflow_uri, sigterm_raises):
    """A signal Python re-raises inside another error (here a class built during the run, as an
    import does) still stops the job: the run records the signal and raises it."""
    import pytest

    from tactile_exp.runtime.termination import Terminated

    class Descriptor:
        def __set_name__(self, owner: type, name: str) -> None:
            os.kill(os.getpid(), 15)

    tracker = Tracker(mlflow_uri, "wrapped")
    with pytest.raises(Terminated), tracker.run("job", {}, {}) as run_id:
        type("Owner", (), {"field": Descriptor()})
    run = MlflowClient(mlflow_uri).get_run(run_id)
    assert run.info.status == "FAILED"
    assert run.data.tags["error"] == "Terminated: terminated by signal 15"


def test_curves_longer_than_a_batch_are_logged_whole(mlflow_uri, monkeypatch):
    from tactile_exp import tracking

    monkeypatch.setattr(tracking, "MAX_BATCH", 4)
    tracker = Tracker(mlflow_uri, "curves")
    batches: list[int] = []
    log_batch = tracker.client.log_batch

    def counted(run_id, metrics=(), **kwargs):
        batches.append(len(metrics))
        return log_batch(run_id, metrics=metrics, **kwargs)

    with tracker.run("r", {}, {}) as run_id:
        monkeypatch.setattr(tracker.client, "log_batch", counted)
        tracker.log_curves(run_id, {"a": [float(i) for i in range(7)], "b": [1.0, 2.0]})
        monkeypatch.undo()
    assert batches == [4, 4, 1]  # as few calls as the batch limit allows
    client = MlflowClient(mlflow_uri)
    assert sorted(m.step for m in client.get_metric_history(run_id, "a")) == list(range(7))
    assert len(client.get_metric_history(run_id, "b")) == 2
    now_ms = time.time() * 1000
    assert all(abs(m.timestamp - now_ms) < 600_000 for m in client.get_metric_history(run_id, "a"))


def test_stale_running_runs_of_dead_processes_are_killed_live_ones_kept(mlflow_uri, caplog):
    import os

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
    untimed = make("untimed", host=host, pid=me)  # no start time recorded: pid alone decides
    reused_pid = make("reused", host=host, pid=me, pid_start="1")  # same pid, other process
    elsewhere = make("elsewhere", host=host + "-other", pid=str(dead.pid))
    no_pid = make("no_pid", host=host)
    other_hash = make("other", host=host, pid=str(dead.pid), config_hash="h2")
    with caplog.at_level("WARNING", logger="tactile_exp.tracking"):
        ended = tracker.end_stale_runs("h1")
    assert caplog.messages == ["marked 2 stale RUNNING run(s) of this config KILLED"]
    assert sorted(ended) == sorted([gone.info.run_id, reused_pid.info.run_id])
    client = MlflowClient(mlflow_uri)
    status = {r: client.get_run(r.info.run_id).info.status for r in (gone, reused_pid)}
    assert set(status.values()) == {"KILLED"}
    error = client.get_run(gone.info.run_id).data.tags["error"]
    assert error == f"stale: process {dead.pid} on {host} ended without closing this run"
    for r in (alive, untimed, elsewhere, no_pid, other_hash):
        assert client.get_run(r.info.run_id).info.status == "RUNNING"
    assert tracker.finished_run("h1", data_identity="any") is None  # RUNNING or KILLED: rerun


def test_a_dataset_row_inserted_by_a_parallel_job_is_reused_not_an_error(mlflow_uri, monkeypatch):
    """Seen in a sweep: two jobs insert the data file's dataset row at once; the loser's
    UNIQUE-constraint error failed its job. It retries and links the row the winner made."""
    from mlflow.exceptions import MlflowException

    tracker, winner = Tracker(mlflow_uri, "tactile_exp"), Tracker(mlflow_uri, "tactile_exp")
    data = {"name": "phac2", "digest": "abc", "source": "file:///data/phac2.h5"}
    log_inputs = tracker.client.log_inputs
    calls = []

    def loses_the_race(run_id, datasets):
        calls.append(run_id)
        if len(calls) == 1:
            with winner.run("winner", {}, {}) as other:
                winner.log_dataset(other, **data)
            raise MlflowException("(sqlite3.IntegrityError) UNIQUE constraint failed: datasets")
        return log_inputs(run_id, datasets=datasets)

    monkeypatch.setattr(tracker.client, "log_inputs", loses_the_race)
    with tracker.run("loser", {}, {}) as run_id:
        tracker.log_dataset(run_id, **data)
    assert len(calls) == 2
    inputs = MlflowClient(mlflow_uri).get_run(run_id).inputs.dataset_inputs
    assert [(i.dataset.name, i.dataset.digest) for i in inputs] == [("phac2", "abc")]

    def broken(run_id, datasets):
        raise MlflowException("disk I/O error")

    monkeypatch.setattr(tracker.client, "log_inputs", broken)
    with pytest.raises(MlflowException, match="disk"), tracker.run("other", {}, {}) as run_id:
        tracker.log_dataset(run_id, **data)


def test_an_experiment_tag_another_job_wrote_at_once_is_read_back_not_an_error(
    mlflow_uri, monkeypatch
):
    """PostgreSQL: two jobs insert the same experiment tag at once and the loser gets a
    UniqueViolation (it once failed a job whose runs were FINISHED). The loser reads the tag
    back: the winner's identical value ends it; a different value is written again."""
    from mlflow.exceptions import MlflowException

    from tactile_exp import tracking

    monkeypatch.setattr(tracking.time, "sleep", lambda s: None)
    tracker = Tracker(mlflow_uri, "tactile_exp")
    client, write = MlflowClient(mlflow_uri), tracker.client.set_experiment_tag
    calls = []

    def loses_the_race(experiment_id, key, value):
        calls.append(value)
        if len(calls) == 1:
            client.set_experiment_tag(experiment_id, key, winner)
            raise MlflowException('UniqueViolation: duplicate key ... "experiment_tag_pk"')
        return write(experiment_id, key, value)

    monkeypatch.setattr(tracker.client, "set_experiment_tag", loses_the_race)
    for winner, expected_calls in (("same", ["same"]), ("other", ["mine", "mine"])):
        calls.clear()
        value = "same" if winner == "same" else "mine"
        tracker.set_experiment_tag(tracker.experiment_id, f"key.{winner}", value)
        assert calls == expected_calls
        assert client.get_experiment(tracker.experiment_id).tags[f"key.{winner}"] == value


def test_a_runs_view_that_cannot_be_stored_never_fails_the_job(mlflow_uri, monkeypatch, caplog):
    from mlflow.exceptions import MlflowException

    tracker = Tracker(mlflow_uri, "tactile_exp")

    def broken(*args):
        raise MlflowException("disk I/O error")

    monkeypatch.setattr(tracker.client, "set_experiment_tag", broken)
    with caplog.at_level(logging.WARNING, logger="tactile_exp.tracking"):
        link = tracker.runs_view(["metrics.`mean_auc`"], order_by="metrics.`mean_auc`")
    assert "viewStateShareKey=" in link and "view was not stored (disk I/O error)" in caplog.text


def test_a_server_that_stops_answering_ends_the_job_in_one_line_and_one_fast_try(
    mlflow_uri, monkeypatch
):
    """MLflow's client has spent its retries on a server that is down: the run's end is tried
    once more without retries (not another ~4 minutes), and the job stops with one line."""
    from mlflow.exceptions import MlflowException

    from tactile_exp.tracking import TrackingError

    tracker = Tracker(mlflow_uri, "tactile_exp")
    terminate, retries = tracker.client.set_terminated, []

    def set_terminated(run_id, status):
        retries.append(os.environ.get("MLFLOW_HTTP_REQUEST_MAX_RETRIES"))
        return terminate(run_id, status=status)

    monkeypatch.setattr(tracker.client, "set_terminated", set_terminated)
    down = "API request to http://h:5/api failed with exception HTTPConnectionPool(host='h', "
    down += "port=5): Max retries exceeded with url (Connection refused)"
    raised = pytest.raises(TrackingError, match="stopped answering")
    with raised as error, tracker.run("job", {}, {}) as run_id:
        raise MlflowException(down)
    assert "\n" not in str(error.value) and retries == ["0"]
    assert "MLFLOW_HTTP_REQUEST_MAX_RETRIES" not in os.environ
    assert MlflowClient(mlflow_uri).get_run(run_id).info.status == "FAILED"


def test_reading_a_missing_experiment_names_the_ones_there(mlflow_uri):
    import pytest

    from tactile_exp.tracking import ExperimentNotFound

    Tracker(mlflow_uri, "present")
    message = (
        rf"^no MLflow experiment 'absent' in {mlflow_uri}; experiments there: Default, present$"
    )
    with pytest.raises(ExperimentNotFound, match=message):
        Tracker.open(mlflow_uri, "absent")
    present = Tracker.open(mlflow_uri, "present").experiment_id
    assert present == Tracker(mlflow_uri, "present").experiment_id
    client = MlflowClient(mlflow_uri)
    assert sorted(e.name for e in client.search_experiments()) == ["Default", "present"]
    for experiment in client.search_experiments():
        client.delete_experiment(experiment.experiment_id)
    with pytest.raises(ExperimentNotFound, match=r"; experiments there: none$"):
        Tracker.open(mlflow_uri, "absent")


def test_unreachable_server_is_reported_before_any_work():
    import pytest

    from tactile_exp.tracking import TrackingError, check_server

    message = (
        r"^tracking.uri: no MLflow server answers at http://127.0.0.1:9/ \(.*Connection refused\); "
        r"start one \(`mlflow server`\) or use tracking=local$"
    )
    with pytest.raises(TrackingError, match=message):
        check_server("http://127.0.0.1:9/", timeout=1.0)
    with pytest.raises(TrackingError, match=r"at http://\[bad \(.*IPv6.*\); start one"):
        check_server("http://[bad")  # no `reason`: the error itself is shown


def test_finished_run_is_the_finished_parent_of_that_config_and_data_only(mlflow_uri):
    tracker = Tracker(mlflow_uri, "resume")
    parent = {"config_hash": "h1", "run_level": "parent", "data.identity": "d1"}
    with pytest.raises(RuntimeError), tracker.run("crashed", {}, parent):
        raise RuntimeError("crash")
    with tracker.run("child", {}, parent | {"run_level": "child"}):
        pass
    with tracker.run("other", {}, parent | {"config_hash": "h2"}):
        pass
    with tracker.run("other data", {}, parent | {"data.identity": "d2"}):
        pass
    tracker.client.create_run(tracker.experiment_id, run_name="running", tags=parent)
    # FAILED, a child, another hash, RUNNING; another file's run is no match either
    assert tracker.finished_run("h1", data_identity="d1") is None
    with tracker.run("done", {}, parent) as done:
        pass
    assert tracker.finished_run("h1", data_identity="d1") == done
    assert Tracker(mlflow_uri, "elsewhere").finished_run("h1", data_identity="d1") is None


def test_run_queries_return_what_they_are_named_after(mlflow_uri):
    """A store of two jobs (one of a sweep), children of every level and status, training-key
    claims, and the same tree in another experiment, which no query may return."""
    tracker, other = Tracker(mlflow_uri, "queries"), Tracker(mlflow_uri, "other")

    def logged(where: Tracker, name: str, tags: dict, parent=None, fail=False, metrics=None):
        time.sleep(0.01)  # distinct start times (ms): "newest" and "oldest" are defined
        try:
            with where.run(name, {}, tags, parent) as run_id:
                where.log_metrics(run_id, metrics or {})
                if fail:
                    raise RuntimeError("crash")
        except RuntimeError:
            pass
        return run_id

    job = {"run_level": "parent"}
    old = logged(tracker, "old", job)
    crashed = logged(tracker, "crashed", job, fail=True)
    new = logged(tracker, "new", job | {"sweep_id": "s1"})
    logged(other, "elsewhere", job)
    hard = logged(
        tracker,
        "hard",
        {"run_level": "child", "adjective": "hard"},
        new,
        metrics={"val_auc": 0.75, "auc": 0.5},
    )
    soft = logged(
        tracker, "soft", {"run_level": "child", "adjective": "soft"}, new, metrics={"auc": 0.25}
    )
    failed = logged(
        tracker,
        "cool",
        {"run_level": "child", "adjective": "cool"},
        new,
        fail=True,
        metrics={"val_auc": 0.5},
    )
    part = logged(tracker, "part", {"run_level": "part", "adjective": "hard"}, new)
    logged(tracker, "old's", {"run_level": "child", "adjective": "hard"}, old)
    running = tracker.client.create_run(tracker.experiment_id, tags=job).info.run_id

    ids = lambda runs: [r.info.run_id for r in runs]  # noqa: E731
    assert ids(tracker.jobs()) == [new, old]  # FINISHED, newest first
    assert ids(tracker.jobs(finished_only=False)) == [running, new, crashed, old]
    assert ids(tracker.jobs(sweep_id="s1")) == [new] and tracker.jobs(sweep_id="s2") == []
    assert ids(tracker.jobs(limit=1)) == [new]
    assert ids(tracker.child_runs(new)) == [hard, soft, failed]  # oldest first, any status
    assert ids(tracker.child_runs(new, finished_only=True)) == [hard, soft]
    assert ids(tracker.child_runs(new, level="part")) == [part]
    assert ids(tracker.child_runs(new, level=None)) == [hard, soft, failed, part]
    assert tracker.children(new) == {"hard": hard, "soft": soft}
    assert tracker.child_metrics(new, "val_auc") == {"hard": 0.75, "cool": 0.5}
    assert tracker.child_metrics(new, "auc") == {"hard": 0.5, "soft": 0.25}
    assert tracker.children(running) == {} and other.children(new) == {}

    assert tracker.trained_run("k") is None and tracker.claims("k") == []
    first = tracker.client.create_run(tracker.experiment_id, tags={"training_key": "k"})
    time.sleep(0.01)
    second = tracker.client.create_run(tracker.experiment_id, tags={"training_key": "k"})
    tracker.client.create_run(tracker.experiment_id, tags={"training_key": "k2"})
    assert ids(tracker.claims("k")) == [first.info.run_id, second.info.run_id]
    assert tracker.trained_run("k") is None  # RUNNING: a claim, not a trained model
    for claim in (first, second):
        tracker.client.set_terminated(claim.info.run_id, "FINISHED")
    assert tracker.claims("k") == [] and other.claims("k") == []
    assert tracker.trained_run("k").info.run_id == second.info.run_id  # the newest

    sweep = logged(tracker, "sweep", {"run_level": "sweep", "sweep_id": "s1"})
    assert ids(tracker.sweep_runs("s1")) == [sweep] and tracker.sweep_runs("s2") == []


def test_no_module_but_tracking_writes_a_run_query():
    """MLflow's filter syntax and the tags it filters on live in ``Tracker`` alone."""
    package = ROOT / "tactile_exp"
    writers = [
        str(path.relative_to(ROOT))
        for path in sorted(package.rglob("*.py"))
        if path != package / "tracking.py"
        and re.search(r"search_runs|filter_string|run_level = '", path.read_text())
    ]
    assert writers == []


def test_runs_carry_source_and_process_tags_and_their_artifacts(mlflow_uri, tmp_path):
    import os

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tracker = Tracker(mlflow_uri, "tags", entry_point="python -m tactile_exp.sweep")
    (tmp_path / "f.txt").write_text("file")
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "g.txt").write_text("dir")
    with tracker.run("r", {}, {"mine": "1"}) as run_id:
        tracker.set_tags(run_id, {"late": "2", "later": "3"})
        tracker.log_dataset(run_id, name="phac2.h5", digest="abc", source="/data/phac2.h5")
        tracker.log_text(run_id, "hello", "notes/t.txt")
        tracker.log_file(run_id, tmp_path / "f.txt", "files")
        tracker.log_dir(run_id, tmp_path / "d", "folder")
        figure = plt.figure(figsize=(2, 1), dpi=50)
        tracker.log_figure(run_id, figure, "plots/f.png")
        plt.close(figure)
    run = MlflowClient(mlflow_uri).get_run(run_id)
    tags = run.data.tags
    assert tags["mlflow.runName"] == "r" and tags["mine"] == "1"
    assert (tags["late"], tags["later"]) == ("2", "3")
    assert tags["mlflow.source.name"] == "python -m tactile_exp.sweep"
    assert tags["mlflow.source.type"] == "LOCAL"
    assert tags["host"] == socket.gethostname() and tags["pid"] == str(os.getpid())
    start = Path(f"/proc/{os.getpid()}/stat").read_text().rsplit(")", 1)[1].split()[19]
    assert tags["pid_start"] == start
    (dataset,) = run.inputs.dataset_inputs
    assert (dataset.dataset.name, dataset.dataset.digest) == ("phac2.h5", "abc")
    assert (dataset.dataset.source, dataset.dataset.source_type) == ("/data/phac2.h5", "local")
    root = Path(run.info.artifact_uri.removeprefix("file://"))
    db_dir = Path(mlflow_uri.removeprefix("sqlite:///")).parent
    assert root.is_relative_to(db_dir / "mlartifacts")  # artifacts beside the database
    assert (root / "notes" / "t.txt").read_text() == "hello"
    assert (root / "files" / "f.txt").read_text() == "file"
    assert (root / "folder" / "g.txt").read_text() == "dir"
    assert (root / "plots" / "f.png").read_bytes().startswith(b"\x89PNG")


def test_artifact_downloads_draw_no_progress_bars(mlflow_uri, tmp_path, monkeypatch):
    """With tqdm installed (a GPU image had it), MLflow drew a bar per download into predict's
    error output; the tracker turns them off. A stand-in tqdm counts the bars drawn."""
    import sys
    import types

    from tactile_exp.store import download

    bars = []
    fake = types.ModuleType("tqdm.auto")
    fake.tqdm = lambda *args, **kwargs: (
        bars.append(kwargs)
        or types.SimpleNamespace(update=lambda n: None, refresh=lambda: None, close=lambda: None)
    )
    monkeypatch.setitem(sys.modules, "tqdm", types.ModuleType("tqdm"))
    monkeypatch.setitem(sys.modules, "tqdm.auto", fake)
    tracker = Tracker(mlflow_uri, "bars")
    (tmp_path / "model").mkdir()
    for name in ("a.json", "b.npz"):
        (tmp_path / "model" / name).write_text(name)
    with tracker.run("r", {}, {}) as run_id:
        tracker.log_dir(run_id, tmp_path / "model", "model")
    folder = download(tracker, run_id, "model", ("a.json", "b.npz"))
    assert (folder / "b.npz").read_text() == "b.npz"
    assert bars == []


def test_tracking_uri_and_artifact_root(monkeypatch, tmp_path):
    from tactile_exp import tracking

    assert tracking._artifact_root("http://host:5000") is None
    assert tracking._artifact_root(f"sqlite:///{tmp_path}/m.db") == f"file://{tmp_path}/mlartifacts"
    monkeypatch.chdir(tmp_path)
    assert tracking.project_root() == ROOT  # the checkout, wherever the cwd is
    monkeypatch.setattr(tracking, "__file__", str(tmp_path / "site" / "pkg" / "tracking.py"))
    assert tracking.project_root() == tmp_path  # an installed package: the cwd


def test_git_commit_of_the_checkout(tmp_path):
    """The commit of a checkout made here: ROOT is none in mutmut's copy of the tree, and a test
    that accepts None there and the commit elsewhere passes either way."""
    (tmp_path / "pyproject.toml").write_text("")

    def git(*args: str) -> str:
        done = subprocess.run(["git", "-C", str(tmp_path), *args], capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        return done.stdout.strip()

    git("init", "-q")
    git("add", "pyproject.toml")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "--no-gpg-sign", "-qm", "1")
    commit = git("log", "-1", "--format=%H")
    assert len(commit) == 40 and git_commit(tmp_path) == commit


def test_check_server_asks_health_once():
    import http.server
    import threading

    from tactile_exp.tracking import check_server

    paths: list[str] = []

    class Health(http.server.BaseHTTPRequestHandler):
        def do_GET(self):  # noqa: N802 (the handler's name)
            paths.append(self.path)
            self.send_response(200)
            self.end_headers()
            self.wfile.write(b"OK")

        def log_message(self, *args):
            pass

    server = http.server.HTTPServer(("127.0.0.1", 0), Health)
    thread = threading.Thread(target=server.handle_request)
    thread.start()
    try:
        check_server(f"http://127.0.0.1:{server.server_port}/")
    finally:
        thread.join(5)
        server.server_close()
    assert paths == ["/health"]


def test_experiment_creation_retries_a_conflict_and_raises_anything_else(mlflow_uri, monkeypatch):
    """Create-or-get: a lost race (or sqlite's lock) is read back and retried with a growing
    wait; an error no other job's write explains raises at once."""
    from mlflow.tracking import MlflowClient as Client

    from tactile_exp import tracking

    waits: list[float] = []
    monkeypatch.setattr(tracking.time, "sleep", waits.append)
    tries: list[str] = []

    def racing(self, name, **kwargs):
        tries.append(name)
        if len(tries) < 3:
            raise RuntimeError("database is locked")
        return original(self, name, **kwargs)

    original = Client.create_experiment
    monkeypatch.setattr(Client, "create_experiment", racing)
    tracker = Tracker(mlflow_uri, "raced")
    assert tries == ["raced"] * 3 and len(waits) == 2 and 0 < waits[0] < waits[1]
    assert Client(mlflow_uri).get_experiment_by_name("raced").experiment_id == (
        tracker.experiment_id
    )
    waits.clear()
    monkeypatch.setattr(Client, "create_experiment", lambda self, name, **kw: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        Tracker(mlflow_uri, "never")
    assert waits == []


def test_check_server_waits_only_its_timeout(monkeypatch):
    from tactile_exp import tracking

    calls: list[tuple[str, object]] = []

    class Answer:
        def __enter__(self):
            return self

        def __exit__(self, *args):
            return False

        def read(self):
            return b"OK"

    def urlopen(url, timeout=None):
        calls.append((url, timeout))
        return Answer()

    monkeypatch.setattr(tracking.urllib.request, "urlopen", urlopen)
    tracking.check_server("http://h:5000")
    tracking.check_server("http://h:5000/", timeout=1.5)
    tracking.check_server("http://mlflowX//")
    assert calls == [
        ("http://h:5000/health", 5.0),
        ("http://h:5000/health", 1.5),
        ("http://mlflowX/health", 5.0),
    ]


def test_a_killed_worker_not_yet_reaped_has_its_runs_closed(mlflow_uri):
    """A zombie (ended, its parent has not waited for it) counts as ended: a terminated sweep
    closes the runs of a worker that loky killed and nobody reaped yet (a CI failure)."""
    from tactile_exp import tracking
    from tactile_exp.runtime import processes

    child = subprocess.Popen(["sleep", "30"])
    tracker = tracking.Tracker(mlflow_uri, "tactile_exp")
    tags = {"host": socket.gethostname(), "pid": str(child.pid)}
    tags["pid_start"] = processes.process_start(child.pid)
    run = tracker.client.create_run(tracker.experiment_id, run_name="adj=hard", tags=tags)
    child.kill()
    deadline = time.monotonic() + 10
    while processes.stat_fields(child.pid)[:1] != ["Z"] and time.monotonic() < deadline:
        time.sleep(0.01)
    try:
        assert processes.stat_fields(child.pid)[0] == "Z"  # not reaped: the PID still exists
        assert not processes.process_alive(child.pid, tags["pid_start"])
        assert tracker.end_runs_of([child.pid], error="killed") == [run.info.run_id]
    finally:
        child.wait()
    closed = tracker.client.get_run(run.info.run_id)
    assert closed.info.status == "FAILED" and closed.data.tags["error"] == "killed"


def test_source_tags_name_the_commit_of_the_checkout_when_there_is_one(monkeypatch):
    from tactile_exp import tracking

    asked: list[Path] = []

    def commit(root):
        asked.append(root)
        return "c0ffee"

    monkeypatch.setattr(tracking, "git_commit", commit)
    assert tracking.source_tags("python -m x") == {
        "mlflow.source.name": "python -m x",
        "mlflow.source.type": "LOCAL",
        "mlflow.source.git.commit": "c0ffee",
    }
    assert asked == [ROOT]  # the checkout holding the package, not the cwd's repository
    monkeypatch.setattr(tracking, "git_commit", lambda root: None)
    assert "mlflow.source.git.commit" not in tracking.source_tags("python -m x")


def test_a_tracking_server_is_checked_before_mlflow_is_asked(mlflow_uri, monkeypatch):
    """http(s) URIs get one short /health request (MLflow itself would retry for minutes)."""
    from tactile_exp.tracking import TrackingError

    # Were the check skipped, MLflow's own request must fail at once, not after its backoff.
    monkeypatch.setenv("MLFLOW_HTTP_REQUEST_MAX_RETRIES", "0")
    monkeypatch.setenv("MLFLOW_HTTP_REQUEST_TIMEOUT", "2")

    for uri in ("http://127.0.0.1:9", "https://127.0.0.1:9"):
        with pytest.raises(
            TrackingError, match=rf"^tracking.uri: no MLflow server answers at {uri} "
        ):
            Tracker(uri, "x")
    assert Tracker(mlflow_uri, "x").source_tags["mlflow.source.name"] == "python -m tactile_exp"


@pytest.mark.job
def test_a_child_found_alone_names_its_job_choices_and_data(tiny_config, mlflow_uri, caplog):
    overrides = (*FAST, "seed=41")
    settings = settings_from_config(tiny_config(list(overrides), "[hard]"), overrides=overrides)
    with caplog.at_level(logging.INFO, logger="tactile_exp"):
        run(settings)
    client = MlflowClient(mlflow_uri)
    experiment = client.get_experiment_by_name("tactile_exp")
    runs = client.search_runs([experiment.experiment_id])
    parent = next(r for r in runs if r.data.tags["run_level"] == "parent")
    child = next(r for r in runs if r.data.tags["run_level"] == "child")
    assert parent.info.run_name == "random-separate-c1-s41"  # what it sets is in the pattern
    assert child.data.tags["job"] == parent.info.run_name
    assert [(i.dataset.name, i.dataset.digest) for i in child.inputs.dataset_inputs] == [
        (i.dataset.name, i.dataset.digest) for i in parent.inputs.dataset_inputs
    ]
    axes = {"axis.model": "random", "axis.combine_instances": "separate", "axis.seed": "41"}
    for r in (parent, child):
        assert r.data.params.items() >= {"choice.model": "random", **axes}.items()
        assert not [k for k, v in r.data.params.items() if k.startswith("choice.") and v == "None"]
    assert child.data.params.items() >= {"adjective": "hard", "combine": "1", "seed": "41"}.items()
    # the log's last lines: the runs table of this job's sweep, and the click without it
    lines = [r.getMessage() for r in caplog.records]
    (link,) = [line for line in lines if line.startswith("runs table")]
    key = link.rsplit("viewStateShareKey=", 1)[1]
    view = json.loads(client.get_experiment(experiment.experiment_id).tags[SHARED_VIEW_TAG + key])
    assert view["selectedColumns"] == [
        "metrics.`mean_auc`",
        *(f"params.`{k}`" for k in ("axis.model", "axis.combine_instances", "axis.seed")),
    ]
    assert "'Model training'" in lines[-1]


def test_runs_view_opens_the_runs_table_with_its_columns(mlflow_uri):
    tracker = Tracker(mlflow_uri, "views")
    columns = ["metrics.`mean_auc`", "params.`axis.combine`"]
    where = {"order_by": "metrics.`mean_auc`"}
    url = tracker.runs_view(columns, **where)
    page, query = url.split("?")
    assert page == f"http://127.0.0.1:5000/#/experiments/{tracker.experiment_id}/runs"
    params = dict(item.split("=") for item in query.split("&"))
    assert params["workflowType"] == "machine_learning"  # not the GenAI Overview
    tags = MlflowClient(mlflow_uri).get_experiment(tracker.experiment_id).tags
    assert json.loads(tags[SHARED_VIEW_TAG + params["viewStateShareKey"]]) == {
        "selectedColumns": columns,
        "searchFilter": "tags.run_level = 'parent'",
        "orderByKey": "metrics.`mean_auc`",
        "orderByAsc": False,
    }
    assert tracker.runs_view(columns, **where) == url  # the jobs of a sweep share one view
    assert tracker.runs_view(columns[:1], **where) != url


@pytest.mark.slow
@pytest.mark.job
@pytest.mark.skipif(
    CHROMIUM is None, reason="no chromium on PATH (Debian: apt-get install chromium)"
)
def test_the_real_ui_opens_the_link_on_the_runs_of_a_sweep(cache_dir, mlflow_uri, tmp_path):
    """A 2-job sweep differing only in the loss (one name, twice), then the
    real ``mlflow ui`` in headless Chromium: the link each job printed opens the runs table
    (not the GenAI Overview) on the two jobs, by name, with mean_auc and the swept axis."""
    args = [*TINY_DATA, f"cache_dir={cache_dir}", f"tracking.uri={mlflow_uri}"]
    args += ["schedule=tiny", "adjectives=[hard]", "loss=hinge,logistic"]
    args += [f"hydra.sweep.dir={tmp_path}/multirun"]
    job = subprocess.run(
        [sys.executable, "-m", "tactile_exp", "-m", *args],
        capture_output=True, text=True, timeout=300, check=True,
    )  # fmt: skip
    links = {
        line.split(": ", 1)[1]
        for line in (job.stdout + job.stderr).splitlines()
        if "runs table" in line
    }
    assert len(links) == 1  # both jobs print one link: their sweep's table
    client = MlflowClient(mlflow_uri)
    experiment = client.get_experiment_by_name("tactile_exp").experiment_id
    parents = client.search_runs([experiment], "tags.run_level = 'parent'")
    names = sorted(r.info.run_name for r in parents)
    assert len(names) == 2 and names[0] != names[1]
    assert "-hinge-" in names[0] and "-logistic-" in names[1]  # the loss, in its short form
    with mlflow_ui(mlflow_uri, tmp_path) as base:
        runs = page(links.pop().replace(UI_DEFAULT, base))
        plain = page(f"{base}/#/experiments/{experiment}")
    assert all(name in runs for name in names)
    text = " ".join(re.sub(r"<[^>]+>", " ", runs).split())
    assert "2 matching runs" in text and "adj=hard" not in runs  # jobs only, children filtered
    assert "mean_auc" in runs and "axis.adjectives" in runs  # the shared view's columns
    # without the link MLflow 3.17 and 3.18 open their GenAI Overview (its text differs between
    # them: 3.17 offers "Detect Issues", 3.18 "Send your first trace"), not the runs table; the
    # documented click is there
    overview = ("Detect Issues", "Send your first trace")
    assert not any(o in runs for o in overview)
    assert any(o in plain for o in overview)
    assert "Model training" in plain and "matching runs" not in plain


def _all_runs(uri: str):
    client = MlflowClient(uri)
    ids = [e.experiment_id for e in client.search_experiments()]
    return client.search_runs(ids, max_results=1000) if ids else []


def test_tracking_uri_is_config_then_environment_then_the_checkout(monkeypatch, tmp_path):
    from tactile_exp import tracking

    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    root = Path(tracking.__file__).resolve().parents[1]
    assert (root / "pyproject.toml").exists()
    assert tracking.resolve_uri(None) == f"sqlite:///{root / 'mlflow.db'}"
    env = f"sqlite:///{tmp_path / 'env.db'}"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", env)
    assert tracking.resolve_uri(None) == env
    assert tracking.resolve_uri("") == env
    assert tracking.resolve_uri("sqlite:///given.db") == "sqlite:///given.db"


@pytest.mark.job
def test_job_without_tracking_uri_logs_to_mlflow_tracking_uri(
    compose_config, cache_dir, mlflow_uri, monkeypatch
):
    monkeypatch.setenv("MLFLOW_TRACKING_URI", mlflow_uri)
    cfg = compose_config([*TINY_DATA, f"cache_dir={cache_dir}", "adjectives=[hard]", *FAST])
    settings = settings_from_config(cfg)
    assert settings.tracking.uri in (None, "")
    result = run(settings)
    runs = _all_runs(mlflow_uri)
    assert result.run_id in {r.info.run_id for r in runs}
    artifacts = Path(mlflow_uri.removeprefix("sqlite:///")).parent / "mlartifacts"
    assert list(artifacts.rglob("auc_per_adjective.csv"))  # artifacts beside the database


@pytest.mark.job
def test_runs_record_host_and_process(tiny_config, mlflow_uri):
    import os

    run(settings_from_config(tiny_config(["model=random", "combine_instances=separate"])))
    runs = _all_runs(mlflow_uri)
    assert runs and all(r.data.tags["host"] == socket.gethostname() for r in runs)
    assert all(r.data.tags["pid"] == str(os.getpid()) for r in runs)
