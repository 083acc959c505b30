"""Fitting and scoring one adjective (T1, E1, E2), touching no tracking store.

``fit_adjective`` takes the job's settings, the data set and one adjective's split, and returns
an ``AdjectiveResult``: the fitted pipeline, every side's scores and metrics (test; train; val
when ``validation.fraction`` > 0), the training curves and the sizes. Trained models and a
modality's parts come from a ``cache.ModelCache`` by training key, so rows H, I and J share one
ConvNet per adjective, and rows M and N the ConvNet of row I or J. Recording the result (an
MLflow child run) is ``recording``'s work; a notebook needs none of it (``tactile_exp.api``).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from tactile_exp import keys, metrics
from tactile_exp.cache import ModelCache, Trained
from tactile_exp.config import Settings, check_data_chain, param_error
from tactile_exp.data.dataset import select_labels
from tactile_exp.data.layout import Instances, Split, Trials
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.data.splits import label_splits
from tactile_exp.errors import ConfigError
from tactile_exp.modalities import MODALITIES, Modality
from tactile_exp.models.base import EpochCallback, History, Model
from tactile_exp.models.registry import MODELS
from tactile_exp.models.schedule import STEPS
from tactile_exp.pipeline import AdjectivePipeline
from tactile_exp.registry import Component
from tactile_exp.runtime import termination
from tactile_exp.validation import validation_split

log = logging.getLogger(__name__)

SIDES = ("test", "train", "val")  # the order scores are drawn in (row O's are random)
Progress = Callable[[str], EpochCallback]  # what trains under a name -> its epoch callback


@dataclass
class Scored:
    """One side's units: labels, scores, names (first trial of each unit), objects, and each
    configured metric that is defined on them, keyed by the metric's key (``auc``, ``f1``)."""

    y: np.ndarray
    scores: np.ndarray
    units: np.ndarray
    objects: np.ndarray
    metrics: dict[str, float] = field(default_factory=dict)


@dataclass
class AdjectiveResult:
    adjective: str
    sides: dict[str, Scored]  # "test", "train", and "val" when objects were held out
    sizes: dict[str, float]  # counts of trials, objects, units; "seconds"
    history: History = field(default_factory=dict)  # training curves (model, then head_*)
    preprocess: dict[str, float] = field(default_factory=dict)  # the modality's own counts
    pipeline: AdjectivePipeline | None = None  # None once released (kept in its run)

    @property
    def test(self) -> Scored:
        return self.sides["test"]

    @property
    def metrics(self) -> dict[str, float]:
        """The test side's metrics: what the paper's Table I reports (``auc``)."""
        return self.sides["test"].metrics


def load(settings: Settings) -> tuple[Any, Modality, dict[str, Split]]:
    """Open the data, check every split, read and cache shared arrays: bad input surfaces here."""
    dataset, modality, splits = open_data(settings)
    modality.check(dataset)
    return dataset, modality, splits


def open_modality(settings: Settings) -> Modality:
    """The job's modality, built from its settings alone (no data read)."""
    try:
        return MODALITIES.build(
            settings.modality.name,
            cache_dir=settings.cache_dir / "preprocessed",
            **settings.modality.params,
        )
    except (TypeError, ValueError) as err:
        raise param_error("modality", settings.modality.params, err) from err


def open_data(
    settings: Settings, modality: Modality | None = None
) -> tuple[Any, Modality, dict[str, Split]]:
    """Open the data (generated on first use) and check ``combine`` and every split, cheaply
    (before a run is created), with ``modality`` (``open_modality``'s, built here if None)."""
    modality = open_modality(settings) if modality is None else modality
    dataset = DATA_SOURCES.build(settings.data.name, **settings.data.params)
    check_data_chain(settings, dataset, modality)
    limit, unit = modality.max_combine(dataset)
    if settings.combine > limit:
        raise ConfigError(
            f"combine: {settings.combine} {unit} per unit, but objects in {dataset.path} have at "
            f"most {limit} {unit}; allowed 1..{limit}"
        )
    splits = label_splits(
        dataset,
        select_labels(dataset, settings.adjectives),
        settings.split,
        settings.seed,
        settings.min_objects,
        **settings.split_params,
    )
    return dataset, modality, splits


