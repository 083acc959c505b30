"""One job: every adjective's run (``recording.record_adjective``: split, fitted pipeline,
scores, metrics) under one parent run, with the job's summary (T1, T4, E1, E2).

Runs without Hydra: it takes the plain ``Settings`` built by ``tactile_exp.config``.
"""

from __future__ import annotations

import importlib
import logging
import os
import time
import warnings
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from tactile_exp import metrics, recording, store
from tactile_exp.config import Settings
from tactile_exp.core import (
    AdjectiveResult,
    ignored_schedule_keys,
    kernels,
    load,
    model_key,
    new_pipeline,
    open_data,
    open_modality,
    stores_model,
)
from tactile_exp.data.dataset import select_labels
from tactile_exp.data.layout import Split
from tactile_exp.data.splits import object_counts
from tactile_exp.models.schedule import STEPS, Schedule
from tactile_exp.runtime import memory, workers

log = logging.getLogger(__name__)


@dataclass
class JobResult:
    run_id: str | None
    results: dict[str, AdjectiveResult]  # fitted pipelines released: kept in their runs
    means: dict[str, float] = field(default_factory=dict)  # mean_<key> over adjectives, ...
    skipped: bool = False
    # Per adjective, the held-out validation objects' metrics by key (those defined on them: AUC
    # where they hold both classes): what the job's objective is computed from
    # (tactile_exp.objective); read back from the runs when the job is skipped.
    validation: dict[str, dict[str, float]] = field(default_factory=dict)


def label_notes(settings: Settings, dataset: Any, splits: Mapping[str, Split]) -> dict[str, str]:
    """Tags on the job's run, each logged once as a warning line: the labels
    ``labels.min_objects`` dropped, with their object counts (``labels.dropped``), and those
    scored on trials of an object seen in training (``labels.seen_object``: a class of one
    object, split by trial). How the split was resolved (``split.resolved``: what
    ``split=declared`` chose, a frozen folds file's digest) is tagged too, printed once when the
    job starts."""
    notes = {"split.resolved": settings.split_note} if settings.split_note else {}
    dropped = [a for a in select_labels(dataset, settings.adjectives) if a not in splits]
    if dropped:
        counts = " ".join(
            f"{a}(+{p}/-{n})" for a in dropped for p, n in [object_counts(dataset, a)]
        )
        notes["labels.dropped"] = f"{counts} min_objects={settings.min_objects}"
        log.warning(
            "labels.min_objects=%d: %d label(s) with fewer positive or negative objects dropped: "
            "%s",
            settings.min_objects,
            len(dropped),
            counts,
        )
    seen = [a for a, s in splits.items() if s.objects("train") & s.objects("test")]
    if seen:
        notes["labels.seen_object"] = " ".join(seen)
        log.warning(
            "%d label(s) have one object of a class, split by trial: scored on trials of an "
            "object seen in training: %s",
            len(seen),
            " ".join(seen),
        )
    return notes


def schedule_notes(settings: Settings) -> dict[str, str]:
    """A tag on the job's run, logged once as a warning line: the ``schedule.<key>`` overrides
    that nothing the job trains reads (``core.ignored_schedule_keys``), and what it trains by
    instead (``schedule.ignored``)."""
    ignored = ignored_schedule_keys(settings)
    if not ignored:
        return {}
    model, combiner = settings.model.name, settings.combiner
    if new_pipeline(settings).trains_model:
        instead = (
            f"combine_instances={combiner} scores every instance with model={model} itself, "
            "trained by schedule.<key>, and trains no head"
        )
    else:
        head = Schedule.of(settings.model.params["schedule"]).for_head()
        steps = " ".join(f"{k}={getattr(head, k)}" for k in STEPS)
        instead = (
            f"model={model} learns no representation, so under combine_instances={combiner} "
            f"only its T4 head is trained, by schedule.head.<key> ({steps})"
        )
    log.warning("%s: set, but read by nothing this job trains: %s", " ".join(ignored), instead)
    return {"schedule.ignored": " ".join(ignored)}


