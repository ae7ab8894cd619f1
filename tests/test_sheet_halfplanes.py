"""Half-planes: a partial sheet's edge inside its voxel
(render/sheet_halfplanes.py).

Held against closed forms and an independent sampling of the section (the
clipped polygon's area and centroid), a straight border built as polygons
(the fitted line within a few hundredths of a voxel of the true one), the
screen distance to the line found by projection, the supersampled polygons
(an open sheet's outline close up), and the NumPy twin of a GPU pixel.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_render_volume import pixel_angle, pixel_rays, render_float
from test_volume_coverage import truth, voxel_pixels

import aniso3d
from aniso3d.build.mesh import Mesh
from aniso3d.grid import tangent_frame
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.sheet_halfplanes import (
    HALF_TOLERANCE,
    clipped_piece,
    fit_halfplanes,
    halfplane_ramp,
    section_polygons,
)
from aniso3d.rendering.volume import entry_sheets, march_ray_np, plane_section_area, sheet_layout

SIZE = (128, 128)


def random_planes(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    lo, hi = np.minimum(normal, 0).sum(1), np.maximum(normal, 0).sum(1)
    return normal, lo + (hi - lo) * rng.uniform(0.1, 0.9, n)


def section_samples(normal, offset, count: int = 400_000, seed: int = 1):
    """Points spread uniformly over the section of the unit cube by one
    plane (rejection from the disc of radius sqrt(3)/2 about q0), in the
    plane's tangent coordinates about q0."""
    rng = np.random.default_rng(seed)
    t1, t2 = (x[0] for x in tangent_frame(normal[None]))
    q0 = 0.5 - (normal.sum() * 0.5 - offset) * normal
    uv = rng.uniform(-0.87, 0.87, (count, 2))
    p = q0 + uv[:, :1] * t1 + uv[:, 1:] * t2
    inside = np.all((p >= 0) & (p <= 1), axis=1)
    return uv[inside], (2 * 0.87) ** 2 / count


# ------------------------------------------------------- no GPU: geometry


def test_section_polygons_have_the_closed_form_area():
    """The polygons' areas are plane_section_area's (closed form) on random
    planes, and the hexagon x + y + z = 3/2 has its 6 corners."""
    n, d = random_planes(500)
    uv, real, _ = section_polygons(n, d)
    area, _, _ = clipped_piece(uv[..., 0], uv[..., 1], np.tile([1.0, 0.0], (500, 1)), np.full(500, -9.0))
    np.testing.assert_allclose(area, plane_section_area(n, d), atol=1e-12)
    _, real, _ = section_polygons(np.full((1, 3), 3**-0.5), np.array([1.5 * 3**-0.5]))
    assert real.sum() == 6


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_clipped_area_and_centroid_against_sampling(seed):
    """A random plane cut by a random line: the area and centroid of the
    section's part on the line's side are those of uniform samples of the
    section (400 000 points: within 1% of the area and 0.01 voxel)."""
    n, d = random_planes(1, seed)
    rng = np.random.default_rng(seed)
    th = rng.uniform(-np.pi, np.pi)
    u = np.array([[np.cos(th), np.sin(th)]])
    c = rng.uniform(-0.2, 0.2, 1)
    uv, _, _ = section_polygons(n, d)
    area, cent, _ = clipped_piece(uv[..., 0], uv[..., 1], u, c)
    pts, cell = section_samples(n[0], d[0])
    side = pts[pts @ u[0] >= c[0]]
    assert abs(area[0] - len(side) * cell) < 0.01 * area[0]
    np.testing.assert_allclose(cent[0], side.mean(axis=0), atol=0.01)