def kernels(settings: Settings, modality: Modality) -> tuple[str, ...]:
    """The compiled kernel modules a job runs: its model's and its modality's parts' models'."""
    models = [settings.model, *(model for _, model in modality.parts().values())]
    return tuple(k for m in models for k in MODELS.build(m.name, **m.params).kernels())


def adjective_key(
    settings: Settings,
    dataset: Any,
    modality: Component,
    model: Component,
    label: str,
    *,
    representation_only: bool = False,
) -> str:
    """``keys.training_key`` of one adjective's model (or part) in this job."""
    return keys.training_key(
        dataset=dataset.identity(),
        modality=modality,
        model=model,
        split=settings.split_key,
        validation=settings.validation_fraction,
        seed=settings.seed,
        adjective=label,
        representation_only=representation_only,
    )


def model_key(settings: Settings, dataset: Any, adjective: str) -> str:
    """The training key of the job's own model for ``adjective`` (``adjective_key``), marked
    when the model is fitted for the head alone (``fits_representation_only``)."""
    return adjective_key(
        settings, dataset, settings.modality, settings.model, adjective,
        representation_only=new_pipeline(settings).fits_representation_only,
    )  # fmt: skip


def stores_model(settings: Settings) -> bool:
    """Whether the job's model is trained and storable, so kept in (and found in) a cache."""
    return new_pipeline(settings).stores_model


def ignored_schedule_keys(settings: Settings) -> tuple[str, ...]:
    """The job's command-line ``schedule.<key>`` overrides that nothing it trains reads.

    A model that learns no representation (``linear``) is not trained under a combiner that
    retrains a head (``concat``, ``mean``): only its head is, by ``schedule.head``, so the
    model's own steps (``schedule.epochs``, ...) that the head node sets change nothing; under
    ``separate`` no head is trained, so ``schedule.head.<key>`` changes nothing. Judged for a
    model that takes the ``schedule`` node whole (``schedule: ${schedule}``); one that mixes
    its own values in (``visual_googlenet``) is not judged: ``()``."""
    node = settings.model.params.get("schedule")
    if not isinstance(node, dict) or node != settings.resolved.get("schedule"):
        return ()
    pipeline = new_pipeline(settings)
    head = node.get("head") or {}

    def read(key: str) -> bool:
        step = key.removeprefix("schedule.")
        if step.startswith("head."):
            return not pipeline.keeps_instances
        return pipeline.trains_model or (not pipeline.keeps_instances and step not in head)

    given = [item.partition("=")[0].lstrip("+~") for item in settings.overrides]
    steps = {f"schedule.{k}" for k in STEPS} | {f"schedule.head.{k}" for k in STEPS}
    return tuple(dict.fromkeys(k for k in given if k in steps and not read(k)))


def new_pipeline(settings: Settings, label: str = "") -> AdjectivePipeline:
    return AdjectivePipeline(
        settings.modality, settings.model, settings.combiner, settings.combine,
        label=label, cache_dir=settings.cache_dir / "preprocessed",
    )  # fmt: skip


def sides(settings: Settings, dataset: Any, split: Split) -> dict[str, Trials]:
    """Training, test and (held out of training) validation trials of ``split``."""
    fit_split, held = validation_split(
        split, fraction=settings.validation_fraction, seed=settings.seed
    )
    out = {"train": fit_split.trials("train", dataset), "test": split.trials("test", dataset)}
    if held:
        out["val"] = replace(split.trials("train", dataset, held), side="validation")
    return out


