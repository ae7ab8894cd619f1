"""Where a surface sheet ends on a voxel face, and the halos that carry its
pixel footprint past the end (docs/coverage.md, "Edges on voxel faces").

A surface sheet (:data:`~aniso3d.rendering.volume.RUN_SHARE`) fills its
plane's section of the voxel: the volume renderer counts it whole where the
centre ray crosses it, and a silhouette's near misses by the share of the
pixel's footprint crossing it along its normal. Neither sees where a surface
*ends* on a voxel face, as a wall's top does on a grid plane: the voxel beyond
holds nothing, the centre ray is in or out, and the edge aliases like one
polygon sample per pixel (the corpus room: its silhouette pixels as wrong as
1-sample polygons). So, at upload, each surface sheet's section edges on the
voxel's faces are classified from the neighbouring voxels (:func:`sheet_edges`):

- **continued**: a sheet within :data:`EDGE_PARALLEL` of its normal, across
  the face (the 3 x 3 voxels beyond it), passes within :data:`EDGE_NEAR` of
  the edge's midpoint: the surface goes on (a bent surface, a plane cut by
  voxel faces). Nothing changes.
- **crease**: no such sheet, but some other sheet (in the voxel or across the
  face) passes that near: another surface meets the edge (a box's edge, a
  room's corner). Its footprint past the edge is carried by a halo (below);
  the sheet itself stays whole, since the surface it meets may cover the rest
  of the footprint (a concave corner, a box's edge seen with both faces).
- **open**: nothing meets it: the surface ends (a wall's top). The sheet
  counts, where the ray crosses its plane, the share of the footprint on its
  side of the edge, and a halo the share past it.

A **halo** is a copy of the sheet in the voxel across the edge's face (which
may lie outside the grid: the GPU grid has a margin, :data:`GRID_PAD`),
counting only the share of the footprint on the sheet's side of the edge
where the ray crosses the sheet's plane extended there.
Along an edge the footprint's share on either side is a ramp of the screen
distance to the edge (:func:`edge_ramp`), so a sheet and its halo add up to
a box filter of the edge.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aniso3d.grid import cell_keys, ranges

#: A sheet's plane passing within this (voxel units) of an edge's midpoint
#: on a voxel face meets the edge (continues the surface or creases it).
EDGE_NEAR = 0.3
#: ... and continues it when its normal is within about 45 degrees (|n . n'|
#: at least this): a bent surface, whose facets fall on neighbouring sample
#: directions.
EDGE_PARALLEL = 0.7
#: Section edges shorter than this (voxel units) on a face are left alone: the
#: plane only grazes the voxel's edge or corner there.
EDGE_MIN_LENGTH = 0.05
#: ... and so are those on faces the plane meets at under 60 degrees (|n_a|
#: above this, a the face's axis): a surface ending on a grid plane crosses
#: it (a wall's top: at 90 degrees), while a plane nearly along the face
#: cuts it only as a fit to a curved surface's tangent there (a sphere's
#: extreme points on the grid's outer planes).
EDGE_SLANT = 0.5
#: Edges kept per sheet (two: a box's corner).
MAX_EDGES = 2
#: For the splats' clip planes (:func:`sheet_edges` ``plane_angle``), a
#: crease partner's angle about the edge is its plane's where the plane cuts
#: the plane normal to the edge at least this steeply (the sine of the angle
#: between its normal and the edge), else its centroid's direction. The
#: volume keeps the centroid's: its crease ramps lost up to 0.13 dB with the
#: plane's (the lattice close up at 256^3; docs/splat_aa.md "Pinholes in
#: closed surfaces", the block at 8814f3f).
PHI_PLANE_MIN = 0.5
#: Edge kinds.
OPEN, CREASE = 0, 1
#: "No face" in the packed edge words (faces are 0-5: 2 * axis + side).
NO_FACE = 7
#: Voxels of margin around the GPU grid, where the halos of edges on the
#: grid's outer planes go: a whole brick (volume.BRICK), so that the
#: texture's voxels fall in the same bricks as without it (a margin of one
#: voxel moved them across brick faces: up to 1.4 times the bricks).
GRID_PAD = 8
#: Sheet edges classified per chunk of (sheet, face) pairs (memory bound).
_CHUNK = 100_000


@dataclass(frozen=True)
class SheetEdges:
    """The edges of a texture's surface sheets on their voxels' faces, and
    their halos. Faces are numbered ``2 * axis + side``: the face
    ``x[axis] = side`` of the voxel (the unit cube).

    Attributes:
        face: (E, 2) int8, the faces of each entry's open or creased edges,
            -1 for none (at most :data:`MAX_EDGES`, open ones first).
        kind: (E, 2) int8, :data:`OPEN` or :data:`CREASE` (0 where no edge).
        angle: (E, 2) float64, a crease's partner: the angle phi (radians)
            of the half-plane of the sheet meeting it, about the edge, from
            the sheet's own: ``cos(phi) u + sin(phi) n``, u the direction in
            the sheet's plane from the edge into its voxel (:func:`inward`), n
            its normal. 0 for open edges.
        halo_cell: (H, 3) int64, the grid cell of each halo (may be -1 or
            ``shape`` along an axis: the margin).
        halo_row: (H,) int64, the entry whose sheet it carries past the edge.
        halo_face: (H,) int8, the face of the halo's voxel on the edge.
        halo_offset: (H,) float64, the sheet's plane ``n . x = offset`` in the
            halo's voxel (voxel-local coordinates).
        halo_kind, halo_angle: (H,) the kind and angle of the edge it carries.
    """

    face: np.ndarray
    kind: np.ndarray
    angle: np.ndarray
    halo_cell: np.ndarray
    halo_row: np.ndarray
    halo_face: np.ndarray
    halo_offset: np.ndarray
    halo_kind: np.ndarray
    halo_angle: np.ndarray

    @property
    def open(self) -> np.ndarray:
        """(E, 2) bool: the open edges (the sheet ramps off across them)."""
        return (self.face >= 0) & (self.kind == OPEN)


def inward(face: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(N, 3) unit direction in the planes of unit ``normal`` (N, 3) across
    their edges on voxel faces ``face`` (N,) into the voxel: the face's
    inward axis direction with its normal part taken out. Mirrors volume.frag."""
    face = np.asarray(face, dtype=np.int64).reshape(-1)
    n = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
    s = np.zeros_like(n)
    s[np.arange(len(face)), face // 2] = np.where(face % 2 == 1, -1.0, 1.0)
    u = s - np.einsum("ek,ek->e", s, n)[:, None] * n
    return u / np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-12)


