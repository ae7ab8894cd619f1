"""The compact encoding of a texture: what an ``.a3d`` file of version 7 stores.

In memory a texture keeps float64 and float32 arrays, about 400 bytes per
occupied voxel of the default tree. To store it, each field is quantised no
finer than the images need, predicted from its neighbours where a surface
continues across voxels, and laid out so that LZMA (the zip container's
compression) finds what is left to squeeze: about 1/17 of the memory for the
default tree (docs/encoding.md). Loading decodes float arrays of the same
dtypes again. With the default :class:`Bits` (h the voxel edge; every bound
is tested in tests/test_encoding.py, the bits were chosen with
``demos/bench_encoding.py``):

==========================  ======================================================  ===============================
field                       stored as                                               error (default bits)
==========================  ======================================================  ===============================
origin, shape, directions   as they are                                             exact
coords                      sorted cell keys, delta-coded, in byte planes           exact
entry_offsets, _direction   one bit per voxel and sample direction (version 5: the  exact
                            odd voxels' bits in order of their neighbours')
entry_parent                per entry, 0 or which of 13 earlier neighbours it       exact
                            copies normal and materials from (see below; version
                            5: its rank among those with an entry there)
entry_area                  log2, 11 bits, over [max / 2**24, max]                  relative 0.41 %
entry_normal (direction)    about the sample direction N_p, 10 bits a coordinate,   0.14 degrees (0.07 at K = 16);
                            or octahedral with 12, whichever deflates smaller;      0.06 degrees; spread normals:
                            fewer bits for spread normals (version 5, below)        sigma / 16 or that
entry_normal (length) c     8 bits of sqrt(1 - c), steps of 1/255                   sqrt(1 - c) within 1/510
entry_centroid              in the frame of the decoded normal: depth along it,     depth h/4724 (12 bits),
                            12 bits, and two tangent coordinates, 6 bits each, on   h/68 in the plane (h/144
                            [-sqrt(3)/2, sqrt(3)/2] h about the voxel centre        closed); the voxel's middle
                            (version 5: fewer depth bits for spread normals;        exact; spread: sigma h / 32
                            version 7: 7 in-plane bits on closed surfaces)          or that
entry_kd                    9 bits: steps of S/511 over the values' own range,      S/1022
                            S = max(1, largest value)
entry_ks                    8 bits, likewise                                        S/510
entry_shininess             8 bits of log2(1 + n), likewise, S = log2(1 + largest)  log2(1 + n) within S/510
entry_cover (version 4)     6 bits of 2 (1 - c), c in [0.5, 1]                     1/252; 1 exact
entry_side (version 6)      per entry, its side mod 3 less its first earlier        exact
                            neighbour's at its sample direction (below)
density                     F (see below), plus D - F in 3 bits of A_v              min(|D - F|, A_v / 14)
==========================  ======================================================  ===============================

**Spread normals** (version 5). A mean normal of length c < 1 averages
facets whose normals spread about it by about ``sigma = sqrt(2 (1 - c))``
radians: scattered foliage, where most entries mix leaves of unrelated
directions. Its direction is stored no finer than ``sigma / 16``
(:data:`NORMAL_SPREAD_SHARE`) and its centroid's depth no finer than
``sigma h / 32`` (:data:`DEPTH_SPREAD_SHARE` of the ``sigma h / 2`` by
which such facets lie off their plane), or the field's bits where those are
coarser: a table per length code of how many bits fewer (``params``
``normal_shifts`` and ``depth_shifts``). Flat facets (c = 1) keep every bit;
smooth surfaces nearly all.

**Orders** (version 5). Members are laid out so that LZMA, which adapts to
what it has just seen, meets runs of alike codes; each order is one the
decoder rebuilds from what it has decoded before, so nothing is lost: the
odd voxels' occupancy bits (every face of theirs touches even voxels) in
order of how many face neighbours have an entry at that direction;
``entry_parent`` as a rank among the neighbours that do, for entries that
have any, in order of how many; directions grouped by shift and sample
direction; shininess and kd by ks (a material's values together); depths by
their bits; a parentless entry's depth from where the line through its
in-plane point enters the voxel. Two orders help scattered leaves and hurt
smooth surfaces, whose neighbouring voxels follow each other in entry order:
the children's in-plane centroid codes in order of their source's centroid
seen from their voxel (a leaf continuing across a face), and areas by their
normal's length code; the encoder keeps whichever of that and entry order
packs smaller (``params`` ``centroid_layout``, ``area_order``).

**Copying from a neighbour** (version 3). A leaf, a blade or a bar that
crosses several voxels leaves in each an entry with the same sample
direction, mean normal and material. An entry whose quantised normal,
normal length, kd, ks and shininess codes all equal those of the entry with
the same sample direction in one of the 13 neighbouring voxels that come
before its own in cell order (:data:`PARENT_OFFSETS`) names that neighbour in
``entry_parent`` and stores none of them: those members hold the other
entries' codes only. This is lossless on the codes (each entry decodes to
exactly what quantising it alone gives); about half the tree's entries copy.
The decoder follows the parents to each chain's first entry by pointer
jumping (a few NumPy passes, not a loop over entries). Such an entry's
centroid lies on its source's plane when their facets are coplanar, so its
depth code is stored as the difference from the depth of the source's plane
in its own voxel (mostly 0).

**Sides** (version 6). An entry whose facets all lie on closed,
consistently wound surfaces is seen from one side only: its points are
one-sided (:func:`aniso3d.build.texture.entry_sides`). ``entry_side`` keeps
which (+1: its mean normal points out of its solid, -1: into it, 0: not
closed), so that a loaded texture makes the built one's points. A side
mostly repeats the neighbouring voxel's at the same sample direction: each
is stored modulo 3 less that of its predictor, the entry at its direction
in the first of the 13 earlier neighbours that has one (known from the
occupancy), entries without one last; closed and open surfaces alike store
runs of 0, a few hundred bytes a scene. The decoder sums the residuals along
the predictors by pointer jumping.

**Closed surfaces' in-plane centroids** (version 7). The volume draws a
thin solid's face inside its voxels as a strip between two lines along the
beam, fitted to the entry's area and centroid
(:mod:`aniso3d.rendering.sheet_strips`): its in-plane centroid places the
strip, where the 6-bit steps (1/34 voxel) cost the corpus lattice 0.11 dB
through its file. Entries on closed surfaces (``entry_side`` +-1, decoded
before the centroids) store theirs in ``centroid_closed`` bits (7: steps of
1/72), the rest in ``centroid``: a leaf's or an open sheet's only slides its
splat in its plane, and the 4M-triangle tree would pass 1/10 of its mesh
with 7 bits everywhere (:func:`plane_bits`; docs/encoding.md).

**Why 12 depth bits and 8 length bits** (version 6's defaults; version 5
wrote 10 and 6). The volume's smooth shading and its runs of surface
sheets (docs/coverage.md) made the images of smooth surfaces fine enough
that the old rounding showed: the blob lost 0.31 dB through its file, the
depth mostly where a voxel spans about two pixels and the length close up,
where it sets the sheets' crossing tolerance (``sqrt(1 - c)``, which 6 bits
put on steps of 1/63 voxel; the blob's lie between 0 and 0.016). See
docs/encoding.md.

A range's two ends decode exactly, so a scene of one material keeps it
exactly (two: both).

The density sphere is not stored as such: ``F_v(p) = sum_e A_e |n_e . N_p|``
over the voxel's entries (their area and mean normal, as decoded) is the
part of ``D_v(p) = sum_s S_s |N_s . N_p|`` that the entries already hold;
it is exact for entries whose facets are flat and never larger than D (the
triangle inequality): 99.2 % of D over the default tree. Only the residual
``D - F`` is stored, rounded to steps of the voxel's registered area
``A_v / (2**bits - 1)`` (``D <= A_v``); rounding to the nearest step stores
0 below half a step, so D is never farther than F alone. Most of it is 0
and deflates to nearly nothing; ``bits.density = 0`` drops it (``D = F``).
Where a thin solid's hidden back was taken out of D (version 4,
:mod:`aniso3d.build.closure`; F counts the entries' covered areas, a mean
over directions) D can lie below F: the codes then start ``density_zero``
steps below 0 (a parameter, absent when nothing is), and D is kept at 0 or
more.

Every field's quantiser is a pair of functions here (``_encode_*`` and
``_decode_*``); :func:`encode` and :func:`decode` run them all. A code array
of b bits is one uint8 (b <= 8) or uint16 array, stored as byte planes (all
low bytes, then all high bytes) so that the mostly empty high bytes compress
away. :func:`decode` also reads versions 3 and 4 (every entry at the
field's bits, members in entry order) and version 2's layout (no ``entry_parent``, every
entry's codes stored, centroids as ``round(62 f)`` per axis of the offset f
in the voxel).

Registration guarantees what the encoding assumes: coords sorted and inside
the grid, each voxel's entries sorted by sample direction without repeats,
areas, materials and density finite and not negative, centroids inside their
voxel and ``F <= D <= A_v``. A texture breaking the first four is refused
(:class:`~aniso3d.errors.InputError`); centroids and densities outside their
ranges are clamped to them.
"""

from __future__ import annotations

import lzma
import math
import zlib
from dataclasses import asdict, dataclass

import numpy as np

from aniso3d.build.closure import facet_density
from aniso3d.errors import FormatError, InputError
from aniso3d.grid import cell_coords, cell_keys, tangent_frame

#: The arrays of a texture (the fields of :class:`aniso3d.build.texture.AnisoTexture`
#: that hold arrays), what :func:`decode` returns and version 1 files store as they are.
ARRAYS = ("origin", "shape", "coords", "directions", "density", "entry_offsets",
          "entry_direction", "entry_area", "entry_kd", "entry_ks", "entry_shininess",
          "entry_centroid", "entry_normal", "entry_cover", "entry_side")  # fmt: skip
#: The arrays of files of format versions 4 and 5 (no ``entry_side``: read as 0).
ARRAYS_V5 = ARRAYS[:-1]
#: The arrays of files before format version 4 (no ``entry_cover``: read as 1).
ARRAYS_V3 = ARRAYS_V5[:-1]

#: The members of the compact encoding of format version 2, in the order they are written.
MEMBERS_V2 = ("origin", "shape", "directions", "coords", "entry_mask", "entry_area",
              "entry_normal", "entry_coherence", "entry_centroid", "entry_kd", "entry_ks",
              "entry_shininess", "density")  # fmt: skip
