# Cross-cutting, so not tests/test_<module>.py: the lab's stack that ci/lab_stack.sh starts
# (SLURM, PostgreSQL, an MLflow server with proxied artifacts) under real jobs, races and faults.
"""The lab's stack: jobs on SLURM logging to a PostgreSQL-backed MLflow server.

These tests need ``ci/lab_stack.sh start`` (root). Without the stack they skip with one line;
with ``TACTILE_EXP_LAB_STACK`` set (CI sets it to the server's URI) a missing stack fails them.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
import time
import urllib.request
import uuid
from pathlib import Path

import pytest
from mlflow.tracking import MlflowClient

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
STACK = ROOT / "ci" / "lab_stack.sh"
DEFAULT_URI = "http://127.0.0.1:5055"  # ci/lab_stack.sh's LAB_MLFLOW_PORT default
N_JOBS = 6  # processes that set up one experiment at once


def _server_answers(uri: str) -> bool:
    try:
        with urllib.request.urlopen(f"{uri}/health", timeout=3) as response:
            return response.status == 200
    except OSError:
        return False


def _slurm_answers() -> bool:
    if shutil.which("sinfo") is None:
        return False
    out = subprocess.run(["sinfo", "-h", "-o", "%t"], capture_output=True, text=True)
    return out.returncode == 0 and any(s in out.stdout for s in ("idle", "mix", "alloc"))


@pytest.fixture(scope="module")
def server() -> str:
    """The stack's tracking URI; a skip (or, where CI expects the stack, a failure) without it."""
    expected = os.environ.get("TACTILE_EXP_LAB_STACK")
    uri = expected or DEFAULT_URI
    missing = [
        what
        for what, up in (("mlflow server", _server_answers(uri)), ("slurm", _slurm_answers()))
        if not up
    ]
    if missing:
        message = f"no lab stack ({', '.join(missing)} down at {uri}): run ci/lab_stack.sh start"
        if expected:
            pytest.fail(f"TACTILE_EXP_LAB_STACK is set but {message}")
        pytest.skip(message)
    return uri


def _experiment() -> str:
    return f"lab-{uuid.uuid4().hex[:10]}"


