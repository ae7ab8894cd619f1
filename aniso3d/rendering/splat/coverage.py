"""The blended qualities: ``quality="high"`` (coverage-aware) and
``quality="blend"``, their shared visibility and accumulation passes, and
their resolves.

``quality="high"`` is coverage-aware (anti-aliased), for accuracy at every
distance and above all where a voxel covers a pixel or less. A splat adds
the fraction ``c`` of each pixel it covers: its shape convolved with the
pixel's box filter (the ground truth's) and sampled at the pixel centre. A
splat well below a pixel is drawn as a filtered box of its *true* projected
area (``sqrt(area)`` a side, no size factor), so the coverages it leaves in
the pixels sum to exactly that area wherever it lies: no splat takes a whole
pixel, as in "fast", and none vanishes. A resolved splat (a few pixels and
more) is its exact perspective shape with the size factor, each pair of
edges filtered across its distance in pixels; between the two regimes
(:data:`~aniso3d.rendering.splat.params.AA_REGIME`) the two blend.

Compositing: each pixel's fragments are grouped into surfaces by depth, and
surfaces composite as independent layers; the rule is stated, and computed
the slow way, in :mod:`~aniso3d.rendering.splat.reference`. Four passes:
visibility (each pixel's nearest pushed depth, and the depth slice of every
fragment set in the pixel's occupancy mask by an atomic OR); surfaces (a
full-screen pass: where the pixel's surfaces start, from the mask, which it
clears); accumulation of ``(colour c, c)`` into the layer of the fragment's
surface (:data:`~aniso3d.rendering.splat.params.AA_LAYERS` layers, the last
holding every surface from there on); and compositing front to back: within
a surface coverages add (its splats tile it), across surfaces they compose
as ``1 - prod(1 - a)``, so an opaque surface hides what lies behind it.
Sub-pixel splats are shaded once at their centre, resolved ones per pixel in
the first layer. The result is composited over what the target holds, or
under it where that is nearer, so separately drawn clouds combine in either
order. Measured against 8 x 8 supersampled polygons: docs/splat_aa.md.

``quality="blend"`` (the earlier "high") is the classic three passes:
visibility (splats pushed back by ``push`` times their size), additive
accumulation of shaded colour times a Gaussian weight, and weight, into a
float texture (fragments behind the visibility depth are rejected before
shading), and normalisation. It blends overlapping splats of one surface
into a continuous one; coverage is on or off per pixel, as in "fast" (the
pixel holding a splat's projected centre is always drawn).
"""

from __future__ import annotations

import moderngl
import numpy as np

from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.splat.buffers import GPUPoints
from aniso3d.rendering.splat.options import SplatOptions
from aniso3d.rendering.splat.params import AA_DTYPE, AA_LAYERS, AA_SLICES, ACCUM_DTYPE
from aniso3d.rendering.splat.pipeline import SplatPipeline, Targets

#: Image unit the occupancy mask of quality "high" is bound to (visibility and
#: surfaces passes), and the surfaces texture (accumulation pass). Both stay 0,
#: the image uniforms' default: setting an image uniform to another unit through
#: moderngl did not take on llvmpipe (the loads read zeros). The accumulation
#: pass's second image, the coverage sums, names its unit in the shader
#: (``layout(binding = 1)``).
MASK_UNIT = 0
SURFACES_UNIT = 0
COVER_UNIT = 1


def visible_then_accumulate(
    pipe: SplatPipeline, handle: GPUPoints, view: FrameView, opts: SplatOptions, uniforms: dict,
    tg: Targets, into: moderngl.Framebuffer,
) -> None:  # fmt: skip
    """The blended qualities' first two passes: each pixel's nearest
    (pushed-back) depth into ``tg.visibility``, then additive accumulation
    into ``into``, where splat.frag tests each fragment against that depth
    itself."""
    ctx = pipe.gl.ctx
    tg.visibility.use()
    tg.visibility.clear(depth=1.0)
    pipe.splats(handle, view, opts, "visibility", uniforms)
    into.use()
    into.clear(0.0, 0.0, 0.0, 0.0)
    ctx.disable(moderngl.DEPTH_TEST)
    ctx.enable(moderngl.BLEND)
    ctx.blend_equation = moderngl.FUNC_ADD
    ctx.blend_func = moderngl.ONE, moderngl.ONE
    tg.depth.use(location=0)
    uniforms["u_visible"] = 0
    pipe.splats(handle, view, opts, "accumulate", uniforms)
    ctx.disable(moderngl.BLEND)
    ctx.enable(moderngl.DEPTH_TEST)


