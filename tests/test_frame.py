"""``Renderer.render_frame``: colour as ``render`` gives it, depth against the
closed form of a plane, and the statistics against independent counts."""

from __future__ import annotations

import math

import numpy as np
import pytest

import aniso3d
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.frame import DrawStats, Frame, view_depth
from aniso3d.rendering.select import select_voxels
from aniso3d.rendering.splat import DEFAULT_PUSH, shape_extent

SIZE = (96, 80)


@pytest.fixture(scope="module")
def quad():
    """A 2 x 2 quad in the plane z = 0 facing +z, its 16^3 texture and points."""
    mesh = aniso3d.scenes.quad(2.0)
    tex = aniso3d.build_texture(mesh, 16, 16)
    return mesh, tex, tex.to_points()


@pytest.fixture(scope="module")
def rf():
    from aniso3d import ResourceError
    from aniso3d.rendering.renderer import Renderer

    try:
        renderer = Renderer(SIZE)
    except ResourceError as exc:
        pytest.skip(str(exc))
    yield renderer
    renderer.release()


CAMERA = Camera((0.4, 0.3, 3.0), (0.1, 0.0, 0.0), fov=40.0)


def plane_depth(cam: Camera, size) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed form for the plane z = 0: per pixel centre, the view-axis depth
    of the ray's hit, the hit point (H, W, 3), and the ray's view-axis
    component over |d_z| (what a chord of thickness h along z becomes in
    view depth, per unit h)."""
    d = cam.ray_directions(size)  # (H, W, 3) unit, row 0 at the top
    e = np.asarray(cam.position, dtype=np.float64)
    t = -e[2] / d[..., 2]
    along = d @ np.asarray(cam.forward)
    return t * along, e + t[..., None] * d, along / np.abs(d[..., 2])


def regions(hit: np.ndarray, margin: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Pixels whose ray hits the quad well inside its edges, and well outside."""
    a = np.abs(hit[..., :2])
    return np.all(a < 1.0 - margin, axis=-1), np.any(a > 1.0 + margin, axis=-1)


# -------------------------------------------------------------- no GPU


def test_view_depth_inverts_the_perspective_window_depth():
    near, far = 0.5, 20.0
    z = np.array([near, 0.7, 3.0, 19.0])
    window = far * (z - near) / (z * (far - near))
    assert np.allclose(view_depth(window, near, far), z, rtol=1e-6)
    out = view_depth(np.array([1.0, np.nan, 0.0]), near, far)
    assert out.dtype == np.float32 and np.isinf(out[0]) and np.isinf(out[1]) and out[2] == near


# ----------------------------------------------------------------- GPU


@pytest.mark.gpu
@pytest.mark.parametrize("method", ["mesh", "splat"])
def test_depth_of_a_quad_is_the_closed_form(rf, quad, method):
    """Polygons and "fast" splats write each pixel's exact depth: the ray's
    hit with the plane, to float32 and 24-bit depth precision (measured
    1.4e-7 and 2.6e-7 relative; 1e-5 is 1/2000 of a pixel's footprint)."""
    mesh, _, points = quad
    thing = mesh if method == "mesh" else points
    frame = rf.render_frame(thing, CAMERA, method)
    z, hit, _ = plane_depth(CAMERA, SIZE)
    inside, outside = regions(hit)
    assert isinstance(frame, Frame) and frame.depth.dtype == np.float32
    assert frame.depth.shape == SIZE[::-1] and not np.isnan(frame.depth).any()
    assert inside.sum() > 1000 and outside.sum() > 500
    np.testing.assert_allclose(frame.depth[inside], z[inside], rtol=1e-5)
    assert np.isinf(frame.depth[outside]).all() and (frame.depth[outside] > 0).all()
    # Supersampled: each pixel keeps the nearest of its samples.
    frame2 = rf.render_frame(thing, CAMERA, method, ssaa=2)
    z2, hit2, _ = plane_depth(CAMERA, (2 * SIZE[0], 2 * SIZE[1]))
    nearest = z2.reshape(SIZE[1], 2, SIZE[0], 2).min(axis=(1, 3))
    np.testing.assert_allclose(frame2.depth[inside], nearest[inside], rtol=1e-5)
    assert not np.allclose(nearest[inside], z[inside], rtol=1e-5)  # the test tells them apart


