"""One frame: what every renderer needs to draw it (:class:`FrameView`: camera,
lights, target size and clip range, with the matrices built in float64 per
uploaded object), and what comes out (:class:`Frame`: colour, depth and
:class:`DrawStats`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from aniso3d.rendering.camera import Camera
from aniso3d.rendering.lighting import Lighting


@dataclass(frozen=True)
class FrameView:
    """One frame's viewing state.

    Attributes:
        camera: the camera.
        lighting: lights, ambient, background.
        size: (width, height) of the framebuffer being drawn, pixels (already
            multiplied by the supersampling factor).
        near, far: clip distances, world units.
        ssaa: supersampling factor the frame is drawn with (renderers that size
            things in pixels use it).
    """

    camera: Camera
    lighting: Lighting
    size: tuple[int, int]
    near: float
    far: float
    ssaa: int = 1

    @property
    def aspect(self) -> float:
        return self.size[0] / self.size[1]

    def projection(self) -> np.ndarray:
        return self.camera.projection_matrix(self.aspect, self.near, self.far)

    def view(self, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        return self.camera.view_matrix(origin)

    def mvp(self, origin=(0.0, 0.0, 0.0)) -> tuple[float, ...]:
        """Column-major float tuple of clip <- local for geometry stored
        relative to ``origin`` (a moderngl mat4 uniform value)."""
        return _mat(self.projection() @ self.view(origin))

    def eye_local(self, origin=(0.0, 0.0, 0.0)) -> tuple[float, float, float]:
        """Eye position in the local frame of geometry stored relative to ``origin``."""
        return tuple(float(x) for x in np.subtract(self.camera.position, origin))

    def pixels_per_unit_at(self, distance: float) -> float:
        """Framebuffer pixels spanned by one world unit at ``distance`` along
        the view axis."""
        return self.size[1] / (2.0 * distance * np.tan(np.radians(self.camera.fov) / 2))


@dataclass(frozen=True)
class DrawStats:
    """What a renderer drew in one frame.

    Attributes:
        drawn: primitives sent to the GPU: triangles (polygons), points
            (splats; a level-of-detail frame's selection) or voxels (volume: those
            of the texture, or of the pyramid level, ray-marched).
        unit: "triangles", "points" or "voxels".
        levels: pyramid levels drawn from, finest = 0 (level-of-detail
            uploads: the splats' levels with points selected, the volume's one
            level); () otherwise.
        lod: the level-of-detail selection's statistics (see
            :meth:`SplatRenderer.select <aniso3d.rendering.splat.SplatRenderer.select>`
            and :func:`~aniso3d.rendering.select.volume_level`), None otherwise.
    """

    drawn: int
    unit: str
    levels: tuple[int, ...] = ()
    lod: dict | None = field(default=None, compare=False)


@dataclass(frozen=True, eq=False)
class Frame:
    """One drawn frame (:meth:`Renderer.render_frame <aniso3d.rendering.renderer.Renderer.render_frame>`).

    Attributes:
        color: (H, W, 3 or 4) uint8, row 0 at the top: what ``Renderer.render``
            returns for the same arguments.
        depth: (H, W) float32, row 0 at the top: distance along the view axis
            (world units) from the eye to what the renderer wrote in the
            pixel's depth buffer (with supersampling, the nearest of the
            pixel's samples); ``+inf`` where nothing was drawn (the
            background). Never NaN. Polygons and "fast" splats write the
            exact surface; "high" and "blend" splats their visibility depth,
            up to ``push`` times a splat's larger half-axis behind it; the
            volume the depth where the opacity reaches one half.
        seconds: time to draw and read back the colour (as
            ``Renderer.last_frame_seconds``; the depth read-back is not counted).
        stats: what the renderer drew (:class:`DrawStats`).
    """

    color: np.ndarray
    depth: np.ndarray
    seconds: float
    stats: DrawStats


def view_depth(window: np.ndarray, near: float, far: float) -> np.ndarray:
    """float32 view-axis distances (world units) of OpenGL window depths
    ``window`` in [0, 1] under a perspective projection with clip distances
    ``near`` and ``far``: ``z = far near / (far - window (far - near))``, the
    inverse of ``window = far (z - near) / (z (far - near))``. A window depth
    of 1 (the cleared value: nothing drawn, or the far plane) gives +inf."""
    d = np.asarray(window, dtype=np.float64)
    near, far = float(near), float(far)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = far * near / (far - np.clip(d, 0.0, 1.0) * (far - near))
    return np.where((d < 1.0) & np.isfinite(z), z, np.inf).astype(np.float32)


def _mat(m: np.ndarray) -> tuple[float, ...]:
    # moderngl expects column-major order; numpy is row-major.
    return tuple(float(x) for x in np.asarray(m, dtype=np.float64).T.ravel())

