"""The compiled LSTM kernels against nn.LSTM: outputs, every gradient, a short training run."""

import subprocess
import sys

import numpy as np
import pytest
import torch
from numba import config as numba_config
from numba import get_num_threads, set_num_threads
from sklearn.metrics import roc_auc_score
from test_models import easy_case
from torch import nn

from tactile_exp.models import MODELS, lstm_kernels
from tactile_exp.models.haptic_lstm import LSTMBody
from tactile_exp.models.losses import LOSSES
from tactile_exp.models.lstm_kernels import CHUNK, lstm_last_hidden, lstm_step
from tactile_exp.models.schedule import Schedule
from tactile_exp.models.scratch import HUGE_PAGE


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


def _paper_sized_step(rows: torch.Tensor) -> tuple[torch.Tensor, list[torch.Tensor]]:
    """h_T and the gradients of (x, every LSTM parameter) at the paper's sizes (C=32, T=150,
    H=10, the model's init), the rows ``rows`` of 400 instances read in place."""
    torch.manual_seed(0)
    body = LSTMBody(32, impl="compiled")
    x = torch.randn(400, 32, 150, requires_grad=True)
    weights = torch.randn(len(rows), 10)
    out = lstm_last_hidden(x, body.lstm, rows)
    (out * weights).sum().backward()
    return out.detach(), [x.grad] + [p.grad for p in body.lstm.parameters()]


def test_paper_sized_rows_match_nn_lstm():
    """Several chunks and a partial one, rows read in place out of order, 150 steps (gradients
    through time decay past float32's normal range: the flush to zero must not show)."""
    rows = torch.randperm(400, generator=torch.Generator().manual_seed(1))[: 2 * CHUNK + 22]
    out, grads = _paper_sized_step(rows)
    torch.manual_seed(0)
    body = LSTMBody(32, impl="torch")
    x = torch.randn(400, 32, 150, requires_grad=True)
    weights = torch.randn(len(rows), 10)
    want = body.lstm(x[rows].transpose(1, 2))[1][0][-1]
    (want * weights).sum().backward()
    torch.testing.assert_close(out, want.detach(), atol=1e-5, rtol=0)
    wanted = [x.grad] + [p.grad for p in body.lstm.parameters()]
    for name, got, ref in zip(["x", "w_ih", "w_hh", "b_ih", "b_hh"], grads, wanted, strict=True):
        scale = float(ref.abs().max())
        assert scale > 0, name
        assert float((got - ref).abs().max()) <= 1e-5 * scale, name
    assert float(grads[0][rows].abs().sum((1, 2)).min()) > 0  # every read row gets a gradient
    others = torch.ones(400, dtype=torch.bool)
    others[rows] = False
    assert not grads[0][others].any()  # rows not read get none


def test_weight_gradients_are_the_same_without_the_inputs_gradient():
    """Without the input's gradient the backward keeps one time step's gate gradients, not all
    of them: the weights' gradients must not change by a bit."""
    torch.manual_seed(0)
    lstm = LSTMBody(32, impl="compiled").lstm
    x = torch.randn(3 * CHUNK + 5, 32, 150)
    weights = torch.randn(len(x), 10)
    grads = []
    for needs in (True, False):
        lstm.zero_grad()
        (lstm_last_hidden(x.clone().requires_grad_(needs), lstm) * weights).sum().backward()
        grads.append([p.grad.clone() for p in lstm.parameters()])
    assert all(float(g.abs().max()) > 0 for g in grads[1])
    for with_x, without in zip(*grads, strict=True):
        assert torch.equal(with_x, without)


@pytest.mark.skipif(numba_config.NUMBA_NUM_THREADS < 2, reason="needs 2 numba threads")
def test_results_do_not_depend_on_the_thread_count():
    rows = torch.arange(3 * CHUNK + 5)
    threads = get_num_threads()
    try:
        set_num_threads(1)
        one = _paper_sized_step(rows)
        set_num_threads(2)
        two = _paper_sized_step(rows)
    finally:
        set_num_threads(threads)
    assert torch.equal(one[0], two[0])
    for a, b in zip(one[1], two[1], strict=True):
        assert torch.equal(a, b)


