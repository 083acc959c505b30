"""A finished job as kept in the tracking store: its config, its adjectives' child runs and
their fitted pipelines. What predict, the exported models and the report's Fig. 6 read."""

from __future__ import annotations

import urllib.parse
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tactile_exp import store
from tactile_exp.modalities import MODALITIES
from tactile_exp.pipeline import AdjectivePipeline


class PredictError(ValueError):
    """Input or stored job that predict cannot use; the message says which and why."""


@dataclass
class StoredJob:
    """A FINISHED job (parent run) of an MLflow experiment."""

    client: Any  # MlflowClient
    uri: str
    experiment_id: str
    run: Any  # the parent run
    config: dict[str, Any]

    @classmethod
    def open(
        cls, run_id: str | None, *, experiment: str = "tactile_exp", tracking_uri: str | None = None
    ) -> StoredJob:
        """Job ``run_id``, default the newest FINISHED job of ``experiment``."""
        import yaml
        from mlflow.exceptions import MlflowException
        from mlflow.tracking import MlflowClient

        from tactile_exp.tracking import resolve_uri

        uri = resolve_uri(tracking_uri)
        client = MlflowClient(tracking_uri=uri)
        found = client.get_experiment_by_name(experiment)
        if found is None:
            raise PredictError(f"no experiment {experiment!r} in the tracking store {uri}")
        if run_id is None:
            runs = client.search_runs(
                [found.experiment_id],
                "tags.run_level = 'parent' and attributes.status = 'FINISHED'",
                order_by=["attributes.start_time DESC"],
                max_results=1,
            )
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
            raise store.ArtifactError(error) from None
        if not isinstance(config, dict) or "modality" not in config:
            raise store.ArtifactError(f"run {job_id}: artifact config.yaml is not a job's config")
        return cls(client, uri, found.experiment_id, run, config)

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
        runs = self.client.search_runs(
            [self.experiment_id],
            f"tags.mlflow.parentRunId = '{self.id}' and tags.run_level = 'child' "
            "and attributes.status = 'FINISHED'",
            max_results=1000,
        )
        found = {r.data.tags["adjective"]: r.info.run_id for r in runs}
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
            return Path(self.client.download_artifacts(child, ""))
        except Exception as err:
            raise store.ArtifactError(f"run {child}: artifacts cannot be read ({err})") from None

    def pipelines(self, adjectives: Sequence[str] | None = None) -> dict[str, AdjectivePipeline]:
        """Each adjective's fitted pipeline, loaded from its child run."""
        return {
            a: AdjectivePipeline.load(self.folder(child), f"run {child}")
            for a, child in self.children(adjectives).items()
        }
