"""What every renderer needs to draw one frame: camera, lights, target size and
clip range, with the matrices built in float64 per uploaded object."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aniso3d.render.camera import Camera
from aniso3d.render.lighting import Lighting


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


def _mat(m: np.ndarray) -> tuple[float, ...]:
    # moderngl expects column-major order; numpy is row-major.
    return tuple(float(x) for x in np.asarray(m, dtype=np.float64).T.ravel())


mat_uniform = _mat
