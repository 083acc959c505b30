"""The SGD loop, device resolution, seeding and the losses."""

import math

import pytest
import torch

from tactile_exp.models.losses import LOSSES
from tactile_exp.train import (
    add_gradients,
    autograd_step,
    momentum_step,
    resolve_device,
    seed_everything,
    sgd_epochs,
    validate_losses,
)

GOOD = dict(
    loss="hinge",
    pretrain_loss="logistic",
    known_losses=("hinge", "logistic"),
)


def test_resolve_device_auto_follows_cuda_availability(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert resolve_device("auto") == torch.device("cpu")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert resolve_device("auto") == torch.device("cuda")
    assert resolve_device("cpu") == torch.device("cpu")


def test_resolve_device_rejects_unknown_and_missing_cuda(monkeypatch):
    with pytest.raises(ValueError, match="device='gpu0'"):
        resolve_device("gpu0")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(ValueError, match="CUDA is not available"):
        resolve_device("cuda")


def test_seed_everything_repeats_init_and_shuffling():
    first = seed_everything(3)
    a = torch.rand(5), torch.randperm(20, generator=first)
    second = seed_everything(3)
    b = torch.rand(5), torch.randperm(20, generator=second)
    assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1])
    assert not torch.equal(torch.randperm(20, generator=seed_everything(4)), a[1])


@pytest.mark.parametrize("key", ["loss", "pretrain_loss"])
def test_validate_losses_names_the_bad_argument(key):
    with pytest.raises(ValueError, match=rf"^{key} must be one of hinge, logistic"):
        validate_losses(**{**GOOD, key: "squared"})


def test_validate_losses_takes_no_pretrain_loss():
    validate_losses(**{**GOOD, "pretrain_loss": None})


def test_losses_on_known_margins():
    scores = torch.tensor([0.0, 2.0, -0.5])
    y = torch.tensor([1, 1, 1])
    assert LOSSES["logistic"](scores[:1], y[:1]).item() == pytest.approx(math.log(2))
    # y = 1: margins 0, 2, -0.5 -> hinge 1, 0, 1.5
    assert LOSSES["hinge"](scores, y).item() == pytest.approx(2.5 / 3)
    # y = 0 flips the sign of the margin
    assert LOSSES["hinge"](torch.tensor([2.0]), torch.tensor([0])).item() == pytest.approx(3.0)
    assert LOSSES.names() == ["hinge", "logistic"]


def test_sgd_epochs_lowers_the_loss_and_reports_each_epoch():
    gen = seed_everything(0)
    X = torch.randn(200, 5)
    y = (X[:, 0] > 0).float()
    layer = torch.nn.Linear(5, 1)
    reported = []
    curve = sgd_epochs(
        autograd_step(lambda X, y, index: LOSSES["logistic"](layer(X[index]).squeeze(1), y[index])),
        list(layer.parameters()),
        X,
        y,
        epochs=15,
        batch_size=64,
        lr=0.1,
        momentum=0.9,
        generator=gen,
        report=reported.append,
    )
    assert reported == curve and len(curve) == 15
    assert curve[-1] < 0.5 * curve[0]


def test_sgd_epochs_batch_larger_than_data_is_one_full_batch():
    """One epoch = one step on the gradient of the mean loss over all 7 rows."""
    torch.manual_seed(0)
    X, y = torch.randn(7, 2), torch.tensor([1.0, 0, 1, 0, 1, 1, 0])
    layer = torch.nn.Linear(2, 1)
    w0, b0 = layer.weight.detach().clone(), layer.bias.detach().clone()
    loss = LOSSES["logistic"]
    before = loss(layer(X).squeeze(1), y)
    gw, gb = torch.autograd.grad(before, [layer.weight, layer.bias])
    curve = sgd_epochs(
        autograd_step(lambda X, y, index: loss(layer(X[index]).squeeze(1), y[index])),
        list(layer.parameters()),
        X,
        y,
        epochs=1,
        batch_size=1000,
        lr=0.5,
        momentum=0.0,
        generator=seed_everything(0),
    )
    assert curve == [pytest.approx(before.item(), rel=1e-6)]
    torch.testing.assert_close(layer.weight.detach(), w0 - 0.5 * gw)
    torch.testing.assert_close(layer.bias.detach(), b0 - 0.5 * gb)


def test_a_cuda_device_turns_tf32_off(monkeypatch):
    flags = (torch.backends.cudnn.conv, torch.backends.cudnn.rnn, torch.backends.cuda.matmul)
    before = [f.fp32_precision for f in flags]
    try:
        for f in flags:
            f.fp32_precision = "tf32"
        monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
        resolve_device("auto")  # CPU: leaves the flags alone
        assert [f.fp32_precision for f in flags] == ["tf32"] * 3
        monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
        assert resolve_device("auto") == torch.device("cuda")
        assert [f.fp32_precision for f in flags] == ["ieee"] * 3
    finally:
        for f, value in zip(flags, before, strict=True):
            f.fp32_precision = value


def test_add_gradients_adds_as_autograds_backward_does():
    """Where ``.grad`` is None the gradient is taken as it is (no copy: the step's own tensor),
    else added in place; the sum equals autograd's accumulation of two backwards."""
    torch.manual_seed(0)
    layer = torch.nn.Linear(3, 1)
    X, y = torch.randn(8, 3), torch.rand(8)
    loss = LOSSES["logistic"]
    params = list(layer.parameters())
    first = torch.autograd.grad(loss(layer(X).squeeze(1), y), params)
    second = torch.autograd.grad(loss(2 * layer(X).squeeze(1), y), params)
    add_gradients(params, first)
    assert all(p.grad is g for p, g in zip(params, first, strict=True))
    kept = [g.clone() for g in first]
    add_gradients(params, second)
    layer.zero_grad()
    loss(layer(X).squeeze(1), y).backward()
    loss(2 * layer(X).squeeze(1), y).backward()
    for p, a, b in zip(params, kept, second, strict=True):
        assert p.grad.abs().max() > 0
        torch.testing.assert_close(a + b, p.grad, rtol=0, atol=0)


def test_the_momentum_step_is_torch_optims_sgd_to_the_bit():
    """``momentum_step`` gives ``torch.optim.SGD``'s parameters over several steps, a parameter
    without a gradient in one step left alone (and its velocity with it), in float32 and 64."""
    for dtype in (torch.float32, torch.float64):
        gen = torch.Generator().manual_seed(0)
        ours = [torch.randn(5, 3, generator=gen, dtype=dtype), torch.randn(7, dtype=dtype)]
        theirs = [p.clone().requires_grad_() for p in ours]
        start = [p.clone() for p in ours]
        optimiser = torch.optim.SGD(theirs, lr=0.03, momentum=0.9)
        velocity = [None, None]
        for step in range(5):
            grads = [torch.randn(p.shape, generator=gen, dtype=dtype) for p in ours]
            if step == 2:
                grads[1] = None
            for p, q, g in zip(ours, theirs, grads, strict=True):
                p.grad = g
                q.grad = None if g is None else g.clone()
            momentum_step(ours, velocity, lr=0.03, momentum=0.9)
            optimiser.step()
            for p, q in zip(ours, theirs, strict=True):
                assert torch.equal(p, q.detach())
        assert not torch.equal(ours[1], start[1])  # the parameters moved
