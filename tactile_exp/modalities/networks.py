"""The plain-torch network a fitted pipeline exports to ONNX, and the manifest's input layouts.

A modality that exports (``Modality.onnx_network``) builds a `Network` from its stored models: a
`DecisionNet` from preprocessed inputs to one decision value per row, the inputs' shapes and
what each input holds. The ConvNet and the LSTM train with numba kernels, but their weights are
ordinary ``nn.Module`` parameters, so a stored model loaded with ``impl="torch"`` (a setting that
changes no weight, ``keys.MODEL_UNKEYED``) is already plain torch: grouped ``Conv1d`` and
``nn.LSTM``. Writing the files is ``tactile_exp.deploy.onnx_export``'s.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from tactile_exp.data.layout import EPS
from tactile_exp.preprocess.haptic import N_SCALAR, SIGNALS
from tactile_exp.preprocess.trunk import INCEPTION5A_CHANNELS as FEATURES

TRUNK_FILE = "googlenet.onnx"
FINGERS = 2
Load = Callable[[str], Any]  # artifact path of the saved pipeline -> its model (plain torch)


class DecisionNet(nn.Module):
    """Inputs -> one decision value per row (> 0: the adjective applies), in plain torch.

    ``body`` maps an instance to its features. With ``per_unit`` the first input holds ``k``
    instances per row whose features are concatenated in order (T4's ``concat``); any further
    input (a visual unit: views x 832) is flattened and appended. ``mean``/``scale``: the
    standardisation of a ``linear`` layer (None: none), then ``layer`` gives the score.
    """

    def __init__(
        self,
        body: nn.Module,
        layer: nn.Linear,
        mean: np.ndarray | None = None,
        scale: np.ndarray | None = None,
        *,
        per_unit: bool = False,
    ) -> None:
        super().__init__()
        self.body, self.layer, self.per_unit = body, layer, per_unit
        as_tensor = None if mean is None else torch.as_tensor(np.asarray(mean, np.float32))
        self.register_buffer("mean", as_tensor)
        as_tensor = None if scale is None else torch.as_tensor(np.asarray(scale, np.float32))
        self.register_buffer("scale", as_tensor)

    def forward(self, first: torch.Tensor, *more: torch.Tensor) -> torch.Tensor:
        n = first.shape[0]
        x = self.body(first.flatten(0, 1) if self.per_unit else first).reshape(n, -1)
        if more:
            x = torch.cat([x, *(m.reshape(n, -1) for m in more)], dim=1)
        if self.mean is not None:
            x = (x - self.mean) / self.scale
        return self.layer(x).squeeze(1)


@dataclass(frozen=True)
class Network:
    """One adjective's exported network: its inputs' shapes (None: any number of rows), the
    manifest's layout of each input kind it takes (``haptic``, ``visual``) and, for visual
    inputs, the trunk that computes them (weights, seed, ...: one per job)."""

    net: DecisionNet
    inputs: dict[str, list[int | None]]
    layouts: dict[str, dict[str, Any]]
    trunk: tuple[Any, ...] | None = None


def channel_names(pca_components: int) -> list[str]:
    """The haptic instance's channels in order: per EP, PAC, PDC, TAC, TDC and the electrode PCs."""
    own = [s.upper() for s in SIGNALS[:N_SCALAR]] + [f"PC{i + 1}" for i in range(pca_components)]
    return [f"{ep}.{name}" for ep in EPS for name in own]


def layer(model: Any) -> tuple[nn.Linear, np.ndarray | None, np.ndarray | None]:
    """A stored SGD model's classification layer and its standardisation (``linear`` only)."""
    model.classifier_.eval()
    return model.classifier_, getattr(model, "mean_", None), getattr(model, "scale_", None)


def haptic_layout(settings: dict[str, Any], trials: int) -> dict[str, Any]:
    return {
        "steps": int(settings["steps"]),
        "offsets": int(settings["offsets"]),
        "pac_downsample": settings["pac_downsample"],
        "pca_components": int(settings["pca_components"]),
        "per_finger": bool(settings["per_finger"]),
        "fingers": FINGERS,
        "trials_per_unit": trials,
        "instances_per_unit": trials * FINGERS * int(settings["offsets"]),
        "raw_signals": list(SIGNALS),
        "eps": list(EPS),
        "channels": channel_names(int(settings["pca_components"])),
        "instance": "(channels, steps): one finger's sub-sampled copy of a trial",
        "unit_order": "trials by name (an object's first ones repeated in order when fewer), "
        "then finger_0, finger_1, then offset",
    }


def visual_layout(settings: dict[str, Any], views: int) -> dict[str, Any]:
    return {
        "trunk": TRUNK_FILE,
        "size": int(settings["size"]),
        "layout": settings["layout"],
        "weights": settings["weights"],
        "seed": settings["seed"],
        "views_per_unit": views,
        "features": FEATURES,
        "unit_order": "the object's photographs by file name: the first views_per_unit (all of "
        "them repeated in order when fewer)",
    }


def trunk_of(settings: dict[str, Any]) -> tuple[Any, ...]:
    """What makes two jobs' GoogLeNet trunks the same network."""
    return (settings["size"], settings["layout"], settings["seed"], settings["weights"])
