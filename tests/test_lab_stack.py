# Cross-cutting, so not tests/test_<module>.py: the lab's stack that ci/lab_stack.sh starts
# (SLURM, PostgreSQL, an MLflow server with proxied artifacts) under real jobs, races and faults.
"""The lab's stack: jobs on SLURM logging to a PostgreSQL-backed MLflow server.

These tests need ``ci/lab_stack.sh start`` (root). Without the stack they skip with one line;
with ``TACTILE_EXP_LAB_STACK`` set (CI sets it to the server's URI) a missing stack fails them.
"""

from __future__ import annotations

import os
import re
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
    experiments and write the same runs-table view tags; none fails (PostgreSQL does not
    serialise writers as sqlite does: two inserts of one tag raise a UniqueViolation)."""
    names = [_experiment() for _ in range(4)]
    outputs = _at_once(SETUP, ["create", "view"], [server, ",".join(names)], tmp_path)
    assert not [out for out in outputs if "not stored" in out]  # each wrote (or read) its views
    client = MlflowClient(server)
    for name in names:
        (experiment,) = [e for e in client.search_experiments() if e.name == name]
        views = [k for k in experiment.tags if k.startswith("mlflow.sharedViewState.")]
        assert len(views) == 3


REGISTER = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    import mlflow
    uri, name, model, folder, me = *sys.argv[1:4], Path(sys.argv[4]), sys.argv[5]
    mlflow.set_tracking_uri(uri)
    (folder / f"register.{me}").touch()
    while not (folder / "register").exists():
        time.sleep(0.002)
    print(mlflow.register_model(model, name).version)
    """
)


