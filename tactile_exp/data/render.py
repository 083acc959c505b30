"""Photographs of the synthetic objects (D3): an object on a circular aluminium plate.

The scene follows what the crop (V1) expects: a light grey, low-saturation plate with a subtle
brushed texture, seen from a slightly elevated camera (a near-circular ellipse), on a dark blue
wall / brown table background, with the object standing on the plate centre. Appearance comes
only from the latent visual properties (``synthetic.object_properties`` or, for a newly drawn
object, ``synthetic.draw_object_properties``), never from labels, so sight tells what the
properties carry and nothing else:

- height from ``thickness`` (0.6 ... 1.5 plate radii: thin objects show a sliver in the crop,
  thick ones fill it), width from ``size``;
- colour from ``hue``, ``saturation``, ``value``; grey objects stay darker than the plate;
- surface: grain whose frequency follows ``roughness`` and contrast ``texture_contrast``;
  shaded bumps (lit from the view's light) from ``bumpiness``;
- lustre: a specular streak, sharper and brighter with ``gloss``; ``metalness`` turns the body
  grey with banded environment reflections and a near-white highlight; ``transparency`` lets
  the background through with a dark refracting rim (glass);
- ``hairiness``: soft, blurred outline and strands over the outline and surface.

Stiffness, porosity, springiness and the other touch properties are not drawn.

Views differ in *what* they show, as PHAC-2's photo sets do (generator version 5). Each view index
has a camera elevation (``ELEVATION``, jittered per view), from a low side view to a high, close
top view:

- side views (low elevation) show the side wall's height (thickness) against the wall, hair as a
  fringe on the outline and a specular streak on the wall; seen at a grazing angle from afar the
  surface detail (grain, bumps, fuzz) is faint;
- top views (high elevation, close) look down on the top face, which fills most of the crop
  whatever the object's height (a third of the height difference still shows), magnified:
  grain, shaded bumps, fuzz and strands over the surface and the specular spot dominate;
- views in between mix both.

On top of that each view is a noisy measurement: lighting level and direction, object rotation
and camera offset vary, some views are out of focus on the object (``DEFOCUS_P``: fine grain and
fuzz wash out) and some have a dark gripper finger hanging into the crop in front of the object
(``OCCLUDE_P``). So one photograph tells part of the properties, and pooling an object's views
tells more (version 4's views differed only in rotation, lighting and offset and were
near-duplicates; the measurements of both versions are in ``synthetic``'s docstring).

``render_view`` returns the true plate geometry so tests can check a crop; ``render_object``
renders all views of one object.
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
VIEWS = 8  # photographs per object in PHAC-2
# camera elevation of view v (ELEVATION[v % 8]): 0 a low side view, 1 a high, close top view.
# Interleaved, so any first few views (pre-training renders 4) mix side and top views.
ELEVATION = (0.05, 0.95, 0.3, 0.8, 0.15, 1.0, 0.45, 0.65)
DEFOCUS_P = 0.3  # chance that a view is out of focus on the object
OCCLUDE_P = 0.3  # chance that a gripper finger hangs into the crop in front of the object
PROPERTIES = (
    "thickness", "size", "hue", "saturation", "value", "roughness", "texture_contrast",
    "bumpiness", "gloss", "metalness", "transparency", "hairiness",
)  # fmt: skip


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


def _check(props: Mapping[str, float]) -> None:
    missing = [k for k in PROPERTIES if k not in props]
    if missing:
        raise KeyError(f"render: latent properties {missing} missing (expected {PROPERTIES})")


def render_object(
    props: Mapping[str, float],
    *,
    width: int = 480,
    height: int = 320,
    seed: int | Sequence[int] = 0,
    views: int = VIEWS,
) -> list[View]:
    """All ``views`` photographs of one object, from its latent ``props`` alone.

    ``props`` needs the keys of ``PROPERTIES`` (values in [0, 1]); any object works, one of the
    60 or a newly drawn one. The same ``seed`` and props give the same images.
    """
    return [render_view(props, v, width, height, seed=seed) for v in range(views)]


def render_view(
    props: Mapping[str, float],
    view: int,
    width: int,
    height: int,
    seed: int | Sequence[int] = 0,
) -> View:
    """Render view ``view`` of an object with latent ``props`` at ``width`` x ``height``."""
    _check(props)
    seeds = [seed] if isinstance(seed, int) else list(seed)
    rng = np.random.default_rng([*seeds, 1000 + view])
    h, w = height, width
    light = rng.uniform(0.8, 1.15)
    light_dir = rng.uniform(-1, 1)
    elevation = float(np.clip(ELEVATION[view % len(ELEVATION)] + rng.normal(0, 0.05), 0, 1))

    # Background: dark blue wall above, brown table below, soft gradients.
    yy = np.linspace(0, 1, h, dtype=np.float32)[:, None, None]
    horizon = rng.uniform(0.35, 0.45)
    wall = np.array([105, 62, 38], np.float32) * (0.8 + 0.3 * yy / horizon)
    table = np.array([45, 75, 115], np.float32) * (0.75 + 0.35 * yy)
    img = np.repeat(np.where(yy < horizon, wall, table), w, axis=1)
    img += 6 * _smooth_noise(rng, h, w, (6, 9))[..., None]

    # Plate: near-circular ellipse, brushed aluminium.
    radius = min(0.27 * h * rng.uniform(0.95, 1.05), 0.4 * w)
    cx = w / 2 + rng.normal(0, 0.03 * w)
    cy = 0.64 * h + rng.normal(0, 0.02 * h)
    ry = radius * (0.82 + 0.08 * elevation) * rng.uniform(0.99, 1.01)  # rounder from above
    y = np.arange(h, dtype=np.float32)[:, None]
    x = np.arange(w, dtype=np.float32)[None, :]
    plate = ((x - cx) / radius) ** 2 + ((y - cy) / ry) ** 2 <= 1.0
    brushed = _smooth_noise(rng, h, w, (h // 2, max(w // 24, 2)))
    shade = PLATE_GREY * light * (1 + 0.05 * light_dir * (x - cx) / radius - 0.04 * (y - cy) / ry)
    plate_img = (shade[plate] + 3.0 * brushed[plate])[:, None] + np.array([3, 0, -2], np.float32)

    # Soft contact shadow under the object (on the plate; elsewhere the factor is 1).
    shadow = np.exp(-(((x - cx) / (0.6 * radius)) ** 2) - ((y - cy) / (0.25 * ry)) ** 2)
    plate_img *= (1 - 0.25 * shadow[plate])[:, None]
    img[plate] = plate_img

    _draw_object(img, props, rng, (cx, cy, radius), light, light_dir, elevation)
    if rng.random() < OCCLUDE_P:
        _draw_finger(img, rng, (cx, cy, radius), ry, light)
    img += rng.normal(0, 2.0, (h, w, 1)).astype(np.float32)
    image = np.clip(img, 0, 255).astype(np.uint8)
    return View(image, (float(cx), float(cy)), float(radius))


def _draw_object(
    img: np.ndarray,
    props: Mapping[str, float],
    rng: np.random.Generator,
    plate: tuple[float, float, float],
    light: float,
    light_dir: float,
    elevation: float,
) -> None:
    """Paint the object standing on the plate centre into ``img`` (float BGR, in place).

    ``elevation`` (0 side ... 1 top view) sets what the view shows: how much of the height
    (thickness) and how much of the surface detail (module docstring). Only a window around the
    object is computed, so large photographs stay cheap.
    """
    cx, cy, radius = plate
    h, w = img.shape[:2]
    hair = props["hairiness"]
    e = elevation
    near = 1 - e  # weight of what a side view shows
    detail = 0.1 + 0.9 * e  # surface detail: faint at a grazing angle, clear close up
    turn = abs(math.cos(rng.uniform(0, math.pi)))
    ow = radius * (0.38 + 0.45 * props["size"]) * (0.8 + 0.2 * turn)  # half width
    side_h = min(0.6 + 0.9 * props["thickness"], 1.5)  # side wall height, side view
    top_h = rng.uniform(0.95, 1.1)  # from above: the top face fills the crop, any height
    seen = 1 - 0.7 * e  # how much of the height shows: all from the side, some from above
    oh = radius * (seen * side_h + (1 - seen) * top_h)  # top face above the base, drawn
    top_ry = ow * (0.12 + 0.6 * e) * rng.uniform(0.9, 1.1)  # top face, rounder from above
    base_ry = ow * rng.uniform(0.22, 0.28)  # front rim of the base, on the plate
    reach = radius * (0.05 + 0.16 * hair)  # strands stick out this far
    x0, x1 = max(int(cx - ow - reach) - 2, 0), min(int(cx + ow + reach) + 3, w)
    y0, y1 = max(int(cy - oh - top_ry - reach) - 2, 0), min(int(cy + base_ry + reach) + 3, h)
    win = img[y0:y1, x0:x1].copy()  # contiguous, for cv2.line
    wh, ww = win.shape[:2]
    ocx, ocy = cx - x0, cy - y0  # object centre in window coordinates
    xs = np.arange(ww, dtype=np.float32)[None, :]
    ys = np.arange(wh, dtype=np.float32)[:, None]

    # Silhouette: side wall, front rim and top face; hair softens the outline.
    mask = np.zeros((wh, ww), np.uint8)
    c, top = (round(ocx), round(ocy)), (round(ocx), round(ocy - oh))
    axes = (max(round(ow), 1), max(round(top_ry), 1))
    cv2.rectangle(mask, (c[0] - axes[0], top[1]), (c[0] + axes[0], c[1]), 255, -1)
    cv2.ellipse(mask, c, (axes[0], max(round(base_ry), 1)), 0, 0, 180, 255, -1)
    cv2.ellipse(mask, top, axes, 0, 0, 360, 255, -1)
    soft = max(w / 800, 0.5) + 0.04 * hair * ow
    body = cv2.GaussianBlur(mask.astype(np.float32) / 255, (0, 0), soft)
    top_face = ((xs - ocx) / ow) ** 2 + ((ys - (ocy - oh)) / top_ry) ** 2 <= 1.0

    # Diffuse colour, cylinder shading, lit top face.
    grey = props["saturation"] < 0.3  # keep grey objects darker than the plate
    value = (0.25 + 0.6 * props["value"]) * (0.7 if grey else 1.0)
    colour = _hsv_to_bgr(props["hue"], props["saturation"], value)
    u = np.clip((xs - ocx) / max(ow, 1), -1, 1)
    cylinder = 0.72 + 0.28 * np.cos((u - 0.4 * light_dir) * math.pi / 2)
    lit = np.where(top_face, 1.12, cylinder)

    # Surface: grain (frequency ~ roughness, contrast ~ texture_contrast), shaded bumps, fuzz;
    # faint in side views, magnified (coarser cells in pixels) and clear in close top views.
    cell = max(ow / (8 + 40 * props["roughness"]), 1.5) * (1 + 1.2 * e)  # finer than the bumps
    grain = _smooth_noise(rng, wh, ww, (round(wh / cell), round(ww / cell)))
    tex = 1 + detail * (0.03 + 0.5 * props["texture_contrast"]) * grain
    bump_cell = max(ow / 3.5, 2)
    relief = _smooth_noise(rng, wh, ww, (round(wh / bump_cell), round(ww / bump_cell)))
    gy, gx = np.gradient(relief)
    slope = gx * light_dir - gy  # light from above, left or right
    slope /= float(slope.std()) + 1e-6
    tex *= 1 + detail * props["bumpiness"] * np.clip(slope, -1.1, 1.1)
    fuzz = rng.standard_normal((wh, ww)).astype(np.float32)
    tex *= 1 + 0.35 * detail * hair * cv2.GaussianBlur(fuzz, (0, 0), max(w / 1200, 0.4))
    obj = colour * (light * lit * tex)[..., None]

    # Metal: dark, bluish grey body with banded reflections of the surroundings.
    metal = props["metalness"]
    phase = rng.uniform(0, 2 * math.pi)
    bands = 0.25 + 0.85 * (0.5 + 0.5 * np.sin(5.5 * u + 1.5 * light_dir + phase)) ** 3
    cool = np.array([1.25, 1.0, 0.85], np.float32)  # reflected wall: bluish, unlike the plate
    steel = cool * np.float32(colour.mean() * 0.3 + 70) + 0.1 * colour
    reflection = steel * (light * np.where(top_face, 0.9, bands) * tex)[..., None]
    obj = (1 - metal) * obj + metal * reflection

    # Glass: the background shows through, a dark refracting rim at the sides.
    clear = 0.8 * props["transparency"]
    rim = np.exp(-(((1 - np.abs(u)) / 0.12) ** 2))
    obj = (1 - clear) * obj + clear * win * np.float32(0.92)
    obj *= (1 - 0.55 * props["transparency"] * rim)[..., None]

    # Specular streak: sharper and brighter with gloss, near-white on metal.
    gloss = props["gloss"]
    hx = ocx + 0.3 * light_dir * ow
    spread = (0.06 + 0.3 * (1 - gloss) ** 2) * ow
    side = np.clip((ys - (ocy - oh)) / max(oh, 1), 0, 1) * np.clip((ocy - ys) / (0.3 * oh), 0, 1)
    streak = np.exp(-(((xs - hx) / spread) ** 2)) * (0.35 + 0.65 * side)
    spot = np.exp(-(((xs - hx) / (2 * spread)) ** 2) - ((ys - (ocy - oh)) / (0.5 * top_ry)) ** 2)
    peak = 260 * gloss**2 + 160 * metal
    # the wall's streak shows best from the side, the top face's spot from above
    obj += (peak * np.maximum((0.4 + 0.6 * near) * streak, (0.4 + 0.8 * e) * spot))[..., None]

    win *= 1 - body[..., None]
    win += obj * body[..., None]

    # Hair strands: a fringe on the outline from the side, over the surface from above.
    strands = int(700 * hair**1.5)
    if strands:
        edge = cv2.morphologyEx(mask, cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)) > 0
        ey, ex = np.nonzero(edge)
        iy, ix = np.nonzero(mask)
        on_edge = rng.random(strands) < 0.9 - 0.7 * e
        pick_e = rng.integers(0, len(ey), strands)
        pick_i = rng.integers(0, len(iy), strands)
        py = np.where(on_edge, ey[pick_e], iy[pick_i])
        px = np.where(on_edge, ex[pick_e], ix[pick_i])
        ang = rng.uniform(0, 2 * math.pi, strands)
        # strands on the front rim point up or sideways: the plate in front stays clear
        ang = np.where((py > ocy) & (np.sin(ang) > 0), -ang, ang)
        length = radius * rng.uniform(0.02, 0.04 + 0.12 * hair, strands)
        tone = colour * rng.uniform(0.5, 1.5, (strands, 1))
        thick = max(1, round(w / 900))
        ends = np.stack([px + length * np.cos(ang), py + length * np.sin(ang)], axis=1)
        for i in range(strands):
            p0, p1 = (int(px[i]), int(py[i])), (int(ends[i, 0]), int(ends[i, 1]))
            cv2.line(win, p0, p1, tone[i].tolist(), thick, cv2.LINE_AA)
    if rng.random() < DEFOCUS_P:  # focused on the plate's rim: grain and fuzz wash out
        win = cv2.GaussianBlur(win, (0, 0), rng.uniform(0.6, 2.0) * max(w / 480, 0.25))
    img[y0:y1, x0:x1] = win


def _draw_finger(
    img: np.ndarray,
    rng: np.random.Generator,
    plate: tuple[float, float, float],
    plate_ry: float,
    light: float,
) -> None:
    """A dark gripper finger hanging from the top into the crop, in front of the object.

    It ends above the plate's far rim, so the plate (and the V1 crop found from it) is intact.
    """
    cx, cy, radius = plate
    h, w = img.shape[:2]
    half = radius * rng.uniform(0.12, 0.25)
    fx = cx + radius * rng.uniform(-0.7, 0.7)
    bottom = cy - plate_ry - radius * rng.uniform(0.05, 0.3)
    x0, x1 = max(int(fx - half), 0), min(int(fx + half) + 1, w)
    y1 = max(min(int(bottom), h), 0)
    if x1 <= x0 or y1 <= 0:
        return
    u = (np.arange(x0, x1, dtype=np.float32) - fx) / half  # -1 ... 1 across the finger
    tone = light * (40 + 25 * np.cos(u * math.pi / 2))  # dark anodised metal, rounded
    img[:y1, x0:x1] = tone[None, :, None] * np.array([1.05, 1.0, 0.95], np.float32)


def write_jpeg(path: Path, image: np.ndarray, quality: int = JPEG_QUALITY) -> None:
    """Write a BGR image as JPEG (deterministic bytes for identical input)."""
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise OSError(f"{path}: JPEG encoding failed for an image of shape {image.shape}")
    Path(path).write_bytes(buf.tobytes())
