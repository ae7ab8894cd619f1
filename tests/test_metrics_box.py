"""Where errors are measured: the object's screen box (metrics.screen_box),
shared by the bench and the figure of ``render --method all``."""

from __future__ import annotations

import numpy as np
import pytest

from aniso3d import metrics
from aniso3d.errors import InputError
from aniso3d.rendering.camera import Camera


def test_box_is_the_points_extent_grown_by_the_margin():
    xy = np.array([[20.2, 30.5], [60.7, 35.0], [40.0, 70.9]])
    # floor/ceil of the extent, then 8 pixels of margin each way.
    assert metrics.screen_box(xy, (200, 100)) == (20 - 8, 30 - 8, 61 + 8, 71 + 8)
    assert metrics.screen_box(xy, (200, 100), margin=0) == (20, 30, 61, 71)


def test_box_is_clamped_to_the_image_and_grown_to_its_minimum_side():
    assert metrics.screen_box(np.array([[-50.0, -5.0], [300.0, 90.0]]), (200, 100)) == (0, 0, 200, 98)
    # One point: a min_side box centred on it.
    assert metrics.screen_box(np.array([[50.0, 50.0]]), (200, 100), margin=0, min_side=16) == (42, 42, 58, 58)
    # Near the edge it slides inside instead of being cut.
    assert metrics.screen_box(np.array([[1.0, 98.0]]), (200, 100), margin=0, min_side=16) == (0, 84, 16, 100)
    # Wholly outside: still a box inside the image.
    x0, y0, x1, y1 = metrics.screen_box(np.array([[500.0, 500.0]]), (200, 100), min_side=16)
    assert 0 <= x0 < x1 <= 200 and 0 <= y0 < y1 <= 100 and (x1 - x0, y1 - y0) == (16, 16)
    # An image smaller than the minimum: the whole image.
    assert metrics.screen_box(np.array([[3.0, 3.0]]), (10, 12), min_side=16) == (0, 0, 10, 12)


def test_box_of_a_projected_cube_holds_its_corners():
    cube = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
    corners = np.array([[x, y, z] for x in cube[:, 0] for y in cube[:, 1] for z in cube[:, 2]])
    cam = Camera((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov=90.0)
    x0, y0, x1, y1 = metrics.screen_box(cam.project(corners, (200, 200)), (200, 200), margin=0)
    # The front face (half-size 1 at depth 4, tan(fov/2) = 1) reaches 1/4 of
    # the half-width of 100 pixels: 25 each side of the centre.
    assert (x0, y0, x1, y1) == (75, 75, 125, 125)


def test_compare_in_box_is_compare_of_the_crops():
    rng = np.random.default_rng(0)
    a = rng.integers(0, 256, (60, 80, 4), dtype=np.uint8)
    b = a.copy()
    b[:10] = 0  # differs outside the box only
    box = (10, 20, 70, 50)
    got = metrics.compare_in_box(a, b, box, with_flip=False)
    assert got["psnr"] == np.inf and got["ssim"] == pytest.approx(1.0)
    b[30, 40, 0] ^= 0xFF
    got = metrics.compare_in_box(a, b, box, with_flip=False)
    want = metrics.compare(a[20:50, 10:70, :3], b[20:50, 10:70, :3], with_flip=False)
    assert got["psnr"] == want["psnr"] < np.inf and got["ssim"] == want["ssim"]
    assert metrics.crop(a, box).shape == (30, 60, 3)


@pytest.mark.parametrize("xy", [np.zeros((0, 2)), np.array([[np.nan, 1.0]])])
def test_bad_points_are_refused(xy):
    with pytest.raises(InputError, match="screen_box"):
        metrics.screen_box(xy, (10, 10))
