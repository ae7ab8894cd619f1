"""Stage 3: registration of sub-polygons onto density and shading spheres.

This is paper section 2.2. Every sub-polygon of a voxel adds
``S * |N . N_p|`` to each sample p of the voxel's density sphere, and its
area ``S`` with area-weighted material to the single shading-sphere sample
nearest its normal. Then the polygons are gone; an :class:`AnisoTexture`
holds only the spheres.

Storage is sparse twice over: only occupied voxels exist (``coords``), and a
voxel's shading sphere keeps only its non-empty samples, as *entries* in CSR
layout (``entry_offsets``; the entries of voxel i are
``entry_offsets[i]:entry_offsets[i+1]``).

Besides what the paper keeps, each entry stores the area-weighted centroid of
its facets and their area-weighted mean normal (a vector whose length, 1 for
a flat patch and less for scattered facets, says how coherent they are). Both
are linear sums, so a coarser texture can still be aggregated exactly from a
finer one (:mod:`aniso3d.build.pyramid`); :func:`entry_points` uses them to
put points on the true surface. The ``.a3d`` file is
:mod:`aniso3d.build.texture_file`'s business, and how it quantises the
fields :mod:`aniso3d.build.encoding`'s: in memory the arrays stay float
(:attr:`AnisoTexture.memory_nbytes`), stored they take about 1/16 of that
(:attr:`AnisoTexture.nbytes`).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
import psutil

from aniso3d.build import stream
from aniso3d.build.clip import Grid, make_grid
from aniso3d.build.encoding import ARRAYS, DEFAULT_BITS, Bits, decode, encode
from aniso3d.build.mesh import Mesh
from aniso3d.build.points import PointCloud
from aniso3d.build.texture_file import FORMAT_VERSION, encoded_size, read_texture_file, write_texture_file
from aniso3d.errors import FormatError, InputError
from aniso3d.grid import cell_keys, ranges, tangent_frame

#: Defaults chosen by measurement (docs/bench/report.md): K = 16 is as
#: accurate as 64 or 256 for the volume and splat renderers (both read the
#: entries' own normals and areas) at half the bytes of K = 64.
DEFAULT_RESOLUTION = 128
DEFAULT_DIRECTIONS = 16

DIRECTION_SETS = ("fibonacci", "random")
PLACEMENTS = ("centroid", "center", "sphere")
POINT_NORMALS = ("mean", "sample")


# --------------------------------------------------------------------- directions


def sphere_directions(k: int, kind: str = "fibonacci", seed: int = 0) -> np.ndarray:
    """K unit vectors (K, 3) float64 on the sphere.

    ``fibonacci`` is a deterministic low-discrepancy spiral; ``random`` is the
    paper's choice, uniform on the sphere from a seeded generator.
    """
    if isinstance(k, bool) or int(k) != k or k < 1:
        raise InputError(f"the number of sphere directions must be a whole number >= 1, got {k!r}")
    k = int(k)
    if k > 65536:
        raise InputError(f"{k} sphere directions is above the supported maximum of 65536")
    if kind == "fibonacci":
        i = np.arange(k, dtype=np.float64)
        z = 1.0 - (2.0 * i + 1.0) / k
        r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
        phi = i * np.pi * (3.0 - np.sqrt(5.0))
        d = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    elif kind == "random":
        g = np.random.default_rng(seed)
        d = g.normal(size=(k, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
    else:
        raise InputError(f"unknown direction set '{kind}'; choose one of {', '.join(DIRECTION_SETS)}")
    return d / np.linalg.norm(d, axis=1, keepdims=True)


# ------------------------------------------------------------------------ texture


#: ``meta`` key set on a texture whose fields went through the compact
#: encoding (loaded from a compact file, or :meth:`AnisoTexture.as_stored`):
#: its centroids and normals carry the encoding's rounding, which the volume
#: renderer's sheet crossings allow for (:func:`aniso3d.rendering.volume.entry_sheets`).
#: Its value is the file's format version (2 to 7; ``True`` in textures saved
#: before version 3, which came from version 2 files): how fine the rounding is.
QUANTISED = "quantised"


@dataclass(frozen=True, eq=False)
class AnisoTexture:
    """A sparse anisotropic 3D texture (density and shading spheres per voxel).

    Attributes:
        origin: (3,) float64 world position of the grid's minimum corner.
        voxel_size: voxel edge h, world units.
        shape: (3,) int64 grid cells along x, y, z.
        coords: (M, 3) int32 integer cell of each occupied voxel, sorted.
        directions: (K, 3) float64 unit sample directions N_p shared by both spheres.
        density: (M, K) float64 density sphere ``D_v(p) = sum S |N . N_p|``,
            units of h^2 (facet area projected along N_p).
        entry_offsets: (M + 1,) int64 CSR offsets of each voxel's shading entries.
        entry_direction: (E,) int32 sample index p of each shading entry.
        entry_area: (E,) float64 facet area registered at the entry, units of h^2.
        entry_kd: (E, 3) float32 area-weighted diffuse reflectance.
        entry_ks: (E,) float32 area-weighted specular coefficient.
        entry_shininess: (E,) float32 area-weighted Phong exponent.
        entry_centroid: (E, 3) float64 area-weighted facet centroid, world units.
        entry_normal: (E, 3) float32 area-weighted mean facet normal (length <= 1).
        meta: provenance (direction set, seed, source, triangle count, mesh area).
        entry_cover: (E,) float32 in [0.5, 1], the share of the entry's area
            that is not hidden behind its own voxel's closed surface (the
            back of a thin solid; :mod:`aniso3d.build.closure`): what splats
            and the volume's sheets draw of it. 1 (default): all of it.
        entry_closed_area, entry_closed_normal: (E,) and (E, 3) float64, the
            area and vector area ``sum S n`` (h^2) of the entry's pieces on
            closed surfaces, as built: what :func:`aniso3d.build.pyramid.coarsen`
            needs to find what a coarser voxel's solids hide. Not stored in
            files; None (a loaded texture): unknown.
        entry_side: (E,) int8, +1 or -1 where every piece of the entry lies
            on a closed surface (:meth:`~aniso3d.build.mesh.Mesh.closed_sides`)
            and the entry's mean normal points out of it or into it, 0
            elsewhere (:func:`entry_sides`, whose points are one-sided where
            it is not 0). None (default): derived from the closed sums when
            they are known, else 0 (two-sided). Files store it since format
            version 6; older ones read as 0.
    """

    origin: np.ndarray
    voxel_size: float
    shape: np.ndarray
    coords: np.ndarray
    directions: np.ndarray
    density: np.ndarray
    entry_offsets: np.ndarray
    entry_direction: np.ndarray
    entry_area: np.ndarray
    entry_kd: np.ndarray
    entry_ks: np.ndarray
    entry_shininess: np.ndarray
    entry_centroid: np.ndarray
    entry_normal: np.ndarray
    meta: dict = field(default_factory=dict)
    entry_cover: np.ndarray | None = None
    entry_closed_area: np.ndarray | None = None
    entry_closed_normal: np.ndarray | None = None
    entry_side: np.ndarray | None = None

    def __post_init__(self) -> None:
        m, k = len(self.coords), len(self.directions)
        e = len(self.entry_direction)
        if self.entry_cover is None:
            object.__setattr__(self, "entry_cover", np.ones(e, dtype=np.float32))
        checks = {
            "origin": (np.shape(self.origin), (3,)),
            "shape": (np.shape(self.shape), (3,)),
            "coords": (np.shape(self.coords), (m, 3)),
            "directions": (np.shape(self.directions), (k, 3)),
            "density": (np.shape(self.density), (m, k)),
            "entry_offsets": (np.shape(self.entry_offsets), (m + 1,)),
            "entry_area": (np.shape(self.entry_area), (e,)),
            "entry_kd": (np.shape(self.entry_kd), (e, 3)),
            "entry_ks": (np.shape(self.entry_ks), (e,)),
            "entry_shininess": (np.shape(self.entry_shininess), (e,)),
            "entry_centroid": (np.shape(self.entry_centroid), (e, 3)),
            "entry_normal": (np.shape(self.entry_normal), (e, 3)),
            "entry_cover": (np.shape(self.entry_cover), (e,)),
        }
        if (self.entry_closed_area is None) != (self.entry_closed_normal is None):
            raise FormatError("texture fields 'entry_closed_area' and 'entry_closed_normal' come together")
        if self.entry_closed_area is not None:
            checks["entry_closed_area"] = (np.shape(self.entry_closed_area), (e,))
            checks["entry_closed_normal"] = (np.shape(self.entry_closed_normal), (e, 3))
        for name, (got, want) in checks.items():
            if tuple(got) != want:
                raise FormatError(f"texture field '{name}' has shape {got}, expected {want}")
        if not (np.isfinite(self.voxel_size) and self.voxel_size > 0):
            raise FormatError(f"texture voxel_size must be positive, got {self.voxel_size}")
        off = np.asarray(self.entry_offsets)
        if m and (off[0] != 0 or off[-1] != e or np.any(np.diff(off) < 0)):
            raise FormatError("texture entry_offsets are not a valid CSR offset array")
        if self.entry_side is None:
            # As built: from the closed sums, against the mean normals (what
            # files store); unknown: every entry two-sided.
            side = np.zeros(e, dtype=np.int8)
            if self.entry_closed_area is not None:
                side = _closed_sides(self, slice(None), _entry_normals(self, slice(None), "mean"))
            object.__setattr__(self, "entry_side", side)
        else:
            side = np.asarray(self.entry_side)
            if side.shape != (e,):
                raise FormatError(f"texture field 'entry_side' has shape {side.shape}, expected {(e,)}")
            if side.size and not np.all((side == -1) | (side == 0) | (side == 1)):
                raise FormatError("texture field 'entry_side' holds values other than -1, 0 and 1")
            object.__setattr__(self, "entry_side", side.astype(np.int8))

    # ---------------------------------------------------------------- basics

    @property
    def n_voxels(self) -> int:
        return len(self.coords)

    @property
    def n_entries(self) -> int:
        return len(self.entry_direction)

    @property
    def n_directions(self) -> int:
        return len(self.directions)

    @property
    def resolution(self) -> int:
        return int(np.max(self.shape))

    @property
    def grid(self) -> Grid:
        return Grid(np.asarray(self.origin, np.float64), float(self.voxel_size), np.asarray(self.shape))

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) world bounds of the grid."""
        o = np.asarray(self.origin, np.float64)
        return np.stack([o, o + np.asarray(self.shape) * self.voxel_size])

    @property
    def entry_voxel(self) -> np.ndarray:
        """(E,) index into ``coords`` of each shading entry."""
        return np.repeat(np.arange(self.n_voxels), np.diff(self.entry_offsets))

    def voxel_centers(self) -> np.ndarray:
        return self.grid.cell_centers(self.coords)

    @property
    def memory_nbytes(self) -> int:
        """Bytes of the arrays as held in memory (float64 density, areas and
        centroids, float32 materials and normals): what computing with the
        texture costs. :attr:`nbytes` is what storing it costs."""
        return int(sum(np.asarray(getattr(self, n)).nbytes for n in ARRAYS if n not in ("origin", "shape")))

    @cached_property
    def nbytes(self) -> int:
        """Bytes of the texture as stored and shipped: the size of the ``.a3d``
        file :meth:`save` writes by default (format version 7, compact
        encoding, LZMA-compressed; :mod:`aniso3d.build.encoding`), computed in memory
        once. :attr:`memory_nbytes` is the size of the arrays in memory."""
        return encoded_size(self._arrays(), self.voxel_size, self.meta)

    def as_stored(self, bits: Bits = DEFAULT_BITS) -> AnisoTexture:
        """The texture as a compact file stores it: what :meth:`load` returns
        after :meth:`save` with these ``bits``, without a file (every field
        quantised and decoded; see :mod:`aniso3d.build.encoding` for the
        error of each)."""
        members, params = encode(self._arrays(), self.voxel_size, bits)
        return AnisoTexture(voxel_size=self.voxel_size, meta={**self.meta, QUANTISED: FORMAT_VERSION},
                            **decode(members, params, self.voxel_size))  # fmt: skip

    def _arrays(self) -> dict[str, np.ndarray]:
        return {n: getattr(self, n) for n in ARRAYS}

    def local_centroids(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(N, 3) float64: the centroids of the entries ``rows`` in their
        voxels' local grid coordinates (the voxel is the unit cube), where
        the renderers fit their sheets, edges and lines."""
        h = float(self.voxel_size)
        local = (np.asarray(self.entry_centroid, np.float64)[rows] - np.asarray(self.origin, np.float64)) / h
        return local - np.asarray(self.coords, np.float64)[np.asarray(self.entry_voxel)[rows]]

    def total_area(self) -> float:
        """Registered facet area, world units squared (equals the mesh area)."""
        return float(np.sum(self.entry_area) * self.voxel_size**2)

    def coverage(self, w: np.ndarray) -> np.ndarray:
        """(M,) fraction ``D_v(w) / P(w)`` of each voxel covered seen along the
        unit vector ``w``, from the density sample nearest ``w``; may exceed 1."""
        w = np.asarray(w, dtype=np.float64)
        w = w / np.linalg.norm(w)
        p = int(np.argmax(np.abs(self.directions @ w)))
        return self.density[:, p] / np.abs(w).sum()

    # ---------------------------------------------------------------- points

    def to_points(
        self,
        placement: str = "centroid",
        per_entry: int | np.ndarray = 1,
        normal: str = "mean",
    ) -> PointCloud:
        """Oriented points from the shading entries (paper section 3.1).

        Every entry becomes ``per_entry`` points (one count for all, or an (E,)
        array of counts per entry) whose areas sum to the entry's facet area.
        ``placement`` puts them at the facets' area-weighted ``centroid`` (on
        the true surface), the voxel ``center``, or on the voxel's virtual
        ``sphere`` (radius h/2) in the entry's sample direction. ``normal`` is
        the facets' area-weighted ``mean`` normal or the entry's ``sample``
        direction N_p (the paper's reading). See :func:`entry_points`.
        """
        arrays = entry_points(self, None, placement, per_entry, normal)
        return PointCloud(*arrays, name=str(self.meta.get("source", "points")),
                          coherence=entry_coherence(self, None, per_entry),
                          one_sided=entry_one_sided(self, None, per_entry, normal))  # fmt: skip

    # ------------------------------------------------------------------ I/O

    #: The arrays of a texture (see :mod:`aniso3d.build.encoding`).
    _ARRAYS = ARRAYS

    def save(self, path: str | os.PathLike, encoding: str = "compact", bits: Bits = DEFAULT_BITS) -> Path:
        """Write a versioned ``.a3d`` file (a zip of .npy arrays and a JSON header
        with a SHA-256 of the arrays); loads without pickle. Written atomically.

        ``encoding="compact"`` (default) quantises every field with ``bits``
        (:mod:`aniso3d.build.encoding`: about 1/16 of :attr:`memory_nbytes`
        for the default tree, with stated error bounds); ``"exact"`` keeps
        the arrays bit for bit (deflated).
        """
        out = write_texture_file(path, self._arrays(), self.voxel_size, self.meta, encoding, bits)
        if encoding == "compact" and bits == DEFAULT_BITS:
            # That is the file nbytes measures: no need to encode it again.
            self.__dict__["nbytes"] = out.stat().st_size
        return out

    @classmethod
    def load(cls, path: str | os.PathLike) -> AnisoTexture:
        """Read a file written by :meth:`save` (any version up to the current
        one); refuse foreign, damaged or newer files."""
        f = read_texture_file(path)
        meta = {**f.meta, QUANTISED: f.version} if f.encoding == "compact" else f.meta
        try:
            return cls(voxel_size=f.voxel_size, meta=meta, **f.arrays)
        except FormatError as exc:
            raise FormatError(f"'{Path(path)}' is damaged: {exc}; rebuild it from its mesh") from None


# ------------------------------------------------------------------------ points


def entry_points(
    texture: AnisoTexture,
    voxels: np.ndarray | None = None,
    placement: str = "centroid",
    per_entry: int | np.ndarray = 1,
    normal: str = "mean",
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The points of a texture's shading entries, as the arrays of a
    :class:`~aniso3d.build.points.PointCloud`: positions (P, 3) float64 world
    units, normals (P, 3) float64 unit, areas (P,) float64 world units
    squared, kd (P, 3), ks (P,) and shininess (P,) float32.

    The one way points are made from entries: :meth:`AnisoTexture.to_points`
    (every voxel) and the pyramid's level clouds
    (:meth:`aniso3d.build.pyramid.Pyramid.level_cloud`) both call it, so the
    two agree bit for bit.

    Args:
        voxels: indices into ``texture.coords`` whose entries are wanted, in
            that order; None: every entry, in entry order.
        placement: "centroid", "center" or "sphere" (see ``to_points``).
        per_entry: points per entry, one whole number >= 1 for all, or an
            (E,) array of counts for every entry of the texture (e.g.
            :func:`aniso3d.build.pyramid.adaptive_points`). An entry of m > 1
            points is spread over a disc of its area in its tangent plane.
        normal: "mean" or "sample" (see ``to_points``).
    """
    t = texture
    if placement not in PLACEMENTS:
        raise InputError(f"unknown placement '{placement}'; choose one of {', '.join(PLACEMENTS)}")
    if normal not in POINT_NORMALS:
        raise InputError(f"unknown point normal '{normal}'; choose one of {', '.join(POINT_NORMALS)}")
    off = np.asarray(t.entry_offsets)
    ent = _entry_selection(t, voxels)
    if voxels is not None:
        voxels = np.asarray(voxels, dtype=np.int64)
    h = float(t.voxel_size)
    sample_n = t.directions[t.entry_direction[ent]]
    nrm = _entry_normals(t, ent, normal)
    if placement == "centroid":
        pos = t.entry_centroid[ent].astype(np.float64)
    else:
        vox = t.entry_voxel if voxels is None else np.repeat(voxels, off[voxels + 1] - off[voxels])
        centre = np.asarray(t.origin, np.float64) + (np.asarray(t.coords, np.float64)[vox] + 0.5) * h
        pos = centre if placement == "center" else centre + 0.5 * h * sample_n
    # What the entry covers: the back of a thin solid is not drawn twice. A
    # one-sided entry's back is culled instead, so it keeps all its area;
    # its normal points out of its solid.
    side = entry_sides(t, ent, nrm)
    nrm = np.where((side < 0)[:, None], -nrm, nrm)
    area = t.entry_area[ent] * np.where(side != 0, 1.0, t.entry_cover[ent]) * h * h
    kd, ks, sh = t.entry_kd[ent], t.entry_ks[ent], t.entry_shininess[ent]
    counts = _point_counts(t, ent, len(area), per_entry)
    if counts is None:
        return pos, nrm, area, kd, ks, sh
    # np.repeat, not a gather by index: the same values, a contiguous copy.
    rep = lambda a: np.repeat(a, counts, axis=0)  # noqa: E731
    m = rep(counts).astype(np.float64)
    return rep(pos) + _spread(nrm, area, counts, h), rep(nrm), rep(area) / m, rep(kd), rep(ks), rep(sh)


def _entry_normals(t: AnisoTexture, ent: slice | np.ndarray, normal: str) -> np.ndarray:
    """(E,) unit normals of the entries ``ent`` as their points get them."""
    sample_n = t.directions[t.entry_direction[ent]]
    if normal != "mean":
        return sample_n
    mean = t.entry_normal[ent].astype(np.float64)
    length = np.linalg.norm(mean, axis=1)
    # Facets that cancel (a two-sided sheet registered both ways) have no
    # mean direction; the sample direction is the honest fallback.
    return np.where((length > 1e-6)[:, None], mean / np.maximum(length, 1e-300)[:, None], sample_n)


def entry_sides(t: AnisoTexture, ent: slice | np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(E,) int8 for the entries ``ent``: +1 or -1 where every piece of the
    entry lies on a closed surface (:meth:`~aniso3d.build.mesh.Mesh.closed_sides`)
    and ``normals`` point out of it or into it, 0 elsewhere. From the closed
    sums where the texture has them (as built), else from ``entry_side``
    (a file's; 0 in files before version 6), the side against the mean
    normal, turned where ``normals`` point away from it."""
    if t.entry_closed_area is None:
        side = np.asarray(t.entry_side)[ent]
        ref = _entry_normals(t, ent, "mean")
        turn = np.sign(np.einsum("ij,ij->i", np.asarray(normals, dtype=np.float64), ref))
        return (side * turn).astype(np.int8)
    return _closed_sides(t, ent, normals)


def _closed_sides(t: AnisoTexture, ent: slice | np.ndarray, normals: np.ndarray) -> np.ndarray:
    """:func:`entry_sides` from the closed sums (which ``t`` has)."""
    area = np.asarray(t.entry_area, dtype=np.float64)[ent]
    closed = np.asarray(t.entry_closed_area, dtype=np.float64)[ent]
    outward = np.einsum("ij,ij->i", normals, np.asarray(t.entry_closed_normal, dtype=np.float64)[ent])
    whole = (area > 0) & (closed >= (1.0 - 1e-9) * area)
    return np.where(whole, np.sign(outward), 0).astype(np.int8)


def entry_one_sided(
    texture: AnisoTexture, voxels: np.ndarray | None = None, per_entry: int | np.ndarray = 1, normal: str = "mean"
) -> np.ndarray:
    """(P,) bool: which points :func:`entry_points` makes with the same
    arguments are one-sided (:attr:`~aniso3d.build.points.PointCloud.one_sided`),
    in the same order."""
    ent = _entry_selection(texture, voxels)
    t = texture
    one = entry_sides(t, ent, _entry_normals(t, ent, normal)) != 0
    counts = _point_counts(t, ent, len(one), per_entry)
    return one if counts is None else np.repeat(one, counts)


def entry_coherence(
    texture: AnisoTexture, voxels: np.ndarray | None = None, per_entry: int | np.ndarray = 1
) -> np.ndarray:
    """(P,) float32 coherence of the points :func:`entry_points` makes with
    the same ``voxels`` and ``per_entry``, in the same order: the length of
    their entry's area-weighted mean facet normal, in [0, 1] (1: a flat
    patch; less: normals that spread). Registration files a facet under the
    sample direction nearest its normal, so an entry's facets lie within one
    cell of the shading sphere, a cone narrower than a hemisphere for K >= 6
    (docs/shading.md): their normals never cancel as opposite faces of a
    two-sided sheet would, and the length measures their spread alone."""
    ent = _entry_selection(texture, voxels)
    c = np.clip(np.linalg.norm(np.asarray(texture.entry_normal[ent], dtype=np.float64), axis=1), 0.0, 1.0)
    counts = _point_counts(texture, ent, len(c), per_entry)
    return (c if counts is None else np.repeat(c, counts)).astype(np.float32)


def _entry_selection(t: AnisoTexture, voxels: np.ndarray | None) -> slice | np.ndarray:
    """The entries of ``voxels`` (indices into ``t.coords``), in that order; every entry for None."""
    if voxels is None:
        return slice(None)
    off = np.asarray(t.entry_offsets)
    voxels = np.asarray(voxels, dtype=np.int64)
    return ranges(off[voxels], off[voxels + 1])


def _point_counts(t: AnisoTexture, ent: slice | np.ndarray, n: int, per_entry: int | np.ndarray) -> np.ndarray | None:
    """Points per selected entry (``n`` of them), or None when every entry makes one."""
    if np.ndim(per_entry) == 0:
        _check_count(per_entry)
        return None if int(per_entry) == 1 else np.full(n, int(per_entry), dtype=np.int64)
    pe = np.asarray(per_entry)
    if pe.shape != (t.n_entries,) or (len(pe) and (pe.min() < 1 or np.any(pe != np.round(pe)))):
        raise InputError(f"per-entry point counts must be ({t.n_entries},) whole numbers >= 1")
    counts = pe[ent].astype(np.int64)
    return None if len(counts) and counts.max() == 1 else counts


def _check_count(value) -> None:
    """Refuse a points-per-entry count that is not a whole number >= 1."""
    number = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
    if not (number and np.isfinite(value) and int(value) == value and value >= 1):
        raise InputError(f"points per entry must be a whole number >= 1, got {value!r}")


def _spread(nrm: np.ndarray, area: np.ndarray, counts: np.ndarray, h: float) -> np.ndarray:
    """(sum(counts), 3) offsets of the points of entries split into ``counts``
    (P,) points each from the entry's position, entry by entry.

    Point i of m lies on a Vogel spiral in the entry's tangent plane (unit
    normal ``nrm`` (P, 3)) at radius ``R sqrt((i + 0.5) / m)``, R the radius of
    a disc of the entry's ``area`` (P,) but at most h/2 (inside the voxel), so
    the points cover the disc evenly.
    """
    t, b = tangent_frame(nrm)
    rep = lambda a: np.repeat(a, counts, axis=0)  # noqa: E731
    i = ranges(np.zeros_like(counts), counts).astype(np.float64)
    m = rep(counts).astype(np.float64)
    r = np.sqrt((i + 0.5) / m)
    ang = i * np.pi * (3.0 - np.sqrt(5.0))
    radius = rep(np.minimum(np.sqrt(area / np.pi), 0.5 * h))
    return (radius * r * np.cos(ang))[:, None] * rep(t) + (radius * r * np.sin(ang))[:, None] * rep(b)


# ------------------------------------------------------------------- registration

#: Triangles clipped per batch: bounds the clipper's working memory (~ a few
#: hundred MB at most) whatever the chunk size.
CLIP_BATCH = stream.CLIP_BATCH
#: Sub-polygons registered per batch (rows of the S x K direction products).
REGISTER_BATCH = stream.REGISTER_BATCH
#: Working memory of a chunk per triangle, bytes: the triangles, the clipper
#: and the chunk's exact sums. Workers measured ~650 on trees at 128^3 (~3.5
#: sub-polygons per triangle, docs/scale.md); this leaves room for meshes
#: that cut into more pieces. Chunk sizes follow from it and the budget.
CHUNK_BYTES_PER_TRIANGLE = 1200
#: Share of the available memory a build plans to use when no budget is given.
DEFAULT_BUDGET_SHARE = 0.5
#: Most triangles in one chunk when no chunk size is given: larger chunks
#: save no time (docs/scale.md), only memory.
MAX_CHUNK = 1 << 18
#: Chunks per worker at least, so that workers finish together.
CHUNKS_PER_WORKER = 4


def estimate_build_bytes(
    mesh: Mesh, resolution: int, directions: int, bounds: np.ndarray | None = None
) -> int:
    """Peak memory of a one-chunk build (and of turning it into points),
    estimated from what is known before clipping, in bytes.

    Sub-polygons are estimated from each triangle's extent in voxels (within
    ~30% on trees, spheres and boxes); occupied voxels are counted as the
    distinct voxels holding a triangle's centroid, which can only be fewer
    than the real ones, so a build refused here could never fit.
    :func:`build_texture` checks again with the exact counts once clipping has
    found them, before the large allocations (density, registration).
    """
    subpolys, voxels = _estimate_counts(mesh, resolution, bounds)
    return _build_bytes(mesh.n_faces, subpolys, voxels, directions)


def _estimate_counts(mesh: Mesh, resolution: int, bounds: np.ndarray | None) -> tuple[float, int]:
    """(expected sub-polygons, lower bound of occupied voxels) of ``mesh``,
    in batches of triangles (the working memory stays small)."""
    b = mesh.bounds if bounds is None else np.asarray(bounds, dtype=np.float64)
    grid = make_grid(b, resolution)
    subpolys = 0.0
    keys = []
    for start in range(0, mesh.n_faces, CLIP_BATCH):
        t = (mesh.vertices[mesh.faces[start:start + CLIP_BATCH]] - grid.origin) / grid.voxel_size
        ext = t.max(axis=1) - t.min(axis=1)
        small = np.all(ext < 1.0, axis=1)
        # a small triangle's expected number of cells; a large one's: its area
        # times |n|_1 (cells a plane crosses per unit area) plus its perimeter
        big = t[~small]
        cross = np.cross(big[:, 1] - big[:, 0], big[:, 2] - big[:, 0])
        perimeter = np.linalg.norm(big - np.roll(big, 1, axis=1), axis=2).sum(axis=1)
        subpolys += float(np.prod(1.0 + ext[small], axis=1).sum())
        subpolys += float((0.5 * np.abs(cross).sum(axis=1) + perimeter + 1.0).sum())
        cell = np.clip(np.floor(t.mean(axis=1)), 0, grid.shape - 1).astype(np.int64)
        keys.append(np.unique(cell_keys(cell, grid.shape)))
    keys = np.unique(np.concatenate(keys)) if keys else np.zeros(0, np.int64)
    return subpolys, len(keys)


def _build_bytes(n_faces: int, subpolys: float, voxels: float, directions: int) -> int:
    """Peak bytes of a one-chunk build's stages (and of ``to_points``) for
    these counts, checked against the real peak measured with tracemalloc on
    trees, spheres and boxes (tests/test_bad_input.py)."""
    K = directions
    entries = min(subpolys, voxels * K)
    mesh = 200.0 * n_faces  # triangles in world and grid units, normals
    # clipping: the pieces (64 B each, twice while concatenated) and the
    # clipper's working arrays, ~1.5 kB per piece of the largest batch
    batch_pieces = subpolys * min(1.0, CLIP_BATCH / max(n_faces, 1))
    clip = mesh + 128.0 * subpolys + 1500.0 * batch_pieces
    # registration: sorted sub-polygon arrays, the exact density sums (16 B a
    # value) and a batch of limbs, the entries' exact sums (144 B each)
    register = (mesh + 300.0 * subpolys + 16.0 * voxels * K
                + 40.0 * min(subpolys * K, stream.BATCH_VALUES) + 200.0 * entries)  # fmt: skip
    # finishing: the exact sums and the float texture side by side
    finish = 24.0 * voxels * K + 220.0 * entries
    points = 8.0 * voxels * K + 20.0 * voxels + 270.0 * entries
    return int(1.2 * max(clip, register, finish, points))


def _refuse_if_too_big(need: int, limit: int | None, resolution: int, directions: int) -> None:
    if limit is not None and need > limit:
        raise InputError(
            f"building at resolution {resolution} with {directions} directions needs an estimated "
            f"{_gib(need)}, more than the {_gib(limit)} available; "
            "lower --resolution or --directions"
        )


def _gib(n: float) -> str:
    return f"{n / 2**30:.1f} GiB" if n >= 2**30 else f"{n / 2**30:.2g} GiB"


def plan_chunk_size(n_faces: int, memory_budget: int, workers: int = 1) -> int:
    """Triangles per chunk for a build of ``n_faces`` faces on ``workers``
    workers within ``memory_budget`` bytes: each worker's chunk gets an equal
    share of the budget, one share kept for the running sums; at most
    :data:`MAX_CHUNK`, and small enough that every worker gets
    :data:`CHUNKS_PER_WORKER` chunks."""
    per_chunk = int(memory_budget) // ((max(1, workers) + 1) * CHUNK_BYTES_PER_TRIANGLE)
    size = min(max(1, per_chunk), MAX_CHUNK)
    if workers > 1:
        size = min(size, -(-n_faces // (CHUNKS_PER_WORKER * workers)))
    return max(1, min(size, n_faces))


def _whole_int(value, what: str, minimum: int = 1) -> int:
    number = isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
    if not number or value < minimum:
        raise InputError(f"{what} must be a whole number >= {minimum}, got {value!r}")
    return int(value)


def build_texture(
    mesh: Mesh | str | os.PathLike | list,
    resolution: int = DEFAULT_RESOLUTION,
    directions: int = DEFAULT_DIRECTIONS,
    *,
    direction_set: str = "fibonacci",
    seed: int = 0,
    bounds: np.ndarray | None = None,
    progress=None,
    timings: dict | None = None,
    memory_limit: int | None = None,
    memory_budget: int | None = None,
    chunk_size: int | None = None,
    workers: int = 1,
    client=None,
    retries: int = 2,
    stats: dict | None = None,
) -> AnisoTexture:
    """Build the anisotropic 3D texture of a mesh, streaming its triangles in
    chunks, optionally in parallel.

    Every facet contribution is summed exactly (fixed point, see
    :mod:`aniso3d.build.stream`), so the texture is the same bit for bit
    whatever the chunk size, the number of workers or the executor.

    Args:
        mesh: a :class:`Mesh`, a mesh file path (binary STL and binary PLY of
            triangles are read in chunks, other formats loaded whole), a
            :class:`~aniso3d.build.mesh_stream.TriangleSource`, or a list of
            these, built as one mesh.
        resolution: voxels along the longest axis of ``bounds`` (the paper: 128).
        directions: K, sample directions shared by density and shading spheres.
        direction_set: "fibonacci" (deterministic, default) or "random" (seeded).
        bounds: (2, 3) world box to grid; the mesh's bounds by default (for a
            path, found by a first pass over the file). Pass the same bounds
            to textures that must share a grid.
        progress: optional callable ``progress(fraction, stage)``; the
            fraction is of the triangles done.
        timings: optional dict that receives seconds per stage (clip and
            register summed over workers; bounds, read, merge, finish).
        memory_limit: bytes; a build estimated above it is refused (up front
            for a mesh in memory, else as soon as the counts say so).
            Default: the machine's available memory.
        memory_budget: bytes the build plans to use; chunk sizes follow from
            it (:func:`plan_chunk_size`). Default: half the available memory.
        chunk_size: triangles per chunk, overriding the budget's choice.
        workers: local worker processes (started with 'spawn'); 1 builds in
            this process.
        client: a ``dask.distributed.Client``: chunks run on its workers
            (which read a path themselves, so it must be visible to them) and
            are reduced there by a tree of merges.
        retries: times Dask retries a failed task (a dead worker's tasks are
            recomputed anyway).
        stats: optional dict that receives how the build ran (chunks,
            chunk size, workers, executor, reader).
    """
    from aniso3d.build.mesh_stream import MeshSource, open_source

    dirs = sphere_directions(directions, direction_set, seed)
    K = len(dirs)
    workers = _whole_int(workers, "workers")
    retries = _whole_int(retries, "retries", 0)
    if chunk_size is not None:
        chunk_size = _whole_int(chunk_size, "chunk size")
    if memory_budget is not None:
        memory_budget = _whole_int(memory_budget, "memory budget")
    timings = {} if timings is None else timings
    stats = {} if stats is None else stats
    report = progress or (lambda fraction, stage: None)

    t0 = time.perf_counter()
    source = open_source(mesh)
    if source.note.startswith("loaded whole"):
        timings["load"] = time.perf_counter() - t0
    n = source.n_faces
    if n == 0:
        raise InputError(f"mesh '{source.name}' has no faces: nothing to build")
    if bounds is None:
        t0 = time.perf_counter()
        bounds = source.bounds()
        if not isinstance(source, MeshSource):
            timings["bounds"] = time.perf_counter() - t0
    grid = make_grid(np.asarray(bounds, dtype=np.float64), resolution)
    if float(np.prod(grid.shape.astype(np.float64))) * K >= 2.0**62:
        raise InputError(
            f"a {'x'.join(str(int(s)) for s in grid.shape)} grid with {K} directions has too many "
            "(voxel, direction) pairs to key; lower --resolution or --directions"
        )
    available = _available_memory()
    limit = memory_limit if memory_limit is not None else available
    if client is not None:
        # On a cluster the budget is each worker's (default: half its memory
        # limit), and every worker should get several chunks.
        workers, worker_memory = stream.dask_workers(client)
        if memory_budget is None and worker_memory:
            memory_budget = max(1, int(DEFAULT_BUDGET_SHARE * worker_memory))
    if memory_budget is None:
        base = limit if limit is not None else 2**33
        memory_budget = max(1, int(DEFAULT_BUDGET_SHARE * base))
    if chunk_size:
        size = chunk_size
    elif client is not None:
        size = min(plan_chunk_size(n, memory_budget, 1), -(-n // (CHUNKS_PER_WORKER * workers)))
    else:
        size = plan_chunk_size(n, memory_budget, workers)
    size = max(1, min(size, n))
    n_chunks = -(-n // size)
    if client is None and n_chunks == 1:
        workers = 1  # one chunk: a pool would only add its start-up
    executor = "dask" if client is not None else ("in process" if workers == 1 else "process pool")
    stats.update(n_faces=n, chunks=n_chunks, chunk_size=size, workers=workers, executor=executor,
                 reader=source.note, memory_budget=memory_budget)  # fmt: skip

    if isinstance(source, MeshSource) and limit is not None:
        # Refuse up front what could never fit: the counts are lower bounds.
        subpolys, voxels = _estimate_counts(source.mesh, resolution, bounds)
        if n_chunks == 1:
            need = _build_bytes(n, subpolys, voxels, K)
        else:
            need = _stream_bytes(size, voxels, voxels, K, workers)  # an entry per voxel at least
        _refuse_if_too_big(need, limit, resolution, K)

    def check(n_sub: int, n_voxels: int, n_entries: int | None = None) -> None:
        # exact counts: of the whole build (one chunk), or so far (chunks)
        if n_entries is None:
            need = _build_bytes(n, n_sub, n_voxels, K)
        else:
            need = _stream_bytes(size, n_voxels, n_entries, K, workers)
        _refuse_if_too_big(need, limit, resolution, K)

    def on_progress(done: int, extra: float, stage: str) -> None:
        report(min(1.0, (done + extra) / n), stage)  # the share of the triangles done

    # Faces on closed surfaces, so that a thin solid's back is not counted
    # on top of its front (aniso3d.build.closure); skipped when reading
    # every face at once would not fit the budget.
    t0 = time.perf_counter()
    found = source.find_closed(memory_budget)
    stats["closed_faces"] = int(np.count_nonzero(source.closed)) if found else None
    stats["repeated_faces"] = int(np.count_nonzero(source.repeat)) if found and source.repeat is not None else None
    enclosed = getattr(source, "enclosed", None)
    stats["enclosed_faces"] = int(np.count_nonzero(enclosed)) if found and enclosed is not None else None
    timings["closed"] = time.perf_counter() - t0
    seconds: dict = {}
    t0 = time.perf_counter()
    arrays = stream.run_chunks(
        source, grid, dirs, size, workers=workers, client=client, retries=retries,
        report=on_progress, check=check if limit is not None and client is None else None,
        seconds=seconds, batches=(CLIP_BATCH, REGISTER_BATCH),
    )  # fmt: skip
    timings.update(seconds)
    timings.setdefault("clip", 0.0)
    timings.setdefault("register", 0.0)
    stats["seconds"] = time.perf_counter() - t0
    report(1.0, "register")

    n_vertices = getattr(source, "n_vertices", 3 * n)
    return AnisoTexture(
        origin=grid.origin,
        voxel_size=grid.voxel_size,
        shape=np.asarray(grid.shape, dtype=np.int64),
        coords=arrays["coords"],
        directions=dirs,
        density=arrays["density"],
        entry_offsets=arrays["entry_offsets"],
        entry_direction=arrays["entry_direction"],
        entry_area=arrays["entry_area"],
        entry_kd=arrays["entry_kd"],
        entry_ks=arrays["entry_ks"],
        entry_shininess=arrays["entry_shininess"],
        entry_centroid=arrays["entry_centroid"],
        entry_normal=arrays["entry_normal"],
        entry_cover=arrays["entry_cover"],
        entry_closed_area=arrays["entry_closed_area"],
        entry_closed_normal=arrays["entry_closed_normal"],
        meta={
            "direction_set": direction_set,
            "seed": int(seed),
            "source": source.name,
            "n_triangles": int(arrays["n_triangles"]),
            "n_subpolygons": int(arrays["n_subpolygons"]),
            "mesh_area": float(arrays["mesh_area"]),
            "mesh_nbytes": int(n_vertices * 12 + n * 32),
        },
    )


def _stream_bytes(chunk: int, voxels: float, entries: float, directions: int, workers: int) -> int:
    """Peak bytes of a build in chunks of ``chunk`` faces on ``workers``
    workers with these counts: the exact sums (16 B per density value, ~210 B
    per entry with its key; they turn into the texture block by block at the
    end) and the chunks in flight (one more than the workers)."""
    sums = 16.0 * voxels * (directions + 1) + 210.0 * entries
    chunks = (max(1, workers) + 1) * chunk * CHUNK_BYTES_PER_TRIANGLE
    return int(1.2 * (sums + chunks))


def _available_memory() -> int | None:
    """Bytes of memory available to a new allocation without swapping (None
    if the platform cannot tell): what a build is checked against."""
    try:
        return int(psutil.virtual_memory().available)
    except (OSError, RuntimeError, AttributeError):
        return None
