"""Register tiles written with LLVM vector types: the compiled kernels' inner loops.

numba vectorises a loop over lanes, but between the loop's passes it keeps running sums in memory: a
gate's sum over 42 inputs is loaded and stored once per few inputs, and those loads and stores, not
the arithmetic, set the rate. Here the sums of ``ROWS`` rows over a block of lanes stay in vector
registers across all their inputs (taps): each input vector is loaded once for four FMAs and each
weight once per vector: the LSTM's gate sums run ~3x faster as a tile than as numba's loop
(bench/bench_roofline.py prints the tile's rate). The code is LLVM IR emitted by numba intrinsics,
so it compiles with the calling kernel and is cached with it: no compiler at install. numba's cache
checks the calling kernel's file, not this one: after editing this file, empty the cache
(``NUMBA_CACHE_DIR``). Like C, the tiles check no bounds: the kernels keep their offsets inside
their arrays (their tests check every shape against torch).

- ``tap_sums``: rows of weighted sums over taps (a convolution's output rows, an LSTM's gates),
  with the ReLU or its backward applied, or added to a running sum, in the one store; a tile's
  vectors along a row's lanes or along time (a convolution's output steps);
- ``tap_dots``: a convolution's weight gradient, rows of gradients against each tap's input rows,
  the products summed over steps in registers and over lanes at the end, and its bias's (the
  rows' own sums) in the same pass;
- ``head_backward``: a one-output layer's backward (the ConvNet's classification layer) over a
  vector of lanes, its weights' gradients' lanes summed ``WIDTH`` at a time by one shuffle tree;
- ``ordered_sum``: per-tile (or per-chunk) partial gradients summed in their order, so that a sum
  does not depend on how many threads made the parts; ``pairwise_sum``: numpy's sum of a vector
  (its order), for a kernel that sums as numpy did before it;
- ``transpose_tile``: a square block of rows transposed in registers (into a kernel's layout);
  ``transpose_rows``: whole rows, tile by tile;
- ``tanh_lanes``: tanh (or, scaled, the sigmoid) of a block of floats in place, a whole vector at
  a time (numba's loops use 256-bit vectors on AVX-512 CPUs, half the width);
- ``lanes``: an elementwise loop written as plain arithmetic on whole vectors (``Lanes``), for
  loops that read and write several arrays, which LLVM cannot prove apart: numba compiles them
  scalar or behind runtime alias checks (as lanes, the LSTM's cell update and its gates'
  gradients made its training step ~6% faster).

The vector width follows the CPU numba compiles for: 16 float32 lanes with AVX-512, 8 with
AVX2, else 4. ``tap_sums`` sums each lane in the same order at any width (the bias, then one
``fma`` per tap), so its results do not depend on the machine or the thread count.
"""

from __future__ import annotations

import numpy as np
from llvmlite import binding, ir
from numba import types
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import intrinsic

from tactile_exp.models.numba_setup import numba

ROWS = 4  # rows of a tile: four gates share each input vector
PLAIN, RELU, GATED, ADDED = 0, 1, 2, 3  # what tap_sums applies to its sums before storing them


def _features() -> set[str]:
    """The CPU features numba compiles for: the host's (none known when ``NUMBA_CPU_NAME`` names
    another CPU), with ``NUMBA_CPU_FEATURES``' +feature and -feature applied, as LLVM does."""
    host = numba.config.CPU_NAME in (None, "host")
    features = {f for f, on in binding.get_host_cpu_features().items() if on} if host else set()
    for change in (numba.config.CPU_FEATURES or "").split(","):
        if change[:1] == "+":
            features.add(change[1:])
        elif change[:1] == "-":
            features.discard(change[1:])
    return features


def _lanes(features: set[str]) -> tuple[int, int]:
    """(floats per vector, vectors per tile) for these features: a tile's running sums (ROWS x
    vectors) take half of the vector registers (32 with AVX-512, 16 with AVX2)."""
    if "avx512f" in features:
        return 16, 4
    if "avx2" in features:
        return 8, 2
    return 4, 2


WIDTH, VECTORS = _lanes(_features())
TILE = WIDTH * VECTORS  # lanes a tile covers


def _check(name: str, **arrays: types.Type) -> None:
    """The tiles read and write float32 arrays in C order (offsets count floats from the start)."""
    for arg, ty in arrays.items():
        if not (isinstance(ty, types.Array) and ty.dtype == types.float32 and ty.layout == "C"):
            raise TypingError(f"{name}: {arg} must be a C-contiguous float32 array, got {ty}")


def _data(context, builder, ty, value):
    """The float32 pointer to the first element of array ``value``."""
    return context.make_array(ty)(context, builder, value).data


