"""One job end to end on tiny generated data into a temporary MLflow store."""

from __future__ import annotations

import contextlib
import csv
import io
import logging
import re
import subprocess
import sys
import weakref

import numpy as np
import pytest
from conftest import TINY_DATA
from mlflow.tracking import MlflowClient
from sklearn.metrics import roc_auc_score

from tactile_exp.config import settings_from_config
from tactile_exp.errors import ConfigError
from tactile_exp.experiment import load, run
from tactile_exp.models import MODELS
from tactile_exp.train import device_name


def _runs(uri: str, config_hash: str | None = None):
    client = MlflowClient(uri)
    exp = client.get_experiment_by_name("tactile_exp")
    if exp is None:  # this test's own store, before the job has created the experiment
        return client, []
    query = f"tags.config_hash = '{config_hash}'" if config_hash else ""
    return client, client.search_runs([exp.experiment_id], filter_string=query, max_results=1000)


def test_job_logs_parent_and_one_child_per_adjective(tiny_config, mlflow_uri, caplog):
    settings = settings_from_config(tiny_config(["seed=11"]))
    with caplog.at_level(logging.INFO, logger="tactile_exp.experiment"):
        result = run(settings)
    # one line says what each phase took: the data, the preprocessing, the adjectives
    (phases,) = [r.getMessage() for r in caplog.records if r.getMessage().startswith("phases:")]
    assert re.fullmatch(
        r"phases: data \(generated on first use\) [\d.]+ s, preprocessing [\d.]+ s, "
        r"3 adjectives [\d.]+ s",
        phases,
    )
    client, runs = _runs(mlflow_uri, settings.config_hash)
    parents = [r for r in runs if r.data.tags["run_level"] == "parent"]
    children = [r for r in runs if r.data.tags["run_level"] == "child"]
    assert len(parents) == 1 and len(children) == 3
    parent = parents[0]
    assert parent.info.status == "FINISHED" and parent.info.run_name == "haptic_cnn-concat-c1-s11"
    assert parent.data.params["model.schedule.epochs"] == "2"
    assert parent.data.params["choice.model"] == "haptic_cnn"
    assert parent.data.tags["device"] == device_name("auto")  # "cpu" here, the GPU on one
    assert {c.data.tags["mlflow.parentRunId"] for c in children} == {parent.info.run_id}
    assert {c.info.run_name for c in children} == {"adj=hard", "adj=soft", "adj=smooth"}
    for child in children:
        assert child.info.status == "FINISHED"
        rows = list(csv.DictReader(io.StringIO(_artifact(client, child, "scores.csv"))))
        y = [int(r["label"]) for r in rows]
        s = [float(r["score"]) for r in rows]
        assert child.data.metrics["auc"] == pytest.approx(roc_auc_score(y, s), abs=1e-12)
        assert child.data.metrics["n_test_units"] == len(rows)
        assert len(client.get_metric_history(child.info.run_id, "train_loss")) == 2
    aucs = [c.data.metrics["auc"] for c in children]
    assert parent.data.metrics["mean_auc"] == pytest.approx(np.mean(aucs))
    assert result.means["mean_auc"] == pytest.approx(np.mean(aucs))
    listed = {a.path for a in client.list_artifacts(parent.info.run_id)}
    assert {"config.yaml", "auc_per_adjective.csv", "roc.png"} <= listed


def test_a_job_compiles_its_kernels_ahead_before_it_opens_its_data(tiny_config, monkeypatch):
    """The job hands its models' kernels to ``compile_ahead`` before it opens (or generates) its
    data and preprocesses them (the modality's check), all of which the compile overlaps; a job
    without compiled kernels starts nothing."""
    from tactile_exp import core
    from tactile_exp.modalities.haptic import Haptic
    from tactile_exp.models import numba_setup

    calls = []
    monkeypatch.setattr(numba_setup, "compile_ahead", lambda modules: calls.append(modules))
    check, build = Haptic.check, core.DATA_SOURCES.build
    monkeypatch.setattr(
        Haptic, "check", lambda self, data: calls.append("check") or check(self, data)
    )
    monkeypatch.setattr(
        core.DATA_SOURCES, "build", lambda *a, **k: calls.append("data") or build(*a, **k)
    )
    run(settings_from_config(tiny_config(["seed=12"], adjectives="[hard]")))
    names = [m.rsplit(".", 1)[-1] for m in calls[0]]
    assert sorted(names) == ["convnet_tiles", "grouped_conv_numba", "linear_sgd"]
    assert calls[1:] == ["data", "check"]
    calls.clear()
    run(settings_from_config(tiny_config(["model=random", "seed=12"], adjectives="[hard]")))
    assert calls == ["data", "check"]


