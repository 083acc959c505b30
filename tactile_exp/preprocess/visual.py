"""Visual preprocessing (METHOD.md V1-V2): find the aluminium plate, crop above it, resize.

The object stands on a circular aluminium plate; the paper crops a 2R x R rectangle centred R above
the plate centre, so the crop holds the object whatever the camera distance. The plate is found by
colour: light grey (low saturation, mid-high value in HSV), which excludes a white background.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple, Protocol

import cv2
import numpy as np

from tactile_exp.data.layout import TrialName
from tactile_exp.data.phac2 import default_cache_dir, load_photograph
from tactile_exp.preprocess.cache import cache_key, load_arrays, save_arrays

CODE_VERSION = 3  # bump when the cached arrays' meaning changes (2: crops padded, not clipped;
# 3: the plate fit ignores the outline above its far half, where a grey object can join it)
IMAGENET_MEAN_RGB = (123.675, 116.28, 103.53)  # per-channel mean, RGB, 0-255 scale
_ARRAY_KEYS = ("object_id", "view", "name", "plate", "images", "missing")


class Plate(NamedTuple):
    """The plate's centre and radius (cx, cy, r) in pixels of the image it was found in."""

    cx: float
    cy: float
    r: float


def _check_image(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8 or 0 in image.shape:
        raise ValueError(f"expected an (H, W, 3) uint8 RGB image, got {image.shape} {image.dtype}")
    return image


def plate_mask(
    image: np.ndarray, sat_max: int = 50, val_min: int = 110, val_max: int = 235
) -> np.ndarray:
    """Pixels coloured like brushed aluminium: bool (H, W)."""
    hsv = cv2.cvtColor(_check_image(image), cv2.COLOR_RGB2HSV)
    s, v = hsv[..., 1], hsv[..., 2]
    return (s <= sat_max) & (v >= val_min) & (v <= val_max)


def find_plate(
    image: np.ndarray,
    work_size: int = 512,
    min_area: float = 0.01,
    sat_max: int = 50,
    val_min: int = 110,
    val_max: int = 235,
) -> Plate:
    """Locate the plate (V1): colour mask, morphological clean-up, largest component, circle.

    Works on a copy shrunk to ``work_size`` pixels on its long side (fast on 6 MP photographs).
    Centre and radius come from an ellipse fitted to the region's outline (``_fit_rim``).
    Raises ``ValueError`` when no plate-coloured region covers ``min_area`` of the image.
    """
    image = _check_image(image)
    h, w = image.shape[:2]
    scale = min(1.0, work_size / max(h, w))
    small = image if scale == 1.0 else cv2.resize(
        image, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_AREA
    )  # fmt: skip
    mask = plate_mask(small, sat_max, val_min, val_max).astype(np.uint8)
    k = max(3, round(min(small.shape[:2]) * 0.015) | 1)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel)
    mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, kernel)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    areas = stats[1:, cv2.CC_STAT_AREA]
    if n < 2 or areas.max() < min_area * mask.size:
        found = 0 if n < 2 else areas.max() / mask.size
        raise ValueError(
            f"no plate found: the largest light-grey region covers {found:.2%} of the image, "
            f"expected at least {min_area:.0%}"
        )
    component = labels == 1 + int(areas.argmax())
    cx, cy, r = _fit_rim(component)
    # pixel centres: +0.5 maps the small image's pixel grid back onto the full one
    return Plate((cx + 0.5) / scale - 0.5, (cy + 0.5) / scale - 0.5, r / scale)


