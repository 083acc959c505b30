"""Trained models kept as artifacts, found again by training key, and composed (rows M, N)."""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import TINY_DATA
from mlflow.tracking import MlflowClient

from tactile_exp import artifacts, keys, store
from tactile_exp.config import settings_from_config
from tactile_exp.data.layout import Instances
from tactile_exp.experiment import run
from tactile_exp.models import MODELS
from tactile_exp.models.haptic_cnn import HapticCNN
from tactile_exp.models.schedule import Schedule
from tactile_exp.registry import Component
from tactile_exp.runtime.processes import process_tags
from tactile_exp.tracking import Tracker

ONE = "[hard]"
REPEAT = ["tracking.skip_finished=false"]  # run a config again (the engine would skip it)


def _instances(n: int = 40, shape: tuple[int, ...] = (64, 20), seed: int = 0) -> Instances:
    rng = np.random.default_rng(seed)
    y = np.arange(n) % 2
    X = rng.normal(size=(n, *shape)).astype(np.float32) + y[:, None, None].astype(np.float32)
    return Instances(X, y, np.array([f"t{i}" for i in range(n)], dtype=object), np.arange(n))


@pytest.mark.parametrize(
    ("name", "shape", "params"),
    [
        ("haptic_cnn", (64, 20), {"widths": (2, 2, 2), "impl": "torch"}),
        ("linear", (7,), {}),
    ],
)
def test_saved_model_loads_with_identical_scores(tmp_path, name, shape, params):
    schedule = Schedule(epochs=2, finetune_epochs=2, batch_size=16, head=Schedule(lr=0.5))
    model = MODELS.build(name, schedule=schedule, **params)
    data = _instances(shape=shape)
    model.fit(data)
    artifacts.write_model(tmp_path, name, model)
    stored = json.loads((tmp_path / "settings.json").read_text())["params"]
    assert stored["schedule"]["head"]["lr"] == 0.5  # the Schedule value kept as its JSON node
    loaded = artifacts.read_model(tmp_path, "here")
    assert type(loaded) is type(model)
    assert loaded.schedule == model.schedule
    as_json = [json.dumps(m.get_params(), default=artifacts.jsonable) for m in (loaded, model)]
    assert as_json[0] == as_json[1]  # every setting back (tuples as the JSON lists they were)
    np.testing.assert_array_equal(loaded.decision_function(data.X), model.decision_function(data.X))
    np.testing.assert_array_equal(loaded.transform(data.X), model.transform(data.X))


def test_corrupt_or_missing_model_files_name_the_file(tmp_path):
    model = HapticCNN(
        widths=(2, 2, 2), schedule=Schedule(epochs=1, finetune_epochs=0), impl="torch"
    )
    model.fit(_instances())
    artifacts.write_model(tmp_path, "haptic_cnn", model)
    (tmp_path / "weights.pt").write_bytes(b"not a state dict")
    with pytest.raises(artifacts.ArtifactError, match=r"run X: artifact model/weights.pt"):
        artifacts.read_model(tmp_path, "run X: artifact model")
    torch.save({"body.weights.0": torch.zeros(3)}, tmp_path / "weights.pt")
    with pytest.raises(artifacts.ArtifactError, match="does not load"):
        artifacts.read_model(tmp_path, "run X: artifact model")
    (tmp_path / "settings.json").write_text("{")
    with pytest.raises(artifacts.ArtifactError, match="settings.json is not readable JSON"):
        artifacts.read_model(tmp_path, "run X: artifact model")


def _children(uri: str, parent_id: str, level: str = "child") -> dict[str, object]:
    client = MlflowClient(uri)
    exp = client.get_experiment_by_name("tactile_exp")
    runs = client.search_runs(
        [exp.experiment_id],
        f"tags.mlflow.parentRunId = '{parent_id}' and tags.run_level = '{level}'",
    )
    return {r.data.tags["adjective"]: r for r in runs}


def _scores(uri: str, child) -> list[float]:
    local = MlflowClient(uri).download_artifacts(child.info.run_id, "scores.csv")
    with open(local) as f:
        return [float(r["score"]) for r in csv.DictReader(io.StringIO(f.read()))]