def test_an_adjectives_pipeline_is_freed_before_the_next_adjective_fits(tiny_config, monkeypatch):
    """A job keeps each adjective's result without its pipeline (the model and its training
    units): the last one's is gone before the next adjective is fitted."""
    from tactile_exp import core

    fit, pipelines, alive = core.fit_adjective, [], []

    def tracked(*args, **kwargs):
        alive.append([p() is not None for p in pipelines])
        result = fit(*args, **kwargs)
        pipelines.append(weakref.ref(result.pipeline))
        return result

    monkeypatch.setattr(core, "fit_adjective", tracked)
    run(settings_from_config(tiny_config(["seed=13"], adjectives="[hard,squishy,soft]")))
    assert alive == [[], [False], [False, False]]


def test_schedule_overrides_the_job_does_not_train_by_are_warned_and_tagged(
    tiny_config, mlflow_uri, caplog
):
    """model=linear under concat trains only its head: a job given schedule.epochs says so in
    one warning line before training, naming the head's schedule, and tags its run."""
    overrides = ("model=linear", "schedule.epochs=50", "schedule.head.lr=0.01")
    settings = settings_from_config(tiny_config(list(overrides), "[hard]"), overrides=overrides)
    with caplog.at_level("WARNING", logger="tactile_exp.experiment"):
        result = run(settings)
    lines = [r.getMessage() for r in caplog.records if r.name == "tactile_exp.experiment"]
    assert lines == [
        "schedule.epochs: set, but read by nothing this job trains: model=linear learns no "
        "representation, so under combine_instances=concat only its T4 head is trained, by "
        "schedule.head.<key> (epochs=2 finetune_epochs=1 batch_size=256 lr=0.01 momentum=0.9)"
    ]
    _, runs = _runs(mlflow_uri, settings.config_hash)
    parent = next(r for r in runs if r.info.run_id == result.run_id)
    assert parent.data.tags["schedule.ignored"] == "schedule.epochs"


def _artifact(client: MlflowClient, run, path: str) -> str:
    local = client.download_artifacts(run.info.run_id, path)
    with open(local) as f:
        return f.read()


def test_finished_job_is_skipped_on_rerun(tiny_config, mlflow_uri):
    cfg = tiny_config(["model=random", "combine_instances=separate", "seed=3"])
    first = run(settings_from_config(cfg))
    again = run(settings_from_config(cfg))
    assert again.skipped and again.run_id == first.run_id
    _, runs = _runs(mlflow_uri, settings_from_config(cfg).config_hash)
    assert sum(r.data.tags["run_level"] == "parent" for r in runs) == 1


def test_same_seed_same_aucs(tiny_config):
    cfg = tiny_config(["seed=5", "tracking.skip_finished=false"], adjectives="[hard,squishy]")
    a, b = run(settings_from_config(cfg)), run(settings_from_config(cfg))
    for adj in ("hard", "squishy"):
        np.testing.assert_array_equal(a.results[adj].test.scores, b.results[adj].test.scores)
        assert a.results[adj].metrics["auc"] == b.results[adj].metrics["auc"]


@pytest.fixture
def replace_model():
    """``replace_model(random=Cls)``: registered models replaced until the test ends."""
    with contextlib.ExitStack() as stack:
        yield lambda **models: stack.enter_context(MODELS.temporary(**models))


def test_a_failing_job_is_marked_failed_and_nothing_stays_running(
    tiny_config, mlflow_uri, replace_model
):
    calls = {"n": 0}
    original = MODELS["random"]

    class Exploding(original):  # type: ignore[misc, valid-type]
        def fit(self, train, on_epoch=None):
            calls["n"] += 1
            if calls["n"] == 2:
                raise RuntimeError("boom in the second adjective")
            return super().fit(train, on_epoch)

    replace_model(random=Exploding)
    settings = settings_from_config(
        tiny_config(["model=random", "combine_instances=separate", "seed=99"])
    )
    with pytest.raises(RuntimeError, match="boom"):
        run(settings)
    _, runs = _runs(mlflow_uri, settings.config_hash)
    status = {r.info.run_name: r.info.status for r in runs}
    assert status == {
        "random-separate-c1-s99": "FAILED",
        "adj=hard": "FINISHED",
        "adj=soft": "FAILED",
    }
    parent = next(r for r in runs if r.data.tags["run_level"] == "parent")
    assert "boom in the second adjective" in parent.data.tags["error"]
    _, everything = _runs(mlflow_uri)
    assert not [r for r in everything if r.info.status == "RUNNING"]


