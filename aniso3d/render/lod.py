"""Level of detail: an exact texture pyramid and view-dependent points (issue 7).

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

For a view, :func:`select_voxels` walks the pyramid top-down: a voxel is
culled if its bounding sphere lies outside the view frustum, drawn if it
projects to at most ``pixel_error`` pixels, and otherwise replaced by its
children one level finer. Each region is therefore drawn at exactly one level
(the coarsest one that is fine enough), and :func:`select_points` turns the
chosen voxels into the same points ``to_points`` makes.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np

from aniso3d.build.points import PointCloud
from aniso3d.build.texture import PLACEMENTS, POINT_NORMALS, AnisoTexture, _tangent_basis
from aniso3d.errors import InputError
from aniso3d.render.camera import Camera

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
        """All points of one level (as ``to_points`` makes them; ``per_entry``
        may be ``"adaptive"``) and the (M+1,) offsets of each voxel's points
        in it, cached: per-frame selection only gathers from these."""
        if isinstance(per_entry, str) and per_entry != "adaptive":
            raise InputError(
                f"points per entry must be a whole number or 'adaptive', got {per_entry!r}"
            )
        key = (level, placement, per_entry, normal)
        if key not in self._clouds:
            tex = self[level]
            pe = self.adaptive_counts(level) if per_entry == "adaptive" else per_entry
            arrays = voxel_points(tex, None, placement, pe, normal)
            cloud = PointCloud(*arrays, name=str(tex.meta.get("source", "points")))
            eoff = np.asarray(tex.entry_offsets, dtype=np.int64)
            if np.ndim(pe) == 0:
                offsets = eoff * int(pe)
            else:
                offsets = np.concatenate([[0], np.cumsum(pe, dtype=np.int64)])[eoff]
            self._clouds[key] = (cloud, offsets)
        return self._clouds[key]

    def clear_cache(self) -> None:
        """Forget cached level point clouds and adaptive counts."""
        self._clouds.clear()
        self._adaptive.clear()

    @property
    def nbytes(self) -> int:
        """Bytes of all levels, the shared sample directions counted once."""
        d = int(np.asarray(self[0].directions).nbytes)
        return int(sum(t.nbytes for t in self) - d * (len(self) - 1))

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
    key = (pc[:, 0] * pshape[1] + pc[:, 1]) * pshape[2] + pc[:, 2]
    pkeys, parent = np.unique(key, return_inverse=True)
    parent = parent.reshape(-1).astype(np.int64)
    Mp = len(pkeys)
    coords = np.stack(
        [pkeys // (pshape[1] * pshape[2]), (pkeys // pshape[2]) % pshape[1], pkeys % pshape[2]],
        axis=1,
    ).astype(np.int32)

    # Density: children grouped by parent, summed, rescaled to (2h)^2.
    order = np.argsort(parent, kind="stable")
    starts = np.zeros(Mp, dtype=np.int64)
    starts[1:] = np.cumsum(np.bincount(parent, minlength=Mp))[:-1]
    if Mp:
        density = np.add.reduceat(np.asarray(t.density)[order], starts, axis=0) * 0.25
    else:
        density = np.zeros((0, K))

    # Shading entries: merged per (parent voxel, sample direction).
    ekey = parent[t.entry_voxel] * K + np.asarray(t.entry_direction, dtype=np.int64)
    ekeys, einv = np.unique(ekey, return_inverse=True)
    einv = einv.reshape(-1)
    E = len(ekeys)
    w = np.asarray(t.entry_area, dtype=np.float64)
    area = np.bincount(einv, weights=w, minlength=E)
    safe = np.where(area > 0, area, 1.0)

    def wmean(values: np.ndarray) -> np.ndarray:
        v = np.asarray(values, dtype=np.float64)
        if v.ndim == 1:
            return np.bincount(einv, weights=w * v, minlength=E) / safe
        return np.stack([wmean(v[:, i]) for i in range(v.shape[1])], axis=1)

    origin = np.asarray(t.origin, dtype=np.float64)
    offsets = np.zeros(Mp + 1, dtype=np.int64)
    offsets[1:] = np.cumsum(np.bincount(ekeys // K, minlength=Mp))
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
    )
    return coarse, parent


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
    cc = np.asarray(coarse.coords, dtype=np.int64)
    ckey = (cc[:, 0] * s[1] + cc[:, 1]) * s[2] + cc[:, 2]
    pc = np.asarray(fine.coords, dtype=np.int64) // 2
    key = (pc[:, 0] * s[1] + pc[:, 1]) * s[2] + pc[:, 2]
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


# -------------------------------------------------------------------- selection


@dataclass(frozen=True)
class Selection:
    """The voxels a view draws, per pyramid level (finest first).

    Attributes:
        voxels: per level, (n_l,) int64 indices into that level's ``coords``,
            sorted (so the points come out in the level's own order).
        culled: per level, voxels found outside the view frustum there (their
            whole subtree is skipped).
        refined: per level, voxels too large on screen, replaced by children.
    """

    voxels: list[np.ndarray]
    culled: list[int]
    refined: list[int]

    @property
    def n_voxels(self) -> int:
        return int(sum(len(v) for v in self.voxels))


def select_voxels(
    levels,
    camera: Camera,
    size: tuple[int, int],
    pixel_error: float = 1.0,
    *,
    cull: bool = True,
    near: float | None = None,
    far: float | None = None,
) -> Selection:
    """Choose per region the coarsest level whose voxels cover at most
    ``pixel_error`` pixels, top-down, culling voxels outside the frustum.

    A voxel of edge h at view depth d covers ``h * H / (2 d tan(fov/2))``
    pixels in an image ``size = (W, H)`` (the framebuffer's size, i.e. with
    supersampling). d is taken conservatively at the front of the voxel's
    bounding sphere (radius ``h sqrt(3) / 2``), so no part of a drawn voxel is
    larger than ``pixel_error`` pixels; voxels the eye is inside of are always
    refined, and the finest level is drawn when nothing finer exists.

    Culling tests the bounding sphere against the four side planes and the
    near and far planes: ``near``/``far`` default to the camera's own, else
    the eye plane and no far limit (so nothing the renderer would draw is
    culled whatever clip range it picks).
    """
    pyr = as_pyramid(levels)
    view = _frustum(camera, size, pixel_error, near, far, "select_voxels")

    L = len(pyr)
    chosen: list[np.ndarray] = [np.zeros(0, dtype=np.int64)] * L
    culled, refined = [0] * L, [0] * L
    cand = np.arange(pyr[-1].n_voxels, dtype=np.int64)
    for lvl in range(L - 1, -1, -1):
        if len(cand) == 0:
            break
        tex = pyr[lvl]
        h = float(tex.voxel_size)
        rad = 0.5 * math.sqrt(3.0) * h
        # Every voxel of the level (a near view): the same set in index order,
        # read without gathering and already sorted.
        ordered = len(cand) == tex.n_voxels
        if ordered:
            cand = np.arange(tex.n_voxels, dtype=np.int64)
        x, y, z = _eye_frame(pyr.centres(lvl), None if ordered else cand, h, tex.origin, view.eye, view.axes)
        if cull:
            inside = view.contains(x, y, z, rad)
            culled[lvl] = int(len(cand) - np.count_nonzero(inside))
            if culled[lvl]:
                cand, z = cand[inside], z[inside]
        if lvl == 0:
            chosen[0] = cand if ordered else np.sort(cand)
            break
        # Depth of the sphere's front; a sphere around the eye is always refined.
        front = z - rad
        big = (front <= 0) | (h * view.scale > pixel_error * np.where(front > 0, front, 1.0))
        chosen[lvl] = cand[~big] if ordered else np.sort(cand[~big])
        parents = cand[big]
        refined[lvl] = len(parents)
        offsets, index = pyr.children(lvl)
        cand = index[_ranges(offsets[parents], offsets[parents + 1])]
    return Selection(chosen, culled, refined)


@dataclass(frozen=True)
class _Frustum:
    """A camera's view as the voxel walks use it: eye, world->eye axes, clip
    depths, the side planes' unit normals in the (lateral, depth) plane, and
    ``scale`` (pixels = size * scale / depth)."""

    eye: np.ndarray
    axes: np.ndarray
    near: float
    far: float
    cx: float
    sx: float
    cy: float
    sy: float
    scale: float

    def contains(self, x, y, z, rad) -> np.ndarray:
        """Which spheres (eye-frame centres x, y, z; radius rad) touch the view."""
        return (
            (z + rad >= self.near) & (z - rad <= self.far)
            & (np.abs(x) * self.cx - z * self.sx <= rad) & (np.abs(y) * self.cy - z * self.sy <= rad)
        )  # fmt: skip


def _frustum(camera, size, pixel_error, near, far, caller: str) -> _Frustum:
    """Check a selection's arguments and set up its view. ``near``/``far``
    default to the camera's own, else the eye plane and no far limit."""
    if not isinstance(camera, Camera):
        raise InputError(f"{caller} needs an aniso3d.Camera, got {type(camera).__name__}")
    w, h_px = (int(size[0]), int(size[1]))
    if w < 1 or h_px < 1:
        raise InputError(f"image size must be at least 1x1 pixels, got {size}")
    if not (pixel_error > 0 and np.isfinite(pixel_error)):
        raise InputError(f"pixel_error must be a positive number of pixels, got {pixel_error}")
    near = camera.near if near is None else near
    far = camera.far if far is None else far
    right, up, fwd = camera.basis()
    tan_y = math.tan(math.radians(camera.fov) / 2.0)
    tan_x = tan_y * w / h_px
    return _Frustum(
        eye=np.asarray(camera.position, dtype=np.float64),
        axes=np.stack([right, up, fwd], axis=1),  # world -> (x, y, z) eye frame
        near=0.0 if near is None else float(near),
        far=np.inf if far is None else float(far),
        cx=1.0 / math.hypot(1.0, tan_x),
        sx=tan_x / math.hypot(1.0, tan_x),
        cy=1.0 / math.hypot(1.0, tan_y),
        sy=tan_y / math.hypot(1.0, tan_y),
        scale=h_px / (2.0 * tan_y),
    )


def _eye_frame(centres, index, h, origin, eye, axes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eye-frame x, y, z of voxel centres: ``centres`` the three columns of
    ``coords + 0.5`` (:meth:`Pyramid.centres`), ``index`` the voxels wanted
    (None: all), ``h`` the voxel edge, ``axes`` (3, 3) with columns right, up,
    forward. Element-wise on purpose: an (n, 3) @ (3, 3) product goes to a
    threaded BLAS whose threads keep spinning after it returns, taking the
    cores a software rasteriser then draws the frame with (+20-30 ms per
    1024^2 frame on 2 cores)."""
    base = (np.asarray(origin, dtype=np.float64) - eye) @ axes
    m = h * axes
    c = centres if index is None else [np.take(col, index) for col in centres]
    return tuple(c[0] * m[0, k] + c[1] * m[1, k] + c[2] * m[2, k] + base[k] for k in range(3))


def _ranges(starts: np.ndarray, stops: np.ndarray) -> np.ndarray:
    """Concatenation of ``arange(starts[i], stops[i])`` over i, vectorised."""
    counts = stops - starts
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64)
    first = np.cumsum(counts) - counts
    return np.repeat(starts - first, counts) + np.arange(total, dtype=np.int64)


# ----------------------------------------------------------------------- points


def voxel_points(
    texture: AnisoTexture,
    voxels: np.ndarray | None = None,
    placement: str = "centroid",
    per_entry: int | np.ndarray = 1,
    normal: str = "mean",
) -> tuple[np.ndarray, ...]:
    """The arrays of :meth:`AnisoTexture.to_points` (positions, normals, areas,
    kd, ks, shininess) restricted to the entries of ``voxels`` (all if None).

    ``per_entry`` is one count for every entry or an (E,) array of counts per
    entry of the whole texture (e.g. :func:`adaptive_points`). With one count
    and all voxels the result is exactly that of ``to_points``.
    """
    t = texture
    if placement not in PLACEMENTS:
        raise InputError(f"unknown placement '{placement}'; choose one of {', '.join(PLACEMENTS)}")
    if normal not in POINT_NORMALS:
        raise InputError(
            f"unknown point normal '{normal}'; choose one of {', '.join(POINT_NORMALS)}"
        )
    off = np.asarray(t.entry_offsets)
    if voxels is None:
        ent = np.arange(t.n_entries, dtype=np.int64)
        vox = t.entry_voxel
    else:
        voxels = np.asarray(voxels, dtype=np.int64)
        ent = _ranges(off[voxels], off[voxels + 1])
        vox = np.repeat(voxels, off[voxels + 1] - off[voxels])
    h = float(t.voxel_size)
    sample_n = t.directions[t.entry_direction[ent]]
    if normal == "mean":
        mean = t.entry_normal[ent].astype(np.float64)
        length = np.linalg.norm(mean, axis=1)
        nrm = np.where(
            (length > 1e-6)[:, None], mean / np.maximum(length, 1e-300)[:, None], sample_n
        )
    else:
        nrm = sample_n
    if placement == "centroid":
        pos = t.entry_centroid[ent].astype(np.float64)
    else:
        centre = (
            np.asarray(t.origin, np.float64) + (np.asarray(t.coords, np.float64)[vox] + 0.5) * h
        )
        pos = centre if placement == "center" else centre + 0.5 * h * sample_n
    area = t.entry_area[ent] * h * h
    kd, ks, sh = t.entry_kd[ent], t.entry_ks[ent], t.entry_shininess[ent]
    if np.ndim(per_entry) == 0:
        if isinstance(per_entry, bool) or int(per_entry) != per_entry or per_entry < 1:
            raise InputError(f"points per entry must be a whole number >= 1, got {per_entry!r}")
        counts = None if int(per_entry) == 1 else np.full(len(ent), int(per_entry), dtype=np.int64)
    else:
        pe = np.asarray(per_entry)
        if pe.shape != (t.n_entries,) or (len(pe) and pe.min() < 1):
            raise InputError(f"per-entry point counts must be ({t.n_entries},) whole numbers >= 1")
        counts = pe[ent].astype(np.int64)
        if len(counts) and counts.max() == 1:
            counts = None
    if counts is not None:
        pos, nrm, area, kd, ks, sh = _spread_counts(pos, nrm, area, kd, ks, sh, counts, h)
    return pos, nrm, area, kd, ks, sh


def _spread_counts(pos, nrm, area, kd, ks, sh, counts, h):
    """Split point i into counts[i] points of area/counts[i] on a Vogel spiral in
    its tangent plane (the same layout as ``to_points(per_entry=m)``)."""
    t, b = _tangent_basis(nrm)
    src = np.repeat(np.arange(len(counts)), counts)
    i = (np.arange(len(src)) - np.repeat(np.cumsum(counts) - counts, counts)).astype(np.float64)
    m = counts[src].astype(np.float64)
    r = np.sqrt((i + 0.5) / m)
    ang = i * np.pi * (3.0 - np.sqrt(5.0))
    radius = np.minimum(np.sqrt(area / np.pi), 0.5 * h)[src]
    along_t = (radius * r * np.cos(ang))[:, None] * t[src]
    offs = along_t + (radius * r * np.sin(ang))[:, None] * b[src]
    return pos[src] + offs, nrm[src], area[src] / m, kd[src], ks[src], sh[src]


def selection_ranges(
    levels,
    selection: Selection,
    placement: str = "centroid",
    per_entry: int | str = 1,
    normal: str = "mean",
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per level, ``(first, count)`` (int64 arrays, one per chosen voxel) of the
    chosen voxels' points inside that level's :meth:`Pyramid.level_cloud`:
    what a renderer that uploads every level once needs to draw a view
    (e.g. with a multi-draw), without building a new point set."""
    pyr = as_pyramid(levels)
    out = []
    for lvl, vox in enumerate(selection.voxels):
        if len(vox) == 0:
            out.append((np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)))
            continue
        _, off = pyr.level_cloud(lvl, placement, per_entry, normal)
        out.append((off[vox], off[vox + 1] - off[vox]))
    return out


def selection_points(
    levels,
    selection: Selection,
    placement: str = "centroid",
    per_entry: int | str = 1,
    normal: str = "mean",
    counts: list[int] | None = None,
) -> PointCloud:
    """One point cloud from the chosen voxels of every level, gathered from the
    cached :meth:`Pyramid.level_cloud` of each level. ``per_entry`` is a count
    or ``"adaptive"``; ``counts``, if given a list, receives the number of
    points per level."""
    pyr = as_pyramid(levels)
    parts = []
    for lvl, (first, n) in enumerate(
        selection_ranges(pyr, selection, placement, per_entry, normal)
    ):
        if counts is not None:
            counts.append(int(n.sum()))
        if len(first):
            parts.append(
                (pyr.level_cloud(lvl, placement, per_entry, normal)[0], _ranges(first, first + n))
            )
    if not parts:
        empty = np.zeros((0, 3))
        return PointCloud(empty, empty, np.zeros(0), empty, np.zeros(0), np.zeros(0),
                          name=str(pyr[0].meta.get("source", "points")))  # fmt: skip
    return _gather(parts)


def _gather(parts: list[tuple[PointCloud, np.ndarray]]) -> PointCloud:
    """Concatenate ``cloud[idx]`` over parts. The clouds were validated when
    made, and a subset of valid points is valid, so the result is assembled
    without :class:`PointCloud`'s checks (which would dominate a frame's
    time): every per-point field is gathered, any other is taken as is."""
    total = int(sum(len(idx) for _, idx in parts))
    first = parts[0][0]
    obj = object.__new__(PointCloud)
    for f in dataclasses.fields(PointCloud):
        v0 = getattr(first, f.name)
        if isinstance(v0, np.ndarray) and v0.ndim >= 1 and len(v0) == len(first):
            out = np.empty((total,) + v0.shape[1:], dtype=v0.dtype)
            pos = 0
            for cloud, idx in parts:
                np.take(
                    getattr(cloud, f.name), idx, axis=0, out=out[pos : pos + len(idx)], mode="clip"
                )
                pos += len(idx)
            object.__setattr__(obj, f.name, out)
        else:
            object.__setattr__(obj, f.name, v0)
    return obj


def select_points(
    levels,
    camera: Camera,
    size: tuple[int, int],
    pixel_error: float = 1.0,
    *,
    placement: str = "centroid",
    per_entry: int | str = 1,
    normal: str = "mean",
    cull: bool = True,
    near: float | None = None,
    far: float | None = None,
    stats: dict | None = None,
) -> PointCloud:
    """The points a view needs: :func:`select_voxels` then the points of the
    chosen voxels (as ``to_points`` makes them, or ``per_entry="adaptive"``).

    ``levels`` is a :class:`Pyramid` (from :func:`pyramid`; a plain list of
    levels or a single texture works but links or levels are rebuilt on every
    call). ``stats``, if a dict, receives ``levels`` (per level: voxel size,
    chosen voxels, points, culled and refined voxels), the totals ``points``,
    ``voxels``, ``culled``, and ``seconds_select`` / ``seconds_points``.
    """
    pyr = as_pyramid(levels)
    t0 = time.perf_counter()
    sel = select_voxels(pyr, camera, size, pixel_error, cull=cull, near=near, far=far)
    t1 = time.perf_counter()
    counts: list[int] = []
    cloud = selection_points(pyr, sel, placement, per_entry, normal, counts=counts)
    t2 = time.perf_counter()
    if stats is not None:
        stats["levels"] = [
            {
                "level": lvl,
                "voxel_size": float(pyr[lvl].voxel_size),
                "voxels": int(len(sel.voxels[lvl])),
                "points": int(counts[lvl]),
                "culled": int(sel.culled[lvl]),
                "refined": int(sel.refined[lvl]),
            }
            for lvl in range(len(pyr))
        ]
        stats["points"] = len(cloud)
        stats["voxels"] = sel.n_voxels
        stats["culled"] = int(sum(sel.culled))
        stats["seconds_select"] = t1 - t0
        stats["seconds_points"] = t2 - t1
        stats["selection"] = sel
    return cloud


# -------------------------------------------------------------- for renderers


@dataclass(frozen=True, eq=False)
class LodPoints:
    """A pyramid and the point options to draw it view-dependently with: what
    :meth:`SplatRenderer.upload <aniso3d.render.splat.SplatRenderer.upload>`
    takes to upload every level's points once and draw, per frame, only
    those :func:`select_voxels` chooses.

    ``per_entry`` is a whole number or ``"adaptive"``; ``placement`` and
    ``normal`` as for :meth:`AnisoTexture.to_points`.
    """

    pyramid: Pyramid
    placement: str = "centroid"
    per_entry: int | str = 1
    normal: str = "mean"

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


def volume_level(
    levels,
    camera: Camera,
    size: tuple[int, int],
    pixel_error: float = 1.0,
    *,
    near: float | None = None,
    far: float | None = None,
    stats: dict | None = None,
) -> int:
    """The one level a ray-marched frame draws: the coarsest whose voxels
    project to at most ``pixel_error`` pixels at the *nearest* view depth of
    the object's visible part.

    That depth is the front of the nearest finest-level voxel (its bounding
    sphere) that survives the frustum culling of :func:`select_voxels`, so
    the choice errs on the fine side; a camera inside or touching the object
    gets level 0, and a view with nothing in it the coarsest level. It is a
    simpler rule than :func:`select_voxels`' per-region choice: one grid per
    frame (the ray marcher draws one texture), so the far parts of a deep view
    are drawn as finely as its nearest part. ``stats``, if a dict, receives
    ``level``, ``voxel_size``, ``depth`` (the nearest depth), ``pixels`` (one
    voxel of the chosen level there) and ``seconds``.
    """
    t0 = time.perf_counter()
    pyr = as_pyramid(levels)
    view = _frustum(camera, size, pixel_error, near, far, "volume_level")
    tex = pyr[0]
    h0 = float(tex.voxel_size)
    rad = 0.5 * math.sqrt(3.0) * h0
    x, y, z = _eye_frame(pyr.centres(0), None, h0, tex.origin, view.eye, view.axes)
    inside = view.contains(x, y, z, rad)
    if not inside.any():
        level, depth = len(pyr) - 1, math.inf
    else:
        depth = float(np.min(z[inside])) - rad
        if depth <= 0.0:
            level = 0
        else:
            # h0 2^l * scale / depth <= pixel_error
            ratio = pixel_error * depth / (h0 * view.scale)
            level = 0 if ratio < 2.0 else min(int(math.floor(math.log2(ratio))), len(pyr) - 1)
    if stats is not None:
        hl = float(pyr[level].voxel_size)
        stats.update(
            level=level,
            voxel_size=hl,
            voxels=pyr[level].n_voxels,
            depth=depth,
            pixels=hl * view.scale / depth if 0 < depth < math.inf else math.inf,
            seconds=time.perf_counter() - t0,
        )
    return level


def describe_stats(stats: dict | None) -> str:
    """One line for a renderer's ``last_lod_stats`` (splat or volume), or "":
    points drawn of the finest level's, points per level drawn, voxels
    culled, selection time."""
    if not stats:
        return ""
    if "level" in stats:  # the volume: one level per frame
        return (
            f"LOD level {stats['level']} · voxel {stats['voxel_size']:.3g} = "
            f"{stats['pixels']:.2f} px at the nearest depth · {stats['selection_ms']:.1f} ms"
        )
    levels = " ".join(f"{lvl}:{n:,}" for lvl, n in enumerate(stats["points_per_level"]) if n)
    return (
        f"LOD {stats['points']:,} of {stats['level0_points']:,} points · levels "
        f"{levels or 'none'} · {stats['culled']:,} culled · {stats['selection_ms']:.1f} ms"
    )
