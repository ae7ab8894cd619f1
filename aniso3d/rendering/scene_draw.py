"""Drawing a :class:`~aniso3d.build.scene.Scene` with the three renderers.

Each asset is converted and uploaded once through the
:class:`~aniso3d.rendering.renderer.Renderer`'s caches (its polygons, or its
pyramid: every level's points, every level's texture) and shared by all its
instances. Per frame, for every asset, all its instances are culled and (splats,
volume) given a pyramid level at once in NumPy
(:mod:`~aniso3d.rendering.instances`); then

- polygons: one instanced draw call per asset (per instance a mat4 and a
  tint as instanced vertex attributes): the ground truth;
- splats: one instanced draw call per (asset, level) and pass, the level's
  points with each instance's matrix applied in the vertex stage (splat.vert
  ``INSTANCED``); quality "fast" shaded in the same pass (splat.frag
  ``FORWARD``), "high" and "blend" by their own passes;
- volume: each visible instance's screen box, farthest first, ray-marched in
  the instance's own frame (the camera moved by the inverse transform, in
  float64 on the CPU for all instances at once; the lights turned per
  fragment; rigid motions with a uniform scale), blended "over": one
  instanced draw call per (asset, level) group and depth slab.

Instances are never Python objects: per frame a renderer writes the drawn
instances' 68 bytes each into one buffer per draw call.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from types import SimpleNamespace

import moderngl
import numpy as np

from aniso3d.build.scene import Scene
from aniso3d.errors import InputError
from aniso3d.rendering.frame import DrawStats, FrameView
from aniso3d.rendering.instances import (
    ViewCone,
    back_to_front,
    groups,
    instance_data,
    instance_levels,
    instance_spheres,
    visible_instances,
)


@dataclass(eq=False)
class SceneUpload:
    """What a scene frame draws from: per asset the method renderer's upload
    (a :class:`~aniso3d.rendering.polygon.GPUMesh`, a pyramid of points or of
    volumes) and its pyramid's voxel sizes (finest first). ``origin`` is the
    frame-local origin every instance matrix is made relative to (float64);
    ``bounds`` the scene's world box."""

    scene: Scene
    method: str
    handles: list
    voxel_sizes: list
    origin: np.ndarray
    bounds: np.ndarray
    nbytes: int = 0
    spheres: list = field(default_factory=list)


def upload_scene(renderer, scene: Scene, method: str, build) -> SceneUpload:
    """Upload every asset of ``scene`` for ``method`` through ``renderer``'s
    caches (a pyramid for splats and volume)."""
    if scene.n_instances == 0:
        raise InputError(f"scene '{scene.name}' has no instances: nothing to draw")
    if build.resolution == "auto" and method != "mesh":
        raise InputError("resolution 'auto' is for one mesh; give a scene a number of voxels (e.g. resolution=64)")
    handles, sizes = [], []
    b = replace(build, lod=method != "mesh")
    for asset in scene.assets:
        handles.append(renderer.upload(asset, method, build=b))
        if method == "mesh":
            sizes.append(np.zeros(1))
        else:
            pyr = renderer.pyramid(asset, resolution=b.resolution, directions=b.directions)
            sizes.append(np.array([float(tex.voxel_size) for tex in pyr]))
    bounds = scene.bounds
    up = SceneUpload(scene, method, handles, sizes, 0.5 * (bounds[0] + bounds[1]), bounds)
    up.nbytes = int(sum(getattr(h, "nbytes", 0) for h in handles))
    return up


def _spheres(up: SceneUpload, i: int, margin: float = 0.0):
    """Asset ``i``'s instance spheres (made per frame: the scene's arrays may change)."""
    c, r, s = instance_spheres(up.scene.transforms[i], up.scene.asset_bounds(i))
    return c, r + margin * s, s


