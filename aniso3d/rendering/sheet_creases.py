"""Crease sheets drawn small: a face's half-plane beside an edge inside its
voxel, in the volume renderer's runs (docs/coverage.md, "Creases inside
voxels").

A crease sheet (:data:`~aniso3d.rendering.volume.SHEET_CREASE`) whose
facets fit a half-plane is drawn as that half-plane where its voxel spans
``HALF_PIXELS`` or more. Smaller, it stays in the ray's runs, where it used
to count over its whole section, past the edge. There its half-plane's line
now cuts it as an edge on a voxel face cuts a surface sheet
(:func:`~aniso3d.rendering.sheet_edges.edge_factors`): where the crease is a
silhouette in this view (the two faces' half-planes on one side of the edge
on screen), the footprint's share on the sheet's side of the line, the two
faces' shares overlapping (the run keeps the larger); any other crease
(both faces seen) keeps its coverage whole and weights its colour by that
share. Which it is depends on the partner: the voxel's entry turned most
from the sheet, whose half-plane leaves the edge at the angle ``phi`` about
it (:func:`crease_partners`), stored in 8 bits beside the line.
"""

from __future__ import annotations

import numpy as np

from aniso3d.rendering.sheet_edges import quantised_angle
from aniso3d.rendering.sheet_halfplanes import SheetHalfplanes, angle_code, halfplane_ramp, line_inward, plane_origin

#: A crease sheet's half-plane is an edge's when its line lies on its
#: partner's plane: its direction tilted out of that plane by at most this
#: (|n' . t|, about 9 degrees) and its distance from it at most
#: :data:`CREASE_GAP` (voxel units). Else the sheet stays a surface sheet
#: (the tree's: leaves meeting at random, 3.5 % of its crease half-planes
#: pass; fandisk's 92 %, a building's 98 %).
CREASE_TILT = 0.15
CREASE_GAP = 0.1


def crease_partners(
    texture, sheets, halfplanes: SheetHalfplanes, rows: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Three (len(rows),) arrays: the angle phi (radians, as the GPU reads it back) of
    each crease half-plane's partner about its line: the voxel's entry whose
    normal turns most from the sheet's, its facets' centroid taken to the
    plane through the line normal to it, ``v = cos(phi) u + sin(phi) n``
    (u the sheet's inward direction, n its normal), as
    :func:`~aniso3d.rendering.sheet_edges.sheet_edges` measures a crease's
    partner on a voxel face; and how far the line lies off the partner's
    plane: its direction's tilt out of it (|n' . t|) and its distance from
    it (voxel units; both inf where the voxel holds no other entry).
    Vectorised over the (entry, other entry) pairs of the rows' voxels."""
    rows = np.asarray(rows, dtype=np.int64)
    phi = np.zeros(len(rows))
    tilt, gap = np.full(len(rows), np.inf), np.full(len(rows), np.inf)
    if len(rows) == 0:
        return phi, tilt, gap
    owner = np.asarray(texture.entry_voxel, dtype=np.int64)
    counts = np.bincount(owner, minlength=texture.n_voxels)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    # Every (row, entry of its voxel) pair.
    k = counts[owner[rows]]
    i = np.repeat(np.arange(len(rows)), k)
    j = starts[owner[rows]][i] + (np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k))
    keep = j != rows[i]
    i, j = i[keep], j[keep]
    turn = np.abs(np.einsum("ek,ek->e", sheets.normal[rows[i]], sheets.normal[j]))
    order = np.lexsort((turn, i))
    first = order[np.r_[True, i[order][1:] != i[order][:-1]]]
    i, j = i[first], j[first]
    r = rows[i]
    n = sheets.normal[r]
    u = line_inward(halfplanes.angle[r], n)
    # A point of the line: q0 + c u (the line is (p - q0) . u = c).
    on_line = plane_origin(n, sheets.offset[r]) + halfplanes.offset[r][:, None] * u
    t = np.cross(n, u)
    v = texture.local_centroids(j) - on_line
    v -= np.einsum("ek,ek->e", v, t)[:, None] * t
    phi[i] = np.arctan2(np.einsum("ek,ek->e", v, n), np.einsum("ek,ek->e", v, u))
    nj = sheets.normal[j]
    tilt[i] = np.abs(np.einsum("ek,ek->e", nj, t))
    gap[i] = np.abs(np.einsum("ek,ek->e", nj, on_line) - sheets.offset[j])
    return quantised_angle(phi), tilt, gap


def partner_codes(phi: np.ndarray) -> np.ndarray:
    """(N,) uint32: ``phi`` as 8-bit codes (the low bits of entry word 12)."""
    return angle_code(phi).astype(np.uint32)


def crease_factors(angle, offset, phi, plane, point, normal, w, foot) -> tuple[np.ndarray, np.ndarray]:
    """What a crease half-plane's line leaves of a run sheet's coverage and
    of its colour's weight, each (N,) in [0, 1], where the ray (unit ``w``)
    crosses its plane at the voxel-local ``point`` (N, 3): the footprint's
    share on its side of the line (:func:`halfplane_ramp`) for both where
    the crease is a silhouette, else the coverage whole and the colour by
    that share. Mirrors crease_factors() in volume.frag."""
    n = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
    w = np.asarray(w, dtype=np.float64)
    ramp = halfplane_ramp(angle, offset, plane, point, n, w, foot)
    u = line_inward(angle, n)
    nu = np.cross(w[None, :], np.cross(n, u))
    al, be = np.einsum("ek,ek->e", nu, u), np.einsum("ek,ek->e", nu, n)
    phi = np.asarray(phi, dtype=np.float64).reshape(-1)
    silhouette = al * (al * np.cos(phi) + be * np.sin(phi)) > 0.0
    return np.where(silhouette, ramp, 1.0), ramp
