"""The ``signals`` modality: any sensor's raw channels, a (channels, ``steps``) instance per trial.

Ours, not the paper's: the generic counterpart of ``haptic`` (P1-P6 are the BioTac's) for a data
set that gives each trial as a (channels, time) array (``signals(name)``, as ``data=folder``
does). Each trial is resampled to ``steps`` samples by linear interpolation (a trial of any
length becomes one instance, as P3 resamples each EP) and each channel is standardised with the
mean and standard deviation of the training trials only.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Self

import numpy as np

from tactile_exp.data.layout import DataError, Instances, InstanceSpec, Trials
from tactile_exp.modalities.base import MODALITIES, Modality, trial_rows

log = logging.getLogger(__name__)
PROGRESS_LINES = 10  # check() logs at most this many progress lines, however many trials


def resample(x: np.ndarray, steps: int) -> np.ndarray:
    """(C, T) -> (C, ``steps``): linear interpolation at ``steps`` evenly spaced points from the
    first sample to the last (``np.interp`` per channel, in one pass); needs T >= 2."""
    n = x.shape[1]
    pos = np.linspace(0.0, n - 1, steps)
    left = np.minimum(pos.astype(np.int64), n - 2)
    weight = pos - left
    return x[:, left] * (1.0 - weight) + x[:, left + 1] * weight


@MODALITIES.register("signals")
class Signals(Modality):
    """Each trial as (channels, ``steps``), channels standardised on the training trials.

    ``check`` reads and resamples every trial of a data set once (so a bad file fails before any
    training) and keeps them in memory: one job reads each ``.npy`` once, and the files
    themselves are the cache, so nothing is written to ``cache_dir``. Trials of a data set that
    was not checked (a new object's, in predict) are read when transformed.
    """

    needs_signals = True
    emits = "signals"

    def __init__(self, *, cache_dir: Path | None = None, steps: int = 100) -> None:
        super().__init__(cache_dir=cache_dir)
        if isinstance(steps, bool) or not isinstance(steps, int) or steps < 2:
            raise ValueError(f"steps must be a whole number of samples >= 2, got {steps!r}")
        self.steps = steps
        self._checked: dict[str, dict[str, np.ndarray]] = {}  # data set identity -> trials

    @staticmethod
    def _require_signals(dataset: Any) -> None:
        if not callable(getattr(dataset, "signals", None)):
            raise DataError(
                f"{dataset.path}: modality=signals reads each trial as a (channels, time) array "
                f"(signals(name)), which this {type(dataset).__name__} data set does not give; "
                "use data=folder (or modality=haptic for PHAC-2's BioTac signals)"
            )

    def output(self, dataset: Any) -> InstanceSpec:
        return InstanceSpec(self.emits, (len(dataset.sensor.channels), self.steps))

    def check(self, dataset: Any) -> None:
        self._require_signals(dataset)
        out: dict[str, np.ndarray] = {}
        n = len(dataset.trials)
        every = max(1, -(-n // PROGRESS_LINES))  # ceil: at most PROGRESS_LINES lines
        for i, trial in enumerate(dataset.trials, 1):
            out[trial.name] = resample(dataset.signals(trial), self.steps)
            if i % every == 0 or i == n:
                log.info("signals: read %d/%d trials of %s", i, n, dataset.path)
        self._checked[dataset.identity()] = out

    def _signals(self, trials: Trials) -> np.ndarray:
        """(n, channels, steps) float64: the checked data set's trials, else read now."""
        checked = self._checked.get(trials.dataset.identity(), {})
        return np.stack(
            [
                checked[t] if t in checked else resample(trials.dataset.signals(t), self.steps)
                for t in trials.names
            ]
        )

    def fit(self, trials: Trials) -> Self:
        X = self._signals(trials)
        std = X.std(axis=(0, 2))
        self.channels_ = tuple(trials.dataset.sensor.channels)
        self.mean_ = X.mean(axis=(0, 2))
        self.scale_ = np.where(std > 0, std, 1.0)  # a constant channel stays centred, not inf
        return self

    def transform(self, trials: Trials) -> Instances:
        channels = tuple(trials.dataset.sensor.channels)
        if channels != self.channels_:
            raise DataError(
                f"{trials.dataset.path}: channels {list(channels)}, but modality=signals was "
                f"fitted on {list(self.channels_)} (expected the same sensor's channels)"
            )
        X = (self._signals(trials) - self.mean_[:, None]) / self.scale_[:, None]
        return Instances(X.astype(np.float32), *trial_rows(trials, 1))

    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """The channels and each one's training mean and standard deviation."""
        return {"channels": list(self.channels_)}, {"mean": self.mean_, "scale": self.scale_}

    def set_state(self, settings: dict[str, Any], arrays: dict[str, np.ndarray]) -> Self:
        channels = tuple(str(c) for c in settings["channels"])
        mean = np.asarray(arrays["mean"], dtype=np.float64)
        scale = np.asarray(arrays["scale"], dtype=np.float64)
        if mean.shape != (len(channels),) or scale.shape != mean.shape or not (scale > 0).all():
            raise ValueError(
                f"mean {mean.shape} and scale {scale.shape}: expected ({len(channels)},) each, "
                "one per channel, scale > 0"
            )
        self.channels_, self.mean_, self.scale_ = channels, mean, scale
        return self
