"""Halos of the lines inside voxels: a strip's footprint carried into the
voxels beside it (docs/coverage.md, "Halos of lines inside voxels").

A strip (:mod:`~aniso3d.rendering.sheet_strips`: a thin closed beam's face
between two lines, or a closed surface's half-plane, a strip of one line)
counts, where the ray crosses its plane inside its voxel, the share of the
pixel's footprint between its lines. With a voxel about a pixel the
footprint reaches half a voxel past the voxel: a ray that crosses the plane
extended in the voxel beside it, within half a footprint of a line, should
count the part of the footprint on the covered side too, and nothing there
knew of the line. So strips were drawn only from 1.5 pixels a voxel, and
smaller they were spread over their sections (the lattice's beams, a CAD
part's faces meeting at an edge inside a voxel).

A **line halo** is a copy of such an entry, with no area, in the voxel
across one of its voxel's faces that its plane crosses, where no sheet of
that voxel continues the plane (within ``EDGE_NEAR`` of it and
``EDGE_PARALLEL`` of its normal at the face: there the surface goes on and
its own entry counts; but see :data:`SPLIT_REST`). It keeps the entry's
plane and lines, moved into its voxel's frame, and counts, where the ray crosses the plane there, the same
share of the footprint as the entry would (:func:`line_halos`). Where the
face's section lies past a line on the uncovered side (the line runs along
the face), that share is all; where the line crosses the face (the covered
part reaches it), it is also cut by the face, as a sheet's halo is past an
edge on a voxel face (:func:`~aniso3d.rendering.sheet_edges.edge_ramp`), so
that a line ending in its voxel does not run on through the next. The
function takes any lines; the renderer gives it the strips only (an open
surface's half-planes with halos over-covered the corpus shell's border:
:func:`~aniso3d.rendering.volume.sheet_line_halos`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aniso3d.grid import cell_keys, entries_at
from aniso3d.rendering.sheet_edges import EDGE_MIN_LENGTH, EDGE_NEAR, EDGE_PARALLEL, face_segments
from aniso3d.rendering.sheet_halfplanes import C_RANGE, decoded_offset, line_inward, offset_code, plane_origin
from aniso3d.rendering.sheet_strips import SheetStrips

#: Entry word 11's bit marking a line halo cut by its face (bits 0-2 and
#: 4-6 hold no face for lines, bit 7 no second edge's kind).
FACE_CUT_BIT = 7
#: Where the plane goes on across a face as another strip, a strip of two
#: lines has a halo all the same, carrying the part of its band that the
#: strip across does not cover, when that part is at least this wide (voxel
#: units, in the plane). A voxel face cutting a beam's face along its
#: length leaves each voxel a strip of its part (a line on the voxel
#: face), and the ray, crossing the plane in one of them, counted that
#: part's share of the footprint alone: a beam 0.8 voxel wide split so kept
#: 0.69 of its shadow at its centre. Where the beam goes on through the
#: face, the strips across share its lines and nothing is left. None: the
#: plane going on stops every halo, as before. A closed half-plane (one
#: line) keeps that rule (docs/coverage.md, "Halos of split beams").
SPLIT_REST: float | None = 0.05
#: ... where the strip across is the other part of the same face: its lines
#: parallel to the entry's (``|u . u'|`` at least this). A strip whose lines
#: cross the entry's (a perpendicular beam's face in the same plane, at a
#: node of the lattice) keeps the rule: no halo (trimming the band by its
#: extent across another axis was meaningless and counted 0.07 of the
#: footprint twice on average where it made halos).
SPLIT_PARALLEL = 0.98
#: Entries whose halos are made per chunk (memory bound: (entry, face)
#: pairs and the entries of the voxels across).
_CHUNK = 100_000


@dataclass(frozen=True)
class LineHalos:
    """The halos of a texture's lines. All (H,) but ``cell`` (H, 3).

    Attributes:
        row: the entry whose lines it carries.
        cell: its grid cell (may be -1 or ``shape`` along an axis: the
            margin, as :class:`~aniso3d.rendering.sheet_edges.SheetEdges`'
            halos).
        face: the face of the halo's voxel on the entry's voxel (``2 * axis
            + side``).
        offset: the plane ``n . x = offset`` in the halo's voxel.
        lo, hi: the lines' offsets in the halo's voxel's frame (as the GPU
            reads them back: lo in 12 bits, hi as float32; hi inf for a
            half-plane's single line).
        cut: bool, the share is also cut by the face (the line crosses it).
    """

    row: np.ndarray
    cell: np.ndarray
    face: np.ndarray
    offset: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    cut: np.ndarray

    @staticmethod
    def empty() -> LineHalos:
        z = np.zeros(0)
        return LineHalos(np.zeros(0, np.int64), np.zeros((0, 3), np.int64), np.zeros(0, np.int8), z, z, z,
                         np.zeros(0, bool))  # fmt: skip


def line_halos(
    texture, sheets, rows: np.ndarray, angle: np.ndarray, lo: np.ndarray, hi: np.ndarray,
    one_line_reach: float = np.inf, strips: SheetStrips | None = None, split_rest: float | None = None,
) -> LineHalos:  # fmt: skip
    """The :class:`LineHalos` of the entries ``rows`` of ``texture`` (its
    :class:`~aniso3d.rendering.volume.EntrySheets` ``sheets``), whose lines
    are at ``angle`` (R,) in their sheets' tangent frames with offsets
    ``lo`` and ``hi`` (R,; covered where ``lo <= (p - q0) . u <= hi``, hi inf
    for a half-plane). A half-plane's halo is left out where its line lies
    farther than ``one_line_reach`` (voxel units, in the plane) from the
    halo's q0. ``strips``: the texture's strips (all entries'); where one of
    them goes on with the plane, an entry of two lines has a halo of the
    part of its band that strip leaves, at least ``split_rest`` wide
    (:data:`SPLIT_REST`; None: never). Vectorised over (entry, face) pairs."""
    rows = np.asarray(rows, dtype=np.int64)
    if len(rows) == 0:
        return LineHalos.empty()
    if len(rows) > _CHUNK:
        parts = [line_halos(texture, sheets, rows[i : i + _CHUNK], angle[i : i + _CHUNK], lo[i : i + _CHUNK],
                            hi[i : i + _CHUNK], one_line_reach, strips, split_rest)
                 for i in range(0, len(rows), _CHUNK)]  # fmt: skip
        return LineHalos(*(np.concatenate([getattr(p, f) for p in parts]) for f in LineHalos.__dataclass_fields__))
    n, d = sheets.normal[rows], sheets.offset[rows]
    length, mid = face_segments(n, d)
    r_idx, f_idx = np.nonzero(length >= EDGE_MIN_LENGTH)
    if len(r_idx) == 0:
        return LineHalos.empty()
    f_idx = f_idx.astype(np.int64)
    nr, dr = n[r_idx], d[r_idx]
    a, side = f_idx // 2, f_idx % 2
    step = np.zeros((len(r_idx), 3), dtype=np.int64)
    step[np.arange(len(r_idx)), a] = 2 * side - 1
    coords = np.asarray(texture.coords, dtype=np.int64)
    owner = np.asarray(texture.entry_voxel, dtype=np.int64)
    cell = coords[owner[rows[r_idx]]] + step
    # Continued: a sheet of the voxel across within EDGE_NEAR of the face
    # segment's midpoint and EDGE_PARALLEL of the normal.
    which, other = entries_at(cell_keys(coords, texture.shape), texture.shape, texture.entry_offsets, cell)
    no = sheets.normal[other]
    local = mid[r_idx[which], f_idx[which]] - step[which]
    near = np.abs(np.einsum("ek,ek->e", no, local) - sheets.offset[other]) <= EDGE_NEAR
    parallel = np.abs(np.einsum("ek,ek->e", no, nr[which])) >= EDGE_PARALLEL
    goes_on = near & parallel & (np.linalg.norm(no, axis=1) > 0.5)
    u = line_inward(angle[r_idx], nr)
    lo_s, hi_s = lo[r_idx].astype(np.float64), hi[r_idx].astype(np.float64)
    if strips is not None and split_rest is not None:
        # Continued by a strip: the entry of two lines keeps the part of its
        # band that the strip across (the one covering most of it) leaves.
        j = np.flatnonzero(goes_on & strips.mask[other] & np.isfinite(hi_s[which]))
        u2 = line_inward(strips.angle[other[j]], sheets.normal[other[j]])
        along = np.abs(np.einsum("ek,ek->e", u2, u[which[j]])) >= SPLIT_PARALLEL
        j, u2 = j[along], u2[along]
        goes_on[j] = False
        lo_s, hi_s = _split_rest(sheets, strips, nr, dr, u, step, lo_s, hi_s, which[j], other[j], u2, split_rest)
    continued = np.zeros(len(r_idx), dtype=bool)
    np.logical_or.at(continued, which, goes_on)
    # The lines in the halo's frame: q0 moves to the plane's point nearest
    # its voxel's centre.
    d_new = dr - np.einsum("ek,ek->e", nr, step)
    shift = np.einsum("ek,ek->e", plane_origin(nr, d_new) + step - plane_origin(nr, dr), u)
    lo_new = lo_s - shift
    hi_new = hi_s - shift
    # The near line's offset must fit its 12 bits; a far one is float32.
    fits = np.abs(lo_new) <= C_RANGE
    # A single line's halo only near it (a closed face's edge at a crease:
    # the partner face covers the footprint past it).
    fits &= np.isfinite(hi_new) | (np.abs(lo_new) <= one_line_reach)
    # The face's segment across the lines: past one line on the uncovered
    # side at both ends (the line runs along the face), or not.
    seg = np.cross(nr, np.eye(3)[a])
    seg /= np.maximum(np.linalg.norm(seg, axis=1, keepdims=True), 1e-12)
    half = 0.5 * length[r_idx, f_idx]
    m = mid[r_idx, f_idx]
    s_mid = np.einsum("ek,ek->e", m - plane_origin(nr, dr), u)
    spread = half * np.abs(np.einsum("ek,ek->e", seg, u))
    s0, s1 = s_mid - spread, s_mid + spread
    below = s1 < lo_s
    above = s0 > hi_s
    cut = ~(below | above)
    keep = ~continued & fits & (lo_s < hi_s)
    k = np.flatnonzero(keep)
    return LineHalos(
        rows[r_idx[k]], cell[k], (2 * a[k] + (1 - side[k])).astype(np.int8), d_new[k],
        decoded_offset(offset_code(lo_new[k])), hi_new[k].astype(np.float32).astype(np.float64), cut[k],
    )  # fmt: skip


def _split_rest(sheets, strips: SheetStrips, nr, dr, u, step, lo, hi, pair, other, u2, least: float):
    """The bands ``[lo, hi]`` (P,; in the entries' frames, along ``u``) less
    what the strips ``other`` of the voxels across (one row per candidate,
    its pair ``pair``, its lines' inward normal ``u2``) cover of them: per pair the candidate covering most;
    the larger piece where it leaves two; an empty band (lo >= hi) where it
    leaves less than ``least``."""
    lo, hi = lo.copy(), hi.copy()
    if len(pair) == 0:
        return lo, hi
    no = sheets.normal[other]
    # The other strip's lines in the entry's frame (its voxel is one step on).
    q2 = plane_origin(no, sheets.offset[other]) + step[pair]
    c = np.einsum("ek,ek->e", plane_origin(nr[pair], dr[pair]) - q2, u2)
    a2, b2 = strips.lo[other] - c, strips.hi[other] - c
    flip = np.einsum("ek,ek->e", u2, u[pair]) < 0.0
    a2, b2 = np.where(flip, -b2, a2), np.where(flip, -a2, b2)
    over = np.minimum(hi[pair], b2) - np.maximum(lo[pair], a2)
    # The candidate covering most of each pair's band.
    order = np.lexsort((over, pair))
    last = np.r_[pair[order][1:] != pair[order][:-1], True]
    best = order[last]
    p, a2, b2, over = pair[best], a2[best], b2[best], over[best]
    lo_p, hi_p = lo[p], hi[p]
    low_left, high_left = np.maximum(a2 - lo_p, 0.0), np.maximum(hi_p - b2, 0.0)
    covered = over > 0.0
    keep_low = covered & (low_left >= high_left)
    keep_high = covered & ~keep_low
    hi[p] = np.where(keep_low, np.minimum(hi_p, a2), hi_p)
    lo[p] = np.where(keep_high, np.maximum(lo_p, b2), lo_p)
    short = hi[p] - lo[p] < least
    hi[p[short]] = lo[p[short]]
    return lo, hi