_VEC = ir.VectorType(ir.FloatType(), WIDTH)  # the vector type of every tile


@intrinsic
def borrowed(typingctx, array):  # noqa: ARG001
    """``array`` with no owner: the same data, shape and strides, a null meminfo. numba counts
    a reference each time an array is bound to a new name (a helper's argument, an unpacked
    tuple, a slice), an atomic add on its meminfo, and on an array both threads read the two
    cores pass that cache line back and forth; a borrowed array's counts only test for null.
    For a kernel whose caller keeps ``array`` alive while it runs."""
    if not isinstance(array, types.Array):
        raise TypingError(f"borrowed: expects an array, got {array}")

    def codegen(context, builder, signature, args):
        source = context.make_array(signature.args[0])(context, builder, args[0])
        view = context.make_array(signature.return_type)(context, builder)
        for field in ("data", "shape", "strides", "itemsize", "nitems"):
            setattr(view, field, getattr(source, field))
        view.meminfo = cgutils.get_null_value(view.meminfo.type)
        view.parent = cgutils.get_null_value(view.parent.type)
        return view._getvalue()

    return array(array), codegen


def _fma(builder):
    """``llvm.fma`` on vectors: a * b + c with one rounding per lane."""
    signature = ir.FunctionType(_VEC, [_VEC, _VEC, _VEC])
    return cgutils.get_or_insert_function(builder.module, signature, f"llvm.fma.v{WIDTH}f32")


def _splat(builder, value):
    """A vector of ``WIDTH`` copies of the float ``value``."""
    i32, undef = ir.IntType(32), ir.Constant(_VEC, ir.Undefined)
    first = ir.Constant(ir.VectorType(i32, WIDTH), [0] * WIDTH)
    return builder.shuffle_vector(
        builder.insert_element(undef, value, ir.Constant(i32, 0)), undef, first
    )


