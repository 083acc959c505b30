"""Search on validation objects: what a job returns to Hydra is its validation
objective, never the test AUC; a search without validation objects is refused before any run; an
interrupted study continues to its number of trials; trials are tagged in MLflow."""

from __future__ import annotations

import math
import os
import shlex
import signal
import socket
import sys
from pathlib import Path

import numpy as np
import optuna
import pytest
from conftest import CONF, TINY_DATA
from hydra.core.global_hydra import GlobalHydra
from mlflow.tracking import MlflowClient

from tactile_exp import experiment, metrics, recording, search
from tactile_exp.config import settings_from_config
from tactile_exp.data.layout import Instances
from tactile_exp.errors import ConfigError
from tactile_exp.modalities.haptic import Haptic
from tactile_exp.objective import value
from tactile_exp.pipeline import AdjectivePipeline


def _search(monkeypatch, tmp_path: Path, cache_dir: Path, mlflow_uri: str, *args: str) -> None:
    """``python -m tactile_exp -m search=haptic_cnn <tiny data> <args>``, in this process."""
    from tactile_exp.__main__ import main

    argv = ["tactile_exp", f"--config-path={CONF}", "-m", "search=haptic_cnn", *TINY_DATA]
    argv.append("schedule=tiny")
    argv += [f"cache_dir={cache_dir}", f"tracking.uri={mlflow_uri}", "adjectives=[hard,soft]"]
    argv += [f"hydra.sweep.dir={tmp_path}/multirun", *args]
    monkeypatch.setattr(sys, "argv", argv)
    handler = signal.getsignal(signal.SIGTERM)
    try:
        main()
    finally:
        signal.signal(signal.SIGTERM, handler)
        GlobalHydra.instance().clear()


def _study(mlflow_uri: str, name: str = "haptic_cnn") -> optuna.Study:
    return optuna.load_study(study_name=name, storage=search.default_storage(mlflow_uri))


def _parents(mlflow_uri: str) -> list:
    client = MlflowClient(mlflow_uri)
    experiment_id = client.get_experiment_by_name("tactile_exp").experiment_id
    return client.search_runs([experiment_id], "tags.run_level = 'parent'")


def _child_val_aucs(mlflow_uri: str, parent_id: str) -> dict[str, float]:
    client = MlflowClient(mlflow_uri)
    runs = client.search_runs(
        [client.get_run(parent_id).info.experiment_id],
        f"tags.mlflow.parentRunId = '{parent_id}' and tags.run_level = 'child'",
    )
    return {r.data.tags["adjective"]: r.data.metrics["val_auc"] for r in runs}


def test_objective_is_a_validation_metric(tiny_config):
    with pytest.raises(ConfigError, match=r"^objective: mean_auc is scored on the test objects"):
        settings_from_config(tiny_config(["objective=mean_auc"]))
    settings = settings_from_config(tiny_config(["objective=min_val_auc"]))
    validation = {"a": {"auc": 0.9, "f1": 0.2}, "b": {"auc": 0.6, "f1": 0.4}, "c": {"f1": 0.9}}
    assert value(settings.objective, validation) == 0.6
    assert value("mean_val_auc", validation) == pytest.approx(0.75)  # c has no AUC
    # Any registered metric, on the validation side: mean_val_<key> and min_val_<key>.
    assert value("mean_val_f1", validation) == pytest.approx(0.5)
    assert value("min_val_f1", validation) == pytest.approx(0.2)
    assert settings_from_config(tiny_config(["objective=mean_val_f1"])).objective == "mean_val_f1"
    assert math.isnan(value("mean_val_auc", {}))  # validation.fraction=0: nothing to select on
    assert math.isnan(value("min_val_average_precision", validation))
    search.check_objective("mean_val_f1", ("roc_auc", "f1"))
    with pytest.raises(ConfigError) as missing:
        search.check_objective("min_val_f1", ("roc_auc",))
    assert str(missing.value) == (
        "objective: min_val_f1 reads the validation f1, which metrics=['roc_auc'] does not "
        "compute; list its metric in metrics"
    )


