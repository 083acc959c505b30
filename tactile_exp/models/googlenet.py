"""The visual CNN (M3): GoogLeNet (Inception v1) truncated after inception (5a), and its loss layer.

``GoogLeNet`` is written in plain torch (torchvision is not importable here) with torchvision's
module names and quirks, so a torchvision-layout ``state_dict`` loads with ``strict=True``:
convolutions without bias followed by ``BatchNorm2d(eps=0.001)``, a 3x3 (not 5x5) convolution in
branch 3 (pytorch/vision#906), ``ceil_mode`` max-pools, a 2x2 ``maxpool4`` and ``transform_input``.
No weights are downloaded: ``load_weights`` reads a file the user gives. The paper's MINC weights
are a Caffe GoogLeNet (no BatchNorm, 5x5 branch 3) and need a converter to this layout.

Design (why the trunk is not inside the model): the trunk is frozen (transfer, as the paper
transfers every layer below 5a; training GoogLeNet on a 2-core CPU is out of reach, about 10
images/s per SGD step, DEPS.md section 6). Its features depend only on the image and the weights, so
the ``visual`` modality computes ``features`` once per data set and weights file (one pass over the
photographs, cached on disk and shared by every adjective, seed and Table I row), and the
``visual_googlenet`` model is the loss layer on them. The engine builds a fresh model for each
adjective; a trunk inside the model would run 24 times per job.
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from tactile_exp.models.registry import MODELS
from tactile_exp.models.sgd import SGDModel
from tactile_exp.train import caffe_xavier_

INCEPTION5A_CHANNELS = 832
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

    Input: (n, 3, H, W) RGB normalised with the ImageNet mean and std, as torchvision expects;
    with ``transform_input`` it is mapped to the (x / 255 - 0.5) / 0.5 scale the weights use.
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


def read_state_dict(path: str | Path) -> dict[str, torch.Tensor]:
    """Tensors of a ``.pth`` file holding a state_dict or ``{"state_dict": ...}``; never unpickles
    arbitrary objects (``weights_only``)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"GoogLeNet weights file {path} does not exist")
    try:
        loaded = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:
        raise ValueError(f"{path}: cannot read as a torch state_dict: {err}") from err
    if isinstance(loaded, dict) and isinstance(loaded.get("state_dict"), dict):
        loaded = loaded["state_dict"]
    if not isinstance(loaded, dict) or not all(
        isinstance(v, torch.Tensor) for v in loaded.values()
    ):
        raise ValueError(f"{path}: expected a state_dict (name -> tensor) or {{'state_dict': ...}}")
    return loaded


def load_weights(model: GoogLeNet, path: str | Path) -> GoogLeNet:
    """Load a torchvision-layout GoogLeNet state_dict from ``path`` into ``model``, strictly.

    ``aux1.*`` / ``aux2.*`` keys are dropped (torchvision's release keeps its auxiliary heads;
    this model has none). Any other missing or unexpected key, or a shape mismatch, raises a
    ``ValueError`` naming the file and the keys.
    """
    return _load_state(model, read_state_dict(path), path)


def _load_state(model: GoogLeNet, state: dict[str, torch.Tensor], path: str | Path) -> GoogLeNet:
    state = {k: v for k, v in state.items() if not k.startswith(("aux1.", "aux2."))}
    own = model.state_dict()
    missing = sorted(set(own) - set(state))
    unexpected = sorted(set(state) - set(own))
    if missing or unexpected:
        raise ValueError(
            f"{path}: not a torchvision-layout GoogLeNet state_dict: {len(missing)} missing keys "
            f"{missing[:8]}, {len(unexpected)} unexpected keys {unexpected[:8]}"
        )
    wrong = [f"{k} {tuple(state[k].shape)} != {tuple(v.shape)}" for k, v in own.items()
             if state[k].shape != v.shape]  # fmt: skip
    if wrong:
        raise ValueError(f"{path}: tensor shapes differ from GoogLeNet's: {wrong[:8]}")
    model.load_state_dict(state, strict=True)
    return model


def build_trunk(weights: str | Path | None, seed: int = 0) -> GoogLeNet:
    """A GoogLeNet in eval mode with ``weights`` (any class count), or Caffe-Xavier random init."""
    if weights is None:
        return xavier_init(GoogLeNet(transform_input=True), seed).eval()
    state = read_state_dict(weights)
    fc = state.get("fc.weight")
    model = GoogLeNet(num_classes=1000 if fc is None else fc.shape[0], transform_input=True)
    return _load_state(model, state, weights).eval()


def file_digest(path: str | Path) -> str:
    """sha1 of a file's bytes: a cache key that survives copies and catches edits."""
    digest = hashlib.sha1()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def pooled_features(
    model: GoogLeNet,
    images: np.ndarray,
    batch_size: int = 32,
    device: str | torch.device = "cpu",
    channels_last: bool = True,
) -> np.ndarray:
    """``model.features`` of ImageNet-normalised (n, 3, H, W) images, in batches: (n, 832) float32.

    ``channels_last`` runs about 2x faster on CPU (DEPS.md section 6; bench/bench_googlenet.py).
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


@MODELS.register("visual_googlenet")
class VisualGoogLeNet(SGDModel):
    """M3's loss layer: a linear classifier on the frozen trunk's pooled, L2-normalised
    inception (5a) features, which the ``visual`` modality supplies as (n, 832) rows.

    Unlike ``linear`` it does not standardise its input: the paper puts the loss directly after
    the L2 normalisation. Trained by the two-stage SGD schedule (T2, T3); ``head()`` gives the
    ``linear`` model for concatenated views (row L).
    """

    learns_representation = False  # the representation is the frozen trunk's, computed upstream
    modalities = ("visual",)

    def _check_input(self, X: np.ndarray) -> None:
        if X.ndim != 2 or X.shape[1] != INCEPTION5A_CHANNELS:
            raise ValueError(
                f"visual_googlenet expects the visual modality's pooled inception (5a) features "
                f"of shape (n, {INCEPTION5A_CHANNELS}), got rows of shape {X.shape[1:]}"
            )

    def _build_body(self, input_shape: tuple[int, ...]) -> tuple[nn.Module, int]:
        return nn.Identity(), int(input_shape[0])

    def transform(self, X: np.ndarray) -> np.ndarray:
        """The features themselves: the trunk is upstream, the loss layer learns no features."""
        return np.asarray(X).reshape(len(X), -1)
