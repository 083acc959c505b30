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
import functools
import io
import json
import sys
import urllib.parse
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
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
    job: str = ""  # the job as a person knows it: run name, model, combine, Table I row
    chosen: str = ""  # how the job was chosen when no run id was given
    data: str = ""  # the data file the trials were read from, and why that one
    objects: list[int | None] = field(default_factory=list)  # each unit's object, when known
    object_names: dict[int, str] = field(default_factory=dict)  # object -> e.g. car_sponge_101
    labels: dict[int, list[str]] = field(default_factory=dict)  # object -> its true adjectives

    def object_predictions(self) -> dict[int, list[str]]:
        """Per object: the adjectives whose mean decision value over its units is > 0."""
        out = {}
        for obj in dict.fromkeys(o for o in self.objects if o is not None):
            rows = [i for i, o in enumerate(self.objects) if o == obj]
            mean = self.scores[rows].mean(axis=0)
            out[obj] = [a for a, s in zip(self.adjectives, mean, strict=True) if s > 0]
        return out

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
        head = {"run_id": self.run_id, "job": self.job, "data": self.data}
        return json.dumps({**head, "units": units}, indent=1)

    def header(self) -> list[str]:
        """Which job, which data file and what the numbers are: the lines above the table."""
        lines = [f"job {self.run_id}: {self.job}" if self.job else f"job {self.run_id}"]
        lines += [f"  {self.chosen}"] if self.chosen else []
        lines += [f"data {self.data}"] if self.data else []
        lines.append(
            "scores: each adjective classifier's decision value; > 0 means the adjective is "
            "predicted"
        )
        return lines

    def to_table(self) -> str:
        lines = [*self.header(), ""]
        for unit, chosen in zip(self.units, self.predicted(), strict=True):
            lines.append(f"{unit}: {', '.join(chosen) or '(none)'}")
        width = max(len(a) for a in self.adjectives)
        cell = max(10, *(len(u) for u in self.units))  # whole unit names, never cut
        lines.append("")
        lines.append(" " * width + "  " + "  ".join(f"{u:>{cell}}" for u in self.units))
        for j, adjective in enumerate(self.adjectives):
            values = "  ".join(f"{s:>{cell}.4f}" for s in self.scores[:, j])
            lines.append(f"{adjective:>{width}}  {values}")
        lines += self._object_lines()
        return "\n".join(lines) + "\n"

    def _object_lines(self) -> list[str]:
        """Each object's predicted set (mean decision value over its units > 0), against its
        true adjectives where the data file has labels (among the adjectives scored)."""
        predicted = self.object_predictions()
        if not predicted:
            return []
        lines = ["", "per object (mean decision value over its units > 0):"]
        for obj, chosen in predicted.items():
            name = f" ({self.object_names[obj]})" if obj in self.object_names else ""
            line = f"  object {obj}{name}: predicted {', '.join(chosen) or '(none)'}"
            if obj in self.labels:
                true = [a for a in self.adjectives if a in self.labels[obj]]
                agree = sum((a in chosen) == (a in true) for a in self.adjectives)
                line += (
                    f"; true {', '.join(true) or '(none)'}; "
                    f"{agree} of {len(self.adjectives)} adjectives right"
                )
            lines.append(line)
        return lines


