"""One job: for each adjective, split, fit the preprocessing on training trials, train, score the
test units, compute ROC AUC, and log it all (T1, T4, E1, E2).

Runs without Hydra: it takes the plain ``Settings`` built by ``tactile_exp.config``.
"""

from __future__ import annotations

import io
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from tactile_exp import evaluate
from tactile_exp.combine import COMBINERS
from tactile_exp.config import ConfigError, Settings
from tactile_exp.data.layout import Instances, Split
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.data.splits import make_split
from tactile_exp.modalities import MODALITIES, Modality
from tactile_exp.models.base import EpochCallback, History, Model
from tactile_exp.models.registry import MODELS
from tactile_exp.tracking import Tracker, flatten

log = logging.getLogger(__name__)


@dataclass
class AdjectiveResult:
    adjective: str
    auc: float
    y: np.ndarray  # test unit labels
    scores: np.ndarray  # test unit scores
    units: np.ndarray  # test unit names (first trial of each unit)
    objects: np.ndarray
    sizes: dict[str, float]
    history: History = field(default_factory=dict)


@dataclass
class JobResult:
    run_id: str | None
    mean_auc: float
    results: dict[str, AdjectiveResult]
    skipped: bool = False


def classify(
    model_factory: Callable[[], Model],
    combiner: str,
    combine: int,
    train: Instances,
    test: Instances,
    on_epoch: EpochCallback | None = None,
) -> tuple[np.ndarray, Instances, History]:
    """Train on ``train`` and score ``test``, combining instances into units first if asked.

    Returns the test scores, the test units they belong to, and the training curves.
    """
    model = model_factory()
    combine_units = COMBINERS.build(combiner)
    if combine_units.keeps_instances:
        history = model.fit(train, on_epoch)
        return model.decision_function(test.X), test, history
    history = model.fit(train, on_epoch) if model.learns_representation else {}
    train_units = combine_units(model.transform(train.X), train, combine)
    test_units = combine_units(model.transform(test.X), test, combine)
    head = model.head()
    head_history = head.fit(train_units)
    history.update({f"head_{k}": v for k, v in head_history.items()})
    return head.decision_function(test_units.X), test_units, history


