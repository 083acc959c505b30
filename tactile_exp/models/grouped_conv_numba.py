"""Compiled CPU kernels (numba) for the haptic ConvNet's grouped temporal convolutions + ReLU.

``F.conv1d(groups=32)`` runs these tiny per-group convolutions (1-8 channels, kernel 3-9) at a
few GFLOP/s on CPU (DEPS.md §7). Here activations live as (groups, channels, time, batch) with
the batch innermost and contiguous, so every filter tap is one vector FMA over the batch. The
batch axis is padded to a multiple of ``LANES`` with zero gradients in the padding, so the
kernels never handle a tail. Forward and backward of the whole three-layer stack run inside one
``torch.autograd.Function``: one transpose into the layout at entry, one out of it at exit. The
training step (``GroupedConvHead``) also runs the one-output classification layer in the layout,
so neither conv3's features nor their gradient are transposed (a step's CPU time -19%, measured).
Layout arrays are reused across steps (``scratch``).

numba was chosen over a C++ extension: it is a wheel on the package index (no compiler needed at
install), and its on-disk cache (``numba_setup``) makes the compile a once-per-machine cost.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch.autograd.function import once_differentiable

from tactile_exp.models.numba_setup import numba
from tactile_exp.models.scratch import scratch

LANES = 16  # batch padding: two AVX2 float32 vectors
CHUNK = 128  # batch columns per task of the classification layer's forward
# Reassociation lets the weight-gradient reductions vectorise; no nnan/ninf, so NaNs propagate.
_FASTMATH = {"reassoc", "contract", "nsz", "arcp"}
_JIT = dict(nogil=True, cache=True, fastmath=_FASTMATH, error_model="numpy")


def conv_out_len(length: int, kernel: int, stride: int) -> int:
    """Output length of a 1-D convolution with padding ``kernel // 2`` on each side."""
    return (length + 2 * (kernel // 2) - kernel) // stride + 1


@numba.njit(inline="always", **_JIT)
def _weighted_sum(row, src, chans, times, weights, count, bias):  # pragma: no cover (compiled)
    """row[:] = bias + sum_q weights[q] * src[chans[q], times[q], :], four taps per pass.

    Four rows per pass keep the row's loads and stores at 1.5 per FMA instead of 3 (one tap
    per pass); the first pass writes the row, so it is never zeroed first.
    """
    n = row.shape[0]
    q = 0
    while q < count:
        take = min(4, count - q)
        s0, w0 = src[chans[q], times[q]], weights[q]
        if take == 4:
            s1, s2, s3 = (
                src[chans[q + 1], times[q + 1]],
                src[chans[q + 2], times[q + 2]],
                src[chans[q + 3], times[q + 3]],
            )
            w1, w2, w3 = weights[q + 1], weights[q + 2], weights[q + 3]
            if q == 0:
                for m in range(n):
                    row[m] = bias + (w0 * s0[m] + w1 * s1[m]) + (w2 * s2[m] + w3 * s3[m])
            else:
                for m in range(n):
                    row[m] += (w0 * s0[m] + w1 * s1[m]) + (w2 * s2[m] + w3 * s3[m])
        elif take == 3:
            s1, s2 = src[chans[q + 1], times[q + 1]], src[chans[q + 2], times[q + 2]]
            w1, w2 = weights[q + 1], weights[q + 2]
            if q == 0:
                for m in range(n):
                    row[m] = bias + (w0 * s0[m] + w1 * s1[m]) + w2 * s2[m]
            else:
                for m in range(n):
                    row[m] += (w0 * s0[m] + w1 * s1[m]) + w2 * s2[m]
        elif take == 2:
            s1, w1 = src[chans[q + 1], times[q + 1]], weights[q + 1]
            if q == 0:
                for m in range(n):
                    row[m] = bias + w0 * s0[m] + w1 * s1[m]
            else:
                for m in range(n):
                    row[m] += w0 * s0[m] + w1 * s1[m]
        elif q == 0:
            for m in range(n):
                row[m] = bias + w0 * s0[m]
        else:
            for m in range(n):
                row[m] += w0 * s0[m]
        q += take
    if count == 0:  # no tap reaches this row (kernel < stride at the edge)
        for m in range(n):
            row[m] = bias


@numba.njit(parallel=True, **_JIT)
def conv_relu_forward(x, w, b, stride, out):  # pragma: no cover (compiled)
    """out[g, o, t, :] = relu(b[g, o] + sum_{i, j} w[g, o, i, j] x[g, i, t * stride - pad + j, :]).

    One task per group, walking time once with every output channel at each step, so the input
    rows a step reads stay in cache for all channels; each output row is built in place.
    """
    groups, c_in, t_in, _ = x.shape
    c_out, k = w.shape[1], w.shape[3]
    t_out = out.shape[2]
    pad = k // 2
    for g in numba.prange(groups):
        chans = np.empty(c_in * k, np.int64)
        times = np.empty(c_in * k, np.int64)
        weights = np.empty(c_in * k, np.float32)
        for t in range(t_out):
            for o in range(c_out):
                count = 0
                for i in range(c_in):
                    for j in range(k):
                        ti = t * stride - pad + j
                        if 0 <= ti < t_in:
                            chans[count], times[count], weights[count] = i, ti, w[g, o, i, j]
                            count += 1
                row = out[g, o, t]
                _weighted_sum(row, x[g], chans, times, weights, count, b[g, o])
                for m in range(row.shape[0]):
                    row[m] = max(row[m], np.float32(0.0))


@numba.njit(parallel=True, **_JIT)
def relu_grad_weight_bias(y, grad, x, stride, grad_w, grad_b):  # pragma: no cover (compiled)
    """Masks ``grad`` by the ReLU in place (grad *= y > 0) and reduces the weight and bias
    gradients: grad_w[g, o, i, j] = sum_{t, m} grad[g, o, t, m] x[g, i, t * stride - pad + j, m].

    One task per group, walking time once: each input row is read once for all output channels
    and taps that use it, and dot products with four output channels at a time are reduced in
    registers.
    """
    groups, c_in, t_in, n = x.shape
    c_out, k = grad_w.shape[1], grad_w.shape[3]
    t_out = y.shape[2]
    pad = k // 2
    for g in numba.prange(groups):
        acc = np.zeros((c_out, c_in, k), np.float32)
        for o in range(c_out):
            total = np.float32(0.0)
            for t in range(t_out):
                gr, yr = grad[g, o, t], y[g, o, t]
                for m in range(n):
                    v = gr[m] if yr[m] > 0 else np.float32(0.0)
                    gr[m] = v
                    total += v
            grad_b[g, o] = total
        for t in range(t_out):
            for i in range(c_in):
                for j in range(k):
                    ti = t * stride - pad + j
                    if ti < 0 or ti >= t_in:
                        continue
                    src = x[g, i, ti]
                    o = 0
                    while o + 4 <= c_out:
                        g0, g1, g2, g3 = (
                            grad[g, o, t],
                            grad[g, o + 1, t],
                            grad[g, o + 2, t],
                            grad[g, o + 3, t],
                        )
                        d0 = d1 = d2 = d3 = np.float32(0.0)
                        for m in range(n):
                            v = src[m]
                            d0 += g0[m] * v
                            d1 += g1[m] * v
                            d2 += g2[m] * v
                            d3 += g3[m] * v
                        acc[o, i, j] += d0
                        acc[o + 1, i, j] += d1
                        acc[o + 2, i, j] += d2
                        acc[o + 3, i, j] += d3
                        o += 4
                    while o < c_out:
                        gr = grad[g, o, t]
                        dot = np.float32(0.0)
                        for m in range(n):
                            dot += gr[m] * src[m]
                        acc[o, i, j] += dot
                        o += 1
        grad_w[g] = acc


@numba.njit(parallel=True, **_JIT)
def conv_grad_input(grad, w, stride, grad_x):  # pragma: no cover (compiled)
    """grad_x[g, i, s, :] = sum over (o, j) with s = t * stride - pad + j of w[g, o, i, j]
    grad[g, o, t, :], with ``grad`` already masked by the ReLU.

    Gather form over input time (one task per (group, input channel), each input-gradient row
    built in place), so no row is zeroed and no two tasks write the same row.
    """
    groups, c_out, t_out, _ = grad.shape
    c_in, t_in = grad_x.shape[1], grad_x.shape[2]
    k = w.shape[3]
    pad = k // 2
    for task in numba.prange(groups * c_in):
        g, i = task // c_in, task % c_in
        chans = np.empty(c_out * k, np.int64)
        times = np.empty(c_out * k, np.int64)
        weights = np.empty(c_out * k, np.float32)
        for s in range(t_in):
            count = 0
            for j in range(k):
                shifted = s + pad - j
                if shifted < 0 or shifted % stride or shifted // stride >= t_out:
                    continue
                for o in range(c_out):
                    chans[count], times[count], weights[count] = o, shifted // stride, w[g, o, i, j]
                    count += 1
            _weighted_sum(grad_x[g, i, s], grad[g], chans, times, weights, count, np.float32(0.0))


@numba.njit(parallel=True, **_JIT)
def head_forward(h, w, b, out):  # pragma: no cover (compiled)
    """out[m] = b + sum_r w[r] h[r, m]: the linear classification layer on conv3's rows, read
    in the layout (no transpose back to instance-major), one task per block of columns."""
    rows, n = h.shape
    for block in numba.prange((n + CHUNK - 1) // CHUNK):
        lo, hi = block * CHUNK, min(n, block * CHUNK + CHUNK)
        block = out[lo:hi]
        for m in range(hi - lo):
            block[m] = b
        for r in range(rows):
            wr, src = w[r], h[r, lo:hi]
            for m in range(hi - lo):
                block[m] += wr * src[m]


@numba.njit(parallel=True, **_JIT)
def head_backward(h, w, grad_scores, grad, grad_w):  # pragma: no cover (compiled)
    """The classification layer's backward in the layout: grad_w[r] = sum_m h[r, m] gs[m] and
    conv3's gradient grad[r, m] = w[r] gs[m], already masked by conv3's ReLU (h > 0)."""
    rows, n = h.shape
    for r in numba.prange(rows):
        wr, src, dst = w[r], h[r], grad[r]
        total = np.float32(0.0)
        for m in range(n):
            v = src[m]
            total += v * grad_scores[m]
            dst[m] = wr * grad_scores[m] if v > 0 else np.float32(0.0)
        grad_w[r] = total


@numba.njit(parallel=True, **_JIT)
def to_layout(x, rows, groups, out):  # pragma: no cover (compiled)
    """Rows ``rows`` of (N, c_in * groups, T), channel c in group c % groups -> (groups, c_in,
    T, n_pad): the batch is read in place from the whole input, never copied out first."""
    channels, steps = x.shape[1], x.shape[2]
    n, c_in, n_pad = rows.shape[0], channels // groups, out.shape[3]
    for task in numba.prange(groups * c_in):
        g, i = task // c_in, task % c_in
        c = i * groups + g
        for m0 in range(0, n_pad, LANES):
            for t in range(steps):
                for m in range(m0, m0 + LANES):
                    out[g, i, t, m] = x[rows[m], c, t] if m < n else np.float32(0.0)


@numba.njit(parallel=True, **_JIT)
def from_layout(h, n, out):  # pragma: no cover (compiled)
    """(rows, n_pad) -> (n, rows): the exit transpose (and its adjoint with the roles swapped)."""
    rows = h.shape[0]
    for r0 in numba.prange((rows + LANES - 1) // LANES):
        for m in range(n):
            for r in range(r0 * LANES, min(rows, r0 * LANES + LANES)):
                out[m, r] = h[r, m]


@numba.njit(parallel=True, **_JIT)
def into_layout(grad, out):  # pragma: no cover (compiled)
    """(n, rows) -> (rows, n_pad) with zeros in the padding: the gradient's entry transpose."""
    n, rows = grad.shape
    n_pad = out.shape[1]
    for r0 in numba.prange((rows + LANES - 1) // LANES):
        for m in range(n_pad):
            for r in range(r0 * LANES, min(rows, r0 * LANES + LANES)):
                out[r, m] = grad[m, r] if m < n else np.float32(0.0)


def _padded(n: int) -> int:
    return -(-n // LANES) * LANES


def _forward_acts(
    x: torch.Tensor,
    rows: torch.Tensor,
    params: Sequence[torch.Tensor],
    groups: int,
    strides: Sequence[int],
) -> list[np.ndarray]:
    """The input rows ``rows`` and each layer's ReLU output in the layout (groups, channels,
    time, n_pad)."""
    if x.requires_grad:
        raise ValueError("the compiled conv stack gives no input gradient; use impl='torch'")
    _, channels, steps = x.shape
    n_pad = _padded(len(rows))
    h = scratch(groups, channels // groups, steps, n_pad)
    to_layout(np.ascontiguousarray(x.detach().numpy()), rows.numpy(), groups, h)
    acts = [h]
    for weight, bias, stride in zip(params[0::2], params[1::2], strides, strict=True):
        c_out, _, k = weight.shape
        w = weight.detach().numpy().reshape(groups, c_out // groups, -1, k)
        t_out = conv_out_len(h.shape[2], k, stride)
        out = scratch(groups, c_out // groups, t_out, n_pad)
        conv_relu_forward(h, w, bias.detach().numpy().reshape(groups, -1), stride, out)
        acts.append(out)
        h = out
    return acts


def _backward_params(
    acts: list[np.ndarray],
    grad: np.ndarray,
    weights: Sequence[torch.Tensor],
    groups: int,
    strides: Sequence[int],
) -> list[torch.Tensor]:
    """Weight and bias gradients of every layer (in parameter order) from conv3's gradient
    ``grad`` in the layout; ``grad`` and each layer's input gradient are masked in place."""
    grads: list[torch.Tensor] = []
    for layer in range(len(weights) - 1, -1, -1):
        weight, stride = weights[layer], strides[layer]
        c_out, c_in, k = weight.shape
        w = weight.detach().numpy().reshape(groups, c_out // groups, c_in, k)
        grad_w = np.empty_like(w)
        grad_b = np.empty((groups, c_out // groups), np.float32)
        x = acts[layer]
        relu_grad_weight_bias(acts[layer + 1], grad, x, stride, grad_w, grad_b)
        grads[:0] = [
            torch.from_numpy(grad_w).view(c_out, c_in, k),
            torch.from_numpy(grad_b).view(-1),
        ]
        if layer > 0:
            grad_x = scratch(*x.shape)
            conv_grad_input(grad, w, stride, grad_x)
            grad = grad_x
    return grads


class GroupedConvStack(torch.autograd.Function):
    """conv1..conv3 + ReLU on (n, C, T) float32 CPU input -> conv3 flattened (n, G * W * T3)."""

    @staticmethod
    def forward(ctx, x, groups: int, strides: Sequence[int], *params: torch.Tensor):
        acts = _forward_acts(x, torch.arange(len(x)), params, groups, strides)
        h = acts[-1].reshape(-1, acts[-1].shape[3])
        result = np.empty((len(x), h.shape[0]), np.float32)
        from_layout(h, len(x), result)
        ctx.acts, ctx.groups, ctx.strides = acts, groups, tuple(strides)
        ctx.save_for_backward(*params[0::2])
        return torch.from_numpy(result)

    @staticmethod
    @once_differentiable
    def backward(ctx, grad_out):
        acts = ctx.acts
        del ctx.acts  # free the activations as soon as the backward is done with them
        grad = scratch(*acts[-1].shape)
        into_layout(np.ascontiguousarray(grad_out.numpy()), grad.reshape(-1, grad.shape[3]))
        grads = _backward_params(acts, grad, ctx.saved_tensors, ctx.groups, ctx.strides)
        return (None, None, None, *grads)


class GroupedConvHead(torch.autograd.Function):
    """The conv stack and a linear classification layer (1 output) on its flattened conv3, for
    the rows ``rows`` of (N, C, T) input -> scores (len(rows),). Training runs through this one:
    the batch is read in place (``X[index]`` would first copy it: 19 MB per step of the default
    net), and conv3 never leaves the layout: no transpose of the features out, nor of their
    gradient in."""

    @staticmethod
    def forward(ctx, x, rows, groups, strides, head_weight, head_bias, *params: torch.Tensor):
        acts = _forward_acts(x, rows, params, groups, strides)
        h = acts[-1].reshape(-1, acts[-1].shape[3])
        scores = np.empty(h.shape[1], np.float32)
        head_forward(h, head_weight.detach().numpy().reshape(-1), head_bias.item(), scores)
        ctx.acts, ctx.groups, ctx.strides = acts, groups, tuple(strides)
        ctx.save_for_backward(head_weight, *params[0::2])
        return torch.from_numpy(scores[: len(rows)])

    @staticmethod
    @once_differentiable
    def backward(ctx, grad_scores):
        acts = ctx.acts
        del ctx.acts
        head_weight, *weights = ctx.saved_tensors
        h = acts[-1].reshape(-1, acts[-1].shape[3])
        padded = np.zeros(h.shape[1], np.float32)  # zero gradient in the padding columns
        padded[: len(grad_scores)] = grad_scores.numpy()
        grad, grad_head = scratch(*acts[-1].shape), np.empty(h.shape[0], np.float32)
        head_backward(
            h, head_weight.detach().numpy().reshape(-1), padded, grad.reshape(h.shape), grad_head
        )
        grads = _backward_params(acts, grad, weights, ctx.groups, ctx.strides)
        grad_head_bias = torch.from_numpy(padded.sum(dtype=np.float32, keepdims=True))
        grad_head_weight = torch.from_numpy(grad_head).view(1, -1)
        return (None, None, None, None, grad_head_weight, grad_head_bias, *grads)


def _interleaved(weights: Sequence[torch.Tensor], biases: Sequence[torch.Tensor]) -> list:
    return [p for pair in zip(weights, biases, strict=True) for p in pair]


def grouped_conv_stack(
    x: torch.Tensor,
    weights: Sequence[torch.Tensor],
    biases: Sequence[torch.Tensor],
    *,
    groups: int,
    strides: Sequence[int],
) -> torch.Tensor:
    """The compiled three-layer grouped conv + ReLU stack; same result as ``F.conv1d`` + relu."""
    params = _interleaved(weights, biases)
    return GroupedConvStack.apply(x.contiguous(), groups, tuple(strides), *params)


def grouped_conv_head(
    x: torch.Tensor,
    weights: Sequence[torch.Tensor],
    biases: Sequence[torch.Tensor],
    head: torch.nn.Linear,
    *,
    groups: int,
    strides: Sequence[int],
    rows: torch.Tensor | None = None,
) -> torch.Tensor:
    """Scores of ``head`` (one output) on the compiled stack's flattened conv3 for the rows
    ``rows`` of ``x`` (None: all); same result as
    ``head(grouped_conv_stack(x[rows], ...)).squeeze(1)``."""
    params = _interleaved(weights, biases)
    rows = torch.arange(len(x)) if rows is None else rows.to(torch.int64)
    return GroupedConvHead.apply(
        x.contiguous(), rows, groups, tuple(strides), head.weight, head.bias, *params
    )
