"""Caffe weights: the caffemodel reader, the GoogLeNet converter CLI and the Caffe-layout trunk,
on caffemodels written here by hand (tests/caffemodel_fixture.py), current and legacy V1."""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys

import numpy as np
import pytest
import torch
from caffemodel_fixture import (
    IGNORED,
    blob,
    googlenet_blobs,
    googlenet_caffemodel,
    googlenet_shapes,
    layer,
    net,
)

from tactile_exp.preprocess.trunk import (
    CAFFE_MEAN_BGR,
    CaffeGoogLeNet,
    GoogLeNet,
    build_trunk,
    network_input,
    read_state_dict,
    save_weights,
    xavier_init,
)
from tactile_exp.weights.__main__ import main
from tactile_exp.weights.caffe import CaffeModelError, read_caffemodel

FORMATS = ("current", "v1")


@pytest.fixture(scope="module")
def blobs() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """bvlc_googlenet's convolutions up to 5a plus ignored layers: about 7M random floats."""
    return googlenet_blobs(seed=0)


@pytest.fixture(scope="module")
def converted(blobs, tmp_path_factory) -> dict[str, dict]:
    """Each format written and converted by the CLI: exit status, stdout, stderr, weights file."""
    out = {}
    for fmt in FORMATS:
        folder = tmp_path_factory.mktemp(fmt)
        model = folder / "googlenet.caffemodel"
        model.write_bytes(googlenet_caffemodel(blobs, v1=fmt == "v1"))
        weights = folder / "googlenet_caffe.pth"
        stdout, stderr = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            status = main(["convert-caffe", str(model), str(weights)])
        out[fmt] = {"status": status, "out": stdout.getvalue(), "err": stderr.getvalue()}
        out[fmt]["weights"] = weights
    return out


def _convert(capsys, args: list[str]) -> tuple[int, str, str]:
    status = main(["convert-caffe", *args])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def test_small_caffemodels_read_back_exactly(tmp_path):
    rng = np.random.default_rng(1)
    w = rng.standard_normal((4, 3, 2, 2)).astype(np.float32)
    b = rng.standard_normal(4).astype(np.float32)
    fc = rng.standard_normal((5, 16))
    cases = {
        "current": net([layer("conv", "Convolution", [blob(w), blob(b, packed=False)]),
                        layer("relu", "ReLU", []),
                        layer("fc", "InnerProduct", [blob(fc, double=True)])]),
        "v1": net([layer("conv", "Convolution", [blob(w, legacy=True, packed=False),
                                                 blob(b, legacy=True)], v1=True),
                   layer("relu", "ReLU", [], v1=True),
                   layer("fc", "InnerProduct", [blob(fc, legacy=True, double=True)], v1=True)]),
    }  # fmt: skip
    for fmt, data in cases.items():
        path = tmp_path / f"{fmt}.caffemodel"
        path.write_bytes(data)
        layers = read_caffemodel(path)
        assert [x.name for x in layers] == ["conv", "relu", "fc"]
        assert [x.type for x in layers] == (
            ["4", "18", "14"] if fmt == "v1" else ["Convolution", "ReLU", "InnerProduct"]
        )
        conv_w, conv_b = layers[0].blobs
        assert conv_w.shape == (4, 3, 2, 2) and layers[1].blobs == []
        assert conv_b.shape == ((1, 1, 1, 4) if fmt == "v1" else (4,))
        np.testing.assert_array_equal(conv_w.data, w.ravel())
        np.testing.assert_array_equal(conv_b.data, b.ravel())
        (fc_blob,) = layers[2].blobs
        assert fc_blob.data.dtype == np.float32
        np.testing.assert_array_equal(fc_blob.data, fc.astype(np.float32).ravel())


