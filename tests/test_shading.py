"""Shading an aggregate's normal spread (lighting.glsl, ``shade_np``'s ``coherence``).

Checked against independent things: the plain Phong closed form where the
facets are one plane; the mean of the facets' own shading for a fine V-groove
minified into voxels (built with ``build_texture``, shaded by the volume's
NumPy twin); a texture built at half the resolution for the pyramid's
aggregation; the GPU against the NumPy twins (volume and splats).
"""

from __future__ import annotations

import numpy as np
import pytest

import aniso3d
from aniso3d.build.mesh import Mesh
from aniso3d.build.points import PointCloud
from aniso3d.build.pyramid import pyramid
from aniso3d.build.texture import build_texture, entry_coherence, sphere_directions
from aniso3d.grid import tangent_frame
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.lighting import Light, Lighting, shade_np
from aniso3d.rendering.volume import trace_ray_np, voxel_colors

ON, OFF = Lighting(normal_spread=True), Lighting(normal_spread=False)


def phong(n, v, kd, ks, s, lighting):
    """The plain two-sided Phong of one plane, written out independently."""
    n = n / np.linalg.norm(n)
    n = n if n @ v >= 0 else -n
    out = np.asarray(lighting.ambient) * kd
    for light in lighting.lights:
        d = np.asarray(light.direction, float)
        d /= np.linalg.norm(d)
        ndl = n @ d
        if ndl > 0:
            r = 2 * ndl * n - d
            out = out + np.asarray(light.color) * (np.asarray(kd) * ndl + ks * max(r @ v, 0.0) ** s)
    return out


def test_one_plane_is_the_plain_closed_form():
    rng = np.random.default_rng(3)
    n = rng.normal(size=(500, 3))
    v = rng.normal(size=(500, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    kd, ks, s = rng.random((500, 3)), rng.random(500), rng.uniform(0.5, 200, 500)
    want = np.array([phong(n[i], v[i], kd[i], ks[i], s[i], ON) for i in range(500)])
    for got in (shade_np(n, v, kd, ks, s, ON, 1.0), shade_np(n, v, kd, ks, s, ON),
                shade_np(n, v, kd, ks, s, OFF, rng.random(500))):  # fmt: skip
        assert np.abs(got - want).max() < 1e-12
    # A spread really changes it, and never to NaN (coherence 0, exponent 0).
    c = rng.random(500)
    c[:5] = 0.0
    s[:3] = 0.0
    spread = shade_np(n, v, kd, ks, s, ON, c)
    assert np.isfinite(spread).all() and np.abs(spread - want).max() > 0.05


def groove(d0: np.ndarray, theta: float, ridges: int = 32) -> Mesh:
    """A unit square of fine V-grooves across the tangent axis b of ``d0``:
    facets of two normals, ``d0`` turned by +-theta about t, equal areas."""
    t, b = (a[0] for a in tangent_frame(d0[None]))
    v = np.arange(2 * ridges + 1) * 0.5 / ridges
    h = np.where(np.arange(2 * ridges + 1) % 2, 0.5 / ridges * np.tan(theta), 0.0)
    verts = np.concatenate([u * t + v[:, None] * b + h[:, None] * d0 for u in (0.0, 1.0)])
    n = len(v)
    i = np.arange(n - 1)
    faces = np.concatenate([np.stack([i, i + 1, i + 1 + n], 1), np.stack([i, i + 1 + n, i + n], 1)])
    tri = verts[faces]
    up = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]) @ d0 < 0
    faces[up] = faces[up][:, [0, 2, 1]]
    return Mesh.from_arrays(verts, faces, (0.7, 0.5, 0.3), 0.5, 30.0)


