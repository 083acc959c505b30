"""Photographs: plate geometry as returned, detectable by colour, object from the properties."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tactile_exp.data.render import (
    ELEVATION,
    PROPERTIES,
    View,
    render_object,
    render_view,
    write_jpeg,
)
from tactile_exp.data.synthetic import (
    _MATERIAL_BASE,
    SyntheticSpec,
    draw_object_properties,
    object_properties,
)
from tactile_exp.preprocess.visual import crop_box, find_plate

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


def crop_stats(view: View) -> dict[str, float]:
    """Appearance of the object in the V1 crop's centre band (half a plate radius wide)."""
    (cx, cy), r = view.centre, view.radius
    band = view.image[
        int(cy - 1.5 * r) : int(cy - 0.5 * r), int(cx - 0.25 * r) : int(cx + 0.25 * r)
    ]
    hsv = cv2.cvtColor(band, cv2.COLOR_BGR2HSV).astype(float)
    grey = cv2.cvtColor(band, cv2.COLOR_BGR2GRAY).astype(np.float32)
    fine = np.abs(grey - cv2.GaussianBlur(grey, (0, 0), 1.0)).mean()
    coarse = np.abs(cv2.GaussianBlur(grey, (0, 0), 1.0) - cv2.GaussianBlur(grey, (0, 0), 4.0))
    return {
        "specular": float(((hsv[..., 2] > 235) & (hsv[..., 1] < 60)).mean()),
        "saturation": float(hsv[..., 1].mean()),
        "fine": float(fine),
        "coarse": float(coarse.mean()),
    }


# a thick, plain, matte object: every cue starts low, so one property at a time shows
PLAIN = {
    **PROPS[508], "thickness": 0.9, "hairiness": 0.0, "gloss": 0.0, "metalness": 0.0,
    "transparency": 0.0, "texture_contrast": 0.0, "roughness": 0.3, "bumpiness": 0.0,
    "saturation": 0.7,
}  # fmt: skip


def test_metal_and_gloss_raise_the_highlight_fraction_and_metal_greys():
    top_views = (1, 3, 5)  # lustre shows best from above (the top face's specular spot)
    views = {
        name: [render_view({**PLAIN, **change}, v, 240, 160, seed=3) for v in top_views]
        for name, change in (
            ("plain", {}),
            ("glossy", {"gloss": 1.0}),
            ("metal", {"metalness": 1.0, "gloss": 0.8}),
        )
    }
    stats = {k: [crop_stats(v) for v in vs] for k, vs in views.items()}
    for i in range(3):
        plain, glossy, metal = (stats[k][i] for k in ("plain", "glossy", "metal"))
        assert plain["specular"] < 0.005
        assert glossy["specular"] > 0.02 and metal["specular"] > 0.02
        assert metal["saturation"] < 0.7 * plain["saturation"]


def test_texture_and_bumps_follow_their_properties():
    def stats(change: dict[str, float]) -> dict[str, float]:  # view 1: a close top view
        return crop_stats(render_view({**PLAIN, **change}, 1, 240, 160, seed=4))

    plain = stats({})
    grain = stats({"texture_contrast": 1.0, "roughness": 1.0})
    bumps = stats({"bumpiness": 1.0})
    assert grain["fine"] > 2 * plain["fine"]
    assert bumps["coarse"] > 1.5 * plain["coarse"]


def test_side_views_show_height_top_views_show_surface():
    """Views differ in what they show: height from the side, grain and bumps from above."""
    side, top = 0, 1  # render.ELEVATION: 0.05 and 0.95

    def height_diff(view: int) -> float:
        thick = render_view({**PLAIN, "thickness": 0.95}, view, 480, 320, seed=1)
        thin = render_view({**PLAIN, "thickness": 0.05}, view, 480, 320, seed=1)
        (cx, cy), r = thick.centre, thick.radius
        diff = np.abs(thick.image.astype(int) - thin.image.astype(int)).sum(axis=2) > 40
        return float(diff[int(cy - 1.5 * r) : int(cy - 0.5 * r), int(cx - r) : int(cx + r)].mean())

    assert height_diff(side) > 1.4 * height_diff(top)  # from above a third of the height shows
    surface = {**PLAIN, "texture_contrast": 1.0, "roughness": 1.0, "bumpiness": 1.0}
    grain = [crop_stats(render_view(surface, v, 240, 160, seed=4)) for v in (side, top)]
    assert grain[1]["fine"] + grain[1]["coarse"] > 2 * (grain[0]["fine"] + grain[0]["coarse"])


