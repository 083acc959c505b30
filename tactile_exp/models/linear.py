"""The linear "loss layer" (registered as ``linear``): an ``SGDModel`` with an identity body on
standardised inputs, and what ``SGDModel.head()`` returns for combined instances (T4)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from torch import nn

from tactile_exp.models.registry import MODELS
from tactile_exp.models.sgd import SGDModel


@MODELS.register("linear")
class LinearModel(SGDModel):
    """A linear classifier on flattened, standardised features (the paper's loss layer).

    Inputs are standardised with the training rows' mean and std (constant columns keep std 1),
    so one learning rate suits concatenated activations of any size and scale. With the default
    schedule the same layer is trained with logistic loss, then fine-tuned with hinge loss.
    """

    learns_representation = False

    def _fit_preprocessing(self, X: np.ndarray) -> None:
        flat = X.reshape(len(X), -1).astype(np.float64)
        std = flat.std(axis=0)
        self.mean_ = flat.mean(axis=0).astype(np.float32)
        self.scale_ = np.where(std > 0, std, 1.0).astype(np.float32)

    def _state_arrays(self) -> dict[str, np.ndarray]:
        return {"mean": self.mean_, "scale": self.scale_}

    def _set_state_arrays(self, arrays: Mapping[str, np.ndarray]) -> None:
        self.mean_ = np.asarray(arrays["mean"], dtype=np.float32)
        self.scale_ = np.asarray(arrays["scale"], dtype=np.float32)

    def _preprocess(self, X: np.ndarray) -> np.ndarray:
        return (X.reshape(len(X), -1) - self.mean_) / self.scale_

    def _build_body(self, input_shape: tuple[int, ...]) -> tuple[nn.Module, int]:
        return nn.Identity(), int(np.prod(input_shape))

    def transform(self, X: np.ndarray) -> np.ndarray:
        """Flattened rows (the identity: a linear model learns no representation)."""
        return np.asarray(X).reshape(len(X), -1)
