"""A finished job as kept in the tracking store: what it was (``JobSpec``, read once from its
``config.yaml``, whose ``_module_``s are imported again), its adjectives' child runs and their
fitted pipelines. What predict, the
exported models (pyfunc and ONNX) and the report's Fig. 6 read; no other module reads a job's
config or the tracking client."""

from __future__ import annotations

import urllib.parse
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tactile_exp import plugins, scores_file
from tactile_exp.artifacts import ArtifactError
from tactile_exp.modalities import MODALITIES
from tactile_exp.models.registry import MODELS
from tactile_exp.pipeline import AdjectivePipeline
from tactile_exp.registry import Component
from tactile_exp.tracking import ExperimentNotFound, Tracker, TrackingError


class PredictError(ValueError):
    """Input or stored job that predict cannot use; the message says which and why."""


def _component(config: Mapping[str, Any], group: str, where: str) -> Component:
    node = config.get(group)
    if not isinstance(node, Mapping) or "name" not in node:
        raise ArtifactError(f"{where}: {group} is not a mapping with a name")
    params = {k: v for k, v in node.items() if k not in ("name", "_module_")}
    return Component(str(node["name"]), params)


@dataclass(frozen=True)
class JobSpec:
    """What a finished job trained on what: the typed view of its logged ``config.yaml``."""

    data: Component
    modality: Component
    model: Component
    combiner: str  # combine_instances (T4)
    combine: int
    row: str | None  # its Table I row, when an experiment file set one

    @classmethod
    def of(cls, config: Any, where: str) -> JobSpec:
        """The spec of a job's resolved ``config``; ArtifactError naming ``where`` when off."""
        if not isinstance(config, Mapping) or "modality" not in config:
            raise ArtifactError(f"{where}: artifact config.yaml is not a job's config")
        try:
            paper = config.get("paper")
            row = paper.get("row") if isinstance(paper, Mapping) else None
            return cls(
                _component(config, "data", where),
                _component(config, "modality", where),
                _component(config, "model", where),
                _component(config, "combine_instances", where).name,
                int(config["combine"]),
                None if row is None else str(row),
            )
        except (KeyError, TypeError, ValueError) as err:
            raise ArtifactError(
                f"{where}: artifact config.yaml: missing or bad entry {err}"
            ) from None

    def data_source(self) -> Any:
        """The data set the job read (opened lazily: its file may have moved since)."""
        from tactile_exp.data.sources import DATA_SOURCES

        return DATA_SOURCES.build(self.data.name, **self.data.params)


