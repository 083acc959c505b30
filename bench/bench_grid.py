"""Per-row wall time of a Table I grid run, read from its MLflow runs (not typed).

Each job's parent run holds its start and end; the row is the job's experiment file
(``choice.experiment``, e.g. ``table1_h_haptic_cnn_separate`` is row H). Prints one line per row
(jobs, status, start after the grid's first start, minutes), then the grid's wall time (first
start to last end: what jobs side by side shorten) and the sum of the jobs' times. A row with
several jobs (seeds, splits) shows their summed time. The grid is one sweep (the ``sweep_id``
tag: ``multirun/<date>/<time>``), by default the one whose job started last.

With ``--against URI`` it also compares the grid's results with another grid's (the code before
a change, in the store at ``URI``; the same store with ``--against-sweep ID``): per Table I row
both ran, each grid's mean AUC as the report pools it and the report's paired difference (after
minus before, 95% paired-bootstrap interval, ``stats.compare``) on the same test objects, and how
many adjectives' AUCs differ; a row the two grids tested on other objects says why it is not
compared. A change that keeps every sum's order changes no AUC; one that sums in another order
moves the last bits, which training amplifies: its differences should not be told from zero.

Run after a grid, e.g. ``python -m tactile_exp -m sweep=table1``:
``.venv/bin/python bench/bench_grid.py [--experiment tactile_exp] [--sweep-id ID] [--json OUT]
[--note TEXT] [--against URI [--against-sweep ID]]`` (``--json``: the figures with the machine
and the date, ``bench/record.py``; ``--note``: how the grid ran, which the runs do not record,
e.g. its launcher).
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tactile_exp import stats
from tactile_exp.report import heldout
from tactile_exp.report import runs as report_runs
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


@dataclass
class RowChange:
    """One Table I row in two grids: each one's mean AUC and the paired difference, after minus
    before, or ``why`` there is none."""

    row: str
    before: float
    after: float
    difference: stats.Interval | None
    changed: int = 0  # adjectives whose AUC differs
    adjectives: int = 0
    why: str = ""


def _row_groups(tracker: Tracker, sweep_id: str) -> dict[str, report_runs.Group]:
    """Table I row -> the sweep's group that stands for it (``report.runs.row_group``)."""
    groups = report_runs.collect(tracker, sweep_id)
    return {g.row: report_runs.row_group(groups, g.row) for g in groups if g.row}


def auc_changes(
    after: Tracker, after_sweep: str, before: Tracker, before_sweep: str
) -> list[RowChange]:
    """Each Table I row both sweeps ran at the same settings, in row order: its mean AUC in each
    (the report's, seeds and folds pooled) and the report's paired comparison of the two."""
    new, old = _row_groups(after, after_sweep), _row_groups(before, before_sweep)
    out = []
    nan = float("nan")
    for row in sorted(set(new) & set(old)):
        if new[row].differences != old[row].differences:  # e.g. a quick schedule in one grid
            settings = [", ".join(g.differences) or "the paper's" for g in (old[row], new[row])]
            why = f"not compared: other settings (before {settings[0]}; after {settings[1]})"
            out.append(RowChange(row, nan, nan, None, why=why))
            continue
        a, b = heldout.load(after, new[row]), heldout.load(before, old[row])
        if not (a.ok and b.ok):
            missing = [f"{n}: {e.missing}" for n, e in (("after", a), ("before", b)) if e.missing]
            out.append(RowChange(row, nan, nan, None, why="; ".join(missing)))
            continue
        before_auc, after_auc = b.interval().estimate, a.interval().estimate
        reason = stats.unpaired_reason(a.evaluations, b.evaluations)
        if reason is not None:
            out.append(RowChange(row, before_auc, after_auc, None, why=f"not paired: {reason}"))
            continue
        c = stats.compare("after", a.evaluations, "before", b.evaluations)
        changed = len(c.a_better) + len(c.b_better)
        out.append(RowChange(row, before_auc, after_auc, c.difference, changed, c.n_adjectives))
    return out


def _print_changes(changes: list[RowChange], figures: dict[str, float]) -> None:
    header = f"{'row':4s} {'before':>7s} {'after':>7s}  after - before [95% paired]"
    print(f"{header}  adjectives changed")
    for c in changes:
        if c.difference is None:
            print(f"{c.row:4s} {c.before:7.4f} {c.after:7.4f}  {c.why}")
            continue
        d = c.difference
        print(
            f"{c.row:4s} {c.before:7.4f} {c.after:7.4f}  {d.estimate:+.4f} [{d.low:+.4f}, "
            f"{d.high:+.4f}]  {c.changed}/{c.adjectives}"
        )
        figures[f"row {c.row}, mean AUC before"] = round(c.before, 4)
        figures[f"row {c.row}, mean AUC after"] = round(c.after, 4)
        figures[f"row {c.row}, AUC after - before"] = round(d.estimate, 4)
        figures[f"row {c.row}, AUC after - before, 95% low"] = round(d.low, 4)
        figures[f"row {c.row}, AUC after - before, 95% high"] = round(d.high, 4)
        figures[f"row {c.row}, adjectives changed"] = c.changed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracking-uri", default=None, help="default: as the jobs' tracking.uri")
    parser.add_argument("--experiment", default="tactile_exp", help="the MLflow experiment")
    parser.add_argument("--sweep-id", default=None, help="default: the newest job's sweep")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    parser.add_argument(
        "--note", default="", help="how the grid ran (launcher, caches), kept with the figures"
    )
    parser.add_argument("--against", default=None, help="compare AUCs with the grid in this store")
    parser.add_argument(
        "--against-sweep", default=None, help="that grid's sweep id (default: its newest job's)"
    )
    args = parser.parse_args()
    try:
        tracker = Tracker.open(args.tracking_uri, args.experiment)
        before = Tracker.open(args.against, args.experiment) if args.against else None
    except ExperimentNotFound as err:
        raise SystemExit(f"error: {err}") from None
    sweep_id, runs = parent_runs(tracker, args.sweep_id)
    if before is not None:
        before_sweep = parent_runs(before, args.against_sweep)[0]
        if before.uri == tracker.uri and before_sweep == sweep_id:
            raise SystemExit(
                f"error: --against names the grid measured ({sweep_id}); give --against-sweep"
            )
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
    if before is not None:
        print(f"mean AUC against sweep {before_sweep} in {before.uri}, paired on the test objects:")
        _print_changes(auc_changes(tracker, sweep_id, before, before_sweep), figures)
    if args.json:
        from record import write

        notes = f"sweep {sweep_id or '(none)'}, {len(runs)} jobs" + (
            f"; {args.note}" if args.note else ""
        )
        if before is not None:
            notes += f"; AUCs against sweep {before_sweep} in {before.uri}"
        write(args.json, "bench_grid", figures, notes)


if __name__ == "__main__":
    main()
