"""Compiled CPU kernels for the haptic LSTM's recurrence (``impl="compiled"``).

``nn.LSTM`` on CPU runs a few small library calls per time step on a (batch, 10) state, so at
the paper's sizes (hidden 10, 150 steps) it is bound by per-call overhead, not arithmetic. Here
a batch is cut into chunks of ``CHUNK`` instances, and each chunk runs forward and backward
through time inside one numba loop, with the chunk as the innermost, contiguous axis (layout
(feature, time, chunk)), so every gate update is one vector FMA over the chunk. The forward
runs step by step, each step's input projection, recurrence and cell update on data in L1; the
weight gradients are summed per chunk (~5 MB of arrays at C=32), not as whole-batch matrix
products through memory, which made the earlier kernels memory-bound. Chunks run in parallel on
numba's threads. The forward pass keeps nothing: backward recomputes a chunk's forward in cache.
Keeping every chunk's activations for the backward instead (~63 MB a batch of 1,000) made a
training step 1.25x faster alone, but in the Table I grid, two jobs side by side on two cores,
the LSTM job gained ~3% and the ConvNet job beside it lost ~5% (rows G and H against the grid
before, scaled by the machine's speed on rows A to F, which neither version touches): writing
and re-reading them takes the memory bandwidth the other job needs. Each chunk's weight
gradient is summed on its own and the chunks' in a fixed order, so results do not depend on the
thread count.
The gate sums (forward) and the states' gradient (backward) are register tiles
(``vector_tiles.tap_sums``: four gates' sums over all 42 inputs stay in registers), and the
chunk's gather transposes square tiles in registers: against numba's own loops a training step
ran 1.5x faster (one thread, batch 1000, interleaved in one process), with bit-identical
results. Also measured and not kept (the same way): the weight gradient as register tiles of dot
products over the lanes, 1.2x faster alone but ~5% of a step, and it summed in another order,
whose last bits row G's 200 epochs amplify; a chunk's input projection as one BLAS product
(numba's ``np.dot``) before its recurrence, a forward 1.2x slower; the input projection kept
from the forward for the backward's recomputation (24 MB a batch), a step 1.2-1.3x slower.

tanh and the sigmoid use a rational approximation (Eigen's float tanh, max error ~4e-7 over the
real line; sigmoid(x) = tanh(x / 2) / 2 + 1 / 2) because numba calls libm's scalar ``exp`` and
``tanh``, which would not vectorise and cost 7x more.

numba's compiled-code cache: see ``numba_setup``.
"""

from __future__ import annotations

import numpy as np
import torch

from tactile_exp.models.numba_setup import announce_compile, numba
from tactile_exp.models.vector_tiles import PLAIN, ROWS, WIDTH, tap_sums, transpose_tile

# error_model="numpy": no ZeroDivisionError check inside the loops, which blocks vectorisation.
_JIT = dict(fastmath=True, error_model="numpy", cache=True)
_CLAMP = np.float32(7.90531110763549805)  # tanh is 1 - 2e-7 here: the approximation's range
_ZERO = np.float32(0.0)
_HALF = np.float32(0.5)
_ONE = np.float32(1.0)
# Gradients through time shrink by the forget gate (~1/2) each step, to ~1e-45 after 150 steps:
# float32 denormals, which the CPU handles ~100x slower (they made backward 10x slower). The
# carried gradients are set to 0 below this, ~1e-27 of any gradient that moves a weight.
_TINY = np.float32(1e-30)


@numba.njit(inline="always", fastmath=True, error_model="numpy")
def _tanh(x):
    """Eigen's rational approximation of tanh (degree 13/6), vectorisable."""
    x = min(max(x, -_CLAMP), _CLAMP)
    x2 = x * x
    p = np.float32(-2.76076847742355e-16)
    p = p * x2 + np.float32(2.00018790482477e-13)
    p = p * x2 + np.float32(-8.60467152213735e-11)
    p = p * x2 + np.float32(5.12229709037114e-08)
    p = p * x2 + np.float32(1.48572235717979e-05)
    p = p * x2 + np.float32(6.37261928875436e-04)
    p = p * x2 + np.float32(4.89352455891786e-03)
    q = np.float32(1.19825839466702e-06)
    q = q * x2 + np.float32(1.18534705686654e-04)
    q = q * x2 + np.float32(2.26843463243900e-03)
    q = q * x2 + np.float32(4.89352518554385e-03)
    return x * p / q


