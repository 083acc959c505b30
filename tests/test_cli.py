# The tests of tactile_exp/__main__.py (one test file per module), named for what a
# user calls it: the command line, run as a subprocess the way a user runs it.
"""The command line works the way Hydra users expect."""

import subprocess
import sys

import yaml


def _run(*args: str) -> str:
    out = subprocess.run(
        [sys.executable, "-m", "tactile_exp", *args],
        check=True,
        capture_output=True,
        text=True,
        timeout=120,
    )
    return out.stdout


def test_help_lists_groups_and_examples():
    text = _run("--help")
    assert "model: estimator, haptic_cnn, haptic_lstm" in text
    assert "python -m tactile_exp -m sweep=table1" in text
    assert "sweep=table1 hydra/launcher=joblib hydra.launcher.n_jobs=2" in text  # docs/scale.md


def test_cfg_job_prints_the_resolved_choices():
    cfg = yaml.safe_load(_run("model=haptic_lstm", "combine=10", "--cfg", "job"))
    assert cfg["model"]["name"] == "haptic_lstm" and cfg["combine"] == 10


def test_cfg_with_multirun_is_one_error_line_not_hydra_s_traceback():
    done = subprocess.run(
        [sys.executable, "-m", "tactile_exp", "-m", "sweep=table1", "--cfg", "job"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.splitlines() == [
        "error: --cfg prints one job's config and Hydra refuses it with -m; to compose and "
        "check every job of a sweep without running any, add sweep.on_invalid=check"
    ]


def test_info_defaults_tree():
    assert "experiment: null" in _run("--info", "defaults-tree")


def test_config_error_is_one_line_and_exit_2_before_any_run(tmp_path, mlflow_uri):
    """The CLI: no traceback, exit 2, and no MLflow run for a typo found only in the data."""
    import os

    from mlflow.tracking import MlflowClient

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
    client = MlflowClient(mlflow_uri)
    assert client.search_runs([e.experiment_id for e in client.search_experiments()]) == []
