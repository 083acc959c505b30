"""Binary losses on raw scores, registered by the names the ``loss`` config group uses (T2).

Labels arrive as 0/1 (the data set's convention) and are mapped to -1/+1 here, so every loss
sees the margin ``s * f`` and models never handle label conventions themselves.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from tactile_exp.registry import Registry

LOSSES: Registry[torch.Tensor] = Registry("loss")  # entries: (scores, y01) -> mean loss


def _margin(scores: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    return (2.0 * y.to(scores.dtype) - 1.0) * scores


@LOSSES.register("logistic")
def logistic(scores: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Mean log(1 + exp(-s f)): Caffe's sigmoid cross-entropy, the paper's first-stage loss."""
    return F.softplus(-_margin(scores, y)).mean()


@LOSSES.register("hinge")
def hinge(scores: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Mean max(0, 1 - s f): the loss behind the paper's reported results."""
    return F.relu(1.0 - _margin(scores, y)).mean()
