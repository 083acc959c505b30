"""The compiled grouped conv stack (``grouped_conv_numba``) as a torch autograd function, and
the kernels of its backward.

``grouped_conv_stack`` gives a ``HapticCNN`` on CPU its conv features, with a gradient for each
weight and bias: the forward runs ``grouped_conv_numba``'s kernels, the backward this module's,
from conv3's output gradient to every parameter's, each group running all layers backwards
(``stack_backward``) with its inner gradients in per-task buffers. A job's training runs the
tiled step (``convnet_tiles``) for the losses that step computes, so these kernels run, and
compile (``numba_setup.ensure_compiled``, on the first backward), only for another loss or
where a test or bench calls them. Rates and what was measured and not kept: the
``grouped_conv_numba`` docstring and bench/bench_haptic_cnn.py.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch.autograd.function import once_differentiable

from tactile_exp.models.grouped_conv_numba import (
    _JIT,
    LANES,
    _combine,
    _in_parallel,
    _per_group,
    stack,
)
from tactile_exp.models.numba_setup import ensure_compiled, numba
from tactile_exp.models.scratch import scratch
from tactile_exp.models.vector_tiles import GATED


@numba.njit(**_JIT)
def _dots4x4(g0, g1, g2, g3, s0, s1, s2, s3, acc, o, i, j):  # pragma: no cover (compiled)
    """acc[o + e, i, j + f] += g_e . s_f for four gradient rows and four source rows (four
    taps): sixteen dot products reduced in registers, eight loads per sixteen FMAs."""
    d00 = d01 = d02 = d03 = d10 = d11 = d12 = d13 = np.float32(0.0)
    d20 = d21 = d22 = d23 = d30 = d31 = d32 = d33 = np.float32(0.0)
    for m in range(s0.shape[0]):
        u, v, p, z = s0[m], s1[m], s2[m], s3[m]
        a, b, c, e = g0[m], g1[m], g2[m], g3[m]
        d00 += a * u
        d01 += a * v
        d02 += a * p
        d03 += a * z
        d10 += b * u
        d11 += b * v
        d12 += b * p
        d13 += b * z
        d20 += c * u
        d21 += c * v
        d22 += c * p
        d23 += c * z
        d30 += e * u
        d31 += e * v
        d32 += e * p
        d33 += e * z
    acc[o, i, j] += d00
    acc[o, i, j + 1] += d01
    acc[o, i, j + 2] += d02
    acc[o, i, j + 3] += d03
    acc[o + 1, i, j] += d10
    acc[o + 1, i, j + 1] += d11
    acc[o + 1, i, j + 2] += d12
    acc[o + 1, i, j + 3] += d13
    acc[o + 2, i, j] += d20
    acc[o + 2, i, j + 1] += d21
    acc[o + 2, i, j + 2] += d22
    acc[o + 2, i, j + 3] += d23
    acc[o + 3, i, j] += d30
    acc[o + 3, i, j + 1] += d31
    acc[o + 3, i, j + 2] += d32
    acc[o + 3, i, j + 3] += d33


@numba.njit(**_JIT)
def _dots4x1(g0, g1, g2, g3, s0, acc, o, i, j):  # pragma: no cover (compiled)
    """acc[o + e, i, j] += g_e . s0 for four gradient rows: one tap."""
    d0 = d1 = d2 = d3 = np.float32(0.0)
    for m in range(s0.shape[0]):
        u = s0[m]
        d0 += g0[m] * u
        d1 += g1[m] * u
        d2 += g2[m] * u
        d3 += g3[m] * u
    acc[o, i, j] += d0
    acc[o + 1, i, j] += d1
    acc[o + 2, i, j] += d2
    acc[o + 3, i, j] += d3


@numba.njit(**_JIT)
def _grad_weight_bias(grad, x, stride, grad_w, grad_b):  # pragma: no cover (compiled)
    """One group's weight and bias gradients from its output gradient ``grad`` (already masked
    by the ReLU): grad_w[o, i, j] = sum_{t, m} grad[o, t, m] x[i, t * stride - pad + j, m].

    Walks time once, with the gradient rows of a step in cache for every input row and tap
    that uses them; output channels go in fours and taps in fours (``_dots4x4``: half the
    loads per FMA of taps in pairs), the last taps one at a time.
    """
    c_in, t_in, n = x.shape
    c_out, k = grad_w.shape[0], grad_w.shape[2]
    pad = k // 2
    acc = np.zeros((c_out, c_in, k), np.float32)
    grad_b[:] = 0.0
    for t in range(grad.shape[1]):
        for o in range(c_out):
            row, total = grad[o, t], np.float32(0.0)
            for m in range(n):
                total += row[m]
            grad_b[o] += total
        j0 = max(0, pad - t * stride)  # the taps inside the input at this step
        j1 = min(k, t_in + pad - t * stride)
        base = t * stride - pad
        for i in range(c_in):
            o = 0
            while o + 4 <= c_out:
                g0, g1, g2, g3 = grad[o, t], grad[o + 1, t], grad[o + 2, t], grad[o + 3, t]
                j = j0
                while j + 4 <= j1:
                    s0, s1 = x[i, base + j], x[i, base + j + 1]
                    s2, s3 = x[i, base + j + 2], x[i, base + j + 3]
                    _dots4x4(g0, g1, g2, g3, s0, s1, s2, s3, acc, o, i, j)
                    j += 4
                while j < j1:
                    _dots4x1(g0, g1, g2, g3, x[i, base + j], acc, o, i, j)
                    j += 1
                o += 4
            while o < c_out:
                gr = grad[o, t]
                for j in range(j0, j1):
                    s0, d0 = x[i, base + j], np.float32(0.0)
                    for m in range(n):
                        d0 += gr[m] * s0[m]
                    acc[o, i, j] += d0
                o += 1
    grad_w[:] = acc


@numba.njit(**_JIT)
def _mask(grad, y):  # pragma: no cover (compiled)
    """grad *= y > 0 row by row: the ReLU's backward (see _JIT for the product form)."""
    for c in range(grad.shape[0]):
        for t in range(grad.shape[1]):
            gr, yr = grad[c, t], y[c, t]
            for m in range(gr.shape[0]):
                gr[m] *= np.float32(yr[m] > 0)


