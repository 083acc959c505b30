"""Reliability (issue 10): one-line config errors before any run, stale RUNNING runs ended at
start, an unreachable tracking server named at once, and small data sets (5 objects)."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from mlflow.tracking import MlflowClient

from tactile_exp.config import ConfigError, settings_from_config
from tactile_exp.data.layout import DataError
from tactile_exp.experiment import run
from tactile_exp.models.linear_svm import ObjectCVLinearSVM
from tactile_exp.tracking import Tracker, TrackingError, process_tags

# 5 objects x 3 trials: absorbent 2 positive objects, squishy 3, cool none.
FIVE_OBJECTS = (101, 116, 214, 316, 501)


@pytest.fixture(scope="module")
def five_objects(tmp_path_factory: pytest.TempPathFactory) -> Path:
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


def _all_runs(uri: str):
    client = MlflowClient(uri)
    exp = client.get_experiment_by_name("tactile_exp")
    return [] if exp is None else client.search_runs([exp.experiment_id], max_results=1000)


@pytest.mark.parametrize(
    "override,line",
    [
        ("seed=-1", "seed: must be a whole number in 0..2**32-1, got -1"),
        ("schedule.epochs=0", "schedule.epochs: epochs must be an int >= 1, got 0"),
        ("schedule.lr=0", "schedule.lr: lr must be > 0 and finite, got 0"),
        ("schedule.head.batch_size=0", "schedule.head.batch_size: batch_size must be an int >= 1"),
        ("+schedule.epoch=2", "schedule.epoch: unknown key; allowed: epochs, finetune_epochs,"),
        (  # Hydra's ++ replaces the interpolated node: refused, not trained for 200 epochs
            "++model.schedule.lr=0.5",
            "model.schedule: missing epochs, finetune_epochs, batch_size, momentum; the model",
        ),
        (
            "model=visual_googlenet modality=visual model.schedule.lr=0",
            "model.schedule.lr: lr must be > 0 and finite, got 0",
        ),
        ("model.kernel_sizes=[5,0,5]", "model.kernel_sizes: kernel_sizes must be >= 1"),
        ("data=phac2", "data.path: missing; set it on the command line"),
        ("data.path=/no/such.h5", "data.path: /no/such.h5: no such file"),
    ],
)
def test_impossible_values_name_the_key_typed(compose_config, override, line):
    overrides = override.split()
    overrides = ["data=phac2", *overrides] if override.startswith("data.path") else overrides
    with pytest.raises(ConfigError) as err:
        settings_from_config(compose_config(overrides))
    assert str(err.value).startswith(line)
    assert "\n" not in str(err.value)


def test_seed_is_checked_the_same_for_every_row(compose_config):
    for row in ("table1_i_haptic_cnn_1trial", "table1_o_random", "table1_a_haptic_static_1trial"):
        with pytest.raises(ConfigError, match="^seed: "):
            settings_from_config(compose_config([f"experiment={row}", "seed=-1"]))


def test_config_error_is_one_line_and_exit_2_before_any_run(tmp_path, mlflow_uri):
    """The CLI: no traceback, exit 2, and no MLflow run for a typo found only in the data."""
    env = {**os.environ, "HYDRA_FULL_ERROR": "0"}
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "tactile_exp",
            "data=phac2",
            f"data.path={tmp_path / 'missing.h5'}",
            f"tracking.uri={mlflow_uri}",
            f"hydra.run.dir={tmp_path / 'run'}",
        ],
        capture_output=True,
        text=True,
        timeout=180,
        env=env,
    )
    assert done.returncode == 2
    errors = [line for line in done.stderr.splitlines() if "Warning" not in line]
    assert errors == [
        f"error: data.path: {tmp_path / 'missing.h5'}: no such file; expected the PHAC-2 HDF5 file"
    ]
    assert _all_runs(mlflow_uri) == []


def test_combine_beyond_the_file_fails_before_a_run_is_created(tiny_config, mlflow_uri):
    settings = settings_from_config(tiny_config(["combine=3", "model=random"]))
    with pytest.raises(ConfigError, match="^combine: 3 trials per unit"):
        run(settings)
    assert _all_runs(mlflow_uri) == []


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_stale_running_runs_of_the_config_are_ended_at_start(mlflow_uri):
    tracker = Tracker(mlflow_uri, "tactile_exp")
    client = tracker.client
    here = process_tags()
    cases = {
        "dead": {**here, "pid": str(_dead_pid()), "pid_start": ""},
        "reused_pid": {**here, "pid_start": "1"},  # our PID, but started at another time
        "alive": here,
        "other_host": {**here, "host": "elsewhere", "pid": str(_dead_pid())},
    }
    ids = {}
    for name, tags in cases.items():
        ids[name] = client.create_run(
            tracker.experiment_id, run_name=name, tags={**tags, "config_hash": "abc"}
        ).info.run_id
    other = client.create_run(
        tracker.experiment_id, tags={**cases["dead"], "config_hash": "zzz"}
    ).info.run_id

    ended = tracker.end_stale_runs("abc")

    assert sorted(ended) == sorted([ids["dead"], ids["reused_pid"]])
    status = {name: client.get_run(i).info for name, i in ids.items()}
    assert status["dead"].status == status["reused_pid"].status == "KILLED"
    assert status["dead"].end_time is not None
    assert "stale: process" in client.get_run(ids["dead"]).data.tags["error"]
    assert status["alive"].status == status["other_host"].status == "RUNNING"
    assert client.get_run(other).info.status == "RUNNING"  # another config: not this job's


def test_runs_record_host_and_process(tiny_config, mlflow_uri):
    run(settings_from_config(tiny_config(["model=random", "combine_instances=separate"])))
    runs = _all_runs(mlflow_uri)
    assert runs and all(r.data.tags["host"] == socket.gethostname() for r in runs)
    assert all(r.data.tags["pid"] == str(os.getpid()) for r in runs)


def test_tracking_server_down_is_one_line_naming_the_uri():
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    uri = f"http://127.0.0.1:{port}"
    start = time.monotonic()
    with pytest.raises(TrackingError) as err:
        Tracker(uri, "tactile_exp")
    assert time.monotonic() - start < 10
    assert str(err.value).startswith(f"tracking.uri: no MLflow server answers at {uri}")


def test_svm_on_few_objects_holds_out_fewer_objects_and_still_chooses_c():
    """A lab's small file: with 4 objects (2 per class) no leave-3-out draw keeps both classes
    in training, so C is chosen by leave-2-out (a CV score per C), with a warning; 5 objects
    (3 + 2) still allow the default leave-3-out, silently; 3 objects allow no CV at all."""
    rng = np.random.default_rng(0)
    groups = np.repeat([1, 2, 3, 4, 5], 6)
    y = (groups <= 3).astype(int)
    X = rng.normal(size=(30, 4)) + y[:, None]
    four = groups >= 2
    svm = ObjectCVLinearSVM(n_draws=20)
    with pytest.warns(UserWarning, match="only 4 training objects: C chosen by leave-2-objects"):
        svm.fit(X[four], y[four], groups[four])
    assert svm.cv_scores_ is not None and len(svm.cv_scores_) == len(svm.Cs)
    assert svm.Cs[int(np.argmax(svm.cv_scores_))] == svm.C_
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # 5 objects: leave-3-out works, nothing to warn about
        assert ObjectCVLinearSVM(n_draws=20).cv_scores(X, y, groups) is not None
    three = groups >= 3  # 1 positive object, 2 negative: no draw scores C
    with pytest.warns(UserWarning, match="middle C"):
        svm.fit(X[three], y[three], groups[three])
    assert svm.cv_scores_ is None and svm.Cs[len(svm.Cs) // 2] == svm.C_


@pytest.mark.parametrize(
    "row,adjectives",
    [
        ("table1_a_haptic_static_1trial", "[absorbent,squishy]"),
        ("table1_i_haptic_cnn_1trial", "[absorbent,squishy]"),
    ],
)
def test_rows_a_and_i_run_on_five_objects(tiny_config, five_objects, row, adjectives):
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
    assert all(0.0 <= r.auc <= 1.0 for r in result.results.values())
    messages = " ".join(str(w.message) for w in caught)
    assert "falling back to the random split" in messages  # published test objects are absent


def test_adjective_without_positive_objects_is_refused_before_a_run(
    tiny_config, five_objects, mlflow_uri
):
    settings = settings_from_config(
        tiny_config(
            ["experiment=table1_a_haptic_static_1trial", "data=phac2", f"data.path={five_objects}"],
            adjectives="[absorbent,cool]",
        )
    )
    with pytest.raises(DataError, match="'cool'"):
        run(settings)
    assert _all_runs(mlflow_uri) == []


TERMINATE = """
import os, subprocess, sys
from multiprocessing import resource_tracker
from tactile_exp import sweep