@pytest.mark.job
@pytest.mark.slow  # ten tiny jobs
def test_training_settings_retrain_while_head_settings_reuse(tiny_config, mlflow_uri):
    first = run(settings_from_config(tiny_config(REPEAT, ONE)))
    trained = _children(mlflow_uri, first.run_id)["hard"]
    assert "reused_from" not in trained.data.tags
    key = trained.data.tags["training_key"]

    again = _children(mlflow_uri, run(settings_from_config(tiny_config(REPEAT, ONE))).run_id)
    assert again["hard"].data.tags["reused_from"] == trained.info.run_id
    assert _scores(mlflow_uri, again["hard"]) == _scores(mlflow_uri, trained)

    for head_only in (["combine=2"], ["combine_instances=mean"], ["schedule.head.lr=0.5"]):
        job = run(settings_from_config(tiny_config(REPEAT + head_only, ONE)))
        child = _children(mlflow_uri, job.run_id)["hard"]
        assert child.data.tags["training_key"] == key, head_only
        assert child.data.tags["reused_from"] == trained.info.run_id, head_only

    for training in (["schedule.lr=0.02"], ["schedule.epochs=1"], ["seed=3"], ["split=random"]):
        job = run(settings_from_config(tiny_config(REPEAT + training, ONE)))
        child = _children(mlflow_uri, job.run_id)["hard"]
        assert child.data.tags["training_key"] != key, training
        assert "reused_from" not in child.data.tags, training

    off = run(settings_from_config(tiny_config([*REPEAT, "tracking.reuse=false"], ONE)))
    child = _children(mlflow_uri, off.run_id)["hard"]
    assert "reused_from" not in child.data.tags
    assert _scores(mlflow_uri, child) == _scores(mlflow_uri, trained)  # retrained: same seed


@pytest.mark.job
def test_missing_artifact_of_a_found_run_is_a_clear_error(tiny_config, mlflow_uri):
    first = run(settings_from_config(tiny_config(REPEAT, ONE)))
    trained = _children(mlflow_uri, first.run_id)["hard"]
    tracker = Tracker(mlflow_uri, "tactile_exp")
    assert isinstance(store.load_model(tracker, trained.info.run_id, "model"), HapticCNN)
    # the local artifact store is a folder: remove the stored weights behind MLflow's back
    Path(trained.info.artifact_uri.removeprefix("file://"), "model", "weights.pt").unlink()
    with pytest.raises(artifacts.ArtifactError, match=rf"run {trained.info.run_id}.*weights.pt"):
        run(settings_from_config(tiny_config(REPEAT, ONE)))


@pytest.mark.job
def test_killed_job_reuses_its_finished_adjectives(tiny_config, mlflow_uri, monkeypatch):
    calls = []
    fit = HapticCNN.fit

    def dies_on_second(self, train, on_epoch=None):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt("killed")
        return fit(self, train, on_epoch)

    monkeypatch.setattr(HapticCNN, "fit", dies_on_second)
    with pytest.raises(KeyboardInterrupt):
        run(settings_from_config(tiny_config(REPEAT, "[hard,soft]")))
    monkeypatch.setattr(HapticCNN, "fit", fit)
    client = MlflowClient(mlflow_uri)
    exp = client.get_experiment_by_name("tactile_exp")
    done = client.search_runs(
        [exp.experiment_id], "tags.adjective = 'hard' and attributes.status = 'FINISHED'"
    )
    assert len(done) == 1
    rerun = _children(
        mlflow_uri, run(settings_from_config(tiny_config(REPEAT, "[hard,soft]"))).run_id
    )
    assert rerun["hard"].data.tags["reused_from"] == done[0].info.run_id
    assert "reused_from" not in rerun["soft"].data.tags


@pytest.mark.job
@pytest.mark.slow  # three tiny jobs, one of them preparing photographs
def test_multimodal_rows_train_only_the_classification_layer(tiny_config, mlflow_uri):
    small = ["modality.visual.size=32", "modality.visual.batch_size=128"]  # 5a at 1x1: fast
    row_m = run(
        settings_from_config(tiny_config(["experiment=table1_m_multimodal_i_l", *small], ONE))
    )
    part = _children(mlflow_uri, row_m.run_id, "part")["hard"]  # no ConvNet yet: trained here
    child = _children(mlflow_uri, row_m.run_id)["hard"]
    assert child.info.status == part.info.status == "FINISHED"
    assert child.data.tags["part.haptic"] == part.info.run_id
    assert child.data.metrics["n_objects_without_photographs"] == 0
    tracker = Tracker(mlflow_uri, "tactile_exp")
    trained, _ = store.load_model(tracker, part.info.run_id, "model").state()
    used, _ = store.load_model(tracker, child.info.run_id, "parts/haptic").state()
    assert trained.keys() == used.keys()
    for name, tensor in trained.items():
        torch.testing.assert_close(used[name], tensor, rtol=0, atol=0)
    layer = store.load_model(tracker, child.info.run_id, "model")
    # one trial's 10 conv3 maps (128 x 19 each) beside 8 views of 832 inception (5a) features
    assert layer.input_shape_ == (10 * 128 * 19 + 8 * 832,)
    assert (layer.loss, layer.pretrain_loss) == ("hinge", None)
    assert "finetune_loss" not in child.data.metrics

    row_i = run(settings_from_config(tiny_config([], ONE)))
    assert _children(mlflow_uri, row_i.run_id)["hard"].data.tags["reused_from"] == part.info.run_id
    overrides = ["experiment=table1_n_multimodal_j_l", "modality.trials=2", *small]
    row_n = run(settings_from_config(tiny_config(overrides, ONE)))
    child_n = _children(mlflow_uri, row_n.run_id)["hard"]
    assert child_n.data.tags["reused_from.haptic"] == part.info.run_id
    assert not _children(mlflow_uri, row_n.run_id, "part")
    layer_n = store.load_model(tracker, child_n.info.run_id, "model")
    assert layer_n.input_shape_ == (2 * 10 * 128 * 19 + 8 * 832,)


