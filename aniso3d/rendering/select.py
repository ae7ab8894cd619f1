"""Level of detail per view: which voxels of a texture pyramid a camera needs.

:func:`select_voxels` walks a :class:`~aniso3d.build.pyramid.Pyramid`
top-down: a voxel is culled if its bounding sphere lies outside the view
frustum, drawn if it projects to at most ``pixel_error`` pixels, and
otherwise replaced by its children one level finer. Each region is therefore
drawn at exactly one level (the coarsest one that is fine enough), and
:func:`select_points` gathers the chosen voxels' points from the pyramid's
level clouds (the same points ``to_points`` makes). :func:`volume_level`
picks the one level a ray-marched frame draws.

Before any of that, :func:`needed_resolution` says how fine a texture a view
needs at all (``--resolution auto``): built once at that resolution, its
pyramid holds every coarser level exactly.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np

from aniso3d.build.points import PointCloud
from aniso3d.build.pyramid import as_pyramid
from aniso3d.errors import InputError
from aniso3d.grid import ranges
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.instances import ViewCone

# ------------------------------------------------------------------- resolution

#: Range of :func:`needed_resolution` (voxels along the longest axis). The
#: floor keeps a texture of a far or tiny object recognisable; the cap bounds
#: the build: a surface's voxels grow as the resolution squared, and the
#: built-in tree (262,000 triangles, K = 16) takes 17 s and 46 MB at 128,
#: 28 s and 150 MB at 256, 67 s and 490 MB at 512 (2 busy cores): 512 is not a
#: default for a software-rendered machine. A larger explicit resolution still works.
AUTO_MIN_RESOLUTION, AUTO_MAX_RESOLUTION = 8, 256


def nearest_depth(camera: Camera, bounds) -> float:
    """Depth along the view axis (world units) of the point of the box
    ``bounds`` (2, 3) nearest the eye plane on its front side: the smallest
    view depth of its eight corners (a linear function's minimum over a box),
    raised to the camera's ``near`` when it has one. 0 when the box reaches
    the eye plane (the eye inside or beside it); ``inf`` when the box lies
    wholly behind the camera (nothing of it is seen)."""
    b = np.asarray(bounds, dtype=np.float64)
    if b.shape != (2, 3) or not np.isfinite(b).all() or (b[1] < b[0]).any():
        raise InputError(f"bounds must be a (2, 3) min/max box of finite numbers, got {b.tolist()}")
    corners = np.array([[x, y, z] for x in b[:, 0] for y in b[:, 1] for z in b[:, 2]])
    depth = (corners - np.asarray(camera.position)) @ camera.forward
    lo, hi = float(depth.min()), float(depth.max())
    if hi <= 0.0:
        return math.inf
    if camera.near is not None:
        lo = max(lo, float(camera.near))
    return max(lo, 0.0)


def needed_resolution(
    camera: Camera,
    size: tuple[int, int],
    bounds,
    *,
    minimum: int = AUTO_MIN_RESOLUTION,
    maximum: int = AUTO_MAX_RESOLUTION,
) -> int:
    """The coarsest texture resolution (voxels along the longest axis of
    ``bounds``) whose voxels are at most about one pixel wherever the object
    is seen, i.e. at its nearest point: a power of two in ``[minimum, maximum]``.

    A pixel of an image ``size = (W, H)`` spans ``h = z 2 tan(fov / 2) / H``
    world units at view depth z (:func:`nearest_depth`); the texture needs
    ``extent / h`` voxels along the longest extent, rounded up to a power of
    two so that every coarser level of its pyramid is a whole halving
    (:mod:`aniso3d.build.pyramid`). ``size`` is the image's own size, not a
    supersampled framebuffer's: supersampling anti-aliases the pixels, it does
    not ask for finer detail than a pixel shows (a voxel is the texture's
    filter, and its box filter is averaged over the pixel either way). A box
    reaching the eye plane gets ``maximum``; one wholly behind the camera
    ``minimum``.
    """
    if not isinstance(camera, Camera):
        raise InputError(f"needed_resolution needs an aniso3d.Camera, got {type(camera).__name__}")
    w, h_px = (int(size[0]), int(size[1]))
    if w < 1 or h_px < 1:
        raise InputError(f"image size must be at least 1x1 pixels, got {size}")
    for name, value in (("minimum", minimum), ("maximum", maximum)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise InputError(f"needed_resolution {name} must be a whole number >= 1, got {value!r}")
    if maximum < minimum:
        raise InputError(f"needed_resolution maximum ({maximum}) is below its minimum ({minimum})")
    b = np.asarray(bounds, dtype=np.float64)
    depth = nearest_depth(camera, b)
    extent = float(np.max(b[1] - b[0]))
    if depth == 0.0:
        return int(maximum)
    if not math.isfinite(depth) or extent <= 0.0:
        return int(minimum)
    pixel = depth * 2.0 * math.tan(math.radians(camera.fov) / 2.0) / h_px
    voxels = extent / pixel
    # A power of two at or above; the tolerance keeps an exact power where rounding nudged it up.
    res = 2 ** max(0, math.ceil(math.log2(voxels) - 1e-9))
    return int(min(max(res, minimum), maximum))


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
        cand = index[ranges(offsets[parents], offsets[parents + 1])]
    return Selection(chosen, culled, refined)


def _frustum(camera, size, pixel_error, near, far, caller: str) -> ViewCone:
    """Check a selection's arguments and set up its view. ``near``/``far``
    default to the camera's own, else the eye plane and no far limit."""
    view = ViewCone.of(camera, size, near, far, caller)
    if not (pixel_error > 0 and np.isfinite(pixel_error)):
        raise InputError(f"pixel_error must be a positive number of pixels, got {pixel_error}")
    return view


def _eye_frame(centres, index, h, origin, eye, axes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eye-frame x, y, z of voxel centres: ``centres`` the three columns of
    ``coords + 0.5`` (:meth:`~aniso3d.build.pyramid.Pyramid.centres`),
    ``index`` the voxels wanted (None: all), ``h`` the voxel edge, ``axes`` (3, 3) with columns right, up,
    forward. Element-wise on purpose: an (n, 3) @ (3, 3) product goes to a
    threaded BLAS whose threads keep spinning after it returns, taking the
    cores a software rasteriser then draws the frame with (+20-30 ms per
    1024^2 frame on 2 cores)."""
    base = (np.asarray(origin, dtype=np.float64) - eye) @ axes
    m = h * axes
    c = centres if index is None else [np.take(col, index) for col in centres]
    return tuple(c[0] * m[0, k] + c[1] * m[1, k] + c[2] * m[2, k] + base[k] for k in range(3))


def selection_ranges(
    levels,
    selection: Selection,
    placement: str = "centroid",
    per_entry: int | str = 1,
    normal: str = "mean",
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per level, ``(first, count)`` (int64 arrays, one per chosen voxel) of the
    chosen voxels' points inside that level's
    :meth:`~aniso3d.build.pyramid.Pyramid.level_cloud`: what a renderer that
    uploads every level once needs to draw a view (e.g. with a multi-draw),
    without building a new point set."""
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
    cached :meth:`~aniso3d.build.pyramid.Pyramid.level_cloud` of each level.
    ``per_entry`` is a count or ``"adaptive"``; ``counts``, if given a list,
    receives the number of points per level."""
    pyr = as_pyramid(levels)
    parts = []
    for lvl, (first, n) in enumerate(
        selection_ranges(pyr, selection, placement, per_entry, normal)
    ):
        if counts is not None:
            counts.append(int(n.sum()))
        if len(first):
            parts.append(
                (pyr.level_cloud(lvl, placement, per_entry, normal)[0], ranges(first, first + n))
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

    ``levels`` is a :class:`~aniso3d.build.pyramid.Pyramid` (from
    :func:`~aniso3d.build.pyramid.pyramid`; a plain list of levels or a single
    texture works but links or levels are rebuilt on every call). ``stats``,
    if a dict, receives ``levels`` (per level: voxel size, chosen voxels,
    points, culled and refined voxels), the totals ``points``, ``voxels``,
    ``culled``, and ``seconds_select`` / ``seconds_points``.
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
    if "instances" in stats:  # a scene's frame
        from aniso3d.rendering.instances import describe_instances

        return describe_instances(stats)
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
