"""Minibatch SGD of a one-output linear layer on fixed features, compiled (numba) for the CPU.

The classification layer is trained alone on frozen features twice per adjective: the
fine-tuning stage (T2) and the T4 head on combined units (24,320 columns at combine=1, batches
of 32). Through autograd each of those small steps pays for a gathered batch copy and torch's
per-call overhead: row I's head took ~8 s of an adjective's ~49 s. Here a step reads its rows in
place, and each row's score, loss and gradient share one visit to the row (the weights move only
after the batch), so an epoch is one pass over the features.

Same algorithm as ``train.sgd_epochs`` with ``torch.optim.SGD`` (momentum, no dampening) and
the losses of ``models/losses.py``, on the same ``torch.randperm`` orders: the results agree with
the torch path to float rounding (tests).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from torch import nn

from tactile_exp.models.numba_setup import numba

LOSSES = ("logistic", "hinge")  # the registered losses this loop computes (others: impl=torch)
SOFTPLUS_THRESHOLD = 20.0  # torch's F.softplus: the identity above it


@numba.njit(nogil=True, cache=True, fastmath={"reassoc", "contract", "nsz"}, error_model="numpy")
def _epoch(X, sign, order, w, b, vel_w, vel_b, lr, momentum, batch, hinge, grad):
    """One epoch over ``order``; updates w, b and their momentum buffers in place, returns the
    summed loss."""
    n, d = X.shape
    total = 0.0
    for start in range(0, n, batch):
        size = min(batch, n - start)
        scale = np.float32(1.0) / np.float32(size)  # the mean's gradient
        grad_b = np.float32(0.0)
        touched = False
        for r in range(start, start + size):
            i = order[r]
            row = X[i]
            s = b[0]
            for j in range(d):
                s += row[j] * w[j]
            m = sign[i] * s
            if hinge:
                slack = np.float32(1.0) - m
                total += max(slack, np.float32(0.0))
                g = -sign[i] * scale if slack > 0 else np.float32(0.0)
            else:
                x = -m
                if x > SOFTPLUS_THRESHOLD:
                    total += x
                    g = -sign[i] * scale
                else:
                    z = np.exp(x)
                    total += np.log1p(z)
                    g = -sign[i] * scale * (z / (z + np.float32(1.0)))
            if g == 0:
                continue
            grad_b += g
            if touched:
                for j in range(d):
                    grad[j] += g * row[j]
            else:  # the first row writes the gradient: never zeroed first
                for j in range(d):
                    grad[j] = g * row[j]
                touched = True
        if not touched:
            grad[:] = 0.0
        for j in range(d):  # from zero buffers: torch's first step (buffer = gradient)
            vel_w[j] = momentum * vel_w[j] + grad[j]
        vel_b[0] = momentum * vel_b[0] + grad_b
        for j in range(d):
            w[j] -= lr * vel_w[j]
        b[0] -= lr * vel_b[0]
    return total


def check_loss(loss: str) -> None:
    """Raise ValueError unless this loop computes ``loss``."""
    if loss not in LOSSES:
        raise ValueError(
            f"the compiled linear SGD computes the losses {', '.join(LOSSES)}, not {loss!r}: "
            "use impl=torch"
        )


def linear_sgd_epochs(
    layer: nn.Linear,
    X: torch.Tensor,
    y: torch.Tensor,
    *,
    loss: str,
    epochs: int,
    batch_size: int,
    lr: float,
    momentum: float,
    generator: torch.Generator,
    report: Callable[[float], None] | None = None,
) -> list[float]:
    """``train.sgd_epochs`` for ``layer`` (one output, on CPU) applied to the rows of ``X``:
    the same shuffles from ``generator``, updates and per-epoch mean losses."""
    if layer.out_features != 1 or layer.weight.device.type != "cpu":
        raise ValueError("the compiled linear SGD trains a one-output layer on CPU")
    check_loss(loss)
    features = np.ascontiguousarray(X.detach().numpy().reshape(len(X), -1), dtype=np.float32)
    sign = (2.0 * y.detach().numpy() - 1.0).astype(np.float32)
    with torch.no_grad():  # updated in place through numpy views of the parameters
        w, b = layer.weight.detach().numpy().reshape(-1), layer.bias.detach().numpy()
        vel_w, vel_b = np.zeros_like(w), np.zeros_like(b)
        grad = np.empty_like(w)
        curve = []
        for _ in range(epochs):
            order = torch.randperm(len(features), generator=generator).numpy()
            total = _epoch(
                features,
                sign,
                order,
                w,
                b,
                vel_w,
                vel_b,
                np.float32(lr),
                np.float32(momentum),
                batch_size,
                loss == "hinge",
                grad,
            )
            curve.append(total / len(features))
            if report is not None:
                report(curve[-1])
    return curve