@dataclass
class StoredJob:
    """A FINISHED job (parent run) of an MLflow experiment."""

    tracker: Tracker  # of the job's experiment
    run: Any  # the parent run
    config: dict[str, Any]  # as logged: what an exported model keeps beside its pipelines
    spec: JobSpec

    @classmethod
    def open(
        cls, run_id: str | None, *, experiment: str = "tactile_exp", tracking_uri: str | None = None
    ) -> StoredJob:
        """Job ``run_id``, default the newest FINISHED job of ``experiment``."""
        try:
            tracker = Tracker.open(tracking_uri, experiment)
        except (ExperimentNotFound, TrackingError) as err:
            raise PredictError(str(err)) from None
        return cls.read(tracker, run_id)

    @classmethod
    def read(cls, tracker: Tracker, run_id: str | None) -> StoredJob:
        """Job ``run_id`` of ``tracker``'s experiment, default its newest FINISHED job."""
        import yaml
        from mlflow.exceptions import MlflowException

        uri = tracker.uri
        if run_id is None:
            runs = tracker.jobs(limit=1)
            if not runs:
                raise PredictError(f"no FINISHED job in the tracking store {uri}")
            run = runs[0]
        else:
            try:
                run = tracker.get_run(run_id)
            except MlflowException:
                raise PredictError(f"unknown run id {run_id} in the tracking store {uri}") from None
        job_id = run.info.run_id
        if run.info.status != "FINISHED":
            raise PredictError(
                f"run {job_id} is {run.info.status}, not FINISHED: its models are incomplete"
            )
        if run.data.tags.get("run_level") != "parent":
            raise PredictError(f"run {job_id} is not a job (a parent run): give the job's run id")
        try:
            config = yaml.safe_load(tracker.download(job_id, "config.yaml").read_text())
        except (OSError, yaml.YAMLError, MlflowException) as err:
            error = f"run {job_id}: artifact config.yaml unreadable ({err})"
            raise ArtifactError(error) from None
        try:  # the job's components kept outside the package register as they import
            plugins.import_modules(config, f"run {job_id}")
        except plugins.PluginError as err:
            raise PredictError(str(err)) from None
        return cls(tracker, run, config, JobSpec.of(config, f"run {job_id}"))

    @property
    def id(self) -> str:
        return self.run.info.run_id

    @property
    def modality(self) -> str:
        return self.spec.modality.name

    @property
    def data_identity(self) -> str | None:
        """The identity of the data file the job ran on (its ``data.identity`` tag)."""
        return self.run.data.tags.get("data.identity")

    def check_applicable(self) -> None:
        """PredictError for a job that keeps no model to apply (row O, random guess)."""
        if not MODELS[self.spec.model.name].applies:
            raise PredictError(
                f"run {self.id} is a random-guess job (model random, Table I row O): its scores "
                "are seeded random numbers that ignore the input, so it keeps no model to apply; "
                "give the run id of a trained job"
            )
        if self.modality not in MODALITIES.names():
            raise PredictError(f"run {self.id}: modality {self.modality!r} is not known here")

    def describe(self) -> str:
        """The job as its run name, what it trains on what, and its Table I row (if one)."""
        spec = self.spec
        units = (
            "one trial per unit"
            if spec.combine == 1
            else f"units of {spec.combine} trials combined by {spec.combiner}"
        )
        what = f"model {spec.model.name} on modality {self.modality}, {units}"
        row = f", Table I row {spec.row}" if spec.row else ""
        return f"{self.run.info.run_name} ({what}{row})"

    def data_file(self) -> Path | None:
        """The data file the job logged as its dataset input (a ``file://`` source)."""
        for dataset_input in self.run.inputs.dataset_inputs if self.run.inputs else ():
            parsed = urllib.parse.urlparse(dataset_input.dataset.source)
            if parsed.scheme == "file":
                return Path(urllib.parse.unquote(parsed.path))
        return None

    def children(self, adjectives: Sequence[str] | None = None) -> dict[str, str]:
        """Adjective -> its FINISHED child run's id (all, or ``adjectives``, in that order)."""
        found = self.tracker.children(self.id)
        wanted = sorted(found) if adjectives is None else list(adjectives)
        missing = [a for a in wanted if a not in found]
        if missing or not wanted:
            raise PredictError(
                f"run {self.id} has no finished model for adjectives {missing or wanted}"
            )
        return {a: found[a] for a in wanted}

    def folder(self, child: str, path: str = "") -> Path:
        """Child run ``child``'s artifact ``path`` (default all: its saved pipeline), local."""
        try:
            return self.tracker.download(child, path)
        except Exception as err:
            where = f"artifact {path}" if path else "artifacts"
            raise ArtifactError(f"run {child}: {where} cannot be read ({err})") from None

    def copy(self, child: str, path: str, into: Path) -> None:
        """Child run ``child``'s artifact ``path`` copied into folder ``into``."""
        self.tracker.download(child, path, into)

    def scores(self, child: str) -> list[scores_file.UnitScore]:
        """Child run ``child``'s test units and scores (its ``scores.csv``)."""
        try:
            return scores_file.read(self.folder(child, scores_file.NAME).read_text())
        except (KeyError, ValueError) as err:
            raise ArtifactError(f"run {child}: artifact {scores_file.NAME}: {err}") from None

    def listed(self, child: str) -> set[str]:
        """The top-level artifact paths of child run ``child``."""
        return self.tracker.artifacts(child)

    def pipelines(self, adjectives: Sequence[str] | None = None) -> dict[str, AdjectivePipeline]:
        """Each adjective's fitted pipeline, loaded from its child run."""
        return {
            a: AdjectivePipeline.load(self.folder(child), f"run {child}")
            for a, child in self.children(adjectives).items()
        }
