"""Local point spacing: splat sizes and normals for point clouds from other tools.

A point cloud from a scanner or another program usually says where its points
are, often their normals and colours, but not how large a surface patch each
stands for. One size for every point leaves holes wherever the sampling is
sparser than average; a surfel renderer sizes each splat from its neighbours
instead. This module finds the ``k`` nearest neighbours of every point and
turns their distances into a local spacing and a splat radius, and (on
request) their spread into a normal.

Local spacing
    ``spacing_i = sqrt(2 pi mean_j(d_ij^2) / (k + 1))`` over the ``k``
    nearest neighbours ``j`` of point ``i`` (distances in world units). For
    points scattered at random with density ``lam`` per unit area,
    ``pi lam d_j^2`` of the j-th neighbour has mean ``j``, so the mean of the
    squared distances is ``(k + 1) / (2 pi lam)`` and ``spacing^2`` estimates
    ``1 / lam``, the area per point. On a square grid of spacing ``s`` it is
    ``sqrt(2 pi m_k / (k + 1)) s`` with ``m_k`` the mean squared length of
    the ``k`` shortest lattice steps: 1.023 s for the default ``k = 8``
    (4 steps of length s, 4 of sqrt(2) s). A mean over all ``k`` varies less
    than one distance, and a squared mean does not jump when the k-th
    neighbour moves from one lattice ring to the next.

Splat radius
    ``radius_i = COVERAGE * spacing_i``, and the point's area ``pi radius^2``
    (the splat renderer draws a disc of ``sqrt(area / pi)`` times its size
    factor, 1.25 for discs, so a drawn disc reaches ``1.875 spacing``).
    Points at random leave empty circles much wider than their mean
    spacing. Measured on 200k random points of a plane (20M test points,
    ``demos/bench_point_holes.py --plane``, docs/point_clouds.md), the
    fraction of the plane that no drawn disc covers is 1.5e-2 for drawn
    discs of one spacing, 1.3e-3 at 1.25, 6.6e-5 at 1.5, 6e-7 at 1.8 and
    none found at 1.9: a drawn radius of 1.875 spacings (``COVERAGE = 1.5``)
    leaves under one pixel in a million open. On a regular grid of
    spacing ``s`` the radius is ``1.5 * 1.023 s = 1.53 s``: more overlap
    than a grid needs, the price of covering random samples.

Neighbour search
    Exact, by a k-d tree (:class:`scipy.spatial.cKDTree`) when scipy is
    installed, else by an exact grid hash in NumPy (:func:`knn_grid`, no
    dependency). Measured on a noisy torus, k = 8 (``demos/bench_point_holes.py
    --knn``, docs/point_clouds.md): 1M points take the tree 2.3 s of CPU and
    316 MiB at peak, the grid 6.7 s and 493 MiB; 100k points 0.39 s and
    57 MiB against 0.62 s and 143 MiB. So the tree is the default (scipy is
    the ``points`` extra); the grid hash finds the same neighbours and keeps
    aniso3d whole without scipy, at about three times the time.
"""

from __future__ import annotations

import math

import numpy as np

from aniso3d.errors import InputError
from aniso3d.grid import cell_keys, ranges

#: Neighbours per point for spacing and normals.
DEFAULT_K = 8

#: Splat radius over local spacing (see the module docstring).
COVERAGE = 1.5

#: Largest number of candidate pairs the grid hash holds at once (memory:
#: about 80 bytes a pair).
GRID_PAIR_BUDGET = 1_000_000

# The 27 cells of a 3 x 3 x 3 block around a cell, as (27, 3) offsets.
_BLOCK = np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)


def have_kdtree() -> bool:
    """True if scipy's k-d tree can be imported."""
    try:
        from scipy.spatial import cKDTree  # noqa: F401
    except ImportError:
        return False
    return True


def nearest_neighbours(points: np.ndarray, k: int = DEFAULT_K, method: str = "auto") -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest other points of every point, exactly.

    Args:
        points: (N, 3) positions, world units, finite.
        k: neighbours per point; at most N - 1.
        method: "kdtree" (scipy), "grid" (NumPy grid hash) or "auto" (the
            tree if scipy is installed).

    Returns:
        distances (N, k) float64, ascending along each row, and indices
        (N, k) int64 into ``points``. A point is never its own neighbour; a
        duplicate of it is (at distance 0). Ties are broken either way.
    """
    p = np.ascontiguousarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {p.shape}")
    if not np.isfinite(p).all():
        raise InputError("points must be finite to find their neighbours")
    k = int(k)
    if k < 1 or k > len(p) - 1:
        raise InputError(f"cannot find {k} neighbours among {len(p)} points: need at least {k + 1} points")
    if method == "auto":
        method = "kdtree" if have_kdtree() else "grid"
    if method == "kdtree":
        return knn_kdtree(p, k)
    if method == "grid":
        return knn_grid(p, k)
    raise InputError(f"unknown neighbour search '{method}'; choose auto, kdtree or grid")


def knn_kdtree(points: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`nearest_neighbours` by scipy's cKDTree (both cores)."""
    from scipy.spatial import cKDTree

    tree = cKDTree(points, balanced_tree=False, compact_nodes=False)
    # Queries in the tree's own order (neighbours in space are neighbours in
    # memory): 2.5 times faster than in the file's order on 1M points.
    order = tree.indices
    d, i = tree.query(tree.data[order], k + 1, workers=-1)
    # The point itself comes first unless duplicates of it tie at distance 0.
    odd = np.flatnonzero(i[:, 0] != order)
    if len(odd):
        d[odd, 1:], i[odd, 1:] = _drop_self(d[odd], i[odd], order[odd], k)
    dist = np.empty((len(points), k))
    idx = np.empty((len(points), k), np.int64)
    dist[order], idx[order] = d[:, 1:], i[:, 1:]
    return dist, idx


