"""M3's frozen trunk: GoogLeNet (Inception v1) truncated after inception (5a), its weights files,
its input (V2) and its pooled features. The ``visual_googlenet`` model is the loss layer on them.

Two layouts of the trunk, chosen by ``modality.layout``:

- ``torchvision``: ``GoogLeNet``, plain torch (torchvision is not importable here) with
  torchvision's module names and quirks, so a torchvision-layout ``state_dict`` loads with
  ``strict=True``: convolutions without bias followed by ``BatchNorm2d(eps=0.001)``, a 3x3 (not
  5x5) convolution in branch 3 (pytorch/vision#906), ``ceil_mode`` max-pools, a 2x2 ``maxpool4``
  and ``transform_input`` (kept for torchvision's input convention, off in ``build_trunk``: V2's
  mean subtraction happens in ``network_input``).
- ``caffe``: ``CaffeGoogLeNet``, bvlc_googlenet's deploy.prototxt as the MINC release uses it:
  biased convolutions, no batch norm, LRN after pool1 and after conv2, a true 5x5 branch, Caffe's
  ceil-mode pooling (3x3 stride 2 pool4) and BGR 0-255 input minus Caffe's mean.
  ``python -m tactile_exp.weights convert-caffe`` turns a ``.caffemodel`` into its weights file.

No weights are downloaded: ``build_trunk`` reads a file the user gives. A weights file written
here records its layout (``save_weights``), so loading it into the other layout fails clearly.

Design (why the trunk is preprocessing, not inside the model): the trunk is frozen (transfer, as the
paper transfers every layer below 5a; training GoogLeNet on a 2-core CPU is out of reach, about 10
images/s per SGD step, bench/bench_googlenet.py). Its features depend only on the image and the
weights, so the ``visual`` modality computes them once per data set and weights file (one pass over
the photographs, cached on disk and shared by every adjective, seed and Table I row), and the
``visual_googlenet`` model (``models/googlenet.py``) is the loss layer on them. The engine builds a
fresh model for each adjective; a trunk inside the model would run 24 times per job.
"""

from __future__ import annotations

import hashlib
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from tactile_exp.train import caffe_xavier_

INCEPTION5A_CHANNELS = 832
IMAGENET_MEAN_RGB = (123.675, 116.28, 103.53)  # per-channel mean, RGB, 0-255 scale
# torchvision's GoogLeNet weights take input on the [-1, 1] scale: (img - mean) / 127.5
TORCHVISION_SCALE = 127.5
# torchvision's transform_input: ImageNet-normalised input -> the [-1, 1] scale of the weights
IMAGENET_STD_RGB = (0.229, 0.224, 0.225)
_IMAGENET_MEAN01 = (0.485, 0.456, 0.406)


class BasicConv2d(nn.Module):
    def __init__(self, in_channels: int, out_channels: int, **kwargs: int) -> None:
        super().__init__()
        self.conv = nn.Conv2d(in_channels, out_channels, bias=False, **kwargs)
        self.bn = nn.BatchNorm2d(out_channels, eps=0.001)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(self.bn(self.conv(x)), inplace=True)


