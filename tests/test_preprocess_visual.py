"""Visual preprocessing (METHOD.md V1-V2): plate detection, crop geometry, network input, cache."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tactile_exp.data import render
from tactile_exp.data.layout import TrialName
from tactile_exp.data.synthetic import SyntheticSpec, object_properties
from tactile_exp.preprocess import visual
from tactile_exp.preprocess.visual import (
    Plate,
    crop_plate,
    find_plate,
    load_visual_arrays,
    resize_square,
)

GREY = (175, 178, 182)  # brushed aluminium: light grey, low saturation


def scene(w: int, h: int, cx: int, cy: int, r: int, object_colour=(200, 40, 30)) -> np.ndarray:
    """White-ish backdrop, a grey plate, a coloured object standing on the plate."""
    image = np.full((h, w, 3), (245, 243, 240), dtype=np.uint8)
    cv2.rectangle(image, (0, cy), (w, h), (90, 70, 50), -1)  # dark table under the plate
    cv2.circle(image, (cx, cy), r, GREY, -1, lineType=cv2.LINE_AA)
    if object_colour is not None:  # covers the plate's top middle, as the object would
        cv2.rectangle(image, (cx - r // 2, cy - int(1.6 * r)), (cx + r // 2, cy), object_colour, -1)
    return image


@pytest.mark.parametrize(
    ("w", "h", "cx", "cy", "r"), [(400, 300, 210, 190, 70), (1500, 1000, 700, 640, 260)]
)
def test_find_plate_on_drawn_circle(w, h, cx, cy, r):
    plate = find_plate(scene(w, h, cx, cy, r))
    assert isinstance(plate, tuple) and len(plate) == 3
    assert abs(plate.cx - cx) < 0.03 * r and abs(plate.cy - cy) < 0.03 * r
    assert abs(plate.r - r) < 0.05 * r


# metal and glass objects are grey themselves; 503 (loofah) is hairy; 101 a coloured sponge
RENDERED = (703, 702, 601, 503, 101)


@pytest.fixture(scope="module")
def properties() -> dict[int, dict[str, float]]:
    return object_properties(SyntheticSpec(object_ids=RENDERED))


@pytest.mark.parametrize(("w", "h"), [(480, 320), (1500, 1000)])
def test_find_plate_on_rendered_views(properties, w, h):
    for oid in RENDERED:
        view = render.render_view(properties[oid], oid % 8, w, h, seed=(0, oid))
        plate = find_plate(cv2.cvtColor(view.image, cv2.COLOR_BGR2RGB))
        r = view.radius
        assert np.hypot(plate.cx - view.centre[0], plate.cy - view.centre[1]) < 0.05 * r, oid
        assert abs(plate.r - r) < 0.1 * r, oid


def test_find_plate_on_tiny_rendered_views(properties):
    """The test data's 96x64 photographs: a radius of ~17 px, so looser bounds."""
    for oid in RENDERED:
        for v in range(4):
            view = render.render_view(properties[oid], v, 96, 64, seed=(0, oid))
            plate = find_plate(cv2.cvtColor(view.image, cv2.COLOR_BGR2RGB))
            r = view.radius
            assert np.hypot(plate.cx - view.centre[0], plate.cy - view.centre[1]) < 0.15 * r
            assert abs(plate.r - r) < 0.1 * r


def test_crop_geometry():
    image = np.arange(300 * 400 * 3, dtype=np.uint32).reshape(300, 400, 3).astype(np.uint8)
    crop = crop_plate(image, Plate(200.0, 220.0, 60.0))
    assert crop.shape == (60, 120, 3)  # height R, width 2R
    np.testing.assert_array_equal(crop, image[130:190, 140:260])  # centre R above the plate
    padded = crop_plate(image, Plate(30.0, 70.0, 60.0))  # near the top-left corner
    assert padded.shape == (60, 120, 3)  # still 2R x R: padded, not clipped
    np.testing.assert_array_equal(padded[20:, 30:], image[0:40, 0:90])  # the part inside
    np.testing.assert_array_equal(padded[:20, 30:], np.broadcast_to(image[0, 0:90], (20, 90, 3)))
    np.testing.assert_array_equal(padded[20:, :30], np.repeat(image[0:40, :1], 30, axis=1))
    with pytest.raises(ValueError, match="outside"):
        crop_plate(image, Plate(200.0, -100.0, 50.0))