def _fit_rim(component: np.ndarray) -> tuple[float, float, float]:
    """(cx, cy, horizontal semi-axis) of the ellipse through the region's outline.

    A camera above the plate's plane sees the circle as an axis-aligned ellipse whose horizontal
    semi-axis is the radius. Outline points: the lowest pixel of each column (the object standing
    on the plate never hides the lower rim) and the outermost pixels of each row. Points far from
    the fitted ellipse (a grey object rising above the plate) are dropped and the fit repeated.
    A light grey object (metal, glass showing the plate, a highlight) can join the plate's region
    above its far rim and pull a first fit upwards; so the fit is repeated on the points no
    higher than half the vertical semi-axis above the centre found, where the object narrower
    than the plate cannot reach the outline.
    """
    h, w = component.shape
    cols = np.flatnonzero(component.any(axis=0))
    rows = np.flatnonzero(component.any(axis=1))
    bottom = h - 1 - np.argmax(component[::-1, cols], axis=0)
    left = np.argmax(component[rows], axis=1)
    right = w - 1 - np.argmax(component[rows, ::-1], axis=1)
    # pixel edges, and no points on the image border (a cut rim says nothing about the ellipse)
    x = np.concatenate([cols, left - 0.5, right + 0.5]).astype(float)
    y = np.concatenate([bottom + 0.5, rows, rows]).astype(float)
    inside = np.concatenate([bottom < h - 1, left > 0, right < w - 1])
    x, y = x[inside], y[inside]
    cx, cy, a2, c1 = _fit_ellipse(x, y)
    low = y >= cy - 0.5 * np.sqrt(a2 / c1)
    if not low.all() and low.sum() >= 8:
        cx, cy, a2, c1 = _fit_ellipse(x[low], y[low])
    return float(cx), float(cy), float(np.sqrt(a2))


def _fit_ellipse(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float, float]:
    """Axis-aligned ellipse through outline points, outliers dropped: the centre (cx, cy), the
    squared horizontal semi-axis a^2 and c1 = a^2 / b^2 (b the vertical semi-axis)."""
    for _ in range(4):
        if x.size < 8:
            raise ValueError(f"no plate found: only {x.size} outline points of the grey region")
        # x^2 + c1 y^2 + c2 x + c3 y + c4 = 0: an axis-aligned ellipse, linear in c
        design = np.stack([y**2, x, y, np.ones_like(x)], axis=1)
        c1, c2, c3, c4 = np.linalg.lstsq(design, -(x**2), rcond=None)[0]
        if not c1 > 0:
            raise ValueError("no plate found: the grey region's outline is not elliptical")
        cx, cy = -c2 / 2, -c3 / (2 * c1)
        a2 = cx**2 + c1 * cy**2 - c4
        if not a2 > 0:
            raise ValueError("no plate found: the grey region's outline is not elliptical")
        value = x**2 + c1 * y**2 + c2 * x + c3 * y + c4
        distance = np.abs(value) / np.hypot(2 * x + c2, 2 * c1 * y + c3)  # Sampson distance
        inliers = distance <= max(1.0, 3 * np.median(distance))
        if inliers.all():
            break
        x, y = x[inliers], y[inliers]
    return cx, cy, a2, c1


