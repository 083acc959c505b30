"""Compiled CPU kernels for the haptic LSTM's recurrence and training step (``impl="compiled"``).

``nn.LSTM`` on CPU runs a few small library calls per time step on a (batch, 10) state, so at the
paper's sizes (hidden 10, 150 steps) it is bound by per-call overhead, not arithmetic. Here a batch
is cut into chunks of ``CHUNK`` instances, and each chunk runs forward and backward through time
inside one numba loop, the chunk the innermost, contiguous axis and time the outermost (layout
(time, feature, chunk)): every gate update is one vector FMA over the chunk, and what a step reads
and writes is one contiguous block of each array, in L1. Chunks run in parallel on numba's
threads; each chunk's gradients are summed on their own and the chunks' in a fixed order
(``vector_tiles.ordered_sum``), so results do not depend on the thread count.

- The training step (``lstm_step``) runs a chunk at a time through everything: the recurrence,
  both FC layers, each instance's loss and back through all of it, so the backward reads the
  chunk's forward from cache and nothing runs twice. It keeps only the current step's gate
  gradients, adds each step's weight-gradient sums to the running sum as the tile stores them
  (``ADDED``: the step's inputs times its gate gradients, ~20 KB, in L1, rather than ~3 MB of
  operands at the chunk's end), and lays the summed gradients out as the parameters' inside the
  compiled step (``_gradient_sums``). Its arrays are kept from call to call in one block on huge
  pages (``scratch.carved``): fresh ones cost a page fault per 4 KB every step.
- Through autograd (``lstm_last_hidden``: scoring, and training with a loss the step does not
  compute) the forward keeps nothing and the backward recomputes a chunk's forward in cache.
  Keeping every chunk's activations instead (~63 MB a batch of 1,000) speeds a lone job but, with
  two jobs side by side on two cores, takes the memory bandwidth the other job needs.
- The inner loops are explicit vectors (``vector_tiles``): the gate sums, the state's gradient and
  the weight gradient are register tiles (``tap_sums``), the nonlinearities and the cell update run
  a whole vector at a time (``tanh_lanes``, ``lanes``: numba's own loops over that many arrays stay
  scalar or behind alias checks), and the chunk's gather transposes square tiles in registers.
  A chunk's input projection as one BLAS product before its recurrence is slower: BLAS at these
  shapes (40 x 32 by 32 x 9600) runs below the tiles' rate (bench/bench_roofline.py prints both).

tanh and the sigmoid use a rational approximation (Eigen's float tanh, max error ~4e-7 over the real
line; sigmoid(x) = tanh(x / 2) / 2 + 1 / 2) because numba calls libm's scalar ``exp`` and ``tanh``,
which would not vectorise. The kernels' rates against the machine's and against the earlier kernels:
docs/benchmarks.md (bench_roofline, bench_lstm).

numba's compiled-code cache: see ``numba_setup``.
"""

from __future__ import annotations

import itertools

import numpy as np
import torch

from tactile_exp.models.linear_sgd import LOSSES, loss_slope
from tactile_exp.models.numba_setup import check_rows, ensure_compiled, numba
from tactile_exp.models.scratch import carved
from tactile_exp.models.vector_tiles import (
    ADDED,
    PLAIN,
    ROWS,
    WIDTH,
    Lanes,
    lanes,
    ordered_sum,
    pairwise_sum,
    tanh_lanes,
    tap_sums,
    transpose_rows,
    transpose_tile,
)
from tactile_exp.train import add_gradients

# error_model="numpy": no ZeroDivisionError check inside the loops, which blocks vectorisation.
_JIT = dict(fastmath=True, error_model="numpy", cache=True)
_ZERO = np.float32(0.0)
_HALF = np.float32(0.5)
_ONE = np.float32(1.0)
_TWO = np.float32(2.0)
# Gradients through time shrink by the forget gate (~1/2) each step, to ~1e-45 after 150 steps:
# float32 denormals, which the CPU handles ~100x slower (they made backward 10x slower). The
# carried gradients are set to 0 below this, ~1e-27 of any gradient that moves a weight.
_TINY = np.float32(1e-30)


# Instances per chunk: ~6 MB of arrays at C=32, T=150. Measured at 32, 64, 128 (a training step,
# one thread, 2-core Xeon): 64 and 128 as fast, 32 1.13x slower.
CHUNK = 64