def test_crop_holds_the_object():
    image = scene(400, 300, 200, 220, 60, object_colour=(20, 200, 40))
    crop = crop_plate(image, find_plate(image))
    assert crop.shape[0] == pytest.approx(60, abs=3) and crop.shape[1] == pytest.approx(120, abs=5)
    green = (crop[..., 1] > 150) & (crop[..., 0] < 60)
    assert green[:, crop.shape[1] // 2].mean() > 0.9  # the object fills the crop's centre column


def test_no_plate_raises_clear_error():
    red = np.zeros((200, 300, 3), np.uint8)
    red[..., 0] = 220
    with pytest.raises(ValueError, match="no plate found"):
        find_plate(red)
    with pytest.raises(ValueError, match="no plate found"):
        find_plate(np.full((200, 300, 3), 250, np.uint8))  # white is not aluminium
    with pytest.raises(ValueError, match=r"\(H, W, 3\) uint8"):
        find_plate(np.zeros((20, 30), np.uint8))


def test_resize_square_keeps_colours_and_orientation():
    """V2's resize: enlarging (linear) and shrinking (area) keep a flat colour exactly and the
    image's left-right order (no transposed axes); the mean is subtracted later, in the trunk's
    input (``preprocess.trunk.network_input``)."""
    image = np.empty((90, 130, 3), np.uint8)
    image[:] = (200, 100, 50)
    out = resize_square(image)
    assert out.shape == (224, 224, 3) and out.dtype == np.uint8
    assert (out == (200, 100, 50)).all()
    gradient = np.tile(np.arange(256, dtype=np.uint8)[None, :, None], (64, 1, 3))
    small = resize_square(gradient, size=16)
    assert small.shape == (16, 16, 3) and np.all(np.diff(small[0, :, 0].astype(int)) > 0)
    with pytest.raises(ValueError, match=r"\(H, W, 3\) uint8"):
        resize_square(np.zeros((20, 30), np.uint8))


class PhotoDataset:
    def __init__(self, folder: Path, photos: dict[int, list[Path]], objects: list[int]) -> None:
        self.trials = tuple(TrialName(f"thing_{o}_01", f"thing_{o}", o, 1) for o in objects)
        self._photos = photos
        self.folder = folder

    def photographs(self) -> dict[int, list[Path]]:
        return self._photos

    def identity(self) -> str:
        return "photos-1"


def test_visual_arrays_cached_and_missing_listed(tmp_path, monkeypatch):
    photos: dict[int, list[Path]] = {}
    for obj, views in ((101, 2), (508, 1)):
        for v in range(views):
            path = tmp_path / f"obj_{obj}_{v}.jpg"
            image = scene(320, 240, 150 + 10 * v, 170, 50, object_colour=(obj % 256, 30, 200))
            cv2.imwrite(str(path), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
            photos.setdefault(obj, []).append(path)
    ds = PhotoDataset(tmp_path, photos, [101, 508, 703])
    reads = []
    real_load = visual.load_photograph
    monkeypatch.setattr(visual, "load_photograph", lambda p: reads.append(p) or real_load(p))
    first = load_visual_arrays(ds, size=32, cache_dir=tmp_path / "cache")
    assert len(reads) == 3
    assert first.images.shape == (3, 3, 32, 32) and first.images.dtype == np.uint8
    np.testing.assert_array_equal(first.object_id, [101, 101, 508])
    np.testing.assert_array_equal(first.view, [0, 1, 0])
    np.testing.assert_array_equal(first.missing, [703])
    np.testing.assert_allclose(first.plate[:, 2], 50, rtol=0.05)
    np.testing.assert_allclose(first.plate[:, 0], [150, 160, 150], atol=2)

    second = load_visual_arrays(ds, size=32, cache_dir=tmp_path / "cache")
    assert len(reads) == 3  # served from the cache
    np.testing.assert_array_equal(second.images, first.images)
    np.testing.assert_array_equal(second.name, first.name)

    mean = second.channel_mean(np.array([0, 1]))
    assert mean.shape == (3,)
    centred = second.images[:2].astype(np.float64) - mean.reshape(1, 3, 1, 1)
    np.testing.assert_allclose(centred.mean(axis=(0, 2, 3)), 0, atol=1e-9)
    assert np.ptp(mean) > 1  # the channels differ: a per-channel mean, not one number


def test_visual_arrays_on_synthetic_file(tmp_path):
    from tactile_exp.data.phac2 import PHAC2
    from tactile_exp.data.synthetic import SyntheticSpec, generate

    spec = SyntheticSpec(
        object_ids=(101, 508, 703), trials=1, duration_scale=0.1, views=2,
        image_width=96, image_height=64,
    )  # fmt: skip
    path = generate(tmp_path / "phac2.h5", spec)
    for photo in (tmp_path / "photographs").glob("brick_508_*.jpg"):
        photo.unlink()  # an object without photographs still counts for haptics
    arrays = load_visual_arrays(PHAC2(path), size=48, cache_dir=tmp_path / "cache")
    np.testing.assert_array_equal(arrays.object_id, [101, 101, 703, 703])
    np.testing.assert_array_equal(arrays.view, [0, 1, 0, 1])
    np.testing.assert_array_equal(arrays.missing, [508])
    assert arrays.images.shape == (4, 3, 48, 48)
    np.testing.assert_allclose(arrays.plate[:, 2], 0.27 * 64, rtol=0.15)  # render.py's radius
