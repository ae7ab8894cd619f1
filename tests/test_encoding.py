"""The compact texture encoding (.a3d version 2): each quantiser against its
stated error bound, the whole texture through a file, strict loading of
damaged compact files, version 1 files, and what ``nbytes`` reports."""

from __future__ import annotations

import hashlib
import io
import json
import math
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest

from aniso3d import AnisoTexture, FormatError, InputError, Mesh, build_texture, scenes, sphere_directions
from aniso3d.app.cli import main as cli_main
from aniso3d.app.common import format_bytes
from aniso3d.build import encoding as enc
from aniso3d.build.encoding import ARRAYS, DEFAULT_BITS, Bits, facet_density
from aniso3d.build.pyramid import pyramid
from aniso3d.build.texture import QUANTISED
from aniso3d.build.texture_file import FORMAT_VERSION, encoded_size, read_texture_file
from aniso3d.grid import tangent_frame

DATA = Path(__file__).resolve().parent / "data"


def small_tree():
    return scenes.tree(levels=4, leaves_per_twig=20)


@pytest.fixture(scope="module")
def tree_tex():
    return build_texture(small_tree(), 24, 16)


@pytest.fixture(scope="module")
def tree_file(tree_tex, tmp_path_factory):
    return tree_tex.save(tmp_path_factory.mktemp("enc") / "tree.a3d")


# ------------------------------------------------------------------ quantisers


def test_byte_planes_round_trip_and_layout():
    rng = np.random.default_rng(0)
    codes = rng.integers(0, 2**16, (3, 1000)).astype(np.uint16)
    planes = enc.to_planes(codes, 2)
    assert planes.shape == (6, 1000) and planes.dtype == np.uint8
    # row r: its low bytes, then its high bytes
    assert np.array_equal(planes[0], codes[0] & 0xFF) and np.array_equal(planes[1], codes[0] >> 8)
    assert np.array_equal(planes[5], codes[2] >> 8)
    assert np.array_equal(enc.from_planes(planes, 3, 2), codes)
    one = rng.integers(0, 256, (2, 7)).astype(np.uint8)
    assert np.array_equal(enc.to_planes(one, 1), one)


