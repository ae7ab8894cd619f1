"""The viewer's window: a pyglet window (optional extra ``aniso3d[viewer]``)
and its OpenGL context, the event wiring, and the main loop that ties the
state, the background builds, the scene and the overlay together.

pyglet is imported only inside :func:`open_window` and
:meth:`Viewer._install_handlers`, so this module (and ``aniso3d view``'s
one-line message where pyglet or a display is missing) works without it.

The log (one line per change on stdout, ``aniso3d view: ...``) is a record
for the user and what the tests wait for. After each buffer swap that shows
something new since the last such line, the viewer logs
``frame N presented (overlay on|off; idle|building WHAT): STATUS``, N counting
every presented frame; a screenshot is the frame presented on its key press,
logged as ``screenshot saved to PATH (frame N)`` and recorded in the PNG's
text (``aniso3d frame``: N, ``aniso3d state``: STATUS). A test that sends a key
thus waits for the state's line, then for a frame presented after it, before
it looks.
"""

from __future__ import annotations

import importlib.util
import io
import os
import sys
import time
from pathlib import Path

import moderngl
import numpy as np

from aniso3d.app.viewer.data import CACHE_BYTES, Conversions, cache_entries
from aniso3d.app.viewer.overlay import GREEN, MARGIN, RED, WHITE, YELLOW, Overlay, key_lines, status_lines, wrap
from aniso3d.app.viewer.scene import SceneView
from aniso3d.app.viewer.state import KEYS, Settings, ViewState
from aniso3d.errors import InputError, ResourceError
from aniso3d.files import atomic_write
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.renderer import Renderer

HEADLESS_HINT = (
    "for images without a window use the headless CLI: 'aniso3d render [INPUT] -o out.png' "
    "(or 'aniso3d frames' for a turntable)"
)
#: Seconds a notice stays in the status panel (errors: twice as long).
NOTICE_SECONDS = 4.0
#: Prefix of a screenshot's PNG text keys: "aniso3d frame" (the frame's number), "aniso3d state".
SCREENSHOT_TEXT = "aniso3d"
#: Frame pacing: frames per second while something moves or builds, and while idle.
BUSY_FPS, IDLE_FPS = 60, 30


def save_screenshot(path: Path, image: np.ndarray, text: dict[str, str]) -> Path:
    """Write an (H, W, 3) uint8 image as PNG, atomically, with ``text`` as its
    text chunks under keys prefixed :data:`SCREENSHOT_TEXT` ("aniso3d frame": "12")."""
    from PIL import Image
    from PIL.PngImagePlugin import PngInfo

    info = PngInfo()
    for key, value in text.items():
        info.add_itxt(f"{SCREENSHOT_TEXT} {key}", value)
    buf = io.BytesIO()
    Image.fromarray(image).save(buf, format="PNG", pnginfo=info)
    return atomic_write(path, buf.getvalue())


def check_display() -> None:
    """Raise :class:`ResourceError` with a clear message where no window can
    be opened: no display, or pyglet (the ``viewer`` extra) missing."""
    if sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
        raise ResourceError(
            "no display: 'aniso3d view' opens a window and needs an X display, but DISPLAY is "
            f"not set (over ssh use 'ssh -X', or run under xvfb-run); {HEADLESS_HINT}"
        )
    if importlib.util.find_spec("pyglet") is None:
        raise ResourceError(f"the viewer needs pyglet: pip install 'aniso3d[viewer]'; {HEADLESS_HINT}")


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
        window = pyglet.window.Window(*size, caption=caption, resizable=True, config=config, vsync=False)
    except Exception as exc:  # each platform fails in its own way
        raise ResourceError(
            f"cannot open an OpenGL 3.3 window on {where} ({type(exc).__name__}: {exc}); " + HEADLESS_HINT
        ) from None
    try:
        ctx = moderngl.create_context(require=330)
    except Exception as exc:
        window.close()
        raise ResourceError(
            f"the window on {where} has no usable OpenGL 3.3 core context ({exc}); {HEADLESS_HINT}"
        ) from None
    return window, ctx