# modality -> (takes trials, takes photographs)
INPUTS = {
    "haptic": (True, False),
    "haptic_features": (True, False),
    "visual": (False, True),
    "multimodal": (True, True),
}


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
    ``data`` (rows A-J), for the photographs in folder ``photos`` (rows K, L), or for both, of
    one object (rows M, N). Row O (random guess) is refused: it keeps no model."""
    tracker = _tracker(tracking_uri, experiment)
    job = _job(tracker, run_id)
    job_id = job.info.run_id
    config = _config(tracker, job_id)
    chosen = (
        ""
        if run_id is not None
        else f"no run id given: the newest FINISHED job of experiment {experiment!r}"
    )
    modality, model_name = str(config["modality"]["name"]), str(config["model"]["name"])
    if model_name == "random":
        raise PredictError(
            f"run {job_id} is a random-guess job (model random, Table I row O): its scores are "
            "seeded random numbers that ignore the input, so it keeps no model to apply; give "
            "the run id of a trained job"
        )
    if modality not in INPUTS:
        raise PredictError(f"run {job_id}: modality {modality!r}; predict applies {list(INPUTS)}")
    takes_trials, takes_photos = INPUTS[modality]
    has_trials = bool(trials) or object_id is not None
    if takes_trials and not has_trials:
        wanted = "and a folder of its photographs" if takes_photos else "not photographs"
        raise PredictError(
            f"run {job_id} holds {modality} models (modality {modality}): give trials "
            f"(--trial NAME, repeated, or --object ID), {wanted}"
        )
    data_line = ""
    if takes_trials:
        data, data_line = _data_file(job, data)
    if takes_photos and photos is None:
        wanted = "and the object's trials (data with trials)" if takes_trials else "not trials"
        raise PredictError(
            f"run {job_id} holds {modality} models (modality {modality}): give a folder of "
            f"photographs {wanted}"
        )
    children = _children(tracker, job_id, adjectives)
    given = _Inputs(tracker, data=data, trials=trials, object_id=object_id, photos=photos)
    scored = apply_job(tracker, job_id, config, children, given)
    return _presented(scored, job, config, chosen, data_line, data if takes_trials else None)


def apply_job(
    tracker: Any, job_id: str, config: dict[str, Any], children: dict[str, str], given: _Inputs
) -> Prediction:
    """Scores of ``given`` by each adjective's child run (adjective -> run id) of job ``job_id``
    with its ``config``; ``tracker`` is anything whose ``client`` downloads and lists the
    children's artifacts (an MLflow store, or the folder an MLflow model keeps them in)."""
    modality, model_name = str(config["modality"]["name"]), str(config["model"]["name"])
    inputs = {
        "haptic": given.haptic,
        "haptic_features": given.features,
        "visual": given.visual,
        "multimodal": given.multimodal,
    }[modality]
    from tactile_exp.modalities import MODALITIES

    pad = MODALITIES[modality].pad_units  # as the job combined its test units
    combiner, combine = str(config["combine_instances"]["name"]), int(config["combine"])
    model_params = {k: v for k, v in config["model"].items() if k != "name"}
    units: list[str] = []
    columns = []
    for child in children.values():
        scores, units = _apply(
            tracker, child, inputs(child), combiner, combine, model_name, model_params, pad=pad
        )
        columns.append(scores)
    return Prediction(job_id, units, list(children), np.column_stack(columns))


def _presented(
    scored: Prediction,
    job: Any,
    config: dict[str, Any],
    chosen: str,
    data_line: str,
    data: str | Path | None,
) -> Prediction:
    """``scored`` as predict shows it: which job and data, each unit's object (a unit of
    several trials named by its object, not its first trial) and the objects' true labels."""
    units = scored.units
    objects = [_object_of(u) for u in units]
    names = {
        n.object_id: n.stem for u in units if (n := TrialName.parse(u.split("#", 1)[0])) is not None
    }  # fmt: skip
    return replace(
        scored,
        units=unit_labels(units, config),
        job=_describe(job, config),
        chosen=chosen,
        data=data_line,
        objects=objects,
        object_names=names,
        labels=_labels(data, objects),
    )


def _describe(job: Any, config: dict[str, Any]) -> str:
    """The job as its run name, what it trains on what, and its Table I row (if one)."""
    combine = int(config["combine"])
    units = (
        "one trial per unit"
        if combine == 1
        else f"units of {combine} trials combined by {config['combine_instances']['name']}"
    )
    what = f"model {config['model']['name']} on modality {config['modality']['name']}, {units}"
    paper = config.get("paper")
    row = f", Table I row {paper['row']}" if isinstance(paper, dict) and paper.get("row") else ""
    return f"{job.info.run_name} ({what}{row})"