def test_bad_data_fails_before_a_run_is_created(tiny_config, mlflow_uri, tmp_path):
    broken = tmp_path / "broken.h5"
    broken.write_bytes(b"not an hdf5 file at all")
    settings = settings_from_config(
        tiny_config(["data=phac2", f"data.path={broken}", "model=random", "seed=7"])
    )
    with pytest.raises(ValueError, match="broken.h5"):
        run(settings)
    _, runs = _runs(mlflow_uri, settings.config_hash)
    assert runs == []


def test_combine_more_trials_than_objects_have_is_rejected(tiny_config, mlflow_uri):
    settings = settings_from_config(tiny_config(["combine=3", "model=random"]))
    with pytest.raises(ConfigError, match="^combine: 3 trials per unit.*allowed 1..2"):
        run(settings)
    assert _runs(mlflow_uri)[1] == []  # refused before any run is created


def test_ten_trial_units_are_objects(tiny_config):
    settings = settings_from_config(
        tiny_config(["experiment=table1_j_haptic_cnn_10trials", "combine=2"], adjectives="[hard]")
    )
    result = run(settings).results["hard"]
    assert len(result.test.units) == len(set(result.test.objects)) == result.sizes["n_test_objects"]


def test_parallel_sweep_runs_every_job(tiny_config, cache_dir, mlflow_uri, tmp_path):
    args = [
        *TINY_DATA,
        f"cache_dir={cache_dir}",
        f"tracking.uri={mlflow_uri}",
        "adjectives=[hard]",
        "model=random",
        "combine_instances=separate",
        "seed=21,22",
        "hydra/launcher=joblib",  # two jobs at once on one sqlite store
        "hydra.launcher.n_jobs=2",
        f"hydra.sweep.dir={tmp_path}/multirun",
    ]
    subprocess.run([sys.executable, "-m", "tactile_exp", "-m", *args], check=True, timeout=300)
    client, runs = _runs(mlflow_uri)
    parents = [r for r in runs if r.data.tags["run_level"] == "parent"]
    assert len(parents) == 2 and all(r.info.status == "FINISHED" for r in parents)
    tiny = "trials=2-duration_scale=0.1-views=1-image_width=96-image_height=64"  # TINY_DATA
    assert sorted(r.info.run_name for r in parents) == [
        f"random-separate-c1-{tiny}-hard-s{seed}" for seed in (21, 22)
    ]
    # one sweep id, the sweep's folder (not its last part: multirun/<date>/<time> repeats times)
    assert {r.data.tags["sweep_id"] for r in parents} == {f"{tmp_path}/multirun"}
    assert (tmp_path / "multirun" / "0" / ".hydra" / "config.yaml").exists()
    listed = {a.path for a in client.list_artifacts(parents[0].info.run_id, ".hydra")}
    assert ".hydra/overrides.yaml" in listed


@pytest.mark.parametrize(
    "row,extra",
    [
        ("table1_a_haptic_static_1trial", []),
        ("table1_b_haptic_static_10trials", ["combine=2"]),  # tiny data: 2 trials per object
        ("table1_c_haptic_dynamic_1trial", []),
        ("table1_f_haptic_static_1trial_dynamic_10trials", []),
    ],
)
def test_baseline_rows_run_from_their_experiment_configs(tiny_config, row, extra):
    overrides = [f"experiment={row}", *extra]
    settings = settings_from_config(tiny_config(overrides, adjectives="[hard,soft]"))
    result = run(settings)
    assert set(result.results) == {"hard", "soft"}
    for r in result.results.values():
        assert np.all(np.isfinite(r.test.scores)) and len(r.test.scores) == len(r.test.y) == len(
            r.test.units
        )
        assert r.metrics["auc"] == pytest.approx(roc_auc_score(r.test.y, r.test.scores), abs=1e-12)
        assert set(r.test.objects) and r.sizes["n_test_objects"] == len(set(r.test.objects))
    pooled = settings.combine > 1
    assert all(
        (len(set(r.test.objects)) == len(r.test.units)) == pooled for r in result.results.values()
    )


