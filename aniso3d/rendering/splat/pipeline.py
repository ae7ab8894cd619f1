"""What every splat pass shares: the programs (one per pass, shape and path),
strict uniform binding, the points' vertex arrays, the frame's uniforms, one
pass over the points (sprites, then the wide splats through the geometry
shader), the full-screen passes and the offscreen targets.

Drawing is perspective-exact: every fragment intersects its pixel's eye ray
with the splat's plane (through the screen-to-plane homography, so a grazing
ray needs no division by the ray-plane cosine), discards what falls outside
the shape, and writes the true depth, so splats foreshorten and occlude like
polygons. Most splats are point sprites (one vertex, the cheapest primitive
a software rasteriser has); splats wider than the largest sprite (255 px on
llvmpipe) go through a geometry shader instead, for the blocks of points
where the CPU finds that possible (:func:`~aniso3d.rendering.splat.culling.large_blocks`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import moderngl
import numpy as np

from aniso3d.errors import ResourceError
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.splat import params
from aniso3d.rendering.splat.buffers import ATTRIBUTES, CLIP_TABLE_PER_ROW, CLIP_TABLE_UNIT, GPULodPoints, GPUPoints
from aniso3d.rendering.splat.culling import depth_range, large_blocks
from aniso3d.rendering.splat.geometry import mask_slicing
from aniso3d.rendering.splat.options import SplatOptions
from aniso3d.rendering.splat.params import (
    AA_FILTER,
    AA_LAYERS,
    AA_PLANE_REACH,
    AA_REGIME,
    AA_SHADE_BOX,
    AA_SLICES,
    filter_radius,
)


@dataclass(eq=False)
class Targets:
    """Offscreen buffers for one framebuffer size, made on first use: the depth
    texture (geometry pass of "fast", visibility pass of "high" and "blend")
    and its framebuffer; the point ids (R32UI, "fast"), the accumulation
    texture ("blend") and, for "high", the occupancy ``mask`` (an R32UI array
    of :data:`~aniso3d.rendering.splat.params.AA_SLICES` / 32 layers), the
    ``nearest`` texture (RGBA32F: each pixel's nearest pushed depth and
    coverage sum) and its framebuffer, the ``surfaces`` texture (RGBA32UI)
    and the ``cover`` texture (RG32F) and their framebuffer, and the ``layers``
    (:data:`~aniso3d.rendering.splat.params.AA_LAYERS` RGBA textures) and
    theirs, each made by its pass."""

    depth: moderngl.Texture
    visibility: moderngl.Framebuffer
    ids: moderngl.Texture | None = None
    geometry: moderngl.Framebuffer | None = None
    accum: moderngl.Texture | None = None
    accumulate: moderngl.Framebuffer | None = None
    mask: moderngl.TextureArray | None = None
    surfaces: moderngl.Texture | None = None
    cover: moderngl.Texture | None = None
    nearest: moderngl.Texture | None = None
    nearest_fbo: moderngl.Framebuffer | None = None
    surfaces_fbo: moderngl.Framebuffer | None = None
    layers: tuple = ()
    layered: moderngl.Framebuffer | None = None

    def framebuffers(self) -> tuple[moderngl.Framebuffer, ...]:
        """The framebuffers made so far."""
        fbos = (self.geometry, self.visibility, self.accumulate, self.nearest_fbo, self.surfaces_fbo, self.layered)
        return tuple(f for f in fbos if f is not None)

    def objects(self) -> tuple:
        return (self.geometry, self.accumulate, self.nearest_fbo, self.surfaces_fbo, self.layered, self.visibility,
                self.ids, self.accum, self.mask, self.nearest, self.surfaces, self.cover, *self.layers,
                self.depth)  # fmt: skip


def reach(opts: SplatOptions) -> float | None:
    """The pixel filter's reach of a coverage-aware pass, None for the others."""
    return filter_radius() if opts.quality == "high" else None


def outside(point, bounds: np.ndarray) -> bool:
    """True if ``point`` lies outside the box ``bounds`` (2, 3) grown by a
    millionth of its diagonal."""
    b = np.asarray(bounds, dtype=np.float64)
    grow = 1e-6 * float(np.linalg.norm(b[1] - b[0]))
    p = np.asarray(point, dtype=np.float64)
    return bool(np.any(p < b[0] - grow) or np.any(p > b[1] + grow))