def _recorded_data(job: Any) -> Path | None:
    """The data file the job logged as its dataset input (a ``file://`` source)."""
    for dataset_input in job.inputs.dataset_inputs if job.inputs else ():
        parsed = urllib.parse.urlparse(dataset_input.dataset.source)
        if parsed.scheme == "file":
            return Path(urllib.parse.unquote(parsed.path))
    return None


def _data_file(job: Any, data: str | Path | None) -> tuple[str | Path, str]:
    """The data file to read trials from: the one given, else the job's own while it exists."""
    if data is not None:
        return data, f"{data} (given)"
    recorded = _recorded_data(job)
    if recorded is None:
        raise PredictError(
            f"run {job.info.run_id} records no data file: give --data FILE, a PHAC-2-layout "
            "file holding the trials"
        )
    if not recorded.is_file():
        raise PredictError(
            f"the job's data file {recorded} is no longer there: give --data FILE, a "
            "PHAC-2-layout file holding the trials"
        )
    return recorded, f"{recorded} (the job's own data file; --data to read another)"


def _object_of(unit: str) -> int | None:
    """The object of a unit named by a trial (``<object>_<id>_<trial>[#k]``), else None."""
    name = TrialName.parse(unit.split("#", 1)[0])
    return None if name is None else name.object_id


def unit_labels(units: list[str], config: dict[str, Any]) -> list[str]:
    """The names predict (and the deployed model) show for scored ``units``: a unit of several
    trials is named by its object, a single trial or instance by itself."""
    from tactile_exp.combine import COMBINERS

    combiner, combine = str(config["combine_instances"]["name"]), int(config["combine"])
    if not COMBINERS.build(combiner).keeps_instances and combine > 1:
        return _object_units(units)
    return list(units)


def _object_units(units: list[str]) -> list[str]:
    """Units of several trials named by their object (``car_sponge_101``, or ``..#2`` for an
    object's second unit), not by the first trial in them."""
    stems = [
        name.stem if (name := TrialName.parse(u)) is not None else u for u in units
    ]  # fmt: skip
    seen: dict[str, int] = {}
    out = []
    for stem in stems:
        seen[stem] = seen.get(stem, 0) + 1
        out.append(stem if stems.count(stem) == 1 else f"{stem}#{seen[stem]}")
    return out


def _labels(data: str | Path | None, objects: list[int | None]) -> dict[int, list[str]]:
    """The true adjectives of ``objects`` where the data file has labels; {} where not."""
    from tactile_exp.data.phac2 import PHAC2, DataError

    if data is None:
        return {}
    try:
        labels = PHAC2(data).labels()
    except (DataError, OSError, KeyError, ValueError):
        return {}
    return {
        obj: [a for a, v in labels[obj].items() if v == 1]
        for obj in dict.fromkeys(objects)
        if obj is not None and obj in labels
    }


def _tracker(uri: str | None, experiment: str) -> Any:
    from tactile_exp.tracking import ExperimentNotFound, Tracker, TrackingError

    try:
        return Tracker.open(uri, experiment)
    except (ExperimentNotFound, TrackingError) as err:
        raise PredictError(str(err)) from None


def _job(tracker: Any, run_id: str | None) -> Any:
    from mlflow.exceptions import MlflowException

    if run_id is None:
        runs = tracker.jobs(limit=1)
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
    found = tracker.children(run_id)
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


