"""Where a thin solid's face lies inside its voxel: a strip per entry
(docs/coverage.md, "Thin beams inside voxels: strips").

A beam under a voxel wide (the corpus lattice's, 0.8 voxel at 128^3) puts
each face into its voxels as a partial sheet: its facets fill a band of
their plane's section, between the two edges where the face meets its
neighbours. The sheet law spreads that fill over the whole section (a beam
drawn across one or two voxels at partial alpha), and the half-planes
(:mod:`~aniso3d.rendering.sheet_halfplanes`) read one line only. Here such
an entry is read, where it can be, as a **strip**: the part of its plane's
section between two parallel lines, of the entry's area, whose centroid is
the facets' (:func:`sheet_strips`). The lines run along the beam's axis,
taken from the voxel's closed normals: the cross product of the entry's
normal with that of another closed entry of the voxel nearly at right
angles to it (a neighbouring face of the same beam). Of the candidates the
one whose strip's centroid comes nearest the facets' is kept; the strip's
two offsets are found by Newton steps on its area and first moment across
the lines (their derivatives are the chords' lengths).

The half-planes of closed entries are taken as strips of one line (the far
one at infinity): on a closed surface the footprint's share past the line
is the neighbouring face's, and they are drawn at the strips' scales.

The renderer counts a strip as the share of the pixel's footprint between
its lines where the ray crosses its plane (:func:`strip_cover`: the
difference of two half-planes' ramps), in the voxel's own sheet sum, as it
does a half-plane's, where the voxel spans :data:`STRIP_PIXELS` or more.
Lines are kept as the half-planes' are: the inward normal u's angle in the
sheet's tangent frame and the near line's offset in entry word 11 (bit
:data:`STRIP_BIT` set), the far line's offset in word 12 as float32 (which
only surface sheets, never strips, use otherwise).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aniso3d.rendering.sheet_halfplanes import (
    HALF_COHERENCE,
    HALF_FILL,
    SheetHalfplanes,
    angle_code,
    clipped_piece,
    decoded_offset,
    halfplane_ramp,
    offset_code,
    plane_origin,
    section_polygons,
)

#: Two closed entries of a voxel are faces of one beam (their normals' cross
#: product its axis) when their unit normals' dot product is at most this.
STRIP_PERPENDICULAR = 0.3
#: An entry is a strip when the fitted strip's centroid lies within this of
#: the facets' (voxel units, in the plane) and its area within
#: STRIP_AREA_ERROR of theirs (h^2). A strip placed that near localises the
#: entry's coverage better than its fill spread over the whole section: a
#: round tube's entries each span an arc of it (a chair's legs: 0.16 off),
#: which 0.03 left out. 0.03, 0.1, 0.2, 0.3 and 0.5 were measured on ten
#: scenes and meshes (docs/coverage.md, "Strips placed near enough").
STRIP_TOLERANCE = 0.2
STRIP_AREA_ERROR = 0.01
#: Strips are drawn where their voxel spans at least this many pixels.
#: The footprint reaching past the voxel is carried on by the strips' line
#: halos (render/sheet_line_halos.py); without them, drawn from a pixel on,
#: the corpus lattice minified kept 0.93 of its alpha and its FLIP rose
#: 0.0685 to 0.0763, so they were drawn from 1.5 pixels. With them, from
#: 0.75 (docs/coverage.md, "Halos of lines inside voxels"); smaller, the
#: partial sheets' clouds filter better. (Open surfaces' half-planes:
#: HALF_PIXELS.)
STRIP_PIXELS = 0.75
#: Their ramps run over this share of the pixel's footprint (a box of the
#: pixel's width; 0.75 gained the lattice 0.1 dB and 0.003-0.004 of FLIP at
#: 3.3 and 1.6 pixels a voxel, before the line halos). With the line halos,
#: 0.85 (docs/coverage.md, "Halos of lines inside voxels": 0.8 to 0.9 were
#: tried on the lattice, the mixed scene and three CAD meshes).
STRIP_FOOT = 0.85
#: Newton steps for the two offsets.
_STEPS = 8
#: Largest move of an offset in one step (voxel units).
_MAX_STEP = 0.25
#: Candidate pairs fitted per chunk (memory bound).
_CHUNK = 200_000
#: Bit of entry word 11 that marks a half-plane as a strip (the first
#: edge's kind bit, unused where the entry has no edges on faces).
STRIP_BIT = 3


@dataclass(frozen=True)
class SheetStrips:
    """The strips of a texture's partial sheets (see the module docstring).
    All (E,).

    Attributes:
        mask: bool, the entry is a strip.
        angle: float64, theta (radians) of the lines' normal u in the
            sheet's tangent frame, as the GPU reads it back (8 bits).
        lo, hi: float64, the lines' offsets c (voxel units, lo < hi): the
            strip is ``lo <= (p - q0) . u <= hi``, as the GPU reads them
            back (lo in 12 bits, hi as float32).
        residual: float64, the in-plane distance between the facets'
            centroid and the fitted strip's (voxel units; inf where not
            fitted).
    """

    mask: np.ndarray
    angle: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    residual: np.ndarray


def fit_strips(normal, offset, area, centroid, axis) -> tuple[np.ndarray, ...]:
    """Fit the strips of area ``area`` (N,) along ``axis`` (N, 3; any vector
    off the normal, projected onto the plane) whose centroids come nearest
    the voxel-local points ``centroid`` (N, 3) in the sections of the unit
    cube by the planes ``normal . x = offset`` (N, 3 unit; N,). Returns (N,)
    theta (the angle of u = n x t in the tangent frame, t the axis in the
    plane), the offsets lo and hi, the residual distance between the
    centroids and the area error (h^2).

    Newton steps on the two offsets with the strip's area ``a`` and first
    moment ``m`` across the lines: ``da/dlo = -L_lo``, ``da/dhi = L_hi``,
    ``dm/dlo = -lo L_lo``, ``dm/dhi = hi L_hi`` (L the chords' lengths), each
    move clamped to :data:`_MAX_STEP` and the offsets to the section; a line
    whose chord is empty (past the section) stays, the other one keeping
    the area."""
    uv, _, frame = section_polygons(normal, offset)
    x, y = uv[..., 0], uv[..., 1]
    n = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(offset, dtype=np.float64).reshape(-1)
    N = len(n)
    t = np.asarray(axis, dtype=np.float64).reshape(-1, 3)
    t = t - np.einsum("nk,nk->n", t, n)[:, None] * n
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)
    u3 = np.cross(n, t)
    theta = np.arctan2(np.einsum("nk,nk->n", u3, frame[:, 1]), np.einsum("nk,nk->n", u3, frame[:, 0]))
    u = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    rel = np.asarray(centroid, np.float64).reshape(-1, 3) - plane_origin(n, d)
    target = np.stack([np.einsum("nk,nk->n", rel, frame[:, 0]), np.einsum("nk,nk->n", rel, frame[:, 1])], 1)
    g = np.einsum("nk,nk->n", target, u)
    s = x * u[:, 0:1] + y * u[:, 1:2]
    smin, smax = s.min(axis=1), s.max(axis=1)
    section, _, _ = clipped_piece(x, y, u, np.full(N, -1e9))
    want = np.minimum(np.asarray(area, np.float64).reshape(-1), section)
    g = np.clip(g, smin, smax)
    _, _, chord = clipped_piece(x, y, u, g)
    width = want / np.maximum(chord, 1e-3)
    lo = np.clip(g - 0.5 * width, smin, smax)
    hi = np.clip(g + 0.5 * width, lo, smax)

    def strip(lo, hi):
        a1, c1, l1 = clipped_piece(x, y, u, lo)
        a2, c2, l2 = clipped_piece(x, y, u, hi)
        return a1 - a2, a1[:, None] * c1 - a2[:, None] * c2, l1, l2

    for _ in range(_STEPS):
        a, moment, l1, l2 = strip(lo, hi)
        r1 = want - a
        r2 = want * g - np.einsum("nk,nk->n", moment, u)
        gap = np.maximum(hi - lo, 1e-9)
        both = (l1 > 1e-6) & (l2 > 1e-6)
        with np.errstate(divide="ignore", invalid="ignore"):
            d_lo = np.where(both, (r2 - hi * r1) / (gap * l1), np.where(l1 > 1e-6, -r1 / l1, 0.0))
            d_hi = np.where(both, (r2 - lo * r1) / (gap * l2), np.where(l2 > 1e-6, r1 / l2, 0.0))
        # A line past the section (empty chord): the other keeps the area.
        d_lo = np.where((l1 <= 1e-6) & (l2 <= 1e-6) & (r1 > 0), -_MAX_STEP, d_lo)
        d_lo = np.clip(np.nan_to_num(d_lo), -_MAX_STEP, _MAX_STEP)
        d_hi = np.clip(np.nan_to_num(d_hi), -_MAX_STEP, _MAX_STEP)
        lo = np.clip(lo + d_lo, smin - 1e-6, smax)
        hi = np.clip(hi + d_hi, lo, smax + 1e-6)
    a, moment, _, _ = strip(lo, hi)
    ok = a > 1e-9
    cent = np.where(ok[:, None], moment / np.where(ok, a, 1.0)[:, None], np.inf)
    residual = np.where(ok, np.hypot(cent[:, 0] - target[:, 0], cent[:, 1] - target[:, 1]), np.inf)
    return theta, lo, hi, residual, np.abs(a - want)


def _partners(texture, candidate: np.ndarray, closed: np.ndarray, normal: np.ndarray):
    """(P,) pairs (i, j) of entries of one voxel: i a candidate, j closed and
    nearly at right angles to it (:data:`STRIP_PERPENDICULAR`)."""
    offsets = np.asarray(texture.entry_offsets, dtype=np.int64)
    owner = np.asarray(texture.entry_voxel, dtype=np.int64)
    rows = np.flatnonzero(candidate)
    counts = offsets[owner[rows] + 1] - offsets[owner[rows]]
    i = np.repeat(rows, counts)
    j = np.repeat(offsets[owner[rows]] - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts)
    j = j + np.arange(int(counts.sum()))
    keep = (i != j) & closed[j] & (np.abs(np.einsum("ek,ek->e", normal[i], normal[j])) <= STRIP_PERPENDICULAR)
    return i[keep], j[keep]


def sheet_strips(texture, sheets, surface: np.ndarray, halfplanes: SheetHalfplanes, sigma: np.ndarray) -> SheetStrips:
    """The strips of ``texture``'s entries (its
    :class:`~aniso3d.rendering.volume.EntrySheets` ``sheets``; ``surface``
    (E,) its surface sheets; ``halfplanes`` its :class:`SheetHalfplanes`;
    ``sigma`` (E,) its :func:`~aniso3d.rendering.volume.closed_sign`): the
    half-planes of closed entries (``sigma`` non-zero), with no far line
    (``hi`` infinite), and the closed entries that are no surface sheet nor
    half-plane, fill :data:`HALF_FILL` of their section, are coherent
    (:data:`HALF_COHERENCE`), and whose facets' centroid a strip of their
    area along the axis given by a closed partner of their voxel matches
    within :data:`STRIP_TOLERANCE`. Vectorised over (entry, partner) pairs,
    in chunks."""
    E = texture.n_entries
    mask = np.zeros(E, dtype=bool)
    angle, lo, hi, residual = np.zeros(E), np.zeros(E), np.zeros(E), np.full(E, np.inf)
    closed = np.asarray(sigma, dtype=np.float64) != 0.0
    taken = halfplanes.mask
    coherence = np.linalg.norm(np.asarray(texture.entry_normal, np.float64), axis=1)
    own = np.where(sheets.section > 1e-9, sheets.area / np.maximum(sheets.section, 1e-12), 0.0)
    candidate = (
        closed & ~np.asarray(surface, dtype=bool) & ~np.asarray(taken, dtype=bool)
        & (own >= HALF_FILL[0]) & (own < HALF_FILL[1]) & (coherence >= HALF_COHERENCE) & (sheets.section > 1e-9)
    )  # fmt: skip
    i, j = _partners(texture, candidate, closed, sheets.normal)
    if len(i) == 0:
        return _with_halfplanes(SheetStrips(mask, angle, lo, hi, residual), halfplanes, closed)
    fits = []
    for start in range(0, len(i), _CHUNK):
        a, b = i[start : start + _CHUNK], j[start : start + _CHUNK]
        local = texture.local_centroids(a)
        axis = np.cross(sheets.normal[a], sheets.normal[b])
        th, c0, c1, res, err = fit_strips(sheets.normal[a], sheets.offset[a], sheets.area[a], local, axis)
        fits.append((th, c0, c1, np.where(err <= STRIP_AREA_ERROR, res, np.inf)))
    th, c0, c1, res = (np.concatenate(f) for f in zip(*fits, strict=True))
    # Per entry, its best partner's strip.
    order = np.lexsort((res, i))
    first = np.r_[True, i[order][1:] != i[order][:-1]]
    best = order[first]
    r = i[best]
    angle[r], lo[r], hi[r], residual[r] = th[best], c0[best], c1[best], res[best]
    mask[r] = res[best] <= STRIP_TOLERANCE
    angle = np.where(mask, angle_code(angle) * (2 * np.pi / 256) - np.pi, 0.0)
    lo = np.where(mask, decoded_offset(offset_code(lo)), 0.0)
    hi = np.where(mask, hi.astype(np.float32).astype(np.float64), 0.0)
    return _with_halfplanes(SheetStrips(mask, angle, lo, hi, residual), halfplanes, closed)


def _with_halfplanes(st: SheetStrips, halfplanes: SheetHalfplanes, closed: np.ndarray) -> SheetStrips:
    """``st`` with the half-planes of closed entries as strips of one line."""
    one = halfplanes.mask & closed
    return SheetStrips(st.mask | one, np.where(one, halfplanes.angle, st.angle),
                       np.where(one, halfplanes.offset, st.lo), np.where(one, np.inf, st.hi),
                       np.where(one, halfplanes.residual, st.residual))  # fmt: skip


def strip_words(st: SheetStrips) -> tuple[np.ndarray, np.ndarray]:
    """(E,) uint32 to OR into entry word 11 (as a half-plane's:
    :func:`~aniso3d.rendering.sheet_halfplanes.halfplane_words`, the near
    line, with bit :data:`STRIP_BIT` set) and (E,) uint32 for word 12 (the
    far line's offset as float32 bits); 0 where no strip."""
    words = (angle_code(st.angle).astype(np.uint32) << 11) | (
        offset_code(st.lo).astype(np.uint32) << 19) | np.uint32(1 << 31) | np.uint32(1 << STRIP_BIT)  # fmt: skip
    far = st.hi.astype(np.float32).view(np.uint32)
    return np.where(st.mask, words, np.uint32(0)).astype(np.uint32), np.where(st.mask, far, np.uint32(0))


def strip_cover(angle, lo, hi, plane, point, normal, w, foot) -> np.ndarray:
    """(N,) share in [0, 1] of a pixel's footprint (width ``foot``) between
    the strips' lines (``angle``, ``lo``, ``hi`` (N,)) where the ray (unit
    ``w``) crosses their planes (unit ``normal`` (N, 3), ``normal . x =
    plane``) at the voxel-local ``point`` (N, 3): the ramp of the near line
    less that of the far one (``hi`` infinite: none, a half-plane), each
    :func:`~aniso3d.rendering.sheet_halfplanes.halfplane_ramp` (a box
    footprint across the projected lines). Mirrors strip_cover() in
    volume.frag."""
    near = halfplane_ramp(angle, lo, plane, point, normal, w, foot)
    hi = np.asarray(hi, dtype=np.float64).reshape(-1)
    far = halfplane_ramp(angle, np.where(np.isinf(hi), 0.0, hi), plane, point, normal, w, foot)
    return np.clip(near - np.where(np.isinf(hi), 0.0, far), 0.0, 1.0)