@intrinsic
def tap_sums(typingctx, w, w_at, w_row, w_col, x, x_at, taps, count, out, out_at, out_step, bias,
             bias_at, slots, x_slot, out_slot, mode, gate):  # fmt: skip  # noqa: ARG001
    """For the ``ROWS`` rows r and the slots v < ``slots`` (each ``WIDTH`` lanes m), with
    ``o = out_at + r * out_step + v * out_slot + m``: ``out[o] = f(bias[bias_at + r]
    + sum_{q < count} w[w_at + r * w_row + q * w_col] * x[x_at + taps[q] + v * x_slot + m]``,
    indices into the flat arrays (``taps``: int64 offsets of the input rows). A slot is a vector of
    lanes: ``x_slot = out_slot = WIDTH`` runs along a row's lanes (``slots`` = lanes / ``WIDTH``);
    a row's length per slot runs along time (a convolution's output steps, ``x_slot`` its stride's
    rows). ``VECTORS`` slots go per register tile, the last ones as one narrower tile. The sum runs
    q = 0, 1, ... with one rounding per term (``fma``), whatever the vector width. ``f`` by
    ``mode`` (``PLAIN``, ``RELU``, ``GATED``, ``ADDED``): v; the ReLU, 0 where v < 0 (a NaN
    stays NaN); v where gate[o] > 0, else 0, a ReLU's backward as torch's (``gate``: the ReLU's
    output, laid out as ``out``); or gate[o] + v, a running sum (``gate`` is ``out`` itself:
    the sums added in the store, with no second pass). ``gate[o]`` is read in every mode, so
    pass ``out`` itself when not GATED (a constant mode drops the unused read). The ReLU and
    its backward are selects, one instruction or two whatever the caller's fastmath flags."""
    _check("tap_sums", w=w, x=x, out=out, bias=bias, gate=gate)
    if not (isinstance(taps, types.Array) and taps.dtype == types.int64):
        raise TypingError(f"tap_sums: taps must be an int64 array, got {taps}")
    i = types.intp
    sig = types.void(w, i, i, i, x, i, taps, i, out, i, i, bias, i, i, i, i, i, gate)

    def codegen(context, builder, signature, args):
        w_p, x_p, o_p, b_p = (
            builder.gep(_data(context, builder, signature.args[n], args[n]), [args[n + 1]])
            for n in (0, 4, 8, 11)
        )
        taps_p = _data(context, builder, signature.args[6], args[6])
        gate_p = builder.gep(_data(context, builder, signature.args[17], args[17]), [args[9]])
        w_r, w_c, q_n, o_s, v_n, x_v, o_v, mode = (args[n] for n in (2, 3, 7, 10, 13, 14, 15, 16))
        relu, gated, added = (
            builder.icmp_signed("==", mode, ir.Constant(mode.type, f)) for f in (RELU, GATED, ADDED)
        )
        fma, zero = _fma(builder), ir.Constant(_VEC, [0.0] * WIDTH)

        def const(n):
            return ir.Constant(q_n.type, n)

        def at(base, offset):  # the vector of WIDTH floats at base + offset (floats)
            return builder.bitcast(builder.gep(base, [offset]), _VEC.as_pointer())

        sums = [cgutils.alloca_once(builder, _VEC) for _ in range(ROWS * VECTORS)]

        def tile(v0, vectors):  # ROWS x vectors sums in registers over every tap, then stored
            x_at = [builder.mul(builder.add(v0, const(v)), x_v) for v in range(vectors)]
            o_at = [builder.mul(builder.add(v0, const(v)), o_v) for v in range(vectors)]
            for r in range(ROWS):
                start = _splat(builder, builder.load(builder.gep(b_p, [const(r)])))
                for v in range(vectors):
                    builder.store(start, sums[r * VECTORS + v])
            with cgutils.for_range(builder, q_n) as loop:
                q = loop.index
                row = builder.load(builder.gep(taps_p, [q]))
                xs = [
                    builder.load(at(x_p, builder.add(row, x_at[v])), align=4)
                    for v in range(vectors)
                ]
                for r in range(ROWS):
                    at_w = builder.add(builder.mul(const(r), w_r), builder.mul(q, w_c))
                    weight = _splat(builder, builder.load(builder.gep(w_p, [at_w])))
                    for v in range(vectors):
                        slot = sums[r * VECTORS + v]
                        builder.store(builder.call(fma, [weight, xs[v], builder.load(slot)]), slot)
            for r in range(ROWS):
                base = builder.mul(const(r), o_s)
                for v in range(vectors):
                    offset = builder.add(base, o_at[v])
                    value = builder.load(sums[r * VECTORS + v])
                    gate_value = builder.load(at(gate_p, offset), align=4)
                    negative = builder.fcmp_ordered("<", value, zero)  # one maxps (NaN kept)
                    value = builder.select(relu, builder.select(negative, zero, value), value)
                    shut = builder.fcmp_unordered("<=", gate_value, zero)
                    value = builder.select(gated, builder.select(shut, zero, value), value)
                    value = builder.select(added, builder.fadd(gate_value, value), value)
                    builder.store(value, at(o_p, offset), align=4)

        tiled = builder.sub(v_n, builder.srem(v_n, const(VECTORS)))
        with cgutils.for_range_slice(builder, const(0), tiled, const(VECTORS)) as (v0, _):
            tile(v0, VECTORS)
        left = builder.sub(v_n, tiled)
        for vectors in range(1, VECTORS):  # the slots past the last whole tile: a narrower tile
            with builder.if_then(builder.icmp_signed("==", left, const(vectors))):
                tile(tiled, vectors)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def transpose_tile(typingctx, src, starts, t, out, out_at, out_step):  # noqa: ARG001
    """``out[out_at + (t + j) * out_step + i] = src[starts[i] + t + j]`` for i, j < ``WIDTH``: a
    square tile of ``WIDTH`` rows of ``src`` (each starting at an index in ``starts``, int64),
    written out transposed. One vector load per row, ``WIDTH`` x log2(``WIDTH``) shuffles and one
    vector store per column, where a scalar transpose takes a load and a store per float."""
    _check("transpose_tile", src=src, out=out)
    if not (isinstance(starts, types.Array) and starts.dtype == types.int64):
        raise TypingError(f"transpose_tile: starts must be an int64 array, got {starts}")
    i = types.intp
    sig = types.void(src, starts, i, out, i, i)

    def codegen(context, builder, signature, args):
        src_v, starts_v, t0, out_v, out_at, o_s = args
        i32 = ir.IntType(32)
        src_p = _data(context, builder, signature.args[0], src_v)
        starts_p = _data(context, builder, signature.args[1], starts_v)
        tile = []
        for row in range(WIDTH):
            begin = builder.load(builder.gep(starts_p, [ir.Constant(t0.type, row)]))
            first = builder.gep(src_p, [builder.add(begin, t0)])
            tile.append(builder.load(builder.bitcast(first, _VEC.as_pointer()), align=4))
        d = WIDTH // 2
        while d:  # swap the off-diagonal d x d blocks of every 2d x 2d block
            low = [lane + WIDTH - d if lane & d else lane for lane in range(WIDTH)]
            high = [lane + WIDTH if lane & d else lane + d for lane in range(WIDTH)]
            masks = [ir.Constant(ir.VectorType(i32, WIDTH), m) for m in (low, high)]
            for row in range(WIDTH):
                if not row & d:
                    a, b = tile[row], tile[row + d]
                    tile[row] = builder.shuffle_vector(a, b, masks[0])
                    tile[row + d] = builder.shuffle_vector(a, b, masks[1])
            d //= 2
        out_p = builder.gep(_data(context, builder, signature.args[3], out_v), [out_at])
        for j in range(WIDTH):
            offset = builder.mul(builder.add(t0, ir.Constant(t0.type, j)), o_s)
            target = builder.bitcast(builder.gep(out_p, [offset]), _VEC.as_pointer())
            builder.store(tile[j], target, align=4)
        return context.get_dummy_value()

    return sig, codegen