def test_sigterm_marks_the_runs_failed(cache_dir, mlflow_uri):
    """SLURM and `kill` send SIGTERM: the job must not leave its runs RUNNING."""
    import signal
    import time

    args = [
        *TINY_DATA,
        f"cache_dir={cache_dir}",
        f"tracking.uri={mlflow_uri}",
        "adjectives=[hard]",
        "schedule.epochs=100000",
        "seed=31",
        f"hydra.run.dir={cache_dir / 'sigterm_run'}",
    ]
    job = subprocess.Popen([sys.executable, "-m", "tactile_exp", *args])
    client = MlflowClient(mlflow_uri)
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:  # wait until the child run is training
            _, runs = _runs(mlflow_uri)
            if any(r.info.run_name == "adj=hard" and r.info.status == "RUNNING" for r in runs):
                break
            time.sleep(0.5)
        else:
            pytest.fail("the job never started its child run")
        job.send_signal(signal.SIGTERM)
        assert job.wait(timeout=60) != 0
    finally:
        job.kill()
    _, runs = _runs(mlflow_uri)
    parent = next(r for r in runs if r.data.tags["run_level"] == "parent")
    child = next(r for r in runs if r.data.tags.get("mlflow.parentRunId") == parent.info.run_id)
    assert (parent.info.status, child.info.status) == ("FAILED", "FAILED")
    assert "signal 15" in parent.data.tags["error"]
    assert client.get_run(child.info.run_id).info.end_time is not None


def test_children_log_train_and_validation_auc_without_test_objects(tiny_config, mlflow_uri):
    """Every child logs train_auc and, when its held-out training objects hold both
    classes, val_auc; those objects are left out of training and are never test objects."""
    overrides = ["seed=5", "validation.fraction=0.15"]
    settings = settings_from_config(tiny_config(overrides, adjectives="[hard,smooth]"))
    assert settings.validation_fraction == 0.15
    result = run(settings)
    splits = load(settings)[2]
    client, runs = _runs(mlflow_uri, settings.config_hash)
    children = {r.data.tags["adjective"]: r for r in runs if r.data.tags["run_level"] == "child"}
    for adjective, child in children.items():
        metrics = child.data.metrics
        assert np.isfinite([metrics["train_auc"], metrics["val_auc"]]).all()  # both logged
        assert metrics["n_val_objects"] >= 2 and metrics["n_val_positive_objects"] >= 1
        res = result.results[adjective]
        validation = ("auc", "average_precision", "f1")  # each listed metric
        assert res.sides["train"].metrics["auc"] == metrics["train_auc"]
        assert res.sides["val"].metrics == {k: metrics[f"val_{k}"] for k in validation}
        split = splits[adjective]
        assert set(res.test.objects) <= split.objects("test")  # test AUC: test objects only
        n_train = metrics["n_train_objects"] + metrics["n_val_objects"]
        assert n_train == len(split.objects("train"))  # held out of the final training
    parent = next(r for r in runs if r.data.tags["run_level"] == "parent")
    assert parent.data.metrics["mean_val_auc"] == pytest.approx(
        np.mean([c.data.metrics["val_auc"] for c in children.values()])
    )


FAST = ["model=random", "combine_instances=separate"]  # a job with no training to speak of
# 5 objects x 3 trials: absorbent 2 positive objects, squishy 3, cool none.
FIVE_OBJECTS = (101, 116, 214, 316, 501)


@pytest.mark.job
@pytest.mark.parametrize("fit_on", ["train", "all"])
def test_job_fits_the_preprocessing_on_what_fit_on_says(tiny_config, monkeypatch, fit_on):
    """A job's normaliser and PCA see the adjective's training trials only, unless fit_on=all."""
    from tactile_exp.data.sources import DATA_SOURCES
    from tactile_exp.data.splits import make_split
    from tactile_exp.preprocess.haptic import HapticPreprocessor

    seen: list[list[str]] = []
    original = HapticPreprocessor.fit

    def spy(self, trials):
        seen.append([str(getattr(t, "name", t)) for t in trials])
        return original(self, trials)

    monkeypatch.setattr(HapticPreprocessor, "fit", spy)
    settings = settings_from_config(
        tiny_config([*FAST, f"modality.fit_on={fit_on}", "seed=41"], adjectives="[hard,soft]")
    )
    run(settings)
    dataset = DATA_SOURCES.build(settings.data.name, **settings.data.params)
    assert len(seen) == 2
    for adjective, fitted in zip(["hard", "soft"], seen, strict=True):
        split = make_split(dataset, adjective, settings.split, settings.seed)
        expected = split.train if fit_on == "train" else [t.name for t in dataset.trials]
        assert sorted(fitted) == sorted(expected)
        if fit_on == "train":
            assert not set(fitted) & set(split.test)


