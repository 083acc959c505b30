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
    assert "model: haptic_cnn, haptic_lstm" in text
    assert "python -m tactile_exp -m sweep=table1" in text
    assert "sweep=table1 hydra/launcher=joblib hydra.launcher.n_jobs=2" in text  # docs/scale.md


def test_cfg_job_prints_the_resolved_choices():
    cfg = yaml.safe_load(_run("model=haptic_lstm", "combine=10", "--cfg", "job"))
    assert cfg["model"]["name"] == "haptic_lstm" and cfg["combine"] == 10


def test_info_defaults_tree():
    assert "experiment: null" in _run("--info", "defaults-tree")
