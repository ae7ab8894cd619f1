"""Grid and array arithmetic shared by building and rendering.

Small, exact helpers that several stages need in the same form, written once
so that they cannot drift apart:

- :func:`cell_keys` / :func:`cell_coords`: integer voxel cells (i, j, k) of a
  grid of ``shape`` as one int64 key each, ordered like the cells
  themselves (x slowest, z fastest), and back;
- :func:`ranges`: the concatenation of many ``arange`` runs, vectorised;
- :func:`tangent_frame`: the tangent axes of a normal, the convention the
  splat shader mirrors;
- :func:`weighted_means`: per-group weighted means, how registration and the
  pyramid turn area-weighted sums into materials, centroids and normals.
"""

from __future__ import annotations

import numpy as np


def cell_keys(coords: np.ndarray, shape) -> np.ndarray:
    """(M,) int64 key ``(i * shape[1] + j) * shape[2] + k`` of each integer
    cell of ``coords`` (M, 3) in a grid of ``shape`` (3,) cells.

    Keys sort like the cells in lexicographic (i, j, k) order, so sorted
    coords have sorted keys. Cells must lie inside the grid (0 <= i < shape[0]
    and so on) for keys to be distinct; this is not checked.
    """
    c = np.asarray(coords, dtype=np.int64).reshape(-1, 3)
    sy, sz = int(shape[1]), int(shape[2])
    return (c[:, 0] * sy + c[:, 1]) * sz + c[:, 2]


def cell_coords(keys: np.ndarray, shape) -> np.ndarray:
    """(M, 3) int64 cells of ``keys`` (M,) made by :func:`cell_keys` with the
    same ``shape``: its inverse."""
    k = np.asarray(keys, dtype=np.int64).reshape(-1)
    sy, sz = int(shape[1]), int(shape[2])
    return np.stack([k // (sy * sz), (k // sz) % sy, k % sz], axis=1)


def ranges(starts: np.ndarray, stops: np.ndarray) -> np.ndarray:
    """Concatenation of ``arange(starts[i], stops[i])`` over i, int64,
    vectorised (stops[i] >= starts[i]; empty runs allowed)."""
    starts = np.asarray(starts, dtype=np.int64)
    counts = np.asarray(stops, dtype=np.int64) - starts
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64)
    first = np.cumsum(counts) - counts
    return np.repeat(starts - first, counts) + np.arange(total, dtype=np.int64)


def entries_at(
    keys: np.ndarray, shape, entry_offsets: np.ndarray, cells: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The entries of the occupied voxels at ``cells`` (N, 3; outside the
    grid or empty: none), of a sparse grid whose voxels, of sorted
    :func:`cell_keys` ``keys``, own the entries ``entry_offsets[v]`` to
    ``entry_offsets[v + 1]``: two int64 arrays, each entry's cell (an index
    into ``cells``) and the entry, cell by cell, in order."""
    keys = np.asarray(keys, dtype=np.int64)
    shape = np.asarray(shape, dtype=np.int64)
    cells = np.asarray(cells, dtype=np.int64).reshape(-1, 3)
    if len(keys) == 0 or len(cells) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    inside = np.all((cells >= 0) & (cells < shape), axis=1)
    key = cell_keys(np.where(inside[:, None], cells, 0), shape)
    pos = np.minimum(np.searchsorted(keys, key), len(keys) - 1)
    hit = np.flatnonzero(inside & (keys[pos] == key))
    offsets = np.asarray(entry_offsets, dtype=np.int64)
    lo, hi = offsets[pos[hit]], offsets[pos[hit] + 1]
    return np.repeat(hit, hi - lo), ranges(lo, hi)


def tangent_frame(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(t, b), each (N, 3) float64: unit tangent axes of unit ``normals`` (N, 3),
    ``t = normalize(n x h)`` with ``h`` = x unless ``|n_x| >= 0.9``, then y;
    ``b = n x t``, so (t, b, n) is right-handed and orthonormal.

    A fixed function of the normal: the splat shader (``shaders/splat.vert``)
    orients squares and ellipses by the same rule, and points spread over a
    patch (:func:`aniso3d.build.texture.entry_points`) use it too.
    """
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    helper = np.where((np.abs(n[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    t = np.cross(n, helper)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return t, np.cross(n, t)


def weighted_means(
    group: np.ndarray, weights: np.ndarray, values: np.ndarray, totals: np.ndarray
) -> np.ndarray:
    """Per-group weighted means of ``values``, float64.

    Args:
        group: (N,) int group index of each row, in ``0..G-1``.
        weights: (N,) float weight of each row (e.g. a facet area).
        values: (N,) or (N, C) values to average.
        totals: (G,) float sum of ``weights`` per group
            (``np.bincount(group, weights, minlength=G)``), computed once by
            the caller, who needs it too.

    Returns:
        (G,) or (G, C): ``sum(w v) / sum(w)`` per group; 0 for a group whose
        weights sum to 0 (never NaN).
    """
    w = np.asarray(weights, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    totals = np.asarray(totals, dtype=np.float64)
    safe = np.where(totals > 0, totals, 1.0)
    if v.ndim == 1:
        return np.bincount(group, weights=w * v, minlength=len(totals)) / safe
    return np.stack([weighted_means(group, w, v[:, i], totals) for i in range(v.shape[1])], axis=1)
