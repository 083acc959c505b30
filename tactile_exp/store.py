"""Trained models kept as MLflow artifacts, found again by their training key, and loaded.

One model is a folder: ``settings.json`` (registry name, ``get_params()``, input shape),
``weights.pt`` (a flat ``state_dict``: ``body.*`` and ``classifier.*``) and ``arrays.npz`` (fitted
input statistics). Preprocessing state is a folder of ``settings.json`` and ``arrays.npz``.
Loading never runs stored code: JSON, ``torch.load(weights_only=True)``, ``np.load(allow_pickle=
False)``; every file is checked and an error names the run id and the artifact.

The training key hashes exactly what determines a learned representation (data identity, modality
and preprocessing settings, architecture, the network's schedule, loss, split rule, seed,
adjective), not what only the head, the evaluation or the machine uses, so rows H, I and J share
one ConvNet per adjective.

Jobs side by side (Hydra's joblib or submitit launcher) train each model once: the RUNNING run
that trains a key is its claim, and a job that needs the key while an older live run claims it
waits for that run's model (``await_trained``) instead of training it again.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import socket
import tempfile
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from tactile_exp.registry import Component
from tactile_exp.runtime import termination
from tactile_exp.runtime.processes import process_alive
from tactile_exp.tracking import Tracker

log = logging.getLogger(__name__)

FORMAT = 1  # bump when the artifact layout changes: older artifacts then no longer match keys
# Model settings that change neither the representation nor the instance classifier; a dotted
# key is a value inside a setting (the T4 head's schedule inside the model's ``schedule``).
MODEL_UNKEYED = ("schedule.head", "impl", "device")
# Modality settings that change only where or how fast features are computed.
MODALITY_UNKEYED = ("device", "batch_size")
MODEL_FILES = ("settings.json", "weights.pt", "arrays.npz")
STATE_FILES = ("settings.json", "arrays.npz")
POLL_SECONDS = 2.0  # how often a job waiting for another job's model looks again


class ArtifactError(RuntimeError):
    """A stored model is missing, unreadable or does not fit; names the run and artifact."""


def training_key(
    *,
    dataset: str,
    modality: Component,
    model: Component,
    split: str,
    validation: float,
    seed: int,
    adjective: str,
) -> str:
    """Hash of what determines one adjective's trained model (not combine/combine_instances).

    ``validation`` is the fraction of training objects held out for the validation score: they
    are left out of training, so it changes the model."""
    keyed = {
        "format": FORMAT,
        "dataset": dataset,
        "modality": [modality.name, _without(modality.params, MODALITY_UNKEYED)],
        "model": [model.name, _without(model.params, MODEL_UNKEYED)],
        "split": split,
        "validation": validation,
        "seed": seed,
        "adjective": adjective,
    }
    raw = json.dumps(keyed, sort_keys=True, default=str)
    return hashlib.sha256(raw.encode()).hexdigest()[:20]


def _without(params: Mapping[str, Any], dropped: tuple[str, ...]) -> dict[str, Any]:
    """``params`` less the (dotted) keys ``dropped``; ``params`` itself is left as it is."""
    out = dict(params)
    for path in dropped:
        *parents, leaf = path.split(".")
        node = out
        for parent in parents:
            if not isinstance(node.get(parent), Mapping):
                break
            node[parent] = node = dict(node[parent])
        else:
            node.pop(leaf, None)
    return out


def unkeyed(params: Mapping[str, Any]) -> dict[str, Any]:
    """The settings of ``MODEL_UNKEYED`` in a job's model ``params``, by dotted key: what a model
    it reuses takes from it (``read_model``'s overrides). A schedule without a head gives
    ``schedule.head`` None: the head then trains like the model, as in the job."""
    out = {}
    for path in MODEL_UNKEYED:
        *parents, leaf = path.split(".")
        node: Any = params
        for parent in parents:
            node = node.get(parent) if isinstance(node, Mapping) else None
        if isinstance(node, Mapping) and (parents or leaf in node):
            out[path] = node.get(leaf)
    return out


def find_trained(tracker: Tracker, key: str) -> str | None:
    """The run that trained the model with training key ``key`` in this experiment: the newest
    FINISHED run with the key, or, when that run reused it, the run it names in ``reused_from``
    (every copy holds the same weights; provenance points at the training)."""
    run = tracker.trained_run(key)
    return None if run is None else run.data.tags.get("reused_from", run.info.run_id)


def await_trained(
    tracker: Tracker, key: str, run_id: str, *, lease: float, poll: float = POLL_SECONDS
) -> str | None:
    """The run that trained the model of ``key`` (as ``find_trained``), waiting while another
    live run claims the key; None when run ``run_id`` (RUNNING, tagged with ``key``) is to train
    it: no run has finished training it and ``run_id`` is the oldest live claim.

    A claim is a RUNNING run tagged with the key; the oldest live one trains, so two jobs that
    start together agree on one. A claim whose process on this host has ended, or another
    host's claim older than ``lease`` seconds (``tracking.claim_lease``), is passed over (taken
    over by the next oldest)."""
    holder, passed = None, set()
    while True:
        # Claims first, then finished runs: a claimant that finishes between the two queries is
        # then seen FINISHED, never missed by both (which would train its model a second time).
        claim, abandoned = _oldest_live_claim(tracker, key, lease)
        source = find_trained(tracker, key)
        if source is not None:
            if holder is not None:
                log.info("  training key %s: trained in run %s, loading it", key, source)
            return source
        for stale in set(abandoned) - passed:
            log.info("  training key %s: run %s's claim is abandoned, passed over", key, stale)
        passed.update(abandoned)
        if claim is None or claim.info.run_id == run_id:
            return None
        if holder != claim.info.run_id:
            holder = claim.info.run_id
            tags = claim.data.tags
            log.info(
                "  training key %s: waiting for run %s (process %s on %s), which trains it",
                key,
                holder,
                tags.get("pid", "?"),
                tags.get("host", "?"),
            )
        termination.check()
        time.sleep(poll)


def reusable(
    tracker: Tracker,
    key: str,
    claim: str,
    *,
    lease: float,
    overrides: Mapping[str, Any] | None = None,
) -> tuple[Any, str] | None:
    """The trained model of ``key`` and the run that trained it, waiting while an older live
    job trains it (``await_trained``); None when run ``claim`` (tagged with the key) is to train
    it. The one find-or-train rule for every stored model: an adjective's and a part's."""
    source = await_trained(tracker, key, claim, lease=lease)
    if source is None:
        return None
    return load_model(tracker, source, "model", overrides), source


def _oldest_live_claim(tracker: Tracker, key: str, lease: float) -> tuple[Any, list[str]]:
    """The oldest RUNNING run tagged ``training_key = key`` whose process may still run it
    (None when there is none), and the ids of the older abandoned ones passed over."""
    host, now = socket.gethostname(), time.time() * 1000
    abandoned = []
    for run in tracker.claims(key):
        tags = run.data.tags
        pid = tags.get("pid", "")
        if tags.get("host") == host and pid.isdigit():
            alive = process_alive(int(pid), tags.get("pid_start", ""))
        else:
            alive = now - run.info.start_time < lease * 1000
        if alive:
            return run, abandoned
        abandoned.append(run.info.run_id)
    return None, abandoned


def log_folder(tracker: Tracker, run_id: str, path: str, write: Callable[[Path], None]) -> None:
    """``write`` fills a temporary folder, which is then logged whole as artifact ``path``."""
    with tempfile.TemporaryDirectory(prefix="tactile_exp-artifact-") as tmp:
        write(Path(tmp))
        tracker.log_dir(run_id, Path(tmp), path)


def model_name(model: Any) -> str:
    """The name ``model``'s class is registered under in ``MODELS`` (what ``read_model`` builds)."""
    from tactile_exp.models.registry import MODELS

    for name in MODELS.names():
        if MODELS[name] is type(model):
            return name
    raise KeyError(f"{type(model).__name__} is not a registered model")