@numba.njit(**_JIT)
def _gather(X, rows, start, inputs):
    """``inputs[:, :C]`` (T, C, CHUNK) <- X[rows[start:start + CHUNK]] (rows, C, T), transposed
    in tiles of ``WIDTH`` instances x ``WIDTH`` steps (``transpose_rows``), the instances past
    the last whole tile (all of them below ``WIDTH`` steps) one by one; lanes past the last row
    are zero, so they carry zeros through forward and backward."""
    _, C, T = X.shape
    n = min(CHUNK, len(rows) - start)
    tiled = n - n % WIDTH if T >= WIDTH else 0
    step = inputs.shape[1] * CHUNK
    flat, flat_in = X.reshape(-1), inputs.reshape(-1)
    starts = np.empty(WIDTH, np.int64)
    for c in range(C):
        for b0 in range(0, tiled, WIDTH):
            for i in range(WIDTH):
                starts[i] = (rows[start + b0 + i] * C + c) * T
            transpose_rows(flat, starts, T, flat_in, c * CHUNK + b0, step)
        for b in range(tiled, n):
            r = rows[start + b]
            for t in range(T):
                inputs[t, c, b] = X[r, c, t]
        for t in range(T):
            for b in range(n, CHUNK):
                inputs[t, c, b] = 0


def _cell(i: Lanes, f: Lanes, g: Lanes, o: Lanes, c: Lanes) -> tuple[Lanes, ...]:
    """From the gates' activations and c_{t-1}: c_{t-1} (kept), c_t, tanh(c_t) and h_t."""
    c_t = f * c + i * g
    tanh_c = c_t.tanh()
    return c, c_t, tanh_c, o * tanh_c


def _gate_grads(
    i: Lanes, f: Lanes, g: Lanes, o: Lanes, tanh_c: Lanes, c_prev: Lanes, dh: Lanes, dc: Lanes
) -> tuple[Lanes, ...]:
    """The gates' pre-activation gradients (i, f, g, o) from d loss / d h_t and d loss / d c_t
    (through c_{t+1}), and d loss / d c_{t-1}, set to 0 below ``_TINY``."""
    dcv = dc + dh * o * (1.0 - tanh_c * tanh_c)
    return (
        dcv * g * i * (1.0 - i),
        dcv * c_prev * f * (1.0 - f),
        dcv * i * (1.0 - g * g),
        dh * tanh_c * o * (1.0 - o),
        (dcv * f).flush(float(_TINY)),
    )


def _flushed(x: Lanes) -> tuple[Lanes]:
    """``x``, 0 below ``_TINY``."""
    return (x.flush(float(_TINY)),)


# The elementwise loops over a step's rows, as whole vectors (``lanes``: numba's own loops over
# these many arrays stay scalar or behind runtime alias checks).
_cell_lanes = lanes(_cell, reads=5)
_gate_grad_lanes = lanes(_gate_grads, reads=8)
_flush_lanes = lanes(_flushed, reads=1)


