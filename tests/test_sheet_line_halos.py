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
    (4.9e-4 voxel) and float32 for the far one; but a split face's halo
    (SPLIT_REST), whose band is the part of its strip's that the strip
    across leaves: within its strip's band, one line its strip's. The
    halo's plane is the strip's."""
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
    # in the strip's voxel's frame: the halo's lines in the strip's frame.
    p = rng.random((len(r), 3))
    p -= (np.einsum("ek,ek->e", n, p) - lh.offset)[:, None] * n
    u = line_inward(st.angle[r], n)
    s_halo = np.einsum("ek,ek->e", p - plane_origin(n, lh.offset), u)
    s_strip = np.einsum("ek,ek->e", p + step - plane_origin(n, sh.offset[r]), u)
    lo, hi = lh.lo + s_strip - s_halo, lh.hi + s_strip - s_halo
    code_step = 2 * C_RANGE / ((1 << C_BITS) - 1)
    tol = 0.5 * code_step + 1e-5
    same_lo, same_hi = np.abs(lo - st.lo[r]) <= tol, np.isclose(hi, st.hi[r], rtol=0, atol=1e-5)
    same_hi |= ~np.isfinite(st.hi[r]) & ~np.isfinite(lh.hi)
    assert np.all(lo >= st.lo[r] - tol) and np.all(hi <= st.hi[r] + tol)
    assert np.all(same_lo | same_hi)
    whole = same_lo & same_hi
    assert whole.mean() > 0.5 and (~whole).any()
    far = np.isfinite(st.hi[r])
    assert far.any()


def _band_in(lh, i, sh, st, r):
    """Strip ``r``'s band in the frame of halo ``i`` (same voxel), along the
    halo's inward normal."""
    n = sh.normal[lh.row[i]]
    q = plane_origin(n[None], lh.offset[i : i + 1])[0]
    u = line_inward(st.angle[lh.row[i] : lh.row[i] + 1], n[None])[0]
    n2 = sh.normal[r]
    u2 = line_inward(st.angle[r : r + 1], n2[None])[0]
    c = (q - plane_origin(n2[None], sh.offset[r : r + 1])[0]) @ u2
    a, b = st.lo[r] - c, st.hi[r] - c
    return (-b, -a) if u2 @ u < 0 else (a, b)


def test_no_halo_where_the_plane_goes_on(beam_texture, monkeypatch):
    """A beam's face goes on through the voxels along the beam: no halo of
    a strip lies in a voxel holding an entry of the same plane (normal
    within 0.7, the plane within 0.3 voxel of the halo's at its centre)
    but a strip of it whose band the halo's does not overlap (at most
    0.005 voxel, a few 12-bit steps: measured 0.0026), the other part of a
    face a voxel face splits along its length (SPLIT_REST); every halo
    lies in a cell beside the beam's, and those of split faces are the only
    ones SPLIT_REST adds."""
    from aniso3d.rendering import sheet_line_halos

    tex, _, layout = beam_texture
    lh, sh, st = layout.line_halos, layout.sheets, layout.strips
    coords = np.asarray(tex.coords, np.int64)
    keys = cell_keys(coords, np.asarray(tex.shape))
    inside = np.all((lh.cell >= 0) & (lh.cell < np.asarray(tex.shape)), axis=1)
    hk = cell_keys(np.where(inside[:, None], lh.cell, 0), np.asarray(tex.shape))
    pos = np.minimum(np.searchsorted(keys, hk), len(keys) - 1)
    occupied = inside & (keys[pos] == hk)
    split = np.zeros(len(lh.row), bool)
    for i in np.flatnonzero(occupied):
        v = pos[i]
        rows = np.arange(tex.entry_offsets[v], tex.entry_offsets[v + 1])
        n = sh.normal[lh.row[i]]
        q = plane_origin(n[None], lh.offset[i : i + 1])[0]
        same = (np.abs(sh.normal[rows] @ n) >= 0.7) & (np.abs(sh.normal[rows] @ q - sh.offset[rows]) <= 0.3)
        assert st.mask[rows[same]].all(), i
        for r in rows[same]:
            a, b = _band_in(lh, i, sh, st, r)
            assert min(lh.hi[i], b) - max(lh.lo[i], a) <= 0.005, (i, r)
            split[i] = True
    assert split.any()
    monkeypatch.setattr(sheet_line_halos, "SPLIT_REST", None)
    before = sheet_layout(tex).line_halos
    old = {(int(r), *map(int, c)) for r, c in zip(before.row, before.cell, strict=True)}
    new = {(int(r), *map(int, c)) for r, c in zip(lh.row[~split], lh.cell[~split], strict=True)}
    assert old == new