@pytest.mark.job
def test_a_crashed_job_runs_again_and_then_is_skipped(tiny_config, mlflow_uri, replace_model):
    """FAILED (here after one adjective's child FINISHED) is rerun; FINISHED is then skipped."""
    original = MODELS["random"]

    class Exploding(original):  # type: ignore[misc, valid-type]
        def fit(self, train, on_epoch=None):
            fits.append(len(train))
            if crash and len(fits) == 2:
                raise RuntimeError("crash in soft")
            return super().fit(train, on_epoch)

    fits: list[int] = []
    crash = {"soft"}
    replace_model(random=Exploding)
    cfg = tiny_config([*FAST, "seed=43"], adjectives="[hard,soft]")
    with pytest.raises(RuntimeError, match="crash in soft"):
        run(settings_from_config(cfg))
    crash.clear()
    again = run(settings_from_config(cfg))
    assert not again.skipped and set(again.results) == {"hard", "soft"}
    assert run(settings_from_config(cfg)).skipped
    parents = [r for r in _runs(mlflow_uri)[1] if r.data.tags.get("run_level") == "parent"]
    assert sorted(r.info.status for r in parents) == ["FAILED", "FINISHED"]


@pytest.mark.job
def test_a_job_left_running_by_a_killed_process_runs_again(tiny_config, mlflow_uri):
    """A parent run still RUNNING (its process was killed -9) is not a finished job."""
    from tactile_exp.tracking import Tracker

    settings = settings_from_config(tiny_config([*FAST, "seed=44"], adjectives="[hard]"))
    tracker = Tracker(mlflow_uri, settings.tracking.experiment)
    tags = {"config_hash": settings.config_hash, "run_level": "parent"}
    stale = tracker.client.create_run(tracker.experiment_id, run_name="killed", tags=tags)
    result = run(settings)
    assert not result.skipped and result.run_id != stale.info.run_id
    assert MlflowClient(mlflow_uri).get_run(result.run_id).info.status == "FINISHED"


@pytest.mark.job
def test_a_finished_run_of_another_config_does_not_skip(tiny_config):
    first = run(settings_from_config(tiny_config([*FAST, "seed=45"], adjectives="[hard]")))
    other = run(settings_from_config(tiny_config([*FAST, "seed=46"], adjectives="[hard]")))
    assert not other.skipped and other.run_id != first.run_id


@pytest.fixture(scope="module")
def five_objects(tmp_path_factory: pytest.TempPathFactory):
    from tactile_exp.data.synthetic import SyntheticSpec, generate

    spec = SyntheticSpec(
        object_ids=FIVE_OBJECTS,
        trials=3,
        duration_scale=0.1,
        views=1,
        image_width=96,
        image_height=64,
    )
    return generate(tmp_path_factory.mktemp("five") / "five.h5", spec)


@pytest.mark.job
@pytest.mark.parametrize(
    "row,adjectives",
    [
        ("table1_a_haptic_static_1trial", "[absorbent,squishy]"),
        ("table1_i_haptic_cnn_1trial", "[absorbent,squishy]"),
    ],
)
def test_rows_a_and_i_run_on_five_objects(tiny_config, five_objects, row, adjectives):
    import warnings

    settings = settings_from_config(
        tiny_config(
            [f"experiment={row}", "data=phac2", f"data.path={five_objects}"],
            adjectives=adjectives,
        )
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = run(settings)
    assert set(result.results) == {"absorbent", "squishy"}
    for r in result.results.values():  # a test side of both classes, and the AUC of its scores
        assert set(r.test.y) == {0, 1} and set(r.test.objects) <= set(FIVE_OBJECTS)
        assert r.metrics["auc"] == pytest.approx(roc_auc_score(r.test.y, r.test.scores), abs=1e-12)
    messages = " ".join(str(w.message) for w in caught)
    assert "falling back to the random split" in messages  # published test objects are absent


def test_adjective_without_positive_objects_is_refused_before_a_run(
    tiny_config, five_objects, mlflow_uri
):
    from tactile_exp.data.layout import DataError

    settings = settings_from_config(
        tiny_config(
            ["experiment=table1_a_haptic_static_1trial", "data=phac2", f"data.path={five_objects}"],
            adjectives="[absorbent,cool]",
        )
    )
    with pytest.raises(DataError, match=r"cannot be evaluated .*: cool \(\+0/-5 objects\)"):
        run(settings)
    assert _runs(mlflow_uri)[1] == []
