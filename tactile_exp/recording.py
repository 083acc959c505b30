"""Results into MLflow: the one engine module that writes runs (the job's parent run, each
adjective's child run with its scores, curves and fitted pipeline, the job's summary).

``record_adjective`` wraps ``core.fit_adjective`` in a child run whose model cache is the MLflow
store (``store.MlflowCache``); everything it computes comes back in the ``AdjectiveResult``.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tactile_exp import core, evaluate, metrics, scores_file, stats, store
from tactile_exp.config import Settings
from tactile_exp.data.layout import Split
from tactile_exp.models.base import EpochCallback
from tactile_exp.runtime import termination
from tactile_exp.tracking import MAX_PARAM_LENGTH, Tracker, canonical_column, flatten
from tactile_exp.train import device_name

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Records:
    """What a job records and shows of its test objects: everything, or for a search trial
    nothing (no test metric, no ``scores.csv``, the side means only, its runs sorted by the
    validation AUC), so what a search selects on stays blind to them."""

    test: bool
    sort: str  # the job metric its runs view sorts by
    what: str  # that metric, in words

    @classmethod
    def of(cls, settings: Settings) -> Records:
        if settings.is_trial:
            return cls(test=False, sort="mean_val_auc", what="validation AUC")
        return cls(test=True, sort="mean_auc", what="AUC")


def open_tracker(settings: Settings) -> Tracker:
    """The job's experiment in its tracking store (created when absent)."""
    return Tracker(settings.tracking.uri, settings.tracking.experiment)


def key_params(settings: Settings) -> dict[str, str]:
    """The params that say which job a run belongs to: the config-group choices (``choice.*``,
    none left at None) and every axis the job sets (``axis.*``: a sweep's swept values, plain
    ones like ``combine`` too), which sort first among the params that differ, so the compare
    view's parallel-coordinates plot, which starts on the first three of those, shows them."""
    out = {f"choice.{k}": v for k, v in settings.choices.items() if v != "None"}
    out.update({f"axis.{k}": v[:MAX_PARAM_LENGTH] for k, v in settings.axes.items()})
    return out


def log_data(tracker: Tracker, run_id: str, dataset: Any) -> None:
    """The data set as the run's MLflow dataset input (name, digest, file source)."""
    tracker.log_dataset(
        run_id,
        name=dataset.path.stem,
        digest=dataset.digest(),
        source=dataset.path.resolve().as_uri(),
    )


