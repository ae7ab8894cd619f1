"""Coverage-aware splats (``quality="high"``): each splat gives every pixel
the fraction of it that the splat covers, so sub-pixel splats keep their
projected area and colours average over the splats inside a pixel.

Closed forms: the projected area of a small flat patch of area A and unit
normal n at p, seen from e, is ``A |n . (e - p)| f^2 / z^3`` pixels (f the
focal length in pixels, z the view depth); a square splat whose edge runs
through pixel centres covers half of each of those pixels. Images are drawn
into float framebuffers where a fraction matters (nothing rounds to 8 bits).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import module_renderer

import aniso3d
from aniso3d import PointCloud
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.lighting import shade_np
from aniso3d.rendering.splat import SHAPES, SplatRenderer

SIZE = (128, 128)


r = module_renderer(SIZE)


def cloud(positions, normals, areas, kd=(0.6, 0.5, 0.4)) -> PointCloud:
    n = len(positions)
    kd = np.broadcast_to(np.asarray(kd, float), (n, 3))
    return PointCloud(np.asarray(positions, float), np.asarray(normals, float),
                      np.asarray(areas, float), kd, 0.0, 8.0)  # fmt: skip


def draw_float(r, clouds, cam: Camera, bounds=None, **opts) -> np.ndarray:
    """(H, W, 4) float32 RGBA (row 0 at the top) of ``clouds`` drawn in order
    into one float framebuffer cleared to the background, one view."""
    clouds = clouds if isinstance(clouds, (list, tuple)) else [clouds]
    impl = r.method_renderer("splat")
    handles = [r.upload(c, "splat") for c in clouds]
    if bounds is None:
        b = np.concatenate([h.bounds for h in handles])
        bounds = np.stack([b.min(0), b.max(0)])
    near, far = cam.clip_range(bounds)
    view = FrameView(cam, r.lighting, SIZE, near, far)
    ctx = r.gl.ctx
    col, dep = ctx.texture(SIZE, 4, dtype="f4"), ctx.depth_texture(SIZE)
    fbo = ctx.framebuffer([col], dep)
    try:
        fbo.use()
        ctx.viewport = (0, 0, *SIZE)
        fbo.clear(*r.lighting.background, 0.0, depth=1.0)
        for h in handles:
            impl.draw(h, view, fbo=fbo, **opts)
        img = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32)
    finally:
        for obj in (fbo, col, dep):
            obj.release()
    return img.reshape(SIZE[1], SIZE[0], 4)[::-1].copy()


def head_on(distance: float = 3.0, fov: float = 40.0) -> tuple[Camera, float]:
    """A camera on the z axis looking at the origin, and its focal length in
    pixels (pixels per unit at unit depth)."""
    cam = Camera((0.0, 0.0, distance), (0.0, 0.0, 0.0), fov=fov)
    return cam, SIZE[1] / (2.0 * math.tan(math.radians(fov) / 2.0))


def projected_px(positions, normals, areas, cam: Camera, focal: float) -> np.ndarray:
    """Closed-form projected area of each small patch, pixels."""
    e = np.asarray(cam.position, float)
    z = (np.asarray(positions) - e) @ np.asarray(cam.forward)
    return np.abs(np.sum(normals * (e - positions), axis=1)) * areas * focal**2 / z**3


def test_high_is_an_option_and_blend_keeps_the_old_mode():
    assert SplatRenderer.options(quality="high").quality == "high"
    assert SplatRenderer.options(quality="blend").quality == "blend"


# ------------------------------------------------------------ coverage


@pytest.mark.gpu
@pytest.mark.parametrize("shape", SHAPES)
def test_sub_pixel_splats_keep_their_projected_area(r, shape):
    # 31 x 31 splats 0.06 apart (3.1 px), each of 0.3 px^2 true projected
    # area, head-on and tilted 37 degrees, at random sub-pixel offsets: the
    # alpha they leave sums to the closed-form total. Measured: to 1e-5 for
    # every shape (the pixel filter's copies sum to 1 anywhere); the bound is
    # 1 %. Fast quality gives each splat a whole pixel or more: 3.3 to 4.3
    # times the area.
    cam, focal = head_on()
    g = np.arange(-0.9, 0.91, 0.06)
    rng = np.random.default_rng(4)
    pos = np.array([(x, y, 0.0) for x in g for y in g])
    pos[:, :2] += rng.uniform(-0.01, 0.01, (len(pos), 2))
    for normal in ((0.0, 0.0, 1.0), (0.6, 0.0, 0.8)):
        nrm = np.tile(normal, (len(pos), 1))
        area = 0.3 / focal**2 * 3.0**2  # 0.3 px^2 head-on at depth 3
        areas = np.full(len(pos), area)
        want = projected_px(pos, nrm, areas, cam, focal).sum()
        img = draw_float(r, cloud(pos, nrm, areas), cam, quality="high", splat=shape)
        got = img[..., 3].sum()
        assert abs(got / want - 1.0) < 0.01, (shape, normal, got, want)
        old = draw_float(r, cloud(pos, nrm, areas), cam, quality="fast", splat=shape)
        assert old[..., 3].sum() > 3.0 * want  # a whole pixel per 0.3 (or 0.24) px^2 splat


@pytest.mark.gpu
def test_a_field_of_sub_pixel_splats_reads_its_covered_fraction(r):
    # 60,000 splats of 0.015 px^2 at random over a 60 x 60 px square of a
    # plane facing the camera: together 25 % of it (about 17 splats, 0.25 of
    # coverage, per pixel). Splats of one surface add, so the mean alpha
    # inside is the covered fraction. Measured: 0.2507 (square and disc; the
    # random field's own count inside varies by about 0.4 %), and the whole
    # field's coverage 1.0000 of its area; the bound is 1 %. Fast quality
    # covers every pixel (mean 1.0).
    cam, focal = head_on()
    half = 30.0 * 3.0 / focal  # 30 px at depth 3, world units
    rng = np.random.default_rng(7)
    n = 60_000
    pos = np.c_[rng.uniform(-half, half, (n, 2)), np.zeros(n)]
    nrm = np.tile([0.0, 0.0, 1.0], (n, 1))
    area_px = 0.25 * 60.0 * 60.0 / n
    areas = np.full(n, area_px * (3.0 / focal) ** 2)
    pts = cloud(pos, nrm, areas)
    mid = SIZE[0] // 2
    inside = (slice(mid - 28, mid + 28), slice(mid - 28, mid + 28))
    for shape in ("square", "disc"):
        img = draw_float(r, pts, cam, quality="high", splat=shape)
        mean = float(img[inside][..., 3].mean())
        assert abs(mean - 0.25) < 0.0025, (shape, mean)
        # the whole field's coverage is its closed-form area, edges included
        assert abs(img[..., 3].sum() / (area_px * n) - 1.0) < 0.01
    fast = draw_float(r, pts, cam, quality="fast")
    assert fast[inside][..., 3].mean() > 0.99


@pytest.mark.gpu
def test_a_pixel_half_covered_reads_half(r):
    # A resolved square splat (size factor 1, 40 px a side) whose right edge
    # runs through the centres of pixel column 80: that column reads 0.5,
    # the one before 1, the one after 0 (the box filter is exact for an edge
    # along the pixel grid). And a sub-pixel splat of 0.5 px^2 in the middle
    # of a pixel: that pixel reads 0.5 and its neighbours nothing.
    cam, focal = head_on()
    px = 3.0 / focal  # one pixel at depth 3, world units
    side = 40.0 * px
    edge = (80.5 - SIZE[0] / 2) * px  # x of the centres of column 80
    sq = cloud([(edge - side / 2, 0.0, 0.0)], [(0.0, 0.0, 1.0)], [side * side])
    img = draw_float(r, sq, cam, quality="high", splat="square", size_factor=1.0)
    rows = slice(SIZE[1] // 2 - 15, SIZE[1] // 2 + 15)
    assert np.abs(img[rows, 80, 3] - 0.5).max() < 1e-3
    assert np.abs(img[rows, 79, 3] - 1.0).max() < 1e-3 and img[rows, 81, 3].max() < 1e-3
    dot = cloud([(0.5 * px, 0.5 * px, 0.0)], [(0.0, 0.0, 1.0)], [0.5 * px * px])
    img = draw_float(r, dot, cam, quality="high", splat="square")
    y, x = SIZE[1] // 2 - 1, SIZE[0] // 2  # the pixel holding (0.5, 0.5) px off the axis
    assert abs(img[y, x, 3] - 0.5) < 1e-3
    assert abs(img[..., 3].sum() - 0.5) < 1e-3


@pytest.mark.gpu
def test_colour_is_the_mean_over_the_splats_in_a_pixel(r):
    # Two splats of 0.3 px^2, red and blue, side by side inside one pixel at
    # the same depth: the pixel reads 0.6 covered, in their mean colour (fast
    # quality shows one of the two, over the whole pixel).
    cam, focal = head_on()
    px = 3.0 / focal
    pos = [(0.35 * px, 0.5 * px, 0.0), (0.65 * px, 0.5 * px, 0.0)]
    nrm = [(0.0, 0.0, 1.0)] * 2
    two = cloud(pos, nrm, [0.3 * px * px] * 2, kd=[(1.0, 0.0, 0.0), (0.0, 0.0, 1.0)])
    img = draw_float(r, two, cam, quality="high", splat="square")
    y, x = SIZE[1] // 2 - 1, SIZE[0] // 2
    assert abs(img[y, x, 3] - 0.6) < 1e-3 and abs(img[..., 3].sum() - 0.6) < 1e-3
    bg = np.asarray(r.lighting.background)
    colour = (img[y, x, :3] - 0.4 * bg) / 0.6  # the splats' own mean, background removed
    view = -cam.forward / np.linalg.norm(cam.forward)
    each = shade_np(two.normals, view, two.kd, two.ks, two.shininess, r.lighting)
    assert np.abs(colour - each.mean(axis=0)).max() < 2e-3  # half red, half blue
    fast = draw_float(r, two, cam, quality="fast", splat="square")[y, x]
    assert fast[3] == 1.0 and abs(fast[0] - fast[2]) > 0.1


@pytest.mark.gpu
def test_separate_draws_composite_in_either_order(r):
    # A large tilted square in front of a field of sub-pixel splats, drawn as
    # two clouds in either order (the second composited over or under what
    # the first left): the same image up to rounding (measured: 6e-8), the
    # square's anti-aliased rim over the field in both. (Drawn as one cloud,
    # the field behind the square's rim is a deep layer there, so it differs
    # a little: by design.)
    cam, focal = head_on()
    px = 3.0 / focal
    rng = np.random.default_rng(2)
    n = 4000
    pos = np.c_[rng.uniform(-40 * px, 40 * px, (n, 2)), np.full(n, -0.5)]
    field = cloud(pos, np.tile([0.0, 0.0, 1.0], (n, 1)), np.full(n, (0.4 * px) ** 2),
                  kd=(0.1, 0.6, 0.2))  # fmt: skip
    front = cloud(
        [(5.3 * px, -3.7 * px, 0.4)], [(0.3, 0.2, 0.93)], [(30 * px) ** 2], kd=(0.8, 0.3, 0.2)
    )
    bounds = np.stack([np.minimum(field.bounds[0], front.bounds[0]),
                       np.maximum(field.bounds[1], front.bounds[1])])  # fmt: skip
    a = draw_float(r, [field, front], cam, bounds, quality="high")
    b = draw_float(r, [front, field], cam, bounds, quality="high")
    rim = (a[..., 3] > 0.05) & (a[..., 3] < 0.95)
    assert rim.sum() > 50  # partly covered pixels: the field's and the rim's
    assert np.abs(a - b).max() < 1e-5


@pytest.mark.gpu
def test_a_just_cleared_target_composites_in_one_pass(r):
    # Renderer.render tells the splats their target was just cleared
    # (cleared=True), and "high" then skips the two passes that put a cloud
    # under nearer pixels: the same image as all three passes (nothing is
    # nearer in a cleared target) for the scene of the test above drawn as
    # one cloud; and the passes are really skipped: the field drawn after
    # the square with cleared=True (wrongly) loses its part under the rim.
    cam, focal = head_on()
    px = 3.0 / focal
    rng = np.random.default_rng(2)
    n = 4000
    pos = np.c_[rng.uniform(-40 * px, 40 * px, (n, 2)), np.full(n, -0.5)]
    field = cloud(pos, np.tile([0.0, 0.0, 1.0], (n, 1)), np.full(n, (0.4 * px) ** 2),
                  kd=(0.1, 0.6, 0.2))  # fmt: skip
    front = cloud(
        [(5.3 * px, -3.7 * px, 0.4)], [(0.3, 0.2, 0.93)], [(30 * px) ** 2], kd=(0.8, 0.3, 0.2)
    )
    both = PointCloud(np.r_[field.positions, front.positions], np.r_[field.normals, front.normals],
                      np.r_[field.areas, front.areas], np.r_[field.kd, front.kd], 0.0, 8.0)  # fmt: skip
    three = draw_float(r, both, cam, quality="high")
    one = draw_float(r, both, cam, quality="high", cleared=True)
    assert three[..., 3].max() > 0.5
    assert np.array_equal(one, three)
    eight = r.render(both, cam, "splat", quality="high", size=SIZE).astype(float)  # cleared=True
    assert np.abs(eight - 255 * three[..., :3]).max() <= 1.0  # blending in 8 bits: one grey level
    bounds = np.stack([np.minimum(field.bounds[0], front.bounds[0]),
                       np.maximum(field.bounds[1], front.bounds[1])])  # fmt: skip
    under = draw_float(r, [front, field], cam, bounds, quality="high")
    skipped = draw_float(r, [front, field], cam, bounds, quality="high", cleared=True)
    rim = (under[..., 3] > 0.05) & (under[..., 3] < 0.95)
    assert np.abs(skipped - under)[rim].max() > 0.05


# ------------------------------------------------------------ accuracy


@pytest.mark.gpu
def test_minified_tree_beats_the_old_modes_and_one_sample_polygons(r):
    # The small tree, 32^3 voxels, seen at four times the framing distance
    # in a 128 x 128 image (a voxel covers 0.6 px), and at 0.7 times (3.5 px):
    # PSNR inside the tree's box against the polygons at 4 x 4 samples.
    # Measured far: high 30.4 dB, 1-spp polygons 22.3, blend 13.7, fast 13.7;
    # near: high 22.9, 1-spp polygons 19.9, blend 15.2. Bounds: far, high at
    # least 5 dB above 1-spp polygons and 10 dB above blend; near, high at
    # least 2 dB above blend.
    from aniso3d.bench.cameras import crop_box
    from aniso3d.metrics import psnr

    tree = aniso3d.scenes.tree(levels=4, leaves_per_twig=20)
    points = aniso3d.build_texture(tree, 32, 32).to_points()
    found = {}
    for scale in (4.0, 0.7):
        cam = Camera.fit(tree.bounds, direction=(0.55, 0.2, 1.0), distance_scale=scale)
        x0, y0, x1, y1 = crop_box(cam, tree.bounds, SIZE)
        ref = r.render(tree, cam, "mesh", ssaa=4)[y0:y1, x0:x1]
        found[scale] = {
            "mesh": psnr(ref, r.render(tree, cam, "mesh")[y0:y1, x0:x1]),
            **{
                q: psnr(ref, r.render(points, cam, "splat", quality=q)[y0:y1, x0:x1])
                for q in ("blend", "high")
            },  # fmt: skip
        }
    far, near = found[4.0], found[0.7]
    assert far["high"] > far["mesh"] + 5.0 and far["high"] > far["blend"] + 10.0, far
    assert near["high"] > near["blend"] + 2.0, near


@pytest.mark.gpu
def test_minified_blob_is_smooth_inside(r):
    # A smooth closed blob, 48^3 voxels, minified so that a voxel covers a
    # pixel (the corpus's minified camera, 128 x 128): inside its silhouette
    # the truth (polygons at 4 x 4 samples) is smooth. Sub-pixel footprints
    # do not tile a surface exactly, and before, the blob's back showed
    # through every pixel whose front summed below 1: a speckle of darker
    # pixels, interior MSE 17.5 against 2.2 for 1-spp polygons. Measured now:
    # 0.85. Bound: below 1-spp polygons' and below 3.
    from aniso3d.bench.corpus import corpus_cameras

    mesh = aniso3d.scenes.blob(subdivisions=5)
    points = aniso3d.build_texture(mesh, 48, 16).to_points()
    cam = corpus_cameras(mesh, SIZE, 48)[1]
    assert abs(cam.voxel_px - 1.0) < 0.05
    truth = r.render(mesh, cam.camera, "mesh", ssaa=4, alpha=True).astype(float)
    covered = truth[..., 3] >= 254
    inside = covered.copy()
    for axis in (0, 1):
        for k in (-2, -1, 1, 2):
            inside &= np.roll(covered, k, axis)
    assert inside.sum() > 1000

    def interior_mse(img: np.ndarray) -> float:
        return float(((img[..., :3].astype(float) - truth[..., :3]) ** 2).mean(-1)[inside].mean())

    mesh_mse = interior_mse(r.render(mesh, cam.camera, "mesh"))
    high_mse = interior_mse(r.render(points, cam.camera, "splat", splat="disc", quality="high"))
    assert high_mse < min(mesh_mse, 3.0), (high_mse, mesh_mse)
