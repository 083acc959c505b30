"""One job: for each adjective, split, fit the preprocessing on training trials, train, score the
test units, compute ROC AUC, and log it all (T1, T4, E1, E2).

Runs without Hydra: it takes the plain ``Settings`` built by ``tactile_exp.config``.
"""

from __future__ import annotations

import functools
import importlib
import io
import logging
import os
import time
import warnings
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tactile_exp import evaluate, stats, store, termination, workers
from tactile_exp.combine import COMBINERS
from tactile_exp.config import ConfigError, Settings, component_modules, param_error
from tactile_exp.data.layout import Instances, Split
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.data.splits import make_split
from tactile_exp.modalities import MODALITIES, Modality
from tactile_exp.modalities.base import PartProvider
from tactile_exp.models.base import EpochCallback, History, Model
from tactile_exp.models.registry import MODELS
from tactile_exp.tracking import MAX_PARAM_LENGTH, Tracker, canonical_column, flatten
from tactile_exp.train import device_name
from tactile_exp.validation import take_trials, validation_split

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


@dataclass
class JobResult:
    run_id: str | None
    mean_auc: float
    results: dict[str, AdjectiveResult]
    skipped: bool = False
    # Per adjective, the held-out validation objects' AUC (where they hold both classes): what
    # the job's objective is computed from (tactile_exp.objective); read back when skipped.
    val_aucs: dict[str, float] = field(default_factory=dict)


def fit_model(
    model: Model, combiner: str, train: Instances, on_epoch: EpochCallback | None = None
) -> History | None:
    """Train ``model`` when its own scores or its learned features are used; None when not."""
    if COMBINERS.build(combiner).keeps_instances or model.learns_representation:
        return model.fit(train, on_epoch)
    return None


def score(
    model: Model,
    combiner: str,
    combine: int,
    train: Instances,
    sets: Mapping[str, Instances],
    *,
    pad: bool = True,
) -> tuple[dict[str, tuple[np.ndarray, Instances]], Model | None, History]:
    """Score each of ``sets`` (test, validation, the training set itself) with a fitted ``model``,
    or with a head retrained once on combined training units (T4).

    ``pad``: whether an object's last short group of instances is padded (``unit_members``).
    Returns, per set, the scores and the units they belong to; the head (None when the model
    scores instances itself) and the head's training curves.
    """
    combine_units = COMBINERS.build(combiner)
    if combine_units.keeps_instances:
        return {k: (model.decision_function(s.X), s) for k, s in sets.items()}, None, {}
    train_units = combine_units(model.transform(train.X), train, combine, pad=pad)
    head = model.head()
    head_history = {f"head_{k}": v for k, v in head.fit(train_units).items()}
    scored = {}
    for name, instances in sets.items():
        units = (
            train_units
            if instances is train
            else combine_units(model.transform(instances.X), instances, combine, pad=pad)
        )
        scored[name] = (head.decision_function(units.X), units)
    return scored, head, head_history


def classify(
    model_factory: Callable[[], Model],
    combiner: str,
    combine: int,
    train: Instances,
    test: Instances,
    on_epoch: EpochCallback | None = None,
    *,
    pad: bool = True,
) -> tuple[np.ndarray, Instances, History]:
    """Train on ``train`` and score ``test``, combining instances into units first if asked.

    ``pad``: whether an object's last short group of instances is padded (``unit_members``).
    Returns the test scores, the test units they belong to, and the training curves.
    """
    model = model_factory()
    history = fit_model(model, combiner, train, on_epoch) or {}
    scored, _, head_history = score(model, combiner, combine, train, {"test": test}, pad=pad)
    history.update(head_history)
    return *scored["test"], history