SETUP = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from tactile_exp.tracking import Tracker, canonical_column
    uri, names, folder, me = sys.argv[1], sys.argv[2].split(","), Path(sys.argv[3]), sys.argv[4]

    def barrier(phase):  # every process at this line before any goes on
        (folder / f"{phase}.{me}").touch()
        while not (folder / phase).exists():
            time.sleep(0.002)

    barrier("create")
    trackers = [Tracker(uri, name) for name in names]  # what every job does first
    barrier("view")
    for tracker in trackers:  # and last: its runs-table view (one per set of columns)
        for key in ("mean_auc", "mean_val_auc", "mean_train_auc"):
            column = canonical_column("metrics", key)
            tracker.runs_view([column], order_by=column)
    """
)


def _release(folder: Path, phase: str, n: int) -> None:
    deadline = time.monotonic() + 120
    while len(list(folder.glob(f"{phase}.*"))) < n and time.monotonic() < deadline:
        time.sleep(0.02)
    (folder / phase).touch()


def test_jobs_set_up_one_experiment_at_once(server, tmp_path):
    """N jobs start together against the PostgreSQL-backed server: all create or find the same
    experiments and write the same runs-table view tag; none fails (PostgreSQL does not
    serialise writers as sqlite does: two inserts of one tag raise a UniqueViolation)."""
    names = [_experiment() for _ in range(4)]
    jobs = [
        subprocess.Popen(
            [sys.executable, "-c", SETUP, server, ",".join(names), str(tmp_path), str(i)],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for i in range(N_JOBS)
    ]
    _release(tmp_path, "create", N_JOBS)
    _release(tmp_path, "view", N_JOBS)
    outputs = [job.communicate(timeout=180)[0] for job in jobs]
    failed = [out for job, out in zip(jobs, outputs, strict=True) if job.returncode != 0]
    assert not failed, f"{len(failed)} of {N_JOBS} jobs failed; the first:\n{failed[0][-3000:]}"
    client = MlflowClient(server)
    for name in names:
        (experiment,) = [e for e in client.search_experiments() if e.name == name]
        views = [k for k in experiment.tags if k.startswith("mlflow.sharedViewState.")]
        assert len(views) == 3


def _tactile(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """``python -m tactile_exp...`` from the repository root, its output kept for the message."""
    return subprocess.run(
        [sys.executable, "-m", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def _runs(uri: str, experiment: str) -> list:
    client = MlflowClient(uri)
    found = client.get_experiment_by_name(experiment)
    return [] if found is None else client.search_runs([found.experiment_id], max_results=1000)


def _most_at_once(runs: list) -> int:
    """The most runs RUNNING at one moment, from their start and end times."""
    events = sorted([(r.info.start_time, 1) for r in runs] + [(r.info.end_time, -1) for r in runs])
    most = now = 0
    for _, step in events:
        now += step
        most = max(most, now)
    return most


# Smoke-sized data (tests/test_every_experiment.py's) and the tiny schedule.
SMOKE = [
    "data.trials=2",
    "data.views=2",
    "data.duration_scale=0.1",
    "data.image_width=96",
    "data.image_height=64",
    "schedule=tiny",
    "adjectives=[hard,thick]",
]
ROWS = "table1_h_haptic_cnn_separate,table1_i_haptic_cnn_1trial,table1_m_multimodal_i_l"


def test_rows_sharing_convnets_on_slurm_log_to_the_server(server, cache_dir, tmp_path):
    """Rows H, I and M through Hydra's submitit SLURM launcher, two jobs at a time, logging to
    the server: every run FINISHED, each ConvNet trained once (I and M load H's through the
    server's artifact proxy), then the report, predict and deploy work against the server."""
    experiment = _experiment()
    sweep = _tactile(
        "tactile_exp",
        "-m",
        "hydra/launcher=submitit_slurm",
        "hydra.launcher.partition=debug",
        "hydra.launcher.cpus_per_task=1",
        f"hydra.sweep.dir={tmp_path / 'multirun'}",
        f"experiment={ROWS}",
        "tracking=server",
        f"tracking.uri={server}",
        f"tracking.experiment={experiment}",
        f"cache_dir={cache_dir}",
        *SMOKE,
        timeout=600,
    )
    logs = "\n".join(p.read_text() for p in (tmp_path / "multirun").rglob("*.err"))
    assert sweep.returncode == 0, sweep.stderr[-3000:] + logs[-3000:]
    assert "3 FINISHED, 0 skipped (invalid), 0 FAILED" in sweep.stdout + sweep.stderr

    runs = _runs(server, experiment)
    parents = [r for r in runs if r.data.tags.get("run_level") == "parent"]
    assert len(parents) == 3 and {r.info.status for r in runs} == {"FINISHED"}
    assert _most_at_once(parents) >= 2  # SLURM ran two jobs side by side
    assert all(r.info.artifact_uri.startswith("mlflow-artifacts:/") for r in runs)
    keyed: dict[str, list] = {}
    for r in runs:
        if "training_key" in r.data.tags:
            keyed.setdefault(r.data.tags["training_key"], []).append(r)
    convnets = [key for key, found in keyed.items() if len(found) > 1]
    assert len(convnets) == 2  # one ConvNet per adjective, used by all three rows
    for key, found in keyed.items():
        trained = [r for r in found if "reused_from" not in r.data.tags]
        assert len(trained) == 1, key
        assert {r.data.tags.get("reused_from") for r in found} - {None} <= {trained[0].info.run_id}

    where = ["--tracking-uri", server, "--experiment", experiment]
    report = _tactile("tactile_exp.report", *where, "--out", str(tmp_path / "report"))
    assert report.returncode == 0, report.stderr[-3000:]
    assert "(I)" in (tmp_path / "report" / "index.md").read_text()
    row_i = next(r for r in parents if r.data.params.get("paper.row") == "I")
    predicted = _tactile(
        "tactile_exp.predict", row_i.info.run_id, *where, "--object", "101", "--format", "csv"
    )
    assert predicted.returncode == 0, predicted.stderr[-3000:]
    assert predicted.stdout.count("\n") >= 2 and "hard" in predicted.stdout
    model = f"{experiment}-model"
    deployed = _tactile("tactile_exp.deploy", *where, "log", row_i.info.run_id, "--register", model)
    assert deployed.returncode == 0, deployed.stderr[-3000:]
    (version,) = MlflowClient(server).search_model_versions(f"name = '{model}'")
    assert version.source.startswith(("mlflow-artifacts:/", "models:/"))
