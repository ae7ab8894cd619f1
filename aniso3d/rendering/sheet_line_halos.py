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
its own entry counts). It keeps the entry's plane and lines, moved into its
voxel's frame, and counts, where the ray crosses the plane there, the same
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

#: Entry word 11's bit marking a line halo cut by its face (bits 0-2 and
#: 4-6 hold no face for lines, bit 7 no second edge's kind).
FACE_CUT_BIT = 7
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
    one_line_reach: float = np.inf,
) -> LineHalos:  # fmt: skip
    """The :class:`LineHalos` of the entries ``rows`` of ``texture`` (its
    :class:`~aniso3d.rendering.volume.EntrySheets` ``sheets``), whose lines
    are at ``angle`` (R,) in their sheets' tangent frames with offsets
    ``lo`` and ``hi`` (R,; covered where ``lo <= (p - q0) . u <= hi``, hi inf
    for a half-plane). A half-plane's halo is left out where its line lies
    farther than ``one_line_reach`` (voxel units, in the plane) from the
    halo's q0. Vectorised over (entry, face) pairs."""
    rows = np.asarray(rows, dtype=np.int64)
    if len(rows) == 0:
        return LineHalos.empty()
    if len(rows) > _CHUNK:
        parts = [line_halos(texture, sheets, rows[i : i + _CHUNK], angle[i : i + _CHUNK], lo[i : i + _CHUNK],
                            hi[i : i + _CHUNK], one_line_reach) for i in range(0, len(rows), _CHUNK)]  # fmt: skip
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
    has_plane = np.linalg.norm(no, axis=1) > 0.5
    continued = np.zeros(len(r_idx), dtype=bool)
    np.logical_or.at(continued, which, near & parallel & has_plane)
    # The lines in the halo's frame: q0 moves to the plane's point nearest
    # its voxel's centre.
    u = line_inward(angle[r_idx], nr)
    d_new = dr - np.einsum("ek,ek->e", nr, step)
    shift = np.einsum("ek,ek->e", plane_origin(nr, d_new) + step - plane_origin(nr, dr), u)
    lo_new = lo[r_idx] - shift
    hi_new = hi[r_idx] - shift
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
    below = s1 < lo[r_idx]
    above = s0 > hi[r_idx]
    cut = ~(below | above)
    keep = ~continued & fits
    k = np.flatnonzero(keep)
    return LineHalos(
        rows[r_idx[k]], cell[k], (2 * a[k] + (1 - side[k])).astype(np.int8), d_new[k],
        decoded_offset(offset_code(lo_new[k])), hi_new[k].astype(np.float32).astype(np.float64), cut[k],
    )  # fmt: skip
