"""Which side of a patch of faces the outside sees.

Modelling tools build solids of patches that meet three or more to an
edge: a building's walls meet its floors, a box's lid is a separate piece
whose edges its walls share. Such a patch (a closed component of the
mesh's topology that ends at such an edge,
:func:`~aniso3d.build.mesh.face_topology`) is no closed surface by itself,
so the sign of its own signed volume says nothing of which way it faces;
whether it is a solid's skin or a wall inside is a question of what the
outside sees of it.

So points just off a patch's faces on either side (the centroids of up to
:data:`SAMPLE_FACES` of its largest faces, fewer when a mesh has more
patches than :data:`SAMPLE_BUDGET` allows for) cast rays in :data:`RAYS`
fixed directions, each turned into that side's half-space, against the
faces of the whole that the patch and the patches it meets at such edges
make (a building, not the next one in its street). A side whose rays
escape (meet no face) is seen from outside. A patch whose front escapes
and whose back does not (at most :data:`ONE_SIDED` of the front's share)
is a skin wound outwards, +1; the reverse, -1; a patch seen from both
sides is open, 0; one seen from neither (a wall inside) is
:data:`ENCLOSED`.

Rays are cast in a frame whose x axis is the ray's direction, through a
grid of columns over the faces' (y, z) boxes; each edge's crossing test is
computed once, in one orientation, and shared by the faces beside it, so a
ray through an edge meets exactly one of them.
"""

from __future__ import annotations

import numpy as np

#: Faces per patch whose centroids cast rays (its largest)...
SAMPLE_FACES = 32
#: ... and in all, at least one a patch (:data:`~aniso3d.build.mesh.OUTSIDE_PATCHES`
#: bounds the patches): at most 2^17 points, 2^21 rays.
SAMPLE_BUDGET = 1 << 17

#: Ray directions per test point, before normalising: spread over the
#: sphere and off every axis, diagonal and plane a modelling tool snaps to.
RAYS = (
    (0.8219, 0.3331, 0.4619),
    (-0.3113, 0.8807, 0.3571),
    (0.2393, -0.4121, 0.8791),
    (-0.7734, -0.5219, 0.3597),
    (0.4107, 0.7123, -0.5691),
    (-0.5023, 0.2119, -0.8387),
    (0.6171, -0.6719, -0.4097),
    (-0.0921, -0.3329, -0.9384),
)

#: How far off a face its test points lie, as a share of the mesh's extent.
OFFSET_SHARE = 2.0**-16

#: A patch is one-sided when the share of its back's rays that escape is at
#: most this share of its front's (or the reverse).
ONE_SIDED = 0.25

#: The least share of a side's rays that must escape for it to be seen.
SEEN = 0.05

#: :func:`outside_sides`' answer for a patch seen from neither side (no ray
#: from it escapes): it lies inside its whole (a storey's roof under the next storey's floor, where
#: two parts of an assembly touch), and no view of the whole shows it.
ENCLOSED = 2

#: Query-candidate pairs tested at once (bounds the memory of a cast).
PAIR_BATCH = 1 << 21

#: At most this many columns per axis of a cast's grid.
COLUMN_CELLS = 1024

#: A cast's columns are made coarser until its faces' copies into them
#: are at most this many per face (bounds its memory).
COLUMN_COPIES = 8

#: Cells per axis of the grid that drops the faces no test ray can meet.
CULL_CELLS = 1024

#: Bits of a face's far end along the ray in a cast's sort key (a coarse,
#: conservative cut of the faces behind a point; the exact test follows).
X_BITS = 16


