"""Line halos: a strip's footprint carried into the voxels beside it
(render/sheet_line_halos.py).

Held against closed forms (a halo's lines are its strip's, moved into its
voxel's frame; no halo where the plane goes on), a beam's shadow across it
with a voxel a pixel wide (the NumPy twin), and the twin of GPU pixels the
halos change.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_render_volume import pixel_angle, pixel_rays, render_float
from test_sheet_strips import BOUNDS, across_the_beam, beam

from aniso3d.build.texture import build_texture
from aniso3d.grid import cell_keys
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.lighting import Lighting
from aniso3d.rendering.sheet_halfplanes import C_BITS, C_RANGE, line_inward, plane_origin
from aniso3d.rendering.sheet_line_halos import LineHalos
from aniso3d.rendering.volume import STRIP_PIXELS, march_ray_np, sheet_layout


def no_line_halos(layout):
    return dataclasses.replace(layout, line_halos=LineHalos.empty(), line_keys=np.zeros(0, np.int64),
                               line_order=np.zeros(0, np.int64))  # fmt: skip


@pytest.fixture(scope="module")
def beam_texture():
    mesh, rot = beam(0.6, 35.0, -25.0)
    tex = build_texture(mesh, 32, 16, bounds=BOUNDS)
    return tex, rot, sheet_layout(tex)


def test_a_halos_lines_are_its_strips(beam_texture):
    """Points of each halo's plane in its voxel lie on the same side of, and
    as far from, the halo's lines as of its strip's (the strip's frame
    shifted by the voxel step): within half the near line's 12-bit step
    (4.9e-4 voxel) and float32 for the far one. The halo's plane is the
    strip's."""
    tex, _, layout = beam_texture
    lh, sh, st = layout.line_halos, layout.sheets, layout.strips
    assert len(lh.row) > 50
    rng = np.random.default_rng(1)
    r = lh.row
    n = sh.normal[r]
    step = lh.cell - np.asarray(tex.coords)[np.asarray(tex.entry_voxel)[r]]
    assert np.all(np.abs(step).sum(axis=1) == 1)
    np.testing.assert_allclose(lh.offset, sh.offset[r] - np.einsum("ek,ek->e", n, step), atol=1e-12)
    # A point of the plane in the halo's voxel (local), and the same point
    # in the strip's voxel's frame.
    p = rng.random((len(r), 3))
    p -= (np.einsum("ek,ek->e", n, p) - lh.offset)[:, None] * n
    u = line_inward(st.angle[r], n)
    s_halo = np.einsum("ek,ek->e", p - plane_origin(n, lh.offset), u)
    s_strip = np.einsum("ek,ek->e", p + step - plane_origin(n, sh.offset[r]), u)
    code_step = 2 * C_RANGE / ((1 << C_BITS) - 1)
    np.testing.assert_allclose(s_halo - lh.lo, s_strip - st.lo[r], atol=0.5 * code_step + 1e-9)
    far = np.isfinite(st.hi[r])
    assert far.any()
    np.testing.assert_allclose((s_halo - lh.hi)[far], (s_strip - st.hi[r])[far], atol=1e-5)


def test_no_halo_where_the_plane_goes_on(beam_texture):
    """A beam's face goes on through the voxels along the beam: no halo of
    a strip lies in a voxel holding an entry of the same plane (normal
    within 0.7, the plane within 0.3 voxel of the halo's at its centre);
    every halo lies in a cell beside the beam's, most of them empty."""
    tex, _, layout = beam_texture
    lh, sh = layout.line_halos, layout.sheets
    coords = np.asarray(tex.coords, np.int64)
    keys = cell_keys(coords, np.asarray(tex.shape))
    inside = np.all((lh.cell >= 0) & (lh.cell < np.asarray(tex.shape)), axis=1)
    hk = cell_keys(np.where(inside[:, None], lh.cell, 0), np.asarray(tex.shape))
    pos = np.minimum(np.searchsorted(keys, hk), len(keys) - 1)
    occupied = inside & (keys[pos] == hk)
    for i in np.flatnonzero(occupied):
        v = pos[i]
        rows = np.arange(tex.entry_offsets[v], tex.entry_offsets[v + 1])
        n = sh.normal[lh.row[i]]
        q = plane_origin(n[None], lh.offset[i : i + 1])[0]
        same = (np.abs(sh.normal[rows] @ n) >= 0.7) & (np.abs(sh.normal[rows] @ q - sh.offset[rows]) <= 0.3)
        assert not same.any(), i
    assert (~occupied).mean() > 0.5


