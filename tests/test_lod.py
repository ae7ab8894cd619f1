"""Level-of-detail pyramid and view-dependent points (issue 7)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import build_open

from aniso3d import scenes
from aniso3d.build.clip import make_grid
from aniso3d.build.mesh import Mesh
from aniso3d.build.pyramid import Pyramid, adaptive_points, as_pyramid, pyramid
from aniso3d.build.texture import AnisoTexture, build_texture
from aniso3d.errors import InputError
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.select import select_points, select_voxels, selection_ranges

K = 32


@pytest.fixture(scope="module")
def tree_mesh():
    return scenes.tree(levels=4, leaves_per_twig=10)


@pytest.fixture(scope="module")
def tree_tex(tree_mesh):
    # every face open: areas conserved level by level (the branches' hidden
    # backs would take them apart: tests/test_thin_solids.py)
    return build_open(tree_mesh, 64, K)


@pytest.fixture(scope="module")
def tree_pyr(tree_tex):
    return pyramid(tree_tex)


def _box_mesh() -> Mesh:
    """A cube stretched to odd extents and moved off the origin: cell counts
    per axis are not powers of two, so ceil(shape / 2) is exercised."""
    return scenes.cube(1.0, center=(0.3, -0.1, 0.2)).transformed(np.diag([1.0, 0.37, 0.61, 1.0]))


def _mean_close(a, b, area, atol):
    """Area-weighted means agree: exactly (to ``atol``) on every entry that is
    not a sub-1e-9 h^2 sliver, and to ``atol`` weighted by area overall (a
    sliver's mean rests on a few rounding-level weights)."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    err = np.abs(a - b).reshape(len(area), -1).max(axis=1)
    big = area > 1e-9
    assert err[big].max(initial=0.0) <= atol, err[big].max()
    assert np.sum(err * area) <= atol * np.sum(area)


def assert_same_texture(agg: AnisoTexture, direct: AnisoTexture) -> None:
    assert np.array_equal(agg.origin, direct.origin)
    assert agg.voxel_size == direct.voxel_size
    assert np.array_equal(agg.shape, direct.shape)
    assert np.array_equal(agg.directions, direct.directions)
    assert np.array_equal(agg.coords, direct.coords)
    assert np.array_equal(agg.entry_offsets, direct.entry_offsets)
    assert np.array_equal(agg.entry_direction, direct.entry_direction)
    # float64 fields, units of h^2: rounding level (areas are O(0.01..1)).
    scale = max(float(direct.density.max(initial=0.0)), 1.0)
    np.testing.assert_allclose(agg.density, direct.density, rtol=1e-12, atol=1e-13 * scale)
    np.testing.assert_allclose(agg.entry_area, direct.entry_area, rtol=1e-12, atol=1e-13)
    area = direct.entry_area
    _mean_close(agg.entry_centroid, direct.entry_centroid, area, 1e-12 * direct.voxel_size)
    # float32 fields: both are float64 means rounded to float32 (the aggregate
    # from float32 children), so they agree to a couple of float32 ulps.
    for name in ("entry_kd", "entry_ks", "entry_shininess"):
        ref = np.asarray(getattr(direct, name), np.float64)
        _mean_close(getattr(agg, name), ref, area, 2.5e-7 * max(float(np.abs(ref).max()), 1e-30))
    _mean_close(agg.entry_normal, direct.entry_normal, area, 2.5e-7)
    np.testing.assert_allclose(agg.entry_cover, direct.entry_cover, atol=1e-6)
    assert agg.entry_kd.dtype == np.float32 and agg.entry_normal.dtype == np.float32


# ------------------------------------------------------------------- pyramid


@pytest.mark.parametrize(
    "name, resolution",
    [("tree", 64), ("sphere", 32), ("cube", 32), ("box", 48)],
)
def test_each_level_equals_direct_build(name, resolution, tree_mesh):
    mesh = {
        "tree": tree_mesh,
        "sphere": scenes.sphere(1.0, center=(0.3, -0.2, 0.1), subdivisions=3),
        "cube": scenes.cube(1.3, center=(0.1, 0.2, 0.3)),
        "box": _box_mesh(),
    }[name]
    fine = build_texture(mesh, resolution, K)
    pyr = pyramid(fine)
    compared = 0
    for level in range(1, len(pyr)):
        if resolution % 2**level:
            break  # make_grid cannot make this grid from an integer resolution
        assert_same_texture(pyr[level], build_texture(mesh, resolution // 2**level, K))
        compared += 1
    assert compared == {64: 6, 32: 5, 48: 4}[resolution]


def test_pyramid_structure(tree_tex, tree_pyr):
    assert isinstance(tree_pyr, Pyramid) and isinstance(tree_pyr, list)
    assert tree_pyr[0] is tree_tex
    assert len(tree_pyr) == 7  # 64, 32, ..., 1
    assert tuple(tree_pyr[-1].shape) == (1, 1, 1) and tree_pyr[-1].n_voxels == 1
    for lo, hi in zip(tree_pyr[:-1], tree_pyr[1:], strict=True):
        assert hi.voxel_size == 2 * lo.voxel_size
        assert np.array_equal(hi.origin, lo.origin)
        assert np.array_equal(hi.shape, (lo.shape + 1) // 2)
        assert hi.directions is lo.directions
        assert hi.n_voxels < lo.n_voxels and hi.nbytes < lo.nbytes
        # sparse: only occupied parents exist, each with at least one entry
        assert np.all(np.diff(hi.entry_offsets) >= 1)
    stats = tree_pyr.level_stats()
    assert [s["nbytes"] for s in stats] == [t.nbytes for t in tree_pyr]
    shared = tree_tex.directions.nbytes * (len(tree_pyr) - 1)
    assert tree_pyr.nbytes == sum(t.nbytes for t in tree_pyr) - shared
    assert len(pyramid(tree_tex, max_levels=3)) == 3
    assert tree_pyr[3].meta["lod_level"] == 3 and "n_subpolygons" not in tree_pyr[3].meta


def test_area_and_density_conserved(tree_mesh, tree_pyr):
    mesh_area = tree_mesh.area()
    per_direction = tree_pyr[0].density.sum(axis=0) * tree_pyr[0].voxel_size ** 2
    for t in tree_pyr:
        assert t.total_area() == pytest.approx(mesh_area, rel=1e-12)
        # projected facet area along every sample direction, world units
        world = t.density.sum(axis=0) * t.voxel_size**2
        np.testing.assert_allclose(world, per_direction, rtol=1e-12)
        # the same per voxel: a parent holds exactly its children's
    for lvl in range(1, len(tree_pyr)):
        fine, coarse = tree_pyr[lvl - 1], tree_pyr[lvl]
        parent = tree_pyr.parents[lvl - 1]
        summed = np.zeros_like(coarse.density)
        np.add.at(summed, parent, fine.density)
        np.testing.assert_allclose(coarse.density * 4, summed, rtol=1e-12, atol=1e-14)
        vox_area = np.bincount(fine.entry_voxel, weights=fine.entry_area)
        coarse_area = np.bincount(coarse.entry_voxel, weights=coarse.entry_area)
        np.testing.assert_allclose(
            coarse_area * 4, np.bincount(parent, weights=vox_area), rtol=1e-12
        )


def test_make_grid_levels_align():
    """make_grid at R / 2**l gives exactly the aggregated grid (same origin,
    doubled h, shape ceil(shape / 2)) for any extents, including ones just
    over or under a whole number of cells."""
    rng = np.random.default_rng(7)
    for _ in range(400):
        R = int(2 ** rng.integers(1, 8)) * int(rng.choice([1, 3, 5]))
        longest = float(rng.uniform(0.01, 100))
        frac = rng.integers(0, R + 1, size=2) / R
        jitter = rng.choice([0, 1e-15, -1e-15, 1e-13, -1e-12, 1e-11, 0.3], size=2)
        ext = np.clip(np.array([longest, *(longest * frac * (1 + jitter))]), 0, longest)
        rng.shuffle(ext)
        lo = rng.uniform(-1000, 1000, 3)
        fine = make_grid(np.stack([lo, lo + ext]), R)
        shape, h, level = fine.shape.copy(), fine.voxel_size, 0
        while R % 2 ** (level + 1) == 0:
            level += 1
            shape, h = (shape + 1) // 2, 2 * h
            g = make_grid(np.stack([lo, lo + ext]), R // 2**level)
            assert np.array_equal(g.origin, fine.origin)
            assert g.voxel_size == h
            assert np.array_equal(g.shape, shape)


def test_coarse_level_saves(tree_pyr, tmp_path):
    path = tree_pyr[2].save(tmp_path / "l2.a3d", encoding="exact")
    back = AnisoTexture.load(path)
    assert np.array_equal(back.density, tree_pyr[2].density)
    assert back.meta["lod_level"] == 2


def test_plain_list_is_linked(tree_pyr):
    again = as_pyramid(list(tree_pyr))
    for a, b in zip(again.parents, tree_pyr.parents, strict=True):
        assert np.array_equal(a, b)
    with pytest.raises(InputError):
        as_pyramid([tree_pyr[0], tree_pyr[2]])


# ------------------------------------------------------------------ selection


def _coverage(pyr, selection) -> np.ndarray:
    """How many chosen voxels (at any level) contain each finest voxel."""
    n0 = pyr[0].n_voxels
    anc = np.arange(n0)
    cover = np.zeros(n0, dtype=np.int64)
    for lvl in range(len(pyr)):
        if lvl:
            anc = pyr.parents[lvl - 1][anc]
        chosen = np.zeros(pyr[lvl].n_voxels, dtype=bool)
        chosen[selection.voxels[lvl]] = True
        cover += chosen[anc]
    return cover


def _chosen_area(pyr, selection) -> float:
    total = 0.0
    for lvl, vox in enumerate(selection.voxels):
        t = pyr[lvl]
        per_voxel = np.bincount(t.entry_voxel, weights=t.entry_area, minlength=t.n_voxels)
        total += per_voxel[vox].sum() * t.voxel_size**2
    return float(total)


def _grazing_camera(tex):
    b = tex.bounds
    c = 0.5 * (b[0] + b[1])
    return Camera(position=(c[0], b[0, 1] + 0.5, b[1, 2] + 1.0), target=(c[0], b[1, 1], b[0, 2]),
                  fov=60.0)  # fmt: skip


def test_far_camera_uses_coarse_levels(tree_tex, tree_pyr):
    full = tree_tex.to_points()
    stats = {}
    cam = Camera.frame(tree_tex.bounds, distance_scale=10)
    cloud = select_points(tree_pyr, cam, (160, 120), stats=stats)
    levels = [s["level"] for s in stats["levels"] if s["voxels"]]
    assert min(levels) >= 2
    assert len(cloud) < len(full) / 4
    assert stats["points"] == len(cloud) == sum(s["points"] for s in stats["levels"])
    assert stats["culled"] == 0
    # everything is in view: the coarse points carry the whole area
    assert cloud.total_area() == pytest.approx(tree_tex.total_area(), rel=1e-12)
    # and the same camera close up draws the finest level
    close = select_points(tree_pyr, Camera.frame(tree_tex.bounds), (160, 120), stats=stats)
    assert stats["levels"][0]["voxels"] == tree_tex.n_voxels and len(close) == len(full)


def test_near_camera_keeps_finest_and_culls(tree_tex, tree_pyr):
    b = tree_tex.bounds
    c = 0.5 * (b[0] + b[1])
    cam = Camera(position=(c[0] + 1.5, c[1] + 1, c[2] + 1.5), target=tuple(c + [0, 1, 0]), fov=40)
    size = (320, 240)
    sel = select_voxels(tree_pyr, cam, size)
    assert sum(sel.culled) > 0
    assert sum(len(v) for v in sel.voxels[1:]) == 0  # near: all at the finest level
    assert 0 < len(sel.voxels[0]) < tree_tex.n_voxels
    # every finest voxel whose centre is on screen is drawn; none far off it is
    centres = tree_tex.voxel_centers()
    depth = (centres - cam.position) @ cam.forward
    px = cam.project(centres, size)
    on = (depth > 0) & np.all((px >= 0) & (px <= size), axis=1)
    drawn = np.zeros(tree_tex.n_voxels, dtype=bool)
    drawn[sel.voxels[0]] = True
    assert on.any() and np.all(drawn[on])
    # a voxel whose bounding sphere is wholly off screen is not drawn
    r = 0.5 * np.sqrt(3) * tree_tex.voxel_size
    ahead = depth > 2 * r
    r_px = r * size[1] / (2 * np.tan(np.radians(cam.fov) / 2) * np.where(ahead, depth - r, 1.0))
    beyond = np.max(np.maximum(-px, px - np.asarray(size)), axis=1)
    off = (depth < -r) | (ahead & (beyond > 2 * r_px + 1))
    assert off.any() and not np.any(drawn & off)


@pytest.mark.parametrize("pixel_error, size", [(1, (32, 24)), (2, (32, 24)), (4, (32, 24))])
def test_no_region_drawn_twice(tree_tex, tree_pyr, pixel_error, size):
    cam = _grazing_camera(tree_tex)
    sel = select_voxels(tree_pyr, cam, size, pixel_error, cull=False)
    assert sum(1 for v in sel.voxels if len(v)) >= 2  # a mix of levels
    assert np.all(_coverage(tree_pyr, sel) == 1)
    assert _chosen_area(tree_pyr, sel) == pytest.approx(tree_tex.total_area(), rel=1e-12)
    cloud = select_points(tree_pyr, cam, size, pixel_error, cull=False)
    assert cloud.total_area() == pytest.approx(tree_tex.total_area(), rel=1e-12)
    # with culling: still at most once, and the area drawn is that of the
    # finest voxels covered
    sel = select_voxels(tree_pyr, cam, size, pixel_error)
    cover = _coverage(tree_pyr, sel)
    assert cover.max() == 1 and sum(sel.culled) > 0 and cover.min() == 0
    t0 = tree_pyr[0]
    fine_area = np.bincount(t0.entry_voxel, weights=t0.entry_area) * t0.voxel_size**2
    assert _chosen_area(tree_pyr, sel) == pytest.approx(fine_area[cover == 1].sum(), rel=1e-12)


def test_selected_points_are_to_points(tree_tex, tree_pyr):
    cam = Camera.frame(tree_tex.bounds)
    for per_entry in (1, 3):
        cloud = select_points(tree_pyr, cam, (4000, 3000), per_entry=per_entry, cull=False)
        ref = tree_tex.to_points(per_entry=per_entry)
        for name in ("positions", "normals", "areas", "kd", "ks", "shininess"):
            assert np.array_equal(getattr(cloud, name), getattr(ref, name)), name
    # a far camera draws one coarse level: its own to_points
    stats = {}
    cloud = select_points(tree_pyr, Camera.frame(tree_tex.bounds, distance_scale=10), (160, 120),
                          placement="center", stats=stats)  # fmt: skip
    (level,) = [s["level"] for s in stats["levels"] if s["voxels"]]
    assert np.array_equal(cloud.positions, tree_pyr[level].to_points("center").positions)
    # ranges for a renderer that uploads each level once
    sel = stats["selection"]
    ranges = selection_ranges(tree_pyr, sel, "center")
    assert int(ranges[level][1].sum()) == len(cloud)


def test_selection_reuses_each_levels_points(tree_pyr, tree_tex, monkeypatch):
    """Per-frame selection only gathers: once a view has built its levels'
    points, the next frames build none (how fast that is: the selection ms
    of demos/bench_lod.py)."""
    import aniso3d.build.pyramid as pyramid_module

    cam = Camera.frame(tree_tex.bounds)
    first = select_points(tree_pyr, cam, (640, 480))  # builds the level caches

    def must_not_build(*a, **k):
        raise AssertionError("a level's points were built again for the same view")

    monkeypatch.setattr(pyramid_module, "entry_points", must_not_build)
    monkeypatch.setattr(pyramid_module, "adaptive_points", must_not_build)
    again = select_points(tree_pyr, cam, (640, 480))
    assert len(again) == len(first) > 0
    assert np.array_equal(again.positions, first.positions)


def test_bad_arguments(tree_pyr):
    cam = Camera()
    with pytest.raises(InputError):
        select_points(tree_pyr, cam, (0, 10))
    with pytest.raises(InputError):
        select_points(tree_pyr, cam, (10, 10), pixel_error=0)
    with pytest.raises(InputError):
        select_points(tree_pyr, cam, (10, 10), per_entry="many")
    with pytest.raises(InputError):
        pyramid(tree_pyr[0], max_levels=0)


# ------------------------------------------------------------ adaptive counts


def test_adaptive_counts_flat_quad_is_one():
    c = np.sqrt(0.5)
    tilt = np.array([[1, 0, 0, 0], [0, c, -c, 0], [0, c, c, 0], [0, 0, 0, 1]])
    # flat, and tilted (plane sections up to sqrt(2) h^2 in a voxel)
    for mesh in (scenes.quad(1.0), scenes.quad(1.0).transformed(tilt)):
        pyr = pyramid(build_texture(mesh, 8, K))
        assert len(pyr) == 4
        for t in pyr:
            assert np.all(np.diff(t.entry_offsets) == 1)  # one entry per voxel
            assert np.all(adaptive_points(t) == 1)


def test_adaptive_counts_grow_with_scatter():
    rng = np.random.default_rng(3)
    n = 400
    centres = rng.uniform(0, 1, (n, 1, 3))
    tris = centres + rng.normal(scale=0.08, size=(n, 3, 3))
    mesh = Mesh.from_arrays(tris.reshape(-1, 3), np.arange(3 * n).reshape(n, 3), name="scatter")
    t = build_texture(mesh, 1, 8)  # one voxel, facets in all directions
    counts = adaptive_points(t, cap=6)
    assert counts.max() > 1 and counts.max() <= 6
    assert np.all(adaptive_points(t, cap=1) == 1)
    pyr = pyramid(build_texture(mesh, 4, 8))
    cloud = select_points(pyr, Camera.frame(pyr[0].bounds), (64, 48), per_entry="adaptive")
    assert cloud.total_area() == pytest.approx(mesh.area(), rel=1e-12)