def _step(impl, loss, rows, n=400, channels=32, steps=150, hidden=10, width=10, again=False):
    """The training step's loss and the gradients of every parameter (LSTM, FC, output layer)
    at the model's init, the rows ``rows`` of ``n`` instances; ``again``: a second step on the
    same batch before the gradients are read."""
    torch.manual_seed(0)
    body = LSTMBody(channels, hidden, width, impl="compiled")
    out = nn.Linear(width, 1)
    x, y = torch.randn(n, channels, steps), (torch.rand(n) > 0.5).float()
    for _ in range(2 if again else 1):
        if impl == "compiled":
            value = lstm_step(x, rows, y, body.lstm, body.fc, out, loss=loss)
        else:
            h = body.lstm(x[rows].transpose(1, 2))[1][0][-1]
            value = LOSSES[loss](out(body.fc(h).relu()).squeeze(1), y[rows])
            value.backward()
    return value.item(), [p.grad.clone() for p in [*body.parameters(), *out.parameters()]]


@pytest.mark.parametrize("loss", ["logistic", "hinge"])
@pytest.mark.parametrize("sizes", [dict(), dict(n=30, channels=5, steps=2, hidden=3, width=4)])
def test_the_training_step_equals_torch(loss, sizes):
    """Loss and every gradient of LSTM -> FC + ReLU -> FC(1) -> loss against torch on the
    copied rows: several chunks and a partial one, rows out of order, one repeated."""
    n = sizes.get("n", 400)
    rows = torch.randperm(n, generator=torch.Generator().manual_seed(1))[: min(n, 2 * CHUNK + 22)]
    rows[-1] = rows[0]
    got, grads = _step("compiled", loss, rows, **sizes)
    want, wanted = _step("torch", loss, rows, **sizes)
    assert got == pytest.approx(want, rel=1e-5)
    names = ["w_ih", "w_hh", "b_ih", "b_hh", "fc.weight", "fc.bias", "out.weight", "out.bias"]
    for name, a, b in zip(names, grads, wanted, strict=True):
        scale = float(b.abs().max())
        assert scale > 0, name
        assert float((a - b).abs().max()) <= 2e-5 * scale, name


def test_the_training_step_adds_its_gradients_to_those_present():
    """As autograd's backward: a step's gradients are added to the parameters' ``.grad`` (a
    second step on the same batch doubles each, exactly: x + x = 2x), and the loss it returns
    is detached."""
    rows = torch.arange(CHUNK + 9)
    _, ones = _step("compiled", "hinge", rows)
    _, twos = _step("compiled", "hinge", rows, again=True)
    for one, two in zip(ones, twos, strict=True):
        assert one.abs().max() > 0 and torch.equal(two, 2 * one)
    layers = (nn.LSTM(4, 2, batch_first=True), nn.Linear(2, 3), nn.Linear(3, 1))
    value = lstm_step(torch.randn(2, 4, 3), torch.tensor([1]), torch.ones(2), *layers, loss="hinge")
    assert value.ndim == 0 and not value.requires_grad


