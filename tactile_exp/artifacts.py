"""Fitted models and preprocessing as files: what a stored pipeline is made of, whatever keeps it.

One model is a folder: ``settings.json`` (registry name, ``get_params()``, input shape),
``weights.pt`` (a flat ``state_dict``: ``body.*`` and ``classifier.*``) and ``arrays.npz`` (fitted
input statistics). Preprocessing state is a folder of ``settings.json`` and ``arrays.npz``.
Loading never runs stored code: JSON, ``torch.load(weights_only=True)``, ``np.load(allow_pickle=
False)``; every file is checked and an error names where it was read from (run id and artifact).
No tracking store here: the MLflow store (``store``) and the in-memory cache (``cache``) both
keep models in these folders.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from tactile_exp import dotted

FORMAT = 1  # bump when the artifact layout changes: older artifacts then no longer match keys
MODEL_FILES = ("settings.json", "weights.pt", "arrays.npz")
STATE_FILES = ("settings.json", "arrays.npz")


class ArtifactError(RuntimeError):
    """A stored model is missing, unreadable or does not fit; names the run and artifact."""


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

    ``overrides``: settings that change no learned weight (``keys.MODEL_UNKEYED``: the head's
    schedule, the kernels, the device; dotted keys as ``keys.unkeyed`` gives them) taken from
    the caller instead of the stored ones."""
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
        dotted.assign(params, path, value)
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