def fit_adjective(
    settings: Settings,
    dataset: Any,
    split: Split,
    cache: ModelCache,
    *,
    progress: Progress | None = None,
) -> AdjectiveResult:
    """Fit ``split``'s adjective on its training trials, score every side, compute metrics.

    ``progress(name)``: the epoch callback of what trains under ``name`` (the adjective, or
    ``<adjective>/<part>``); the test side's metrics raise when undefined on its labels."""
    termination.check()
    on_epoch = None if progress is None else progress(split.adjective)
    start = time.perf_counter()
    adjective = split.adjective
    pipeline = new_pipeline(settings, adjective)
    trials = sides(settings, dataset, split)
    parts = {
        part: _part(settings, dataset, cache, part, modality, model, trials["train"], progress)
        for part, (modality, model) in pipeline.preprocess.parts().items()
    }

    def trainer(train: Callable[[], tuple[Model, History]]) -> tuple[Model, History]:
        """The model by its training key, trained by ``train`` if the cache has none."""
        key = model_key(settings, dataset, adjective)
        trained = cache.get_or_train(key, train, overrides=keys.unkeyed(settings.model))
        return trained.model, trained.history

    history = pipeline.fit(
        trials["train"],
        parts=parts,
        on_epoch=on_epoch,
        trainer=trainer if pipeline.stores_model else None,
    )
    test = pipeline.preprocess.transform(trials["test"])
    scored = {"test": pipeline.score(test), "train": pipeline.train_scores()}
    if "val" in trials:
        scored["val"] = pipeline.decision_function(trials["val"])
    result = {
        side: _scored(settings.metrics, *scored[side], side == "test")
        for side in SIDES
        if side in scored
    }
    sizes = _sizes(split, trials, pipeline, test, scored["test"][1], scored.get("val"))
    sizes["seconds"] = time.perf_counter() - start
    return AdjectiveResult(
        adjective, result, sizes, history, pipeline.preprocess.metrics(), pipeline
    )


def _part(
    settings: Settings,
    dataset: Any,
    cache: ModelCache,
    part: str,
    modality: Component,
    model: Component,
    train: Trials,
    progress: Progress | None,
) -> Model:
    """A modality's part (row M's ConvNet), found by its training key or trained on ``train``
    after the part's own modality, as the job that trains it alone would."""

    def fit() -> tuple[Model, History]:
        preprocess = MODALITIES.build(
            modality.name, cache_dir=settings.cache_dir / "preprocessed", **modality.params
        )
        net = MODELS.build(model.name, **model.params)
        on_epoch = None if progress is None else progress(f"{train.label}/{part}")
        return net, net.fit(preprocess.fit(train).transform(train), on_epoch)

    key = adjective_key(settings, dataset, modality, model, train.label)
    trained: Trained = cache.get_or_train(key, fit, part=part, overrides=keys.unkeyed(model))
    return trained.model


def _scored(names: tuple[str, ...], scores: np.ndarray, units: Instances, strict: bool) -> Scored:
    """A side's scores with every metric of ``names``: those defined on its labels, or (strict,
    the test side) all of them, raising when one is not."""
    if strict:
        values = metrics.compute(names, units.y, scores)
    else:
        both = len(np.unique(units.y)) == 2
        defined = [n for n in names if both or not metrics.METRICS.build(n).needs_both_classes]
        values = metrics.compute(defined, units.y, scores)
    return Scored(units.y, scores, units.trial, units.object_id, values)


def _sizes(
    split: Split,
    trials: dict[str, Trials],
    pipeline: AdjectivePipeline,
    test: Instances,
    units: Instances,
    val: tuple[np.ndarray, Instances] | None,
) -> dict[str, float]:
    val_units = val[1] if val is not None else Instances(np.zeros((0, 1)), *[np.zeros(0)] * 3)
    return {
        "n_train_instances": pipeline.n_train_instances_,
        "n_test_instances": len(test),
        "n_train_trials": len(trials["train"]),
        "n_test_trials": len(split.test),
        "n_train_objects": len(trials["train"].objects),
        "n_test_objects": len(split.objects("test")),
        "n_test_units": len(units),
        "n_test_positive_units": int(units.y.sum()),
        "n_val_objects": len(np.unique(val_units.object_id)),
        "n_val_positive_objects": len(np.unique(val_units.object_id[val_units.y == 1])),
    }
