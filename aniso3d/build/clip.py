"""Stage 2: exact clipping of triangles into the cells of a voxel grid.

Everything here works in *grid coordinates*: ``u = (x - origin) / h``, so cell
(i, j, k) is the unit cube [i, i+1) x [j, j+1) x [k, k+1), planes sit on
integers, and areas come out directly in units of h^2 (the S of METHOD.md).
Working relative to the grid origin keeps float64 exact enough for meshes far
from the world origin.

Cells are half-open: a facet lying exactly on the plane u = k belongs to cell
k (the one above), never to both and never to neither. The first and last
cell along each axis are unbounded outwards, so geometry on the grid's outer
faces (and rounding just beyond them) is kept.

Clipping is a vectorised Sutherland-Hodgman: polygons are held as padded
(n, V, 3) arrays with a vertex count each; one axis at a time, every polygon is
repeated once per slab it spans and clipped against the slab's two planes.
Polygons that fit in one slab (most facets of fine structure) skip the clip.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aniso3d.errors import InputError


@dataclass(frozen=True, eq=False)
class Grid:
    """A regular grid of cubic voxels.

    Attributes:
        origin: (3,) float64 world position of the grid's minimum corner.
        voxel_size: edge h of a voxel, world units.
        shape: (3,) int64 number of cells along x, y, z.
    """

    origin: np.ndarray
    voxel_size: float
    shape: np.ndarray

    def to_grid(self, points: np.ndarray) -> np.ndarray:
        return (np.asarray(points, dtype=np.float64) - self.origin) / self.voxel_size

    def cell_centers(self, coords: np.ndarray) -> np.ndarray:
        """(M, 3) world centres of integer cells ``coords``."""
        return self.origin + (np.asarray(coords, dtype=np.float64) + 0.5) * self.voxel_size


def make_grid(bounds: np.ndarray, resolution: int) -> Grid:
    """Grid over ``bounds`` with ``resolution`` cells along the longest axis."""
    if isinstance(resolution, bool) or int(resolution) != resolution or resolution < 1:
        raise InputError(f"resolution must be a whole number >= 1, got {resolution!r}")
    resolution = int(resolution)
    if resolution > 65536:
        raise InputError(f"resolution {resolution} is above the supported maximum of 65536")
    lo, hi = np.asarray(bounds, dtype=np.float64)
    extent = hi - lo
    longest = float(extent.max())
    if not np.isfinite(longest) or longest <= 0.0:
        raise InputError(
            "the mesh has zero extent (all vertices at one point): there is nothing to voxelise"
        )
    h = longest / resolution
    # The tiny shrink keeps e.g. 128 * (L / 128) from rounding up to 129 cells;
    # the unbounded last cell still holds geometry on the far face.
    shape = np.maximum(1, np.ceil(extent / h * (1.0 - 1e-12))).astype(np.int64)
    shape[int(np.argmax(extent))] = resolution
    return Grid(lo.copy(), h, shape)


@dataclass(frozen=True, eq=False)
class SubPolygons:
    """The pieces of triangles inside single voxels.

    Attributes:
        face: (S,) int64 index of the triangle each piece came from.
        cell: (S, 3) int64 integer cell of each piece.
        area: (S,) float64 area in units of h^2 (METHOD.md's S).
        centroid: (S, 3) float64 area centroid, grid coordinates.
    """

    face: np.ndarray
    cell: np.ndarray
    area: np.ndarray
    centroid: np.ndarray

    def __len__(self) -> int:
        return len(self.face)


def triangle_normals(tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (n, 3) and doubled areas (n,) of (n, 3, 3) triangles.

    Degenerate triangles get a zero normal and zero area.
    """
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(cross, axis=1)
    ok = (length > 0) & np.isfinite(length)
    normals = np.zeros_like(cross)
    normals[ok] = cross[ok] / length[ok, None]
    return normals, np.where(ok, length, 0.0)


def _clip_halfspace(
    poly: np.ndarray, count: np.ndarray, axis: int, plane: np.ndarray, keep_above: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Clip padded convex polygons against one axis-aligned plane per polygon.

    ``keep_above`` keeps u[axis] >= plane (closed); otherwise keeps
    u[axis] < plane (open), which makes cells half-open. Returns the new padded
    array (one more vertex slot) and counts.
    """
    n, V, _ = poly.shape
    slot = np.arange(V)
    valid = slot[None, :] < count[:, None]
    x = poly[:, :, axis]
    if keep_above:
        d = x - plane[:, None]
        inside = d >= 0.0
    else:
        d = plane[:, None] - x
        inside = d > 0.0
    nxt = (slot[None, :] + 1) % np.maximum(count, 1)[:, None]
    poly_n = np.take_along_axis(poly, nxt[:, :, None], axis=1)
    d_n = np.take_along_axis(d, nxt, axis=1)
    inside_n = np.take_along_axis(inside, nxt, axis=1)
    crosses = valid & (inside != inside_n)
    denom = np.where(crosses, d - d_n, 1.0)
    t = np.where(crosses, d / denom, 0.0)
    inter = poly + t[:, :, None] * (poly_n - poly)
    # Put the new vertex exactly on the plane: no drift into the next cell.
    inter[:, :, axis] = np.where(crosses, plane[:, None], inter[:, :, axis])
    cand = np.stack([poly, inter], axis=2).reshape(n, 2 * V, 3)
    keep = np.stack([inside & valid, crosses], axis=2).reshape(n, 2 * V)
    pos = np.cumsum(keep, axis=1) - 1
    out = np.zeros((n, V + 1, 3))
    rows, cols = np.nonzero(keep)
    out[rows, pos[rows, cols]] = cand[rows, cols]
    return out, keep.sum(axis=1)


def _plane(k: np.ndarray, base: np.ndarray) -> np.ndarray:
    """Grid plane k in coordinates local to ``base``. Every use goes through
    here so that slab decisions and cuts see bit-identical plane values."""
    return k.astype(np.float64) - base


def _split_axis(
    poly: np.ndarray,
    count: np.ndarray,
    face: np.ndarray,
    cell: np.ndarray,
    shift: np.ndarray,
    axis: int,
    n_cells: int,
):
    """Cut every polygon into the slabs [k, k+1) along ``axis`` it overlaps.

    Polygon coordinates are local: grid coordinates minus the polygon's
    ``shift`` (its triangle's first vertex), so plane k is at ``_plane(k,
    shift)``. Slabs are decided against exactly the plane values the cuts use.
    """
    V = poly.shape[1]
    valid = np.arange(V)[None, :] < count[:, None]
    x = poly[:, :, axis]
    base = shift[:, axis]
    xmin = np.where(valid, x, np.inf).min(axis=1)
    xmax = np.where(valid, x, -np.inf).max(axis=1)
    # k0: the slab holding xmin, P(k0) <= xmin < P(k0 + 1). The estimate from
    # absolute coordinates is off by at most one; fix it against P itself.
    k0 = np.floor(xmin + base).astype(np.int64)
    k0 -= xmin < _plane(k0, base)
    k0 += xmin >= _plane(k0 + 1, base)
    k0 = np.clip(k0, 0, n_cells - 1)
    # k1: the last plane strictly below xmax, P(k1) < xmax <= P(k1 + 1): a
    # polygon ending exactly on plane k does not enter slab k; max with k0:
    # one lying in plane k stays in slab k.
    k1 = np.ceil(xmax + base).astype(np.int64) - 1
    k1 -= xmax <= _plane(k1, base)
    k1 += xmax > _plane(k1 + 1, base)
    k1 = np.maximum(k0, np.clip(k1, 0, n_cells - 1))
    span = k1 - k0 + 1

    single = span == 1
    cell_single = cell[single].copy()
    cell_single[:, axis] = k0[single]
    pad = np.zeros((int(single.sum()), V + 2, 3))
    pad[:, :V] = poly[single]
    outs_poly = [pad]
    outs_count = [count[single]]
    outs_face = [face[single]]
    outs_cell = [cell_single]
    outs_shift = [shift[single]]

    multi = np.nonzero(~single)[0]
    if len(multi):
        reps = span[multi]
        src = np.repeat(multi, reps)
        first = np.repeat(np.cumsum(reps) - reps, reps)
        k = k0[src] + (np.arange(len(src)) - first)
        p, c = poly[src], count[src]
        b = base[src]
        # A piece in the polygon's first slab lies above its lower plane already,
        # and one in its last slab below its upper plane: clip only what can cut.
        # The outermost slabs are unbounded, so nothing on or beyond the grid's
        # faces is lost; inner ones are [k, k+1).
        p = np.concatenate([p, np.zeros((len(p), 2, 3))], axis=1)
        cut_low = (k > k0[src]) & (k > 0)
        cut_high = (k < k1[src]) & (k < n_cells - 1)
        for cut, plane, above in ((cut_low, k, True), (cut_high, k + 1, False)):
            idx = np.nonzero(cut)[0]
            if len(idx):
                # Each cut adds at most one vertex; p has room for two.
                p[idx], c[idx] = _clip_halfspace(
                    p[idx, :-1], c[idx], axis, _plane(plane[idx], b[idx]), above
                )
        ok = c >= 3
        new_cell = cell[src[ok]].copy()
        new_cell[:, axis] = k[ok]
        outs_poly.append(p[ok])
        outs_count.append(c[ok])
        outs_face.append(face[src[ok]])
        outs_cell.append(new_cell)
        outs_shift.append(shift[src[ok]])
    return (
        np.concatenate(outs_poly),
        np.concatenate(outs_count),
        np.concatenate(outs_face),
        np.concatenate(outs_cell),
        np.concatenate(outs_shift),
    )


def _polygon_area_centroid(poly: np.ndarray, count: np.ndarray, normal: np.ndarray):
    """Area (projected on the known unit normal) and centroid of padded polygons."""
    n, V, _ = poly.shape
    v0 = poly[:, :1]
    a = poly[:, 1:-1] - v0
    b = poly[:, 2:] - v0
    fan_ok = (np.arange(1, V - 1)[None, :] + 1) < count[:, None]
    tri_area = 0.5 * np.einsum("nfi,ni->nf", np.cross(a, b), normal)
    tri_area = np.where(fan_ok, tri_area, 0.0)
    area = tri_area.sum(axis=1)
    tri_centroid = (v0 + poly[:, 1:-1] + poly[:, 2:]) / 3.0
    weighted = np.einsum("nf,nfi->ni", tri_area, tri_centroid)
    safe = np.where(area > 0, area, 1.0)
    centroid = np.where((area > 0)[:, None], weighted / safe[:, None], poly[:, 0])
    return area, centroid


def clip_to_grid(
    tri_grid: np.ndarray,
    normals: np.ndarray,
    shape: np.ndarray,
    face_index: np.ndarray,
    first: np.ndarray | None = None,
) -> SubPolygons:
    """Clip triangles (n, 3, 3), given in grid coordinates, into grid cells.

    ``normals`` are the triangles' unit normals (zero for degenerate ones, which
    are dropped); ``face_index`` labels each triangle in the output.

    With ``first`` (n, 3), ``tri_grid`` instead holds each triangle relative to
    its first vertex (``(x - x0) / h``) and ``first`` that vertex's grid
    coordinates: tiny triangles far from the grid origin then keep their shape
    exactly, which converting every vertex to grid coordinates would not.
    """
    keep = np.any(normals != 0, axis=1)
    local = np.nonzero(keep)[0]
    # Clip each triangle in coordinates relative to its first vertex: cut
    # points then carry rounding errors relative to the triangle's size, not
    # to its position in the grid, so even triangles far smaller than a voxel
    # keep their area to ~1e-15 relative. (Pieces of a triangle always tile
    # it, whatever rounding does to a plane's local position; a vertex lying
    # exactly on a plane stays exactly on it, as both go through the same
    # subtraction.)
    if first is None:
        shift = tri_grid[local, 0].copy()
        poly = tri_grid[local] - shift[:, None, :]
    else:
        shift = np.asarray(first, dtype=np.float64)[local]
        poly = np.array(tri_grid[local], dtype=np.float64)
    count = np.full(len(poly), 3, dtype=np.int64)
    cell = np.zeros((len(poly), 3), dtype=np.int64)
    for axis in range(3):
        poly, count, local, cell, shift = _split_axis(
            poly, count, local, cell, shift, axis, int(shape[axis])
        )
    area, centroid = _polygon_area_centroid(poly, count, normals[local])
    centroid = centroid + shift
    ok = area > 0
    return SubPolygons(np.asarray(face_index)[local[ok]], cell[ok], area[ok], centroid[ok])