class _Inputs:
    """The new object's trials and photographs, read once and turned into each adjective's
    instances as that adjective's job turned its test trials and photographs into instances."""

    def __init__(
        self,
        tracker: Any,
        *,
        data: str | Path | None,
        trials: Sequence[str],
        object_id: int | None,
        photos: str | Path | None,
    ) -> None:
        self.tracker, self.data, self.trials, self.object_id = tracker, data, trials, object_id
        self.photos = None if photos is None else Path(photos)
        self._haptic_arrays: dict[tuple[Any, ...], Any] = {}
        self._views: dict[tuple[Any, ...], np.ndarray] = {}

    @functools.cached_property
    def selected(self) -> tuple[Any, list[TrialName]]:
        """The data set and the chosen trials (given ones, then the object's others)."""
        from tactile_exp.data.phac2 import PHAC2, DataError

        if self.data is None:
            raise PredictError("haptic models need --data FILE: a PHAC-2-layout file of the trials")
        try:
            dataset = PHAC2(self.data)
            names = [dataset.trial_name(t) for t in self.trials]
        except DataError as err:
            raise PredictError(str(err)) from None
        if self.object_id is not None:
            obj = self.object_id
            names += [t for t in dataset.trials if t.object_id == obj and t not in names]
            if not any(t.object_id == obj for t in names):
                raise PredictError(f"{self.data}: no trials of object {obj}")
        if not names:
            raise PredictError("give at least one trial (--trial NAME) or an object (--object ID)")
        return dataset, names

    def state(self, child: str) -> tuple[dict[str, Any], dict[str, np.ndarray], str]:
        """The child's fitted preprocessing (``preprocess/``): settings, arrays, its name."""
        where = f"run {child}: artifact preprocess"
        folder = store.download(self.tracker, child, "preprocess", store.STATE_FILES)
        return store.read_json(folder, where), store.read_arrays(folder, where), where

    def haptic(self, child: str) -> Instances:
        return self._haptic(*self.state(child))

    def _haptic(self, settings: dict[str, Any], arrays: dict[str, np.ndarray], where: str):
        from tactile_exp.data.phac2 import DataError
        from tactile_exp.preprocess.haptic import HapticPreprocessor, compute_haptic_arrays

        dataset, names = self.selected
        try:
            key = (settings["steps"], settings["offsets"], settings["pac_downsample"])
            components, per_finger = settings["pca_components"], settings["per_finger"]
        except KeyError as err:
            raise store.ArtifactError(f"{where}/settings.json: missing entry {err}") from None
        if key not in self._haptic_arrays:
            try:
                self._haptic_arrays[key] = compute_haptic_arrays(_Subset(dataset, names), *key)
            except (DataError, ValueError, KeyError) as err:
                lacks = f"{self.data}: a trial lacks what the models need: {err}"
                raise PredictError(lacks) from None
        try:
            pre = HapticPreprocessor(self._haptic_arrays[key], components, per_finger)
            pre.restore(arrays)
        except (KeyError, ValueError) as err:
            raise store.ArtifactError(f"{where}: {err}") from None
        X = pre.transform(names)
        per_trial = X.shape[1] * X.shape[2]
        trial = np.repeat(np.array([t.name for t in names], dtype=object), per_trial)
        obj = np.repeat([t.object_id for t in names], per_trial)
        return Instances(X.reshape(-1, *X.shape[3:]), np.zeros(len(trial), np.int64), trial, obj)

    @functools.cached_property
    def trial_data(self) -> list[Any]:
        """The chosen trials as read, optional channels included (the static features use the
        gripper and the hand transforms)."""
        from tactile_exp.data.phac2 import DataError

        dataset, names = self.selected
        try:
            return list(dataset.iter_trials(names))
        except DataError as err:
            raise PredictError(str(err)) from None

    def features(self, child: str) -> Instances:
        """Rows A-F: the hand-designed features of each trial (one instance per trial)."""
        from tactile_exp.modalities.haptic_features import trial_features

        settings, arrays, where = self.state(child)
        trials = self.trial_data
        try:
            X = trial_features(trials, settings, arrays)
        except KeyError as err:
            raise store.ArtifactError(f"{where}: missing entry {err}") from None
        except ValueError as err:
            raise PredictError(f"{self.data}: {err}") from None
        names = np.array([t.name.name for t in trials], dtype=object)
        obj = np.array([t.name.object_id for t in trials])
        return Instances(X, np.zeros(len(trials), np.int64), names, obj)

    def _visual(self, settings: dict[str, Any], arrays: dict[str, np.ndarray], where: str):
        """(n, 832) features of the folder's photographs, in file-name order (views)."""
        from tactile_exp.models.googlenet import build_trunk, network_input, pooled_features

        try:
            size, layout, seed = int(settings["size"]), settings["layout"], settings["seed"]
            weights = settings["weights"]
            mean = tuple(float(m) for m in arrays["channel_mean"])
        except (KeyError, TypeError, ValueError) as err:
            raise store.ArtifactError(f"{where}: missing or bad entry {err}") from None
        key = (size, layout, seed, weights, mean)
        if key not in self._views:
            _, images = read_photographs(Path(str(self.photos)), size)
            if weights is not None and not Path(weights).is_file():
                raise PredictError(f"{where}: the GoogLeNet weights file {weights} is not there")
            trunk = build_trunk(None if weights is None else Path(weights), seed, layout)
            self._views[key] = pooled_features(trunk, network_input(images, mean, layout))
        return self._views[key]

    def visual(self, child: str) -> Instances:
        """Rows K, L: one instance per photograph, named ``<folder>_v<VV>`` in file-name order."""
        X = self._visual(*self.state(child))
        n, stem = len(X), Path(str(self.photos)).name
        names = np.array([f"{stem}_v{i:02d}" for i in range(n)], dtype=object)
        return Instances(X, np.zeros(n, np.int64), names, np.zeros(n, np.int64))

    def multimodal(self, child: str) -> Instances:
        """Rows M, N: each haptic unit's frozen ConvNet conv3 beside the object's visual unit,
        built by the ``multimodal`` modality's own rules (``multimodal_units``)."""
        from tactile_exp.modalities.multimodal import multimodal_units, visual_units

        settings, arrays, where = self.state(child)

        def part(name: str) -> dict[str, np.ndarray]:
            prefix = f"{name}."
            return {k.removeprefix(prefix): v for k, v in arrays.items() if k.startswith(prefix)}

        try:
            haptic, visual = settings["haptic"], settings["visual"]
            n_trials, views = int(settings["trials"]), int(settings["views"])
        except (KeyError, TypeError, ValueError) as err:
            raise store.ArtifactError(f"{where}: missing or bad entry {err}") from None
        instances = self._haptic(haptic, part("haptic"), where)
        objects = np.unique(instances.object_id).tolist()
        if len(objects) != 1:
            raise PredictError(
                f"a multimodal unit joins trials of one object with that object's photographs; "
                f"the trials given are of objects {objects}"
            )
        net = store.load_model(self.tracker, child, "parts/haptic")
        photos = self._visual(visual, part("visual"), where)
        seen = visual_units(photos, np.full(len(photos), objects[0]), views)
        return multimodal_units(net, instances, n_trials, seen)