class BlendPass:
    """Visibility, weighted accumulation, normalisation (``splat_resolve.frag``)."""

    quality = "blend"

    def __init__(self, pipe: SplatPipeline):
        self.pipe = pipe

    def targets(self, size: tuple[int, int]) -> Targets:
        """The shared targets plus the accumulation texture and its framebuffer."""
        tg = self.pipe.targets(size)
        if tg.accum is None:
            ctx, track = self.pipe.gl.ctx, self.pipe.gl.track
            tg.accum = track(ctx.texture(size, 4, dtype=ACCUM_DTYPE))
            tg.accum.filter = moderngl.NEAREST, moderngl.NEAREST
            tg.accumulate = track(ctx.framebuffer(color_attachments=[tg.accum]))
        return tg

    def draw(
        self, handle: GPUPoints, view: FrameView, opts: SplatOptions, uniforms: dict, tg: Targets,
        target, viewport, cleared: bool = False,
    ) -> None:  # fmt: skip
        """The three passes, the last into ``target`` with ``viewport``
        (``cleared`` changes nothing here)."""
        pipe = self.pipe
        visible_then_accumulate(pipe, handle, view, opts, uniforms, tg, tg.accumulate)
        textures = {"u_accum": tg.accum, "u_visible": tg.depth}
        prog, vao = pipe.resolve("splat_resolve.frag", textures, uniforms, target, viewport)
        pipe.bind(prog, uniforms)
        vao.render(moderngl.TRIANGLES, vertices=3)