KNOWN_KEY = "24dfe35e9f0f5088575a"  # training_key of `_key()`'s settings at FORMAT 1


def _key(**change) -> str:
    from tactile_exp.registry import Component

    base = {
        "dataset": "phac2-abc",
        "modality": Component("haptic", {"steps": 150, "device": "cpu", "batch_size": 8}),
        "model": Component("haptic_cnn", {"lr": 0.01, "impl": "torch", "device": "cpu"}),
        "split": "published",
        "validation": 0.0,
        "seed": 0,
        "adjective": "hard",
    }
    return keys.training_key(**(base | change))


def test_training_key_changes_with_what_trains_the_model_and_nothing_else():
    """Reuse is by equal key: every trained-on setting must change it, machine settings not."""
    from tactile_exp.registry import Component

    key = _key()
    # Pinned: a key that changes for the same settings orphans every stored model (bump FORMAT).
    assert key == KNOWN_KEY
    differ = [
        _key(dataset="phac2-abd"),
        _key(modality=Component("haptic_features", {"steps": 150})),
        _key(modality=Component("haptic", {"steps": 100, "device": "cpu", "batch_size": 8})),
        _key(model=Component("linear", {"lr": 0.01, "impl": "torch", "device": "cpu"})),
        _key(model=Component("haptic_cnn", {"lr": 0.02, "impl": "torch", "device": "cpu"})),
        _key(split="random"),
        _key(validation=0.15),
        _key(seed=1),
        _key(adjective="soft"),
    ]
    assert key not in differ and len(set(differ)) == len(differ)
    same = [
        _key(modality=Component("haptic", {"steps": 150, "device": "cuda", "batch_size": 64})),
        _key(model=Component("haptic_cnn", {"lr": 0.01, "impl": "numba", "device": "cuda"})),
    ]
    assert same == [key] * 2
    # The head's schedule inside the model's schedule is not keyed; the model's own steps are.
    schedule = {"epochs": 2, "lr": 0.01}
    scheduled = _key(model=Component("haptic_cnn", {"schedule": schedule}))
    head = {"schedule": {**schedule, "head": {"epochs": 3, "lr": 0.5}}}
    assert _key(model=Component("haptic_cnn", head)) == scheduled
    assert _key(model=Component("haptic_cnn", {"schedule": {**schedule, "lr": 0.02}})) != scheduled
    odd = Component("haptic_cnn", {"weights": Path("w.pt")})  # not JSON: hashed as its text
    assert _key(model=odd) == _key(model=Component("haptic_cnn", {"weights": "w.pt"}))


@pytest.mark.job
def test_resume_skips_a_finished_job_only_on_the_same_data_file(tiny_config, mlflow_uri, tmp_path):
    """skip-if-finished keys on the data file's identity too: the same config on a changed file
    (another generator version, a replaced or real file) runs again."""
    from tactile_exp.data.sources import DATA_SOURCES

    generated = settings_from_config(tiny_config([], ONE)).data
    source = DATA_SOURCES.build(generated.name, **generated.params).path
    copy = tmp_path / "phac2.h5"
    shutil.copy(source, copy)
    overrides = ["data=phac2", f"data.path={copy}", "model=random", "combine_instances=separate"]
    first = run(settings_from_config(tiny_config(overrides, ONE)))
    assert not first.skipped
    assert run(settings_from_config(tiny_config(overrides, ONE))).skipped  # same file: resume
    os.utime(copy, ns=(time.time_ns(), time.time_ns() + 10**9))  # another file at that path
    again = run(settings_from_config(tiny_config(overrides, ONE)))
    assert not again.skipped and again.run_id != first.run_id
    client = MlflowClient(mlflow_uri)
    identity = [client.get_run(r.run_id).data.tags["data.identity"] for r in (first, again)]
    assert identity[0] != identity[1]
    assert run(settings_from_config(tiny_config(overrides, ONE))).skipped