@pytest.mark.parametrize("shift", [-0.5, -0.4])
def test_a_beams_alpha_across_it_with_a_voxel_a_pixel(shift, monkeypatch):
    """A beam 0.6 voxel wide along x, inside one column of voxels (the grid
    shifted by ``shift``: its faces 0.2 and 0.1 voxel from the column's
    walls), parallel rays across it with a voxel a pixel wide (footprint 1
    voxel, strips drawn from STRIP_PIXELS, ramps over the whole footprint:
    STRIP_FOOT 1), at three places along it, against its shadow ``W (|a . u|
    + |b . u|)`` box-filtered by the pixel. Rays that pass beside the column
    (on screen) reach the beam only through the halos: there alpha is 0
    without them and within 0.01 of the filtered shadow on average with
    them (measured 0.0055 and 0.0060; 0.025 and 0.023 off without). Over the
    whole profile the halos halve the error (measured 0.027 against 0.054
    and 0.062; the rest is the strips' own, inside the column)."""
    from aniso3d.rendering import volume

    assert STRIP_PIXELS <= 1.0
    monkeypatch.setattr(volume, "STRIP_FOOT", 1.0)
    W = 0.6
    mesh, rot = beam(W, 0.0, 0.0)
    tex = build_texture(mesh, 32, 16, bounds=BOUNDS + shift)
    layout = sheet_layout(tex)
    c, w, u, width = across_the_beam(rot, W)
    ds, foot = 0.05, 1.0
    s = np.arange(-2.0, 2.0 + 1e-9, ds)
    want = np.clip(np.minimum(s + foot / 2, width / 2) - np.maximum(s - foot / 2, -width / 2), 0, None) / foot
    # The column (y, z in [shift, shift + 1]) seen along w spans its centre's
    # offset on u plus or minus half its shadow's width.
    beside = np.abs(s - (shift + 0.5) * (u[1] + u[2])) > 0.5 * (abs(u[1]) + abs(u[2]))
    assert (want[beside] > 0).sum() >= 8
    light = Lighting()
    err, past = {}, {}
    for name, lay in (("halos", layout), ("none", no_line_halos(layout))):
        got = np.array([[march_ray_np(tex, along * c + x * u - 100 * w, w, light, pixel_angle=foot / 100,
                                      layout=lay)[1] for x in s] for along in (-4.0, 0.3, 4.1)])  # fmt: skip
        e = np.abs(got - want[None])
        err[name], past[name] = float(e.mean()), float(e[:, beside].mean())
        if name == "none":
            assert np.all(got[:, beside] == 0.0)
    assert past["halos"] < 0.01 < 0.02 < past["none"], past
    assert err["halos"] < 0.6 * err["none"], err


@pytest.mark.gpu
@pytest.mark.parametrize("yaw, pitch, shift, least", [(0.0, 0.0, -0.5, 10), (35.0, -25.0, 0.0, 4)])
def test_twin_agrees_where_the_halos_draw(r, yaw, pitch, shift, least):
    """The beam, along x in a column of voxels and turned off the grid,
    with a voxel about a pixel: up to 20 pixels the halos change (against
    the twin without them; at least ``least``: the turned beam's voxels
    along it mostly continue each other's planes) and 10 others partly
    covered, the GPU against march_ray_np within 1/255 (RGB and alpha)."""
    mesh, _ = beam(0.6, yaw, pitch)
    tex = build_texture(mesh, 32, 16, bounds=BOUNDS + shift)
    layout = sheet_layout(tex)
    size = (96, 96)
    cam = Camera((9.0 * 1.6, 13.0 * 1.6, 55.0 * 1.6), (0.0, 0.0, 0.0), fov=30.0)
    img, _ = render_float(r, tex, cam, size)
    dirs, t0, t1 = pixel_rays(cam, size, tex.bounds)
    pa = pixel_angle(cam, size)
    a = img[..., 3]
    partial = np.argwhere((a > 0.02) & (a < 0.98))
    assert len(partial) > 40
    bare = no_line_halos(layout)
    changed, other = [], []
    for y, x in partial:
        with_h = march_ray_np(tex, cam.position, dirs[y, x], r.lighting, (t0[y, x], t1[y, x]), pixel_angle=pa,
                              layout=layout)  # fmt: skip
        without = march_ray_np(tex, cam.position, dirs[y, x], r.lighting, (t0[y, x], t1[y, x]), pixel_angle=pa,
                               layout=bare)  # fmt: skip
        (changed if abs(with_h[1] - without[1]) > 2 / 255 else other).append((y, x, with_h))
        if len(changed) >= 20 and len(other) >= 10:
            break
    assert len(changed) >= least and len(other) >= 10, (len(changed), len(other))
    for y, x, (rgb, alpha) in changed[:20] + other[:10]:
        got = img[y, x]
        assert np.abs(rgb - got[:3]).max() < 1 / 255 and abs(alpha - got[3]) < 1 / 255, (y, x, rgb, alpha, got)


def test_halos_made_in_chunks_are_the_same(beam_texture, monkeypatch):
    """line_halos in chunks of 7 entries gives the halos it gives at once
    (the memory bound changes nothing)."""
    from aniso3d.rendering import sheet_line_halos
    from aniso3d.rendering.volume import sheet_line_halos as layout_halos

    tex, _, layout = beam_texture
    whole = layout.line_halos
    monkeypatch.setattr(sheet_line_halos, "_CHUNK", 7)
    chunked = layout_halos(layout.sheets, layout.halfplanes, layout.strips, tex)
    for f in LineHalos.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(chunked, f), getattr(whole, f), err_msg=f)