def test_search_trial_needs_validation_objects(tiny_config):
    with pytest.raises(ConfigError, match=r"^validation\.fraction: 0 holds out no validation"):
        settings_from_config(tiny_config(["search=haptic_cnn", "validation.fraction=0"]))
    settings = settings_from_config(tiny_config(["search=haptic_cnn"]))
    assert settings.study_tags == {"search.study": "haptic_cnn", "search.role": "trial"}
    # The study's keys only tag a job: a trial is the same job as a plain run of its values.
    plain = settings_from_config(tiny_config(["validation.fraction=0.15"]))
    assert settings.config_hash == plain.config_hash


def test_search_space_from_hydra_expressions():
    space = search.search_space(
        {
            "model.kernel_sizes": "choice([3,3,3],[5,5,5])",
            "model.widths.0": "range(2,9,step=2)",
            "schedule.lr": "tag(log, interval(0.001, 0.1))",
            "schedule.momentum": "interval(0.5, 0.99)",
        }
    )
    assert space["model.kernel_sizes"].choices == ("[3,3,3]", "[5,5,5]")
    assert (space["model.widths.0"].low, space["model.widths.0"].high) == (2, 8)
    assert space["model.widths.0"].step == 2
    assert space["schedule.lr"].log and (space["schedule.lr"].low, space["schedule.lr"].high) == (
        0.001,
        0.1,
    )
    assert not space["schedule.momentum"].log
    with pytest.raises(ConfigError, match=r"^hydra\.sweeper\.params\.validation\.fraction: "):
        search.search_space({"validation.fraction": "interval(0.1, 0.3)"})
    # Keys that change the data, the split or the labels change the question: one line each.
    for key in ("split", "split.folds", "data", "data.path", "+data", "adjectives",
                "modality.fit_on", "seed", "tracking.uri", "study.name", "objective"):  # fmt: skip
        with pytest.raises(ConfigError) as refused:
            search.search_space({key: "choice(1,2)"})
        line = str(refused.value)
        assert line.startswith(f"hydra.sweeper.params.{key}: {key} is fixed in a search, not ")
        assert "\n" not in line and line.endswith(search.fixed_reason(key))
    assert "the question, not the answer" in search.fixed_reason("split.fold")
    # A group chosen into another package (``group@package``) is still that group.
    assert search.fixed_reason("+data@sensors") == search.FIXED_KEYS["data"]
    assert search.fixed_reason("~split@outer") == search.FIXED_KEYS["split"]
    with pytest.raises(ConfigError, match=r"^hydra\.sweeper\.params\.schedule\.lr: cannot parse"):
        search.search_space({"schedule.lr": "interval(0.1"})
    for bad in ("range(0.5,3)", "range(5,2)"):  # whole numbers, lo < hi: each alone refused
        with pytest.raises(ConfigError, match=r"takes whole numbers, lo < hi$"):
            search.search_space({"model.widths.0": bad})
    assert (
        search.fixed_reason("adjectives")
        == "it changes the labels, so the question, not the answer"
    )
    for free in ("modality.window", "seeds", "database", "model.widths.0", "splitter"):
        assert search.fixed_reason(free) == ""
    assert set(search.search_space({"modality.window": "choice(1,2)"})) == {"modality.window"}
    with pytest.raises(ConfigError, match=r"^hydra\.sweeper\.params\.schedule\.lr: expected"):
        search.search_space({"schedule.lr": "0.01"})


def test_search_space_edges_a_researcher_meets():
    """A range's last value is the last one its step reaches below hi (Optuna's high is
    inclusive); an empty range, a log interval from 0 and a search with nothing to sample are
    each one line naming what to change."""
    space = search.search_space({"model.widths.0": "range(2,10,step=3)"})
    assert (space["model.widths.0"].low, space["model.widths.0"].high) == (2, 8)  # 2, 5, 8
    with pytest.raises(ConfigError, match=r"takes whole numbers, lo < hi$"):
        search.search_space({"model.widths.0": "range(3,3)"})
    with pytest.raises(
        ConfigError,
        match=r"^hydra\.sweeper\.params\.schedule\.lr: a log interval needs a positive lower end$",
    ):
        search.search_space({"schedule.lr": "tag(log, interval(0, 0.1))"})
    with pytest.raises(ConfigError) as empty:
        search.search_space({})
    assert str(empty.value) == (
        "hydra.sweeper.params: a search needs at least one parameter to sample"
    )


