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
