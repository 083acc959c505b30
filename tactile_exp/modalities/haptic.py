"""The ``haptic`` modality: P1-P6 signals, one instance per finger and offset of a trial."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tactile_exp.data.layout import Instances, Split
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.modalities.base import MODALITIES, Modality, trial_rows


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
        from tactile_exp.preprocess.haptic import N_ELECTRODES, check_settings

        check_settings(steps, offsets, pac_downsample)  # before any run, not in prepare()
        if not isinstance(pca_components, int) or not 1 <= pca_components <= N_ELECTRODES:
            raise ValueError(
                f"pca_components must be an integer in 1..{N_ELECTRODES} (electrodes per "
                f"BioTac), got {pca_components!r}"
            )
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
        self.fitted_ = pre
        return self._instances(pre, split.train, split), self._instances(pre, split.test, split)

    def state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """P1's normaliser and P4's PCA as fitted for the last split, with the P2-P6 settings."""
        settings = dict(
            modality="haptic", **self.settings, pca_components=self.pca_components,
            per_finger=self.per_finger, fit_on=self.fit_on,
        )  # fmt: skip
        return settings, self.fitted_.state()

    def _instances(self, pre, trials: Sequence[str], split: Split) -> Instances:
        X = pre.transform(trials)  # (n, fingers, offsets, 32, steps)
        per_trial = X.shape[1] * X.shape[2]
        y, names, objects = trial_rows(trials, split, per_trial)
        return Instances(X.reshape(-1, *X.shape[3:]), y, names, objects)