@numba.njit(**_JIT)
def _conv_grad_input(grad, w, stride, y, grad_x):  # pragma: no cover (compiled)
    """One group: grad_x[i, s, :] = (y[i, s, :] > 0) sum over (o, j) with s = t * stride - pad
    + j of w[o, i, j] grad[o, t, :]: the input gradient through the layer, masked by the ReLU
    that produced its input ``y`` while each row is still in cache.

    Gather form over input time: each input-gradient row is built in place (never zeroed),
    every input channel from the same taps.
    """
    c_out, t_out, n = grad.shape
    c_in, t_in = grad_x.shape[0], grad_x.shape[1]
    k = w.shape[2]
    pad = k // 2
    taps = np.empty(c_out * k, np.int64)  # the gradient rows reaching input step s, flat
    wts = np.empty((c_out * k, c_in), np.float32)
    zeros = np.zeros(c_in, np.float32)
    for s in range(t_in):
        count = 0
        for j in range(k):
            shifted = s + pad - j
            if shifted < 0 or shifted % stride or shifted // stride >= t_out:
                continue
            for o in range(c_out):
                taps[count] = (o * t_out + shifted // stride) * n
                for i in range(c_in):
                    wts[count, i] = w[o, i, j]
                count += 1
        _combine(grad_x, s, grad, taps, wts, count, zeros, GATED, y)


@numba.njit(**_JIT)
def stack_backward(
    x, a1, a2, a3, w1, w2, w3, strides, grad3, work, grads, slot, start, stop
):  # pragma: no cover (compiled)
    """Every parameter's gradient of groups ``start`` to ``stop`` from conv3's output gradient
    ``grad3``, each group running all layers backwards. ``work[.][slot]`` is this task's pair of
    gradient buffers (conv2's and conv1's output gradients), reused from group to group while in
    cache. ``grads`` = (w1, b1, w2, b2, w3, b3) gradients, per group.
    """
    gw1, gb1, gw2, gb2, gw3, gb3 = grads
    work2, work1 = work
    for g in range(start, stop):
        d3 = grad3[g]
        _mask(d3, a3[g])
        d2, d1 = work2[slot], work1[slot]
        _grad_weight_bias(d3, a2[g], strides[2], gw3[g], gb3[g])
        _conv_grad_input(d3, w3[g], strides[2], a2[g], d2)
        _grad_weight_bias(d2, a1[g], strides[1], gw2[g], gb2[g])
        _conv_grad_input(d2, w2[g], strides[1], a1[g], d1)
        _grad_weight_bias(d1, x[g], strides[0], gw1[g], gb1[g])


@numba.njit(**_JIT)
def into_layout(grad, out, start, stop):  # pragma: no cover (compiled)
    """(n, rows) -> (rows, n_pad) with zeros in the padding, for the blocks of ``LANES`` rows
    ``start`` to ``stop``: the gradient's entry transpose."""
    n, rows = grad.shape
    n_pad = out.shape[1]
    for r0 in range(start, stop):
        for m in range(n_pad):
            for r in range(r0 * LANES, min(rows, r0 * LANES + LANES)):
                out[r, m] = grad[m, r] if m < n else np.float32(0.0)


def _backward(
    acts: list[np.ndarray],
    grad3: np.ndarray,
    weights: Sequence[torch.Tensor],
    groups: int,
    strides: tuple[int, int, int],
) -> list[torch.Tensor]:
    """Gradients of (w1, b1, w2, b2, w3, b3) from conv3's output gradient ``grad3``."""
    threads = numba.get_num_threads()
    work = tuple(scratch(threads, *a.shape[1:]) for a in (acts[2], acts[1]))
    grads = []  # in parameter order and shape; the kernel writes them through per-group views
    for weight in weights:
        grads += [np.empty(weight.shape, np.float32), np.empty(weight.shape[0], np.float32)]
    w = [_per_group(weight.detach().numpy(), groups) for weight in weights]
    gw = [_per_group(g, groups) for g in grads]
    _in_parallel(
        lambda slot, a, b: stack_backward(*acts, *w, strides, grad3, work, tuple(gw), slot, a, b),
        groups,
    )
    return [torch.from_numpy(g) for g in grads]


class GroupedConvStack(torch.autograd.Function):
    """conv1..conv3 + ReLU on (n, C, T) float32 CPU input -> conv3 flattened (n, G * W * T3)."""

    @staticmethod
    def forward(ctx, x, groups: int, strides: Sequence[int], *params: torch.Tensor):
        result, acts = stack(x, params, groups, tuple(strides))
        ctx.acts, ctx.groups, ctx.strides = acts, groups, tuple(strides)
        ctx.save_for_backward(*params[0::2])
        return torch.from_numpy(result)

    @staticmethod
    @once_differentiable
    def backward(ctx, grad_out):
        ensure_compiled(__name__)
        acts = ctx.acts
        del ctx.acts  # free the activations as soon as the backward is done with them
        grad = scratch(*acts[-1].shape)
        rows, grad_rows = np.ascontiguousarray(grad_out.numpy()), grad.reshape(-1, grad.shape[3])
        blocks = -(-len(grad_rows) // LANES)
        _in_parallel(lambda _, a, b: into_layout(rows, grad_rows, a, b), blocks)
        grads = _backward(acts, grad, ctx.saved_tensors, ctx.groups, ctx.strides)
        return (None, None, None, *grads)


def grouped_conv_stack(
    x: torch.Tensor,
    weights: Sequence[torch.Tensor],
    biases: Sequence[torch.Tensor],
    *,
    groups: int,
    strides: Sequence[int],
) -> torch.Tensor:
    """The compiled three-layer grouped conv + ReLU stack; same result as ``F.conv1d`` + relu."""
    params = [p for pair in zip(weights, biases, strict=True) for p in pair]
    return GroupedConvStack.apply(x.contiguous(), groups, tuple(strides), *params)


def warm_up() -> None:
    """Compile every kernel of this module (into numba's cache) on a toy batch, with the types a
    job's calls have: the stack's forward and its backward."""
    torch.manual_seed(0)
    groups, strides = 2, (2, 2, 2)
    x = torch.randn(3, 2 * groups, 40)
    weights = [torch.randn(4 * groups, c_in, 5, requires_grad=True) for c_in in (2, 4, 4)]
    biases = [torch.zeros(4 * groups, requires_grad=True) for _ in weights]
    out = grouped_conv_stack(x, weights, biases, groups=groups, strides=strides)
    out.sum().backward()
