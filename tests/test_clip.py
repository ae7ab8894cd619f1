"""Stage 2: exact clipping of triangles into half-open voxel cells.

Everything here calls :func:`aniso3d.build.clip.clip_to_grid` directly, in grid
coordinates (cell (i, j, k) is [i, i+1) x [j, j+1) x [k, k+1)), so areas are
in units of h^2 and the expected values are exact numbers.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aniso3d import InputError, scenes
from aniso3d.build.clip import clip_to_grid, make_grid, triangle_normals

EPS = np.finfo(np.float64).eps


def clip(tri, shape):
    """Clip (n, 3, 3) grid-coordinate triangles; returns (sub-polygons, areas)."""
    tri = np.asarray(tri, dtype=np.float64).reshape(-1, 3, 3)
    normals, area2 = triangle_normals(tri)
    sp = clip_to_grid(tri, normals, np.asarray(shape), np.arange(len(tri)))
    return sp, 0.5 * area2


def per_triangle_area(sp, n):
    return np.bincount(sp.face, weights=sp.area, minlength=n)


def pieces_by_cell(sp):
    """{cell tuple: total area} of the sub-polygons."""
    out: dict[tuple, float] = {}
    for c, a in zip(map(tuple, sp.cell.tolist()), sp.area, strict=True):
        out[c] = out.get(c, 0.0) + a
    return out


def conservation_tolerance(tri, area):
    """1e-9 relative, plus the floating-point uncertainty of the reference area
    itself: a needle triangle's 0.5 |e1 x e2| is only known to ~eps * L^2
    (L its longest edge), so it cannot be judged beyond that. For any
    reasonably shaped triangle the first term is the binding one."""
    edges = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
    return 1e-9 * area + 64 * EPS * edges**2


# ------------------------------------------------------------------- make_grid


def test_make_grid_longest_axis_gets_resolution_and_cubic_cells():
    g = make_grid(np.array([[0.0, 0.0, 0.0], [10.0, 5.0, 2.5]]), 8)
    assert g.voxel_size == pytest.approx(10.0 / 8)
    assert g.shape.tolist() == [8, 4, 2]
    assert np.array_equal(g.origin, [0.0, 0.0, 0.0])


def test_make_grid_does_not_round_up_an_exact_multiple():
    # 128 * (L / 128) must not become 129 cells.
    g = make_grid(np.array([[0.0, 0.0, 0.0], [1.0, 0.7, 0.3]]), 128)
    assert g.shape[0] == 128
    assert g.shape[1] == int(np.ceil(0.7 * 128 - 1e-9))


def test_make_grid_flat_mesh_gets_one_cell_across():
    g = make_grid(np.array([[0.0, 0.0, 0.0], [2.0, 2.0, 0.0]]), 4)
    assert g.shape.tolist() == [4, 4, 1]


@pytest.mark.parametrize("bad", [0, -3, 1.5, True, 70000])
def test_make_grid_rejects_bad_resolution(bad):
    with pytest.raises(InputError, match="resolution"):
        make_grid(np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]), bad)


def test_make_grid_rejects_zero_extent():
    with pytest.raises(InputError, match="zero extent"):
        make_grid(np.array([[1.0, 1.0, 1.0], [1.0, 1.0, 1.0]]), 4)


# ------------------------------------------------------------------ exact cases


def test_right_triangle_pieces_are_exact():
    # (0,0), (2,0), (0,2) at z = 0.5 in a 2x2x1 grid: a full unit square in
    # cell (0,0), two half squares, and nothing in (1,1) (the hypotenuse only
    # touches its corner).
    sp, area = clip([[0, 0, 0.5], [2, 0, 0.5], [0, 2, 0.5]], (2, 2, 1))
    got = pieces_by_cell(sp)
    assert got == {(0, 0, 0): 1.0, (1, 0, 0): 0.5, (0, 1, 0): 0.5}
    full = np.nonzero((sp.cell == [0, 0, 0]).all(axis=1))[0]
    assert np.allclose(sp.centroid[full], [[0.5, 0.5, 0.5]], atol=1e-15)
    assert area[0] == 2.0


def test_triangle_crossing_many_cells_exact_total_and_cells():
    # A triangle in the plane z = 1.25 spanning a 4 x 4 block: every cell it
    # touches gets a piece, the pieces tile it.
    tri = [[0, 0, 1.25], [4, 0, 1.25], [0, 4, 1.25]]
    sp, area = clip(tri, (4, 4, 3))
    assert area[0] == 8.0
    assert per_triangle_area(sp, 1)[0] == pytest.approx(8.0, rel=1e-15)
    assert set(sp.cell[:, 2].tolist()) == {1}
    # cells strictly below the hypotenuse x + y = 4 are full squares
    for (i, j, _), a in pieces_by_cell(sp).items():
        if i + j + 2 <= 4:
            assert a == pytest.approx(1.0, abs=1e-15)
        elif i + j + 1 == 4:
            assert a == pytest.approx(0.5, abs=1e-15)
    assert len(pieces_by_cell(sp)) == 10


def test_tilted_plane_piece_in_a_cell_has_closed_form_area():
    # The plane x + z = 3 + d cuts cell (1,1,1) of a 3^3 grid in a rectangle
    # of width 1 (along y) and length (1 - |d|) * sqrt(2).
    for d in (0.0, 0.25, -0.4):
        c = 3.0 + d
        # a big triangle in that plane covering the whole grid
        tri = [[-10, -10, c + 10], [10, -10, c - 10], [0, 20, c]]
        sp, _ = clip(tri, (3, 3, 3))
        got = pieces_by_cell(sp).get((1, 1, 1), 0.0)
        assert got == pytest.approx((1 - abs(d)) * np.sqrt(2), rel=1e-12)


def test_face_index_labels_the_output():
    tri = np.array([[[0, 0, 0.5], [1, 0, 0.5], [0, 1, 0.5]]] * 2, dtype=float)
    normals, _ = triangle_normals(tri)
    sp = clip_to_grid(tri, normals, np.array([1, 1, 1]), np.array([7, 42]))
    assert sorted(sp.face.tolist()) == [7, 42]


# ------------------------------------------------------------ half-open cells


def test_facet_on_interior_plane_goes_to_upper_cell_once():
    # z = 2 is the plane between cells k=1 and k=2: only k=2 gets it.
    for normal_sign in (1, -1):
        tri = np.array([[0.3, 0.3, 2], [3.7, 0.3, 2], [0.3, 3.7, 2]])
        if normal_sign < 0:
            tri = tri[::-1]
        sp, area = clip(tri, (4, 4, 4))
        assert set(sp.cell[:, 2].tolist()) == {2}
        assert per_triangle_area(sp, 1)[0] == pytest.approx(area[0], rel=1e-14)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_facet_on_interior_plane_every_axis(axis):
    # A unit square lying on plane `axis` = 2, aligned with the cell grid
    # (its edges on grid lines, its corners on grid points).
    a, b = [i for i in range(3) if i != axis]
    quad = np.zeros((4, 3))
    quad[:, axis] = 2.0
    quad[:, a] = [1, 3, 3, 1]
    quad[:, b] = [1, 1, 3, 3]
    tri = quad[[[0, 1, 2], [0, 2, 3]]]
    sp, area = clip(tri, (4, 4, 4))
    cells = pieces_by_cell(sp)
    expected = {}
    for i in (1, 2):
        for j in (1, 2):
            c = [0, 0, 0]
            c[axis], c[a], c[b] = 2, i, j
            expected[tuple(c)] = 1.0
    assert cells == expected  # exact: everything sits on integers
    assert area.sum() == 4.0


def test_facet_along_a_grid_edge_and_through_a_corner():
    # A triangle in plane y = 1 whose edge runs along the grid line
    # y = 1, z = 1 and whose corner sits on the grid point (1, 1, 1).
    tri = [[1, 1, 1], [3, 1, 1], [1, 1, 3]]
    sp, area = clip(tri, (3, 3, 3))
    cells = pieces_by_cell(sp)
    assert set(c[1] for c in cells) == {1}  # upper cell in y
    assert set(c[2] for c in cells) >= {1}
    assert all(c[0] >= 1 and c[2] >= 1 for c in cells)  # nothing leaks below
    assert sum(cells.values()) == pytest.approx(area[0], rel=1e-15)
    assert cells[(1, 1, 1)] == 1.0
    # A sliver line segment on the edge itself has no area and is dropped.
    sp2, area2 = clip([[1, 1, 1], [3, 1, 1], [2, 1, 1]], (3, 3, 3))
    assert area2[0] == 0.0 and len(sp2) == 0


def test_facets_on_outer_faces_are_kept():
    n = 3
    lo, hi = 0.0, float(n)
    tris = []
    for axis in range(3):
        a, b = [i for i in range(3) if i != axis]
        for value in (lo, hi):
            t = np.zeros((3, 3))
            t[:, axis] = value
            t[:, a] = [0.2, 2.8, 0.2]
            t[:, b] = [0.2, 0.2, 2.8]
            tris.append(t)
    tris = np.array(tris)
    sp, area = clip(tris, (n, n, n))
    got = per_triangle_area(sp, len(tris))
    assert np.allclose(got, area, rtol=1e-14)
    # the face on the plane u = n (the grid's far face) lands in the last cell
    for f in range(len(tris)):
        axis, far = divmod(f, 2)
        cells = sp.cell[sp.face == f, axis]
        assert set(cells.tolist()) == {n - 1 if far else 0}


def test_geometry_slightly_outside_the_grid_is_kept_in_outer_cells():
    # Rounding can put vertices a hair beyond the grid's faces.
    tri = [[-1e-12, -1e-12, -1e-12], [2 + 1e-12, 0, 0], [0, 2 + 1e-12, 2 + 1e-12]]
    sp, area = clip(tri, (2, 2, 2))
    assert per_triangle_area(sp, 1)[0] == pytest.approx(area[0], rel=1e-12)
    assert sp.cell.min() >= 0 and sp.cell.max() <= 1


# ------------------------------------------------------------------ degenerate


def test_degenerate_triangles_have_zero_normal_and_produce_nothing():
    tri = np.array(
        [
            [[1, 1, 1], [1, 1, 1], [1, 1, 1]],  # one point
            [[0, 0, 0], [1, 1, 1], [2, 2, 2]],  # collinear, across cells
            [[0.5, 0.5, 0.5], [0.5, 0.5, 0.5], [1.5, 0.2, 0.1]],  # repeated vertex
            [[0, 1, 0], [2, 1, 0], [1, 1, 0]],  # collinear on a grid plane
        ],
        dtype=float,
    )
    normals, area2 = triangle_normals(tri)
    assert np.all(normals == 0) and np.all(area2 == 0)
    sp = clip_to_grid(tri, normals, np.array([3, 3, 3]), np.arange(4))
    assert len(sp) == 0
    assert sp.cell.shape == (0, 3) and sp.centroid.shape == (0, 3)


def test_degenerate_triangles_mixed_in_do_not_disturb_the_others():
    good = np.array([[[0.2, 0.1, 0.3], [2.7, 0.4, 1.1], [0.5, 2.9, 2.2]]])
    bad = np.array([[[1, 1, 1], [2, 2, 2], [3, 3, 3]], [[0, 0, 0]] * 3], dtype=float)
    alone, _ = clip(good, (3, 3, 3))
    mixed, _ = clip(np.concatenate([bad[:1], good, bad[1:]]), (3, 3, 3))
    assert np.array_equal(mixed.face, np.ones(len(alone), dtype=np.int64))
    assert np.array_equal(mixed.area, alone.area)
    assert np.array_equal(mixed.cell, alone.cell)
    assert np.array_equal(mixed.centroid, alone.centroid)


def test_no_triangles_at_all():
    sp = clip_to_grid(np.zeros((0, 3, 3)), np.zeros((0, 3)), np.array([2, 2, 2]), np.arange(0))
    assert len(sp) == 0


# ---------------------------------------------------------------- conservation


def test_tree_pieces_conserve_each_triangle_area():
    mesh = scenes.tree(levels=4, leaves_per_twig=20)
    for resolution in (8, 33):
        g = make_grid(mesh.bounds, resolution)
        tri = g.to_grid(mesh.triangles)
        sp, area = clip(tri, g.shape)
        got = per_triangle_area(sp, len(tri))
        assert np.all(np.abs(got - area) <= 1e-9 * area)
        inside_cells(sp, g.shape)


def test_random_soup_pieces_conserve_area_and_stay_in_cells():
    rng = np.random.default_rng(5)
    shape = np.array([7, 5, 6])
    for scale in (1e-8, 1e-6, 1e-3, 0.3, 3.0, 20.0):
        centre = rng.uniform(0, 1, (3000, 1, 3)) * shape
        # a third centred on grid points, so they straddle three planes, and a
        # third on a plane of one axis only, half a voxel from the others
        centre[::3] = np.round(centre[::3])
        centre[1::3, :, 0] = np.round(centre[1::3, :, 0])
        tri = np.clip(centre + rng.normal(size=(3000, 3, 3)) * scale, 0, shape)
        sp, area = clip(tri, shape)
        got = per_triangle_area(sp, len(tri))
        assert np.all(np.abs(got - area) <= conservation_tolerance(tri, area)), scale
        inside_cells(sp, shape)


def test_far_from_origin_mesh_still_conserves_area():
    # Working relative to the grid origin keeps precision far from (0, 0, 0).
    mesh = scenes.sphere(radius=1.0, center=(1e6, -2e6, 5e5), subdivisions=3)
    g = make_grid(mesh.bounds, 16)
    sp, _ = clip(g.to_grid(mesh.triangles), g.shape)
    got = per_triangle_area(sp, mesh.n_faces) * g.voxel_size**2
    assert np.allclose(got, mesh.face_areas(), rtol=1e-9, atol=0)


def test_first_vertex_form_gives_the_same_pieces():
    # clip_to_grid(local, ..., first=v0) is the same clip as on absolute grid
    # coordinates, only with the triangle's shape kept exactly.
    mesh = scenes.tree(levels=3, leaves_per_twig=10)
    g = make_grid(mesh.bounds, 20)
    absolute = g.to_grid(mesh.triangles)
    world = mesh.triangles
    local = (world - world[:, :1]) / g.voxel_size
    normals, _ = triangle_normals(local)
    a = clip_to_grid(absolute, normals, g.shape, np.arange(mesh.n_faces))
    b = clip_to_grid(local, normals, g.shape, np.arange(mesh.n_faces), first=g.to_grid(world[:, 0]))
    assert len(a) == len(b)
    np.testing.assert_array_equal(a.face, b.face)
    np.testing.assert_array_equal(a.cell, b.cell)
    np.testing.assert_allclose(a.area, b.area, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(a.centroid, b.centroid, rtol=0, atol=1e-9)
    inside_cells(b, g.shape)


def test_a_hair_across_a_plane_still_counts_first_vertex_form():
    # In first-vertex form the geometry is exact even where absolute grid
    # coordinates could not resolve it: a vertex 1e-17 below plane x = 3 puts
    # a sliver in cell 2, one 2.2e-16 above plane x = 3 (first vertex at
    # x = 2) a sliver in cell 3; neither is lost or put in the wrong cell.
    shape = np.array([5, 2, 2])
    below = np.array([[[0.0, 0.0, 0.0], [-1e-17, 0.5, 0.0], [0.3, 0.0, 0.5]]])
    above = np.array([[[0.0, 0.0, 0.0], [1.0 + 2.2e-16, 0.5, 0.0], [0.3, 0.0, 0.5]]])
    for tri, first, cells in (
        (below, [[3.0, 0.2, 0.2]], {2, 3}),
        (above, [[2.0, 0.2, 0.2]], {2, 3}),
    ):
        normals, area2 = triangle_normals(tri)
        sp = clip_to_grid(tri, normals, shape, np.arange(1), first=np.array(first))
        assert set(sp.cell[:, 0].tolist()) == cells
        assert sp.area.sum() == pytest.approx(0.5 * area2[0], rel=1e-15)
        inside_cells(sp, shape, tol=0.0)


def inside_cells(sp, shape, tol=1e-9):
    """Every piece's cell is in the grid and its centroid inside that cell
    (outer cells are unbounded outwards)."""
    shape = np.asarray(shape)
    assert np.all(sp.cell >= 0) and np.all(sp.cell < shape)
    rel = sp.centroid - sp.cell
    low_ok = (rel >= -tol) | (sp.cell == 0)
    high_ok = (rel <= 1 + tol) | (sp.cell == shape - 1)
    assert np.all(low_ok & high_ok)
    assert np.all(sp.area > 0)


# ------------------------------------------------------------- property-based


@st.composite
def triangle_soups(draw):
    shape = np.array(draw(st.tuples(*[st.integers(1, 5)] * 3)))
    n = draw(st.integers(1, 10))
    coord = [
        st.one_of(
            st.floats(0, float(s), allow_nan=False),
            st.integers(0, int(s)).map(float),  # on a grid plane
        )
        for s in shape
    ]
    tris = []
    for _ in range(n):
        kind = draw(st.sampled_from(["general", "tiny", "on_plane", "huge", "lattice"]))
        if kind == "general":
            t = [[draw(coord[a]) for a in range(3)] for _ in range(3)]
        elif kind == "lattice":
            t = [[float(draw(st.integers(0, int(shape[a])))) for a in range(3)] for _ in range(3)]
        elif kind == "tiny":
            # often centred on a grid point, so it straddles up to three planes
            centre = np.array([draw(coord[a]) for a in range(3)])
            # snap some axes onto grid planes so it straddles them
            snap = np.array(draw(st.lists(st.booleans(), min_size=3, max_size=3)))
            centre = np.where(snap, np.round(centre), centre)
            size = 10.0 ** draw(st.floats(-9, -1))
            offs = draw(st.lists(st.floats(-1, 1, allow_nan=False), min_size=9, max_size=9))
            t = centre + size * np.reshape(offs, (3, 3))
        elif kind == "on_plane":
            axis = draw(st.integers(0, 2))
            k = float(draw(st.integers(0, int(shape[axis]))))
            t = [[k if a == axis else draw(coord[a]) for a in range(3)] for _ in range(3)]
        else:  # huge: corners of the grid, give or take, spanning every cell
            t = [
                [
                    draw(st.sampled_from([0.0, float(shape[a])])) + draw(st.floats(-0.5, 0.5))
                    for a in range(3)
                ]
                for _ in range(3)
            ]
        tris.append(t)
    return shape, np.asarray(tris, dtype=np.float64)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(triangle_soups())
def test_property_clipping_conserves_area_and_keeps_pieces_in_cells(soup):
    shape, tri = soup
    sp, area = clip(tri, shape)
    got = per_triangle_area(sp, len(tri))
    assert np.all(np.abs(got - area) <= conservation_tolerance(tri, area))
    inside_cells(sp, shape)
    # degenerate triangles contribute nothing
    assert np.all(got[area == 0] == 0)