# Instances per chunk: ~5 MB of arrays at C=32, T=150. Measured at 16, 32, 64, 128 (the bench's
# step on a shared 2-core Xeon): 64 fastest, 128 ~1.6x slower (the chunk leaves the cache).
CHUNK = 64


@numba.njit(**_JIT)
def _gather(X, rows, start, inputs):
    """``inputs[:C]`` (C, T, CHUNK) <- X[rows[start:start + CHUNK]] (rows, C, T), transposed in
    tiles of ``WIDTH`` instances x ``WIDTH`` steps (``transpose_tile``), the rest one by one;
    lanes past the last row are zero, so they carry zeros through forward and backward."""
    _, C, T = X.shape
    n = min(CHUNK, len(rows) - start)
    tiled, steps = n - n % WIDTH, T - T % WIDTH
    flat, flat_in = X.reshape(-1), inputs.reshape(-1)
    starts = np.empty(WIDTH, np.int64)
    for c in range(C):
        for b0 in range(0, tiled, WIDTH):
            for i in range(WIDTH):
                starts[i] = (rows[start + b0 + i] * C + c) * T
            for t in range(0, steps, WIDTH):
                transpose_tile(flat, starts, t, flat_in, c * T * CHUNK + b0, CHUNK)
        for b in range(n):
            r = rows[start + b]
            for t in range(steps if b < tiled else 0, T):
                inputs[c, t, b] = X[r, c, t]
        for t in range(T):
            for b in range(n, CHUNK):
                inputs[c, t, b] = 0


@numba.njit(inline="always", **_JIT)
def _gate_sums(w, bias, inputs, acts, taps, t):
    """acts[:, t] = bias + w @ inputs[:, t] over the chunk's lanes, ``ROWS`` gates per register
    tile (``tap_sums``); ``taps``: each input's offset in ``inputs.flat`` at step 0."""
    G, K = w.shape
    step = inputs.shape[1] * CHUNK
    w_flat, x_flat, acts_flat = w.reshape(-1), inputs.reshape(-1), acts.reshape(-1)
    for g in range(0, G, ROWS):
        at = g * step + t * CHUNK
        tap_sums(w_flat, g * K, K, 1, x_flat, t * CHUNK, taps, K, acts_flat, at, step, bias, g,
                 CHUNK, PLAIN, acts_flat)  # fmt: skip


@numba.njit(**_JIT)
def _chunk_forward(w, bias, inputs, acts, c_prev, tanh_c, h, c):
    """Run the LSTM over one gathered chunk. ``w`` (4H, C + H) is ``[weight_ih | weight_hh]``,
    gates in nn.LSTM's order (i, f, g, o), ``inputs`` (C + H, T, CHUNK) the inputs x_t above the
    states h_{t-1}, which this fills. Keeps the gate activations ``acts`` (4H, T, CHUNK), c_{t-1}
    ``c_prev`` and tanh(c_t) ``tanh_c`` (H, T, CHUNK) for backward; ends with h_T, c_T in h, c.

    Step by step, so that what a step touches (~20 KB) stays in L1: four gates at a time
    (``tap_sums``), each gate's sum is its bias, then its inputs, then its states; then per state
    its four nonlinearities, and the cell update in a second pass that reads them back from
    ``acts`` (in the same pass, the compiler rearranged the update's arithmetic across the
    nonlinearities, off by float rounding)."""
    G, K = w.shape
    H = G // 4
    C = K - H
    T = inputs.shape[1]
    step = T * CHUNK  # floats from one input's (or gate's) row to the next
    c[:] = 0
    for j in range(H):
        for b in range(CHUNK):
            inputs[C + j, 0, b] = 0
    taps = np.arange(K) * step  # input k of step t: inputs.flat[t * CHUNK + taps[k] + lane]
    for t in range(T):
        _gate_sums(w, bias, inputs, acts, taps, t)
        for j in range(H):
            for b in range(CHUNK):
                i = _HALF * _tanh(_HALF * acts[j, t, b]) + _HALF
                f = _HALF * _tanh(_HALF * acts[H + j, t, b]) + _HALF
                g = _tanh(acts[2 * H + j, t, b])
                o = _HALF * _tanh(_HALF * acts[3 * H + j, t, b]) + _HALF
                acts[j, t, b] = i
                acts[H + j, t, b] = f
                acts[2 * H + j, t, b] = g
                acts[3 * H + j, t, b] = o
            for b in range(CHUNK):
                cp = c[j, b]
                c_prev[j, t, b] = cp
                cv = acts[H + j, t, b] * cp + acts[j, t, b] * acts[2 * H + j, t, b]
                tc = _tanh(cv)
                c[j, b] = cv
                tanh_c[j, t, b] = tc
                h[j, b] = acts[3 * H + j, t, b] * tc
            if t + 1 < T:
                for b in range(CHUNK):
                    inputs[C + j, t + 1, b] = h[j, b]


