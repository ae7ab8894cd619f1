"""One call for a quick picture: ``aniso3d.render(thing)``.

Makes a :class:`~aniso3d.rendering.renderer.Renderer` (and its GL context) for
one image, frames the object when no camera is given, and releases every GPU
object before returning. For many frames, keep a ``Renderer`` instead: it
converts and uploads once.
"""

from __future__ import annotations

import numpy as np

from aniso3d.build.bounds import bounds_of, surface_sample
from aniso3d.build.mesh import Mesh
from aniso3d.build.points import PointCloud
from aniso3d.build.scene import Scene
from aniso3d.build.texture import AnisoTexture
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.renderer import Renderer, check_size

#: The direction the default camera looks from (target towards the eye).
DEFAULT_VIEW = (0.55, 0.35, 1.0)


def framing_camera(thing: Mesh | AnisoTexture | PointCloud | Scene, size: tuple[int, int] = (512, 512),
                   direction=DEFAULT_VIEW, fov: float = 40.0) -> Camera:  # fmt: skip
    """A camera from ``direction`` just far enough that the object fills an
    image of ``size`` (width, height): the framing of ``aniso3d render``."""
    w, h = check_size(size)
    return Camera.fit(bounds_of(thing), direction=direction, fov=fov, aspect=w / h, points=surface_sample(thing))


def render(
    thing: Mesh | AnisoTexture | PointCloud | Scene,
    camera: Camera | None = None,
    method: str | None = None,
    size: int | tuple[int, int] = 512,
    backend: str = "auto",
    **options,
) -> np.ndarray:
    """(H, W, 3) uint8 image of ``thing`` (row 0 at the top): a mesh, texture,
    point cloud or :class:`~aniso3d.build.scene.Scene` of instances.

    ``method`` is "mesh", "volume" or "splat" (default: what the thing is);
    ``size`` is pixels, one number for a square or (width, height);
    ``options`` are the Renderer's build and draw options (e.g.
    ``resolution=64``, ``quality="high"``, ``ssaa=4``).
    """
    size = (size, size) if isinstance(size, int) else tuple(size)
    size = check_size(size)
    camera = camera or framing_camera(thing, size)
    with Renderer(size, backend=backend) as r:
        return r.render(thing, camera, method, **options)
