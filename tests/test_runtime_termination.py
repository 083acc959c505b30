"""SIGTERM never lands inside an MLflow write (a half-done sqlite transaction left runs RUNNING)."""

import ctypes
import os
import signal
import sys

import pytest

from tactile_exp.runtime import termination
from tactile_exp.tracking import Tracker


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


def test_a_sigterm_dropped_by_a_ctypes_callback_is_raised_at_the_next_check(
    sigterm_raises, monkeypatch
):
    """numba compiles through llvmlite's ctypes callbacks: the handler's exception raised inside
    one is printed and dropped, and the job trained on (seen in CI). ``check`` raises it again."""
    termination.check()  # nothing received: no-op
    dropped = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: dropped.append(u.exc_type))
    callback = ctypes.CFUNCTYPE(None)(lambda: os.kill(os.getpid(), signal.SIGTERM))
    callback()  # "Exception ignored on calling ctypes callback function"
    assert dropped == [termination.Terminated]
    with pytest.raises(termination.Terminated, match="signal 15"):
        termination.check()


@pytest.mark.job
def test_a_job_that_received_sigterm_stops_at_its_next_epoch(
    sigterm_raises, tiny_config, mlflow_uri, monkeypatch
):
    """The epoch loop calls ``check``: a dropped SIGTERM ends the training, its runs FAILED."""
    from mlflow.tracking import MlflowClient

    from tactile_exp import experiment, recording
    from tactile_exp.config import settings_from_config

    logger = recording.epoch_logger
    epochs: list[int] = []

    def signalled_in_epoch_2(name):
        on_epoch = logger(name)

        def wrapped(epoch, n_epochs, metrics):
            epochs.append(epoch)
            if epoch == 2:
                termination._state["received"] = signal.SIGTERM  # as a dropped raise leaves it
            on_epoch(epoch, n_epochs, metrics)

        return wrapped

    monkeypatch.setattr(recording, "epoch_logger", signalled_in_epoch_2)
    overrides = ["model=haptic_cnn", "model.impl=torch"]
    settings = settings_from_config(tiny_config(overrides, adjectives="[hard]"))
    with pytest.raises(termination.Terminated, match="signal 15"):
        experiment.run(settings)
    assert epochs == [1, 2]
    client = MlflowClient(mlflow_uri)
    runs = client.search_runs([client.get_experiment_by_name("tactile_exp").experiment_id])
    assert sorted(r.info.status for r in runs) == ["FAILED", "FAILED"]


def test_a_signal_python_wraps_is_still_the_signal(sigterm_raises):
    """A SIGTERM landing in ``__set_name__`` (a class body being built, e.g. during an import)
    reaches the caller as Python's RuntimeError on 3.11: ``reason`` gives back the signal."""

    class Descriptor:
        def __set_name__(self, owner: type, name: str) -> None:
            os.kill(os.getpid(), signal.SIGTERM)

    other = ValueError("before any signal")
    assert termination.reason(other) is other
    with pytest.raises(BaseException) as caught:
        type("Owner", (), {"field": Descriptor()})
    stop = termination.reason(caught.value)
    assert isinstance(stop, termination.Terminated) and str(stop) == "terminated by signal 15"