@numba.njit(nogil=True, cache=True)  # no fastmath: the order of the sums is kept
def ordered_sum(parts):  # pragma: no cover (compiled)
    """``parts`` (count, ...) summed over the first axis in order, a new float32 array (numpy's
    ``parts.sum(axis=0)``, to the bit)."""
    rows = parts.reshape(len(parts), -1)
    total = np.empty(parts.shape[1:], np.float32)
    out = total.reshape(-1)
    out[:] = rows[0]
    for part in range(1, len(rows)):
        for e in range(len(out)):
            out[e] += rows[part, e]
    return total


@numba.njit(inline="always", nogil=True, cache=True)  # no fastmath: the order is kept
def _pairwise_block(a, start, n, zero):  # pragma: no cover (compiled)
    """The sum of ``a[start:start + n]``, ``n`` <= 128, in numpy's order, in ``zero``'s type:
    below 8 in order, else in eight running sums, then the rest in order."""
    if n < 8:
        res = zero
        for i in range(start, start + n):
            res += a[i]
        return res
    b = start
    r0, r1, r2, r3 = zero + a[b], zero + a[b + 1], zero + a[b + 2], zero + a[b + 3]
    r4, r5, r6, r7 = zero + a[b + 4], zero + a[b + 5], zero + a[b + 6], zero + a[b + 7]
    i, end = b + 8, b + n - n % 8
    while i < end:
        r0, r1, r2, r3 = r0 + a[i], r1 + a[i + 1], r2 + a[i + 2], r3 + a[i + 3]
        r4, r5, r6, r7 = r4 + a[i + 4], r5 + a[i + 5], r6 + a[i + 6], r7 + a[i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    for j in range(i, b + n):
        res += a[j]
    return res


@numba.njit(nogil=True, cache=True)  # no fastmath: the order of the sums is kept
def pairwise_sum(a, zero):  # pragma: no cover (compiled)
    """numpy's ``a.sum()`` of a 1-d float32 array to the bit, in ``zero``'s type: with
    ``np.float64(0)``, ``a.sum(dtype=np.float64)`` (to the bit up to numpy's buffer of 8,192
    values, which it sums one buffer at a time). numpy splits ``a`` in two (the first part a
    multiple of 8) until the parts have at most 128 values and adds the parts' sums: here a
    walk of that tree with a stack (numba's cache cannot load a recursive function)."""
    starts, counts = np.zeros(64, np.int64), np.zeros(64, np.int64)
    left, lefts = np.zeros(64, np.bool_), np.full(64, zero)  # a node's left sum, once known
    depth, counts[0] = 0, len(a)
    while True:
        start, n = starts[depth], counts[depth]
        if n > 128:  # a node: its left part first
            half = n // 2 - n // 2 % 8
            depth += 1
            starts[depth], counts[depth], left[depth] = start, half, False
            continue
        total = _pairwise_block(a, start, n, zero)
        while depth > 0:  # up the tree while the part summed is a right part
            depth -= 1
            if not left[depth + 1]:  # a left part: its right part next
                lefts[depth], left[depth + 1] = total, True
                half = counts[depth] // 2 - counts[depth] // 2 % 8
                starts[depth + 1], counts[depth + 1] = starts[depth] + half, counts[depth] - half
                depth += 1
                break
            total = lefts[depth] + total
        else:
            return zero + total


@numba.njit(inline="always", nogil=True, cache=True)
def transpose_rows(src, starts, steps, out, out_at, out_step):  # pragma: no cover (compiled)
    """``out[out_at + t * out_step + i] = src[starts[i] + t]`` for i < ``WIDTH``, t < ``steps``
    (``steps >= WIDTH``): ``WIDTH`` rows transposed a square tile at a time, the last tile
    overlapping the one before where ``WIDTH`` does not divide ``steps`` (its rows written
    twice, with the same values), so no step is copied one float at a time."""
    for t in range(0, steps - WIDTH, WIDTH):
        transpose_tile(src, starts, t, out, out_at, out_step)
    transpose_tile(src, starts, steps - WIDTH, out, out_at, out_step)


# Eigen's float tanh: x * P(x^2) / Q(x^2) on [-CLAMP, CLAMP] (max error ~4e-7 over the real line;
# tanh is 1 - 2e-7 at CLAMP), P's and Q's coefficients from the highest degree down.
TANH_CLAMP = 7.90531110763549805
TANH_P = (-2.76076847742355e-16, 2.00018790482477e-13, -8.60467152213735e-11,
          5.12229709037114e-08, 1.48572235717979e-05, 6.37261928875436e-04,
          4.89352455891786e-03)  # fmt: skip
TANH_Q = (1.19825839466702e-06, 1.18534705686654e-04, 2.26843463243900e-03, 4.89352518554385e-03)


def _tanh(builder, v):
    """Eigen's tanh of the vector ``v``: clamped, then v P(v^2) / Q(v^2); NaN stays NaN."""
    fma = _fma(builder)

    def const(value):
        return ir.Constant(_VEC, [value] * WIDTH)

    def poly(coefficients, x2):
        value = const(coefficients[0])
        for c in coefficients[1:]:
            value = builder.call(fma, [value, x2, const(c)])
        return value

    low, high = const(-TANH_CLAMP), const(TANH_CLAMP)
    v = builder.select(builder.fcmp_ordered("<", v, low), low, v)
    v = builder.select(builder.fcmp_ordered(">", v, high), high, v)
    x2 = builder.fmul(v, v)
    return builder.fdiv(builder.fmul(v, poly(TANH_P, x2)), poly(TANH_Q, x2))


@intrinsic
def tanh_lanes(typingctx, x, at, count, scale, shift):  # noqa: ARG001
    """``x[at + m] = scale * tanh(scale * x[at + m]) + shift`` for m < ``count`` (a multiple of
    ``WIDTH``), tanh by Eigen's rational approximation, vectorisable where libm's is not:
    scale 1, shift 0 is tanh; 1/2, 1/2 the sigmoid. NaN stays NaN."""
    _check("tanh_lanes", x=x)
    f32 = types.float32
    sig = types.void(x, types.intp, types.intp, f32, f32)

    def codegen(context, builder, signature, args):
        x_v, at_v, n, scale_v, shift_v = args
        scale, shift = _splat(builder, scale_v), _splat(builder, shift_v)
        base = builder.gep(_data(context, builder, signature.args[0], x_v), [at_v])
        zero, step = ir.Constant(n.type, 0), ir.Constant(n.type, WIDTH)
        with cgutils.for_range_slice(builder, zero, n, step) as (m, _):
            where = builder.bitcast(builder.gep(base, [m]), _VEC.as_pointer())
            t = _tanh(builder, builder.fmul(builder.load(where, align=4), scale))
            builder.store(builder.call(_fma(builder), [scale, t, shift]), where, align=4)
        return context.get_dummy_value()

    return sig, codegen


class Lanes:
    """A vector of ``WIDTH`` floats inside a ``lanes`` body: ``+``, ``-`` and ``*`` with other
    vectors or numbers, ``tanh`` and ``flush`` emit the vector instructions (each operation
    rounded once, in the order written: the same floats at any width)."""

    def __init__(self, builder, value) -> None:
        self.builder, self.value = builder, value

    def _other(self, other):
        if isinstance(other, Lanes):
            return other.value
        return ir.Constant(_VEC, [float(other)] * WIDTH)

    def __add__(self, other):
        return Lanes(self.builder, self.builder.fadd(self.value, self._other(other)))

    __radd__ = __add__

    def __sub__(self, other):
        return Lanes(self.builder, self.builder.fsub(self.value, self._other(other)))

    def __rsub__(self, other):
        return Lanes(self.builder, self.builder.fsub(self._other(other), self.value))

    def __mul__(self, other):
        return Lanes(self.builder, self.builder.fmul(self.value, self._other(other)))

    __rmul__ = __mul__

    def tanh(self):
        """``tanh_lanes``' tanh."""
        return Lanes(self.builder, _tanh(self.builder, self.value))

    def flush(self, tiny: float):
        """The value where its magnitude is at least ``tiny``, else 0 (NaN too)."""
        magnitude = self.builder.call(
            cgutils.get_or_insert_function(
                self.builder.module, ir.FunctionType(_VEC, [_VEC]), f"llvm.fabs.v{WIDTH}f32"
            ),
            [self.value],
        )
        keep = self.builder.fcmp_ordered(">=", magnitude, self._other(tiny))
        return Lanes(self.builder, self.builder.select(keep, self.value, self._other(0.0)))


def lanes(body, reads: int):
    """An intrinsic ``f(arrays, offsets, count)`` running ``body`` over lanes m < ``count`` (a
    multiple of ``WIDTH``), a vector at a time: ``arrays`` a tuple of flat float32 arrays,
    ``offsets`` one int per array; ``body`` takes the vectors ``arrays[k][offsets[k] + m]`` of
    the first ``reads`` arrays as ``Lanes`` and returns one ``Lanes`` per other array, stored at
    its offset, in order (an array named twice holds the later value)."""

    @intrinsic
    def kernel(typingctx, arrays, offsets, count):  # noqa: ARG001
        if not (
            isinstance(arrays, types.BaseTuple)
            and isinstance(offsets, types.BaseTuple)
            and len(arrays) == len(offsets) > reads
        ):
            raise TypingError(f"{body.__name__}: expects tuples of arrays and of their offsets")
        for ty in arrays:
            _check(body.__name__, array=ty)
        sig = types.void(arrays, offsets, types.intp)

        def codegen(context, builder, signature, args):
            arrays_v = cgutils.unpack_tuple(builder, args[0])
            offsets_v = [
                context.cast(builder, v, ty, types.intp)
                for v, ty in zip(
                    cgutils.unpack_tuple(builder, args[1]), signature.args[1], strict=True
                )
            ]
            bases = [
                builder.gep(_data(context, builder, ty, v), [at])
                for ty, v, at in zip(signature.args[0], arrays_v, offsets_v, strict=True)
            ]
            n = args[2]
            zero, step = ir.Constant(n.type, 0), ir.Constant(n.type, WIDTH)
            with cgutils.for_range_slice(builder, zero, n, step) as (m, _):
                where = [builder.bitcast(builder.gep(b, [m]), _VEC.as_pointer()) for b in bases]
                inputs = [Lanes(builder, builder.load(p, align=4)) for p in where[:reads]]
                outputs = body(*inputs)
                if len(outputs) != len(where) - reads:
                    raise TypingError(f"{body.__name__}: returns {len(outputs)} vectors")
                for p, value in zip(where[reads:], outputs, strict=True):
                    builder.store(value.value, p, align=4)
            return context.get_dummy_value()

        return sig, codegen

    return kernel


DOT_TAPS = 5  # taps per tap_dots call: ROWS x DOT_TAPS running sums in registers


def _hsums(builder, vectors):
    """The sums of the lanes of ``WIDTH`` vectors as one vector, lane l that of vector
    ``_bit_reversed(l)``, each in a fixed tree (halves added, the lower first, until one lane is
    left), the same whatever the other vectors: all of them at once, two vectors' halves per
    shuffle, where a tree per vector takes log2 ``WIDTH`` shuffles and adds each."""
    i32, width = ir.IntType(32), WIDTH
    while width > 1:
        width //= 2
        paired = []
        for a, b in zip(vectors[0::2], vectors[1::2], strict=True):
            lanes = range(0, WIDTH, 2 * width)  # each segment's start: a's, then b's (+ WIDTH)
            low = [k + i + side for k in lanes for side in (0, WIDTH) for i in range(width)]
            high = [index + width for index in low]
            masks = [ir.Constant(ir.VectorType(i32, WIDTH), pick) for pick in (low, high)]
            paired.append(builder.fadd(*(builder.shuffle_vector(a, b, m) for m in masks)))
        vectors = paired
    return vectors[0]


def _bit_reversed(lane: int) -> int:
    """``lane``'s bits (log2 ``WIDTH`` of them) in reverse order."""
    bits = WIDTH.bit_length() - 1
    return int(f"{lane:0{bits}b}"[::-1], 2) if bits else 0


@intrinsic
def head_backward(typingctx, w, w_at, x, x_at, y, y_at, rows, row_step, steps, out, out_at, acc,
                  acc_at):  # fmt: skip  # noqa: ARG001
    """A one-output layer's backward over one vector of lanes: for q = r * ``steps`` + s (r <
    ``rows``, s < ``steps``) and o = r * ``row_step`` + s * ``WIDTH``: ``acc[acc_at + q] =
    sum_m y[y_at + o + m] * x[x_at + m]`` (its weights' gradient: its input rows ``y``, the
    ReLU's output, against the loss gradients ``x``) and ``out[out_at + o + m] = w[w_at + q] *
    x[x_at + m]`` where ``y[y_at + o + m] > 0``, else 0 (its input's gradient through the
    ReLU), m < ``WIDTH``. The same bits as a ``tap_dots`` (one tap, one step) and a ``GATED``
    ``tap_sums`` (one slot, zero bias) per q, computed in one pass, the lanes of ``WIDTH``
    products summed by one shuffle tree (``_hsums``) rather than a tree each."""
    _check("head_backward", w=w, x=x, y=y, out=out, acc=acc)
    i = types.intp
    sig = types.void(w, i, x, i, y, i, i, i, i, out, i, acc, i)

    def codegen(context, builder, signature, args):
        w_p, x_p, y_p, out_p, acc_p = (
            builder.gep(_data(context, builder, signature.args[n], args[n]), [args[n + 1]])
            for n in (0, 2, 4, 9, 11)
        )
        rows, row_step, steps = args[6], args[7], args[8]
        fma, zero = _fma(builder), ir.Constant(_VEC, [0.0] * WIDTH)
        gs = builder.load(builder.bitcast(x_p, _VEC.as_pointer()), align=4)
        count = builder.mul(rows, steps)

        def const(n):
            return ir.Constant(rows.type, n)

        # (r, s) of the next q, carried from batch to batch: no division per q
        r_at, s_at = (cgutils.alloca_once_value(builder, const(0)) for _ in range(2))

        def batch(first, guarded):  # the q from ``first`` on: WIDTH products, summed together
            products = [zero] * WIDTH
            r, s = builder.load(r_at), builder.load(s_at)
            for j in range(WIDTH):
                q = builder.add(first, const(j))
                read_q, read_r, read_s = q, r, s
                valid = builder.icmp_signed("<", q, count) if guarded else None
                if guarded:  # past the last q: read q = 0's rows, add nothing, store nothing
                    read_q, read_r, read_s = (builder.select(valid, v, const(0)) for v in (q, r, s))
                o = builder.add(builder.mul(read_r, row_step), builder.mul(read_s, const(WIDTH)))
                ys = builder.load(builder.bitcast(builder.gep(y_p, [o]), _VEC.as_pointer()),
                                  align=4)  # fmt: skip
                product = builder.call(fma, [ys, gs, zero])
                product = builder.select(valid, product, zero) if guarded else product
                products[_bit_reversed(j)] = product  # so that lane j of the sums is q's
                weight = _splat(builder, builder.load(builder.gep(w_p, [read_q])))
                shut = builder.fcmp_unordered("<=", ys, zero)
                value = builder.select(shut, zero, builder.call(fma, [weight, gs, zero]))
                target = builder.bitcast(builder.gep(out_p, [o]), _VEC.as_pointer())
                if guarded:
                    with builder.if_then(valid):
                        builder.store(value, target, align=4)
                else:
                    builder.store(value, target, align=4)
                s = builder.add(s, const(1))
                wrapped = builder.icmp_signed("==", s, steps)
                s = builder.select(wrapped, const(0), s)
                r = builder.select(wrapped, builder.add(r, const(1)), r)
            builder.store(r, r_at)
            builder.store(s, s_at)
            sums = _hsums(builder, products)
            if not guarded:
                target = builder.bitcast(builder.gep(acc_p, [first]), _VEC.as_pointer())
                builder.store(sums, target, align=4)
                return
            for lane in range(WIDTH):
                q = builder.add(first, const(lane))
                with builder.if_then(builder.icmp_signed("<", q, count)):
                    lane_sum = builder.extract_element(sums, ir.Constant(ir.IntType(32), lane))
                    builder.store(lane_sum, builder.gep(acc_p, [q]))

        whole = builder.sub(count, builder.srem(count, const(WIDTH)))
        with cgutils.for_range_slice(builder, const(0), whole, const(WIDTH)) as (first, _):
            batch(first, False)
        with builder.if_then(builder.icmp_signed("<", whole, count)):
            batch(whole, True)
        return context.get_dummy_value()

    return sig, codegen


def _store_first(builder, value, where, n):
    """The first ``n`` lanes of the vector ``value`` stored at the float pointer ``where``, the
    floats past them untouched (one masked store)."""
    target = builder.bitcast(where, _VEC.as_pointer())
    if n == WIDTH:
        builder.store(value, target, align=4)
        return
    mask_type = ir.VectorType(ir.IntType(1), WIDTH)
    signature = ir.FunctionType(ir.VoidType(), [_VEC, _VEC.as_pointer(), ir.IntType(32), mask_type])
    store = cgutils.get_or_insert_function(
        builder.module, signature, f"llvm.masked.store.v{WIDTH}f32.p0v{WIDTH}f32"
    )
    mask = ir.Constant(mask_type, [int(lane < n) for lane in range(WIDTH)])
    builder.call(store, [value, target, ir.Constant(ir.IntType(32), 4), mask])


@intrinsic
def tap_dots(typingctx, d, d_at, d_row, d_step, x, x_at, taps, count, x_step, steps, acc,
             acc_at, own):  # fmt: skip  # noqa: ARG001
    """For the ``ROWS`` rows r and the taps q < ``count`` (at most ``DOT_TAPS``), over one
    vector of lanes m < ``WIDTH``: ``acc[acc_at + r * count + q] = sum_m sum_{s < steps}
    d[d_at + r * d_row + s * d_step + m] * x[x_at + taps[q] + s * x_step + m]``: a
    convolution's weight gradient, its output-gradient rows against the input rows of each tap;
    and where ``own`` is not 0, the rows' own sums, ``acc[acc_at + ROWS * count + r] = sum_m
    sum_s d[...]`` (its bias's gradient), in the same pass: ``ROWS`` more running sums beside
    the products' instead of a pass of its own, whose four dependent chains waited on each add.
    Each vector of lanes sums over the steps in registers (one ``fma`` per term, steps in order;
    an add for a row's own sum, which is an ``fma`` with 1), then its lanes in a fixed tree: the
    same result at any thread count. The trees of ``WIDTH`` sums run as one (``_hsums``) and
    their sums are stored as they come out of it, a vector (or its first lanes) at a time, which
    is why a call's sums lie together in ``acc``: one vector store where a scalar add per sum
    into the weights' own layout cost the ConvNet's training step ~5%."""
    _check("tap_dots", d=d, x=x, acc=acc)
    if not (isinstance(taps, types.Array) and taps.dtype == types.int64):
        raise TypingError(f"tap_dots: taps must be an int64 array, got {taps}")
    i = types.intp
    sig = types.void(d, i, i, i, x, i, taps, i, i, i, acc, i, i)

    def codegen(context, builder, signature, args):
        d_p, x_p, acc_p = (
            builder.gep(_data(context, builder, signature.args[n], args[n]), [args[n + 1]])
            for n in (0, 4, 10)
        )
        taps_p = _data(context, builder, signature.args[6], args[6])
        d_r, d_s, q_n, x_s, s_n, own = (args[n] for n in (2, 3, 7, 8, 9, 12))
        fma, zero = _fma(builder), ir.Constant(_VEC, [0.0] * WIDTH)

        def const(n):
            return ir.Constant(q_n.type, n)

        def at(base, offset):
            return builder.bitcast(builder.gep(base, [offset]), _VEC.as_pointer())

        sums = [cgutils.alloca_once(builder, _VEC) for _ in range(ROWS * (DOT_TAPS + 1))]

        def body(taps_n, summed):
            offsets = [builder.load(builder.gep(taps_p, [const(q)])) for q in range(taps_n)]
            used = [r * DOT_TAPS + q for r in range(ROWS) for q in range(taps_n)]
            mine = [ROWS * DOT_TAPS + r for r in range(ROWS)] if summed else []
            for slot in used + mine:
                builder.store(zero, sums[slot])
            with cgutils.for_range(builder, s_n) as loop:
                s = loop.index
                ds = [
                    builder.load(at(d_p, builder.add(builder.mul(const(r), d_r),
                                                     builder.mul(s, d_s))), align=4)
                    for r in range(ROWS)
                ]  # fmt: skip
                row = builder.mul(s, x_s)
                for q in range(taps_n):
                    xv = builder.load(at(x_p, builder.add(offsets[q], row)), align=4)
                    for r in range(ROWS):
                        slot = sums[r * DOT_TAPS + q]
                        builder.store(builder.call(fma, [ds[r], xv, builder.load(slot)]), slot)
                for r, slot in enumerate(mine):
                    builder.store(builder.fadd(builder.load(sums[slot]), ds[r]), sums[slot])
            targets = used + mine  # in acc's order: the products row by row, then the rows' own
            for first in range(0, len(targets), WIDTH):  # WIDTH sums per shuffle tree
                part = [builder.load(sums[slot]) for slot in targets[first : first + WIDTH]]
                vectors = [_bit_reversed(slot) for slot in range(WIDTH)]
                vectors = [part[v] if v < len(part) else zero for v in vectors]
                lane_sums = _hsums(builder, vectors)  # lane k: the sum of part[k]'s lanes
                _store_first(builder, lane_sums, builder.gep(acc_p, [const(first)]), len(part))

        summed = builder.icmp_signed("!=", own, const(0))
        for taps_n in range(1, DOT_TAPS + 1):
            chosen = builder.icmp_signed("==", q_n, const(taps_n))
            with builder.if_then(builder.and_(chosen, summed)):
                body(taps_n, True)
            with builder.if_then(builder.and_(chosen, builder.not_(summed))):
                body(taps_n, False)
        return context.get_dummy_value()

    return sig, codegen