@numba.njit(**_JIT)
def _weight_grad(d_gates, inputs, d_w):
    """``d_w`` (4H, K) = ``d_gates`` (4H, n) @ ``inputs`` (K, n).T, in blocks of four gates x four
    inputs: sixteen running sums per eight loads."""
    G, n = d_gates.shape
    K = inputs.shape[0]
    k4 = K - K % 4
    for g in range(0, G, 4):
        e0, e1, e2, e3 = d_gates[g], d_gates[g + 1], d_gates[g + 2], d_gates[g + 3]
        for k in range(0, k4, 4):
            x0, x1, x2, x3 = inputs[k], inputs[k + 1], inputs[k + 2], inputs[k + 3]
            s00 = s01 = s02 = s03 = s10 = s11 = s12 = s13 = np.float32(0)
            s20 = s21 = s22 = s23 = s30 = s31 = s32 = s33 = np.float32(0)
            for m in range(n):
                f0, f1, f2, f3 = e0[m], e1[m], e2[m], e3[m]
                y0, y1, y2, y3 = x0[m], x1[m], x2[m], x3[m]
                s00 += f0 * y0
                s01 += f0 * y1
                s02 += f0 * y2
                s03 += f0 * y3
                s10 += f1 * y0
                s11 += f1 * y1
                s12 += f1 * y2
                s13 += f1 * y3
                s20 += f2 * y0
                s21 += f2 * y1
                s22 += f2 * y2
                s23 += f2 * y3
                s30 += f3 * y0
                s31 += f3 * y1
                s32 += f3 * y2
                s33 += f3 * y3
            d_w[g, k], d_w[g, k + 1], d_w[g, k + 2], d_w[g, k + 3] = s00, s01, s02, s03
            d_w[g + 1, k], d_w[g + 1, k + 1], d_w[g + 1, k + 2], d_w[g + 1, k + 3] = (
                s10,
                s11,
                s12,
                s13,
            )
            d_w[g + 2, k], d_w[g + 2, k + 1], d_w[g + 2, k + 2], d_w[g + 2, k + 3] = (
                s20,
                s21,
                s22,
                s23,
            )
            d_w[g + 3, k], d_w[g + 3, k + 1], d_w[g + 3, k + 2], d_w[g + 3, k + 3] = (
                s30,
                s31,
                s32,
                s33,
            )
        for k in range(k4, K):
            x = inputs[k]
            s0 = s1 = s2 = s3 = np.float32(0)
            for m in range(n):
                y = x[m]
                s0 += e0[m] * y
                s1 += e1[m] * y
                s2 += e2[m] * y
                s3 += e3[m] * y
            d_w[g, k], d_w[g + 1, k], d_w[g + 2, k], d_w[g + 3, k] = s0, s1, s2, s3