def _drop_self(dist: np.ndarray, idx: np.ndarray, own: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(M, k) neighbours of the points ``own`` (M,) from their (M, k + 1)
    nearest, which hold the point itself unless more than k duplicates of it
    tie at distance 0 (then the last column goes)."""
    mine = idx == own[:, None]
    mine[~mine.any(axis=1), -1] = True
    first = np.argmax(mine, axis=1)
    keep = np.ones_like(mine)
    keep[np.arange(len(idx)), first] = False
    return dist[keep].reshape(-1, k), idx[keep].reshape(-1, k)


def knn_grid(points: np.ndarray, k: int, cell: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`nearest_neighbours` by an exact grid hash, NumPy only.

    Points are sorted into cubic cells of side ``cell``; the neighbours of a
    point are searched among the 27 cells around its own, which hold every
    point within ``cell`` of it. A point whose k-th candidate is farther than
    that (a sparse region) is searched again on a grid of twice the cell, until
    every answer is exact. The first cell size comes from the occupancy of a
    trial grid, so that a 3 x 3 x 3 block holds a few times ``k`` points.
    """
    n = len(points)
    lo = points.min(axis=0)
    extent = float(np.ptp(points, axis=0).max())
    if cell is None:
        cell = _grid_cell(points, lo, extent, k)
    dist = np.full((n, k), np.inf)
    idx = np.zeros((n, k), np.int64)
    todo = np.arange(n)
    while len(todo):
        # A cell as wide as the cloud holds every point: the last round is exact.
        final = cell > extent
        d, i, ok = _grid_round(points, lo, cell, k, todo, final)
        dist[todo[ok]], idx[todo[ok]] = d[ok], i[ok]
        todo = todo[~ok]
        cell *= 2.0
    return dist, idx


def _grid_cell(points: np.ndarray, lo: np.ndarray, extent: float, k: int) -> float:
    """A first cell size: a trial grid of about N cells along the cloud's
    volume, rescaled by its occupancy so that a 3 x 3 x 3 block holds about
    ``4 k`` points on a surface (the cell count grows as the square of the
    scale) or in a volume (as its cube)."""
    if extent == 0:
        return 1.0
    trial = extent / max(math.ceil(len(points) ** (1 / 3)), 1)
    keys = _keys(points, lo, trial)[0]
    per_cell = len(points) / len(np.unique(keys))
    # 27 cells of a surface hold about 9 cells' worth; 2D scaling is the safer guess.
    return max(trial * math.sqrt(4.0 * k / (9.0 * per_cell)), extent * 1e-9)


def _keys(points: np.ndarray, lo: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Cell key of each point on a grid padded by one cell on every side (so
    that the 27 cells around any point have valid keys), and the grid shape."""
    ijk = np.floor((points - lo) / cell).astype(np.int64) + 1
    shape = ijk.max(axis=0) + 2
    if float(np.prod(shape.astype(np.float64))) > 2.0**62:
        raise InputError("points span too many grid cells for the grid neighbour search; install scipy")
    return cell_keys(ijk, shape), shape


def _grid_round(points, lo, cell, k, todo, final):
    """One grid of ``cell``: the k nearest candidates of the points ``todo``
    and whether each answer is exact (k-th distance within ``cell``)."""
    keys, shape = _keys(points, lo, cell)
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    sorted_pts = points[order]
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order))
    cells, starts, counts = np.unique(sorted_keys, return_index=True, return_counts=True)
    step = cell_keys(_BLOCK, shape) - cell_keys(np.zeros((1, 3)), shape)  # (27,) key offsets
    # Each occupied cell of a query: its 27 neighbour cells' runs in `order`.
    qcell = np.searchsorted(cells, keys[todo])
    ucell, qinv = np.unique(qcell, return_inverse=True)
    nb = cells[ucell][:, None] + step[None, :]
    pos = np.minimum(np.searchsorted(cells, nb), len(cells) - 1)
    present = cells[pos] == nb
    del nb
    nb_start = np.where(present, starts[pos], 0).astype(np.int64)
    nb_count = np.where(present, counts[pos], 0).astype(np.int32)
    del pos, present
    cand_count = nb_count.sum(axis=1)[qinv]  # candidates of each query
    dist = np.full((len(todo), k), np.inf)
    idx = np.zeros((len(todo), k), np.int64)
    # Queries by candidate count (in cell order for equal counts, for memory
    # locality), in chunks of about GRID_PAIR_BUDGET pairs
    # padded to the chunk's largest count (little padding once sorted).
    in_cells = np.argsort(keys[todo], kind="stable")
    by_count = in_cells[np.argsort(cand_count[in_cells], kind="stable")]
    sorted_count = np.maximum(cand_count[by_count], 1)
    lo_q = 0
    while lo_q < len(by_count):
        # Rows [lo_q, hi) padded to the width of the last: the most that fit the budget.
        window = sorted_count[lo_q : lo_q + GRID_PAIR_BUDGET // int(sorted_count[lo_q]) + 1]
        padded = np.arange(1, len(window) + 1) * window
        hi_q = lo_q + max(1, int(np.searchsorted(padded, GRID_PAIR_BUDGET, side="right")))
        q = by_count[lo_q:hi_q]
        d, i = _chunk_knn(sorted_pts, nb_start[qinv[q]], nb_count[qinv[q]], rank[todo[q]], k)
        dist[q], idx[q] = d, order[i]
        lo_q = hi_q
    ok = np.full(len(todo), True) if final else dist[:, -1] <= cell
    return dist, idx, ok


def _chunk_knn(sorted_pts, nb_start, nb_count, queries, k):
    """k nearest of ``queries`` (positions in ``sorted_pts``) among their
    candidate runs: distances and positions, (Q, k) each."""
    nq = len(queries)
    total = nb_count.sum(axis=1)
    width = max(int(total.max()), k)
    # Every (query, candidate) pair, run after run: runs are contiguous in the
    # sorted points, so the gathers below read memory nearly in order.
    rows = np.repeat(np.arange(nq), total)
    flat = ranges(nb_start.reshape(-1), (nb_start + nb_count).reshape(-1))
    cols = np.arange(len(flat)) - np.repeat(np.cumsum(total) - total, total)
    own = queries[rows]
    diff = sorted_pts[flat] - sorted_pts[own]
    d2 = np.einsum("ij,ij->i", diff, diff)
    d2[flat == own] = np.inf
    d2m = np.full((nq, width), np.inf)
    cand = np.zeros((nq, width), np.int64)
    d2m[rows, cols], cand[rows, cols] = d2, flat
    part = np.argpartition(d2m, k - 1, axis=1)[:, :k] if width > k else np.broadcast_to(np.arange(k), (nq, k))
    part_d2 = np.take_along_axis(d2m, part, axis=1)
    srt = np.argsort(part_d2, axis=1)
    best = np.take_along_axis(part, srt, axis=1)
    return np.sqrt(np.take_along_axis(part_d2, srt, axis=1)), np.take_along_axis(cand, best, axis=1)


def local_spacing(distances: np.ndarray) -> np.ndarray:
    """(N,) local spacing, world units, from (N, k) neighbour distances:
    ``sqrt(2 pi mean(d^2) / (k + 1))``, the square root of the area per point
    of a random sample with the same neighbour distances (module docstring)."""
    d = np.asarray(distances, dtype=np.float64)
    k = d.shape[1]
    return np.sqrt(2.0 * math.pi * np.mean(d * d, axis=1) / (k + 1))


def splat_radii(
    points: np.ndarray, k: int = DEFAULT_K, coverage: float = COVERAGE, method: str = "auto"
) -> np.ndarray:
    """(N,) splat radius of each point, world units: ``coverage`` times its
    local spacing over its ``k`` nearest neighbours. Sized so that discs of
    these radii (drawn with the renderer's default disc size factor) leave no
    holes in a random sample of a surface."""
    dist, _ = nearest_neighbours(points, k, method)
    return coverage * local_spacing(dist)


def pca_normals(points: np.ndarray, neighbours: np.ndarray) -> np.ndarray:
    """(N, 3) float64 unit normals: the direction of least spread of each point
    with its neighbours (``neighbours`` (N, k) indices), i.e. the normal of the
    plane that fits them best by least squares.

    The sign of a fitted normal is arbitrary; each is turned to point away from
    the cloud's centroid (outwards on a closed, star-shaped surface). The
    renderer lights both sides alike, so the sign does not change an image.
    """
    p = np.asarray(points, dtype=np.float64)
    group = np.concatenate([np.arange(len(p))[:, None], np.asarray(neighbours, np.int64)], axis=1)
    q = p[group]  # (N, k + 1, 3)
    q = q - q.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", q, q)
    _, vec = np.linalg.eigh(cov)  # eigenvalues ascending
    normal = vec[:, :, 0]
    outward = np.einsum("ij,ij->i", normal, p - p.mean(axis=0))
    return normal * np.where(outward < 0, -1.0, 1.0)[:, None]
