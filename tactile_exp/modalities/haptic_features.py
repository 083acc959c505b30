"""The ``haptic_features`` modality: Chu et al.'s hand-designed features, one row per trial."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tactile_exp.data.layout import Instances, Split
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.modalities.base import MODALITIES, Modality, trial_rows


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
            out.append(Instances(X, *trial_rows(trials, split, 1)))
        return out[0], out[1]
