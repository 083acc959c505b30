"""The haptic ConvNet's training step, compiled (numba), a tile of instances at a time in cache.

At batch 1000 a layer's activations are 10-40 MB: a step that runs each layer over the whole batch
writes them to memory in the forward and reads them back in the backward, and the step is bound by
memory bandwidth (``grouped_conv_numba``'s layout, bench/bench_roofline.py). Here a step runs
forward, loss and backward for ``TILE_LANES`` instances at once (one vector: 16 with AVX-512):
their input gathered from the training set (rows read in place), every layer of every signal
group, the classification layer, each instance's loss and its gradient, and back through all
layers, with the tile's activations (~1.4 MB at the paper's sizes with 16 lanes) in the core's L2
cache. Nothing of a tile outlives it but its share of the gradients. The loss is computed inside
(``linear_sgd.LOSSES``: the registered losses it computes); a step with another loss runs through
autograd (``grouped_conv_autograd``).

Layout per tile: (groups, channels, time, lanes), the tile's instances innermost and
contiguous as in ``grouped_conv_numba``, with ``pad`` zero rows before and after each channel's
time axis, so every output step of a convolution reads all its taps (zeros at the edges add
exactly 0) and each layer's taps are one fixed offset table. Output channels are padded to a
multiple of ``ROWS`` with zero weights; their gradients are dropped. ``tap_sums`` computes
``ROWS`` rows x ``VECTORS`` slots in registers, the slots running along time: a convolution's
output steps (its input's rows a stride apart), and for an input gradient the input steps of one
phase of the stride. The forward and the input gradients sum their taps in the order
``grouped_conv_numba``'s kernels do; the weight gradients sum each tile over its steps and lanes
(``tap_dots``), then the tiles in order: results do not depend on the thread count (the weight
gradients' order does on the vector width: 16-lane tiles with AVX-512, 8 with AVX2), and differ
from the whole-batch kernels' by float rounding.

With one vector of lanes a tile keeps its activations in L2: wider tiles (32 or 64 lanes, ~2.7
and 5.4 MB) made a one-thread step 1.1-1.3x slower. The whole-batch kernels through autograd
against this: bench/bench_roofline.py --before.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import torch

from tactile_exp.models.grouped_conv_numba import _in_parallel, conv_out_len
from tactile_exp.models.linear_sgd import LOSSES, loss_slope
from tactile_exp.models.numba_setup import ensure_compiled, numba
from tactile_exp.models.scratch import carved
from tactile_exp.models.vector_tiles import (
    DOT_TAPS,
    GATED,
    PLAIN,
    RELU,
    ROWS,
    WIDTH,
    borrowed,
    head_backward,
    pairwise_sum,
    tap_dots,
    tap_sums,
    transpose_rows,
)
from tactile_exp.train import add_gradients

TILE_LANES = WIDTH  # instances per tile, one vector: see the module docstring for wider tiles
# Reassociation lets the reductions over lanes vectorise; no nnan/ninf, so NaNs propagate.
_JIT = dict(nogil=True, cache=True, fastmath={"reassoc", "contract", "nsz", "arcp"},
            error_model="numpy")  # fmt: skip


@numba.njit(**_JIT)
def _gather(X, rows, m0, n, groups, pad, a0):  # pragma: no cover (compiled)
    """a0[c % groups, c // groups, pad + t, m] = X[rows[m0 + m], c, t] for the tile's ``n``
    instances (zeros in the lanes past them), in ``WIDTH`` x ``WIDTH`` register transposes
    (``transpose_rows``); one value at a time only in a part tile or below ``WIDTH`` steps.
    Each row index is checked first: the transposes read without bounds checks."""
    for m in range(m0, m0 + n):
        if not 0 <= rows[m] < len(X):
            raise IndexError("tiled ConvNet step: rows must lie in [0, len(X)), the rows of X")
    channels, steps = X.shape[1], X.shape[2]
    lanes, tp, c_in = a0.shape[3], a0.shape[2], a0.shape[1]
    flat_x, flat0 = X.reshape(-1), a0.reshape(-1)
    starts = np.empty(WIDTH, np.int64)
    for c in range(channels):
        base = (((c % groups) * c_in + c // groups) * tp + pad) * lanes
        for l0 in range(0, lanes, WIDTH):
            if l0 + WIDTH <= n and steps >= WIDTH:
                for w in range(WIDTH):
                    starts[w] = (rows[m0 + l0 + w] * channels + c) * steps
                transpose_rows(flat_x, starts, steps, flat0, base + l0, lanes)
                continue
            for t in range(steps):
                for m in range(l0, l0 + WIDTH):
                    flat0[base + t * lanes + m] = (
                        X[rows[m0 + m], c, t] if m < n else np.float32(0.0)
                    )


@numba.njit(inline="always", **_JIT)
def _shape(geo, layer):  # pragma: no cover (compiled)
    """A layer's kernel, stride, left padding, input and output channels (``geo``'s row)."""
    return geo[layer, 0], geo[layer, 1], geo[layer, 2], geo[layer, 3], geo[layer, 4]


@numba.njit(inline="always", **_JIT)
def _conv_forward(geo, layer, pad, lanes, g, w, b, taps, fin, fout):  # pragma: no cover (compiled)
    """Convolution ``layer`` of group ``g`` and its ReLU: ``fin`` and ``fout`` the layer's input
    and output for every group, ``w`` and ``b`` its weights and biases, all flat."""
    k, s, left, cin, cout = _shape(geo, layer)
    tpi, tpo = geo[layer, 5] + 2 * pad, geo[layer, 6] + 2 * pad
    at_w, at_in = g * cout * cin * k, (g * cin * tpi + pad - left) * lanes
    at_out = (g * cout * tpo + pad) * lanes
    for e in range(0, cout, ROWS):  # each output step a slot
        tap_sums(w, at_w + e * cin * k, cin * k, 1, fin, at_in, taps, cin * k, fout,
                 at_out + e * tpo * lanes, tpo * lanes, b, g * cout + e, geo[layer, 6], s * lanes,
                 lanes, RELU, fout)  # fmt: skip


@numba.njit(inline="always", **_JIT)
def _conv_backward(geo, layer, pad, lanes, g, at, fin, fd, fdin, gp, bw, btaps, bcount, jtaps,
                   zeros):  # fmt: skip  # pragma: no cover (compiled)
    """Convolution ``layer`` of group ``g`` backward from its output's gradient ``fd`` (ReLU's
    backward applied): its weights' and biases' gradients into ``gp`` (flat, this group's at
    ``at`` x their size, in the order ``_dots_order`` gives) and, but for the first layer, its
    input's gradient through the ReLU before it into ``fdin``. ``fin``: the layer's input for
    every group, flat."""
    k, s, left, cin, cout = _shape(geo, layer)
    tpi, tpo, steps = geo[layer, 5] + 2 * pad, geo[layer, 6] + 2 * pad, geo[layer, 6]
    at_in, at_gp = g * cin * tpi * lanes, at * cout * (cin * k + 1)
    for e in range(0, cout, ROWS):
        for i in range(cin):
            for j in range(0, k, DOT_TAPS):  # the bias's gradient with the first taps'
                taps, own = min(DOT_TAPS, k - j), 1 if i == 0 and j == 0 else 0
                tap_dots(fd, (e * tpo + pad) * lanes, tpo * lanes, lanes, fin,
                         at_in + (i * tpi + pad - left + j) * lanes, jtaps, taps, s * lanes,
                         steps, gp, at_gp, own)  # fmt: skip
                at_gp += ROWS * (taps + own)
    if layer > 0:  # the input of the first needs no gradient
        most = geo[layer, 7]
        for phase in range(s):  # the input steps u * s + phase, each a slot
            slots = (geo[layer, 5] - phase + s - 1) // s
            for i in range(0, cin, ROWS):
                tap_sums(bw, ((g * s + phase) * cin + i) * most, most, 1, fd, pad * lanes,
                         btaps[phase], bcount[phase], fdin, (i * tpi + pad + phase) * lanes,
                         tpi * lanes, zeros, 0, slots, lanes, s * lanes, GATED,
                         fin[at_in:])  # fmt: skip


@numba.njit(nogil=True, cache=True)  # no fastmath: the tiles' shares summed in their order
def _add_shares(shares, start, stop, sums, first):  # pragma: no cover (compiled)
    """``sums[k]`` (+)= the shares of tiles ``start`` to ``stop`` of every gradient ``k``
    (``shares[k]``: tiles x size), in tile order; ``first``: the sums start from tile
    ``start``'s. In two parts, the first tiles' then the rest's, it is ``ordered_sum``."""
    for k in range(len(shares)):
        part, total = shares[k], sums[k]
        if first:
            total[:] = part[start]
        for tile in range(start + 1 if first else start, stop):
            for e in range(len(total)):
                total[e] += part[tile, e]