def test_visual_units_are_row_l_units_never_padded_beyond_an_object_with_fewer_views():
    from tactile_exp.modalities.multimodal import visual_units

    features = np.arange(13, dtype=np.float32)[:, None] * np.ones((1, 2), np.float32)
    object_id = np.array([5] * 10 + [7] * 3)
    units = visual_units(features, object_id, 8)
    assert sorted(units) == [5, 7]
    np.testing.assert_array_equal(units[5], features[:8].reshape(-1))  # views 0-7, no 2nd unit
    np.testing.assert_array_equal(units[7], features[[10, 11, 12, 10, 11, 12, 10, 11]].reshape(-1))


# ---------------------------------------------------------------- store functions, direct
def _linear():
    model = MODELS.build("linear", schedule=Schedule(epochs=2, batch_size=16))
    data = _instances(shape=(7,))
    model.fit(data)
    return model, data


def test_find_trained_is_the_newest_finished_run_of_the_key_or_what_it_reused(mlflow_uri):
    import time

    tracker = Tracker(mlflow_uri, "store")

    def logged(name: str, tags: dict[str, str], fail: bool = False) -> str:
        time.sleep(0.01)  # distinct start times
        try:
            with tracker.run(name, {}, tags) as run_id:
                if fail:
                    raise RuntimeError("crash")
        except RuntimeError:
            pass
        return run_id

    assert store.find_trained(tracker, "k1") is None
    first = logged("first", {"training_key": "k1"})
    logged("other", {"training_key": "k2"})
    logged("crashed", {"training_key": "k1"}, fail=True)
    assert store.find_trained(tracker, "k1") == first
    second = logged("second", {"training_key": "k1"})
    assert store.find_trained(tracker, "k1") == second
    logged("copy", {"training_key": "k1", "reused_from": second})
    assert store.find_trained(tracker, "k1") == second  # provenance: the training run
    assert store.find_trained(Tracker(mlflow_uri, "another"), "k1") is None


def test_a_logged_model_loads_from_its_run_and_missing_files_name_the_run(mlflow_uri, tmp_path):
    model, data = _linear()
    tracker = Tracker(mlflow_uri, "store")
    with tracker.run("r", {}, {}) as run_id:
        store.log_folder(
            tracker, run_id, "model", lambda d: artifacts.write_model(d, "linear", model)
        )
        store.log_folder(tracker, run_id, "half", lambda d: (d / "settings.json").write_text("{}"))
    loaded = store.load_model(tracker, run_id, "model", {"device": "cpu"})
    assert loaded.get_params()["device"] == "cpu"
    np.testing.assert_array_equal(loaded.decision_function(data.X), model.decision_function(data.X))
    local = store.download(tracker, run_id, "model", artifacts.MODEL_FILES)
    assert sorted(p.name for p in local.iterdir()) == sorted(artifacts.MODEL_FILES)
    with pytest.raises(
        artifacts.ArtifactError,
        match=rf"^run {run_id}: artifact half/ lacks weights.pt, arrays.npz$",
    ):
        store.load_model(tracker, run_id, "half")
    with pytest.raises(
        artifacts.ArtifactError, match=rf"^run {run_id}: artifact nothing/ cannot be"
    ):
        store.download(tracker, run_id, "nothing", artifacts.STATE_FILES)


def test_state_folders_round_trip_and_bad_files_name_the_artifact(tmp_path):
    settings = {"steps": np.int64(3), "shape": (1, 2), "sizes": np.array([4, 5])}
    artifacts.write_state(tmp_path, settings, {"a": [1.5, 2.0]})
    settings = artifacts.read_json(tmp_path, "here")
    assert settings == {"format": artifacts.FORMAT, "steps": 3, "shape": [1, 2], "sizes": [4, 5]}
    np.testing.assert_array_equal(artifacts.read_arrays(tmp_path, "here")["a"], [1.5, 2.0])
    assert list(artifacts.read_arrays(tmp_path, "here")) == ["a"]
    with pytest.raises(TypeError, match="^cannot store object as JSON$"):
        artifacts.write_state(tmp_path, {"x": object()}, {})
    for text in ("[1]", '{"format": 0}', "{}"):
        (tmp_path / "settings.json").write_text(text)
        with pytest.raises(
            artifacts.ArtifactError,
            match=rf"^here/settings.json: expected a mapping with format {artifacts.FORMAT}$",
        ):
            artifacts.read_json(tmp_path, "here")
    (tmp_path / "settings.json").write_text("{")
    with pytest.raises(
        artifacts.ArtifactError, match=r"^here/settings.json is not readable JSON \("
    ):
        artifacts.read_json(tmp_path, "here")
    (tmp_path / "arrays.npz").write_bytes(b"garbage")
    with pytest.raises(
        artifacts.ArtifactError, match=r"^here/arrays.npz is not a readable npz file"
    ):
        artifacts.read_arrays(tmp_path, "here")