def face_normals(mesh: Mesh) -> np.ndarray:
    tri = mesh.vertices[mesh.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_minified_v_groove_shades_closer_to_its_facets_mean():
    """Each voxel holds both facets of several grooves in one entry (both
    normals lie in one sample direction's cell): its coherence is cos theta,
    and the volume twin's colour with the spread shaded is closer to the mean
    of the two facets' own colours (weighted by projected area, as a pixel
    sees them) than the colour of their mean normal."""
    dirs = sphere_directions(16)
    d0, theta = dirs[3], np.radians(20.0)
    mesh = groove(d0, theta)
    face_n = np.unique(np.round(face_normals(mesh), 9), axis=0)
    assert len(face_n) == 2 and all(np.argmax(dirs @ n) == 3 for n in face_n)
    tex = build_texture(mesh, 8, 16)
    coh = entry_coherence(tex)
    single = np.flatnonzero((np.diff(tex.entry_offsets) == 1) & (np.abs(coh - np.cos(theta)) < 0.01))
    assert len(single) > 50  # voxels holding whole grooves
    rng = np.random.default_rng(1)
    views = rng.normal(size=(400, 3))
    views /= np.linalg.norm(views, axis=1, keepdims=True)
    views = np.concatenate([[d0], views[views @ d0 > 0.2]])
    err = {True: [], False: []}
    for v in views:
        for on in (True, False):
            light = ON if on else OFF
            each = np.clip(shade_np(face_n, np.tile(v, (2, 1)), mesh.kd[0], mesh.ks[0], mesh.shininess[0], light), 0, 1)
            w = np.abs(face_n @ v)
            truth = (w[:, None] * each).sum(0) / w.sum()
            got = voxel_colors(tex, -v, light, voxels=single)
            err[on].append(np.abs(got - truth).mean())
    on, off = np.array(err[True]), np.array(err[False])
    assert on[0] < 0.5 * off[0]  # head-on: both facets equally weighted
    assert on.mean() < 0.8 * off.mean()


def test_coherence_aggregates_exactly_up_the_pyramid():
    """Level 1 of the pyramid is the texture built at half the resolution:
    the entries' coherence too (the mean normal is a linear sum)."""
    mesh = aniso3d.scenes.sphere(1.0, subdivisions=3)
    fine = build_texture(mesh, 16, 16)
    half = build_texture(mesh, 8, 16, bounds=fine.bounds)
    lvl = pyramid(fine, 2)[1]
    assert np.array_equal(lvl.coords, half.coords) and np.array_equal(lvl.entry_direction, half.entry_direction)
    a, b = entry_coherence(lvl), entry_coherence(half)
    assert np.abs(a - b).max() < 1e-5
    assert a.min() < 0.995  # the sphere's curvature spreads the normals of a coarse voxel
    # The level's points carry it, per point.
    cloud, _ = pyramid(fine, 2).level_cloud(1, per_entry=2)
    assert np.array_equal(cloud.coherence, np.repeat(a, 2))


def test_point_cloud_coherence_is_checked():
    p = np.zeros((2, 3))
    n = np.tile([0.0, 0.0, 1.0], (2, 1))
    assert np.array_equal(PointCloud(p, n, [1.0, 1.0], (0.5,) * 3, 0.1, 8.0).coherence, [1.0, 1.0])
    assert np.array_equal(PointCloud(p, n, [1.0, 1.0], (0.5,) * 3, 0.1, 8.0, coherence=[1.5, -1]).coherence,
                          [1.0, 0.0])  # fmt: skip
    with pytest.raises(aniso3d.errors.InputError, match="coherence"):
        PointCloud(p, n, [1.0, 1.0], (0.5,) * 3, 0.1, 8.0, coherence=[1.0])
    with pytest.raises(aniso3d.errors.InputError, match="coherence"):
        PointCloud(p, n, [1.0, 1.0], (0.5,) * 3, 0.1, 8.0, coherence=[np.nan, 1.0])


# ------------------------------------------------------------------- GPU

SIZE = (96, 96)
ONE_LIGHT = Lighting(ambient=(0.1, 0.1, 0.1), lights=(Light((0.3, 0.5, 0.8), (0.9, 0.9, 0.9)),))


@pytest.mark.gpu
@pytest.mark.parametrize("quality", ["fast", "high"])
def test_splats_shade_their_coherence_as_the_twin(r, quality):
    """One splat filling the view with coherence 0.8: every pixel is
    shade_np with that coherence (float32 against float64: well under a grey
    level), and visibly not the plain closed form."""
    cloud = PointCloud([[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]], [1e4], [(0.6, 0.5, 0.4)], 0.6, 12.0,
                       coherence=[0.8])  # fmt: skip
    cam = Camera((0.3, 0.2, 2.0), (0.3, 0.2, 0.0), fov=70.0)
    d = cam.ray_directions(SIZE).reshape(-1, 3)
    n = np.tile([0.0, 0.0, 1.0], (len(d), 1))
    for light in (ONE_LIGHT, Lighting(ONE_LIGHT.ambient, ONE_LIGHT.lights, normal_spread=False)):
        own = aniso3d.Renderer(SIZE, gl=r.gl, lighting=light)
        try:
            img = own.render(cloud, cam, "splat", quality=quality, alpha=True).astype(np.float64) / 255
        finally:
            own.release()
        want = np.clip(shade_np(n, -d, cloud.kd, cloud.ks, cloud.shininess, light, cloud.coherence), 0, 1)
        assert np.abs(img[..., :3].reshape(-1, 3) - want).max() <= 1.01 / 255
    plain = np.clip(shade_np(n, -d, cloud.kd, cloud.ks, cloud.shininess, ONE_LIGHT), 0, 1)
    spread = np.clip(shade_np(n, -d, cloud.kd, cloud.ks, cloud.shininess, ONE_LIGHT, 0.8), 0, 1)
    assert np.abs(plain - spread).max() > 0.05


@pytest.mark.gpu
def test_volume_shades_the_entries_coherence_as_the_twin(r):
    """The V-groove texture in the volume renderer: pixels against the NumPy
    ray with the spread on and off, and the two differ."""
    dirs = sphere_directions(16)
    mesh = groove(dirs[3], np.radians(20.0))
    tex = build_texture(mesh, 8, 16)
    cam = Camera.frame(tex.bounds, direction=dirs[3] + 0.2 * tangent_frame(dirs[3][None])[0][0])
    dirs_px = cam.ray_directions(SIZE)
    near, far = cam.clip_range(tex.bounds)
    cos_f = dirs_px @ cam.forward
    angle = 2.0 * np.tan(np.radians(cam.fov) / 2) / SIZE[1]
    got = {}
    for on in (True, False):
        light = Lighting(ONE_LIGHT.ambient, ONE_LIGHT.lights, normal_spread=on)
        own = aniso3d.Renderer(SIZE, gl=r.gl, lighting=light)
        try:
            img = own.render(tex, cam, "volume", alpha=True).astype(np.float64) / 255
        finally:
            own.release()
        opaque = np.argwhere(img[..., 3] > 0.99)
        assert len(opaque) > 100
        for y, x in opaque[:: max(1, len(opaque) // 30)]:
            tr = trace_ray_np(tex, cam.position, dirs_px[y, x], light, (near / cos_f[y, x], far / cos_f[y, x]),
                              pixel_angle=angle)  # fmt: skip
            assert np.abs(tr.rgb - img[y, x, :3]).max() < 1.5 / 255, (on, y, x)
        got[on] = img
    assert np.abs(got[True][..., :3] - got[False][..., :3]).max() > 0.03
