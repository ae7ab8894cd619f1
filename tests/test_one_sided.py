"""One-sided points: a piece of a closed surface is never seen from behind
(while the eye is outside it), so its points face one way and the splat
renderer culls those that face away (aniso3d.build.points.PointCloud.one_sided).

Without it, a closed object's back splats fall into the same pixels and
depths as its front ones at the silhouette, and the coverage-aware splats
add the two: its outline comes out too thick.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import module_renderer

from aniso3d import AnisoTexture, PointCloud, build_texture, scenes
from aniso3d.bench.corpus import corpus_cameras
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.splat import SplatOptions
from aniso3d.rendering.splat.reference import composite_np, subpixel_fragments_np

SIZE = (64, 64)


r = module_renderer(SIZE)


def two_sided(p: PointCloud) -> PointCloud:
    return PointCloud(p.positions, p.normals, p.areas, p.kd, p.ks, p.shininess, coherence=p.coherence)


def test_points_of_closed_surfaces_are_one_sided_and_face_out():
    cube = scenes.cube()
    pts = build_texture(cube, 16, 16).to_points()
    assert pts.one_sided is not None and pts.one_sided.all()
    outward = np.einsum("ij,ij->i", pts.normals, pts.positions - cube.bounds.mean(axis=0))
    assert np.all(outward > 0)
    # Wound inwards: the points still face out, and keep the whole area.
    inward = scenes.cube()
    inward = type(inward).from_arrays(inward.vertices, inward.faces[:, ::-1])
    back = build_texture(inward, 16, 16).to_points()
    assert back.one_sided.all()
    assert np.all(np.einsum("ij,ij->i", back.normals, back.positions - cube.bounds.mean(axis=0)) > 0)
    np.testing.assert_allclose(back.areas.sum(), pts.areas.sum(), rtol=1e-9)
    # Open surfaces (a quad; a tree's leaves): two-sided.
    assert build_texture(scenes.quad(1.0), 16, 16).to_points().one_sided is None


@pytest.mark.gpu
def test_a_sheet_facing_away_is_culled_and_the_twin_agrees(r):
    # Sub-pixel splats of a square facing away from the eye (normal -z, the
    # eye on +z): one-sided, nothing is drawn; two-sided, the square is.
    cam = Camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov=40.0)
    g = (np.arange(-16, 16, 0.5) + 0.25) * 0.034
    x, y = (v.ravel() for v in np.meshgrid(g, g))
    n = x.size
    sheet = PointCloud(np.c_[x, y, np.zeros(n)], np.tile([0.0, 0.0, -1.0], (n, 1)), np.full(n, 0.017**2),
                       np.tile([0.2, 0.7, 0.3], (n, 1)), 0.0, 8.0, one_sided=np.ones(n, bool))  # fmt: skip
    near, far = cam.clip_range(sheet.bounds)
    view = FrameView(cam, r.lighting, SIZE, near, far)
    for cloud, drawn in ((sheet, False), (two_sided(sheet), True)):
        img = r.render(cloud, cam, "splat", quality="high", alpha=True)
        assert (img[..., 3].max() > 0) == drawn
        if drawn:
            assert img[20:44, 20:44, 3].min() == 255
        frags = subpixel_fragments_np(cloud, view, SplatOptions(quality="high"))
        _, alpha = composite_np(frags, view.lighting.background)
        assert (alpha.max() > 0) == drawn
    # The eye inside the cloud's bounds (between the splats of a box): no culling.
    inside = Camera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), fov=40.0)
    box = PointCloud(sheet.positions * [1, 1, 0] + [0, 0, -0.3], np.tile([0.0, 0.0, 1.0], (n, 1)), sheet.areas,
                     sheet.kd, 0.0, 8.0, one_sided=np.ones(n, bool))  # fmt: skip
    guard = PointCloud(np.array([[0.0, 0.0, 0.3]]), np.array([[0.0, 0.0, 1.0]]), np.array([1e-4]),
                       np.array([[0.5, 0.5, 0.5]]), 0.0, 8.0)  # fmt: skip
    cloud = PointCloud(*(np.concatenate([getattr(box, a), getattr(guard, a)])
                         for a in ("positions", "normals", "areas", "kd", "ks", "shininess")),
                       one_sided=np.r_[np.ones(n, bool), False])  # fmt: skip
    assert np.all(cloud.bounds[0] < 0) and np.all(cloud.bounds[1] > 0)
    img = r.render(cloud, inside, "splat", quality="high", alpha=True)
    assert img[24:40, 24:40, 3].min() == 255  # faces away from the eye, drawn all the same


@pytest.mark.gpu
@pytest.mark.parametrize("name, resolution, size", [("sphere", 64, 256), ("cube", 32, 192)])
def test_a_closed_objects_outline_is_as_thick_as_its_meshs(name, resolution, size):
    # Minified (a voxel about a pixel), alpha in the outline's pixels (the
    # truth's alpha strictly between 0.02 and 0.98) against 8x8 polygons:
    # mean error within 0.07 (measured -0.048 on the sphere, -0.001 on the
    # cube); with the points two-sided +0.114 and +0.273.
    mesh = scenes.get_scene(name)
    pts = build_texture(mesh, resolution, 16).to_points()
    spec = [s for s in corpus_cameras(mesh, (size, size), resolution) if s.label == "minified"][0]
    with Renderer((size, size)) as rr:
        truth = rr.render(mesh, spec.camera, "mesh", ssaa=8, alpha=True)[..., 3] / 255.0
        ring = (truth > 0.02) & (truth < 0.98)
        err = {}
        for label, cloud in (("one", pts), ("two", two_sided(pts))):
            alpha = rr.render(cloud, spec.camera, "splat", quality="high", alpha=True)[..., 3] / 255.0
            err[label] = float((alpha - truth)[ring].mean())
    assert abs(err["one"]) < 0.07, err
    assert err["two"] > 0.1, err
    assert math.isfinite(err["one"])


# ------------------------------------------------------- through a file (v6)


def sided_scene():
    """Sides +1, -1 and 0: a cube wound outwards, a cube wound inwards, a thin
    slab (both its faces in one voxel: cover 1/2 as two-sided points) and an
    open square."""
    cube = scenes.cube()
    move = lambda m, x, y, z, sz=1.0: m.transformed(np.array(  # noqa: E731
        [[1, 0, 0, x], [0, 1, 0, y], [0, 0, sz, z], [0, 0, 0, 1]], dtype=np.float64))
    inward = type(cube).from_arrays(cube.vertices, cube.faces[:, ::-1])
    from aniso3d.build.mesh import concatenate
    return concatenate([cube, move(inward, 2.0, 0.0, 0.0), move(cube, 0.0, 2.0, 0.0, 0.02),
                        move(scenes.quad(1.0), 2.0, 2.0, 0.0)], name="sided")  # fmt: skip


@pytest.fixture(scope="module")
def sided():
    return build_texture(sided_scene(), 24, 16)


def test_the_scene_has_every_side(sided):
    side = sided.entry_side
    assert {-1, 0, 1} <= set(np.unique(side).tolist())
    assert np.any((side != 0) & (sided.entry_cover < 0.9))  # the slab's faces hide each other


@pytest.mark.parametrize("encoding", ["compact", "exact"])
@pytest.mark.parametrize("normal", ["mean", "sample"])
def test_points_of_a_loaded_texture_are_the_built_ones(sided, tmp_path, encoding, normal):
    # Loaded from a file, the points are one-sided where the built ones are,
    # face the same way (out of their solids) and keep the same areas (a
    # one-sided point of the slab all of its entry's, a two-sided one the
    # share its cover says). Version 5 files lost the sides: every point
    # two-sided, the inward cube's facing in, the slab's halved.
    back = AnisoTexture.load(sided.save(tmp_path / "s.a3d", encoding=encoding))
    np.testing.assert_array_equal(back.entry_side, sided.entry_side)
    a, b = sided.to_points(normal=normal), back.to_points(normal=normal)
    assert a.one_sided is not None and b.one_sided is not None
    np.testing.assert_array_equal(b.one_sided, a.one_sided)
    cos = np.einsum("ij,ij->i", a.normals, b.normals)
    assert cos.min() > math.cos(math.radians(0.2))
    np.testing.assert_allclose(b.areas, a.areas, rtol=0.005 if encoding == "compact" else 0.0)
    if encoding == "exact":
        np.testing.assert_array_equal(b.normals, a.normals)


def test_pyramid_levels_of_a_loaded_texture_keep_the_sides(sided):
    # Coarser levels of a loaded texture merge its entries' sides; the built
    # texture's levels find theirs from the closed sums: the same sides and
    # one-sided points at every level.
    from aniso3d.build.pyramid import pyramid

    built, loaded = pyramid(sided), pyramid(sided.as_stored())
    assert len(built) == len(loaded) > 3
    for level, (a, b) in enumerate(zip(built, loaded, strict=True)):
        np.testing.assert_array_equal(b.entry_side, a.entry_side, err_msg=f"level {level}")
        np.testing.assert_array_equal(loaded.level_cloud(level)[0].one_sided, built.level_cloud(level)[0].one_sided)
    assert np.any(built[2].entry_side == -1) and np.any(built[2].entry_side == 1)
