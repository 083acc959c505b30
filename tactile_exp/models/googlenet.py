"""The visual CNN's loss layer (M3): a linear classifier on the frozen GoogLeNet trunk's features.

The trunk, its weights and its input live in ``tactile_exp.preprocess.trunk``: the ``visual``
modality runs it once per data set and weights file (cached on disk), so this model only sees
its pooled, L2-normalised inception (5a) features (see that module's docstring for why).
"""

from __future__ import annotations

import numpy as np
from torch import nn

from tactile_exp.data.layout import InstanceSpec
from tactile_exp.models.registry import MODELS
from tactile_exp.models.sgd import SGDModel
from tactile_exp.preprocess.trunk import INCEPTION5A_CHANNELS


@MODELS.register("visual_googlenet")
class VisualGoogLeNet(SGDModel):
    """M3's loss layer: a linear classifier on the frozen trunk's pooled, L2-normalised
    inception (5a) features, which the ``visual`` modality supplies as (n, 832) rows.

    Unlike ``linear`` it does not standardise its input: the paper puts the loss directly after
    the L2 normalisation. Trained by the two-stage SGD schedule (T2, T3); ``head()`` gives the
    ``linear`` model for concatenated views (row L), without standardisation either. Unit-norm
    rows need a larger step than T3's (conf/model/visual_googlenet.yaml says which and why).
    """

    learns_representation = False  # the representation is the frozen trunk's, computed upstream
    head_standardize = False  # row L's head: the loss directly on the concatenated unit-norm rows
    accepts = ("features",)  # the visual modality's trunk features (check_input: their width)

    def check_input(self, spec: InstanceSpec) -> None:
        if spec.shape != (INCEPTION5A_CHANNELS,):
            raise ValueError(
                "visual_googlenet is the loss layer on the visual modality's "
                f"({INCEPTION5A_CHANNELS},) trunk features, got {spec.describe()}"
            )

    def _check_input(self, X: np.ndarray) -> None:
        if X.ndim != 2 or X.shape[1] != INCEPTION5A_CHANNELS:
            raise ValueError(
                f"visual_googlenet expects the visual modality's pooled inception (5a) features "
                f"of shape (n, {INCEPTION5A_CHANNELS}), got rows of shape {X.shape[1:]}"
            )

    def _build_body(self, input_shape: tuple[int, ...]) -> tuple[nn.Module, int]:
        return nn.Identity(), int(input_shape[0])

    def transform(self, X: np.ndarray) -> np.ndarray:
        """The features themselves: the trunk is upstream, the loss layer learns no features."""
        return np.asarray(X).reshape(len(X), -1)
