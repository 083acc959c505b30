"""The register tiles against numpy: sums, masks, transposes, tanh, elementwise lanes; the vector
width."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
import torch
from numba.core.errors import TypingError

from tactile_exp.models import vector_tiles as vt
from tactile_exp.models.numba_setup import numba


@numba.njit
def _tap_sums(w, x, taps, count, out, out_step, bias, lanes, mode, gate):
    """Every row of ``out`` in tiles of ROWS (w: (rows, taps) as the LSTM's gates use it)."""
    flat_w, flat_x, flat_out, flat_gate = (
        w.reshape(-1),
        x.reshape(-1),
        out.reshape(-1),
        gate.reshape(-1),
    )
    for r in range(0, w.shape[0], vt.ROWS):
        vt.tap_sums(flat_w, r * w.shape[1], w.shape[1], 1, flat_x, 0, taps, count, flat_out,
                    r * out_step, out_step, bias, r, lanes // vt.WIDTH, vt.WIDTH, vt.WIDTH, mode,
                    flat_gate)  # fmt: skip


@numba.njit
def _tap_dots(d, d_at, d_row, d_step, x, x_at, taps, count, x_step, steps, acc, acc_at, own):
    vt.tap_dots(d.reshape(-1), d_at, d_row, d_step, x.reshape(-1), x_at, taps, count, x_step,
                steps, acc.reshape(-1), acc_at, own)  # fmt: skip


@numba.njit
def _tanh_lanes(x, at, count, scale, shift):
    vt.tanh_lanes(x.reshape(-1), at, count, np.float32(scale), np.float32(shift))


@numba.njit
def _transpose(src, starts, t, out, out_at, out_step):
    vt.transpose_tile(src.reshape(-1), starts, t, out.reshape(-1), out_at, out_step)


def _mix(a, b, c):
    """A ``lanes`` body: every operation a Lanes has."""
    s = a * b - c
    return 1.0 - s, (a + 2.0).tanh(), (s * 1e-28).flush(1e-30), 3.0 * b + s


_mix_lanes = vt.lanes(_mix, reads=3)


@numba.njit
def _run_mix(x, out, n):
    """_mix of the first n lanes of x's three rows into out's four rows."""
    xf, of, r, o = x.reshape(-1), out.reshape(-1), x.shape[1], out.shape[1]
    _mix_lanes((xf, xf, xf, of, of, of, of), (0, r, 2 * r, 0, o, 2 * o, 3 * o), n)


@numba.njit
def _run_in_place(x, n):
    """x's first row <- _mix's first and then (the same array named twice) its last output."""
    xf = x.reshape(-1)
    _mix_lanes((xf, xf, xf, xf, xf, xf, xf), (0, n, 2 * n, 3 * n, 4 * n, 5 * n, 3 * n), n)


def _mix_case(n):
    rng = np.random.default_rng(3)
    x = rng.standard_normal((3, n), dtype=np.float32)
    x[2, :4] = x[0, :4] * x[1, :4] + np.float32(1e-3)  # s = -1e-3 or so: flushed
    x[2, 5] = np.nan
    return x


def _case(rows=8, taps=21, lanes=3 * vt.TILE + 2 * vt.WIDTH, seed=0):
    """Weights, inputs (taps rows, in reverse order in memory), biases; lanes past whole tiles."""
    rng = np.random.default_rng(seed)
    w = rng.standard_normal((rows, taps), dtype=np.float32)
    x = rng.standard_normal((taps, lanes), dtype=np.float32)
    order = np.arange(taps)[::-1].copy()  # tap q reads row order[q]
    return w, x, order, rng.standard_normal(rows, dtype=np.float32)


def _sums(w, x, order, bias, count, lanes):
    expected = (
        bias[:, None].astype(np.float64)
        + w[:, :count].astype(np.float64) @ x[order[:count], :lanes]
    )
    out = np.full((w.shape[0], x.shape[1]), np.nan, np.float32)
    return expected, out


@pytest.mark.parametrize("count", [0, 1, 5, 21])
def test_tap_sums_match_numpy_on_every_lane_and_leave_the_rest(count):
    w, x, order, bias = _case()
    lanes = x.shape[1] - vt.WIDTH  # the last vector of each row is not written
    expected, out = _sums(w, x, order, bias, count, lanes)
    _tap_sums(w, x, order * x.shape[1], count, out, x.shape[1], bias, lanes, vt.PLAIN, out)
    np.testing.assert_allclose(out[:, :lanes], expected, rtol=1e-5, atol=1e-5)
    assert np.isnan(out[:, lanes:]).all()


@pytest.mark.parametrize("extra", range(vt.VECTORS))
def test_tap_sums_cover_every_width_of_the_last_tile(extra):
    """Lanes past the whole tiles go as one narrower tile, of 1 to VECTORS - 1 vectors."""
    w, x, order, bias = _case(lanes=vt.TILE + extra * vt.WIDTH)
    expected, out = _sums(w, x, order, bias, 21, x.shape[1])
    _tap_sums(w, x, order * x.shape[1], 21, out, x.shape[1], bias, x.shape[1], vt.PLAIN, out)
    np.testing.assert_allclose(out, expected, rtol=1e-5, atol=1e-5)


@numba.njit
def _tap_sums_along_time(w, x, taps, out, bias, slots, stride):
    """A strided convolution's first ``slots`` output steps, ReLU'd: w (rows, taps), x (steps,
    WIDTH), out (rows, steps, WIDTH)."""
    flat_out, row = out.reshape(-1), out.shape[1] * vt.WIDTH
    for r in range(0, w.shape[0], vt.ROWS):
        vt.tap_sums(w.reshape(-1), r * w.shape[1], w.shape[1], 1, x.reshape(-1), 0, taps,
                    len(taps), flat_out, r * row, row, bias, r, slots, stride * vt.WIDTH,
                    vt.WIDTH, vt.RELU, flat_out)  # fmt: skip


@pytest.mark.parametrize("slots", [3 * vt.VECTORS, 3 * vt.VECTORS + 1, vt.VECTORS - 1])
def test_tap_sums_with_slots_along_time_are_a_strided_convolution(slots):
    """Slot v reads the taps' rows ``stride`` steps on from slot v - 1 and writes the next output
    row: whole tiles of VECTORS slots, then the rest as one narrower tile."""
    rng = np.random.default_rng(5)
    kernel, stride, rows = 5, 2, 8
    w = rng.standard_normal((rows, kernel), dtype=np.float32)
    bias = rng.standard_normal(rows, dtype=np.float32)
    x = rng.standard_normal((stride * slots + kernel, vt.WIDTH), dtype=np.float32)
    out = np.full((rows, slots + 1, vt.WIDTH), np.nan, np.float32)
    _tap_sums_along_time(w, x, np.arange(kernel) * vt.WIDTH, out, bias, slots, stride)
    windows = np.stack([x[v * stride : v * stride + kernel] for v in range(slots)])  # (v, j, m)
    expected = bias[:, None, None] + np.einsum("rj,vjm->rvm", w.astype(np.float64), windows)
    np.testing.assert_allclose(out[:, :slots], np.maximum(expected, 0), rtol=1e-5, atol=1e-5)
    assert np.isnan(out[:, slots:]).all()


def test_tap_sums_relu_keeps_nans_and_a_shut_gate_gives_zero():
    """The ReLU keeps a NaN; its backward gives 0 wherever the gate is shut, NaN or not, as
    torch's threshold_backward does."""
    w, x, order, bias = _case()
    lanes = x.shape[1]
    x[3, 5] = x[3, 6] = np.nan  # tap 17 reads row 3: lanes 5 and 6 of every output row are NaN
    plain = np.empty((w.shape[0], lanes), np.float32)
    relu, gated = np.empty_like(plain), np.empty_like(plain)
    gate = np.where(np.arange(lanes) % 3 == 0, -1.0, 1.0).astype(np.float32) * np.ones_like(plain)
    taps = order * lanes
    for mode, out, g in ((vt.PLAIN, plain, plain), (vt.RELU, relu, relu), (vt.GATED, gated, gate)):
        _tap_sums(w, x, taps, x.shape[0], out, lanes, bias, lanes, mode, g)
    finite = ~np.isnan(plain)
    assert np.isnan(plain[:, 5:7]).all() and np.isnan(relu[:, 5:7]).all()
    assert np.isnan(gated[:, 5]).all() and (gated[:, 6] == 0).all()  # gate open at 5, shut at 6
    np.testing.assert_array_equal(relu[finite], np.maximum(plain, 0)[finite])
    np.testing.assert_array_equal(gated[finite], (plain * (gate > 0))[finite])
    assert (relu[finite] >= 0).all() and (plain[finite] < 0).any()
    expected = torch.ops.aten.threshold_backward(torch.from_numpy(plain), torch.from_numpy(gate), 0)
    np.testing.assert_array_equal(gated, expected.numpy())


def test_tap_sums_added_is_a_running_sum_rounded_as_two_passes():
    """ADDED stores gate[o] + sum, the sum rounded as PLAIN computes it: bit for bit the sums
    computed into a buffer, then added (the LSTM's weight gradient, step by step)."""
    w, x, order, bias = _case()
    lanes = x.shape[1]
    taps = order * lanes
    plain = np.empty((w.shape[0], lanes), np.float32)
    _tap_sums(w, x, taps, x.shape[0], plain, lanes, bias, lanes, vt.PLAIN, plain)
    running = np.random.default_rng(2).standard_normal(plain.shape).astype(np.float32)
    expected = running + plain
    _tap_sums(w, x, taps, x.shape[0], running, lanes, bias, lanes, vt.ADDED, running)
    np.testing.assert_array_equal(running, expected)
    _tap_sums(w, x, taps, x.shape[0], running, lanes, bias, lanes, vt.ADDED, running)
    np.testing.assert_array_equal(running, expected + plain)


def test_tap_sums_are_the_same_at_every_vector_width():
    """Each lane is summed in one order (bias, then one fma per tap), and each float's tanh and
    ``lanes`` body computed by the same operations, at any width: a child process compiled for
    4-float vectors gives the same bits as this one."""
    w, x, order, bias = _case(rows=4, taps=42, lanes=64)
    out = np.empty((4, 64), np.float32)
    _tap_sums(w, x, order * 64, 42, out, 64, bias, 64, vt.PLAIN, out)
    _tanh_lanes(out, 0, out.size, 0.5, 0.5)
    mixed = np.empty((4, 64), np.float32)
    _run_mix(out[:3].copy(), mixed, 64)
    code = (
        "import json, numpy as np, test_vector_tiles as t\n"
        "from tactile_exp.models import vector_tiles as vt\n"
        "w, x, order, bias = t._case(rows=4, taps=42, lanes=64)\n"
        "out = np.empty((4, 64), np.float32)\n"
        "t._tap_sums(w, x, order * 64, 42, out, 64, bias, 64, vt.PLAIN, out)\n"
        "t._tanh_lanes(out, 0, out.size, 0.5, 0.5)\n"
        "mixed = np.empty((4, 64), np.float32)\n"
        "t._run_mix(out[:3].copy(), mixed, 64)\n"
        "print(json.dumps([vt.WIDTH, out.view(np.uint32).tolist(), "
        "mixed.view(np.uint32).tolist()]))\n"
    )
    env = {
        **os.environ,
        "NUMBA_CPU_FEATURES": "-avx512f,-avx2",
        "PYTHONPATH": os.path.dirname(__file__),
    }
    child = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    width, bits, mixed_bits = json.loads(child.stdout)
    assert width == 4
    np.testing.assert_array_equal(np.array(bits, np.uint32), out.view(np.uint32))
    np.testing.assert_array_equal(np.array(mixed_bits, np.uint32), mixed.view(np.uint32))


@pytest.mark.parametrize("count", range(1, vt.DOT_TAPS + 1))
def test_tap_dots_store_each_rows_dot_products_with_each_taps_rows(count):
    """Four gradient rows (every 3rd step of a (rows, steps, lanes) block) against the input
    rows of ``count`` taps (stride 2 in steps), over the first vector of lanes of 3: stored
    together, row by row, nothing past them written; and, where asked, the rows' own sums (a
    bias's gradient) after them, to the bit what the products with a row of ones give."""
    rng = np.random.default_rng(count)
    width, steps = 3 * vt.WIDTH, 7
    d = rng.standard_normal((vt.ROWS, 3 * steps, width), dtype=np.float32)
    x = rng.standard_normal((2 * steps + 9, width), dtype=np.float32)
    taps = np.array([5, 0, 8, 2, 1, 3][:count], np.int64) * width  # the taps' first rows
    products, summed = vt.ROWS * count, vt.ROWS * (count + 1)
    acc = rng.standard_normal(summed + 2, dtype=np.float32)
    before = acc.copy()
    _tap_dots(d, 0, d.shape[1] * width, 3 * width, x, 0, taps, count, 2 * width, steps, acc, 1, 0)
    np.testing.assert_array_equal(acc[[0, *range(1 + products, len(acc))]],
                                  before[[0, *range(1 + products, len(acc))]])  # fmt: skip
    expected = np.zeros((vt.ROWS, count))
    for r in range(vt.ROWS):
        for q in range(count):
            rows = x[taps[q] // width + 2 * np.arange(steps), : vt.WIDTH].astype(np.float64)
            expected[r, q] = (d[r, 3 * np.arange(steps), : vt.WIDTH] * rows).sum()
    np.testing.assert_allclose(acc[1 : 1 + products], expected.ravel(), rtol=1e-5, atol=1e-5)
    alone = acc[1 : 1 + products].copy()
    acc[...] = before
    _tap_dots(d, 0, d.shape[1] * width, 3 * width, x, 0, taps, count, 2 * width, steps, acc, 1, 1)
    np.testing.assert_array_equal(acc[1 : 1 + products], alone)  # the same products beside
    np.testing.assert_array_equal(acc[[0, -1]], before[[0, -1]])
    # the rows' own sums: the products' with a row of ones for input, to the bit
    ones, row_sums = np.ones((1, width), np.float32), np.zeros(vt.ROWS, np.float32)
    _tap_dots(d, 0, d.shape[1] * width, 3 * width, ones, 0, np.zeros(1, np.int64), 1, 0, steps,
              row_sums, 0, 0)  # fmt: skip
    np.testing.assert_array_equal(acc[1 + products : 1 + summed], row_sums)
    own = d[:, 3 * np.arange(steps), : vt.WIDTH].astype(np.float64).sum(axis=(1, 2))
    np.testing.assert_allclose(row_sums, own, rtol=1e-5, atol=1e-5)


@numba.njit
def _head_backward(w, x, y, rows, row_step, steps, out, acc, pad):
    vt.head_backward(w, 0, x, 0, y, pad, rows, row_step, steps, out, pad, acc, 1)


@numba.njit
def _head_backward_per_step(w, x, y, rows, row_step, steps, out, acc, pad):
    """What ``head_backward`` replaces: per step, a ``tap_dots`` and a gated ``tap_sums``."""
    taps, zeros = np.zeros(1, np.int64), np.zeros(vt.ROWS, np.float32)
    four = np.zeros(vt.ROWS, np.float32)  # a call's sums, one per row
    for r in range(0, rows, vt.ROWS):
        for s in range(steps):
            o = pad + r * row_step + s * vt.WIDTH
            vt.tap_dots(y, o, row_step, 0, x, 0, taps, 1, 0, 1, four, 0, 0)
            acc[1 + r * steps + s : 1 + (r + vt.ROWS) * steps : steps] = four
            vt.tap_sums(w, r * steps + s, steps, 1, x, 0, taps, 1, out, o, row_step, zeros, 0, 1,
                        vt.WIDTH, vt.WIDTH, vt.GATED, y)  # fmt: skip


@pytest.mark.parametrize("steps", [1, 3, 19, vt.WIDTH])
def test_head_backward_is_the_per_step_tiles_to_the_bit(steps):
    """A one-output layer's weight gradient (lanes summed by one shuffle tree for ``WIDTH``
    sums) and its input's gradient through the ReLU: the bits of a ``tap_dots`` and a gated
    ``tap_sums`` per (row, step), with fewer sums than a vector, a last part vector and none;
    rows ``pad`` apart and 2 padding rows around them untouched; numpy's values; a gate of 0,
    below 0 or NaN shuts a lane."""
    rng = np.random.default_rng(steps)
    rows, pad, gap = 2 * vt.ROWS, 3 * vt.WIDTH, 2 * vt.WIDTH
    row_step = steps * vt.WIDTH + gap
    y = rng.standard_normal(2 * pad + rows * row_step, dtype=np.float32)
    y *= np.float32(10.0) ** rng.integers(-3, 4, y.shape).astype(np.float32)
    y[rng.random(y.shape) < 0.1] = 0.0
    y[pad + 1] = np.nan
    x = rng.standard_normal(vt.WIDTH, dtype=np.float32)
    w = rng.standard_normal(rows * steps, dtype=np.float32)
    got_out, got_acc = np.full_like(y, 7.0), np.full(rows * steps + 2, 7.0, np.float32)
    want_out, want_acc = got_out.copy(), got_acc.copy()
    _head_backward(w, x, y, rows, row_step, steps, got_out, got_acc, pad)
    _head_backward_per_step(w, x, y, rows, row_step, steps, want_out, want_acc, pad)
    assert got_out.tobytes() == want_out.tobytes() and got_acc.tobytes() == want_acc.tobytes()
    assert got_acc[0] == got_acc[-1] == 7.0
    read = pad + np.arange(rows)[:, None, None] * row_step + np.arange(steps * vt.WIDTH)
    read = read.reshape(rows, steps, vt.WIDTH)
    untouched = np.ones_like(y, bool)
    untouched[read] = False
    assert (got_out[untouched] == 7.0).all()
    ys = y[read].astype(np.float64)
    sums = np.where(np.isnan(ys), 0, ys) @ x.astype(np.float64)
    finite = ~np.isnan(ys).any(axis=2)
    np.testing.assert_allclose(got_acc[1:-1][finite.ravel()], sums[finite], rtol=1e-5, atol=1e-4)
    assert np.isnan(got_acc[1])  # the NaN's sum
    gated = np.where(ys > 0, w.reshape(rows, steps, 1) * x.astype(np.float64), 0)
    np.testing.assert_allclose(got_out[read], gated, rtol=1e-6, atol=1e-30)


def test_tanh_lanes_is_tanh_and_the_sigmoid_within_the_approximations_error():
    x = np.linspace(-12, 12, 50 * vt.WIDTH, dtype=np.float32)
    x[7] = np.nan
    tanh, sigmoid = np.full(x.size + 2 * vt.WIDTH, 5.0, np.float32), np.empty_like(x)
    tanh[vt.WIDTH : -vt.WIDTH], sigmoid[:] = x, x
    _tanh_lanes(tanh, vt.WIDTH, x.size, 1.0, 0.0)
    _tanh_lanes(sigmoid, 0, x.size, 0.5, 0.5)
    exact = x.astype(np.float64)
    got = tanh[vt.WIDTH : -vt.WIDTH]
    assert np.isnan(got[7]) and np.isnan(sigmoid[7])
    finite = ~np.isnan(x)
    np.testing.assert_allclose(got[finite], np.tanh(exact)[finite], rtol=0, atol=1e-6)
    np.testing.assert_allclose(sigmoid[finite], (1 / (1 + np.exp(-exact)))[finite], atol=1e-6)
    assert (tanh[: vt.WIDTH] == 5).all() and (tanh[-vt.WIDTH :] == 5).all()  # the rest untouched
    assert abs(got[-1] - 1) < 3e-7 and abs(got[0] + 1) < 3e-7  # clamped: saturated, no overflow


def test_lanes_run_the_bodys_arithmetic_a_vector_at_a_time():
    """Each operation rounded once in float32, as numpy's; tanh is tanh_lanes'; flush zeroes
    magnitudes under the threshold and NaN; lanes past ``count`` are left alone."""
    n = 5 * vt.WIDTH
    x = _mix_case(n)
    out = np.full((4, n + vt.WIDTH), 7.0, np.float32)
    _run_mix(x, out, n)
    a, b, c = x
    s = a * b - c
    tanh = (a + np.float32(2)).reshape(1, -1).copy()
    _tanh_lanes(tanh, 0, n, 1.0, 0.0)
    small = s * np.float32(1e-28)
    flushed = np.where(np.abs(small) >= np.float32(1e-30), small, np.float32(0))
    expected = [np.float32(1) - s, tanh[0], flushed, np.float32(3) * b + s]
    for row, want in zip(out[:, :n], expected, strict=True):
        np.testing.assert_array_equal(row, want)
    assert (out[2, :4] == 0).all() and out[2, 5] == 0 and (out[2, 6:n] != 0).all()
    assert np.isnan(out[0, 5]) and np.isnan(out[3, 5])  # NaN stays NaN through arithmetic
    assert (out[:, n:] == 7).all()
    x2 = np.concatenate([x, np.zeros((4, n), np.float32)])
    _run_in_place(x2, n)
    np.testing.assert_array_equal(x2[3], expected[3])  # the later of the two values stored


def test_lanes_refuse_what_they_cannot_address():
    flat = _mix_case(vt.WIDTH).reshape(-1)
    with pytest.raises(TypingError, match="_mix: expects tuples of arrays and of their offsets"):
        _mix_reads_only(flat)
    with pytest.raises(TypingError, match="_mix: array must be a C-contiguous float32 array"):
        _mix_four(flat.astype(np.float64))


@numba.njit
def _mix_reads_only(flat):
    _mix_lanes((flat, flat, flat), (0, 1, 2), 0)  # arrays to read, none to write


@numba.njit
def _mix_four(flat):
    _mix_lanes((flat, flat, flat, flat), (0, 1, 2, 3), 0)


def test_transpose_tile_writes_the_rows_as_columns():
    rng = np.random.default_rng(0)
    src = rng.standard_normal((40, 50), dtype=np.float32)
    rows = rng.permutation(40)[: vt.WIDTH]
    out = np.full((60, 3 * vt.WIDTH), np.nan, np.float32)
    _transpose(src, rows * 50 + 1, 7, out, 5 * out.shape[1] + vt.WIDTH, out.shape[1])
    block = out[5 + 7 : 5 + 7 + vt.WIDTH, vt.WIDTH : 2 * vt.WIDTH]
    np.testing.assert_array_equal(block, src[rows, 8 : 8 + vt.WIDTH].T)
    assert np.isnan(out).sum() == out.size - vt.WIDTH**2


@numba.njit
def _transpose_rows(src, starts, steps, out, out_at, out_step):
    vt.transpose_rows(src.reshape(-1), starts, steps, out.reshape(-1), out_at, out_step)


@pytest.mark.parametrize("steps", [vt.WIDTH, 2 * vt.WIDTH, 150])
def test_transpose_rows_writes_every_step_once_the_last_tile_overlapping(steps):
    """Whole rows: every step written, whether or not WIDTH divides the steps, nothing past."""
    rng = np.random.default_rng(1)
    src = rng.standard_normal((30, steps + 3), dtype=np.float32)
    rows = rng.permutation(30)[: vt.WIDTH]
    out = np.full((steps + 4, 2 * vt.WIDTH), np.nan, np.float32)
    _transpose_rows(src, rows * src.shape[1] + 2, steps, out, 2 * out.shape[1] + 1, out.shape[1])
    np.testing.assert_array_equal(out[2 : 2 + steps, 1 : 1 + vt.WIDTH], src[rows, 2 : 2 + steps].T)
    assert np.isnan(out).sum() == out.size - steps * vt.WIDTH


def test_tiles_refuse_arrays_they_cannot_address():
    w, x, order, bias = _case(rows=4)
    out = np.empty((4, x.shape[1]), np.float32)
    with pytest.raises(TypingError, match="w must be a C-contiguous float32 array"):
        _tap_sums(w.astype(np.float64), x, order, 1, out, x.shape[1], bias, vt.WIDTH, vt.PLAIN, out)
    with pytest.raises(TypingError, match="taps must be an int64 array"):
        _tap_sums(w, x, order.astype(np.int32), 1, out, x.shape[1], bias, vt.WIDTH, vt.PLAIN, out)
    with pytest.raises(TypingError, match="tap_dots: taps must be an int64 array"):
        _tap_dots(w, 0, 1, 1, x, 0, order.astype(np.int32), 1, 1, 1, out, 0, 0)


@pytest.mark.parametrize(
    ("name", "features", "on", "off"),
    [
        (None, "-avx512f", {"sse2"}, {"avx512f"}),
        ("generic", None, set(), {"sse2", "avx2"}),
        ("generic", "+avx2,+fma", {"avx2", "fma"}, {"avx512f"}),
    ],
)
def test_the_features_are_numbas_target(monkeypatch, name, features, on, off):
    """The host's features, or none for another named CPU, with NUMBA_CPU_FEATURES applied."""
    monkeypatch.setattr(numba.config, "CPU_NAME", name)
    monkeypatch.setattr(numba.config, "CPU_FEATURES", features)
    found = vt._features()
    assert on <= found and not off & found


@pytest.mark.parametrize(
    ("features", "width", "registers"),
    [({"avx512f", "avx2"}, 16, 32), ({"avx2", "fma"}, 8, 16), ({"sse2"}, 4, 16), (set(), 4, 16)],
)
def test_a_tile_fits_the_vector_registers(features, width, registers):
    """The running sums, a tap's input vectors and a weight stay in registers at every width."""
    got, vectors = vt._lanes(features)
    assert got == width
    assert vt.ROWS * vectors + vectors + 1 <= registers


def test_ordered_sum_is_numpys_sum_over_the_first_axis_to_the_bit():
    """Partial sums of very different sizes (so that any other order rounds differently): the
    sum is numpy's ``sum(axis=0)``, bit for bit, and differs from the reversed order's."""
    rng = np.random.default_rng(3)
    parts = rng.standard_normal((63, 500)).astype(np.float32)
    parts *= np.float32(10.0) ** rng.integers(-4, 5, parts.shape).astype(np.float32)
    out = vt.ordered_sum(parts)
    assert np.array_equal(out, parts.sum(axis=0))
    assert not np.array_equal(out, parts[::-1].sum(axis=0))


def test_pairwise_sum_is_numpys_sum_to_the_bit():
    """Every length to 400 (below 8, the eight running sums, the halves) and two larger, values of
    very different sizes: numpy's ``sum()`` in float32 and ``sum(dtype=np.float64)`` to the bit,
    a zero's sign included; a plain running sum differs on some of them."""
    rng = np.random.default_rng(4)
    differs = 0
    for n in [*range(400), 1000, 5000]:
        a = (rng.standard_normal(n) * np.exp(rng.uniform(-8, 8, n))).astype(np.float32)
        for zero, dtype in ((np.float32(0), np.float32), (np.float64(0), np.float64)):
            got = dtype(vt.pairwise_sum(a, zero))
            assert got.tobytes() == a.sum(dtype=dtype).tobytes(), (n, dtype)
        differs += vt.ordered_sum(a.reshape(n, 1))[0] != a.sum() if n else 0
    assert differs > 100
    minus = np.full(9, -0.0, np.float32)
    assert np.float32(vt.pairwise_sum(minus, np.float32(0))).tobytes() == minus.sum().tobytes()


@numba.njit
def _borrowed_sum_and_fill(a, value):
    view = vt.borrowed(a)
    total = view.sum()
    part = view[1:]  # a slice of a borrowed array, passed on
    part[:] = value
    return total, view.shape[0], view.strides[0]


def test_borrowed_is_the_same_array_without_an_owner():
    """A borrowed array reads the same data with the same shape and strides, and writes land
    in the original (a view of it); anything but an array is refused when compiled."""
    a = np.arange(10, dtype=np.float32)[::2]  # strided: the strides are carried over
    total, length, stride = _borrowed_sum_and_fill(a, np.float32(7.0))
    assert (total, length, stride) == (20.0, 5, 8)
    assert a.tolist() == [0.0, 7.0, 7.0, 7.0, 7.0]
    with pytest.raises(TypingError, match="borrowed: expects an array"):
        numba.njit(lambda x: vt.borrowed(x))(1.0)