class HighPass:
    """Visibility with the occupancy mask, the surfaces pass
    (``splat_surfaces.frag``), accumulation into layers, compositing
    (``splat_aa_resolve.frag``)."""

    quality = "high"

    def __init__(self, pipe: SplatPipeline):
        self.pipe = pipe

    def targets(self, size: tuple[int, int]) -> Targets:
        """The shared targets plus the mask, the surfaces and the layers."""
        tg = self.pipe.targets(size)
        words = AA_SLICES // 32
        if tg.mask is None or tg.mask.layers != words or len(tg.layers) != AA_LAYERS:
            gl = self.pipe.gl
            gl.free(tg.layered, tg.surfaces_fbo, tg.nearest_fbo, tg.mask, tg.nearest, tg.surfaces, tg.cover,
                    *tg.layers)  # fmt: skip
            # Cleared here; then the surfaces pass clears what each draw set.
            zeros = np.zeros(size[0] * size[1] * words, "u4")
            tg.mask = gl.track(gl.ctx.texture_array((*size, words), 1, zeros, dtype="u4"))
            tg.nearest = gl.track(gl.ctx.texture(size, 4, dtype="f4"))
            tg.surfaces = gl.track(gl.ctx.texture(size, 4, dtype="u4"))
            tg.cover = gl.track(gl.ctx.texture(size, 2, dtype="f4"))
            tg.layers = tuple(gl.track(gl.ctx.texture(size, 4, dtype=AA_DTYPE)) for _ in range(AA_LAYERS))
            for tex in (tg.mask, tg.nearest, tg.surfaces, tg.cover, *tg.layers):
                tex.filter = moderngl.NEAREST, moderngl.NEAREST
            tg.nearest_fbo = gl.track(gl.ctx.framebuffer(color_attachments=[tg.nearest]))
            tg.surfaces_fbo = gl.track(gl.ctx.framebuffer(color_attachments=[tg.surfaces, tg.cover]))
            tg.layered = gl.track(gl.ctx.framebuffer(color_attachments=list(tg.layers)))
        return tg

    def draw(
        self, handle: GPUPoints, view: FrameView, opts: SplatOptions, uniforms: dict, tg: Targets,
        target, viewport, cleared: bool = False,
    ) -> None:  # fmt: skip
        """The four passes, the last composited onto ``target`` with ``viewport``
        (``cleared``: see :meth:`composite`)."""
        pipe = self.pipe
        ctx = pipe.gl.ctx
        # Visibility: the pushed nearest depth and the least depth the
        # fragments' surfaces reach (MIN blends), the coverage sum (an
        # additive one; blending costs llvmpipe far less than an image atomic
        # per fragment) and the occupancy mask.
        tg.nearest_fbo.use()
        tg.nearest_fbo.clear(1.0, 1.0, 1.0, 0.0)
        ctx.disable(moderngl.DEPTH_TEST)
        ctx.enable(moderngl.BLEND)
        ctx.blend_equation = (moderngl.MIN, moderngl.FUNC_ADD)
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        tg.mask.bind_to_image(MASK_UNIT, read=True, write=True)
        try:
            pipe.splats(handle, view, opts, "visibility", {**uniforms, "u_mask": MASK_UNIT})
            ctx.disable(moderngl.BLEND)
            ctx.blend_equation = moderngl.FUNC_ADD
            ctx.memory_barrier(moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT)
            # Surfaces: where each pixel's surfaces start; clears the mask.
            tg.surfaces_fbo.use()
            tg.nearest.use(location=0)
            prog, vao = pipe.screen("splat_surfaces.frag", aa=True)
            pipe.bind(prog, {"u_mask": MASK_UNIT, "u_span": uniforms["u_span"], "u_slices": uniforms["u_slices"],
                             "u_visible": 0})  # fmt: skip
            vao.render(moderngl.TRIANGLES, vertices=3)
        except Exception:
            tg.mask.write(np.zeros(tg.mask.width * tg.mask.height * tg.mask.layers, "u4"))  # no stale bits
            raise
        finally:
            ctx.disable(moderngl.BLEND)
            ctx.blend_equation = moderngl.FUNC_ADD
        ctx.memory_barrier(moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT)
        # Accumulation into the layers.
        tg.layered.use()
        tg.layered.clear(0.0, 0.0, 0.0, 0.0)
        ctx.enable(moderngl.BLEND)
        ctx.blend_equation = moderngl.FUNC_ADD
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        tg.surfaces.bind_to_image(SURFACES_UNIT, read=True, write=False)
        tg.cover.bind_to_image(COVER_UNIT, read=True, write=False)
        pipe.splats(handle, view, opts, "accumulate", {**uniforms, "u_surfaces": SURFACES_UNIT, "u_cover": COVER_UNIT})
        ctx.disable(moderngl.BLEND)
        ctx.enable(moderngl.DEPTH_TEST)
        textures = {"u_visible": tg.nearest, "u_surfaces": tg.surfaces, "u_cover": tg.cover}
        for i, tex in enumerate(tg.layers):
            textures[f"u_layer[{i}]"] = tex
        prog, vao = pipe.resolve("splat_aa_resolve.frag", textures, uniforms, target, viewport, aa=True)
        units = [uniforms.pop(f"u_layer[{i}]") for i in range(len(tg.layers))]
        uniforms["u_layer"] = units if len(units) > 1 else units[0]
        self.composite(prog, vao, uniforms, target, cleared)

    def composite(self, prog, vao, uniforms: dict, target, cleared: bool = False) -> None:
        """The layers composited onto ``target`` (bound), which may hold
        earlier draws: over them where this cloud's visible layer is nearer
        (or nothing is there), and under them where it is farther, so that
        separately drawn clouds combine like one (up to rounding) in either
        order. The target's colour already holds its background, so "under"
        adds (1 - alpha) (this colour - background): the positive part, then
        the negative part by reverse subtraction. ``cleared``: the caller
        has just cleared ``target`` (depth 1 everywhere), so nothing can lie
        in front of the cloud and the two "under" passes, each as costly as
        the first (their depth test runs after the shader), are skipped."""
        ctx = self.pipe.gl.ctx
        bind = self.pipe.bind
        ctx.enable(moderngl.BLEND)
        ctx.blend_equation = moderngl.FUNC_ADD
        ctx.blend_func = moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA
        bind(prog, {**uniforms, "u_mode": 0})
        vao.render(moderngl.TRIANGLES, vertices=3)
        if cleared:
            return
        ctx.depth_func = ">"
        target.depth_mask = False
        ctx.blend_func = (moderngl.ONE_MINUS_DST_ALPHA, moderngl.ONE, moderngl.ZERO, moderngl.ONE)
        bind(prog, {**uniforms, "u_mode": 1})
        vao.render(moderngl.TRIANGLES, vertices=3)
        ctx.blend_equation = (moderngl.FUNC_REVERSE_SUBTRACT, moderngl.FUNC_ADD)
        ctx.blend_func = (moderngl.ONE_MINUS_DST_ALPHA, moderngl.ONE) * 2
        bind(prog, {**uniforms, "u_mode": 2})
        vao.render(moderngl.TRIANGLES, vertices=3)
