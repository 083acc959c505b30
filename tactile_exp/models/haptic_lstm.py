"""The haptic LSTM (M2): 10 recurrent units over time -> FC(10) + ReLU -> FC(1).

``impl`` picks how the recurrence runs: ``torch`` is ``nn.LSTM`` (cuDNN on a GPU), ``compiled``
the numba kernels of ``lstm_kernels`` (CPU only, same parameters; ``bench/bench_lstm.py``
measures them), ``auto`` the compiled kernels on CPU and ``nn.LSTM`` elsewhere.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import torch
from torch import nn

from tactile_exp.models.lstm_kernels import LOSSES as LSTM_LOSSES
from tactile_exp.models.lstm_kernels import lstm_last_hidden, lstm_step
from tactile_exp.models.registry import MODELS
from tactile_exp.models.schedule import Schedule
from tactile_exp.models.sgd import SGDModel
from tactile_exp.train import Step, caffe_xavier_


class LSTMBody(nn.Module):
    """LSTM over the time axis of (n, C, T) input; the last hidden state -> FC(hidden) + ReLU.

    Both implementations share ``nn.LSTM``'s parameters, so they start from the same weights.
    """

    def __init__(
        self, n_channels: int, hidden: int = 10, fc_width: int = 10, impl: str = "torch"
    ) -> None:
        super().__init__()
        if impl not in ("compiled", "torch"):
            raise ValueError(f"LSTMBody impl must be 'compiled' or 'torch', got {impl!r}")
        self.impl = impl
        self.lstm = nn.LSTM(n_channels, hidden, batch_first=True)
        self.fc = nn.Linear(hidden, fc_width)
        for name, param in self.lstm.named_parameters():
            if name.startswith("weight"):
                caffe_xavier_(param, param.shape[1])
            else:
                nn.init.zeros_(param)
        caffe_xavier_(self.fc.weight, hidden)
        nn.init.zeros_(self.fc.bias)

    def forward(self, x: torch.Tensor, rows: torch.Tensor | None = None) -> torch.Tensor:
        """Features of ``x[rows]`` (all rows by default); the compiled kernels read the rows in
        place, so a training batch is never copied out of the training set."""
        if self.impl == "compiled":
            last = lstm_last_hidden(x, self.lstm, rows)
        else:
            x = x if rows is None else x[rows]
            last = self.lstm(x.transpose(1, 2))[1][0][-1]
        return self.fc(last).relu()


@MODELS.register("haptic_lstm")
class HapticLSTM(SGDModel):
    """Haptic LSTM (M2) trained by the two-stage schedule of ``SGDModel``.

    All C input signals (PHAC-2: 32, or 64 with both fingers) enter the LSTM at every time
    step. Stage 1 trains everything with ``pretrain_loss``; stage 2 fine-tunes only the final
    FC(1) with ``loss``. ``transform`` returns the FC(10) activations after the ReLU.
    """

    accepts = ("signals",)  # (n, channels, time): 32 per finger for PHAC-2, any C elsewhere
    body_kernels = ("tactile_exp.models.lstm_kernels",)

    def __init__(
        self,
        *,
        hidden: int = 10,
        fc_width: int = 10,
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
        for name, value in (("hidden", hidden), ("fc_width", fc_width)):
            if not (isinstance(value, int) and value >= 1):
                raise ValueError(f"{name} must be an int >= 1, got {value!r}")
        self.hidden, self.fc_width = hidden, fc_width

    def _check_input(self, X: np.ndarray) -> None:
        if X.ndim != 3:
            raise ValueError(f"haptic_lstm expects X of shape (n, channels, time), got {X.shape}")

    def _train_scores(
        self, body: nn.Module, classifier: nn.Linear
    ) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor]:
        return lambda X, index: classifier(body(X, index)).squeeze(1)

    def _train_step(self, body: nn.Module, classifier: nn.Linear, loss: str) -> Step:
        """Compiled, with a loss the step computes: one pass per batch through the recurrence,
        both FC layers, the loss and back, each chunk's forward kept in cache for its backward
        (``lstm_kernels.lstm_step``); otherwise the loss on ``_train_scores`` through autograd."""
        if body.impl == "compiled" and loss in LSTM_LOSSES:
            return lambda X, y, index: lstm_step(
                X, index, y, body.lstm, body.fc, classifier, loss=loss
            )
        return super()._train_step(body, classifier, loss)

    def _build_body(self, input_shape: tuple[int, ...]) -> tuple[nn.Module, int]:
        impl = self.impl
        if impl == "auto":
            impl = "compiled" if self.device_.type == "cpu" else "torch"
        return LSTMBody(input_shape[0], self.hidden, self.fc_width, impl), self.fc_width