def write_model(folder: Path, name: str, model: Any) -> None:
    """``model`` (a fitted storable model registered as ``name``) into ``folder``."""
    import torch

    tensors, arrays = model.state()
    settings = {
        "format": FORMAT,
        "model": name,
        "params": model.get_params(),
        "input_shape": list(model.input_shape_),
    }
    (folder / "settings.json").write_text(json.dumps(settings, indent=1, default=jsonable))
    torch.save(tensors, folder / "weights.pt")
    np.savez(folder / "arrays.npz", **arrays)


def write_state(folder: Path, settings: Mapping[str, Any], arrays: Mapping[str, Any]) -> None:
    """Fitted preprocessing: its settings as JSON and its arrays as npz."""
    (folder / "settings.json").write_text(
        json.dumps({"format": FORMAT, **settings}, indent=1, default=jsonable)
    )
    np.savez(folder / "arrays.npz", **{k: np.asarray(v) for k, v in arrays.items()})


def jsonable(value: Any) -> Any:
    """``json.dumps``' ``default`` for numpy values, tuples and a model's ``Schedule``."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):  # a model's Schedule
        return dataclasses.asdict(value)
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, tuple | np.ndarray):
        return list(value)
    raise TypeError(f"cannot store {type(value).__name__} as JSON")


def download(tracker: Tracker, run_id: str, path: str, files: tuple[str, ...]) -> Path:
    """Artifact folder ``path`` of ``run_id`` as a local folder holding every one of ``files``."""
    try:
        local = Path(tracker.client.download_artifacts(run_id, path))
    except Exception as err:
        raise ArtifactError(f"run {run_id}: artifact {path}/ cannot be read ({err})") from None
    check_files(local, files, f"run {run_id}: artifact {path}")
    return local


def check_files(folder: Path, files: tuple[str, ...], where: str) -> None:
    """ArtifactError naming the artifact ``where`` when ``folder`` lacks any of ``files``."""
    missing = [f for f in files if not (folder / f).is_file()]
    if missing:
        raise ArtifactError(f"{where}/ lacks {', '.join(missing)}")


def read_json(folder: Path, where: str, name: str = "settings.json") -> dict[str, Any]:
    try:
        settings = json.loads((folder / name).read_text())
    except (OSError, ValueError) as err:
        raise ArtifactError(f"{where}/{name} is not readable JSON ({err})") from None
    if not isinstance(settings, dict) or settings.get("format") != FORMAT:
        raise ArtifactError(f"{where}/{name}: expected a mapping with format {FORMAT}")
    return settings


def read_arrays(folder: Path, where: str) -> dict[str, np.ndarray]:
    try:
        with np.load(folder / "arrays.npz", allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except (OSError, ValueError) as err:
        raise ArtifactError(f"{where}/arrays.npz is not a readable npz file ({err})") from None


def read_model(folder: Path, where: str, overrides: Mapping[str, Any] | None = None) -> Any:
    """The fitted model stored in ``folder`` (``where`` names it in errors: run id and path).

    ``overrides``: settings that change no learned weight (``MODEL_UNKEYED``: the head's schedule,
    the kernels, the device; dotted keys as ``unkeyed`` gives them) taken from the caller
    instead of the stored ones."""
    import torch

    from tactile_exp.models.registry import MODELS

    check_files(folder, MODEL_FILES, where)
    settings = read_json(folder, where)
    try:
        name, params = str(settings["model"]), dict(settings["params"])
        shape = tuple(int(n) for n in settings["input_shape"])
    except (KeyError, TypeError, ValueError) as err:
        raise ArtifactError(f"{where}/settings.json: missing or bad entry ({err})") from None
    for path, value in (overrides or {}).items():
        *parents, leaf = path.split(".")
        node = params
        for parent in parents:
            node[parent] = node = dict(node.get(parent) or {})
        node[leaf] = value
    try:
        tensors = torch.load(folder / "weights.pt", map_location="cpu", weights_only=True)
    except Exception as err:
        raise ArtifactError(f"{where}/weights.pt is not a readable state_dict ({err})") from None
    if not isinstance(tensors, dict) or not all(
        isinstance(v, torch.Tensor) for v in tensors.values()
    ):
        raise ArtifactError(f"{where}/weights.pt: expected a mapping of names to tensors")
    arrays = read_arrays(folder, where)
    try:
        model = MODELS.build(name, **params)
        return model.restore(shape, tensors, arrays)
    except (KeyError, TypeError, ValueError) as err:
        raise ArtifactError(f"{where}: the stored {name} model does not load ({err})") from None


def load_model(
    tracker: Tracker, run_id: str, path: str, overrides: Mapping[str, Any] | None = None
) -> Any:
    """The model kept as artifact ``path`` of run ``run_id`` (see ``read_model``)."""
    folder = download(tracker, run_id, path, MODEL_FILES)
    return read_model(folder, f"run {run_id}: artifact {path}", overrides)