def face_segments(normal: np.ndarray, offset: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the planes ``normal . x = offset`` (N, 3 unit; N,) cut the faces
    of the unit cube: (N, 6) length of the segment on each face ``2 a + s``
    (0 where the plane misses the face or lies in it) and (N, 6, 3) its
    midpoint (voxel-local)."""
    n = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(offset, dtype=np.float64).reshape(-1)
    N = len(n)
    length = np.zeros((N, 6))
    mid = np.zeros((N, 6, 3))
    eps = 1e-9
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        nb, nc = n[:, b], n[:, c]
        l2 = nb * nb + nc * nc
        ok = l2 > 1e-12
        inv = np.where(ok, 1.0 / np.where(ok, l2, 1.0), 0.0)
        norm = np.sqrt(l2)
        db = np.where(ok, -nc / np.where(ok, norm, 1.0), 0.0)
        dc = np.where(ok, nb / np.where(ok, norm, 1.0), 0.0)
        for side in (0, 1):
            r = d - n[:, a] * side
            pb, pc = r * nb * inv, r * nc * inv
            lo = np.full(N, -np.inf)
            hi = np.full(N, np.inf)
            inside = ok.copy()
            for p, dd in ((pb, db), (pc, dc)):
                moving = np.abs(dd) > 1e-12
                with np.errstate(divide="ignore", invalid="ignore"):
                    s0 = np.where(moving, (0.0 - p) / dd, -np.inf)
                    s1 = np.where(moving, (1.0 - p) / dd, np.inf)
                lo = np.maximum(lo, np.where(moving, np.minimum(s0, s1), -np.inf))
                hi = np.minimum(hi, np.where(moving, np.maximum(s0, s1), np.inf))
                inside &= moving | ((p >= -eps) & (p <= 1.0 + eps))
            # (A plane's line moves along one axis at least: lo, hi finite.)
            seg = np.where(inside & (hi > lo), hi - lo, 0.0)
            with np.errstate(invalid="ignore"):
                s_mid = np.where(seg > 0, 0.5 * (lo + hi), 0.0)
            f = 2 * a + side
            length[:, f] = seg
            mid[:, f, a] = side
            mid[:, f, b] = pb + s_mid * db
            mid[:, f, c] = pc + s_mid * dc
    return length, mid


def sheet_edges(texture, sheets, surface: np.ndarray, plane_angle: bool = False) -> SheetEdges:
    """Classify the section edges of the surface sheets ``surface`` ((E,)
    bool) of ``texture`` (its :class:`~aniso3d.rendering.volume.EntrySheets`
    ``sheets``) on their voxels' faces, and make the halos of the open and
    creased ones (see the module docstring). A crease partner's angle is the
    direction to its centroid, or with ``plane_angle`` its plane's (the
    splats' clip planes, :data:`PHI_PLANE_MIN`). Vectorised over (sheet,
    face) pairs and their neighbouring voxels' entries, in chunks."""
    E = texture.n_entries
    face = np.full((E, MAX_EDGES), -1, dtype=np.int8)
    kind = np.zeros((E, MAX_EDGES), dtype=np.int8)
    angle = np.zeros((E, MAX_EDGES))
    empty = SheetEdges(face, kind, angle, np.zeros((0, 3), np.int64), np.zeros(0, np.int64),
                       np.zeros(0, np.int8), np.zeros(0), np.zeros(0, np.int8), np.zeros(0))  # fmt: skip
    rows = np.flatnonzero(np.asarray(surface, dtype=bool) & (sheets.section > 1e-9))
    if len(rows) == 0:
        return empty
    nh, d = sheets.normal, sheets.offset
    length, mid = face_segments(nh[rows], d[rows])
    # A plane lying in a face (|n_a| = 1) is cut by the four faces around it, not by that one.
    slant = np.abs(nh[rows][:, np.arange(6) // 2]) <= EDGE_SLANT
    r_idx, f_idx = np.nonzero((length >= EDGE_MIN_LENGTH) & slant)
    pr, pf = rows[r_idx], f_idx.astype(np.int64)
    pm, plen = mid[r_idx, f_idx], length[r_idx, f_idx]
    shape = np.asarray(texture.shape, dtype=np.int64)
    coords = np.asarray(texture.coords, dtype=np.int64)
    keys = cell_keys(coords, shape)
    offsets = np.asarray(texture.entry_offsets, dtype=np.int64)
    has_plane = np.linalg.norm(nh, axis=1) > 0.5
    owner = np.asarray(texture.entry_voxel, dtype=np.int64)
    centroid = texture.local_centroids()
    continued = np.zeros(len(pr), dtype=bool)
    met = np.zeros(len(pr), dtype=bool)
    # Sheets meeting an edge across: (pair, entry, its offset, distance).
    meets: list[tuple[np.ndarray, ...]] = []
    # The 9 voxels across each face (the face's neighbour and its 8 around),
    # then the voxel itself (offset 0), as the cell offset of each face (6,
    # 10, 3). Most edges are continued by the face's neighbour (a surface
    # goes on): that step is tried first, and a pair found continued is
    # dropped from every later step (its kind and partner are never used).
    # The other pairs see every step in this order, so their partners (the
    # nearest sheet, the first in this order on a tie) stay as they were.
    steps = [(u, v) for u in (-1, 0, 1) for v in (-1, 0, 1)]
    step_delta = np.zeros((6, len(steps) + 1, 3), dtype=np.int64)
    for f6 in range(6):
        a6, s6 = f6 // 2, f6 % 2
        for j, (u, v) in enumerate(steps):
            step_delta[f6, j, a6] = 2 * s6 - 1
            step_delta[f6, j, (a6 + 1) % 3] = u
            step_delta[f6, j, (a6 + 2) % 3] = v
    ahead = steps.index((0, 0))

    def neighbours(pairs: np.ndarray, j: int):
        """The entries of the voxel at step ``j`` of each of ``pairs`` (pair
        indices into the chunk) as rows: (the row's pair, its entry; the
        step's cell offset and row count of each pair with a voxel there;
        the entry's plane's distance to the edge's midpoint, |n . n'|)."""
        delta = step_delta[f[pairs], j]
        nb_cell = cell[pairs] + delta
        inside = np.all((nb_cell >= 0) & (nb_cell < shape), axis=1)
        key = cell_keys(np.where(inside[:, None], nb_cell, 0), shape)
        pos = np.minimum(np.searchsorted(keys, key), len(keys) - 1)
        vox = np.where(inside & (keys[pos] == key), pos, -1)
        hit = np.flatnonzero(vox >= 0)
        lo, hi = offsets[vox[hit]], offsets[vox[hit] + 1]
        counts = hi - lo
        which = pairs[np.repeat(hit, counts)]
        other = ranges(lo, hi)
        local = (m[pairs[hit]] - delta[hit])[np.repeat(np.arange(len(hit)), counts)]
        no = nh[other]
        dist = np.abs(np.einsum("ek,ek->e", no, local) - d[other])
        along = np.abs(np.einsum("ek,ek->e", no, nr[which]))
        return which, other, delta[hit], counts, dist, along

    for start in range(0, len(pr), _CHUNK):
        sl = slice(start, start + _CHUNK)
        r, f, m = pr[sl], pf[sl], pm[sl]
        cell = coords[owner[r]]
        nr = nh[r]
        alive = np.ones(len(r), dtype=bool)
        # The face's neighbour first: only whether it continues the edge.
        which, other, _, _, dist, along = neighbours(np.arange(len(r)), ahead)
        alive[which[(dist <= EDGE_NEAR) & has_plane[other] & (along >= EDGE_PARALLEL)]] = False
        for j in range(len(steps) + 1):
            across = j < len(steps)
            pairs = np.flatnonzero(alive)
            if len(pairs) == 0:
                break
            which, other, delta, counts, dist, along = neighbours(pairs, j)
            near = (dist <= EDGE_NEAR) & has_plane[other]
            parallel = along >= EDGE_PARALLEL
            if across:
                alive[which[near & parallel]] = False
                crossing = near
            else:
                # In the voxel itself only another surface (not the sheet's
                # own layers) meets an edge.
                crossing = near & ~parallel & (other != r[which])
            met[start + which[crossing]] = True
            k = np.flatnonzero(crossing & ~parallel)
            meets.append((start + which[k], other[k], np.repeat(delta, counts, axis=0)[k], dist[k]))
        continued[sl] = ~alive
    # A crease's partner: the nearest sheet meeting it; the angle phi of its
    # half-plane about the edge, from the sheet's own (u, in its plane into
    # the voxel, towards n): u2 = cos(phi) u + sin(phi) n.
    phi = np.zeros(len(pr))
    if meets:
        q, other, delta, dist = (np.concatenate(x) for x in zip(*meets, strict=True))
        own = ~continued[q]
        q, other, delta, dist = q[own], other[own], delta[own], dist[own]
        order = np.lexsort((dist, q))
        first = order[np.r_[True, q[order][1:] != q[order][:-1]]] if len(order) else order
        q, other, delta = q[first], other[first], delta[first]
        n1, f = nh[pr[q]], pf[q]
        u1 = inward(f, n1)
        t = np.cross(n1, u1)
        v = centroid[other] + delta - pm[q]
        v -= np.einsum("ek,ek->e", v, t)[:, None] * t
        # With plane_angle, the half-plane's direction is its plane's, across
        # the edge (the line where the partner's plane cuts the plane normal
        # to the edge), turned towards its centroid: the partner's plane
        # passes up to EDGE_NEAR from the edge, and the direction to its
        # centroid would tilt by as much (a wall 0.2 voxel inside its plate's
        # voxel face stood at 63 degrees, not 90, and hid the plate's
        # splats before it from eyes between the two). Where the partner's
        # plane is nearly normal to the edge its centroid's direction stays.
        along = np.cross(t, nh[other])
        size = np.linalg.norm(along, axis=1)
        plane = (size >= PHI_PLANE_MIN) & plane_angle
        along = along / np.where(plane, size, 1.0)[:, None]
        along *= np.where(np.einsum("ek,ek->e", along, v) < 0.0, -1.0, 1.0)[:, None]
        v = np.where(plane[:, None], along, v)
        phi[q] = np.arctan2(np.einsum("ek,ek->e", v, n1), np.einsum("ek,ek->e", v, u1))
    keep = ~continued
    pr, pf, plen, phi = pr[keep], pf[keep], plen[keep], phi[keep]
    pkind = np.where(met[keep], CREASE, OPEN)
    # Per sheet, open edges first, then the longer.
    order = np.lexsort((-plen, pkind, pr))
    pr, pf, pkind, phi = pr[order], pf[order], pkind[order], phi[order]
    rank = np.arange(len(pr)) - np.searchsorted(pr, pr)
    sel = rank < MAX_EDGES
    face[pr[sel], rank[sel]] = pf[sel]
    kind[pr[sel], rank[sel]] = pkind[sel]
    angle[pr[sel], rank[sel]] = phi[sel]
    # Halos: the sheet's copy in the voxel across each kept edge's face.
    hr, hf = pr[sel], pf[sel]
    a, side = hf // 2, hf % 2
    step = np.zeros((len(hr), 3), dtype=np.int64)
    step[np.arange(len(hr)), a] = 2 * side - 1
    halo_cell = coords[owner[hr]] + step
    halo_face = (2 * a + (1 - side)).astype(np.int8)
    halo_offset = d[hr] - np.einsum("ek,ek->e", nh[hr], step)
    angle = quantised_angle(angle)
    return SheetEdges(face, kind, angle, halo_cell, hr, halo_face, halo_offset, pkind[sel], quantised_angle(phi[sel]))


def edge_ramp(
    face: np.ndarray, point: np.ndarray, normal: np.ndarray, w: np.ndarray, foot: np.ndarray, inside: bool
) -> np.ndarray:
    """Share in [0, 1] of a pixel's footprint (width ``foot`` > 0, grid units
    across the ray) on a sheet's side of its edge on voxel face ``face``
    (N,), where the ray (unit direction ``w``) crosses the sheet's plane at
    the voxel-local ``point`` (N, 3); ``normal`` (N, 3) unit. ``inside``: the
    sheet lies on the voxel's side of the face (a sheet's own edge), else
    past it (a halo). Mirrors edge_ramp() in volume.frag.

    The crossing lies ``delta`` from the face along its axis a (positive
    into the voxel), ``delta / sqrt(1 - n_a^2)`` from the edge across the
    plane; seen along w that shrinks by ``|n . w| / sqrt(1 - (t . w)^2)``
    (t the edge's direction), giving ``delta |n . w| / sqrt(1 - n_a^2 -
    (w x n)_a^2)``. A box footprint across the edge: a ramp of that
    distance over the footprint's width, 1/2 on the edge."""
    face = np.asarray(face, dtype=np.int64).reshape(-1)
    p = np.asarray(point, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
    w = np.asarray(w, dtype=np.float64)
    foot = np.broadcast_to(np.asarray(foot, dtype=np.float64), face.shape)
    a, side = face // 2, face % 2
    idx = np.arange(len(face))
    pa = p[idx, a]
    delta = np.where(side == 1, 1.0 - pa, pa)
    na = n[idx, a]
    ca = np.cross(w[None, :], n)[idx, a]
    den = np.sqrt(np.maximum(1.0 - na * na - ca * ca, 1e-12))
    dist = delta * np.abs(n @ w) / den
    sign = 1.0 if inside else -1.0
    return np.clip(0.5 + sign * dist / np.maximum(foot, 1e-12), 0.0, 1.0)


def _angle_code(angle: np.ndarray) -> np.ndarray:
    """8-bit code of angles in [-pi, pi) (as volume.frag decodes them)."""
    return np.round((np.asarray(angle, dtype=np.float64) + np.pi) * (256 / (2 * np.pi))).astype(np.int64) % 256


def quantised_angle(angle: np.ndarray) -> np.ndarray:
    """``angle`` (radians) as the GPU reads it back: 8 bits over the turn."""
    return _angle_code(angle) * (2 * np.pi / 256) - np.pi


def edge_words(
    face: np.ndarray, kind: np.ndarray, angle: np.ndarray, halo_face: np.ndarray | None = None,
) -> np.ndarray:  # fmt: skip
    """(N,) uint32, an entry's edges as volume.frag reads them (entry word
    11): bits 0-2 the first edge's face (:data:`NO_FACE`: none), bit 3 its
    kind, bits 4-7 the same of the second, bits 8-10 the face of a halo's
    edge (:data:`NO_FACE`: the entry is no halo), bits 11-18 and 19-26 the
    two edges' angles (:func:`quantised_angle`). ``face``, ``kind`` and
    ``angle`` (N, 2) (face -1: none); a halo's edge is its first, with no
    face but ``halo_face`` (N,)."""
    f = np.where(np.asarray(face) >= 0, np.asarray(face), NO_FACE).astype(np.uint32)
    k = np.asarray(kind).astype(np.uint32) & 1
    q = _angle_code(angle).astype(np.uint32)
    hf = np.full(len(f), NO_FACE) if halo_face is None else np.asarray(halo_face)
    h = np.where(hf >= 0, hf, NO_FACE).astype(np.uint32)
    return f[:, 0] | (k[:, 0] << 3) | (f[:, 1] << 4) | (k[:, 1] << 7) | (h << 8) | (q[:, 0] << 11) | (q[:, 1] << 19)


def edge_factors(
    face: np.ndarray, kind: np.ndarray, angle: np.ndarray, point: np.ndarray, normal: np.ndarray,
    w: np.ndarray, foot: np.ndarray, halo: bool,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """What a sheet's edge on voxel face ``face`` (N,) leaves of its coverage
    and of its colour's weight, each (N,) in [0, 1], where the ray (unit
    ``w``) crosses its plane at the voxel-local ``point`` (N, 3); ``normal``
    (N, 3) unit, ``kind`` and ``angle`` (N,) as in :class:`SheetEdges`.
    ``halo``: the sheet lies past the face (a halo), else in the voxel.
    Mirrors edge_factors() in volume.frag.

    With ``ramp`` the footprint's share on the sheet's side (:func:`edge_ramp`):

    - an open edge: both the ramp (a halo: its share past the edge);
    - a crease that is a silhouette in this view (the two half-planes on
      the same side of the edge on screen, so that past it lies what is
      behind): the same, but the halo of the face turned away (the hidden
      one: ``sin(phi) (n . w) <= 0``) carries nothing, the visible face
      covering that share of the footprint;
    - any other crease (both faces seen, or a concave corner): the sheet's
      coverage whole (the other face covers the rest of the footprint; a
      share would leak where the ray misses the other's halo), its colour
      weighted by the ramp; a halo both the ramp, for the colour."""
    face = np.asarray(face, dtype=np.int64).reshape(-1)
    n = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
    w = np.asarray(w, dtype=np.float64)
    ramp = edge_ramp(face, point, n, w, foot, inside=not halo)
    u = inward(face, n) * (-1.0 if halo else 1.0)
    nu = np.cross(w[None, :], np.cross(n, u))
    al, be = np.einsum("ek,ek->e", nu, u), np.einsum("ek,ek->e", nu, n)
    angle = np.asarray(angle, dtype=np.float64).reshape(-1)
    silhouette = al * (al * np.cos(angle) + be * np.sin(angle)) > 0.0
    crease = np.asarray(kind).reshape(-1) == CREASE
    if halo:
        hidden = crease & silhouette & (np.sin(angle) * (n @ w) <= 0.0)
        cov = np.where(hidden, 0.0, ramp)
        return cov, cov
    return np.where(crease & ~silhouette, 1.0, ramp), ramp
