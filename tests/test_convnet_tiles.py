"""The tiled training step equals torch's ConvNet, classification layer and loss, with gradients.

The first call in a run compiles the step (~20 s) into the session's ``NUMBA_CACHE_DIR``
(conftest); every later test reuses it.
"""

import numpy as np
import pytest
import torch
from numba import config as numba_config
from numba import get_num_threads, set_num_threads

from tactile_exp.models import convnet_tiles
from tactile_exp.models.haptic_cnn import GroupedTemporalConvNet
from tactile_exp.models.losses import LOSSES
from tactile_exp.models.scratch import HUGE_PAGE

# (instances, batch, channels, steps, groups, kernel_sizes, widths, strides)
SHAPES = [
    (300, 150, 32, 150, 32, (5, 5, 5), (4, 4, 4), (2, 2, 2)),  # the default net; a part tile
    (9, 1, 32, 150, 32, (5, 5, 5), (4, 4, 4), (2, 2, 2)),  # a batch of one
    (20, 7, 64, 41, 32, (3, 9, 5), (1, 8, 4), (3, 1, 2)),  # kernel 9 > DOT_TAPS, widths 1 and 8
    (80, 70, 6, 20, 1, (9, 3, 5), (8, 1, 4), (1, 3, 2)),  # one group of 6 channels
    (17, 17, 32, 23, 32, (9, 5, 3), (8, 3, 1), (2, 3, 1)),  # widths 3 and 1: padded to 4
    (5, 5, 32, 4, 32, (3, 3, 3), (4, 4, 4), (3, 3, 3)),  # lengths 4 -> 2 -> 1 -> 1
    (24, 19, 32, 30, 32, (5, 5, 5), (4, 2, 8), (2, 2, 2)),  # last width 8: two row tiles
]


def _net(channels, steps, groups, kernels, widths, strides, seed):
    torch.manual_seed(seed)
    net = GroupedTemporalConvNet(
        channels, steps, groups=groups, kernel_sizes=kernels, widths=widths, strides=strides
    )
    head = torch.nn.Linear(net.n_features, 1)
    with torch.no_grad():  # non-zero biases, so the bias path and the ReLU mask both matter
        for bias in [*net.biases, head.bias]:
            bias.uniform_(-0.1, 0.1)
    return net, head


def _loss_and_grads(net, head, X, y, rows, loss, impl):
    net.impl = impl
    net.zero_grad()
    head.zero_grad()
    value = net.batch_step(X, y, head, loss, rows)
    return value.item(), [p.grad.clone() for p in [*net.parameters(), *head.parameters()]]


@pytest.mark.parametrize("loss", convnet_tiles.LOSSES)
@pytest.mark.parametrize(
    ("n", "batch", "channels", "steps", "groups", "kernels", "widths", "strides"), SHAPES
)
def test_tiled_step_and_gradients_equal_torch(
    loss, n, batch, channels, steps, groups, kernels, widths, strides
):
    """Every parameter's gradient, the rows read in place (a repeated row included), against
    torch's convolutions, classification layer and loss on the copied rows."""
    net, head = _net(channels, steps, groups, kernels, widths, strides, seed=n)
    X, y = torch.randn(n, channels, steps), (torch.rand(n) > 0.5).float()
    rows = torch.randperm(n)[:batch]
    rows[-1] = rows[0]
    got, grads_c = _loss_and_grads(net, head, X, y, rows, loss, "compiled")
    want, grads_t = _loss_and_grads(net, head, X, y, rows, loss, "torch")
    assert got == pytest.approx(want, rel=1e-5, abs=1e-6)
    names = [name for name, _ in net.named_parameters()] + ["head.weight", "head.bias"]
    for name, g_c, g_t in zip(names, grads_c, grads_t, strict=True):
        assert g_t.abs().max() > 0, name
        torch.testing.assert_close(g_c, g_t, rtol=1e-4, atol=1e-5, msg=name)


def test_the_loss_is_the_registered_one():
    """Margins far past softplus's threshold and inside hinge's zero: the value is the mean of
    the registered loss."""
    net, head = _net(32, 40, 32, (5, 5, 5), (4, 4, 4), (2, 2, 2), seed=1)
    with torch.no_grad():
        head.weight.mul_(40.0)
    X, y = torch.randn(100, 32, 40), (torch.rand(100) > 0.5).float()
    rows = torch.arange(100)
    for loss in convnet_tiles.LOSSES:
        net.impl = "compiled"
        value = net.batch_step(X, y, head, loss, rows)
        scores = head(net(X)).squeeze(1)
        assert value.item() == pytest.approx(LOSSES[loss](scores, y).item(), rel=1e-5)
        assert (scores.abs() > 20).any()  # softplus's linear branch is taken


