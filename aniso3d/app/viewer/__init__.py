"""The interactive viewer: a window on a mesh, a saved texture or a point
cloud, drawn live by any of the three renderers, so that one can look around
a scene and feel the speed/accuracy trade.

Modules, in the order the data flows:

- :mod:`~aniso3d.app.viewer.state`: the settings, the orbiting camera and what
  each key does to them; no window, no OpenGL.
- :mod:`~aniso3d.app.viewer.worker`: one background thread for the slow
  conversions, so the window keeps answering while a texture builds.
- :mod:`~aniso3d.app.viewer.data`: the data each renderer needs for the
  current settings, the conversion jobs, and a cache for switching back.
- :mod:`~aniso3d.app.viewer.scene`: uploads, and the scene drawn through the
  :class:`~aniso3d.rendering.renderer.Renderer` into an offscreen framebuffer.
- :mod:`~aniso3d.app.viewer.overlay`: the text panels over the scene.
- :mod:`~aniso3d.app.viewer.window`: the pyglet window (optional extra
  ``aniso3d[viewer]``, imported only when a window opens), its events and the
  main loop.
"""

from aniso3d.app.viewer.state import (
    ACTIONS,
    CONTROLS,
    DEFAULT_RESOLUTION,
    DEGREES_PER_PIXEL,
    HOME_AZIMUTH,
    HOME_ELEVATION,
    KEYS,
    METHODS,
    QUALITIES,
    RESOLUTIONS,
    SPLATS,
    Orbit,
    Reply,
    Settings,
    ViewState,
    step_resolution,
)
from aniso3d.app.viewer.window import HEADLESS_HINT, Viewer, check_display, open_window, run_viewer

__all__ = [
    "ACTIONS",
    "CONTROLS",
    "DEFAULT_RESOLUTION",
    "DEGREES_PER_PIXEL",
    "HEADLESS_HINT",
    "HOME_AZIMUTH",
    "HOME_ELEVATION",
    "KEYS",
    "METHODS",
    "QUALITIES",
    "RESOLUTIONS",
    "SPLATS",
    "Orbit",
    "Reply",
    "Settings",
    "ViewState",
    "Viewer",
    "check_display",
    "open_window",
    "run_viewer",
    "step_resolution",
]
