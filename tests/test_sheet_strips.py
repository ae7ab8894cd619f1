"""Strips: a thin solid's face between two lines inside its voxel
(render/sheet_strips.py).

Held against closed forms: strips made on random planes (the fit finds
their lines again), a closed square beam of known width turned off the grid
(its faces' lines are its edges; its alpha across it, with a voxel several
pixels wide, is its shadow box-filtered by the pixel), the screen distances
to the lines found by projection, and the NumPy twin of a GPU pixel.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_render_volume import pixel_angle, pixel_rays, render_float
from test_sheet_halfplanes import random_planes

from aniso3d.build.mesh import Mesh
from aniso3d.build.scenes import _boxes
from aniso3d.build.texture import build_texture
from aniso3d.grid import tangent_frame
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.lighting import Lighting
from aniso3d.rendering.sheet_halfplanes import clipped_piece, section_polygons
from aniso3d.rendering.sheet_strips import STRIP_TOLERANCE, SheetStrips, fit_strips, strip_cover
from aniso3d.rendering.volume import march_ray_np, sheet_layout

# ------------------------------------------------------- no GPU: geometry


def test_fit_recovers_a_strip():
    """Strips made on random planes (random directions, both lines inside
    the section): given their area, centroid and direction, the fit finds
    both lines within 1e-3 voxel on 95 % of them and its centroid within
    the tolerance on all but 2 %."""
    N = 400
    n, d = random_planes(N, seed=5)
    rng = np.random.default_rng(6)
    th = rng.uniform(-np.pi, np.pi, N)
    u = np.stack([np.cos(th), np.sin(th)], 1)
    uv, _, frame = section_polygons(n, d)
    s = np.einsum("nek,nk->ne", uv, u)
    lo_s, hi_s = s.min(1), s.max(1)
    a, b = np.sort(rng.uniform(0.1, 0.9, (N, 2)), axis=1).T
    b = np.maximum(b, a + 0.1)
    lo, hi = lo_s + (hi_s - lo_s) * a, lo_s + (hi_s - lo_s) * b
    a1, c1, _ = clipped_piece(uv[..., 0], uv[..., 1], u, lo)
    a2, c2, _ = clipped_piece(uv[..., 0], uv[..., 1], u, hi)
    area = a1 - a2
    cent = (a1[:, None] * c1 - a2[:, None] * c2) / area[:, None]
    q0 = 0.5 - (n.sum(1) * 0.5 - d)[:, None] * n
    centroid = q0 + cent[:, :1] * frame[:, 0] + cent[:, 1:] * frame[:, 1]
    # The lines' direction t = u x n in 3D (u = n x t).
    u3 = u[:, :1] * frame[:, 0] + u[:, 1:] * frame[:, 1]
    axis = np.cross(u3, n) + 0.3 * n  # (off the plane: the fit projects it)
    th_fit, lo_fit, hi_fit, residual, err = fit_strips(n, d, area, centroid, axis)
    np.testing.assert_allclose(np.cos(th_fit - th), 1.0, atol=1e-12)
    good = (np.abs(lo_fit - lo) < 1e-3) & (np.abs(hi_fit - hi) < 1e-3)
    assert good.mean() > 0.95, good.mean()
    assert (residual < STRIP_TOLERANCE).mean() > 0.98
    assert err[good].max() < 1e-4


def beam(width: float, yaw: float, pitch: float) -> tuple[Mesh, np.ndarray]:
    """A closed square beam ``width`` voxels wide (grid of 32 over 32 units:
    voxels of 1), 24 long, turned ``yaw`` degrees about y and ``pitch`` about
    x; and its rotation (columns: axis, then the faces' normals)."""
    y, p = np.radians(yaw), np.radians(pitch)
    ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    rx = np.array([[1, 0, 0], [0, np.cos(p), -np.sin(p)], [0, np.sin(p), np.cos(p)]])
    rot = rx @ ry
    v, f, _ = _boxes(np.array([[-12.0, -width / 2, -width / 2]]), np.array([[12.0, width / 2, width / 2]]))
    return Mesh.from_arrays(v @ rot.T, f, (0.8, 0.4, 0.1), 0.3, 20.0, name="beam"), rot


BOUNDS = np.array([[-16.0] * 3, [16.0] * 3])


def across_the_beam(rot: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """For parallel rays across the beam of rotation ``rot`` and ``width``:
    its axis c, the rays' unit direction w, the unit direction u across the
    beam and the rays, and the beam's shadow's width along u, ``W (|a . u|
    + |b . u|)`` (a and b its faces' normals)."""
    c, a, b = rot[:, 0], rot[:, 1], rot[:, 2]
    w = np.array([0.3, -0.4, -1.0]) / np.linalg.norm([0.3, -0.4, -1.0])
    wp = w - (w @ c) * c
    u = np.cross(c, wp / np.linalg.norm(wp))
    return c, w, u, width * (abs(a @ u) + abs(b @ u))
ANGLES = [(20.0, 10.0), (35.0, -25.0), (60.0, 5.0)]


@pytest.mark.parametrize("yaw, pitch", ANGLES)
def test_a_beams_faces_read_as_strips_along_its_edges(yaw, pitch):
    """A beam 0.6 voxel wide at three angles: away from its ends, 90 % of
    its faces' partial sheets are strips (or closed half-planes), and the
    strips' lines, where they cross their sections, lie on the beam's edges:
    within 0.002 voxel at the median and 0.01 at the 95th percentile
    (measured 1e-4 and 3e-4)."""
    W = 0.6
    mesh, rot = beam(W, yaw, pitch)
    tex = build_texture(mesh, 32, 16, bounds=BOUNDS)
    layout = sheet_layout(tex)
    sh, st = layout.sheets, layout.strips
    centre = (tex.coords[tex.entry_voxel] + 0.5) * tex.voxel_size + tex.origin
    inner = np.abs(centre @ rot[:, 0]) < 10.0
    partial = inner & (sh.fill > 0.05) & (sh.fill < 0.95)
    assert partial.sum() > 100
    assert st.mask[partial].mean() > 0.9, st.mask[partial].mean()
    rows = np.flatnonzero(st.mask & inner & np.isfinite(st.hi))
    assert len(rows) > 50
    n = sh.normal[rows]
    t1, t2 = tangent_frame(n)
    u2 = np.stack([np.cos(st.angle[rows]), np.sin(st.angle[rows])], 1)
    u = u2[:, :1] * t1 + u2[:, 1:] * t2
    q0 = 0.5 - (n.sum(1) * 0.5 - sh.offset[rows])[:, None] * n
    uv, _, _ = section_polygons(n, sh.offset[rows])
    # The other cross axis of the beam (the face's edges lie at +-W/2 on it).
    across = np.where((np.abs(n @ rot[:, 1]) > 0.9)[:, None], rot[:, 2], rot[:, 1])
    off = []
    for c in (st.lo[rows], st.hi[rows]):
        _, _, chord = clipped_piece(uv[..., 0], uv[..., 1], u2, c)
        on_line = (q0 + c[:, None] * u + tex.coords[tex.entry_voxel[rows]]) * tex.voxel_size + tex.origin
        dist = np.abs(np.abs(np.einsum("nk,nk->n", on_line, across)) - W / 2)
        off.append(dist[chord > 0.05])
    off = np.concatenate(off) / tex.voxel_size
    assert np.median(off) < 0.002 and np.quantile(off, 0.95) < 0.01, (np.median(off), np.quantile(off, 0.95))


def test_strip_cover_is_the_footprints_share_between_the_projected_lines():
    """Random planes, strips, crossings and views: the cover is the overlap
    of the footprint (a box across the lines, centred on the crossing) with
    the band between the two lines projected along the ray onto a plane
    across it, over the footprint's width; with an infinite far line, the
    near line's side."""
    rng = np.random.default_rng(9)
    N = 300
    n, d = random_planes(N, seed=10)
    th = rng.uniform(-np.pi, np.pi, N)
    lo = rng.uniform(-0.4, 0.2, N)
    hi = lo + rng.uniform(0.05, 0.6, N)
    t1, t2 = tangent_frame(n)
    q0 = 0.5 - (n.sum(1) * 0.5 - d)[:, None] * n
    p = q0 + rng.uniform(-0.5, 0.5, (N, 1)) * t1 + rng.uniform(-0.5, 0.5, (N, 1)) * t2
    w = rng.normal(size=3)
    w /= np.linalg.norm(w)
    foot = rng.uniform(0.2, 1.5, N)
    got = strip_cover(th, lo, hi, d, p, n, w, foot)
    u = np.cos(th)[:, None] * t1 + np.sin(th)[:, None] * t2
    t = np.cross(n, u)
    flat = lambda x: x - (x @ w)[:, None] * w  # noqa: E731  (projection along the ray)
    ta = flat(t)
    ta /= np.linalg.norm(ta, axis=1, keepdims=True)

    def screen(c):
        """Signed screen distance from the crossing to the line at offset c
        (positive on the side u points to)."""
        pa = flat(p - (q0 + c[:, None] * u))
        across = pa - np.einsum("nk,nk->n", pa, ta)[:, None] * ta
        return np.sign(np.einsum("nk,nk->n", p - (q0 + c[:, None] * u), u)) * np.linalg.norm(across, axis=1)

    a, b = screen(lo), screen(hi)  # covered where a + y >= 0 and b + y < 0
    want = np.clip(np.minimum(0.5 * foot, -b) - np.maximum(-0.5 * foot, -a), 0.0, None) / foot
    np.testing.assert_allclose(got, want, atol=1e-9)
    half = strip_cover(th, lo, np.full(N, np.inf), d, p, n, w, foot)
    np.testing.assert_allclose(half, np.clip(0.5 + a / foot, 0, 1), atol=1e-9)


def no_strips(layout):
    E = len(layout.strips.mask)
    return dataclasses.replace(layout, strips=SheetStrips(np.zeros(E, bool), *np.zeros((3, E)), np.full(E, np.inf)))


@pytest.mark.parametrize("yaw, pitch", ANGLES[:2])
def test_a_beams_alpha_across_it_is_its_shadow_filtered(yaw, pitch):
    """Parallel rays across a beam 0.6 voxel wide with a voxel 4 pixels (the
    NumPy twin of the GPU), at three places along it: alpha across the beam
    is its shadow ``W (|a . u| + |b . u|)`` (u across the beam and the rays,
    a and b its faces' normals) box-filtered by the pixel, within 0.04 on
    average (measured 0.024 and 0.014; its backs, a quarter drawn, add a
    little at the sides); its sum is the shadow's width within 5 %. Without
    strips (each face's fill spread over its section) the profile is off by
    more than four times that (measured 0.15 and 0.21)."""
    W = 0.6
    mesh, rot = beam(W, yaw, pitch)
    tex = build_texture(mesh, 32, 16, bounds=BOUNDS)
    layout = sheet_layout(tex)
    c, w, u, width = across_the_beam(rot, W)
    ds, foot = 0.05, 0.25
    s = np.arange(-1.5, 1.5 + 1e-9, ds)
    want = np.clip(np.minimum(s + foot / 2, width / 2) - np.maximum(s - foot / 2, -width / 2), 0, None) / foot
    light = Lighting()
    err, total = {}, {}
    for name, lay in (("strips", layout), ("spread", no_strips(layout))):
        got = np.array([[march_ray_np(tex, along * c + x * u - 100 * w, w, light, pixel_angle=foot / 100,
                                      layout=lay)[1] for x in s] for along in (-4.0, 0.3, 4.1)])  # fmt: skip
        err[name] = float(np.abs(got - want).mean())
        total[name] = float(got.sum(axis=1).mean() * ds)
    assert err["strips"] < 0.04 and err["spread"] > 4 * err["strips"], err
    assert abs(total["strips"] / width - 1.0) < 0.05, (total, width)


# ------------------------------------------------------------- GPU


@pytest.mark.gpu
@pytest.mark.parametrize("distance", [20.0, 55.0])
def test_twin_agrees_on_strips(r, distance):
    """30 partly covered and 10 opaque pixels of a beam 0.6 voxel wide
    (voxels about 4 and 1.5 pixels) against march_ray_np: RGB and alpha
    within 1/255."""
    mesh, _ = beam(0.6, 35.0, -25.0)
    tex = build_texture(mesh, 32, 16, bounds=BOUNDS)
    layout = sheet_layout(tex)
    assert layout.strips.mask.sum() > 100
    size = (96, 96)
    cam = Camera(tuple(np.array([9.0, 13.0, 55.0]) * distance / 55.0), (0.0, 0.0, 0.0), fov=30.0)
    img, _ = render_float(r, tex, cam, size)
    dirs, t0, t1 = pixel_rays(cam, size, tex.bounds)
    a = img[..., 3]
    partial, opaque = np.argwhere((a > 0.03) & (a < 0.97)), np.argwhere(a >= 0.97)
    assert len(partial) > 30 and len(opaque) > 10
    rng = np.random.default_rng(4)
    picks = np.concatenate([partial[rng.choice(len(partial), 30)], opaque[rng.choice(len(opaque), 10)]])
    for y, x in picks:
        rgb, alpha = march_ray_np(tex, cam.position, dirs[y, x], r.lighting, (t0[y, x], t1[y, x]),
                                  pixel_angle=pixel_angle(cam, size), layout=layout)  # fmt: skip
        got = img[y, x]
        assert np.abs(rgb - got[:3]).max() < 1 / 255 and abs(alpha - got[3]) < 1 / 255, (y, x, rgb, alpha, got)