def test_stored_model_settings_are_checked_before_loading(tmp_path):
    model, data = _linear()
    artifacts.write_model(tmp_path, "linear", model)
    settings = json.loads((tmp_path / "settings.json").read_text())
    assert settings["model"] == "linear"
    assert settings["input_shape"] == list(data.X.shape[1:])
    assert settings["format"] == artifacts.FORMAT
    for broken in ({"model": None}, {"input_shape": ["x"]}, {"params": 3}):
        (tmp_path / "settings.json").write_text(json.dumps(settings | broken))
        if broken == {"model": None}:
            (tmp_path / "settings.json").write_text(
                json.dumps({k: v for k, v in settings.items() if k != "model"})
            )
        with pytest.raises(
            artifacts.ArtifactError, match=r"^w/settings.json: missing or bad entry"
        ):
            artifacts.read_model(tmp_path, "w")
    (tmp_path / "settings.json").write_text(json.dumps(settings | {"model": "nope"}))
    with pytest.raises(artifacts.ArtifactError, match=r"^w: the stored nope model does not load"):
        artifacts.read_model(tmp_path, "w")
    (tmp_path / "settings.json").write_text(json.dumps(settings))
    torch.save({"w": [1, 2]}, tmp_path / "weights.pt")
    with pytest.raises(
        artifacts.ArtifactError, match=r"^w/weights.pt: expected a mapping of names to tensors$"
    ):
        artifacts.read_model(tmp_path, "w")
    torch.save([torch.zeros(1)], tmp_path / "weights.pt")
    with pytest.raises(artifacts.ArtifactError, match=r"^w/weights.pt: expected a mapping"):
        artifacts.read_model(tmp_path, "w")


def test_model_name_is_the_registry_name_that_read_model_builds(tmp_path):
    """A stored model is rebuilt from the name ``model_name`` gives: it must be its own class's."""
    model, data = _linear()
    assert artifacts.model_name(model) == "linear"
    assert artifacts.model_name(HapticCNN(widths=(2, 2, 2))) == "haptic_cnn"
    artifacts.write_model(tmp_path, artifacts.model_name(model), model)
    assert type(artifacts.read_model(tmp_path, "here")) is type(model)
    with pytest.raises(KeyError, match="^'Instances is not a registered model'$"):
        artifacts.model_name(data)


