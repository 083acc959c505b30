"""Apply a finished job's kept models to new trials or photographs (the paper's robot pipeline).

``predict(run_id=..., data=FILE, trials=[...])`` (or ``object_id=``) for haptic jobs, ``photos=DIR``
for visual ones: each adjective's child run gives its fitted preprocessing (``preprocess/``), its
model (``model/``) and head (``head/``), applied exactly as the job applied them to its test
units, so a test trial's score equals the one in the job's ``scores.csv``. Decision value > 0
means the adjective applies. ``python -m tactile_exp.predict --help`` is the command line.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tactile_exp import store
from tactile_exp.data.layout import Instances, TrialName

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp")


class PredictError(ValueError):
    """Input or stored job that predict cannot use; the message says which and why."""


@dataclass
class Prediction:
    """Per-adjective scores of each unit (a trial, a group of trials, or an object's views)."""

    run_id: str
    units: list[str]
    adjectives: list[str]
    scores: np.ndarray  # (n_units, n_adjectives) decision values

    def predicted(self) -> list[list[str]]:
        """The adjectives whose decision value is > 0, per unit."""
        return [
            [a for a, s in zip(self.adjectives, row, strict=True) if s > 0] for row in self.scores
        ]

    def to_csv(self) -> str:
        out = io.StringIO()
        writer = csv.writer(out)
        writer.writerow(["unit", *self.adjectives, "predicted"])
        for unit, row, chosen in zip(self.units, self.scores, self.predicted(), strict=True):
            writer.writerow([unit, *(f"{s:.6f}" for s in row), " ".join(chosen)])
        return out.getvalue()

    def to_json(self) -> str:
        units = [
            {"unit": u, "scores": dict(zip(self.adjectives, map(float, row), strict=True)),
             "predicted": chosen}
            for u, row, chosen in zip(self.units, self.scores, self.predicted(), strict=True)
        ]  # fmt: skip
        return json.dumps({"run_id": self.run_id, "units": units}, indent=1)

    def to_table(self) -> str:
        lines = [f"job {self.run_id}"]
        for unit, chosen in zip(self.units, self.predicted(), strict=True):
            lines.append(f"{unit}: {', '.join(chosen) or '(none)'}")
        width = max(len(a) for a in self.adjectives)
        lines.append("")
        lines.append(" " * width + "  " + "  ".join(f"{u[-12:]:>12}" for u in self.units))
        for j, adjective in enumerate(self.adjectives):
            values = "  ".join(f"{s:>12.4f}" for s in self.scores[:, j])
            lines.append(f"{adjective:>{width}}  {values}")
        return "\n".join(lines) + "\n"


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
    ``experiment``) for ``trials`` (or all trials of ``object_id``) of the PHAC-2-layout file
    ``data``, or for the photographs in folder ``photos``."""
    tracker = _tracker(tracking_uri, experiment)
    job = _job(tracker, run_id)
    config = _config(tracker, job.info.run_id)
    children = _children(tracker, job.info.run_id, adjectives)
    modality = str(config["modality"]["name"])
    haptic_input = data is not None or trials or object_id is not None
    if modality == "haptic":
        if not haptic_input:
            raise PredictError(
                f"run {job.info.run_id} holds haptic models (modality haptic): give trials "
                "(data with trials or an object id), not photographs"
            )
        inputs = _haptic_inputs(data, trials, object_id, children, tracker)
    elif modality == "visual":
        if photos is None:
            raise PredictError(
                f"run {job.info.run_id} holds visual models (modality visual): give a folder "
                "of photographs, not trials"
            )
        inputs = _visual_inputs(Path(photos), children, tracker)
    else:
        raise PredictError(
            f"run {job.info.run_id}: modality {modality!r}; predict applies haptic and visual "
            "jobs (rows A-L need their own features, rows M and N both inputs: not supported yet)"
        )
    combiner, combine = str(config["combine_instances"]["name"]), int(config["combine"])
    model_name, model_params = config["model"]["name"], dict(config["model"])
    model_params.pop("name")
    units: list[str] = []
    columns = []
    for child in children.values():
        instances = inputs(child)
        scores, names = _apply(
            tracker, child, instances, combiner, combine, model_name, model_params
        )
        columns.append(scores)
        units = names
    return Prediction(job.info.run_id, units, list(children), np.column_stack(columns))


def _tracker(uri: str | None, experiment: str) -> Any:
    from mlflow.tracking import MlflowClient

    from tactile_exp.tracking import resolve_uri

    uri = resolve_uri(uri)
    client = MlflowClient(tracking_uri=uri)
    found = client.get_experiment_by_name(experiment)
    if found is None:
        raise PredictError(f"no experiment {experiment!r} in the tracking store {uri}")
    tracker = object.__new__(_Store)
    tracker.client, tracker.uri, tracker.experiment_id = client, uri, found.experiment_id
    return tracker


class _Store:
    """What ``store.load_model`` needs of a ``Tracker``, without creating any experiment."""

    client: Any
    uri: str
    experiment_id: str


def _job(tracker: Any, run_id: str | None) -> Any:
    from mlflow.exceptions import MlflowException

    if run_id is None:
        runs = tracker.client.search_runs(
            [tracker.experiment_id],
            "tags.run_level = 'parent' and attributes.status = 'FINISHED'",
            order_by=["attributes.start_time DESC"],
            max_results=1,
        )
        if not runs:
            raise PredictError(f"no FINISHED job in the tracking store {tracker.uri}")
        return runs[0]
    try:
        job = tracker.client.get_run(run_id)
    except MlflowException:
        raise PredictError(f"unknown run id {run_id} in the tracking store {tracker.uri}") from None
    if job.info.status != "FINISHED":
        raise PredictError(
            f"run {run_id} is {job.info.status}, not FINISHED: its models are incomplete"
        )
    if job.data.tags.get("run_level") != "parent":
        raise PredictError(f"run {run_id} is not a job (a parent run): give the job's run id")
    return job


def _config(tracker: Any, run_id: str) -> dict[str, Any]:
    import yaml

    folder = Path(tracker.client.download_artifacts(run_id, ""))
    try:
        config = yaml.safe_load((folder / "config.yaml").read_text())
    except (OSError, yaml.YAMLError) as err:
        raise store.ArtifactError(
            f"run {run_id}: artifact config.yaml unreadable ({err})"
        ) from None
    if not isinstance(config, dict) or "modality" not in config:
        raise store.ArtifactError(f"run {run_id}: artifact config.yaml is not a job's config")
    return config


def _children(tracker: Any, run_id: str, adjectives: Sequence[str] | None) -> dict[str, str]:
    runs = tracker.client.search_runs(
        [tracker.experiment_id],
        f"tags.mlflow.parentRunId = '{run_id}' and tags.run_level = 'child' "
        "and attributes.status = 'FINISHED'",
        max_results=1000,
    )
    found = {r.data.tags["adjective"]: r.info.run_id for r in runs}
    wanted = sorted(found) if adjectives is None else list(adjectives)
    missing = [a for a in wanted if a not in found]
    if missing or not wanted:
        raise PredictError(f"run {run_id} has no finished model for adjectives {missing or wanted}")
    return {a: found[a] for a in wanted}


class _Subset:
    """A PHAC-2 file's chosen trials, as ``compute_haptic_arrays`` reads a data set."""

    def __init__(self, dataset: Any, names: Sequence[TrialName]) -> None:
        self.dataset, self.trials = dataset, tuple(names)

    def iter_trials(self, names: Iterable[TrialName] | None = None) -> Iterator[Any]:
        return self.dataset.iter_trials(self.trials if names is None else names, optional=False)

    def identity(self) -> str:
        return self.dataset.identity()