def test_views_are_partial_measurements_deterministic_under_the_seed():
    """Each view draws its own elevation jitter, light, defocus and occluder from the seed."""
    a = render_object(PROPS[703], width=160, height=120, seed=(0, 703))
    b = render_object(PROPS[703], width=160, height=120, seed=(0, 703))
    c = render_object(PROPS[703], width=160, height=120, seed=(1, 703))
    assert all(np.array_equal(x.image, y.image) for x, y in zip(a, b, strict=True))
    assert not any(np.array_equal(x.image, y.image) for x, y in zip(a, c, strict=True))
    assert len(ELEVATION) == 8 and ELEVATION[0] < 0.5 < ELEVATION[1]  # side and top interleave


def test_hairy_objects_get_strands_beyond_their_outline():
    plain = render_view(PLAIN, 0, 480, 320, seed=2)
    hairy = render_view({**PLAIN, "hairiness": 1.0}, 0, 480, 320, seed=2)

    def edges(v: View) -> float:
        return float(cv2.Canny(cv2.cvtColor(v.image, cv2.COLOR_BGR2GRAY), 80, 160).mean())

    assert edges(hairy) > 1.3 * edges(plain)
    # strands cross the wall beside the object: the crop's outer columns change
    (cx, cy), r = plain.centre, plain.radius
    rows = slice(int(cy - 1.4 * r), int(cy - 0.6 * r))
    ow = r * (0.38 + 0.45 * PLAIN["size"])  # render.py's half width at most
    beside = slice(int(cx + ow + 2), int(cx + ow + 0.1 * r))
    diff = np.abs(hairy.image.astype(int) - plain.image.astype(int)).sum(axis=2) > 60
    assert diff[rows, beside].mean() > 0.02


def test_touch_only_properties_leave_the_photograph_alone():
    touch = {
        "stiffness": 0.0, "porosity": 1.0, "springiness": 1.0, "effusivity": 1.0,
        "stickiness": 1.0, "friction": 1.0, "crinkliness": 1.0, "contact_area": 1.5,
    }  # fmt: skip
    a = render_view(PROPS[101], 2, 160, 120, seed=5)
    b = render_view({**PROPS[101], **touch}, 2, 160, 120, seed=5)
    assert np.array_equal(a.image, b.image)


def test_render_object_from_newly_drawn_properties():
    rng = np.random.default_rng(11)
    for material in sorted(_MATERIAL_BASE):
        props = draw_object_properties(material, rng)
        assert set(props) == set(PROPS[101])  # drawn like the 60 objects
        assert all(0 <= props[k] <= 1 for k in PROPERTIES)
        views = render_object(props, width=160, height=120, seed=(7, 1))
        again = render_object(props, width=160, height=120, seed=(7, 1))
        assert len(views) == 8
        assert all(np.array_equal(a.image, b.image) for a, b in zip(views, again, strict=True))
        for view in views[:3]:
            plate = find_plate(cv2.cvtColor(view.image, cv2.COLOR_BGR2RGB))
            assert (
                np.hypot(plate.cx - view.centre[0], plate.cy - view.centre[1]) < 0.08 * view.radius
            )
            assert crop_box(view.image.shape, plate)[3] > 0
    same = [draw_object_properties("foam", np.random.default_rng(3)) for _ in range(2)]
    assert same[0] == same[1]
    metal = [draw_object_properties("metal", rng)["metalness"] for _ in range(20)]
    foam = [draw_object_properties("foam", rng)["metalness"] for _ in range(20)]
    assert np.mean(metal) > np.mean(foam) + 0.5
    with pytest.raises(ValueError, match="material 'wood'"):
        draw_object_properties("wood", rng)
    with pytest.raises(KeyError, match="metalness"):
        render_view({k: v for k, v in PROPS[101].items() if k != "metalness"}, 0, 96, 64)


@pytest.mark.slow
def test_paper_resolution_renders():
    view = render_view(PROPS[406], 0, 3000, 2000, seed=0)
    assert view.image.shape == (2000, 3000, 3)
    assert plate_like(view.image)[int(view.centre[1] + 0.5 * view.radius), int(view.centre[0])]