def test_models_configured_with_numpy_values_are_stored_as_plain_json(tmp_path):
    """Settings from array code (a C grid made by np.logspace, a numpy int seed) are stored."""
    model = MODELS.build("linear_svm", Cs=tuple(np.logspace(-2, 0, 3)), n_draws=4, seed=np.int64(3))
    X, y = _instances(shape=(7,)).X, np.arange(40) % 2
    data = Instances(X, y, np.array([f"t{i}" for i in range(40)], dtype=object), np.arange(40) // 2)
    model.fit(data)
    artifacts.write_model(tmp_path, "linear_svm", model)
    params = json.loads((tmp_path / "settings.json").read_text())["params"]
    assert params["Cs"] == [0.01, 0.1, 1.0] and params["seed"] == 3
    loaded = artifacts.read_model(tmp_path, "here")
    np.testing.assert_array_equal(loaded.decision_function(X), model.decision_function(X))


def test_a_model_that_does_not_load_from_its_run_names_the_run_and_artifact(mlflow_uri):
    model, _ = _linear()
    tracker = Tracker(mlflow_uri, "store")

    def broken(folder: Path) -> None:
        artifacts.write_model(folder, "linear", model)
        (folder / "settings.json").write_text('{"format": 0}')

    with tracker.run("r", {}, {}) as run_id:
        store.log_folder(tracker, run_id, "model", broken)
    with pytest.raises(
        artifacts.ArtifactError,
        match=rf"^run {run_id}: artifact model/settings.json: expected a mapping with format 1$",
    ):
        store.load_model(tracker, run_id, "model")


class _Marker:
    """Pickles as a call that creates a file: what a crafted weights.pt could run on load."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self):
        return (self.path.touch, ())


def test_stored_weights_never_run_code_and_arrays_are_checked(tmp_path):
    model, _ = _linear()
    artifacts.write_model(tmp_path, "linear", model)
    ran = tmp_path / "ran"
    torch.save({"body.w": torch.zeros(1), "x": _Marker(ran)}, tmp_path / "weights.pt")
    with pytest.raises(
        artifacts.ArtifactError, match=r"^w/weights.pt is not a readable state_dict"
    ):
        artifacts.read_model(tmp_path, "w")
    assert not ran.exists()
    artifacts.write_model(tmp_path, "linear", model)
    (tmp_path / "arrays.npz").write_bytes(b"garbage")
    with pytest.raises(artifacts.ArtifactError, match=r"^w/arrays.npz is not a readable npz file"):
        artifacts.read_model(tmp_path, "w")


def test_weights_saved_on_a_gpu_load_on_the_cpu(tmp_path, monkeypatch):
    """A model trained on a GPU machine loads where there is none (the CPU-only test machine)."""
    model, data = _linear()
    with monkeypatch.context() as patch:  # stored as if its tensors lived on the GPU
        patch.setattr(torch.serialization, "location_tag", lambda storage: "cuda:0")
        artifacts.write_model(tmp_path, "linear", model)
    loaded = artifacts.read_model(tmp_path, "w")
    assert all(t.device.type == "cpu" for t in loaded.state()[0].values())
    np.testing.assert_array_equal(loaded.decision_function(data.X), model.decision_function(data.X))


# --- claims: jobs side by side train each model once -----------------------------------------

KEY = "k" * 20


def _claim(tracker: Tracker, **who: str) -> str:
    """A RUNNING run tagged with KEY, as a job training it makes; ``who``: host, pid, pid_start."""
    run = tracker.client.create_run(tracker.experiment_id, tags={"training_key": KEY, **who})
    time.sleep(0.01)  # start times in ms: the next claim is strictly younger
    return run.info.run_id


def _await_in_thread(tracker: Tracker, run_id: str, lease: float = 3600.0):
    found: list[str | None] = []
    thread = threading.Thread(
        target=lambda: found.append(
            store.await_trained(tracker, KEY, run_id, lease=lease, poll=0.05)
        )
    )
    thread.start()
    return thread, found


def test_a_live_claim_is_waited_for_and_its_model_then_loaded(mlflow_uri, caplog):
    tracker = Tracker(mlflow_uri, "tactile_exp")
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        theirs = _claim(tracker, host=socket.gethostname(), pid=str(live.pid))
        mine = _claim(tracker, **process_tags())
        with caplog.at_level("INFO", logger="tactile_exp.store"):
            thread, found = _await_in_thread(tracker, mine)
            time.sleep(0.6)  # a dozen polls
            assert thread.is_alive() and not found  # not taken over: its process runs
            tracker.client.set_terminated(theirs, "FINISHED")  # it trained the model
            thread.join(10)
    finally:
        live.kill()
        live.wait()
    assert found == [theirs]
    waiting = [r for r in caplog.messages if "waiting for run" in r]
    assert len(waiting) == 1 and theirs in waiting[0] and str(live.pid) in waiting[0]


def test_a_claimant_finishing_between_the_stores_queries_is_not_missed(mlflow_uri, monkeypatch):
    """The claimant finishes right after a look for finished runs found none: the waiting job
    must load its model, not find no claim left and train the model a second time."""
    tracker = Tracker(mlflow_uri, "tactile_exp")
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        theirs = _claim(tracker, host=socket.gethostname(), pid=str(live.pid))
        mine = _claim(tracker, **process_tags())
        looked = store.find_trained

        def finishes_after_the_first_look(tracker_: Tracker, key: str) -> str | None:
            found = looked(tracker_, key)
            if tracker.client.get_run(theirs).info.status == "RUNNING":
                tracker.client.set_terminated(theirs, "FINISHED")
            return found

        monkeypatch.setattr(store, "find_trained", finishes_after_the_first_look)
        assert store.await_trained(tracker, KEY, mine, lease=3600.0, poll=0.05) == theirs
    finally:
        live.kill()
        live.wait()


def test_a_dead_claimants_claim_is_taken_over(mlflow_uri, caplog):
    tracker = Tracker(mlflow_uri, "tactile_exp")
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = _claim(tracker, host=socket.gethostname(), pid=str(dead.pid))
    mine = _claim(tracker, **process_tags())
    with caplog.at_level("INFO", logger="tactile_exp.store"):
        assert store.await_trained(tracker, KEY, mine, lease=3600.0, poll=0.05) is None
    assert any(stale in m and "abandoned" in m for m in caplog.messages)
    younger = _claim(tracker, **process_tags())  # a third job now waits for this one
    thread, found = _await_in_thread(tracker, younger)
    time.sleep(0.3)
    assert thread.is_alive()
    tracker.client.set_terminated(mine, "FAILED")  # training failed: the next live claim trains
    thread.join(10)
    assert found == [None]


@pytest.mark.job
def test_a_job_claims_with_the_configured_lease(tiny_config, monkeypatch):
    """``tracking.claim_lease`` (a typed setting) is the lease the job's claims hold for."""
    leases = []
    waited = store.await_trained

    def spy(tracker: Tracker, key: str, run_id: str, *, lease: float) -> str | None:
        leases.append(lease)
        return waited(tracker, key, run_id, lease=lease)

    monkeypatch.setattr(store, "await_trained", spy)
    run(settings_from_config(tiny_config([*REPEAT, "tracking.claim_lease=42"], ONE)))
    assert leases == [42.0]


@pytest.mark.parametrize(("lease", "waits"), [(3600.0, True), (0.001, False)])
def test_another_hosts_claim_holds_for_its_lease(mlflow_uri, lease, waits):
    tracker = Tracker(mlflow_uri, "tactile_exp")
    theirs = _claim(tracker, host="elsewhere." + socket.gethostname(), pid="1")
    mine = _claim(tracker, **process_tags())
    thread, found = _await_in_thread(tracker, mine, lease=lease)
    time.sleep(0.3)
    assert thread.is_alive() == waits
    tracker.client.set_terminated(theirs, "FAILED")
    thread.join(10)
    assert found == [None]


def _job(overrides: list[str], log: Path) -> subprocess.Popen:
    """``python -m tactile_exp`` in a process of its own, its output in ``log``."""
    with log.open("w") as out:
        return subprocess.Popen(
            [sys.executable, "-m", "tactile_exp", *overrides, f"hydra.run.dir={log.parent}/hydra"],
            stdout=out,
            stderr=subprocess.STDOUT,
        )


@pytest.mark.job
@pytest.mark.slow  # two tiny jobs in processes of their own, two in this one
def test_two_jobs_side_by_side_train_a_shared_model_once(
    tiny_config, cache_dir, mlflow_uri, tmp_path
):
    jobs = {"A": [], "B": ["combine=2"]}  # a head-only difference: one ConvNet for both
    sequential = {}
    for name, extra in jobs.items():
        config = tiny_config([*REPEAT, *extra], ONE)
        sequential[name] = _children(mlflow_uri, run(settings_from_config(config)).run_id)["hard"]
    key = sequential["A"].data.tags["training_key"]
    assert sequential["B"].data.tags["reused_from"] == sequential["A"].info.run_id

    # This test holds the key's claim, so both jobs are seen waiting before either trains.
    tracker = Tracker(mlflow_uri, "side_by_side")
    held = tracker.client.create_run(
        tracker.experiment_id, tags={"training_key": key, **process_tags()}
    ).info.run_id
    base = [*TINY_DATA, f"cache_dir={cache_dir}", f"tracking.uri={mlflow_uri}", *REPEAT]
    base += ["tracking.experiment=side_by_side"]
    base += [f"adjectives={ONE}", "schedule=tiny"]
    logs = {name: tmp_path / name / "job.log" for name in jobs}
    procs = {}
    for name, extra in jobs.items():
        logs[name].parent.mkdir()
        procs[name] = _job([*base, *extra], logs[name])
    try:
        deadline = time.monotonic() + 120
        while not all(f"waiting for run {held}" in logs[n].read_text() for n in jobs):
            assert time.monotonic() < deadline and all(p.poll() is None for p in procs.values())
            time.sleep(0.2)
        tracker.client.set_terminated(held, "FAILED")  # released without a model
        for p in procs.values():
            assert p.wait(120) == 0
    finally:
        for p in procs.values():
            p.kill()

    runs = tracker.client.search_runs(
        [tracker.experiment_id],
        f"tags.training_key = '{key}' and attributes.status = 'FINISHED'",
    )
    trained = [r for r in runs if "reused_from" not in r.data.tags]
    assert len(runs) == 2 and len(trained) == 1  # one of the two trained it, once
    reused = next(r for r in runs if "reused_from" in r.data.tags)
    assert reused.data.tags["reused_from"] == trained[0].info.run_id
    assert "waiting for run " + trained[0].info.run_id in "".join(
        log.read_text() for log in logs.values()
    )
    by_combine = {_parent_combine(tracker, r): r for r in runs}
    for name, reference in sequential.items():  # results equal the one-at-a-time jobs'
        concurrent = by_combine[_parent_combine(tracker, reference)]
        assert _scores(mlflow_uri, concurrent) == _scores(mlflow_uri, reference), name


@pytest.mark.job
@pytest.mark.slow  # two tiny jobs
def test_an_adjective_trained_elsewhere_is_put_off_and_the_others_trained_meanwhile(
    tiny_config, mlflow_uri, caplog
):
    two = "[hard,soft]"
    reference = _children(mlflow_uri, run(settings_from_config(tiny_config(REPEAT, two))).run_id)
    key = reference["hard"].data.tags["training_key"]

    # This test holds hard's claim, as a job side by side that trains it would: the job takes
    # soft first, then waits for hard; the claim is released (without a model) once it does.
    tracker = Tracker(mlflow_uri, "put_off")
    held = tracker.client.create_run(
        tracker.experiment_id, tags={"training_key": key, **process_tags()}
    ).info.run_id
    seen: dict[str, str] = {}

    def release_when_waited_for() -> None:
        deadline = time.monotonic() + 120
        while len(tracker.claims(key)) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)  # the job's own run for hard is its second claim: its turn came
        soft = tracker.client.search_runs(
            [tracker.experiment_id], "tags.adjective = 'soft' and tags.run_level = 'child'"
        )
        seen["soft"] = ",".join(r.info.status for r in soft)
        waiting = f"training key {key}: waiting for run {held}"
        while waiting not in caplog.text and time.monotonic() < deadline:
            time.sleep(0.05)  # released once the job waits for it, not before
        tracker.client.set_terminated(held, "FAILED")

    releaser = threading.Thread(target=release_when_waited_for)
    releaser.start()
    with caplog.at_level("INFO", logger="tactile_exp"):
        job = run(settings_from_config(tiny_config([*REPEAT, "tracking.experiment=put_off"], two)))
    releaser.join()

    assert seen["soft"] == "FINISHED"  # trained while hard's model was being trained elsewhere
    assert f"hard: run {held} trains its model; taken after the others" in caplog.text
    assert f"training key {key}: waiting for run {held}" in caplog.text  # not released earlier
    assert list(job.results) == ["hard", "soft"]  # the job's order, whichever ran first
    children = {
        a: tracker.client.get_run(r.info.run_id)
        for a, r in _children_in(tracker, job.run_id).items()
    }
    assert children["soft"].info.start_time < children["hard"].info.start_time
    assert "reused_from" not in children["hard"].data.tags  # released without a model: trained
    for adjective, ref in reference.items():  # results equal the job's run in the usual order
        assert _scores(mlflow_uri, children[adjective]) == _scores(mlflow_uri, ref), adjective


