"""Material pre-training of the Caffe-layout trunk, for users without the MINC weights (M3).

The paper's trunk is GoogLeNet fine-tuned on MINC material classification. Here the same source
task runs on photographs of *newly drawn* synthetic objects: materials and latent properties drawn
like the 60 objects' (``synthetic.draw_object_properties``, no label effects), rendered by the
same renderer with seeds of their own, so no object or photograph of the data set is ever seen.

What makes it fit in minutes on 2 CPU cores (none of it is the paper's):

- the layers below ``train_from`` (default inception (5a)) keep their random Caffe-Xavier
  weights; their output is computed once per photograph, and only the blocks from
  ``train_from`` up to 5a and a linear material classifier on the pooled 5a map are trained;
- photographs are cropped (V1) and resized to ``size`` (default 112, a quarter of V2's pixels);
  convolution weights do not depend on the input size, so the file serves V2's 224 input;
- Adam (lr 1e-3) for a few epochs instead of Caffe's long SGD schedule.

Held-out accuracy is measured on whole new objects (the last ``holdout`` fraction, every material
equally often) that training never sees.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from tactile_exp.data.render import render_object
from tactile_exp.data.synthetic import MATERIALS, draw_object_properties
from tactile_exp.preprocess.trunk import (
    INCEPTION5A_CHANNELS,
    CaffeGoogLeNet,
    network_input,
    save_weights,
    xavier_init,
)
from tactile_exp.preprocess.visual import crop_plate, find_plate, resize_square

# blocks above the frozen stem, in network order; "pool3"/"pool4" run between them
TRAINABLE = ("inception_4a", "inception_4b", "inception_4c", "inception_4d", "inception_4e",
             "inception_5a")  # fmt: skip
MIN_SIZE = 32  # five stride-2 stages: 32 px leaves a 1x1 inception (5a) map
_SEED_SALT = 7_340_021  # keeps new objects' random streams apart from the 60 objects'


class PretrainError(ValueError):
    """Bad pre-training settings or output path; raised before any work."""


@dataclass(frozen=True)
class PretrainSettings:
    objects: int = 240  # new objects, cycling through the materials
    views: int = 4  # photographs per object
    size: int = 112  # crop resized to size x size (V2 uses 224)
    train_from: str = "inception_5a"  # the lowest trained block; everything below stays random
    epochs: int = 6
    batch_size: int = 32
    lr: float = 1e-3
    holdout: float = 0.2  # fraction of objects held out for the accuracy
    seed: int = 0
    image_width: int = 480  # rendered photograph, as the synthetic data set's
    image_height: int = 320

    def check(self) -> None:
        n = len(MATERIALS)
        checks = [
            (self.objects >= 2 * n, f"objects must be >= {2 * n} (one train and one held-out "
             f"object per material), got {self.objects}"),
            (self.views >= 1, f"views must be >= 1, got {self.views}"),
            (MIN_SIZE <= self.size <= 512, f"size must be in {MIN_SIZE}..512 pixels (five "
             f"stride-2 stages need >= {MIN_SIZE}), got {self.size}"),
            (self.train_from in TRAINABLE, f"train_from must be one of {TRAINABLE}, got "
             f"{self.train_from!r}"),
            (self.epochs >= 1, f"epochs must be >= 1, got {self.epochs}"),
            (self.batch_size >= 1, f"batch_size must be >= 1, got {self.batch_size}"),
            (self.lr > 0, f"lr must be > 0, got {self.lr}"),
            (0 < self.holdout < 1, f"holdout must be in (0, 1), got {self.holdout}"),
            (min(self.image_width, self.image_height) >= 64, "image width and height must be "
             f">= 64, got {self.image_width}x{self.image_height}"),
        ]  # fmt: skip
        for ok, message in checks:
            if not ok:
                raise PretrainError(message)

    def held_out_objects(self) -> int:
        """A whole number of material rounds, at least one, at most all but one round."""
        n = len(MATERIALS)
        rounds = self.objects // n
        return n * min(max(1, round(rounds * self.holdout)), rounds - 1)


def check_output(out: Path) -> None:
    """Fail before any work when ``out`` cannot be written."""
    out = Path(out)
    if out.is_dir():
        raise PretrainError(f"{out}: is a folder, expected a weights file path")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise PretrainError(f"{out}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK) or (out.exists() and not os.access(out, os.W_OK)):
        raise PretrainError(f"{out}: not writable (folder {parent})")


def material_photographs(settings: PretrainSettings) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Render, JPEG-encode, crop (V1) and resize new objects' photographs.

    Returns images (n, 3, size, size) uint8 RGB, material index per image and object index.
    """
    s = settings
    images = np.empty((s.objects * s.views, 3, s.size, s.size), dtype=np.uint8)
    material = np.repeat(np.arange(s.objects) % len(MATERIALS), s.views)
    obj = np.repeat(np.arange(s.objects), s.views)
    for i in range(s.objects):
        rng = np.random.default_rng([_SEED_SALT, s.seed, i])
        props = draw_object_properties(MATERIALS[i % len(MATERIALS)], rng)
        views = render_object(
            props,
            width=s.image_width,
            height=s.image_height,
            seed=[_SEED_SALT, s.seed, i, 1],
            views=s.views,
        )
        for v, view in enumerate(views):
            ok, jpeg = cv2.imencode(".jpg", view.image, [cv2.IMWRITE_JPEG_QUALITY, 90])
            rgb = cv2.cvtColor(cv2.imdecode(jpeg, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
            crop = crop_plate(rgb, find_plate(rgb))
            images[i * s.views + v] = resize_square(crop, s.size).transpose(2, 0, 1)
        if (i + 1) % max(1, s.objects // 5) == 0:
            print(f"pretrain: rendered {i + 1}/{s.objects} objects", file=sys.stderr)
    return images, material, obj


def _frozen(trunk: CaffeGoogLeNet, x: torch.Tensor, train_from: str) -> torch.Tensor:
    """The random lower layers: input -> the input of block ``train_from``."""
    x = trunk.pool3(trunk.inception_3b(trunk.inception_3a(trunk.stem(x))))
    for name in TRAINABLE[: TRAINABLE.index(train_from)]:
        x = getattr(trunk, name)(x)
        if name == "inception_4e":
            x = trunk.pool4(x)
    return x


def _upper(trunk: CaffeGoogLeNet, x: torch.Tensor, train_from: str) -> torch.Tensor:
    """The trained blocks: block ``train_from`` input -> pooled inception (5a), (n, 832)."""
    for name in TRAINABLE[TRAINABLE.index(train_from) :]:
        x = getattr(trunk, name)(x)
        if name == "inception_4e":
            x = trunk.pool4(x)
    return torch.flatten(trunk.avgpool(x), 1)


def pretrain(settings: PretrainSettings, out: Path) -> dict[str, float]:
    """Train, save the Caffe-layout weights file ``out`` and return its figures."""
    settings.check()
    check_output(out)
    s = settings
    start = time.perf_counter()
    images, material, obj = material_photographs(s)
    rendered = time.perf_counter() - start

    torch.manual_seed(s.seed)
    trunk = xavier_init(CaffeGoogLeNet(), s.seed).eval()
    fmt = torch.channels_last
    trunk = trunk.to(memory_format=fmt)
    x_all = network_input(images, (123.0, 117.0, 104.0), "caffe")  # Caffe's mean, RGB order
    with torch.inference_mode():
        lower = torch.cat([
            _frozen(trunk, torch.as_tensor(x_all[i : i + 64]).contiguous(memory_format=fmt),
                    s.train_from)
            for i in range(0, len(x_all), 64)
        ])  # fmt: skip
    lower = lower.clone()  # out of inference mode, so autograd can use it
    frozen_s = time.perf_counter() - start - rendered

    held = obj >= s.objects - s.held_out_objects()
    train_idx, test_idx = np.flatnonzero(~held), np.flatnonzero(held)
    upper = [getattr(trunk, n) for n in TRAINABLE[TRAINABLE.index(s.train_from) :]]
    classifier = nn.Linear(INCEPTION5A_CHANNELS, len(MATERIALS))
    params = [p for m in upper for p in m.parameters()] + list(classifier.parameters())
    optimiser = torch.optim.Adam(params, lr=s.lr)
    y = torch.as_tensor(material)
    generator = torch.Generator().manual_seed(s.seed)
    for epoch in range(s.epochs):
        for m in upper:
            m.train()
        order = torch.as_tensor(train_idx)[torch.randperm(len(train_idx), generator=generator)]
        total = 0.0
        for b in range(0, len(order), s.batch_size):
            idx = order[b : b + s.batch_size]
            loss = F.cross_entropy(classifier(_upper(trunk, lower[idx], s.train_from)), y[idx])
            optimiser.zero_grad(set_to_none=True)
            loss.backward()
            optimiser.step()
            total += float(loss.detach()) * len(idx)
        accuracy = _accuracy(trunk, classifier, lower, y, test_idx, s.train_from)
        print(
            f"pretrain: epoch {epoch + 1}/{s.epochs} loss {total / len(order):.3f} held-out "
            f"accuracy {accuracy:.3f}",
            file=sys.stderr,
        )
    trained = time.perf_counter() - start - rendered - frozen_s
    state = {k: v.detach().contiguous() for k, v in trunk.state_dict().items()}
    try:
        save_weights(out, state, layout="caffe")
    except OSError as err:
        raise PretrainError(f"{out}: cannot write: {err.strerror or err}") from None
    return {
        "held_out_accuracy": accuracy,
        "chance": 1.0 / len(MATERIALS),
        "train_images": float(len(train_idx)),
        "held_out_images": float(len(test_idx)),
        "render_s": rendered,
        "frozen_s": frozen_s,
        "train_s": trained,
        "total_s": time.perf_counter() - start,
    }


@torch.no_grad()
def _accuracy(
    trunk: CaffeGoogLeNet,
    classifier: nn.Linear,
    lower: torch.Tensor,
    y: torch.Tensor,
    index: np.ndarray,
    train_from: str,
) -> float:
    trunk.eval()
    correct = 0
    for b in range(0, len(index), 128):
        idx = torch.as_tensor(index[b : b + 128])
        pred = classifier(_upper(trunk, lower[idx], train_from)).argmax(1)
        correct += int((pred == y[idx]).sum())
    return correct / max(1, len(index))