def _epoch_logger(adjective: str) -> EpochCallback:
    """A compact line at ~5 points per run instead of one per epoch."""

    def on_epoch(epoch: int, n_epochs: int, metrics: dict[str, float]) -> None:
        if epoch == 1 or epoch % max(1, n_epochs // 5) == 0 or epoch == n_epochs:
            shown = " ".join(f"{k}={v:.4f}" for k, v in metrics.items())
            log.info("  %s epoch %d/%d %s", adjective, epoch, n_epochs, shown)

    return on_epoch


def _open(settings: Settings) -> tuple[PHAC2, Modality]:
    """The data set and the modality; an impossible ``combine`` for this file raises here."""
    dataset = DATA_SOURCES.build(settings.data.name, **settings.data.params)
    modality = MODALITIES.build(
        settings.modality.name,
        dataset=dataset,
        cache_dir=settings.cache_dir / "preprocessed",
        **settings.modality.params,
    )
    limit, unit = modality.max_combine()
    if settings.combine > limit:
        raise ConfigError(
            f"combine: {settings.combine} {unit} per unit, but objects in {dataset.path} have at "
            f"most {limit} {unit}; allowed 1..{limit}"
        )
    return dataset, modality


def check_combine(settings: Settings) -> None:
    """Raise ``ConfigError`` for a ``combine`` the file cannot give, before any run is created.

    Other bad input is left to ``load``, inside the job's run, so that the run records it.
    """
    try:
        _open(settings)
    except ConfigError:
        raise
    except Exception:
        return


def load(settings: Settings) -> tuple[PHAC2, Modality, dict[str, Split]]:
    """Open the data, check every split, read and cache shared arrays: bad input surfaces here."""
    dataset, modality = _open(settings)
    splits = {a: make_split(dataset, a, settings.split, settings.seed) for a in settings.adjectives}
    modality.prepare()
    return dataset, modality, splits


def run(settings: Settings) -> JobResult:
    """Run (or skip, if already FINISHED) one job and log it to MLflow."""
    tracker = Tracker(settings.tracking.uri, settings.tracking.experiment)
    if settings.tracking.skip_finished:
        done = tracker.finished_run(settings.config_hash)
        if done is not None:
            log.info(
                "skipping %s: run %s already FINISHED with this config", settings.run_name, done
            )
            return JobResult(done, float("nan"), {}, skipped=True)
    check_combine(settings)

    params = flatten(settings.resolved)
    params.update({f"choice.{k}": v for k, v in settings.choices.items()})
    tags = {
        "config_hash": settings.config_hash,
        "run_level": "parent",
        "sweep_id": settings.sweep_id,
    }
    with tracker.run(settings.run_name, params, tags) as parent_id:
        log.info("MLflow run %s (%s) in %s", settings.run_name, parent_id, tracker.uri)
        _log_config(tracker, parent_id, settings)
        dataset, modality, splits = load(settings)
        results: dict[str, AdjectiveResult] = {}
        for i, adjective in enumerate(settings.adjectives, start=1):
            log.info("[%d/%d] %s", i, len(settings.adjectives), adjective)
            results[adjective] = _run_adjective(
                settings, tracker, parent_id, modality, splits[adjective]
            )
            log.info(
                "[%d/%d] %s AUC %.3f (%.1f s)",
                i,
                len(settings.adjectives),
                adjective,
                results[adjective].auc,
                results[adjective].sizes["seconds"],
            )
        aucs = {a: r.auc for a, r in results.items()}
        mean = evaluate.mean_auc(aucs)
        tracker.log_metrics(
            parent_id, {"mean_auc": mean, **{f"auc.{a}": v for a, v in aucs.items()}}
        )
        _log_summary(tracker, parent_id, settings, dataset, results)
        log.info("mean AUC over %d adjectives: %.4f", len(aucs), mean)
    return JobResult(parent_id, mean, results)


def _run_adjective(
    settings: Settings, tracker: Tracker, parent_id: str, modality: Modality, split: Split
) -> AdjectiveResult:
    adjective = split.adjective
    tags = {"config_hash": settings.config_hash, "run_level": "child", "adjective": adjective}
    with tracker.run(f"adj={adjective}", {"adjective": adjective}, tags, parent_id) as run_id:
        start = time.perf_counter()
        train, test = modality.instances(split)
        scores, units, history = classify(
            lambda: MODELS.build(settings.model.name, **settings.model.params),
            settings.combiner,
            settings.combine,
            train,
            test,
            _epoch_logger(adjective),
        )
        auc = evaluate.auc(units.y, scores)
        sizes = {
            "n_train_instances": len(train),
            "n_test_instances": len(test),
            "n_train_trials": len(split.train),
            "n_test_trials": len(split.test),
            "n_train_objects": len(split.objects("train")),
            "n_test_objects": len(split.objects("test")),
            "n_test_units": len(units),
            "n_test_positive_units": int(units.y.sum()),
            "seconds": time.perf_counter() - start,
        }
        tracker.log_metrics(run_id, {"auc": auc, **sizes})
        tracker.log_curves(run_id, history)
        table = io.StringIO()
        np.savetxt(
            table,
            np.column_stack([units.trial, units.object_id, units.y, scores]),
            fmt="%s",
            delimiter=",",
            header="unit,object_id,label,score",
            comments="",
        )
        tracker.log_text(run_id, table.getvalue(), "scores.csv")
    return AdjectiveResult(
        adjective, auc, units.y, scores, units.trial, units.object_id, sizes, history
    )


def _log_config(tracker: Tracker, run_id: str, settings: Settings) -> None:
    import yaml

    tracker.log_text(run_id, yaml.safe_dump(settings.resolved, sort_keys=False), "config.yaml")
    if settings.output_dir is not None and (settings.output_dir / ".hydra").is_dir():
        tracker.log_dir(run_id, settings.output_dir / ".hydra", ".hydra")


def _log_summary(
    tracker: Tracker,
    run_id: str,
    settings: Settings,
    dataset: PHAC2,
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
