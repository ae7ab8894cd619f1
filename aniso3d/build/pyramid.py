"""Level of detail, built on the CPU: an exact texture pyramid (issue 7).

Registration is linear in the facets, so a coarser texture is a sum of the
finer one, not a new build. A parent voxel ``(i//2, j//2, k//2)`` has edge 2h;
an area S in units of h^2 is S/4 in units of (2h)^2, so

- the parent's density sphere is the sum of its children's, divided by 4;
- its shading entries are the children's entries merged per sample direction:
  areas summed and divided by 4, material, centroid and mean normal as
  area-weighted means.

The sample directions are shared by all levels, so nothing is re-quantised:
level l equals ``build_texture(mesh, resolution / 2**l)`` to rounding, as long
as ``2**l`` divides the finest resolution (``make_grid`` halves h exactly
and its cell counts satisfy ``ceil(ceil(x) / 2) == ceil(x / 2)``; see
:func:`pyramid`).

A :class:`Pyramid` also keeps, per level, the parent/child links and the
points of every voxel (made by :func:`aniso3d.build.texture.entry_points`, as
``to_points`` makes them, or :func:`adaptive_points` per entry), so that a
view only has to choose voxels: that choice needs a camera and is
:mod:`aniso3d.rendering.select`'s job.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aniso3d.build.closure import hidden_density, hidden_sides
from aniso3d.build.points import PointCloud
from aniso3d.build.texture import (
    PLACEMENTS,
    POINT_NORMALS,
    AnisoTexture,
    entry_coherence,
    entry_one_sided,
    entry_points,
)
from aniso3d.errors import InputError
from aniso3d.grid import cell_coords, cell_keys, weighted_means

#: Area (units of h^2) that one point of a perfectly flat patch may carry: the
#: largest plane section of a unit cube is sqrt(2), so a flat patch inside one
#: voxel never needs more than one point.
FLAT_AREA = math.sqrt(2.0)


# --------------------------------------------------------------------- pyramid


class Pyramid(list):
    """The levels of a texture pyramid, finest first (a ``list`` of
    :class:`~aniso3d.build.texture.AnisoTexture`), with the parent/child links
    between consecutive levels kept for fast per-frame selection.

    ``self[0]`` is the finest texture itself; ``self[l]`` has voxel edge
    ``2**l`` times as large.
    """

    def __init__(self, levels, parents: list[np.ndarray] | None = None):
        super().__init__(levels)
        if not self:
            raise InputError("a texture pyramid needs at least one level")
        if parents is None:
            parents = [_parent_index(self[i], self[i + 1]) for i in range(len(self) - 1)]
        #: parents[l] (M_l,) int64: index in level l+1 of each voxel of level l.
        self.parents = list(parents)
        self._children: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._adaptive: dict[tuple, np.ndarray] = {}
        self._clouds: dict[tuple, tuple[PointCloud, np.ndarray]] = {}
        self._centres: dict[int, tuple[np.ndarray, ...]] = {}

    def centres(self, level: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The voxel centres of a level in grid units (``coords + 0.5``), as
        three contiguous float64 columns, cached for per-frame selection."""
        hit = self._centres.get(level)
        if hit is None:
            c = np.asarray(self[level].coords, dtype=np.float64) + 0.5
            hit = self._centres[level] = tuple(np.ascontiguousarray(c[:, i]) for i in range(3))
        return hit

    def children(self, level: int) -> tuple[np.ndarray, np.ndarray]:
        """CSR links from level ``level`` to ``level - 1``: ``(offsets, index)``;
        the children of voxel v are ``index[offsets[v]:offsets[v+1]]``."""
        if not 1 <= level < len(self):
            raise InputError(f"level {level} has no children in a pyramid of {len(self)} levels")
        if level not in self._children:
            parent = self.parents[level - 1]
            index = np.argsort(parent, kind="stable")
            offsets = np.zeros(self[level].n_voxels + 1, dtype=np.int64)
            offsets[1:] = np.cumsum(np.bincount(parent, minlength=self[level].n_voxels))
            self._children[level] = (offsets, index)
        return self._children[level]

    def adaptive_counts(self, level: int, **options) -> np.ndarray:
        """:func:`adaptive_points` of one level, cached."""
        key = (level, tuple(sorted(options.items())))
        if key not in self._adaptive:
            self._adaptive[key] = adaptive_points(self[level], **options)
        return self._adaptive[key]

    def level_cloud(
        self,
        level: int,
        placement: str = "centroid",
        per_entry: int | str = 1,
        normal: str = "mean",
    ) -> tuple[PointCloud, np.ndarray]:
        """All points of one level (as ``to_points`` makes them, through
        :func:`~aniso3d.build.texture.entry_points`; ``per_entry`` may be
        ``"adaptive"``) and the (M+1,) offsets of each voxel's points in it,
        cached: per-frame selection only gathers from these."""
        if isinstance(per_entry, str) and per_entry != "adaptive":
            raise InputError(
                f"points per entry must be a whole number or 'adaptive', got {per_entry!r}"
            )
        key = (level, placement, per_entry, normal)
        if key not in self._clouds:
            tex = self[level]
            pe = self.adaptive_counts(level) if per_entry == "adaptive" else per_entry
            arrays = entry_points(tex, None, placement, pe, normal)
            cloud = PointCloud(*arrays, name=str(tex.meta.get("source", "points")),
                               coherence=entry_coherence(tex, None, pe),
                               one_sided=entry_one_sided(tex, None, pe, normal))  # fmt: skip
            eoff = np.asarray(tex.entry_offsets, dtype=np.int64)
            if np.ndim(pe) == 0:
                offsets = eoff * int(pe)
            else:
                offsets = np.concatenate([[0], np.cumsum(pe, dtype=np.int64)])[eoff]
            self._clouds[key] = (cloud, offsets)
        return self._clouds[key]

    @property
    def nbytes(self) -> int:
        """Bytes of all levels as stored (:attr:`AnisoTexture.nbytes`), the
        shared sample directions counted once."""
        d = int(np.asarray(self[0].directions).nbytes)
        return int(sum(t.nbytes for t in self) - d * (len(self) - 1))

    @property
    def memory_nbytes(self) -> int:
        """Bytes of all levels' arrays in memory (:attr:`AnisoTexture.memory_nbytes`),
        the shared sample directions counted once."""
        d = int(np.asarray(self[0].directions).nbytes)
        return int(sum(t.memory_nbytes for t in self) - d * (len(self) - 1))

    def level_stats(self) -> list[dict]:
        """Per level: resolution, voxel size, voxels, entries and bytes."""
        return [
            {
                "level": i,
                "resolution": t.resolution,
                "voxel_size": float(t.voxel_size),
                "voxels": t.n_voxels,
                "entries": t.n_entries,
                "nbytes": t.nbytes,
            }
            for i, t in enumerate(self)
        ]