def epoch_logger(name: str) -> EpochCallback:
    """A compact line at ~5 points per run instead of one per epoch; and a SIGTERM check."""

    def on_epoch(epoch: int, n_epochs: int, metrics: dict[str, float]) -> None:
        termination.check()
        if epoch == 1 or epoch % max(1, n_epochs // 5) == 0 or epoch == n_epochs:
            shown = " ".join(f"{k}={v:.4f}" for k, v in metrics.items())
            log.info("  %s epoch %d/%d %s", name, epoch, n_epochs, shown)

    return on_epoch


def finished_job(tracker: Tracker, settings: Settings, data_identity: str) -> str | None:
    """The FINISHED job with this config on this data file, if there is one."""
    return tracker.finished_run(settings.config_hash, data_identity=data_identity)


def val_metrics(
    tracker: Tracker, parent_id: str, names: tuple[str, ...]
) -> dict[str, dict[str, float]]:
    """A finished job's per-adjective validation metrics (``names``), from its adjectives' runs."""
    out: dict[str, dict[str, float]] = {}
    for key in (metrics.METRICS.build(n).key for n in names):
        for adjective, v in tracker.child_metrics(parent_id, f"val_{key}").items():
            out.setdefault(adjective, {})[key] = v
    return out


@contextmanager
def job_run(tracker: Tracker, settings: Settings) -> Iterator[str]:
    """The job's parent run: ended FINISHED, or FAILED with the error, whatever happens inside."""
    params = {**flatten(settings.resolved), **key_params(settings)}
    tags = {
        "config_hash": settings.config_hash,
        "row_hash": settings.row_hash,
        "run_level": "parent",
        "sweep_id": settings.sweep_id,
        "overrides": " ".join(settings.overrides)[:5000],  # what the report calls a variant
        "device": device_name(settings.device),  # what device=auto picked here
        **settings.study_tags,  # search.study, search.role, search.trial
    }
    with tracker.run(settings.run_name, params, tags) as parent_id:
        log.info(
            "MLflow run %s (%s) in %s, on %s",
            settings.run_name,
            parent_id,
            tracker.uri,
            tags["device"],
        )
        _log_config(tracker, parent_id, settings)
        yield parent_id


def record_data(tracker: Tracker, parent_id: str, dataset: Any, notes: Mapping[str, str]) -> None:
    """The checked data set on the job's run: its identity, labels, ``notes`` on them, its file."""
    tracker.set_tags(
        parent_id,
        {
            "data.identity": dataset.identity(),
            "data.labels": " ".join(dataset.label_names),
            "data.layout": dataset.sensor.layout or "none",  # the report's paper preset reads it
            **notes,
        },
    )
    log_data(tracker, parent_id, dataset)


def record_adjective(
    settings: Settings, tracker: Tracker, parent_id: str, dataset: Any, split: Split
) -> core.AdjectiveResult:
    """Fit, score and log one adjective in a child run of ``parent_id``."""
    termination.check()
    adjective = split.adjective
    stores_model = core.stores_model(settings)
    key = core.model_key(settings, dataset, adjective)
    tags = {
        "config_hash": settings.config_hash,
        "run_level": "child",
        "adjective": adjective,
        "job": settings.run_name,  # a child found alone says which job it is part of
        "sweep_id": settings.sweep_id,
        **({"training_key": key} if stores_model else {}),  # the run is the key's claim
    }
    params = {"adjective": adjective, "combine": str(settings.combine), "seed": str(settings.seed)}
    params.update(key_params(settings))
    with tracker.run(f"adj={adjective}", params, tags, parent_id) as run_id:
        log_data(tracker, run_id, dataset)
        cache = store.MlflowCache(
            tracker,
            run_id=run_id,
            parent_id=parent_id,
            adjective=adjective,
            reuse=settings.tracking.reuse,
            lease=settings.tracking.claim_lease,
            tags={"config_hash": settings.config_hash},
        )
        result = core.fit_adjective(settings, dataset, split, cache, progress=epoch_logger)
        others = side_metrics(result)
        records = Records.of(settings)
        tested = result.metrics if records.test else {}
        tracker.log_metrics(run_id, {**tested, **result.sizes, **others, **result.preprocess})
        log.info("  %s %s", adjective, " ".join(f"{k}={v:.3f}" for k, v in others.items()))
        tracker.log_curves(run_id, result.history)
        if records.test:
            tracker.log_text(run_id, scores_table(result.test), scores_file.NAME)
        # The run turns FINISHED only after the pipeline is written, and lookups take FINISHED
        # runs only, so a job killed while writing leaves nothing reusable.
        store.log_folder(tracker, run_id, "", pipeline_of(result).save)
    return result


def pipeline_of(result: core.AdjectiveResult) -> Any:
    if result.pipeline is None:
        raise ValueError(f"{result.adjective}: the result's pipeline was released")
    return result.pipeline


def side_metrics(result: core.AdjectiveResult) -> dict[str, float]:
    """The training and validation sides' metrics as logged: ``train_auc``, ``val_f1``, ..."""
    return {
        f"{side}_{key}": value
        for side, scored in result.sides.items()
        if side != "test"
        for key, value in scored.metrics.items()
    }


def scores_table(scored: core.Scored) -> str:
    """``scores.csv``: each test unit's name, object, label and score."""
    return scores_file.write(scored.units, scored.objects, scored.y, scored.scores)


def record_summary(
    tracker: Tracker,
    run_id: str,
    settings: Settings,
    dataset: Any,
    results: Mapping[str, core.AdjectiveResult],
) -> dict[str, float]:
    """The job's metrics (``mean_<key>``, ``<key>.<adjective>``, the side means, the interval),
    its per-adjective table and ROC figure; returns the metrics logged. A search trial's job logs
    the side means alone: its test metrics wait for the study's final evaluation."""
    if not Records.of(settings).test:
        logged = side_means(results)
        tracker.log_metrics(run_id, logged)
        return logged
    logged = metrics.summary({a: r.metrics for a, r in results.items()})
    held_out = {
        a: stats.HeldOut(r.test.objects, r.test.y, r.test.scores) for a, r in results.items()
    }
    ci = stats.mean_interval([held_out])  # over test objects
    logged |= side_means(results) | {"mean_auc_ci_low": ci.low, "mean_auc_ci_high": ci.high}
    tracker.log_metrics(run_id, logged)
    lines = ["adjective,auc,n_test_units,n_test_positive_units,n_train_objects,n_test_objects"]
    for adjective, r in results.items():
        s = r.sizes
        lines.append(
            f"{adjective},{r.metrics['auc']:.6f},{s['n_test_units']},"
            f"{s['n_test_positive_units']},{s['n_train_objects']},{s['n_test_objects']}"
        )
    tracker.log_text(run_id, "\n".join(lines) + "\n", "auc_per_adjective.csv")
    log_roc(tracker, run_id, settings, dataset, results)
    return logged


def log_roc(
    tracker: Tracker,
    run_id: str,
    settings: Settings,
    dataset: Any,
    results: Mapping[str, core.AdjectiveResult],
) -> None:
    """The job's ROC curves, one per adjective, as ``roc.png``."""
    curves = {a: (r.test.y, r.test.scores) for a, r in results.items()}
    figure = evaluate.roc_figure(curves, f"{settings.run_name} on {dataset.path.name}")
    tracker.log_figure(run_id, figure, "roc.png")
    import matplotlib.pyplot as plt

    plt.close(figure)


def side_means(results: Mapping[str, core.AdjectiveResult]) -> dict[str, float]:
    """``mean_<side>_<key>`` and ``n_<side>_<key>`` over the adjectives whose training or
    validation side has the metric (validation AUC: both classes held out)."""
    per_adjective = {a: side_metrics(r) for a, r in results.items()}
    out = {}
    for name in dict.fromkeys(k for values in per_adjective.values() for k in values):
        values = [v[name] for v in per_adjective.values() if name in v]
        out[f"mean_{name}"] = float(np.mean(values))
        out[f"n_{name}"] = len(values)
    return out


def log_view(tracker: Tracker, settings: Settings) -> None:
    """The last lines of a job's log: where its sweep's runs table is, with its numbers (a
    search trial's: by validation AUC, no test metric shown)."""
    records = Records.of(settings)
    sort, what = records.sort, records.what
    columns = [canonical_column("metrics", sort)]
    columns += [canonical_column("params", f"axis.{k}") for k in settings.axes]
    if not settings.axes:
        columns += [canonical_column("params", k) for k in ("choice.model", "combine")]
    url = tracker.runs_view(columns, order_by=canonical_column("metrics", sort))
    log.info("runs table (jobs by mean %s, with what each sets): %s", what, url)
    if not tracker.uri.startswith(("http://", "https://")):
        log.info("  serve it first: %s ui --backend-store-uri %s", _mlflow_command(), tracker.uri)
    log.info("  (MLflow opened without this link shows its GenAI Overview: click 'Model training')")


def _mlflow_command() -> str:
    """This interpreter's ``mlflow`` (``.venv/bin/mlflow`` from the clone): a bare ``mlflow``
    fails in a shell without the venv activated."""
    path = Path(sys.executable).with_name("mlflow")
    try:
        return str(path.relative_to(Path.cwd()))
    except ValueError:
        return str(path)


def _log_config(tracker: Tracker, run_id: str, settings: Settings) -> None:
    import yaml

    tracker.log_text(run_id, yaml.safe_dump(settings.resolved, sort_keys=False), "config.yaml")
    if settings.output_dir is not None and (settings.output_dir / ".hydra").is_dir():
        tracker.log_dir(run_id, settings.output_dir / ".hydra", ".hydra")