def _at_once(script: str, phases: list[str], args: list[str], folder: Path) -> list[str]:
    """``script`` in N_JOBS processes (arguments: ``args``, the folder of its barriers, its
    number), released together at each barrier in ``phases``; their outputs."""
    jobs = [
        subprocess.Popen(
            [sys.executable, "-c", script, *args, str(folder), str(i)],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for i in range(N_JOBS)
    ]
    for phase in phases:
        _release(folder, phase, N_JOBS)
    outputs = [job.communicate(timeout=180)[0] for job in jobs]
    failed = [out for job, out in zip(jobs, outputs, strict=True) if job.returncode != 0]
    assert not failed, f"{len(failed)} of {N_JOBS} failed; the first:\n{failed[0][-3000:]}"
    return outputs


STUDY = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    import optuna
    from tactile_exp.search import open_study
    storage, name, folder, me = sys.argv[1], sys.argv[2], Path(sys.argv[3]), sys.argv[4]
    (folder / f"study.{me}").touch()
    while not (folder / "study").exists():
        time.sleep(0.002)
    study = open_study(name, storage, direction="maximize", sampler=optuna.samplers.RandomSampler())
    trial = study.ask()
    study.tell(trial, 0.5)
    """
)
STUDY_STORAGE = "postgresql+psycopg://mlflow:mlflow@127.0.0.1:55432/optuna"  # ci/lab_stack.sh's


def test_searches_open_one_study_at_once(server, tmp_path):
    """N sweeps of one search start together on the stack's study database: each makes or
    finds the one study (and, on a fresh database, Optuna's tables) and adds its trial."""
    pytest.importorskip("optuna", reason="no optuna: pip install -e '.[search]'")
    import optuna

    name = _experiment()
    _at_once(STUDY, ["study"], [STUDY_STORAGE, name], tmp_path)
    study = optuna.load_study(study_name=name, storage=STUDY_STORAGE)
    assert len(study.trials) == N_JOBS


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
    # N jobs register the same logged model under one name at once: each gets its own version.
    logged = re.search(r"logged (models:/\S+)", deployed.stdout).group(1)
    outputs = _at_once(REGISTER, ["register"], [server, model, logged], tmp_path)
    versions = sorted(int(out.strip().splitlines()[-1]) for out in outputs)
    assert versions == list(range(2, N_JOBS + 2))


def _job(server: str, experiment: str, cache_dir: Path, run_dir: Path) -> list[str]:
    """One job of two adjectives, the second of which trains for seconds after its first epoch
    line (tests/test_kill_resume.py's): time to stop the server or cancel the job mid-training."""
    return [
        sys.executable,
        "-m",
        "tactile_exp",
        *SMOKE[:5],
        "schedule=tiny",
        "schedule.epochs=50",
        "adjectives=[hard,soft]",
        "seed=41",
        "tracking=server",
        f"tracking.uri={server}",
        f"tracking.experiment={experiment}",
        f"cache_dir={cache_dir}",
        f"hydra.run.dir={run_dir}",
    ]


def _wait_for_line(log: Path, text: str, *, alive=lambda: True, timeout: float = 300) -> None:
    deadline = time.monotonic() + timeout
    while not (log.is_file() and text in log.read_text()):
        assert alive() and time.monotonic() < deadline, f"no {text!r} in {log}"
        time.sleep(0.2)


def _stack(command: str, part: str) -> None:
    subprocess.run([str(STACK), command, part], check=True, capture_output=True, timeout=300)


def _by_adjective(runs: list) -> dict[str, list]:
    out: dict[str, list] = {}
    for r in sorted(runs, key=lambda r: r.info.start_time):
        if r.data.tags.get("run_level") == "child":
            out.setdefault(r.data.tags["adjective"], []).append(r)
    return out


def test_a_job_waits_out_a_server_restart(server, cache_dir, tmp_path):
    """The tracking server restarts while a job trains: the job's next writes are retried with
    backoff until it is back, and the job finishes with every run FINISHED."""
    experiment, log = _experiment(), tmp_path / "run" / "__main__.log"
    job = subprocess.Popen(
        _job(server, experiment, cache_dir, tmp_path / "run"),
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        _wait_for_line(log, "soft epoch 1/", alive=lambda: job.poll() is None)
        _stack("stop", "mlflow")
        time.sleep(2)
        _stack("start", "mlflow")
        output = job.communicate(timeout=400)[0]
    finally:
        job.kill()
    assert job.returncode == 0, output[-3000:]
    runs = _runs(server, experiment)
    assert len(runs) == 3 and {r.info.status for r in runs} == {"FINISHED"}


def test_a_server_down_too_long_ends_the_job_then_a_rerun_finishes_it(server, cache_dir, tmp_path):
    """The server stays down past the client's retries (cut short here): the job ends with one
    ``error:`` line; once the server is back a rerun marks the job's runs KILLED, reuses the
    adjective that finished and finishes the job."""
    experiment, log = _experiment(), tmp_path / "run" / "__main__.log"
    command = _job(server, experiment, cache_dir, tmp_path / "run")
    short = {**os.environ, "MLFLOW_HTTP_REQUEST_MAX_RETRIES": "1"}
    short["MLFLOW_HTTP_REQUEST_BACKOFF_FACTOR"] = "1"
    job = subprocess.Popen(
        command, cwd=ROOT, env=short, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        _wait_for_line(log, "soft epoch 1/", alive=lambda: job.poll() is None)
        _stack("stop", "mlflow")
        _, stderr = job.communicate(timeout=300)
    finally:
        job.kill()
        _stack("start", "mlflow")
    assert job.returncode == 2, stderr[-3000:]
    errors = [line for line in stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "stopped answering" in errors[0], stderr[-3000:]

    rerun = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=400)
    assert rerun.returncode == 0, rerun.stderr[-3000:]
    runs = _runs(server, experiment)
    assert "RUNNING" not in {r.info.status for r in runs}
    hard, soft = _by_adjective(runs)["hard"], _by_adjective(runs)["soft"]
    assert [r.info.status for r in hard] == ["FINISHED", "FINISHED"]
    assert hard[1].data.tags["reused_from"] == hard[0].info.run_id
    assert [r.info.status for r in soft] == ["KILLED", "FINISHED"]


def test_a_cancelled_slurm_job_leaves_no_running_run_and_its_rerun_reuses(
    server, cache_dir, tmp_path
):
    """``scancel`` while the second adjective trains: SLURM's SIGTERM ends the job's runs
    FAILED (before its SIGKILL); the rerun reuses the first adjective's model."""
    experiment, log = _experiment(), tmp_path / "run" / "__main__.log"
    command = _job(server, experiment, cache_dir, tmp_path / "run")
    submitted = subprocess.run(
        ["sbatch", "--parsable", "-p", "debug", "-c", "1", "-o", str(tmp_path / "slurm.out")]
        + ["--chdir", str(ROOT), "--wrap", "exec " + " ".join(command)],
        capture_output=True,
        text=True,
        check=True,
    )
    job_id = submitted.stdout.strip().split(";")[0]

    def queued() -> bool:
        out = subprocess.run(["squeue", "-h", "-j", job_id], capture_output=True, text=True)
        return bool(out.stdout.strip())

    try:
        _wait_for_line(log, "soft epoch 1/", alive=queued)
    finally:
        subprocess.run(["scancel", job_id], check=True)
    deadline = time.monotonic() + 60
    while queued():
        assert time.monotonic() < deadline, f"job {job_id} still queued after scancel"
        time.sleep(0.5)
    runs = _runs(server, experiment)
    assert "RUNNING" not in {r.info.status for r in runs}
    (hard,), (soft,) = _by_adjective(runs)["hard"], _by_adjective(runs)["soft"]
    assert hard.info.status == "FINISHED" and soft.info.status in ("FAILED", "KILLED")

    rerun = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=400)
    assert rerun.returncode == 0, rerun.stderr[-3000:]
    runs = _runs(server, experiment)
    assert "RUNNING" not in {r.info.status for r in runs}
    assert _by_adjective(runs)["hard"][1].data.tags["reused_from"] == hard.info.run_id
