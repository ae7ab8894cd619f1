"""Shading across voxels (render/sheet_slopes.py): each surface sheet's
linear model of its normal and reflectance across its plane, fitted to its
neighbours, with which the volume renderer shades where the ray crosses it.
Held against closed forms (a sphere's shape operator is the identity over
its radius; a linear colour ramp's slope; a colour step is not smeared), the
model's evaluation, and the supersampled polygons of smooth objects.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_render_volume import render_float
from test_volume_coverage import erode, truth

import aniso3d
from aniso3d.build.mesh import Mesh
from aniso3d.grid import tangent_frame
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.sheet_slopes import sheet_slopes, smoothed
from aniso3d.rendering.volume import RUN_SHARE, entry_sheets


def _slopes(tex):
    sh = entry_sheets(tex)
    surface = sh.share >= RUN_SHARE
    return sh, surface, sheet_slopes(tex, sh, surface)


@pytest.mark.parametrize("resolution", [32, 64])
def test_a_spheres_shape_operator_is_one_over_its_radius(resolution):
    """A unit sphere (R = resolution / 2 voxels): the normal turns by 1/R
    per voxel along any direction of the plane, so S11 = S22 = 1/R and S12
    = 0. The limited slopes (the smaller of the two sides') measured 2-4%
    under 1/R at the median (S12 under 5% of it)."""
    tex = aniso3d.build_texture(aniso3d.scenes.sphere(1.0, subdivisions=6), resolution, 16)
    _, surface, sl = _slopes(tex)
    k = tex.voxel_size / 1.0
    s = sl.shape[surface]
    assert np.median(s[:, 0]) == pytest.approx(k, rel=0.05)
    assert np.median(s[:, 2]) == pytest.approx(k, rel=0.05)
    assert np.median(np.abs(s[:, 1])) < 0.05 * k
    np.testing.assert_array_equal(sl.shape[~surface], 0.0)


def _coloured_plane(kd_of_x) -> Mesh:
    """A 2 x 2 plane (z = 0.01, off the grid planes) of 64 x 64 quads, each
    quad coloured by ``kd_of_x`` at its centre's x."""
    n = 64
    u = np.linspace(-1.0, 1.0, n + 1)
    x, y = np.meshgrid(u, u, indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.full(x.size, 0.01)], axis=1)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = (i * (n + 1) + j).ravel()
    f = np.concatenate([np.stack([a, a + n + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + 1], 1)])
    cx = np.concatenate([(u[:-1] + 0.5 * (u[1] - u[0]))[i.ravel()]] * 2)
    return Mesh.from_arrays(v, f, kd_of_x(cx), 0.1, 10.0, name="plane")


def test_a_colour_ramp_has_its_slope_and_a_step_none():
    """A plane whose red rises linearly along x by 0.25 per unit: each
    sheet's red slope along x is 0.25 h per voxel (h the voxel edge), in the
    tangent frame's terms (measured at the median within 2%); green, blue
    and the normal's slopes 0. A plane whose colour steps at x = 0.1: no
    sheet gets a slope (the limiter sees a flat side), so the step stays
    sharp."""
    bounds = np.array([[-1.0, -1.0, -0.5], [1.0, 1.0, 0.5]])
    ramp = _coloured_plane(lambda x: np.stack([0.5 + 0.25 * x, np.full_like(x, 0.4), np.full_like(x, 0.3)], 1))
    tex = aniso3d.build_texture(ramp, 32, 16, bounds=bounds)
    sh, surface, sl = _slopes(tex)
    inner = surface & (np.abs(tex.entry_centroid[:, :2]) < 0.85).all(axis=1)
    t1, t2 = tangent_frame(sh.normal[inner])
    # d(red)/dx = 0.25 per unit = 0.25 h per voxel; along (t1, t2): t . x times that.
    want = 0.25 * tex.voxel_size * np.stack([t1[:, 0], t2[:, 0]], axis=1)
    np.testing.assert_allclose(np.median(sl.kd[inner][:, :, 0] - want, axis=0), 0.0, atol=0.02 * 0.25 * tex.voxel_size)
    assert np.abs(sl.kd[inner][:, :, 1:]).max() < 1e-6
    assert np.abs(sl.shape[inner]).max() < 1e-6
    step = _coloured_plane(lambda x: np.where((x < 0.1)[:, None], [0.8, 0.2, 0.2], [0.2, 0.2, 0.8]))
    tex = aniso3d.build_texture(step, 32, 16, bounds=bounds)
    sh, surface, sl = _slopes(tex)
    # Sheets of one colour, among them those beside the voxels the step
    # crosses (whose colour is mixed): a least-squares fit over both sides
    # would slope them towards the step.
    pure = surface & ((np.abs(tex.entry_kd[:, 0] - 0.8) < 1e-6) | (np.abs(tex.entry_kd[:, 0] - 0.2) < 1e-6))
    mixed = surface & ~pure
    assert mixed.sum() >= 32 and (pure & (np.abs(tex.entry_centroid[:, 0] - 0.1) < 1.5 * tex.voxel_size)).sum() >= 32
    assert np.abs(sl.kd[pure]).max() < 1e-6