@numba.njit(**_JIT)
def _chunk_backward(w, inputs, acts, c_prev, tanh_c, dh, dc, d_gates, d_w, d_b):
    """Back-propagate d loss / d h_T ``dh`` (H, CHUNK) through one chunk's forward into the gate
    pre-activation gradients ``d_gates`` (4H, T, CHUNK) and the chunk's weight and bias
    gradients ``d_w`` (4H, C + H), ``d_b`` (4H). ``dh`` and ``dc`` are overwritten."""
    G, K = w.shape
    H = G // 4
    C = K - H
    T = inputs.shape[1]
    step = T * CHUNK
    rows = -(-H // ROWS) * ROWS  # the states' gradient in whole tiles, the last rows zero
    w_state = np.zeros((rows, G), np.float32)  # weight_hh transposed: d h_t-1 = w_state @ d_gates
    for g in range(G):
        for k in range(H):
            w_state[k, g] = w[g, C + k]
    dh_sum = np.empty((rows, CHUNK), np.float32)
    zero = np.zeros(ROWS, np.float32)
    w_state_flat, d_flat, dh_flat = w_state.reshape(-1), d_gates.reshape(-1), dh_sum.reshape(-1)
    taps = np.arange(G) * step  # gate g of step t: d_flat[t * CHUNK + taps[g] + lane]
    dc[:] = 0
    for t in range(T - 1, -1, -1):
        for j in range(H):
            for b in range(CHUNK):
                i = acts[j, t, b]
                f = acts[H + j, t, b]
                g = acts[2 * H + j, t, b]
                o = acts[3 * H + j, t, b]
                tc = tanh_c[j, t, b]
                d = dh[j, b]
                dcv = dc[j, b] + d * o * (_ONE - tc * tc)
                d_gates[j, t, b] = dcv * g * i * (_ONE - i)
                d_gates[H + j, t, b] = dcv * c_prev[j, t, b] * f * (_ONE - f)
                d_gates[2 * H + j, t, b] = dcv * i * (_ONE - g * g)
                d_gates[3 * H + j, t, b] = d * tc * o * (_ONE - o)
                dcn = dcv * f
                dc[j, b] = dcn if abs(dcn) >= _TINY else _ZERO
        for k in range(0, rows, ROWS):
            tap_sums(w_state_flat, k * G, G, 1, d_flat, t * CHUNK, taps, G, dh_flat, k * CHUNK,
                     CHUNK, zero, 0, CHUNK, PLAIN, dh_flat)  # fmt: skip
        for k in range(H):
            for b in range(CHUNK):
                s = dh_sum[k, b]
                dh[k, b] = s if abs(s) >= _TINY else _ZERO
    n = T * CHUNK
    flat_d = d_gates.reshape(G, n)
    flat_in = inputs.reshape(K, n)
    _weight_grad(flat_d, flat_in, d_w)
    for gate in range(G):
        s = np.float32(0)
        for m in range(n):
            s += flat_d[gate, m]
        d_b[gate] = s


@numba.njit(parallel=True, **_JIT)
def _forward(X, rows, w, bias, h_last, parts):
    """h_T (len(rows), H) of the instances ``X[rows]`` (N, C, T), chunks shared by ``parts``
    threads."""
    G, K = w.shape
    H = G // 4
    T = X.shape[2]
    n_chunks = (len(rows) + CHUNK - 1) // CHUNK
    for p in numba.prange(parts):
        inputs = np.empty((K, T, CHUNK), np.float32)
        acts = np.empty((G, T, CHUNK), np.float32)
        c_prev = np.empty((H, T, CHUNK), np.float32)
        tanh_c = np.empty((H, T, CHUNK), np.float32)
        h = np.empty((H, CHUNK), np.float32)
        c = np.empty((H, CHUNK), np.float32)
        for chunk in range(p, n_chunks, parts):
            start = chunk * CHUNK
            _gather(X, rows, start, inputs)
            _chunk_forward(w, bias, inputs, acts, c_prev, tanh_c, h, c)
            for b in range(min(CHUNK, len(rows) - start)):
                for j in range(H):
                    h_last[start + b, j] = h[j, b]


@numba.njit(parallel=True, **_JIT)
def _backward(X, rows, w, bias, dh_last, d_w, d_b, dx, parts):
    """Gradients of the loss through h_T: each chunk's weight and bias gradients in ``d_w``
    (n_chunks, 4H, C + H) and ``d_b`` (n_chunks, 4H) (the caller sums them in order), and d loss
    / d X[rows] in ``dx`` (len(rows), C, T) unless ``dx`` is empty; as ``_forward``."""
    G, K = w.shape
    H = G // 4
    C = K - H
    T = X.shape[2]
    n_chunks = d_w.shape[0]
    for p in numba.prange(parts):
        inputs = np.empty((K, T, CHUNK), np.float32)
        acts = np.empty((G, T, CHUNK), np.float32)
        c_prev = np.empty((H, T, CHUNK), np.float32)
        tanh_c = np.empty((H, T, CHUNK), np.float32)
        d_gates = np.empty((G, T, CHUNK), np.float32)
        h = np.empty((H, CHUNK), np.float32)
        c = np.empty((H, CHUNK), np.float32)
        for chunk in range(p, n_chunks, parts):
            start = chunk * CHUNK
            n = min(CHUNK, len(rows) - start)
            _gather(X, rows, start, inputs)
            _chunk_forward(w, bias, inputs, acts, c_prev, tanh_c, h, c)
            h[:] = 0  # now d loss / d h_T; lanes past the last row stay zero
            for b in range(n):
                for j in range(H):
                    h[j, b] = dh_last[start + b, j]
            _chunk_backward(w, inputs, acts, c_prev, tanh_c, h, c, d_gates, d_w[chunk], d_b[chunk])
            if dx.shape[0] > 0:
                for b in range(n):
                    for ch in range(C):
                        for t in range(T):
                            s = np.float32(0)
                            for gate in range(G):
                                s += w[gate, ch] * d_gates[gate, t, b]
                            dx[start + b, ch, t] = s


def _parts(n_rows: int) -> int:
    """Threads for ``n_rows`` instances: numba's, at most one per chunk (the kernels take it as
    an argument: calling ``numba.get_num_threads`` inside would keep them out of the cache)."""
    return max(1, min(-(-n_rows // CHUNK), numba.get_num_threads()))


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
        _forward(X, rows.numpy(), w.numpy(), bias.numpy(), h_last, _parts(len(rows)))
        ctx.save_for_backward(x, rows)
        ctx.weights = (w, bias)
        return torch.from_numpy(h_last)

    @staticmethod
    def backward(ctx, dh):  # type: ignore[override]
        x, rows = ctx.saved_tensors
        w, bias = ctx.weights
        G, K = w.shape
        n_chunks = (len(rows) + CHUNK - 1) // CHUNK
        d_w = np.empty((n_chunks, G, K), np.float32)
        d_b = np.empty((n_chunks, G), np.float32)
        dx = np.empty((len(rows) if ctx.needs_input_grad[0] else 0, *x.shape[1:]), np.float32)
        X = x.detach().numpy()
        dh_last = dh.contiguous().numpy()
        parts = _parts(len(rows))
        _backward(X, rows.numpy(), w.numpy(), bias.numpy(), dh_last, d_w, d_b, dx, parts)
        d_w_all = torch.from_numpy(d_w.sum(0))
        d_b_all = torch.from_numpy(d_b.sum(0))
        C = x.shape[1]
        d_x = None
        if ctx.needs_input_grad[0]:
            d_x = torch.zeros_like(x).index_add_(0, rows, torch.from_numpy(dx))
        return d_x, None, d_w_all[:, :C], d_w_all[:, C:], d_b_all, d_b_all


def lstm_last_hidden(
    x: torch.Tensor, lstm: torch.nn.LSTM, rows: torch.Tensor | None = None
) -> torch.Tensor:
    """``lstm(x[rows].transpose(1, 2))``'s last hidden state (B, H), computed by the compiled
    kernels; ``rows`` (default: all) are read in place, never copied out as a batch."""
    if x.device.type != "cpu" or x.dtype != torch.float32:
        raise ValueError(f"compiled LSTM: expects float32 CPU input, got {x.dtype} on {x.device}")
    x = x.contiguous()
    rows = torch.arange(len(x)) if rows is None else rows.to(torch.int64).contiguous()
    if len(rows) and not 0 <= int(rows.min()) <= int(rows.max()) < len(x):
        raise IndexError(f"compiled LSTM: rows must lie in [0, {len(x)}), the rows of x")
    params = (lstm.weight_ih_l0, lstm.weight_hh_l0, lstm.bias_ih_l0, lstm.bias_hh_l0)
    announce_compile(__name__)
    return LSTMLastHidden.apply(x, rows, *params)


def warm_up() -> None:
    """Compile every kernel of this module (into numba's cache) on a toy batch, with the types a
    job's calls have: forward and backward, with and without the input's gradient."""
    torch.manual_seed(0)
    lstm = torch.nn.LSTM(3, 2, batch_first=True)
    x = torch.randn(5, 3, 4)
    lstm_last_hidden(x, lstm, torch.tensor([0, 2, 4])).sum().backward()
    lstm_last_hidden(x.requires_grad_(), lstm).sum().backward()
