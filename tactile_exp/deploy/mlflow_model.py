"""Log a finished job as one MLflow pyfunc model (``pyfunc_model.py``) and register it.

The model is logged into the job's own run (artifact path ``model``), so
``mlflow.pyfunc.load_model("runs:/<job run id>/model")`` and, once registered,
``mlflow models serve -m models:/<name>/<version>`` answer with predict's scores. The
registered version is tagged with the job's experiment, Table I row, data identity and mean AUC.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from tactile_exp.jobs import PredictError, StoredJob
from tactile_exp.modalities import MODALITIES
from tactile_exp.models.registry import MODELS
from tactile_exp.pipeline import SETTINGS

MODEL_FILE = Path(__file__).with_name("pyfunc_model.py")
ARTIFACT_PATH = "model"
KEPT = (SETTINGS, "preprocess", "model", "head", "parts")  # each child run's saved pipeline


def _signature(adjectives: list[str]) -> Any:
    from mlflow.models import ModelSignature
    from mlflow.types import ColSpec, Schema

    from tactile_exp.deploy.pyfunc_model import INPUT_COLUMNS

    inputs = Schema([ColSpec("string", c, required=False) for c in INPUT_COLUMNS])
    outputs = Schema(
        [ColSpec("string", "unit"), *(ColSpec("double", a) for a in adjectives),
         ColSpec("string", "predicted")]
    )  # fmt: skip
    return ModelSignature(inputs=inputs, outputs=outputs)


def _example(job: StoredJob, child: str) -> Any:
    """A held-out unit of the job as a request: its trial in the job's data file; for rows that
    take photographs, ``photos/<object stem>``, the folder of that object's photographs a user
    makes (the data file keeps them all in one folder), so that example shows the shape only."""
    import pandas as pd

    modality = MODALITIES[job.modality]
    takes_trials, takes_photos = modality.takes_trials, modality.takes_photographs
    unit = job.scores(child)[0].unit.split("#")[0]
    example: dict[str, list[str]] = {}
    if takes_trials:
        example = {"data": [str(job.spec.data_source().path)], "trial": [unit]}
    if takes_photos:
        stem = unit.rsplit("_", 1)[0]  # <stem>_<trial> or <stem>_v<view>
        example["photos"] = [f"photos/{stem}"]
    return pd.DataFrame(example)


def log_job(
    run_id: str | None,
    *,
    experiment: str = "tactile_exp",
    tracking_uri: str | None = None,
    register: str | None = None,
) -> tuple[Any, str | None]:
    """Log job ``run_id`` (default: the newest FINISHED) as a pyfunc model into its run; with
    ``register``, also a new version of registered model ``register`` in the same store.
    Returns MLflow's ``ModelInfo`` and the registered version (None: not registered)."""
    import mlflow

    stored = StoredJob.open(run_id, experiment=experiment, tracking_uri=tracking_uri)
    job, job_id, spec = stored.run, stored.id, stored.spec
    if not MODELS[spec.model.name].applies:
        raise PredictError(
            f"run {job_id}: a {spec.model.name} job on {stored.modality} keeps no model to log"
        )
    children = stored.children()
    with tempfile.TemporaryDirectory(prefix="tactile_exp-model-") as tmp:
        folder = Path(tmp) / "job"
        for child in children.values():
            (folder / "runs" / child).mkdir(parents=True)
            listed = stored.listed(child)
            for path in KEPT:
                if path in listed:
                    stored.copy(child, path, folder / "runs" / child)
        (folder / "job.json").write_text(
            json.dumps({"job": job_id, "config": stored.config, "adjectives": children}, indent=1)
        )
        mlflow.set_tracking_uri(stored.tracker.uri)
        metrics = job.data.metrics
        tags = {
            "experiment": experiment,
            "row": str(spec.row),
            "data.identity": job.data.tags.get("data.identity", ""),
            "mean_auc": f"{metrics.get('mean_auc', float('nan')):.4f}",
            "job": job_id,
        }
        example = _example(stored, next(iter(children.values())))
        mlflow.start_run(run_id=job_id)
        try:
            info = mlflow.pyfunc.log_model(
                name=ARTIFACT_PATH,
                python_model=str(MODEL_FILE),
                artifacts={"job": str(folder)},
                signature=_signature(list(children)),
                input_example=example,
                pip_requirements=_requirements(),
                tags=tags,
            )
        finally:  # FINISHED, as the job was: a failed log must not mark the job FAILED
            mlflow.end_run()
    if not register:
        return info, None
    return info, mlflow.register_model(info.model_uri, register, tags=tags).version


def _requirements() -> list[str]:
    """The serving environment: this package installed beside these (``--env-manager local``)."""
    import mlflow
    import pandas
    import torch

    pins = {"mlflow": mlflow.__version__, "numpy": np.__version__, "pandas": pandas.__version__}
    pins["torch"] = torch.__version__.split("+")[0]
    return [f"{name}=={version}" for name, version in pins.items()]
