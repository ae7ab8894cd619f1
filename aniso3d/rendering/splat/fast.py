"""``quality="fast"``: opaque splats, each pixel shaded once.

Two passes: the splats write each pixel's nearest point id and exact depth
(the geometry pass), then a full-screen pass (``splat_deferred.frag``) shades
each pixel's visible splat once with ``shade()`` (view vector along the
pixel's ray, i.e. from the intersection point to the eye). That is the colour
forward shading would give, without shading the hidden layers of a dense
cloud, which is most of the work on a software rasteriser. The pixel holding
a splat's projected centre is always drawn, so a splat smaller than a pixel
(or seen edge-on) never vanishes; a point of zero area draws nothing.
"""

from __future__ import annotations

import moderngl

from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.splat.buffers import ATTRIB_PER_ROW, GPUPoints
from aniso3d.rendering.splat.options import SplatOptions
from aniso3d.rendering.splat.pipeline import SplatPipeline, Targets


class FastPass:
    """The geometry pass and the deferred shading pass."""

    quality = "fast"

    def __init__(self, pipe: SplatPipeline):
        self.pipe = pipe

    def targets(self, size: tuple[int, int]) -> Targets:
        """The shared targets plus the point-id texture and its framebuffer."""
        tg = self.pipe.targets(size)
        if tg.ids is None:
            ctx, track = self.pipe.gl.ctx, self.pipe.gl.track
            tg.ids = track(ctx.texture(size, 1, dtype="u4"))
            tg.ids.filter = moderngl.NEAREST, moderngl.NEAREST
            tg.geometry = track(
                ctx.framebuffer(color_attachments=[tg.ids], depth_attachment=tg.depth)
            )
        return tg

    def draw(
        self, handle: GPUPoints, view: FrameView, opts: SplatOptions, uniforms: dict, tg: Targets,
        target, viewport, cleared: bool = False,
    ) -> None:  # fmt: skip
        """Both passes, the second into ``target`` with ``viewport``
        (``cleared`` changes nothing here)."""
        pipe = self.pipe
        tg.visibility.use()  # depth only: the id target needs no clearing
        tg.visibility.clear(depth=1.0)
        tg.geometry.use()
        pipe.splats(handle, view, opts, "geometry", uniforms)
        uniforms["u_per_row"] = ATTRIB_PER_ROW
        textures = {"u_ids": tg.ids, "u_geodepth": tg.depth, "u_attrib": handle.attrib}
        prog, vao = pipe.resolve("splat_deferred.frag", textures, uniforms, target, viewport)
        pipe.bind(prog, uniforms)
        vao.render(moderngl.TRIANGLES, vertices=3)
