"""How quality "high" composites the splats of a pixel (docs/splat_aa.md,
aniso3d.rendering.splat.reference): the pixel's fragments are grouped into
surfaces by depth; within a surface coverages add (its splats tile it),
surfaces compose front to back as independent layers do, 1 - prod(1 - a_k),
and an opaque surface hides whatever lies behind it.

The NumPy twin (``subpixel_fragments_np`` and ``composite_np``) is checked
against closed forms without a GPU; the GPU is then held to the twin, pixel by
pixel, on explicit point clouds of sub-pixel splats drawn into a float
framebuffer. Tolerances: 2e-4 in alpha and colour per pixel (float32 sums on
the GPU against float64; measured at most 6e-6 here), on scenes whose depths
keep off the slice boundaries, where float32 and float64 could round a
fragment into different slices.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import module_renderer

from aniso3d import PointCloud
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.lighting import Lighting, shade_np
from aniso3d.rendering.splat import AA_CLOSE, AA_LAYERS, AA_SPAN_MIN, SplatOptions
from aniso3d.rendering.splat.reference import Fragments, composite_np, subpixel_fragments_np

SIZE = (64, 64)
FOV = 40.0
DISTANCE = 3.0
#: Pixels per world unit at unit depth.
FOCAL = SIZE[1] / (2.0 * math.tan(math.radians(FOV) / 2.0))
TOL = 2e-4
WHITE = (1.0, 1.0, 1.0)


r = module_renderer(SIZE)


def camera() -> Camera:
    return Camera((0.0, 0.0, DISTANCE), (0.0, 0.0, 0.0), fov=FOV)


def px_at(z: float) -> float:
    """World units per pixel at world z (the camera looks down -z from z = 3)."""
    return (DISTANCE - z) / FOCAL


def merge(*clouds: PointCloud) -> PointCloud:
    return PointCloud(*(np.concatenate([getattr(c, a) for c in clouds])
                        for a in ("positions", "normals", "areas", "kd", "ks", "shininess")))  # fmt: skip


def sheet(z: float, kd, spacing_px: float = 0.5, half_px: float = 24.0, area_px: float | None = None,
          jitter: float = 0.0, seed: int = 0, normal=(0.0, 0.0, 1.0)) -> PointCloud:  # fmt: skip
    """Sub-pixel square splats on a grid ``spacing_px`` apart (pixels at depth
    3 - z) over a square ``2 half_px`` pixels wide facing the camera at z, each
    of ``area_px`` (default: the grid cell, so they tile the square)."""
    px = px_at(z)
    g = (np.arange(-half_px, half_px, spacing_px) + spacing_px / 2) * px
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    rng = np.random.default_rng(seed)
    x, y = x + rng.uniform(-jitter, jitter, x.size) * px, y + rng.uniform(-jitter, jitter, y.size) * px
    n = x.size
    area = (spacing_px if area_px is None else math.sqrt(area_px)) ** 2 * px * px
    return PointCloud(np.c_[x, y, np.full(n, z)], np.tile(normal, (n, 1)), np.full(n, area),
                      np.tile(kd, (n, 1)), np.zeros(n), np.full(n, 8.0))  # fmt: skip


def draw_float(r, cloud: PointCloud, **opts) -> tuple[np.ndarray, FrameView]:
    """(H, W, 4) float32 RGBA, row 0 at the top, of ``cloud`` drawn over the
    background into a float framebuffer, and the view it was drawn with."""
    cam = camera()
    near, far = cam.clip_range(cloud.bounds)
    view = FrameView(cam, r.lighting, SIZE, near, far)
    impl = r.method_renderer("splat")
    handle = impl.upload(cloud)
    ctx = r.gl.ctx
    col, dep = ctx.texture(SIZE, 4, dtype="f4"), ctx.depth_texture(SIZE)
    fbo = ctx.framebuffer([col], dep)
    try:
        fbo.use()
        ctx.viewport = (0, 0, *SIZE)
        fbo.clear(*r.lighting.background, 0.0, depth=1.0)
        impl.draw(handle, view, fbo=fbo, quality="high", **opts)
        img = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32)
    finally:
        for obj in (fbo, col, dep):
            obj.release()
        impl.release(handle)
    return img.reshape(SIZE[1], SIZE[0], 4)[::-1].copy(), view


def twin(cloud: PointCloud, view: FrameView, **opts) -> tuple[np.ndarray, np.ndarray]:
    opts = SplatOptions(quality="high", **opts)
    return composite_np(subpixel_fragments_np(cloud, view, opts), view.lighting.background)


def assert_matches_twin(r, cloud: PointCloud, **opts) -> np.ndarray:
    img, view = draw_float(r, cloud, **opts)
    rgb, alpha = twin(cloud, view, **opts)
    assert np.abs(img[..., 3] - alpha).max() < TOL, np.abs(img[..., 3] - alpha).max()
    assert np.abs(img[..., :3] - rgb).max() < TOL, np.abs(img[..., :3] - rgb).max()
    return img


def one_pixel(coverage, depth, rgb, span: float = 2.0) -> tuple[np.ndarray, float]:
    """The twin's colour and alpha of one pixel holding these fragments
    (depths in slices: the slicing is (0, 1, span))."""
    n = len(coverage)
    frags = Fragments(np.zeros(n, np.int64), np.asarray(coverage, float), np.asarray(depth, float),
                      np.asarray(rgb, float).reshape(n, 3), (1, 1), (0.0, 1.0, span))  # fmt: skip
    out, alpha = composite_np(frags, WHITE)
    return out[0, 0], float(alpha[0, 0])


# ------------------------------------------------------------ the twin's rule

RED, GREEN, BLUE, GREY = (0.9, 0.1, 0.1), (0.1, 0.8, 0.2), (0.1, 0.2, 0.9), (0.5, 0.5, 0.5)


def test_splats_of_one_surface_add_and_surfaces_compose():
    # Four quarter-pixel splats at one depth tile the pixel: alpha 1. The same
    # four each on its own surface (depths far apart): 1 - 0.75^4.
    _, alpha = one_pixel([0.25] * 4, [10.2, 10.4, 10.5, 10.7], [GREY] * 4)
    assert alpha == pytest.approx(1.0, abs=1e-12)
    colour, alpha = one_pixel([0.25] * 4, [10.5, 20.5, 30.5, 40.5], [RED, GREEN, BLUE, GREY])
    assert alpha == pytest.approx(1.0 - 0.75**4, abs=1e-12)
    # Front to back: red, then green behind what red leaves, ...
    want = 0.25 * (np.array(RED) + 0.75 * np.array(GREEN) + 0.75**2 * np.array(BLUE) + 0.75**3 * np.array(GREY))
    assert np.abs(colour - (want + 0.75**4)).max() < 1e-12  # + the white background


def test_an_opaque_surface_hides_everything_behind_it():
    # A grey speck (1 % of the pixel) in front of a red surface tiled by two
    # splats, and a blue one behind: 0.01 grey + 0.99 red, no blue, alpha 1.
    colour, alpha = one_pixel([0.01, 0.5, 0.5, 0.6, 0.4], [3.5, 9.5, 9.7, 30.5, 31.0],
                              [GREY, RED, RED, BLUE, BLUE])  # fmt: skip
    assert alpha == 1.0
    assert np.abs(colour - (0.01 * np.array(GREY) + 0.99 * np.array(RED))).max() < 1e-12


def test_a_surface_spans_its_tolerance_from_its_first_slice():
    # span 2 slices: fragments in slices 10 and 11 are one surface (add), one
    # in slice 12 starts the next (composes).
    _, alpha = one_pixel([0.5, 0.5], [10.5, 11.9], [GREY] * 2)
    assert alpha == 1.0
    _, alpha = one_pixel([0.5, 0.5], [10.5, 12.1], [GREY] * 2)
    assert alpha == 0.75


def test_surfaces_beyond_the_last_layer_share_it_equally():
    # 7 surfaces of 0.3 each: AA_LAYERS - 1 layers of one, the last holds the
    # rest and composes them as equal shares, which is exact here.
    k = 7
    _, alpha = one_pixel([0.3] * k, 10.5 + 10.0 * np.arange(k), [GREY] * k)
    assert AA_LAYERS < k
    assert alpha == pytest.approx(1.0 - 0.7**k, abs=1e-12)
    # Their colours too: each surface counts with what those in front leave
    # of it, also inside the last layer (an equal-weight mean there gave the
    # surfaces behind as much weight as the front one).
    colours = np.random.default_rng(3).uniform(0.0, 1.0, (k, 3))
    colour, _ = one_pixel([0.3] * k, 10.5 + 10.0 * np.arange(k), colours)
    want = sum(0.3 * 0.7**i * colours[i] for i in range(k)) + 0.7**k
    assert np.abs(colour - want).max() < 1e-12
    # Unequal ones: equal shares are a lower bound there (an opaque surface
    # behind AA_LAYERS - 1 others no longer closes the pixel: a known limit).
    cover = [0.3] * (k - 1) + [1.0]
    _, alpha = one_pixel(cover, 10.5 + 10.0 * np.arange(k), [GREY] * k)
    n = k - (AA_LAYERS - 1)
    last = 1.0 - (1.0 - sum(cover[AA_LAYERS - 1 :]) / n) ** n
    assert alpha == pytest.approx(1.0 - 0.7 ** (AA_LAYERS - 1) * (1.0 - last), abs=1e-12)
    assert alpha < 1.0
    # Within the first AA_LAYERS - 1 surfaces an opaque one closes the pixel,
    # whatever lies behind.
    cover = [0.3] * (AA_LAYERS - 2) + [1.0] + [0.3] * 5
    _, alpha = one_pixel(cover, 10.5 + 10.0 * np.arange(len(cover)), [GREY] * len(cover))
    assert alpha == 1.0


def image(coverage, depth, span: float = 2.0) -> np.ndarray:
    """The twin's alpha of an image of one fragment per pixel: ``coverage``
    and ``depth`` (in slices) (H, W) arrays, 0 coverage for none."""
    coverage, depth = np.asarray(coverage, float), np.asarray(depth, float)
    h, w = coverage.shape
    at = np.flatnonzero(coverage.ravel() > 0)
    frags = Fragments(at, coverage.ravel()[at], depth.ravel()[at], np.full((len(at), 3), 0.5), (w, h),
                      (0.0, 1.0, span))  # fmt: skip
    return composite_np(frags, WHITE)[1]


def test_a_whole_surface_is_opaque_where_its_sums_scatter_about_one():
    # Sub-pixel footprints do not tile a sheet exactly: its sums scatter
    # about 1 (0.83 to 1.16 inside a minified blob). A pixel of 0.8 among
    # neighbours of 1.1 on the same surface is whole; among neighbours of 0.3
    # (a translucent sheet), at an edge (two neighbours empty), or among
    # neighbours on another surface (farther than AA_CLOSE's reach), it
    # keeps its sum; below 5 mean - 4 (0.5) it is a hole, and keeps it.
    mean, reach = AA_CLOSE
    cover = np.full((5, 5), 1.1)
    cover[2, 2] = 0.8
    depth = np.full((5, 5), 10.5)
    assert image(cover, depth)[2, 2] == 1.0
    assert image(np.where(cover > 1, 0.3, cover), depth)[2, 2] == pytest.approx(0.8, abs=1e-12)
    edge = cover.copy()
    edge[:, 3:] = 0.0
    assert image(edge, depth)[2, 2] == pytest.approx(0.8, abs=1e-12)
    far = depth.copy()
    far[[1, 3, 2, 2], [2, 2, 1, 3]] += 2.0 * reach + 1.0  # the four neighbours, another surface
    assert image(cover, far)[2, 2] == pytest.approx(0.8, abs=1e-12)
    hole = cover.copy()
    hole[2, 2] = 5.0 * mean - 4.0 - 0.05
    assert image(hole, depth)[2, 2] == pytest.approx(hole[2, 2], abs=1e-12)
    # The mean is over min(1, sum): two full neighbours and two of 0.5 do not
    # make it whole, however far above 1 the full ones sum.
    big = np.where(cover > 1, 5.0, cover)
    big[2, 1] = big[2, 3] = 0.5
    assert (0.8 + 2.0 + 1.0) / 5.0 < mean
    assert image(big, depth)[2, 2] == pytest.approx(0.8, abs=1e-12)


def test_twin_fragments_keep_the_projected_area():
    # The twin's fragments of a tiled sheet sum to the sheet's projected area,
    # its coverage in the pixels inside is 1, and depths are the sheet's.
    cam = camera()
    s = sheet(0.0, GREY, spacing_px=0.5, half_px=8.0)
    view = FrameView(cam, Lighting(), SIZE, *cam.clip_range(s.bounds))
    frags = subpixel_fragments_np(s, view, SplatOptions(quality="high"))
    assert frags.coverage.sum() == pytest.approx(16.0 * 16.0, rel=1e-9)
    per_pixel = np.bincount(frags.pixel, frags.coverage, SIZE[0] * SIZE[1]).reshape(SIZE[::-1])
    assert np.abs(per_pixel[26:38, 26:38] - 1.0).max() < 1e-9
    t = view.near + frags.depth * (view.far - view.near)
    assert np.abs(t - DISTANCE).max() < 1e-9


# ------------------------------------------------------------ GPU against the twin


@pytest.mark.gpu
def test_a_speck_in_front_of_an_opaque_plane_does_not_let_what_is_behind_through(r):
    # The measured wrong case: a grey speck covering 1 % of a pixel in front
    # of an opaque red plane (sub-pixel splats tiling it) with a blue plane
    # behind, on white. Before: (101, 35, 100) at alpha 221, blue and white
    # through the red plane. Now: 0.99 red + 0.01 grey, alpha 255.
    red, blue = sheet(0.0, (1.0, 0.0, 0.0)), sheet(-0.5, (0.0, 0.0, 1.0))
    px = px_at(0.5)
    speck = PointCloud([(0.5 * px, 0.5 * px, 0.5)], [(0.0, 0.0, 1.0)], [0.01 * px * px], [(0.5, 0.5, 0.5)],
                       0.0, 8.0)  # fmt: skip
    cloud = merge(red, blue, speck)
    y, x = SIZE[1] // 2 - 1, SIZE[0] // 2  # the pixel holding the speck
    img8 = r.render(cloud, camera(), "splat", quality="high", alpha=True)
    view = -np.asarray(camera().forward)
    shaded = np.clip(shade_np(np.array([[0, 0, 1.0]] * 2), view, np.array([(1.0, 0, 0), (0.5, 0.5, 0.5)]),
                              0.0, 8.0, r.lighting), 0, 1)  # fmt: skip
    want = 0.99 * shaded[0] + 0.01 * shaded[1]
    assert img8[y, x, 3] == 255
    assert np.abs(img8[y, x, :3] - 255 * want).max() <= 1.0, (img8[y, x], 255 * want)
    assert int(img8[y, x, 2]) <= 1  # no blue
    img = assert_matches_twin(r, cloud)
    assert np.abs(img[y, x, :3] - want).max() < TOL and img[y, x, 3] == 1.0


@pytest.mark.gpu
def test_translucent_sheets_compose_as_independent_layers(r):
    # The measured wrong case: five random sheets, each covering 30 % of
    # every pixel on average (sub-pixel splats at random places), 0.1 apart
    # (far beyond a surface's span): before, alpha 0.993 where independent
    # sheets give 1 - 0.7^5 = 0.832. The mean over the middle is that to the
    # sampling error (measured 0.8316); each pixel is the twin's.
    sheets = []
    rng = np.random.default_rng(5)
    for k in range(5):
        z = -0.1 * k - 0.003  # off the slice boundaries
        px = px_at(z)
        n = 12000
        pos = np.c_[rng.uniform(-20, 20, (n, 2)) * px, np.full(n, z)]
        area = 0.3 * 40 * 40 / n * px * px
        sheets.append(PointCloud(pos, np.tile([0.0, 0.0, 1.0], (n, 1)), np.full(n, area),
                                 np.tile(rng.uniform(0.2, 0.9, 3), (n, 1)), 0.0, 8.0))  # fmt: skip
    img = assert_matches_twin(r, merge(*sheets))
    inside = img[20:44, 20:44, 3]
    assert abs(float(inside.mean()) - (1.0 - 0.7**5)) < 0.01, inside.mean()
    # The same sheets 1e-4 apart, well within one surface's span, are one
    # surface: each pixel reads min(1, its summed coverage), 1.5 on average,
    # or 1 where the surface is whole (its sum and its neighbours' high).
    close = merge(*(PointCloud(s.positions * [1, 1, 0] + [0, 0, -1e-4 * k], s.normals, s.areas, s.kd, s.ks,
                               s.shininess) for k, s in enumerate(sheets)))  # fmt: skip
    img, view = draw_float(r, close)
    frags = subpixel_fragments_np(close, view, SplatOptions(quality="high"))
    total = np.bincount(frags.pixel, frags.coverage, SIZE[0] * SIZE[1]).reshape(SIZE[::-1])
    _, alpha = composite_np(frags, view.lighting.background)
    assert np.abs(img[..., 3] - alpha).max() < TOL
    whole = alpha > np.minimum(total, 1.0) + 1e-9
    assert np.all(alpha[whole] == 1.0) and np.all(total[whole] >= 5.0 * AA_CLOSE[0] - 4.0 - 1e-9)
    assert np.abs(img[~whole][..., 3] - np.minimum(total[~whole], 1.0)).max() < TOL
    assert float(img[20:44, 20:44, 3].mean()) > 0.97


@pytest.mark.gpu
def test_many_equal_sheets_compose_as_layers_in_colour(r):
    # Nine sheets of different colours, each covering exactly 0.3 of every
    # pixel (four splats of 0.075 px in each), 0.1 apart: more surfaces than
    # layers. Independent layers give sum 0.3 0.7^k colour_k + 0.7^9 white,
    # the last layer's surfaces included; its equal-weight mean was off by
    # by 0.008 here (2 steps of an 8-bit image).
    k = 9
    assert k > AA_LAYERS
    rng = np.random.default_rng(11)
    kd = rng.uniform(0.1, 0.9, (k, 3))
    sheets = [sheet(-0.1 * i - 0.003, kd[i], area_px=0.075) for i in range(k)]
    img = assert_matches_twin(r, merge(*sheets))
    view = -np.asarray(camera().forward)
    shaded = np.clip(shade_np(np.tile([0.0, 0.0, 1.0], (k, 1)), view, kd, 0.0, 8.0, r.lighting), 0, 1)
    want = sum(0.3 * 0.7**i * shaded[i] for i in range(k)) + 0.7**k * np.ones(3)
    inside = img[16:48, 16:48]
    assert np.abs(inside[..., 3] - (1.0 - 0.7**k)).max() < 1e-4
    assert np.abs(inside[..., :3] - want).max() < 1e-4, np.abs(inside[..., :3] - want).max()


@pytest.mark.gpu
def test_an_opaque_plane_hides_any_clutter_behind_it(r):
    # A tiled green plane in front of ten random translucent sheets: alpha 1
    # and the plane's colour exactly, whatever number of surfaces lies behind
    # (more than the layers there are).
    rng = np.random.default_rng(9)
    front = sheet(0.2, (0.1, 0.8, 0.2))
    behind = [sheet(-0.05 * k - 0.013, rng.uniform(0, 1, 3), spacing_px=1.0, area_px=0.3, jitter=0.5, seed=k)
              for k in range(10)]  # fmt: skip
    img = assert_matches_twin(r, merge(front, *behind))
    view = -np.asarray(camera().forward)
    green = np.clip(shade_np(np.array([[0, 0, 1.0]]), view, np.array([(0.1, 0.8, 0.2)]), 0.0, 8.0, r.lighting), 0, 1)
    inside = img[12:52, 12:52]
    assert np.abs(inside[..., 3] - 1.0).max() < 1e-6
    assert np.abs(inside[..., :3] - green[0]).max() < 1e-5


@pytest.mark.gpu
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_gpu_matches_the_twin_on_random_clouds(r, seed):
    # Random translucent sheets of random sub-pixel splats (random sizes,
    # colours, tilts up to 30 degrees), some close enough to be one surface,
    # more of them than there are layers.
    rng = np.random.default_rng(seed)
    parts = []
    for k in range(int(rng.integers(3, 9))):
        z = float(rng.uniform(-0.6, 0.4))
        tilt = math.radians(float(rng.uniform(0, 30)))
        normal = (0.0, math.sin(tilt), math.cos(tilt))
        parts.append(sheet(z, rng.uniform(0, 1, 3), spacing_px=float(rng.uniform(0.4, 1.2)),
                           half_px=float(rng.uniform(8, 26)), area_px=float(rng.uniform(0.05, 0.6)),
                           jitter=0.5, seed=seed * 100 + k, normal=normal))  # fmt: skip
    assert_matches_twin(r, merge(*parts))


@pytest.mark.gpu
def test_a_jittered_opaque_sheet_hides_the_sheet_behind_it(r):
    # A red sheet tiled by sub-pixel splats 1 px apart, each jittered by up to
    # 0.1 px: its sums scatter about 1 (0.82 to 1.26 inside, as a minified
    # blob's 0.83 to 1.16), and the blue sheet behind showed through every
    # pixel below 1 (the speckle on a minified blob). Whole inside now: no
    # blue, red alone has alpha 1; the twin's pixel by pixel.
    red = sheet(0.0, (1.0, 0.0, 0.0), spacing_px=1.0, jitter=0.1, seed=4)
    blue = sheet(-0.5, (0.0, 0.0, 1.0))
    img = assert_matches_twin(r, merge(red, blue))
    assert float(img[12:52, 12:52, 2].max()) < 1e-6
    alone = assert_matches_twin(r, red)
    assert np.abs(alone[12:52, 12:52, 3] - 1.0).max() < 1e-6


@pytest.mark.gpu
def test_a_tilted_tiled_plane_stays_opaque(r):
    # A plane tiled by sub-pixel splats (0.5 px apart), tilted 60 degrees: its
    # fragments in a pixel spread over more depth than a surface spans, but
    # they lie on one plane, and a fragment's depth is where the pixel's ray
    # meets its splat's plane, so they stay one surface. Before (the depth
    # kept within the splat's bounding sphere): alpha 0.94 on average inside,
    # 0.75 at worst.
    a = math.radians(60.0)
    px = px_at(0.0)
    g = (np.arange(-30, 30, 0.5) + 0.25) * px
    x, y = (v.ravel() for v in np.meshgrid(g, g))
    n = x.size
    plane = PointCloud(np.c_[x, y * math.cos(a), y * math.sin(a)], np.tile([0, -math.sin(a), math.cos(a)], (n, 1)),
                       np.full(n, (0.5 * px) ** 2), np.tile(GREY, (n, 1)), 0.0, 8.0)  # fmt: skip
    img = assert_matches_twin(r, plane)
    _, view = draw_float(r, plane)
    frags = subpixel_fragments_np(plane, view, SplatOptions(quality="high"))
    total = np.bincount(frags.pixel, frags.coverage, SIZE[0] * SIZE[1]).reshape(SIZE[::-1])
    inside = (slice(27, 37), slice(16, 48))
    # One surface: alpha is at least the summed coverage (1 up to the tilted
    # boxes' tiling, within 0.2 %; 1 where the surface is whole), not
    # 1 - prod(1 - a) over pieces.
    assert np.all(img[inside][..., 3] >= np.minimum(total[inside], 1.0) - TOL)
    assert float(img[inside][..., 3].min()) > 0.998


@pytest.mark.gpu
def test_a_rough_sheet_stays_one_surface_where_the_span_is_least(r):
    # A sheet facing the camera whose splats lie up to half a slice off its
    # plane, and a speck far behind it that stretches the depth range, so
    # that a surface's span is the least, AA_SPAN_MIN slices. The sheet's
    # fragments in a pixel fall into two neighbouring slices where their
    # depths straddle a boundary; they must stay one surface (alpha 1 or
    # the summed coverage), not two composed as independent layers. At a
    # least span of 1 slice: alpha 0.951 on average inside, 0.61 at worst
    # (now 0.9997; a few pixels keep a summed coverage below 1, where the
    # depth offsets moved the tiling).
    rng = np.random.default_rng(8)
    px = px_at(0.0)
    g = (np.arange(-20, 20, 0.5) + 0.25) * px
    x, y = (v.ravel() for v in np.meshgrid(g, g))
    n = x.size
    speck_px = px_at(-40.0)
    speck = PointCloud(np.array([[-28 * speck_px, -28 * speck_px, -40.0]]), np.array([[0.0, 0.0, 1.0]]),
                       np.array([(0.5 * speck_px) ** 2]), np.array([BLUE]), 0.0, 8.0)  # fmt: skip
    flat = PointCloud(np.c_[x, y, np.zeros(n)], np.tile([0.0, 0.0, 1.0], (n, 1)), np.full(n, (0.5 * px) ** 2),
                      np.tile(GREY, (n, 1)), 0.0, 8.0)  # fmt: skip
    _, view = draw_float(r, merge(flat, speck))
    lo, scale, span = subpixel_fragments_np(merge(flat, speck), view, SplatOptions(quality="high")).slicing
    assert span == AA_SPAN_MIN
    slice_world = (view.far - view.near) / scale
    rough = PointCloud(flat.positions + np.c_[np.zeros((n, 2)), rng.uniform(-0.5, 0.5, n) * slice_world],
                       flat.normals, flat.areas, flat.kd, flat.ks, flat.shininess)  # fmt: skip
    cloud = merge(rough, speck)
    img = assert_matches_twin(r, cloud)
    _, view = draw_float(r, cloud)
    frags = subpixel_fragments_np(cloud, view, SplatOptions(quality="high"))
    slices = np.floor((frags.depth - frags.slicing[0]) * frags.slicing[1])
    inside = np.zeros(SIZE[::-1], bool)
    inside[16:48, 16:48] = True
    at = inside.ravel()[frags.pixel]
    lo_s = np.full(SIZE[0] * SIZE[1], np.inf)
    np.minimum.at(lo_s, frags.pixel[at], slices[at])
    hi_s = np.full(SIZE[0] * SIZE[1], -np.inf)
    np.maximum.at(hi_s, frags.pixel[at], slices[at])
    assert np.mean((hi_s > lo_s)[inside.ravel()]) > 0.3  # many pixels straddle a boundary
    total = np.bincount(frags.pixel, frags.coverage, SIZE[0] * SIZE[1]).reshape(SIZE[::-1])
    alpha = img[..., 3][inside]
    assert np.all(alpha >= np.minimum(total[inside], 1.0) - TOL)
    assert float(alpha.mean()) > 0.995


@pytest.mark.gpu
def test_a_closed_surface_behind_translucent_sheets_counts_its_culled_back(r):
    # Five translucent sheets (0.3 of every pixel each) in front of an opaque
    # sheet of one-sided splats facing the eye: the opaque one lands in the
    # last layer with two of the translucent ones, whose equal shares would
    # let 0.7^3 (1 - 1.6/3)^3 = 3.5 % through (a two-sided closed surface's
    # back used to add its share there). A one-sided splat counts twice in
    # its pixel's coverage sum: 0.7^3 (1 - 2.6/3)^3 = 0.08 % through.
    front = [sheet(0.3 - 0.1 * k - 0.003, GREY, area_px=0.075) for k in range(5)]
    wall = sheet(-0.3 - 0.003, RED)
    wall = PointCloud(wall.positions, wall.normals, wall.areas, wall.kd, wall.ks, wall.shininess,
                      one_sided=np.ones(len(wall), bool))  # fmt: skip
    cloud = merge(*front, wall)
    cloud = PointCloud(cloud.positions, cloud.normals, cloud.areas, cloud.kd, cloud.ks, cloud.shininess,
                       one_sided=np.r_[np.zeros(len(cloud) - len(wall), bool), np.ones(len(wall), bool)])  # fmt: skip
    img = assert_matches_twin(r, cloud)
    inside = img[20:44, 20:44, 3]
    want = 1.0 - 0.7**3 * (1.0 - 2.6 / 3.0) ** 3
    assert np.abs(inside - want).max() < 1e-3, (inside.min(), inside.max(), want)



def test_a_closed_surfaces_rim_stays_one_surface(r, monkeypatch):
    # The corpus blob's texture points at 64^3 (one-sided: a closed surface),
    # 47 pixels wide, sub-pixel splats. Near the rim the surface runs along
    # the rays, its splats' planes meet a pixel's ray at scattered depths, and
    # with the span alone their fragments split into surfaces that composed
    # as independent layers, letting the background through
    # (AA_SURFACE_REACH = 0 below: pixels at 0.92 even with the closure of
    # closed surfaces). The nearest surface reaching as far as its
    # fragments' depths change across a pixel keeps the rim whole.
    from scipy import ndimage

    from aniso3d.build import scenes
    from aniso3d.build.mesh import Mesh
    from aniso3d.build.texture import build_texture
    from aniso3d.rendering.splat import params

    blob = scenes.get_scene("blob", subdivisions=3)
    b = np.asarray(blob.bounds)
    scale = 1.6 / float((b[1] - b[0]).max())
    mesh = Mesh.from_arrays((blob.vertices - b.mean(axis=0)) * scale, blob.faces, (0.9, 0.4, 0.2), 0.3, 20.0)
    cloud = build_texture(mesh, 64, 16, bounds=mesh.bounds).to_points("centroid", 1, "mean")
    assert cloud.one_sided is not None and cloud.one_sided.all()
    img = assert_matches_twin(r, cloud)
    truth = r.render(mesh, camera(), "mesh", ssaa=4, alpha=True)[..., 3] / 255.0
    inside = ndimage.binary_erosion(truth > 0.999, iterations=1)
    assert inside.sum() > 1000
    assert img[..., 3][inside].min() > 0.995, img[..., 3][inside].min()
    cam = camera()
    view = FrameView(cam, r.lighting, SIZE, *cam.clip_range(cloud.bounds))
    monkeypatch.setattr(params, "AA_SURFACE_REACH", 0.0)
    _, alpha = twin(cloud, view)
    assert alpha[inside].min() < 0.95 and (alpha[inside] < 0.99).sum() >= 3


@pytest.mark.parametrize("counts, whole", [(1.0, False), (2.0, True)])
def test_a_closed_surface_closes_a_pinhole_a_sheet_keeps(counts, whole):
    # A 3 x 3 image: the centre pixel covered 0.2 by a surface that covers
    # its four neighbours whole, at one depth. The mean over the five, 0.84,
    # is below AA_CLOSE's 0.9, so a two-sided sheet keeps the pinhole; a
    # closed surface seen from outside (one-sided splats, counted twice) has
    # no holes, and AA_CLOSE_SIDED (0.8) takes the centre as whole.
    from aniso3d.rendering.splat import params

    assert params.AA_CLOSE_SIDED <= 0.84 < params.AA_CLOSE[0]
    pixels = np.array([4, 1, 3, 5, 7])  # the centre, then its four neighbours
    cover = np.array([0.2, 1.0, 1.0, 1.0, 1.0])
    frags = Fragments(pixels, cover, np.full(5, 10.0), np.tile(RED, (5, 1)), (3, 3), (0.0, 1.0, 2.0),
                      np.full(5, counts))  # fmt: skip
    rgb, alpha = composite_np(frags, WHITE)
    assert alpha[1, 1] == pytest.approx(1.0 if whole else 0.2)
    assert np.allclose(rgb[1, 1], RED if whole else 0.2 * np.array(RED) + 0.8 * np.array(WHITE))


def test_a_speck_just_in_front_of_a_closed_surface_is_not_its_pixels_surface(monkeypatch):
    # A 3 x 3 image of a closed surface (one-sided splats, counted twice),
    # whole in every pixel; in the centre a speck of a two-sided sheet
    # covering 1 % of it lies just in front (a separate surface, starting
    # within AA_CLOSE's reach of its neighbours'). The speck is the centre's
    # nearest surface; its sum is far below AA_CLOSE_OWN, so it is no whole
    # surface: 1 % grey over red. Without the floor (5 x 0.8 - 4 = 0 with
    # the sided mean) the neighbours made it whole and it painted the pixel
    # grey (a scan's stray faces on a 1M-triangle bunny's tail).
    from aniso3d.rendering.splat import params

    mean, reach = params.AA_CLOSE
    span = 2.0
    assert 5.0 * params.AA_CLOSE_SIDED - 4.0 < 0.01 < params.AA_CLOSE_OWN
    pixels = np.array([4, 4, 1, 3, 5, 7])
    cover = np.array([0.01, 1.0, 1.0, 1.0, 1.0, 1.0])
    depth = np.array([10.0, 10.0 + 2 * span, 12.0, 12.0, 12.0, 12.0])
    assert abs(depth[2] - depth[0]) < reach * span
    rgb = np.array([GREY, RED, RED, RED, RED, RED])
    counts = np.array([1.0, 2.0, 2.0, 2.0, 2.0, 2.0])

    def centre() -> tuple[np.ndarray, float]:
        frags = Fragments(pixels, cover, depth, rgb, (3, 3), (0.0, 1.0, span), counts)
        out, alpha = composite_np(frags, WHITE)
        return out[1, 1], float(alpha[1, 1])

    colour, alpha = centre()
    assert alpha == pytest.approx(1.0)
    np.testing.assert_allclose(colour, 0.01 * np.array(GREY) + 0.99 * np.array(RED), atol=1e-12)
    monkeypatch.setattr(params, "AA_CLOSE_OWN", 0.0)
    np.testing.assert_allclose(centre()[0], GREY, atol=1e-12)


@pytest.mark.gpu
def test_the_gpu_keeps_the_speck_floor_of_the_twin(r, monkeypatch):
    # A closed surface's sheet (one-sided splats facing the eye, tiling it)
    # with two-sided specks of 1 % of a pixel at a range of small heights
    # in front of it, one a pixel: the GPU matches the twin, and some of
    # the specks are the case the floor is for (the twin without it paints
    # those pixels grey).
    from aniso3d.rendering.splat import params

    wall = sheet(0.0, RED, half_px=12.0)
    wall = PointCloud(wall.positions, wall.normals, wall.areas, wall.kd, wall.ks, wall.shininess,
                      one_sided=np.ones(len(wall), bool))  # fmt: skip
    px = px_at(0.0)
    k = np.arange(40)
    x, y = ((k % 8) * 2 - 7.5) * px, ((k // 8) * 2 - 3.5) * px
    h = 0.05 * (k + 1) * px
    n = len(k)
    specks = PointCloud(np.c_[x, y, h], np.tile((0.0, 0.0, 1.0), (n, 1)), np.full(n, 0.01 * px * px),
                        np.tile(GREY, (n, 1)), np.zeros(n), np.full(n, 8.0), one_sided=np.zeros(n, bool))  # fmt: skip
    cloud = merge(wall, specks)
    cloud = PointCloud(cloud.positions, cloud.normals, cloud.areas, cloud.kd, cloud.ks, cloud.shininess,
                       one_sided=np.r_[np.ones(len(wall), bool), np.zeros(n, bool)])  # fmt: skip
    img = assert_matches_twin(r, cloud)
    view_dir = -np.asarray(camera().forward)
    grey, red = np.clip(shade_np(np.array([[0, 0, 1.0]] * 2), view_dir, np.array([GREY, RED]), 0.0, 8.0,
                                 r.lighting), 0, 1)  # fmt: skip

    def greyish(rgb: np.ndarray) -> np.ndarray:
        return np.linalg.norm(rgb - grey, axis=-1) < np.linalg.norm(rgb - red, axis=-1)

    inside = img[..., 3] > 0.999  # the wall (white around it reads nearer grey than red)
    assert inside.sum() > 400
    assert not greyish(img[..., :3])[inside].any()
    cam = camera()
    view = FrameView(cam, r.lighting, SIZE, *cam.clip_range(cloud.bounds))
    monkeypatch.setattr(params, "AA_CLOSE_OWN", 0.0)
    rgb, _ = twin(cloud, view)
    assert greyish(rgb)[inside].sum() >= 3, greyish(rgb)[inside].sum()
