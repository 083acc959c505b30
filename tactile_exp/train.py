"""The SGD loop shared by every trained model (T3), device resolution and seeding.

Kept free of the model registry (a batch's step arrives as a callable) so models can import it
without an import cycle; the two-stage schedule that uses it lives in ``models/sgd.py``
(``SGDModel``).
"""

from __future__ import annotations

import random
from collections.abc import Callable, Collection, Sequence

import numpy as np
import torch
from torch import nn


def resolve_device(device: str) -> torch.device:
    """``"auto"`` -> CUDA when available, else CPU; otherwise the named device, checked.

    A CUDA device also turns TF32 off (``ieee_fp32_on_cuda``)."""
    if device == "auto":
        resolved = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    else:
        try:
            resolved = torch.device(device)
        except RuntimeError as err:
            raise ValueError(f"device={device!r} is not 'auto', 'cpu' or 'cuda[:N]'") from err
        if resolved.type == "cuda" and not torch.cuda.is_available():
            raise ValueError(f"device={device!r} but CUDA is not available; use 'auto' or 'cpu'")
    if resolved.type == "cuda":
        ieee_fp32_on_cuda()
    return resolved


def device_name(device: str) -> str:
    """What ``device`` resolves to on this machine, for the run's ``device`` tag: ``cpu``, or the
    CUDA device and its GPU (``cuda:0 (NVIDIA H100 80GB HBM3)``)."""
    resolved = resolve_device(device)
    if resolved.type != "cuda":
        return str(resolved)
    index = torch.cuda.current_device() if resolved.index is None else resolved.index
    return f"cuda:{index} ({torch.cuda.get_device_name(index)})"


def ieee_fp32_on_cuda() -> None:
    """Full float32 in cuDNN convolutions/RNNs and CUDA matmuls (no TF32), for this process.

    cuDNN convolutions default to TF32 on Ampere and later GPUs (10-bit mantissa): the haptic
    ConvNet's conv3 then differed from the CPU kernels by ~4e-4 relative, and GoogLeNet's
    inception (5a) features by up to 1.4e-4 absolute (measured on an H100), while caches and
    stored models are shared between CPU and GPU runs (the device is not part of their keys).
    These models are far too small for TF32 to pay off."""
    backends = torch.backends
    if hasattr(backends.cudnn, "conv"):  # torch >= 2.9: the new API only (never mix them)
        for flags in (backends.cudnn.conv, backends.cudnn.rnn, backends.cuda.matmul):
            flags.fp32_precision = "ieee"
    else:  # pragma: no cover - older torch
        backends.cudnn.allow_tf32 = False
        backends.cuda.matmul.allow_tf32 = False


def seed_everything(seed: int) -> torch.Generator:
    """Seed Python, numpy and torch; return a CPU generator for batch shuffling."""
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)
    return torch.Generator().manual_seed(seed)


def validate_losses(*, loss: str, pretrain_loss: str | None, known_losses: Collection[str]) -> None:
    """Raise ValueError naming the bad loss argument and the registered losses."""
    losses = ", ".join(sorted(known_losses))
    if loss not in known_losses:
        raise ValueError(f"loss must be one of {losses}, got {loss!r}")
    if pretrain_loss is not None and pretrain_loss not in known_losses:
        raise ValueError(f"pretrain_loss must be one of {losses} or None, got {pretrain_loss!r}")


# (X, y, the batch's row index) -> the batch's mean loss, detached, its gradient added to the
# parameters' ``.grad`` (``sgd_epochs``)
Step = Callable[[torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor]


def autograd_step(
    loss_of: Callable[[torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor],
) -> Step:
    """The step of a loss autograd differentiates: ``loss_of(X, y, index)`` and its backward."""

    def step(X: torch.Tensor, y: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
        value = loss_of(X, y, index)
        value.backward()
        return value.detach()

    return step


def add_gradients(params: Sequence[torch.Tensor], grads: Sequence[torch.Tensor]) -> None:
    """Each gradient added to its parameter's ``.grad`` as autograd's backward adds it: taken
    as it is where ``.grad`` is None (no copy), else added in place."""
    with torch.no_grad():
        for param, grad in zip(params, grads, strict=True):
            if param.grad is None:
                param.grad = grad
            else:
                param.grad.add_(grad)


def sgd_epochs(
    step: Step,
    params: list[nn.Parameter],
    X: torch.Tensor,
    y: torch.Tensor,
    *,
    epochs: int,
    batch_size: int,
    lr: float,
    momentum: float,
    generator: torch.Generator,
    report: Callable[[float], None] | None = None,
) -> list[float]:
    """Minibatch SGD with momentum (``momentum_step``) over shuffled ``X``; returns the mean
    loss of each epoch.

    ``step(X, y, index)`` returns the mean loss of the rows ``index`` of ``X``, detached, with
    its gradient added to the parameters' ``.grad``: ``autograd_step`` of a loss, or one pass
    that computes both, reading the rows in place rather than from a copied batch (the compiled
    haptic ConvNet's and LSTM's: no autograd graph around a kernel that already has the
    gradients)."""
    velocity: list[torch.Tensor | None] = [None] * len(params)
    n = len(X)
    curve = []
    for _ in range(epochs):
        order = torch.randperm(n, generator=generator).to(X.device)
        total = torch.zeros((), device=X.device)
        for start in range(0, n, batch_size):
            index = order[start : start + batch_size]
            for param in params:
                param.grad = None
            value = step(X, y, index)
            momentum_step(params, velocity, lr=lr, momentum=momentum)
            total += value * len(index)
        curve.append(float(total) / n)
        if report is not None:
            report(curve[-1])
    return curve


@torch.no_grad()
def momentum_step(
    params: Sequence[torch.Tensor],
    velocity: list[torch.Tensor | None],
    *,
    lr: float,
    momentum: float,
) -> None:
    """One step of ``torch.optim.SGD(params, lr, momentum)`` (no dampening, weight decay or
    Nesterov), op for op as its CPU update, so the same bits: ``velocity[i]`` starts as a copy
    of the first gradient, then ``v = momentum * v + grad``; ``param -= lr * v``. Written out
    because torch.optim's first optimiser imports torch's compiler stack (torch._dynamo: ~0.9 s
    and 70 MB in every training process), and that import's frames keep the caller's alive
    until the cyclic garbage collector runs (the first adjective's training set with them).
    Parameters without a gradient are left as they are."""
    for i, param in enumerate(params):
        grad = param.grad
        if grad is None:
            continue
        if momentum != 0:
            if velocity[i] is None:
                velocity[i] = grad.detach().clone()
            else:
                velocity[i].mul_(momentum).add_(grad)
            grad = velocity[i]
        param.add_(grad, alpha=-lr)


def caffe_xavier_(weight: torch.Tensor, fan_in: int) -> torch.Tensor:
    """Caffe's default "xavier" filler (the paper's init): U(+-sqrt(3 / fan_in))."""
    bound = (3.0 / fan_in) ** 0.5
    with torch.no_grad():
        return weight.uniform_(-bound, bound)
