""":class:`SplatRenderer`: uploads points once and draws them with one of the
three qualities (:mod:`~aniso3d.rendering.splat.fast`,
:mod:`~aniso3d.rendering.splat.coverage`), from all points or, for a pyramid
upload, from this frame's level-of-detail selection."""

from __future__ import annotations

import moderngl

from aniso3d.build.points import PointCloud
from aniso3d.build.pyramid import LodPoints
from aniso3d.errors import InputError
from aniso3d.rendering.base import option_parser
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.frame import DrawStats, FrameView
from aniso3d.rendering.splat import buffers, culling
from aniso3d.rendering.splat.buffers import GPULodPoints, GPUPoints
from aniso3d.rendering.splat.coverage import BlendPass, HighPass
from aniso3d.rendering.splat.fast import FastPass
from aniso3d.rendering.splat.options import SplatOptions
from aniso3d.rendering.splat.pipeline import SplatPipeline, reach


class SplatRenderer:
    """Draws a :class:`~aniso3d.build.points.PointCloud` (or every level of a
    :class:`~aniso3d.build.pyramid.LodPoints`) as perspective-exact splats.

    ``quality="fast"``: one geometry pass writes each pixel's nearest splat
    (exact depth, point id), then one full-screen pass shades it with
    ``shade()``. ``quality="high"``: coverage-aware, visibility, accumulation
    into depth layers, compositing. ``quality="blend"``: visibility,
    accumulation, normalisation.

    ``max_sprite`` (pixels) is the widest splat drawn as a point sprite; wider
    ones take the geometry-shader path. It defaults to the context's largest
    point size; set it to 0 to send every splat through the geometry path.
    """

    method = "splat"
    Options = SplatOptions
    options = option_parser(SplatOptions)

    def __init__(self, gl: GLContext):
        self.gl = gl
        self.pipe = SplatPipeline(gl)
        self._passes = {p.quality: p for p in (FastPass(self.pipe), HighPass(self.pipe), BlendPass(self.pipe))}
        #: The last pyramid frame's selection statistics (see :meth:`select`).
        self.last_lod_stats: dict | None = None
        # Compile the default variant now so shader errors surface at once.
        self.pipe.program("geometry", "square", sprite=True)

    @property
    def max_sprite(self) -> float:
        return self.pipe.max_sprite

    @max_sprite.setter
    def max_sprite(self, value: float) -> None:
        self.pipe.max_sprite = float(value)

    # -------------------------------------------------------------- upload

    def upload(self, cloud: PointCloud | LodPoints) -> GPUPoints:
        """Upload ``cloud`` once (:func:`~aniso3d.rendering.splat.buffers.upload_points`);
        a :class:`~aniso3d.build.pyramid.LodPoints` uploads every level of its
        pyramid (:class:`GPULodPoints`), and :meth:`draw` then selects per frame."""
        return buffers.upload_points(self.gl, cloud)

    def select(self, handle: GPULodPoints, view: FrameView, pixel_error: float = 1.0) -> dict:
        """This frame's points of a pyramid upload
        (:func:`~aniso3d.rendering.splat.buffers.select`); the statistics are
        also kept as :attr:`last_lod_stats`."""
        stats = buffers.select(handle, view, pixel_error)
        self.last_lod_stats = stats
        return stats

    def release(self, handle: GPUPoints) -> None:
        buffers.release_points(self.gl, handle)

    def release_all(self) -> None:
        """Free the offscreen buffers and full-screen pass objects."""
        self.pipe.release_all()

    # -------------------------------------------------------------- frames

    def large_blocks(
        self, handle: GPUPoints, view: FrameView, opts: SplatOptions, limit: float | None = None
    ) -> list[tuple[int, int]]:
        """(first, count) ranges of points that may hold a splat wider than
        ``limit`` pixels (default :attr:`max_sprite`) in this frame
        (:func:`~aniso3d.rendering.splat.culling.large_blocks`)."""
        return self.pipe.large_blocks(handle, view, opts, limit)

    def screen_box(
        self, handle: GPUPoints, view: FrameView, opts: SplatOptions
    ) -> tuple[int, int, int, int] | None:
        """The pixels holding every splat (:func:`~aniso3d.rendering.splat.culling.screen_box`)."""
        return culling.screen_box(handle, view, opts.extent, reach(opts))

    def draw(
        self, handle: GPUPoints, view: FrameView, fbo=None, options: SplatOptions | None = None,
        *, cleared: bool = False, **values,
    ) -> DrawStats:  # fmt: skip
        """Draw into ``fbo`` (bound, cleared to the background with alpha 0,
        viewport covering it); writes colour, alpha 1 where a splat landed
        (coverage) and depth. With ``quality="high"`` alpha is the covered
        fraction, and the cloud is composited with what ``fbo`` holds
        (over it where nearer, under it where farther); ``cleared=True``
        says ``fbo`` holds nothing drawn yet (depth 1 everywhere), which
        spares "high" the passes that put the cloud under nearer pixels.

        Options: ``options`` (:class:`SplatOptions`) or the same as keywords.
        A pyramid upload (:class:`GPULodPoints`) first selects this frame's
        points (:meth:`select`) with the screen-space error ``pixel_error``
        (framebuffer pixels, default 1), then draws only those."""
        opts = SplatOptions.resolve(options, values)
        lod = None
        if isinstance(handle, GPULodPoints):
            lod = self.select(handle, view, 1.0 if opts.pixel_error is None else opts.pixel_error)
        elif opts.pixel_error is not None:
            raise InputError(
                "pixel_error applies to a level-of-detail upload only (upload a LodPoints)"
            )
        ctx = self.gl.ctx
        target = fbo if fbo is not None else ctx.fbo
        viewport = ctx.viewport
        uniforms = self.pipe.uniforms(handle, view, opts)
        quality = self._passes[opts.quality]
        tg = quality.targets(view.size)
        box = self.screen_box(handle, view, opts)
        for buf in (*tg.framebuffers(), target):
            buf.scissor = box
        ctx.enable(moderngl.DEPTH_TEST | moderngl.PROGRAM_POINT_SIZE)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        ctx.depth_func = "<"
        try:
            quality.draw(handle, view, opts, uniforms, tg, target, viewport, cleared)
        finally:
            target.depth_mask = True
            target.scissor = None
            ctx.blend_equation = moderngl.FUNC_ADD
            ctx.depth_func = "<"
            ctx.blend_func = moderngl.DEFAULT_BLENDING
            ctx.disable(moderngl.BLEND)
            ctx.enable(moderngl.DEPTH_TEST)
            if ctx.fbo is not target:
                target.use()
                ctx.viewport = viewport
        if lod is None:
            return DrawStats(drawn=int(handle.n_points), unit="points")
        levels = tuple(lvl for lvl, n in enumerate(lod["points_per_level"]) if n)
        return DrawStats(drawn=int(lod["points"]), unit="points", levels=levels, lod=lod)

    def draw_floor(
        self, handle: GPUPoints, view: FrameView, fbo=None, options: SplatOptions | None = None,
        **values,
    ) -> None:  # fmt: skip
        """The benchmark floor: the same points as plain GL_POINTS covering the
        same on-screen boxes as the splats' sprites, straight into ``fbo``,
        with a flat-colour shader (no intersection, discard, lighting, depth
        writes from the fragment stage or second pass). Splats wider than
        :attr:`max_sprite` are not drawn. Not for pyramid uploads."""
        if isinstance(handle, GPULodPoints):
            raise InputError("the benchmark floor draws a plain point cloud, not a pyramid upload")
        opts = SplatOptions.resolve(options, values)
        ctx = self.gl.ctx
        ctx.enable(moderngl.DEPTH_TEST | moderngl.PROGRAM_POINT_SIZE)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        ctx.depth_func = "<"
        prog = self.pipe.program("floor", opts.splat, sprite=True)
        self.pipe.bind(prog, self.pipe.uniforms(handle, view, opts))
        self.pipe.vao(handle, prog).render(moderngl.POINTS)
