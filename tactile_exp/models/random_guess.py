"""Random guess (M6, Table I row O): seeded uniform scores, AUC 0.5 in expectation."""

from __future__ import annotations

import numpy as np

from tactile_exp.data.layout import Instances
from tactile_exp.models.base import EpochCallback, History, Model
from tactile_exp.models.registry import MODELS


@MODELS.register("random")
class RandomGuess(Model):
    """Scores drawn from U(0, 1), independent of the input; the chance floor of Table I."""

    learns_representation = False
    reads = ()  # no schedule, no loss
    applies = False  # seeded random numbers: nothing to apply to new trials
    onnx_refusal = "its scores are seeded random numbers, not a network"

    def __init__(self, *, seed: int = 0) -> None:
        self.seed = seed
        self._rng = np.random.default_rng(seed)

    def fit(self, train: Instances, on_epoch: EpochCallback | None = None) -> History:
        return {}

    def decision_function(self, X: np.ndarray) -> np.ndarray:
        return self._rng.random(len(X))

    def head(self) -> Model:
        return RandomGuess(seed=self.seed + 1)
