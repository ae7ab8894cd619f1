"""Grid arithmetic shared by building and rendering (aniso3d.grid), against
closed forms and independent NumPy routines."""

from __future__ import annotations

import numpy as np
import pytest

from aniso3d.grid import cell_coords, cell_keys, ranges, tangent_frame, weighted_means

# ------------------------------------------------------------------ cell keys


@pytest.mark.parametrize("shape", [(1, 1, 1), (2, 3, 5), (7, 1, 4), (64, 64, 64), (65536, 3, 65536)])
def test_cell_keys_are_numpys_row_major_index(shape):
    rng = np.random.default_rng(0)
    coords = np.stack([rng.integers(0, s, 500) for s in shape], axis=1)
    keys = cell_keys(coords, np.asarray(shape))
    assert keys.dtype == np.int64
    np.testing.assert_array_equal(keys, np.ravel_multi_index(coords.T, shape))
    np.testing.assert_array_equal(cell_coords(keys, shape), coords)


def test_cell_keys_closed_form_and_order():
    # (i * sy + j) * sz + k for a 3 x 4 x 5 grid: the corner cells
    coords = np.array([[0, 0, 0], [0, 0, 4], [0, 3, 0], [2, 0, 0], [2, 3, 4]], dtype=np.int32)
    np.testing.assert_array_equal(cell_keys(coords, (3, 4, 5)), [0, 4, 15, 40, 59])
    # every cell once: keys are 0..n-1 in lexicographic (i, j, k) order
    every = np.stack(np.meshgrid(np.arange(3), np.arange(4), np.arange(5), indexing="ij"), -1).reshape(-1, 3)
    np.testing.assert_array_equal(cell_keys(every, (3, 4, 5)), np.arange(60))
    # int32 coords of a 65536^3 grid do not overflow
    big = np.array([[65535, 65535, 65535]], dtype=np.int32)
    assert cell_keys(big, (65536,) * 3)[0] == 65536**3 - 1


def test_cell_coords_of_no_keys():
    assert cell_coords(np.zeros(0, dtype=np.int64), (2, 2, 2)).shape == (0, 3)
    assert cell_keys(np.zeros((0, 3)), (2, 2, 2)).shape == (0,)


# --------------------------------------------------------------------- ranges


def test_ranges_is_concatenated_aranges():
    rng = np.random.default_rng(1)
    starts = rng.integers(-50, 1000, 300)
    stops = starts + rng.integers(0, 6, 300)  # empty runs included
    want = np.concatenate([np.arange(a, b) for a, b in zip(starts, stops, strict=True)])
    got = ranges(starts, stops)
    assert got.dtype == np.int64
    np.testing.assert_array_equal(got, want)


def test_ranges_edge_cases():
    assert ranges(np.array([3, 7]), np.array([3, 7])).shape == (0,)
    assert ranges(np.zeros(0, int), np.zeros(0, int)).shape == (0,)
    np.testing.assert_array_equal(ranges(np.array([5]), np.array([9])), [5, 6, 7, 8])
    np.testing.assert_array_equal(ranges(np.array([4, 0, 2]), np.array([6, 0, 3])), [4, 5, 2])


# ------------------------------------------------------------- tangent frames


