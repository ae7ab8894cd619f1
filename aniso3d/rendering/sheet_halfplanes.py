"""Where a partial sheet ends inside its voxel: a half-plane per entry
(docs/coverage.md, "Edges inside voxels").

An entry whose facets fill only part of their plane's section of the voxel
(a surface's border crossing the voxel, as the corpus shell's open edge
does) is drawn by the volume renderer as its section covered at ``fill``
everywhere (a sheet) or as a cloud along the ray: both smear the border
over the voxel, which close up shows as a staircase of translucent voxels
along the outline. Where the facets' centroid says the covered part is one
side of a straight line across the section, the entry is read instead as a
**half-plane**: the part of the section on one side of the line, of the
entry's area, its centroid the facets' (:func:`sheet_halfplanes`). The
renderer then counts it as a surface sheet whose coverage, where the ray
crosses its plane, is the share of the pixel's footprint on the covered side
of the line (:func:`halfplane_ramp`), a box filter of the border.

The line is kept in the tangent frame (t1, t2) of the sheet's unit normal
(:func:`aniso3d.grid.tangent_frame`, as volume.frag repeats it), relative to
the point q0 of its plane nearest the voxel's centre: covered where
``(p - q0) . u >= c`` with ``u = cos(theta) t1 + sin(theta) t2``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aniso3d.grid import cell_keys, entries_at, tangent_frame

#: Entries whose facets fill between these shares of their plane's section
#: can be half-planes (fuller: a surface sheet; emptier: too little to place).
HALF_FILL = (0.02, 0.999)
#: ... whose mean normal is at least this long (their facets nearly coplanar:
#: a piece of one surface, not a crumpled ball or two leaves at an angle) ...
HALF_COHERENCE = 0.9
#: ... and whose facets' centroid lies within this (voxel units, in the
#: plane) of the half-plane's centroid: a leaf in the middle of a voxel, or
#: a strip across it, is no half-plane.
HALF_TOLERANCE = 0.03
#: Half-planes are drawn where their voxel spans at least this many pixels:
#: smaller, the footprint reaches past the voxel, where nothing carries the
#: half-plane on (the minified tree lost 1.6 dB with them everywhere), and
#: the sheet laws' partial sheets and clouds filter better.
HALF_PIXELS = 2.0
#: ... and whose covered side goes on past the voxel: a voxel from the
#: facets' centroid along the line's inward normal, a sheet within about 45
#: degrees of its normal (|n . n'| at least HALF_PARALLEL) passes within
#: HALF_NEAR (voxel units): a surface's border, not a leaf smaller than a
#: voxel (whose half-planes over-covered a cloud of them by 0.02-0.06 of
#: alpha: a small piece's ramp spills past its line along the whole chord).
HALF_PARALLEL = 0.7
HALF_NEAR = 0.3
#: Newton steps for the line's offset (safeguarded by bisection).
_STEPS = 5
#: Least rate the centroid is taken to turn with the line (a secant step no
#: wilder than twice the angle left).
RATE_MIN = 0.5
#: Entries fitted per chunk (memory bound).
_CHUNK = 200_000
#: The 12 edges of the unit cube: start corner and axis.
_EDGE_START = np.array(
    [[0, 0, 0], [0, 1, 0], [0, 0, 1], [0, 1, 1],
     [0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1],
     [0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=np.float64,
)  # fmt: skip
_EDGE_AXIS = np.repeat(np.arange(3), 4)
#: Offsets c are stored in 12 bits over [-C_RANGE, C_RANGE] (voxel units;
#: steps of 1e-3), angles in 8 bits over the turn. A voxel's section lies
#: within sqrt(3)/2 of q0, but a line halo's line (render/sheet_line_halos.py)
#: is its neighbour's, up to a voxel farther: with 0.875 they lost 62 % of
#: the lattice's halos, and the lattice minified 0.47 dB and 0.0069 of FLIP
#: (docs/coverage.md, "Halos of lines inside voxels").
C_RANGE = 2.0
C_BITS = 12


@dataclass(frozen=True)
class SheetHalfplanes:
    """The half-planes of a texture's partial sheets (see the module
    docstring). All (E,).

    Attributes:
        mask: bool, the entry is a half-plane.
        angle: float64, theta (radians) of the line's inward normal u in the
            sheet's tangent frame, as the GPU reads it back (8 bits).
        offset: float64, c (voxel units), as the GPU reads it back.
        residual: float64, the in-plane distance between the facets'
            centroid and the fitted half-plane's (voxel units; inf where
            not fitted).
    """

    mask: np.ndarray
    angle: np.ndarray
    offset: np.ndarray
    residual: np.ndarray


def plane_origin(normal: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """(N, 3) q0: the point of each plane ``normal . x = offset`` (N, 3 unit;
    N,) nearest the voxel's centre, voxel-local, where the sheets' lines
    are measured from."""
    n = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(offset, dtype=np.float64).reshape(-1)
    return 0.5 - (n.sum(axis=1) * 0.5 - d)[:, None] * n


def line_inward(angle: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(N, 3) the inward unit direction u (into the covered side) of lines at
    ``angle`` (N,) in the tangent frame of the unit ``normal`` (N, 3)."""
    t1, t2 = tangent_frame(normal)
    th = np.asarray(angle, dtype=np.float64).reshape(-1)
    return np.cos(th)[:, None] * t1 + np.sin(th)[:, None] * t2


