"""Points on the GPU: a cloud, or every level of a pyramid, uploaded once
(:func:`upload_points`, :func:`upload_lod`), and a pyramid frame's selection
written to its index buffer (:func:`select`).

Points are uploaded once, positions relative to the cloud's centre (float64
subtraction, then float32), and the shaders never form eye-relative positions
in float32 either (see splat.vert), so a far-off cloud, or a camera far away
with a narrow field of view, keeps its precision.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import moderngl
import numpy as np

from aniso3d.build.points import PointCloud
from aniso3d.build.pyramid import LodPoints
from aniso3d.errors import InputError, ResourceError
from aniso3d.grid import ranges
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.select import select_voxels
from aniso3d.rendering.splat.clips import clipped
from aniso3d.rendering.splat.geometry import morton_order

#: Points per block of the CPU's large-splat test (points are Morton-sorted, so
#: a block is a compact piece of the cloud).
BLOCK = 4096
#: Points per row of the attribute texture (two texels each).
ATTRIB_PER_ROW = 2048
#: Vertex attributes of one point, in buffer order, and their float counts.
ATTRIBUTES = (("in_position", 3), ("in_normal", 3), ("in_size", 1), ("in_kd", 3), ("in_spec", 2))
#: float32 values per point in the vertex buffer.
FLOATS_PER_POINT = sum(k for _, k in ATTRIBUTES)
#: Clip planes (:attr:`~aniso3d.build.points.PointCloud.clips`) are few (a
#: surface's ends: 0.3 % of the tree's points, 12 % of the room's), and the
#: code that cuts a splat by them costs llvmpipe about a third of a high frame's
#: vertex work for every point it runs on, planes or none (it runs every
#: branch for every lane). So the points with planes are drawn apart: in the
#: cloud's buffer their shininess is negated (its sign bit set; splat.vert
#: reads its absolute value) and quality "high" skips them there; a second,
#: small upload (:attr:`GPUPoints.cut`) holds them again, in buffer order,
#: with their planes as rows of a table, the row of a point its index there:
#: per plane (code, o, phi), the half-space ``s x_a <= o`` in the local frame,
#: code ``s (a + 1)``, 0: none (:func:`clip_attributes`), two RGB32F texels a
#: row, :data:`CLIP_TABLE_PER_ROW` rows a texture row.
CLIP_TABLE_PER_ROW = 2048
#: float32 values per row of the clip table.
CLIP_FLOATS_PER_ROW = 6
#: Texture unit of the clip table while the cut points are drawn (the passes
#: of quality "high" sample no other textures).
CLIP_TABLE_UNIT = 7


@dataclass(eq=False)
class GPUPoints:
    """A point cloud uploaded once: 12 float32 per point, positions relative to
    ``origin``, Morton-sorted, in blocks of :data:`BLOCK` points; and the
    per-point shading attributes again as a texture (two RGBA32F texels per
    point, :data:`ATTRIB_PER_ROW` points per row) for the deferred shading pass.

    ``block_lo``/``block_hi`` (B, 3) are the blocks' position bounds in the
    local frame and ``block_size`` (B,) their largest ``sqrt(area)``. A cloud
    with clip planes has the points that have them uploaded again in ``cut``
    (their indices here ``cut_ids``, ascending; ``cut_mask`` (N,) marks them),
    whose ``clip_table`` holds their planes (:data:`CLIP_TABLE_PER_ROW`).
    """

    vbo: moderngl.Buffer
    attrib: moderngl.Texture
    origin: np.ndarray
    bounds: np.ndarray
    n_points: int
    nbytes: int
    block_start: np.ndarray
    block_count: np.ndarray
    block_lo: np.ndarray
    block_hi: np.ndarray
    block_size: np.ndarray
    vaos: dict = field(default_factory=dict)
    #: Median ``sqrt(area)`` of the points (of level 0 for a pyramid).
    typical_size: float = 0.0
    #: The points with clip planes, uploaded again (None: none), and where
    #: they lie in this upload.
    cut: GPUPoints | None = None
    cut_ids: np.ndarray | None = None
    cut_mask: np.ndarray | None = None
    #: A cut upload's planes, a row per point (:data:`CLIP_TABLE_PER_ROW`).
    clip_table: moderngl.Texture | None = None

    @property
    def n_clipped(self) -> int:
        """Points with clip planes."""
        return 0 if self.cut is None else self.cut.n_points


@dataclass(eq=False)
class GPULodPoints(GPUPoints):
    """Every level of a pyramid's points (:class:`~aniso3d.build.pyramid.LodPoints`)
    uploaded once, one after the other in one buffer (finest level first),
    each level's voxels in Morton order of their grid cells with every voxel's
    points contiguous. A frame draws only the voxels
    :func:`~aniso3d.rendering.select.select_voxels` chooses, through an index buffer
    rewritten per frame (4 bytes per point drawn), in ascending order.

    ``bounds`` (and so the clip range) covers every level's points, whatever a
    frame selects. Per level l: ``level_first[l]`` is its first point in the
    buffer, ``rank[l]`` (M_l,) each voxel's place in Morton order and
    ``run_first[l]``, ``run_count[l]`` (M_l,) the buffer range of the voxel
    of each rank. ``last_stats`` is the last frame's selection (see
    :func:`select`).
    """

    lod: LodPoints | None = None
    level_first: np.ndarray | None = None
    rank: list = field(default_factory=list)
    run_first: list = field(default_factory=list)
    run_count: list = field(default_factory=list)
    level_bounds: np.ndarray | None = None  # (L, 2, 3) each level's point bounds
    level_size: np.ndarray | None = None  # (L,) each level's largest sqrt(area)
    index_buffer: moderngl.Buffer | None = None
    indexed_vaos: dict = field(default_factory=dict)
    drawn: np.ndarray | None = None  # this frame's indices (sorted uint32)
    frame_box: tuple | None = None  # (bounds, largest size) of the levels drawn this frame
    last_stats: dict = field(default_factory=dict)


def upload_points(gl: GLContext, cloud: PointCloud | LodPoints) -> GPUPoints:
    """Upload ``cloud`` once: float64 positions minus the cloud's centre,
    then float32, so far-off clouds keep their precision.

    A :class:`~aniso3d.build.pyramid.LodPoints` uploads every level of its pyramid
    (:class:`GPULodPoints`), which :func:`select` draws from per frame."""
    if isinstance(cloud, LodPoints):
        return upload_lod(gl, cloud)
    if not isinstance(cloud, PointCloud):
        raise InputError(f"the splat renderer draws a PointCloud, got {type(cloud).__name__}")
    n = len(cloud)
    if n == 0:
        raise InputError("cannot draw an empty point cloud (it has no points)")
    bounds = cloud.bounds
    origin = 0.5 * (bounds[0] + bounds[1])
    order = morton_order(cloud.positions - origin)
    arrays = (cloud.positions, uploaded_normals(cloud), cloud.areas, cloud.kd, cloud.ks, cloud.shininess)
    return _upload_arrays(gl, GPUPoints, arrays, order, bounds, origin, one_sided=cloud.one_sided,
                          clips=cloud.clips, sheet=cloud.sheet)  # fmt: skip


#: Least coherence uploaded: the normal's length carries it, and the splat's
#: orientation must survive normalising it.
MIN_COHERENCE = 1e-3


def uploaded_normals(cloud: PointCloud) -> np.ndarray:
    """(N, 3) float32 normals as uploaded: the unit normal times the point's
    coherence (at least :data:`MIN_COHERENCE`), so one vertex attribute gives
    the shaders both (splat.vert normalises it for the splat's plane and
    passes its length to shade())."""
    return cloud.normals * np.maximum(cloud.coherence, MIN_COHERENCE)[:, None]


def clip_attributes(clips: np.ndarray, origin) -> np.ndarray:
    """(N, 2, 3) float32 (code, offset, angle) of clip planes ``clips`` (N, 2, 5)
    (:attr:`~aniso3d.build.points.PointCloud.clips`) in the frame whose
    origin is ``origin``: the half-space ``s x_a <= o`` as code ``s (a + 1)``
    (0: none) and ``o`` less ``s origin_a``; the angle as it is."""
    m = np.asarray(clips[..., :3], dtype=np.float64)
    axis = np.argmax(np.abs(m), axis=-1)
    sign = np.take_along_axis(m, axis[..., None], axis=-1)[..., 0]
    local = clips[..., 3] - sign * np.asarray(origin, dtype=np.float64)[axis]
    angle = np.where(sign != 0, clips[..., 4], 0.0)
    return np.stack([sign * (axis + 1), np.where(sign != 0, local, 0.0), angle], axis=-1).astype(np.float32)


def _texture_rows(data: np.ndarray, per_row: int) -> tuple[np.ndarray, tuple[int, int]]:
    """``data`` (n, c) padded with zero rows to whole texture rows of
    ``per_row`` entries (one row of n, at least 1, if n is less), and the
    texture's size in entries."""
    per_row = min(per_row, max(1, len(data)))
    rows = max(1, -(-len(data) // per_row))
    out = np.zeros((rows * per_row, *data.shape[1:]), dtype=data.dtype)
    out[: len(data)] = data
    return out, (per_row, rows)


def _upload_arrays(
    gl: GLContext, cls, arrays, order, bounds, origin, one_sided=None, clips=None, sheet=None, attrib=True,
    **extra,
) -> GPUPoints:
    """Upload the points ``order`` of ``arrays`` (positions, normals,
    areas, kd, ks, shininess), in that order, relative to ``origin``; a
    ``one_sided`` point (:attr:`~aniso3d.build.points.PointCloud.one_sided`)
    gets its size negated (splat.vert culls it where it faces away); a
    ``sheet`` point (:attr:`~aniso3d.build.points.PointCloud.sheet`) gets the
    sign bit of its ks set (-0.0 for ks 0; splat.vert reads it); the points
    with ``clips`` (:attr:`~aniso3d.build.points.PointCloud.clips`, None:
    none) get their shininess negated and are uploaded again, with their
    planes in the local frame (:attr:`GPUPoints.cut`). ``attrib``: make the
    attribute texture (only the deferred shading of quality "fast" reads it,
    and it never draws a cut upload)."""
    positions, normals, areas, kd, ks, shininess = arrays
    n = len(order)
    rows = -(-n // ATTRIB_PER_ROW)
    if attrib and rows > gl.max_texture_size:
        raise ResourceError(
            f"{n} points need a {2 * ATTRIB_PER_ROW}x{rows} attribute texture, above this "
            f"OpenGL's limit of {gl.max_texture_size}; draw the cloud in parts"
        )
    local = positions[order] - origin
    size = np.sqrt(areas[order])
    data = np.empty((n, FLOATS_PER_POINT), dtype=np.float32)
    data[:, 0:3] = local
    data[:, 3:6] = normals[order]
    data[:, 6] = size if one_sided is None else np.where(one_sided[order], -size, size)
    data[:, 7:10] = kd[order]
    data[:, 10] = ks[order] if sheet is None else np.where(sheet[order], np.copysign(ks[order], -1.0), ks[order])
    data[:, 11] = shininess[order]
    ctx = gl.ctx
    tex, attrib_nbytes = None, 0
    if attrib:
        values = np.zeros((rows * ATTRIB_PER_ROW, 8), dtype=np.float32)
        values[:n, 0:3] = data[:, 3:6]
        values[:n, 3] = ks[order]  # plain: the sheet bit is for the high passes
        values[:n, 4:7] = data[:, 7:10]
        values[:n, 7] = data[:, 11]
        tex = gl.track(ctx.texture((2 * ATTRIB_PER_ROW, rows), 4, values.tobytes(), dtype="f4"))
        tex.filter = moderngl.NEAREST, moderngl.NEAREST
        attrib_nbytes = values.nbytes
    cut = cut_ids = cut_mask = None
    if clips is not None:
        clips = clips[order]
        cut_mask = np.any(clips[..., :3] != 0, axis=(1, 2))
        cut_ids = np.flatnonzero(cut_mask)
        if len(cut_ids):
            cut = _upload_cut(gl, cls, arrays, order[cut_ids], clips[cut_ids], bounds, origin,
                              one_sided, sheet)  # fmt: skip
            data[cut_ids, 11] = -data[cut_ids, 11]  # the sign bit: drawn apart (-0.0 for 0)
        else:
            cut_ids = cut_mask = None
    vbo = gl.track(ctx.buffer(data.tobytes()))
    start = np.arange(0, n, BLOCK)
    count = np.minimum(BLOCK, n - start)
    return cls(
        vbo=vbo,
        attrib=tex,
        origin=origin,
        bounds=bounds,
        n_points=n,
        nbytes=data.nbytes + attrib_nbytes + (0 if cut is None else cut.nbytes),
        cut=cut,
        cut_ids=cut_ids,
        cut_mask=cut_mask,
        block_start=start,
        block_count=count,
        block_lo=np.minimum.reduceat(local, start, axis=0),
        block_hi=np.maximum.reduceat(local, start, axis=0),
        block_size=np.maximum.reduceat(size, start),
        typical_size=float(np.median(size)),
        **extra,
    )


def _upload_cut(gl: GLContext, cls, arrays, order, clips, bounds, origin, one_sided, sheet=None) -> GPUPoints:
    """The points ``order`` of ``arrays`` with clip planes ``clips`` (their
    rows, in that order) as a :attr:`GPUPoints.cut` upload: the same origin,
    no attribute texture, the planes in its ``clip_table`` (row i: point i)."""
    table = clip_attributes(clips, origin).reshape(-1, CLIP_FLOATS_PER_ROW)
    padded, (w, h) = _texture_rows(table, CLIP_TABLE_PER_ROW)
    if h > gl.max_texture_size:
        raise ResourceError(f"{len(table)} points' clip planes need a texture of {h} rows, above this "
                            f"OpenGL's limit of {gl.max_texture_size}; draw the cloud in parts")  # fmt: skip
    cut = _upload_arrays(gl, GPULodPoints if cls is GPULodPoints else GPUPoints, arrays, order, bounds, origin,
                         one_sided, sheet=sheet, attrib=False)  # fmt: skip
    cut.clip_table = gl.track(gl.ctx.texture((2 * w, h), 3, padded.tobytes(), dtype="f4"))
    cut.clip_table.filter = moderngl.NEAREST, moderngl.NEAREST
    cut.nbytes += padded.nbytes
    if isinstance(cut, GPULodPoints):
        cut.index_buffer = gl.track(gl.ctx.buffer(reserve=4 * max(cut.n_points, 1)))
    return cut


def upload_lod(gl: GLContext, lod: LodPoints) -> GPULodPoints:
    """Every level's points in one buffer: level by level, finest first,
    voxels in Morton order of their cells, a voxel's points together; with
    ``lod.clips``, each with the clip planes of its level's texture
    (:func:`~aniso3d.rendering.splat.clips.clipped`)."""
    pyr = lod.pyramid
    clouds, parts, rank, run_first, run_count, level_first = [], [], [], [], [], []
    base = 0
    for lvl in range(len(pyr)):
        cloud, off = lod.level_cloud(lvl)
        if lod.clips and cloud.clips is None and len(cloud):
            counts = pyr.adaptive_counts(lvl) if lod.per_entry == "adaptive" else lod.per_entry
            cloud = clipped(cloud, pyr[lvl], None, counts)
        m = pyr[lvl].n_voxels
        vorder = morton_order(pyr[lvl].coords) if m > 1 else np.arange(m)
        counts = (off[vorder + 1] - off[vorder]).astype(np.int64)
        r = np.empty(m, dtype=np.int64)
        r[vorder] = np.arange(m)
        clouds.append(cloud)
        parts.append(base + ranges(off[vorder], off[vorder + 1]))
        rank.append(r)
        run_first.append(base + np.cumsum(counts) - counts)
        run_count.append(counts)
        level_first.append(base)
        base += len(cloud)
    if len(clouds[0]) == 0:
        raise InputError("cannot draw an empty point cloud (it has no points)")
    if base >= 2**32:
        raise ResourceError(f"{base} points in all levels are too many for 32-bit indices")
    bounds = np.stack([
        np.min([c.bounds[0] for c in clouds if len(c)], axis=0),
        np.max([c.bounds[1] for c in clouds if len(c)], axis=0),
    ])  # fmt: skip
    b0 = clouds[0].bounds  # level 0 keeps the origin a plain upload of its points has
    origin = 0.5 * (b0[0] + b0[1])
    arrays = tuple(
        np.concatenate([uploaded_normals(c) if name == "normals" else getattr(c, name) for c in clouds])
        for name in ("positions", "normals", "areas", "kd", "ks", "shininess")
    )
    one_sided = None
    if any(c.one_sided is not None for c in clouds):
        one_sided = np.concatenate([np.zeros(len(c), bool) if c.one_sided is None else c.one_sided for c in clouds])
    sheet = None
    if any(c.sheet is not None for c in clouds):
        sheet = np.concatenate([np.zeros(len(c), bool) if c.sheet is None else c.sheet for c in clouds])
    clips = None
    if any(c.clips is not None for c in clouds):
        clips = np.concatenate([np.zeros((len(c), 2, 5)) if c.clips is None else c.clips for c in clouds])
    empty = np.full((2, 3), np.nan)
    handle = _upload_arrays(
        gl, GPULodPoints, arrays, np.concatenate(parts), bounds, origin, one_sided=one_sided, clips=clips,
        sheet=sheet, lod=lod, level_first=np.asarray(level_first, dtype=np.int64),
        rank=rank, run_first=run_first, run_count=run_count,
        level_bounds=np.stack([c.bounds if len(c) else empty for c in clouds]),
        level_size=np.array([np.sqrt(c.areas.max()) if len(c) else 0.0 for c in clouds]),
    )  # fmt: skip
    handle.index_buffer = gl.track(gl.ctx.buffer(reserve=4 * max(len(clouds[0]), 1)))
    handle.typical_size = float(np.median(np.sqrt(clouds[0].areas)))
    return handle


def select(handle: GPULodPoints, view: FrameView, pixel_error: float = 1.0) -> dict:
    """This frame's points of a pyramid upload: :func:`~aniso3d.rendering.select.select_voxels`
    for the view's camera and framebuffer size (clip range ``view.near``
    to ``view.far``), their buffer indices written to the index buffer.
    Returns (and keeps as ``handle.last_stats``) the frame's statistics: ``points`` drawn,
    ``points_per_level``, ``voxels_per_level``, ``culled`` (voxels found
    outside the view, their subtrees skipped), ``culled_per_level``,
    ``total_points`` (uploaded, all levels), ``select_ms`` (the voxel
    walk), ``index_ms`` (indices made and written) and ``selection_ms``
    (both)."""
    pyr = handle.lod.pyramid
    t0 = time.perf_counter()
    sel = select_voxels(pyr, view.camera, view.size, pixel_error, near=view.near, far=view.far)
    t1 = time.perf_counter()
    firsts, counts, per_level = [], [], []
    for lvl, vox in enumerate(sel.voxels):
        if len(vox) == 0:
            per_level.append(0)
            continue
        if len(vox) == len(handle.rank[lvl]):  # the whole level (a near view): one run
            c = np.array([handle.run_count[lvl].sum()])
            firsts.append(handle.level_first[lvl : lvl + 1])
        else:
            r = np.sort(handle.rank[lvl][vox])
            c = handle.run_count[lvl][r]
            firsts.append(handle.run_first[lvl][r])
        counts.append(c)
        per_level.append(int(c.sum()))
    if firsts:
        f, c = np.concatenate(firsts), np.concatenate(counts)
        idx = ranges(f, f + c).astype(np.uint32)
    else:
        idx = np.zeros(0, dtype=np.uint32)
    buf = handle.index_buffer
    if idx.nbytes > buf.size:
        buf.orphan(max(idx.nbytes, 2 * buf.size))
    if idx.nbytes:
        buf.write(idx)
    handle.drawn = idx
    used = [lvl for lvl, n in enumerate(per_level) if n]
    if used:
        lb = handle.level_bounds[used]
        box = np.stack([lb[:, 0].min(axis=0), lb[:, 1].max(axis=0)])
        handle.frame_box = (box, float(handle.level_size[used].max()))
    else:
        handle.frame_box = None
    cut = handle.cut
    if cut is not None:  # the drawn points with clip planes, as indices into their own upload
        mine = idx[handle.cut_mask[idx]]
        cut.drawn = np.searchsorted(handle.cut_ids, mine).astype(np.uint32)
        if cut.drawn.nbytes > cut.index_buffer.size:
            cut.index_buffer.orphan(max(cut.drawn.nbytes, 2 * cut.index_buffer.size))
        if cut.drawn.nbytes:
            cut.index_buffer.write(cut.drawn)
        cut.frame_box = handle.frame_box
    t2 = time.perf_counter()
    stats = {
        "points": int(len(idx)),
        "points_per_level": per_level,
        "voxels_per_level": [int(len(v)) for v in sel.voxels],
        "culled": int(sum(sel.culled)),
        "culled_per_level": [int(c) for c in sel.culled],
        "total_points": int(handle.n_points),
        "level0_points": int(handle.level_first[1] if len(pyr) > 1 else handle.n_points),
        "pixel_error": float(pixel_error),
        "select_ms": 1000.0 * (t1 - t0),
        "index_ms": 1000.0 * (t2 - t1),
        "selection_ms": 1000.0 * (t2 - t0),
    }
    handle.last_stats = stats
    return stats


def release_points(gl: GLContext, handle: GPUPoints) -> None:
    """Free an upload's GPU objects."""
    if handle.cut is not None:
        release_points(gl, handle.cut)
    gl.free(*handle.vaos.values(), handle.vbo, *(t for t in (handle.attrib, handle.clip_table) if t is not None))
    handle.vaos.clear()
    if isinstance(handle, GPULodPoints):
        gl.free(*handle.indexed_vaos.values(), handle.index_buffer)
        handle.indexed_vaos.clear()