def test_resume_queues_interrupted_and_orphaned_trials_again(monkeypatch):
    study = optuna.create_study(direction="maximize")
    space = search.search_space({"schedule.lr": "interval(0.001, 0.1)"})
    done = study.ask(space)
    study.tell(done, 0.7)
    broken = study.ask(space)
    search.failed(study, broken, "ValueError: job failed")  # a result: counted, not rerun
    stopped = study.ask(space)
    search.interrupted(study, stopped)  # Ctrl-C: not counted, rerun
    orphan = study.ask(space)  # RUNNING in a process that died (kill -9)
    search.claim(orphan)
    orphan.set_user_attr("pid", 2**22 + 1)  # above pid_max: no such process
    assert search.counted(study) == 2
    assert broken.user_attrs == {"error": "ValueError: job failed"}
    assert study.trials[stopped.number].user_attrs == {search.INTERRUPTED: True}
    assert orphan.user_attrs["host"] == socket.gethostname()
    assert study.trials[broken.number].state == optuna.trial.TrialState.FAIL
    assert study.trials[stopped.number].state == optuna.trial.TrialState.FAIL
    alive = study.ask(space)  # RUNNING in this live process: not an orphan
    search.claim(alive)
    assert alive.user_attrs == {"host": socket.gethostname(), "pid": os.getpid()}
    assert search.resume(study) == 2
    assert search.resume(study) == 0  # queued once
    assert study.trials[alive.number].state == optuna.trial.TrialState.RUNNING
    assert search.counted(study) == 2  # the orphan, now failed without an error, is not counted
    assert study.trials[orphan.number].state == optuna.trial.TrialState.FAIL
    again = [study.ask(space).params["schedule.lr"] for _ in range(2)]  # queued values first
    assert sorted(again) == sorted([stopped.params["schedule.lr"], orphan.params["schedule.lr"]])


def test_best_prints_overrides_and_the_final_command(tmp_path, capsys):
    storage = f"sqlite:///{tmp_path}/optuna.db"
    study = search.open_study(
        "s1", storage, direction="maximize", sampler=optuna.samplers.RandomSampler(seed=0)
    )
    fixed = ["search=haptic_cnn", "experiment=table1_i_haptic_cnn_1trial", "adjectives=[hard]"]
    search.check_same_search(study, [*fixed, "validation.fraction=0.2"], "mean_val_auc")
    space = search.search_space({"model.kernel_sizes": "choice([3,3,3],[5,5,5])"})
    for score in (0.6, 0.8):
        study.tell(study.ask(space), score)
    search.failed(study, study.ask(space), "ValueError: job failed")
    best = study.best_trial
    command = search.final_command(search.load_study("s1", storage))
    assert command == [
        "python",
        "-m",
        "tactile_exp",
        *fixed,
        f"model.kernel_sizes={best.params['model.kernel_sizes']}",
        "validation.fraction=0",
        "study.name=s1",
        "study.role=final",
        f"study.trial={best.number}",
    ]
    with pytest.raises(ConfigError, match=r"^hydra\.sweeper\.study_name: study 's1' was run with"):
        search.check_same_search(study, fixed, "mean_val_auc")
    with pytest.raises(ConfigError) as other_objective:  # same overrides, another objective
        search.check_same_search(study, [*fixed, "validation.fraction=0.2"], "min_val_auc")
    recorded = " ".join([*fixed, "validation.fraction=0.2"])
    assert str(other_objective.value) == (
        f"hydra.sweeper.study_name: study 's1' was run with {recorded} (objective mean_val_auc); "
        f"this command has {recorded} (objective min_val_auc): name another study"
    )
    capsys.readouterr()
    assert search.main(["best", "s1", "--storage", storage]) == 0
    assert capsys.readouterr().out.splitlines() == [
        f"study s1: 2 of 3 trials finished; best trial {best.number}: mean_val_auc 0.8000 "
        "(validation objects)",
        "best values:",
        f"  model.kernel_sizes={best.params['model.kernel_sizes']}",
        "the one test evaluation (retrained on every training object, tagged search.role=final):",
        "  " + shlex.join(command),  # quoted: it pastes into a shell as it is
    ]
    import logging

    assert logging.getLogger("optuna").level == logging.WARNING
    with pytest.raises(SystemExit) as no_command:
        search.main([])
    assert no_command.value.code == 2
    with pytest.raises(SystemExit) as exit_info:
        search.main(["best", "nope", "--storage", storage])
    assert exit_info.value.code == 2


