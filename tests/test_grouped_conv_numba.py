"""The compiled (numba) grouped conv stack equals ``F.conv1d(groups=...)``; its array pool.

The first compiled call in a run compiles the kernels (~35 s on 2 idle cores) into the session's
``NUMBA_CACHE_DIR`` (conftest); every later test reuses them.
"""

import subprocess
import sys
import time

import numpy as np
import pytest
import torch

from tactile_exp.models.haptic_cnn import GroupedTemporalConvNet

# (batch, channels, steps, groups, kernel_sizes, widths, strides)
SHAPES = [
    (1, 32, 150, 32, (5, 5, 5), (4, 4, 4), (2, 2, 2)),  # the default net, a batch of 1
    (7, 64, 41, 32, (3, 9, 5), (1, 8, 4), (3, 1, 2)),  # odd batch, stride 3 not dividing 41
    (33, 6, 20, 1, (9, 3, 5), (8, 1, 4), (1, 3, 2)),  # one group, several input channels
    (17, 32, 23, 32, (9, 5, 3), (8, 4, 1), (2, 3, 1)),  # kernel 9 wider than the stride
    (5, 32, 4, 32, (3, 3, 3), (4, 4, 4), (3, 3, 3)),  # lengths 4 -> 2 -> 1 -> 1
]


def _forward_and_grads(
    net: GroupedTemporalConvNet, x: torch.Tensor, impl: str, weights: torch.Tensor | None = None
):
    net.impl = impl
    net.zero_grad()
    out = net(x)
    # A non-uniform upstream gradient, so every output position is weighted differently.
    weights = torch.linspace(-1.0, 1.0, out.shape[1]) if weights is None else weights
    (out * weights).sum().backward()
    return out.detach(), [p.grad.clone() for p in net.parameters()]


@pytest.mark.parametrize(
    ("n", "channels", "steps", "groups", "kernels", "widths", "strides"), SHAPES
)
def test_compiled_forward_and_gradients_equal_torch(
    n, channels, steps, groups, kernels, widths, strides
):
    torch.manual_seed(n)
    net = GroupedTemporalConvNet(
        channels, steps, groups=groups, kernel_sizes=kernels, widths=widths, strides=strides
    )
    with torch.no_grad():  # non-zero biases, so the bias path and the ReLU mask both matter
        for bias in net.biases:
            bias.uniform_(-0.1, 0.1)
    x = torch.randn(n, channels, steps)
    out_c, grads_c = _forward_and_grads(net, x, "compiled")
    out_t, grads_t = _forward_and_grads(net, x, "torch")
    assert out_c.shape == (n, net.n_features)
    assert (out_t > 0).float().mean() > 0.2  # the ReLUs neither all pass nor all block
    torch.testing.assert_close(out_c, out_t, rtol=1e-5, atol=1e-5)
    for name, g_c, g_t in zip(
        [name for name, _ in net.named_parameters()], grads_c, grads_t, strict=True
    ):
        assert g_t.abs().max() > 0, name
        torch.testing.assert_close(g_c, g_t, rtol=1e-4, atol=1e-4, msg=name)


