"""Compiled CPU kernels (numba) for the haptic ConvNet's grouped temporal convolutions + ReLU:
the layout and the forward (their backward: ``grouped_conv_autograd``).

``F.conv1d(groups=32)`` runs these tiny per-group convolutions (1-8 channels, kernel 3-9) at a few
GFLOP/s on CPU (bench/bench_haptic_cnn.py). Here activations live as (groups, channels, time,
batch) with the batch innermost and contiguous, so every filter tap is one vector FMA over the
batch. The batch axis is padded to a multiple of ``LANES`` with zero gradients in the padding, so
the kernels never handle a tail. The whole three-layer stack runs in the layout (``stack``): one
transpose into it at entry, one out of it at exit. It gives the features a fitted net scores with
(``transform``, ``decision_function``); training runs the tiled step (``convnet_tiles``), or, with
a loss that step does not compute, this forward and ``grouped_conv_autograd``'s backward, whose
kernels compile only when a backward first runs (a job with the usual losses never compiles them:
bench/bench_readme_job.py's compile alone). A task runs every layer of a range of signal groups
(``stack_forward``; the backward's ``stack_backward``). The convolutions' inner loops are register
tiles (``vector_tiles``): an output step's taps feed ``ROWS`` output channels whose sums stay in
registers, the ReLU (or, backward, its mask) applied before the one store; the entry transpose goes
in square tiles. Against numba's own loops they made a training step 1.3x faster (one thread, batch
1000, interleaved in one process) and the first compile shorter (21 against 26 s), with
bit-identical results. The weight gradients keep numba's loops (``_dots4x4``: sixteen dot products
in registers): as register tiles of dot products over the batch they made a step at most 5% faster
and summed in another order, which moved the rows built on the ConvNets by float rounding. Tasks
run side by side on threads (``_in_parallel``; the kernels release the GIL), one per numba thread
(``numba.set_num_threads``): plain serial kernels compile in about two thirds of the time numba's
parallel loops took, and the first compile is on a fresh clone's critical path (the README job,
bench_readme_job). Layout arrays are reused across steps (``scratch``). Rates per kernel:
bench/bench_haptic_cnn.py.

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

from tactile_exp.models.numba_setup import ensure_compiled, numba
from tactile_exp.models.scratch import scratch
from tactile_exp.models.vector_tiles import (
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


def stack(
    x: torch.Tensor, params: Sequence[torch.Tensor], groups: int, strides: tuple[int, int, int]
) -> tuple[np.ndarray, list[np.ndarray]]:
    """conv3's output flattened, (n, G * W * T3), and every layer's activations in the layout
    (``_forward``: what a backward reads)."""
    acts = _forward(x, params, groups, strides)
    h = acts[-1].reshape(-1, acts[-1].shape[3])
    result = np.empty((len(x), h.shape[0]), np.float32)
    _in_parallel(lambda _, a, b: from_layout(h, len(x), result, a, b), -(-len(h) // LANES))
    return result, acts


def warm_up() -> None:
    """Compile every kernel of this module (into numba's cache) on a toy batch, with the types a
    job's calls have: the stack's forward."""
    torch.manual_seed(0)
    groups, strides = 2, (2, 2, 2)
    x = torch.randn(3, 2 * groups, 40)
    params = [p for c_in in (2, 4, 4) for p in (torch.randn(4 * groups, c_in, 5), torch.zeros(8))]
    stack(x, params, groups, strides)
