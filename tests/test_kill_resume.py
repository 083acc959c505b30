# Cross-cutting, so not tests/test_<module>.py: real job and sweep processes killed
# mid-run, then rerun: the engine, tracking, workers and the sweep together, in one process tree.
"""Killed jobs and terminated sweeps: nothing stays RUNNING, a rerun finishes the
job with the AUCs of an uninterrupted run, and SIGTERM to a parallel sweep stops its workers."""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from conftest import TINY_DATA
from mlflow.tracking import MlflowClient

from tactile_exp.runtime import processes

pytestmark = pytest.mark.slow


def _runs(uri: str):
    client = MlflowClient(uri)
    exp = client.get_experiment_by_name("tactile_exp")
    return [] if exp is None else client.search_runs([exp.experiment_id], max_results=1000)


def _job(cache_dir: Path, uri: str, run_dir: Path, *extra: str) -> list[str]:
    return [
        sys.executable,
        "-m",
        "tactile_exp",
        *TINY_DATA,
        f"cache_dir={cache_dir}",
        f"tracking.uri={uri}",
        "schedule=tiny",
        "schedule.epochs=50",  # soft trains for seconds after its first epoch line: time to kill
        "adjectives=[hard,soft,smooth]",
        "seed=41",
        f"hydra.run.dir={run_dir}",
        *extra,
    ]


def _parent_aucs(uri: str) -> dict[str, float]:
    (parent,) = [
        r
        for r in _runs(uri)
        if r.data.tags.get("run_level") == "parent" and r.info.status == "FINISHED"
    ]
    return {k: v for k, v in parent.data.metrics.items() if k.startswith("auc.")}


def test_sigkill_mid_adjective_then_rerun(cache_dir, mlflow_uri, mlflow_template, tmp_path):
    """SIGKILL right after soft's first epoch: no handler runs. The rerun marks the orphans
    KILLED, reuses hard's stored model and retrains soft, with an uninterrupted run's AUCs."""
    job = subprocess.Popen(
        _job(cache_dir, mlflow_uri, tmp_path / "killed"),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        for line in job.stdout:  # type: ignore[union-attr]
            if "soft epoch 1/" in line:  # inside soft's training, 49 epochs to go
                break
        else:
            pytest.fail("the job ended before its second adjective")
        job.send_signal(signal.SIGKILL)
        job.wait(timeout=30)
    finally:
        job.kill()
    left = {r.info.run_name: r for r in _runs(mlflow_uri)}
    assert left["adj=hard"].info.status == "FINISHED" and left["adj=soft"].info.status == "RUNNING"

    reference = tmp_path / "reference" / "mlflow.db"
    reference.parent.mkdir()
    shutil.copy(mlflow_template, reference)
    uninterrupted = subprocess.Popen(  # side by side with the rerun: CI time
        _job(cache_dir, f"sqlite:///{reference}", tmp_path / "reference-run"),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    rerun = subprocess.run(
        _job(cache_dir, mlflow_uri, tmp_path / "rerun"), capture_output=True, text=True
    )
    assert rerun.returncode == 0, rerun.stderr[-2000:]
    _, errors = uninterrupted.communicate(timeout=300)
    assert uninterrupted.returncode == 0, errors[-2000:]
    runs = _runs(mlflow_uri)
    assert not [r.info.run_name for r in runs if r.info.status == "RUNNING"]
    killed = [r for r in runs if r.info.status == "KILLED"]
    assert sorted(r.data.tags.get("adjective", "(job)") for r in killed) == ["(job)", "soft"]
    assert all(r.info.end_time is not None for r in killed)
    rerun_children = {
        r.info.run_name: r
        for r in runs
        if r.info.status == "FINISHED" and r.info.run_id != left["adj=hard"].info.run_id
    }
    assert rerun_children["adj=hard"].data.tags["reused_from"] == left["adj=hard"].info.run_id
    assert "reused_from" not in rerun_children["adj=soft"].data.tags
    aucs = _parent_aucs(mlflow_uri)
    assert set(aucs) == {"auc.hard", "auc.soft", "auc.smooth"}
    assert aucs == _parent_aucs(f"sqlite:///{reference}")


def test_sigterm_to_a_parallel_sweep_stops_its_workers(cache_dir, mlflow_uri, tmp_path):
    args = [
        *TINY_DATA,
        f"cache_dir={cache_dir}",
        f"tracking.uri={mlflow_uri}",
        "adjectives=[hard]",
        "schedule=tiny",
        "schedule.epochs=100000",
        "seed=51,52,53",
        "hydra/launcher=joblib",
        "hydra.launcher.n_jobs=2",
        f"hydra.sweep.dir={tmp_path}/multirun",
    ]
    sweep = subprocess.Popen([sys.executable, "-m", "tactile_exp", "-m", *args])
    try:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:  # two jobs training at once
            training = [
                r
                for r in _runs(mlflow_uri)
                if r.info.run_name == "adj=hard" and r.info.status == "RUNNING"
            ]
            if len(training) == 2:
                break
            time.sleep(0.5)
        else:
            pytest.fail("the sweep never had two jobs training")
        workers = processes.children(sweep.pid)
        sweep.send_signal(signal.SIGTERM)
        assert sweep.wait(timeout=120) != 0
    finally:
        sweep.kill()
    time.sleep(1.0)
    assert [pid for pid in workers if processes.process_alive(pid)] == []  # no orphaned worker
    runs = _runs(mlflow_uri)
    assert not [r.info.run_name for r in runs if r.info.status == "RUNNING"]
    parents = [r for r in runs if r.data.tags.get("run_level") == "parent"]
    assert len(parents) == 2 and all(r.info.status == "FAILED" for r in parents)
    assert all("signal 15" in r.data.tags["error"] for r in parents)
    assert not [r for r in runs if r.info.run_name.endswith("-s53")]  # never started


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_a_stopped_job_stops_its_adjective_workers(sig, cache_dir, mlflow_uri, tmp_path):
    """workers=2, both training: SIGTERM to the job passes it on (the workers' runs end FAILED);
    SIGKILL takes the workers with it (the parent-death signal: their runs end FAILED too)."""
    args = _job(cache_dir, mlflow_uri, tmp_path / "job", "workers=2", "schedule.epochs=100000")
    job = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    started = set()
    try:
        for line in job.stdout:  # type: ignore[union-attr]
            if " epoch 1/" in line:
                started.add(line.split(" epoch 1/")[0].split()[-1])
            if len(started) == 2:  # two adjectives training at once
                break
        else:
            pytest.fail("the job ended before two adjectives were training")
        # Keep reading: a job whose stdout pipe fills up blocks, its workers' log relay with it.
        threading.Thread(target=job.stdout.read, daemon=True).start()  # type: ignore[union-attr]
        workers = processes.children(job.pid)
        assert len(workers) >= 2
        job.send_signal(sig)
        assert job.wait(timeout=120) != 0
    finally:
        job.kill()
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and any(processes.process_alive(pid) for pid in workers):
        time.sleep(0.2)
    assert [pid for pid in workers if processes.process_alive(pid)] == []  # no orphaned worker
    runs = {r.info.run_name: r for r in _runs(mlflow_uri)}
    children = [runs[f"adj={a}"] for a in sorted(started)]
    assert all(r.info.status == "FAILED" for r in children)
    assert all("signal 15" in r.data.tags["error"] for r in children)
    assert "adj=smooth" not in runs  # never started
    if sig == signal.SIGTERM:
        (parent,) = [r for r in runs.values() if r.data.tags["run_level"] == "parent"]
        assert parent.info.status == "FAILED"
