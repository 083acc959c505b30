"""Where trained models come from: one interface, ``get_or_train(key, train)``, for every model a
job might find already trained (an adjective's model, a modality's part such as row M's ConvNet).

``MemoryCache`` keeps them for the life of a process (tests, notebooks): each model is kept as
the files a stored pipeline holds (``artifacts``), so a model found here is loaded exactly as one
found in the MLflow store (``store.MlflowCache``, which adds claims between jobs side by side).
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from tactile_exp import artifacts
from tactile_exp.models.base import History, Model

Train = Callable[[], tuple[Model, History]]  # trains the model here: (fitted model, its curves)


@dataclass
class Trained:
    """A model from a cache: trained now (``source`` None, its curves in ``history``) or found
    (``source`` says where it was trained: a run id, a key)."""

    model: Model
    history: History = field(default_factory=dict)
    source: str | None = None


class ModelCache(Protocol):
    def get_or_train(
        self,
        key: str,
        train: Train,
        *,
        part: str | None = None,
        overrides: Mapping[str, Any] | None = None,
    ) -> Trained:
        """The model of training key ``key``: found, or ``train()``-ed and kept under ``key``.

        ``part``: a modality's part (its name), None for the adjective's own model.
        ``overrides``: settings a found model takes from the caller (``keys.unkeyed``)."""
        ...


class NoCache:
    """Trains every time and keeps nothing (``tracking.reuse=false`` without a store)."""

    def get_or_train(
        self,
        key: str,
        train: Train,
        *,
        part: str | None = None,
        overrides: Mapping[str, Any] | None = None,
    ) -> Trained:
        return Trained(*train())


class MemoryCache:
    """Models kept in a temporary folder of this process, one per training key."""

    def __init__(self) -> None:
        self._folder = tempfile.TemporaryDirectory(prefix="tactile_exp-cache-")
        self.keys: list[str] = []  # in the order they were trained

    def get_or_train(
        self,
        key: str,
        train: Train,
        *,
        part: str | None = None,
        overrides: Mapping[str, Any] | None = None,
    ) -> Trained:
        folder = Path(self._folder.name) / key
        if folder.is_dir():
            return Trained(artifacts.read_model(folder, f"cache {key}", overrides), source=key)
        model, history = train()
        folder.mkdir()
        artifacts.write_model(folder, artifacts.model_name(model), model)
        self.keys.append(key)
        return Trained(model, history)