def crop_box(shape: tuple[int, ...], plate: Plate) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) of the 2R x R rectangle centred R above the plate centre, in image
    coordinates; it may reach past the image border (``crop_plate`` pads there)."""
    h, w = shape[:2]
    x0, x1 = round(plate.cx - plate.r), round(plate.cx + plate.r)
    y0, y1 = round(plate.cy - 1.5 * plate.r), round(plate.cy - 0.5 * plate.r)
    if x1 <= max(x0, 0) or x0 >= min(x1, w) or y1 <= max(y0, 0) or y0 >= min(y1, h):
        raise ValueError(f"crop above {plate} lies outside the {w}x{h} image")
    return int(x0), int(y0), int(x1), int(y1)


def crop_plate(image: np.ndarray, plate: Plate) -> np.ndarray:
    """V1's crop: width 2R, height R, centre R above the plate centre.

    Where the rectangle reaches past the image border the crop is padded by repeating the border
    pixels, so it keeps its 2:1 aspect ratio and the object its proportions (clipping would
    stretch the object when the crop is resized to a square).
    """
    image = _check_image(image)
    h, w = image.shape[:2]
    x0, y0, x1, y1 = crop_box(image.shape, plate)
    inside = image[max(y0, 0) : min(y1, h), max(x0, 0) : min(x1, w)]
    pad = (max(-y0, 0), max(y1 - h, 0), max(-x0, 0), max(x1 - w, 0))  # top, bottom, left, right
    if not any(pad):
        return inside
    return cv2.copyMakeBorder(inside, *pad, borderType=cv2.BORDER_REPLICATE)


def resize_square(image: np.ndarray, size: int = 224) -> np.ndarray:
    """Resize to (size, size, 3) uint8; area interpolation when shrinking, linear otherwise."""
    image = _check_image(image)
    shrink = image.shape[0] >= size and image.shape[1] >= size
    interp = cv2.INTER_AREA if shrink else cv2.INTER_LINEAR
    return cv2.resize(image, (size, size), interpolation=interp)


def prepare_image(
    image: np.ndarray, size: int = 224, mean: Sequence[float] = IMAGENET_MEAN_RGB
) -> np.ndarray:
    """V2: resize to size x size, subtract the per-channel RGB mean -> (3, size, size) float32.

    ``mean`` defaults to the ImageNet mean (the GoogLeNet weights expect it); pass
    ``VisualArrays.channel_mean`` of the training images to use a fitted one.
    """
    if size < 1:
        raise ValueError(f"size must be >= 1, got {size}")
    resized = resize_square(image, size).astype(np.float32)
    return (resized - _rgb_mean(mean)).transpose(2, 0, 1).copy()


def _rgb_mean(mean: Sequence[float]) -> np.ndarray:
    mean_arr = np.asarray(mean, dtype=np.float32)
    if mean_arr.shape != (3,):
        raise ValueError(f"mean must hold 3 values (R, G, B), got shape {mean_arr.shape}")
    return mean_arr


class PhotoSource(Protocol):
    """What visual preprocessing needs from a data set (``tactile_exp.data.phac2.PHAC2`` fits)."""

    trials: tuple[TrialName, ...]

    def photographs(self) -> dict[int, list[Path]]: ...

    def identity(self) -> str: ...


@dataclass
class VisualArrays:
    """Every photograph cropped and resized, uint8 (4x smaller than float; see ``prepared``)."""

    object_id: np.ndarray  # (n,) int
    view: np.ndarray  # (n,) int: index of the photograph among its object's (sorted by name)
    name: np.ndarray  # (n,) str: file name
    plate: np.ndarray  # (n, 3) float: detected (cx, cy, r) in the original photograph
    images: np.ndarray  # (n, 3, size, size) uint8 RGB, before mean subtraction
    missing: np.ndarray  # (m,) int: objects of the data set without photographs

    def channel_mean(self, index: np.ndarray | None = None) -> np.ndarray:
        """Per-channel RGB mean of the chosen images (e.g. the training objects'): (3,)."""
        images = self.images if index is None else self.images[index]
        if len(images) == 0:
            raise ValueError("channel_mean needs at least one image")
        return images.mean(axis=(0, 2, 3), dtype=np.float64)

    def prepared(
        self, index: np.ndarray | None = None, mean: Sequence[float] = IMAGENET_MEAN_RGB
    ) -> np.ndarray:
        """Mean-subtracted float32 network input (V2): (n, 3, size, size)."""
        images = self.images if index is None else self.images[index]
        return images.astype(np.float32) - _rgb_mean(mean).reshape(1, 3, 1, 1)


def _photo_list(dataset: PhotoSource) -> list[tuple[int, int, Path]]:
    photos = dataset.photographs()
    return [(obj, v, p) for obj in sorted(photos) for v, p in enumerate(sorted(photos[obj]))]


def compute_visual_arrays(dataset: PhotoSource, size: int = 224) -> VisualArrays:
    """Find the plate, crop and resize every photograph; one image in memory at a time."""
    photos = _photo_list(dataset)
    objects = sorted({t.object_id for t in dataset.trials})
    with_photos = {obj for obj, _, _ in photos}
    images = np.empty((len(photos), 3, size, size), dtype=np.uint8)
    plates = np.empty((len(photos), 3))
    report = max(1, len(photos) // 10)
    for i, (_, _, path) in enumerate(photos):
        image = load_photograph(path)
        try:
            plate = find_plate(image)
            crop = crop_plate(image, plate)
        except ValueError as e:
            raise ValueError(f"{path}: {e}") from None
        plates[i] = (plate.cx, plate.cy, plate.r)
        images[i] = resize_square(crop, size).transpose(2, 0, 1)
        if len(photos) >= 20 and ((i + 1) % report == 0 or i + 1 == len(photos)):
            print(f"visual preprocessing: {i + 1}/{len(photos)} photographs", file=sys.stderr)
    return VisualArrays(
        object_id=np.array([obj for obj, _, _ in photos], dtype=np.int64),
        view=np.array([v for _, v, _ in photos], dtype=np.int64),
        name=np.array([p.name for _, _, p in photos], dtype=str),
        plate=plates,
        images=images,
        missing=np.array([o for o in objects if o not in with_photos], dtype=np.int64),
    )


def load_visual_arrays(
    dataset: PhotoSource, size: int = 224, cache_dir: Path | None = None
) -> VisualArrays:
    """``compute_visual_arrays``, cached under ``cache_dir`` (default: the reader's cache dir).

    The key covers the data set identity, the size, and each photograph's name, size and mtime.
    """
    if size < 1:
        raise ValueError(f"size must be >= 1, got {size}")
    photos = [(p.name, p.stat().st_size, p.stat().st_mtime_ns) for _, _, p in _photo_list(dataset)]
    key = cache_key(
        kind="visual", dataset=dataset.identity(), size=size, photos=photos, version=CODE_VERSION
    )
    path = Path(cache_dir if cache_dir is not None else default_cache_dir()) / f"visual-{key}.npz"
    cached = load_arrays(path, _ARRAY_KEYS)
    if cached is not None:
        return VisualArrays(**cached)
    arrays = compute_visual_arrays(dataset, size)
    save_arrays(path, {k: getattr(arrays, k) for k in _ARRAY_KEYS})
    return arrays


class VisualFeatures:
    """V2 and M3's frozen trunk over a set of photographs: the pooled, L2-normalised inception
    (5a) features of every photograph with a given channel mean subtracted, (n, 832).

    The trunk runs once per set of images, weights file (or seed) and mean, cached on disk under
    ``cache_dir`` (none: not cached, as for a new object's photographs): shared by every
    adjective and job.
    """

    def __init__(
        self,
        arrays: VisualArrays,
        *,
        cache_dir: Path | None,
        weights: Path | None = None,
        layout: str = "torchvision",
        seed: int = 0,
        batch_size: int = 32,
        device: str = "auto",
    ) -> None:
        self.arrays = arrays
        self.cache_dir = cache_dir
        self.weights = weights
        self.layout = layout
        self.seed = seed
        self.batch_size = batch_size
        self.device = device
        self._by_mean: dict[tuple[float, ...], np.ndarray] = {}

    def features(self, mean: tuple[float, ...]) -> np.ndarray:
        """Every photograph's features with channel ``mean`` subtracted (the latest kept)."""
        if mean not in self._by_mean:
            self._by_mean = {mean: self._all_features(mean)}
        return self._by_mean[mean]

    def _all_features(self, mean: tuple[float, ...]) -> np.ndarray:
        """The trunk's features of every photograph with channel ``mean`` subtracted; cached on
        disk by the images' bytes, the weights file's bytes (or seed) and the mean."""
        import hashlib

        from tactile_exp.models.googlenet import (
            build_trunk,
            file_digest,
            network_input,
            pooled_features,
        )
        from tactile_exp.train import resolve_device

        key = cache_key(
            kind="googlenet_5a",
            images=hashlib.sha1(self.arrays.images.tobytes()).hexdigest(),
            weights=file_digest(self.weights) if self.weights else f"xavier-seed{self.seed}",
            mean=mean,
            layout=self.layout,
            version=2,  # 2: torchvision input without transform_input (the mean counts)
        )
        path = None if self.cache_dir is None else self.cache_dir / f"googlenet5a-{key}.npz"
        cached = None if path is None else load_arrays(path, ("features",))
        if cached is not None:
            return cached["features"]
        images = network_input(self.arrays.images, mean, self.layout)  # V2, in the trunk's layout
        trunk = build_trunk(self.weights, self.seed, self.layout)
        features = pooled_features(trunk, images, self.batch_size, resolve_device(self.device))
        if path is not None:
            save_arrays(path, {"features": features})
        return features