def test_the_model_holds_the_entry_at_the_voxel_centre_and_is_linear_across():
    """smoothed(): at the plane's point nearest the voxel's centre the stored
    normal and reflectance; a step (u, v) along the tangent frame adds the
    shape operator's and the reflectance slopes' terms (the normal keeps its
    stored length, the coherence)."""
    n = np.array([[0.0, 0.0, 0.8]])
    unit = np.array([[0.0, 0.0, 1.0]])
    kd = np.array([[0.5, 0.4, 0.3]])
    shape = np.array([[0.1, 0.02, -0.05]])
    kds = np.array([[[0.01, 0.0, -0.02], [0.0, 0.03, 0.0]]])
    centre = np.array([[0.5, 0.5, 0.3]])
    n0, k0 = smoothed(n, kd, shape, kds, unit, np.array([0.3]), centre)
    np.testing.assert_allclose(n0, n)
    np.testing.assert_allclose(k0, kd)
    t1, t2 = tangent_frame(unit)
    p = centre + 0.4 * t1 - 0.2 * t2
    n1, k1 = smoothed(n, kd, shape, kds, unit, np.array([0.3]), p)
    u, v = 0.4, -0.2
    direction = unit + (0.1 * u + 0.02 * v) * t1 + (0.02 * u - 0.05 * v) * t2
    np.testing.assert_allclose(n1, 0.8 * direction / np.linalg.norm(direction))
    np.testing.assert_allclose(k1, kd + u * kds[:, 0] + v * kds[:, 1])


@pytest.mark.gpu
@pytest.mark.parametrize("name", ["sphere", "blob"])
@pytest.mark.parametrize("scale", [1.0, 2.0])
def test_smooth_surfaces_shade_smoothly(r, name, scale, tmp_path):
    """A sphere and the corpus blob (32^3; a voxel about 2 and 1 pixels):
    inside their outline (eroded by 2 pixels) the volume's colour is within
    1/255 of the 8 x 8 polygons' on average (measured 0.47-0.56). Shading
    each sheet with its voxel's values (``shading="flat"``) puts the surface
    in steps a voxel wide: measured 1.61-1.83."""
    mesh = aniso3d.scenes.sphere(1.0, subdivisions=6) if name == "sphere" else aniso3d.scenes.get_scene("blob")
    tex = aniso3d.build_texture(mesh, 32, 16)
    cam = Camera.frame(mesh.bounds, (0.55, 0.35, 1.0), fov=30.0, distance_scale=scale)
    ref = truth(r, mesh, cam, ssaa=8)
    core = erode(ref[..., 3] >= 254.5 / 255, 2)
    assert core.sum() > 500
    err = {}
    for shading in ("smooth", "flat"):
        img, _ = render_float(r, tex, cam, shading=shading)
        err[shading] = float(np.abs(img[..., :3] - ref[..., :3]).mean(axis=-1)[core].mean()) * 255
    assert err["smooth"] < 1.0, err
    assert err["flat"] > 1.4, err
