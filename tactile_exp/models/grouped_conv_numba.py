"""Compiled CPU kernels (numba) for the haptic ConvNet's grouped temporal convolutions + ReLU.

``F.conv1d(groups=32)`` runs these tiny per-group convolutions (1-8 channels, kernel 3-9) at a few
GFLOP/s on CPU (bench/bench_haptic_cnn.py). Here activations live as (groups, channels, time, batch)
with the batch innermost and contiguous, so every filter tap is one vector FMA over the batch. The
batch axis is padded to a multiple of ``LANES`` with zero gradients in the padding, so the kernels
never handle a tail. Forward and backward of the whole three-layer stack run inside one
``torch.autograd.Function``: one transpose into the layout at entry, one out of it at exit. It
gives the features a fitted net scores with (``transform``, ``decision_function``) and trains
with a loss the tiled training step does not compute (``convnet_tiles``: the usual path). A
task runs every layer of a range of signal groups (``stack_forward``, ``stack_backward``), the
backward's inner gradients in per-task buffers. The convolutions' inner loops are
register tiles (``vector_tiles``): an output step's taps feed ``ROWS`` output channels whose
sums stay in registers, the ReLU (or, backward, its mask) applied before the one store; the
entry transpose goes in square tiles. Against numba's own loops they made a training step 1.3x
faster (one thread, batch 1000, interleaved in one process) and the first compile shorter (21
against 26 s), with bit-identical results. The weight gradients keep numba's loops (``_dots4x4``:
sixteen dot products in registers): as register tiles of dot products over the batch they made
a step at most 5% faster and summed in another order, which moved the rows built on the
ConvNets by float rounding. Tasks run side by side on threads (``_in_parallel``;
the kernels release the GIL), one per numba thread (``numba.set_num_threads``): plain serial
kernels compile in about two thirds of the time numba's parallel loops took, and the first
compile is on a fresh clone's critical path (the README job, bench_readme_job). Layout arrays
are reused across steps (``scratch``). Rates per kernel: bench/bench_haptic_cnn.py.

Measured on one thread and not kept: the batch in chunks with conv1 and conv2 recomputed in the
backward (1.3-2x slower), a step as 2 to 8 smaller batches (1.1-1.75x slower), software
prefetches of the next rows (``to_layout`` 1.1-1.3x slower, the weight gradients ~4% of a step
faster alone), conv2's and conv3's weight and input gradients in one walk through time (no
faster). Time a layout change on another batch each call, as training runs it: on the same batch
again its rows are left in cache and it looks up to 2x faster.

numba was chosen over a C++ extension: it is a wheel on the package index (no compiler needed at
install), and its on-disk cache (``numba_setup``) makes the compile a once-per-machine cost.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor, wait

import numpy as np
import torch
from torch.autograd.function import once_differentiable

from tactile_exp.models.numba_setup import ensure_compiled, numba
from tactile_exp.models.scratch import scratch
from tactile_exp.models.vector_tiles import (
    GATED,
    PLAIN,
    RELU,
    ROWS,
    WIDTH,
    tap_sums,
    transpose_rows,
)

LANES = 16  # batch padding: a whole number of vectors at every width (vector_tiles.WIDTH)
# Reassociation lets the weight-gradient reductions vectorise; no nnan/ninf, so NaNs propagate.
# ReLUs and their masks are written v * (v > 0), not max(v, 0) or a conditional: those compile
# to a branch per element (NaN semantics), mispredicted on every other one; conv1's forward ran
# 2.5x slower with them (in cache). The product differs from max(v, 0) only at v = -inf (NaN).
_FASTMATH = {"reassoc", "contract", "nsz", "arcp"}
_JIT = dict(nogil=True, cache=True, fastmath=_FASTMATH, error_model="numpy")


def conv_out_len(length: int, kernel: int, stride: int) -> int:
    """Output length of a 1-D convolution with padding ``kernel // 2`` on each side."""
    return (length + 2 * (kernel // 2) - kernel) // stride + 1


@numba.njit(**_JIT)
def _weighted_sum(row, src, taps, weights, count, bias):  # pragma: no cover (compiled)
    """row[:] = bias + sum_q weights[q] * src[taps[q]:taps[q] + n] (src flat), four taps per pass:
    the rows of a layer whose width is not a multiple of ``ROWS``, one at a time.

    Four taps per pass keep the row's loads and stores at 1.5 per FMA instead of 3 (one tap
    per pass); the first pass writes the row, so it is never zeroed first.
    """
    n = row.shape[0]
    q = 0
    while q < count:
        take = min(4, count - q)
        s0, w0 = src[taps[q] : taps[q] + n], weights[q]
        if take == 4:
            s1, s2, s3 = (
                src[taps[q + 1] : taps[q + 1] + n],
                src[taps[q + 2] : taps[q + 2] + n],
                src[taps[q + 3] : taps[q + 3] + n],
            )
            w1, w2, w3 = weights[q + 1], weights[q + 2], weights[q + 3]
            if q == 0:
                for m in range(n):
                    row[m] = bias + (w0 * s0[m] + w1 * s1[m]) + (w2 * s2[m] + w3 * s3[m])
            else:
                for m in range(n):
                    row[m] += (w0 * s0[m] + w1 * s1[m]) + (w2 * s2[m] + w3 * s3[m])
        elif take == 3:
            s1, s2 = src[taps[q + 1] : taps[q + 1] + n], src[taps[q + 2] : taps[q + 2] + n]
            w1, w2 = weights[q + 1], weights[q + 2]
            if q == 0:
                for m in range(n):
                    row[m] = bias + (w0 * s0[m] + w1 * s1[m]) + w2 * s2[m]
            else:
                for m in range(n):
                    row[m] += (w0 * s0[m] + w1 * s1[m]) + w2 * s2[m]
        elif take == 2:
            s1, w1 = src[taps[q + 1] : taps[q + 1] + n], weights[q + 1]
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


@numba.njit(**_JIT)
def _combine(dst, s, src, taps, wts, count, bias, mode, gate):  # pragma: no cover (compiled)
    """dst[e, s, :] = f(bias[e] + sum_{q < count} wts[q, e] src.flat[taps[q]:taps[q] + n]) for
    every destination channel e, f by ``mode`` as in ``tap_sums`` (``gate`` laid out as ``dst``):
    the taps are shared by all channels, so ``ROWS`` go per register tile, the rest one by one."""
    c_out, t_dst, n = dst.shape
    flat_dst, flat_src, flat_w, flat_gate = (
        dst.reshape(-1),
        src.reshape(-1),
        wts.reshape(-1),
        gate.reshape(-1),
    )
    e = 0
    while e + ROWS <= c_out:
        at = (e * t_dst + s) * n
        tap_sums(flat_w, e, 1, c_out, flat_src, 0, taps, count, flat_dst, at, t_dst * n, bias, e,
                 n // WIDTH, WIDTH, WIDTH, mode, flat_gate)  # fmt: skip
        e += ROWS
    while e < c_out:
        row = dst[e, s]
        _weighted_sum(row, flat_src, taps, wts[:, e], count, bias[e])
        if mode != PLAIN:
            mask = row if mode == RELU else gate[e, s]
            for m in range(n):
                row[m] *= np.float32(mask[m] > 0)  # see _JIT
        e += 1


@numba.njit(**_JIT)
def _conv_relu(x, w, b, stride, out):  # pragma: no cover (compiled)
    """One group: out[o, t, :] = relu(b[o] + sum_{i, j} w[o, i, j] x[i, t * stride - pad + j, :]).

    Walks time once with every output channel at each step, so the input rows a step reads
    stay in cache for all channels; each output row is built in place.
    """
    c_in, t_in, n = x.shape
    c_out, k = w.shape[0], w.shape[2]
    pad = k // 2
    taps = np.empty(c_in * k, np.int64)  # the input rows of output step t, as flat offsets
    wts = np.empty((c_in * k, c_out), np.float32)
    for t in range(out.shape[1]):
        count = 0
        for i in range(c_in):
            for j in range(k):
                ti = t * stride - pad + j
                if 0 <= ti < t_in:
                    taps[count] = (i * t_in + ti) * n
                    for o in range(c_out):
                        wts[count, o] = w[o, i, j]
                    count += 1
        _combine(out, t, x, taps, wts, count, b, RELU, out)


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
def stack_forward(x, w1, b1, w2, b2, w3, b3, strides, a1, a2, a3, start, stop):  # pragma: no cover
    """conv1..conv3 + ReLU of groups ``start`` to ``stop`` (x: (groups, c_in, T, n_pad) -> a1,
    a2, a3).

    A group runs all layers, so a layer's output is read by the next while still in
    cache (a group's activations are ~3 MB at batch 1000), not fetched back from memory.
    conv1's output, the largest, is kept for the backward: recomputing it there from ``x``
    instead, in a per-thread buffer, saved no time in forward + backward (measured).
    """
    for g in range(start, stop):
        _conv_relu(x[g], w1[g], b1[g], strides[0], a1[g])
        _conv_relu(a1[g], w2[g], b2[g], strides[1], a2[g])
        _conv_relu(a2[g], w3[g], b3[g], strides[2], a3[g])


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
def to_layout(x, groups, out, start, stop):  # pragma: no cover (compiled)
    """The batch ``x`` (n, c_in * groups, T), channel c in group c % groups -> (groups, c_in,
    T, n_pad), for the blocks of ``LANES`` instances ``start`` to ``stop``.

    Block by block, each instance's channels in order (a sequential sweep of its signals), in
    square tiles of ``WIDTH`` instances x ``WIDTH`` steps transposed in registers
    (``transpose_rows``); instances past the batch's last whole tile, and batches of fewer than
    ``WIDTH`` steps, one value at a time.
    """
    channels, steps = x.shape[1], x.shape[2]
    n, n_pad = x.shape[0], out.shape[3]
    flat_x, flat_out = x.reshape(-1), out.reshape(-1)
    starts = np.empty(WIDTH, np.int64)
    for block in range(start, stop):
        for c in range(channels):
            dst = out[c % groups, c // groups]
            at = ((c % groups) * out.shape[1] + c // groups) * steps * n_pad
            for m0 in range(block * LANES, (block + 1) * LANES, WIDTH):
                if m0 + WIDTH <= n and steps >= WIDTH:
                    for i in range(WIDTH):
                        starts[i] = ((m0 + i) * channels + c) * steps
                    transpose_rows(flat_x, starts, steps, flat_out, at + m0, n_pad)
                    continue
                for t in range(steps):
                    for m in range(m0, m0 + WIDTH):
                        dst[t, m] = x[m, c, t] if m < n else np.float32(0.0)


@numba.njit(**_JIT)
def from_layout(h, n, out, start, stop):  # pragma: no cover (compiled)
    """(rows, n_pad) -> (n, rows) for the blocks of ``LANES`` rows ``start`` to ``stop``: the
    exit transpose (and its adjoint with the roles swapped)."""
    rows = h.shape[0]
    for r0 in range(start, stop):
        for m in range(n):
            for r in range(r0 * LANES, min(rows, r0 * LANES + LANES)):
                out[m, r] = h[r, m]


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


def _in_parallel(task: Callable[[int, int, int], None], count: int) -> None:
    """``task(slot, start, stop)`` over ``range(count)`` cut into ``numba.get_num_threads()``
    contiguous parts (slot: the part's index), run side by side: this thread takes the first,
    a pool's threads the others (the kernels release the GIL). Where the parts cannot be equal
    the first is the larger: a pool thread starts ~0.05 ms after this one, and this one,
    finishing last, need not be woken (with the pool's part the larger, this thread waited
    ~0.3 ms for it in the ConvNet's two-thread step)."""
    parts = max(1, min(count, numba.get_num_threads()))
    bounds = [count - count * (parts - k) // parts for k in range(parts + 1)]
    others = [_threads().submit(task, k, bounds[k], bounds[k + 1]) for k in range(1, parts)]
    try:
        task(0, bounds[0], bounds[1])
    finally:  # none of the parts still runs when this returns or raises
        wait(others)
    for done in others:
        done.result()


@functools.cache
def _threads() -> ThreadPoolExecutor:
    return ThreadPoolExecutor(max(1, numba.config.NUMBA_NUM_THREADS - 1), "conv-kernels")


def _padded(n: int) -> int:
    return -(-n // LANES) * LANES


def _per_group(a: np.ndarray, groups: int) -> np.ndarray:
    """A view of a weight (C_out, c_in, k) as (groups, c_out, c_in, k), of a bias (C_out,) as
    (groups, c_out)."""
    return a.reshape(groups, -1, *a.shape[1:])


def _forward(
    x: torch.Tensor, params: Sequence[torch.Tensor], groups: int, strides: tuple[int, int, int]
) -> list[np.ndarray]:
    """The input and each layer's ReLU output in the layout (groups, channels, time, n_pad)."""
    if x.requires_grad:
        raise ValueError("the compiled conv stack gives no input gradient; use impl='torch'")
    ensure_compiled(__name__)
    _, channels, steps = x.shape
    n_pad = _padded(len(x))
    h = scratch(groups, channels // groups, steps, n_pad)
    batch = np.ascontiguousarray(x.detach().numpy())
    _in_parallel(lambda _, a, b: to_layout(batch, groups, h, a, b), n_pad // LANES)
    acts = [h]
    for weight, stride in zip(params[0::2], strides, strict=True):
        h = scratch(
            groups,
            weight.shape[0] // groups,
            conv_out_len(h.shape[2], weight.shape[2], stride),
            n_pad,
        )
        acts.append(h)
    per_group = [_per_group(p.detach().numpy(), groups) for p in params]
    _in_parallel(
        lambda _, a, b: stack_forward(acts[0], *per_group, strides, *acts[1:], a, b), groups
    )
    return acts


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
        acts = _forward(x, params, groups, tuple(strides))
        h = acts[-1].reshape(-1, acts[-1].shape[3])
        result = np.empty((len(x), h.shape[0]), np.float32)
        _in_parallel(lambda _, a, b: from_layout(h, len(x), result, a, b), -(-len(h) // LANES))
        ctx.acts, ctx.groups, ctx.strides = acts, groups, tuple(strides)
        ctx.save_for_backward(*params[0::2])
        return torch.from_numpy(result)

    @staticmethod
    @once_differentiable
    def backward(ctx, grad_out):
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
