"""The grid's per-row wall times (bench/bench_grid.py), read from a store of known runs."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest
from sklearn.metrics import roc_auc_score

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


ADJ = ("hard", "rough", "smooth", "soft")
OBJECTS = range(12)  # objects 0-4 positive; 2 trials each


def _scored_job(tracker: Tracker, row: str, sweep: str, objects=OBJECTS, shift=None, **params):
    """A parent run of Table I row ``row`` at the paper's settings (unless ``params`` say
    otherwise) and a child per adjective holding its held-out scores.csv: fixed scores per
    (row, object, trial, adjective), ``shift`` (adjective -> added to its positive objects')
    scores) the change between two grids. Returns each adjective's AUC."""
    rng = np.random.default_rng(ord(row))
    table = rng.normal(0, 1, (len(OBJECTS), 2, len(ADJ)))
    p = {"choice.experiment": f"table1_{row.lower()}_x", "paper.row": row, "seed": "0"}
    p |= {"choice.schedule": "paper", "split.name": "published", **params}
    tags = {"run_level": "parent", "row_hash": row, "config_hash": f"{row}{sweep}"}
    tags |= {"sweep_id": sweep, "data.labels": " ".join(ADJ), "overrides": ""}
    aucs = {}
    with tracker.run(f"{p['choice.experiment']}-s0", p, tags) as job:
        for j, adjective in enumerate(ADJ):
            lines, ys, ss = ["unit,object_id,label,score"], [], []
            for o in objects:
                y = int(o < 5)
                for u in range(2):
                    s = table[o, u, j] + y + (shift or {}).get(adjective, 0.0) * y
                    lines.append(f"t{o}_{u},{o},{y},{s}")
                    ys.append(y)
                    ss.append(s)
            aucs[adjective] = roc_auc_score(ys, ss)
            ctags = {"run_level": "child", "adjective": adjective}
            with tracker.run(f"adj={adjective}", {}, ctags, job) as child:
                tracker.log_text(child, "\n".join(lines) + "\n", "scores.csv")
        metrics = {f"auc.{a}": v for a, v in aucs.items()}
        tracker.log_metrics(job, {"mean_auc": float(np.mean(list(aucs.values()))), **metrics})
    return aucs


@pytest.fixture
def two_grids(mlflow_uri: str) -> tuple[Tracker, dict[str, dict[str, float]]]:
    """A grid before a change and after it, in one store: row A scored the same; row I with
    soft's positive objects scored higher; row G tested on other objects after; row K on a
    quick schedule after."""
    tracker = Tracker(mlflow_uri, "auc_test")
    aucs = {}
    for sweep in ("before", "after"):
        later = sweep == "after"
        aucs[f"A {sweep}"] = _scored_job(tracker, "A", sweep)
        aucs[f"I {sweep}"] = _scored_job(
            tracker, "I", sweep, shift={"soft": 0.8} if later else None
        )
        aucs[f"G {sweep}"] = _scored_job(tracker, "G", sweep, range(12 - 2 * later))
        _scored_job(tracker, "K", sweep, **({"choice.schedule": "quick"} if later else {}))
    return tracker, aucs


def test_auc_changes_pair_each_row_on_its_test_objects(two_grids):
    tracker, aucs = two_grids
    changes = {c.row: c for c in bench_grid.auc_changes(tracker, "after", tracker, "before")}
    assert sorted(changes) == ["A", "G", "I", "K"]
    a = changes["A"]
    assert (a.difference.estimate, a.difference.low, a.difference.high) == (0.0, 0.0, 0.0)
    assert (a.changed, a.adjectives) == (0, 4)
    i = changes["I"]
    # the mean AUC as the report pools it is the mean of the adjectives' AUCs (one seed)
    assert i.before == pytest.approx(np.mean(list(aucs["I before"].values())))
    expected = np.mean([aucs["I after"][j] - aucs["I before"][j] for j in ADJ])
    assert expected > 0.01 and i.difference.estimate == pytest.approx(expected)
    assert i.difference.low <= i.difference.high and (i.changed, i.adjectives) == (1, 4)
    assert changes["G"].difference is None and "not paired: different test objects" in (
        changes["G"].why
    )
    assert changes["K"].difference is None
    assert changes["K"].why == (
        "not compared: other settings (before the paper's; after schedule=quick)"
    )


def test_script_compares_with_another_sweep(two_grids, mlflow_uri, monkeypatch, capsys, tmp_path):
    monkeypatch.syspath_prepend(str(ROOT / "bench"))
    args = ["bench_grid.py", "--tracking-uri", mlflow_uri, "--experiment", "auc_test"]
    out = tmp_path / "grid.json"
    monkeypatch.setattr(
        sys, "argv", [*args, "--sweep-id", "after", "--against", mlflow_uri, "--json", str(out)]
    )
    with pytest.raises(SystemExit, match=r"--against names the grid measured \(after\)"):
        bench_grid.main()
    monkeypatch.setattr(sys, "argv", [*sys.argv, "--against-sweep", "before"])
    bench_grid.main()
    text = capsys.readouterr().out
    assert "mean AUC against sweep before in " in text
    assert "A     " in text and "+0.0000 [+0.0000, +0.0000]  0/4" in text
    figures = json.loads(out.read_text())["figures"]
    assert figures["row A, AUC after - before"] == 0.0 and figures["row I, adjectives changed"] == 1
    assert "row G, AUC after - before" not in figures  # not paired: no difference to record
