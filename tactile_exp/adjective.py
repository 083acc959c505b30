"""One adjective's run (T1, E1, E2): its split's trials -> a fitted pipeline -> scores of the
test units -> ROC AUC, logged as a child run of the job with the pipeline as its artifacts.

A trained model is found by its training key before it is trained (``store.reusable``): rows H,
I and J share one ConvNet per adjective, and a part (row M's ConvNet) is found or trained in a run
of its own, so any later job finds it.
"""

from __future__ import annotations

import io
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from tactile_exp import metrics, store
from tactile_exp.config import Settings
from tactile_exp.data.layout import Instances, Split, Trials
from tactile_exp.modalities.base import Modality, PartProvider
from tactile_exp.models.base import EpochCallback, History, Model
from tactile_exp.models.registry import MODELS
from tactile_exp.pipeline import AdjectivePipeline
from tactile_exp.registry import Component
from tactile_exp.runtime import termination
from tactile_exp.tracking import MAX_PARAM_LENGTH, Tracker
from tactile_exp.validation import validation_split

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
    diagnostics: dict[str, float] = field(default_factory=dict)  # train_auc, val_auc
    metrics: dict[str, float] = field(default_factory=dict)  # key -> value: settings.metrics


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


def _key(settings: Settings, dataset: Any, modality: Component, model: Component, label: str):
    return store.training_key(
        dataset=dataset.identity(),
        modality=modality,
        model=model,
        split=settings.split_key,
        validation=settings.validation_fraction,
        seed=settings.seed,
        adjective=label,
    )


def _unkeyed(params: dict[str, Any]) -> dict[str, Any]:
    """The model settings a reused model takes from this job (not from where it was trained)."""
    return store.unkeyed(params)


def _sides(settings: Settings, dataset: Any, split: Split) -> dict[str, Trials]:
    """Training, test and (held out of training, issue 13) validation trials of ``split``."""
    fit_split, held = validation_split(
        split, fraction=settings.validation_fraction, seed=settings.seed
    )
    sides = {"train": fit_split.trials("train", dataset), "test": split.trials("test", dataset)}
    if held:
        sides["val"] = replace(split.trials("train", dataset, held), side="validation")
    return sides


def run_adjective(
    settings: Settings, tracker: Tracker, parent_id: str, dataset: Any, split: Split
) -> AdjectiveResult:
    """Fit, score and log one adjective in a child run of ``parent_id``."""
    termination.check()
    adjective = split.adjective
    pipeline = AdjectivePipeline(
        settings.modality, settings.model, settings.combiner, settings.combine,
        label=adjective, cache_dir=settings.cache_dir / "preprocessed",
    )  # fmt: skip
    reuse = settings.tracking.reuse
    stores_model = pipeline.trains_model and MODELS[settings.model.name].storable
    key = _key(settings, dataset, settings.modality, settings.model, adjective)
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
        start = time.perf_counter()
        sides = _sides(settings, dataset, split)
        found = None
        if reuse and stores_model:
            lease = settings.tracking.claim_lease
            found = store.reusable(
                tracker, key, run_id, lease=lease, overrides=_unkeyed(settings.model.params)
            )
        if found is not None:
            log.info("  %s: reusing the model trained in run %s", adjective, found[1])
            tracker.set_tags(run_id, {"reused_from": found[1]})
        provide = _part_provider(settings, tracker, parent_id, run_id, dataset, pipeline.preprocess)
        history = pipeline.fit(
            sides["train"],
            model=None if found is None else found[0],
            provide=provide,
            on_epoch=epoch_logger(adjective),
        )
        test = pipeline.preprocess.transform(sides["test"])
        scores, units = pipeline.score(test)
        # Test, training, validation: the order the scores are drawn in (row O's are random).
        scored = {"test": (scores, units), "train": pipeline.train_scores()}
        if "val" in sides:
            scored["val"] = pipeline.decision_function(sides["val"])
        values = metrics.compute(settings.metrics, units.y, scores)
        diagnostics = _diagnostics(scored, settings.metrics)
        sizes = _sizes(split, sides, pipeline, test, units, scored.get("val"))
        sizes["seconds"] = time.perf_counter() - start
        # A search trial logs no test metric and no test score: what selects stays blind to them.
        trial = settings.study_tags.get("search.role") == "trial"
        tested = {} if trial else values
        logged = {**tested, **sizes, **diagnostics, **pipeline.preprocess.metrics()}
        tracker.log_metrics(run_id, logged)
        log.info("  %s %s", adjective, " ".join(f"{k}={v:.3f}" for k, v in diagnostics.items()))
        tracker.log_curves(run_id, history)
        if not trial:
            tracker.log_text(run_id, scores_table(scores, units), "scores.csv")
        # The run turns FINISHED only after the pipeline is written, and lookups take FINISHED
        # runs only, so a job killed while writing leaves nothing reusable.
        store.log_folder(tracker, run_id, "", pipeline.save)
    return AdjectiveResult(
        adjective,
        values["auc"],
        units.y,
        scores,
        units.trial,
        units.object_id,
        sizes,
        history,
        diagnostics,
        values,
    )