def scene_clip_range(up: SceneUpload, camera) -> tuple[float, float]:
    """(near, far) from the instances' own bounding spheres, not the scene's
    box: one far instance must not push the near plane past the close ones.
    Near is the nearest sphere in front, but never less than 1e-4 of that
    sphere's radius (an eye inside an instance) nor 1e-6 of far; the camera's
    own ``near``/``far`` win when set."""
    eye = np.asarray(camera.position, dtype=np.float64)
    fwd = np.asarray(camera.forward, dtype=np.float64)
    near_auto, near_radius, far_auto = np.inf, 0.0, -np.inf
    for i in range(len(up.scene.assets)):  # per asset; the instances at once
        c, r, _ = _spheres(up, i)
        if not len(r):
            continue
        d = (c - eye) @ fwd
        front, back = d - 1.01 * r, d + 1.01 * r
        far_auto = max(far_auto, float(back.max()))
        ahead = back > 0
        if ahead.any():
            k = int(np.argmin(np.where(ahead, front, np.inf)))
            if front[k] < near_auto:
                near_auto, near_radius = float(front[k]), float(r[k])
    if not np.isfinite(near_auto):  # nothing ahead: any valid range draws nothing
        return camera.clip_range(up.bounds)
    near_auto = max(near_auto, 1e-4 * near_radius, 1e-6 * far_auto, 1e-30)
    near = camera.near if camera.near is not None else near_auto
    far = camera.far if camera.far is not None else far_auto
    if far <= near:
        far = near * 2.0
    return float(near), float(far)


def draw_scene(impl, up: SceneUpload, view: FrameView, fbo, opts) -> DrawStats:
    """One frame of a scene with the method renderer ``impl``."""
    if up.method == "mesh":
        return _draw_mesh(impl, up, view)
    if up.method == "splat":
        return _draw_splat(impl, up, view, fbo, opts)
    return _draw_volume(impl, up, view, fbo, opts)


# --------------------------------------------------------------------- polygons


def _draw_mesh(impl, up: SceneUpload, view: FrameView) -> DrawStats:
    t0 = time.perf_counter()
    cone = ViewCone.of(view.camera, view.size, view.near, view.far)
    ctx = impl.gl.ctx
    drawn, visible = 0, []
    for i in range(len(up.handles)):
        c, r, _ = _spheres(up, i)
        visible.append(np.flatnonzero(visible_instances(c, r, cone)))
    lod = _stats(up, visible, None, t0)
    for i, (handle, sel) in enumerate(zip(up.handles, visible, strict=True)):
        if not len(sel):
            continue
        data = instance_data(up.scene.transforms[i][sel], up.scene.tints[i][sel], up.origin, handle.origin)
        buf = ctx.buffer(data)
        try:
            drawn += impl.draw_instances(handle, view, buf, len(sel), up.origin).drawn
        finally:
            buf.release()
    return DrawStats(drawn=drawn, unit="triangles", lod=lod)


def _stats(up: SceneUpload, visible: list, levels: list | None, t0: float) -> dict:
    """The frame's per-instance choices: ``instance_levels`` per asset ((N,)
    int64, -1 where culled; 0 for polygons), ``instances``, ``visible``,
    ``culled``, ``instances_per_level`` and ``selection_ms`` (culling and
    level choice, from ``t0``)."""
    per_asset = []
    for i, sel in enumerate(visible):
        lv = np.full(len(up.scene.transforms[i]), -1, dtype=np.int64)
        lv[sel] = 0 if levels is None else levels[i]
        per_asset.append(lv)
    n_vis = int(sum(len(s) for s in visible))
    counts = np.bincount(np.concatenate([lv[lv >= 0] for lv in per_asset] + [np.zeros(0, np.int64)]))
    return {
        "instances": up.scene.n_instances,
        "visible": n_vis,
        "culled": up.scene.n_instances - n_vis,
        "instance_levels": per_asset,
        "instances_per_level": [int(n) for n in counts],
        "selection_ms": 1000.0 * (time.perf_counter() - t0),
    }


# ----------------------------------------------------------------------- splats


@dataclass(eq=False)
class _Plan:
    """One instanced draw: asset ``asset``'s level ``level`` for the instances
    ``sel``, with the widest splat each may show (pixels, inf when it reaches
    the eye plane)."""

    asset: int
    level: int
    sel: np.ndarray
    widest: np.ndarray