def test_best_finds_a_study_beside_the_mlflow_store_and_says_how_in_its_help(mlflow_uri, capsys):
    storage = search.default_storage(mlflow_uri)
    study = search.open_study(
        "s4", storage, direction="minimize", sampler=optuna.samplers.RandomSampler(seed=0)
    )  # made by Optuna alone: no objective or fixed overrides recorded
    study.tell(study.ask(search.search_space({"schedule.lr": "choice(0.1)"})), 0.25)
    assert search.main(["best", "s4", "--tracking-uri", mlflow_uri]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "study s4: 1 of 1 trials finished; best trial 0: objective 0.2500 " + (
        "(validation objects)"
    )
    assert out[-1] == "  python -m tactile_exp schedule.lr=0.1 validation.fraction=0 " + (
        "study.name=s4 study.role=final study.trial=0"
    )
    # docs/search.md names both options and where each looks by default.
    with pytest.raises(SystemExit):
        search.main(["best", "--help"])
    usage = " ".join(capsys.readouterr().out.split())
    assert usage.startswith("usage: python -m tactile_exp.search best [-h] [--storage STORAGE]")
    assert "--storage STORAGE study storage URL (default: beside the MLflow store)" in usage
    assert "--tracking-uri TRACKING_URI MLflow store whose folder holds optuna.db" in usage


@pytest.mark.job
def test_search_without_validation_objects_is_refused_before_any_run(
    monkeypatch, tmp_path, cache_dir, mlflow_uri, capsys
):
    with pytest.raises(SystemExit) as exit_info:
        _search(monkeypatch, tmp_path, cache_dir, mlflow_uri, "validation.fraction=0")
    assert exit_info.value.code == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and errors[0].startswith("error: validation.fraction: 0 holds out")
    assert not Path(search.default_storage(mlflow_uri).removeprefix("sqlite:///")).exists()
    client = MlflowClient(mlflow_uri)
    assert not client.search_runs([e.experiment_id for e in client.search_experiments()])


@pytest.mark.slow
@pytest.mark.job
def test_returned_objective_is_the_validation_mean_not_the_test_mean(
    monkeypatch, tmp_path, cache_dir, mlflow_uri
):
    """Test objects made easy (each replaced by a training instance of its label, which the
    model has fitted), validation objects as they are: the study receives the validation mean,
    and the trial shows and logs no test metric."""
    real_transform = Haptic.transform
    fitted: list[Instances] = []

    def easy_test(self, trials):
        instances = real_transform(self, trials)
        if trials.side == "train":  # what the model is fitted on
            fitted.append(instances)
        elif trials.side == "test":
            train = fitted[-1]
            rows = [np.flatnonzero(train.y == label)[i] for i, label in enumerate(instances.y)]
            instances = Instances(train.X[rows], instances.y, instances.trial, instances.object_id)
        return instances

    monkeypatch.setattr(Haptic, "transform", easy_test)
    _search(monkeypatch, tmp_path, cache_dir, mlflow_uri, "hydra.sweeper.n_trials=1")
    (trial,) = _study(mlflow_uri).trials
    (parent,) = _parents(mlflow_uri)
    val_aucs = _child_val_aucs(mlflow_uri, parent.info.run_id)
    assert set(val_aucs) == {"hard", "soft"}
    assert trial.value == pytest.approx(np.mean(list(val_aucs.values())), abs=1e-12)
    assert trial.value == pytest.approx(parent.data.metrics["mean_val_auc"], abs=1e-12)
    # A trial logs no test metric and no test score, in its job's run or its adjectives'.
    assert not [k for k in parent.data.metrics if k.startswith(("mean_auc", "auc."))]
    client = MlflowClient(mlflow_uri)
    for child in client.search_runs(
        [parent.info.experiment_id], f"tags.mlflow.parentRunId = '{parent.info.run_id}'"
    ):
        assert "auc" not in child.data.metrics and "val_auc" in child.data.metrics
        assert "scores.csv" not in {a.path for a in client.list_artifacts(child.info.run_id)}


@pytest.mark.slow
@pytest.mark.job
def test_interrupted_study_continues_to_its_number_of_trials(
    monkeypatch, tmp_path, cache_dir, mlflow_uri
):
    """Ctrl-C after the third trial's job finished (before the study heard of it): the same
    command ends with 4 finished trials, the third's job skipped as FINISHED, not rerun."""
    real_run = experiment.run
    calls = []

    def interrupted_third(settings):
        result = real_run(settings)
        calls.append(result.run_id)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return result

    monkeypatch.setattr(experiment, "run", interrupted_third)
    with pytest.raises(KeyboardInterrupt):
        _search(monkeypatch, tmp_path, cache_dir, mlflow_uri, "hydra.sweeper.n_trials=4")
    State = optuna.trial.TrialState
    assert [t.state for t in _study(mlflow_uri).trials] == [State.COMPLETE] * 2 + [State.FAIL]

    monkeypatch.setattr(experiment, "run", real_run)
    _search(monkeypatch, tmp_path, cache_dir, mlflow_uri, "hydra.sweeper.n_trials=4")
    trials = _study(mlflow_uri).trials
    complete = [t for t in trials if t.state == State.COMPLETE]
    assert len(complete) == 4 and len(trials) == 5  # 4 finished, 1 interrupted: not 6
    rerun = trials[3]
    assert rerun.user_attrs["requeue_of"] == 2 and rerun.params == trials[2].params
    # Every job ran once: 4 FINISHED runs, tagged with the study and the trial that ran them.
    parents = {r.info.run_id: r for r in _parents(mlflow_uri)}
    assert len(parents) == 4 and all(r.info.status == "FINISHED" for r in parents.values())
    tags = sorted(
        (r.data.tags["search.study"], r.data.tags["search.trial"]) for r in parents.values()
    )
    assert tags == [("haptic_cnn", str(n)) for n in (0, 1, 2, 4)]
    third = parents[calls[2]]
    assert rerun.value == pytest.approx(third.data.metrics["mean_val_auc"], abs=1e-12)
    assert third.data.params["schedule.lr"] == str(trials[2].params["schedule.lr"])
    # The study's summary run: best values, trials.csv, Optuna's two plots.
    client = MlflowClient(mlflow_uri)
    (summary,) = client.search_runs(
        [third.info.experiment_id], "tags.run_level = 'study'", order_by=["start_time DESC"]
    )[:1]
    best = max(complete, key=lambda t: t.value)
    assert summary.data.metrics["best_value"] == pytest.approx(best.value)
    assert summary.data.params["schedule.lr"] == str(best.params["schedule.lr"])
    listed = {a.path for a in client.list_artifacts(summary.info.run_id)}
    assert listed == {"trials.csv", "optimization_history.png", "param_importances.png"}
    csv = client.download_artifacts(summary.info.run_id, "trials.csv", str(tmp_path))
    assert sum(",COMPLETE," in line for line in Path(csv).read_text().splitlines()) == 4


@pytest.mark.slow
@pytest.mark.job
def test_test_scores_never_enter_the_objective(monkeypatch, tiny_config):
    """Sentinel: with every test object's score set to NaN the objective is unchanged."""
    overrides = ["validation.fraction=0.3", "tracking.skip_finished=false"]
    settings = settings_from_config(tiny_config(overrides, adjectives="[hard,soft]"))
    clean = value(settings.objective, experiment.run(settings).validation)

    real_score, real_compute = AdjectivePipeline.score, metrics.compute

    def nan_test_scores(self, instances):  # the engine scores the test side with score()
        scores, units = real_score(self, instances)
        return np.full_like(scores, np.nan, dtype=float), units

    def clean_decision_function(self, trials):  # validation (and predict) go through here
        return real_score(self, self.preprocess.transform(trials))

    def nan_tolerant(names, y, scores):
        if np.all(np.isfinite(scores)):
            return real_compute(names, y, scores)
        return {metrics.METRICS.build(n).key: float("nan") for n in names}

    monkeypatch.setattr(AdjectivePipeline, "score", nan_test_scores)
    monkeypatch.setattr(AdjectivePipeline, "decision_function", clean_decision_function)
    monkeypatch.setattr(metrics, "compute", nan_tolerant)
    monkeypatch.setattr(recording, "log_roc", lambda *args: None)  # ROC of NaN scores
    sentinel = experiment.run(settings)
    assert math.isnan(sentinel.means["mean_auc"])  # the test scores were NaN
    assert math.isfinite(clean) and value(settings.objective, sentinel.validation) == clean


SEARCHES = {  # each search file, and the Table I row it is meant for
    "haptic_cnn": "table1_i_haptic_cnn_1trial",
    "haptic_lstm": "table1_g_haptic_lstm",
    "head": "table1_j_haptic_cnn_10trials",
}


@pytest.mark.parametrize("name", sorted(SEARCHES))
def test_search_files_sample_keys_that_exist(name, compose_config):
    """Each conf/search file is a study of its own name whose sampled keys exist in its row."""
    assert {p.stem for p in (CONF / "search").glob("*.yaml")} == set(SEARCHES)
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose("config", [f"search={name}"], return_hydra_config=True)
    assert cfg.hydra.sweeper.study_name == name and cfg.study.role == "trial"
    assert 0 < cfg.validation.fraction < 1
    space = search.search_space(dict(cfg.hydra.sweeper.params))
    values = {k: d.choices[0] if hasattr(d, "choices") else d.low for k, d in space.items()}
    sampled = [f"{k}={search.as_override(v)}" for k, v in values.items()]
    row = compose_config([f"search={name}", f"experiment={SEARCHES[name]}", *sampled])
    for key, v in values.items():
        node = row
        for part in key.split("."):
            node = node[int(part)] if part.isdigit() else node[part]
        assert str(node) == str(v)


class _Views:
    """A tracker that records the runs view a job's log links to."""

    uri = "http://mlflow"

    def runs_view(self, columns, *, order_by):
        self.columns, self.order_by = list(columns), order_by
        return "http://mlflow/#view"


def test_a_trials_runs_link_sorts_and_shows_validation_not_test_metrics(tiny_config, caplog):
    views = _Views()
    trial = settings_from_config(tiny_config(["search=haptic_cnn"]))
    with caplog.at_level("INFO", logger="tactile_exp"):
        recording.log_view(views, trial)
    assert views.order_by == "metrics.`mean_val_auc`"
    assert not [c for c in views.columns if "mean_auc" in c]
    assert "runs table (jobs by mean validation AUC" in caplog.text
    plain = settings_from_config(tiny_config([]))
    recording.log_view(views, plain)
    assert views.order_by == "metrics.`mean_auc`"


def test_summary_run_trials_csv_and_storage_beside_the_store(
    tmp_path, mlflow_uri, monkeypatch, caplog
):
    from tactile_exp.tracking import Tracker

    assert search.default_storage(mlflow_uri) == (
        f"sqlite:///{Path(mlflow_uri.removeprefix('sqlite:///')).parent / 'optuna.db'}"
    )
    served = search.default_storage("http://mlflow:5000")  # a server: beside the default store
    assert served == search.default_storage(None)
    assert served.startswith("sqlite:////") and served.endswith("/optuna.db")
    storage = f"sqlite:///{tmp_path}/optuna.db"
    assert search.trials_made("s2", storage) == 0
    with pytest.raises(ConfigError, match=r"^study 'nope': not in .*; studies there: none$"):
        search.load_study("nope", storage)
    study = search.open_study(
        "s2", storage, direction="maximize", sampler=optuna.samplers.RandomSampler(seed=1)
    )
    search.check_same_search(study, ["experiment=x"], "mean_val_f1")
    space = search.search_space(
        {"schedule.lr": "interval(0.001, 0.1)", "model.kernel_sizes": "choice([3,3],[5,5])"}
    )
    for score in (0.6, 0.8, 0.7):
        study.tell(study.ask(space), score)
    search.failed(study, study.ask(space), "ValueError: job failed")
    # The same sampler seed draws the same values: a study is reproducible from its command.
    twin = search.open_study(
        "twin", storage, direction="maximize", sampler=optuna.samplers.RandomSampler(seed=1)
    )
    assert twin.ask(space).params == study.trials[0].params
    # A search continued with one more parameter: earlier trials leave its column empty.
    study.tell(study.ask({**space, **search.search_space({"model.widths.0": "range(2,5)"})}), 0.5)
    assert search.trials_made("s2", storage) == 5
    csv_text = search.trials_csv(study)
    assert "\r" not in csv_text
    lines = csv_text.splitlines()
    assert lines[0] == "number,state,value,model.kernel_sizes,model.widths.0,schedule.lr,error"
    assert lines[2].startswith('1,COMPLETE,0.800000,"[') and lines[2].endswith(",")
    assert lines[2].split(",")[-3] == ""  # no model.widths.0 in trial 1
    assert lines[4].startswith("3,FAIL,,") and lines[4].endswith(",ValueError: job failed")
    assert lines[5].startswith("4,COMPLETE,0.500000,")
    tracker = Tracker(mlflow_uri, "searches")
    figures = {}
    log_figure = tracker.log_figure
    monkeypatch.setattr(
        tracker, "log_figure", lambda r, f, p: (figures.setdefault(p, f), log_figure(r, f, p))
    )
    run_id = search.log_summary(study, tracker)
    run = MlflowClient(mlflow_uri).get_run(run_id)
    assert run.info.run_name == "study=s2" and run.info.status == "FINISHED"
    tags = run.data.tags
    assert (tags["run_level"], tags["search.study"], tags["search.objective"]) == (
        "study", "s2", "mean_val_f1"
    )  # fmt: skip
    assert (tags["search.fixed_overrides"], tags["search.best_trial"]) == ("experiment=x", "1")
    assert run.data.metrics == {
        "n_trials": 5.0, "n_complete": 4.0, "best_value": 0.8, "best_trial": 1.0
    }  # fmt: skip
    best = study.best_trial.params
    assert run.data.params == {k: search.as_override(v) for k, v in best.items()}
    listed = {a.path for a in MlflowClient(mlflow_uri).list_artifacts(run_id)}
    assert listed == {"trials.csv", "optimization_history.png", "param_importances.png"}
    # The history's legend (objective value, best value) is drawn inside its axes, not cut off.
    history = figures["optimization_history.png"].axes[0]
    history.figure.canvas.draw()
    inside = history.get_window_extent()
    legend = history.get_legend().get_window_extent()
    assert inside.x0 <= legend.x0 and legend.x1 <= inside.x1 and legend.y1 <= inside.y1
    # Importances from the fewest trials and values that have them: two, one parameter.
    few = search.open_study(
        "s5", storage, direction="maximize", sampler=optuna.samplers.RandomSampler(seed=1)
    )
    search.check_same_search(few, ["experiment=x"], "mean_val_auc")
    for score in (0.6, 0.8):
        few.tell(few.ask({"schedule.lr": space["schedule.lr"]}), score)
    figures.clear()
    search.log_summary(few, tracker)
    assert set(figures) == {"optimization_history.png", "param_importances.png"}
    # A plot Optuna cannot draw is left out with one line saying which and why.
    from optuna.visualization import matplotlib as plots

    def refused(_study):
        raise RuntimeError("no importances here")

    monkeypatch.setattr(plots, "plot_param_importances", refused)
    figures.clear()
    caplog.clear()  # Optuna's own records of the studies above, when its logger propagates
    with caplog.at_level("WARNING", logger="tactile_exp.search"):
        search.log_summary(few, tracker)
    assert set(figures) == {"optimization_history.png"}
    said = [r.getMessage() for r in caplog.records if r.name == "tactile_exp.search"]
    assert said == ["study s5: no param_importances.png (no importances here)"]
    empty = search.open_study(
        "s3", storage, direction="minimize", sampler=optuna.samplers.RandomSampler(seed=1)
    )
    search.check_same_search(empty, ["experiment=x"], "mean_val_auc")
    run = MlflowClient(mlflow_uri).get_run(search.log_summary(empty, tracker))
    assert run.data.metrics == {"n_trials": 0.0, "n_complete": 0.0} and not run.data.params
    with pytest.raises(ConfigError, match=r"^hydra\.sweeper\.direction: study 's3' in .* was made"):
        search.open_study(
            "s3", storage, direction="maximize", sampler=optuna.samplers.RandomSampler()
        )
    with pytest.raises(ConfigError, match=r"was made to minimize, got maximize$"):
        search.open_study("s3", storage, direction="maximize", sampler=None)
    with pytest.raises(ConfigError, match=r"^hydra\.sweeper\.direction: "):
        search.open_study("s7", storage, direction="sideways", sampler=None)
    with pytest.raises(ConfigError, match=r"^study 's3': no finished trial yet"):
        search.best_report(empty)
    with pytest.raises(ConfigError, match=r"^study 'nope': not in .*; studies there: s2, twin, "):
        search.load_study("nope", storage)


def test_a_jobs_return_value_becomes_a_finite_objective_or_nan():
    assert search.objective_or_nan(0.75) == 0.75 and search.objective_or_nan("0.5") == 0.5
    for bad in (None, "x", float("inf"), float("nan"), [1]):
        assert math.isnan(search.objective_or_nan(bad))
    assert search.as_override([[3, 3], 5]) == "[[3,3],5]" and search.as_override(0.1) == "0.1"
