"""The MLflow model of a finished job, by MLflow's "models from code": this file is the model.

``mlflow_model.log_job`` logs it with the job's stored artifacts beside it (artifact ``job``:
``job.json`` with the job's config and its adjectives' child run ids, and ``runs/<child run id>/``
holding each child's ``preprocess/``, ``model/``, ``head/`` and ``parts/`` folders as the
tracking store keeps them: each adjective's saved ``AdjectivePipeline``). Loading runs no stored
object: ``AdjectivePipeline.load`` reads JSON, npz and ``torch.load(weights_only=True)``, so a
corrupt or missing file is its error, naming the child run and the artifact.

Input, one row per trial (``INPUT_COLUMNS``): ``data`` (a PHAC-2-layout HDF5 file) and ``trial``
(a trial group name) for haptic rows; ``photos`` (a folder of one object's photographs) for
visual rows; all three for multimodal rows. Output, one row per unit predict scores (a trial, a
trial's instance ``<trial>#<k>`` for rows G/H, an object's views, an object for combine > 1,
named as predict names it): ``unit``, each adjective's decision value (> 0: it applies) and
``predicted``, the applying adjectives joined by spaces.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import mlflow
import pandas as pd
from mlflow.pyfunc import PythonModel

from tactile_exp import plugins
from tactile_exp.jobs import JobSpec
from tactile_exp.pipeline import AdjectivePipeline
from tactile_exp.predict import PredictError, apply, new_trials

INPUT_COLUMNS = ("data", "trial", "photos")


def _one(frame: pd.DataFrame, column: str) -> str | None:
    """The single value of ``column`` over the request's rows (None when absent or empty)."""
    if column not in frame:
        return None
    values = {str(v) for v in frame[column].dropna() if str(v)}
    if len(values) > 1:
        raise PredictError(f"input column {column!r}: one value per request, got {sorted(values)}")
    return values.pop() if values else None


class JobModel(PythonModel):
    """A job's adjectives' models: trials or photographs in, decision values out."""

    def load_context(self, context: Any) -> None:
        folder = Path(context.artifacts["job"])
        self.job = json.loads((folder / "job.json").read_text())
        where = f"job {self.job['job']}"
        plugins.import_modules(self.job["config"], where)  # its components outside the package
        self.spec = JobSpec.of(self.job["config"], where)
        self.pipelines = {
            adjective: AdjectivePipeline.load(folder / "runs" / child, f"run {child}")
            for adjective, child in self.job["adjectives"].items()
        }

    def predict(
        self, context: Any, model_input: pd.DataFrame, params: dict[str, Any] | None = None
    ) -> pd.DataFrame:
        frame = pd.DataFrame(model_input)
        unknown = sorted(set(frame.columns) - set(INPUT_COLUMNS))
        if unknown:
            raise PredictError(f"input columns {unknown}: expected among {list(INPUT_COLUMNS)}")
        trials = [str(t) for t in frame["trial"].dropna()] if "trial" in frame else []
        given = new_trials(
            self.spec.modality.name,
            data=_one(frame, "data"),
            trials=trials,
            object_id=None,
            photos=_one(frame, "photos"),
            job=self.job["job"],
        )
        result = apply(self.pipelines, given)
        out = pd.DataFrame(result.scores, columns=result.adjectives)
        out.insert(0, "unit", result.units)
        out["predicted"] = [" ".join(chosen) for chosen in result.predicted()]
        return out


mlflow.models.set_model(JobModel())