@pytest.mark.skipif(numba_config.NUMBA_NUM_THREADS < 2, reason="needs 2 numba threads")
def test_results_do_not_depend_on_the_thread_count():
    """Each tile's share of the gradients is summed on its own, the tiles in order: one thread
    and two give the same bits."""
    net, head = _net(32, 150, 32, (5, 5, 5), (4, 4, 4), (2, 2, 2), seed=2)
    X, y = torch.randn(400, 32, 150), (torch.rand(400) > 0.5).float()
    rows = torch.randperm(400)[:333]
    threads = get_num_threads()
    try:
        set_num_threads(1)
        one = _loss_and_grads(net, head, X, y, rows, "logistic", "compiled")
        set_num_threads(2)
        two = _loss_and_grads(net, head, X, y, rows, "logistic", "compiled")
    finally:
        set_num_threads(threads)
    assert one[0] == two[0]
    for a, b in zip(one[1], two[1], strict=True):
        assert torch.equal(a, b)


def test_other_losses_train_through_the_compiled_stack_and_autograd():
    """A registered loss the step does not compute: the conv stack's kernels with torch's
    classification layer and loss, the same gradients as torch's convolutions."""
    net, head = _net(32, 30, 32, (5, 3, 3), (4, 4, 4), (2, 2, 2), seed=3)
    X, y = torch.randn(50, 32, 30), (torch.rand(50) > 0.5).float()
    rows = torch.randperm(50)[:20]
    hinge = LOSSES["hinge"]
    with LOSSES.temporary(squared_hinge=lambda s, y: hinge(s, y) ** 2):
        got, grads_c = _loss_and_grads(net, head, X, y, rows, "squared_hinge", "compiled")
        want, grads_t = _loss_and_grads(net, head, X, y, rows, "squared_hinge", "torch")
    assert got == pytest.approx(want, rel=1e-5)
    for g_c, g_t in zip(grads_c, grads_t, strict=True):
        torch.testing.assert_close(g_c, g_t, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("impl", ["compiled", "torch"])
def test_a_step_adds_its_gradients_to_those_present(impl):
    """As autograd's backward, on either path: a step's gradients are added to the parameters'
    ``.grad`` (a second step on the same batch doubles each, exactly: x + x = 2x), and the loss
    it returns is detached."""
    net, head = _net(32, 30, 32, (5, 3, 3), (4, 4, 4), (2, 2, 2), seed=6)
    net.impl = impl
    X, y = torch.randn(40, 32, 30), (torch.rand(40) > 0.5).float()
    params = [*net.parameters(), *head.parameters()]
    net.zero_grad()
    head.zero_grad()
    first = net.batch_step(X, y, head, "hinge", torch.arange(40))
    once = [p.grad.clone() for p in params]
    second = net.batch_step(X, y, head, "hinge", torch.arange(40))
    assert first.item() == second.item() and not first.requires_grad
    for one, p in zip(once, params, strict=True):
        assert one.abs().max() > 0 and torch.equal(p.grad, 2 * one)


def test_a_larger_batch_then_a_smaller_one_again():
    """The tiles' gradient shares are kept from step to step and grown for a larger batch: a
    small batch after a larger one gives its gradients of before, and the larger one torch's."""
    net, head = _net(32, 30, 32, (5, 3, 3), (4, 4, 4), (2, 2, 2), seed=7)
    X, y = torch.randn(60, 32, 30), (torch.rand(60) > 0.5).float()
    small = _loss_and_grads(net, head, X, y, torch.arange(5), "logistic", "compiled")
    large = _loss_and_grads(net, head, X, y, torch.arange(60), "logistic", "compiled")
    again = _loss_and_grads(net, head, X, y, torch.arange(5), "logistic", "compiled")
    want = _loss_and_grads(net, head, X, y, torch.arange(60), "logistic", "torch")
    assert small[0] == again[0] and large[0] == pytest.approx(want[0], rel=1e-5)
    for a, b, c, d in zip(small[1], again[1], large[1], want[1], strict=True):
        assert torch.equal(a, b)
        torch.testing.assert_close(c, d, rtol=1e-4, atol=1e-5)


def test_rows_outside_the_input_are_refused_by_the_thread_that_reads_them(monkeypatch):
    """The kernel checks each tile's rows before it reads them: a bad row in the last tile, run
    by a pool thread (three parts), is refused, and the next step runs."""
    monkeypatch.setattr(convnet_tiles.numba, "get_num_threads", lambda: 3)
    net, head = _net(32, 30, 32, (5, 3, 3), (4, 4, 4), (2, 2, 2), seed=4)
    X, y = torch.randn(40, 32, 30), torch.zeros(40)

    def step(rows: torch.Tensor) -> torch.Tensor:
        return convnet_tiles.tiled_step(X, rows, y, net.weights, net.biases, head,
                                        loss="logistic", groups=32, strides=(2, 2, 2))  # fmt: skip

    for bad in (40, -1):
        rows = torch.arange(40)
        rows[-1] = bad
        with pytest.raises(IndexError, match=r"rows must lie in \[0, len\(X\)\), the rows of X"):
            step(rows)
    assert torch.isfinite(step(torch.arange(40)))


def test_a_tiles_padding_rows_stay_zero_across_steps():
    """The kernels never write the padding of the kept buffers: after steps on other data
    (NaN-free), the next step still equals torch's."""
    net, head = _net(32, 150, 32, (5, 5, 5), (4, 4, 4), (2, 2, 2), seed=5)
    convnet_tiles._BUFFERS.clear()  # only this net's buffers below
    for seed in range(2):
        torch.manual_seed(seed)
        X, y = 5 * torch.randn(70, 32, 150), (torch.rand(70) > 0.5).float()
        rows = torch.arange(70)
        got, grads_c = _loss_and_grads(net, head, X, y, rows, "hinge", "compiled")
    want, grads_t = _loss_and_grads(net, head, X, y, rows, "hinge", "torch")
    assert got == pytest.approx(want, rel=1e-5)
    for g_c, g_t in zip(grads_c, grads_t, strict=True):
        torch.testing.assert_close(g_c, g_t, rtol=1e-4, atol=1e-5)
    pad = 5  # the largest kernel: every time axis's padding on each side
    kept = [b for mine in convnet_tiles._BUFFERS.values() for b in (*mine.acts, *mine.grads)]
    assert kept and np.isfinite(got)
    for buffer in kept:  # time is the second axis from the end
        assert not buffer[..., :pad, :].any() and not buffer[..., -pad:, :].any()


def test_a_threads_buffers_are_one_block_from_a_huge_page_boundary(monkeypatch):
    """A thread's activations, gradients and a tile's scores and loss gradients (~1.7 MB at the
    paper's sizes) in one mapping starting on a huge page: on 4 kB pages the step ran ~20%
    slower. The flat arrays are the shaped ones, flat."""
    monkeypatch.setattr(convnet_tiles, "_BUFFERS", {})
    plan = convnet_tiles._Plan(32, 150, [(128, 1, 5), (128, 4, 5), (128, 4, 5)], 32, (2, 2, 2))
    mine = convnet_tiles._buffers(0, plan.shapes, plan.pad)
    lanes = plan.shapes[0][3]
    arrays = (*mine.acts, *mine.grads, mine.partial, mine.gs)
    assert [a.shape for a in mine.acts] == plan.shapes and len(mine.grads) == 3
    assert [g.shape for g in mine.grads] == [s[1:] for s in plan.shapes[1:]]
    assert mine.partial.shape == (32 * lanes,) and mine.gs.shape == (lanes,)
    for shaped, flat in zip((*mine.acts, *mine.grads), (*mine.flat_acts, *mine.flat_grads),
                            strict=True):  # fmt: skip
        assert flat.ndim == 1 and np.shares_memory(flat, shaped) and flat.size == shaped.size
    assert arrays[0].ctypes.data % HUGE_PAGE == 0
    for before, after in zip(arrays, arrays[1:], strict=False):  # back to back, in order
        assert after.ctypes.data == before.ctypes.data + before.nbytes
    assert sum(a.nbytes for a in arrays) < HUGE_PAGE and not any(a.any() for a in arrays)
    assert convnet_tiles._buffers(0, plan.shapes, plan.pad).acts[0] is mine.acts[0]  # kept
