"""The haptic ConvNet (M1): grouped temporal convolutions, one group per haptic signal.

PyTorch's CPU grouped ``Conv1d`` is the project's hot spot (bench/bench_haptic_cnn.py): with 32
groups of a few channels it runs at a few GFLOP/s. ``impl="compiled"`` runs the three conv + ReLU
layers through numba kernels over a batch-innermost layout (``grouped_conv_numba``; their autograd
function, ``grouped_conv_autograd``), an order of magnitude faster on CPU; ``impl="torch"`` runs
the plain ``F.conv1d(groups=...)``; ``impl="auto"`` (default) picks compiled on CPU and torch on
GPU (the kernels are CPU only). Both agree to float rounding (tests; ``bench/bench_haptic_cnn.py``
measures the speed). Training goes through ``GroupedTemporalConvNet.batch_step``, which compiled
runs the whole step, the classification layer, the loss and the gradients included, in tiles of
instances that stay in cache (``convnet_tiles``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from tactile_exp.data.layout import InstanceSpec
from tactile_exp.models.losses import LOSSES
from tactile_exp.models.registry import MODELS
from tactile_exp.models.schedule import Schedule
from tactile_exp.models.sgd import IMPLS, SGDModel
from tactile_exp.train import Step, caffe_xavier_

PER_CHANNEL = "channels"  # groups=channels: one group per input channel, whatever their number


def _conv_out_len(length: int, kernel: int, stride: int) -> int:
    return (length + 2 * (kernel // 2) - kernel) // stride + 1


class GroupedTemporalConvNet(nn.Module):
    """conv1..conv3 (+ ReLU each), each haptic signal in its own group; output conv3, flattened.

    Input (n, C, T) with C = groups x c_in; channel c belongs to group c mod ``groups``, so with
    both fingers concatenated along channels (finger-major, C = 64) each group sees the same
    signal from both fingers. The output is conv3 flattened in (group, width, time) order, i.e.
    the channel x time map of a ``Conv1d`` stack with channel g * width + j.
    """

    def __init__(
        self,
        n_channels: int,
        n_steps: int,
        *,
        groups: int = 32,
        kernel_sizes: Sequence[int] = (5, 5, 5),
        widths: Sequence[int] = (4, 4, 4),
        strides: Sequence[int] = (2, 2, 2),
        impl: str = "auto",
    ) -> None:
        super().__init__()
        if impl not in IMPLS:
            raise ValueError(f"impl must be one of {', '.join(IMPLS)}, got {impl!r}")
        if n_channels % groups:
            raise ValueError(f"input has {n_channels} channels, not a multiple of groups={groups}")
        if not len(kernel_sizes) == len(widths) == len(strides) == 3:
            raise ValueError(
                "kernel_sizes, widths and strides need one entry per conv layer (3), got "
                f"{list(kernel_sizes)}, {list(widths)}, {list(strides)}"
            )
        for name, values in (("kernel_sizes", kernel_sizes), ("widths", widths)):
            if min(values) < 1:
                raise ValueError(f"{name} must be >= 1, got {list(values)}")
        if min(strides) < 1:
            raise ValueError(f"strides must be >= 1, got {list(strides)}")
        self.groups, self.impl, self.strides = groups, impl, tuple(strides)
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        c_in, length = n_channels // groups, n_steps
        for k, width, stride in zip(kernel_sizes, widths, strides, strict=True):
            weight = nn.Parameter(torch.empty(groups * width, c_in, k))
            caffe_xavier_(weight, c_in * k)
            self.weights.append(weight)
            self.biases.append(nn.Parameter(torch.zeros(groups * width)))
            c_in, length = width, _conv_out_len(length, k, stride)
        if length < 1:
            raise ValueError(
                f"kernel_sizes {list(kernel_sizes)} with strides {list(strides)} leave no time "
                f"step of a {n_steps}-step input"
            )
        self.out_shape = (groups * widths[-1], length)  # conv3: channels x time
        self.n_features = int(np.prod(self.out_shape))

    def _compiled(self, x: torch.Tensor) -> bool:
        """Whether ``x`` goes through the numba kernels (``impl``; ``auto``: on CPU)."""
        if self.impl == "compiled" and x.device.type != "cpu":
            raise ValueError(f"impl='compiled' runs on CPU only, got input on {x.device}")
        # The kernels give no gradient for the input itself: torch's path does, when asked.
        return self.impl == "compiled" or (
            self.impl == "auto" and x.device.type == "cpu" and not x.requires_grad
        )

    def batch_step(
        self, x: torch.Tensor, y: torch.Tensor, head: nn.Linear, loss: str, rows: torch.Tensor
    ) -> torch.Tensor:
        """The training step (``train.sgd_epochs``): ``LOSSES[loss](head(self(x[rows]))
        .squeeze(1), y[rows])``, returned detached, its gradients added to the ``.grad`` of this
        net's and ``head``'s parameters. Compiled, for a one-output ``head`` and a loss the tiled
        step computes, one pass computes both a tile of instances at a time in cache, reading
        the rows in place (``convnet_tiles``); otherwise autograd."""
        if head.out_features == 1 and self._compiled(x):
            from tactile_exp.models import convnet_tiles  # numba: lazy

            if loss in convnet_tiles.LOSSES:
                return convnet_tiles.tiled_step(
                    x.float(),
                    rows,
                    y,
                    self.weights,
                    self.biases,
                    head,
                    loss=loss,
                    groups=self.groups,
                    strides=self.strides,
                )
        value = LOSSES[loss](head(self(x[rows])).squeeze(1), y[rows])
        value.backward()
        return value.detach()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self._compiled(x):
            from tactile_exp.models.grouped_conv_autograd import grouped_conv_stack  # numba: lazy

            return grouped_conv_stack(
                x.float(), self.weights, self.biases, groups=self.groups, strides=self.strides
            )
        n, channels, steps = x.shape
        h = x.view(n, channels // self.groups, self.groups, steps).transpose(1, 2)
        h = h.reshape(n, channels, steps)
        for weight, bias, stride in zip(self.weights, self.biases, self.strides, strict=True):
            h = F.conv1d(h, weight, bias, stride, weight.shape[2] // 2, 1, self.groups).relu()
        return h.flatten(1)


@MODELS.register("haptic_cnn")
class HapticCNN(SGDModel):
    """Haptic ConvNet (M1) trained by the two-stage schedule (T2, T3) of ``SGDModel``.

    The paper fixes three grouped conv layers with ReLU, groups of 32 and Xavier init, but not
    kernels or widths. Defaults chosen for speed on a 2-core CPU (bench/bench_haptic_cnn.py):
    kernels (5, 5, 5), widths (4, 4, 4) per group (128 channels per layer), stride 2 in every
    layer (150 -> 75 -> 38 -> 19 steps), so conv3 gives 128 x 19 = 2,432 features per instance.
    Stage 1 trains conv1..conv3 and the classification layer with ``pretrain_loss``; stage 2
    fine-tunes only the classification layer with ``loss`` on frozen conv3 features.
    ``transform`` returns conv3 activations flattened in (channel, time) order; reshape to
    ``conv3_shape_`` for a channel x time map.
    """

    accepts = ("signals",)  # (n, channels, time): groups must divide channels (check_input)
    body_kernels = ("tactile_exp.models.grouped_conv_numba", "tactile_exp.models.convnet_tiles")
    # Fitted: conv3's (channels, time), the map each row of ``transform`` flattens (Fig. 6)
    conv3_shape_: tuple[int, int] | None = None

    def __init__(
        self,
        *,
        kernel_sizes: Sequence[int] = (5, 5, 5),
        widths: Sequence[int] = (4, 4, 4),
        strides: Sequence[int] = (2, 2, 2),
        groups: int | str = 32,
        impl: str = "auto",
        schedule: Schedule | Mapping[str, Any] | None = None,
        loss: str = "hinge",
        pretrain_loss: str | None = "logistic",
        seed: int = 0,
        device: str = "auto",
    ) -> None:
        super().__init__(
            schedule=schedule,
            loss=loss,
            pretrain_loss=pretrain_loss,
            impl=impl,
            seed=seed,
            device=device,
        )
        self.kernel_sizes, self.widths, self.strides = kernel_sizes, widths, strides
        if isinstance(groups, str) and groups != PER_CHANNEL:
            raise ValueError(f"groups: expected a whole number or {PER_CHANNEL!r}, got {groups!r}")
        self.groups = groups
        self.net_args = dict(
            groups=1 if groups == PER_CHANNEL else groups,
            kernel_sizes=tuple(kernel_sizes),
            widths=tuple(widths),
            strides=tuple(strides),
            impl=impl,
        )
        self.check_steps(150)  # validate the architecture now (P3's 150 steps)

    def check_steps(self, n_steps: int) -> None:
        """Raise ValueError unless the conv stack leaves time steps of an ``n_steps`` input."""
        GroupedTemporalConvNet(self.net_args["groups"], n_steps, **self.net_args)

    def check_input(self, spec: InstanceSpec) -> None:
        """Groups that divide the channels, and a conv stack that leaves time steps."""
        channels, steps = spec.shape if len(spec.shape) == 2 else (None, None)
        groups = self.net_args["groups"]
        if channels is not None and self.groups != PER_CHANNEL and channels % groups:
            raise ValueError(
                f"groups={groups} does not divide the {channels} channels of each instance; "
                f"model.groups={PER_CHANNEL} (one group per channel, as M1 has one per signal; "
                f"ours) or a divisor of {channels}"
            )
        if steps is not None:
            self.check_steps(steps)

    def _check_input(self, X: np.ndarray) -> None:
        per_channel = self.groups == PER_CHANNEL and X.ndim == 3
        groups = X.shape[1] if per_channel else self.net_args["groups"]
        if X.ndim != 3 or X.shape[1] % groups:
            raise ValueError(
                f"haptic_cnn expects X of shape (n, channels, time) with channels a multiple "
                f"of groups={groups} (one group per signal), got {X.shape}"
            )

    def _build_body(self, input_shape: tuple[int, ...]) -> tuple[nn.Module, int]:
        args = self.net_args
        if self.groups == PER_CHANNEL:
            args = {**args, "groups": input_shape[0]}
        net = GroupedTemporalConvNet(*input_shape, **args)
        self.conv3_shape_ = net.out_shape
        return net, net.n_features

    def kernels(self) -> tuple[str, ...]:
        """``SGDModel.kernels``, with the conv stack's backward (``grouped_conv_autograd``) only
        where stage 1 trains with a loss the tiled step does not compute (a plugin's loss): the
        usual losses never run it, so a job does not compile it."""
        kernels = super().kernels()
        if kernels:
            from tactile_exp.models.linear_sgd import LOSSES  # numba: lazy

            if (self.pretrain_loss or self.loss) not in LOSSES:
                kernels += ("tactile_exp.models.grouped_conv_autograd",)
        return kernels

    def _train_step(self, body: nn.Module, classifier: nn.Linear, loss: str) -> Step:
        return lambda X, y, index: body.batch_step(X, y, classifier, loss, index)
