"""The interactive viewer: a window on a mesh, a saved texture or a point
cloud, drawn live by any of the three renderers, so that one can look around
a scene and feel the speed/accuracy trade.

Layers, top down:

- :class:`Viewer` owns a pyglet window (optional extra ``aniso3d[viewer]``)
  and its OpenGL context, wrapped by :meth:`GLContext.wrap` so the ordinary
  per-method renderers (:meth:`Renderer.method_renderer`) draw into it. The
  scene is drawn into an offscreen framebuffer only when something changed
  (camera, a setting, the window size, a finished build) and shown with one
  textured quad; the overlay is text drawn by Pillow into small textures.
- :class:`Builder` runs the conversions (mesh -> texture -> points) on one
  background thread, so the window keeps answering while a texture builds.
  GL work stays on the main thread: a finished conversion is uploaded on the
  next frame.
- :class:`Orbit` is the camera control (orbit, pan, zoom, turntable), plain
  arithmetic on top of :class:`~aniso3d.render.camera.Camera`, testable without a
  window.

A renderer whose module is missing (or fails to start) is reported on screen
instead of crashing, and is looked for again while it is selected, so a
renderer that lands while the viewer runs starts working.

The viewer logs one line on stdout per change of what it shows ("showing
splat (...) at 960x640, ...", "building texture 128³ ...", "camera azimuth
...", "screenshot saved to ..."): a record for the user, and what the tests
wait for.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import math
import os
import sys
import threading
import time
import traceback
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import moderngl
import numpy as np

from aniso3d.build.bounds import bounds_of
from aniso3d.build.mesh import Mesh
from aniso3d.build.points import PointCloud
from aniso3d.build.pyramid import LodPoints, Pyramid, pyramid
from aniso3d.build.texture import DEFAULT_DIRECTIONS, PLACEMENTS, AnisoTexture, build_texture
from aniso3d.errors import InputError, ResourceError
from aniso3d.render.camera import Camera
from aniso3d.render.select import describe_stats

METHODS = ("mesh", "volume", "splat")
METHOD_LABELS = {"mesh": "polygons", "volume": "volume", "splat": "splats"}
SPLATS = ("square", "disc", "ellipse")
QUALITIES = ("fast", "high")
#: Voxels along the longest axis that ``[`` and ``]`` step through.
RESOLUTIONS = (8, 16, 24, 32, 48, 64, 96, 128, 192, 256)
DEFAULT_RESOLUTION = 64

#: Start view, from the direction of ``aniso3d render``'s default camera: azimuth about +y from +z
#: towards +x, elevation above the horizon, degrees.
HOME_AZIMUTH, HOME_ELEVATION = 30.0, 15.0
DEGREES_PER_PIXEL = 0.4
ZOOM_PER_STEP = 0.85
FRAME_MARGIN = 1.1
#: Converted textures and point clouds kept for switching back (oldest dropped first).
CACHE_ENTRIES, CACHE_BYTES = 8, 1 << 30
TURNTABLE_DEGREES_PER_SECOND = 30.0

HEADLESS_HINT = (
    "for images without a window use the headless CLI: 'aniso3d render [INPUT] -o out.png' "
    "(or 'aniso3d frames' for a turntable)"
)

#: The controls, as the overlay's key bar and ``aniso3d view --help`` show
#: them: (keys, action).
CONTROLS: tuple[tuple[str, str], ...] = (
    ("drag", "orbit"),
    ("right/shift+drag", "pan"),
    ("wheel", "zoom"),
    ("r", "reset view"),
    ("t", "turntable"),
    ("1 2 3", "polygons/volume/splats"),
    ("m", "next renderer"),
    ("s", "splat shape"),
    ("h", "quality"),
    ("p", "point placement"),
    ("l", "level of detail"),
    ("[ ] or - +", "voxels down/up"),
    ("c or F12", "screenshot"),
    ("o", "overlay"),
    ("q or Esc", "quit"),
)


def step_resolution(current: int, step: int) -> int:
    """The next resolution of :data:`RESOLUTIONS` above (``step`` > 0) or below
    (``step`` < 0) ``current``; ``current`` itself at either end."""
    if step > 0:
        return next((r for r in RESOLUTIONS if r > current), current)
    return next((r for r in reversed(RESOLUTIONS) if r < current), current)


def cycle(options: tuple, current):
    return (
        options[(options.index(current) + 1) % len(options)] if current in options else options[0]
    )


def _direction(azimuth: float, elevation: float) -> np.ndarray:
    az, el = math.radians(azimuth), math.radians(elevation)
    return np.array([math.sin(az) * math.cos(el), math.sin(el), math.cos(az) * math.cos(el)])


# ------------------------------------------------------------------ the camera


class Orbit:
    """An orbiting camera: a target point, a distance, an azimuth about +y
    (from +z towards +x) and an elevation above the horizon, in degrees.

    Pixel arguments are window pixels with y up (pyglet's convention).
    """

    def __init__(self, bounds: np.ndarray, fov: float = 40.0, aspect: float = 1.0):
        self.bounds = np.asarray(bounds, dtype=np.float64)
        self.fov = float(fov)
        self.reset(aspect)

    def reset(self, aspect: float | None = None) -> None:
        """The start view: looking at the centre of the bounds from the home
        direction, just far enough that the box's eight corners fit the window
        with a 10% margin (tighter than :meth:`Camera.frame`'s bounding sphere,
        which leaves a cube at half the window)."""
        if aspect is not None:
            self.aspect = float(aspect)
        self.azimuth, self.elevation = HOME_AZIMUTH, HOME_ELEVATION
        home = _direction(self.azimuth, self.elevation)
        cam = Camera.fit(self.bounds, home, self.fov, self.aspect, FRAME_MARGIN)
        self.target = np.asarray(cam.target, dtype=np.float64)
        self.distance = float(np.linalg.norm(np.subtract(cam.position, cam.target)))
        self.home_distance = self.distance

    def camera(self) -> Camera:
        eye = self.target + _direction(self.azimuth, self.elevation) * self.distance
        return Camera(tuple(eye), tuple(self.target), (0.0, 1.0, 0.0), self.fov)

    def rotate(self, dx: float, dy: float) -> None:
        """Turn as if the scene were grabbed: dragging right turns it to the right."""
        self.azimuth = (self.azimuth - DEGREES_PER_PIXEL * dx) % 360.0
        self.elevation = float(np.clip(self.elevation - DEGREES_PER_PIXEL * dy, -89.0, 89.0))

    def pan(self, dx: float, dy: float, viewport_height: float) -> None:
        """Move the target so the point under the cursor follows it (at the
        target's depth)."""
        right, up, _ = self.camera().basis()
        per_pixel = (
            2.0 * self.distance * math.tan(math.radians(self.fov) / 2) / max(viewport_height, 1.0)
        )
        self.target = self.target - (right * dx + up * dy) * per_pixel

    def zoom(self, steps: float) -> None:
        """Move closer by ``steps`` wheel notches (negative: farther)."""
        d = self.distance * ZOOM_PER_STEP**steps
        self.distance = float(np.clip(d, 0.01 * self.home_distance, 20.0 * self.home_distance))

    def spin(self, seconds: float) -> None:
        self.azimuth = (self.azimuth + TURNTABLE_DEGREES_PER_SECOND * seconds) % 360.0

    def describe(self) -> str:
        t = ", ".join(f"{x:.3g}" for x in self.target)
        return (f"azimuth {self.azimuth:.1f} elevation {self.elevation:.1f} "
                f"distance {self.distance:.4g} target ({t})")  # fmt: skip


# ------------------------------------------------------------ background builds


class Cancelled(Exception):
    """Raised inside a build whose result is no longer wanted."""


class Builder:
    """One background thread for the slow conversions. One job at a time;
    :meth:`poll` hands its result (or exception) to the main thread.

    A job is called with a ``progress(fraction, stage)`` callable (the one
    :func:`build_texture` takes); it records the progress and raises
    :class:`Cancelled` once :meth:`cancel` was called, which is how a build
    the user has moved on from stops early.
    """

    def __init__(self):
        self._thread: threading.Thread | None = None
        self._result: tuple | None = None
        self._cancel = threading.Event()
        self.key: tuple | None = None
        self.label = ""
        self.started = 0.0
        self.fraction = 0.0

    @property
    def busy(self) -> bool:
        return self._thread is not None

    def start(self, key: tuple, label: str, job: Callable[[Callable], dict]) -> None:
        if self.busy:
            raise RuntimeError("a build is already running")
        cancel = self._cancel = threading.Event()

        def progress(fraction: float, stage: str = "") -> None:
            self.fraction = float(fraction)
            if cancel.is_set():
                raise Cancelled()

        def work():
            try:
                result = (job(progress), None)
            except BaseException as exc:  # reported in the window, never raised in a thread
                result = (None, exc)
            self._result = result

        self.key, self.label, self.started, self._result = key, label, time.perf_counter(), None
        self.fraction = 0.0
        # A daemon: quitting mid-build must not wait for the build.
        self._thread = threading.Thread(target=work, name="aniso3d-build", daemon=True)
        self._thread.start()

    def cancel(self) -> None:
        """Ask the running job to stop at its next progress report."""
        self._cancel.set()

    @property
    def cancelling(self) -> bool:
        return self.busy and self._cancel.is_set()

    def poll(self) -> tuple[dict | None, BaseException | None, float] | None:
        """(results, exception, seconds) once the job has finished, else None."""
        if self._thread is None or self._thread.is_alive():
            return None
        self._thread.join()
        self._thread = None
        results, exc = self._result or (None, RuntimeError("the build ended without a result"))
        return results, exc, time.perf_counter() - self.started

    def elapsed(self) -> float:
        return time.perf_counter() - self.started if self.busy else 0.0


# --------------------------------------------------------------------- settings


@dataclass
class Settings:
    """What the user chose; every key of the viewer changes one of these."""

    method: str | None = None  # None: what the input is (mesh, volume for a texture, splat)
    splat: str = "disc"
    quality: str = "fast"
    placement: str = "centroid"
    resolution: int = DEFAULT_RESOLUTION
    directions: int = DEFAULT_DIRECTIONS
    turntable: bool = False
    overlay: bool = True
    lod: bool = False  # splats and volume from the texture's pyramid (aniso3d.build.pyramid)


def _takes(impl, name: str) -> bool:
    """Whether a per-method renderer takes draw option ``name``: a named
    parameter of its ``draw``, or of its ``options`` (renderers whose ``draw``
    passes ``**options`` on to a validating ``options`` method)."""
    named = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    for func in (getattr(impl, "draw", None), getattr(impl, "options", None)):
        try:
            param = inspect.signature(func).parameters.get(name)
        except (TypeError, ValueError):
            continue
        if param is not None and param.kind in named:
            return True
    return False


def _fmt_int(n: int) -> str:
    return f"{int(n):,}"


# ------------------------------------------------------------------------ text


def _load_font(px: int):
    from PIL import ImageFont

    for name in ("DejaVuSansMono.ttf", "DejaVuSans.ttf"):
        try:
            return ImageFont.truetype(name, px)
        except OSError:
            continue
    try:
        return ImageFont.load_default(size=px)
    except TypeError:  # Pillow < 10.1: one bitmap size
        return ImageFont.load_default()


def text_panel(lines: list[tuple[str, tuple[int, int, int]]], font, pad: int = 8,
               background=(20, 22, 28, 190)) -> np.ndarray:  # fmt: skip
    """(H, W, 4) uint8 RGBA image of coloured text lines on a translucent panel,
    top row first."""
    from PIL import Image, ImageDraw

    probe = ImageDraw.Draw(Image.new("RGBA", (1, 1)))
    ascent, descent = font.getmetrics() if hasattr(font, "getmetrics") else (12, 3)
    line_h = ascent + descent + 2
    width = max((probe.textlength(text, font=font) for text, _ in lines), default=0)
    w, h = int(width) + 2 * pad, line_h * len(lines) + 2 * pad - 2
    img = Image.new("RGBA", (max(w, 1), max(h, 1)), (0, 0, 0, 0))
    draw = ImageDraw.Draw(img)
    draw.rounded_rectangle([0, 0, w - 1, h - 1], radius=min(6, pad), fill=background)
    for i, (text, color) in enumerate(lines):
        draw.text((pad, pad + i * line_h), text, font=font, fill=(*color, 255))
    return np.asarray(img)


WHITE, GREY, YELLOW, RED, GREEN = (
    (235, 235, 235),
    (160, 165, 175),
    (255, 205, 80),
    (255, 120, 110),
    (150, 220, 150),
)

_QUAD_VERT = """
#version 330
// A screen rectangle from gl_VertexID (triangle strip of 4, no buffers).
// u_rect: (x0, y0, x1, y1) in normalised device coordinates.
// u_flip: 1 for images stored top row first (Pillow), 0 for GL textures.
uniform vec4 u_rect;
uniform int u_flip;
out vec2 v_uv;
void main() {
    vec2 c = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1));
    v_uv = vec2(c.x, u_flip == 1 ? 1.0 - c.y : c.y);
    gl_Position = vec4(mix(u_rect.xy, u_rect.zw, c), 0.0, 1.0);
}
"""
_QUAD_FRAG = """
#version 330
// Output: the texture; opaque (alpha 1) when u_opaque is set (the scene).
uniform sampler2D u_tex;
uniform int u_opaque;
in vec2 v_uv;
out vec4 f_color;
void main() {
    vec4 c = texture(u_tex, v_uv);
    f_color = u_opaque == 1 ? vec4(c.rgb, 1.0) : c;
}
"""


# ----------------------------------------------------------------------- window


def check_display() -> None:
    """Raise :class:`ResourceError` with a clear message where no window can
    be opened: no display, or pyglet (the ``viewer`` extra) missing."""
    if sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
        raise ResourceError(
            "no display: 'aniso3d view' opens a window and needs an X display, but DISPLAY is "
            f"not set (over ssh use 'ssh -X', or run under xvfb-run); {HEADLESS_HINT}"
        )
    if importlib.util.find_spec("pyglet") is None:
        raise ResourceError(
            f"the viewer needs pyglet: pip install 'aniso3d[viewer]'; {HEADLESS_HINT}"
        )


def open_window(size: tuple[int, int], caption: str):
    """A resizable pyglet window with a current OpenGL 3.3+ core context, and
    its moderngl context. Raises :class:`ResourceError` with a clear message
    where there is no display, no pyglet or no suitable OpenGL."""
    check_display()
    import pyglet

    pyglet.options["debug_gl"] = False  # pyglet checks glGetError after each of its calls otherwise
    where = os.environ.get("DISPLAY", "the display")
    try:
        import pyglet.window  # connects to the display (and makes pyglet's shadow context)

        config = pyglet.gl.Config(major_version=3, minor_version=3, forward_compatible=True,
                                  double_buffer=True, depth_size=24)  # fmt: skip
        window = pyglet.window.Window(*size, caption=caption, resizable=True, config=config,
                                      vsync=False)  # fmt: skip
    except Exception as exc:  # each platform fails in its own way
        raise ResourceError(
            f"cannot open an OpenGL 3.3 window on {where} ({type(exc).__name__}: {exc}); "
            + HEADLESS_HINT
        ) from None
    try:
        ctx = moderngl.create_context(require=330)
    except Exception as exc:
        window.close()
        raise ResourceError(
            f"the window on {where} has no usable OpenGL 3.3 core context ({exc}); {HEADLESS_HINT}"
        ) from None
    return window, ctx


@dataclass
class _Shown:
    """A method's uploaded data: its key, GPU handle, renderer and a count for the overlay."""

    key: tuple
    handle: object
    impl: object
    counts: str


@dataclass
class _Frame:
    """What the scene shows: state is ready, stale (older settings while a
    build runs), building, unavailable or failed; message says why."""

    state: str
    impl: object = None
    shown: _Shown | None = None
    message: str = ""
    key: tuple | None = None  # the data being built, when building


def _memory_bytes(thing) -> int:
    """Bytes ``thing`` holds in memory: ``memory_nbytes`` where it has one (a
    texture's ``nbytes`` is its stored, compressed size), else ``nbytes``."""
    if hasattr(thing, "memory_nbytes"):
        return int(thing.memory_nbytes)
    return int(getattr(thing, "nbytes", 0))


def _counts(data) -> str:
    if isinstance(data, Mesh):
        return f"{_fmt_int(data.n_faces)} triangles"
    if isinstance(data, AnisoTexture):
        return f"{_fmt_int(data.n_voxels)} voxels of {'x'.join(str(int(x)) for x in data.shape)}"
    if isinstance(data, PointCloud):
        return f"{_fmt_int(len(data))} points"
    if isinstance(data, Pyramid):
        return f"a pyramid of {len(data)} levels, {_counts(data[0])} at the finest"
    if isinstance(data, LodPoints):
        n = sum(len(data.level_cloud(lvl)[0]) for lvl in range(len(data.pyramid)))
        return f"{_fmt_int(n)} points in {len(data.pyramid)} levels"
    return type(data).__name__


class _Slot:
    """A texture holding one overlay panel, rewritten when its text changes."""

    def __init__(self):
        self.key = None
        self.tex = None
        self.size = (0, 0)


class Viewer:
    """The window app. ``thing`` is a :class:`Mesh`, :class:`AnisoTexture` or
    :class:`PointCloud`; ``name`` labels it. Call :meth:`run`; it returns the
    exit status (0 when closed by a key or the window's close button)."""

    def __init__(
        self,
        thing,
        name: str = "scene",
        size: tuple[int, int] = (960, 640),
        settings: Settings | None = None,
        screenshot_dir: str | os.PathLike = ".",
        out=None,
    ):
        self.thing = thing
        self.name = name
        kinds = {Mesh: "mesh", AnisoTexture: "texture", PointCloud: "points"}
        self.kind = next((v for t, v in kinds.items() if isinstance(thing, t)), None)
        if self.kind is None:
            raise InputError(
                f"cannot view a {type(thing).__name__}; give a mesh, a .a3d texture "
                "or a PLY point cloud"
            )
        self.settings = settings or Settings()
        if self.settings.method is None:
            self.settings.method = {"mesh": "mesh", "texture": "volume", "points": "splat"}[
                self.kind
            ]
        if self.kind == "texture":
            self.settings.resolution, self.settings.directions = (
                thing.resolution,
                thing.n_directions,
            )
        self.screenshot_dir = Path(screenshot_dir)
        if not self.screenshot_dir.is_dir():
            raise InputError(
                f"screenshot folder '{self.screenshot_dir}' does not exist; create it first"
            )
        self.out = out or sys.stdout
        self.bounds = bounds_of(thing)

        from aniso3d.render.context import GLContext
        from aniso3d.render.renderer import Renderer

        self.window, self.ctx = open_window(size, f"aniso3d view — {name}")
        try:
            self.gl = GLContext.wrap(self.ctx)
            self.renderer = Renderer(self.window.get_framebuffer_size(), gl=self.gl)
            self._setup()
        except BaseException:
            self.window.close()
            raise

    # ------------------------------------------------------------- set-up

    def _setup(self) -> None:
        w, h = self.window.get_framebuffer_size()
        self.orbit = Orbit(self.bounds, aspect=w / max(h, 1))
        self.builder = Builder()
        self._sources = {("mesh",): self.thing} if self.kind == "mesh" else {}
        if self.kind == "texture":
            self._sources[("texture",)] = self.thing
        if self.kind == "points":
            self._sources[("points",)] = self.thing
        self._cache: OrderedDict[tuple, object] = OrderedDict()  # built textures and points, LRU
        # Why a build (by data key) or an upload (by (method, data key)) failed.
        self._failed: dict[tuple, str] = {}
        self._shown: dict[str, _Shown] = {}  # method -> what is uploaded for it
        self._impl_error: dict[str, tuple[str, float]] = {}
        self._quit = False
        self._dirty = True
        self._dragging = False
        self._notice: tuple[str, float, tuple] = ("", 0.0, WHITE)
        self._frame_ms: float | None = None
        self._fps_text = ""
        self._fps_updated = 0.0
        self._last_status = ""
        self._draw_error: str | None = None
        self._scene_fbo = None
        self._scene_size = (0, 0)
        self._frame = _Frame("building")
        self._quad = self.gl.track(
            self.ctx.program(vertex_shader=_QUAD_VERT, fragment_shader=_QUAD_FRAG)
        )
        self._quad_vao = self.gl.track(self.ctx.vertex_array(self._quad, []))
        ratio = w / max(self.window.width, 1)
        self._font = _load_font(int(round(13 * ratio)))
        self._big_font = _load_font(int(round(16 * ratio)))
        self._slots = {name: _Slot() for name in ("status", "keys", "badge", "center")}
        self._install_handlers()
        self._say(
            f"window {self.window.width}x{self.window.height}, "
            f"OpenGL {self.gl.version} ({self.gl.renderer})"
        )

    def _install_handlers(self) -> None:
        import pyglet
        from pyglet.window import key, mouse

        win = self.window
        handled = pyglet.event.EVENT_HANDLED
        k = key
        bindings: list[tuple[tuple[int, ...], Callable[[], None]]] = [
            ((k.ESCAPE, k.Q), self.quit),
            ((k._1, k.NUM_1), lambda: self.set_method("mesh")),
            ((k._2, k.NUM_2), lambda: self.set_method("volume")),
            ((k._3, k.NUM_3), lambda: self.set_method("splat")),
            ((k.M,), lambda: self.set_method(cycle(METHODS, self.settings.method))),
            ((k.S,), lambda: self._set("splat", cycle(SPLATS, self.settings.splat))),
            ((k.H,), lambda: self._set("quality", cycle(QUALITIES, self.settings.quality))),
            ((k.P,), self.next_placement),
            ((k.L,), self.toggle_lod),
            ((k.BRACKETLEFT, k.MINUS, k.NUM_SUBTRACT), lambda: self.step_resolution(-1)),
            ((k.BRACKETRIGHT, k.EQUAL, k.PLUS, k.NUM_ADD), lambda: self.step_resolution(1)),
            ((k.R,), self.reset_view),
            ((k.T,), self.toggle_turntable),
            ((k.C, k.F12), self.request_screenshot),
            ((k.O,), lambda: self._set("overlay", not self.settings.overlay)),
        ]
        actions = {symbol: action for symbols, action in bindings for symbol in symbols}

        @win.event
        def on_key_press(symbol, modifiers):
            if modifiers & (key.MOD_CTRL | key.MOD_ALT | key.MOD_COMMAND):
                return None  # leave ctrl/alt combinations to the system
            action = actions.get(symbol)
            if action is not None:
                action()
            return handled  # also keeps pyglet's own Esc handler out

        @win.event
        def on_mouse_press(x, y, button, modifiers):
            self._dragging = False
            return handled

        @win.event
        def on_mouse_drag(x, y, dx, dy, buttons, modifiers):
            self._dragging = True
            if buttons & (mouse.RIGHT | mouse.MIDDLE) or (
                buttons & mouse.LEFT and modifiers & key.MOD_SHIFT
            ):
                self.orbit.pan(dx, dy, win.height)
            elif buttons & mouse.LEFT:
                self.orbit.rotate(dx, dy)
            self._dirty = True
            return handled

        @win.event
        def on_mouse_release(x, y, button, modifiers):
            if self._dragging:
                self._say(f"camera {self.orbit.describe()}")
            self._dragging = False
            return handled

        @win.event
        def on_mouse_scroll(x, y, scroll_x, scroll_y):
            self.orbit.zoom(scroll_y)
            self._dirty = True
            return handled

        @win.event
        def on_resize(width, height):
            self._dirty = True
            return handled  # pyglet's default sets up its own projection; not ours

        @win.event
        def on_close():
            self.quit()
            return handled

        @win.event
        def on_expose():
            self._dirty = True

    # ------------------------------------------------------------ actions

    def quit(self) -> None:
        self._quit = True

    def _set(self, name: str, value) -> None:
        setattr(self.settings, name, value)
        if name in ("quality", "splat"):
            self._frame_ms = None  # another frame-time regime: average afresh
        self._dirty = True

    def set_method(self, method: str) -> None:
        self.settings.method = method
        self._frame_ms = None  # another renderer: start the frame-time average afresh
        self._impl_error.pop(method, None)  # look for the renderer again
        self._draw_error = None
        self._dirty = True

    def next_placement(self) -> None:
        if self.kind == "points":
            self._notify("placement is fixed: the input is a point cloud", YELLOW)
            return
        self._set("placement", cycle(PLACEMENTS, self.settings.placement))

    def toggle_lod(self) -> None:
        if self.kind == "points":
            self._notify("level of detail needs a texture: the input is a point cloud", YELLOW)
            return
        self._set("lod", not self.settings.lod)
        if self.settings.method == "mesh":
            state = "on" if self.settings.lod else "off"
            self._notify(f"level of detail {state}: it applies to the volume and splats", YELLOW)

    def step_resolution(self, step: int) -> None:
        if self.kind != "mesh":
            what = "saved texture" if self.kind == "texture" else "point cloud"
            self._notify(f"resolution is fixed: the input is a {what}", YELLOW)
            return
        new = step_resolution(self.settings.resolution, step)
        if new == self.settings.resolution:
            self._notify(
                f"resolution {new}³ is the {'highest' if step > 0 else 'lowest'} step", YELLOW
            )
        self._set("resolution", new)

    def reset_view(self) -> None:
        w, h = self.window.get_framebuffer_size()
        self.orbit.reset(w / max(h, 1))
        self._dirty = True
        self._say(f"camera {self.orbit.describe()}")

    def toggle_turntable(self) -> None:
        self._set("turntable", not self.settings.turntable)

    def request_screenshot(self) -> None:
        """Save what the window shows now, after the events before this key
        (not after later ones in the same batch)."""
        if self._dirty:
            self._render_scene()
        self._compose(time.perf_counter())
        self._save_screenshot()

    def _notify(self, text: str, color=WHITE, seconds: float = 4.0) -> None:
        self._notice = (text, time.perf_counter() + seconds, color)
        self._say(text)

    def _say(self, text: str) -> None:
        """One line of the viewer's log on stdout (the tests read it)."""
        print(f"aniso3d view: {text}", file=self.out, flush=True)

    # --------------------------------------------------------------- data

    def _texture_key(self) -> tuple:
        s = self.settings
        return ("texture",) if self.kind == "texture" else ("texture", s.resolution, s.directions)

    def _points_key(self) -> tuple:
        return (
            ("points",)
            if self.kind == "points"
            else ("points", self._texture_key(), self.settings.placement)
        )

    def _lod(self) -> bool:
        return self.settings.lod and self.kind != "points"

    def requirement(self, method: str) -> tuple[tuple | None, str | None]:
        """(data key ``method`` draws, None), or (None, why it cannot draw this input)."""
        if method == "mesh":
            if self.kind != "mesh":
                what = "saved texture" if self.kind == "texture" else "point cloud"
                return None, f"the polygon renderer needs the mesh: a {what} keeps no polygons"
            return ("mesh",), None
        if method == "volume":
            if self.kind == "points":
                return (
                    None,
                    "the volume renderer needs an anisotropic texture: a point cloud has none",
                )
            return (("pyramid", self._texture_key()) if self._lod() else self._texture_key()), None
        if self._lod():
            return ("lod points", self._texture_key(), self.settings.placement), None
        return self._points_key(), None

    def _lookup(self, key: tuple):
        if key in self._sources:
            return self._sources[key]
        value = self._cache.get(key)
        if value is not None:
            self._cache.move_to_end(key)
        return value

    def _describe_key(self, key: tuple) -> str:
        if key[0] == "pyramid":
            return f"pyramid of the {self._describe_key(key[1])}"
        if key[0] == "lod points":
            return f"level-of-detail points ({key[2]}) of the {self._describe_key(key[1])}"
        if key[0] == "texture" and len(key) == 3:
            return f"texture {key[1]}³ (K={key[2]})"
        if key[0] == "points" and len(key) == 3:
            return f"points ({key[2]}) from the {self._describe_key(key[1])}"
        return key[0]

    def _job(self, key: tuple) -> Callable[[Callable], dict]:
        mesh = self.thing
        if key[0] in ("pyramid", "lod points"):
            tkey = key[1]
            tex = self._lookup(tkey)
            pyr = self._lookup(("pyramid", tkey))

            def levels(progress):
                t = tex
                if t is None:
                    t = build_texture(mesh, tkey[1], tkey[2], progress=progress)
                progress(1.0, "pyramid")
                p = pyr if pyr is not None else pyramid(t)
                out = {tkey: t, ("pyramid", tkey): p}
                if key[0] == "lod points":
                    lp = out[key] = LodPoints(p, key[2])
                    for lvl in range(len(p)):  # the level point sets, off the main thread
                        lp.level_cloud(lvl)
                return out

            return levels
        if key[0] == "texture":
            _, res, k = key
            return lambda progress: {key: build_texture(mesh, res, k, progress=progress)}
        _, tkey, placement = key
        tex = self._lookup(tkey)

        def points(progress):
            t = tex
            if t is None:
                t = build_texture(mesh, tkey[1], tkey[2], progress=progress)
            progress(1.0, "points")
            return {tkey: t, key: t.to_points(placement)}

        return points

    def _wanted(self) -> list[tuple]:
        """Data the current settings need, most urgent first: what the
        selected renderer draws, then (for a mesh) the texture and points, so
        a switch of renderer finds them ready."""
        method_key, _ = self.requirement(self.settings.method)
        wanted = [method_key]
        if self._lod() and method_key is not None and method_key[0] != "mesh":
            wanted += [self.requirement(m)[0] for m in ("volume", "splat")]
        if self.kind == "mesh":
            wanted += [self._texture_key(), self._points_key()]
        elif self.kind == "texture":
            wanted += [self._points_key()]
        return [k for k in wanted if k is not None]

    def _schedule(self) -> None:
        """Start the next conversion the settings need; stop one they no
        longer need (a resolution stepped past, say)."""
        wanted = self._wanted()
        if self.builder.busy:
            key = self.builder.key
            if not (key in wanted or (key[0] == "points" and key[1] in wanted)):
                if not self.builder.cancelling:
                    self.builder.cancel()
            return
        for key in wanted:
            if self._lookup(key) is not None or key in self._failed:
                continue
            label = self._describe_key(key)
            self._say(f"building {label}")
            self.builder.start(key, label, self._job(key))
            return

    def _collect(self) -> None:
        done = self.builder.poll()
        if done is None:
            return
        results, exc, seconds = done
        label = self.builder.label
        if isinstance(exc, Cancelled):
            self._say(f"stopped building {label} after {seconds:.2f} s: no longer needed")
        elif exc is not None:
            msg = (
                str(exc)
                if not isinstance(exc, MemoryError)
                else "out of memory; step the resolution down"
            )
            if not isinstance(exc, (InputError, MemoryError)):
                traceback.print_exception(exc, file=sys.stderr)
                msg = f"{type(exc).__name__}: {exc}"
            self._failed[self.builder.key] = msg  # not retried: the settings must change first
            self._notify(f"building {label} failed: {msg}", RED, 8.0)
        else:
            for key, value in results.items():
                self._cache[key] = value
                self._cache.move_to_end(key)
            # Keep recent conversions for quick switching back, within a memory budget.
            while len(self._cache) > 2 and (
                len(self._cache) > CACHE_ENTRIES
                or sum(_memory_bytes(v) for v in self._cache.values()) > CACHE_BYTES
            ):
                self._cache.popitem(last=False)
            self._say(f"built {label} in {seconds:.2f} s: {_counts(results[self.builder.key])}")
        self._dirty = True

    # ------------------------------------------------------------ drawing

    def _impl(self, method: str):
        """(per-method renderer, None), or (None, why it is not available)."""
        err = self._impl_error.get(method)
        now = time.perf_counter()
        if err is not None and now < err[1]:
            return None, err[0]
        if err is not None:
            importlib.invalidate_caches()  # its module may have appeared since
        try:
            impl = self.renderer.method_renderer(method)
            self._impl_error.pop(method, None)
            return impl, None
        except ModuleNotFoundError as exc:
            if exc.name and exc.name.startswith("aniso3d.render."):
                path = exc.name.replace(".", "/") + ".py"
                msg = (
                    f"the {METHOD_LABELS[method]} renderer is not available yet ({path} is missing)"
                )
            else:
                msg = f"the {METHOD_LABELS[method]} renderer cannot start: {exc}"
        except Exception as exc:  # a renderer failing to start must not take the window down
            msg = (
                f"the {METHOD_LABELS[method]} renderer failed to start: {type(exc).__name__}: {exc}"
            )
            if err is None:
                traceback.print_exc(file=sys.stderr)
        self._impl_error[method] = (msg, now + 2.0)  # look again in 2 s while selected
        return None, msg

    def _retry_due(self) -> bool:
        err = self._impl_error.get(self.settings.method)
        return err is not None and time.perf_counter() >= err[1]

    def _current(self) -> _Frame:
        """What to draw for the selected method, uploading data that just became ready."""
        method = self.settings.method
        impl, why = self._impl(method)
        if impl is None:
            return _Frame("unavailable", message=why)
        key, why = self.requirement(method)
        if key is None:
            return _Frame("unavailable", impl, message=why)
        shown = self._shown.get(method)
        data = self._lookup(key)
        failed = self._failed.get(key) or self._failed.get((method, key))
        if data is not None and (shown is None or shown.key != key) and failed is None:
            label = METHOD_LABELS[method]
            try:
                t0 = time.perf_counter()
                handle = impl.upload(data)
                self._say(f"uploaded {self._describe_key(key)} for {label} "
                          f"in {time.perf_counter() - t0:.2f} s")  # fmt: skip
            except Exception as exc:  # not retried: the settings must change first
                traceback.print_exc(file=sys.stderr)
                failed = self._failed[(method, key)] = (
                    f"the {label} renderer could not take the {self._describe_key(key)}: "
                    f"{type(exc).__name__}: {exc}"
                )
            else:
                if shown is not None:
                    shown.impl.release(shown.handle)
                shown = self._shown[method] = _Shown(key, handle, impl, _counts(data))
        if failed is not None and (shown is None or shown.key != key):
            return _Frame("failed", impl, message=failed)
        if shown is None:
            return _Frame(
                "building", impl, message=f"building the {self._describe_key(key)}…", key=key
            )
        return _Frame("stale" if shown.key != key else "ready", impl, shown)

    def _ensure_scene_target(self, size: tuple[int, int]):
        if self._scene_fbo is not None and self._scene_size == size:
            return self._scene_fbo
        if self._scene_fbo is not None:
            fbo = self._scene_fbo
            self.gl.free(*fbo.color_attachments, fbo.depth_attachment, fbo)
        color = self.gl.track(self.ctx.texture(size, 4, dtype="f1"))
        color.filter = (moderngl.LINEAR, moderngl.LINEAR)  # the 2x2 box filter when supersampled
        color.repeat_x = color.repeat_y = False
        depth = self.gl.track(self.ctx.depth_texture(size))
        self._scene_fbo = self.gl.track(
            self.ctx.framebuffer(color_attachments=[color], depth_attachment=depth)
        )
        self._scene_size = size
        return self._scene_fbo

    def _draw_options(self, impl) -> tuple[dict, int]:
        """Options the renderer takes, and the supersampling the viewer adds
        for "high" quality where the renderer has no quality option of its own
        (the polygons: 2x2 samples per pixel)."""
        s = self.settings
        options = {}
        if _takes(impl, "splat"):
            options["splat"] = s.splat
        if _takes(impl, "quality"):
            options["quality"] = s.quality
            return options, 1
        return options, 2 if s.quality == "high" else 1

    def _render_scene(self) -> None:
        from aniso3d.render.frame import FrameView

        self._dirty = False
        w, h = self.window.get_framebuffer_size()
        if w < 1 or h < 1:
            return
        frame = self._current()
        options, ssaa = self._draw_options(frame.impl) if frame.shown is not None else ({}, 1)
        if max(w, h) * ssaa > min(self.gl.max_texture_size, *self.gl.max_viewport):
            ssaa = 1
        size = (w * ssaa, h * ssaa)
        fbo = self._ensure_scene_target(size)
        fbo.use()
        self.ctx.viewport = (0, 0, *size)
        bg = self.renderer.lighting.background
        fbo.clear(bg[0], bg[1], bg[2], 0.0, depth=1.0)
        if frame.shown is not None:
            camera = self.orbit.camera()
            near, far = camera.clip_range(getattr(frame.shown.handle, "bounds", self.bounds))
            view = FrameView(camera, self.renderer.lighting, size, near, far, ssaa)
            try:
                t0 = time.perf_counter()
                frame.impl.draw(frame.shown.handle, view, fbo=fbo, **options)
                self.ctx.finish()  # time the whole frame, not just queueing its commands
                ms = 1000.0 * (time.perf_counter() - t0)
                self._frame_ms = ms if self._frame_ms is None else 0.7 * self._frame_ms + 0.3 * ms
                self._draw_error = None
            except Exception as exc:  # a renderer bug shows on screen; the window stays
                if self._draw_error is None:
                    traceback.print_exc(file=sys.stderr)
                label = METHOD_LABELS[self.settings.method]
                self._draw_error = f"the {label} renderer failed: {type(exc).__name__}: {exc}"
                frame = _Frame("failed", frame.impl, message=self._draw_error)
                fbo.use()
                fbo.clear(bg[0], bg[1], bg[2], 0.0, depth=1.0)
        self._frame = frame
        self._announce(frame, (w, h))

    def _announce(self, frame: _Frame, size) -> None:
        """Log the settled state when it changes (the tests wait for these lines)."""
        method = self.settings.method
        if frame.state == "ready":
            status = (f"showing {method} ({frame.shown.counts}) at {size[0]}x{size[1]}, "
                      f"{self._settings_text()}")  # fmt: skip
        elif frame.state == "stale":
            status = f"building {method}: showing the previous {METHOD_LABELS[method]} meanwhile"
        else:
            status = f"{frame.state} {method}: {frame.message}"
        if status != self._last_status:
            self._last_status = status
            self._say(status)

    def _settings_text(self) -> str:
        s = self.settings
        parts = [f"quality {s.quality}"]
        if s.method == "splat":
            parts.insert(0, f"splat {s.splat}")
            if self.kind != "points":
                parts.append(f"placement {s.placement}")
        if s.method != "mesh" and self.kind != "points":
            parts.append(f"voxels {s.resolution}³ K={s.directions}")
            if s.lod:
                parts.append("level of detail")
        return ", ".join(parts)

    # ------------------------------------------------------------ overlay

    def _panel(self, slot_name: str, lines, font):
        slot = self._slots[slot_name]
        key = (tuple(lines), id(font))
        if slot.key != key:
            img = text_panel(list(lines), font)
            h, w = img.shape[:2]
            if slot.tex is None or slot.size != (w, h):
                if slot.tex is not None:
                    self.gl.free(slot.tex)
                slot.tex = self.gl.track(self.ctx.texture((w, h), 4, img.tobytes()))
                slot.tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
                slot.size = (w, h)
            else:
                slot.tex.write(img.tobytes())
            slot.key = key
        return slot

    def _blit(self, tex, px: tuple[float, float, float, float], screen: tuple[int, int], flip: bool,
              opaque: bool) -> None:  # fmt: skip
        """Draw ``tex`` over pixels px = (left, top, right, bottom), y down."""
        sw, sh = screen
        x0, y0, x1, y1 = px
        rect = (2 * x0 / sw - 1, 1 - 2 * y1 / sh, 2 * x1 / sw - 1, 1 - 2 * y0 / sh)
        self._quad["u_rect"].value = rect
        self._quad["u_flip"].value = 1 if flip else 0
        self._quad["u_opaque"].value = 1 if opaque else 0
        self._quad["u_tex"].value = 0
        tex.use(0)
        self._quad_vao.render(moderngl.TRIANGLE_STRIP, vertices=4)

    def _status_lines(self, now: float):
        s = self.settings
        lines = [(f"aniso3d view · {self.name}", WHITE)]
        names = "  ".join(
            (f"[{i}:{METHOD_LABELS[m]}]" if m == s.method else f" {i}:{METHOD_LABELS[m]} ")
            for i, m in enumerate(METHODS, 1)
        )
        lines.append((f"renderer  {names}", WHITE))
        vox = f"{s.resolution}³ K={s.directions}" + ("" if self.kind == "mesh" else " (fixed)")
        if self.kind == "points":
            vox = "n/a (point cloud)"
        lines.append((f"splat {s.splat} · quality {s.quality} · placement {s.placement}", GREY))
        lines.append((f"voxels {vox}" + (" · turntable" if s.turntable else ""), GREY))
        if now - self._fps_updated > 0.25:
            self._fps_updated = now
            if self._frame_ms is not None:
                self._fps_text = (
                    f"frame {self._frame_ms:.1f} ms · {1000.0 / max(self._frame_ms, 1e-3):.0f} fps"
                )
        w, h = self.window.get_framebuffer_size()
        lines.append(((self._fps_text or "frame –") + f" · {w}x{h}", WHITE))
        f = self._frame
        if f.shown is not None:
            old = " (previous settings)" if f.state == "stale" else ""
            lines.append((f"drawing {f.shown.counts}{old}", WHITE))
            lod = describe_stats(getattr(f.shown.handle, "last_stats", None))
            if lod:
                lines.append((lod, WHITE))
        if self.builder.busy:
            lines.append((self._building_text(), YELLOW))
        text, until, color = self._notice
        if text and now < until:
            lines.append((text, color))
        return lines

    def _compose(self, now: float) -> None:
        """Draw the window: the scene image, then the overlay panels."""
        ctx = self.ctx
        w, h = self.window.get_framebuffer_size()
        ctx.screen.use()
        ctx.viewport = (0, 0, w, h)
        ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE | moderngl.BLEND)
        if self._scene_fbo is not None:
            scene = self._scene_fbo.color_attachments[0]
            self._blit(scene, (0, 0, w, h), (w, h), flip=False, opaque=True)
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        m = 10  # margin, pixels
        f = self._frame
        if f.message:
            color = {"building": WHITE, "unavailable": YELLOW}.get(f.state, RED)
            text = f.message
            if f.state == "building" and self.builder.busy and self.builder.key == f.key:
                text += f" {100 * self.builder.fraction:.0f}% {self.builder.elapsed():.1f} s"
            elif f.state == "building" and self.builder.busy:
                then = "stops" if self.builder.cancelling else "is done"
                text += f" (once the {self.builder.label} under way {then})"
            self._place("center", self._wrap(text, w, color), self._big_font, None, None)
        if self.settings.overlay:
            self._place("status", self._status_lines(now), self._font, m, m)
            self._place("keys", self._key_lines(w - 2 * m - 16), self._font, m, -m)
        elif self.builder.busy:  # the building state stays visible without the overlay
            self._place("badge", [(self._building_text(), YELLOW)], self._font, -m, m)
        ctx.disable(moderngl.BLEND)

    def _building_text(self) -> str:
        b = self.builder
        return f"building {b.label}… {100 * b.fraction:.0f}% {b.elapsed():.1f} s"

    def _place(self, slot_name: str, lines, font, x: int | None, y: int | None) -> tuple[int, int]:
        """Draw a text panel; x, y >= 0 from the left/top, < 0 from the
        right/bottom, None centred. Returns the panel's size."""
        slot = self._panel(slot_name, lines, font)
        w, h = self.window.get_framebuffer_size()
        pw, ph = slot.size
        left = (w - pw) // 2 if x is None else x if x >= 0 else w + x - pw
        top = (h - ph) // 2 if y is None else y if y >= 0 else h + y - ph
        self._blit(slot.tex, (left, top, left + pw, top + ph), (w, h), flip=True, opaque=False)
        return pw, ph

    def _key_lines(self, width_px: int) -> list:
        """The controls as a few lines of "key action" items that fit the window."""
        lines, line = [], ""
        for keys, action in CONTROLS:
            item = f"{keys} {action}"
            joined = f"{line}   {item}" if line else item
            if line and self._font.getlength(joined) > width_px:
                lines.append(line)
                joined = item
            line = joined
        lines.append(line)
        return [(ln, GREY) for ln in lines]

    def _wrap(self, text: str, width_px: int, color) -> list:
        """Split a long message into lines that fit the window."""
        per_line = max(20, int(width_px / max(self._big_font.getlength("M"), 1)) - 4)
        words, lines, line = text.split(), [], ""
        for word in words:
            if line and len(line) + 1 + len(word) > per_line:
                lines.append(line)
                line = word
            else:
                line = f"{line} {word}".strip()
        lines.append(line)
        return [(ln, color) for ln in lines]

    # ---------------------------------------------------------- screenshot

    def _next_screenshot_path(self) -> Path:
        n = 1
        while (self.screenshot_dir / f"aniso3d-view-{n:03d}.png").exists():
            n += 1
        return self.screenshot_dir / f"aniso3d-view-{n:03d}.png"

    def _save_screenshot(self) -> None:
        from aniso3d.render.images import save_png

        w, h = self.window.get_framebuffer_size()
        raw = self.ctx.screen.read(viewport=(0, 0, w, h), components=3, alignment=1)
        img = np.frombuffer(raw, dtype=np.uint8).reshape(h, w, 3)[::-1]
        try:
            path = save_png(self._next_screenshot_path(), np.ascontiguousarray(img))
        except (OSError, InputError) as exc:
            self._notify(f"screenshot not saved: {exc}", RED)
            return
        self._notify(f"screenshot saved to {path}", GREEN)

    # ---------------------------------------------------------------- loop

    def run(self) -> int:
        """The main loop; returns 0 when closed by q, Esc or the close button."""
        win = self.window
        last = time.perf_counter()
        try:
            while not self._quit:
                win.dispatch_events()
                if self._quit or win.has_exit:
                    break
                now = time.perf_counter()
                dt, last = now - last, now
                self._collect()
                self._schedule()
                if self.settings.turntable:
                    self.orbit.spin(dt)
                    self._dirty = True
                if self._dirty or self._retry_due():
                    self._render_scene()
                self._compose(now)
                win.flip()
                busy = self.settings.turntable or self.builder.busy or self._dragging
                spare = (1 / 60 if busy else 1 / 30) - (time.perf_counter() - now)
                if spare > 0:
                    time.sleep(spare)
        finally:
            self.close()
        return 0

    def close(self) -> None:
        """Release every GPU object, then the window."""
        if self.window is None:
            return
        try:
            for shown in self._shown.values():
                shown.impl.release(shown.handle)
            self._shown.clear()
            self.renderer.release()
            self.gl.release()
            self.ctx.release()
        finally:
            self.window.close()
            self.window = None


def run_viewer(thing, name: str = "scene", **kwargs) -> int:
    """Open the viewer on ``thing`` and run it until closed; the exit status."""
    return Viewer(thing, name, **kwargs).run()
