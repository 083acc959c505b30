"""A finished job as kept in the tracking store: its config, its adjectives' child runs and
their fitted pipelines. What predict, the exported models and the report's Fig. 6 read."""

from __future__ import annotations

import urllib.parse
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tactile_exp import artifacts
from tactile_exp.modalities import MODALITIES
from tactile_exp.pipeline import AdjectivePipeline
from tactile_exp.tracking import ExperimentNotFound, Tracker, TrackingError


class PredictError(ValueError):
    """Input or stored job that predict cannot use; the message says which and why."""


@dataclass
class StoredJob:
    """A FINISHED job (parent run) of an MLflow experiment."""

    tracker: Tracker  # of the job's experiment
    run: Any  # the parent run
    config: dict[str, Any]

    @classmethod
    def open(
        cls, run_id: str | None, *, experiment: str = "tactile_exp", tracking_uri: str | None = None
    ) -> StoredJob:
        """Job ``run_id``, default the newest FINISHED job of ``experiment``."""
        import yaml
        from mlflow.exceptions import MlflowException

        try:
            tracker = Tracker.open(tracking_uri, experiment)
        except (ExperimentNotFound, TrackingError) as err:
            raise PredictError(str(err)) from None
        client, uri = tracker.client, tracker.uri
        if run_id is None:
            runs = tracker.jobs(limit=1)
            if not runs:
                raise PredictError(f"no FINISHED job in the tracking store {uri}")
            run = runs[0]
        else:
            try:
                run = client.get_run(run_id)
            except MlflowException:
                raise PredictError(f"unknown run id {run_id} in the tracking store {uri}") from None
        job_id = run.info.run_id
        if run.info.status != "FINISHED":
            raise PredictError(
                f"run {job_id} is {run.info.status}, not FINISHED: its models are incomplete"
            )
        if run.data.tags.get("run_level") != "parent":
            raise PredictError(f"run {job_id} is not a job (a parent run): give the job's run id")
        folder = Path(client.download_artifacts(job_id, ""))
        try:
            config = yaml.safe_load((folder / "config.yaml").read_text())
        except (OSError, yaml.YAMLError) as err:
            error = f"run {job_id}: artifact config.yaml unreadable ({err})"
            raise artifacts.ArtifactError(error) from None
        if not isinstance(config, dict) or "modality" not in config:
            raise artifacts.ArtifactError(
                f"run {job_id}: artifact config.yaml is not a job's config"
            )
        return cls(tracker, run, config)

    @property
    def id(self) -> str:
        return self.run.info.run_id

    @property
    def modality(self) -> str:
        return str(self.config["modality"]["name"])

    def check_applicable(self) -> None:
        """PredictError for a job that keeps no model to apply (row O, random guess)."""
        if str(self.config["model"]["name"]) == "random":
            raise PredictError(
                f"run {self.id} is a random-guess job (model random, Table I row O): its scores "
                "are seeded random numbers that ignore the input, so it keeps no model to apply; "
                "give the run id of a trained job"
            )
        if self.modality not in MODALITIES.names():
            raise PredictError(f"run {self.id}: modality {self.modality!r} is not known here")

    def describe(self) -> str:
        """The job as its run name, what it trains on what, and its Table I row (if one)."""
        combine = int(self.config["combine"])
        units = (
            "one trial per unit"
            if combine == 1
            else f"units of {combine} trials combined by {self.config['combine_instances']['name']}"
        )
        what = f"model {self.config['model']['name']} on modality {self.modality}, {units}"
        paper = self.config.get("paper")
        row = (
            f", Table I row {paper['row']}" if isinstance(paper, dict) and paper.get("row") else ""
        )
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

    def folder(self, child: str) -> Path:
        """Child run ``child``'s artifacts (its saved pipeline), as a local folder."""
        try:
            return Path(self.tracker.client.download_artifacts(child, ""))
        except Exception as err:
            raise artifacts.ArtifactError(
                f"run {child}: artifacts cannot be read ({err})"
            ) from None

    def pipelines(self, adjectives: Sequence[str] | None = None) -> dict[str, AdjectivePipeline]:
        """Each adjective's fitted pipeline, loaded from its child run."""
        return {
            a: AdjectivePipeline.load(self.folder(child), f"run {child}")
            for a, child in self.children(adjectives).items()
        }