def test_tangent_frame_closed_forms():
    # n = z: h = x, t = z x x = y, b = z x y = -x
    t, b = tangent_frame(np.array([[0.0, 0.0, 1.0]]))
    np.testing.assert_array_equal(t, [[0.0, 1.0, 0.0]])
    np.testing.assert_array_equal(b, [[-1.0, 0.0, 0.0]])
    # n = x: |n_x| >= 0.9, so h = y: t = x x y = z, b = x x z = -y
    t, b = tangent_frame(np.array([[1.0, 0.0, 0.0]]))
    np.testing.assert_array_equal(t, [[0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(b, [[0.0, -1.0, 0.0]])
    # n = y: h = x, t = y x x = -z, b = y x -z = -x
    t, b = tangent_frame(np.array([[0.0, 1.0, 0.0]]))
    np.testing.assert_array_equal(t, [[0.0, 0.0, -1.0]])
    np.testing.assert_array_equal(b, [[-1.0, 0.0, 0.0]])


def test_tangent_frame_is_right_handed_orthonormal():
    rng = np.random.default_rng(2)
    n = rng.normal(size=(1000, 3))
    n = np.concatenate([n, [[0.9, np.sqrt(1 - 0.81), 0.0], [-0.9, 0.0, np.sqrt(1 - 0.81)]]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    t, b = tangent_frame(n)
    frame = np.stack([t, b, n], axis=2)  # columns t, b, n
    np.testing.assert_allclose(np.einsum("nij,nik->njk", frame, frame), np.broadcast_to(np.eye(3), frame.shape),
                               atol=1e-12)  # fmt: skip
    np.testing.assert_allclose(np.linalg.det(frame), 1.0, atol=1e-12)


# -------------------------------------------------------------- weighted means


def test_weighted_means_match_numpy_average():
    rng = np.random.default_rng(3)
    G, N = 40, 2000
    group = rng.integers(0, G, N)
    weights = rng.uniform(0, 2, N)
    values = rng.normal(size=(N, 3))
    totals = np.bincount(group, weights, minlength=G)
    got = weighted_means(group, weights, values, totals)
    got1 = weighted_means(group, weights, values[:, 1], totals)
    assert got.shape == (G, 3) and got1.shape == (G,)
    for g in range(G):
        sel = group == g
        want = np.average(values[sel], axis=0, weights=weights[sel])
        np.testing.assert_allclose(got[g], want, rtol=1e-12, atol=1e-14)
        assert got1[g] == pytest.approx(want[1], rel=1e-12, abs=1e-14)


def test_weighted_means_closed_form_and_empty_groups():
    # group 0: values 1 and 4 with weights 2 and 1 -> 2; group 1: no weight; group 2: 5
    group = np.array([0, 0, 2, 1])
    weights = np.array([2.0, 1.0, 3.0, 0.0])
    values = np.array([1.0, 4.0, 5.0, 7.0])
    totals = np.bincount(group, weights, minlength=4)
    got = weighted_means(group, weights, values, totals)
    np.testing.assert_array_equal(got, [2.0, 0.0, 5.0, 0.0])  # weightless groups: 0, not NaN
    # a constant is its own mean, to rounding, for any weights
    w = np.random.default_rng(4).uniform(0.1, 1.0, 1000)
    g = np.arange(1000) % 7
    np.testing.assert_allclose(weighted_means(g, w, np.full(1000, 0.3), np.bincount(g, w)), 0.3, rtol=1e-13)


def test_entries_at_lists_each_cells_entries_against_a_loop():
    """entries_at against a loop over the cells: occupied cells give their
    entries in order, empty cells and cells outside the grid none."""
    from aniso3d.grid import entries_at

    rng = np.random.default_rng(5)
    shape = np.array([5, 4, 3])
    keys = np.sort(rng.choice(int(np.prod(shape)), 20, replace=False))
    coords = cell_coords(keys, shape)
    counts = rng.integers(1, 4, len(coords))
    offsets = np.concatenate([[0], np.cumsum(counts)])
    cells = rng.integers(-1, 6, (200, 3))
    which, other = entries_at(keys, shape, offsets, cells)
    want_w, want_o = [], []
    for i, c in enumerate(cells):
        match = np.flatnonzero((coords == c).all(axis=1))
        if len(match):
            v = match[0]
            want_w += [i] * int(counts[v])
            want_o += list(range(offsets[v], offsets[v + 1]))
    assert len(want_w) > 20
    np.testing.assert_array_equal(which, want_w)
    np.testing.assert_array_equal(other, want_o)