def _two_strips(u_across):
    """line_halos of one strip in voxel (5, 5, 5) on the plane z = 0.5 (voxel
    units), its band y in [0.6, 1] (its line on the face to +y), and a strip
    of the same plane in the voxel across that face, its lines along the
    inward normal ``u_across``: the halos' cells and bands."""
    import types

    from aniso3d.grid import tangent_frame
    from aniso3d.rendering.sheet_line_halos import SPLIT_REST, line_halos

    shape = np.array([16, 16, 16])
    coords = np.array([[5, 5, 5], [5, 6, 5]])
    assert np.all(np.diff(cell_keys(coords, shape)) > 0)
    n = np.array([[0.0, 0.0, 1.0]] * 2)

    def angle(u):
        t1, t2 = tangent_frame(n[:1])
        return float(np.arctan2(np.asarray(u) @ t2[0], np.asarray(u) @ t1[0]))

    tex = types.SimpleNamespace(coords=coords, shape=shape, entry_voxel=np.array([0, 1]),
                                entry_offsets=np.array([0, 1, 2]))  # fmt: skip
    sheets = types.SimpleNamespace(normal=n, offset=np.array([0.5, 0.5]))
    # Across: y in [0, 0.3] of its voxel (s = y - 0.5), or x in [0.4, 0.6].
    lo2, hi2 = (-0.5, -0.2) if u_across[1] else (-0.1, 0.1)
    strips = types.SimpleNamespace(mask=np.array([True, True]), angle=np.array([angle([0, 1, 0]), angle(u_across)]),
                                   lo=np.array([0.1, lo2]), hi=np.array([0.5, hi2]))  # fmt: skip
    out = {}
    for rest in (SPLIT_REST, None):
        lh = line_halos(tex, sheets, np.array([0]), strips.angle[:1], strips.lo[:1], strips.hi[:1], np.inf, strips,
                        rest)  # fmt: skip
        across = np.all(lh.cell == coords[1], axis=1)
        out[rest] = (lh.lo[across], lh.hi[across])
    return out


def test_a_split_halo_only_beside_the_other_part_of_its_face():
    """Where the strip across has lines parallel to the entry's (the other
    part of a face a voxel face splits along its length), the entry has a
    halo there carrying its whole band (moved one voxel: y - 1.5 in [-0.9,
    -0.5]); where its lines cross the entry's (another beam's face in the
    same plane), none, as without SPLIT_REST."""
    from aniso3d.rendering.sheet_line_halos import SPLIT_REST

    parallel = _two_strips([0.0, 1.0, 0.0])
    lo, hi = parallel[SPLIT_REST]
    assert len(lo) == 1
    np.testing.assert_allclose([lo[0], hi[0]], [-0.9, -0.5], atol=1e-3)
    assert len(parallel[None][0]) == 0
    crossing = _two_strips([1.0, 0.0, 0.0])
    assert len(crossing[SPLIT_REST][0]) == 0 and len(crossing[None][0]) == 0


def test_a_beam_split_along_a_voxel_face(monkeypatch):
    """A beam 0.8 voxel wide along x, whose faces the grid's voxel faces
    split down the middle: each voxel holds a strip of half a face, and a
    ray crossing the plane in one of them counted that half of the
    footprint alone. With a voxel a pixel, parallel rays across it against
    its box-filtered shadow (as above): with the halos of the halves
    (SPLIT_REST) the shadow's centre is covered (alpha at least 0.98;
    measured 1.0) and the error over the profile is under 0.6 of that
    without them (measured 0.028 against 0.060; the centre 0.74-0.79)."""
    from aniso3d.rendering import sheet_line_halos, volume

    assert sheet_line_halos.SPLIT_REST is not None
    monkeypatch.setattr(volume, "STRIP_FOOT", 1.0)
    W = 0.8
    mesh, rot = beam(W, 0.0, 0.0)
    tex = build_texture(mesh, 32, 16, bounds=BOUNDS)
    c, w, u, width = across_the_beam(rot, W)
    ds, foot = 0.05, 1.0
    s = np.arange(-2.0, 2.0 + 1e-9, ds)
    want = np.clip(np.minimum(s + foot / 2, width / 2) - np.maximum(s - foot / 2, -width / 2), 0, None) / foot
    assert want.max() == 1.0
    light = Lighting()
    err, centre = {}, {}
    for name in ("split", "none"):
        if name == "none":
            monkeypatch.setattr(sheet_line_halos, "SPLIT_REST", None)
        layout = sheet_layout(tex)
        got = np.array([[march_ray_np(tex, along * c + x * u - 100 * w, w, light, pixel_angle=foot / 100,
                                      layout=layout)[1] for x in s] for along in (-4.0, 0.3, 4.1)])  # fmt: skip
        err[name] = float(np.abs(got - want[None]).mean())
        centre[name] = got[:, np.argmin(np.abs(s))]
    assert np.all(centre["split"] >= 0.98), centre
    assert err["split"] < 0.6 * err["none"], err


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
@pytest.mark.parametrize("yaw, pitch, shift, least", [(0.0, 0.0, -0.5, 10), (0.0, 0.0, 0.0, 10), (35.0, -25.0, 0.0, 4)])
def test_twin_agrees_where_the_halos_draw(r, yaw, pitch, shift, least):
    """The beam, along x in a column of voxels, along x split down the
    middle by voxel faces (its halves' halos, SPLIT_REST) and turned off
    the grid, with a voxel about a pixel: up to 20 pixels the halos change (against
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
    chunked = layout_halos(layout.sheets, layout.strips, tex)
    for f in LineHalos.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(chunked, f), getattr(whole, f), err_msg=f)