def _epoch_logger(adjective: str) -> EpochCallback:
    """A compact line at ~5 points per run instead of one per epoch; and a SIGTERM check."""

    def on_epoch(epoch: int, n_epochs: int, metrics: dict[str, float]) -> None:
        termination.check()
        if epoch == 1 or epoch % max(1, n_epochs // 5) == 0 or epoch == n_epochs:
            shown = " ".join(f"{k}={v:.4f}" for k, v in metrics.items())
            log.info("  %s epoch %d/%d %s", adjective, epoch, n_epochs, shown)

    return on_epoch


def load(settings: Settings) -> tuple[PHAC2, Modality, dict[str, Split]]:
    """Open the data, check every split, read and cache shared arrays: bad input surfaces here."""
    dataset, modality, splits = open_data(settings)
    modality.prepare()
    return dataset, modality, splits


def open_data(settings: Settings) -> tuple[PHAC2, Modality, dict[str, Split]]:
    """Open the data and check ``combine`` and every split, cheaply (before a run is created)."""
    dataset = DATA_SOURCES.build(settings.data.name, **settings.data.params)
    try:
        modality = MODALITIES.build(
            settings.modality.name,
            dataset=dataset,
            cache_dir=settings.cache_dir / "preprocessed",
            **settings.modality.params,
        )
    except (TypeError, ValueError) as err:
        raise param_error("modality", settings.modality.params, err) from err
    limit, unit = modality.max_combine()
    if settings.combine > limit:
        raise ConfigError(
            f"combine: {settings.combine} {unit} per unit, but objects in {dataset.path} have at "
            f"most {limit} {unit}; allowed 1..{limit}"
        )
    splits = {
        a: make_split(dataset, a, settings.split, settings.seed, **settings.split_params)
        for a in settings.adjectives
    }
    return dataset, modality, splits


def run(settings: Settings) -> JobResult:
    """Run (or skip, if already FINISHED) one job and log it to MLflow."""
    tracker = Tracker(settings.tracking.uri, settings.tracking.experiment)
    if settings.tracking.skip_finished:
        identity = DATA_SOURCES.build(settings.data.name, **settings.data.params).identity()
        done = tracker.finished_run(settings.config_hash, data_identity=identity)
        if done is not None:
            log.info(
                "skipping %s: run %s already FINISHED with this config on this data file",
                settings.run_name,
                done,
            )
            _log_view(tracker, settings)
            return JobResult(
                done, float("nan"), {}, skipped=True, val_aucs=_val_aucs(tracker, done)
            )
    tracker.end_stale_runs(settings.config_hash)
    store.claim_lease(settings.resolved)  # a bad value is an error before any run is created
    dataset, modality, splits = open_data(settings)

    params = {**flatten(settings.resolved), **key_params(settings)}
    tags = {
        "config_hash": settings.config_hash,
        "row_hash": settings.row_hash,
        "run_level": "parent",
        "sweep_id": settings.sweep_id,
        "overrides": " ".join(settings.overrides)[:5000],  # what the report calls a variant
        "device": device_name(settings.resolved["device"]),  # what device=auto picked here
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
        modality.prepare()
        tracker.set_tags(parent_id, {"data.identity": dataset.identity()})
        _log_data(tracker, parent_id, dataset)
        results: dict[str, AdjectiveResult] = {}
        for i, result in enumerate(_adjectives(settings, tracker, parent_id, modality, splits), 1):
            results[result.adjective] = result
            log.info(
                "[%d/%d] %s AUC %.3f (%.1f s)",
                i,
                len(settings.adjectives),
                result.adjective,
                result.auc,
                result.sizes["seconds"],
            )
        aucs = {a: r.auc for a, r in results.items()}
        mean = evaluate.mean_auc(aucs)
        held_out = {a: stats.HeldOut(r.objects, r.y, r.scores) for a, r in results.items()}
        ci = stats.mean_interval([held_out])  # over test objects (issue 27)
        tracker.log_metrics(
            parent_id,
            {"mean_auc": mean, **{f"auc.{a}": v for a, v in aucs.items()}, **_means(results)}
            | {"mean_auc_ci_low": ci.low, "mean_auc_ci_high": ci.high},
        )
        _log_summary(tracker, parent_id, settings, dataset, results)
        log.info("mean AUC over %d adjectives: %.4f", len(aucs), mean)
    val_aucs = {
        a: r.diagnostics["val_auc"] for a, r in results.items() if "val_auc" in r.diagnostics
    }
    _log_view(tracker, settings)
    return JobResult(parent_id, mean, results, val_aucs=val_aucs)


def _val_aucs(tracker: Tracker, parent_id: str) -> dict[str, float]:
    """A finished job's per-adjective validation AUCs, from its adjectives' runs."""
    runs = tracker.client.search_runs(
        [tracker.experiment_id],
        filter_string=f"tags.mlflow.parentRunId = '{parent_id}' and tags.run_level = 'child'",
        max_results=1000,
    )
    return {
        r.data.tags["adjective"]: r.data.metrics["val_auc"]
        for r in runs
        if "val_auc" in r.data.metrics
    }


def key_params(settings: Settings) -> dict[str, str]:
    """The params that say which job a run belongs to: the config-group choices (``choice.*``,
    none left at None) and every axis the job sets (``axis.*``: a sweep's swept values, plain
    ones like ``combine`` too), which sort first among the params that differ, so the compare
    view's parallel-coordinates plot, which starts on the first three of those, shows them."""
    out = {f"choice.{k}": v for k, v in settings.choices.items() if v != "None"}
    out.update({f"axis.{k}": v[:MAX_PARAM_LENGTH] for k, v in settings.axes.items()})
    return out


def _log_data(tracker: Tracker, run_id: str, dataset: PHAC2) -> None:
    tracker.log_dataset(
        run_id,
        name=dataset.path.stem,
        digest=dataset.digest(),
        source=dataset.path.resolve().as_uri(),
    )


def _log_view(tracker: Tracker, settings: Settings) -> None:
    """The last lines of a job's log: where its sweep's runs table is, with its numbers."""
    columns = [canonical_column("metrics", "mean_auc")]
    columns += [canonical_column("params", f"axis.{k}") for k in settings.axes]
    if not settings.axes:
        columns += [canonical_column("params", k) for k in ("choice.model", "combine")]
    url = tracker.runs_view(
        columns,
        order_by=canonical_column("metrics", "mean_auc"),
        filter_string="tags.run_level = 'parent'",
    )
    log.info("runs table (jobs by mean AUC, with what each sets): %s", url)
    if not tracker.uri.startswith(("http://", "https://")):
        log.info("  serve it first: mlflow ui --backend-store-uri %s", tracker.uri)
    log.info("  (MLflow opened without this link shows its GenAI Overview: click 'Model training')")


def _adjectives(
    settings: Settings,
    tracker: Tracker,
    parent_id: str,
    modality: Modality,
    splits: Mapping[str, Split],
) -> Iterator[AdjectiveResult]:
    """Each adjective's result, in order: here, or ``settings.workers`` at a time in worker
    processes (``tactile_exp.workers``) that open the data and the tracking store once each."""
    n = len(settings.adjectives)
    processes = min(settings.workers, n)
    if processes == 1:
        for i, adjective in enumerate(settings.adjectives, start=1):
            log.info("[%d/%d] %s", i, n, adjective)
            yield _run_adjective(settings, tracker, parent_id, modality, splits[adjective])
        return
    pool = workers.Pool(processes, init=_open_in_worker, initargs=(settings, parent_id))
    log.info("%d adjectives in %d worker processes", n, processes)
    try:
        with pool:
            calls = [(i, n, a) for i, a in enumerate(settings.adjectives, start=1)]
            yield from pool.map(_adjective_in_worker, calls)
    except BaseException:
        error = "a worker was stopped before it ended this run (the job failed or was terminated)"
        tracker.end_runs_of(pool.pids, error=error)
        raise


_WORKER: dict[str, Any] = {}  # what a worker process opened once: see _open_in_worker


def _open_in_worker(settings: Settings, parent_id: str) -> None:
    for module in component_modules(settings.resolved):
        importlib.import_module(module)
    with warnings.catch_warnings():  # the job's own load() has already shown them
        warnings.simplefilter("ignore")
        _, modality, splits = load(settings)
    _WORKER.update(
        settings=settings,
        tracker=Tracker(settings.tracking.uri, settings.tracking.experiment),
        parent_id=parent_id,
        modality=modality,
        splits=splits,
    )


def _adjective_in_worker(i: int, n: int, adjective: str) -> AdjectiveResult:
    log.info("[%d/%d] %s (worker %d)", i, n, adjective, os.getpid())
    w = _WORKER
    return _run_adjective(
        w["settings"], w["tracker"], w["parent_id"], w["modality"], w["splits"][adjective]
    )


def _run_adjective(
    settings: Settings, tracker: Tracker, parent_id: str, modality: Modality, split: Split
) -> AdjectiveResult:
    termination.check()
    adjective = split.adjective
    reuse = store.reuse_enabled(settings.resolved)
    model = MODELS.build(settings.model.name, **settings.model.params)
    key = store.training_key(
        dataset=modality.dataset.identity(),
        modality=settings.modality,
        model=settings.model,
        split=settings.split_key,
        validation=settings.validation_fraction,
        seed=settings.seed,
        adjective=adjective,
    )
    tags = {
        "config_hash": settings.config_hash,
        "run_level": "child",
        "adjective": adjective,
        "job": settings.run_name,  # a child found alone says which job it is part of
        "sweep_id": settings.sweep_id,
    }
    params = {"adjective": adjective, "combine": str(settings.combine), "seed": str(settings.seed)}
    params.update(key_params(settings))
    trains = model.storable and (
        model.learns_representation or COMBINERS.build(settings.combiner).keeps_instances
    )
    if trains:
        tags["training_key"] = key
    with tracker.run(f"adj={adjective}", params, tags, parent_id) as run_id:
        _log_data(tracker, run_id, modality.dataset)
        start = time.perf_counter()
        parts: dict[str, tuple[str, Model]] = {}
        modality.use_parts(_part_provider(settings, tracker, parent_id, run_id, modality, parts))
        # Held-out training objects score the model without touching the test objects (issue 13).
        fit_split, val_trials = validation_split(
            split, fraction=settings.validation_fraction, seed=settings.seed
        )
        train, rest = modality.instances(
            Split(adjective, fit_split.train, split.test + val_trials, split.labels)
        )
        val, test = take_trials(rest, val_trials)
        sets = {"test": test, "train": train, **({"val": val} if len(val) else {})}
        # This run, tagged with the key, is its claim: wait while an older live job trains it.
        lease = store.claim_lease(settings.resolved)
        source = (
            store.await_trained(tracker, key, run_id, lease=lease) if reuse and trains else None
        )
        if source is not None:
            log.info("  %s: reusing the model trained in run %s", adjective, source)
            tracker.set_tags(run_id, {"reused_from": source})
            model = store.load_model(
                tracker, source, "model", overrides=_unkeyed(settings.model.params)
            )
            history: History = {}
        else:
            history = fit_model(model, settings.combiner, train, _epoch_logger(adjective)) or {}
        scored, head, head_history = score(
            model, settings.combiner, settings.combine, train, sets, pad=modality.pad_units
        )
        history.update(head_history)
        scores, units = scored["test"]
        auc = evaluate.auc(units.y, scores)
        diagnostics = _diagnostics(scored)
        sizes = {
            "n_train_instances": len(train),
            "n_test_instances": len(test),
            "n_train_trials": len(fit_split.train),
            "n_test_trials": len(split.test),
            "n_train_objects": len(fit_split.objects("train")),
            "n_test_objects": len(split.objects("test")),
            "n_test_units": len(units),
            "n_test_positive_units": int(units.y.sum()),
            "n_val_objects": len(np.unique(val.object_id)),
            "n_val_positive_objects": len(np.unique(val.object_id[val.y == 1])),
            "seconds": time.perf_counter() - start,
        }
        tracker.log_metrics(run_id, {"auc": auc, **sizes, **diagnostics, **modality.metrics()})
        log.info("  %s %s", adjective, " ".join(f"{k}={v:.3f}" for k, v in diagnostics.items()))
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
        _keep_models(settings, tracker, run_id, modality, model if trains else None, head, parts)
    return AdjectiveResult(
        adjective, auc, units.y, scores, units.trial, units.object_id, sizes, history, diagnostics
    )


def _unkeyed(params: dict[str, Any]) -> dict[str, Any]:
    """The model settings a reused model takes from this job (not from where it was trained)."""
    return store.unkeyed(params)


def _part_provider(
    settings: Settings,
    tracker: Tracker,
    parent_id: str,
    run_id: str,
    modality: Modality,
    parts: dict[str, tuple[str, Model]],
) -> PartProvider:
    """A modality's trained parts (row M's ConvNet): found by training key, else trained here
    in a run of their own (run_level=part, tagged with the key), so any later job finds them."""

    def provide(part: str, split: Split, train: Instances) -> Model:
        part_modality, part_model = modality.parts()[part]
        key = store.training_key(
            dataset=modality.dataset.identity(),
            modality=part_modality,
            model=part_model,
            split=settings.split_key,
            validation=settings.validation_fraction,
            seed=settings.seed,
            adjective=split.adjective,
        )
        name = f"{split.adjective}/{part}"
        reuse = store.reuse_enabled(settings.resolved)
        source = store.find_trained(tracker, key) if reuse else None
        model = None
        if source is None:
            tags = {
                "config_hash": settings.config_hash,
                "run_level": "part",
                "adjective": split.adjective,
                "part": part,
                "training_key": key,
            }
            with tracker.run(f"adj={name}", {"adjective": split.adjective}, tags, parent_id) as rid:
                # This run is the key's claim: wait while an older live job trains the part.
                lease = store.claim_lease(settings.resolved)
                source = store.await_trained(tracker, key, rid, lease=lease) if reuse else None
                if source is None:
                    model = MODELS.build(part_model.name, **part_model.params)
                    tracker.log_curves(rid, model.fit(train, _epoch_logger(name)))
                    store.log_folder(
                        tracker,
                        rid,
                        "model",
                        lambda f: store.write_model(f, part_model.name, model),
                    )
                    source = rid
                else:
                    tracker.set_tags(rid, {"reused_from": source})
        if model is None:
            log.info("  %s: reusing the model trained in run %s", name, source)
            tracker.set_tags(run_id, {f"reused_from.{part}": source})
            model = store.load_model(
                tracker, source, "model", overrides=_unkeyed(part_model.params)
            )
        tracker.set_tags(run_id, {f"part.{part}": source})
        parts[part] = (part_model.name, model)
        return model

    return provide


def _keep_models(
    settings: Settings,
    tracker: Tracker,
    run_id: str,
    modality: Modality,
    model: Model | None,
    head: Model | None,
    parts: dict[str, tuple[str, Model]],
) -> None:
    """What applies this adjective's classifier to new data, as artifacts of its run: the model
    (``model/``), the head (``head/``), the parts (``parts/<part>/``) and the fitted
    preprocessing (``preprocess/``). The run turns FINISHED only after all are written, and
    lookups take FINISHED runs only, so a job killed while writing leaves nothing reusable."""
    if model is not None:
        store.log_folder(
            tracker, run_id, "model", lambda f: store.write_model(f, settings.model.name, model)
        )
    if head is not None and head.storable:
        write = functools.partial(store.write_model, name=store.model_name(head), model=head)
        store.log_folder(tracker, run_id, "head", write)
    for part, (name, fitted) in parts.items():
        write = functools.partial(store.write_model, name=name, model=fitted)
        store.log_folder(tracker, run_id, f"parts/{part}", write)
    state, arrays = modality.state()
    if state:
        store.log_folder(
            tracker, run_id, "preprocess", lambda f: store.write_state(f, state, arrays)
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


def _diagnostics(scored: Mapping[str, tuple[np.ndarray, Instances]]) -> dict[str, float]:
    """Training AUC, and the held-out training objects' AUC when they hold both classes."""
    out = {}
    for name in ("train", "val"):
        if name in scored and len(np.unique(scored[name][1].y)) == 2:
            scores, units = scored[name]
            out[f"{name}_auc"] = evaluate.auc(units.y, scores)
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