def test_cell_keys_round_trip_exactly_and_need_sorted_cells():
    rng = np.random.default_rng(1)
    shape = np.array([300, 200, 100])
    keys = np.unique(rng.integers(0, shape.prod(), 5000))
    coords = np.stack([keys // 20000, (keys // 100) % 200, keys % 100], axis=1)
    planes = enc._encode_keys(coords, shape)
    assert planes.shape[0] in (1, 2, 4)
    assert np.array_equal(enc._decode_keys(planes, shape), coords)
    with pytest.raises(InputError, match="not sorted"):
        enc._encode_keys(coords[::-1], shape)
    with pytest.raises(InputError, match="not sorted"):
        enc._encode_keys(np.repeat(coords[:2], 2, axis=0), shape)
    with pytest.raises(FormatError, match="outside the grid"):
        enc._decode_keys(planes, np.array([3, 3, 3]))
    with pytest.raises(FormatError, match="byte planes"):
        enc._decode_keys(np.zeros((3, 4), np.uint8), shape)


def test_occupancy_mask_round_trips_offsets_and_directions():
    rng = np.random.default_rng(2)
    for k in (1, 5, 16, 64, 100):
        occupied = rng.random((50, k)) < 0.2
        occupied[:, 0] |= ~occupied.any(axis=1)
        voxel, d = np.nonzero(occupied)
        offsets = np.concatenate([[0], np.cumsum(occupied.sum(axis=1))])
        mask = enc._encode_mask(offsets, d, k)
        assert mask.shape == (50, (k + 7) // 8)
        got_off, got_d = enc._decode_mask(mask, 50, k)
        assert np.array_equal(got_off, offsets) and np.array_equal(got_d, d)
    with pytest.raises(InputError, match="not sorted"):
        enc._encode_mask(np.array([0, 2]), np.array([3, 1]), 4)
    with pytest.raises(InputError, match="outside"):
        enc._encode_mask(np.array([0, 1]), np.array([4]), 4)
    bad = np.full((1, 1), 0xFF, np.uint8)  # K = 5: bits 5..7 must be clear
    with pytest.raises(FormatError, match="past the last"):
        enc._decode_mask(bad, 1, 5)


@pytest.mark.parametrize("k", [1, 5, 16, 64])
def test_split_occupancy_mask_round_trips(k):
    """Version 5's mask (even voxels' rows, then the odd voxels' bits in
    order of their face neighbours' occupancy) decodes to the same offsets
    and directions, on a grid where neighbours share directions (a surface)
    and where they do not; a bit set past the last one is refused."""
    rng = np.random.default_rng(k)
    shape = np.array([9, 7, 8])
    keys = np.unique(rng.integers(0, shape.prod(), 300))
    coords = np.stack([keys // 56, (keys // 8) % 7, keys % 8], axis=1).astype(np.int64)
    for occupied in (rng.random((len(keys), k)) < 0.3, np.broadcast_to(rng.random(k) < 0.4, (len(keys), k)).copy()):
        occupied[:, 0] |= ~occupied.any(axis=1)
        voxel, d = np.nonzero(occupied)
        offsets = np.concatenate([[0], np.cumsum(occupied.sum(axis=1))])
        mask = enc._encode_mask_split(offsets, d, k, coords, shape)
        got_off, got_d = enc._decode_mask_split(mask, len(keys), k, coords, shape)
        assert np.array_equal(got_off, offsets) and np.array_equal(got_d, d)
    odd = int((coords.sum(axis=1) % 2).sum())
    if (odd * k) % 8:
        bad = mask.copy()
        bad[0, -1] |= 1  # the last byte's lowest bit lies past the last odd voxel's bits
        with pytest.raises(FormatError, match="past the last"):
            enc._decode_mask_split(bad, len(keys), k, coords, shape)
    with pytest.raises(FormatError, match="entry_mask has shape"):
        enc._decode_mask_split(mask[:, :-1], len(keys), k, coords, shape)


@pytest.mark.parametrize("bits", [8, 12, 16])
def test_log_areas_are_within_their_relative_step(bits):
    rng = np.random.default_rng(3)
    a = np.concatenate([10.0 ** rng.uniform(-12, 1, 20000), [0.0, 0.0]])
    codes, span = enc._encode_log(a, bits)
    back = enc._decode_log(codes, bits, span)
    lo, hi = span
    assert hi == pytest.approx(np.log2(a.max()), abs=1e-12) and lo == pytest.approx(hi - enc.AREA_SPAN)
    big = a >= 2.0**lo
    # half a step in log2, plus float64 rounding
    step = (hi - lo) / (2**bits - 2)
    assert np.max(np.abs(np.log2(back[big]) - np.log2(a[big]))) <= step / 2 + 1e-12
    small = (a > 0) & ~big
    assert small.any() and np.all(back[small] <= 2.0 ** (lo + step / 2) + 1e-300) and np.all(back[small] > a[small])
    assert np.all(back[a == 0] == 0.0)
    # the default bits: 0.2 % relative
    if bits == DEFAULT_BITS.area:
        assert np.max(np.abs(back[big] / a[big] - 1)) <= 2.0 ** (enc.AREA_SPAN / (2 * 4094)) - 1 <= 0.0021


def test_log_areas_keep_a_single_value_exactly():
    for value in (1.0, 0.25, 3.7):
        codes, span = enc._encode_log(np.full(5, value), 12)
        assert np.all(enc._decode_log(codes, 12, span) == value)


@pytest.mark.parametrize("bits", [8, 10, 12, 16])
def test_octahedral_normals_are_within_the_closed_form_bound(bits):
    """A coordinate error of half a step 1/m (m = 2**(bits-1) - 1) in the
    unfolded square moves the point on the octahedron by at most sqrt(3)
    times its length (sqrt(2)/2m), and the octahedron lies at least 1/sqrt(3)
    from the centre: at most 3 / (sqrt(2) m) radians."""
    rng = np.random.default_rng(4)
    v = rng.normal(size=(200000, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    axes = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1],
                     [0.6, 0, -0.8], [0, -0.6, -0.8], [-0.6, 0.8, 0]], float)  # fmt: skip
    v = np.concatenate([v, axes])
    back = enc._decode_oct(enc._encode_oct(v, bits), bits)
    angle = np.arccos(np.clip(np.sum(back * v, axis=1), -1, 1))
    m = 2 ** (bits - 1) - 1
    assert angle.max() <= 3 / (np.sqrt(2) * m) + 1e-7
    np.testing.assert_array_equal(back[-9:-3], axes[:6])  # the axes are exact


@pytest.mark.parametrize("bits", [8, 10, 12])
def test_sample_frame_normals_are_within_the_closed_form_bound(bits):
    """About its sample direction P a normal is the point P + g on the tangent
    plane; each coordinate of g is off by at most span / 2m, and a point of
    that plane (at least 1 from the centre) moved by d turns by at most d:
    span / (sqrt(2) m) radians."""
    rng = np.random.default_rng(7)
    dirs = sphere_directions(16)
    v = rng.normal(size=(100000, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    nearest = np.argmax(v @ dirs.T, axis=1)  # each normal in its sample direction's cell
    sample = dirs[nearest]
    span = enc._frame_span(v, sample)
    assert span is not None and 0.5 < span < np.tan(np.radians(enc.FRAME_MAX_ANGLE))
    back = enc._decode_frame(enc._encode_frame(v, sample, bits, span), sample, bits, span)
    m = 2 ** (bits - 1) - 1
    angle = np.arccos(np.clip(np.sum(back * v, axis=1), -1, 1))
    assert angle.max() <= span / (np.sqrt(2) * m) + 1e-9
    assert angle.max() > 0.3 * span / (np.sqrt(2) * m)  # the bound is not vacuous
    # normals on their sample directions are exact; one 70 degrees off sends the file octahedral
    same = enc._decode_frame(enc._encode_frame(sample, sample, bits, 0.0), sample, bits, 0.0)
    np.testing.assert_allclose(same, sample, atol=1e-15)
    tilted = np.array([[np.sin(np.radians(70)), 0.0, np.cos(np.radians(70))]])
    assert enc._frame_span(tilted, np.array([[0.0, 0.0, 1.0]])) is None


def test_range_unit_and_centroid_quantisers_are_within_half_a_step():
    rng = np.random.default_rng(5)
    x = rng.uniform(0, 2.5, 10000)
    back = enc._decode_unit(enc._encode_unit(x, 8, 2.5), 8, 2.5)
    assert np.max(np.abs(back - x)) <= 2.5 / 510 + 1e-12
    exact = np.arange(256) / 255
    assert np.array_equal(enc._decode_unit(enc._encode_unit(exact, 8, 1.0), 8, 1.0), exact)
    # per-row ranges: steps of at most S / (2**bits - 1), S = max(1, largest)
    # (log2(1 + largest) in log); the ends and constant rows exact
    rows = np.stack([rng.uniform(0.1, 0.35, 5000), rng.uniform(0.35, 0.7, 5000), np.full(5000, 0.8)])
    for log, bits, scale in ((False, 8, 1.0), (False, 6, 1.0), (True, 8, 1.0), (False, 8, 40.0), (True, 5, 1e4)):
        x = rows * scale
        codes, ranges = enc._encode_range(x, bits, log=log)
        got = enc._decode_range(codes, bits, ranges, log=log)
        f = (lambda v: np.log2(1 + v)) if log else (lambda v: v)
        S = f(x.max()) if log else max(1.0, x.max())
        assert np.max(np.abs(f(got) - f(x))) <= S / (2 * (2**bits - 1)) * (1 + 1e-9)
        assert np.array_equal(got.min(axis=1), x.min(axis=1)) and np.array_equal(got.max(axis=1), x.max(axis=1))
        assert np.all(got[2] == x[2, 0])
        assert max(r[2] for r in ranges) <= 2**bits - 1 and ranges[2][2] == 0
    h, origin = 0.37, np.array([-3.0, 2.0, 11.0])
    coords = rng.integers(0, 50, (1000, 3))
    cent = origin + (coords + rng.uniform(0, 1, (1000, 3))) * h
    voxel = np.arange(1000)
    cent[:3] = origin + (coords[:3] + [[0.0, 0.5, 1.0], [0.5, 0.5, 0.5], [1.0, 0.0, 0.5]]) * h
    for bits in (2, 4, 8, 12):
        codes = enc._encode_centroid(cent, origin, h, coords, voxel, bits)
        got = enc._decode_centroid(codes, origin, h, coords, voxel, bits)
        assert np.max(np.abs(got - cent)) <= h / (2 * (2**bits - 2)) * (1 + 1e-9)
        # the voxel's faces and middle plane are exact (axis-aligned surfaces)
        np.testing.assert_allclose(got[:3], cent[:3], rtol=0, atol=1e-13)


def test_facet_density_is_the_entries_projected_area():
    rng = np.random.default_rng(6)
    dirs = rng.normal(size=(9, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    offsets = np.array([0, 3, 3, 7, 8])
    area = rng.uniform(0, 2, 8)
    normal = rng.normal(size=(8, 3)) * 0.3
    got = facet_density(area, normal, offsets, dirs)
    want = np.zeros((4, 9))
    for v in range(4):
        for e in range(offsets[v], offsets[v + 1]):
            want[v] += area[e] * np.abs(dirs @ normal[e])
    np.testing.assert_allclose(got, want, rtol=1e-14, atol=1e-15)


def test_bits_are_checked():
    bad_bits = (dict(area=1), dict(normal=17), dict(centroid=1), dict(kd=0), dict(density=-1), dict(ks=True),
                dict(centroid=8.0), dict(depth=1), dict(depth=17),
                dict(centroid_closed=1), dict(centroid_closed=17))  # fmt: skip
    for bad in bad_bits:
        with pytest.raises(InputError, match="bits for"):
            Bits(**bad)
    assert Bits(density=0).density == 0


# ------------------------------------------------------------ a whole texture


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a / np.maximum(np.linalg.norm(a, axis=1, keepdims=True), 1e-300)
    b = b / np.maximum(np.linalg.norm(b, axis=1, keepdims=True), 1e-300)
    return np.arccos(np.clip(np.sum(a * b, axis=1), -1.0, 1.0))


def assert_within_bounds(tex: AnisoTexture, got: AnisoTexture, bits: Bits = DEFAULT_BITS) -> None:
    """Every field of ``got`` (``tex`` through the compact encoding) within its stated bound."""
    h = tex.voxel_size
    for name in ("origin", "shape", "coords", "directions", "entry_offsets", "entry_direction", "entry_side"):
        assert np.array_equal(getattr(got, name), getattr(tex, name)), name
    for name in ARRAYS:
        assert getattr(got, name).dtype == getattr(tex, name).dtype, name
    # areas: half a log2 step relative, or below the span's floor
    a, a2 = tex.entry_area, got.entry_area
    step = enc.AREA_SPAN / (2**bits.area - 2)
    floor = a.max() * 2.0**-enc.AREA_SPAN
    rel = np.abs(a2 / np.maximum(a, 1e-300) - 1)
    assert np.all((rel <= 2 ** (step / 2) - 1 + 1e-12) | ((a < floor) & (a2 <= floor * 2 ** (step / 2) * 1.000001)))
    # normals: direction (octahedral, or about the sample direction with a
    # span below tan 60 degrees < 3, whichever deflates smaller) and length
    m, m_oct = 2 ** (bits.normal - 1) - 1, 2 ** (enc.oct_bits(bits) - 1) - 1
    n, n2 = tex.entry_normal.astype(np.float64), got.entry_normal.astype(np.float64)
    length = np.linalg.norm(n, axis=1)
    bound = max(3 / (np.sqrt(2) * m_oct), np.tan(np.radians(enc.FRAME_MAX_ANGLE)) / (np.sqrt(2) * m))
    # version 5: a spread mean normal (length c < 1) within NORMAL_SPREAD_SHARE
    # of its facets' spread sqrt(2 (1 - c)), as its length code gives it
    # (sqrt(1 - c) to half a code)
    code_spread = np.sqrt(np.clip(1 - np.minimum(length, 1), 0, 1)) + 1 / (2 * (2**bits.coherence - 1))
    sigma = np.sqrt(2) * code_spread
    assert np.all(angle_between(n, n2) <= np.maximum(bound, enc.NORMAL_SPREAD_SHARE * sigma) + 1e-6)
    assert angle_between(n, n2)[length >= 1 - 1e-7].max(initial=0) <= bound + 1e-6
    # length c: sqrt(1 - c) within half a step (float32 normals: |n| to 1e-7,
    # so sqrt(1 - c) to 3e-4), c within a step, 1 exact
    ell = np.minimum(length, 1)
    half = 1 / (2 * (2**bits.coherence - 1))
    ell2 = np.minimum(np.linalg.norm(n2, axis=1), 1)
    assert np.max(np.abs(np.sqrt(1 - ell2) - np.sqrt(1 - ell)), initial=0) <= half + 5e-4
    assert np.max(np.abs(ell2 - ell), initial=0) <= 2 * half + 1e-6
    assert np.all(ell2[ell == 1] >= 1 - 1e-6)
    # centroids: rounded in the frame of the decoded normal (depth along it,
    # two tangent coordinates), then clamped into the voxel (which moves no
    # point farther from the original, inside it): half a step each
    _, s_depth = enc._steps(bits.depth)
    # (version 7: closed entries' in-plane codes have bits.centroid_closed)
    _, s_plane = enc._steps(enc.plane_bits(tex.entry_side, bits))
    # version 5: a spread entry's depth within DEPTH_SPREAD_SHARE of how far its
    # facets lie off its plane, about sigma / 2 voxel
    half_depth = np.maximum(1 / (2 * s_depth), enc.DEPTH_SPREAD_SHARE * sigma / 2)
    err = np.linalg.norm(got.entry_centroid - tex.entry_centroid, axis=1) / h
    assert np.all(err <= np.sqrt(half_depth**2 + 2 / (2 * s_plane) ** 2) * (1 + 1e-9))
    # along the decoded normal, where the clamp left the point alone: half a depth step
    f2 = (got.entry_centroid - tex.origin) / h - tex.coords[tex.entry_voxel]
    inside = np.all((f2 > 1e-9) & (f2 < 1 - 1e-9), axis=1) & (ell > 0)
    unit2 = n2 / np.maximum(np.linalg.norm(n2, axis=1, keepdims=True), 1e-300)
    depth_err = np.abs(np.sum((got.entry_centroid - tex.entry_centroid) * unit2, axis=1))[inside] / h
    assert np.all(depth_err <= half_depth[inside] * (1 + 1e-4) + 1e-6)
    assert np.max(depth_err[length[inside] >= 1 - 1e-7], initial=0) <= (1 / (2 * s_depth)) * (1 + 1e-4) + 1e-6
    # materials: steps of at most S / (2**bits - 1), ends exact
    for name, log in (("entry_kd", False), ("entry_ks", False), ("entry_shininess", True)):
        x = getattr(tex, name).astype(np.float64).reshape(len(a), -1)
        y = getattr(got, name).astype(np.float64).reshape(len(a), -1)
        if not len(x):
            continue
        f = (lambda v: np.log2(1 + v)) if log else (lambda v: v)
        S = f(x.max()) if log else max(1.0, x.max())
        half = S / (2 * (2 ** getattr(bits, name.removeprefix("entry_")) - 1))
        assert np.all(np.abs(f(y) - f(x)) <= half * (1 + 1e-6) + 1e-6), name
        assert np.array_equal(y.min(axis=0), x.min(axis=0)) and np.array_equal(y.max(axis=0), x.max(axis=0))
    # density: the residual's half step (of the voxel's area) plus what the
    # entries' own errors move F by (from the actual differences: a bound
    # per voxel and sample, not a fit)
    ev = tex.entry_voxel
    A_v = np.bincount(ev, weights=a2, minlength=tex.n_voxels)
    dirs = tex.directions
    moved = np.abs(a2 - a)[:, None] + a[:, None] * np.abs(
        np.abs(n2 @ dirs.T) - np.abs(n @ dirs.T)
    )  # |A'|n'.p| - A|n.p|| <= |A' - A| |n'.p| + A ||n'.p| - |n.p||, |n'| <= 1
    f_err = np.zeros((tex.n_voxels, len(dirs)))
    np.add.at(f_err, ev, moved)
    d_err = np.abs(got.density - tex.density)
    if bits.density:
        assert np.all(d_err <= A_v[:, None] / (2 * (2**bits.density - 1)) + f_err + 1e-9)
    # D >= F where no thin solid's back is hidden (D is below F there by
    # what the front hides, aniso3d.build.closure): what the volume
    # renderer's residual reading relies on
    f2 = facet_density(a2, n2, got.entry_offsets, dirs)
    whole = np.bincount(got.entry_voxel, weights=got.entry_cover < 1, minlength=got.n_voxels) == 0
    assert np.all(got.density[whole] >= f2[whole] - 1e-12)
    assert got.total_area() == pytest.approx(tex.total_area(), rel=2 ** (step / 2) - 1)


def test_tree_through_a_file_is_within_every_bound(tree_tex, tree_file):
    back = AnisoTexture.load(tree_file)
    f = read_texture_file(tree_file)
    assert f.version == FORMAT_VERSION == 7 and f.encoding == "compact"
    with zipfile.ZipFile(tree_file) as zf:
        assert {i.compress_type for i in zf.infolist() if i.filename.endswith(".npy")} == {zipfile.ZIP_LZMA}
        assert zf.getinfo("header.json").compress_type == zipfile.ZIP_DEFLATED
    # the file holds exactly what as_stored() computes without one
    ref = tree_tex.as_stored()
    for name in ARRAYS:
        a, b = getattr(back, name), getattr(ref, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert back.meta == {**tree_tex.meta, QUANTISED: 7} and back.voxel_size == tree_tex.voxel_size
    assert_within_bounds(tree_tex, back)


@pytest.mark.parametrize("bits", [Bits(), Bits(area=8, normal=10, centroid=6, kd=6, density=4),
                                  Bits(area=2, normal=2, coherence=1, centroid=2, depth=2, kd=1, ks=1,
                                       shininess=1, density=1, centroid_closed=2),
                                  Bits(area=16, normal=16, coherence=16, centroid=16, kd=16, ks=16,
                                       shininess=16, density=16, centroid_closed=16)])  # fmt: skip
def test_bounds_hold_at_other_bits(tree_tex, bits):
    assert_within_bounds(tree_tex, tree_tex.as_stored(bits), bits)


def test_more_bits_cost_more_bytes_and_err_less(tree_tex, tmp_path):
    fine = Bits(area=16, normal=16, centroid=12, centroid_closed=12, depth=12, kd=12, density=12)
    sizes = [tree_tex.save(tmp_path / f"{i}.a3d", bits=b).stat().st_size for i, b in enumerate((Bits(), fine))]
    assert sizes[0] < sizes[1]
    # on entries of flat facets (a spread entry's steps follow its spread, version 5)
    flat = np.linalg.norm(tree_tex.entry_normal, axis=1) >= 1 - 1e-7
    assert 0.3 < flat.mean() < 1
    errs = [np.abs(tree_tex.as_stored(b).entry_centroid - tree_tex.entry_centroid)[flat].max() for b in (Bits(), fine)]
    assert errs[1] < errs[0] / 8


def test_derived_density_is_the_facet_density_and_exact_for_flat_entries(tree_tex):
    got = tree_tex.as_stored(Bits(density=0))
    # (the entries' covered areas: the branches' backs hide behind their fronts)
    assert (got.entry_cover < 1).any()
    f2 = facet_density(got.entry_area * got.entry_cover, got.entry_normal, got.entry_offsets, got.directions)
    # (covers are float32: their products round at float32's 6e-8)
    np.testing.assert_allclose(got.density, f2, rtol=2e-7, atol=1e-15)
    # a quad: one flat facet per voxel, so D = F up to the entries' quantisation
    quad = build_texture(scenes.quad(), 16, 16)
    q = quad.as_stored(Bits(density=0))
    assert np.max(np.abs(q.density - quad.density)) <= 1e-3 * quad.density.max()


def test_pyramid_levels_and_dense_voxels_encode(tree_tex):
    for level in pyramid(tree_tex, max_levels=4):
        assert_within_bounds(level, level.as_stored())
    layers = 40
    quads = [scenes.quad(1.0, (0.0, 0.0, (k + 0.5) / layers - 0.5)) for k in range(layers)]
    from aniso3d.build.mesh import concatenate

    dense = build_texture(concatenate(quads), 1, 32)
    assert dense.n_voxels == 1 and dense.density.max() > 30
    assert_within_bounds(dense, dense.as_stored())


def test_materials_above_one_are_kept_and_single_materials_exact(tree_tex):
    from dataclasses import replace

    tex = replace(tree_tex, entry_kd=tree_tex.entry_kd * 3, entry_ks=tree_tex.entry_ks * 2.5,
                  entry_shininess=tree_tex.entry_shininess * 50)  # fmt: skip
    got = tex.as_stored()
    assert got.entry_kd.max() == tex.entry_kd.max() > 1
    assert_within_bounds(tex, got)
    cube = build_texture(scenes.cube(kd=(0.8, 0.3, 0.55), ks=0.25, shininess=33.0), 12, 16)
    c = cube.as_stored()
    for name in ("entry_kd", "entry_ks", "entry_shininess"):
        assert np.array_equal(getattr(c, name), getattr(cube, name)), name


def test_empty_texture_round_trips(tmp_path):
    mesh = Mesh.from_arrays([[0, 0, 0], [1, 1, 1], [2, 2, 2]], [[0, 1, 2]])
    tex = build_texture(mesh, 4, 8)
    assert tex.n_voxels == 0
    back = AnisoTexture.load(tex.save(tmp_path / "e.a3d"))
    assert back.n_voxels == 0 and back.density.shape == (0, 8) and back.n_entries == 0


def test_unencodable_textures_are_refused_and_leave_no_file(tree_tex, tmp_path):
    from dataclasses import replace

    bad_kd = tree_tex.entry_kd.copy()
    bad_kd[3, 1] = np.nan
    cases = [
        (replace(tree_tex, entry_kd=bad_kd), "entry_kd' holds NaN"),
        (replace(tree_tex, entry_area=-tree_tex.entry_area), "entry_area' holds negative"),
        (replace(tree_tex, coords=tree_tex.coords[::-1].copy(), density=tree_tex.density[::-1].copy()), "not sorted"),
        (replace(tree_tex, entry_direction=tree_tex.entry_direction + 16), "entry_direction lies outside 0..15"),
    ]
    for tex, match in cases:
        with pytest.raises(InputError, match=match):
            tex.save(tmp_path / "x.a3d")
        assert list(tmp_path.iterdir()) == []
    # the exact encoding keeps whatever the arrays hold
    back = AnisoTexture.load(cases[0][0].save(tmp_path / "x.a3d", encoding="exact"))
    assert np.isnan(back.entry_kd[3, 1])
    with pytest.raises(InputError, match="unknown texture encoding 'lossy'"):
        tree_tex.save(tmp_path / "y.a3d", encoding="lossy")


# ------------------------------------------------------------- sizes reported


def test_nbytes_is_the_file_size_and_memory_nbytes_the_arrays(tree_tex, tree_file):
    assert tree_tex.nbytes == tree_file.stat().st_size
    arrays = [n for n in ARRAYS if n not in ("origin", "shape")]
    assert tree_tex.memory_nbytes == sum(getattr(tree_tex, n).nbytes for n in arrays)
    assert tree_tex.nbytes < tree_tex.memory_nbytes / 5
    pyr = pyramid(tree_tex, max_levels=3)
    assert pyr.memory_nbytes == sum(t.memory_nbytes for t in pyr) - 2 * tree_tex.directions.nbytes


def test_cli_reports_the_stored_texture_bytes(tmp_path, capsys):
    out = tmp_path / "t.a3d"
    assert cli_main(["build", "scene:sphere", "-o", str(out), "-r", "10", "-k", "8", "-q"]) == 0
    rows = {}
    for line in capsys.readouterr().out.splitlines():
        key, _, value = re.split(r"(\s{2,})", line.strip(), maxsplit=1)
        rows[key] = value
    assert rows["bytes: texture"] == format_bytes(out.stat().st_size)


# ---------------------------------------------------------------- file format


def test_version_1_file_still_loads():
    """tests/data/three_triangles_v1.a3d was written by the version 1 writer
    (before the compact encoding): three triangles, 3^3 voxels, K = 8."""
    path = DATA / "three_triangles_v1.a3d"
    f = read_texture_file(path)
    assert f.version == 1 and f.encoding == "exact"
    with zipfile.ZipFile(path) as zf:
        assert json.loads(zf.read("header.json"))["version"] == 1
        assert all(i.compress_type == zipfile.ZIP_STORED for i in zf.infolist())
    back = AnisoTexture.load(path)
    v = np.array([[0, 0, 0], [1, 0.2, 0.1], [0.3, 1, 0.4], [0.9, 0.8, 1.0], [0.1, 0.5, 0.9]], float)
    faces = np.array([[0, 1, 2], [1, 3, 2], [2, 3, 4]])
    kd = np.array([[0.8, 0.2, 0.1], [0.1, 0.7, 0.2], [0.5, 0.5, 0.5]])
    mesh = Mesh.from_arrays(v, faces, kd, np.array([0.1, 0.3, 0.0]), np.array([8.0, 32.0, 1.0]), name="v1-fixture")
    assert back.total_area() == pytest.approx(mesh.area(), rel=1e-12)
    ref = build_texture(mesh, 3, 8)
    for name in ARRAYS:
        np.testing.assert_allclose(getattr(back, name), getattr(ref, name), rtol=1e-12, atol=1e-14, err_msg=name)
    assert back.meta["source"] == "v1-fixture"


def rewrite(src: Path, dst: Path, header=None, members=None) -> Path:
    """Copy a texture file, changing header fields and members, and sign it
    again with a SHA-256 computed here (the digest's definition, twinned):
    a well-formed file whose checksum holds, so only validation can refuse it."""
    with zipfile.ZipFile(src) as zin:
        h = json.loads(zin.read("header.json"))
        arrays = {}
        for name in zin.namelist():
            if name.endswith(".npy"):
                with zin.open(name) as fh:
                    arrays[name[:-4]] = np.lib.format.read_array(fh)
    if header:
        header(h)
    if members:
        members(arrays)
    sha = hashlib.sha256()
    for n in sorted(arrays):
        a = np.ascontiguousarray(arrays[n])
        sha.update(f"{n}:{a.dtype.str}:{a.shape}".encode())
        sha.update(a.tobytes())
    sha.update(json.dumps({"encoding": h["encoding"], "params": h["params"]}, sort_keys=True).encode())
    h["sha256"] = sha.hexdigest()
    with zipfile.ZipFile(dst, "w") as zout:
        zout.writestr("header.json", json.dumps(h))
        for n, a in arrays.items():
            buf = io.BytesIO()
            np.save(buf, a)
            zout.writestr(n + ".npy", buf.getvalue())
    return dst


def test_resigned_copy_loads_unchanged(tree_file, tmp_path):
    # the test's own digest agrees with the writer's: the cases below are refused by validation
    back = AnisoTexture.load(rewrite(tree_file, tmp_path / "same.a3d"))
    assert np.array_equal(back.density, AnisoTexture.load(tree_file).density)


def _set(name, fn):
    def change(arrays):
        arrays[name] = fn(arrays[name])

    return change


DAMAGED = [
    ("future version", dict(header=lambda h: h.update(version=8)), "version 8.*Upgrade aniso3d.*aniso3d build"),
    ("side code above 2", dict(members=_set("entry_side", lambda a: np.where(np.arange(len(a)) == 3, np.uint8(3), a))),
     "entry_side holds codes above 2"),
    ("side length", dict(members=_set("entry_side", lambda a: a[:-1])), "entry_side has shape"),
    ("normal shifts short", dict(header=lambda h: h["params"].update(normal_shifts=[0, 1])), "normal_shifts"),
    ("normal shift too coarse", dict(header=lambda h: h["params"]["normal_shifts"].__setitem__(5, 15)),
     "normal_shifts"),
    ("depth shifts missing", dict(header=lambda h: h["params"].pop("depth_shifts")), "depth_shifts"),
    ("centroid layout unknown", dict(header=lambda h: h["params"].update(centroid_layout="zigzag")),
     "centroid_layout is 'zigzag'"),
    ("area order missing", dict(header=lambda h: h["params"].pop("area_order")), "area_order is None"),
    ("normal past its spread's range",
     dict(header=lambda h: h["params"].update(normal_shifts=[8] * len(h["params"]["normal_shifts"]))),
     "entry_normal holds codes past"),
    ("unknown encoding", dict(header=lambda h: h.update(encoding="zstd")), "encoding 'zstd'.*Upgrade aniso3d"),
    ("params not an object", dict(header=lambda h: h.update(params=[1])), "params is not an object"),
    ("bits missing", dict(header=lambda h: h["params"].pop("bits")), "encoding parameters are damaged"),
    ("bits out of range", dict(header=lambda h: h["params"]["bits"].update(area=40)), "bits for 'area'"),
    ("range not finite", dict(header=lambda h: h["params"]["ranges"].update(ks=[[0, float("inf"), 3]])),
     "range of ks"),
    ("ranges short", dict(header=lambda h: h["params"]["ranges"].update(kd=[[0, 1, 3]])), "range of kd"),
    ("range steps", dict(header=lambda h: h["params"]["ranges"].update(ks=[[0, 1, 300]])), "range of ks"),
    ("centroid past voxel",
     dict(members=_set("entry_centroid", lambda a: np.concatenate([a[:2], a[2:3] | 0xFF, a[3:]]))),
     "past the voxel"),
    ("parent past 13", dict(members=_set("entry_parent", lambda a: a | np.uint8(0x10))), "entry_parent holds codes"),
    ("parent without entry", dict(members=_set("entry_parent", lambda a: np.where(a == 0, np.uint8(13), a))),
     "entry_parent names a neighbour"),
    ("parent length", dict(members=_set("entry_parent", lambda a: a[:-1])), "entry_parent has shape"),
    ("copied member length", dict(members=_set("entry_kd", lambda a: a[:, :-1])), "entry_kd has shape"),
    ("codes past range", dict(header=lambda h: h["params"]["ranges"]["kd"][0].__setitem__(2, 1)),
     "codes past its range"),
    ("coords repeat", dict(members=_set("coords", lambda a: np.concatenate([a, a[:, -1:] * 0], axis=1))),
     "entry_mask has shape|coords repeat"),
    ("coords past the grid", dict(members=_set("coords", lambda a: a + np.uint8(200))), "outside the grid"),
    ("coords planes", dict(members=_set("coords", lambda a: np.concatenate([a, a, a]))), "byte planes"),
    ("mask shape", dict(members=_set("entry_mask", lambda a: a[:-1])), "entry_mask has shape"),
    ("area length", dict(members=_set("entry_area", lambda a: a[:, :-1])), "entry_area has shape"),
    ("area dtype", dict(members=_set("entry_area", lambda a: a.astype(np.int16))), "entry_area has shape .* dtype"),
    ("codes above bits", dict(members=_set("entry_normal", lambda a: a | np.uint8(0xF0))),
     "entry_normal holds codes above (10|12) bits"),
    ("density shape", dict(members=_set("density", lambda a: a[:, :-1])), "density has shape"),
    ("directions dtype", dict(members=_set("directions", lambda a: a.astype(np.float32))), "directions has shape"),
]  # fmt: skip


@pytest.mark.parametrize("change, match", [c[1:] for c in DAMAGED], ids=[c[0] for c in DAMAGED])
def test_damaged_compact_files_are_refused_with_one_clear_error(tree_file, tmp_path, change, match):
    bad = rewrite(tree_file, tmp_path / "bad.a3d", **change)
    with pytest.raises(FormatError, match=match) as info:
        AnisoTexture.load(bad)
    msg = str(info.value)
    assert str(bad) in msg and "\n" not in msg
    assert "rebuild" in msg or "Upgrade" in msg


def test_normals_take_the_smaller_of_the_two_maps(tree_tex):
    """Scattered facets deflate smaller about their sample directions, a smooth
    sphere on the octahedral map: each file keeps whichever is smaller."""
    chosen = []
    for tex in (tree_tex, build_texture(scenes.sphere(), 48, 16)):
        members, params = enc.encode({n: getattr(tex, n) for n in ARRAYS}, tex.voxel_size)
        n = tex.entry_normal.astype(np.float64)
        unit = n / np.linalg.norm(n, axis=1, keepdims=True)
        sample = tex.directions[tex.entry_direction]
        span = enc._frame_span(unit, sample)
        sizes = [enc._deflated(enc._encode_oct(unit, enc.oct_bits(DEFAULT_BITS)), enc.oct_bits(DEFAULT_BITS)),
                 enc._deflated(enc._encode_frame(unit, sample, DEFAULT_BITS.normal, span), DEFAULT_BITS.normal)]
        chosen.append(params["normal_frame_span"] is not None)
        assert chosen[-1] == (sizes[1] < sizes[0])
    assert chosen == [True, False]


@pytest.mark.parametrize("bits", [2, 3, 8])
def test_a_coarse_residual_is_never_worse_than_none(tree_tex, bits):
    """Rounding the residual r = D - F to the nearest step s stores 0 below
    s/2 (error r, as without it) and otherwise errs by at most s/2 <= r: at
    every voxel and sample the density is at least as close as F alone."""
    d = tree_tex.density
    f = tree_tex.as_stored(Bits(density=0)).density
    got = tree_tex.as_stored(Bits(density=bits)).density
    assert np.all(np.abs(got - d) <= np.abs(f - d) + 1e-12)
    assert np.any(np.abs(got - d) < np.abs(f - d) - 1e-9)  # and it does store something


def old_fixture(version: int):
    """The compact file ``tests/data/small_tree_v{version}.a3d`` written by
    that version's writer, and ``..._decoded.a3d`` (exact encoding), what
    that writer's decoder gave for it: today's decoder must give those
    arrays, integer ones exactly and float ones to within 4 units in the
    last place (the areas decode through exp2 and the density sums them;
    NumPy's vectorised exp2 differs by an ulp between builds: with 2.4.6
    the decoded areas differ from the fixtures' by 1 ulp at most, the
    densities by 2). Returns both
    :class:`TextureFile`s."""
    f = read_texture_file(DATA / f"small_tree_v{version}.a3d")
    assert f.version == version and f.encoding == "compact"
    ref = read_texture_file(DATA / f"small_tree_v{version}_decoded.a3d")
    assert ref.version == version and ref.encoding == "exact"
    for name in ARRAYS:
        a, b = f.arrays[name], ref.arrays[name]
        assert a.dtype == b.dtype and a.shape == b.shape, name
        if np.issubdtype(a.dtype, np.floating):
            np.testing.assert_array_max_ulp(a, b, maxulp=4)
        else:
            np.testing.assert_array_equal(a, b, err_msg=name)
    return f, ref


def test_version_2_compact_file_still_loads():
    """tests/data/small_tree_v2.a3d was written by the version 2 compact
    writer (deflated quantised members), and small_tree_v2_decoded.a3d (exact
    encoding) holds what that writer's decoder gave for it: a later format
    must still decode the old file to exactly those arrays."""
    old_fixture(2)
    back = AnisoTexture.load(DATA / "small_tree_v2.a3d")
    assert back.meta[QUANTISED] == 2 and back.meta["source"] == "v2-fixture"
    built = build_texture(scenes.tree(levels=3, leaves_per_twig=12), 10, 16)
    assert back.n_entries == built.n_entries and np.array_equal(back.coords, built.coords)
    assert back.total_area() == pytest.approx(built.total_area(), rel=0.01)


def parents(tex: AnisoTexture, members: dict) -> np.ndarray:
    """Each entry's ``entry_parent`` code (0, or 1 + its index in
    PARENT_OFFSETS) from version 5's member, which stores ranks among the
    neighbours that have an entry at its direction."""
    cand = enc._candidates(tex.coords.astype(np.int64), np.asarray(tex.shape, np.int64), tex.entry_offsets,
                           tex.entry_voxel, tex.entry_direction, len(tex.directions))  # fmt: skip
    return enc._decode_parent_ranks(members["entry_parent"], cand)


def test_parents_are_stored_as_ranks_among_their_candidates(tree_tex):
    """A parent is one of the neighbours with an entry at the same sample
    direction (its candidates): version 5 stores its rank among them, for
    entries that have any, and the ranks decode to the parents."""
    arrays = {n: getattr(tree_tex, n) for n in ARRAYS}
    coords, shape = tree_tex.coords.astype(np.int64), np.asarray(tree_tex.shape, np.int64)
    cand = enc._candidates(coords, shape, tree_tex.entry_offsets, tree_tex.entry_voxel, tree_tex.entry_direction,
                           len(tree_tex.directions))  # fmt: skip
    # the candidates, one by one against a dict of the entries
    key = {(tuple(c), d) for c, d in zip(map(tuple, tree_tex.coords[tree_tex.entry_voxel]), tree_tex.entry_direction,
                                         strict=True)}  # fmt: skip
    rng = np.random.default_rng(0)
    for i in rng.choice(tree_tex.n_entries, 200, replace=False):
        c, d = tree_tex.coords[tree_tex.entry_voxel[i]], tree_tex.entry_direction[i]
        want = [(tuple(c + o), d) in key for o in enc.PARENT_OFFSETS]
        assert cand[i].tolist() == want
    parent = enc._copy_parents(coords, shape, tree_tex.entry_voxel, tree_tex.entry_direction.astype(np.int64),
                               len(tree_tex.directions), [enc._encode_range(tree_tex.entry_kd.T, 9)[0]])  # fmt: skip
    ranks = enc._encode_parent_ranks(parent, cand)
    assert len(ranks) == np.sum(cand.any(axis=1)) < tree_tex.n_entries and ranks.max() < parent.max()
    assert np.array_equal(enc._decode_parent_ranks(ranks, cand), parent)
    assert np.all(cand[np.flatnonzero(parent), parent[parent > 0].astype(np.int64) - 1])
    members, _ = enc.encode(arrays, tree_tex.voxel_size)
    assert members["entry_parent"].shape == (np.sum(cand.any(axis=1)),)


def test_copying_from_a_neighbour_loses_nothing(tree_tex):
    """Entries with a parent take its normal and material codes instead of
    storing their own: only where the codes are equal, so every entry decodes
    to what quantising it alone gives. Checked against each field's quantiser
    run on every entry, on a tree where many entries do copy."""
    arrays = {n: getattr(tree_tex, n) for n in ARRAYS}
    members, params = enc.encode(arrays, tree_tex.voxel_size)
    parent = parents(tree_tex, members)
    assert 0.2 < np.mean(parent > 0) < 1 and parent.max() <= len(enc.PARENT_OFFSETS)
    got = tree_tex.as_stored()
    for name, field, log in (("entry_kd", "kd", False), ("entry_ks", "ks", False),
                             ("entry_shininess", "shininess", True)):  # fmt: skip
        x = np.asarray(arrays[name], dtype=np.float64).reshape(tree_tex.n_entries, -1).T
        codes, ranges = enc._encode_range(x, getattr(DEFAULT_BITS, field), log=log)
        alone = enc._decode_range(codes, getattr(DEFAULT_BITS, field), ranges, log=log).T.astype(np.float32)
        np.testing.assert_array_equal(getattr(got, name).reshape(alone.shape), alone, err_msg=name)
    n = tree_tex.entry_normal.astype(np.float64)
    length = np.linalg.norm(n, axis=1)
    sample = tree_tex.directions[tree_tex.entry_direction]
    unit = np.where((length > 0)[:, None], n / np.where(length > 0, length, 1)[:, None], sample)
    span = params["normal_frame_span"]
    cc = enc._encode_spread(np.minimum(length, 1.0), DEFAULT_BITS.coherence)
    shift = np.asarray(enc.normal_shifts(DEFAULT_BITS, span))[cc[0]]
    assert params["normal_shifts"] == enc.normal_shifts(DEFAULT_BITS, span) and np.mean(shift > 0) > 0.05
    nc = enc._encode_frame(unit, sample, DEFAULT_BITS.normal - shift, span) if span is not None else enc._encode_oct(
        unit, enc.oct_bits(DEFAULT_BITS) - shift)
    alone = enc._decode_normal(nc, cc, None, DEFAULT_BITS, span, sample, shift=shift)
    np.testing.assert_array_equal(got.entry_normal, alone)
    # and each entry with a parent has the same codes as the neighbour it names
    voxel = tree_tex.entry_voxel
    child = np.flatnonzero(parent)
    cell = tree_tex.coords[voxel[child]] + enc.PARENT_OFFSETS[parent[child] - 1]
    key = {(tuple(c), d): i for i, (c, d) in enumerate(zip(map(tuple, tree_tex.coords[voxel]),
                                                           tree_tex.entry_direction, strict=True))}  # fmt: skip
    nb = np.array([key[(tuple(c), d)] for c, d in zip(cell, tree_tex.entry_direction[child], strict=True)])
    assert np.all(nb < child)
    np.testing.assert_array_equal(got.entry_kd[child], got.entry_kd[nb])
    np.testing.assert_array_equal(got.entry_normal[child], got.entry_normal[nb])


def test_a_childs_depth_is_stored_against_its_sources_plane():
    """A flat square across many voxels: every entry after the first copies
    its normal, and its centroid's depth code, stored as the difference from
    the plane of its source, is a few codes (the square's plane, up to
    rounding) where the depth itself spans hundreds."""
    import math
    q = scenes.quad()
    a = math.radians(23.0)
    rot = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    mesh = Mesh.from_arrays(q.vertices @ rot.T, q.faces, q.kd, q.ks, q.shininess, name="tilted")
    tex = build_texture(mesh, 32, 16)
    members, _ = enc.encode({n: getattr(tex, n) for n in ARRAYS}, tex.voxel_size)
    parent = parents(tex, members)
    assert np.mean(parent > 0) > 0.95
    b = DEFAULT_BITS.depth
    depth = enc.from_planes(members["entry_centroid"], 3, enc._width(max(b, DEFAULT_BITS.centroid)))[0]
    residual = depth[parent > 0].astype(np.int64)
    residual = np.where(residual >= 2 ** (b - 1), residual - 2**b, residual)
    # the depth of a plane tilted 23 degrees spans hundreds of codes across
    # its voxels; the residual is what rounding and the decoded normal's
    # 0.13 degrees leave, growing with the distance from the source (up to
    # 32 voxels here): a few codes
    f = (tex.entry_centroid - tex.origin) / tex.voxel_size - tex.coords[tex.entry_voxel] - 0.5
    n = tex.entry_normal / np.linalg.norm(tex.entry_normal, axis=1, keepdims=True)
    assert np.std(enc._depth_codes(f, n, b)) > 100
    assert np.median(np.abs(residual)) <= 3 and np.max(np.abs(residual)) <= 8
    assert_within_bounds(tex, tex.as_stored())


@pytest.mark.parametrize("bits", [2, 6, 8, 10, 16])
def test_centroid_frame_steps_cover_the_voxel_and_keep_its_middle_and_faces(bits):
    """A coordinate in the normal's frame spans the voxel's half diagonal
    sqrt(3)/2 within its codes; 0 and +-1/2 (the middle, and the faces of an
    axis-aligned plane) fall on codes exactly."""
    m, s = enc._steps(bits)
    assert m == 2 ** (bits - 1) - 1 and s >= 1
    assert s * np.sqrt(3) / 2 <= m and (s % 2 == 0 or bits == 2)
    f = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [-0.5, 0.0, 0.0], [0.0, 0.5, -0.5]])
    unit = np.array([[1.0, 0.0, 0.0]] * 4)
    codes = np.zeros((3, 4), dtype=np.int64)
    codes[0] = enc._depth_codes(f, unit, bits)
    t, b = enc.tangent_frame(unit)
    mp, sp = enc._steps(6)
    codes[1] = mp + np.round(np.sum(f * t, axis=1) * sp)
    codes[2] = mp + np.round(np.sum(f * b, axis=1) * sp)
    got = enc._frame_offsets(codes, unit, t, b, Bits(depth=bits))
    assert np.all(np.isfinite(got))
    exact = slice(None) if bits > 2 else slice(0, 1)  # 2 bits: the middle only
    np.testing.assert_allclose(got[exact, 0], f[exact, 0], atol=1e-15)
    np.testing.assert_allclose(got[:, 1:], f[:, 1:], atol=1e-15)


def test_version_4_compact_file_still_loads():
    """tests/data/small_tree_v4.a3d was written by the version 4 writer (every
    direction and depth at the field's bits, no shift tables), and
    small_tree_v4_decoded.a3d (exact encoding) holds what that writer's
    decoder gave for it: version 5's decoder must give exactly those arrays."""
    _, ref = old_fixture(4)
    with zipfile.ZipFile(DATA / "small_tree_v4.a3d") as zf:
        params = json.loads(zf.read("header.json"))["params"]
    assert "normal_shifts" not in params and "depth_shifts" not in params
    back = AnisoTexture.load(DATA / "small_tree_v4.a3d")
    assert back.meta[QUANTISED] == 4 and back.meta["source"] == "v4-fixture"
    # and today's encoding of the same texture has version 5's shifts
    members, params = enc.encode(dict(ref.arrays), ref.voxel_size)
    assert max(params["normal_shifts"]) > 0 and max(params["depth_shifts"]) > 0


@pytest.mark.parametrize("bits", [DEFAULT_BITS, Bits(normal=6, depth=6, coherence=3), Bits(normal=16, depth=16)])
@pytest.mark.parametrize("span", [None, 0.8, 1.7])
def test_spread_normals_get_the_coarsest_step_within_their_share(bits, span):
    """Per length code q, the direction's and the depth's shift: 0 for flat
    facets (q = 0); otherwise the coarsest step whose error stays within the
    share of the facets' spread sigma = sqrt(2) q / (2**bits - 1), checked
    against the closed-form errors (the next coarser step would exceed it,
    or the codes are down to 2 bits)."""
    full = bits.normal if span is not None else enc.oct_bits(bits)
    top = 2**bits.coherence - 1
    shifts, dshifts = enc.normal_shifts(bits, span), enc.depth_shifts(bits)
    assert len(shifts) == len(dshifts) == top + 1 and shifts[0] == dshifts[0] == 0
    assert np.all(np.diff(shifts) >= 0) and np.all(np.diff(dshifts) >= 0) and shifts[-1] > 0 and dshifts[-1] > 0
    m = lambda b: 2 ** (b - 1) - 1  # noqa: E731
    err = lambda b: (3.0 if span is None else span) / (np.sqrt(2) * m(b))  # noqa: E731
    derr = lambda b: 1 / (2 * max(1, 2 * math.floor(m(b) / math.sqrt(3))))  # noqa: E731
    for q in range(top + 1):
        sigma = np.sqrt(2) * q / top
        for s, e, b, share in ((shifts[q], err, full, enc.NORMAL_SPREAD_SHARE),
                               (dshifts[q], derr, bits.depth, enc.DEPTH_SPREAD_SHARE / 2)):  # fmt: skip
            assert s == 0 or e(b - s) <= share * sigma
            assert b - s == 2 or e(b - s - 1) > share * sigma


def test_spread_entries_make_the_file_smaller_and_flat_ones_keep_their_codes(tree_tex, monkeypatch):
    """The shifts pay: the tree's file without them (shares 0) is larger;
    entries of flat facets decode to the same values either way."""
    arrays = {n: getattr(tree_tex, n) for n in ARRAYS}
    with_shifts = tree_tex.as_stored()
    size = encoded_size(arrays, tree_tex.voxel_size, {})
    monkeypatch.setattr(enc, "NORMAL_SPREAD_SHARE", 0.0)
    monkeypatch.setattr(enc, "DEPTH_SPREAD_SHARE", 0.0)
    members, params = enc.encode(arrays, tree_tex.voxel_size)
    assert not any(params["normal_shifts"]) and not any(params["depth_shifts"])
    without = tree_tex.as_stored()
    assert size < 0.98 * encoded_size(arrays, tree_tex.voxel_size, {})
    flat = np.linalg.norm(tree_tex.entry_normal, axis=1) >= 1 - 1e-7
    for name in ("entry_normal", "entry_centroid", "entry_area", "entry_kd"):
        np.testing.assert_array_equal(getattr(with_shifts, name)[flat], getattr(without, name)[flat], err_msg=name)
    assert not np.array_equal(with_shifts.entry_normal[~flat], without.entry_normal[~flat])


def test_stored_orders_lose_nothing(tree_tex):
    """Version 5 stores depths grouped by their bits, the children's in-plane
    codes in order of their sources' centroids (or entry order), areas in
    order of their normal's length (or entry order), shininess and kd in
    order of ks: orders only. The
    centroids decode to exactly what the same codes in entry order give, kd
    and areas to what quantising them alone gives."""
    arrays = {n: getattr(tree_tex, n) for n in ARRAYS}
    members, params = enc.encode(arrays, tree_tex.voxel_size)
    got = enc.decode(members, params, tree_tex.voxel_size)
    coords, shape = tree_tex.coords.astype(np.int64), np.asarray(tree_tex.shape, np.int64)
    voxel, direction, k = tree_tex.entry_voxel, tree_tex.entry_direction, len(tree_tex.directions)
    parent = parents(tree_tex, members)
    src = enc._copy_sources(parent, coords, shape, voxel, direction, k)
    assert np.mean(src != np.arange(tree_tex.n_entries)) > 0.2
    unit = got["entry_normal"].astype(np.float64)
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    q = enc._encode_spread(np.minimum(np.linalg.norm(got["entry_normal"], axis=1), 1.0), DEFAULT_BITS.coherence)[0]
    db = DEFAULT_BITS.depth - np.asarray(params["depth_shifts"])[q]
    assert len(np.unique(db)) > 1
    args = (tree_tex.origin, tree_tex.voxel_size, coords, voxel)
    pb = enc.plane_bits(tree_tex.entry_side, DEFAULT_BITS)
    assert len(np.unique(pb)) == 2
    codes, back = {}, {}
    for layout in (None, *enc.CENTROID_LAYOUTS):
        codes[layout] = enc._encode_centroid_frame(tree_tex.entry_centroid, *args, unit, src, DEFAULT_BITS, db,
                                                   layout, pb)  # fmt: skip
        back[layout] = enc._decode_centroid_frame(codes[layout], *args, unit, tangent_frame(unit), src,
                                                  DEFAULT_BITS, db, layout, pb)  # fmt: skip
        # (the decoder's unit normals are float64 from their codes: within rounding of these)
        np.testing.assert_allclose(back[layout], got["entry_centroid"], rtol=0, atol=1e-6 * tree_tex.voxel_size)
    for layout in enc.CENTROID_LAYOUTS:
        assert not np.array_equal(codes[layout], codes[None]) and np.array_equal(back[layout], back[None])
    # the tree's leaves pack smaller in their sources' order
    assert params["centroid_layout"] == "sources"
    x = tree_tex.entry_kd.astype(np.float64).T
    kd_codes, kd_range = enc._encode_range(x, DEFAULT_BITS.kd)
    alone = enc._decode_range(kd_codes, DEFAULT_BITS.kd, kd_range).T.astype(np.float32)
    np.testing.assert_array_equal(got["entry_kd"], alone)
    area_codes, span = enc._encode_log(tree_tex.entry_area, DEFAULT_BITS.area)
    np.testing.assert_array_equal(got["entry_area"], enc._decode_log(area_codes, DEFAULT_BITS.area, span))


def test_each_file_keeps_the_smaller_layout(tree_tex, monkeypatch):
    """Centroids' in-plane rows and areas are laid out in entry order or in a
    predicted order, whichever packs smaller (LZMA's fastest preset):
    checked against both layouts made here, and each decodes to the same
    texture."""
    arrays = {n: getattr(tree_tex, n) for n in ARRAYS}
    members, params = enc.encode(arrays, tree_tex.voxel_size)
    got = enc.decode(members, params, tree_tex.voxel_size)
    length = np.linalg.norm(tree_tex.entry_normal.astype(np.float64), axis=1)
    q = enc._encode_spread(np.minimum(length, 1.0), DEFAULT_BITS.coherence)[0]
    area_codes, _ = enc._encode_log(tree_tex.entry_area, DEFAULT_BITS.area)
    laid = {"entries": enc.to_planes(area_codes, 2),
            "length": enc.to_planes(area_codes[np.argsort(q, kind="stable")], 2)}  # fmt: skip
    assert params["area_order"] == min(laid, key=lambda o: enc._packed(laid[o]))
    assert np.array_equal(members["entry_area"], laid[params["area_order"]])
    for layout in enc.CENTROID_LAYOUTS:
        for order in enc.AREA_ORDERS:
            monkeypatch.setattr(enc, "CENTROID_LAYOUTS", (layout,))
            monkeypatch.setattr(enc, "AREA_ORDERS", (order,))
            m, p = enc.encode(arrays, tree_tex.voxel_size)
            assert p["centroid_layout"] == layout and p["area_order"] == order
            if layout == params["centroid_layout"]:
                assert np.array_equal(m["entry_centroid"], members["entry_centroid"])
            else:
                assert enc._packed(m["entry_centroid"]) >= enc._packed(members["entry_centroid"])
            monkeypatch.undo()
            back = enc.decode(m, p, tree_tex.voxel_size)
            for name in ARRAYS:
                np.testing.assert_array_equal(back[name], got[name], err_msg=name)


def test_version_5_compact_file_still_loads():
    """tests/data/small_tree_v5.a3d was written by the version 5 writer (at
    commit 0b52bf1: a small tree and a closed cube, ``build_texture(mesh,
    12, 16)``), and small_tree_v5_decoded.a3d (exact encoding) holds what that
    writer's decoder gave for it: version 6's decoder gives exactly those
    arrays, and every entry two-sided (version 5 kept no sides), where a build
    of the same mesh makes the cube's points one-sided."""
    old_fixture(5)
    with zipfile.ZipFile(DATA / "small_tree_v5.a3d") as zf:
        assert "entry_side.npy" not in zf.namelist()
    back = AnisoTexture.load(DATA / "small_tree_v5.a3d")
    assert back.meta[QUANTISED] == 5 and back.meta["source"] == "v5-fixture"
    assert not back.entry_side.any() and back.to_points().one_sided is None
    tree = scenes.tree(levels=3, leaves_per_twig=12)
    cube = scenes.cube()
    lo, hi = tree.bounds
    s = 0.25 * (hi - lo).max() / (cube.bounds[1] - cube.bounds[0]).max()
    m = np.diag([s, s, s, 1.0])
    m[:3, 3] = lo - cube.bounds[0] * s
    from aniso3d.build.mesh import concatenate

    built = build_texture(concatenate([tree, cube.transformed(m)]), 12, 16)
    assert built.n_entries == back.n_entries and np.array_equal(built.coords, back.coords)
    assert built.to_points().one_sided.sum() > 20
    # today's file of the same texture stores the sides
    members, params = enc.encode(dict(built._arrays()), built.voxel_size)
    assert np.array_equal(enc.decode(members, params, built.voxel_size)["entry_side"], built.entry_side)


def test_version_6_compact_file_still_loads():
    """tests/data/small_tree_v6.a3d was written by the version 6 writer (at
    commit 61b2f51, the mesh of the version 5 fixture: a small tree and a
    closed cube, ``build_texture(mesh, 12, 16)``; every in-plane centroid
    code in 6 bits), and small_tree_v6_decoded.a3d (exact encoding) holds
    what that writer's decoder gave for it: today's decoder gives exactly
    those arrays, though today's files give the cube's entries 7 bits."""
    f, ref = old_fixture(6)
    with zipfile.ZipFile(DATA / "small_tree_v6.a3d") as zf:
        assert "centroid_closed" not in json.loads(zf.read("header.json"))["params"]["bits"]
    back = AnisoTexture.load(DATA / "small_tree_v6.a3d")
    assert back.meta[QUANTISED] == 6 and back.meta["source"] == "v6-fixture"
    assert (back.entry_side != 0).sum() > 20
    # today's encoding of the same arrays places the closed entries finer
    arrays = {n: ref.arrays[n] for n in ARRAYS}
    members, params = enc.encode(arrays, ref.voxel_size)
    assert params["bits"]["centroid_closed"] == DEFAULT_BITS.centroid_closed > DEFAULT_BITS.centroid
    assert not np.array_equal(enc.decode(members, params, ref.voxel_size)["entry_centroid"],
                              f.arrays["entry_centroid"])  # fmt: skip


def test_closed_entries_keep_finer_in_plane_centroids():
    """Version 7: the in-plane centroid codes of entries on closed surfaces
    (a thin beam's faces, which the volume draws as strips placed by their
    centroid) have ``centroid_closed`` bits, the rest ``centroid``. Checked
    on a truss of thin closed beams and open leaves together: the closed
    entries' in-plane error stays within half a step of their bits (and
    exceeds that bound at the open entries' bits), the open entries' within
    theirs, and the open entries decode exactly as with one count for all."""
    from aniso3d.build.mesh import concatenate

    truss = scenes.lattice(cells=3, beam_width=0.15)
    leaves = scenes.tree(levels=3, leaves_per_twig=12)
    lo, hi = truss.bounds
    s = (hi - lo).max() / (leaves.bounds[1] - leaves.bounds[0]).max()
    m = np.diag([s, s, s, 1.0])
    m[:3, 3] = lo - leaves.bounds[0] * s
    tex = build_texture(concatenate([truss, leaves.transformed(m)]), 32, 16)
    closed = tex.entry_side != 0
    assert 0.2 < closed.mean() < 0.95

    def in_plane_error(got):
        n = got.entry_normal.astype(np.float64)
        unit = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        d = (got.entry_centroid - tex.entry_centroid) / tex.voxel_size
        d -= np.sum(d * unit, axis=1, keepdims=True) * unit
        f2 = (got.entry_centroid - tex.origin) / tex.voxel_size - tex.coords[tex.entry_voxel]
        inside = np.all((f2 > 1e-9) & (f2 < 1 - 1e-9), axis=1)
        return np.linalg.norm(d, axis=1), inside

    err, inside = in_plane_error(tex.as_stored())
    half = {b: np.sqrt(2) / (2 * enc._steps(b)[1]) for b in (6, 7)}
    assert err[closed & inside].max() <= half[7] * (1 + 1e-6)
    assert err[~closed & inside].max() <= half[6] * (1 + 1e-6)
    coarse, _ = in_plane_error(tex.as_stored(Bits(centroid_closed=6)))
    assert coarse[closed & inside].max() > half[7]
    assert np.mean(err[closed & inside]) < 0.7 * np.mean(coarse[closed & inside])
    same = tex.as_stored(Bits(centroid_closed=6))
    np.testing.assert_array_equal(tex.as_stored().entry_centroid[~closed], same.entry_centroid[~closed])


def test_sides_decode_along_their_predictors_as_one_by_one():
    """Version 6 stores each entry's side against the first earlier
    neighbour's at its sample direction; the decoder sums the residuals
    along those chains by pointer jumping. Checked against summing them
    entry by entry in cell order, on sides drawn at random (long chains of
    every code) and on a closed surface's (a member of nearly nothing)."""
    tex = build_texture(scenes.sphere(), 32, 16)
    coords, shape = tex.coords.astype(np.int64), np.asarray(tex.shape, np.int64)
    pred = enc._side_predictors(coords, shape, tex.entry_voxel, tex.entry_direction.astype(np.int64), 16)
    assert np.all(pred < np.arange(tex.n_entries)) and np.mean(pred >= 0) > 0.9
    rng = np.random.default_rng(1)
    for side in (rng.integers(-1, 2, tex.n_entries).astype(np.int8), tex.entry_side):
        stored = enc._encode_sides(side, pred)
        resid = np.empty(tex.n_entries, dtype=np.int64)
        resid[np.argsort(pred < 0, kind="stable")] = stored
        code = np.zeros(tex.n_entries, dtype=np.int64)
        for i in range(tex.n_entries):  # the reference: one entry after another
            code[i] = (resid[i] + (code[pred[i]] if pred[i] >= 0 else 0)) % 3
        np.testing.assert_array_equal(np.where(code == 2, -1, code), side)
        np.testing.assert_array_equal(enc._decode_sides(stored, pred), side)
    assert np.all(tex.entry_side == 1)
    # a closed surface's sides: all 0 but the first entry of each chain
    assert np.count_nonzero(enc._encode_sides(tex.entry_side, pred)) == np.count_nonzero(pred < 0)
