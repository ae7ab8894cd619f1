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
(:attr:`AnisoTexture.memory_nbytes`), stored they take about 1/12 of that
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

from aniso3d.build.clip import Grid, clip_to_grid, make_grid, triangle_normals
from aniso3d.build.encoding import ARRAYS, DEFAULT_BITS, Bits, decode, encode
from aniso3d.build.mesh import Mesh
from aniso3d.build.points import PointCloud
from aniso3d.build.texture_file import encoded_size, read_texture_file, write_texture_file
from aniso3d.errors import FormatError, InputError
from aniso3d.grid import cell_coords, cell_keys, ranges, tangent_frame, weighted_means

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

    def __post_init__(self) -> None:
        m, k = len(self.coords), len(self.directions)
        e = len(self.entry_direction)
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
        }
        for name, (got, want) in checks.items():
            if tuple(got) != want:
                raise FormatError(f"texture field '{name}' has shape {got}, expected {want}")
        if not (np.isfinite(self.voxel_size) and self.voxel_size > 0):
            raise FormatError(f"texture voxel_size must be positive, got {self.voxel_size}")
        off = np.asarray(self.entry_offsets)
        if m and (off[0] != 0 or off[-1] != e or np.any(np.diff(off) < 0)):
            raise FormatError("texture entry_offsets are not a valid CSR offset array")

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
        file :meth:`save` writes by default (format version 2, compact
        encoding, deflated; :mod:`aniso3d.build.encoding`), computed in memory
        once. :attr:`memory_nbytes` is the size of the arrays in memory."""
        return encoded_size(self._arrays(), self.voxel_size, self.meta)

    def as_stored(self, bits: Bits = DEFAULT_BITS) -> AnisoTexture:
        """The texture as a compact file stores it: what :meth:`load` returns
        after :meth:`save` with these ``bits``, without a file (every field
        quantised and decoded; see :mod:`aniso3d.build.encoding` for the
        error of each)."""
        members, params = encode(self._arrays(), self.voxel_size, bits)
        return AnisoTexture(voxel_size=self.voxel_size, meta=dict(self.meta),
                            **decode(members, params, self.voxel_size))  # fmt: skip

    def _arrays(self) -> dict[str, np.ndarray]:
        return {n: getattr(self, n) for n in ARRAYS}

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
        return PointCloud(*arrays, name=str(self.meta.get("source", "points")))

    # ------------------------------------------------------------------ I/O

    #: The arrays of a texture (see :mod:`aniso3d.build.encoding`).
    _ARRAYS = ARRAYS

    def save(self, path: str | os.PathLike, encoding: str = "compact", bits: Bits = DEFAULT_BITS) -> Path:
        """Write a versioned ``.a3d`` file (a zip of .npy arrays and a JSON header
        with a SHA-256 of the arrays); loads without pickle. Written atomically.

        ``encoding="compact"`` (default) quantises every field with ``bits``
        (:mod:`aniso3d.build.encoding`: about 1/12 of :attr:`memory_nbytes`
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
        try:
            return cls(voxel_size=f.voxel_size, meta=f.meta, **f.arrays)
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
    if voxels is None:
        ent = slice(None)
    else:
        voxels = np.asarray(voxels, dtype=np.int64)
        ent = ranges(off[voxels], off[voxels + 1])
    h = float(t.voxel_size)
    sample_n = t.directions[t.entry_direction[ent]]
    if normal == "mean":
        mean = t.entry_normal[ent].astype(np.float64)
        length = np.linalg.norm(mean, axis=1)
        # Facets that cancel (a two-sided sheet registered both ways) have no
        # mean direction; the sample direction is the honest fallback.
        nrm = np.where((length > 1e-6)[:, None], mean / np.maximum(length, 1e-300)[:, None], sample_n)
    else:
        nrm = sample_n
    if placement == "centroid":
        pos = t.entry_centroid[ent].astype(np.float64)
    else:
        vox = t.entry_voxel if voxels is None else np.repeat(voxels, off[voxels + 1] - off[voxels])
        centre = np.asarray(t.origin, np.float64) + (np.asarray(t.coords, np.float64)[vox] + 0.5) * h
        pos = centre if placement == "center" else centre + 0.5 * h * sample_n
    area = t.entry_area[ent] * h * h
    kd, ks, sh = t.entry_kd[ent], t.entry_ks[ent], t.entry_shininess[ent]
    if np.ndim(per_entry) == 0:
        _check_count(per_entry)
        counts = None if int(per_entry) == 1 else np.full(len(area), int(per_entry), dtype=np.int64)
    else:
        pe = np.asarray(per_entry)
        if pe.shape != (t.n_entries,) or (len(pe) and (pe.min() < 1 or np.any(pe != np.round(pe)))):
            raise InputError(f"per-entry point counts must be ({t.n_entries},) whole numbers >= 1")
        counts = pe[ent].astype(np.int64)
        if len(counts) and counts.max() == 1:
            counts = None
    if counts is None:
        return pos, nrm, area, kd, ks, sh
    # np.repeat, not a gather by index: the same values, a contiguous copy.
    rep = lambda a: np.repeat(a, counts, axis=0)  # noqa: E731
    m = rep(counts).astype(np.float64)
    return rep(pos) + _spread(nrm, area, counts, h), rep(nrm), rep(area) / m, rep(kd), rep(ks), rep(sh)


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
#: hundred MB at most) whatever the mesh size.
CLIP_BATCH = 65536
#: Sub-polygons registered per batch (rows of the S x K direction products).
REGISTER_BATCH = 32768


def estimate_build_bytes(
    mesh: Mesh, resolution: int, directions: int, bounds: np.ndarray | None = None
) -> int:
    """Peak memory of a build (and of turning it into points), estimated from
    what is known before clipping, in bytes.

    Sub-polygons are estimated from each triangle's extent in voxels (within
    ~30% on trees, spheres and boxes); occupied voxels are counted as the
    distinct voxels holding a triangle's centroid, which can only be fewer
    than the real ones, so a build refused here could never fit.
    :func:`build_texture` checks again with the exact counts once clipping has
    found them, before the large allocations (density, registration).
    """
    b = mesh.bounds if bounds is None else np.asarray(bounds, dtype=np.float64)
    grid = make_grid(b, resolution)
    t = (mesh.triangles - grid.origin) / grid.voxel_size
    ext = t.max(axis=1) - t.min(axis=1)
    small = np.all(ext < 1.0, axis=1)
    # a small triangle's expected number of cells; a large one's: its area
    # times |n|_1 (cells a plane crosses per unit area) plus its perimeter
    cross = np.cross(t[~small, 1] - t[~small, 0], t[~small, 2] - t[~small, 0])
    perimeter = np.linalg.norm(t[~small] - np.roll(t[~small], 1, axis=1), axis=2).sum(axis=1)
    subpolys = float(np.prod(1.0 + ext[small], axis=1).sum())
    subpolys += float((0.5 * np.abs(cross).sum(axis=1) + perimeter + 1.0).sum())
    cell = np.clip(np.floor(t.mean(axis=1)), 0, grid.shape - 1).astype(np.int64)
    keys = np.sort(cell_keys(cell, grid.shape))
    voxels = int(np.count_nonzero(np.diff(keys)) + 1) if len(keys) else 0
    return _build_bytes(mesh.n_faces, subpolys, voxels, directions)


def _build_bytes(n_faces: int, subpolys: float, voxels: float, directions: int) -> int:
    """Peak bytes of the build's stages (and of ``to_points``) for these
    counts: 1.05 to 1.9 times the real peak measured with tracemalloc on
    trees, spheres, boxes and triangle soups (tests/test_bad_input.py)."""
    K = directions
    entries = min(subpolys, voxels * K)
    mesh = 200.0 * n_faces  # triangles in world and grid units, normals
    # clipping: the pieces (64 B each, twice while concatenated) and the
    # clipper's working arrays, ~1.5 kB per piece of the largest batch
    batch_pieces = subpolys * min(1.0, CLIP_BATCH / max(n_faces, 1))
    clip = mesh + 128.0 * subpolys + 1500.0 * batch_pieces
    # registration: sorted sub-polygon arrays, the density spheres, the batch
    # of S x K products (three arrays), the entries' sums; points after it
    register = (mesh + 300.0 * subpolys + 8.0 * voxels * K
                + 24.0 * min(subpolys, REGISTER_BATCH) * K + 200.0 * entries)  # fmt: skip
    points = 8.0 * voxels * K + 20.0 * voxels + 270.0 * entries
    return int(1.2 * max(clip, register, points))


def _refuse_if_too_big(need: int, limit: int | None, resolution: int, directions: int) -> None:
    if limit is not None and need > limit:
        raise InputError(
            f"building at resolution {resolution} with {directions} directions needs an estimated "
            f"{_gib(need)}, more than the {_gib(limit)} available; "
            "lower --resolution or --directions"
        )


def _gib(n: float) -> str:
    return f"{n / 2**30:.1f} GiB" if n >= 2**30 else f"{n / 2**30:.2g} GiB"


def build_texture(
    mesh: Mesh,
    resolution: int = DEFAULT_RESOLUTION,
    directions: int = DEFAULT_DIRECTIONS,
    *,
    direction_set: str = "fibonacci",
    seed: int = 0,
    bounds: np.ndarray | None = None,
    progress=None,
    timings: dict | None = None,
    memory_limit: int | None = None,
) -> AnisoTexture:
    """Build the anisotropic 3D texture of ``mesh``.

    Args:
        resolution: voxels along the longest axis of ``bounds`` (the paper: 128).
        directions: K, sample directions shared by density and shading spheres.
        direction_set: "fibonacci" (deterministic, default) or "random" (seeded).
        bounds: (2, 3) world box to grid; the mesh's bounds by default. Pass the
            same bounds to textures that must share a grid.
        progress: optional callable ``progress(fraction, stage)`` for long builds.
        timings: optional dict that receives seconds per stage.
        memory_limit: bytes; a build estimated above it is refused up front.
            Default: the machine's available memory.
    """
    if not isinstance(mesh, Mesh):
        raise InputError(f"build_texture needs an aniso3d.Mesh, got {type(mesh).__name__}")
    dirs = sphere_directions(directions, direction_set, seed)
    if bounds is None:
        bounds = mesh.bounds
    grid = make_grid(np.asarray(bounds, dtype=np.float64), resolution)
    limit = memory_limit if memory_limit is not None else _available_memory()
    need = estimate_build_bytes(mesh, resolution, len(dirs), bounds)
    _refuse_if_too_big(need, limit, resolution, len(dirs))
    timings = {} if timings is None else timings
    report = progress or (lambda fraction, stage: None)

    # ---- clip, in batches of triangles
    t0 = time.perf_counter()
    # Triangles relative to their first vertex, in units of h, plus that
    # vertex's grid position: keeps tiny triangles exact in shape anywhere.
    world = mesh.triangles
    first = grid.to_grid(world[:, 0])
    tri = (world - world[:, :1]) / grid.voxel_size
    normals, _ = triangle_normals(tri)
    pieces = []
    n = len(tri)
    for start in range(0, n, CLIP_BATCH):
        stop = min(n, start + CLIP_BATCH)
        pieces.append(
            clip_to_grid(
                tri[start:stop], normals[start:stop], grid.shape, np.arange(start, stop),
                first=first[start:stop],
            )  # fmt: skip
        )
        report(0.6 * stop / n, "clip")
    face = np.concatenate([p.face for p in pieces])
    cell = np.concatenate([p.cell for p in pieces])
    S = np.concatenate([p.area for p in pieces])
    centroid = np.concatenate([p.centroid for p in pieces])
    del pieces
    timings["clip"] = time.perf_counter() - t0
    n_sub = len(S)

    # ---- register
    t0 = time.perf_counter()
    key = cell_keys(cell, grid.shape)
    order = np.argsort(key, kind="stable")
    key, face, S, centroid = key[order], face[order], S[order], centroid[order]
    # The exact counts are known now: check again before the large arrays.
    n_voxels = int(np.count_nonzero(np.diff(key)) + 1) if n_sub else 0
    need = _build_bytes(mesh.n_faces, n_sub, n_voxels, len(dirs))
    _refuse_if_too_big(need, limit, resolution, len(dirs))
    N = normals[face]
    vox_keys, vox_start = np.unique(key, return_index=True)
    M, K = len(vox_keys), len(dirs)
    voxel_of = np.repeat(np.arange(M), np.diff(np.append(vox_start, n_sub)))
    density = np.zeros((M, K))
    nearest = np.empty(n_sub, dtype=np.int64)
    # Batches end on voxel boundaries so reduceat never splits a voxel.
    bounds_idx = _batch_bounds(vox_start, n_sub, REGISTER_BATCH)
    for b0, b1 in zip(bounds_idx[:-1], bounds_idx[1:], strict=True):
        r0, r1 = vox_start[b0], (vox_start[b1] if b1 < M else n_sub)
        dots = N[r0:r1] @ dirs.T
        nearest[r0:r1] = np.argmax(dots, axis=1)
        contrib = np.abs(dots) * S[r0:r1, None]
        density[b0:b1] = np.add.reduceat(contrib, vox_start[b0:b1] - r0, axis=0)
        report(0.6 + 0.3 * r1 / max(n_sub, 1), "register")

    # Shading entries: one per (voxel, nearest sample) pair; sorted by voxel.
    ekey = voxel_of * K + nearest
    ekeys, einv = np.unique(ekey, return_inverse=True)
    E = len(ekeys)
    e_area = np.bincount(einv, weights=S, minlength=E)

    def wmean(values: np.ndarray) -> np.ndarray:
        return weighted_means(einv, S, values, e_area)

    e_kd = wmean(mesh.kd[face].astype(np.float64))
    e_ks = wmean(mesh.ks[face].astype(np.float64))
    e_sh = wmean(mesh.shininess[face].astype(np.float64))
    e_cent = grid.origin + wmean(centroid) * grid.voxel_size
    e_norm = wmean(N)
    e_voxel = ekeys // K
    offsets = np.zeros(M + 1, dtype=np.int64)
    offsets[1:] = np.cumsum(np.bincount(e_voxel, minlength=M))
    coords = cell_coords(vox_keys, grid.shape)
    timings["register"] = time.perf_counter() - t0
    report(1.0, "register")

    return AnisoTexture(
        origin=grid.origin,
        voxel_size=grid.voxel_size,
        shape=np.asarray(grid.shape, dtype=np.int64),
        coords=coords.astype(np.int32),
        directions=dirs,
        density=density,
        entry_offsets=offsets,
        entry_direction=(ekeys % K).astype(np.int32),
        entry_area=e_area,
        entry_kd=e_kd.astype(np.float32),
        entry_ks=e_ks.astype(np.float32),
        entry_shininess=e_sh.astype(np.float32),
        entry_centroid=e_cent,
        entry_normal=e_norm.astype(np.float32),
        meta={
            "direction_set": direction_set,
            "seed": int(seed),
            "source": mesh.name,
            "n_triangles": int(mesh.n_faces),
            "n_subpolygons": int(n_sub),
            "mesh_area": float(mesh.area()),
            "mesh_nbytes": int(mesh.nbytes),
        },
    )


def _batch_bounds(starts: np.ndarray, total: int, batch: int) -> list[int]:
    """Voxel indices that split rows into batches of about ``batch`` rows."""
    M = len(starts)
    if M == 0:
        return [0]
    cuts = np.searchsorted(starts, np.arange(batch, total, batch), side="right") - 1
    cuts = np.unique(np.concatenate([[0], cuts[cuts > 0], [M]]))
    return [int(c) for c in cuts]


def _available_memory() -> int | None:
    """Bytes of memory available to a new allocation without swapping (None
    if the platform cannot tell): what a build is checked against."""
    try:
        return int(psutil.virtual_memory().available)
    except (OSError, RuntimeError, AttributeError):
        return None