class _InstancedGL:
    """The context with ``defines`` added to every program it compiles."""

    def __init__(self, gl, defines: dict):
        self._gl, self._defines = gl, defines

    def program(self, vertex, fragment, geometry=None, defines=None):
        return self._gl.program(vertex, fragment, geometry, {**(defines or {}), **self._defines})

    def __getattr__(self, name):
        return getattr(self._gl, name)


class _InstancedPipe:
    """The splat pipeline with one pass over the points replaced by the
    instanced draws of a frame's plans: the passes of qualities "high" and
    "blend" (:mod:`~aniso3d.rendering.splat.coverage`) run on it unchanged,
    their programs compiled with ``INSTANCED`` (splat.vert)."""

    def __init__(self, pipe, up: SceneUpload, plans: list, defines: dict):
        self._pipe = pipe
        self.gl = _InstancedGL(pipe.gl, {"INSTANCED": 1, **defines})
        self.up, self.plans = up, plans
        self.drawn = 0

    def program(self, kind: str, shape: str, sprite: bool, aa: bool = False) -> moderngl.Program:
        return type(self._pipe).program(self, kind, shape, sprite, aa)

    def __getattr__(self, name):
        return getattr(self._pipe, name)

    def splats(self, handle, view: FrameView, opts, kind: str, uniforms: dict) -> None:
        """Every plan's instances: point sprites, then, for the instances that
        may hold wider splats, the geometry path."""
        from aniso3d.rendering.splat.params import AA_SHADE_BOX

        aa = opts.quality == "high"
        limit = self._pipe.max_sprite
        if aa and kind == "accumulate":  # as SplatPipeline.splats: wide boxes are shaded in the geometry path
            limit = min(limit, AA_SHADE_BOX)
        ctx = self._pipe.gl.ctx
        values = {**uniforms, "u_max_sprite": limit, "u_shade_box": AA_SHADE_BOX}
        for sprite in (True, False):
            prog = self.program(kind, opts.splat, sprite=sprite, aa=aa)
            self._pipe.bind(prog, values)
            for plan in self.plans:
                sel = plan.sel if sprite else plan.sel[plan.widest + 4.0 > limit]
                h = self.up.handles[plan.asset]
                first = int(h.level_first[plan.level])
                last = int(h.level_first[plan.level + 1]) if plan.level + 1 < len(h.level_first) else h.n_points
                if not len(sel) or last <= first:
                    continue
                s = self.up.scene
                buf = ctx.buffer(instance_data(s.transforms[plan.asset][sel], s.tints[plan.asset][sel],
                                               self.up.origin, h.origin))  # fmt: skip
                try:
                    vao = _splat_vao(self._pipe.gl, h, prog, buf)
                    try:
                        vao.render(moderngl.POINTS, vertices=last - first, first=first, instances=len(sel))
                    finally:
                        vao.release()
                finally:
                    buf.release()
                if sprite and kind in ("geometry", "visibility"):
                    self.drawn += (last - first) * len(sel)


def _splat_vao(gl, handle, prog, instances) -> moderngl.VertexArray:
    """The asset's points (per vertex, as ``inst_*``) and the instances' mat4 and tint (divisor 1)."""
    from aniso3d.rendering.splat.buffers import ATTRIBUTES

    fmt, names = [], []
    for name, k in ATTRIBUTES:
        local = name.replace("in_", "inst_") if name != "in_spec" else name
        if local in prog:
            fmt.append(f"{k}f")
            names.append(local)
        else:
            fmt.append(f"{4 * k}x")
    per_instance = ("16f 4f1/i", "in_instance", "in_tint") if "in_tint" in prog else ("16f 4x/i", "in_instance")
    return gl.ctx.vertex_array(prog, [(handle.vbo, " ".join(fmt), *names), (instances, *per_instance)])