@numba.njit(inline="always", **_JIT)
def _gate_sums(w_flat, G, K, bias, x_flat, x_at, acts_flat, taps, t):
    """acts[t] = bias + w @ inputs[t, :K] over the chunk's lanes, ``ROWS`` gates per register
    tile (``tap_sums``), on the flat arrays (``x_at``: where ``inputs[t]`` starts); ``taps``:
    each input's offset in ``inputs[t].flat``."""
    for g in range(0, G, ROWS):
        tap_sums(w_flat, g * K, K, 1, x_flat, x_at, taps, K, acts_flat, (t * G + g) * CHUNK,
                 CHUNK, bias, g, CHUNK // WIDTH, WIDTH, WIDTH, PLAIN, acts_flat)  # fmt: skip


@numba.njit(**_JIT)
def _chunk_forward(w, bias, inputs, acts, c_prev, tanh_c, h, c):
    """Run the LSTM over one gathered chunk. ``w`` (4H, C + H) is ``[weight_ih | weight_hh]``,
    gates in nn.LSTM's order (i, f, g, o), ``inputs`` (T, >= C + H, CHUNK) the inputs x_t above
    the states h_{t-1}, which this fills. Keeps the gate activations ``acts`` (T, 4H, CHUNK),
    c_{t-1} ``c_prev`` and tanh(c_t) ``tanh_c`` (T, H, CHUNK) for backward; ends with h_T, c_T
    in h, c.

    Step by step, so that what a step touches (~20 KB, contiguous in each array) stays in L1:
    four gates at a time (``tap_sums``), each gate's sum is its bias, then its inputs, then its
    states; the gates' nonlinearities over the step's rows (``tanh_lanes``); then c_t, its
    tanh and h_t (``_cell``), h_t into the next step's inputs."""
    G, K = w.shape
    H = G // 4
    C = K - H
    T = inputs.shape[0]
    c[:] = 0
    for j in range(H):
        for b in range(CHUNK):
            inputs[0, C + j, b] = 0
    taps = np.arange(K) * CHUNK  # input k of step t: inputs[t].flat[taps[k] + lane]
    acts_flat, in_flat = acts.reshape(-1), inputs.reshape(-1)
    c_flat, c_prev_flat, tanh_c_flat, h_flat = (
        c.reshape(-1),
        c_prev.reshape(-1),
        tanh_c.reshape(-1),
        h.reshape(-1),
    )
    rows = H * CHUNK  # floats of one gate's (or the states') rows in a step
    K_in = inputs.shape[1]
    w_flat = w.reshape(-1)
    for t in range(T):
        _gate_sums(w_flat, G, K, bias, in_flat, t * K_in * CHUNK, acts_flat, taps, t)
        at = t * G * CHUNK
        tanh_lanes(acts_flat, at, 2 * rows, _HALF, _HALF)  # i, f: sigmoid
        tanh_lanes(acts_flat, at + 2 * rows, rows, _ONE, _ZERO)  # g: tanh
        tanh_lanes(acts_flat, at + 3 * rows, rows, _HALF, _HALF)  # o: sigmoid
        # h_t into the next step's inputs, the last one into h
        h_out, h_at = (in_flat, ((t + 1) * K_in + C) * CHUNK) if t + 1 < T else (h_flat, 0)
        _cell_lanes(
            (acts_flat, acts_flat, acts_flat, acts_flat, c_flat, c_prev_flat, c_flat, tanh_c_flat,
             h_out),
            (at, at + rows, at + 2 * rows, at + 3 * rows, 0, t * rows, 0, t * rows, h_at),
            rows,
        )  # fmt: skip


@numba.njit(inline="always", **_JIT)
def _step_weight_grad(
    in_flat, K_pad, G_pad, d_flat, t, td, starts, d_t_flat, taps, zero, d_wt_flat
):
    """``d_wt`` (K', G') += ``inputs[t]`` (K', CHUNK) @ ``d_gates[td]`` (G', CHUNK).T, on the
    flat arrays: the step's gate gradients transposed in registers into ``d_t`` (CHUNK, G'),
    then summed over the chunk's lanes by register tiles (``tap_sums``: four inputs x all
    gates), each sum added to the running sum as it is stored (``ADDED``): the sum over the
    chunk's steps runs one step at a time."""
    for g in range(0, G_pad, WIDTH):
        for i in range(WIDTH):
            starts[i] = (td * G_pad + g + i) * CHUNK
        for m in range(0, CHUNK, WIDTH):
            transpose_tile(d_flat, starts, m, d_t_flat, g, G_pad)
    for k in range(0, K_pad, ROWS):
        tap_sums(in_flat, (t * K_pad + k) * CHUNK, CHUNK, 1, d_t_flat, 0, taps, CHUNK, d_wt_flat,
                 k * G_pad, G_pad, zero, 0, G_pad // WIDTH, WIDTH, WIDTH, ADDED,
                 d_wt_flat)  # fmt: skip


@numba.njit(**_JIT)
def _chunk_backward(w, inputs, acts, c_prev, tanh_c, dh, dc, d_gates, d_wt):
    """Back-propagate d loss / d h_T ``dh`` (H, CHUNK) through one chunk's forward into the gate
    pre-activation gradients ``d_gates`` (T, G', CHUNK; or (1, G', CHUNK): only the current
    step's, all a step needs, which stay in L1) and the chunk's weight and bias
    gradients, transposed, in ``d_wt`` (K', G'): row k < C + H input k's, row C + H the bias's
    (``inputs[:, C + H]`` is ones), columns past the 4H gates zero (``d_gates``' rows past 4H
    are zero). ``dh`` and ``dc`` are overwritten."""
    G, K = w.shape
    H = G // 4
    C = K - H
    T = inputs.shape[0]
    G_pad = d_gates.shape[1]
    rows = -(-H // ROWS) * ROWS  # the states' gradient in whole tiles, the last rows zero
    w_state = np.zeros((rows, G), np.float32)  # weight_hh transposed: d h_t-1 = w_state @ d_gates
    for g in range(G):
        for k in range(H):
            w_state[k, g] = w[g, C + k]
    dh_sum = np.empty((rows, CHUNK), np.float32)
    zero = np.zeros(ROWS, np.float32)
    w_state_flat, d_flat, dh_flat = w_state.reshape(-1), d_gates.reshape(-1), dh_sum.reshape(-1)
    taps = np.arange(G) * CHUNK  # gate g of step t: d_gates[t].flat[taps[g] + lane]
    starts = np.empty(WIDTH, np.int64)
    d_t = np.empty((CHUNK, G_pad), np.float32)
    lane_taps = np.arange(CHUNK) * G_pad  # lane m of d_t: d_t.flat[lane_taps[m] + gate]
    d_wt[:] = 0
    dc[:] = 0
    acts_flat, tanh_c_flat, c_prev_flat = acts.reshape(-1), tanh_c.reshape(-1), c_prev.reshape(-1)
    dh_in, dc_flat = dh.reshape(-1), dc.reshape(-1)
    in_flat, d_t_flat, d_wt_flat = inputs.reshape(-1), d_t.reshape(-1), d_wt.reshape(-1)
    K_pad = d_wt.shape[0]
    n = H * CHUNK  # floats of one gate's (or the states') rows in a step
    for t in range(T - 1, -1, -1):
        td = t if len(d_gates) > 1 else 0
        at, d_at = t * G * CHUNK, td * G_pad * CHUNK
        _gate_grad_lanes(
            (acts_flat, acts_flat, acts_flat, acts_flat, tanh_c_flat, c_prev_flat, dh_in, dc_flat,
             d_flat, d_flat, d_flat, d_flat, dc_flat),
            (at, at + n, at + 2 * n, at + 3 * n, t * n, t * n, 0, 0,
             d_at, d_at + n, d_at + 2 * n, d_at + 3 * n, 0),
            n,
        )  # fmt: skip
        for k in range(0, rows, ROWS):
            tap_sums(w_state_flat, k * G, G, 1, d_flat, d_at, taps, G, dh_flat,
                     k * CHUNK, CHUNK, zero, 0, CHUNK // WIDTH, WIDTH, WIDTH, PLAIN,
                     dh_flat)  # fmt: skip
        _flush_lanes((dh_flat, dh_in), (0, 0), n)
        _step_weight_grad(in_flat, K_pad, G_pad, d_flat, t, td, starts, d_t_flat, lane_taps,
                          zero, d_wt_flat)  # fmt: skip


@numba.njit(parallel=True, **_JIT)
def _forward(X, rows, w, bias, h_last, inputs, acts, c_prev, tanh_c):
    """h_T (len(rows), H) of the instances ``X[rows]`` (N, C, T), chunks shared by threads: one
    per row of the arrays ``_activations`` gives."""
    n_chunks = (len(rows) + CHUNK - 1) // CHUNK
    parts = len(inputs)
    for p in numba.prange(parts):
        h, c = _states(c_prev)
        for chunk in range(p, n_chunks, parts):
            start = chunk * CHUNK
            _gather(X, rows, start, inputs[p])
            _chunk_forward(w, bias, inputs[p], acts[p], c_prev[p], tanh_c[p], h, c)
            for b in range(min(CHUNK, len(rows) - start)):
                for j in range(len(h)):
                    h_last[start + b, j] = h[j, b]


@numba.njit(inline="always", **_JIT)
def _states(c_prev):
    """A thread's h and c (H, CHUNK), H from ``c_prev`` (threads, T, H, CHUNK)."""
    H = c_prev.shape[2]
    return np.empty((H, CHUNK), np.float32), np.empty((H, CHUNK), np.float32)


@numba.njit(parallel=True, **_JIT)
def _backward(X, rows, w, bias, dh_last, d_wt, dx, inputs, acts, c_prev, tanh_c, d_gates):
    """Gradients of the loss through h_T: each chunk's weight and bias gradients, transposed, in
    ``d_wt`` (n_chunks, K', G') (as ``_chunk_backward``; the caller sums them in order), and
    d loss / d X[rows] in ``dx`` (len(rows), C, T) unless ``dx`` is empty; as ``_forward``, with
    each thread's gate gradients in ``d_gates`` (``_gate_gradients``: every step's when ``dx``
    is wanted, else the current step's)."""
    G, K = w.shape
    H = G // 4
    C = K - H
    T = X.shape[2]
    n_chunks = d_wt.shape[0]
    parts = len(inputs)
    for p in numba.prange(parts):
        h, c = _states(c_prev)
        for chunk in range(p, n_chunks, parts):
            start = chunk * CHUNK
            n = min(CHUNK, len(rows) - start)
            _gather(X, rows, start, inputs[p])
            _chunk_forward(w, bias, inputs[p], acts[p], c_prev[p], tanh_c[p], h, c)
            h[:] = 0  # now d loss / d h_T; lanes past the last row stay zero
            for b in range(n):
                for j in range(H):
                    h[j, b] = dh_last[start + b, j]
            _chunk_backward(
                w, inputs[p], acts[p], c_prev[p], tanh_c[p], h, c, d_gates[p], d_wt[chunk]
            )
            if dx.shape[0] > 0:
                for b in range(n):
                    for ch in range(C):
                        for t in range(T):
                            s = np.float32(0)
                            for gate in range(G):
                                s += w[gate, ch] * d_gates[p, t, gate, b]
                            dx[start + b, ch, t] = s


@numba.njit(parallel=True, **_JIT)
def _train(X, rows, y, w_ih, w_hh, b_ih, b_hh, fc_w, fc_b, out_w, out_b, hinge, d_wt, d_fc, d_out,
           losses, inputs, acts, c_prev, tanh_c, d_gates, grads):  # fmt: skip
    """One training step of LSTM -> FC(F) + ReLU -> FC(1) -> loss, a chunk at a time: its
    forward, the two layers, each instance's loss (0/1 labels ``y`` per row of ``X``; the mean
    over the batch) and back through all of it, the chunk's activations still in cache (no
    forward run again). ``w_ih``, ``w_hh``, ``b_ih``, ``b_hh``: ``nn.LSTM``'s parameters;
    ``fc_w``, ``fc_b`` the FC layer's; ``out_w`` (F,) and ``out_b`` (1,) the output layer's. Per
    chunk: ``d_wt`` as ``_backward``'s, ``d_fc`` (F, H + 1) the FC layer's weight and bias
    gradients, ``d_out`` (F + 1) the output layer's, ``losses`` its summed loss. The arrays after
    them as ``_backward``'s. ``grads`` <- the chunks' gradients summed (``_gradient_sums``).
    Returns the summed loss (numpy's float64 sum of the chunks'). Every row index is checked
    first: the gathers read without bounds checks."""
    for r in rows:
        if not 0 <= r < len(X):
            raise IndexError("compiled LSTM: rows must lie in [0, len(X)), the rows of X")
    (G, C), H = w_ih.shape, w_hh.shape[1]
    K = C + H
    w = np.empty((G, K), np.float32)  # as ``_forward``'s
    w[:, :C], w[:, C:] = w_ih, w_hh
    bias = b_ih + b_hh
    n_chunks = d_wt.shape[0]
    parts = len(inputs)
    F = fc_w.shape[0]
    scale = _ONE / np.float32(len(rows))  # the mean's gradient
    for p in numba.prange(parts):
        h, c = _states(c_prev)
        z = np.empty((F, CHUNK), np.float32)  # FC pre-activations, then their gradients
        a = np.empty((F, CHUNK), np.float32)  # after the ReLU
        gs = np.empty(CHUNK, np.float32)
        for chunk in range(p, n_chunks, parts):
            start = chunk * CHUNK
            n = min(CHUNK, len(rows) - start)
            _gather(X, rows, start, inputs[p])
            _chunk_forward(w, bias, inputs[p], acts[p], c_prev[p], tanh_c[p], h, c)
            for f in range(F):
                for b in range(CHUNK):
                    z[f, b] = fc_b[f]
                for j in range(H):
                    weight = fc_w[f, j]
                    for b in range(CHUNK):
                        z[f, b] += weight * h[j, b]
                for b in range(CHUNK):
                    a[f, b] = z[f, b] * np.float32(z[f, b] > 0)
            total = np.float32(0.0)
            gs[:] = 0
            for b in range(n):
                score = out_b[0]
                for f in range(F):
                    score += out_w[f] * a[f, b]
                label = _TWO * y[rows[start + b]] - _ONE
                loss, slope = loss_slope(label * score, hinge, _ONE)
                total += loss
                gs[b] = label * slope * scale
            losses[chunk] = total
            out = d_out[chunk]
            out[F] = gs.sum()
            for f in range(F):
                acc = np.float32(0.0)
                for b in range(CHUNK):
                    acc += gs[b] * a[f, b]
                    z[f, b] = out_w[f] * gs[b] * np.float32(z[f, b] > 0)  # the ReLU's backward
                out[f] = acc
            fc = d_fc[chunk]
            for f in range(F):
                fc[f, H] = z[f].sum()
                for j in range(H):
                    acc = np.float32(0.0)
                    for b in range(CHUNK):
                        acc += z[f, b] * h[j, b]
                    fc[f, j] = acc
            for j in range(H):  # h becomes d loss / d h_T
                for b in range(CHUNK):
                    h[j, b] = 0
                for f in range(F):
                    weight = fc_w[f, j]
                    for b in range(CHUNK):
                        h[j, b] += weight * z[f, b]
            _chunk_backward(
                w, inputs[p], acts[p], c_prev[p], tanh_c[p], h, c, d_gates[p], d_wt[chunk]
            )
    _gradient_sums(d_wt, d_fc, d_out, C, H, grads)
    return pairwise_sum(losses, np.float64(0.0))


@numba.njit(**_JIT)
def _weight_gradients(d_wt, C, H, grads):
    """``grads`` <- ``nn.LSTM``'s weight_ih (G, C), weight_hh (G, H), bias_ih and bias_hh (both
    the gates' summed gradient) gradients, one after another, from the chunks' transposed
    weight gradients ``d_wt`` (chunks, K', G'), summed in chunk order; returns how many floats
    that is."""
    total = ordered_sum(d_wt)
    G, K = 4 * H, C + H
    for g in range(G):
        for c in range(C):
            grads[g * C + c] = total[c, g]
        for j in range(H):
            grads[G * C + g * H + j] = total[C + j, g]
        grads[G * K + g] = total[K, g]
        grads[G * K + G + g] = total[K, g]
    return G * K + 2 * G


@numba.njit(**_JIT)
def _gradient_sums(d_wt, d_fc, d_out, C, H, grads):
    """``grads`` <- the training step's gradients in the parameters' order and layout, the
    chunks' summed in order: the LSTM's (``_weight_gradients``), then the FC layer's weight
    (F, H) and bias and the output layer's weight (1, F) and bias."""
    at = _weight_gradients(d_wt, C, H, grads)
    fc, out = ordered_sum(d_fc), ordered_sum(d_out)
    F = len(fc)
    for f in range(F):
        for j in range(H):
            grads[at + f * H + j] = fc[f, j]
        grads[at + F * H + f] = fc[f, H]
    at += F * H + F
    for f in range(F + 1):
        grads[at + f] = out[f]


def _parts(n_rows: int) -> int:
    """Threads for ``n_rows`` instances: numba's, at most one per chunk (the kernels take it as
    an argument: calling ``numba.get_num_threads`` inside would keep them out of the cache)."""
    return max(1, min(-(-n_rows // CHUNK), numba.get_num_threads()))


def _padded(K: int, G: int) -> tuple[int, int]:
    """(K', G'): the inputs and the bias's row of ones in whole tiles of rows, the gates in whole
    vectors (the shapes of the transposed weight gradient)."""
    return -(-(K + 1) // ROWS) * ROWS, -(-G // WIDTH) * WIDTH


# (which, shapes) -> arrays kept from call to call (``_activations``, ``_gate_gradients``)
_KEPT: dict[tuple[str, int, int, int, int], tuple[np.ndarray, ...]] = {}


def _activations(n_rows: int, T: int, K: int, G: int) -> tuple[np.ndarray, ...]:
    """Each thread's arrays for a chunk's forward, one row per thread, kept from call to call
    (fresh ones, ~4 MB a thread, cost a page fault per 4 KB every step; the kernels write no
    row they read as constant), in one block on huge pages (``carved``): inputs (T, K', CHUNK)
    with the bias's row of ones (its gradient is the gate gradients' sum) and zero rows past
    it, activations (T, G, CHUNK), c_{t-1} and tanh(c_t) (T, H, CHUNK)."""
    threads, (K_pad, _), H = _parts(n_rows), _padded(K, G), G // 4
    key = ("activations", threads, T, K, G)
    if key not in _KEPT:
        arrays = carved([(threads, T, rows, CHUNK) for rows in (K_pad, G, H, H)])
        arrays[0][:, :, K] = 1  # the rows past it stay zero
        _KEPT[key] = tuple(arrays)
    return _KEPT[key]


def _gate_gradients(threads: int, steps: int, G: int, G_pad: int) -> np.ndarray:
    """Each thread's gate gradients (threads, steps, G_pad, CHUNK), kept from call to call, the
    rows past the G gates zero: every step's for the input's gradient, else one step's (what a
    step's weight and state gradients use at once; 12 KB, in L1, against the chunk's 1.8 MB)."""
    key = ("gate gradients", threads, steps, G, G_pad)
    if key not in _KEPT:
        _KEPT[key] = (np.zeros((threads, steps, G_pad, CHUNK), np.float32),)
    return _KEPT[key][0]


class LSTMLastHidden(torch.autograd.Function):
    """The last hidden state (B, H) of a one-layer LSTM over the rows ``rows`` of (N, C, T)
    float32 CPU input, with ``nn.LSTM``'s parameters (weight_ih (4H, C), weight_hh (4H, H),
    bias_ih, bias_hh)."""

    @staticmethod
    def forward(ctx, x, rows, w_ih, w_hh, b_ih, b_hh):  # type: ignore[override]
        w = torch.cat([w_ih, w_hh], 1).detach().contiguous()
        bias = (b_ih + b_hh).detach().contiguous()
        h_last = np.empty((len(rows), w_hh.shape[1]), np.float32)
        X = x.detach().numpy()
        G, K = w.shape
        arrays = _activations(len(rows), x.shape[2], K, G)
        _forward(X, rows.numpy(), w.numpy(), bias.numpy(), h_last, *arrays)
        ctx.save_for_backward(x, rows)
        ctx.weights = (w, bias)
        return torch.from_numpy(h_last)

    @staticmethod
    def backward(ctx, dh):  # type: ignore[override]
        x, rows = ctx.saved_tensors
        w, bias = ctx.weights
        G, K = w.shape
        n_chunks = (len(rows) + CHUNK - 1) // CHUNK
        d_wt = np.empty((n_chunks, *_padded(K, G)), np.float32)
        dx = np.empty((len(rows) if ctx.needs_input_grad[0] else 0, *x.shape[1:]), np.float32)
        X = x.detach().numpy()
        dh_last = dh.contiguous().numpy()
        arrays = _activations(len(rows), x.shape[2], K, G)
        steps = x.shape[2] if len(dx) else 1
        d_gates = _gate_gradients(len(arrays[0]), steps, G, d_wt.shape[2])
        _backward(X, rows.numpy(), w.numpy(), bias.numpy(), dh_last, d_wt, dx, *arrays, d_gates)
        C, H = x.shape[1], K - x.shape[1]
        grads = np.empty(G * K + 2 * G, np.float32)
        _weight_gradients(d_wt, C, H, grads)
        parts = np.split(grads, [G * C, G * K, G * K + G])
        shapes = [(G, C), (G, H), (G,), (G,)]  # weight_ih, weight_hh, bias_ih, bias_hh
        weights = [torch.from_numpy(g.reshape(s)) for g, s in zip(parts, shapes, strict=True)]
        d_x = None
        if ctx.needs_input_grad[0]:
            d_x = torch.zeros_like(x).index_add_(0, rows, torch.from_numpy(dx))
        return d_x, None, *weights


def lstm_last_hidden(
    x: torch.Tensor, lstm: torch.nn.LSTM, rows: torch.Tensor | None = None
) -> torch.Tensor:
    """``lstm(x[rows].transpose(1, 2))``'s last hidden state (B, H), computed by the compiled
    kernels; ``rows`` (default: all) are read in place, never copied out as a batch."""
    if x.device.type != "cpu" or x.dtype != torch.float32:
        raise ValueError(f"compiled LSTM: expects float32 CPU input, got {x.dtype} on {x.device}")
    x = x.contiguous()
    rows = torch.arange(len(x)) if rows is None else rows.to(torch.int64).contiguous()
    check_rows(rows, len(x), "compiled LSTM")
    params = (lstm.weight_ih_l0, lstm.weight_hh_l0, lstm.bias_ih_l0, lstm.bias_hh_l0)
    ensure_compiled(__name__)
    return LSTMLastHidden.apply(x, rows, *params)


def lstm_step(
    x: torch.Tensor,
    rows: torch.Tensor,
    y: torch.Tensor,
    lstm: torch.nn.LSTM,
    fc: torch.nn.Linear,
    out: torch.nn.Linear,
    *,
    loss: str,
) -> torch.Tensor:
    """``losses.LOSSES[loss](out(fc(h_T).relu()).squeeze(1), y[rows])``, h_T the last hidden state
    of ``lstm`` over ``x[rows]`` (float32 CPU (n, C, T), 0/1 labels ``y``), to float rounding,
    returned detached, its gradients added to the parameters' ``.grad``
    (``train.add_gradients``; ``x`` gets none): one compiled pass per step, each chunk's forward
    kept in cache for its backward, with no autograd graph around it (as the ConvNet's
    ``convnet_tiles.tiled_step``)."""
    if loss not in LOSSES:
        raise ValueError(f"the compiled LSTM step computes {', '.join(LOSSES)}, not {loss!r}")
    if x.device.type != "cpu" or x.dtype != torch.float32:
        raise ValueError(f"compiled LSTM: expects float32 CPU input, got {x.dtype} on {x.device}")
    ensure_compiled(__name__)
    params = (lstm.weight_ih_l0, lstm.weight_hh_l0, lstm.bias_ih_l0, lstm.bias_hh_l0, fc.weight,
              fc.bias, out.weight, out.bias)  # fmt: skip
    (G, H), F = params[1].shape, params[4].shape[0]  # weight_hh, the FC layer's weight
    rows = rows.to(torch.int64).contiguous()  # each checked to lie in ``x`` by ``_train``
    n_chunks = (len(rows) + CHUNK - 1) // CHUNK
    K_pad, G_pad = _padded(x.shape[1] + H, G)
    d_wt = np.empty((n_chunks, K_pad, G_pad), np.float32)
    d_fc = np.empty((n_chunks, F, H + 1), np.float32)
    d_out = np.empty((n_chunks, F + 1), np.float32)
    losses = np.empty(n_chunks, np.float32)
    sizes = [p.numel() for p in params]
    grads = np.empty(sum(sizes), np.float32)
    arrays = _activations(len(rows), x.shape[2], x.shape[1] + H, G)
    w_ih, w_hh, b_ih, b_hh, fc_w, fc_b, out_w, out_b = (p.detach().numpy() for p in params)
    total = _train(
        x.detach().contiguous().numpy(), rows.numpy(), y.to(torch.float32).contiguous().numpy(),
        w_ih, w_hh, b_ih, b_hh, fc_w, fc_b, out_w.reshape(-1), out_b, loss == "hinge", d_wt, d_fc,
        d_out, losses, *arrays, _gate_gradients(len(arrays[0]), 1, G, G_pad), grads,
    )  # fmt: skip
    ends = itertools.accumulate(sizes)  # one tensor per parameter, taken as its ``.grad``
    add_gradients(params, [torch.from_numpy(grads[end - size : end].reshape(p.shape))
                           for end, size, p in zip(ends, sizes, params, strict=True)])  # fmt: skip
    return torch.tensor(total / len(rows), dtype=torch.float32)


def warm_up() -> None:
    """Compile every kernel of this module (into numba's cache) on a toy batch, with the types a
    job's calls have: forward and backward, with and without the input's gradient, and the
    training step with each loss."""
    torch.manual_seed(0)
    lstm = torch.nn.LSTM(3, 2, batch_first=True)
    x = torch.randn(5, 3, 4)
    lstm_last_hidden(x, lstm, torch.tensor([0, 2, 4])).sum().backward()
    lstm_last_hidden(x.requires_grad_(), lstm).sum().backward()
    fc, out, y = torch.nn.Linear(2, 3), torch.nn.Linear(3, 1), torch.tensor([0.0, 1.0, 1.0])
    for loss in LOSSES:
        lstm_step(x.detach(), torch.tensor([0, 2, 4]), y, lstm, fc, out, loss=loss)
