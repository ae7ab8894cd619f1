"""Camera conventions, checked without a GPU."""

import numpy as np
import pytest

from aniso3d import InputError
from aniso3d.rendering.camera import Camera, turntable


def test_view_matrix_maps_eye_to_origin_and_target_down_minus_z():
    cam = Camera((1.0, 2.0, 3.0), (1.0, 2.0, -7.0))
    v = cam.view_matrix()
    eye = v @ np.array([1.0, 2.0, 3.0, 1.0])
    tgt = v @ np.array([1.0, 2.0, -7.0, 1.0])
    np.testing.assert_allclose(eye[:3], 0, atol=1e-12)
    np.testing.assert_allclose(tgt[:3], [0, 0, -10], atol=1e-12)


def test_local_origin_fold_is_exact_far_from_world_origin():
    far = np.array([1e7, -2e7, 3e7])
    cam = Camera(tuple(far + [0, 0, 5]), tuple(far))
    p_local = np.array([0.25, -0.5, 0.125])
    world = far + p_local
    a = cam.view_matrix(local_origin=far) @ np.append(p_local, 1)
    b = cam.view_matrix() @ np.append(world, 1)
    np.testing.assert_allclose(a[:3], [0.25, -0.5, -4.875], atol=1e-12)
    np.testing.assert_allclose(a[:3], b[:3], atol=1e-8)


def test_projection_puts_target_at_centre_and_fov_edge_at_border():
    cam = Camera((0, 0, 10), (0, 0, 0), fov=60)
    size = (200, 100)
    top = 10 * np.tan(np.radians(30))
    px = cam.project(np.array([[0, 0, 0], [0, top, 0]]), size)
    np.testing.assert_allclose(px[0], [100, 50], atol=1e-9)
    np.testing.assert_allclose(px[1], [100, 0], atol=1e-9)


def test_ray_directions_agree_with_projection():
    cam = Camera((3, 1, 4), (0, 0.5, 0), fov=50)
    size = (64, 48)
    rays = cam.ray_directions(size)
    pts = np.asarray(cam.position) + rays.reshape(-1, 3) * 7.0
    px = cam.project(pts, size)
    ys, xs = np.mgrid[0:48, 0:64]
    np.testing.assert_allclose(px[:, 0], xs.ravel() + 0.5, atol=1e-6)
    np.testing.assert_allclose(px[:, 1], ys.ravel() + 0.5, atol=1e-6)


def test_clip_range_covers_bounds_and_stays_positive_inside():
    b = np.array([[-1.0, -1, -1], [1, 1, 1]])
    near, far = Camera((0, 0, 10), (0, 0, 0)).clip_range(b)
    assert 0 < near < 10 - np.sqrt(3) and far > 10 + np.sqrt(3)
    near, far = Camera((0, 0, 0.1), (0, 0, 0)).clip_range(b)  # inside the box
    assert near > 0 and far > near and near < 1e-2


def test_frame_fits_bounds_and_orbit_keeps_distance():
    b = np.array([[10.0, 0, 0], [12, 4, 2]])
    cam = Camera.frame(b, fov=40)
    corners = np.array([[x, y, z] for x in b[:, 0] for y in b[:, 1] for z in b[:, 2]])
    px = cam.project(corners, (100, 100), bounds=b)
    assert px.min() >= 0 and px.max() <= 100
    d0 = np.linalg.norm(np.subtract(cam.position, cam.target))
    for c in turntable(cam, 8):
        assert np.isclose(np.linalg.norm(np.subtract(c.position, c.target)), d0)
    np.testing.assert_allclose(cam.orbit(360).position, cam.position, atol=1e-9)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"position": (0, 0, 0), "target": (0, 0, 0)},
        {"position": (0, 5, 0), "target": (0, 0, 0), "up": (0, 1, 0)},
        {"fov": 0},
        {"fov": 180},
        {"position": (np.nan, 0, 0)},
        {"near": -1},
    ],
)
def test_bad_cameras_are_refused(kwargs):
    with pytest.raises(InputError):
        Camera(**kwargs)


@pytest.mark.parametrize("aspect", [0.5, 1.0, 2.0])
def test_fit_puts_every_corner_inside_and_touches_an_edge(aspect):
    b = np.array([[0.0, 0, 0], [3, 1, 0.5]])
    size = (int(200 * aspect), 200)
    cam = Camera.fit(b, direction=(0.3, 0.4, 1.0), fov=40, aspect=aspect, margin=1.1)
    corners = np.array([[x, y, z] for x in b[:, 0] for y in b[:, 1] for z in b[:, 2]])
    px = cam.project(corners, size, bounds=b)
    assert px[:, 0].min() >= 0 and px[:, 0].max() <= size[0]
    assert px[:, 1].min() >= 0 and px[:, 1].max() <= size[1]
    # Tight: some corner reaches within the 10% margin of a border.
    slack = np.minimum(np.minimum(px[:, 0], size[0] - px[:, 0]) / size[0],
                       np.minimum(px[:, 1], size[1] - px[:, 1]) / size[1])  # fmt: skip
    assert slack.min() < 0.1


def test_fit_to_points_frames_and_centres_them():
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(2000, 3)) * [3.0, 1.0, 0.5] + [4.0, 0.0, 0.0]
    b = np.array([pts.min(0) - [0, 0, 5], pts.max(0)])  # a box the points do not fill
    size = (300, 200)
    cam = Camera.fit(b, direction=(0.2, 0.3, 1.0), fov=40, aspect=1.5, margin=1.1, points=pts)
    px = cam.project(pts, size, bounds=b)
    assert px[:, 0].min() >= 0 and px[:, 0].max() <= size[0]
    assert px[:, 1].min() >= 0 and px[:, 1].max() <= size[1]
    # Centred within a few pixels (perspective makes it approximate).
    assert abs(0.5 * (px[:, 0].min() + px[:, 0].max()) - size[0] / 2) < 0.05 * size[0]
    assert abs(0.5 * (px[:, 1].min() + px[:, 1].max()) - size[1] / 2) < 0.05 * size[1]
    # Tighter than fitting the box.
    box = Camera.fit(b, direction=(0.2, 0.3, 1.0), fov=40, aspect=1.5, margin=1.1)
    assert np.linalg.norm(np.subtract(cam.position, cam.target)) < np.linalg.norm(
        np.subtract(box.position, box.target)
    )
