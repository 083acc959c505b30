"""Photographs: plate geometry as returned, detectable by colour, object from the properties."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tactile_exp.data.render import View, render_view, write_jpeg
from tactile_exp.data.synthetic import SyntheticSpec, object_properties

PROPS = object_properties(SyntheticSpec(object_ids=(101, 406, 508, 703)))


def plate_like(image: np.ndarray) -> np.ndarray:
    """Light grey, low saturation: what the crop (V1) looks for."""
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    return (hsv[..., 1] < 40) & (hsv[..., 2] > 140)


@pytest.mark.parametrize("oid", sorted(PROPS))
@pytest.mark.parametrize(("width", "height"), [(96, 64), (480, 320), (300, 400)])
def test_plate_is_where_render_says(oid, width, height):
    view = render_view(PROPS[oid], 3, width, height, seed=(0, oid))
    assert isinstance(view, View)
    assert view.image.shape == (height, width, 3) and view.image.dtype == np.uint8
    (cx, cy), r = view.centre, view.radius
    assert r > 0.1 * min(width, height)
    assert cy - 1.5 * r >= 0 and cx - r >= 0 and cx + r <= width  # the V1 crop fits
    mask = plate_like(view.image)
    # front of the plate (below the object) is plate-coloured; beside the plate is not
    for ang in np.linspace(0.3, np.pi - 0.3, 7):
        x, y = cx + 0.75 * r * np.cos(ang), cy + 0.6 * r * np.sin(ang)
        assert mask[int(y), int(x)], (oid, ang)
    for x in (cx - 1.15 * r, cx + 1.15 * r):
        if 0 <= x < width:
            assert not mask[int(cy), int(x)]
    # a colour-based estimate recovers centre and radius from the plate's widest row
    ys, xs = np.nonzero(mask[int(cy) :, :])
    row = ys == np.bincount(ys).argmax()
    est_r = (xs[row].max() - xs[row].min() + 1) / 2
    est_cx = (xs[row].max() + xs[row].min()) / 2
    assert abs(est_r - r) <= 0.06 * r + 1.5 and abs(est_cx - cx) <= 0.05 * r + 1.5


def test_thickness_makes_the_object_taller_in_the_crop():
    base = dict(PROPS[508])
    thick = render_view({**base, "thickness": 0.95}, 0, 480, 320, seed=1)
    thin = render_view({**base, "thickness": 0.05}, 0, 480, 320, seed=1)
    assert thick.centre == thin.centre and thick.radius == thin.radius
    (cx, cy), r = thick.centre, thick.radius
    diff = np.abs(thick.image.astype(int) - thin.image.astype(int)).sum(axis=2) > 40
    crop = diff[int(cy - 1.5 * r) : int(cy - 0.5 * r), int(cx - r) : int(cx + r)]
    assert crop.mean() > 0.15  # the thick object fills the V1 crop; the thin one does not
    assert not diff[int(cy + 0.3 * r) :].any()  # the plate front is unchanged


def test_views_differ_and_renders_are_deterministic(tmp_path):
    a = render_view(PROPS[406], 0, 160, 120, seed=(0, 406))
    b = render_view(PROPS[406], 0, 160, 120, seed=(0, 406))
    c = render_view(PROPS[406], 1, 160, 120, seed=(0, 406))
    assert np.array_equal(a.image, b.image) and a.centre == b.centre
    assert not np.array_equal(a.image, c.image)
    write_jpeg(tmp_path / "a.jpg", a.image)
    write_jpeg(tmp_path / "b.jpg", b.image)
    assert (tmp_path / "a.jpg").read_bytes() == (tmp_path / "b.jpg").read_bytes()
    back = cv2.imread(str(tmp_path / "a.jpg"))
    assert back.shape == a.image.shape and np.abs(back.astype(int) - a.image).mean() < 4


def test_hairy_objects_get_strands_and_glossy_ones_a_highlight():
    base = dict(PROPS[508])
    plain = render_view({**base, "hairiness": 0.0, "gloss": 0.0}, 0, 480, 320, seed=2)
    hairy = render_view({**base, "hairiness": 1.0, "gloss": 0.0}, 0, 480, 320, seed=2)
    glossy = render_view({**base, "hairiness": 0.0, "gloss": 1.0}, 0, 480, 320, seed=2)

    def edges(v: View) -> float:
        return float(cv2.Canny(cv2.cvtColor(v.image, cv2.COLOR_BGR2GRAY), 80, 160).mean())

    assert edges(hairy) > 1.15 * edges(plain)
    assert glossy.image.astype(int).sum() > plain.image.astype(int).sum()


@pytest.mark.slow
def test_paper_resolution_renders():
    view = render_view(PROPS[406], 0, 3000, 2000, seed=0)
    assert view.image.shape == (2000, 3000, 3)
    assert plate_like(view.image)[int(view.centre[1] + 0.5 * view.radius), int(view.centre[0])]
