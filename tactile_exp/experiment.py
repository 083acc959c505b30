"""One job: every adjective's run (``adjective.run_adjective``: split, fitted pipeline, scores,
ROC AUC) under one parent run, with the job's summary (T1, T4, E1, E2).

Runs without Hydra: it takes the plain ``Settings`` built by ``tactile_exp.config``.
"""

from __future__ import annotations

import importlib
import logging
import os
import warnings
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tactile_exp import evaluate, metrics, stats
from tactile_exp.adjective import AdjectiveResult, key_params, log_data, run_adjective
from tactile_exp.config import Settings, param_error
from tactile_exp.data.dataset import select_labels
from tactile_exp.data.layout import Split
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.data.splits import make_split
from tactile_exp.errors import ConfigError
from tactile_exp.modalities import MODALITIES, Modality
from tactile_exp.runtime import workers
from tactile_exp.tracking import Tracker, canonical_column, flatten
from tactile_exp.train import device_name

log = logging.getLogger(__name__)


@dataclass
class JobResult:
    run_id: str | None
    mean_auc: float
    results: dict[str, AdjectiveResult]
    skipped: bool = False
    # Per adjective, the held-out validation objects' metrics by key (where they hold both
    # classes): what the job's objective is computed from (tactile_exp.objective); read back
    # when skipped.
    validation: dict[str, dict[str, float]] = field(default_factory=dict)


def load(settings: Settings) -> tuple[Any, Modality, dict[str, Split]]:
    """Open the data, check every split, read and cache shared arrays: bad input surfaces here."""
    dataset, modality, splits = open_data(settings)
    modality.check(dataset)
    return dataset, modality, splits


def open_data(settings: Settings) -> tuple[Any, Modality, dict[str, Split]]:
    """Open the data and check ``combine`` and every split, cheaply (before a run is created)."""
    dataset = DATA_SOURCES.build(settings.data.name, **settings.data.params)
    try:
        modality = MODALITIES.build(
            settings.modality.name,
            cache_dir=settings.cache_dir / "preprocessed",
            **settings.modality.params,
        )
    except (TypeError, ValueError) as err:
        raise param_error("modality", settings.modality.params, err) from err
    limit, unit = modality.max_combine(dataset)
    if settings.combine > limit:
        raise ConfigError(
            f"combine: {settings.combine} {unit} per unit, but objects in {dataset.path} have at "
            f"most {limit} {unit}; allowed 1..{limit}"
        )
    splits = {
        a: make_split(dataset, a, settings.split, settings.seed, **settings.split_params)
        for a in select_labels(dataset, settings.adjectives)
    }
    return dataset, modality, splits