def pyramid(texture: AnisoTexture, max_levels: int | None = None) -> Pyramid:
    """All levels of ``texture``, finest (``texture`` itself) first, each one
    aggregated exactly from the one before, down to a single cell along every
    axis (or ``max_levels`` levels).

    Level l has the same origin, voxel edge ``h * 2**l`` and
    ``shape = ceil(shape_{l-1} / 2)``. It equals ``build_texture(mesh,
    R / 2**l)`` of a finest build ``build_texture(mesh, R)`` (same bounds,
    directions) to rounding whenever ``2**l`` divides ``R``: ``make_grid``
    then gives the same origin, exactly twice the voxel edge (a division by a
    halved integer is exactly doubled in binary floating point) and the same
    cell counts. Levels beyond that (e.g. below 3 cells for ``R = 96``) are
    still exact aggregates, but ``make_grid`` cannot make their grid from an
    integer resolution.
    """
    if not isinstance(texture, AnisoTexture):
        raise InputError(f"pyramid needs an AnisoTexture, got {type(texture).__name__}")
    bad = max_levels is not None and (
        isinstance(max_levels, bool) or int(max_levels) != max_levels or max_levels < 1
    )
    if bad:
        raise InputError(f"max_levels must be a whole number >= 1, got {max_levels!r}")
    levels, parents = [texture], []
    while int(np.max(levels[-1].shape)) > 1 and (max_levels is None or len(levels) < max_levels):
        coarse, parent = coarsen(levels[-1])
        levels.append(coarse)
        parents.append(parent)
    return Pyramid(levels, parents)