def test_a_steps_arrays_are_kept_on_huge_pages_their_constant_rows_intact(monkeypatch):
    """The chunks' arrays are one block from a huge page boundary, handed out again on the next
    call; after training steps and a backward with the input's gradient (which writes every
    step's gate gradients), the bias's row of ones and the zero rows past it, and the gate
    gradients' rows past the gates, are as made, and the next step still equals torch's."""
    monkeypatch.setattr(lstm_kernels, "_KEPT", {})
    rows = torch.arange(CHUNK + 9)
    first = _step("compiled", "hinge", rows)
    x = torch.randn(CHUNK + 9, 32, 150, requires_grad=True)
    lstm_last_hidden(x, nn.LSTM(32, 10, batch_first=True)).sum().backward()
    again, grads = _step("compiled", "hinge", rows)
    want, wanted = _step("torch", "hinge", rows)
    assert again == first[0] and again == pytest.approx(want, rel=1e-5)
    for a, b in zip(grads, wanted, strict=True):
        assert float((a - b).abs().max()) <= 2e-5 * float(b.abs().max())
    inputs, acts, c_prev, tanh_c = lstm_kernels._activations(CHUNK + 9, 150, 42, 40)
    assert inputs.ctypes.data % HUGE_PAGE == 0
    for before, after in zip((inputs, acts, c_prev), (acts, c_prev, tanh_c), strict=True):
        assert after.ctypes.data == before.ctypes.data + before.nbytes  # one block
    assert (inputs[:, :, 42] == 1).all() and not inputs[:, :, 43:].any()
    assert lstm_kernels._activations(CHUNK + 9, 150, 42, 40)[0] is inputs  # kept
    d_gates = [a for key, (a, *_) in lstm_kernels._KEPT.items() if key[0] == "gate gradients"]
    assert {a.shape[1] for a in d_gates} == {1, 150}  # a step's, and every step's
    assert all(not a[:, :, 40:].any() for a in d_gates)


@pytest.mark.skipif(numba_config.NUMBA_NUM_THREADS < 2, reason="needs 2 numba threads")
def test_the_training_step_does_not_depend_on_the_thread_count():
    rows = torch.arange(3 * CHUNK + 5)
    threads = get_num_threads()
    try:
        set_num_threads(1)
        one = _step("compiled", "logistic", rows)
        set_num_threads(2)
        two = _step("compiled", "logistic", rows)
    finally:
        set_num_threads(threads)
    assert one[0] == two[0]
    for a, b in zip(one[1], two[1], strict=True):
        assert torch.equal(a, b)


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
    with pytest.raises(IndexError, match="rows must lie in"):
        lstm_last_hidden(torch.zeros(2, 4, 3), nn.LSTM(4, 2, batch_first=True), torch.tensor([2]))
    with pytest.raises(ValueError, match="float32 CPU"):
        lstm_last_hidden(torch.zeros(2, 4, 3, dtype=torch.float64), nn.LSTM(4, 2, batch_first=True))
    layers = (nn.LSTM(4, 2, batch_first=True), nn.Linear(2, 3), nn.Linear(3, 1))
    x, y = torch.zeros(2, 4, 3), torch.zeros(2)
    with pytest.raises(IndexError, match="rows must lie in"):
        lstm_step(x, torch.tensor([2]), y, *layers, loss="hinge")
    with pytest.raises(ValueError, match="computes logistic, hinge, not 'squared'"):
        lstm_step(x, torch.tensor([1]), y, *layers, loss="squared")


def test_warm_up_compiles_every_signature_training_and_scoring_use():
    """``warm_up`` (the job's compile ahead) must leave nothing for the job to compile: in a
    fresh process, after it, a HapticLSTM's fit (its training step) and scores add no
    signature."""
    code = """
import numpy as np
from tactile_exp.data.layout import Instances
from tactile_exp.models import MODELS, lstm_kernels as kernels

def signatures():
    return {name: len(f.signatures) for name, f in vars(kernels).items()
            if hasattr(f, "signatures")}

kernels.warm_up()
before = signatures()
rng = np.random.default_rng(0)
X = rng.normal(size=(70, 32, 150)).astype(np.float32)
y = np.arange(70) % 2
schedule = dict(epochs=1, finetune_epochs=1, batch_size=16)
model = MODELS.build("haptic_lstm", schedule=schedule)
model.fit(Instances(X, y, np.arange(70), np.arange(70)))
model.decision_function(X[:5])
print(before == signatures(), before["_forward"], before["_backward"], before["_train"])
"""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.split()
    assert out == ["True", "1", "1", "1"]  # the entry points compiled by warm_up, nothing after it
