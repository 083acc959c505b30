"""What a model sees: the ``modality`` config group.

A modality turns one adjective's split into training and test ``Instances``, fitting whatever it
must fit (normaliser, PCA, HMM chains) on the training trials only. ``prepare`` does the one pass
over the file that every adjective shares (cached on disk), before any training starts.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tactile_exp.data.layout import Instances, Split, TrialName
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.models.base import Model
from tactile_exp.registry import Component, Registry

# provide(part, split, training instances of the part's modality) -> the part's fitted model
PartProvider = Callable[[str, Split, Instances], Model]


class Modality(ABC):
    # Capability, declared: whether combining pads an object's last short group of instances by
    # repeating its own (True, haptic trials) or drops it (``combine.unit_members``).
    pad_units: bool = True

    def __init__(self, dataset: PHAC2, cache_dir: Path) -> None:
        self.dataset = dataset
        self.cache_dir = cache_dir

    def max_combine(self) -> tuple[int, str]:
        """The largest ``combine`` (instances of one object grouped as a unit) and its unit name."""
        return int(max(np.bincount([t.object_id for t in self.dataset.trials]))), "trials"

    @abstractmethod
    def prepare(self) -> None:
        """Read and cache what all adjectives share; raises on bad input before any training."""

    @abstractmethod
    def instances(self, split: Split) -> tuple[Instances, Instances]:
        """Training and test instances of one adjective's split."""

    def state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """Settings and arrays of what the last ``instances`` call fitted (kept with the model)."""
        return {}, {}

    def metrics(self) -> dict[str, float]:
        """Counts of the last ``instances`` call worth logging on the adjective's run."""
        return {}

    def parts(self) -> dict[str, tuple[Component, Component]]:
        """Trained models this modality's features come from: part -> (modality, model).

        The engine finds or trains each per adjective and hands it over through ``use_parts``.
        """
        return {}

    def use_parts(self, provide: PartProvider) -> None:
        """Receive the engine's ``provide(part, split, train) -> fitted model``."""
        self.provide = provide


MODALITIES: Registry[Modality] = Registry(
    "modality",
    Modality,
    modules=(
        "tactile_exp.modalities.haptic",
        "tactile_exp.modalities.haptic_features",
        "tactile_exp.modalities.multimodal",
        "tactile_exp.modalities.visual",
    ),
)


def trial_rows(trials: Sequence[str], split: Split, per_trial: int) -> tuple[np.ndarray, ...]:
    """Labels, names and object ids of ``per_trial`` consecutive rows per trial of ``trials``."""
    names = np.repeat(np.asarray(trials, dtype=object), per_trial)
    y = np.repeat([split.labels[t] for t in trials], per_trial).astype(np.int64)
    objects = np.repeat([TrialName.parse(t).object_id for t in trials], per_trial)  # type: ignore[union-attr]
    return y, names, objects
