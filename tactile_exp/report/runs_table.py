"""One job's runs as ``mlflow ui``'s runs table lists them (parent, then its children), in
Markdown: the README's picture of what a researcher sees, generated from the MLflow records."""

from __future__ import annotations

from datetime import UTC, datetime

from tactile_exp.tracking import Tracker

COLUMNS = ("Run Name", "Created (UTC)", "Duration", "Source", "Dataset", "mean_auc", "auc")


def _cells(run) -> list[str]:
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
        f"{metrics['mean_auc']:.3f}" if "mean_auc" in metrics else "",
        f"{metrics['auc']:.3f}" if "auc" in metrics else "",
    ]


def runs_table(*, tracker: Tracker, job_id: str) -> str:
    """The job (parent) run and its child runs, oldest first, with the columns ``COLUMNS``."""
    parent = tracker.client.get_run(job_id)
    found = tracker.child_runs(job_id, level=None)
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines.append("| " + " | ".join(_cells(parent)) + " |")
    for run in found:
        cells = _cells(run)
        cells[0] = f"└ {cells[0]}"
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
