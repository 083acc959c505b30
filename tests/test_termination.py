"""SIGTERM never lands inside an MLflow write (a half-done sqlite transaction left runs RUNNING)."""

import os
import signal

import pytest

from tactile_exp import termination
from tactile_exp.tracking import Tracker


@pytest.fixture
def sigterm_raises():
    before = signal.signal(signal.SIGTERM, termination.handle)
    yield
    signal.signal(signal.SIGTERM, before)


def test_sigterm_inside_a_shielded_block_is_raised_when_it_ends(sigterm_raises):
    done = []
    with pytest.raises(termination.Terminated, match="signal 15"), termination.shielded():
        os.kill(os.getpid(), signal.SIGTERM)
        done.append("the write finished")
    assert done == ["the write finished"]
    with termination.shielded():  # nothing pending afterwards
        pass


def test_sigterm_outside_a_shielded_block_is_raised_at_once(sigterm_raises):
    with pytest.raises(termination.Terminated):
        os.kill(os.getpid(), signal.SIGTERM)
        signal.pause()  # not reached: the handler raises


def test_sigterm_while_a_run_is_created_still_ends_it_failed(
    sigterm_raises, mlflow_uri, monkeypatch
):
    from mlflow.tracking import MlflowClient

    tracker = Tracker(mlflow_uri, "terminated")
    create = tracker.client.create_run

    def create_then_signal(*args, **kwargs):
        run = create(*args, **kwargs)
        os.kill(os.getpid(), signal.SIGTERM)  # arrives mid-write
        return run

    monkeypatch.setattr(tracker.client, "create_run", create_then_signal)
    with pytest.raises(termination.Terminated), tracker.run("job", {"a": "1"}, {}):
        pytest.fail("the job body must not start after the signal")
    (run,) = MlflowClient(mlflow_uri).search_runs([tracker.experiment_id])
    assert run.info.status == "FAILED" and run.data.params == {"a": "1"}
    assert run.data.tags["error"].startswith("Terminated: terminated by signal 15")
