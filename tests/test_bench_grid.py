"""The grid's per-row wall times (bench/bench_grid.py), read from a store of known runs."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

from tactile_exp.tracking import Tracker

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("bench_grid", ROOT / "bench" / "bench_grid.py")
bench_grid = importlib.util.module_from_spec(_spec)
sys.modules["bench_grid"] = bench_grid  # a dataclass looks its module up there
_spec.loader.exec_module(bench_grid)

T0 = 1_700_000_000_000  # ms
MIN = 60_000


def _job(tracker: Tracker, experiment: str, start: int, end: int | None, sweep: str) -> None:
    run = tracker.client.create_run(
        tracker.experiment_id,
        start_time=T0 + start * MIN,
        tags={"run_level": "parent", "sweep_id": sweep},
    )
    tracker.client.log_param(run.info.run_id, "choice.experiment", experiment)
    if end is not None:
        tracker.client.set_terminated(run.info.run_id, "FINISHED", end_time=T0 + end * MIN)


@pytest.fixture
def grid(mlflow_uri: str) -> Tracker:
    """An older sweep, then a two-at-a-time grid: G 0-17 beside H 0-12, then I 12-14 beside
    A 17-18, and a second seed of A 14-15 (minutes after the first start)."""
    tracker = Tracker(mlflow_uri, "tactile_exp")
    _job(tracker, "table1_g_haptic_lstm", -100, -50, "multirun/old")
    for experiment, start, end in [
        ("table1_g_haptic_lstm", 0, 17),
        ("table1_h_haptic_cnn_separate", 0, 12),
        ("table1_i_haptic_cnn_1trial", 12, 14),
        ("table1_a_haptic_static_1trial", 14, 15),
        ("table1_a_haptic_static_1trial", 17, 18),
    ]:
        _job(tracker, experiment, start, end, "multirun/new")
    return tracker


def test_rows_wall_and_sum_of_the_newest_sweep(grid):
    sweep, runs = bench_grid.parent_runs(grid, None)
    assert sweep == "multirun/new" and len(runs) == 5
    table, wall, total = bench_grid.rows(runs)
    assert [(r.row, r.jobs, r.start, r.seconds) for r in table] == [
        ("A", 2, 14 * 60, 2 * 60),
        ("G", 1, 0, 17 * 60),
        ("H", 1, 0, 12 * 60),
        ("I", 1, 12 * 60, 2 * 60),
    ]
    assert wall == 18 * 60 and total == 33 * 60
    _, old = bench_grid.parent_runs(grid, "multirun/old")
    assert bench_grid.rows(old)[1:] == (50 * 60, 50 * 60)


def test_row_names():
    assert bench_grid.row_of("table1_h_haptic_cnn_separate") == "H"
    assert bench_grid.row_of("quick_table1_i") == "quick_table1_i"


def test_script_prints_the_table_and_writes_json(grid, mlflow_uri, tmp_path, monkeypatch, capsys):
    monkeypatch.syspath_prepend(str(ROOT / "bench"))  # as when run as a script: record.py
    out = tmp_path / "grid.json"
    args = ["bench_grid.py", "--tracking-uri", mlflow_uri]
    monkeypatch.setattr(sys, "argv", [*args, "--json", str(out), "--note", "joblib, 2 jobs"])
    bench_grid.main()
    text = capsys.readouterr().out
    assert "G    table1_g_haptic_lstm" in text and "grid: 18.0 min wall" in text
    result = json.loads(out.read_text())
    figures = result["figures"]
    assert figures["row G, min"] == 17.0 and figures["grid wall, min"] == 18.0
    assert figures["sum of job times, min"] == 33.0
    assert result["notes"].endswith(" jobs; joblib, 2 jobs")
    monkeypatch.setattr(sys, "argv", [*args, "--sweep-id", "x"])
    with pytest.raises(SystemExit, match="error: no job runs with sweep_id 'x'"):
        bench_grid.main()
