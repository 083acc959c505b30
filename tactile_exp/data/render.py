"""Photographs of the synthetic objects (D3): an object on a circular aluminium plate.

The scene follows what the crop (V1) expects: a light grey, low-saturation plate with a subtle
brushed texture, seen from a slightly elevated camera (a near-circular ellipse), on a dark blue
wall / brown table background, with the object standing on the plate centre. Appearance comes
only from the latent properties of ``synthetic.object_properties``: height from thickness (the
strongest cue, so thick/thin are visual), width from size, colour from hue/saturation/value,
gloss highlight, texture contrast, bumps and hair strands. Views differ in object rotation,
lighting and camera offset. ``render_view`` returns the true plate geometry so tests can check
a crop.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import NamedTuple

import cv2
import numpy as np

JPEG_QUALITY = 90
PLATE_GREY = 190.0


class View(NamedTuple):
    """One rendered photograph (BGR uint8) and the true plate centre (x, y) and radius in px."""

    image: np.ndarray
    centre: tuple[float, float]
    radius: float


def _smooth_noise(rng: np.random.Generator, h: int, w: int, cells: tuple[int, int]) -> np.ndarray:
    """Zero-mean, unit-ish noise varying over ``cells`` (rows, cols) cells, at full size."""
    small = rng.standard_normal((max(cells[0], 2), max(cells[1], 2))).astype(np.float32)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)


def _hsv_to_bgr(h: float, s: float, v: float) -> np.ndarray:
    pixel = np.array([[[h * 179, s * 255, v * 255]]], dtype=np.float32).astype(np.uint8)
    return cv2.cvtColor(pixel, cv2.COLOR_HSV2BGR)[0, 0].astype(np.float32)


def render_view(
    props: Mapping[str, float],
    view: int,
    width: int,
    height: int,
    seed: int | Sequence[int] = 0,
) -> View:
    """Render view ``view`` of an object with latent ``props`` at ``width`` x ``height``."""
    seeds = [seed] if isinstance(seed, int) else list(seed)
    rng = np.random.default_rng([*seeds, 1000 + view])
    h, w = height, width
    light = rng.uniform(0.85, 1.1)
    light_dir = rng.uniform(-1, 1)

    # Background: dark blue wall above, brown table below, soft gradients.
    yy = np.linspace(0, 1, h, dtype=np.float32)[:, None, None]
    horizon = rng.uniform(0.35, 0.45)
    wall = np.array([105, 62, 38], np.float32) * (0.8 + 0.3 * yy / horizon)
    table = np.array([45, 75, 115], np.float32) * (0.75 + 0.35 * yy)
    img = np.where(yy < horizon, wall, table) * np.ones((1, w, 1), np.float32)
    img += 6 * _smooth_noise(rng, h, w, (6, 9))[..., None]

    # Plate: near-circular ellipse, brushed aluminium.
    radius = min(0.27 * h * rng.uniform(0.95, 1.05), 0.4 * w)
    cx = w / 2 + rng.normal(0, 0.03 * w)
    cy = 0.64 * h + rng.normal(0, 0.02 * h)
    ry = radius * rng.uniform(0.82, 0.9)
    y = np.arange(h, dtype=np.float32)[:, None]
    x = np.arange(w, dtype=np.float32)[None, :]
    plate = ((x - cx) / radius) ** 2 + ((y - cy) / ry) ** 2 <= 1.0
    brushed = _smooth_noise(rng, h, w, (h // 2, max(w // 24, 2)))
    shade = PLATE_GREY * light * (1 + 0.05 * light_dir * (x - cx) / radius - 0.04 * (y - cy) / ry)
    plate_img = (shade + 3.0 * brushed)[..., None] + np.array([3, 0, -2], np.float32)
    img = np.where(plate[..., None], plate_img, img)

    # Soft contact shadow under the object.
    shadow = np.exp(-(((x - cx) / (0.6 * radius)) ** 2) - ((y - cy) / (0.25 * ry)) ** 2)
    img *= (1 - 0.25 * shadow * plate)[..., None]

    # Object: a body standing on the plate centre.
    turn = abs(math.cos(rng.uniform(0, math.pi)))
    ow = radius * (0.45 + 0.45 * props["size"]) * (0.75 + 0.25 * turn)
    oh = radius * min(0.12 + 1.3 * props["thickness"], 1.4)
    top_ry = ow * 0.25 * (1 - props["stiffness"] * 0.5)
    mask = np.zeros((h, w), np.uint8)
    c = (round(cx), round(cy))
    axes = (max(round(ow), 1), max(round(top_ry), 1))
    cv2.rectangle(mask, (c[0] - axes[0], round(cy - oh)), (c[0] + axes[0], c[1]), 255, -1)
    cv2.ellipse(mask, c, axes, 0, 0, 180, 255, -1)
    cv2.ellipse(mask, (c[0], round(cy - oh)), axes, 0, 180, 360, 255, -1)
    body = cv2.GaussianBlur(mask.astype(np.float32) / 255, (0, 0), max(w / 800, 0.5))

    grey = props["saturation"] < 0.3  # keep grey objects darker than the plate
    value = (0.25 + 0.6 * props["value"]) * (0.7 if grey else 1.0)
    colour = _hsv_to_bgr(props["hue"], props["saturation"], value)
    rel = np.clip((x - cx) / max(ow, 1), -1, 1)
    cylinder = 0.75 + 0.25 * np.cos((rel - 0.4 * light_dir) * math.pi / 2)
    cell = max(ow / (6 + 10 * props["roughness"]), 2)
    grain = _smooth_noise(rng, h, w, (max(round(h / cell), 2), max(round(w / cell), 2)))
    tex = 1 + (0.05 + 0.3 * props["texture_contrast"]) * grain
    lumps = np.sin((x - cx) / max(ow, 1) * 9 + rng.uniform(0, 6)) * np.sin(
        (y - cy) / max(ow, 1) * 9
    )
    tex = tex + 0.25 * props["bumpiness"] * lumps
    obj = colour * (light * cylinder * tex)[..., None]
    hx = cx + 0.4 * light_dir * ow
    hy = cy - 0.65 * oh
    spread = (0.08 + 0.25 * (1 - props["gloss"])) * ow
    spot = np.exp(-(((x - hx) / spread) ** 2) - ((y - hy) / (2.5 * spread)) ** 2)
    obj += (180 * props["gloss"] ** 1.5 * spot)[..., None]
    img = img * (1 - body[..., None]) + obj * body[..., None]

    # Hair strands along the outline.
    strands = int(400 * props["hairiness"] ** 1.5 * (w * h / (480 * 320)) ** 0.5)
    if strands:
        ys, xs = np.nonzero(mask[::2, ::2])
        pick = rng.integers(0, len(ys), strands)
        ang = rng.uniform(0, 2 * math.pi, strands)
        length = radius * rng.uniform(0.03, 0.1, strands)
        tone = colour * rng.uniform(0.6, 1.3, (strands, 1))
        thick = max(1, round(w / 1000))
        for i in range(strands):
            p0 = (int(xs[pick[i]] * 2), int(ys[pick[i]] * 2))
            dx, dy = length[i] * math.cos(ang[i]), length[i] * math.sin(ang[i])
            p1 = (int(p0[0] + dx), int(p0[1] + dy))
            cv2.line(img, p0, p1, tone[i].tolist(), thick, cv2.LINE_AA)

    img += rng.normal(0, 2.0, (h, w, 1)).astype(np.float32)
    image = np.clip(img, 0, 255).astype(np.uint8)
    return View(image, (float(cx), float(cy)), float(radius))


def write_jpeg(path: Path, image: np.ndarray, quality: int = JPEG_QUALITY) -> None:
    """Write a BGR image as JPEG (deterministic bytes for identical input)."""
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise OSError(f"{path}: JPEG encoding failed for an image of shape {image.shape}")
    Path(path).write_bytes(buf.tobytes())