def test_forwards_awaiting_their_backward_never_share_pooled_arrays():
    """Layout arrays are reused across steps (``scratch``): two forwards in flight, each
    backward run afterwards in reverse order, still give each batch torch's gradients."""
    torch.manual_seed(3)
    net = GroupedTemporalConvNet(32, 150)
    batches = [(torch.randn(40, 32, 150), torch.randn(40, net.n_features)) for _ in range(2)]
    expected = [_forward_and_grads(net, x, "torch", y)[1] for x, y in batches]
    net.impl = "compiled"
    with torch.no_grad():  # a forward without backward frees its arrays for reuse at once
        net(batches[0][0])
    pending = [(net(x) * y).sum() for x, y in batches]
    for value, want in zip(pending[::-1], expected[::-1], strict=True):
        net.zero_grad()
        value.backward()
        for g_c, g_t in zip([p.grad for p in net.parameters()], want, strict=True):
            torch.testing.assert_close(g_c, g_t, rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("parts", [[(0, 3)], [(0, 1), (1, 3)], [(0, 2), (2, 3)]])
def test_to_layout_fills_every_block_whatever_the_split(parts):
    """A batch of 37 padded to 48 lanes: whole tiles, the last instance one value at a time,
    zero padding, and 21 steps (16 in tiles); each task's blocks alone, in any split."""
    from tactile_exp.models.grouped_conv_numba import LANES, to_layout

    rng = np.random.default_rng(3)
    x = rng.standard_normal((37, 2 * 3, 21), dtype=np.float32)  # 3 groups of 2 channels
    out = np.full((3, 2, 21, 3 * LANES), np.nan, np.float32)
    for start, stop in parts:
        to_layout(x, 3, out, start, stop)
    want = np.zeros_like(out)
    for c in range(6):
        want[c % 3, c // 3, :, :37] = x[:, c, :].T
    np.testing.assert_array_equal(out, want)


def test_warm_up_compiles_every_signature_a_training_step_and_scoring_use():
    """``warm_up`` (the job's compile ahead) must leave nothing for the job to compile: in a
    fresh process, after it, a HapticCNN's fit, features and scores add no signature."""
    code = """
import numpy as np
from tactile_exp.data.layout import Instances
from tactile_exp.models import MODELS, convnet_tiles, grouped_conv_numba as kernels, linear_sgd
from tactile_exp.models.schedule import Schedule

def signatures():
    return {name: len(f.signatures) for module in (kernels, convnet_tiles, linear_sgd)
            for name, f in vars(module).items() if hasattr(f, "signatures")}

kernels.warm_up()
convnet_tiles.warm_up()
linear_sgd.warm_up()
before = signatures()
rng = np.random.default_rng(0)
X = rng.normal(size=(40, 32, 150)).astype(np.float32)
y = np.arange(40) % 2
model = MODELS.build("haptic_cnn", schedule=Schedule(epochs=1, finetune_epochs=1, batch_size=16))
model.fit(Instances(X, y, np.arange(40), np.arange(40)))
head = model.head()
head.fit(Instances(model.transform(X), y, np.arange(40), np.arange(40)))
head.decision_function(model.transform(X[:5]))
entry = ("stack_forward", "stack_backward", "to_layout", "from_layout", "into_layout",
         "_tiles", "_epoch", "_gram_epoch")  # called from Python; the others compile inside them
print(before == signatures(), *(before[name] for name in entry))
"""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.split()
    assert out == ["True"] + ["1"] * 8  # the entry points compiled by warm_up, nothing after it


@pytest.mark.parametrize("count", [1, 2, 5, 63, 64])
def test_in_parallel_runs_every_index_once_this_threads_part_the_largest(count, monkeypatch):
    """The parts cover ``range(count)`` once each, in order by slot; where they cannot be equal
    this thread's (slot 0, started first) is the larger, so it is the one that finishes last.
    Three parts whatever the machine's cores (the pool queues what its threads cannot take)."""
    import threading

    from tactile_exp.models import grouped_conv_numba as kernels

    monkeypatch.setattr(kernels.numba, "get_num_threads", lambda: 3)
    calls = []

    def task(slot: int, start: int, stop: int) -> None:
        calls.append((slot, start, stop, threading.get_ident()))

    kernels._in_parallel(task, count)
    calls.sort()
    assert [c[0] for c in calls] == list(range(min(count, 3)))
    assert [i for _, a, b, _ in calls for i in range(a, b)] == list(range(count))
    sizes = [b - a for _, a, b, _ in calls]
    assert sizes[0] == max(sizes) and max(sizes) - min(sizes) <= 1
    assert calls[0][3] == threading.get_ident()  # slot 0 ran here


def test_in_parallel_returns_only_when_every_part_has_finished(monkeypatch):
    """A part that fails here leaves no other still running when the error reaches the caller
    (it would write into buffers the next call hands out)."""
    from tactile_exp.models import grouped_conv_numba as kernels

    monkeypatch.setattr(kernels.numba, "get_num_threads", lambda: 2)
    finished = []

    def task(slot: int, start: int, stop: int) -> None:
        if slot == 0:
            raise RuntimeError("part 0 failed")
        time.sleep(0.2)
        finished.append(slot)

    with pytest.raises(RuntimeError, match="part 0 failed"):
        kernels._in_parallel(task, 4)
    assert finished == [1]