@pytest.mark.gpu
@pytest.mark.parametrize("quality", ["high", "blend"])
def test_blended_splats_write_their_pushed_visibility_depth(rf, quad, quality):
    """"high" and "blend" keep the visibility pass's depth: the surface pushed
    back along the view axis by at most ``push`` times a splat's larger
    half-axis."""
    _, _, points = quad
    frame = rf.render_frame(points, CAMERA, "splat", quality=quality)
    z, hit, _ = plane_depth(CAMERA, SIZE)
    inside, outside = regions(hit)
    push = DEFAULT_PUSH * max(shape_extent("square", 1.3)) * math.sqrt(points.areas.max())
    gap = frame.depth[inside] - z[inside]
    assert gap.min() > -1e-5 * z.max() and gap.max() <= push * (1 + 1e-4)
    assert gap.max() > 0.5 * push  # it is pushed, not the surface itself
    assert np.isinf(frame.depth[outside]).all() and not np.isnan(frame.depth).any()


@pytest.mark.gpu
def test_volume_depth_lies_in_the_quads_voxel_layer(rf, quad):
    """The volume writes where the opacity reaches one half: inside the one
    layer of voxels that holds the plane, so within one voxel chord of it."""
    _, tex, _ = quad
    frame = rf.render_frame(tex, CAMERA, "volume", opacity="linear")
    z, hit, chord = plane_depth(CAMERA, SIZE)
    inside, outside = regions(hit, margin=tex.voxel_size)
    err = np.abs(frame.depth[inside] - z[inside])
    assert err.max() <= tex.voxel_size * chord[inside].max()
    assert np.isinf(frame.depth[outside]).all() and not np.isnan(frame.depth).any()


@pytest.mark.gpu
def test_frame_colour_is_what_render_returns_and_stats_count_what_was_drawn(rf, quad):
    mesh, tex, points = quad
    cases = [(mesh, "mesh", "triangles", mesh.n_faces), (points, "splat", "points", len(points)),
             (tex, "volume", "voxels", tex.n_voxels)]  # fmt: skip
    for thing, method, unit, count in cases:
        frame = rf.render_frame(thing, CAMERA, method, alpha=True)
        assert frame.seconds == rf.last_frame_seconds > 0
        assert np.array_equal(frame.color, rf.render(thing, CAMERA, method, alpha=True))
        assert frame.stats == DrawStats(drawn=count, unit=unit) and frame.stats.lod is None


@pytest.mark.gpu
@pytest.mark.parametrize("distance", [1.0, 6.0])
def test_lod_frame_stats_count_the_selected_points(rf, distance):
    """A pyramid frame draws the points of the voxels ``select_voxels`` picks
    for the same view: counted here from the level clouds' offsets."""
    tree = aniso3d.scenes.tree(levels=4, leaves_per_twig=20)
    tex = aniso3d.build_texture(tree, 32, 16)
    cam = Camera.fit(tree.bounds, distance_scale=distance)
    frame = rf.render_frame(tex, cam, "splat", lod=True, pixel_error=2.0)
    pyr = rf.pyramid(tex)
    near, far = cam.clip_range(rf.upload(tex, "splat", lod=True).bounds)
    sel = select_voxels(pyr, cam, SIZE, 2.0, near=near, far=far)
    per_level = []
    for lvl, vox in enumerate(sel.voxels):
        off = pyr.level_cloud(lvl)[1]
        per_level.append(int((off[vox + 1] - off[vox]).sum()))
    assert frame.stats.drawn == sum(per_level) > 0
    assert frame.stats.levels == tuple(lvl for lvl, n in enumerate(per_level) if n)
    assert frame.stats.lod["points_per_level"] == per_level and frame.stats.lod == rf.last_lod_stats
    # The volume marches one level: all of its voxels.
    frame = rf.render_frame(tex, cam, "volume", lod=True, pixel_error=2.0)
    (level,) = frame.stats.levels
    assert frame.stats.drawn == pyr[level].n_voxels and frame.stats.lod["level"] == level


@pytest.mark.parametrize("s", [2, 3, 8, 260])
def test_supersampling_filter_in_integers_is_the_mean_rounded(s):
    """The box filter sums a uint8 frame in integers (uint16 rows, uint32
    past 257 samples a side); each pixel is its samples' mean rounded half
    to even, as the float mean of the samples gives it."""
    rng = np.random.default_rng(s)
    h, w = (3, 2) if s > 8 else (17, 11)
    img = rng.integers(0, 256, (h * s, w * s, 4), dtype=np.uint8)
    img[:s, :s] = 255  # the largest sums
    img[s : 2 * s, :s] = np.arange(s * s).reshape(s, s, 1) % 2 * 255  # a mean of x.5: to even
    want = np.round(img.astype(np.float64).reshape(h, s, w, s, 4).mean(axis=(1, 3))).astype(np.uint8)
    from aniso3d.rendering.renderer import downsample

    got = downsample(img, s)
    assert got.dtype == np.uint8
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(downsample(img[::-1], s), want[::-1])
