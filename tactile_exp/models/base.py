"""What every classifier looks like to the experiment engine.

A model is scikit-learn shaped: ``fit`` on training instances, ``decision_function`` on anything.
Models that learn a representation (the haptic CNN's conv3, the LSTM) also ``transform`` instances
into features, and ``head()`` gives a fresh classifier for features combined over several
instances: the paper's "concatenate activations and retrain only the loss layer" (T4).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

# on_epoch(epoch, n_epochs, metrics): called after each epoch (1-based) to show progress.
EpochCallback = Callable[[int, int, dict[str, float]], None]
History = dict[str, list[float]]  # metric name -> one value per epoch


@dataclass
class Instances:
    """Model inputs with the bookkeeping needed to combine, split and evaluate them."""

    X: np.ndarray  # (n, ...) float32
    y: np.ndarray  # (n,) int 0/1
    trial: np.ndarray  # (n,) trial group names
    object_id: np.ndarray  # (n,) int

    def __post_init__(self) -> None:
        n = len(self.X)
        for key in ("y", "trial", "object_id"):
            if len(getattr(self, key)) != n:
                raise ValueError(f"Instances.{key} has {len(getattr(self, key))} rows, X has {n}")

    def __len__(self) -> int:
        return len(self.X)


class Model(ABC):
    """A binary classifier for one adjective."""

    learns_representation: bool = True  # False: transform() needs no fit (e.g. hand features)

    @abstractmethod
    def fit(self, train: Instances, on_epoch: EpochCallback | None = None) -> History:
        """Train on ``train``; return per-epoch curves (empty for non-iterative models)."""

    @abstractmethod
    def decision_function(self, X: np.ndarray) -> np.ndarray:
        """One real score per row of ``X``; larger means more likely positive."""

    def transform(self, X: np.ndarray) -> np.ndarray:
        """Features (n, D) to combine over instances; the identity unless overridden."""
        return X.reshape(len(X), -1)

    def head(self) -> Model:
        """A fresh classifier for combined features (T4: retrain only the loss layer)."""
        raise NotImplementedError(f"{type(self).__name__} cannot classify combined instances")
