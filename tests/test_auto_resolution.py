"""``--resolution auto``: the texture resolution a view needs
(:func:`needed_resolution`, against closed forms), and the Renderer building
it once and taking coarser ones from its pyramid."""

from __future__ import annotations

import math

import numpy as np
import pytest

from aniso3d import ResourceError, scenes
from aniso3d.build.pyramid import pyramid
from aniso3d.build.texture import build_texture
from aniso3d.errors import InputError
from aniso3d.rendering.camera import Camera, turntable
from aniso3d.rendering.renderer import BuildOptions, Renderer
from aniso3d.rendering.select import AUTO_MAX_RESOLUTION, AUTO_MIN_RESOLUTION, nearest_depth, needed_resolution

CUBE = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])


def head_on(d: float, fov: float) -> Camera:
    """A camera on +z looking at the cube's centre, its front face d away."""
    return Camera((0.0, 0.0, 1.0 + d), (0.0, 0.0, 0.0), fov=fov)


@pytest.mark.parametrize(
    "d, fov, height, expected",
    [
        # fov 90: a pixel at depth d spans 2d/H, the cube's extent 2 needs H/d voxels.
        (4.0, 90.0, 256, 64),  # exactly 64
        (3.0, 90.0, 256, 128),  # 85.3 -> 128
        (5.0, 90.0, 256, 64),  # 51.2 -> 64
        (4.0, 90.0, 512, 128),  # twice the pixels, twice the voxels
        # fov 60: H sqrt(3) / d voxels.
        (math.sqrt(3.0) * 300 / 32 * 1.001, 60.0, 300, 32),  # just under 32
        (math.sqrt(3.0) * 300 / 32 * 0.999, 60.0, 300, 64),  # just over 32
    ],
)
def test_head_on_camera_matches_the_closed_form(d, fov, height, expected):
    cam = head_on(d, fov)
    assert nearest_depth(cam, CUBE) == pytest.approx(d)
    for width in (1, height, 3 * height):  # only the height counts
        assert needed_resolution(cam, (width, height), CUBE) == expected


def test_diagonal_camera_sees_the_nearest_corner_first():
    D = 10.0
    eye = np.ones(3) / math.sqrt(3.0) * D
    cam = Camera(tuple(eye), (0.0, 0.0, 0.0), fov=40.0)
    z = D - math.sqrt(3.0)  # depth of the corner (1, 1, 1)
    assert nearest_depth(cam, CUBE) == pytest.approx(z)
    voxels = 2.0 / (z * 2 * math.tan(math.radians(20.0)) / 400)
    assert needed_resolution(cam, (400, 400), CUBE) == 2 ** math.ceil(math.log2(voxels))


def test_the_longest_extent_counts_and_the_result_is_the_coarsest_fine_enough():
    box = np.array([[0.0, 0.0, 0.0], [8.0, 1.0, 0.5]])
    rng = np.random.default_rng(3)
    for _ in range(50):
        target = rng.uniform(box[0], box[1])
        eye = target + rng.normal(size=3) * rng.uniform(5, 200)
        cam = Camera(tuple(eye), tuple(target), fov=float(rng.uniform(10, 120)))
        h = int(rng.integers(32, 2048))
        res = needed_resolution(cam, (h, h), box)
        z = nearest_depth(cam, box)
        per_voxel = 8.0 * h / (2 * z * math.tan(math.radians(cam.fov) / 2)) if z > 0 else math.inf
        assert res & (res - 1) == 0 and AUTO_MIN_RESOLUTION <= res <= AUTO_MAX_RESOLUTION
        if z > 0:
            assert res == AUTO_MAX_RESOLUTION or per_voxel / res <= 1.0 + 1e-9, "voxels larger than a pixel"
            assert res == AUTO_MIN_RESOLUTION or per_voxel / (res / 2) > 1.0, "half as many voxels would do"