class NoRuns:
    def end_runs_of(self, pids, *, error):
        return []

sweep.WORKER_GRACE_S = 5.0
resource_tracker.ensure_running()  # a child that ignores SIGTERM, as loky's does
worker = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
before = sweep._children(os.getpid())
trackers = sorted(p for p in before if sweep._resource_tracker(p))
try:
    sweep.terminate_workers(15, None, tracker=NoRuns())
except SystemExit as stop:
    print("exit", stop.code)
print("before", *sorted(before))
print("alive", *sorted(p for p in before if not sweep._gone(p)))
print("worker", worker.pid)
print("trackers", *trackers)
"""


def test_a_terminated_sweep_stops_its_workers_and_leaves_resource_trackers_alone():
    """Resource trackers ignore SIGTERM and end with the launcher: waiting for them cost a
    terminated sweep the whole grace period, then SIGKILLed them."""
    done = subprocess.run(
        [sys.executable, "-c", TERMINATE], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr[-2000:]
    lines = {key: value for key, _, value in (s.partition(" ") for s in done.stdout.splitlines())}
    assert lines["exit"] == "143"
    before, alive = lines["before"].split(), lines["alive"].split()
    assert lines["worker"] in before and len(before) == 2
    assert len(lines["trackers"].split()) == 1
    assert alive == lines["trackers"].split()  # the tracker neither killed nor waited for