@numba.njit(**_JIT)
def _tiles(X, rows, y, groups, pad, geo, ws, bs, hw, hb, ftaps, btaps, bcount, bwts, jtaps,
           htaps, acts, flat_acts, grads, hinge, ghb, losses, partial, gs, zeros, shares, sums,
           start, stop):  # fmt: skip  # pragma: no cover (compiled)
    """Tiles ``start`` to ``stop`` of the batch ``rows`` (0/1 labels ``y`` per row of ``X``), each
    tile's rows checked to lie in ``X`` first: each tile's summed loss into ``losses[tile]`` and its
    share of every gradient into ``shares`` (tiles x size: each layer's weights' and biases'
    gradients, padded, in ``_dots_order``; the classification layer's weight's) and ``ghb``; from
    tile 0, each tile's shares added to ``sums`` (``_add_shares``) while in cache. ``geo[layer]``:
    kernel, stride, left padding, input and output channels (padded), input and output steps, and
    the input gradient's taps per input channel (output channels x kernel). ``hw`` (groups, c3', t3)
    the classification layer's weight, flat; ``htaps`` its taps' offsets in a group's last
    activation.
    ``acts`` (``flat_acts``: the same arrays flat), ``grads``, ``partial`` (groups, lanes; flat),
    ``gs``: this task's buffers (``acts``' and ``grads``' padding rows zero). The weights, the input
    gradients' weights, ``grads`` and the shares come flat, one array per layer, taken from their
    tuples once, here, and each layer's pass is a helper called with its arrays: an array taken from
    a tuple at a layer known only at run time, or a view made in the loops, costs numba two atomic
    reference counts each time. The helpers take borrowed arrays (``vector_tiles.borrowed``): their
    reference counts cost ~5% of a step. The classification layer runs on register tiles too: its
    forward a ``tap_sums`` over its (channel, step) taps (one row of weights, computed as ``ROWS``
    equal rows: 4x the multiplies, still ~3x faster than numba's loop over the lanes); its
    backward, per group, a ``head_backward`` (its weights' gradient, the lanes of ``WIDTH`` sums
    added by one shuffle tree, and the last layer's output gradient through the ReLU)."""
    lanes, n_batch = acts[0].shape[3], len(rows)
    scale = np.float32(1.0) / np.float32(n_batch)  # the mean's gradient
    # Every array the tiles' loops pass on, borrowed (``vector_tiles.borrowed``): no atomic
    # reference counts, most on arrays the other threads share.
    X, rows, y, geo, hw = borrowed(X), borrowed(rows), borrowed(y), borrowed(geo), borrowed(hw)
    jtaps, htaps, zeros = borrowed(jtaps), borrowed(htaps), borrowed(zeros)
    ghb, losses, partial, gs = borrowed(ghb), borrowed(losses), borrowed(partial), borrowed(gs)
    c3, t3 = geo[2, 4], geo[2, 6]
    tp3, head = t3 + 2 * pad, c3 * t3  # the last activation's rows per channel, the head's taps
    x0 = borrowed(acts[0])
    a0, a1 = borrowed(flat_acts[0]), borrowed(flat_acts[1])
    a2, a3 = borrowed(flat_acts[2]), borrowed(flat_acts[3])
    w0, w1, w2 = borrowed(ws[0]), borrowed(ws[1]), borrowed(ws[2])
    b0, b1, b2 = borrowed(bs[0]), borrowed(bs[1]), borrowed(bs[2])
    t0, t1, t2 = borrowed(ftaps[0]), borrowed(ftaps[1]), borrowed(ftaps[2])
    d0, d1, d2 = borrowed(grads[0]), borrowed(grads[1]), borrowed(grads[2])
    gp0, gp1 = borrowed(shares[0].reshape(-1)), borrowed(shares[1].reshape(-1))
    gp2, ghw = borrowed(shares[2].reshape(-1)), borrowed(shares[3].reshape(-1))
    bw1, bw2, bt1 = borrowed(bwts[1]), borrowed(bwts[2]), borrowed(btaps[1])
    bt2, bc1, bc2 = borrowed(btaps[2]), borrowed(bcount[1]), borrowed(bcount[2])
    for tile in range(start, stop):
        m0 = tile * lanes
        n = min(lanes, n_batch - m0)
        _gather(X, rows, m0, n, groups, pad, x0)
        for g in range(groups):
            _conv_forward(geo, 0, pad, lanes, g, w0, b0, t0, a0, a1)
            _conv_forward(geo, 1, pad, lanes, g, w1, b1, t1, a1, a2)
            _conv_forward(geo, 2, pad, lanes, g, w2, b2, t2, a2, a3)
            # the classification layer's share of the group's scores: its one row of weights
            # over every tap (channel, step), as ROWS equal rows storing the same lanes
            tap_sums(hw, g * head, 0, 1, a3, (g * c3 * tp3 + pad) * lanes, htaps, head, partial,
                     g * lanes, 0, zeros, 0, 1, lanes, lanes, PLAIN, partial)  # fmt: skip
        total = np.float32(0.0)
        gs[:] = 0.0
        for m in range(n):
            score = partial[m]
            for g in range(1, groups):  # the groups' shares in order, then the bias
                score += partial[g * lanes + m]
            f = np.float32(2.0) * y[rows[m0 + m]] - np.float32(1.0)  # the label as +-1
            loss, slope = loss_slope(f * (score + hb), hinge, np.float32(1.0))
            total += loss
            gs[m] = f * slope * scale
        losses[tile], ghb[tile] = total, gs.sum()
        for g in range(groups - 1, -1, -1):  # the last groups' activations are still in cache
            at_h, at_y = (tile * groups + g) * head, g * c3 * tp3 * lanes
            # the classification layer's backward: its weights' gradient (a3 . gs over the
            # lanes, per channel and step) and the last layer's output gradient (hw gs, gated)
            head_backward(hw, g * head, gs, 0, a3, at_y + pad * lanes, c3, tp3 * lanes, t3, d2,
                          pad * lanes, ghw, at_h)  # fmt: skip
            at = tile * groups + g
            _conv_backward(geo, 2, pad, lanes, g, at, a2, d2, d1, gp2, bw2, bt2, bc2, jtaps, zeros)
            _conv_backward(geo, 1, pad, lanes, g, at, a1, d1, d0, gp1, bw1, bt1, bc1, jtaps, zeros)
            # the first layer's input gradient arguments are not used: any of the right types
            _conv_backward(geo, 0, pad, lanes, g, at, a0, d0, d0, gp0, bw1, bt1, bc1, jtaps, zeros)
        if start == 0:  # the first tiles: their shares summed while in cache
            _add_shares(shares, tile, tile + 1, sums, tile == 0)


