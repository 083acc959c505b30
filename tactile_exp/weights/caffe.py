"""Read a Caffe ``.caffemodel`` without Caffe or protobuf, and convert GoogLeNet to the trunk.

A ``.caffemodel`` is a binary protobuf ``NetParameter`` (caffe.proto). Only what the weights need
is decoded; every other field is skipped by its wire type:

- ``NetParameter``: ``layer`` = 100 (``LayerParameter``), legacy ``layers`` = 2
  (``V1LayerParameter``).
- ``LayerParameter``: name = 1, type = 2 (string), blobs = 7.
- ``V1LayerParameter``: name = 4, type = 5 (enum: CONVOLUTION = 4), blobs = 6; field 1 holds a
  V0 layer (pre-2014 files), which is refused with a hint to upgrade the file.
- ``BlobProto``: shape = 7 (``BlobShape``: dim = 1, packed int64), legacy num/channels/height/
  width = 1-4, data = 5 (packed float), double_data = 8 (packed double); unpacked repeated
  values are accepted too, as protobuf parsers must.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from tactile_exp.preprocess.trunk import CaffeGoogLeNet, caffe_layer_map

VARINT, FIXED64, BYTES, FIXED32 = 0, 1, 2, 5
V1_CONVOLUTION = 4


class CaffeModelError(ValueError):
    """A file that is not a readable caffemodel, or not one the trunk can hold."""


@dataclass
class Blob:
    shape: tuple[int, ...]
    data: np.ndarray  # float32, flat
    legacy_shape: bool  # from num/channels/height/width rather than ``shape``


@dataclass
class Layer:
    name: str
    type: str  # the type string, or the V1 enum value as text
    blobs: list[Blob]


class _Reader:
    """Fields of one protobuf message in ``buf[start:end]``; errors carry the file offset."""

    def __init__(self, buf: memoryview, start: int, end: int, what: str) -> None:
        self.buf, self.pos, self.end, self.what = buf, start, end, what

    def error(self, message: str) -> CaffeModelError:
        return CaffeModelError(f"{message} at byte {self.pos} (in {self.what})")

    def varint(self) -> int:
        value, shift = 0, 0
        while True:
            if self.pos >= self.end:
                raise self.error("truncated varint")
            byte = self.buf[self.pos]
            self.pos += 1
            value |= (byte & 0x7F) << shift
            if byte < 0x80:
                return value
            shift += 7
            if shift >= 70:
                raise self.error("varint longer than 10 bytes")

    def take(self, n: int) -> int:
        """Skip ``n`` bytes; returns where they start."""
        if n > self.end - self.pos:
            raise self.error(f"truncated: a field needs {n} bytes, {self.end - self.pos} remain")
        start = self.pos
        self.pos += n
        return start

    def fields(self) -> Iterator[tuple[int, int]]:
        """(field number, wire type) of each field; the caller reads or ``skip``s its value."""
        while self.pos < self.end:
            key = self.varint()
            number, wire = key >> 3, key & 7
            if number == 0 or wire not in (VARINT, FIXED64, BYTES, FIXED32):
                raise self.error(f"invalid protobuf field key {key} (field {number}, wire {wire})")
            yield number, wire

    def skip(self, wire: int) -> None:
        if wire == VARINT:
            self.varint()
        else:
            self.take({FIXED64: 8, FIXED32: 4}.get(wire) or self.varint())

    def sub(self, what: str) -> _Reader:
        """The length-delimited value at the cursor as a message reader."""
        n = self.varint()
        start = self.take(n)
        return _Reader(self.buf, start, start + n, what)

    def text(self) -> str:
        n = self.varint()
        start = self.take(n)
        try:
            return bytes(self.buf[start : start + n]).decode("utf-8")
        except UnicodeDecodeError:
            raise self.error("a string field is not UTF-8") from None

    def expect(self, wire: int, allowed: tuple[int, ...], field: str) -> None:
        if wire not in allowed:
            raise self.error(f"field {field} has wire type {wire}, expected one of {allowed}")


def _numbers(r: _Reader, wire: int, dtype: str, field: str) -> np.ndarray:
    """One occurrence of a repeated float/double field: packed (one run) or a run of unpacked
    values with the same key (read together, so millions of unpacked floats stay fast)."""
    size = np.dtype(dtype).itemsize
    if wire == BYTES:
        n = r.varint()
        if n % size:
            raise r.error(f"packed {field} of {n} bytes is not a whole number of {dtype}s")
        return np.frombuffer(r.buf, dtype, n // size, r.take(n)).astype(np.float32)
    r.expect(wire, (FIXED32,) if size == 4 else (FIXED64,), field)
    key = r.buf[r.pos - 1]  # the one-byte key just read (field numbers 5 and 8)
    start = r.pos
    step = 1 + size
    avail = (r.end - start + 1) // step  # whole (key, value) records left in the message
    run = np.frombuffer(r.buf, np.uint8, avail * step, start - 1)[::step] == key
    count = max(1, len(run) if run.all() else int(np.argmin(run)))
    r.take(count * step - 1)
    raw = np.frombuffer(r.buf, np.uint8, count * step, start - 1).reshape(count, step)[:, 1:]
    return raw.copy().view(dtype).ravel().astype(np.float32)


def _blob(r: _Reader) -> Blob:
    dims: list[int] = []
    legacy = [0, 0, 0, 0]
    has_shape = False
    chunks: list[np.ndarray] = []
    doubles: list[np.ndarray] = []
    for number, wire in r.fields():
        if number == 7:
            r.expect(wire, (BYTES,), "BlobProto.shape")
            has_shape = True
            shape = r.sub(f"{r.what} shape")
            for dim_number, dim_wire in shape.fields():
                if dim_number != 1:
                    shape.skip(dim_wire)
                elif dim_wire == BYTES:
                    packed = shape.sub("BlobShape.dim")
                    while packed.pos < packed.end:
                        dims.append(packed.varint())
                else:
                    shape.expect(dim_wire, (VARINT,), "BlobShape.dim")
                    dims.append(shape.varint())
        elif number in (1, 2, 3, 4):
            r.expect(wire, (VARINT,), "BlobProto.num/channels/height/width")
            legacy[number - 1] = r.varint()
        elif number == 5:
            chunks.append(_numbers(r, wire, "<f4", "BlobProto.data"))
        elif number == 8:
            doubles.append(_numbers(r, wire, "<f8", "BlobProto.double_data"))
        else:
            r.skip(wire)
    data = np.concatenate(chunks or doubles or [np.zeros(0, np.float32)])
    shape_tuple = tuple(dims) if has_shape else tuple(legacy)
    expected = int(np.prod(shape_tuple, dtype=np.int64)) if shape_tuple else 0
    if len(data) != expected:
        raise r.error(f"blob holds {len(data)} values but its shape {shape_tuple} needs {expected}")
    return Blob(shape_tuple, data, legacy_shape=not has_shape)


def _layer(r: _Reader, v1: bool) -> Layer:
    name_field, type_field, blobs_field = (4, 5, 6) if v1 else (1, 2, 7)
    name, kind, blobs = "", "", []
    for number, wire in r.fields():
        if number == name_field:
            r.expect(wire, (BYTES,), "layer name")
            name = r.text()
            r.what = f"layer {name!r}"
        elif number == type_field:
            r.expect(wire, (VARINT,) if v1 else (BYTES,), "layer type")
            kind = str(r.varint()) if v1 else r.text()
        elif number == blobs_field:
            r.expect(wire, (BYTES,), "layer blobs")
            blobs.append(_blob(r.sub(f"{r.what} blob {len(blobs)}")))
        elif v1 and number == 1:
            raise r.error(
                "a V0 layer (Caffe before 2014): upgrade the file with Caffe's "
                "upgrade_net_proto_binary first"
            )
        else:
            r.skip(wire)
    return Layer(name, kind, blobs)


def read_caffemodel(path: str | Path) -> list[Layer]:
    """Every layer of a ``.caffemodel`` (current ``layer`` or legacy V1 ``layers``), in order."""
    path = Path(path)
    try:
        buf = memoryview(path.read_bytes())
    except OSError as err:
        raise CaffeModelError(f"{path}: cannot read: {err.strerror or err}") from None
    if not len(buf):
        raise CaffeModelError(f"{path}: empty file, not a caffemodel")
    r = _Reader(buf, 0, len(buf), "NetParameter")
    layers: list[Layer] = []
    try:
        for number, wire in r.fields():
            if number in (100, 2):
                r.expect(wire, (BYTES,), "NetParameter.layer")
                layers.append(_layer(r.sub(f"layer {len(layers)}"), v1=number == 2))
            else:
                r.skip(wire)
    except CaffeModelError as err:
        hint = ""
        if bytes(buf[:64]).isascii() and not layers:
            hint = " (it looks like text: a .prototxt? give the binary .caffemodel)"
        raise CaffeModelError(f"{path}: not a readable caffemodel: {err}{hint}") from None
    if not layers:
        raise CaffeModelError(f"{path}: not a caffemodel: no layers (NetParameter fields 100 or 2)")
    return layers


def convert_googlenet(
    layers: list[Layer], source: str | Path = "caffemodel"
) -> tuple[dict[str, torch.Tensor], list[str], list[str]]:
    """The ``CaffeGoogLeNet`` state_dict held by ``layers`` (bvlc_googlenet / MINC names), with
    a line per mapped layer and the names of the ignored layers that hold weights.

    Raises ``CaffeModelError`` on a missing or duplicated layer, a layer that is not a
    convolution, a blob count other than 2 (weight, bias) or a blob shape that does not fit.
    """
    by_name: dict[str, Layer] = {}
    for layer in layers:
        if not layer.blobs:
            continue  # ReLU, pooling, LRN, concat: nothing to convert
        if layer.name in by_name:
            raise CaffeModelError(f"{source}: two layers named {layer.name!r} hold weights")
        by_name[layer.name] = layer
    own = CaffeGoogLeNet().state_dict()
    mapping = caffe_layer_map()
    missing = [name for name in mapping if name not in by_name]
    if missing:
        raise CaffeModelError(
            f"{source}: {len(missing)} GoogLeNet layer(s) with weights missing, e.g. "
            f"{missing[:4]} (a truncated file, or not a GoogLeNet up to inception_5a)"
        )
    state: dict[str, torch.Tensor] = {}
    mapped: list[str] = []
    for name, module in mapping.items():
        layer = by_name[name]
        if layer.type not in ("Convolution", str(V1_CONVOLUTION)):
            raise CaffeModelError(
                f"{source}: layer {name!r} has type {layer.type}, expected a convolution"
            )
        if len(layer.blobs) != 2:
            raise CaffeModelError(
                f"{source}: layer {name!r} holds {len(layer.blobs)} blobs, "
                "expected 2 (weight, bias)"
            )
        weight, bias = layer.blobs
        w_shape = tuple(own[f"{module}.weight"].shape)
        b_shape = tuple(own[f"{module}.bias"].shape)
        b_fits = bias.shape == b_shape or (bias.legacy_shape and bias.shape == (1, 1, 1, *b_shape))
        if weight.shape != w_shape or not b_fits:
            raise CaffeModelError(
                f"{source}: layer {name!r} has blobs of shape {weight.shape} and {bias.shape}, "
                f"expected {w_shape} and {b_shape}"
            )
        state[f"{module}.weight"] = torch.from_numpy(weight.data.reshape(w_shape).copy())
        state[f"{module}.bias"] = torch.from_numpy(bias.data.reshape(b_shape).copy())
        mapped.append(f"{name} -> {module} weight {w_shape} bias {b_shape}")
    ignored = [name for name in by_name if name not in mapping]
    return state, mapped, ignored
