"""The compiled LSTM kernels against nn.LSTM: outputs, every gradient, a short training run."""

import numpy as np
import pytest
import torch
from sklearn.metrics import roc_auc_score
from test_models import easy_case
from torch import nn

from tactile_exp.models import MODELS
from tactile_exp.models.haptic_lstm import LSTMBody
from tactile_exp.models.lstm_kernels import lstm_last_hidden
from tactile_exp.models.schedule import Schedule


@pytest.mark.parametrize(
    ("batch", "channels", "steps", "hidden"), [(37, 32, 20, 10), (1, 5, 1, 3), (16, 64, 9, 7)]
)
def test_compiled_matches_nn_lstm_forward_and_gradients(batch, channels, steps, hidden):
    torch.manual_seed(batch)
    lstm = nn.LSTM(channels, hidden, batch_first=True)
    x = torch.randn(batch, channels, steps, requires_grad=True)
    weights = torch.randn(batch, hidden)  # a loss that weighs every output differently
    outputs, grads = [], []
    for run in (lambda: lstm(x.transpose(1, 2))[1][0][-1], lambda: lstm_last_hidden(x, lstm)):
        lstm.zero_grad()
        x.grad = None
        out = run()
        (out * weights).sum().backward()
        outputs.append(out.detach())
        grads.append([x.grad.clone()] + [p.grad.clone() for p in lstm.parameters()])
    torch.testing.assert_close(outputs[1], outputs[0], atol=2e-6, rtol=1e-5)
    for got, want in zip(grads[1], grads[0], strict=True):
        torch.testing.assert_close(got, want, atol=2e-5, rtol=1e-4)


def test_short_training_matches_torch_impl():
    train, test = easy_case(120, steps=30, seed=1), easy_case(60, steps=30, seed=2)
    schedule = Schedule(epochs=6, finetune_epochs=3, batch_size=40, lr=0.05)
    settings = dict(schedule=schedule, device="cpu", seed=3)
    runs = {}
    for impl in ("torch", "compiled"):
        model = MODELS.build("haptic_lstm", impl=impl, **settings)
        history = model.fit(train)
        runs[impl] = (history, roc_auc_score(test.y, model.decision_function(test.X)))
    (h_torch, auc_torch), (h_fast, auc_fast) = runs["torch"], runs["compiled"]
    for key in ("train_loss", "finetune_loss"):
        np.testing.assert_allclose(h_fast[key], h_torch[key], rtol=1e-4, atol=1e-5)
    assert abs(auc_fast - auc_torch) < 0.01


def test_impl_choice():
    assert MODELS.build("haptic_lstm", device="cpu").impl == "auto"
    model = MODELS.build(
        "haptic_lstm", device="cpu", schedule=Schedule(epochs=1, finetune_epochs=0, batch_size=8)
    )
    model.fit(easy_case(16, steps=5))
    assert model.body_.impl == "compiled"  # auto on CPU
    with pytest.raises(ValueError, match="impl must be one of"):
        MODELS.build("haptic_lstm", impl="cudnn", device="cpu")
    with pytest.raises(ValueError, match="compiled"):
        LSTMBody(4, impl="fast")
    with pytest.raises(ValueError, match="float32 CPU"):
        lstm_last_hidden(torch.zeros(2, 4, 3, dtype=torch.float64), nn.LSTM(4, 2, batch_first=True))
