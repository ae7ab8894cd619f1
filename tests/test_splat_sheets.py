"""Surface sheets in quality "high" (docs/splat_aa.md, "An open sheet's
folds"): a point of a surface sheet (``PointCloud.sheet``: its entry fills
its plane's section of the voxel) reaches as a closed surface's does where it
grazes the ray, and a pixel without closed surfaces chains its nearest
surface's slices up to that reach. Checked without a GPU against closed
forms (one pixel's fragments), then on a wavy open sheet seen at a grazing
angle, twin and GPU, pixel by pixel.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import module_renderer
from scipy import ndimage

from aniso3d import PointCloud
from aniso3d.build.mesh import Mesh
from aniso3d.build.texture import build_texture
from aniso3d.errors import InputError
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.splat import SplatOptions, params
from aniso3d.rendering.splat.clips import texture_points
from aniso3d.rendering.splat.reference import Fragments, composite_np, subpixel_fragments_np

SIZE = (64, 64)
TOL = 2e-4
RED, BLUE, GREY = (0.9, 0.1, 0.1), (0.1, 0.2, 0.9), (0.5, 0.5, 0.5)
WHITE = (1.0, 1.0, 1.0)


r = module_renderer(SIZE)


def pixel(depth, coverage, rgb, reach, counts: float = 1.0, span: float = 2.0) -> tuple[np.ndarray, float]:
    """The twin's colour and alpha of one pixel holding these fragments
    (depths and reaches in slices: the slicing is (0, 1, span))."""
    n = len(depth)
    frags = Fragments(np.zeros(n, np.int64), np.asarray(coverage, float), np.asarray(depth, float),
                      np.asarray(rgb, float).reshape(n, 3), (1, 1), (0.0, 1.0, span), np.full(n, counts),
                      np.asarray(reach, float))  # fmt: skip
    out, alpha = composite_np(frags, WHITE)
    return out[0, 0], float(alpha[0, 0])


# ------------------------------------------------------------ closed forms


def test_a_grazing_sheets_slices_chain_into_one_surface():
    # Five fragments of one grazing sheet, a fifth of the pixel each, two
    # slices apart (the span is 2: five surfaces without a reach, composed
    # as independent layers, 1 - 0.8^5). Reaching to slice 30 and chained
    # (each less than AA_SHEET_CHAIN = 1.5 spans beyond the one before):
    # one surface, whose coverages add to 1.
    assert 2.0 < params.AA_SHEET_CHAIN * 2.0 <= 4.0
    depth = [10.5, 12.5, 14.5, 16.5, 18.5]
    _, alpha = pixel(depth, [0.2] * 5, [GREY] * 5, reach=depth)
    assert alpha == pytest.approx(1.0 - 0.8**5)
    _, alpha = pixel(depth, [0.2] * 5, [GREY] * 5, reach=[30.0] * 5)
    assert alpha == pytest.approx(1.0)
    # The reach bounds the chain: reaching to slice 14, the surface ends at
    # 14 + span = 16 (slices 10, 12 and 14 one surface, 16 and 18 two more).
    _, alpha = pixel(depth, [0.2] * 5, [GREY] * 5, reach=[14.5] * 5)
    assert alpha == pytest.approx(1.0 - 0.4 * 0.8**2)


def test_a_grazing_sheet_does_not_reach_across_a_gap():
    # A grazing red sheet covering half the pixel at slice 10, reaching to
    # slice 30, and a blue sheet behind it at slice 20 covering the whole
    # pixel (a bed's top and the headboard behind its edge). The gap of 10
    # slices breaks the chain: two surfaces, half red and half blue. A
    # closed surface's reach (its splats one-sided, counted twice) is not
    # chained and takes the blue sheet in: coverages add, 1 / 3 red.
    rgb, alpha = pixel([10.5, 20.5], [0.5, 1.0], [RED, BLUE], reach=[30.0, 30.0])
    assert alpha == pytest.approx(1.0)
    assert np.allclose(rgb, 0.5 * np.array(RED) + 0.5 * np.array(BLUE))
    rgb, _ = pixel([10.5, 20.5], [0.5, 0.5], [RED, BLUE], reach=[30.0, 30.0], counts=2.0)
    assert np.allclose(rgb, 0.5 * np.array(RED) + 0.5 * np.array(BLUE))  # one surface, equal coverages


def test_point_sheet_flags_are_checked():
    p = np.zeros((3, 3))
    n = np.tile([0.0, 0.0, 1.0], (3, 1))
    cloud = PointCloud(p, n, np.ones(3), GREY, 0.0, 8.0, sheet=np.array([True, False, True]))
    assert cloud.sheet.tolist() == [True, False, True]
    assert PointCloud(p, n, np.ones(3), GREY, 0.0, 8.0, sheet=np.zeros(3, bool)).sheet is None
    with pytest.raises(InputError, match="sheet"):
        PointCloud(p, n, np.ones(3), GREY, 0.0, 8.0, sheet=np.ones(2, bool))
    with pytest.raises(InputError, match="sheet"):
        PointCloud(p, n, np.ones(3), GREY, 0.0, 8.0, sheet=np.ones(3))


def test_a_planes_points_are_sheets_and_scattered_leaves_are_not():
    # A square whose sides lie on voxel faces, filling its voxels' sections:
    # every entry a surface sheet. Tiny triangles scattered one to a voxel
    # (leaves far smaller than a voxel): none.
    v = np.array([[0.125, 0.125, 0.53], [0.875, 0.125, 0.53], [0.875, 0.875, 0.53], [0.125, 0.875, 0.53]])
    plane = Mesh.from_arrays(v, np.array([[0, 1, 2], [0, 2, 3]]), GREY, 0.0, 8.0)
    bounds = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    pts = texture_points(build_texture(plane, 16, 16, bounds=bounds))
    assert pts.sheet is not None and pts.sheet.all()
    rng = np.random.default_rng(3)
    centres = (rng.integers(0, 16, (200, 3)) + 0.5) / 16
    tri = centres[:, None, :] + rng.normal(0.0, 0.004, (200, 3, 3))
    leaves = Mesh.from_arrays(tri.reshape(-1, 3), np.arange(600).reshape(200, 3), GREY, 0.0, 8.0)
    pts = texture_points(build_texture(leaves, 16, 16, bounds=bounds))
    assert pts.sheet is None


# ------------------------------------------------------ a wavy open sheet


def wavy(n: int = 48, amp: float = 0.12) -> Mesh:
    """An open sheet over [-0.8, 0.8]^2 in x and z, waved in y: two waves
    along x, a slow bend along z. ks 0: a sheet's flag rides as the sign
    bit of ks, -0.0 here."""
    u = np.linspace(-0.8, 0.8, n)
    x, z = np.meshgrid(u, u)
    v = np.c_[x.ravel(), (amp * np.sin(2.0 * math.pi * x) * np.cos(1.3 * z)).ravel(), z.ravel()]
    a, b = (g.ravel() for g in np.meshgrid(np.arange(n - 1), np.arange(n - 1)))
    p = b * n + a
    faces = np.r_[np.c_[p, p + 1, p + n + 1], np.c_[p, p + n + 1, p + n]]
    return Mesh.from_arrays(v, faces, (0.8, 0.75, 0.6), 0.0, 20.0, name="wavy")


def draw_float(r, cloud: PointCloud, cam: Camera) -> tuple[np.ndarray, FrameView]:
    """(H, W, 4) float32 RGBA of quality "high" in a float framebuffer, row 0
    at the top, and the view it was drawn with."""
    view = FrameView(cam, r.lighting, SIZE, *cam.clip_range(cloud.bounds))
    impl = r.method_renderer("splat")
    handle = impl.upload(cloud)
    ctx = r.gl.ctx
    col, dep = ctx.texture(SIZE, 4, dtype="f4"), ctx.depth_texture(SIZE)
    fbo = ctx.framebuffer([col], dep)
    try:
        fbo.use()
        ctx.viewport = (0, 0, *SIZE)
        fbo.clear(*r.lighting.background, 0.0, depth=1.0)
        impl.draw(handle, view, fbo=fbo, quality="high")
        img = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32)
    finally:
        for obj in (fbo, col, dep):
            obj.release()
        impl.release(handle)
    return img.reshape(SIZE[1], SIZE[0], 4)[::-1].copy(), view


@pytest.mark.gpu
def test_a_wavy_sheet_seen_grazing_stays_whole(r, monkeypatch):
    # The sheet's texture points at 64^3 (voxels of 0.7 pixel: sub-pixel
    # splats, which the twin draws), seen from 15 degrees above its mean
    # plane. Where a wave's far side grazes the rays its splats' planes meet
    # a pixel's ray at scattered depths; with the span alone (no sheet
    # reaches) the fragments split into surfaces that composed as
    # independent layers and the background showed through: 60 pixels
    # inside the polygons' outline below alpha 0.95, 0.972 on average. The
    # sheet's reach: 20, 0.988. The GPU matches the twin.
    mesh = wavy()
    cloud = texture_points(build_texture(mesh, 64, 16, bounds=mesh.bounds))
    assert cloud.one_sided is None and cloud.sheet is not None and cloud.sheet.mean() > 0.95
    el = math.radians(15.0)
    cam = Camera((0.0, 3.2 * math.sin(el), 3.2 * math.cos(el)), (0.0, 0.0, 0.0), fov=40.0)
    img, view = draw_float(r, cloud, cam)
    rgb, alpha = composite_np(subpixel_fragments_np(cloud, view, SplatOptions(quality="high")),
                              view.lighting.background)  # fmt: skip
    assert np.abs(img[..., 3] - alpha).max() < TOL, np.abs(img[..., 3] - alpha).max()
    assert np.abs(img[..., :3] - rgb).max() < TOL, np.abs(img[..., :3] - rgb).max()
    truth = r.render(mesh, cam, "mesh", ssaa=4, alpha=True)[..., 3] / 255.0
    inside = ndimage.binary_erosion(truth > 0.999, iterations=1)
    assert inside.sum() > 300
    assert (img[..., 3][inside] < 0.95).sum() <= 25 and img[..., 3][inside].mean() > 0.985
    monkeypatch.setattr(params, "AA_SHEET_REACH", False)
    _, before = composite_np(subpixel_fragments_np(cloud, view, SplatOptions(quality="high")))
    assert (before[inside] < 0.95).sum() >= 50 and before[inside].mean() < 0.975


@pytest.mark.gpu
def test_a_sheets_flag_leaves_its_shading_alone(r):
    # The flag rides as ks's sign bit: "fast" (deferred shading from the
    # attribute texture) and "high" draw a flagged cloud as they draw it
    # unflagged, from straight above (no splat grazes, so none reaches).
    mesh = wavy(amp=0.02)
    flagged = texture_points(build_texture(mesh, 32, 16, bounds=mesh.bounds))
    assert flagged.sheet is not None
    plain = PointCloud(flagged.positions, flagged.normals, flagged.areas, flagged.kd, flagged.ks + 0.3,
                       flagged.shininess, coherence=flagged.coherence, clips=flagged.clips)  # fmt: skip
    flagged = PointCloud(plain.positions, plain.normals, plain.areas, plain.kd, plain.ks, plain.shininess,
                         coherence=plain.coherence, clips=plain.clips, sheet=flagged.sheet)  # fmt: skip
    cam = Camera((0.0, 3.0, 0.0), (0.0, 0.0, 0.0), up=(0.0, 0.0, -1.0), fov=40.0)
    for quality in ("fast", "high"):
        a = r.render(plain, cam, "splat", quality=quality)
        b = r.render(flagged, cam, "splat", quality=quality)
        assert np.array_equal(a, b), quality