#: The members of the compact encoding (format version 3): version 2's and
#: ``entry_parent``, which lets an entry take its normal and materials from a
#: neighbour's (:func:`_copy_parents`); the fields it names are then stored
#: for the other entries only.
MEMBERS_V3 = (*MEMBERS_V2[:5], "entry_parent", *MEMBERS_V2[5:])
#: Version 4's and 5's: version 3's and ``entry_cover``.
MEMBERS_V5 = (*MEMBERS_V3, "entry_cover")
#: Version 6's: version 5's and ``entry_side``.
MEMBERS = (*MEMBERS_V5, "entry_side")
#: Fields (members) an entry with a parent copies from it instead of storing.
COPIED = ("entry_normal", "entry_coherence", "entry_kd", "entry_ks", "entry_shininess")

#: The field of :class:`Bits` each copied member's codes have.
_BITS_OF = {"entry_normal": "normal", "entry_coherence": "coherence", "entry_kd": "kd", "entry_ks": "ks",
            "entry_shininess": "shininess"}  # fmt: skip

#: The 13 neighbours (di, dj, dk) of a voxel that come before it in cell-key
#: order (faces first, then edges, then corners): ``entry_parent`` j > 0
#: names the entry with the same sample direction in the voxel at
#: ``PARENT_OFFSETS[j - 1]`` from the entry's own.
PARENT_OFFSETS = np.array(
    sorted(
        ((i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) < (0, 0, 0)),
        key=lambda o: (abs(o[0]) + abs(o[1]) + abs(o[2]), [-x for x in o[::-1]]),
    ),
    dtype=np.int64,
)

#: Areas below ``max area / 2**AREA_SPAN`` are stored as that (an absolute
#: error below 6e-8 of the largest entry's area): keeps the log range, and so
#: the step, small whatever the smallest sliver is.
AREA_SPAN = 24.0
#: Mean normals are stored about their sample direction (:func:`_encode_frame`)
#: when none lies farther than this from it, in degrees; else octahedral.
FRAME_MAX_ANGLE = 60.0


@dataclass(frozen=True)
class Bits:
    """Bits per stored value of each quantised field (see the module table).

    ``density`` 0 stores no residual: the density sphere is then derived
    from the entries alone. Each count lies in 1..16 (2..16 for ``area``, whose
    code 0 means a zero area, ``normal``, a signed coordinate, and
    ``centroid``, a signed coordinate, and ``depth``). ``centroid`` is the
    bits of each of a centroid's two coordinates in the plane of its mean
    normal, ``depth`` of its offset along that normal (version 2 files stored
    each axis with ``centroid`` bits and had no ``depth``). ``centroid_closed``
    replaces ``centroid`` for the entries of closed surfaces (``entry_side``
    +-1, version 7): the strips of thin solids' faces
    (:mod:`aniso3d.rendering.sheet_strips`) are placed by it.
    """

    area: int = 11
    normal: int = 10
    coherence: int = 8
    centroid: int = 6
    kd: int = 9
    ks: int = 8
    shininess: int = 8
    density: int = 3
    depth: int = 12
    cover: int = 6
    centroid_closed: int = 7

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            low = 0 if name == "density" else 2 if name in ("area", "normal", "centroid", "depth",
                                                            "centroid_closed") else 1
            if name == "cover" and value > 8:
                raise InputError(f"bits for 'cover' must be a whole number in 1..8, got {value!r}")
            if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= 16:
                raise InputError(f"bits for '{name}' must be a whole number in {low}..16, got {value!r}")


DEFAULT_BITS = Bits()


# ------------------------------------------------------------------ byte planes


def _width(bits: int) -> int:
    """Bytes of one code of ``bits`` bits (1 or 2)."""
    return 1 if bits <= 8 else 2


def to_planes(codes: np.ndarray, width: int) -> np.ndarray:
    """(R, N) unsigned codes -> (R * width, N) uint8 byte planes: for each row
    its low bytes, then the next bytes, little-endian."""
    c = np.ascontiguousarray(np.atleast_2d(codes), dtype=f"<u{width}")
    rows, n = c.shape
    return np.ascontiguousarray(c.view(np.uint8).reshape(rows, n, width).transpose(0, 2, 1)).reshape(
        rows * width, n
    )


def from_planes(planes: np.ndarray, rows: int, width: int) -> np.ndarray:
    """The inverse of :func:`to_planes`: (rows, N) unsigned codes of ``width`` bytes."""
    n = planes.shape[1]
    b = np.ascontiguousarray(planes.reshape(rows, width, n).transpose(0, 2, 1))
    return b.view(f"<u{width}").reshape(rows, n)


# ------------------------------------------------------------------- quantisers


def _encode_keys(coords: np.ndarray, shape: np.ndarray) -> np.ndarray:
    """Sorted cell keys as deltas (the first key itself), in the fewest of 1,
    2, 4 or 8 bytes that hold them all: (width, M) byte planes."""
    keys = cell_keys(coords, shape)
    if len(keys) > 1 and np.any(np.diff(keys) <= 0):
        raise InputError("texture coords are not sorted by cell or repeat a cell; they cannot be encoded")
    delta = np.diff(keys, prepend=0).astype(np.uint64)
    top = int(delta.max()) if len(delta) else 0
    width = next(w for w in (1, 2, 4, 8) if top < 256**w)
    return to_planes(delta, width)


def _decode_keys(planes: np.ndarray, shape: np.ndarray) -> np.ndarray:
    width = planes.shape[0]
    if width not in (1, 2, 4, 8):
        raise FormatError(f"coords has {width} byte planes, expected 1, 2, 4 or 8")
    delta = from_planes(planes, 1, width)[0].astype(np.uint64)
    if len(delta) > 1 and np.any(delta[1:] == 0):
        raise FormatError("coords repeat a cell")
    keys = np.cumsum(delta, dtype=np.uint64)
    cells = int(np.prod(np.asarray(shape, dtype=np.int64)))
    if len(keys) and int(keys[-1]) >= cells:
        raise FormatError("coords lie outside the grid")
    return cell_coords(keys.astype(np.int64), shape).astype(np.int32)


def _encode_mask(offsets: np.ndarray, direction: np.ndarray, k: int) -> np.ndarray:
    """(M, ceil(K / 8)) uint8: bit p of voxel v set when v has an entry at
    sample p (entries sorted by direction within a voxel, as registration makes them)."""
    m = len(offsets) - 1
    voxel = np.repeat(np.arange(m), np.diff(offsets))
    d = np.asarray(direction, dtype=np.int64)
    if len(d) and (d.min() < 0 or d.max() >= k):
        raise InputError(f"texture entry_direction lies outside 0..{k - 1}; it cannot be encoded")
    key = voxel * k + d
    if len(key) > 1 and np.any(np.diff(key) <= 0):
        raise InputError(
            "texture entries are not sorted by sample direction within each voxel, or repeat one; "
            "they cannot be encoded"
        )
    occupied = np.zeros((m, k), dtype=bool)
    occupied[voxel, d] = True
    return np.packbits(occupied, axis=1)


