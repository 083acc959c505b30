"""Per-row wall time of a Table I grid run, read from its MLflow runs (not typed).

Each job's parent run holds its start and end; the row is the job's experiment file
(``choice.experiment``, e.g. ``table1_h_haptic_cnn_separate`` is row H). Prints one line per row
(jobs, status, start after the grid's first start, minutes), then the grid's wall time (first
start to last end: what jobs side by side shorten) and the sum of the jobs' times. A row with
several jobs (seeds, splits) shows their summed time. The grid is one sweep (the ``sweep_id``
tag: ``multirun/<date>/<time>``), by default the one whose job started last.

Run after a grid, e.g. ``python -m tactile_exp -m sweep=table1``:
``.venv/bin/python bench/bench_grid.py [--experiment tactile_exp] [--sweep-id ID] [--json OUT]
[--note TEXT]`` (``--json``: the figures with the machine and the date, ``bench/record.py``;
``--note``: how the grid ran, which the runs do not record, e.g. its launcher).
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tactile_exp.tracking import ExperimentNotFound, Tracker


@dataclass
class Row:
    """One Table I row's jobs in a grid: times in seconds, ``start`` after the grid's start."""

    row: str
    experiment: str
    jobs: int
    statuses: set[str]
    start: float
    seconds: float


def row_of(experiment: str) -> str:
    """``table1_h_haptic_cnn_separate`` -> ``H``; any other experiment name is its own row."""
    parts = experiment.split("_")
    if len(parts) > 2 and parts[0] == "table1" and len(parts[1]) == 1:
        return parts[1].upper()
    return experiment


def parent_runs(tracker: Tracker, sweep_id: str | None) -> tuple[str, list[Any]]:
    """The sweep's id (``sweep_id``, else the newest job's) and its jobs' parent runs."""
    runs = tracker.jobs(finished_only=False)
    if sweep_id is None:
        if not runs:
            raise SystemExit(f"error: experiment {tracker.experiment_id} holds no job runs")
        sweep_id = runs[0].data.tags.get("sweep_id", "")
    chosen = [r for r in runs if r.data.tags.get("sweep_id", "") == sweep_id]
    if not chosen:
        raise SystemExit(f"error: no job runs with sweep_id {sweep_id!r}")
    return sweep_id, chosen


def rows(runs: list[Any]) -> tuple[list[Row], float, float]:
    """Per row (in row order), and the grid's wall seconds and summed job seconds. A job still
    RUNNING counts up to now."""
    now = time.time() * 1000
    grid_start = min(r.info.start_time for r in runs)
    grid_end = max(r.info.end_time or now for r in runs)
    grouped: dict[str, list[Any]] = defaultdict(list)
    for r in runs:
        grouped[r.data.params.get("choice.experiment") or r.info.run_name].append(r)
    out = [
        Row(
            row=row_of(name),
            experiment=name,
            jobs=len(jobs),
            statuses={j.info.status for j in jobs},
            start=(min(j.info.start_time for j in jobs) - grid_start) / 1000,
            seconds=sum((j.info.end_time or now) - j.info.start_time for j in jobs) / 1000,
        )
        for name, jobs in grouped.items()
    ]
    out.sort(key=lambda r: (len(r.row) > 1, r.row))
    return out, (grid_end - grid_start) / 1000, sum(r.seconds for r in out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracking-uri", default=None, help="default: as the jobs' tracking.uri")
    parser.add_argument("--experiment", default="tactile_exp", help="the MLflow experiment")
    parser.add_argument("--sweep-id", default=None, help="default: the newest job's sweep")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    parser.add_argument(
        "--note", default="", help="how the grid ran (launcher, caches), kept with the figures"
    )
    args = parser.parse_args()
    try:
        tracker = Tracker.open(args.tracking_uri, args.experiment)
    except ExperimentNotFound as err:
        raise SystemExit(f"error: {err}") from None
    sweep_id, runs = parent_runs(tracker, args.sweep_id)
    table, wall, total = rows(runs)
    print(f"{len(runs)} jobs of sweep {sweep_id or '(none)'} in {tracker.uri}, {args.experiment}")
    print(
        f"{'row':4s} {'experiment':46s} {'jobs':>4s} {'status':10s} {'start':>8s} {'minutes':>8s}"
    )
    figures: dict[str, float] = {}
    for r in table:
        status = "/".join(sorted(r.statuses))
        print(
            f"{r.row:4s} {r.experiment:46s} {r.jobs:4d} {status:10s} "
            f"{r.start / 60:+8.1f} {r.seconds / 60:8.2f}"
        )
        figures[f"row {r.row}, min"] = round(r.seconds / 60, 2)
    print(
        f"grid: {wall / 60:.1f} min wall (first start to last end), jobs' sum {total / 60:.1f} "
        f"min ({total / wall:.2f} jobs at a time on average)"
    )
    figures["grid wall, min"] = round(wall / 60, 2)
    figures["sum of job times, min"] = round(total / 60, 2)
    if args.json:
        from record import write

        notes = f"sweep {sweep_id or '(none)'}, {len(runs)} jobs" + (
            f"; {args.note}" if args.note else ""
        )
        write(args.json, "bench_grid", figures, notes)


if __name__ == "__main__":
    main()
