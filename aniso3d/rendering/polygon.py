"""Renderer (a): the polygon model itself, per-face Phong, the ground truth.

Supersampling is the frame's business (:class:`~aniso3d.rendering.renderer.Renderer`
draws at ``ssaa`` times the size and box-filters); this module only draws.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import moderngl
import numpy as np

from aniso3d.build.mesh import Mesh
from aniso3d.errors import InputError
from aniso3d.rendering.base import DrawOptions, option_parser
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.frame import DrawStats, FrameView


@dataclass(frozen=True)
class MeshOptions(DrawOptions):
    """The polygon renderer has no draw options of its own: the ground truth
    is the mesh as it is. Its one quality setting, supersampling, is the
    frame's (``Renderer.render(..., ssaa=)``), as for every method."""

    what: ClassVar[str] = "mesh"


@dataclass(eq=False)
class GPUMesh:
    """A mesh uploaded once: unshared vertices relative to ``origin``."""

    vao: moderngl.VertexArray
    vbo: moderngl.Buffer
    origin: np.ndarray
    bounds: np.ndarray
    n_faces: int
    nbytes: int


class MeshRenderer:
    """Draws a :class:`~aniso3d.build.mesh.Mesh` with flat face normals and two-sided Phong."""

    method = "mesh"
    Options = MeshOptions
    options = option_parser(MeshOptions)

    def __init__(self, gl: GLContext):
        self.gl = gl
        self.prog = gl.program("mesh.vert", "mesh.frag")

    def upload(self, mesh: Mesh) -> GPUMesh:
        """Upload ``mesh`` once: unshared vertices, float64 minus the mesh's
        centre, then float32, with per-face normals and materials."""
        if not isinstance(mesh, Mesh):
            raise InputError(f"the polygon renderer draws a Mesh, got {type(mesh).__name__}")
        bounds = mesh.bounds
        origin = 0.5 * (bounds[0] + bounds[1])
        tri = mesh.triangles - origin  # float64 subtraction, then float32
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        length = np.linalg.norm(cross, axis=1, keepdims=True)
        normal = np.where(length > 0, cross / np.where(length > 0, length, 1), 0.0)
        n = mesh.n_faces
        data = np.empty((n, 3, 11), dtype=np.float32)
        data[:, :, 0:3] = tri
        data[:, :, 3:6] = normal[:, None]
        data[:, :, 6:9] = mesh.kd[:, None]
        data[:, :, 9] = mesh.ks[:, None]
        data[:, :, 10] = mesh.shininess[:, None]
        vbo = self.gl.track(self.gl.ctx.buffer(data.tobytes()))
        vao = self.gl.track(
            self.gl.ctx.vertex_array(
                self.prog, [(vbo, "3f 3f 3f 2f", "in_position", "in_normal", "in_kd", "in_spec")]
            )
        )
        return GPUMesh(vao, vbo, origin, bounds, n, data.nbytes)

    def draw(
        self, handle: GPUMesh, view: FrameView, fbo=None, options: MeshOptions | None = None, **values
    ) -> DrawStats:
        """Draw into the bound framebuffer (``fbo``; depth tested)."""
        MeshOptions.resolve(options, values)
        ctx = self.gl.ctx
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        GLContext.set_uniforms(
            self.prog,
            {
                "u_mvp": view.mvp(handle.origin),
                "u_eye": view.eye_local(handle.origin),
                **view.lighting.uniforms(),
            },
            strict=False,
        )
        handle.vao.render(moderngl.TRIANGLES)
        return DrawStats(drawn=int(handle.n_faces), unit="triangles")

    def draw_instances(
        self, handle: GPUMesh, view: FrameView, instances: moderngl.Buffer, count: int,
        origin=(0.0, 0.0, 0.0),
    ) -> DrawStats:  # fmt: skip
        """Draw ``count`` instances of ``handle`` in one instanced call: per
        instance a mat4 and an RGBA8 tint (:func:`~aniso3d.rendering.instances.instance_data`,
        relative to ``origin``) read from the buffer ``instances``."""
        prog = self.gl.program("mesh.vert", "mesh.frag", defines={"INSTANCED": 1})
        vao = self.gl.ctx.vertex_array(
            prog,
            [(handle.vbo, "3f 3f 3f 2f", "in_position", "in_normal", "in_kd", "in_spec"),
             (instances, "16f 4f1/i", "in_instance", "in_tint")],
        )  # fmt: skip
        try:
            ctx = self.gl.ctx
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
            GLContext.set_uniforms(
                prog, {"u_mvp": view.mvp(origin), "u_eye": view.eye_local(origin), **view.lighting.uniforms()},
                strict=False,
            )
            vao.render(moderngl.TRIANGLES, instances=int(count))
        finally:
            vao.release()
        return DrawStats(drawn=int(handle.n_faces) * int(count), unit="triangles")

    def release(self, handle: GPUMesh) -> None:
        self.gl.free(handle.vao, handle.vbo)

    def release_all(self) -> None:
        """Nothing of its own to free: the program is cached by the context."""