Arrays = tuple[np.ndarray, ...]


class Buffers(NamedTuple):
    """A thread's arrays for its tiles (``_buffers``)."""

    acts: Arrays  # the input and each layer's output, (groups, channels, time, lanes)
    grads: Arrays  # each layer's output gradient, a group's, (channels, time, lanes)
    flat_acts: Arrays  # the same arrays flat, as the kernels index them
    flat_grads: Arrays
    partial: np.ndarray  # the groups' shares of a tile's scores, (groups x lanes,)
    gs: np.ndarray  # the tile's loss gradients, (lanes,)


# (thread slot, activations' shapes, padding) -> that slot's buffers
_BUFFERS: dict[tuple[int, tuple[tuple[int, ...], ...], int], Buffers] = {}


def _buffers(slot: int, shapes: Sequence[tuple[int, ...]], pad: int) -> Buffers:
    """A thread's arrays for its tiles, kept from step to step, zeroed when made (the kernels
    never write the ``pad`` rows at either end of time, so they stay zero), cut from one block
    on huge pages (``mapped``): a tile's ~1.7 MB at the paper's sizes in one 2 MB page instead
    of ~420 pages of 4 kB, more than the core's TLB holds (``carved``)."""
    key = (slot, tuple(shapes), pad)
    if key not in _BUFFERS:
        groups, lanes = shapes[0][0], shapes[0][3]
        layout = [*shapes, *(shape[1:] for shape in shapes[1:]), (groups * lanes,), (lanes,)]
        arrays = carved(layout)
        flat = [a.reshape(-1) for a in arrays]
        n = len(shapes)
        _BUFFERS[key] = Buffers(
            tuple(arrays[:n]), tuple(arrays[n : 2 * n - 1]), tuple(flat[:n]),
            tuple(flat[n : 2 * n - 1]), flat[-2], flat[-1],
        )  # fmt: skip
    return _BUFFERS[key]