def haptic_instances(
    tracker: Any, *, data: str | Path, trials: Sequence[str], child: str
) -> Instances:
    """The instances of ``trials`` as child run ``child`` built its own (its stored
    preprocessing): what the report's Fig. 6 feeds the stored ConvNet."""
    return _Inputs(tracker, data=data, trials=trials, object_id=None, photos=None).haptic(child)


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


def _apply(
    tracker: Any,
    child: str,
    instances: Instances,
    combiner: str,
    combine: int,
    model_name: str,
    model_params: dict[str, Any],
    *,
    pad: bool,
) -> tuple[np.ndarray, list[str]]:
    """One adjective's scores of ``instances`` and the units they belong to; ``pad``: the
    modality's ``pad_units`` (views are never padded, row L)."""
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
    units = combine_units(model.transform(instances.X), instances, combine, pad=pad)
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
    parser.add_argument(
        "--data",
        help="a PHAC-2-layout HDF5 file holding the trials; default: the job's own data file",
    )
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
    if args.format != "table":  # the table says it itself; csv and json stay data only
        print("\n".join(result.header()), file=sys.stderr)
    text = {"table": result.to_table, "csv": result.to_csv, "json": result.to_json}[args.format]()
    if args.out:
        Path(args.out).write_text(text)
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