def run(settings: Settings) -> JobResult:
    """Run (or skip, if already FINISHED) one job and log it to MLflow."""
    if settings.split_note:
        log.info("split: %s", settings.split_note)
    start = time.perf_counter()
    modality = open_modality(settings)
    compiled = kernels(settings, modality)
    if compiled:  # a first compile (empty cache) overlaps generating, opening and preprocessing
        from tactile_exp.models.numba_setup import compile_ahead

        compile_ahead(compiled)
    dataset, modality, splits = open_data(settings, modality)  # generated on first use
    phases = {"data (generated on first use)": time.perf_counter() - start}
    tracker = recording.open_tracker(settings)
    if settings.tracking.skip_finished:
        done = recording.finished_job(tracker, settings, dataset.identity())
        if done is not None and not settings.is_trial and not tracker.child_metrics(done, "auc"):
            done = None  # a search trial's job: it logged no test metric, so run it again
        if done is not None:
            log.info(
                "skipping %s: run %s already FINISHED with this config on this data file",
                settings.run_name,
                done,
            )
            recording.log_view(tracker, settings)
            validation = recording.val_metrics(tracker, done, settings.metrics)
            return JobResult(done, {}, skipped=True, validation=validation)
    tracker.end_stale_runs(settings.config_hash)
    with recording.job_run(tracker, settings) as parent_id:
        start = time.perf_counter()
        modality.check(dataset)
        memory.give_back()  # the trials read and freed while preprocessing
        phases["preprocessing"] = time.perf_counter() - start
        start = time.perf_counter()
        notes = label_notes(settings, dataset, splits) | schedule_notes(settings)
        recording.record_data(tracker, parent_id, dataset, notes)
        results: dict[str, AdjectiveResult] = {}
        headline = metrics.METRICS.build(settings.metrics[0])
        trial = settings.is_trial
        # A search trial shows and logs its validation AUC only: test metrics wait for the
        # study's final evaluation.
        shown, label = ("auc", "validation AUC") if trial else (headline.key, headline.label)
        # Not enumerate: its reused tuple would hold the last result, and with it its
        # pipeline (model, training units), while the next adjective is fitted.
        for result in _adjectives(settings, tracker, parent_id, dataset, splits):
            results[result.adjective] = replace(result, pipeline=None)  # kept in its run
            values = result.sides["val"].metrics if trial and "val" in result.sides else {}
            shown_value = values.get("auc", float("nan")) if trial else result.metrics[shown]
            log.info(
                "[%d/%d] %s %s %.3f (%.1f s)",
                len(results),
                len(splits),
                result.adjective,
                label,
                shown_value,
                result.sizes["seconds"],
            )
            del result  # its pipeline (model, training units) freed before the next adjective
            memory.give_back()  # what the last adjective's pipeline freed
        results = {a: results[a] for a in splits}  # the adjectives' order, whichever ran first
        phases[f"{len(results)} adjectives"] = time.perf_counter() - start
        log.info(
            "phases: %s", ", ".join(f"{name} {seconds:.1f} s" for name, seconds in phases.items())
        )
        means = recording.record_summary(tracker, parent_id, settings, dataset, results)
        if not trial:
            key = headline.key
            log.info("mean %s over %d adjectives: %.4f", label, len(results), means[f"mean_{key}"])
    validation = {a: r.sides["val"].metrics for a, r in results.items() if "val" in r.sides}
    recording.log_view(tracker, settings)
    return JobResult(parent_id, results, means, validation=validation)


def _adjectives(
    settings: Settings,
    tracker: recording.Tracker,
    parent_id: str,
    dataset: Any,
    splits: Mapping[str, Split],
) -> Iterator[AdjectiveResult]:
    """Each adjective's result, in order: here, or ``settings.workers`` at a time in worker
    processes (``runtime.workers``) that open the data and the tracking store once each."""
    n = len(splits)
    processes = min(settings.workers, n)
    if processes == 1:
        for i, adjective in enumerate(_in_turn(settings, tracker, dataset, splits), start=1):
            log.info("[%d/%d] %s", i, n, adjective)
            yield recording.record_adjective(
                settings, tracker, parent_id, dataset, splits[adjective]
            )
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


def _in_turn(
    settings: Settings, tracker: recording.Tracker, dataset: Any, splits: Mapping[str, Split]
) -> Iterator[str]:
    """The adjectives in order, each looked at just before its turn; one whose model another
    live job is training at that moment (``store.training_elsewhere``) is put off until the
    others are done, then waited for as usual. Jobs side by side that need the same models
    (rows H and I) thus train different ones instead of one job idling while the other trains."""
    if not (settings.tracking.reuse and stores_model(settings)):
        yield from splits
        return
    put_off = []
    for adjective in splits:
        key = model_key(settings, dataset, adjective)
        holder = store.training_elsewhere(tracker, key, lease=settings.tracking.claim_lease)
        if holder is None:
            yield adjective
        else:
            log.info("  %s: run %s trains its model; taken after the others", adjective, holder)
            put_off.append(adjective)
    yield from put_off


_WORKER: dict[str, Any] = {}  # what a worker process opened once: see _open_in_worker


def _open_in_worker(settings: Settings, parent_id: str) -> None:
    for module in settings.modules:
        importlib.import_module(module)
    with warnings.catch_warnings():  # the job's own load() has already shown them
        warnings.simplefilter("ignore")
        dataset, _, splits = load(settings)
    _WORKER.update(
        settings=settings,
        tracker=recording.open_tracker(settings),
        parent_id=parent_id,
        dataset=dataset,
        splits=splits,
    )


def _adjective_in_worker(i: int, n: int, adjective: str) -> AdjectiveResult:
    log.info("[%d/%d] %s (worker %d)", i, n, adjective, os.getpid())
    w = _WORKER
    result = recording.record_adjective(
        w["settings"], w["tracker"], w["parent_id"], w["dataset"], w["splits"][adjective]
    )
    return replace(result, pipeline=None)  # kept in its run; not sent back to the job
