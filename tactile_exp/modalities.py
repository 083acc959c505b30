"""What a model sees: the ``modality`` config group.

A modality turns one adjective's split into training and test ``Instances``, fitting whatever it
must fit (normaliser, PCA, HMM chains) on the training trials only. ``prepare`` does the one pass
over the file that every adjective shares (cached on disk), before any training starts.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tactile_exp.data.layout import Split, TrialName
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.models.base import Instances
from tactile_exp.registry import Registry


class Modality(ABC):
    def __init__(self, dataset: PHAC2, cache_dir: Path) -> None:
        self.dataset = dataset
        self.cache_dir = cache_dir

    @abstractmethod
    def prepare(self) -> None:
        """Read and cache what all adjectives share; raises on bad input before any training."""

    @abstractmethod
    def instances(self, split: Split) -> tuple[Instances, Instances]:
        """Training and test instances of one adjective's split."""


MODALITIES: Registry[Modality] = Registry("modality", Modality)


def _bookkeeping(trials: Sequence[str], split: Split, per_trial: int) -> tuple[np.ndarray, ...]:
    names = np.repeat(np.asarray(trials, dtype=object), per_trial)
    y = np.repeat([split.labels[t] for t in trials], per_trial).astype(np.int64)
    objects = np.repeat([TrialName.parse(t).object_id for t in trials], per_trial)  # type: ignore[union-attr]
    return y, names, objects


@MODALITIES.register("haptic")
class Haptic(Modality):
    """P1-P6: each trial gives 2 fingers x ``offsets`` instances of (32 signals, ``steps``)."""

    def __init__(
        self,
        dataset: PHAC2,
        cache_dir: Path,
        steps: int = 150,
        offsets: int = 5,
        pca_components: int = 4,
        pac_downsample: str = "subsample",
        per_finger: bool = True,
        fit_on: str = "train",
    ) -> None:
        super().__init__(dataset, cache_dir)
        if fit_on not in ("train", "all"):
            raise ValueError(f"modality.fit_on must be 'train' or 'all', got {fit_on!r}")
        self.settings = dict(steps=steps, offsets=offsets, pac_downsample=pac_downsample)
        self.pca_components = pca_components
        self.per_finger = per_finger
        self.fit_on = fit_on

    def prepare(self) -> None:
        from tactile_exp.preprocess.haptic import load_haptic_arrays

        self.arrays = load_haptic_arrays(self.dataset, cache_dir=self.cache_dir, **self.settings)

    def instances(self, split: Split) -> tuple[Instances, Instances]:
        from tactile_exp.preprocess.haptic import HapticPreprocessor

        pre = HapticPreprocessor(self.arrays, self.pca_components, self.per_finger)
        pre.fit(split.train if self.fit_on == "train" else self.arrays.trials)
        return self._instances(pre, split.train, split), self._instances(pre, split.test, split)

    def _instances(self, pre, trials: Sequence[str], split: Split) -> Instances:
        X = pre.transform(trials)  # (n, fingers, offsets, 32, steps)
        per_trial = X.shape[1] * X.shape[2]
        y, names, objects = _bookkeeping(trials, split, per_trial)
        return Instances(X.reshape(-1, *X.shape[3:]), y, names, objects)


@MODALITIES.register("haptic_features")
class HapticFeatures(Modality):
    """Chu et al.'s hand-designed features (M5): one vector per trial."""

    def __init__(self, dataset: PHAC2, cache_dir: Path, **settings: Any) -> None:
        """``settings``: BaselineFeatures' (features, faithful, dynamic_pool, hmm_grid, ...)."""
        super().__init__(dataset, cache_dir)
        from tactile_exp.baselines.features import BaselineFeatures

        self.features = BaselineFeatures(dataset, cache_dir=cache_dir, **settings)

    def prepare(self) -> None:
        self.features.prepare()

    def instances(self, split: Split) -> tuple[Instances, Instances]:
        self.features.fit(split)
        out = []
        for trials in (split.train, split.test):
            X = self.features.transform(trials).astype(np.float32)
            out.append(Instances(X, *_bookkeeping(trials, split, 1)))
        return out[0], out[1]