class Inception(nn.Module):
    """Four parallel branches concatenated along channels; branch 3 is 3x3 as in torchvision."""

    def __init__(
        self, c_in: int, c1: int, c3_red: int, c3: int, c5_red: int, c5: int, pool_proj: int
    ) -> None:
        super().__init__()
        self.branch1 = BasicConv2d(c_in, c1, kernel_size=1)
        self.branch2 = nn.Sequential(
            BasicConv2d(c_in, c3_red, kernel_size=1),
            BasicConv2d(c3_red, c3, kernel_size=3, padding=1),
        )
        self.branch3 = nn.Sequential(
            BasicConv2d(c_in, c5_red, kernel_size=1),
            BasicConv2d(c5_red, c5, kernel_size=3, padding=1),
        )
        self.branch4 = nn.Sequential(
            nn.MaxPool2d(kernel_size=3, stride=1, padding=1, ceil_mode=True),
            BasicConv2d(c_in, pool_proj, kernel_size=1),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        branches = (self.branch1, self.branch2, self.branch3, self.branch4)
        return torch.cat([b(x) for b in branches], 1)


class GoogLeNet(nn.Module):
    """Inception v1 in torchvision's layout, without the auxiliary heads (344 state_dict keys).

    Input: ``network_input``'s (img - mean) / 127.5, the [-1, 1] scale the weights use. With
    ``transform_input`` it takes torchvision's convention instead (RGB normalised with the
    ImageNet mean and std, mapped to (x / 255 - 0.5) / 0.5, whatever mean was subtracted).
    """

    def __init__(self, num_classes: int = 1000, transform_input: bool = False) -> None:
        super().__init__()
        self.transform_input = transform_input
        self.conv1 = BasicConv2d(3, 64, kernel_size=7, stride=2, padding=3)
        self.maxpool1 = nn.MaxPool2d(3, stride=2, ceil_mode=True)
        self.conv2 = BasicConv2d(64, 64, kernel_size=1)
        self.conv3 = BasicConv2d(64, 192, kernel_size=3, padding=1)
        self.maxpool2 = nn.MaxPool2d(3, stride=2, ceil_mode=True)
        self.inception3a = Inception(192, 64, 96, 128, 16, 32, 32)
        self.inception3b = Inception(256, 128, 128, 192, 32, 96, 64)
        self.maxpool3 = nn.MaxPool2d(3, stride=2, ceil_mode=True)
        self.inception4a = Inception(480, 192, 96, 208, 16, 48, 64)
        self.inception4b = Inception(512, 160, 112, 224, 24, 64, 64)
        self.inception4c = Inception(512, 128, 128, 256, 24, 64, 64)
        self.inception4d = Inception(512, 112, 144, 288, 32, 64, 64)
        self.inception4e = Inception(528, 256, 160, 320, 32, 128, 128)
        self.maxpool4 = nn.MaxPool2d(2, stride=2, ceil_mode=True)
        self.inception5a = Inception(832, 256, 160, 320, 32, 128, 128)
        self.inception5b = Inception(832, 384, 192, 384, 48, 128, 128)
        self.avgpool = nn.AdaptiveAvgPool2d((1, 1))
        self.dropout = nn.Dropout(p=0.2)
        self.fc = nn.Linear(1024, num_classes)

    def _transform_input(self, x: torch.Tensor) -> torch.Tensor:
        if not self.transform_input:
            return x
        std = x.new_tensor(IMAGENET_STD_RGB).view(1, 3, 1, 1)
        mean = x.new_tensor(_IMAGENET_MEAN01).view(1, 3, 1, 1)
        return x * (std / 0.5) + (mean - 0.5) / 0.5

    def inception5a_map(self, x: torch.Tensor) -> torch.Tensor:
        """Everything up to and including inception (5a): (n, 832, 7, 7) at 224x224."""
        x = self.maxpool1(self.conv1(self._transform_input(x)))
        x = self.maxpool2(self.conv3(self.conv2(x)))
        x = self.maxpool3(self.inception3b(self.inception3a(x)))
        for block in (self.inception4a, self.inception4b, self.inception4c, self.inception4d):
            x = block(x)
        x = self.maxpool4(self.inception4e(x))
        return self.inception5a(x)

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """M3: inception (5a), global average pooling, L2 normalisation -> (n, 832)."""
        pooled = torch.flatten(self.avgpool(self.inception5a_map(x)), 1)
        return F.normalize(pooled, dim=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """The whole classifier (logits), as torchvision's model in eval mode without aux heads."""
        x = self.inception5b(self.inception5a_map(x))
        return self.fc(self.dropout(torch.flatten(self.avgpool(x), 1)))


class CaffeInception(nn.Module):
    """bvlc_googlenet's inception module: biased convolutions, ReLU, a true 5x5 branch.

    Attribute names follow the Caffe layer names (``inception_3a/5x5`` -> ``b5x5``), so the
    converter's mapping reads off ``CAFFE_BRANCHES``.
    """

    def __init__(
        self, c_in: int, c1: int, c3_red: int, c3: int, c5_red: int, c5: int, pool_proj: int
    ) -> None:
        super().__init__()
        self.b1x1 = nn.Conv2d(c_in, c1, kernel_size=1)
        self.b3x3_reduce = nn.Conv2d(c_in, c3_red, kernel_size=1)
        self.b3x3 = nn.Conv2d(c3_red, c3, kernel_size=3, padding=1)
        self.b5x5_reduce = nn.Conv2d(c_in, c5_red, kernel_size=1)
        self.b5x5 = nn.Conv2d(c5_red, c5, kernel_size=5, padding=2)
        self.pool = nn.MaxPool2d(kernel_size=3, stride=1, padding=1, ceil_mode=True)
        self.pool_proj = nn.Conv2d(c_in, pool_proj, kernel_size=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        branches = (
            F.relu(self.b1x1(x)),
            F.relu(self.b3x3(F.relu(self.b3x3_reduce(x)))),
            F.relu(self.b5x5(F.relu(self.b5x5_reduce(x)))),
            F.relu(self.pool_proj(self.pool(x))),
        )
        return torch.cat(branches, 1)


# Caffe layer-name suffix of each inception branch convolution -> CaffeInception attribute
CAFFE_BRANCHES = {
    "1x1": "b1x1",
    "3x3_reduce": "b3x3_reduce",
    "3x3": "b3x3",
    "5x5_reduce": "b5x5_reduce",
    "5x5": "b5x5",
    "pool_proj": "pool_proj",
}
CAFFE_STEM = {"conv1/7x7_s2": "conv1", "conv2/3x3_reduce": "conv2_reduce", "conv2/3x3": "conv2"}
CAFFE_INCEPTIONS = ("3a", "3b", "4a", "4b", "4c", "4d", "4e", "5a")
# bvlc_googlenet deploy.prototxt: LRN local_size 5, alpha 1e-4, beta 0.75 (k 1); Caffe's LRN
# divides alpha by local_size, as torch's LocalResponseNorm does
CAFFE_LRN = {"size": 5, "alpha": 1e-4, "beta": 0.75, "k": 1.0}
CAFFE_MEAN_BGR = (104.0, 117.0, 123.0)  # bvlc_googlenet's mean_value, BGR, 0-255 scale


class CaffeGoogLeNet(nn.Module):
    """bvlc_googlenet up to inception (5a) in Caffe's layout (the MINC-CNN's, M3).

    Input: (n, 3, H, W) BGR on the 0-255 scale minus ``CAFFE_MEAN_BGR`` (``network_input``).
    The layers above 5a (5b, pool5, the classifier) and the auxiliary heads are not held: the
    paper's features stop at 5a. ``caffe_layer_map`` names the Caffe layer of every parameter.
    """

    def __init__(self) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(3, 64, kernel_size=7, stride=2, padding=3)
        self.pool1 = nn.MaxPool2d(3, stride=2, ceil_mode=True)
        self.norm1 = nn.LocalResponseNorm(**CAFFE_LRN)
        self.conv2_reduce = nn.Conv2d(64, 64, kernel_size=1)
        self.conv2 = nn.Conv2d(64, 192, kernel_size=3, padding=1)
        self.norm2 = nn.LocalResponseNorm(**CAFFE_LRN)
        self.pool2 = nn.MaxPool2d(3, stride=2, ceil_mode=True)
        self.inception_3a = CaffeInception(192, 64, 96, 128, 16, 32, 32)
        self.inception_3b = CaffeInception(256, 128, 128, 192, 32, 96, 64)
        self.pool3 = nn.MaxPool2d(3, stride=2, ceil_mode=True)
        self.inception_4a = CaffeInception(480, 192, 96, 208, 16, 48, 64)
        self.inception_4b = CaffeInception(512, 160, 112, 224, 24, 64, 64)
        self.inception_4c = CaffeInception(512, 128, 128, 256, 24, 64, 64)
        self.inception_4d = CaffeInception(512, 112, 144, 288, 32, 64, 64)
        self.inception_4e = CaffeInception(528, 256, 160, 320, 32, 128, 128)
        self.pool4 = nn.MaxPool2d(3, stride=2, ceil_mode=True)  # 3x3 here, 2x2 in torchvision
        self.inception_5a = CaffeInception(832, 256, 160, 320, 32, 128, 128)
        self.avgpool = nn.AdaptiveAvgPool2d((1, 1))

    def stem(self, x: torch.Tensor) -> torch.Tensor:
        """conv1, pool1, norm1, conv2 (reduce, 3x3), norm2, pool2: (n, 192, 28, 28) at 224."""
        x = self.norm1(self.pool1(F.relu(self.conv1(x))))
        x = F.relu(self.conv2(F.relu(self.conv2_reduce(x))))
        return self.pool2(self.norm2(x))

    def inception5a_map(self, x: torch.Tensor) -> torch.Tensor:
        """Everything up to and including inception (5a): (n, 832, 7, 7) at 224x224."""
        x = self.pool3(self.inception_3b(self.inception_3a(self.stem(x))))
        for block in (
            self.inception_4a,
            self.inception_4b,
            self.inception_4c,
            self.inception_4d,
            self.inception_4e,
        ):
            x = block(x)
        return self.inception_5a(self.pool4(x))

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """M3: inception (5a), global average pooling, L2 normalisation -> (n, 832)."""
        pooled = torch.flatten(self.avgpool(self.inception5a_map(x)), 1)
        return F.normalize(pooled, dim=1)


def caffe_layer_map() -> dict[str, str]:
    """Caffe layer name (``inception_4c/5x5``) -> ``CaffeGoogLeNet`` module (``inception_4c.b5x5``),
    for every convolution up to inception (5a), in network order."""
    names = dict(CAFFE_STEM)
    for block in CAFFE_INCEPTIONS:
        for suffix, attr in CAFFE_BRANCHES.items():
            names[f"inception_{block}/{suffix}"] = f"inception_{block}.{attr}"
    return names


Trunk = GoogLeNet | CaffeGoogLeNet
LAYOUTS = ("torchvision", "caffe")


# the mean each layout's weights were trained with, RGB on the 0-255 scale (modality.mean=imagenet)
LAYOUT_MEAN_RGB = {"torchvision": IMAGENET_MEAN_RGB, "caffe": CAFFE_MEAN_BGR[::-1]}


def network_input(images: np.ndarray, mean_rgb: Sequence[float], layout: str) -> np.ndarray:
    """(n, 3, H, W) uint8 RGB images -> the trunk's float32 input in ``layout`` (V2).

    V2 subtracts the per-channel mean and divides by no per-channel std. ``caffe``: BGR on the
    0-255 scale minus the mean, as Caffe's data layer feeds bvlc_googlenet. ``torchvision``: RGB
    minus the mean, divided by ``TORCHVISION_SCALE`` (one number for all channels), the [-1, 1]
    range torchvision's GoogLeNet weights were trained on. The trunk then skips
    ``transform_input``, which would map any ImageNet-normalised input back to
    ``img / 127.5 - 1`` and so undo the mean subtraction.
    """
    if images.ndim != 4 or images.shape[1] != 3:
        raise ValueError(f"expected images of shape (n, 3, H, W), got {images.shape}")
    _check_layout(layout)
    mean = np.asarray(mean_rgb, np.float32)
    if mean.shape != (3,):
        raise ValueError(f"mean must hold 3 values (R, G, B), got shape {mean.shape}")
    x = images.astype(np.float32) - mean.reshape(1, 3, 1, 1)
    if layout == "caffe":
        return np.ascontiguousarray(x[:, ::-1])
    x /= TORCHVISION_SCALE
    return x


def _check_layout(layout: str) -> None:
    if layout not in LAYOUTS:
        raise ValueError(f"modality.layout must be one of {LAYOUTS}, got {layout!r}")


def xavier_init(model: nn.Module, seed: int) -> nn.Module:
    """Caffe "xavier" filler (T3) on every conv and linear weight; leaves the global RNG alone."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        for m in model.modules():
            if isinstance(m, nn.Conv2d | nn.Linear):
                caffe_xavier_(m.weight, m.weight[0].numel())
                if m.bias is not None:
                    nn.init.zeros_(m.bias)
    return model


def save_weights(path: str | Path, state: dict[str, torch.Tensor], layout: str) -> None:
    """Write a trunk weights file: ``{"layout": ..., "state_dict": ...}``, read by ``build_trunk``
    with ``weights_only`` (no pickled code). The layout makes a wrong-layout load fail clearly."""
    _check_layout(layout)
    torch.save({"layout": layout, "state_dict": state}, Path(path))


def read_state_dict(path: str | Path) -> tuple[dict[str, torch.Tensor], str | None]:
    """Tensors of a ``.pth`` file holding a state_dict or ``{"state_dict": ...}``, and the layout
    it records (``save_weights``; None for a plain state_dict, e.g. torchvision's release).
    Never unpickles arbitrary objects (``weights_only``)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"GoogLeNet weights file {path} does not exist")
    try:
        loaded = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:
        raise ValueError(f"{path}: cannot read as a torch state_dict: {err}") from err
    layout = None
    if isinstance(loaded, dict) and isinstance(loaded.get("state_dict"), dict):
        layout = loaded.get("layout")
        loaded = loaded["state_dict"]
    if not isinstance(loaded, dict) or not all(
        isinstance(v, torch.Tensor) for v in loaded.values()
    ):
        raise ValueError(f"{path}: expected a state_dict (name -> tensor) or {{'state_dict': ...}}")
    if layout is not None and layout not in LAYOUTS:
        raise ValueError(f"{path}: records layout {layout!r}, expected one of {LAYOUTS}")
    return loaded, layout


def load_weights(model: Trunk, path: str | Path) -> Trunk:
    """Load a GoogLeNet state_dict of ``model``'s layout from ``path`` into ``model``, strictly.

    ``aux1.*`` / ``aux2.*`` keys are dropped (torchvision's release keeps its auxiliary heads;
    this model has none). A file recording the other layout, any other missing or unexpected
    key, or a shape mismatch raises a ``ValueError`` naming the file and the keys.
    """
    state, recorded = read_state_dict(path)
    return _load_state(model, state, recorded, path)


def _load_state(
    model: Trunk, state: dict[str, torch.Tensor], recorded: str | None, path: str | Path
) -> Trunk:
    layout = "caffe" if isinstance(model, CaffeGoogLeNet) else "torchvision"
    if recorded is not None and recorded != layout:
        raise ValueError(
            f"{path}: holds {recorded}-layout GoogLeNet weights, but the trunk has the {layout} "
            f"layout: set modality.layout={recorded}"
        )
    state = {k: v for k, v in state.items() if not k.startswith(("aux1.", "aux2."))}
    own = model.state_dict()
    missing = sorted(set(own) - set(state))
    unexpected = sorted(set(state) - set(own))
    if missing or unexpected:
        raise ValueError(
            f"{path}: not a {layout}-layout GoogLeNet state_dict: {len(missing)} missing keys "
            f"{missing[:8]}, {len(unexpected)} unexpected keys {unexpected[:8]}"
        )
    wrong = [f"{k} {tuple(state[k].shape)} != {tuple(v.shape)}" for k, v in own.items()
             if state[k].shape != v.shape]  # fmt: skip
    if wrong:
        raise ValueError(f"{path}: tensor shapes differ from GoogLeNet's: {wrong[:8]}")
    model.load_state_dict(state, strict=True)
    return model


def build_trunk(weights: str | Path | None, seed: int = 0, layout: str = "torchvision") -> Trunk:
    """A GoogLeNet trunk of ``layout`` in eval mode with ``weights`` (for torchvision: any class
    count), or Caffe-Xavier random init when ``weights`` is None. It takes ``network_input``:
    the torchvision trunk is built without ``transform_input`` (see there)."""
    _check_layout(layout)
    if weights is None:
        model = CaffeGoogLeNet() if layout == "caffe" else GoogLeNet()
        return xavier_init(model, seed).eval()
    state, recorded = read_state_dict(weights)
    if layout == "caffe":
        model = CaffeGoogLeNet()
    else:
        fc = state.get("fc.weight")
        model = GoogLeNet(num_classes=1000 if fc is None else fc.shape[0])
    return _load_state(model, state, recorded, weights).eval()


def file_digest(path: str | Path) -> str:
    """sha1 of a file's bytes: a cache key that survives copies and catches edits."""
    digest = hashlib.sha1()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def pooled_features(
    model: Trunk,
    images: np.ndarray,
    batch_size: int = 32,
    device: str | torch.device = "cpu",
    channels_last: bool = True,
) -> np.ndarray:
    """``model.features`` of (n, 3, H, W) ``network_input`` images, in batches: (n, 832) float32.

    ``channels_last`` runs about 2x faster on CPU (bench/bench_googlenet.py).
    """
    if images.ndim != 4 or images.shape[1] != 3:
        raise ValueError(f"expected images of shape (n, 3, H, W), got {images.shape}")
    if batch_size < 1:
        raise ValueError(f"batch_size must be >= 1, got {batch_size}")
    fmt = torch.channels_last if channels_last else torch.contiguous_format
    model = model.to(device=device, memory_format=fmt).eval()
    out = np.empty((len(images), INCEPTION5A_CHANNELS), dtype=np.float32)
    step = max(1, len(images) // batch_size // 10) * batch_size
    with torch.inference_mode():
        for start in range(0, len(images), batch_size):
            x = torch.as_tensor(np.asarray(images[start : start + batch_size], np.float32))
            out[start : start + len(x)] = model.features(x.to(device, memory_format=fmt)).cpu()
            done = start + len(x)
            if len(images) > 4 * batch_size and (done % step == 0 or done == len(images)):
                print(f"GoogLeNet inception (5a): {done}/{len(images)} images", file=sys.stderr)
    return out