def test_fit_recovers_a_half_plane():
    """Half-planes made on random planes (random directions and offsets):
    given their area and centroid, the fit comes within half the
    tolerance of their centroid on 93% of them (the rest are read as
    before), and where it does it finds their line again (the covered side
    agrees on 99% of the section's samples)."""
    N = 400
    n, d = random_planes(N, seed=3)
    rng = np.random.default_rng(4)
    th = rng.uniform(-np.pi, np.pi, N)
    u = np.stack([np.cos(th), np.sin(th)], 1)
    uv, _, frame = section_polygons(n, d)
    s = np.einsum("nek,nk->ne", uv, u)
    c = s.min(1) + (s.max(1) - s.min(1)) * rng.uniform(0.2, 0.8, N)
    area, cent, _ = clipped_piece(uv[..., 0], uv[..., 1], u, c)
    q0 = 0.5 - (n.sum(1) * 0.5 - d)[:, None] * n
    centroid = q0 + cent[:, :1] * frame[:, 0] + cent[:, 1:] * frame[:, 1]
    th_fit, c_fit, residual, _, _ = fit_halfplanes(n, d, area, centroid)
    good = residual < HALF_TOLERANCE / 2
    assert good.mean() > 0.93
    for i in np.flatnonzero(good)[::40]:
        pts, _ = section_samples(n[i], d[i], 40_000)
        want = pts @ u[i] >= c[i]
        got = pts @ np.array([np.cos(th_fit[i]), np.sin(th_fit[i])]) >= c_fit[i]
        assert (want == got).mean() > 0.99


def open_sheet(size: float = 1.0, slant: float = 0.3) -> Mesh:
    """A flat square sheet (one layer, open border) turned so that none of
    its edges lies along the grid, 40 x 40 cells."""
    u = np.linspace(-0.5 * size, 0.5 * size, 41)
    x, y = np.meshgrid(u, u, indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    a, b = slant, 0.5 * slant
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    idx = np.arange(41 * 41).reshape(41, 41)
    q = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 4)
    faces = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    return Mesh.from_arrays(v @ (rx @ rz).T, faces, (0.8, 0.7, 0.6), 0.1, 16.0, name="sheet")


def test_an_open_sheets_border_reads_as_half_planes():
    """The voxels along a flat sheet's border (not on grid planes) that it
    fills in part: all but a few (its corners) are half-planes, and their
    lines away from the corners lie within 0.01 voxel of the sheet's true
    border at the median, 0.1 at worst."""
    mesh = open_sheet()
    tex = aniso3d.build_texture(mesh, 24, 16)
    layout = sheet_layout(tex)
    hp, sh = layout.halfplanes, layout.sheets
    partial = (sh.fill > 0.05) & (sh.fill < 0.95)
    assert partial.sum() > 40
    assert hp.mask[partial].mean() > 0.85
    # The border's lines in world units: the square's edges.
    rows = np.flatnonzero(hp.mask)
    h = tex.voxel_size
    n = sh.normal[rows]
    t1, t2 = tangent_frame(n)
    u = np.cos(hp.angle[rows])[:, None] * t1 + np.sin(hp.angle[rows])[:, None] * t2
    q0 = 0.5 - (n.sum(1) * 0.5 - sh.offset[rows])[:, None] * n
    # The line's point nearest q0, in world units, back in the sheet's own frame.
    on_line = (q0 + hp.offset[rows][:, None] * u + tex.coords[tex.entry_voxel[rows]]) * h + tex.origin
    a, b = 0.3, 0.15
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    local = on_line @ (rx @ rz)
    to_border = 0.5 - np.abs(local[:, :2]).max(axis=1)
    # (Away from the corners, where two borders meet in one voxel.)
    cell = (tex.coords[tex.entry_voxel[rows]] + 0.5) * h + tex.origin
    corner = np.abs(np.abs(cell @ (rx @ rz))[:, :2] - 0.5).max(axis=1) < 1.5 * h
    assert (~corner).sum() > 30
    off = np.abs(to_border[~corner]) / h
    assert np.median(off) < 0.01 and off.max() < 0.1, (np.median(off), off.max())


def test_halfplane_ramp_is_the_footprint_share_across_the_projected_line():
    """Random planes, lines, crossings and views: the ramp is 1/2 plus the
    screen distance from the crossing to the line (both projected along the
    ray onto a plane across it) over the footprint, clamped; with no
    footprint, the side alone."""
    rng = np.random.default_rng(7)
    N = 300
    n, d = random_planes(N, seed=8)
    th = rng.uniform(-np.pi, np.pi, N)
    c = rng.uniform(-0.3, 0.3, N)
    t1, t2 = tangent_frame(n)
    q0 = 0.5 - (n.sum(1) * 0.5 - d)[:, None] * n
    p = q0 + rng.uniform(-0.4, 0.4, (N, 1)) * t1 + rng.uniform(-0.4, 0.4, (N, 1)) * t2
    w = rng.normal(size=3)
    w /= np.linalg.norm(w)
    foot = rng.uniform(0.2, 1.5, N)
    got = halfplane_ramp(th, c, d, p, n, w, foot)
    u = np.cos(th)[:, None] * t1 + np.sin(th)[:, None] * t2
    t = np.cross(n, u)
    a = q0 + c[:, None] * u  # a point on the line
    flat = lambda x: x - (x @ w)[:, None] * w  # noqa: E731  (projection along the ray)
    pa, ta = flat(p - a), flat(t)
    ta /= np.linalg.norm(ta, axis=1, keepdims=True)
    across = pa - np.einsum("nk,nk->n", pa, ta)[:, None] * ta
    side = np.sign(np.einsum("nk,nk->n", p - a, u))
    want = np.clip(0.5 + side * np.linalg.norm(across, axis=1) / foot, 0, 1)
    np.testing.assert_allclose(got, want, atol=1e-9)
    np.testing.assert_array_equal(halfplane_ramp(th, c, d, p, n, w, 0.0), (side > 0).astype(float))