def outside_sides(vertices: np.ndarray, faces: np.ndarray, ids: np.ndarray, patch: np.ndarray,
                  wanted: np.ndarray, whole: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """(P,) int8 the side of each patch in ``wanted`` (labels into
    ``patch``) that the outside sees (see the module): +1 its faces' normals
    face it, -1 they face away, 0 both, :data:`ENCLOSED` neither. ``faces`` (F, 3) are the
    faces rays are cast against (indices into ``vertices``), ``ids`` (F, 3)
    their corners' merged position ids
    (:func:`~aniso3d.build.mesh.merged_vertices`), ``patch`` (F,) each
    face's patch label, ``whole`` (F,) the label of the whole it belongs to
    (rays from a patch meet only its whole's faces; None: one whole)."""
    wanted = np.asarray(wanted, dtype=np.int64)
    out = np.zeros(len(wanted), dtype=np.int8)
    if len(wanted) == 0:
        return out
    v = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    ids = np.asarray(ids, dtype=np.int64)
    # One position per merged id (the first vertex holding it).
    first = np.full(int(ids.max()) + 1, -1, dtype=np.int64)
    first[ids.reshape(-1)[::-1]] = faces.reshape(-1)[::-1]
    whole = np.zeros(len(faces), np.int64) if whole is None else np.unique(whole, return_inverse=True)[1]
    used = v[first[first >= 0]]
    lo = used.min(axis=0)
    extent = float(np.ptp(used, axis=0).max())
    if not np.isfinite(extent) or not extent > 0.0:
        return out
    pos = (v[first] - lo) / extent  # the whole mesh within the unit cube: no overflow
    tri = pos[ids]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(cross, axis=1)
    # The sample: each wanted patch's largest faces.
    slot = np.full(int(patch.max()) + 1, -1, dtype=np.int64)
    slot[wanted] = np.arange(len(wanted))
    mine = np.flatnonzero((slot[patch] >= 0) & (area > 0))
    order = np.lexsort((-area[mine], slot[patch[mine]]))
    mine = mine[order]
    rank = np.arange(len(mine)) - np.searchsorted(slot[patch[mine]], slot[patch[mine]], side="left")
    mine = mine[rank < int(np.clip(SAMPLE_BUDGET // len(wanted), 1, SAMPLE_FACES))]
    if len(mine) == 0:
        return out
    normal = cross[mine] / area[mine, None]
    centroid = tri[mine].mean(axis=1)
    # The offset scales with the extent of each point's whole (a wall a
    # thousandth of its building thick stays thicker than it, however far
    # the next building).
    corners = tri.reshape(-1, 3)
    owner = np.repeat(whole, 3)
    wlo = np.full((int(whole.max()) + 1, 3), np.inf)
    whi = np.full((int(whole.max()) + 1, 3), -np.inf)
    np.minimum.at(wlo, owner, corners)
    np.maximum.at(whi, owner, corners)
    eps = OFFSET_SHARE * (whi - wlo).max(axis=1)[whole[mine], None]
    weight = area[mine]
    seen = np.zeros((2, len(wanted)))
    tried = np.zeros((2, len(wanted)))
    dirs = np.asarray(RAYS, dtype=np.float64)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    group = slot[patch[mine]]
    points = [centroid + sign * eps * normal for sign in (1.0, -1.0)]
    for d in dirs:
        caster = _Caster(pos, ids, d, whole, near=np.concatenate(points))
        for k, sign in enumerate((1.0, -1.0)):
            # Each side casts along d or -d, whichever points into its half-space.
            forward = normal @ d * sign > 0.0
            free = caster.escapes(points[k], whole[mine], forward)
            seen[k] += np.bincount(group, weights=weight * free, minlength=len(wanted))
            tried[k] += np.bincount(group, weights=weight, minlength=len(wanted))
    with np.errstate(divide="ignore", invalid="ignore"):
        front, back = np.where(tried > 0, seen / tried, 0.0)
    out[(front >= SEEN) & (back <= ONE_SIDED * front)] = 1
    out[(back >= SEEN) & (front <= ONE_SIDED * back)] = -1
    # No ray from either side escapes (not even SEEN's few: a patch seen a
    # little, through a window, is left drawn).
    out[(tried[0] > 0) & (seen[0] == 0) & (seen[1] == 0)] = ENCLOSED
    return out


class _Caster:
    """Rays along one direction against every face, through a grid of
    columns in a frame whose x axis is that direction."""

    def __init__(self, pos: np.ndarray, ids: np.ndarray, direction: np.ndarray, whole: np.ndarray | None = None,
                 near: np.ndarray | None = None):  # fmt: skip
        """``near``: the points rays will be cast from (as :meth:`escapes`
        takes them), when known: faces whose (y, z) box holds none of them
        are dropped first (no ray from them can meet one), which turns a
        large scan's few test rays from seconds per direction into a
        fraction of one."""
        a = np.cross(direction, [0.0, 0.0, 1.0])
        if np.linalg.norm(a) < 1e-6:
            a = np.cross(direction, [0.0, 1.0, 0.0])
        a /= np.linalg.norm(a)
        self.frame = np.stack([direction, a, np.cross(direction, a)])
        p = pos @ self.frame.T
        whole = np.zeros(len(ids), np.int64) if whole is None else np.asarray(whole, np.int64)
        if near is not None:
            held = _boxes_holding(p[:, 1:], ids, (np.asarray(near, np.float64) @ self.frame.T)[:, 1:])
            ids, whole = ids[held], whole[held]
        corner = p[ids]
        y, z = corner[..., 1], corner[..., 2]
        area = (y[:, 1] - y[:, 0]) * (z[:, 2] - z[:, 0]) - (z[:, 1] - z[:, 0]) * (y[:, 2] - y[:, 0])
        keep = area != 0  # seen edge on: never met
        self.ids, self.corner, self.area = ids[keep], corner[keep], area[keep]
        self.whole = whole[keep]
        self.lo, hi = p.min(axis=0), p.max(axis=0)
        yz = self.corner[:, :, 1:]
        ext = (yz.max(axis=1) - yz.min(axis=1)).max(axis=1)
        typical = float(np.median(ext)) if len(ext) else 0.0
        width = float((hi - self.lo)[1:].max())
        cells = int(np.clip(width / typical if typical > 0 else 1, 1, COLUMN_CELLS))
        # Coarser columns where long faces (a fan of slivers across a CAD
        # part's flat face) would copy themselves into too many of them.
        while True:
            self.cells = cells
            self.step = np.maximum((hi - self.lo)[1:] / self.cells, 1e-300)
            c0, c1 = self._column(yz.min(axis=1)), self._column(yz.max(axis=1))
            span = c1 - c0 + 1
            if cells == 1 or int((span[:, 0] * span[:, 1]).sum()) <= COLUMN_COPIES * len(span) + (1 << 16):
                break
            cells = max(1, cells // 2)
        owner, k = _expand(span[:, 0] * span[:, 1])
        col = (self.whole[owner] * self.cells + c0[owner, 0] + k % span[owner, 0]) * self.cells + (
            c0[owner, 1] + k // span[owner, 0]
        )
        self.x_scale = float(1 << (X_BITS - 1)) / max(float((hi - self.lo).max()), 1e-300)
        # Two orders of the same columns: by the faces' far ends along the
        # ray (rays along +x meet those past their point) and by their near
        # ends (rays along -x).
        top = (1 << X_BITS) - 1
        xs = (self.corner[owner, :, 0] - self.lo[0]) * self.x_scale
        self.keys, self.owners = [], []
        for end in (np.clip(np.ceil(xs.max(axis=1)), 0, top), np.clip(np.floor(xs.min(axis=1)), 0, top)):
            key = (col << X_BITS) + end.astype(np.int64)
            order = np.argsort(key, kind="stable")
            self.keys.append(key[order])
            self.owners.append(owner[order])
        self._tables()

    def _tables(self) -> None:
        """Per face, what a ray's test reads: its (y, z) box; per edge, from
        its lower position id to its higher, the start, the direction, the
        sign an exact 0 takes and the sign a point inside the face gives;
        and its plane as x = a + b y + c z."""
        c, ids = self.corner, self.ids
        yz = c[:, :, 1:]
        self.box = np.concatenate([yz.min(axis=1), yz.max(axis=1)], axis=1)  # ymin zmin ymax zmax
        orient = np.sign(self.area)
        edges = np.empty((len(ids), 3, 6))
        for e in range(3):
            i, j = ids[:, e], ids[:, (e + 1) % 3]
            flip = i > j
            p0 = np.where(flip[:, None], yz[:, (e + 1) % 3], yz[:, e])
            p1 = np.where(flip[:, None], yz[:, e], yz[:, (e + 1) % 3])
            d = p1 - p0
            edges[:, e, 0:2] = p0
            edges[:, e, 2:4] = d
            edges[:, e, 4] = np.where((d[:, 0] > 0) | ((d[:, 0] == 0) & (d[:, 1] > 0)), 1.0, -1.0)
            edges[:, e, 5] = np.where(flip, -orient, orient)
        self.edges = edges
        n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
        b, cc = -n[:, 1] / n[:, 0], -n[:, 2] / n[:, 0]
        self.plane = np.stack([c[:, 0, 0] - b * c[:, 0, 1] - cc * c[:, 0, 2], b, cc], axis=1)

    def meets(self, q: np.ndarray, j: np.ndarray, forward: np.ndarray | bool = True) -> np.ndarray:
        """(N,) bool: the ray from ``q[i]`` (frame coordinates) along +x
        (``forward``; else along -x) meets face ``j[i]`` ahead of it. Each edge's test is computed from
        its lower position id to its higher, so the two faces beside an edge
        get exactly opposite values; an exact 0 counts on the side the
        edge's direction picks."""
        box = self.box[j]
        qy, qz = q[:, 1], q[:, 2]
        near = (qy >= box[:, 0]) & (qy <= box[:, 2]) & (qz >= box[:, 1]) & (qz <= box[:, 3])
        idx = np.flatnonzero(near)
        q, j, qy, qz = q[idx], j[idx], qy[idx], qz[idx]
        forward = np.broadcast_to(forward, near.shape)[idx]
        e = self.edges[j]
        s = e[..., 2] * (qz[:, None] - e[..., 1]) - e[..., 3] * (qy[:, None] - e[..., 0])
        s = np.where(s == 0, e[..., 4], s)
        inside = np.all(s * e[..., 5] > 0, axis=1)
        pl = self.plane[j]
        x = pl[:, 0] + pl[:, 1] * qy + pl[:, 2] * qz
        ahead = np.where(forward, x > q[:, 0], x < q[:, 0])
        out = np.zeros(len(near), dtype=bool)
        out[idx] = inside & ahead
        return out

    def _column(self, yz: np.ndarray) -> np.ndarray:
        return np.clip(((yz - self.lo[1:]) / self.step).astype(np.int64), 0, self.cells - 1)

    def escapes(self, points: np.ndarray, whole: np.ndarray | None = None,
                forward: np.ndarray | bool = True) -> np.ndarray:  # fmt: skip
        """(P,) bool: the ray from each point (world frame, less the mesh's
        minimum corner) along the direction (``forward``; else against it)
        meets no face (of the point's ``whole``)."""
        p = points @ self.frame.T
        n = len(p)
        whole = np.zeros(n, np.int64) if whole is None else np.asarray(whole, np.int64)
        forward = np.broadcast_to(np.asarray(forward, dtype=bool), (n,))
        hit = np.zeros(n, dtype=bool)
        if n == 0 or len(self.ids) == 0:
            return ~hit
        c = self._column(p[:, 1:])
        col = ((whole * self.cells + c[:, 0]) * self.cells + c[:, 1]) << X_BITS
        xs = (p[:, 0] - self.lo[0]) * self.x_scale
        top = (1 << X_BITS) - 1
        fk, bk = self.keys
        lo_f = np.searchsorted(fk, col + np.clip(np.floor(xs), 0, top).astype(np.int64), "left")
        hi_f = np.searchsorted(fk, col + (1 << X_BITS), "left")
        lo_b = np.searchsorted(bk, col, "left")
        hi_b = np.searchsorted(bk, col + np.clip(np.ceil(xs), 0, top).astype(np.int64), "right")
        # Candidates nearest first (by their far end ahead, their near end
        # behind), in rounds of 1, 2, 4, ... per ray: a ray stops at its
        # first hit, as most rays into a solid do within a few.
        many = np.where(forward, hi_f - lo_f, hi_b - lo_b)
        done, width = 0, 1
        active = np.flatnonzero(many > 0)
        while len(active):
            m = np.minimum(many[active] - done, width)
            ends = np.cumsum(m)
            a = 0
            while a < len(active):
                b = max(int(np.searchsorted(ends, (ends[a - 1] if a else 0) + PAIR_BATCH, side="right")), a + 1)
                row, k = _expand(m[a:b])
                who = active[a + row]
                kk = done + k
                fw = forward[who]
                j = np.where(fw, self.owners[0][np.minimum(lo_f[who] + kk, len(fk) - 1)],
                             self.owners[1][np.clip(hi_b[who] - 1 - kk, 0, len(bk) - 1)])  # fmt: skip
                hit[who[self.meets(p[who], j, fw)]] = True
                a = b
            done += width
            width *= 2
            active = active[~hit[active] & (many[active] > done)]
        return ~hit


def _boxes_holding(yz: np.ndarray, ids: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(F,) bool: whether the (y, z) box of each face (corners ``ids`` (F, 3)
    into positions ``yz`` (V, 2)) may hold one of ``points`` (P, 2): the
    points binned into a grid of about as many cells as faces (at most
    :data:`CULL_CELLS` a side) over the positions' box (clamped at its
    border), a face kept when its box's cells hold one (a summed-area
    table: one look-up per face). Conservative: a face dropped holds no
    point (the cells are monotone in y and z, so a point inside a box falls
    between its corners' cells)."""
    n = len(ids)
    if n == 0 or len(points) == 0:
        return np.zeros(n, dtype=bool)
    cells = int(np.clip(np.ceil(np.sqrt(n)), 1, CULL_CELLS))
    g_lo = yz.min(axis=0)
    step = np.maximum((yz.max(axis=0) - g_lo) / cells, 1e-300)

    def cell(q: np.ndarray) -> np.ndarray:
        return np.clip(np.floor((q - g_lo) / step), 0, cells - 1).astype(np.int32)

    table = np.zeros((cells + 1, cells + 1), dtype=np.int64)
    c = cell(points)
    np.add.at(table, (c[:, 0] + 1, c[:, 1] + 1), 1)
    table = table.cumsum(axis=0).cumsum(axis=1)
    vc = cell(yz)[ids]  # (F, 3, 2): the corners' cells
    c0 = np.minimum(np.minimum(vc[:, 0], vc[:, 1]), vc[:, 2])
    c1 = np.maximum(np.maximum(vc[:, 0], vc[:, 1]), vc[:, 2]) + 1
    held = table[c1[:, 0], c1[:, 1]] - table[c0[:, 0], c1[:, 1]] - table[c1[:, 0], c0[:, 1]] + table[c0[:, 0], c0[:, 1]]
    return held > 0


def _expand(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(row, k)``: each row index repeated its count, and k = 0, 1, ... within it."""
    counts = np.asarray(counts, dtype=np.int64)
    row = np.repeat(np.arange(len(counts)), counts)
    return row, np.arange(len(row)) - np.repeat(np.cumsum(counts) - counts, counts)
