"""The compiled grouped conv stack's autograd function equals ``F.conv1d(groups=...)`` + ReLU,
forward and gradients; its forwards' pooled arrays; its compile ahead.

The first compiled backward in a run compiles its kernels into the session's ``NUMBA_CACHE_DIR``
(conftest); every later test reuses them.
"""

import subprocess
import sys

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


def test_warm_up_compiles_every_signature_a_backward_uses():
    """A plugin loss trains stage 1 through this backward (``HapticCNN.kernels`` lists the
    module then): after its ``warm_up``, in a fresh process, a compiled forward and backward of
    another shape add no signature."""
    code = """
import torch
from tactile_exp.models import grouped_conv_autograd, grouped_conv_numba
from tactile_exp.models.haptic_cnn import GroupedTemporalConvNet

def signatures():
    return {name: len(f.signatures) for module in (grouped_conv_numba, grouped_conv_autograd)
            for name, f in vars(module).items() if hasattr(f, "signatures")}

grouped_conv_autograd.warm_up()
before = signatures()
net = GroupedTemporalConvNet(32, 150, impl="compiled")
net(torch.randn(20, 32, 150)).sum().backward()
print(before == signatures(), *(before[name] for name in ("stack_backward", "into_layout")))
"""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.split()
    assert out == ["True", "1", "1"]