def _decode_mask(mask: np.ndarray, m: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(offsets (M + 1,) int64, direction (E,) int32) from the occupancy mask."""
    if mask.shape != (m, (k + 7) // 8):
        raise FormatError(f"entry_mask has shape {mask.shape}, expected {(m, (k + 7) // 8)}")
    occupied = np.unpackbits(mask, axis=1, count=k).astype(bool) if m else np.zeros((0, k), bool)
    if k % 8 and np.any(np.unpackbits(mask, axis=1)[:, k:]):
        raise FormatError("entry_mask sets bits past the last sample direction")
    voxel, d = np.nonzero(occupied)
    offsets = np.zeros(m + 1, dtype=np.int64)
    offsets[1:] = np.cumsum(np.bincount(voxel, minlength=m))
    return offsets, d.astype(np.int32)


#: The six face neighbours of a voxel (:func:`_mask_contexts`).
FACES = np.array([(-1, 0, 0), (1, 0, 0), (0, -1, 0), (0, 1, 0), (0, 0, -1), (0, 0, 1)], dtype=np.int64)


def _mask_contexts(occupied: np.ndarray, coords: np.ndarray, shape: np.ndarray, which: np.ndarray) -> np.ndarray:
    """(len(which), K) context of each sample direction of the voxels
    ``which``: ``8 n + f``, n of their face neighbours occupied at that
    direction (``occupied`` (M, K) read at the neighbours only) and f of them
    voxels at all."""
    keys = cell_keys(coords, shape)
    ctx = np.zeros((len(which), occupied.shape[1]), dtype=np.int64)
    for off in FACES:  # six
        cell = coords[which] + off
        inside = np.all((cell >= 0) & (cell < shape), axis=1)
        key = cell_keys(np.clip(cell, 0, shape - 1), shape)
        i = np.minimum(np.searchsorted(keys, key), max(len(keys) - 1, 0))
        hit = inside & (keys[i] == key) if len(keys) else np.zeros(len(which), bool)
        ctx += 8 * (hit[:, None] & occupied[i]) + hit[:, None]
    return ctx


def _encode_mask_split(offsets: np.ndarray, direction: np.ndarray, k: int, coords: np.ndarray,
                       shape: np.ndarray) -> np.ndarray:  # fmt: skip
    """(1, L) uint8: version 5's occupancy. The voxels whose ``i + j + k`` is
    even store their mask rows as :func:`_encode_mask` does; the odd ones'
    faces all touch even voxels, so each of their bits is stored in order of
    its context (:func:`_mask_contexts`: how many face neighbours are
    voxels and have an entry at that direction), bits packed. A surface
    continuing across a face makes a bit with occupied neighbours nearly
    always set, one without nearly always clear: the runs compress."""
    rows = _encode_mask(offsets, direction, k)
    occupied = np.unpackbits(rows, axis=1, count=k).astype(bool)
    odd = np.flatnonzero(coords.sum(axis=1) % 2 == 1)
    ctx = _mask_contexts(occupied, coords, shape, odd)
    bits = occupied[odd].ravel()[_by_shift(ctx.ravel())]
    return np.concatenate([rows[coords.sum(axis=1) % 2 == 0].ravel(), np.packbits(bits)])[None]


def _decode_mask_split(mask: np.ndarray, m: int, k: int, coords: np.ndarray,
                       shape: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The inverse of :func:`_encode_mask_split`: (offsets, direction) as :func:`_decode_mask`."""
    nb = (k + 7) // 8
    even = coords.sum(axis=1) % 2 == 0
    ne, no = int(even.sum()), int(m - even.sum())
    if mask.shape != (1, ne * nb + (no * k + 7) // 8):
        raise FormatError(f"entry_mask has shape {mask.shape}, expected {(1, ne * nb + (no * k + 7) // 8)}")
    rows = np.zeros((m, nb), dtype=np.uint8)
    rows[even] = mask[0, : ne * nb].reshape(ne, nb)
    occupied = np.unpackbits(rows, axis=1, count=k).astype(bool) if m else np.zeros((0, k), bool)
    odd = np.flatnonzero(~even)
    ctx = _mask_contexts(occupied, coords, shape, odd)
    packed = mask[0, ne * nb :]
    if np.any(np.unpackbits(packed)[no * k :]):
        raise FormatError("entry_mask sets bits past the last sample direction")
    flat = np.empty(no * k, dtype=bool)
    flat[_by_shift(ctx.ravel())] = np.unpackbits(packed, count=no * k).astype(bool)
    occupied[odd] = flat.reshape(no, k)
    rows[odd] = np.packbits(occupied[odd], axis=1)
    return _decode_mask(rows, m, k)


def _encode_log(a: np.ndarray, bits: int) -> tuple[np.ndarray, list[float]]:
    """Positive values as ``1 + round((log2 a - lo) / (hi - lo) * (2**bits - 2))``
    over ``[lo, hi] = [max(log2 min, hi - AREA_SPAN), log2 max]``, 0 as 0."""
    a = np.asarray(a, dtype=np.float64)
    pos = a > 0
    if not pos.any():
        return np.zeros(len(a), dtype=np.uint16), [0.0, 0.0]
    hi = float(np.log2(a.max()))
    lo = max(float(np.log2(a[pos].min())), hi - AREA_SPAN)
    steps = 2**bits - 2
    t = (np.log2(np.maximum(a, 2.0**lo)) - lo) / (hi - lo) if hi > lo else np.zeros(len(a))
    codes = np.where(pos, 1 + np.round(np.clip(t, 0.0, 1.0) * steps), 0)
    return codes.astype(np.uint16), [lo, hi]


def _decode_log(codes: np.ndarray, bits: int, span: list[float]) -> np.ndarray:
    lo, hi = span
    steps = 2**bits - 2
    value = np.exp2(lo + (codes.astype(np.float64) - 1.0) * ((hi - lo) / steps))
    return np.where(codes > 0, value, 0.0)


def _half(bits) -> np.ndarray | int:
    """``2**(bits-1) - 1``, the steps a side of a signed coordinate of ``bits``
    bits (an int, or an array of one per entry)."""
    if np.ndim(bits):
        return (np.left_shift(1, np.asarray(bits, dtype=np.int64) - 1) - 1).astype(np.float64)
    return 2 ** (bits - 1) - 1


def _encode_oct(v: np.ndarray, bits) -> np.ndarray:
    """(2, E) codes of unit vectors ``v`` (E, 3) on the octahedron, each
    coordinate rounded symmetrically to ``2**(bits-1) - 1`` steps a side (so
    0 and +-1, the axes, are exact). ``bits`` is one count or one per entry
    (version 5: coarser for spread normals, :func:`normal_shifts`)."""
    v = np.asarray(v, dtype=np.float64)
    s = np.abs(v).sum(axis=1)
    p = v[:, :2] / np.where(s > 0, s, 1.0)[:, None]
    sign = np.where(p >= 0, 1.0, -1.0)
    p = np.where((v[:, 2] < 0)[:, None], (1.0 - np.abs(p[:, ::-1])) * sign, p)
    m = _half(bits)
    m = m[:, None] if np.ndim(m) else m
    return (np.round(np.clip(p, -1.0, 1.0) * m) + m).astype(np.uint16).T


def _decode_oct(codes: np.ndarray, bits) -> np.ndarray:
    m = _half(bits)
    m = m[:, None] if np.ndim(m) else m
    p = (codes.T.astype(np.float64) - m) / m
    z = 1.0 - np.abs(p).sum(axis=1)
    sign = np.where(p >= 0, 1.0, -1.0)
    p = np.where((z < 0)[:, None], (1.0 - np.abs(p[:, ::-1])) * sign, p)
    v = np.column_stack([p, z])
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _encode_frame(v: np.ndarray, sample: np.ndarray, bits, span: float) -> np.ndarray:
    """(2, E) codes of unit vectors ``v`` (E, 3) as the point where they meet
    the plane tangent to their sample direction ``sample`` (E, 3) at distance 1
    (gnomonic coordinates along :func:`~aniso3d.grid.tangent_frame`), each
    rounded to ``2**(bits-1) - 1`` steps on ``[-span, span]``. Needs
    ``v . sample > 0``; registration puts every mean normal inside its sample
    direction's Voronoi cell, so the coordinates stay small. ``bits`` is one
    count or one per entry."""
    t, b = tangent_frame(sample)
    c = np.sum(v * sample, axis=1)
    g = np.stack([np.sum(v * t, axis=1), np.sum(v * b, axis=1)]) / c
    m = _half(bits)
    scaled = g / span if span > 0 else np.zeros_like(g)
    return (np.round(np.clip(scaled, -1.0, 1.0) * m) + m).astype(np.uint16)


def _decode_frame(codes: np.ndarray, sample: np.ndarray, bits, span: float, frame=None) -> np.ndarray:
    """The inverse of :func:`_encode_frame`; ``frame`` is ``tangent_frame(sample)``
    when already known (a sample direction's rows, gathered)."""
    m = _half(bits)
    g = (codes.astype(np.float64) - m) / m * span
    t, b = tangent_frame(sample) if frame is None else frame
    v = sample + g[0][:, None] * t + g[1][:, None] * b
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _frame_span(v: np.ndarray, sample: np.ndarray) -> float | None:
    """The largest gnomonic coordinate of unit vectors ``v`` about their sample
    directions, or None when one lies more than ``FRAME_MAX_ANGLE`` from its
    sample direction (then the octahedral map serves better)."""
    if not len(v):
        return 0.0
    c = np.sum(v * sample, axis=1)
    if c.min() < np.cos(np.radians(FRAME_MAX_ANGLE)):
        return None
    t, b = tangent_frame(sample)
    return float(np.max(np.abs(np.stack([np.sum(v * t, axis=1), np.sum(v * b, axis=1)]) / c)))


def oct_bits(bits: Bits) -> int:
    """Bits a coordinate of the octahedral map gets: two more than about a
    sample direction (whose plane spans 2 tan 40 degrees or so, against the
    map's 2 for the whole sphere), so the two are about as precise (at most 16)."""
    return min(16, bits.normal + 2)


#: Version 5's orders of ``entry_area`` (``params["area_order"]``): entry
#: order, or by the normal's length code (:func:`_by_shift`).
AREA_ORDERS = ("entries", "length")


def _packed(planes: np.ndarray) -> int:
    """Bytes of byte planes once compressed by LZMA's fastest preset: the
    encoder's quick measure when it chooses between layouts that the file's
    LZMA then compresses (deflate ranks some differently: a sphere's areas)."""
    return len(lzma.compress(np.ascontiguousarray(planes).tobytes(), format=lzma.FORMAT_RAW,
                             filters=[{"id": lzma.FILTER_LZMA1, "preset": 1}]))  # fmt: skip


def _deflated(codes: np.ndarray, bits: int) -> int:
    """Bytes of ``codes`` as stored byte planes once deflated (zlib's default level)."""
    return len(zlib.compress(to_planes(codes, _width(bits)).tobytes()))


def _decode_unit_normal(codes: np.ndarray, bits: Bits, span: float | None, sample: np.ndarray,
                        frame=None, shift: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """(E, 3) float64 unit normals from their direction codes (2, E), each
    ``shift`` (E,) bits coarser than ``bits`` say (version 5; None: 0)."""
    nb = oct_bits(bits) if span is None else bits.normal
    if shift is not None:
        nb = nb - np.asarray(shift, dtype=np.int64)
    if span is None:
        return _decode_oct(codes, nb)
    return _decode_frame(codes, sample, nb, span, frame)


#: A spread mean normal's direction is stored no finer than this fraction of
#: its facets' angular spread about it (:func:`normal_shifts`).
NORMAL_SPREAD_SHARE = 1 / 16


def direction_error(bits: int, span: float | None) -> float:
    """The largest angle (radians) between a unit normal and its direction
    codes of ``bits`` bits decoded: half a step on each of two coordinates,
    about the sample direction (gnomonic, ``span``; an angle is never larger
    than its gnomonic offset) or octahedral (``span`` None; the map
    stretches by at most 3)."""
    return (3.0 if span is None else span) / (math.sqrt(2.0) * (2 ** (bits - 1) - 1))


#: A spread entry's centroid depth is stored no finer than this fraction of
#: how far its facets lie off its plane (:func:`depth_shifts`).
DEPTH_SPREAD_SHARE = 1 / 16


def depth_shifts(bits: Bits) -> list[int]:
    """Per normal-length code q, how many bits coarser than ``bits.depth``
    a centroid's depth is stored (version 5). Facets whose normals spread by
    sigma about their mean (:func:`normal_shifts`) across a voxel lie up to
    about ``sigma h / 2`` off the plane through their centroid: the plane
    stands for them only that well, and its depth is kept within
    ``DEPTH_SPREAD_SHARE`` of that (never coarser than 2 bits)."""
    return _coarsest(bits.depth, lambda b: 1 / (2 * _steps(b)[1]), DEPTH_SPREAD_SHARE / 2, bits.coherence)


def _by_shift(shift: np.ndarray, then: np.ndarray | None = None) -> np.ndarray:
    """The order in which version 5 stores codes that it groups by another
    field's codes ``shift`` (directions by their shift and sample direction,
    depths by their bits, areas by their normal's length, shininess and kd
    by ks): by ``shift``, then ``then``, stable, so the decoder, which has
    those first, puts them back."""
    key = np.asarray(shift, dtype=np.int64)
    if then is not None:
        then = np.asarray(then, dtype=np.int64)
        key = key * (int(then.max(initial=0)) + 1) + then
    if len(key) and 0 <= key.min() and key.max() < 2**16:
        key = key.astype(np.uint16)  # NumPy's stable sort of small integers is a radix sort
    return np.argsort(key, kind="stable")


def normal_shifts(bits: Bits, span: float | None) -> list[int]:
    """Per normal-length code q (:func:`_encode_spread`), how many bits
    coarser than the field's the direction of a mean normal of that length
    is stored (version 5). A mean normal of length c averages facets whose
    normals spread about it by about ``sigma = sqrt(2 (1 - c))`` radians (two
    facets sigma either side: exactly, to first order; a cone: its RMS
    angle), a spread that the volume's sheets bend by and the shading
    averages over. Its direction is kept within ``NORMAL_SPREAD_SHARE``
    sigma (and never coarser than 2 bits): most entries of scattered
    foliage mix leaves of unrelated directions and need far fewer bits;
    flat and smooth surfaces (q = 0, or a few) keep all of theirs."""
    full = oct_bits(bits) if span is None else bits.normal
    return _coarsest(full, lambda b: direction_error(b, span), NORMAL_SPREAD_SHARE, bits.coherence)


def _coarsest(full: int, error, share: float, coherence_bits: int) -> list[int]:
    """Per length code q, the most bits below ``full`` (down to 2) whose
    ``error(bits)`` stays within ``share`` times the spread of that code,
    ``sqrt(2) q / (2**coherence_bits - 1)`` (``error`` grows as bits drop)."""
    top = 2**coherence_bits - 1
    sigma = math.sqrt(2.0) * np.arange(top + 1) / top
    err = np.array([error(b) for b in range(full - 1, 1, -1)])  # shifts 1, 2, ... (at most 15)
    return np.sum(err[None, :] <= share * sigma[:, None], axis=1).tolist()


def _encode_spread(length: np.ndarray, bits: int) -> np.ndarray:
    """(1, E) codes of mean normal lengths c in [0, 1] (version 3):
    ``round(sqrt(1 - c) * (2**bits - 1))``. The volume's sheets bend by
    ``sqrt(1 - c)`` (``aniso3d.rendering.volume.entry_sheets``), steepest
    near c = 1, where smooth surfaces are: this spends the steps there (at 6
    bits, codes about 1/63**2 apart in c near 1, where linear steps were
    1/63; the largest error, near c = 0, about 1/63). c = 1 and c = 0 are
    exact."""
    top = 2**bits - 1
    spread = np.clip(1.0 - np.asarray(length, dtype=np.float64), 0.0, 1.0)
    return np.round(np.sqrt(spread) * top).astype(np.uint16)[None]


def _decode_spread(codes: np.ndarray, bits: int) -> np.ndarray:
    return 1.0 - (np.atleast_2d(codes)[0].astype(np.float64) / (2**bits - 1)) ** 2


def _decode_normal(
    codes: np.ndarray | None,
    length: np.ndarray,
    length_range: list | None,
    bits: Bits,
    span: float | None,
    sample: np.ndarray | None,
    unit: np.ndarray | None = None,
    shift: np.ndarray | None = None,
) -> np.ndarray:
    """(E, 3) float32 mean normals from their direction codes (2, E), in the
    sample frame (``span``) or octahedral (``span`` None), or their unit
    directions ``unit`` when already decoded, and length codes (1, E): of
    :func:`_encode_spread` when ``length_range`` is None (version 3), else
    on ``length_range`` (version 2). float32 as built; F is computed from
    these very values by encoder and decoder, so that decoded D >= F exactly.
    ``shift``: see :func:`_decode_unit_normal`."""
    if unit is None:
        unit = _decode_unit_normal(codes, bits, span, sample, shift=shift)
    if length_range is None:
        scale = _decode_spread(length, bits.coherence)
    else:
        scale = _decode_range(np.atleast_2d(length), bits.coherence, length_range)[0]
    return (unit * scale[:, None]).astype(np.float32)


def _encode_range(x: np.ndarray, bits: int, log: bool = False) -> tuple[np.ndarray, list[list[float]]]:
    """(R, N) codes of the rows of ``x`` (R, N), non-negative, each on its own
    range ``[lo, hi]`` cut into ``n`` equal steps no longer than
    ``S / (2**bits - 1)``, with ``S = max(1, largest value)`` (or, when ``log``,
    steps of ``log2(1 + x)`` with ``S = log2(1 + largest)``): the precision of
    ``bits`` bits over ``[0, S]``, spent only where the values are. Returns
    the codes and ``[lo, hi, n]`` per row. Both ends decode exactly (one
    material is exact, two are at the ends); the rest within half a step."""
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    f = (lambda v: np.log2(1.0 + v)) if log else (lambda v: v)
    top = 2**bits - 1
    codes = np.zeros(x.shape, dtype=np.uint16)
    ranges = []
    for row in range(len(x)):  # a row per colour channel: at most 3
        lo, hi = (float(x[row].min()), float(x[row].max())) if x.shape[1] else (0.0, 0.0)
        a, b = f(lo), f(hi)
        full = f(hi) if log else max(1.0, hi)
        n = min(top, math.ceil((b - a) / full * top - 1e-9)) if b > a else 0
        if n:
            codes[row] = np.round(np.clip((f(x[row]) - a) / (b - a), 0.0, 1.0) * n)
        ranges.append([lo, hi, n])
    return codes, ranges


def _decode_range(codes: np.ndarray, bits: int, ranges: list[list[float]], log: bool = False) -> np.ndarray:
    lo, hi, n = (np.array([r[i] for r in ranges], dtype=np.float64)[:, None] for i in (0, 1, 2))
    if codes.size and np.any(codes > n):
        raise FormatError("a quantised field holds codes past its range")
    t = codes.astype(np.float64) / np.maximum(n, 1)
    if log:
        a, b = np.log2(1.0 + lo), np.log2(1.0 + hi)
        mid = np.exp2(a + t * (b - a)) - 1.0
    else:
        mid = lo + t * (hi - lo)
    return np.where(codes == 0, lo, np.where(codes == n, hi, mid))


def _encode_unit(x: np.ndarray, bits: int, scale: float) -> np.ndarray:
    """``round(x / scale * (2**bits - 1))`` for x in [0, scale] (clamped)."""
    top = 2**bits - 1
    return np.round(np.clip(np.asarray(x, dtype=np.float64) / scale, 0.0, 1.0) * top).astype(np.uint16)


def _decode_unit(codes: np.ndarray, bits: int, scale: float) -> np.ndarray:
    return codes.astype(np.float64) / (2**bits - 1) * scale


def _encode_cover(cover: np.ndarray, bits: int) -> np.ndarray:
    """(1, E) codes ``round(2 (1 - c) (2**bits - 1))`` of covers c in [0.5, 1]
    (clamped): 0 for the open facets' 1, so a scene without closed thin
    parts stores a member of zeros."""
    top = 2**bits - 1
    c = np.clip(np.asarray(cover, dtype=np.float64), 0.5, 1.0)
    return np.round(2.0 * (1.0 - c) * top).astype(np.uint8)[None]


def _decode_cover(codes: np.ndarray, bits: int) -> np.ndarray:
    return 1.0 - codes[0].astype(np.float64) / (2.0 * (2**bits - 1))


def _side_predictors(coords: np.ndarray, shape: np.ndarray, voxel: np.ndarray, direction: np.ndarray,
                     k: int) -> np.ndarray:  # fmt: skip
    """(E,) int64: for each entry, the entry with the same sample direction in
    the first of the 13 earlier neighbouring voxels (:data:`PARENT_OFFSETS`)
    that has one, -1 where none does: the entry whose side predicts its own
    (version 6). Known to the decoder from the occupancy alone; each points
    to an earlier entry, so they form a forest."""
    ekeys = _entry_keys(coords, shape, voxel, direction, k)
    pred = np.full(len(voxel), -1, dtype=np.int64)
    for offset in PARENT_OFFSETS:  # thirteen
        open_ = np.flatnonzero(pred < 0)
        if not len(open_):
            break
        pred[open_] = _neighbour_entries(coords, shape, voxel, direction, k, ekeys, offset, open_)
    return pred


def _encode_sides(side: np.ndarray, pred: np.ndarray) -> np.ndarray:
    """(N,) uint8, version 6's ``entry_side``: each entry's side s in {-1, 0,
    1} as ``s mod 3``, less its predictor's (:func:`_side_predictors`)
    modulo 3 where it has one: 0 wherever a closed (or an open) surface goes
    on into the neighbouring voxel. Entries with a predictor first, then the
    others, each in entry order: long runs of 0, which LZMA makes nearly
    free (a few hundred bytes on the corpus scenes)."""
    code = np.asarray(side, dtype=np.int64) % 3
    has = pred >= 0
    resid = np.where(has, (code - code[np.where(has, pred, 0)]) % 3, code)
    return resid[_by_shift(~has)].astype(np.uint8)


def _decode_sides(stored: np.ndarray, pred: np.ndarray) -> np.ndarray:
    """The inverse of :func:`_encode_sides`: (E,) int8 sides. Each entry's
    code is its residual plus its predictor's code, along the predictor
    forest: summed by pointer jumping (each NumPy pass halves every chain),
    not entry by entry."""
    e = len(pred)
    if stored.dtype != np.uint8 or stored.shape != (e,):
        raise FormatError(f"entry_side has shape {stored.shape} and dtype {stored.dtype}, expected ({e},) uint8")
    if e and int(stored.max()) > 2:
        raise FormatError("entry_side holds codes above 2")
    acc = np.empty(e, dtype=np.int64)
    acc[_by_shift(pred < 0)] = stored
    ptr = pred.copy()
    while True:  # predictors come earlier, so this ends
        live = np.flatnonzero(ptr >= 0)
        if not len(live):
            break
        up = ptr[live]
        acc[live] = (acc[live] + acc[up]) % 3
        ptr[live] = ptr[up]
    return np.where(acc == 2, -1, acc).astype(np.int8)


def _encode_centroid(centroid, origin, voxel_size, coords, voxel, bits) -> np.ndarray:
    """Version 2's centroids (read by :func:`decode`, no longer written):
    (3, E) codes of each centroid's offset f in [0, 1] inside its voxel, per
    axis: ``round(f * n)`` with ``n = 2**bits - 2`` (even), so the voxel's
    faces and middle plane (0, 1/2, 1: axis-aligned surfaces) are exact and
    the rest within ``h / 2n``."""
    f = (np.asarray(centroid, dtype=np.float64) - origin) / voxel_size - coords[voxel]
    n = 2**bits - 2
    return np.round(np.clip(f, 0.0, 1.0) * n).astype(np.uint16).T


def _decode_centroid(codes, origin, voxel_size, coords, voxel, bits) -> np.ndarray:
    f = codes.T.astype(np.float64) / (2**bits - 2)
    return origin + (coords[voxel] + f) * voxel_size


def _steps(bits: int) -> tuple[int, int]:
    """(m, s) of a signed coordinate in the centroid's normal frame: codes
    ``m + round(x s)`` in 0..2m for x in [-sqrt(3)/2, sqrt(3)/2] (a voxel's
    half diagonal), ``m = 2**(bits-1) - 1`` and ``s`` the largest even number
    with ``s sqrt(3)/2 <= m``: 0 and +-1/2 (the voxel's middle and faces)
    are exact. (2 bits: ``s = 1``, codes -1, 0, 1 voxel, clamped into it.)"""
    if np.ndim(bits):  # one count per entry (version 5's coarser depths)
        m = np.left_shift(1, np.asarray(bits, dtype=np.int64) - 1) - 1
        return m, np.maximum(1, 2 * np.floor(m / math.sqrt(3.0)).astype(np.int64))
    m = 2 ** (bits - 1) - 1
    return m, max(1, 2 * math.floor(m / math.sqrt(3.0)))


def _frame_offsets(codes: np.ndarray, unit: np.ndarray, t: np.ndarray, b: np.ndarray, bits: Bits,
                   depth_bits=None, plane_bits=None) -> np.ndarray:  # fmt: skip
    """(E, 3) offsets from the voxel centre, in voxels, of centroid codes
    (3, E) (depth along the unit normal, then the two tangent coordinates
    along ``t`` and ``b``, :func:`~aniso3d.grid.tangent_frame` of it),
    clamped into the voxel. ``depth_bits``: the depth codes' bits, one per
    entry (version 5), else ``bits.depth``; ``plane_bits`` likewise the
    in-plane codes' (version 7, :func:`plane_bits`), else ``bits.centroid``."""
    md, sd = _steps(bits.depth if depth_bits is None else depth_bits)
    mp, sp = _steps(bits.centroid if plane_bits is None else plane_bits)
    d = (codes[0].astype(np.float64) - md) / sd
    u = (codes[1].astype(np.float64) - mp) / sp
    v = (codes[2].astype(np.float64) - mp) / sp
    return np.clip(d[:, None] * unit + u[:, None] * t + v[:, None] * b, -0.5, 0.5)


def _depth_codes(f: np.ndarray, unit: np.ndarray, bits) -> np.ndarray:
    """Depth codes (E,) int64 of offsets ``f`` (E, 3) from the voxel centre along ``unit`` (E, 3)."""
    m, s = _steps(bits)
    return m + np.clip(np.round(np.sum(f * unit, axis=1) * s), -m, m).astype(np.int64)


def _plane_orders(at: np.ndarray, t: np.ndarray, b: np.ndarray, child: np.ndarray, e: int,
                  plane_bits: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Version 5's order of the two in-plane centroid rows: first the
    entries without a parent, in order, then the children in order of their
    source's centroid as seen from their voxel, ``at`` (its code along ``t``,
    along ``b``; stable). A leaf continuing across a face puts its centroid
    near its source's: each run of one predicted code holds a narrow spread.
    ``plane_bits`` (E,): each entry's in-plane bits (:func:`plane_bits`)."""
    _, sp = _steps(plane_bits[child])
    root = np.setdiff1d(np.arange(e), child, assume_unique=True)
    tc, bc = t[child], b[child]
    up = np.round(np.sum(at * tc, axis=1) * sp)
    vp = np.round(np.sum(at * bc, axis=1) * sp)
    return (np.concatenate([root, child[np.argsort(up, kind="stable")]]),
            np.concatenate([root, child[np.argsort(vp, kind="stable")]]))  # fmt: skip


def _chord_start(codes: np.ndarray, unit: np.ndarray, t: np.ndarray, b: np.ndarray, depth_bits: np.ndarray,
                 plane_bits: np.ndarray) -> np.ndarray:  # fmt: skip
    """(E,) int64 depth code just below where the line through each
    centroid's in-plane point (its codes 1 and 2), along its normal, enters
    the voxel: version 5 stores a parentless entry's depth from there
    (modulo its bits). Oblique planes cut a chord shorter than the voxel's
    extent along the normal, so the codes from its start span fewer values."""
    mp, sp = _steps(plane_bits)
    md, sd = _steps(depth_bits)
    p0 = ((codes[1] - mp) / sp)[:, None] * t + ((codes[2] - mp) / sp)[:, None] * b
    with np.errstate(divide="ignore", invalid="ignore"):
        enter = np.where(unit != 0, (np.where(unit > 0, -0.5, 0.5) - p0) / unit, -np.inf).max(axis=1)
    lo = np.floor(np.clip(enter, -1.0, 1.0) * sd).astype(np.int64) - 1
    return np.clip(md + lo, 0, 2 * md)


def plane_bits(side: np.ndarray, bits: Bits) -> np.ndarray:
    """(E,) int64 bits of each entry's two in-plane centroid codes (version
    7): ``bits.centroid_closed`` for entries of closed surfaces (``side``
    +-1), whose thin solids' faces the volume draws as strips placed by
    their centroid (the corpus lattice's beams lost 0.17 dB close up through
    6-bit codes, steps of 1/34 voxel), ``bits.centroid`` for the rest
    (leaves, blades, open sheets: a splat slides in its plane by the step)."""
    return np.where(np.asarray(side) != 0, bits.centroid_closed, bits.centroid).astype(np.int64)


#: Version 5's layouts of the in-plane centroid rows (``params["centroid_layout"]``):
#: in entry order (cell order: a smooth surface's neighbouring voxels follow
#: each other), or :func:`_plane_orders` (scattered leaves). The encoder keeps
#: whichever packs smaller.
CENTROID_LAYOUTS = ("entries", "sources")


def _centroid_bits(bits: Bits) -> int:
    """The widest of a centroid's codes (the member's byte planes)."""
    return max(bits.centroid, bits.centroid_closed, bits.depth)


def _encode_centroid_frame(centroid, origin, voxel_size, coords, voxel, unit, parent_src, bits,
                           depth_bits=None, layout: str | None = None, plane_bits=None) -> np.ndarray:  # fmt: skip
    """(3, E) codes of each centroid in its entry's normal frame (version 3):
    its offset from the voxel centre along the decoded unit normal ``unit``
    (``bits.depth`` bits, within h sqrt(3) / 4 s), and in the plane
    (``bits.centroid`` bits a coordinate). Depth is what the volume's sheets
    and the splats' depth need; the tangent coordinates only slide a splat
    in its plane. An entry with a parent (``parent_src``, its source entry, is
    not itself) lies on its source's plane when their facets are coplanar
    (a leaf across voxels): its depth is stored as the difference, modulo
    ``2**bits.depth``, from the depth of that plane in its voxel.
    ``depth_bits`` (E,): each entry's depth bits (version 5: fewer for
    spread normals, :func:`depth_shifts`; a child has its source's), else
    ``bits.depth``. ``layout`` (version 5, one of :data:`CENTROID_LAYOUTS`;
    None: versions 3 and 4, entry order): a parentless entry's depth is
    stored from its chord's start (:func:`_chord_start`), the depths grouped
    by their bits (:func:`_by_shift`), the in-plane rows in entry order or in
    :func:`_plane_orders`. ``plane_bits`` (E,): each entry's in-plane bits
    (version 7, :func:`plane_bits`), else ``bits.centroid``."""
    f = (np.asarray(centroid, dtype=np.float64) - origin) / voxel_size - coords[voxel] - 0.5
    f = np.clip(f, -0.5, 0.5)
    t, b = tangent_frame(unit)
    db = np.full(len(f), bits.depth, dtype=np.int64) if depth_bits is None else np.asarray(depth_bits, np.int64)
    pb = np.full(len(f), bits.centroid, dtype=np.int64) if plane_bits is None else np.asarray(plane_bits, np.int64)
    mp, sp = _steps(pb)
    codes = np.empty((3, len(f)), dtype=np.int64)
    codes[0] = _depth_codes(f, unit, db)
    codes[1] = mp + np.clip(np.round(np.sum(f * t, axis=1) * sp), -mp, mp)
    codes[2] = mp + np.clip(np.round(np.sum(f * b, axis=1) * sp), -mp, mp)
    child = np.flatnonzero(parent_src != np.arange(len(f)))
    at = np.zeros((0, 3))
    if len(child):
        root = parent_src[child]
        # The sources' centroids as decoded, seen from each child's voxel.
        at = _frame_offsets(codes[:, root], unit[root], t[root], b[root], bits, db[root], pb[root])
        at += coords[voxel[root]] - coords[voxel[child]]
        dc = db[child]
        codes[0, child] = (codes[0, child] - _depth_codes(at, unit[child], dc)) % np.left_shift(1, dc)
    if layout is not None:
        free = np.setdiff1d(np.arange(len(f)), child, assume_unique=True)
        start = _chord_start(codes[:, free], unit[free], t[free], b[free], db[free], pb[free])
        codes[0, free] = (codes[0, free] - start) % np.left_shift(1, db[free])
        ou = ov = np.arange(len(f))
        if layout == "sources":
            ou, ov = _plane_orders(at, t, b, child, len(f), pb)
        codes = np.stack([codes[0][_by_shift(db)], codes[1][ou], codes[2][ov]])
    return codes.astype(np.uint16)


def _decode_centroid_frame(codes, origin, voxel_size, coords, voxel, unit, tb, parent_src, bits,
                           depth_bits=None, layout: str | None = None, plane_bits=None) -> np.ndarray:  # fmt: skip
    """The inverse of :func:`_encode_centroid_frame`; ``tb`` is
    :func:`~aniso3d.grid.tangent_frame` of ``unit``."""
    t, b = tb
    e = codes.shape[1]
    stored = codes.astype(np.int64)
    db = np.full(e, bits.depth, dtype=np.int64) if depth_bits is None else depth_bits
    pb = np.full(e, bits.centroid, dtype=np.int64) if plane_bits is None else np.asarray(plane_bits, np.int64)
    md, _ = _steps(db)
    mp, _ = _steps(pb)
    child = np.flatnonzero(parent_src != np.arange(e))
    codes = stored if layout is None else np.empty_like(stored)
    if layout is not None:
        # depths back from their groups
        codes[0, _by_shift(db)] = stored[0]
    if codes.size and (np.any(codes[0] >= np.left_shift(1, db)) or int(stored[1:].max()) > 2 * int(mp.max())):
        raise FormatError("entry_centroid holds codes past the voxel")
    free = np.setdiff1d(np.arange(e), child, assume_unique=True) if layout is not None else None
    if layout == "entries":
        codes[1:] = stored[1:]
    elif layout == "sources":
        # the parentless entries' in-plane codes lead both rows, in order:
        # with their depths they give the children's order
        codes[1:, free] = stored[1:, : len(free)]
    if layout is not None:
        start = _chord_start(codes[:, free], unit[free], t[free], b[free], db[free], pb[free])
        codes[0, free] = (codes[0, free] + start) % np.left_shift(1, db[free])
    if len(child):
        root = parent_src[child]
        at = _frame_offsets(codes[:, root], unit[root], t[root], b[root], bits, db[root], pb[root])
        at += coords[voxel[root]] - coords[voxel[child]]
        if layout == "sources":
            ou, ov = _plane_orders(at, t, b, child, e, pb)
            codes[1, ou[len(free) :]] = stored[1, len(free) :]
            codes[2, ov[len(free) :]] = stored[2, len(free) :]
        dc = db[child]
        codes[0, child] = (codes[0, child] + _depth_codes(at, unit[child], dc)) % np.left_shift(1, dc)
    if codes.size and (np.any(codes[0] > 2 * md) or np.any(codes[1:] > 2 * mp)):
        raise FormatError("entry_centroid holds codes past the voxel")
    return origin + (coords[voxel] + 0.5 + _frame_offsets(codes, unit, t, b, bits, db, pb)) * voxel_size


# ------------------------------------------------------------ copy prediction


def _entry_keys(coords: np.ndarray, shape: np.ndarray, voxel: np.ndarray, direction: np.ndarray, k: int):
    """(E,) int64 ``cell key * K + sample direction`` of each entry: sorted,
    as entries are sorted by cell and then by direction."""
    return cell_keys(coords, shape)[voxel] * k + np.asarray(direction, dtype=np.int64)


def _neighbour_entries(coords, shape, voxel, direction, k, ekeys, offset, which=None) -> np.ndarray:
    """(E,) (or (len(which),)) index of the entry with the same sample
    direction in the voxel at ``offset`` from each entry's, -1 where there is none."""
    sel = slice(None) if which is None else which
    cell = coords[voxel[sel]] + offset
    inside = np.all((cell >= 0) & (cell < shape), axis=1)
    key = cell_keys(np.clip(cell, 0, shape - 1), shape) * k + np.asarray(direction, dtype=np.int64)[sel]
    i = np.minimum(np.searchsorted(ekeys, key), max(len(ekeys) - 1, 0))
    hit = inside & (ekeys[i] == key) if len(ekeys) else np.zeros(len(key), bool)
    return np.where(hit, i, -1)


def _copy_parents(coords, shape, voxel, direction, k, fields: list[np.ndarray]) -> np.ndarray:
    """(E,) uint8 ``entry_parent``: j > 0 when the entry's codes of every
    array of ``fields`` (each (R, E)) equal those of the entry with the same
    sample direction in the voxel at ``PARENT_OFFSETS[j - 1]`` (the first such
    neighbour), else 0. A leaf or a blade crossing several voxels leaves
    entries with the same normal and material in each: all but the first
    copy theirs. Neighbours come earlier in cell order, so parents form a forest."""
    e = len(direction)
    ekeys = _entry_keys(coords, shape, voxel, direction, k)
    codes = np.vstack([np.atleast_2d(f) for f in fields]) if fields else np.zeros((0, e))
    parent = np.zeros(e, dtype=np.uint8)
    for j, offset in enumerate(PARENT_OFFSETS, start=1):
        open_ = np.flatnonzero(parent == 0)
        if not len(open_):
            break
        nb = _neighbour_entries(coords, shape, voxel, direction, k, ekeys, offset, open_)
        has = nb >= 0
        cand, nb = open_[has], nb[has]
        same = np.all(codes[:, cand] == codes[:, nb], axis=0)
        parent[cand[same]] = j
    return parent


def _candidates(coords: np.ndarray, shape: np.ndarray, offsets: np.ndarray, voxel: np.ndarray,
                direction: np.ndarray, k: int) -> np.ndarray:  # fmt: skip
    """(E, 13) bool: whether the voxel at each of :data:`PARENT_OFFSETS` from
    an entry's has an entry at its sample direction (a parent it could
    name). Looked up per voxel, then read per entry."""
    m = len(coords)
    keys = cell_keys(coords, shape)
    occupied = np.zeros((m + 1, k), dtype=bool)  # row m: no voxel
    occupied[voxel, direction] = True
    out = np.zeros((len(voxel), len(PARENT_OFFSETS)), dtype=bool)
    for j, off in enumerate(PARENT_OFFSETS):  # thirteen
        cell = coords + off
        inside = np.all((cell >= 0) & (cell < shape), axis=1)
        key = cell_keys(np.clip(cell, 0, shape - 1), shape)
        i = np.minimum(np.searchsorted(keys, key), max(m - 1, 0))
        nb = np.where(inside & (keys[i] == key), i, m) if m else np.zeros(0, np.int64)
        out[:, j] = occupied[nb[voxel], direction]
    return out


def _encode_parent_ranks(parent: np.ndarray, cand: np.ndarray) -> np.ndarray:
    """(N,) uint8, version 5's ``entry_parent``: for each entry with at least
    one candidate (:func:`_candidates`), 0 or the rank of its parent among
    its candidates (1 the first), in order of how many it has (stable). An
    entry without candidates has no parent and stores nothing."""
    n = cand.sum(axis=1)
    j = np.maximum(parent.astype(np.int64) - 1, 0)
    rank = np.where(parent > 0, np.take_along_axis(np.cumsum(cand, axis=1), j[:, None], axis=1)[:, 0], 0)
    has = np.flatnonzero(n > 0)
    return rank[has][_by_shift(n[has])].astype(np.uint8)


def _decode_parent_ranks(ranks: np.ndarray, cand: np.ndarray) -> np.ndarray:
    """The inverse of :func:`_encode_parent_ranks`: (E,) uint8 parents."""
    n = cand.sum(axis=1)
    has = np.flatnonzero(n > 0)
    if ranks.shape != (len(has),):
        raise FormatError(f"entry_parent has shape {ranks.shape}, expected {(len(has),)}")
    if len(ranks) and int(ranks.max()) > len(PARENT_OFFSETS):
        raise FormatError(f"entry_parent holds codes above {len(PARENT_OFFSETS)}")
    rank = np.zeros(len(n), dtype=np.int64)
    rank[has[_by_shift(n[has])]] = ranks
    if np.any(rank > n):
        raise FormatError("entry_parent names a neighbour without an entry in that sample direction")
    # the rank-th candidate: the first offset whose running count reaches it
    j = np.argmax(np.cumsum(cand, axis=1) >= np.maximum(rank, 1)[:, None], axis=1)
    return np.where(rank > 0, j + 1, 0).astype(np.uint8)


def _copy_sources(parent: np.ndarray, coords, shape, voxel, direction, k) -> np.ndarray:
    """(E,) index of the entry whose stored codes each entry takes: itself
    when ``parent`` is 0, else its parent's source (pointer jumping: about
    log2 of the longest chain of NumPy passes). Raises FormatError for a
    parent that names no entry."""
    e = len(parent)
    src = np.arange(e, dtype=np.int64)
    if e and int(parent.max()) > len(PARENT_OFFSETS):
        raise FormatError(f"entry_parent holds codes above {len(PARENT_OFFSETS)}")
    child = np.flatnonzero(parent)
    if not len(child):
        return src
    ekeys = _entry_keys(coords, shape, voxel, direction, k)
    nb = np.empty(len(child), dtype=np.int64)
    pj = parent[child].astype(np.int64) - 1
    for j in np.unique(pj):
        sel = np.flatnonzero(pj == j)
        nb[sel] = _neighbour_entries(coords, shape, voxel, direction, k, ekeys, PARENT_OFFSETS[j], child[sel])
    if np.any(nb < 0):
        raise FormatError("entry_parent names a neighbour without an entry in that sample direction")
    src[child] = nb
    while True:  # parents come earlier, so this ends (each pass halves every chain)
        nxt = src[src]
        if np.array_equal(nxt, src):
            return src
        src = nxt


# ------------------------------------------------------------------- the whole


def _check_shapes(arrays: dict[str, np.ndarray]) -> None:
    """Refuse arrays that do not make one texture (what the compact encoding relies on)."""
    m, k = len(arrays["coords"]), len(arrays["directions"])
    e = len(arrays["entry_direction"])
    want = {"origin": (3,), "shape": (3,), "coords": (m, 3), "directions": (k, 3), "density": (m, k),
            "entry_offsets": (m + 1,), "entry_area": (e,), "entry_kd": (e, 3), "entry_ks": (e,),
            "entry_shininess": (e,), "entry_centroid": (e, 3), "entry_normal": (e, 3), "entry_cover": (e,),
            "entry_side": (e,)}  # fmt: skip
    for name, shape in want.items():
        got = np.shape(arrays[name])
        if got != shape:
            raise InputError(f"texture field '{name}' has shape {got}, expected {shape}; it cannot be encoded")
    off = np.asarray(arrays["entry_offsets"])
    if off[0] != 0 or off[-1] != e or np.any(np.diff(off) < 0):
        raise InputError("texture entry_offsets are not a valid CSR offset array; it cannot be encoded")
    d = np.asarray(arrays["entry_direction"])
    if e and (d.min() < 0 or d.max() >= k):
        raise InputError(f"texture entry_direction lies outside 0..{k - 1}; it cannot be encoded")
    side = np.asarray(arrays["entry_side"])
    if e and not np.all((side == -1) | (side == 0) | (side == 1)):
        raise InputError("texture entry_side holds values other than -1, 0 and 1; it cannot be encoded")


def _check_finite_nonnegative(arrays: dict[str, np.ndarray]) -> None:
    for name in ("density", "entry_area", "entry_kd", "entry_ks", "entry_shininess",
                 "entry_centroid", "entry_normal", "directions", "origin"):  # fmt: skip
        a = np.asarray(arrays[name])
        if not np.isfinite(a).all():
            raise InputError(f"texture field '{name}' holds NaN or infinite values; it cannot be encoded")
        if name in ("density", "entry_area", "entry_kd", "entry_ks", "entry_shininess") and np.any(a < 0):
            raise InputError(f"texture field '{name}' holds negative values; it cannot be encoded")


def encode(arrays: dict[str, np.ndarray], voxel_size: float, bits: Bits = DEFAULT_BITS) -> tuple[dict, dict]:
    """The compact encoding of a texture's ``arrays`` (every name of :data:`ARRAYS`).

    Returns ``(members, params)``: ``members`` maps each name of :data:`MEMBERS`
    (``density`` only when ``bits.density > 0``) to an array to store, and
    ``params`` the JSON numbers :func:`decode` needs (the bits and each
    quantiser's range). Deterministic: equal inputs give equal outputs.
    """
    _check_shapes(arrays)
    _check_finite_nonnegative(arrays)
    origin = np.asarray(arrays["origin"], dtype=np.float64)
    shape = np.asarray(arrays["shape"], dtype=np.int64)
    coords = np.asarray(arrays["coords"], dtype=np.int64)
    dirs = np.asarray(arrays["directions"], dtype=np.float64)
    offsets = np.asarray(arrays["entry_offsets"], dtype=np.int64)
    k = len(dirs)
    if len(coords) and (np.any(coords < 0) or np.any(coords >= shape)):
        raise InputError("texture coords lie outside its grid shape; it cannot be encoded")
    voxel = np.repeat(np.arange(len(coords)), np.diff(offsets))

    area_codes, area_span = _encode_log(arrays["entry_area"], bits.area)
    normal = np.asarray(arrays["entry_normal"], dtype=np.float64)
    length = np.linalg.norm(normal, axis=1)
    # A zero mean normal (facets that cancel) has no direction: any will do.
    sample = dirs[np.asarray(arrays["entry_direction"], dtype=np.int64)]
    unit = np.where((length > 0)[:, None], normal / np.where(length > 0, length, 1.0)[:, None], sample)
    coherence_codes = _encode_spread(np.minimum(length, 1.0), bits.coherence)
    # (version 2 stored lengths on their own range; the range written says
    # the codes' limit, and version 3 decodes them with _decode_spread)
    coherence_range = [[0.0, 1.0, 2**bits.coherence - 1]]
    kd_codes, kd_range = _encode_range(np.asarray(arrays["entry_kd"]).T, bits.kd)
    ks_codes, ks_range = _encode_range(arrays["entry_ks"], bits.ks)
    sh_codes, sh_range = _encode_range(arrays["entry_shininess"], bits.shininess, log=True)
    direction = np.asarray(arrays["entry_direction"], dtype=np.int64)
    span = _frame_span(unit, sample)
    # Spread mean normals' directions are stored coarser (version 5): a shift
    # per length code, written into params.
    nb_full = oct_bits(bits)
    table = normal_shifts(bits, None)
    shift = np.asarray(table, dtype=np.int64)[coherence_codes[0]]
    normal_codes = _encode_oct(unit, oct_bits(bits) - shift)
    if span is not None:
        # Smooth surfaces: spatially adjacent normals are adjacent on the
        # octahedral map, and deflate finds that; scattered facets (foliage)
        # take fewer bytes about their sample directions. Keep the smaller.
        framed_table = normal_shifts(bits, span)
        framed_shift = np.asarray(framed_table, dtype=np.int64)[coherence_codes[0]]
        framed = _encode_frame(unit, sample, bits.normal - framed_shift, span)
        if _deflated(framed[:, _by_shift(framed_shift, direction)], bits.normal) < _deflated(
                normal_codes[:, _by_shift(shift, direction)], oct_bits(bits)):  # fmt: skip
            normal_codes, table, shift, nb_full = framed, framed_table, framed_shift, bits.normal
        else:
            span = None
    params = {
        "bits": asdict(bits),
        "area_log2_range": area_span,
        "normal_frame_span": span,
        "normal_shifts": table,
        "ranges": {"coherence": coherence_range, "kd": kd_range, "ks": ks_range, "shininess": sh_range},
    }
    members = {
        "origin": origin,
        "shape": shape,
        "directions": dirs,
        "coords": _encode_keys(coords, shape),
        "entry_mask": _encode_mask_split(offsets, arrays["entry_direction"], k, coords, shape),
        "entry_coherence": to_planes(coherence_codes, _width(bits.coherence)),
        "entry_kd": to_planes(kd_codes, _width(bits.kd)),
        "entry_ks": to_planes(ks_codes, _width(bits.ks)),
        "entry_shininess": to_planes(sh_codes, _width(bits.shininess)),
    }
    copied = {"entry_normal": normal_codes, "entry_coherence": coherence_codes, "entry_kd": kd_codes,
              "entry_ks": ks_codes, "entry_shininess": sh_codes}  # fmt: skip
    parent = _copy_parents(coords, shape, voxel, direction, k, [copied[n] for n in COPIED])
    members["entry_parent"] = _encode_parent_ranks(parent, _candidates(coords, shape, offsets, voxel, direction, k))
    src = _copy_sources(parent, coords, shape, voxel, direction, k)
    unit_dec = _decode_unit_normal(normal_codes, bits, span, sample, shift=shift)
    dtable = depth_shifts(bits)
    params["depth_shifts"] = dtable
    dshift = np.asarray(dtable, dtype=np.int64)[coherence_codes[0]]
    pbits = plane_bits(arrays["entry_side"], bits)
    # Both layouts of the in-plane rows; the file keeps the one that packs smaller.
    laid = {layout: to_planes(_encode_centroid_frame(arrays["entry_centroid"], origin, float(voxel_size), coords,
                                                     voxel, unit_dec, src, bits, bits.depth - dshift, layout, pbits),
                              _width(_centroid_bits(bits)))
            for layout in CENTROID_LAYOUTS}  # fmt: skip
    params["centroid_layout"] = min(CENTROID_LAYOUTS, key=lambda layout: _packed(laid[layout]))
    members["entry_centroid"] = laid[params["centroid_layout"]]
    roots = parent == 0
    for n in COPIED:
        members[n] = to_planes(np.atleast_2d(copied[n])[:, roots], _width(getattr(bits, _BITS_OF[n])))
    # Directions grouped by their shift (stable): LZMA then sees codes of one
    # range at a time, instead of a mixture that hides the coarse ones' savings.
    members["entry_normal"] = to_planes(normal_codes[:, roots][:, _by_shift(shift[roots], direction[roots])],
                                        _width(nb_full))  # fmt: skip
    # Shininess and kd in the order of the ks codes: a material's values go
    # together, so a run of one ks holds nearly one shininess, and the bark's
    # (one colour) or a wall's kd repeat there instead of between the leaves'.
    by_ks = _by_shift(ks_codes[0, roots])
    members["entry_shininess"] = to_planes(sh_codes[:, roots][:, by_ks], _width(bits.shininess))
    members["entry_kd"] = to_planes(kd_codes[:, roots][:, by_ks], _width(bits.kd))
    cover_codes = _encode_cover(arrays["entry_cover"], bits.cover)
    members["entry_cover"] = cover_codes
    members["entry_side"] = _encode_sides(arrays["entry_side"], _side_predictors(coords, shape, voxel, direction, k))
    # Areas in entry order (a smooth surface's follow each other), or by their
    # normal's length (a mix of several facets is larger): whichever packs smaller.
    laid = {"entries": to_planes(area_codes, _width(bits.area)),
            "length": to_planes(area_codes[_by_shift(coherence_codes[0])], _width(bits.area))}  # fmt: skip
    params["area_order"] = min(AREA_ORDERS, key=lambda order: _packed(laid[order]))
    members["entry_area"] = laid[params["area_order"]]
    members = {n: members[n] for n in MEMBERS if n in members}
    if bits.density:
        # The residual against F of the *decoded* entries: what decode adds back.
        area = _decode_log(area_codes, bits.area, area_span)
        nrm = _decode_normal(normal_codes, coherence_codes, None, bits, span, sample, shift=shift)
        f = facet_density(area * _decode_cover(cover_codes, bits.cover), nrm, offsets, dirs)
        a_v = np.bincount(voxel, weights=area, minlength=len(coords))
        residual = np.asarray(arrays["density"], dtype=np.float64) - f
        scale = np.where(a_v > 0, a_v, 1.0)[:, None]
        # Below F where a thin solid's back is hidden (aniso3d.build.closure):
        # codes then start ``zero`` steps below 0 (version 4; 0 otherwise).
        top = 2**bits.density - 1
        hidden = bool(np.any(np.asarray(arrays["entry_cover"]) < 1.0))
        # A voxel whose decoded covers hide nothing keeps D >= F, as without hiding.
        covered = _decode_cover(cover_codes, bits.cover) < 1.0
        whole = np.bincount(voxel, weights=covered, minlength=len(coords)) == 0
        residual = np.where(whole[:, None], np.maximum(residual, 0.0), residual)
        low = float(np.min(residual / scale, initial=0.0)) if hidden else 0.0
        zero = min(int(math.ceil(-low * top - 0.5)), top - 1) if low < 0 else 0
        codes = _encode_unit(residual / scale + zero / top, bits.density, 1.0)
        members["density"] = to_planes(codes.reshape(1, -1), _width(bits.density))
        if zero:
            params["density_zero"] = zero
    return members, params


def decode(members: dict[str, np.ndarray], params: dict, voxel_size: float, version: int = 7
           ) -> dict[str, np.ndarray]:
    """The texture arrays (every name of :data:`ARRAYS`, dtypes as
    :func:`~aniso3d.build.texture.build_texture` makes them) of a compact
    encoding. Raises :class:`~aniso3d.errors.FormatError` naming what does
    not fit when members or params are inconsistent."""
    try:
        stated = dict(params["bits"])
        if version < 7:  # one in-plane count for every entry
            stated["centroid_closed"] = stated["centroid"]
        bits = Bits(**stated)
        area_span = [float(x) for x in params["area_log2_range"]]
        span = params["normal_frame_span"]
        span = None if span is None else float(span)
        ranges = {}
        for name, rows in (("coherence", 1), ("kd", 3), ("ks", 1), ("shininess", 1)):
            r = [[float(lo), float(hi), n] for lo, hi, n in params["ranges"][name]]
            b = getattr(bits, name)
            ok = len(r) == rows and all(
                math.isfinite(lo) and math.isfinite(hi) and 0 <= lo <= hi
                and not isinstance(n, bool) and isinstance(n, int) and 0 <= n < 2**b
                for lo, hi, n in r
            )  # fmt: skip
            if not ok:
                raise ValueError(f"range of {name} is {r}")
            ranges[name] = r
    except (KeyError, TypeError, ValueError) as exc:
        raise FormatError(f"the encoding parameters are damaged ({exc})") from None
    if len(area_span) != 2 or not all(math.isfinite(x) for x in (*area_span, 0.0 if span is None else span)):
        raise FormatError("the encoding parameters are damaged (not finite numbers)")
    table, layout, area_order = None, None, None
    if version >= 5:
        table = params.get("normal_shifts")
        full = bits.normal if span is not None else oct_bits(bits)
        if not (isinstance(table, list) and len(table) == 2**bits.coherence and all(
                not isinstance(x, bool) and isinstance(x, int) and 0 <= x <= full - 2 for x in table)):
            raise FormatError("the encoding parameters are damaged (normal_shifts)")
        layout = params.get("centroid_layout")
        if layout not in CENTROID_LAYOUTS:
            raise FormatError(f"the encoding parameters are damaged (centroid_layout is {layout!r})")
        area_order = params.get("area_order")
        if area_order not in AREA_ORDERS:
            raise FormatError(f"the encoding parameters are damaged (area_order is {area_order!r})")
        dtable = params.get("depth_shifts")
        if not (isinstance(dtable, list) and len(dtable) == 2**bits.coherence and all(
                not isinstance(x, bool) and isinstance(x, int) and 0 <= x <= bits.depth - 2 for x in dtable)):
            raise FormatError("the encoding parameters are damaged (depth_shifts)")
    origin = _shaped(members, "origin", np.float64, (3,))
    shape = _shaped(members, "shape", np.int64, (3,))
    if np.any(shape < 1):
        raise FormatError(f"shape {shape.tolist()} is not a grid")
    dirs = members["directions"]
    if dirs.ndim != 2 or dirs.shape[1] != 3 or dirs.dtype != np.float64:
        raise FormatError(f"directions has shape {dirs.shape} and dtype {dirs.dtype}, expected (K, 3) float64")
    k = len(dirs)
    coords = _decode_keys(_uint8(members, "coords", None), shape)
    m = len(coords)
    if version >= 5:
        offsets, direction = _decode_mask_split(_uint8(members, "entry_mask", None), m, k, coords.astype(np.int64),
                                                shape)  # fmt: skip
    else:
        offsets, direction = _decode_mask(_uint8(members, "entry_mask", None), m, k)
    e = len(direction)
    voxel = np.repeat(np.arange(m), np.diff(offsets))

    if version >= 3:
        if version >= 5:
            ranks = members["entry_parent"]
            if ranks.dtype != np.uint8 or ranks.ndim != 1:
                raise FormatError(f"entry_parent has shape {ranks.shape} and dtype {ranks.dtype}, expected uint8")
            parent = _decode_parent_ranks(ranks, _candidates(coords.astype(np.int64), shape, offsets, voxel,
                                                             direction, k))  # fmt: skip
        else:
            parent = _uint8(members, "entry_parent", (e,))
        src = _copy_sources(parent, coords.astype(np.int64), shape, voxel, direction, k)
        # A copied member holds the codes of entries without a parent, in
        # order: entry i takes row rank[src[i]] of it. Decoded for those
        # entries only, then gathered.
        roots = np.flatnonzero(parent == 0)
        take = (np.cumsum(parent == 0) - 1)[src]
    else:
        src, roots, take = None, np.arange(e), np.arange(e)

    if version >= 6:  # first: version 7's in-plane centroid bits follow the sides
        side = _decode_sides(members["entry_side"], _side_predictors(coords.astype(np.int64), shape, voxel,
                                                                     direction.astype(np.int64), k))  # fmt: skip
    else:
        side = np.zeros(e, dtype=np.int8)

    def codes(name: str, rows: int, b: int) -> np.ndarray:
        n = len(roots) if name in COPIED else e
        planes = _uint8(members, name, (rows * _width(b), n))
        c = from_planes(planes, rows, _width(b))
        if c.size and int(c.max()) >= 2**b:
            raise FormatError(f"{name} holds codes above {b} bits")
        return c

    nb = bits.normal if span is not None else oct_bits(bits)
    coherence = codes("entry_coherence", 1, bits.coherence)
    area_codes = codes("entry_area", 1, bits.area)[0]
    if area_order == "length":
        grouped, area_codes = area_codes, np.empty_like(area_codes)
        area_codes[_by_shift(coherence[0][take])] = grouped
    area = _decode_log(area_codes, bits.area, area_span)
    normal_codes = codes("entry_normal", 2, nb)
    shift = None
    if version >= 5:
        shift = np.asarray(table, dtype=np.int64)[coherence[0]]
        grouped, normal_codes = normal_codes, np.empty_like(normal_codes)
        normal_codes[:, _by_shift(shift, direction[roots])] = grouped
        if normal_codes.size and np.any(normal_codes > 2 * (np.left_shift(1, nb - shift - 1) - 1)):
            raise FormatError("entry_normal holds codes past their spread's range")
    # tangent frames of the K sample directions, gathered (not one per entry)
    frame = tuple(x[direction[roots]] for x in tangent_frame(dirs)) if span is not None else None
    unit = _decode_unit_normal(normal_codes, bits, span, dirs[direction[roots]], frame, shift)
    length_range = None if version >= 3 else ranges["coherence"]
    normal = _decode_normal(None, coherence, length_range, bits, span, None, unit)[take]
    if version >= 3:
        # The tangent frames of the entries that store a normal, gathered like it.
        tb = tuple(x[take] for x in tangent_frame(unit))
        centroid_codes = codes("entry_centroid", 3, _centroid_bits(bits))
        depth_bits = None
        if version >= 5:
            dshift = np.asarray(dtable, dtype=np.int64)[coherence[0][take]]
            depth_bits = bits.depth - dshift
        # (before version 7, bits.centroid_closed is bits.centroid: one count for all)
        pbits = plane_bits(side, bits)
        centroid = _decode_centroid_frame(centroid_codes, origin, float(voxel_size), coords.astype(np.int64), voxel,
                                          unit[take], tb, src, bits, depth_bits, layout, pbits)  # fmt: skip
    else:
        centroid_codes = codes("entry_centroid", 3, bits.centroid)
        if centroid_codes.size and int(centroid_codes.max()) > 2**bits.centroid - 2:
            raise FormatError("entry_centroid holds codes past the voxel")
        centroid = _decode_centroid(
            centroid_codes, origin, float(voxel_size), coords.astype(np.int64), voxel,
            bits.centroid,
        )  # fmt: skip
    ks_codes = codes("entry_ks", 1, bits.ks)
    ks = _decode_range(ks_codes, bits.ks, ranges["ks"])[0][take]
    sh_codes = codes("entry_shininess", 1, bits.shininess)
    kd_codes = codes("entry_kd", 3, bits.kd)
    if version >= 5:
        by_ks = _by_shift(ks_codes[0])
        grouped, sh_codes = sh_codes, np.empty_like(sh_codes)
        sh_codes[:, by_ks] = grouped
        grouped, kd_codes = kd_codes, np.empty_like(kd_codes)
        kd_codes[:, by_ks] = grouped
    kd = _decode_range(kd_codes, bits.kd, ranges["kd"]).T[take]
    sh = _decode_range(sh_codes, bits.shininess, ranges["shininess"],
                       log=True)[0][take]  # fmt: skip
    if version >= 4:
        cover_codes = _uint8(members, "entry_cover", (1, e))
        if cover_codes.size and int(cover_codes.max()) >= 2**bits.cover:
            raise FormatError(f"entry_cover holds codes above {bits.cover} bits")
        cover = _decode_cover(cover_codes, bits.cover)
    else:
        cover = np.ones(e)
    density = facet_density(area * cover, normal, offsets, dirs)
    if bits.density:
        w = _width(bits.density)
        res = from_planes(_uint8(members, "density", (w, m * k)), 1, w)[0].reshape(m, k)
        if res.size and int(res.max()) >= 2**bits.density:
            raise FormatError(f"density holds codes above {bits.density} bits")
        a_v = np.bincount(voxel, weights=area, minlength=m)
        zero = params.get("density_zero", 0)
        if isinstance(zero, bool) or not isinstance(zero, int) or not 0 <= zero < 2**bits.density:
            raise FormatError(f"the encoding parameters are damaged (density_zero is {zero!r})")
        step = _decode_unit(res, bits.density, 1.0) - zero / (2**bits.density - 1)
        density = np.maximum(density + step * np.where(a_v > 0, a_v, 1.0)[:, None], 0.0)
    return {
        "origin": origin,
        "shape": shape,
        "coords": coords,
        "directions": dirs,
        "density": density,
        "entry_offsets": offsets,
        "entry_direction": direction,
        "entry_area": area,
        "entry_kd": kd.astype(np.float32),
        "entry_ks": ks.astype(np.float32),
        "entry_shininess": np.maximum(sh, 0.0).astype(np.float32),
        "entry_centroid": centroid,
        "entry_normal": normal,
        "entry_cover": cover.astype(np.float32),
        "entry_side": side,
    }


def _shaped(members: dict, name: str, dtype, shape: tuple) -> np.ndarray:
    a = members[name]
    if a.dtype != dtype or a.shape != shape:
        raise FormatError(f"{name} has shape {a.shape} and dtype {a.dtype}, expected {shape} {np.dtype(dtype)}")
    return a


def _uint8(members: dict, name: str, shape: tuple | None) -> np.ndarray:
    a = members[name]
    if a.dtype != np.uint8 or a.ndim != (2 if shape is None else len(shape)):
        raise FormatError(f"{name} has shape {a.shape} and dtype {a.dtype}, expected uint8 byte planes")
    if shape is not None and a.shape != shape:
        raise FormatError(f"{name} has shape {a.shape}, expected {shape}")
    return a
