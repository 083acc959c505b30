"""A tiny protobuf wire-format writer for test caffemodels (caffe.proto field numbers).

Independent of the reader under test: it writes bytes by hand, and the GoogLeNet layer table
below is copied from bvlc_googlenet's deploy.prototxt, not from the trunk's code.
"""

from __future__ import annotations

import numpy as np

VARINT, FIXED64, BYTES, FIXED32 = 0, 1, 2, 5
V1_TYPES = {"Data": 5, "Convolution": 4, "InnerProduct": 14, "ReLU": 18, "Pooling": 17, "LRN": 15}

# bvlc_googlenet: block -> (input channels, #1x1, #3x3 reduce, #3x3, #5x5 reduce, #5x5, pool proj)
INCEPTION = {
    "3a": (192, 64, 96, 128, 16, 32, 32),
    "3b": (256, 128, 128, 192, 32, 96, 64),
    "4a": (480, 192, 96, 208, 16, 48, 64),
    "4b": (512, 160, 112, 224, 24, 64, 64),
    "4c": (512, 128, 128, 256, 24, 64, 64),
    "4d": (512, 112, 144, 288, 32, 64, 64),
    "4e": (528, 256, 160, 320, 32, 128, 128),
    "5a": (832, 256, 160, 320, 32, 128, 128),
    "5b": (832, 384, 192, 384, 48, 128, 128),
}


def varint(n: int) -> bytes:
    n &= (1 << 64) - 1  # negative int64 as protobuf writes it: 10 bytes
    out = bytearray()
    while True:
        byte, n = n & 0x7F, n >> 7
        out.append(byte | (0x80 if n else 0))
        if not n:
            return bytes(out)


def key(number: int, wire: int) -> bytes:
    return varint(number << 3 | wire)


def length_delimited(number: int, payload: bytes) -> bytes:
    return key(number, BYTES) + varint(len(payload)) + payload


def blob(
    array: np.ndarray,
    legacy: bool = False,
    packed: bool = True,
    double: bool = False,
    shape: tuple[int, ...] | None = None,
) -> bytes:
    """A BlobProto: ``shape`` (7) or legacy num/channels/height/width (1-4, padded to 4-d with
    leading 1s as Caffe's V1 files hold biases), then data (5, float) or double_data (8).
    ``shape`` overrides the array's, to write a blob whose data does not fill its shape."""
    shape = array.shape if shape is None else shape
    if legacy:
        dims = (1,) * (4 - len(shape)) + shape
        head = b"".join(key(i + 1, VARINT) + varint(d) for i, d in enumerate(dims))
    else:
        head = length_delimited(7, length_delimited(1, b"".join(varint(d) for d in shape)))
    number, dtype = (8, "<f8") if double else (5, "<f4")
    values = np.asarray(array, dtype).ravel()
    if packed:
        return head + length_delimited(number, values.tobytes())
    wire = FIXED64 if double else FIXED32
    return head + b"".join(key(number, wire) + v.tobytes() for v in values)


def layer(name: str, kind: str, blobs: list[bytes], v1: bool = False) -> bytes:
    """A LayerParameter (net field 100: name 1, type 2, blobs 7) or a V1LayerParameter (net
    field 2: name 4, type enum 5, blobs 6), with a bottom/top pair the reader must skip."""
    if v1:
        body = length_delimited(4, name.encode()) + key(5, VARINT) + varint(V1_TYPES[kind])
        body += length_delimited(2, b"bottom") + length_delimited(3, name.encode())
        body += b"".join(length_delimited(6, b) for b in blobs)
        return length_delimited(2, body)
    body = length_delimited(1, name.encode()) + length_delimited(2, kind.encode())
    body += length_delimited(3, b"bottom") + length_delimited(4, name.encode())
    body += b"".join(length_delimited(7, b) for b in blobs)
    return length_delimited(100, body)


def net(layers: list[bytes], name: str = "GoogleNet") -> bytes:
    """A NetParameter: its name (1), an input_dim (4) and the layers."""
    head = length_delimited(1, name.encode()) + key(4, VARINT) + varint(10)
    return head + b"".join(layers)


def googlenet_shapes(upper: bool = True) -> dict[str, tuple[tuple[int, ...], ...]]:
    """Caffe layer name -> (weight shape, bias shape) of bvlc_googlenet's convolutions up to
    inception_5a, and with ``upper`` some layers the converter must ignore (auxiliary heads,
    inception_5b, the classifier)."""
    shapes = {
        "conv1/7x7_s2": ((64, 3, 7, 7), (64,)),
        "conv2/3x3_reduce": ((64, 64, 1, 1), (64,)),
        "conv2/3x3": ((192, 64, 3, 3), (192,)),
    }
    for block, (c_in, c1, c3r, c3, c5r, c5, pp) in INCEPTION.items():
        if block == "5b" and not upper:
            continue
        p = f"inception_{block}/"
        shapes[p + "1x1"] = ((c1, c_in, 1, 1), (c1,))
        shapes[p + "3x3_reduce"] = ((c3r, c_in, 1, 1), (c3r,))
        shapes[p + "3x3"] = ((c3, c3r, 3, 3), (c3,))
        shapes[p + "5x5_reduce"] = ((c5r, c_in, 1, 1), (c5r,))
        shapes[p + "5x5"] = ((c5, c5r, 5, 5), (c5,))
        shapes[p + "pool_proj"] = ((pp, c_in, 1, 1), (pp,))
        if block == "4a" and upper:
            shapes["loss1/conv"] = ((128, 512, 1, 1), (128,))
            shapes["loss1/classifier"] = ((23, 1024), (23,))
        if block == "4d" and upper:
            shapes["loss2/conv"] = ((128, 528, 1, 1), (128,))
    if upper:
        shapes["loss3/classifier"] = ((1000, 1024), (1000,))
    return shapes


IGNORED = ("loss1/conv", "loss1/classifier", "loss2/conv", "loss3/classifier")


def googlenet_blobs(seed: int, upper: bool = True) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Random float32 blobs of ``googlenet_shapes``, scaled like trained weights (fan-in)."""
    rng = np.random.default_rng(seed)
    out = {}
    for name, (w_shape, b_shape) in googlenet_shapes(upper).items():
        fan_in = int(np.prod(w_shape[1:]))
        w = rng.standard_normal(w_shape, dtype=np.float32) * np.float32((2 / fan_in) ** 0.5)
        out[name] = (w, rng.uniform(0.0, 0.2, b_shape).astype(np.float32))
    return out


def googlenet_caffemodel(
    blobs: dict[str, tuple[np.ndarray, np.ndarray]], v1: bool = False
) -> bytes:
    """A GoogLeNet caffemodel of ``blobs`` in the current or the legacy V1 format (V1: legacy
    4-d blob shapes, as V1-era files hold them), with parameterless layers in between."""
    layers = [layer("data", "Data", [], v1)]
    for name, (w, b) in blobs.items():
        kind = "InnerProduct" if w.ndim == 2 else "Convolution"
        layers.append(layer(name, kind, [blob(w, legacy=v1), blob(b, legacy=v1)], v1))
        layers.append(layer(f"{name}_relu", "ReLU", [], v1))
        if name == "conv1/7x7_s2":
            layers.append(layer("pool1/norm1", "LRN", [], v1))
    return net(layers)