@pytest.mark.parametrize("fmt", FORMATS)
def test_full_googlenet_converts_every_blob(fmt, converted, blobs):
    case = converted[fmt]
    out = case["out"]
    assert case["status"] == 0, case["err"]
    trunk_layers = googlenet_shapes(upper=False)
    assert "51 mapped onto the Caffe-layout trunk" in out
    for name in trunk_layers:
        assert f"  {name} -> " in out
    ignored_line = out.split("ignored ")[1].splitlines()[1]
    expected_ignored = [n for n in blobs if n not in trunk_layers]
    assert ignored_line.strip().split(", ") == expected_ignored
    assert set(IGNORED) <= set(expected_ignored) and "inception_5b/5x5" in expected_ignored
    state, layout = read_state_dict(case["weights"])
    assert layout == "caffe" and len(state) == 2 * len(trunk_layers) == 102
    assert set(state) == set(CaffeGoogLeNet().state_dict())
    for name, (w, b) in blobs.items():
        if name not in trunk_layers:
            continue
        module = name.replace("/", ".").replace("conv1.7x7_s2", "conv1")
        module = module.replace("conv2.3x3_reduce", "conv2_reduce").replace("conv2.3x3", "conv2")
        for suffix in ("1x1", "3x3_reduce", "3x3", "5x5_reduce", "5x5"):
            module = module.replace(f".{suffix}", f".b{suffix}")
        assert torch.equal(state[f"{module}.weight"], torch.from_numpy(w)), name
        assert torch.equal(state[f"{module}.bias"], torch.from_numpy(b)), name


def test_converted_file_runs_the_caffe_trunk(converted):
    case = converted["current"]
    trunk = build_trunk(case["weights"], layout="caffe")
    rgb = np.random.default_rng(2).integers(0, 256, (2, 3, 224, 224), dtype=np.uint8)
    rgb[1] = np.linspace(0, 255, 224).astype(np.uint8)  # a smooth ramp beside the noise
    x = torch.from_numpy(network_input(rgb, CAFFE_MEAN_BGR[::-1], "caffe"))
    with torch.inference_mode():
        assert trunk.inception5a_map(x).shape == (2, 832, 7, 7)
        features = trunk.features(x)
    assert features.shape == (2, 832)
    np.testing.assert_allclose(features.norm(dim=1).numpy(), 1.0, rtol=1e-5)
    assert (features[0] - features[1]).norm() > 0.05  # different images, different features
    with pytest.raises(ValueError, match="holds caffe-layout .* modality.layout=caffe"):
        build_trunk(case["weights"], layout="torchvision")


def test_torchvision_weights_do_not_load_into_the_caffe_layout(tmp_path):
    plain = tmp_path / "torchvision.pth"
    torch.save(GoogLeNet().state_dict(), plain)
    with pytest.raises(ValueError, match="torchvision.pth: not a caffe-layout GoogLeNet"):
        build_trunk(plain, layout="caffe")
    recorded = tmp_path / "recorded.pth"
    save_weights(recorded, GoogLeNet().state_dict(), layout="torchvision")
    with pytest.raises(ValueError, match="holds torchvision-layout .* modality.layout=torchv"):
        build_trunk(recorded, layout="caffe")
    assert isinstance(build_trunk(recorded, layout="torchvision"), GoogLeNet)


# --- Caffe's layer semantics, written out in numpy from caffe's layer sources -------------------


def _conv(x: np.ndarray, w: np.ndarray, b: np.ndarray, stride: int = 1, pad: int = 0):
    c, h, wd = x.shape
    k = w.shape[2]
    xp = np.pad(x, ((0, 0), (pad, pad), (pad, pad)))
    oh, ow = (h + 2 * pad - k) // stride + 1, (wd + 2 * pad - k) // stride + 1
    out = np.zeros((w.shape[0], oh, ow)) + b[:, None, None]
    for dy in range(k):
        for dx in range(k):
            patch = xp[
                :,
                dy : dy + stride * (oh - 1) + 1 : stride,
                dx : dx + stride * (ow - 1) + 1 : stride,
            ]
            out += np.einsum("oc,chw->ohw", w[:, :, dy, dx], patch)
    return out


def _relu_conv(x, state, module, stride=1, pad=0):
    w, b = (state[f"{module}.{p}"].double().numpy() for p in ("weight", "bias"))
    return np.maximum(_conv(x, w, b, stride, pad), 0)