def _draw_splat(impl, up: SceneUpload, view: FrameView, fbo, opts) -> DrawStats:
    """Quality "fast": one forward-shaded pass (splat.frag ``FORWARD``: an
    instance's normal and tint exist only in its vertex stage, so the
    deferred shading of one cloud does not apply); "high" and "blend": their
    own passes, each pass over the points made of the instanced draws. Each
    instance's level: :func:`~aniso3d.rendering.instances.instance_levels`
    with the points budget :data:`~aniso3d.rendering.instances.POINTS_PER_PIXEL`
    (read at each frame)."""
    from aniso3d.rendering import instances
    from aniso3d.rendering.splat.coverage import BlendPass, HighPass

    points_per_pixel = instances.POINTS_PER_PIXEL

    t0 = time.perf_counter()
    pixel_error = 1.0 if opts.pixel_error is None else opts.pixel_error
    cone = ViewCone.of(view.camera, view.size, view.near, view.far)
    reach = math.hypot(*opts.extent)
    plans, visible, levels_of = [], [], []
    for i, handle in enumerate(up.handles):
        grow = float(handle.level_size.max()) * reach  # the largest splat's reach past its point
        c, r, s = _spheres(up, i, grow)
        vis = np.flatnonzero(visible_instances(c, r, cone))
        first = np.append(handle.level_first, handle.n_points)
        lv = instance_levels(c[vis], r[vis], s[vis], up.voxel_sizes[i], cone, pixel_error,
                             level_points=np.diff(first), points_per_pixel=points_per_pixel)  # fmt: skip
        visible.append(vis)
        levels_of.append(lv)
        for level, idx in groups(lv):
            sel = vis[idx]
            front = cone.eye_frame(c[sel])[:, 2] - r[sel]
            big = 2.0 * float(handle.level_size[level]) * reach * s[sel] * cone.scale
            widest = np.where(front > 0, big / np.where(front > 0, front, 1.0), np.inf)
            plans.append(_Plan(i, level, sel, widest))
    lod = _stats(up, visible, levels_of, t0)
    pipe = impl.pipe
    proxy = SimpleNamespace(
        origin=up.origin, bounds=up.bounds,
        block_size=np.array([max(float(h.level_size.max()) for h in up.handles)]),
        typical_size=float(np.median([h.typical_size for h in up.handles])),
    )  # fmt: skip
    # Instances may be mirrored, and the eye may stand among them: no culling.
    uniforms = pipe.uniforms(proxy, view, opts, one_sided=False)
    ctx = impl.gl.ctx
    target = fbo if fbo is not None else ctx.fbo
    viewport = ctx.viewport
    ctx.enable(moderngl.DEPTH_TEST | moderngl.PROGRAM_POINT_SIZE)
    ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
    ctx.depth_func = "<"
    try:
        if opts.quality == "fast":
            ipipe = _InstancedPipe(pipe, up, plans, {"FORWARD": 1})
            ipipe.splats(proxy, view, opts, "geometry", uniforms)
        else:
            ipipe = _InstancedPipe(pipe, up, plans, {})
            quality = {"high": HighPass, "blend": BlendPass}[opts.quality](ipipe)
            quality.draw(proxy, view, opts, uniforms, quality.targets(view.size), target, viewport)
    finally:
        target.depth_mask = True
        ctx.blend_equation = moderngl.FUNC_ADD
        ctx.depth_func = "<"
        ctx.blend_func = moderngl.DEFAULT_BLENDING
        ctx.disable(moderngl.BLEND)
        ctx.enable(moderngl.DEPTH_TEST)
        if ctx.fbo is not target:
            target.use()
            ctx.viewport = viewport
    lod.update(points=ipipe.drawn, draw_calls=len(plans))
    used = tuple(int(lvl) for lvl, n in enumerate(lod["instances_per_level"]) if n)
    return DrawStats(drawn=ipipe.drawn, unit="points", levels=used, lod=lod)


# ----------------------------------------------------------------------- volume


