"""The linear "loss layer" (registered as ``linear``): an ``SGDModel`` with an identity body on
(by default) standardised inputs, and what ``SGDModel.head()`` returns for combined instances
(T4)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from torch import nn

from tactile_exp.models.registry import MODELS
from tactile_exp.models.schedule import Schedule
from tactile_exp.models.scratch import empty_on_huge_pages
from tactile_exp.models.sgd import SGDModel

ROW_BLOCK = 64  # rows per float64 block in _column_mean_std: 12 MB at 24,320 columns


def _column_mean_std(flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Float64 mean and (population) std of each column of ``flat``: the same sums in the same
    order as ``flat.astype(np.float64).mean(axis=0)`` and ``.std(axis=0)`` (row after row), in
    blocks of ``ROW_BLOCK`` rows, so no float64 copy of the whole matrix is made (the T4 head's
    530 x 24,320 features would take three of 103 MB each)."""
    n = len(flat)
    mean = np.add.reduce(flat, axis=0, dtype=np.float64) / n  # row after row, as numpy's mean
    squares = np.zeros(flat.shape[1])
    for start in range(0, n, ROW_BLOCK):
        block = np.subtract(flat[start : start + ROW_BLOCK], mean)
        np.multiply(block, block, out=block)
        for row in block:
            squares += row
    return mean, np.sqrt(squares / n)


@MODELS.register("linear")
class LinearModel(SGDModel):
    """A linear classifier on flattened features (the paper's loss layer).

    With ``standardize`` (the default) inputs are standardised with the training rows' mean and
    std (constant columns keep std 1), so one learning rate suits concatenated activations of any
    size and scale (not in the paper). Without it the layer sees its input as it comes: the
    visual rows' head (``VisualGoogLeNet.head_standardize``), which the paper puts directly on the
    L2-normalised features. With the default schedule the same layer is trained with logistic
    loss, then fine-tuned with hinge loss.
    """

    learns_representation = False

    def __init__(
        self,
        *,
        standardize: bool = True,
        schedule: Schedule | Mapping[str, Any] | None = None,
        loss: str = "hinge",
        pretrain_loss: str | None = "logistic",
        impl: str = "auto",
        seed: int = 0,
        device: str = "auto",
    ) -> None:
        if not isinstance(standardize, bool):
            raise ValueError(f"standardize must be true or false, got {standardize!r}")
        self.standardize = standardize
        super().__init__(
            schedule=schedule,
            loss=loss,
            pretrain_loss=pretrain_loss,
            impl=impl,
            seed=seed,
            device=device,
        )

    def _fit_preprocessing(self, X: np.ndarray) -> None:
        if not self.standardize:
            self.mean_ = self.scale_ = None
            return
        mean, std = _column_mean_std(X.reshape(len(X), -1))
        self.mean_ = mean.astype(np.float32)
        self.scale_ = np.where(std > 0, std, 1.0).astype(np.float32)

    def _state_arrays(self) -> dict[str, np.ndarray]:
        return {"mean": self.mean_, "scale": self.scale_} if self.standardize else {}

    def _set_state_arrays(self, arrays: Mapping[str, np.ndarray]) -> None:
        if not self.standardize:
            self.mean_ = self.scale_ = None
            return
        self.mean_ = np.asarray(arrays["mean"], dtype=np.float32)
        self.scale_ = np.asarray(arrays["scale"], dtype=np.float32)

    def _preprocess(self, X: np.ndarray) -> np.ndarray:
        flat = X.reshape(len(X), -1)
        if not self.standardize:
            return flat
        out = empty_on_huge_pages(*flat.shape)  # where a fit trains on it (``on_huge_pages``)
        np.subtract(flat, self.mean_, out=out, dtype=np.float32)
        return np.divide(out, self.scale_, out=out)

    def _build_body(self, input_shape: tuple[int, ...]) -> tuple[nn.Module, int]:
        return nn.Identity(), int(np.prod(input_shape))

    def transform(self, X: np.ndarray) -> np.ndarray:
        """Flattened rows (the identity: a linear model learns no representation)."""
        return np.asarray(X).reshape(len(X), -1)
