"""What a model sees: the ``modality`` config group.

A modality is a preprocessor, shaped as scikit-learn's: hyperparameters in the constructor, data
in ``fit(trials)`` (normaliser, PCA, HMM chains: fitted on training trials only) and
``transform(trials) -> Instances`` (training, validation, test or new trials alike). ``check``
makes the one pass over a data set that every adjective shares (cached on disk) before any run,
so bad input surfaces there. ``get_state``/``set_state`` carry what ``fit`` learned to the store.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from pathlib import Path
from typing import TYPE_CHECKING, Any, Self

import numpy as np

from tactile_exp.data.layout import Instances, InstanceSpec, TrialName, Trials
from tactile_exp.models.base import Model
from tactile_exp.registry import Component, Registry

if TYPE_CHECKING:
    from tactile_exp.modalities.networks import Load, Network


class Modality(ABC):
    # Capability, declared: whether combining pads an object's last short group of instances by
    # repeating its own (True, haptic trials) or drops it (``combine.unit_members``).
    pad_units: bool = True
    # What the data set must give for new trials: trials (signals), photographs, or both.
    takes_trials: bool = True
    takes_photographs: bool = False
    # What it needs from a data set, declared (checked by `lacks` when the data opens, never
    # by the sensor's name): trials in a physical layout (``Sensor.layout``, e.g. PHAC-2's
    # BioTac frames), or trials as (channels, time) arrays (``signals(name)``).
    needs_layout: str | None = None
    needs_signals: bool = False
    # The kind of instance rows it gives (`INSTANCE_KINDS`); `output` adds their shape.
    emits: str = ""
    # Why its fitted pipelines cannot be exported to ONNX, or None where `onnx_network` builds
    # the plain-torch network that computes them (``python -m tactile_exp.deploy onnx``).
    onnx_refusal: str | None = "its features are computed by this package's code, not a network"

    def __init__(self, *, cache_dir: Path | None = None) -> None:
        self.cache_dir = cache_dir

    @classmethod
    def onnx_network(
        cls, load: Load, settings: dict[str, Any], keeps: bool, combine: int
    ) -> Network:
        """One adjective's network, from its stored models (``load("model")``, ``load("head")``,
        ``load("parts/<part>")``, loaded as plain torch) and the modality's ``settings`` as the job
        set them; ``keeps``: the combiner scores instances one by one, else ``combine`` of them
        make a unit (T4). Raises NotImplementedError unless the modality declares it exports."""
        raise NotImplementedError(f"modality {cls.__name__}: {cls.onnx_refusal}")

    @classmethod
    def lacks(cls, dataset: Any) -> str | None:
        """What ``dataset`` does not give that this modality needs (a phrase), else None."""
        if cls.needs_layout and dataset.sensor.layout != cls.needs_layout:
            return f"trials in the {cls.needs_layout} layout"
        if cls.needs_signals and not callable(getattr(dataset, "signals", None)):
            return "trials as (channels, time) arrays"
        if cls.takes_photographs and not dataset.photographs():
            return "photographs"
        return None

    def output(self, dataset: Any) -> InstanceSpec:
        """What each instance row will be on ``dataset``: checked against the model when the
        data opens. Its kind, shape unknown, unless overridden."""
        return InstanceSpec(self.emits)

    def max_combine(self, dataset: Any) -> tuple[int, str]:
        """The largest ``combine`` (instances of one object grouped as a unit) and its unit name.
        Called when the data opens, before any run."""
        return int(max(np.bincount([t.object_id for t in dataset.trials]))), "trials"

    @abstractmethod
    def check(self, dataset: Any) -> None:
        """Read and cache what all adjectives share; raises on bad input before any training."""

    @abstractmethod
    def fit(self, trials: Trials) -> Self:
        """Learn the preprocessing from (training) ``trials``."""

    @abstractmethod
    def transform(self, trials: Trials) -> Instances:
        """The instances of ``trials``, labelled with ``trials.labels``."""

    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """What ``fit`` learned: JSON-able settings and arrays (kept with the model)."""
        return {}, {}

    def set_state(self, settings: dict[str, Any], arrays: dict[str, np.ndarray]) -> Self:
        """Take ``get_state()``'s output instead of fitting; ValueError/KeyError when it is off."""
        return self

    def metrics(self) -> dict[str, float]:
        """Counts of the last ``fit`` worth logging on the adjective's run."""
        return {}

    def parts(self) -> dict[str, tuple[Component, Component]]:
        """Trained models this modality's features come from: part -> (modality, model), the
        part's model trained on its own modality's instances of the same training trials.

        Whoever fits the modality finds or trains each one (by its training key) and gives them
        fitted through ``set_parts`` before ``fit``; a loaded pipeline gives the stored ones."""
        return {}

    def set_parts(self, parts: dict[str, Model]) -> None:
        """Take the fitted parts that ``parts()`` declares (before ``fit`` or ``set_state``)."""
        if parts:
            raise ValueError(f"{type(self).__name__} has no parts, got {sorted(parts)}")


MODALITIES: Registry[Modality] = Registry(
    "modality",
    Modality,
    modules=(
        "tactile_exp.modalities.haptic",
        "tactile_exp.modalities.haptic_features",
        "tactile_exp.modalities.multimodal",
        "tactile_exp.modalities.signals",
        "tactile_exp.modalities.visual",
    ),
)


def trial_rows(trials: Trials, per_trial: int) -> tuple[np.ndarray, ...]:
    """Labels, names and object ids of ``per_trial`` consecutive rows per trial of ``trials``."""
    names = np.repeat(np.asarray(trials.names, dtype=object), per_trial)
    y = np.repeat(trials.y(), per_trial).astype(np.int64)
    objects = np.repeat([TrialName.parse(t).object_id for t in trials.names], per_trial)  # type: ignore[union-attr]
    return y, names, objects
