"""Streaming, parallel registration whose result does not depend on the chunks.

Registration is a sum over sub-polygons (METHOD.md, paper section 2.2): every
piece adds ``S |N . N_p|`` to its voxel's density sphere and ``S``, ``S k_d``,
``S k_s``, ``S n``, ``S c`` and ``S N`` to one shading entry. A texture built
from chunks of triangles is therefore the sum of the chunks' textures, and a
build can stream a mesh of any size through a bounded amount of memory,
clipping chunks in parallel (local processes or a Dask cluster).

Floating-point addition is not associative, so summing chunk by chunk in
float64 would make the result depend on the chunk size and on the order in
which workers finish. Here every contribution is rounded once, on its own, to
a fixed-point number, and fixed-point numbers are summed as integers, which is
exact and associative. The texture is then a function of the set of
triangles alone: bit for bit the same for any chunk size, any number of
workers, any reduction order (a Dask tree reduction, a worker's chunk redone
elsewhere), and any order of the faces.

Every sum is a 128-bit fixed-point number with :data:`FRAC_BITS` = 84
fractional bits (areas in units of h^2): a quantum of 2^-84 h^2 (5e-26) and
sums up to 2^43. A piece of area S and its weighted values ``S x`` (``x``:
k_d, k_s, n, the centroid within its cell, the unit normal) are rounded in
the same scale, so a mean ``sum(S x) / sum(S)`` stays within the range of
``x`` even for an entry made of slivers, and keeps full float32 precision
for any entry above ~1e-18 h^2 (the tests' 1e-12 m^2 triangles at a 10 m
grid's 0.078 m voxels are found to 1e-9). A value is held as two words,
``hi`` (int64) and ``lo`` (uint64), value ``hi * 2^64 + lo``; while summing
within a chunk it is split into int64 limbs (two of 44 bits for values below
:data:`SMALL_VALUE`, which is nearly all of them, else three of 32 bits: the
same integer either way) so that ``np.add.reduceat`` cannot overflow.
Converting a sum back to float64 rounds at most twice (deterministically).
Sums that could leave the format (an entry of more than
:data:`MAX_ENTRY_AREA` h^2, pieces of more than :data:`MAX_PIECE_VALUE`:
only geometry far outside the grid) are refused rather than wrapped around.
Pieces smaller than half a quantum (clipping's ~1e-30 h^2 slivers) are not
registered at all.

Cost, measured on trees at 128^3: the sums take about a third of the time of
clipping, and hold 16 bytes per density value and ~210 per shading entry
until the end (a float texture holds 8 and 68).

Module layout: :class:`TriangleChunk` (what a chunk reader yields),
:class:`Partial` (the exact sums of one chunk, or of several merged), the
chunk function :func:`chunk_partial`, :func:`merge_partials` (Dask's tree
reduction), :class:`ExactTable` (the local accumulator, grown in place in
blocks so that merging never holds two copies), and :func:`run_chunks`, which
feeds chunks to an executor: in process, a local process pool, or a Dask
client.
"""

from __future__ import annotations

import math
import multiprocessing
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, replace

import numpy as np

from aniso3d.build.clip import Grid, clip_to_grid, triangle_normals
from aniso3d.build.closure import hidden_sides
from aniso3d.errors import InputError, ResourceError
from aniso3d.grid import cell_coords, cell_keys

# ------------------------------------------------------------- fixed point

#: Fractional bits of every exact sum (values in units of h^2).
FRAC_BITS = 84
#: Summed columns of a shading entry: S, S (c - cell) (3), S k_d (3), S k_s,
#: S n, S N (3), and of its pieces on closed surfaces (TriangleChunk.closed)
#: S and S N (3), N turned outwards.
ENTRY_COLUMNS = 16
#: The Phong exponent is summed as ``S n 2^-14`` (exact scaling), so that
#: every summed value of a piece inside the grid is small (SMALL_VALUE).
SHININESS_SCALE = 2.0**-14
#: Largest facet area in one shading entry, h^2 (with n <= 1e4, keeps every
#: sum far below 2^43).
MAX_ENTRY_AREA = 2.0**28
#: Largest value one piece may add (``S n``, ``S (c - cell)``), h^2: pieces
#: inside the grid add < 2e4; only geometry far outside the bounds a build was
#: given can add more.
MAX_PIECE_VALUE = 2.0**31
#: Values quantised per batch while summing within a chunk (bounds the limbs'
#: working memory, ~30 bytes per value).
BATCH_VALUES = 1 << 20
#: Triangles clipped per batch within a chunk: bounds the clipper's working
#: memory (~1.2 kB per piece: ~35 MB on a tree at 128^3) whatever the chunk
#: size; 8192 clips a tree 1.3x faster in CPU time than 65536 (cache).
CLIP_BATCH = 8192
#: Most sub-polygons summed per batch (fewer when K is large: BATCH_VALUES).
REGISTER_BATCH = 32768

_MASK32 = np.int64(0xFFFFFFFF)
_TWO64 = 2.0**64