class Viewer:
    """The window app. ``thing`` is a :class:`Mesh`, :class:`AnisoTexture`,
    :class:`PointCloud` or :class:`~aniso3d.build.scene.Scene`; ``name`` labels it. Call :meth:`run`; it returns the
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
        self.name = name
        self.state = ViewState.for_input(thing, settings, aspect=size[0] / max(size[1], 1))
        self.screenshot_dir = Path(screenshot_dir)
        if not self.screenshot_dir.is_dir():
            raise InputError(f"screenshot folder '{self.screenshot_dir}' does not exist; create it first")
        self.out = out or sys.stdout
        self.window, self.ctx = open_window(size, f"aniso3d view — {name}")
        try:
            self.gl = GLContext.wrap(self.ctx)
            # One conversion cache and one upload cache, the renderer's, for the whole viewer.
            self.renderer = Renderer(self.window.get_framebuffer_size(), gl=self.gl,
                                     cache_entries=cache_entries(thing), cache_bytes=CACHE_BYTES)  # fmt: skip
            self.data = Conversions(thing, self.state.kind, self.renderer.conversions)
            w, h = self.window.get_framebuffer_size()
            self.state.orbit.reset(w / max(h, 1))
            auto = self.state.resolve_resolution((w, h))
            self.scene = SceneView(self.gl, self.renderer, self.data, self.state.orbit.bounds, self._say)
            self.overlay = Overlay(self.gl, scale=w / max(self.window.width, 1))
            self._install_handlers()
        except BaseException:
            self.window.close()
            raise
        self._quit = False
        self._dirty = True  # the scene must be drawn again
        self._dragging = False
        self._notice: tuple[str, float, tuple] = ("", 0.0, WHITE)
        self._frames = 0  # frames presented
        self._unpresented = False  # a line was logged since the last "frame N presented"
        self._say(f"window {self.window.width}x{self.window.height}, OpenGL {self.gl.version} ({self.gl.renderer})")
        if auto:
            self._say(auto)

    # ------------------------------------------------------------- events

    def _install_handlers(self) -> None:
        import pyglet
        from pyglet.window import key, mouse

        win = self.window
        handled = pyglet.event.EVENT_HANDLED
        actions = {getattr(key, name): action for name, action in KEYS.items()}

        @win.event
        def on_key_press(symbol, modifiers):
            if modifiers & (key.MOD_CTRL | key.MOD_ALT | key.MOD_COMMAND):
                return None  # leave ctrl/alt combinations to the system
            action = actions.get(symbol)
            if action is not None:
                self.press(action)
            return handled  # also keeps pyglet's own Esc handler out

        @win.event
        def on_mouse_press(x, y, button, modifiers):
            self._dragging = False
            return handled

        @win.event
        def on_mouse_drag(x, y, dx, dy, buttons, modifiers):
            self._dragging = True
            if buttons & (mouse.RIGHT | mouse.MIDDLE) or (buttons & mouse.LEFT and modifiers & key.MOD_SHIFT):
                self.state.orbit.pan(dx, dy, win.height)
            elif buttons & mouse.LEFT:
                self.state.orbit.rotate(dx, dy)
            self._dirty = True
            return handled

        @win.event
        def on_mouse_release(x, y, button, modifiers):
            if self._dragging:
                self._say(f"camera {self.state.orbit.describe()}")
            self._dragging = False
            return handled

        @win.event
        def on_mouse_scroll(x, y, scroll_x, scroll_y):
            self.state.orbit.zoom(scroll_y)
            self._dirty = True
            return handled

        @win.event
        def on_resize(width, height):
            self._dirty = True
            return handled  # pyglet's default sets up its own projection; not ours

        @win.event
        def on_close():
            self._quit = True
            return handled

        @win.event
        def on_expose():
            self._dirty = True

    def press(self, action: str) -> None:
        """Do what a key does (see :data:`~aniso3d.app.viewer.state.KEYS`)."""
        w, h = self.window.get_framebuffer_size()
        reply = self.state.press(action, aspect=w / max(h, 1))
        if reply.quit:
            self._quit = True
            return
        if reply.screenshot:
            self.screenshot()
            return
        if reply.notice:
            self._notify(reply.text, YELLOW)
        elif reply.text:
            self._say(reply.text)
        if "method" in reply.changed:
            self.scene.reselect(self.state.settings.method)
        elif {"quality", "splat"} & set(reply.changed):
            self.scene.frame_ms = None  # another frame-time regime: average afresh
        self._dirty = True

    def _notify(self, text: str, color=WHITE, seconds: float = NOTICE_SECONDS) -> None:
        """Log ``text`` and show it in the status panel for ``seconds``."""
        self._notice = (text, time.perf_counter() + seconds, color)
        self._say(text)

    def _say(self, text: str) -> None:
        """One line of the viewer's log on stdout (the tests read it)."""
        self._unpresented = True
        self._write(text)

    def _write(self, text: str) -> None:
        print(f"aniso3d view: {text}", file=self.out, flush=True)

    # ------------------------------------------------------------- frames

    def _compose(self, now: float) -> None:
        """Draw the window: the scene image, then the overlay panels."""
        size = w, h = self.window.get_framebuffer_size()
        ov, frame, builder, s = self.overlay, self.scene.frame, self.data.builder, self.state.settings
        ov.begin(size)
        if self.scene.image is not None:
            ov.blit(self.scene.image, (0, 0, w, h), size, flip=False, opaque=True)
        ov.blend(True)
        if frame.message:
            color = {"building": WHITE, "unavailable": YELLOW}.get(frame.state, RED)
            text = frame.message
            if frame.state == "building" and builder.busy and builder.key == frame.key:
                text += f" {100 * builder.fraction:.0f}% {builder.elapsed():.1f} s"
            elif frame.state == "building" and builder.busy:
                then = "stops" if builder.cancelling else "is done"
                text += f" (once the {builder.label} under way {then})"
            ov.place("center", wrap(text, ov.big_font, w, color), size, None, None, big=True)
        building = builder.describe() if builder.busy else None
        if s.overlay:
            text, until, color = self._notice
            notice = (text, color) if text and now < until else None
            timing = ov.timing(self.scene.frame_ms, now)
            lines = status_lines(self.name, self.state, frame, timing, size, building, notice)
            ov.place("status", lines, size, MARGIN, MARGIN)
            ov.place("keys", key_lines(ov.font, w - 2 * MARGIN - 16), size, MARGIN, -MARGIN)
        elif building:  # the building state stays visible without the overlay
            ov.place("badge", [(building, YELLOW)], size, -MARGIN, MARGIN)
        ov.blend(False)

    def _present(self, capture: bool = False) -> np.ndarray | None:
        """Draw the scene (if it changed) and the overlay, swap buffers, count
        the frame, and log it if it shows something new since the last frame
        logged. ``capture``: the frame's pixels, (H, W, 3) uint8, top row first."""
        if self._dirty:
            self._dirty = False
            self.scene.render(self.state, self.window.get_framebuffer_size())
        self._compose(time.perf_counter())
        image = None
        if capture:  # the back buffer: what the swap below presents
            w, h = self.window.get_framebuffer_size()
            raw = self.ctx.screen.read(viewport=(0, 0, w, h), components=3, alignment=1)
            image = np.ascontiguousarray(np.frombuffer(raw, dtype=np.uint8).reshape(h, w, 3)[::-1])
        self.window.flip()
        self._frames += 1
        if self._unpresented:
            self._unpresented = False
            builder = self.data.builder
            build = f"building {builder.label}" if builder.busy else "idle"
            overlay = "on" if self.state.settings.overlay else "off"
            self._write(f"frame {self._frames} presented (overlay {overlay}; {build}): {self.scene.status}")
        return image

    def screenshot(self) -> None:
        """Present a frame now, after the events before this key (not after
        later ones in the same batch), and save it as the next
        ``aniso3d-view-NNN.png`` in the screenshot folder, with the frame's
        number and state in the PNG's text (:data:`SCREENSHOT_TEXT`)."""
        image = self._present(capture=True)
        n = 1
        while (self.screenshot_dir / f"aniso3d-view-{n:03d}.png").exists():
            n += 1
        text = {"frame": str(self._frames), "state": self.scene.status}
        try:
            path = save_screenshot(self.screenshot_dir / f"aniso3d-view-{n:03d}.png", image, text)
        except OSError as exc:
            self._notify(f"screenshot not saved: {exc}", RED)
            return
        self._notify(f"screenshot saved to {path} (frame {self._frames})", GREEN)

    # ---------------------------------------------------------------- loop

    def run(self) -> int:
        """The main loop; returns 0 when closed by q, Esc or the close button."""
        win, state = self.window, self.state
        last = time.perf_counter()
        try:
            while not self._quit:
                win.dispatch_events()
                if self._quit or win.has_exit:
                    break
                now = time.perf_counter()
                dt, last = now - last, now
                done = self.data.collect()
                if done is not None:
                    if done.error:
                        self._notify(done.text, RED, 2 * NOTICE_SECONDS)
                    else:
                        self._say(done.text)
                    self._dirty = True
                self.scene.collect()
                started = self.data.schedule(state)
                if started is not None:
                    self._say(f"building {started}")
                if state.settings.turntable:
                    state.orbit.spin(dt)
                    self._dirty = True
                self._present()
                busy = state.settings.turntable or self.data.builder.busy or self._dragging
                # Pace the loop: events are answered at this rate, and the CPU is left to the build.
                spare = 1 / (BUSY_FPS if busy else IDLE_FPS) - (time.perf_counter() - now)
                if spare > 0:
                    time.sleep(spare)
        finally:
            builder = self.data.builder
            if builder.running:
                # Cancelled (it stops at its next progress report); a daemon
                # thread, so nothing here waits for it.
                builder.cancel()
                self._write(f"quit while building {builder.label}: cancelled, not waiting for it")
            self.close()
        return 0

    def close(self) -> None:
        """Release every GPU object, then the window."""
        if self.window is None:
            return
        try:
            self.scene.release()
            self.renderer.release()
            self.gl.release()
            self.ctx.release()
        finally:
            self.window.close()
            self.window = None


def run_viewer(thing, name: str = "scene", **kwargs) -> int:
    """Open the viewer on ``thing`` and run it until closed; the exit status."""
    return Viewer(thing, name, **kwargs).run()