def _children_in(tracker: Tracker, parent_id: str) -> dict[str, object]:
    runs = tracker.client.search_runs(
        [tracker.experiment_id],
        f"tags.mlflow.parentRunId = '{parent_id}' and tags.run_level = 'child'",
    )
    return {r.data.tags["adjective"]: r for r in runs}


def _parent_combine(tracker: Tracker, child) -> str:
    parent = tracker.client.get_run(child.data.tags["mlflow.parentRunId"])
    return parent.data.params["combine"]


def test_a_reused_model_takes_the_head_schedule_kernels_and_device_of_the_job(tmp_path):
    """What ``MODEL_UNKEYED`` names comes from the job that reuses a model (dotted keys: the
    head inside the schedule), everything keyed from where it was trained."""
    trained = {"schedule": {"epochs": 2, "batch_size": 16, "head": {"lr": 0.5}}, "impl": "torch"}
    model = MODELS.build("linear", **trained)
    data = _instances(shape=(7,))
    model.fit(data)
    artifacts.write_model(tmp_path, "linear", model)
    job = {"schedule": {"epochs": 2, "batch_size": 16, "head": {"lr": 0.1}}, "impl": "auto"}
    assert keys.unkeyed(Component("linear", job)) == {"schedule.head": {"lr": 0.1}, "impl": "auto"}
    loaded = artifacts.read_model(
        tmp_path, "here", keys.unkeyed(Component("linear", job | {"device": "cpu"}))
    )
    assert (loaded.impl, loaded.device) == ("auto", "cpu")
    assert loaded.schedule == Schedule.of(job["schedule"]) != model.schedule
    assert loaded.head().schedule.lr == 0.1
    np.testing.assert_array_equal(loaded.decision_function(data.X), model.decision_function(data.X))
    # a job whose schedule has no head: the reused model's head trains like the model, as there
    plain = artifacts.read_model(
        tmp_path, "here", keys.unkeyed(Component("linear", {"schedule": {"epochs": 2}}))
    )
    assert plain.schedule.head is None
    assert keys.unkeyed(Component("linear_svm", {"Cs": None, "seed": 0})) == {}  # nothing unkeyed