def _split3(v: np.ndarray, frac_bits: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Round float64 ``v`` to the nearest multiple of ``2^-frac_bits`` as three
    int64 limbs ``(l2, l1, l0)`` with value ``(l2 2^64 + l1 2^32 + l0) 2^-frac_bits``
    and ``0 <= l1, l0 <= 2^32``: sums of up to 2^31 of them cannot overflow."""
    x = v * 2.0 ** (frac_bits - 64)
    l2 = np.floor(x)
    x -= l2
    x *= 2.0**32
    l1 = np.floor(x)
    x -= l1
    x *= 2.0**32
    np.rint(x, out=x)
    return l2.astype(np.int64), l1.astype(np.int64), x.astype(np.int64)


#: Values below this (in h^2) are split into two limbs, not three: most are
#: (S <= ~2 inside the grid), and two limbs of a batch of REGISTER_BATCH rows
#: cannot overflow below it. Both splits give the same integer.
SMALL_VALUE = 64.0
_MASK44 = np.int64((1 << 44) - 1)
_MASK20 = np.int64((1 << 20) - 1)


def _split2(v: np.ndarray, frac_bits: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_split3` for ``|v| < SMALL_VALUE``: ``round(v 2^frac_bits)`` as
    ``l1 2^44 + l0`` with ``0 <= l0 <= 2^44``."""
    x = v * 2.0 ** (frac_bits - 44)
    l1 = np.floor(x)
    x -= l1
    x *= 2.0**44
    np.rint(x, out=x)
    return l1.astype(np.int64), x.astype(np.int64)


def _join2(l1: np.ndarray, l0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Carry summed two-limb values into the two-word form."""
    c = l0 >> 44
    l0 = l0 & _MASK44
    l1 = l1 + c
    lo = ((l1 & _MASK20).astype(np.uint64) << np.uint64(44)) | l0.astype(np.uint64)
    return l1 >> 20, lo


def _join3(l2: np.ndarray, l1: np.ndarray, l0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Carry summed limbs into the two-word form ``(hi int64, lo uint64)``."""
    c = l0 >> 32
    l0 = l0 & _MASK32
    l1 = l1 + c
    c = l1 >> 32
    l1 = l1 & _MASK32
    hi = l2 + c
    lo = (l1.astype(np.uint64) << np.uint64(32)) | l0.astype(np.uint64)
    return hi, lo


def _add128(hi_a, lo_a, hi_b, lo_b) -> tuple[np.ndarray, np.ndarray]:
    """Exact sum of two arrays of 128-bit numbers given as (hi, lo) words."""
    lo = lo_a + lo_b  # wraps modulo 2^64; the carry is the wrap
    carry = (lo < lo_a).astype(np.int64)
    return hi_a + hi_b + carry, lo


def _to_float(hi: np.ndarray, lo: np.ndarray, frac_bits) -> np.ndarray:
    """float64 value of 128-bit fixed-point numbers (at most two roundings;
    negative numbers are converted through their magnitude, so small negative
    sums keep their precision)."""
    neg = hi < 0
    if np.any(neg):
        hi = hi.copy()
        lo = lo.copy()
        lo[neg] = ~lo[neg] + np.uint64(1)
        hi[neg] = ~hi[neg] + (lo[neg] == 0)
    mag = hi.astype(np.float64) * _TWO64 + lo.astype(np.float64)
    mag *= np.exp2(-np.asarray(frac_bits, dtype=np.float64))
    return np.where(neg, -mag, mag)


def exact_sum(values: np.ndarray) -> int:
    """The exact sum of float64 ``values`` as an integer count of 2^-1074
    (every double is a whole multiple of it); add such integers to combine
    partial sums in any order, and divide by ``2**1074`` for the correctly
    rounded float. Vectorised: one Python step per distinct exponent."""
    v = np.asarray(values, dtype=np.float64).ravel()
    v = v[v != 0]
    if not len(v):
        return 0
    if not np.all(np.isfinite(v)):
        raise InputError("cannot sum NaN or infinite values exactly")
    m, e = np.frexp(v)
    mant = np.ldexp(m, 53).astype(np.int64)  # exact: |m| < 1 has 53 bits
    order = np.argsort(e, kind="stable")
    e, mant = e[order], mant[order]
    starts = np.flatnonzero(np.r_[True, e[1:] != e[:-1]])
    # two 26/27-bit halves: sums of up to 2^36 values fit in int64
    high = np.add.reduceat(mant >> 26, starts)
    low = np.add.reduceat(mant & ((1 << 26) - 1), starts)
    total = 0
    for exp, h, lo in zip(e[starts].tolist(), high.tolist(), low.tolist(), strict=True):
        shift = exp - 53 + 1074
        part = (h << 26) + lo
        total += part << shift if shift >= 0 else part >> -shift  # low bits are zero there
    return total


def exact_to_float(total: int) -> float:
    """The correctly rounded float of a sum made by :func:`exact_sum`."""
    return total / 2**1074


# ------------------------------------------------------------------ chunks


@dataclass(frozen=True, eq=False)
class TriangleChunk:
    """A run of triangles with their materials: what a chunk reader yields.

    Attributes:
        triangles: (n, 3, 3) float64 corner positions, world units.
        kd: (n, 3) float32 diffuse reflectance.
        ks: (n,) float32 specular coefficient.
        shininess: (n,) float32 Phong exponent.
        closed: (n,) +1 or -1 where the face lies on a closed surface wound
            outwards or inwards, 0 elsewhere (:meth:`~aniso3d.build.mesh.Mesh.closed_sides`;
            a bool array: wound outwards); None: none does (readers that
            stream a file never see its topology whole).
    """

    triangles: np.ndarray
    kd: np.ndarray
    ks: np.ndarray
    shininess: np.ndarray
    closed: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.triangles)


@dataclass(eq=False)
class Partial:
    """Exact registration sums of a set of triangles (a chunk, or chunks merged).

    Attributes:
        voxel_keys: (M,) int64 sorted cell keys (:func:`aniso3d.grid.cell_keys`).
        density_hi, density_lo: (M, K) int64 / uint64 words of the density sums.
        entry_keys: (E,) int64 sorted ``voxel_key * K + p``.
        entry_hi, entry_lo: (E, 12) words of the entries' sums
            (:data:`ENTRY_COLUMNS`).
        n_triangles: triangles read (degenerate ones included).
        n_subpolygons: sub-polygons registered.
        area: exact facet area, world units^2, as :func:`exact_sum` integers.
        seconds: {"clip": s, "register": s} spent making it.
    """

    voxel_keys: np.ndarray
    density_hi: np.ndarray
    density_lo: np.ndarray
    entry_keys: np.ndarray
    entry_hi: np.ndarray
    entry_lo: np.ndarray
    n_triangles: int
    n_subpolygons: int
    area: int
    seconds: dict

    @property
    def nbytes(self) -> int:
        return int(sum(getattr(self, n).nbytes for n in (
            "voxel_keys", "density_hi", "density_lo", "entry_keys", "entry_hi", "entry_lo")))  # fmt: skip


def _segment_sums(
    seg: np.ndarray,
    n_seg: int,
    values: Callable[[int, int], np.ndarray],
    width: int,
    max_rows: int = REGISTER_BATCH,
) -> tuple[np.ndarray, np.ndarray]:
    """Exact per-segment sums of rows, in batches.

    ``seg`` (n,) holds each row's segment, ascending; ``values(r0, r1)``
    returns rows ``r0:r1`` as (b, width) float64. Returns the (n_seg, width)
    hi and lo words of the sums.
    """
    hi = np.zeros((n_seg, width), dtype=np.int64)
    lo = np.zeros((n_seg, width), dtype=np.uint64)
    n = len(seg)
    batch = max(1, min(max_rows, REGISTER_BATCH, BATCH_VALUES // max(1, 3 * width)))
    for r0 in range(0, n, batch):
        r1 = min(n, r0 + batch)
        s = seg[r0:r1]
        starts = np.flatnonzero(np.r_[True, s[1:] != s[:-1]])
        rows = slice(int(s[0]), int(s[-1]) + 1)  # segment ids are consecutive
        v = values(r0, r1)
        big = np.abs(v).max() if v.size else 0.0
        if not big <= MAX_PIECE_VALUE:
            raise InputError(
                f"a facet piece adds {big:.3g} voxel areas to one voxel: the mesh reaches far outside "
                "the bounds given to the build; pass bounds that contain the mesh"
            )
        if big < SMALL_VALUE:
            h, lw = _join2(*(np.add.reduceat(x, starts, axis=0) for x in _split2(v, FRAC_BITS)))
        else:
            h, lw = _join3(*(np.add.reduceat(x, starts, axis=0) for x in _split3(v, FRAC_BITS)))
        hi[rows], lo[rows] = _add128(hi[rows], lo[rows], h, lw)
    return hi, lo


def chunk_partial(
    chunk: TriangleChunk,
    grid: Grid,
    dirs: np.ndarray,
    report: Callable[[float, str], None] | None = None,
    check: Callable[[int, int], None] | None = None,
    batches: tuple[int, int] = (CLIP_BATCH, REGISTER_BATCH),
) -> Partial:
    """Clip a chunk of triangles into ``grid`` and register its pieces onto
    the K sample directions ``dirs`` (K, 3), as exact sums.

    ``report(fraction, stage)`` follows the chunk's progress; ``check(n_sub,
    n_voxels)`` is called once clipping has found the counts, before the
    (voxels, K) arrays exist (a build that cannot fit is refused there).
    ``batches``: triangles clipped and sub-polygons summed per batch (working
    memory only: the result does not depend on them).
    """
    clip_batch, register_batch = batches
    report = report or (lambda fraction, stage: None)
    t0 = time.perf_counter()
    world = np.asarray(chunk.triangles, dtype=np.float64)
    n = len(world)
    h = grid.voxel_size
    # Face areas as Mesh.face_areas computes them, summed exactly.
    area = exact_sum(0.5 * np.linalg.norm(np.cross(world[:, 1] - world[:, 0], world[:, 2] - world[:, 0]), axis=1))
    # Triangles relative to their first vertex, in units of h, plus that
    # vertex's grid position: keeps tiny triangles exact in shape anywhere.
    first = grid.to_grid(world[:, 0])
    tri = (world - world[:, :1]) / h
    del world
    normals, _ = triangle_normals(tri)
    cols: dict[str, list] = {"face": [], "cell": [], "area": [], "centroid": []}
    for start in range(0, n, clip_batch):
        stop = min(n, start + clip_batch)
        sub = clip_to_grid(tri[start:stop], normals[start:stop], grid.shape, np.arange(start, stop),
                           first=first[start:stop])  # fmt: skip
        # Pieces below half a quantum would add nothing (clipping's slivers of
        # ~1e-30 h^2): they are not registered, so no entry is made of nothing.
        keep = sub.area >= 2.0 ** -(FRAC_BITS + 1)
        for name in cols:
            cols[name].append(getattr(sub, name)[keep])
        del sub, keep
        report(0.8 * stop / max(n, 1), "clip")
    del tri, first
    face, cell, S, centroid = (np.concatenate(cols.pop(k)) for k in ("face", "cell", "area", "centroid"))
    t1 = time.perf_counter()
    n_sub = len(S)
    K = len(dirs)

    def dots(tri_normals: np.ndarray) -> np.ndarray:
        # N . N_p elementwise, not as a matrix product: BLAS may round a row
        # differently depending on the batch, and nothing may depend on batching
        nb = tri_normals
        return nb[:, 0:1] * dirs[:, 0] + nb[:, 1:2] * dirs[:, 1] + nb[:, 2:3] * dirs[:, 2]

    # The shading sample nearest each triangle's normal (pieces share it).
    nearest = np.empty(n, dtype=np.int64)
    step = max(1, BATCH_VALUES // max(1, K))
    for r0 in range(0, n, step):
        nearest[r0:r0 + step] = np.argmax(dots(normals[r0:r0 + step]), axis=1)
    # One sort by entry key (voxel key * K + nearest sample) orders the
    # pieces by voxel and, within a voxel, by sample: both sums run on it.
    key = cell_keys(cell, grid.shape) * K
    key += nearest[face]
    del nearest
    order = np.argsort(key, kind="stable")
    key = key[order]
    new_entry = np.r_[True, key[1:] != key[:-1]] if n_sub else np.zeros(0, bool)
    entry_keys = key[new_entry]
    eid = np.cumsum(new_entry) - 1
    del new_entry
    key //= K
    new_voxel = np.r_[True, key[1:] != key[:-1]] if n_sub else np.zeros(0, bool)
    vkeys = key[new_voxel]
    vid = np.cumsum(new_voxel) - 1
    del key, new_voxel
    M = len(vkeys)
    if check is not None:
        check(n_sub, M)

    def density(r0: int, r1: int) -> np.ndarray:
        idx = order[r0:r1]
        d = dots(normals[face[idx]])
        np.abs(d, out=d)
        d *= S[idx, None]
        return d

    dens_hi, dens_lo = _segment_sums(vid, M, density, K, register_batch)
    del vid
    report(0.9, "register")
    # Per triangle: k_d, k_s, n (scaled by 2^-14, exactly, so that every
    # summed value is small) and the normal: one gather per piece.
    # The closed columns: the face's area, and its normal turned outwards.
    side = np.zeros(n) if chunk.closed is None else np.asarray(chunk.closed, dtype=np.float64)
    per_face = np.concatenate([chunk.kd, chunk.ks[:, None], chunk.shininess[:, None] * np.float32(SHININESS_SCALE),
                               normals, np.abs(side)[:, None], side[:, None] * normals],
                              axis=1, dtype=np.float64)  # fmt: skip
    del side

    def entry(r0: int, r1: int) -> np.ndarray:
        idx = order[r0:r1]
        x = np.empty((len(idx), ENTRY_COLUMNS))
        x[:, 0] = 1.0
        np.subtract(centroid[idx], cell[idx], out=x[:, 1:4])  # the centroid within its cell, 0..1
        x[:, 4:] = per_face[face[idx]]
        x *= S[idx, None]
        return x

    e_hi, e_lo = _segment_sums(eid, len(entry_keys), entry, ENTRY_COLUMNS, register_batch)
    report(1.0, "register")
    return Partial(
        voxel_keys=vkeys,
        density_hi=dens_hi,
        density_lo=dens_lo,
        entry_keys=entry_keys,
        entry_hi=e_hi,
        entry_lo=e_lo,
        n_triangles=n,
        n_subpolygons=n_sub,
        area=area,
        seconds={"clip": t1 - t0, "register": time.perf_counter() - t1},
    )


# --------------------------------------------------------------- reduction


def merge_partials(*parts: Partial) -> Partial:
    """The exact sum of several partials (sorted union of their keys): the
    step of a tree reduction. Any grouping and order gives the same bits."""
    parts = [p for p in parts if p is not None]
    if len(parts) == 1:
        return parts[0]
    vkeys = np.unique(np.concatenate([p.voxel_keys for p in parts]))
    ekeys = np.unique(np.concatenate([p.entry_keys for p in parts]))
    K = parts[0].density_hi.shape[1]
    d_hi = np.zeros((len(vkeys), K), np.int64)
    d_lo = np.zeros((len(vkeys), K), np.uint64)
    e_hi = np.zeros((len(ekeys), ENTRY_COLUMNS), np.int64)
    e_lo = np.zeros((len(ekeys), ENTRY_COLUMNS), np.uint64)
    for p in parts:
        i = np.searchsorted(vkeys, p.voxel_keys)
        d_hi[i], d_lo[i] = _add128(d_hi[i], d_lo[i], p.density_hi, p.density_lo)
        j = np.searchsorted(ekeys, p.entry_keys)
        e_hi[j], e_lo[j] = _add128(e_hi[j], e_lo[j], p.entry_hi, p.entry_lo)
    seconds: dict = {}
    for p in parts:
        for k, v in p.seconds.items():
            seconds[k] = seconds.get(k, 0.0) + v
    return Partial(vkeys, d_hi, d_lo, ekeys, e_hi, e_lo,
                   sum(p.n_triangles for p in parts), sum(p.n_subpolygons for p in parts),
                   sum(p.area for p in parts), seconds)  # fmt: skip


class ExactTable:
    """Exact sums keyed by int64 keys, accumulated in place.

    Rows live in fixed-size blocks in the order their keys first arrived, with
    a sorted key index beside them: adding a partial touches only its own rows
    and appends new ones, so the table is never copied whole (a sorted-union
    merge would hold the old and the new table at once).
    """

    def __init__(self, width: int):
        self.width = width
        # blocks of ~1 MB: small tables stay small, big ones take ~1 step per MB
        self.shift = int(max(4, min(16, math.floor(math.log2(max(1, (1 << 20) // (16 * max(width, 1))))))))
        self.keys = np.zeros(0, dtype=np.int64)
        self.slots = np.zeros(0, dtype=np.int64)
        self.hi: list[np.ndarray] = []
        self.lo: list[np.ndarray] = []

    @property
    def n(self) -> int:
        return len(self.keys)

    @property
    def nbytes(self) -> int:
        return int(sum(b.nbytes for b in self.hi + self.lo) + self.keys.nbytes + self.slots.nbytes)

    def _groups(self, slots: np.ndarray):
        """(block, rows of ``slots`` in it, offsets in the block) per block touched."""
        block = slots >> self.shift
        offset = slots & ((1 << self.shift) - 1)
        order = np.argsort(block, kind="stable")
        if not len(order):
            return
        cuts = np.flatnonzero(np.r_[True, np.diff(block[order]) != 0, True])
        for a, b in zip(cuts[:-1], cuts[1:], strict=True):  # one step per block, not per row
            rows = order[a:b]
            yield int(block[rows[0]]), rows, offset[rows]

    def add(self, keys: np.ndarray, hi: np.ndarray, lo: np.ndarray) -> None:
        """Add rows (``keys`` sorted and distinct, (n, width) words) to the table."""
        if not len(keys):
            return
        pos = np.searchsorted(self.keys, keys)
        found = np.zeros(len(keys), dtype=bool)
        inside = pos < len(self.keys)
        found[inside] = self.keys[pos[inside]] == keys[inside]
        slot = np.empty(len(keys), dtype=np.int64)
        slot[found] = self.slots[pos[found]]
        new = ~found
        n_new = int(np.count_nonzero(new))
        if n_new:
            fresh = np.arange(self.n, self.n + n_new, dtype=np.int64)
            slot[new] = fresh
            # np.insert at sorted positions keeps the index sorted: O(n), no sort
            self.keys = np.insert(self.keys, pos[new], keys[new])
            self.slots = np.insert(self.slots, pos[new], fresh)
            size = 1 << self.shift
            while len(self.hi) * size < self.n:
                self.hi.append(np.zeros((size, self.width), np.int64))
                self.lo.append(np.zeros((size, self.width), np.uint64))
        for k, rows, off in self._groups(slot):
            self.hi[k][off], self.lo[k][off] = _add128(self.hi[k][off], self.lo[k][off], hi[rows], lo[rows])

    def drain(self):
        """Yield (slots, float64 values (n, width)) block by block in slot
        order, dropping each block's words once converted: the table's memory
        turns into the caller's float arrays instead of adding to them."""
        size = 1 << self.shift
        step = max(1, (4 << 20) // (16 * max(self.width, 1)))  # ~4 MB of words converted at a time
        for k in range(len(self.hi)):
            a, b = k * size, min(self.n, (k + 1) * size)
            for r0 in range(a, b, step):
                r1 = min(b, r0 + step)
                yield slice(r0, r1), _to_float(self.hi[k][r0 - a:r1 - a], self.lo[k][r0 - a:r1 - a], FRAC_BITS)
            self.hi[k] = self.lo[k] = None
        self.hi, self.lo = [], []

    @property
    def in_key_order(self) -> bool:
        """True if rows are stored in key order (a table made from one partial)."""
        return len(self.hi) <= 1 and bool(np.all(self.slots == np.arange(self.n)))

    @classmethod
    def from_rows(cls, keys: np.ndarray, hi: np.ndarray, lo: np.ndarray) -> ExactTable:
        """A table holding sorted rows as they are (one block, no copy)."""
        t = cls(hi.shape[1])
        t.shift = max(1, int(len(keys) - 1).bit_length())
        t.keys, t.slots = keys, np.arange(len(keys), dtype=np.int64)
        t.hi, t.lo = [hi], [lo]
        return t


@dataclass(eq=False)
class Accumulator:
    """The running sum of every chunk's partial: a voxel table (density) and
    an entry table (areas, centroids, materials, normals), plus counts."""

    voxels: ExactTable
    entries: ExactTable
    n_triangles: int = 0
    n_subpolygons: int = 0
    area: int = 0

    @classmethod
    def empty(cls, k: int) -> Accumulator:
        return cls(ExactTable(k), ExactTable(ENTRY_COLUMNS))

    @classmethod
    def of(cls, p: Partial) -> Accumulator:
        """An accumulator that is exactly one partial (no copy)."""
        return cls(
            ExactTable.from_rows(p.voxel_keys, p.density_hi, p.density_lo),
            ExactTable.from_rows(p.entry_keys, p.entry_hi, p.entry_lo),
            p.n_triangles, p.n_subpolygons, p.area,
        )  # fmt: skip

    def add(self, p: Partial) -> None:
        self.voxels.add(p.voxel_keys, p.density_hi, p.density_lo)
        self.entries.add(p.entry_keys, p.entry_hi, p.entry_lo)
        self.n_triangles += p.n_triangles
        self.n_subpolygons += p.n_subpolygons
        self.area += p.area

    @property
    def nbytes(self) -> int:
        return self.voxels.nbytes + self.entries.nbytes


def finalize(acc: Accumulator, grid: Grid, dirs: np.ndarray) -> dict:
    """The texture's arrays (see :class:`aniso3d.build.texture.AnisoTexture`)
    and counts from exact sums over the sample directions ``dirs`` (K, 3),
    with what thin solids hide of themselves taken out
    (:func:`aniso3d.build.closure.hidden_sides`). Sums are converted block by
    block as the tables drain, into arrays in slot order, then put in key
    order one array at a time: the peak is about the exact sums, not sums
    plus texture."""
    k = len(dirs)
    shape = np.asarray(grid.shape)
    vox, ent = acc.voxels, acc.entries
    vkeys, ekeys = vox.keys, ent.keys
    M, E = vox.n, ent.n

    def key_order(by_slot: np.ndarray, table: ExactTable, ordered: bool) -> np.ndarray:
        return by_slot if ordered else by_slot[table.slots]

    ordered = vox.in_key_order, ent.in_key_order
    density = np.empty((M, k))
    for rows, values in vox.drain():
        density[rows] = values
    density = key_order(density, vox, ordered[0])
    area = np.empty(E)
    local = np.empty((E, 3))
    kd = np.empty((E, 3), np.float32)
    ks = np.empty(E, np.float32)
    sh = np.empty(E, np.float32)
    normal = np.empty((E, 3), np.float32)
    closed_area = np.empty(E)
    closed_normal = np.empty((E, 3))
    for rows, v in ent.drain():
        a = v[:, 0]
        area[rows] = a
        # a mean is 0 where no area was registered (never NaN)
        mean = np.where((a > 0)[:, None], v[:, 1:] / np.where(a > 0, a, 1.0)[:, None], 0.0)
        local[rows] = mean[:, 0:3]
        kd[rows] = mean[:, 3:6]
        ks[rows] = mean[:, 6]
        sh[rows] = mean[:, 7] / SHININESS_SCALE
        normal[rows] = mean[:, 8:11]
        closed_area[rows] = v[:, 12]
        closed_normal[rows] = v[:, 13:16]
        del v, mean
    area, local, kd, ks, sh, normal, closed_area, closed_normal = (
        key_order(x, ent, ordered[1]) for x in (area, local, kd, ks, sh, normal, closed_area, closed_normal))
    if E and area.max() > MAX_ENTRY_AREA:
        raise ResourceError(
            f"a voxel holds {area.max():.3g} voxel faces' worth of facets facing one direction, more than "
            f"the {MAX_ENTRY_AREA:.3g} a build sums exactly; build at a higher resolution"
        )
    evk = ekeys // k
    offsets = np.zeros(M + 1, dtype=np.int64)
    offsets[1:] = np.cumsum(np.bincount(np.searchsorted(vkeys, evk), minlength=M))
    step = 1 << 16
    for r0 in range(0, E, step):  # in place: the centroid within its cell -> world
        r = slice(r0, r0 + step)
        local[r] = grid.origin + (cell_coords(evk[r], shape) + local[r]) * grid.voxel_size
    density, cover = hidden_sides(density, offsets, dirs, area, closed_area, closed_normal)
    return {
        "coords": cell_coords(vkeys, shape).astype(np.int32),
        "density": density,
        "entry_offsets": offsets,
        "entry_direction": (ekeys % k).astype(np.int32),
        "entry_area": area,
        "entry_kd": kd,
        "entry_ks": ks,
        "entry_shininess": sh,
        "entry_centroid": local,
        "entry_normal": normal,
        "entry_cover": cover,
        "entry_closed_area": closed_area,
        "entry_closed_normal": closed_normal,
        "n_triangles": acc.n_triangles,
        "n_subpolygons": acc.n_subpolygons,
        "mesh_area": exact_to_float(acc.area),
    }


def finalize_partial(p: Partial, grid: Grid, dirs: np.ndarray) -> dict:
    """:func:`finalize` of one partial (where a Dask reduction ends), with
    the seconds its chunks spent clipping and registering."""
    arrays = finalize(Accumulator.of(p), grid, dirs)
    arrays["seconds"] = dict(p.seconds)
    return arrays


# --------------------------------------------------------------- executors


def plan_chunks(n_faces: int, chunk_size: int) -> list[tuple[int, int]]:
    """(start, stop) face ranges of ``chunk_size`` faces (the last shorter)."""
    return [(a, min(n_faces, a + chunk_size)) for a in range(0, n_faces, chunk_size)]


def read_chunk(source, start: int, stop: int) -> TriangleChunk:
    """Faces ``start:stop`` of ``source`` with the closed-surface flags the
    source found before the build (``source.closed``), if any, less the
    faces that repeat an earlier one (``source.repeat``) and those their
    whole encloses (``source.enclosed``)."""
    chunk = source.read(start, stop)
    closed = getattr(source, "closed", None)
    if chunk.closed is None and closed is not None:
        chunk = replace(chunk, closed=closed[start:stop])
    left_out = np.zeros(stop - start, dtype=bool)
    for name in ("repeat", "enclosed"):
        faces = getattr(source, name, None)
        if faces is not None:
            left_out |= faces[start:stop]
    if left_out.any():
        keep = ~left_out
        chunk = TriangleChunk(chunk.triangles[keep], chunk.kd[keep], chunk.ks[keep], chunk.shininess[keep],
                              None if chunk.closed is None else chunk.closed[keep])  # fmt: skip
    return chunk


def _source_task(source, start: int, stop: int, grid: Grid, dirs: np.ndarray, batches) -> Partial:
    """A worker reads its own chunk (sources that pickle cheaply: paths)."""
    return chunk_partial(read_chunk(source, start, stop), grid, dirs, batches=batches)


def _chunk_task(chunk: TriangleChunk, grid: Grid, dirs: np.ndarray, batches) -> Partial:
    """A worker registers a chunk it was sent."""
    return chunk_partial(chunk, grid, dirs, batches=batches)


def run_chunks(
    source,
    grid: Grid,
    dirs: np.ndarray,
    chunk_size: int,
    *,
    workers: int = 1,
    client=None,
    retries: int = 2,
    report: Callable[[int, float, str], None] | None = None,
    check: Callable[..., None] | None = None,
    seconds: dict | None = None,
    batches: tuple[int, int] = (CLIP_BATCH, REGISTER_BATCH),
) -> dict:
    """Register every chunk of ``source`` and finalise: the texture's arrays.

    Executors: in this process (``workers == 1``, no client), a local pool of
    ``workers`` processes started with 'spawn' (never forking a process that
    may hold a GL context), or a Dask ``client`` (tree reduction on the
    workers, each task retried ``retries`` times; a dead worker's tasks are
    recomputed elsewhere). ``report(done, fraction_in_flight, stage)`` counts
    triangles done; ``check(n_sub, n_voxels, n_entries)`` may refuse a build
    whose sums outgrow the memory it has (``n_entries`` None: the counts of
    a one-chunk build, before its entries exist).
    """
    report = report or (lambda done, extra, stage: None)
    seconds = {} if seconds is None else seconds
    ranges = plan_chunks(source.n_faces, chunk_size)
    if client is not None:
        out = _run_dask(source, ranges, grid, dirs, batches, client, retries, report, seconds)
    elif workers <= 1:
        out = _run_here(source, ranges, grid, dirs, batches, report, check, seconds)
    else:
        out = _run_pool(source, ranges, grid, dirs, batches, workers, report, check, seconds)
    if isinstance(out, dict):
        return out
    t0 = time.perf_counter()
    arrays = finalize(out, grid, dirs)
    seconds["finish"] = seconds.get("finish", 0.0) + time.perf_counter() - t0
    return arrays


def _tally(seconds: dict, p: Partial) -> None:
    for k, v in p.seconds.items():
        seconds[k] = seconds.get(k, 0.0) + v


def _run_here(source, ranges, grid, dirs, batches, report, check, seconds) -> Accumulator:
    acc = None
    done = 0
    for a, b in ranges:
        t0 = time.perf_counter()
        chunk = read_chunk(source, a, b)
        seconds["read"] = seconds.get("read", 0.0) + time.perf_counter() - t0
        single = len(ranges) == 1
        p = chunk_partial(
            chunk, grid, dirs,
            report=lambda f, stage, d=done, n=b - a: report(d, f * n, stage),
            check=check if single else None, batches=batches,
        )  # fmt: skip
        del chunk
        _tally(seconds, p)
        t0 = time.perf_counter()
        if single:
            acc = Accumulator.of(p)
        else:
            acc = acc or Accumulator.empty(len(dirs))
            acc.add(p)
            del p  # before the next chunk is read
            if check is not None:
                check(acc.n_subpolygons, acc.voxels.n, acc.entries.n)
        seconds["merge"] = seconds.get("merge", 0.0) + time.perf_counter() - t0
        done += b - a
        report(done, 0.0, "register")
    return acc or Accumulator.empty(len(dirs))


def _run_pool(source, ranges, grid, dirs, batches, workers, report, check, seconds) -> Accumulator:
    acc = Accumulator.empty(len(dirs))
    portable = getattr(source, "portable", False)
    ctx = multiprocessing.get_context("spawn")
    pending: dict = {}
    todo = list(ranges)
    done = 0
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx)
    try:
        def submit():
            a, b = todo.pop(0)
            if portable:
                f = pool.submit(_source_task, source, a, b, grid, dirs, batches)
            else:
                t0 = time.perf_counter()
                chunk = read_chunk(source, a, b)
                seconds["read"] = seconds.get("read", 0.0) + time.perf_counter() - t0
                f = pool.submit(_chunk_task, chunk, grid, dirs, batches)
            pending[f] = b - a

        # One chunk in hand beyond the workers keeps them busy without
        # holding many chunks (or their results) at once.
        while todo and len(pending) < workers + 1:
            submit()
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for f in finished:
                n = pending.pop(f)
                p = f.result()
                _tally(seconds, p)
                t0 = time.perf_counter()
                acc.add(p)
                del p
                seconds["merge"] = seconds.get("merge", 0.0) + time.perf_counter() - t0
                if check is not None:
                    check(acc.n_subpolygons, acc.voxels.n, acc.entries.n)
                done += n
                report(done, 0.0, "register")
                if todo:
                    submit()
    except BrokenProcessPool:
        raise ResourceError(
            "a build worker process died (out of memory?); lower --workers or --memory-budget"
        ) from None
    finally:
        # on an error (or Ctrl-C) drop the chunks not started yet
        pool.shutdown(wait=True, cancel_futures=True)
    return acc


#: Partials merged per task of the Dask tree reduction.
FAN_IN = 2


def _run_dask(source, ranges, grid, dirs, batches, client, retries, report, seconds) -> dict:
    try:
        from distributed import as_completed
    except ImportError:
        raise _missing_dask() from None
    portable = getattr(source, "portable", False)
    futures = []
    sizes = {}
    for a, b in ranges:
        if portable:
            f = client.submit(_source_task, source, a, b, grid, dirs, batches, retries=retries, pure=False)
        else:
            f = client.submit(_chunk_task, read_chunk(source, a, b), grid, dirs, batches, retries=retries, pure=False)
        futures.append(f)
        sizes[f.key] = b - a
    level = list(futures)
    while len(level) > 1:
        level = [
            client.submit(merge_partials, *level[i:i + FAN_IN], retries=retries, pure=False)
            for i in range(0, len(level), FAN_IN)
        ]  # fmt: skip
    final = client.submit(finalize_partial, level[0], grid, dirs, retries=retries, pure=False)
    # Hold no future but the last: a result the client still references stays
    # in a worker's memory after its merge has used it.
    del level
    pending = as_completed(futures)
    futures.clear()
    done = 0
    for f in pending:
        done += sizes[f.key]
        report(done, 0.0, "register")
        del f
    t0 = time.perf_counter()
    arrays = final.result()
    seconds["finish"] = seconds.get("finish", 0.0) + time.perf_counter() - t0
    for k, v in arrays.pop("seconds").items():
        seconds[k] = seconds.get(k, 0.0) + v
    return arrays


def local_cluster(n_workers: int):
    """A Dask ``LocalCluster`` of ``n_workers`` worker processes of one thread
    each, for building on the spot (use it as a context manager).

    Dask starts workers with ``MALLOC_TRIM_THRESHOLD_=65536`` by default, which
    makes glibc hand every large temporary back to the system and fault it in
    again: the clipper's many temporaries then run 1.8x slower (measured on a
    1M-triangle tree). The workers made here keep glibc's own default.
    """
    try:
        import dask
        from distributed import LocalCluster
    except ImportError:
        raise _missing_dask() from None
    with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}):
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None)


def dask_workers(client) -> tuple[int, int | None]:
    """(number of workers, smallest worker memory limit in bytes or None) of
    a Dask client's cluster; a clear error if dask.distributed is missing."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise _missing_dask() from None
    try:
        info = client.scheduler_info()["workers"]
    except (AttributeError, KeyError, TypeError):
        raise InputError(f"client must be a dask.distributed.Client, got {type(client).__name__}") from None
    limits = [w.get("memory_limit") or 0 for w in info.values()]
    return max(1, len(info)), (min(limits) or None) if limits else None


def _missing_dask() -> ResourceError:
    return ResourceError(
        "building on a Dask cluster needs dask.distributed, which is not installed; "
        "install it with: pip install 'aniso3d[cluster]'"
    )
