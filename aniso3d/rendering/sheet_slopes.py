"""How a surface sheet's normal and colour change across its plane, from
its neighbours (docs/coverage.md, "Shading across voxels").

A voxel's entries keep the mean normal and reflectance of their facets: one
value per voxel. Where a voxel spans about a pixel, a pixel takes the value
of the voxel its centre ray crosses, and a smooth surface's shading comes out
in steps that beat against the pixel grid (rings of moiré on the corpus blob
minified). So at upload each surface sheet gets a linear model of its
normal and reflectance across its plane (:func:`sheet_slopes`), fitted by
least squares to the sheets that continue it in the neighbouring voxels
(within :data:`SLOPE_PARALLEL` of its normal, their planes through its
centroid's neighbourhood), and the renderer shades the crossing point with
the model's values: a first-order interpolation between voxels, so the
shading varies smoothly where the surface does. A crease sharper than
:data:`SLOPE_PARALLEL` stops the fit (no neighbour across it), so folds stay
sharp.

The model is written in the tangent frame (t1, t2) of the sheet's unit
normal n (:func:`aniso3d.grid.tangent_frame`, the rule volume.frag repeats),
relative to the point q0 of its plane nearest the voxel's centre, at which
the entry's own values are taken to hold (its facets' centroid lies near
it for a sheet that fills its voxel): for the crossing point p, with
``(u, v) = ((p - q0) . t1, (p - q0) . t2)``,

- the normal ``n + (S11 u + S12 v) t1 + (S12 u + S22 v) t2`` (S the
  symmetric shape operator, voxel units),
- the reflectance ``kd + u dkd/du + v dkd/dv``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aniso3d.grid import cell_keys, entries_at, tangent_frame

#: Neighbouring sheets within this of the sheet's normal (|n . n'|, about 25
#: degrees) take part in its fit: a bent surface's, not a fold's other side.
SLOPE_PARALLEL = 0.9
#: ... and whose plane passes within this (voxel units) of the sheet's
#: centroid moved into their voxel.
SLOPE_NEAR = 0.5
#: Largest slope kept (per voxel; the normal's is a curvature of radius one
#: voxel): a fit from badly placed neighbours is not extrapolated wildly.
SLOPE_MAX = 1.0


@dataclass(frozen=True)
class SheetSlopes:
    """Linear models across their planes of a texture's surface sheets (see
    the module docstring); zero for other entries.

    Attributes:
        shape: (E, 3) float64 ``(S11, S12, S22)``, the normal's shape
            operator in the sheet's tangent frame, per voxel.
        kd: (E, 2, 3) float64, ``dkd/du`` and ``dkd/dv``, per voxel.
    """

    shape: np.ndarray
    kd: np.ndarray


def sheet_slopes(texture, sheets, surface: np.ndarray) -> SheetSlopes:
    """Fit the linear models of the surface sheets ``surface`` ((E,) bool) of
    ``texture`` (its :class:`~aniso3d.rendering.volume.EntrySheets`
    ``sheets``) to their neighbours in the voxels beside theirs across the
    two axes most along their plane (3 cells along the third axis, for a
    tilted plane), vectorised over (sheet, neighbour entry) pairs."""
    E = texture.n_entries
    shape_op = np.zeros((E, 3))
    kd_slope = np.zeros((E, 2, 3))
    rows = np.flatnonzero(np.asarray(surface, dtype=bool) & (sheets.section > 1e-9))
    if len(rows) == 0:
        return SheetSlopes(shape_op, kd_slope)
    nh, d = sheets.normal, sheets.offset
    grid = np.asarray(texture.shape, dtype=np.int64)
    coords = np.asarray(texture.coords, dtype=np.int64)
    keys = cell_keys(coords, grid)
    offsets = np.asarray(texture.entry_offsets, dtype=np.int64)
    owner = np.asarray(texture.entry_voxel, dtype=np.int64)
    local = texture.local_centroids()
    normal = np.asarray(texture.entry_normal, dtype=np.float64)
    kd = np.asarray(texture.entry_kd, dtype=np.float64)
    n = nh[rows]
    axis = np.argmax(np.abs(n), axis=1)
    # Neighbour pairs: (sheet, entry, offset to its voxel) over the 4 in-plane
    # directions and 3 cells along the plane's axis.
    found_q, found_o, found_delta, found_dist, found_dir = [], [], [], [], []
    idx = np.arange(len(rows))
    for direction, (across, sign) in enumerate([(1, -1), (1, 1), (2, -1), (2, 1)]):
        for k in (-1, 0, 1):
            delta = np.zeros((len(rows), 3), dtype=np.int64)
            delta[idx, (axis + across) % 3] = sign
            delta[idx, axis] = k
            which, other = entries_at(keys, grid, offsets, coords[owner[rows]] + delta)
            if len(which) == 0:
                continue
            c_moved = local[rows[which]] - delta[which]
            dist = np.abs(np.einsum("ek,ek->e", nh[other], c_moved) - d[other])
            ok = (np.abs(np.einsum("ek,ek->e", nh[other], n[which])) >= SLOPE_PARALLEL) & (dist <= SLOPE_NEAR)
            ok &= np.linalg.norm(nh[other], axis=1) > 0.5
            found_q.append(which[ok])
            found_o.append(other[ok])
            found_delta.append(delta[which[ok]])
            found_dist.append(dist[ok])
            found_dir.append(np.full(int(ok.sum()), direction))
    if not found_q:
        return SheetSlopes(shape_op, kd_slope)
    q = np.concatenate(found_q)
    other = np.concatenate(found_o)
    delta = np.concatenate(found_delta)
    # One neighbour per direction: the plane nearest the centroid.
    dist = np.concatenate(found_dist)
    direction = np.concatenate(found_dir)
    order = np.lexsort((dist, direction, q))
    keep = order[np.r_[True, (q[order][1:] != q[order][:-1]) | (direction[order][1:] != direction[order][:-1])]]
    q, other, delta, direction = q[keep], other[keep], delta[keep], direction[keep]
    t1, t2 = tangent_frame(n)
    dx = local[other] + delta - local[rows[q]]
    R = len(rows)
    # Per sheet and direction (-b, +b, -c, +c): whether a neighbour was found,
    # its in-plane offset (u, v) and the differences of the values fitted:
    # the normal's t1 and t2 parts, then kd.
    found = np.zeros((R, 4), dtype=bool)
    offset_uv = np.zeros((R, 4, 2))
    diff = np.zeros((R, 4, 5))
    found[q, direction] = True
    offset_uv[q, direction] = np.stack([np.einsum("ek,ek->e", dx, t1[q]), np.einsum("ek,ek->e", dx, t2[q])], 1)
    # Neighbour normals turned to the sheet's side (a surface wound either way).
    n2 = normal[other] * np.sign(np.einsum("ek,ek->e", normal[other], n[q]))[:, None]
    dn = n2 / np.maximum(np.linalg.norm(n2, axis=1, keepdims=True), 1e-12) - n[q]
    diff[q, direction, 0] = np.einsum("ek,ek->e", dn, t1[q])
    diff[q, direction, 1] = np.einsum("ek,ek->e", dn, t2[q])
    diff[q, direction, 2:] = kd[other] - kd[rows[q]]
    axis_dir, axis_slope, axis_ok = [], [], []
    for lo, hi in ((0, 1), (2, 3)):
        # Along each axis a slope from each side, limited (minmod): the
        # smaller where both agree in sign, else 0, so that a step (a
        # tile's edge, a fold's other side) is not smeared over its voxels.
        fl, fh = found[:, lo], found[:, hi]
        span = offset_uv[:, hi] * fh[:, None] - offset_uv[:, lo] * fl[:, None]
        length = np.linalg.norm(span, axis=1)
        ok = (fl | fh) & (length > 1e-6)
        e = span / np.where(ok, length, 1.0)[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            lh = np.einsum("ek,ek->e", offset_uv[:, hi], e)
            ll = -np.einsum("ek,ek->e", offset_uv[:, lo], e)
            sh = np.where((fh & (lh > 1e-6))[:, None], diff[:, hi] / lh[:, None], np.nan)
            sl = np.where((fl & (ll > 1e-6))[:, None], -diff[:, lo] / ll[:, None], np.nan)
        both = ~np.isnan(sh) & ~np.isnan(sl)
        limited = np.where(np.sign(sh) == np.sign(sl), np.sign(sh) * np.minimum(np.abs(sh), np.abs(sl)), 0.0)
        slope = np.where(both, limited, np.where(np.isnan(sh), np.where(np.isnan(sl), 0.0, sl), sh))
        axis_dir.append(e)
        axis_slope.append(np.where(ok[:, None], slope, 0.0))
        axis_ok.append(ok)
    # The gradient (u, v) whose derivatives along the two axes' directions
    # are their slopes (along one axis only where the other has none).
    eb, ec = axis_dir
    det = eb[:, 0] * ec[:, 1] - eb[:, 1] * ec[:, 0]
    two = axis_ok[0] & axis_ok[1] & (np.abs(det) > 0.2)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.stack([ec[:, 1], -eb[:, 1], -ec[:, 0], eb[:, 0]], axis=1) / np.where(two, det, 1.0)[:, None]
    sb, sc = axis_slope
    gu = inv[:, 0, None] * sb + inv[:, 1, None] * sc
    gv = inv[:, 2, None] * sb + inv[:, 3, None] * sc
    one_u = np.where(axis_ok[0][:, None], eb[:, 0, None] * sb, ec[:, 0, None] * sc)
    one_v = np.where(axis_ok[0][:, None], eb[:, 1, None] * sb, ec[:, 1, None] * sc)
    grad = np.stack([np.where(two[:, None], gu, one_u), np.where(two[:, None], gv, one_v)], axis=1)  # (R, 2, 5)
    g1, g2 = grad[:, :, 0], grad[:, :, 1]  # d(n . t1)/d(u, v), d(n . t2)/d(u, v)
    s = np.stack([g1[:, 0], 0.5 * (g1[:, 1] + g2[:, 0]), g2[:, 1]], axis=1)
    shape_op[rows] = np.clip(s, -SLOPE_MAX, SLOPE_MAX)
    kd_slope[rows] = np.clip(grad[:, :, 2:], -SLOPE_MAX, SLOPE_MAX)
    return SheetSlopes(shape_op, kd_slope)


def smoothed(normal: np.ndarray, kd: np.ndarray, slopes_shape: np.ndarray, slopes_kd: np.ndarray,
             unit: np.ndarray, offset: np.ndarray, point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The normals (N, 3; with the stored ones' lengths, the coherence) and
    reflectances (N, 3, never negative) of sheets (stored ``normal``, ``kd``,
    their unit normals ``unit`` and plane offsets ``offset``) at the
    voxel-local points ``point`` (N, 3) of their planes (u and v clamped to
    a voxel), by their linear models (``slopes_shape`` (N, 3), ``slopes_kd``
    (N, 2, 3)). Mirrors smooth_sheet() in volume.frag."""
    t1, t2 = tangent_frame(unit)
    centre = np.full(3, 0.5)
    q0 = centre - ((unit @ centre) - offset)[:, None] * unit
    rel = np.asarray(point, np.float64) - q0
    # Within a voxel of q0 (a near miss crosses the plane far off).
    u = np.clip(np.einsum("ek,ek->e", rel, t1), -1.0, 1.0)
    v = np.clip(np.einsum("ek,ek->e", rel, t2), -1.0, 1.0)
    s11, s12, s22 = slopes_shape.T
    n = unit + (s11 * u + s12 * v)[:, None] * t1 + (s12 * u + s22 * v)[:, None] * t2
    n *= (np.linalg.norm(normal, axis=1) / np.linalg.norm(n, axis=1))[:, None]
    k = kd + u[:, None] * slopes_kd[:, 0] + v[:, None] * slopes_kd[:, 1]
    return n, np.maximum(k, 0.0)