def test_clamps_eye_inside_box_behind_and_near_plane():
    assert needed_resolution(head_on(1e-6, 40.0), (64, 64), CUBE) == AUTO_MAX_RESOLUTION
    inside = Camera((0.0, 0.0, 0.5), (0.0, 0.0, 0.0))
    assert nearest_depth(inside, CUBE) == 0.0 and needed_resolution(inside, (64, 64), CUBE) == AUTO_MAX_RESOLUTION
    behind = Camera((0.0, 0.0, 5.0), (0.0, 0.0, 10.0))
    assert nearest_depth(behind, CUBE) == math.inf
    assert needed_resolution(behind, (64, 64), CUBE) == AUTO_MIN_RESOLUTION
    assert needed_resolution(head_on(1e6, 40.0), (64, 64), CUBE) == AUTO_MIN_RESOLUTION
    # A near plane hides what is nearer: the depth is raised to it.
    clipped = Camera((0.0, 0.0, 0.5), (0.0, 0.0, 0.0), fov=90.0, near=4.0)
    assert nearest_depth(clipped, CUBE) == 4.0
    assert needed_resolution(clipped, (256, 256), CUBE) == 64
    assert needed_resolution(head_on(4.0, 90.0), (256, 256), CUBE, minimum=2, maximum=32) == 32


@pytest.mark.parametrize(
    "args, match",
    [
        (("camera", (64, 64), CUBE), "Camera"),
        ((head_on(1, 40), (0, 64), CUBE), "size"),
        ((head_on(1, 40), (64, 64), np.zeros(3)), "bounds"),
        ((head_on(1, 40), (64, 64), np.array([[1.0, 0, 0], [0, 1, 1]])), "bounds"),
        ((head_on(1, 40), (64, 64), np.array([[np.nan, 0, 0], [1, 1, 1]])), "bounds"),
    ],
)
def test_bad_arguments_are_one_clear_error(args, match):
    with pytest.raises(InputError, match=match):
        needed_resolution(*args)
    with pytest.raises(InputError, match="maximum"):
        needed_resolution(head_on(1, 40), (64, 64), CUBE, minimum=16, maximum=8)


def test_build_options_take_auto():
    assert BuildOptions(resolution="auto").resolution == "auto"
    with pytest.raises(InputError, match="'auto'"):
        BuildOptions(resolution="fine")


# ----------------------------------------------------------------- renderer


@pytest.fixture(scope="module")
def r():
    try:
        renderer = Renderer((64, 64))
    except ResourceError as exc:
        pytest.skip(str(exc))
    yield renderer
    renderer.release()


@pytest.mark.gpu
def test_render_auto_builds_once_and_takes_coarser_levels_from_the_pyramid(r):
    mesh = scenes.sphere()
    K = 8
    near = Camera.frame(mesh.bounds)
    far = Camera.frame(mesh.bounds, distance_scale=4.0)
    r_near = needed_resolution(near, r.size, mesh.bounds)
    r_far = needed_resolution(far, r.size, mesh.bounds)
    assert r_near > r_far  # 64 and 16 for this sphere in 64 x 64 pixels

    r.render(mesh, near, "volume", resolution="auto", directions=K)
    fine = r.conversions.get(mesh, ("texture", r_near, K))
    assert fine is not None and fine.resolution == r_near
    img = r.render(mesh, far, "volume", resolution="auto", directions=K)
    coarse = r.conversions.get(mesh, ("texture", r_far, K))
    level = int(math.log2(r_near // r_far))
    assert coarse is r.conversions.get(fine, ("pyramid",))[level], "the far texture was built again"
    # The level is the texture a build at that resolution gives (to rounding).
    direct = r.render(build_texture(mesh, r_far, K), far, "volume")
    assert np.abs(img.astype(int) - direct.astype(int)).max() <= 1
    assert coarse.n_voxels == pyramid(build_texture(mesh, r_near, K))[level].n_voxels


@pytest.mark.gpu
def test_auto_needs_a_camera_and_paths_take_the_finest(r, tmp_path):
    mesh = scenes.cube()
    with pytest.raises(InputError, match="needs a camera"):
        r.upload(mesh, "splat", resolution="auto")
    with pytest.raises(InputError, match="needs a camera"):
        r.pyramid(mesh, resolution="auto")
    r.render(mesh, Camera.frame(mesh.bounds), "mesh", resolution="auto")  # polygons: no texture at all

    base = Camera.frame(mesh.bounds, distance_scale=8.0)
    cams = [base, Camera(base.position, base.target, fov=10.0)] + turntable(base, 2)
    needs = [needed_resolution(c, (48, 48), mesh.bounds) for c in cams]
    assert len(set(needs)) > 1
    r.render_path(mesh, cams, tmp_path, "splat", size=(48, 48), build=BuildOptions(resolution="auto", directions=4))
    made = {k[1] for k, v in r.conversions.items() if k[0] == "texture" and k[2] == 4}
    assert made == {max(needs)}, "one texture, the finest any frame needs"
    assert len(list(tmp_path.glob("*.png"))) == len(cams)