class SplatPipeline:
    """The shared GPU plumbing of the splat passes (see the module docstring).

    ``max_sprite`` (pixels) is the widest splat drawn as a point sprite; wider
    ones take the geometry-shader path.
    """

    def __init__(self, gl: GLContext):
        self.gl = gl
        info = gl.ctx.info
        self.max_sprite = float(info.get("GL_POINT_SIZE_RANGE", (1.0, 64.0))[1])
        self._targets: dict[tuple[int, int], Targets] = {}
        self._required: dict[int, frozenset[str]] = {}
        self._screen_vaos: dict[int, moderngl.VertexArray] = {}

    # ------------------------------------------------------------ programs

    def program(
        self, kind: str, shape: str, sprite: bool, aa: bool = False, clips: bool = False
    ) -> moderngl.Program:
        """The splat program of a pass (geometry, visibility, accumulate, floor);
        ``aa``: the coverage-aware variant of visibility and accumulate;
        ``clips`` (with ``aa``): for a cut upload, each point's clip planes
        read from its table (:attr:`~aniso3d.rendering.splat.buffers.GPUPoints.cut`)."""
        defines: dict[str, object] = {"ROUND": int(shape != "square")}
        if kind == "floor":
            return self.gl.program("splat.vert", "splat_floor.frag", defines=defines)
        defines["PASS"] = {"geometry": 0, "visibility": 1, "accumulate": 2}[kind]
        if aa:
            defines.update(
                AA=1, LAYERS=AA_LAYERS, SLICES=AA_SLICES, FILTER=AA_FILTER, PLANE_REACH=float(AA_PLANE_REACH),
                LAST_WEIGHTS=int(params.AA_LAST_WEIGHTS), SURFACE_REACH=float(params.AA_SURFACE_REACH),
                SHEET_REACH=int(params.AA_SHEET_REACH), SHEET_GRAZE=float(params.AA_SHEET_GRAZE),
                SIDED_HIDDEN=int(params.AA_PARTNER_HIDES_SIDED),
            )
            if clips:
                defines.update(CLIPS=1, CLIP_TABLE_PER_ROW=CLIP_TABLE_PER_ROW)
        if sprite:
            return self.gl.program("splat.vert", "splat.frag", defines=defines)
        defines["GEOMETRY_PATH"] = 1
        return self.gl.program("splat.vert", "splat.frag", geometry="splat.geom", defines=defines)

    def bind(self, prog: moderngl.Program, values: dict[str, object]) -> None:
        """Set uniforms; every active uniform of ``prog`` must be given (a
        misspelt key leaves a real uniform unset and is caught here)."""
        required = self._required.get(id(prog))
        if required is None:
            required = frozenset(n for n in prog if isinstance(prog[n], moderngl.Uniform))
            self._required[id(prog)] = required
        missing = required - values.keys()
        if missing:
            raise ResourceError(f"splat shader uniforms not set: {sorted(missing)}")
        for name in required:
            prog[name].value = values[name]

    def vao(
        self, handle: GPUPoints, prog: moderngl.Program, indexed: bool = False
    ) -> moderngl.VertexArray:
        """The points' vertex array for ``prog`` (kept on the handle);
        ``indexed``: through the handle's index buffer (a pyramid upload)."""
        cache = handle.indexed_vaos if indexed else handle.vaos
        vao = cache.get(id(prog))
        if vao is None:
            if "in_position" not in prog:
                raise ResourceError("splat vertex shader has no active in_position attribute")
            fmt, names = [], []
            for name, k in ATTRIBUTES:
                if name in prog:  # attributes a variant does not read are skipped
                    fmt.append(f"{k}f")
                    names.append(name)
                else:
                    fmt.append(f"{4 * k}x")
            content = [(handle.vbo, " ".join(fmt), *names)]
            if indexed:
                vao = self.gl.ctx.vertex_array(
                    prog, content, index_buffer=handle.index_buffer, index_element_size=4
                )
            else:
                vao = self.gl.ctx.vertex_array(prog, content)
            vao = cache[id(prog)] = self.gl.track(vao)
        return vao

    def screen(
        self, fragment: str, aa: bool = False, far: bool = False
    ) -> tuple[moderngl.Program, moderngl.VertexArray]:
        """A full-screen pass: one triangle, no vertex buffer (``aa``: a pass
        of quality "high", with its defines; ``far``: the triangle at the far
        plane, for an early depth test)."""
        defines: dict[str, object] = {}
        if aa:
            mean, reach_ = (float(x) for x in params.AA_CLOSE)
            defines = {"LAYERS": AA_LAYERS, "WORDS": AA_SLICES // 32, "CLOSE_MEAN": mean, "CLOSE_REACH": reach_,
                       "CLOSE_MEAN_SIDED": float(params.AA_CLOSE_SIDED), "CLOSE_OWN": float(params.AA_CLOSE_OWN),
                       "CLOSE_SLOPE": int(params.AA_CLOSE_SLOPE),
                       "CHAIN": float(params.AA_SHEET_CHAIN)}  # fmt: skip
        if far:
            defines["FAR"] = 1
        prog = self.gl.program("splat_resolve.vert", fragment, defines=defines)
        vao = self._screen_vaos.get(id(prog))
        if vao is None:
            vao = self._screen_vaos[id(prog)] = self.gl.track(self.gl.ctx.vertex_array(prog, []))
        return prog, vao

    # -------------------------------------------------------------- frames

    def uniforms(
        self, handle: GPUPoints, view: FrameView, opts: SplatOptions, one_sided: bool = True
    ) -> dict[str, object]:
        """Every uniform a pass may need for this frame and upload.
        ``one_sided``: cull one-sided points seen from behind
        (:attr:`~aniso3d.build.points.PointCloud.one_sided`), which holds
        only while the eye is outside the cloud's bounds (inside a closed
        surface its back is what the eye sees)."""
        cam = view.camera
        r, u, f = cam.basis()
        tan = math.tan(math.radians(cam.fov) / 2)
        rot = np.stack([r, u, -f])
        ray = np.stack([f, r * tan * view.aspect, u * tan], axis=1)  # columns f, R, U
        near, far = float(view.near), float(view.far)
        # float64 here, so the shaders never form eye-relative positions (see
        # splat.vert): t0, the view depth of the local origin, and q0, the foot
        # of the origin on the view axis, in the local frame.
        eye = np.asarray(view.eye_local(handle.origin), np.float64)
        t0 = -float(eye @ f)
        q0 = eye + t0 * f
        lo, scale, span = mask_slicing(view, *depth_range(handle, view, opts.extent), handle.typical_size, opts)
        return {
            "u_q0": tuple(float(x) for x in q0),
            "u_t0": t0,
            "u_view_rot": tuple(float(x) for x in rot.T.ravel()),  # column-major
            "u_ray": tuple(float(x) for x in ray.T.ravel()),
            "u_proj_scale": (1.0 / (tan * view.aspect), 1.0 / tan),
            "u_viewport": (float(view.size[0]), float(view.size[1])),
            "u_near": near,
            "u_far": far,
            "u_extent": opts.extent,
            "u_max_sprite": self.max_sprite,
            "u_push": opts.push,
            "u_depth": (far / (far - near), t0 - near),
            "u_srange": (near - t0, far - t0),
            "u_range": far - near,
            "u_size_factor": opts.size_factor,
            "u_regime": tuple(float(x) for x in AA_REGIME),
            "u_slices": (lo, scale),
            "u_span": span,
            "u_background": tuple(float(x) for x in view.lighting.background),
            "u_one_sided": int(one_sided and outside(view.camera.position, handle.bounds)),
            **view.lighting.uniforms(),
        }

    def large_blocks(
        self, handle: GPUPoints, view: FrameView, opts: SplatOptions, limit: float | None = None
    ) -> list[tuple[int, int]]:
        """(first, count) ranges of points that may hold a splat wider than
        ``limit`` pixels (default :attr:`max_sprite`) in this frame."""
        limit = self.max_sprite if limit is None else limit
        return large_blocks(handle, view, opts.extent, limit, reach(opts))

    def splats(
        self, handle: GPUPoints, view: FrameView, opts: SplatOptions, kind: str, uniforms: dict
    ) -> None:
        """One pass over the points: sprites, then the wide splats' quads. A
        pyramid upload draws this frame's selection (``handle.drawn``).
        Quality "high" draws the points with clip planes apart, from their own
        upload (:attr:`~aniso3d.rendering.splat.buffers.GPUPoints.cut`), with
        the program that reads and cuts by them; the others' program has no
        clipping code (llvmpipe runs it for every point it is in)."""
        aa = opts.quality == "high"
        limit = self.max_sprite
        if aa and kind == "accumulate":
            # Quality "high" shades per pixel only splats of boxes wider than
            # AA_SHADE_BOX, in the geometry path (llvmpipe pays for shading
            # code in a shader even where no pixel runs it), so those go there.
            limit = min(limit, AA_SHADE_BOX)
        uniforms = {**uniforms, "u_max_sprite": limit, "u_shade_box": AA_SHADE_BOX}
        self._draw(handle, view, opts, kind, uniforms, limit, aa, clips=False)
        if aa and handle.cut is not None:
            handle.cut.clip_table.use(location=CLIP_TABLE_UNIT)
            self._draw(handle.cut, view, opts, kind, {**uniforms, "u_clip_table": CLIP_TABLE_UNIT}, limit, aa,
                       clips=True)  # fmt: skip

    def _draw(
        self, handle: GPUPoints, view: FrameView, opts: SplatOptions, kind: str, uniforms: dict, limit: float,
        aa: bool, clips: bool,
    ) -> None:  # fmt: skip
        """:meth:`splats` of one upload, sprites up to ``limit`` pixels."""
        indexed = isinstance(handle, GPULodPoints)
        if indexed and not len(handle.drawn):
            return
        prog = self.program(kind, opts.splat, sprite=True, aa=aa, clips=clips)
        self.bind(prog, uniforms)
        if indexed:
            self.vao(handle, prog, True).render(moderngl.POINTS, vertices=len(handle.drawn))
        else:
            self.vao(handle, prog).render(moderngl.POINTS)
        ranges = self.large_blocks(handle, view, opts, limit)
        if indexed and ranges:
            # Buffer ranges -> ranges of the (ascending) drawn indices.
            lo = np.searchsorted(handle.drawn, [f for f, _ in ranges])
            hi = np.searchsorted(handle.drawn, [f + c for f, c in ranges])
            ranges = [(int(a), int(b - a)) for a, b in zip(lo, hi, strict=True) if b > a]
        if ranges:
            prog = self.program(kind, opts.splat, sprite=False, aa=aa, clips=clips)
            self.bind(prog, uniforms)
            vao = self.vao(handle, prog, indexed)
            for first, count in ranges:
                vao.render(moderngl.POINTS, vertices=count, first=first)

    def resolve(
        self, fragment: str, textures: dict[str, moderngl.Texture], uniforms: dict, target,
        viewport, aa: bool = False,
    ) -> tuple[moderngl.Program, moderngl.VertexArray]:  # fmt: skip
        """Set up the closing full-screen pass into ``target``: bound, its
        viewport restored, depth test ``<=`` (pushed depths may sit at the far
        plane), ``textures`` on units 0, 1, ... and named so in ``uniforms``.
        Returns the pass's program and vertex array."""
        ctx = self.gl.ctx
        target.use()
        ctx.viewport = viewport
        ctx.depth_func = "<="
        for unit, (name, tex) in enumerate(textures.items()):
            tex.use(location=unit)
            uniforms[name] = unit
        return self.screen(fragment, aa)

    # ------------------------------------------------------------- targets

    def targets(self, size: tuple[int, int]) -> Targets:
        """The offscreen targets of ``size`` (depth and visibility made here,
        the rest by the passes that need them)."""
        tg = self._targets.get(size)
        if tg is None:
            ctx, track = self.gl.ctx, self.gl.track
            depth = track(ctx.depth_texture(size))
            depth.compare_func = ""  # read as plain values, not as a shadow sampler
            depth.filter = moderngl.NEAREST, moderngl.NEAREST
            vis = track(ctx.framebuffer(depth_attachment=depth))
            tg = self._targets[size] = Targets(depth, vis)
        return tg

    def release_all(self) -> None:
        """Free the offscreen buffers and full-screen pass objects."""
        for tg in self._targets.values():
            self.gl.free(*tg.objects())
        self._targets.clear()
        self.gl.free(*self._screen_vaos.values())
        self._screen_vaos.clear()