def coarsen(texture: AnisoTexture) -> tuple[AnisoTexture, np.ndarray]:
    """One level up: the texture with voxels twice as large, and for each voxel
    of ``texture`` the index of its parent in it."""
    t = texture
    K = t.n_directions
    pshape = (np.asarray(t.shape, dtype=np.int64) + 1) // 2
    pc = np.asarray(t.coords, dtype=np.int64) // 2
    pkeys, parent = np.unique(cell_keys(pc, pshape), return_inverse=True)
    parent = parent.reshape(-1).astype(np.int64)
    Mp = len(pkeys)
    coords = cell_coords(pkeys, pshape).astype(np.int32)

    # Density: children grouped by parent, summed, rescaled to (2h)^2. With
    # the closed facets' sums known, the density as registered, from which
    # what the coarser voxels' solids hide is taken again below.
    known = t.entry_closed_area is not None
    dens = np.asarray(t.density)
    if known:
        dens = dens + hidden_density(t.entry_offsets, t.directions, t.entry_closed_normal)
    order = np.argsort(parent, kind="stable")
    starts = np.zeros(Mp, dtype=np.int64)
    starts[1:] = np.cumsum(np.bincount(parent, minlength=Mp))[:-1]
    if Mp:
        density = np.add.reduceat(dens[order], starts, axis=0) * 0.25
    else:
        density = np.zeros((0, K))

    # Shading entries: merged per (parent voxel, sample direction).
    ekey = parent[t.entry_voxel] * K + np.asarray(t.entry_direction, dtype=np.int64)
    ekeys, einv = np.unique(ekey, return_inverse=True)
    einv = einv.reshape(-1)
    E = len(ekeys)
    w = np.asarray(t.entry_area, dtype=np.float64)
    area = np.bincount(einv, weights=w, minlength=E)

    def wmean(values: np.ndarray) -> np.ndarray:
        return weighted_means(einv, w, values, area)

    origin = np.asarray(t.origin, dtype=np.float64)
    offsets = np.zeros(Mp + 1, dtype=np.int64)
    offsets[1:] = np.cumsum(np.bincount(ekeys // K, minlength=Mp))
    if known:
        closed_area = np.bincount(einv, weights=t.entry_closed_area, minlength=E) * 0.25
        closed_normal = np.stack([np.bincount(einv, weights=t.entry_closed_normal[:, i], minlength=E)
                                  for i in range(3)], axis=1) * 0.25  # fmt: skip
        density, cover = hidden_sides(density, offsets, t.directions, area * 0.25, closed_area, closed_normal)
    else:
        # What the children's facets cover of their own backs, as a mean: a
        # coarser voxel holding more of a solid hides more, which this misses.
        closed_area = closed_normal = None
        cover = wmean(t.entry_cover).astype(np.float32)
    side = None
    if not known:
        side = _merged_sides(t, einv, E, wmean(t.entry_normal), ekeys % K)
    meta = {k: v for k, v in t.meta.items() if k != "n_subpolygons"}
    meta["lod_level"] = int(t.meta.get("lod_level", 0)) + 1
    coarse = AnisoTexture(
        origin=origin.copy(),
        voxel_size=float(t.voxel_size) * 2.0,
        shape=pshape,
        coords=coords,
        directions=t.directions,
        density=density,
        entry_offsets=offsets,
        entry_direction=(ekeys % K).astype(np.int32),
        entry_area=area * 0.25,
        entry_kd=wmean(t.entry_kd).astype(np.float32),
        entry_ks=wmean(t.entry_ks).astype(np.float32),
        entry_shininess=wmean(t.entry_shininess).astype(np.float32),
        # Relative to the origin, as build_texture does, to keep precision far
        # from the world origin.
        entry_centroid=origin + wmean(np.asarray(t.entry_centroid) - origin),
        entry_normal=wmean(t.entry_normal).astype(np.float32),
        meta=meta,
        entry_cover=cover,
        entry_closed_area=closed_area,
        entry_closed_normal=closed_normal,
        entry_side=side,
    )
    return coarse, parent


def _merged_sides(t: AnisoTexture, einv: np.ndarray, n: int, normal: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(n,) int8 sides of the merged entries of a texture without closed sums
    (loaded from a file; ``einv`` (E,) the merged entry of each of ``t``'s,
    ``normal`` (n, 3) their mean normals, ``direction`` (n,) their sample
    directions): what the closed sums would give. A child of side s (against
    its mean normal m, area A) has the closed vector area ``s A m`` when all
    its facets lie on one closed surface; a merged entry is on closed
    surfaces where all its children with area are, and its side is the sign
    of its normal against the sum of theirs (s where they agree). Where a
    child mixed surfaces wound both ways this is what is known of it."""
    side = np.asarray(t.entry_side, dtype=np.float64)
    area = np.asarray(t.entry_area, dtype=np.float64)
    open_ = np.bincount(einv, weights=((side == 0) & (area > 0)).astype(np.float64), minlength=n) > 0
    vec = np.asarray(t.entry_normal, dtype=np.float64) * (side * area)[:, None]
    closed = np.stack([np.bincount(einv, weights=vec[:, i], minlength=n) for i in range(3)], axis=1)
    length = np.linalg.norm(normal, axis=1)
    sample = np.asarray(t.directions, dtype=np.float64)[direction]
    ref = np.where((length > 1e-6)[:, None], normal / np.maximum(length, 1e-300)[:, None], sample)
    merged_area = np.bincount(einv, weights=area, minlength=n)
    out = np.sign(np.einsum("ij,ij->i", ref, closed))
    return np.where(open_ | (merged_area <= 0), 0, out).astype(np.int8)


def _parent_index(fine: AnisoTexture, coarse: AnisoTexture) -> np.ndarray:
    """Index in ``coarse`` of each voxel's parent, checking the two are
    consecutive pyramid levels."""
    consistent = (
        np.array_equal(np.asarray(fine.origin), np.asarray(coarse.origin))
        and coarse.voxel_size == 2.0 * fine.voxel_size
        and np.array_equal(np.asarray(coarse.shape), (np.asarray(fine.shape) + 1) // 2)
        and np.array_equal(np.asarray(fine.directions), np.asarray(coarse.directions))
    )
    if not consistent:
        raise InputError(
            "pyramid levels must share origin and directions and double the voxel size"
        )
    s = np.asarray(coarse.shape, dtype=np.int64)
    ckey = cell_keys(coarse.coords, s)
    key = cell_keys(np.asarray(fine.coords, dtype=np.int64) // 2, s)
    idx = np.searchsorted(ckey, key)
    if len(key) and (idx.max() >= len(ckey) or np.any(ckey[idx] != key)):
        raise InputError("pyramid levels are inconsistent: a voxel has no parent one level up")
    return idx.astype(np.int64)


def as_pyramid(levels) -> Pyramid:
    """``levels`` as a :class:`Pyramid` (a single texture is aggregated)."""
    if isinstance(levels, Pyramid):
        return levels
    if isinstance(levels, AnisoTexture):
        return pyramid(levels)
    levels = list(levels)
    if not all(isinstance(t, AnisoTexture) for t in levels):
        raise InputError("pyramid levels must be AnisoTexture objects, finest first")
    return Pyramid(levels)


# -------------------------------------------------------------- adaptive counts


def adaptive_points(
    texture: AnisoTexture,
    cap: int = 8,
    gain: float = 7.0,
    flat_area: float = FLAT_AREA,
) -> np.ndarray:
    """(E,) points per shading entry, from how coherent the voxel's facets are.

    A voxel's *coherence* is ``c = |n_e| * |n_v|``: ``n_e`` the entry's
    area-weighted mean normal (length 1 when all its facets are parallel) and
    ``n_v`` the voxel's (the area-weighted mean of its entries' ``n_e``; length
    1 only when the voxel holds one flat patch, less when facets face many
    ways or cancel, as the two sides of a twig do). One point may carry
    ``flat_area / (1 + gain * (1 - c))`` of facet area (units of h^2): a flat
    patch (c = 1) carries up to ``flat_area`` = sqrt(2), the largest plane
    section of a voxel, so it is always one point; scattered facets carry
    less per point and get more points. The count is
    ``clip(ceil(A_e / that), 1, cap)``.
    """
    if isinstance(cap, bool) or int(cap) != cap or cap < 1:
        raise InputError(f"the adaptive point cap must be a whole number >= 1, got {cap!r}")
    if not (gain >= 0 and flat_area > 0):
        raise InputError("adaptive point gain must be >= 0 and flat_area > 0")
    t = texture
    if t.n_entries == 0:
        return np.zeros(0, dtype=np.int32)
    area = np.asarray(t.entry_area, dtype=np.float64)
    n_e = np.asarray(t.entry_normal, dtype=np.float64)
    len_e = np.minimum(np.linalg.norm(n_e, axis=1), 1.0)
    ev = t.entry_voxel
    vox_area = np.bincount(ev, weights=area, minlength=t.n_voxels)
    n_v = np.stack(
        [np.bincount(ev, weights=area * n_e[:, i], minlength=t.n_voxels) for i in range(3)], axis=1
    )
    n_v /= np.where(vox_area > 0, vox_area, 1.0)[:, None]
    len_v = np.minimum(np.linalg.norm(n_v, axis=1), 1.0)[ev]
    coherence = len_e * len_v
    # float32 normals of a flat patch have length 1 only to ~1e-7.
    incoherence = np.where(coherence > 1.0 - 1e-5, 0.0, 1.0 - coherence)
    per_point = flat_area / (1.0 + gain * incoherence)
    return np.clip(np.ceil(area / per_point - 1e-9), 1, int(cap)).astype(np.int32)


# -------------------------------------------------------------- for renderers


@dataclass(frozen=True, eq=False)
class LodPoints:
    """A pyramid and the point options to draw it view-dependently with: what
    :meth:`SplatRenderer.upload <aniso3d.rendering.splat.SplatRenderer.upload>`
    takes to upload every level's points once and draw, per frame, only
    those :func:`~aniso3d.rendering.select.select_voxels` chooses.

    ``per_entry`` is a whole number or ``"adaptive"``; ``placement`` and
    ``normal`` as for :meth:`AnisoTexture.to_points`. ``clips``: the upload
    gives each level's points the clip planes of that level's texture
    (:mod:`aniso3d.rendering.splat.clips`: quality "high" cuts a splat where
    its surface ends), as the renderer gives a texture's points; False: the
    level clouds as they are.
    """

    pyramid: Pyramid
    placement: str = "centroid"
    per_entry: int | str = 1
    normal: str = "mean"
    clips: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "pyramid", as_pyramid(self.pyramid))
        if self.placement not in PLACEMENTS:
            raise InputError(
                f"unknown placement '{self.placement}'; choose one of {', '.join(PLACEMENTS)}"
            )
        if self.normal not in POINT_NORMALS:
            raise InputError(
                f"unknown point normal '{self.normal}'; choose one of {', '.join(POINT_NORMALS)}"
            )
        pe = self.per_entry
        bad = (
            pe != "adaptive"
            if isinstance(pe, str)
            else isinstance(pe, bool) or int(pe) != pe or pe < 1
        )
        if bad:
            raise InputError(
                f"points per entry must be a whole number >= 1 or 'adaptive', got {pe!r}"
            )

    def level_cloud(self, level: int) -> tuple[PointCloud, np.ndarray]:
        """:meth:`Pyramid.level_cloud` of one level with these options."""
        return self.pyramid.level_cloud(level, self.placement, self.per_entry, self.normal)

    @property
    def nbytes(self) -> int:
        """Bytes of the pyramid (the level point clouds are made at upload)."""
        return self.pyramid.nbytes

    @property
    def memory_nbytes(self) -> int:
        """Bytes of the pyramid in memory (the level point clouds are made at upload)."""
        return self.pyramid.memory_nbytes