def test_leaves_in_the_middle_of_voxels_are_no_half_planes():
    """Small square leaves wholly inside their voxels (centred in them):
    their centroid is far from any half-plane's of their area."""
    rng = np.random.default_rng(2)
    centres = (np.stack(np.meshgrid(*[np.arange(4)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5) / 4
    quads = []
    for cen in centres:  # a few dozen leaves: the test's setup, not the code under test
        r = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        quads.append(aniso3d.scenes.quad(0.1, (0, 0, 0)).vertices @ r.T + cen)
    v = np.concatenate(quads)
    f = (np.arange(len(centres))[:, None, None] * 4 + np.array([[0, 1, 2], [0, 2, 3]])).reshape(-1, 3)
    mesh = Mesh.from_arrays(v, f, (0.3, 0.6, 0.2), 0.1, 16.0, name="leaves")
    tex = aniso3d.build_texture(mesh, 4, 16, bounds=np.array([[0.0, 0, 0], [1, 1, 1]]))
    sh = entry_sheets(tex)
    assert (sh.fill > 0.01).all()
    assert not sheet_layout(tex).halfplanes.mask.any()


# ------------------------------------------------------------- GPU


@pytest.mark.gpu
def test_an_open_sheets_outline_close_up(r):
    """A flat open sheet seen with a voxel over 3 pixels: the mean alpha
    error over its outline's pixels (those the 8 x 8 polygons cover in
    part) is under 0.06 (measured 0.037; its border smeared over its voxels'
    sections without half-planes: 0.30)."""
    mesh = open_sheet()
    tex = aniso3d.build_texture(mesh, 24, 16)
    cam = Camera.frame(tex.bounds, (0.3, 0.5, 1.0), fov=30.0)
    assert voxel_pixels(tex, cam) > 3.0
    ref = truth(r, mesh, cam, ssaa=8)
    img, _ = render_float(r, tex, cam)
    edge = (ref[..., 3] > 0.02) & (ref[..., 3] < 0.98)
    assert edge.sum() > 100
    err = np.abs(img[..., 3] - ref[..., 3])[edge].mean()
    assert err < 0.06, err


@pytest.mark.gpu
@pytest.mark.parametrize("scale", [1.0, 3.0])
def test_twin_agrees_on_half_planes(r, scale):
    """30 pixels of a flat open sheet's outline (close up and with a voxel
    about a pixel) against march_ray_np: RGB and alpha within 1/255."""
    mesh = open_sheet()
    tex = aniso3d.build_texture(mesh, 24, 16)
    cam = Camera.frame(tex.bounds, (0.3, 0.5, 1.0), fov=30.0, distance_scale=scale)
    img, _ = render_float(r, tex, cam)
    dirs, t0, t1 = pixel_rays(cam, SIZE, tex.bounds)
    layout = sheet_layout(tex)
    a = img[..., 3]
    partial = np.argwhere((a > 0.03) & (a < 0.97))
    assert len(partial) > 30
    rng = np.random.default_rng(3)
    for y, x in partial[rng.choice(len(partial), 30, replace=False)]:
        rgb, alpha = march_ray_np(tex, cam.position, dirs[y, x], r.lighting, (t0[y, x], t1[y, x]),
                                  pixel_angle=pixel_angle(cam, SIZE), layout=layout)  # fmt: skip
        got = img[y, x]
        assert np.abs(rgb - got[:3]).max() < 1 / 255 and abs(alpha - got[3]) < 1 / 255, (y, x, rgb, alpha, got)
