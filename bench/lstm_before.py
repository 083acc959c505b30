"""The haptic LSTM's earlier compiled kernels, kept here as ``bench_lstm.py``'s reference.

Not part of the package: the package has one compiled path (``tactile_exp.models.lstm_kernels``).
These kernels (commit 3e6f3cd) ran the whole batch at once in a (feature, time, batch) layout:
the batch copied out of the training set and transposed, the input projection and the weight
gradients as whole-batch matrix products, the recurrence forward and backward as two
single-threaded numba loops. ``lstm_last_hidden(x, lstm)`` takes the batch ``x`` itself.
"""

from __future__ import annotations

import numpy as np
import torch

from tactile_exp.models.numba_setup import numba
from tactile_exp.models.scratch import scratch

# error_model="numpy": no ZeroDivisionError check inside the loops, which blocks vectorisation.
_JIT = dict(fastmath=True, error_model="numpy", cache=True)
_CLAMP = np.float32(7.90531110763549805)  # tanh is 1 - 2e-7 here: the approximation's range
_HALF = np.float32(0.5)
_ONE = np.float32(1.0)


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


@numba.njit(**_JIT)
def _to_feature_time_batch(x, out):
    """(B, C, T) -> (C, T, B), in blocks of 16 rows so reads and writes stay in cache."""
    B, C, T = x.shape
    for b0 in range(0, B, 16):
        b1 = min(b0 + 16, B)
        for c in range(C):
            for t in range(T):
                for b in range(b0, b1):
                    out[c, t, b] = x[b, c, t]


@numba.njit(**_JIT)
def _forward(acts, w_hh, c_prev, tanh_c, h_prev, h_last):
    """Run the recurrence on the input projection in ``acts`` (4H, T, B), gates in nn.LSTM's
    order (i, f, g, o), overwriting it with the gate activations. Fills the state before each
    step ``c_prev``/``h_prev`` (H, T, B), ``tanh_c`` = tanh(c_t) (H, T, B) and ``h_last`` (H, B)."""
    G, T, B = acts.shape
    H = G // 4
    acc = np.empty(B, acts.dtype)
    c = np.zeros((H, B), acts.dtype)
    h = np.zeros((H, B), acts.dtype)
    for t in range(T):
        for j in range(H):
            for b in range(B):
                c_prev[j, t, b] = c[j, b]
                h_prev[j, t, b] = h[j, b]
        for gate in range(G):
            for b in range(B):
                acc[b] = acts[gate, t, b]
            for k in range(H):
                w = w_hh[gate, k]
                for b in range(B):
                    acc[b] += w * h[k, b]
            if 2 * H <= gate < 3 * H:
                for b in range(B):
                    acts[gate, t, b] = _tanh(acc[b])
            else:
                for b in range(B):
                    acts[gate, t, b] = _HALF * _tanh(_HALF * acc[b]) + _HALF
        for j in range(H):
            for b in range(B):
                cv = acts[H + j, t, b] * c[j, b] + acts[j, t, b] * acts[2 * H + j, t, b]
                tc = _tanh(cv)
                c[j, b] = cv
                tanh_c[j, t, b] = tc
                h[j, b] = acts[3 * H + j, t, b] * tc
    h_last[:] = h


@numba.njit(**_JIT)
def _backward(dh_last, w_hh, acts, c_prev, tanh_c, d_gates):
    """Back-propagate d loss / d h_T (H, B) through time into the gate pre-activation
    gradients ``d_gates`` (4H, T, B)."""
    G, T, B = acts.shape
    H = G // 4
    dh = dh_last.copy()
    dc = np.zeros_like(dh)
    for t in range(T - 1, -1, -1):
        for j in range(H):
            for b in range(B):
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
                dc[j, b] = dcv * f
        for k in range(H):
            for b in range(B):
                dh[k, b] = 0
            for gate in range(G):
                w = w_hh[gate, k]
                for b in range(B):
                    dh[k, b] += w * d_gates[gate, t, b]


class LSTMLastHidden(torch.autograd.Function):
    """The last hidden state (B, H) of a one-layer LSTM over (B, C, T) float32 CPU input, with
    ``nn.LSTM``'s parameters (weight_ih (4H, C), weight_hh (4H, H), bias_ih, bias_hh)."""

    @staticmethod
    def forward(ctx, x, w_ih, w_hh, b_ih, b_hh):  # type: ignore[override]
        B, C, T = x.shape
        H = w_hh.shape[1]
        inputs = scratch(C + H, T, B)  # x and h_{t-1}, stacked: one gemm for both gradients
        xs, h_prev = inputs[:C], inputs[C:]
        acts = scratch(4 * H, T, B)
        c_prev, tanh_c = scratch(H, T, B), scratch(H, T, B)
        h_last = np.empty((H, B), np.float32)
        _to_feature_time_batch(x.detach().contiguous().numpy(), xs)
        torch.addmm(
            (b_ih + b_hh)[:, None],
            w_ih,
            torch.from_numpy(xs).view(C, T * B),
            out=torch.from_numpy(acts).view(4 * H, T * B),
        )
        _forward(acts, w_hh.detach().numpy(), c_prev, tanh_c, h_prev, h_last)
        ctx.save_for_backward(w_ih, w_hh)
        ctx.arrays = (inputs, acts, c_prev, tanh_c)
        return torch.from_numpy(h_last).t()

    @staticmethod
    def backward(ctx, dh):  # type: ignore[override]
        w_ih, w_hh = ctx.saved_tensors
        inputs, acts, c_prev, tanh_c = ctx.arrays
        G, T, B = acts.shape
        d_gates = scratch(G, T, B)
        dh = dh.t().contiguous().numpy()
        _backward(dh, w_hh.detach().numpy(), acts, c_prev, tanh_c, d_gates)
        flat = torch.from_numpy(d_gates).view(G, T * B)
        d_w = flat @ torch.from_numpy(inputs).view(-1, T * B).t()
        d_w_ih, d_w_hh = d_w[:, : w_ih.shape[1]], d_w[:, w_ih.shape[1] :]
        d_b = flat.sum(1)
        dx = (w_ih.t() @ flat).view(-1, T, B).permute(2, 0, 1) if ctx.needs_input_grad[0] else None
        return dx, d_w_ih, d_w_hh, d_b, d_b


def lstm_last_hidden(x: torch.Tensor, lstm: torch.nn.LSTM) -> torch.Tensor:
    """``lstm(x.transpose(1, 2))``'s last hidden state (B, H), computed by the compiled kernels."""
    if x.device.type != "cpu" or x.dtype != torch.float32:
        raise ValueError(f"compiled LSTM: expects float32 CPU input, got {x.dtype} on {x.device}")
    params = (lstm.weight_ih_l0, lstm.weight_hh_l0, lstm.bias_ih_l0, lstm.bias_hh_l0)
    return LSTMLastHidden.apply(x, *params)