def _haptic_inputs(
    data: str | Path | None,
    trials: Sequence[str],
    object_id: int | None,
    children: dict[str, str],
    tracker: Any,
) -> Any:
    from tactile_exp.data.phac2 import PHAC2, DataError
    from tactile_exp.preprocess.haptic import HapticPreprocessor, compute_haptic_arrays

    if data is None:
        raise PredictError("haptic models need data: a PHAC-2-layout file holding the trials")
    try:
        dataset = PHAC2(data)
        names = [dataset.trial_name(t) for t in trials]
    except DataError as err:
        raise PredictError(str(err)) from None
    if object_id is not None:
        names += [t for t in dataset.trials if t.object_id == object_id and t not in names]
        if not any(t.object_id == object_id for t in names):
            raise PredictError(f"{data}: no trials of object {object_id}")
    if not names:
        raise PredictError("give at least one trial (trials=...) or an object id")
    first = next(iter(children.values()))
    settings = store.read_json(
        store.download(tracker, first, "preprocess", store.STATE_FILES),
        f"run {first}: artifact preprocess",
    )
    try:
        arrays = compute_haptic_arrays(
            _Subset(dataset, names), settings["steps"], settings["offsets"],
            settings["pac_downsample"],
        )  # fmt: skip
    except (DataError, ValueError, KeyError) as err:
        raise PredictError(f"{data}: a trial lacks what the models need: {err}") from None

    def instances(child: str) -> Instances:
        where = f"run {child}: artifact preprocess"
        folder = store.download(tracker, child, "preprocess", store.STATE_FILES)
        state = store.read_json(folder, where)
        try:
            pre = HapticPreprocessor(arrays, state["pca_components"], state["per_finger"])
            pre.restore(store.read_arrays(folder, where))
        except (KeyError, ValueError) as err:
            raise store.ArtifactError(f"{where}: {err}") from None
        X = pre.transform(names)
        per_trial = X.shape[1] * X.shape[2]
        trial = np.repeat(np.array([t.name for t in names], dtype=object), per_trial)
        obj = np.repeat([t.object_id for t in names], per_trial)
        return Instances(X.reshape(-1, *X.shape[3:]), np.zeros(len(trial), np.int64), trial, obj)

    return instances