def run(settings: Settings) -> JobResult:
    """Run (or skip, if already FINISHED) one job and log it to MLflow."""
    tracker = Tracker(settings.tracking.uri, settings.tracking.experiment)
    if settings.tracking.skip_finished:
        identity = DATA_SOURCES.build(settings.data.name, **settings.data.params).identity()
        done = tracker.finished_run(settings.config_hash, data_identity=identity)
        if done is not None and not _trial(settings) and not tracker.child_metrics(done, "auc"):
            done = None  # a search trial's job: it logged no test metric, so run it again
        if done is not None:
            log.info(
                "skipping %s: run %s already FINISHED with this config on this data file",
                settings.run_name,
                done,
            )
            _log_view(tracker, settings)
            return JobResult(
                done,
                float("nan"),
                {},
                skipped=True,
                validation=_validation(tracker, done, settings.metrics),
            )
    tracker.end_stale_runs(settings.config_hash)
    dataset, modality, splits = open_data(settings)

    params = {**flatten(settings.resolved), **key_params(settings)}
    tags = {
        "config_hash": settings.config_hash,
        "row_hash": settings.row_hash,
        "run_level": "parent",
        "sweep_id": settings.sweep_id,
        "overrides": " ".join(settings.overrides)[:5000],  # what the report calls a variant
        "device": device_name(settings.device),  # what device=auto picked here
        **settings.study_tags,  # search.study, search.role, search.trial (issue 28)
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
        modality.check(dataset)
        tracker.set_tags(
            parent_id,
            {"data.identity": dataset.identity(), "data.labels": " ".join(dataset.label_names)},
        )
        log_data(tracker, parent_id, dataset)
        results: dict[str, AdjectiveResult] = {}
        headline = metrics.METRICS.build(settings.metrics[0])
        trial = _trial(settings)
        # A search trial shows and logs its validation AUC only: test metrics wait for the
        # study's final evaluation.
        shown, label = ("val_auc", "validation AUC") if trial else (headline.key, headline.label)
        for i, result in enumerate(_adjectives(settings, tracker, parent_id, dataset, splits), 1):
            results[result.adjective] = result
            values = result.diagnostics if trial else result.metrics
            log.info(
                "[%d/%d] %s %s %.3f (%.1f s)",
                i,
                len(splits),
                result.adjective,
                label,
                values.get(shown, float("nan")),
                result.sizes["seconds"],
            )
        logged = metrics.summary({a: r.metrics for a, r in results.items()})
        mean = float("nan") if trial else logged["mean_auc"]
        if trial:
            tracker.log_metrics(parent_id, _means(results))
        else:
            held_out = {a: stats.HeldOut(r.objects, r.y, r.scores) for a, r in results.items()}
            ci = stats.mean_interval([held_out])  # over test objects (issue 27)
            ends = {"mean_auc_ci_low": ci.low, "mean_auc_ci_high": ci.high}
            tracker.log_metrics(parent_id, logged | _means(results) | ends)
            _log_summary(tracker, parent_id, settings, dataset, results)
            key = headline.key
            log.info("mean %s over %d adjectives: %.4f", label, len(results), logged[f"mean_{key}"])
    validation = {
        a: {k.removeprefix("val_"): v for k, v in r.diagnostics.items() if k.startswith("val_")}
        for a, r in results.items()
    }
    _log_view(tracker, settings)
    return JobResult(
        parent_id, mean, results, validation={a: v for a, v in validation.items() if v}
    )


def _validation(
    tracker: Tracker, parent_id: str, names: tuple[str, ...]
) -> dict[str, dict[str, float]]:
    """A finished job's per-adjective validation metrics, from its adjectives' runs."""
    out: dict[str, dict[str, float]] = {}
    for key in (metrics.METRICS.build(n).key for n in names):
        for adjective, v in tracker.child_metrics(parent_id, f"val_{key}").items():
            out.setdefault(adjective, {})[key] = v
    return out


def _trial(settings: Settings) -> bool:
    return settings.study_tags.get("search.role") == "trial"


def _log_view(tracker: Tracker, settings: Settings) -> None:
    """The last lines of a job's log: where its sweep's runs table is, with its numbers (a
    search trial's: by validation AUC, no test metric shown)."""
    sort, what = ("mean_val_auc", "validation AUC") if _trial(settings) else ("mean_auc", "AUC")
    columns = [canonical_column("metrics", sort)]
    columns += [canonical_column("params", f"axis.{k}") for k in settings.axes]
    if not settings.axes:
        columns += [canonical_column("params", k) for k in ("choice.model", "combine")]
    url = tracker.runs_view(columns, order_by=canonical_column("metrics", sort))
    log.info("runs table (jobs by mean %s, with what each sets): %s", what, url)
    if not tracker.uri.startswith(("http://", "https://")):
        log.info("  serve it first: mlflow ui --backend-store-uri %s", tracker.uri)
    log.info("  (MLflow opened without this link shows its GenAI Overview: click 'Model training')")


def _adjectives(
    settings: Settings,
    tracker: Tracker,
    parent_id: str,
    dataset: Any,
    splits: Mapping[str, Split],
) -> Iterator[AdjectiveResult]:
    """Each adjective's result, in order: here, or ``settings.workers`` at a time in worker
    processes (``runtime.workers``) that open the data and the tracking store once each."""
    n = len(splits)
    processes = min(settings.workers, n)
    if processes == 1:
        for i, adjective in enumerate(splits, start=1):
            log.info("[%d/%d] %s", i, n, adjective)
            yield run_adjective(settings, tracker, parent_id, dataset, splits[adjective])
        return
    pool = workers.Pool(processes, init=_open_in_worker, initargs=(settings, parent_id))
    log.info("%d adjectives in %d worker processes", n, processes)
    try:
        with pool:
            calls = [(i, n, a) for i, a in enumerate(splits, start=1)]
            yield from pool.map(_adjective_in_worker, calls)
    except BaseException:
        error = "a worker was stopped before it ended this run (the job failed or was terminated)"
        tracker.end_runs_of(pool.pids, error=error)
        raise


_WORKER: dict[str, Any] = {}  # what a worker process opened once: see _open_in_worker


def _open_in_worker(settings: Settings, parent_id: str) -> None:
    for module in settings.modules:
        importlib.import_module(module)
    with warnings.catch_warnings():  # the job's own load() has already shown them
        warnings.simplefilter("ignore")
        dataset, _, splits = load(settings)
    _WORKER.update(
        settings=settings,
        tracker=Tracker(settings.tracking.uri, settings.tracking.experiment),
        parent_id=parent_id,
        dataset=dataset,
        splits=splits,
    )


def _adjective_in_worker(i: int, n: int, adjective: str) -> AdjectiveResult:
    log.info("[%d/%d] %s (worker %d)", i, n, adjective, os.getpid())
    w = _WORKER
    return run_adjective(
        w["settings"], w["tracker"], w["parent_id"], w["dataset"], w["splits"][adjective]
    )


def _means(results: Mapping[str, AdjectiveResult]) -> dict[str, float]:
    """mean_train_auc and mean_val_auc over the adjectives that have them (val: both classes)."""
    out = {}
    for name in ("train_auc", "val_auc"):
        values = [r.diagnostics[name] for r in results.values() if name in r.diagnostics]
        if values:
            out[f"mean_{name}"] = float(np.mean(values))
            out[f"n_{name}"] = len(values)
    return out


def _log_config(tracker: Tracker, run_id: str, settings: Settings) -> None:
    import yaml

    tracker.log_text(run_id, yaml.safe_dump(settings.resolved, sort_keys=False), "config.yaml")
    if settings.output_dir is not None and (settings.output_dir / ".hydra").is_dir():
        tracker.log_dir(run_id, settings.output_dir / ".hydra", ".hydra")


def _log_summary(
    tracker: Tracker,
    run_id: str,
    settings: Settings,
    dataset: Any,
    results: dict[str, AdjectiveResult],
) -> None:
    lines = ["adjective,auc,n_test_units,n_test_positive_units,n_train_objects,n_test_objects"]
    for adjective, r in results.items():
        s = r.sizes
        lines.append(
            f"{adjective},{r.auc:.6f},{s['n_test_units']},{s['n_test_positive_units']},"
            f"{s['n_train_objects']},{s['n_test_objects']}"
        )
    tracker.log_text(run_id, "\n".join(lines) + "\n", "auc_per_adjective.csv")
    curves = {a: (r.y, r.scores) for a, r in results.items()}
    figure = evaluate.roc_figure(curves, f"{settings.run_name} on {dataset.path.name}")
    tracker.log_figure(run_id, figure, "roc.png")
    import matplotlib.pyplot as plt

    plt.close(figure)