def _max_pool(x: np.ndarray, k: int, stride: int, pad: int = 0) -> np.ndarray:
    """Caffe's PoolingLayer (MAX): ceil-rounded output size, the last window starting inside."""
    c, h, w = x.shape

    def size(n: int) -> int:
        pooled = int(np.ceil((n + 2 * pad - k) / stride)) + 1
        return pooled - 1 if pad and (pooled - 1) * stride >= n + pad else pooled

    out = np.empty((c, size(h), size(w)))
    for i in range(out.shape[1]):
        for j in range(out.shape[2]):
            y0, x0 = i * stride - pad, j * stride - pad
            y1, x1 = min(y0 + k, h), min(x0 + k, w)
            out[:, i, j] = x[:, max(y0, 0) : y1, max(x0, 0) : x1].max(axis=(1, 2))
    return out


def _lrn(x: np.ndarray, size: int = 5, alpha: float = 1e-4, beta: float = 0.75) -> np.ndarray:
    """Caffe's LRNLayer, ACROSS_CHANNELS: x / (1 + alpha / size * sum of squares)^beta."""
    sq = np.pad(x**2, ((size // 2, size // 2), (0, 0), (0, 0)))
    window = sum(sq[i : i + len(x)] for i in range(size))
    return x / (1 + alpha / size * window) ** beta


def test_caffe_trunk_matches_caffe_layer_semantics():
    """stem and inception (3a) of a randomly weighted trunk against the numpy reference on a
    43x43 input, where ceil-mode pooling changes the sizes (floor would give 10, not 11)."""
    model = xavier_init(CaffeGoogLeNet(), seed=5).eval()
    with torch.no_grad():
        for name, p in model.named_parameters():
            if name.endswith("bias"):
                p.uniform_(-0.1, 0.3)  # non-zero biases, as trained weights have
    state = model.state_dict()
    x = np.random.default_rng(3).normal(0, 60, (3, 43, 43))  # Caffe's input scale
    h = _max_pool(_relu_conv(x, state, "conv1", stride=2, pad=3), 3, 2)
    assert h.shape == (64, 11, 11)
    h = _lrn(h)
    h = _relu_conv(_relu_conv(h, state, "conv2_reduce"), state, "conv2", pad=1)
    stem = _max_pool(_lrn(h), 3, 2)
    p = "inception_3a."
    block = np.concatenate([
        _relu_conv(stem, state, p + "b1x1"),
        _relu_conv(_relu_conv(stem, state, p + "b3x3_reduce"), state, p + "b3x3", pad=1),
        _relu_conv(_relu_conv(stem, state, p + "b5x5_reduce"), state, p + "b5x5", pad=2),
        _relu_conv(_max_pool(stem, 3, 1, pad=1), state, p + "pool_proj"),
    ])  # fmt: skip
    with torch.no_grad():
        got_stem = model.stem(torch.from_numpy(x[None]).float())
        got_block = model.inception_3a(got_stem)
    np.testing.assert_allclose(got_stem[0].numpy(), stem, rtol=1e-4, atol=1e-4 * np.abs(stem).max())
    np.testing.assert_allclose(
        got_block[0].numpy(), block, rtol=1e-4, atol=1e-4 * np.abs(block).max()
    )


def test_caffe_input_is_bgr_minus_caffe_mean_without_std():
    rgb = np.zeros((1, 3, 2, 2), np.uint8)
    rgb[0, :, 0, 0] = (123, 117, 104)  # Caffe's mean, R G B
    rgb[0, :, 1, 1] = (255, 0, 10)
    x = network_input(rgb, CAFFE_MEAN_BGR[::-1], "caffe")
    assert x.dtype == np.float32 and x.flags.c_contiguous
    np.testing.assert_array_equal(x[0, :, 0, 0], [0, 0, 0])
    np.testing.assert_array_equal(x[0, :, 1, 1], [10 - 104, 0 - 117, 255 - 123])  # B, G, R
    with pytest.raises(ValueError, match="modality.layout must be one of"):
        network_input(rgb, CAFFE_MEAN_BGR, "bgr")


# --- bad input: one line, exit status 2 ---------------------------------------------------------


def _expect_error(capsys, args: list[str], pattern: str) -> None:
    status, out, err = _convert(capsys, args)
    assert status == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err
    assert pattern in lines[0], lines[0]


def test_bad_caffemodels_fail_with_one_line(blobs, tmp_path, capsys):
    out = str(tmp_path / "out.pth")
    prototxt = tmp_path / "deploy.prototxt"
    prototxt.write_text('name: "GoogleNet"\nlayer {\n  name: "data"\n  type: "Input"\n}\n')
    _expect_error(capsys, [str(prototxt), out], "looks like text: a .prototxt?")
    junk = tmp_path / "junk.caffemodel"
    junk.write_bytes(bytes(range(256)) * 4)
    _expect_error(capsys, [str(junk), out], "junk.caffemodel: not a readable caffemodel")
    _expect_error(capsys, [str(tmp_path / "absent.caffemodel"), out], "cannot read")
    whole = googlenet_caffemodel(blobs)
    cut = tmp_path / "cut.caffemodel"
    cut.write_bytes(whole[: len(whole) // 2])
    _expect_error(capsys, [str(cut), out], "truncated")

    def variant(name: str, changed: dict) -> str:
        path = tmp_path / f"{name}.caffemodel"
        edited = {k: changed.get(k, v) for k, v in blobs.items() if changed.get(k, v) is not None}
        path.write_bytes(googlenet_caffemodel(edited))
        return str(path)

    missing = variant("missing", {"inception_4c/pool_proj": None})
    _expect_error(capsys, [missing, out], "GoogLeNet layer(s) with weights missing")
    w, b = blobs["inception_4a/5x5"]
    torchvision_like = variant("3x3", {"inception_4a/5x5": (w[:, :, 1:4, 1:4].copy(), b)})
    _expect_error(capsys, [torchvision_like, out],
                  "'inception_4a/5x5' has blobs of shape (48, 16, 3, 3) and (48,), "
                  "expected (48, 16, 5, 5)")  # fmt: skip
    assert not (tmp_path / "out.pth").exists()


def test_wrong_blob_count_and_layer_type(blobs, tmp_path, capsys):
    out = str(tmp_path / "out.pth")
    w, b = blobs["conv1/7x7_s2"]
    for name, first in (
        ("nobias", layer("conv1/7x7_s2", "Convolution", [blob(w)])),
        ("ip", layer("conv1/7x7_s2", "InnerProduct", [blob(w), blob(b)])),
    ):
        rest = googlenet_caffemodel({k: v for k, v in blobs.items() if k != "conv1/7x7_s2"})
        path = tmp_path / f"{name}.caffemodel"
        path.write_bytes(net([first]) + rest)
        expected = "holds 1 blobs, expected 2" if name == "nobias" else "expected a convolution"
        _expect_error(capsys, [str(path), out], expected)
    twice = tmp_path / "twice.caffemodel"
    twice.write_bytes(net([layer("conv1/7x7_s2", "Convolution", [blob(w), blob(b)])])
                      + googlenet_caffemodel(blobs))  # fmt: skip
    _expect_error(capsys, [str(twice), out], "two layers named 'conv1/7x7_s2' hold weights")
    bad_count = tmp_path / "count.caffemodel"
    bad_count.write_bytes(net([layer("x", "Convolution", [blob(w[:-1], shape=w.shape)])]))
    _expect_error(
        capsys,
        [str(bad_count), out],
        "blob holds 9261 values but its shape (64, 3, 7, 7) needs 9408",
    )


def test_module_entry_point_exits_2_without_traceback(tmp_path):
    junk = tmp_path / "model.caffemodel"
    junk.write_bytes(b"\xff" * 32)
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "tactile_exp.weights",
            "convert-caffe",
            str(junk),
            str(tmp_path / "o"),
        ],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 2
    assert result.stderr.startswith("error: ") and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_reader_errors_are_caffemodel_errors(tmp_path):
    empty = tmp_path / "empty.caffemodel"
    empty.write_bytes(b"")
    with pytest.raises(CaffeModelError, match="empty file"):
        read_caffemodel(empty)
    no_layers = tmp_path / "nolayers.caffemodel"
    no_layers.write_bytes(net([]))
    with pytest.raises(CaffeModelError, match="no layers"):
        read_caffemodel(no_layers)