def _similarity(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """(N,) uniform scales, (N, 3, 3) rotations and whether every linear part
    is a rotation times a uniform scale (to 1e-4)."""
    a = m[:, :3, :3].astype(np.float64)
    s = np.cbrt(np.abs(np.linalg.det(a)))
    rot = a / s[:, None, None]
    ok = np.allclose(np.einsum("nji,njk->nik", rot, rot), np.eye(3), atol=1e-4)
    return s, rot, ok


#: Draw a scene's volume instances by instanced draw calls (one per (asset,
#: level) group and depth slab); False: one pass per instance, as first
#: written (kept for comparison; read at each frame).
VOLUME_INSTANCED = True
#: The instances' back-to-front order is cut into this many depth slabs of
#: equal counts, and each slab draws its (asset, level) groups farthest
#: first: calls at most slabs x groups, and instances of different groups
#: composed out of order only inside a slab (read at each frame).
VOLUME_DEPTH_SLABS = 16


def _draw_volume(impl, up: SceneUpload, view: FrameView, fbo, opts) -> DrawStats:
    """Back to front over the visible instances of every asset (one sort), each
    ray-marched inside its screen box in its own frame, blended "over".

    Instanced (:data:`VOLUME_INSTANCED`): the sorted instances of one (asset,
    level) group and depth slab (:data:`VOLUME_DEPTH_SLABS`) go, in that
    order, into one instance buffer and one draw call
    (:meth:`~aniso3d.rendering.volume.VolumeRenderer.draw_instanced`). GL
    draws instances in order, so "over" blending composes correctly between
    instance boxes that do not interpenetrate; overlapping boxes compose as
    wholes (approximate, as with one pass per instance), and so do instances
    of different groups within one slab."""
    t0 = time.perf_counter()
    pixel_error = 1.0 if opts.pixel_error is None else opts.pixel_error
    cone = ViewCone.of(view.camera, view.size, view.near, view.far)
    visible, levels_of, parts = [], [], []
    for i in range(len(up.handles)):
        m = up.scene.transforms[i]
        _, _, ok = _similarity(m) if len(m) else (None, None, True)
        if not ok:
            raise InputError(
                "the volume renderer draws instances moved by rotations, translations and uniform "
                "scales only; this scene has a shear or a non-uniform scale (draw it as mesh or splat)"
            )
        c, r, s = _spheres(up, i)
        vis = np.flatnonzero(visible_instances(c, r, cone))
        lv = instance_levels(c[vis], r[vis], s[vis], up.voxel_sizes[i], cone, pixel_error)
        visible.append(vis)
        levels_of.append(lv)
        parts.append(np.stack([np.full(len(vis), i), vis, lv, *cone.eye_frame(c[vis]).T, r[vis]], axis=1))
    table = np.concatenate(parts) if parts else np.zeros((0, 7))
    table = table[back_to_front(table[:, 3:6] @ cone.axes.T + cone.eye, cone)] if len(table) else table
    lod = _stats(up, visible, levels_of, t0)
    ctx = impl.gl.ctx
    target = fbo if fbo is not None else ctx.fbo
    w, h = view.size
    cam = view.camera
    lighting = view.lighting
    black = replace(lighting, background=(0.0, 0.0, 0.0))
    drawn = 0
    calls = 0
    vopts = replace(opts, pixel_error=None)
    impl.blend_over = True
    target.depth_mask = False
    try:
        # Every drawn instance's camera and lights in its own frame, at once:
        # x_local = R^T (x - t) / s for the eye; directions by R^T alone.
        m = np.zeros((len(table), 4, 4))
        for i in range(len(up.handles)):
            rows = table[:, 0] == i
            m[rows] = up.scene.transforms[i][table[rows, 1].astype(np.int64)]
        scale = np.cbrt(np.abs(np.linalg.det(m[:, :3, :3]))) if len(m) else np.zeros(0)
        rot_t = np.swapaxes(m[:, :3, :3], 1, 2) / scale[:, None, None]  # R^T
        eye = np.einsum("nij,nj->ni", rot_t, np.asarray(cam.position) - m[:, :3, 3]) / scale[:, None]
        axes = np.einsum("nij,jk->nki", rot_t, np.stack(cam.basis(), axis=1))  # (N, 3 axes, 3)
        if VOLUME_INSTANCED:
            calls, drawn = _draw_volume_instanced(impl, up, replace(view, lighting=black), table, scale, eye,
                                                  axes, cone, vopts)  # fmt: skip
        else:
            dirs = lighting.directions()
            local_dirs = np.einsum("nij,lj->nli", rot_t, dirs)
            base = black.uniforms()
            for row in range(len(table)):
                i, _, level, x, y, z, r = table[row]
                box = _screen_box(x, y, z, r, cone, w, h)
                if box is None:
                    continue
                light_dir = list(base["u_light_dir"])
                light_dir[: len(dirs)] = [tuple(map(float, d)) for d in local_dirs[row]]
                local_view = FrameView(
                    _LocalCamera(tuple(map(float, eye[row])), cam.fov, tuple(axes[row])),
                    _LocalLighting({**base, "u_light_dir": light_dir}, black.background),
                    view.size, view.near / scale[row], view.far / scale[row], view.ssaa,
                )  # fmt: skip
                target.scissor = box
                # The pass writes every pixel of the box, the "over" operator by blending.
                stats = impl.draw(up.handles[int(i)].levels[int(level)], local_view, fbo=target, options=vopts)
                drawn += stats.drawn
                calls += 1
    finally:
        impl.blend_over = False
        target.depth_mask = True
        target.scissor = None
        ctx.disable(moderngl.BLEND)
        ctx.blend_func = moderngl.DEFAULT_BLENDING
        ctx.depth_func = "<"
    lod.update(voxels=drawn, draw_calls=calls)
    used = tuple(int(lvl) for lvl, n in enumerate(lod["instances_per_level"]) if n)
    return DrawStats(drawn=drawn, unit="voxels", levels=used, lod=lod)


def _draw_volume_instanced(impl, up: SceneUpload, view: FrameView, table: np.ndarray, scale: np.ndarray,
                           eye: np.ndarray, axes: np.ndarray, cone: ViewCone, opts) -> tuple[int, int]:  # fmt: skip
    """The sorted ``table`` (rows asset, instance, level, eye-frame centre,
    radius) drawn by instanced calls, each instance with the camera ``eye``
    (N, 3) and ``axes`` (N, 3, 3) moved into its frame and its ``scale``
    (N,); returns the number of draw calls and the voxels drawn."""
    from aniso3d.rendering.volume import instance_rays

    w, h = view.size
    boxes = _screen_boxes(table[:, 3:7], cone, w, h)
    keep = np.flatnonzero(boxes[:, 2] > 0)
    if not len(keep):
        return 0, 0
    table, boxes, scale, eye, axes = table[keep], boxes[keep], scale[keep], eye[keep], axes[keep]
    asset, level = table[:, 0].astype(np.int64), table[:, 2].astype(np.int64)
    pairs, group = np.unique(np.stack([asset, level], axis=1), axis=0, return_inverse=True)
    group = group.reshape(-1)
    grids = [up.handles[int(a)].levels[int(lv)] for a, lv in pairs]
    origin = np.stack([g.grid_origin for g in grids])[group]
    size = np.array([g.voxel_size for g in grids])[group]
    shape = np.stack([np.asarray(g.shape, dtype=np.float64) for g in grids])[group]
    rays = instance_rays(origin, size, shape, eye, axes, view.near / scale, view.far / scale)
    ndc = np.stack([boxes[:, 0] / w, boxes[:, 1] / h, (boxes[:, 0] + boxes[:, 2]) / w,
                    (boxes[:, 1] + boxes[:, 3]) / h], axis=1) * 2.0 - 1.0  # fmt: skip
    rows = np.concatenate([ndc, rays], axis=1).astype(np.float32)
    # Calls: (slab, group), each slab's groups by their members' mean rank.
    n = len(rows)
    rank = np.arange(n)
    slab = rank * max(1, int(VOLUME_DEPTH_SLABS)) // n
    keys, call = np.unique(slab * len(pairs) + group, return_inverse=True)
    call = call.reshape(-1)
    mean_rank = np.bincount(call, rank) / np.bincount(call)
    order = np.lexsort((mean_rank, keys // len(pairs)))
    by_call = np.argsort(call, kind="stable")  # the rows of each call, in rank order
    first = np.searchsorted(call[by_call], np.arange(len(keys) + 1))
    ctx = impl.gl.ctx
    ctx.enable(moderngl.DEPTH_TEST | moderngl.BLEND)
    ctx.disable(moderngl.CULL_FACE)
    ctx.depth_func = "1"  # always: the frame composes by blending alone
    ctx.blend_func = moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA
    for k in order:
        sel = by_call[first[k]:first[k + 1]]
        impl.draw_instanced(grids[int(keys[k] % len(pairs))], view, rows[sel], opts)
    voxels = np.array([g.n_voxels for g in grids], dtype=np.int64)
    return len(keys), int(voxels[group].sum())


@dataclass(frozen=True)
class _LocalCamera:
    """The camera seen from an instance's frame, as the volume renderer reads
    a camera (position, fov, ``basis()``), made without a Camera's checks:
    it is the checked frame camera moved by a checked similarity."""

    position: tuple
    fov: float
    axes: tuple  # right, up, forward (unit)

    def basis(self) -> tuple:
        return self.axes

    @property
    def forward(self) -> np.ndarray:
        return self.axes[2]


@dataclass(frozen=True)
class _LocalLighting:
    """The frame's lights turned into an instance's frame, as the volume renderer reads them."""

    values: dict
    background: tuple

    def uniforms(self) -> dict:
        return self.values


def _screen_boxes(spheres: np.ndarray, cone: ViewCone, w: int, h: int) -> np.ndarray:
    """:func:`_screen_box` of (N, 4) spheres (eye-frame centre, radius) at
    once: (N, 4) pixel boxes (x, y, width, height), width 0 where none."""
    x, y, z, r = spheres.T
    out = np.zeros((len(spheres), 4))
    whole = z - r <= max(cone.near, 1e-9)
    tx, ty = cone.sx / cone.cx, cone.sy / cone.cy
    zn = np.where(whole, 1.0, z - r)
    zf = np.where(whole, 1.0, z + r)
    x0 = np.where(x - r < 0, (x - r) / zn, (x - r) / zf) / tx
    x1 = np.where(x + r > 0, (x + r) / zn, (x + r) / zf) / tx
    y0 = np.where(y - r < 0, (y - r) / zn, (y - r) / zf) / ty
    y1 = np.where(y + r > 0, (y + r) / zn, (y + r) / zf) / ty
    with np.errstate(invalid="ignore", over="ignore"):
        px0 = np.maximum(0, np.floor((x0 * 0.5 + 0.5) * w) - 1)
        px1 = np.minimum(w, np.ceil((x1 * 0.5 + 0.5) * w) + 1)
        py0 = np.maximum(0, np.floor((y0 * 0.5 + 0.5) * h) - 1)
        py1 = np.minimum(h, np.ceil((y1 * 0.5 + 0.5) * h) + 1)
    ok = (px1 > px0) & (py1 > py0)
    out[ok] = np.stack([px0, py0, px1 - px0, py1 - py0], axis=1)[ok]
    out[whole] = (0, 0, w, h)
    return out


def _screen_box(x, y, z, r, cone: ViewCone, w: int, h: int) -> tuple[int, int, int, int] | None:
    """Pixels (x, y, width, height) holding a sphere of eye-frame centre (x, y,
    z) and radius r, or the whole viewport when it reaches the eye plane."""
    if z - r <= max(cone.near, 1e-9):
        return (0, 0, w, h)
    tx = cone.sx / cone.cx
    ty = cone.sy / cone.cy
    zn = z - r
    x0 = ((x - r) / zn if x - r < 0 else (x - r) / (z + r)) / tx
    x1 = ((x + r) / zn if x + r > 0 else (x + r) / (z + r)) / tx
    y0 = ((y - r) / zn if y - r < 0 else (y - r) / (z + r)) / ty
    y1 = ((y + r) / zn if y + r > 0 else (y + r) / (z + r)) / ty
    px0 = max(0, math.floor((x0 * 0.5 + 0.5) * w) - 1)
    px1 = min(w, math.ceil((x1 * 0.5 + 0.5) * w) + 1)
    py0 = max(0, math.floor((y0 * 0.5 + 0.5) * h) - 1)
    py1 = min(h, math.ceil((y1 * 0.5 + 0.5) * h) + 1)
    if px1 <= px0 or py1 <= py0:
        return None
    return (px0, py0, px1 - px0, py1 - py0)