def scores_table(scores: np.ndarray, units: Instances) -> str:
    """``scores.csv``: each test unit's name, object, label and score."""
    table = io.StringIO()
    np.savetxt(
        table,
        np.column_stack([units.trial, units.object_id, units.y, scores]),
        fmt="%s",
        delimiter=",",
        header="unit,object_id,label,score",
        comments="",
    )
    return table.getvalue()


def _sizes(
    split: Split,
    sides: dict[str, Trials],
    pipeline: AdjectivePipeline,
    test: Instances,
    units: Instances,
    val: tuple[np.ndarray, Instances] | None,
) -> dict[str, float]:
    val_units = val[1] if val is not None else Instances(np.zeros((0, 1)), *[np.zeros(0)] * 3)
    return {
        "n_train_instances": pipeline.n_train_instances_,
        "n_test_instances": len(test),
        "n_train_trials": len(sides["train"]),
        "n_test_trials": len(split.test),
        "n_train_objects": len(sides["train"].objects),
        "n_test_objects": len(split.objects("test")),
        "n_test_units": len(units),
        "n_test_positive_units": int(units.y.sum()),
        "n_val_objects": len(np.unique(val_units.object_id)),
        "n_val_positive_objects": len(np.unique(val_units.object_id[val_units.y == 1])),
    }


def _diagnostics(
    scored: dict[str, tuple[np.ndarray, Instances]], names: Sequence[str]
) -> dict[str, float]:
    """Training AUC, and the held-out training objects' metrics (``names``: val_auc, val_f1, ...,
    what a search objective reads) when they hold both classes."""
    out = {}
    for name, measured in (("train", ("roc_auc",)), ("val", names)):
        if name in scored and len(np.unique(scored[name][1].y)) == 2:
            scores, units = scored[name]
            found = metrics.compute(measured, units.y, scores)
            out.update({f"{name}_{key}": v for key, v in found.items()})
    return out


def _part_provider(
    settings: Settings,
    tracker: Tracker,
    parent_id: str,
    run_id: str,
    dataset: Any,
    modality: Modality,
) -> PartProvider:
    """A modality's trained parts (row M's ConvNet): found by training key, else trained here
    in a run of their own (run_level=part, tagged with the key), so any later job finds them."""

    def provide(part: str, train: Instances, trials: Trials) -> Model:
        part_modality, part_model = modality.parts()[part]
        key = _key(settings, dataset, part_modality, part_model, trials.label)
        name = f"{trials.label}/{part}"
        reuse = settings.tracking.reuse
        overrides = _unkeyed(part_model.params)
        source = store.find_trained(tracker, key) if reuse else None
        found = None if source is None else (None, source)
        if source is None:
            tags = {
                "config_hash": settings.config_hash,
                "run_level": "part",
                "adjective": trials.label,
                "part": part,
                "training_key": key,
            }
            with tracker.run(f"adj={name}", {"adjective": trials.label}, tags, parent_id) as rid:
                # This run is the key's claim: wait while an older live job trains the part.
                lease = settings.tracking.claim_lease
                found = (
                    store.reusable(tracker, key, rid, lease=lease, overrides=overrides)
                    if reuse
                    else None
                )
                if found is None:
                    model = MODELS.build(part_model.name, **part_model.params)
                    tracker.log_curves(rid, model.fit(train, epoch_logger(name)))
                    write = lambda f: store.write_model(f, part_model.name, model)  # noqa: E731
                    store.log_folder(tracker, rid, "model", write)
                    source = rid
                else:
                    source = found[1]
                    tracker.set_tags(rid, {"reused_from": source})
        if found is not None:
            log.info("  %s: reusing the model trained in run %s", name, source)
            tracker.set_tags(run_id, {f"reused_from.{part}": source})
            model = found[0]
            if model is None:
                model = store.load_model(tracker, source, "model", overrides)
        tracker.set_tags(run_id, {f"part.{part}": source})
        return model

    return provide
