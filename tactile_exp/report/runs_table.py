"""One job's runs as ``mlflow ui``'s runs table lists them (parent, then its children), in
Markdown: the README's picture of what a researcher sees, generated from the MLflow records."""

from __future__ import annotations

from datetime import UTC, datetime

from tactile_exp.metrics import METRICS
from tactile_exp.tracking import Tracker

COLUMNS = ("Run Name", "Created (UTC)", "Duration", "Source", "Dataset")  # then the metric's


def _cells(run, key: str) -> list[str]:
    info, data = run.info, run.data
    created = datetime.fromtimestamp(info.start_time / 1000, UTC)
    seconds = ((info.end_time or info.start_time) - info.start_time) / 1000
    datasets = [f"{d.dataset.name} ({d.dataset.digest})" for d in run.inputs.dataset_inputs]
    metrics, commit = data.metrics, data.tags.get("mlflow.source.git.commit", "")
    return [
        info.run_name,
        f"{created:%Y-%m-%d %H:%M:%S}",
        f"{seconds:.1f} s" if seconds < 120 else f"{seconds / 60:.1f} min",
        data.tags.get("mlflow.source.name", "") + (f" @ {commit[:7]}" if commit else ""),
        ", ".join(datasets),
        f"{metrics[f'mean_{key}']:.3f}" if f"mean_{key}" in metrics else "",
        f"{metrics[key]:.3f}" if key in metrics else "",
    ]


def runs_table(*, tracker: Tracker, job_id: str, metric: str = "roc_auc") -> str:
    """The job (parent) run and its child runs, oldest first, with the columns ``COLUMNS`` and
    ``mean_<key>``, ``<key>`` of ``metric`` (``mean_auc``, ``auc`` by default)."""
    key = METRICS.build(metric).key
    columns = (*COLUMNS, f"mean_{key}", key)
    parent = tracker.get_run(job_id)
    found = tracker.child_runs(job_id, level=None)
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines.append("| " + " | ".join(_cells(parent, key)) + " |")
    for run in found:
        cells = _cells(run, key)
        cells[0] = f"└ {cells[0]}"
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