# (which share, its size) -> every tile's share, rows for the largest batch so far
_SHARES: dict[tuple[int, int], np.ndarray] = {}


def _shares(share: int, tiles: int, size: int) -> np.ndarray:
    """(tiles, ``size``) for every tile's share of some gradients (the kernels write it whole),
    kept from step to step: a fresh one faults in ~2 MB of pages every step at the paper's
    sizes."""
    if len(_SHARES.get((share, size), ())) < tiles:
        _SHARES[share, size] = np.empty((tiles, size), np.float32)
    return _SHARES[share, size][:tiles]


def _ceil(n: int, multiple: int) -> int:
    return -(-n // multiple) * multiple


def _dots_order(outs: int, ins: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Where a group's weight gradient (``outs`` padded output channels, ``ins`` input channels,
    ``k`` taps) and bias gradient lie in its share: in the order ``_conv_backward``'s
    ``tap_dots`` calls write them, each call's products row by row, then, in a row block's
    first call, its bias's."""
    weight, bias = np.zeros((outs, ins, k), np.int64), np.zeros(outs, np.int64)
    at = 0
    for e in range(0, outs, ROWS):
        for i in range(ins):
            for j in range(0, k, DOT_TAPS):
                taps = min(DOT_TAPS, k - j)
                weight[e : e + ROWS, i, j : j + taps] = at + np.arange(ROWS * taps).reshape(
                    ROWS, taps
                )
                at += ROWS * taps
                if i == 0 and j == 0:
                    bias[e : e + ROWS] = at + np.arange(ROWS)
                    at += ROWS
    return weight, bias


class _Plan:
    """The arguments of ``_tiles`` for one set of shapes: the geometry and offset tables of every
    layer's taps, built once (``_plan``), and the padded weights, refilled each step (``load``,
    compiled). What runs between two steps' kernels runs from cold caches (the tiles fill L2),
    ~20-50 us a numpy or torch call, so as little as can runs there: the shares are summed in the
    kernels (``_tiles`` the first thread's, as it goes; ``_finish`` the rest, the gradients laid
    out as the parameters), the labels' signs and the rows' check are the kernels', and
    ``_tiles``' arguments are the plan's and the buffers'."""

    def __init__(
        self,
        channels: int,
        steps: int,
        shapes: Sequence[tuple[int, int, int]],
        groups: int,
        strides: Sequence[int],
    ) -> None:
        lanes = TILE_LANES
        kernels = [shape[2] for shape in shapes]
        self.pad = pad = max(kernels)  # >= every layer's padding on either side
        lengths, c_in, self.geo = [steps], channels // groups, np.zeros((3, 8), np.int64)
        ins, outs = [], []
        for layer, (shape, stride) in enumerate(zip(shapes, strides, strict=True)):
            k = shape[2]
            lengths.append(conv_out_len(lengths[-1], k, stride))
            ins.append(c_in if layer == 0 else outs[-1])
            outs.append(_ceil(shape[0] // groups, ROWS))
            real = shape[0] // groups  # output channels, unpadded
            self.geo[layer] = (k, stride, k // 2, ins[-1], outs[-1], *lengths[-2:], real * k)
        rows = [t + 2 * pad for t in lengths]
        self.shapes = [(groups, c, t, lanes) for c, t in zip([c_in, *outs], rows, strict=True)]
        self.ws, self.bs, self.ftaps, self.btaps, self.bcount, self.bwts = [], [], [], [], [], []
        self.reach: list[tuple[np.ndarray, np.ndarray]] = []  # per phase: each tap's o, j
        for layer, (shape, stride) in enumerate(zip(shapes, strides, strict=True)):
            k, cout = shape[2], shape[0] // groups
            self.ws.append(np.zeros((groups, outs[layer], ins[layer], k), np.float32))
            self.bs.append(np.zeros((groups, outs[layer]), np.float32))
            taps = [(i * rows[layer] + j) * lanes for i in range(ins[layer]) for j in range(k)]
            self.ftaps.append(np.array(taps, np.int64))
            # The input gradient at step u * stride + phase: the output rows t = u + delta that
            # read it, in the order grouped_conv_numba sums them (tap j, then channel o).
            taps = np.zeros((stride, cout * k), np.int64)
            count = np.zeros(stride, np.int64)
            reach = np.zeros((2, stride, cout * k), np.int64)
            for phase in range(stride):
                pairs = [(o, j) for j in range(k) if (phase + k // 2 - j) % stride == 0
                         for o in range(cout)]  # fmt: skip
                for q, (o, j) in enumerate(pairs):
                    taps[phase, q] = (o * rows[layer + 1] + (phase + k // 2 - j) // stride) * lanes
                    reach[:, phase, q] = o, j
                count[phase] = len(pairs)
            self.reach.append((reach[0], reach[1]))
            self.btaps.append(taps)
            self.bcount.append(count)
            self.bwts.append(np.zeros((groups, stride, ins[layer], cout * k), np.float32))
        self.hw = np.zeros((groups, outs[2], lengths[3]), np.float32)
        self.jtaps = np.arange(pad, dtype=np.int64) * lanes
        # the head's taps: (channel, step) of the last activation, from its first real step
        self.htaps = np.array([(e * rows[3] + t) * lanes for e in range(outs[2])
                               for t in range(lengths[3])], np.int64)  # fmt: skip
        # The tiles' gradient shares summed, in one block ``totals`` (``sums``: each share's
        # part: each layer's weights' and biases' gradients, padded, a group's in
        # ``_dots_order``; the head's weight's); ``take``: where each parameter's entries lie in
        # it, the parameters in order; ``cuts``: each gradient's slice of a step's output and
        # its shape (the head bias's last).
        orders = [_dots_order(*w.shape[1:]) for w in self.ws]
        self.share_sizes = [groups * (w.size + b.size) for w, b in orders] + [self.hw.size]
        ats = list(itertools.pairwise(np.cumsum([0, *self.share_sizes])))
        self.totals = np.zeros(ats[-1][1], np.float32)
        self.sums = tuple(self.totals[a:b] for a, b in ats)
        kept = []
        for layer, (shape, (weight, bias)) in enumerate(zip(shapes, orders, strict=True)):
            cout, cin = shape[0] // groups, shape[1]
            base = ats[layer][0] + (weight.size + bias.size) * np.arange(groups)  # each group's
            kept += [base[:, None, None, None] + weight[None, :cout, :cin],
                     base[:, None] + bias[None, :cout]]  # fmt: skip
        kept.append(np.arange(*ats[3]).reshape(self.hw.shape)[:, : shapes[2][0] // groups])
        self.take = np.concatenate([spot.ravel() for spot in kept])
        given = [*(s for shape in shapes for s in (shape, shape[:1])), (1, kept[-1].size), (1,)]
        ends = np.cumsum([int(np.prod(shape)) for shape in given])
        self.cuts = [(end - int(np.prod(shape)), end, shape)
                     for end, shape in zip(ends, given, strict=True)]  # fmt: skip
        # ``_tiles``' arguments from the plan, flat (the weights refilled in place by ``load``)
        self.args = (self.geo, tuple(a.reshape(-1) for a in self.ws),
                     tuple(a.reshape(-1) for a in self.bs), self.hw.reshape(-1))  # fmt: skip
        self.taps = (tuple(self.ftaps), tuple(self.btaps), tuple(self.bcount),
                     tuple(a.reshape(-1) for a in self.bwts), self.jtaps, self.htaps)  # fmt: skip

    def load(
        self, weights: Sequence[np.ndarray], biases: Sequence[np.ndarray], head: np.ndarray
    ) -> None:
        """Copy the step's weights into the padded ones (their padding stays zero)."""
        for layer, (w, b) in enumerate(zip(weights, biases, strict=True)):
            _load_layer(w, b, self.ws[layer], self.bs[layer], self.bwts[layer],
                        *self.reach[layer], self.bcount[layer])  # fmt: skip
        groups, c3 = self.hw.shape[0], weights[2].shape[0] // self.hw.shape[0]
        self.hw[:, :c3] = head.reshape(groups, c3, self.hw.shape[2])


@numba.njit(**_JIT)
def _load_layer(w, b, ws, bs, bwts, reach_o, reach_j, count):  # pragma: no cover (compiled)
    """A layer's weight (C_out, c_in, k) and bias into its padded weights ``ws`` (groups,
    c_out', c_in', k) and biases ``bs``, and into the input gradient's ``bwts`` (groups, stride,
    c_in', taps): tap ``q`` of ``phase`` applies output channel ``reach_o[phase, q]``'s tap
    ``reach_j[phase, q]``. Padding entries are left as they are (zero)."""
    groups, (_, cin, k) = ws.shape[0], w.shape
    cout = w.shape[0] // groups
    for g in range(groups):
        for o in range(cout):
            bs[g, o] = b[g * cout + o]
            for i in range(cin):
                for j in range(k):
                    ws[g, o, i, j] = w[g * cout + o, i, j]
        for phase in range(bwts.shape[1]):
            for q in range(count[phase]):
                row = w[g * cout + reach_o[phase, q]]
                for i in range(cin):
                    bwts[g, phase, i, q] = row[i, reach_j[phase, q]]


# (channels, steps, weight shapes, groups, strides) -> its plan
_PLANS: dict[tuple, _Plan] = {}


def _plan(
    channels: int,
    steps: int,
    weights: Sequence[np.ndarray],
    biases: Sequence[np.ndarray],
    head: np.ndarray,
    groups: int,
    strides: Sequence[int],
) -> _Plan:
    """The plan for these shapes, built on first use, loaded with these weights."""
    shapes = tuple(w.shape for w in weights)
    key = (channels, steps, shapes, groups, tuple(strides))
    if key not in _PLANS:
        _PLANS[key] = _Plan(channels, steps, shapes, groups, strides)
    _PLANS[key].load(weights, biases, head)
    return _PLANS[key]


@numba.njit(nogil=True, cache=True)
def _finish(shares, start, stop, sums, totals, take, ghb, losses, out):  # pragma: no cover
    """The shares of tiles ``start`` to ``stop`` added to the sums (``_add_shares``), the sums'
    entries ``take`` into ``out`` with the head bias's gradient (numpy's sum of the tiles')
    last; returns the summed loss (numpy's float64 sum of the tiles')."""
    _add_shares(shares, start, stop, sums, False)
    for q in range(len(take)):
        out[q] = totals[take[q]]
    out[len(take)] = pairwise_sum(ghb, np.float32(0.0))
    return pairwise_sum(losses, np.float64(0.0))


_ZEROS = np.zeros(ROWS, np.float32)  # the biases of passes that have none


def train_step(
    X: np.ndarray,
    rows: np.ndarray,
    y: np.ndarray,
    weights: Sequence[np.ndarray],
    biases: Sequence[np.ndarray],
    head_weight: np.ndarray,
    head_bias: float,
    *,
    groups: int,
    strides: Sequence[int],
    loss: str,
) -> tuple[float, list[np.ndarray]]:
    """The mean ``loss`` of the rows ``rows`` of ``X`` (n, C, T) with 0/1 labels ``y`` (float32,
    one per row of ``X``) and its gradients: (w1, b1, w2, b2, w3, b3, head weight, head bias),
    shaped as the parameters. Every tile's gradient shares are summed in tile order: the first
    thread's tiles as soon as it has run them, while the others run theirs."""
    if loss not in LOSSES:
        raise ValueError(f"the tiled ConvNet step computes {', '.join(LOSSES)}, not {loss!r}")
    ensure_compiled(__name__)  # before the first kernel call (``_plan``'s)
    plan = _plan(X.shape[1], X.shape[2], weights, biases, head_weight, groups, strides)
    tiles = -(-len(rows) // TILE_LANES)
    shares = tuple(_shares(k, tiles, size) for k, size in enumerate(plan.share_sizes))
    ghb, losses = np.empty(tiles, np.float32), np.empty(tiles, np.float32)
    summed = []  # the tiles the first thread summed

    def task(slot: int, start: int, stop: int) -> None:
        mine = _buffers(slot, plan.shapes, plan.pad)
        _tiles(X, rows, y, groups, plan.pad, *plan.args, np.float32(head_bias), *plan.taps,
               mine.acts, mine.flat_acts, mine.flat_grads, loss == "hinge", ghb, losses,
               mine.partial, mine.gs, _ZEROS, shares, plan.sums, start, stop)  # fmt: skip
        if start == 0:
            summed.append(stop)

    _in_parallel(task, tiles)
    out = np.empty(len(plan.take) + 1, np.float32)
    total = _finish(shares, summed[0], tiles, plan.sums, plan.totals, plan.take, ghb, losses, out)
    return total / len(rows), [out[a:b].reshape(shape) for a, b, shape in plan.cuts]


def tiled_step(
    X: torch.Tensor,
    rows: torch.Tensor,
    y: torch.Tensor,
    weights: Sequence[torch.Tensor],
    biases: Sequence[torch.Tensor],
    head: torch.nn.Linear,
    *,
    loss: str,
    groups: int,
    strides: Sequence[int],
) -> torch.Tensor:
    """``losses.LOSSES[loss](head(grouped_conv_stack(X[rows])).squeeze(1), y[rows])`` for float32
    CPU ``X`` (n, C, T) and 0/1 labels ``y`` (n,), to float rounding, returned detached, its
    gradients added to the parameters' ``.grad`` (``train.add_gradients``; ``X`` gets none): one
    compiled pass per step (the rows read in place, each checked to lie in ``X``), with no
    autograd graph around it: an autograd function's apply and backward, cold after the kernels,
    cost ~0.5 ms of a ~6.5 ms two-thread step."""
    value, grads = train_step(
        X.detach().contiguous().numpy(),
        rows.to(torch.int64).contiguous().numpy(),
        y.to(torch.float32).contiguous().numpy(),
        [w.detach().numpy() for w in weights],
        [b.detach().numpy() for b in biases],
        head.weight.detach().numpy(),
        float(head.bias.detach()),
        groups=groups,
        strides=strides,
        loss=loss,
    )
    params = [*(p for pair in zip(weights, biases, strict=True) for p in pair), *head.parameters()]
    add_gradients(params, [torch.from_numpy(g) for g in grads])
    return torch.tensor(value, dtype=torch.float32)


def warm_up() -> None:
    """Compile the step (into numba's cache) on a toy batch with the types a job's calls have,
    both losses."""
    torch.manual_seed(0)
    groups, x = 2, torch.randn(3, 4, 40)
    weights = [torch.randn(4 * groups, c_in, 5, requires_grad=True) for c_in in (2, 4, 4)]
    biases = [torch.zeros(4 * groups, requires_grad=True) for _ in weights]
    head = torch.nn.Linear(4 * groups * 5, 1)
    for loss in LOSSES:
        tiled_step(x, torch.arange(3), torch.tensor([0.0, 1.0, 1.0]), weights, biases, head,
                   loss=loss, groups=groups, strides=(2, 2, 2))  # fmt: skip