def read_photographs(folder: Path, size: int) -> tuple[list[Path], np.ndarray]:
    """The photographs in ``folder`` cropped above the plate and resized (V1): (n, 3, s, s)."""
    from tactile_exp.data.phac2 import DataError, load_photograph
    from tactile_exp.preprocess.visual import crop_plate, find_plate, resize_square

    if not folder.is_dir():
        raise PredictError(f"{folder}: no such folder of photographs")
    paths = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not paths:
        raise PredictError(f"{folder}: no photographs ({', '.join(IMAGE_SUFFIXES)} files)")
    images = np.empty((len(paths), 3, size, size), dtype=np.uint8)
    for i, path in enumerate(paths):
        try:
            image = load_photograph(path)
            images[i] = resize_square(crop_plate(image, find_plate(image)), size).transpose(2, 0, 1)
        except DataError as err:
            raise PredictError(str(err)) from None
        except ValueError as err:
            raise PredictError(f"{path}: {err}") from None
    return paths, images


def _visual_inputs(folder: Path, children: dict[str, str], tracker: Any) -> Any:
    from tactile_exp.models.googlenet import build_trunk, network_input, pooled_features

    first = next(iter(children.values()))
    where = f"run {first}: artifact preprocess"
    state = store.read_json(store.download(tracker, first, "preprocess", store.STATE_FILES), where)
    paths, images = read_photographs(folder, int(state["size"]))
    weights = state["weights"]
    if weights is not None and not Path(weights).is_file():
        raise PredictError(f"{where}: the GoogLeNet weights file {weights} is not there")
    trunk = build_trunk(None if weights is None else Path(weights), state["seed"], state["layout"])
    by_mean: dict[tuple[float, ...], np.ndarray] = {}

    def instances(child: str) -> Instances:
        folder_ = store.download(tracker, child, "preprocess", store.STATE_FILES)
        mean = tuple(float(m) for m in store.read_arrays(folder_, where)["channel_mean"])
        if mean not in by_mean:
            by_mean[mean] = pooled_features(trunk, network_input(images, mean, state["layout"]))
        names = np.array([f"{folder.name}_v{i:02d}" for i in range(len(paths))], dtype=object)
        n = len(paths)
        return Instances(by_mean[mean], np.zeros(n, np.int64), names, np.zeros(n, np.int64))

    return instances


def _apply(
    tracker: Any,
    child: str,
    instances: Instances,
    combiner: str,
    combine: int,
    model_name: str,
    model_params: dict[str, Any],
) -> tuple[np.ndarray, list[str]]:
    from tactile_exp.combine import COMBINERS
    from tactile_exp.models.registry import MODELS

    combine_units = COMBINERS.build(combiner)
    listed = {a.path for a in tracker.client.list_artifacts(child)}
    if "model" in listed:
        model = store.load_model(tracker, child, "model")
    else:  # a model that learns nothing before its head (visual_googlenet, linear)
        model = MODELS.build(model_name, **model_params)
    if combine_units.keeps_instances:
        names = [str(t) for t in instances.trial]
        if len(set(names)) < len(names):  # a trial's instances (fingers x offsets): <trial>#<k>
            counts: dict[str, int] = {}
            for i, t in enumerate(names):
                counts[t] = counts.get(t, -1) + 1
                names[i] = f"{t}#{counts[t]}"
        return model.decision_function(instances.X), names
    units = combine_units(model.transform(instances.X), instances, combine)
    head = store.load_model(tracker, child, "head")
    return head.decision_function(units.X), [str(t) for t in units.trial]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m tactile_exp.predict",
        description="Per-adjective scores of new trials or photographs from a finished job.",
    )
    parser.add_argument("run_id", nargs="?", help="the job's (parent) run id; default: newest")
    parser.add_argument("--experiment", default="tactile_exp", help="MLflow experiment name")
    parser.add_argument("--tracking-uri", help="MLflow store (default: as the jobs use)")
    parser.add_argument("--data", help="a PHAC-2-layout HDF5 file holding the trials")
    parser.add_argument("--trial", action="append", default=[], help="a trial group (repeat)")
    parser.add_argument("--object", type=int, help="all trials of this object id")
    parser.add_argument("--photos", help="a folder of one object's photographs")
    parser.add_argument("--adjective", action="append", help="only these adjectives (repeat)")
    parser.add_argument("--format", choices=("table", "csv", "json"), default="table")
    parser.add_argument("--out", help="write here instead of standard output")
    args = parser.parse_args(argv)
    try:
        result = predict(
            run_id=args.run_id, experiment=args.experiment, tracking_uri=args.tracking_uri,
            data=args.data, trials=args.trial, object_id=args.object, photos=args.photos,
            adjectives=args.adjective,
        )  # fmt: skip
    except (PredictError, store.ArtifactError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    text = {"table": result.to_table, "csv": result.to_csv, "json": result.to_json}[args.format]()
    if args.out:
        Path(args.out).write_text(text)
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
