"""Apply a finished job's fitted pipelines to new trials or photographs (the robot pipeline).

``predict(run_id=..., data=FILE, trials=[...])`` (or ``object_id=``) for haptic jobs, ``photos=DIR``
for visual ones, both for multimodal ones: each adjective's child run keeps its fitted
``AdjectivePipeline``, which scores the new units exactly as it scored the job's test units, so
a test trial's score equals the one in the job's ``scores.csv``. Decision value > 0 means the
adjective applies. ``python -m tactile_exp.predict --help`` is the command line.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from tactile_exp.data.layout import DataError, Trials
from tactile_exp.data.photos import PhotoFolder
from tactile_exp.data.sources import open_path
from tactile_exp.jobs import PredictError, StoredJob
from tactile_exp.modalities import MODALITIES
from tactile_exp.pipeline import AdjectivePipeline
from tactile_exp.predict.prediction import Prediction, object_of, true_labels, unit_names


def predict(
    *,
    run_id: str | None = None,
    experiment: str = "tactile_exp",
    tracking_uri: str | None = None,
    data: str | Path | None = None,
    trials: Sequence[str] = (),
    object_id: int | None = None,
    photos: str | Path | None = None,
    adjectives: Sequence[str] | None = None,
) -> Prediction:
    """Scores of each adjective of job ``run_id`` (default: the newest FINISHED job of
    ``experiment``) for ``trials`` (or all trials of ``object_id``) of the data file ``data``
    (default: the job's own), for the photographs in folder ``photos``, or for both, of one
    object (rows M, N). Row O (random guess) is refused: it keeps no model."""
    job = StoredJob.open(run_id, experiment=experiment, tracking_uri=tracking_uri)
    job.check_applicable()
    data_line = ""
    if MODALITIES[job.modality].takes_trials:
        data, data_line = _data_file(job, data)
    given = new_trials(
        job.modality, data=data, trials=trials, object_id=object_id, photos=photos, job=job.id,
        source=job.config.get("data"),
    )  # fmt: skip
    scored = apply(job.pipelines(adjectives), given)
    chosen = "" if run_id is not None else (
        f"no run id given: the newest FINISHED job of experiment {experiment!r}"
    )  # fmt: skip
    objects = [object_of(u) for u in scored.units]
    names = {o: given.dataset.object_name(o) for o in objects if o is not None}
    return replace(
        scored, run_id=job.id, job=job.describe(), chosen=chosen, data=data_line, objects=objects,
        object_names=names, labels=true_labels(given, objects, scored.adjectives),
    )  # fmt: skip


def new_trials(
    modality_name: str,
    *,
    data: str | Path | None,
    trials: Sequence[str],
    object_id: int | None,
    photos: str | Path | None,
    job: str,
    source: Mapping[str, Any] | None = None,
) -> Trials:
    """The new object's trials and/or photographs, as job ``job``'s modality takes them.
    ``source``: the job's ``data`` node, whose source reads ``data`` first (`open_path`)."""
    modality = MODALITIES[modality_name]
    if modality.takes_trials and not (trials or object_id is not None):
        wanted = (
            "and a folder of its photographs" if modality.takes_photographs else "not photographs"
        )
        raise PredictError(
            f"run {job} holds {modality_name} models (modality {modality_name}): give trials "
            f"(--trial NAME, repeated, or --object ID), {wanted}"
        )
    if modality.takes_photographs and photos is None:
        wanted = (
            "and the object's trials (data with trials)" if modality.takes_trials else "not trials"
        )
        raise PredictError(
            f"run {job} holds {modality_name} models (modality {modality_name}): give a folder of "
            f"photographs {wanted}"
        )
    try:
        if not modality.takes_trials:
            return Trials(PhotoFolder(str(photos)), (), object_ids=(0,))
        dataset: Any = _open(data, source)
        names = [dataset.trial_name(t) for t in trials]
        if object_id is not None:
            names += [t for t in dataset.trials if t.object_id == object_id and t not in names]
            if not any(t.object_id == object_id for t in names):
                raise PredictError(f"{data}: no trials of object {object_id}")
        objects = sorted({t.object_id for t in names})
        if modality.takes_photographs:
            if len(objects) != 1:
                raise PredictError(
                    "a multimodal unit joins trials of one object with that object's photographs; "
                    f"the trials given are of objects {objects}"
                )
            dataset = PhotoFolder(str(photos), trials=dataset, object_id=objects[0])
    except DataError as err:
        raise PredictError(str(err)) from None
    return Trials(dataset, tuple(t.name for t in names))


def apply(pipelines: Mapping[str, AdjectivePipeline], given: Trials) -> Prediction:
    """Each adjective's scores of ``given``'s units (one column per adjective)."""
    columns, units = [], None
    for adjective, pipeline in pipelines.items():
        try:
            scores, units = pipeline.decision_function(given)
        except DataError as err:
            raise PredictError(str(err)) from None
        except (KeyError, ValueError) as err:
            raise PredictError(f"{given.dataset.path}: {adjective}: {err}") from None
        columns.append(scores)
    first = next(iter(pipelines.values()))
    by_object = not first.keeps_instances and first.combine > 1
    names = unit_names(units, by_object=by_object)  # type: ignore[arg-type]
    return Prediction("", names, list(pipelines), np.column_stack(columns))


def _open(data: str | Path | None, source: Mapping[str, Any] | None) -> Any:
    """``data`` read by the job's own data source if it reads such a path (a plugin's: its
    ``_module_`` imported with the job, ``StoredJob.read``), else by any registered source
    that does."""
    node = dict(source or {})
    node.pop("_module_", None)
    name = node.pop("name", None)
    params = {k: v for k, v in node.items() if k != "path"}
    return open_path(str(data), None if name is None else str(name), params)


def _data_file(job: StoredJob, data: str | Path | None) -> tuple[str | Path, str]:
    """The data file to read trials from: the one given, else the job's own while it exists."""
    if data is not None:
        return data, f"{data} (given)"
    recorded = job.data_file()
    if recorded is None:
        raise PredictError(f"run {job.id} records no data file: give --data PATH")
    if not recorded.exists():
        raise PredictError(f"the job's data file {recorded} is no longer there: give --data PATH")
    return recorded, f"{recorded} (the job's own data file; --data to read another)"