def section_polygons(normal: np.ndarray, offset: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sections of the unit cube by the planes ``normal . x = offset``
    (N, 3 unit; N,) as closed convex polygons in the planes' tangent frames
    relative to q0 (the plane's point nearest the cube's centre): (N, 12, 2)
    vertices in order (unused slots repeat the first vertex, adding nothing
    to any sum along the boundary), (N, 12) which are real, and the frames
    (t1, t2) as (N, 2, 3)."""
    n = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(offset, dtype=np.float64).reshape(-1)
    t1, t2 = tangent_frame(n)
    q0 = plane_origin(n, d)
    na = n[:, _EDGE_AXIS]  # (N, 12)
    start_dot = n @ _EDGE_START.T  # (N, 12)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (d[:, None] - start_dot) / na
    real = (np.abs(na) > 1e-12) & (s >= 0.0) & (s <= 1.0)
    pts = np.broadcast_to(_EDGE_START, (len(n), 12, 3)).copy()
    pts[:, np.arange(12), _EDGE_AXIS] += np.where(real, s, 0.0)
    rel = pts - q0[:, None, :]
    uv = np.stack([np.einsum("nek,nk->ne", rel, t1), np.einsum("nek,nk->ne", rel, t2)], axis=-1)
    count = np.maximum(real.sum(axis=1), 1)
    mid = np.where(real[..., None], uv, 0.0).sum(axis=1) / count[:, None]
    ang = np.arctan2(uv[..., 1] - mid[:, None, 1], uv[..., 0] - mid[:, None, 0])
    order = np.argsort(np.where(real, ang, np.inf), axis=1, kind="stable")
    uv = np.take_along_axis(uv, order[..., None], axis=1)
    real = np.take_along_axis(real, order, axis=1)
    uv = np.where(real[..., None], uv, uv[:, :1, :])
    return uv, real, np.stack([t1, t2], axis=1)


def clipped_piece(x: np.ndarray, y: np.ndarray, u: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, ...]:
    """Area (N,), centroid (N, 2) and chord length along the line (N,) of
    the closed convex polygons with vertices ``(x, y)`` (N, 12 each,
    counter-clockwise) where ``(x, y) . u >= c`` (u (N, 2) unit)."""
    x2, y2 = np.roll(x, -1, axis=1), np.roll(y, -1, axis=1)
    ux, uy, cc = u[:, 0:1], u[:, 1:2], c[:, None]
    sp = x * ux + y * uy - cc
    sq = x2 * ux + y2 * uy - cc
    den = sp - sq
    f = sp / np.where(den != 0.0, den, 1.0)
    cx, cy = x + (x2 - x) * f, y + (y2 - y) * f  # where each edge crosses the line
    pin, qin = sp >= 0.0, sq >= 0.0
    keep = pin | qin
    ax = np.where(keep, np.where(pin | ~qin, x, cx), 0.0)  # kept piece: start
    ay = np.where(keep, np.where(pin | ~qin, y, cy), 0.0)
    bx = np.where(keep, np.where(qin | ~pin, x2, cx), 0.0)  # ... and end
    by = np.where(keep, np.where(qin | ~pin, y2, cy), 0.0)
    # The chord along the line closes the piece: from the edge leaving the
    # half-plane to the one entering it.
    ex, en = pin & ~qin, ~pin & qin
    xax, xay = np.where(ex, cx, 0.0).sum(axis=1), np.where(ex, cy, 0.0).sum(axis=1)
    xbx, xby = np.where(en, cx, 0.0).sum(axis=1), np.where(en, cy, 0.0).sum(axis=1)
    cr = ax * by - ay * bx
    chord = xax * xby - xay * xbx
    area2 = cr.sum(axis=1) + chord
    mx = ((ax + bx) * cr).sum(axis=1) + (xax + xbx) * chord
    my = ((ay + by) * cr).sum(axis=1) + (xay + xby) * chord
    ok = area2 > 1e-12
    safe = np.where(ok, 3.0 * area2, 1.0)
    centroid = np.stack([np.where(ok, mx / safe, 0.0), np.where(ok, my / safe, 0.0)], axis=1)
    length = np.where(ex.any(axis=1) & en.any(axis=1), np.hypot(xbx - xax, xby - xay), 0.0)
    return 0.5 * area2, centroid, length


def _wrap(a: np.ndarray) -> np.ndarray:
    return np.arctan2(np.sin(a), np.cos(a))


def fit_halfplanes(normal, offset, area, centroid, turns: int = 3) -> tuple[np.ndarray, ...]:
    """Fit the half-planes of area ``area`` (N,) whose centroids come nearest
    the voxel-local points ``centroid`` (N, 3) in the sections of the unit
    cube by the planes ``normal . x = offset``. Returns (N,) theta, c and
    the residual distance (see the module docstring), and (N,) the
    sections' areas. The line's direction starts from the section's
    centroid towards the facets' and is turned ``turns`` times by the angle
    between where the half-plane's centroid came and where the facets' is
    (over the rate the centroid turned with the line at the last turn);
    its offset is found by safeguarded Newton steps (the area's derivative
    is the chord's length)."""
    uv, real, frame = section_polygons(normal, offset)
    x, y = uv[..., 0], uv[..., 1]
    n = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(offset, dtype=np.float64).reshape(-1)
    N = len(n)
    rel = np.asarray(centroid, np.float64).reshape(-1, 3) - plane_origin(n, d)
    target = np.stack([np.einsum("nk,nk->n", rel, frame[:, 0]), np.einsum("nk,nk->n", rel, frame[:, 1])], 1)
    section, s_cent, _ = clipped_piece(x, y, np.tile([1.0, 0.0], (N, 1)), np.full(N, -1e9))
    want = np.minimum(np.asarray(area, np.float64).reshape(-1), section)
    aim = np.arctan2(target[:, 1] - s_cent[:, 1], target[:, 0] - s_cent[:, 0])
    theta = aim
    prev = None  # the last turn's (theta, angle of the centroid), for a secant step
    for it in range(turns + 1):
        u = np.stack([np.cos(theta), np.sin(theta)], axis=1)
        s = x * u[:, 0:1] + y * u[:, 1:2]
        lo, hi = s.min(axis=1), s.max(axis=1)
        c = lo + (hi - lo) * (1.0 - want / np.maximum(section, 1e-12))
        for _ in range(_STEPS):
            got, g, length = clipped_piece(x, y, u, c)
            more = got > want  # the line must move up
            lo, hi = np.where(more, c, lo), np.where(more, hi, c)
            step = c + (got - want) / np.maximum(length, 1e-9)
            c = np.where((step >= lo) & (step <= hi), step, 0.5 * (lo + hi))
        got, g, _ = clipped_piece(x, y, u, c)
        if it == turns:
            break
        # Turn the line by the angle still between the centroids, over how
        # far the centroid turned with the line last time (a secant step).
        phi = np.arctan2(g[:, 1] - s_cent[:, 1], g[:, 0] - s_cent[:, 0])
        turn = _wrap(aim - phi)
        rate = np.ones(N)
        if prev is not None:
            dt, dp = _wrap(theta - prev[0]), _wrap(phi - prev[1])
            with np.errstate(divide="ignore", invalid="ignore"):
                rate = np.where(np.abs(dt) > 1e-6, np.clip(dp / dt, RATE_MIN, 5.0), 1.0)
        prev = theta, phi
        theta = theta + turn / rate
    residual = np.hypot(g[:, 0] - target[:, 0], g[:, 1] - target[:, 1])
    return np.arctan2(np.sin(theta), np.cos(theta)), c, residual, section, np.abs(got - want)


def angle_code(angle: np.ndarray) -> np.ndarray:
    """8-bit code of angles in [-pi, pi) (as volume.frag's edge_angle() decodes them)."""
    return np.round((np.asarray(angle, dtype=np.float64) + np.pi) * (256 / (2 * np.pi))).astype(np.int64) % 256


def offset_code(offset: np.ndarray) -> np.ndarray:
    """:data:`C_BITS`-bit code of offsets in [-C_RANGE, C_RANGE]."""
    top = (1 << C_BITS) - 1
    x = (np.clip(np.asarray(offset, dtype=np.float64), -C_RANGE, C_RANGE) + C_RANGE) / (2 * C_RANGE)
    return np.round(x * top).astype(np.int64)


def decoded_offset(code: np.ndarray) -> np.ndarray:
    """The offsets the GPU reads back from :func:`offset_code`."""
    return np.asarray(code, dtype=np.float64) / ((1 << C_BITS) - 1) * (2 * C_RANGE) - C_RANGE


def sheet_halfplanes(texture, sheets, surface: np.ndarray) -> SheetHalfplanes:
    """The half-planes of ``texture``'s entries (its
    :class:`~aniso3d.rendering.volume.EntrySheets` ``sheets``; ``surface``
    (E,) bool the surface sheets, which are none): entries filling
    :data:`HALF_FILL` of their section, coherent (:data:`HALF_COHERENCE`),
    whose facets' centroid a half-plane of their area matches within
    :data:`HALF_TOLERANCE`. Vectorised, in chunks."""
    E = texture.n_entries
    mask = np.zeros(E, dtype=bool)
    angle, offset, residual = np.zeros(E), np.zeros(E), np.full(E, np.inf)
    coherence = np.linalg.norm(np.asarray(texture.entry_normal, np.float64), axis=1)
    own = np.where(sheets.section > 1e-9, sheets.area / np.maximum(sheets.section, 1e-12), 0.0)
    rows = np.flatnonzero(
        ~np.asarray(surface, dtype=bool) & (own >= HALF_FILL[0]) & (own < HALF_FILL[1])
        & (coherence >= HALF_COHERENCE) & (sheets.section > 1e-9)
    )  # fmt: skip
    if len(rows) == 0:
        return SheetHalfplanes(mask, angle, offset, residual)
    # First a cheap pass (the fit's cost): only entries whose covered side,
    # taken from the plane's point nearest the voxel's centre towards the
    # facets' centroid, goes on past the voxel.
    local = texture.local_centroids(rows)
    n = sheets.normal[rows]
    rel = local - plane_origin(n, sheets.offset[rows])
    t1, t2 = tangent_frame(n)
    angle[rows] = np.arctan2(np.einsum("nk,nk->n", rel, t2), np.einsum("nk,nk->n", rel, t1))
    rows = rows[_continued(texture, sheets, surface, angle, rows)]
    for start in range(0, len(rows), _CHUNK):
        r = rows[start : start + _CHUNK]
        th, c, res, _, _ = fit_halfplanes(sheets.normal[r], sheets.offset[r], sheets.area[r],
                                          texture.local_centroids(r))  # fmt: skip
        angle[r], offset[r], residual[r] = th, c, res
    mask[rows] = residual[rows] <= HALF_TOLERANCE
    mask[mask] = _continued(texture, sheets, surface, angle, np.flatnonzero(mask))
    angle = np.where(mask, angle_code(angle) * (2 * np.pi / 256) - np.pi, 0.0)
    offset = np.where(mask, decoded_offset(offset_code(offset)), 0.0)
    return SheetHalfplanes(mask, angle, offset, residual)


def _continued(texture, sheets, surface: np.ndarray, angle: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(R,) bool: entries ``rows``' covered sides go on past their voxels:
    the point a voxel from the facets' centroid along the line's inward
    normal (angle ``angle`` in the tangent frame) lies within
    :data:`HALF_NEAR` of the plane of a sheet within :data:`HALF_PARALLEL`
    of the entry's normal, in the voxel it falls in, which a surface sheet
    (``surface``) or a sheet filling at least half its section."""
    if len(rows) == 0:
        return np.zeros(0, dtype=bool)
    n = sheets.normal[rows]
    t1, t2 = tangent_frame(n)
    u = np.cos(angle[rows])[:, None] * t1 + np.sin(angle[rows])[:, None] * t2
    coords = np.asarray(texture.coords, dtype=np.int64)
    owner = np.asarray(texture.entry_voxel, dtype=np.int64)
    local = texture.local_centroids(rows)
    q = local + u
    step = np.floor(q).astype(np.int64)
    cell = coords[owner[rows]] + step
    q -= step
    which, other = entries_at(cell_keys(coords, texture.shape), texture.shape, texture.entry_offsets, cell)
    sheet = np.asarray(surface, bool)[other] | (sheets.fill[other] >= 0.5)
    parallel = np.abs(np.einsum("ek,ek->e", sheets.normal[other], n[which])) >= HALF_PARALLEL
    near = np.abs(np.einsum("ek,ek->e", sheets.normal[other], q[which]) - sheets.offset[other]) <= HALF_NEAR
    hit = np.zeros(len(rows), dtype=bool)
    np.logical_or.at(hit, which, sheet & parallel & near)
    return hit


def halfplane_words(hp: SheetHalfplanes) -> np.ndarray:
    """(E,) uint32 to OR into entry word 11 (no edges on faces then): bit 31
    the flag, bits 11-18 the angle's code, bits 19-30 the offset's."""
    words = (angle_code(hp.angle).astype(np.uint32) << 11) | (
        offset_code(hp.offset).astype(np.uint32) << 19) | np.uint32(1 << 31)  # fmt: skip
    return np.where(hp.mask, words, np.uint32(0)).astype(np.uint32)


def halfplane_ramp(angle, offset, plane, point, normal, w, foot) -> np.ndarray:
    """(N,) share in [0, 1] of a pixel's footprint (width ``foot``, grid
    units across the ray) on the covered side of the half-planes (``angle``,
    ``offset`` (N,), unit ``normal`` (N, 3), planes ``normal . x = plane``)
    where the ray (unit ``w``) crosses them at the voxel-local ``point``
    (N, 3). The crossing
    lies ``e = (p - q0) . u - c`` from the line in the plane; seen along w
    that shrinks by ``|n . w| / sqrt(1 - (t . w)^2)`` (t = n x u, the line's
    direction): a ramp over the footprint, 1/2 on the line. ``foot`` 0: the
    centre ray's side, 1 or 0. Mirrors halfplane_ramp() in volume.frag."""
    n = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
    p = np.asarray(point, dtype=np.float64).reshape(-1, 3)
    w = np.asarray(w, dtype=np.float64)
    u = line_inward(angle, n)
    e = np.einsum("nk,nk->n", p - plane_origin(n, plane), u) - np.asarray(offset, np.float64).reshape(-1)
    tw = np.cross(n, u) @ w
    dist = e * np.abs(n @ w) / np.sqrt(np.maximum(1.0 - tw * tw, 1e-12))
    foot = np.broadcast_to(np.asarray(foot, dtype=np.float64), e.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        ramp = np.clip(0.5 + dist / np.where(foot > 0, foot, 1.0), 0.0, 1.0)
    return np.where(foot > 0, ramp, (dist >= 0.0).astype(np.float64))
