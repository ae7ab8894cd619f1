"""The viewer's scene image: the selected renderer's view of the current data,
drawn through the :class:`~aniso3d.rendering.renderer.Renderer`'s per-method
renderers into an offscreen framebuffer that the window shows with one quad.

Data is uploaded once per method when it becomes ready and kept until newer
data replaces it, so the previous image stays while a rebuild runs. A renderer
that fails to start, to take its data, or to draw is reported in the frame
(and its traceback on stderr) instead of taking the window down.
"""

from __future__ import annotations

import inspect
import sys
import time
import traceback
from dataclasses import dataclass

import moderngl
import numpy as np

from aniso3d.app.viewer.data import Conversions, describe_data, describe_key
from aniso3d.app.viewer.state import METHOD_LABELS, ViewState, settings_text
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.renderer import Renderer


@dataclass
class Shown:
    """A method's uploaded data: its key, GPU handle, renderer and a count for the overlay."""

    key: tuple
    handle: object
    impl: object
    counts: str


@dataclass
class Frame:
    """What the scene shows: state is ready, stale (older settings while a
    build runs), building, unavailable (the method cannot draw this input)
    or failed; message says why."""

    state: str
    impl: object = None
    shown: Shown | None = None
    message: str = ""
    key: tuple | None = None  # the data being built, when building


def takes_option(impl, name: str) -> bool:
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


class SceneView:
    """Draws the state's view into an offscreen framebuffer when asked
    (:meth:`render`); ``say`` receives the log lines (uploads, the settled state)."""

    def __init__(self, gl: GLContext, renderer: Renderer, data: Conversions, bounds: np.ndarray, say):
        self.gl, self.renderer, self.data, self.bounds, self._say = gl, renderer, data, bounds, say
        self._shown: dict[str, Shown] = {}  # method -> what is uploaded for it
        self._start_errors: dict[str, str] = {}  # method -> why its renderer did not start
        self._upload_errors: dict[tuple, str] = {}  # (method, data key) -> why the upload failed
        self._draw_error: str | None = None
        self.frame = Frame("building")
        #: Smoothed draw time of the scene, ms; None until the first frame of a regime.
        self.frame_ms: float | None = None
        #: The last settled state in words (the log's "showing ..." line).
        self.status = ""
        self.fbo: moderngl.Framebuffer | None = None
        self._size = (0, 0)

    def reselect(self, method: str) -> None:
        """The user picked ``method`` again: try its renderer afresh."""
        self._start_errors.pop(method, None)
        self._draw_error = None
        self.frame_ms = None

    # -------------------------------------------------------------- frame

    def _impl(self, method: str):
        """(per-method renderer, None), or (None, why it did not start)."""
        err = self._start_errors.get(method)
        if err is not None:
            return None, err
        try:
            return self.renderer.method_renderer(method), None
        except Exception as exc:  # a renderer failing to start must not take the window down
            traceback.print_exc(file=sys.stderr)
            err = self._start_errors[method] = (
                f"the {METHOD_LABELS[method]} renderer failed to start: {type(exc).__name__}: {exc}"
            )
            return None, err

    def current(self, state: ViewState) -> Frame:
        """What to draw for the selected method, uploading data that just became ready."""
        method = state.settings.method
        impl, why = self._impl(method)
        if impl is None:
            return Frame("failed", message=why)
        key, why = self.data.requirement(state, method)
        if key is None:
            return Frame("unavailable", impl, message=why)
        shown = self._shown.get(method)
        data = self.data.lookup(key)
        failed = self.data.failed.get(key) or self._upload_errors.get((method, key))
        if data is not None and (shown is None or shown.key != key) and failed is None:
            label = METHOD_LABELS[method]
            try:
                t0 = time.perf_counter()
                handle = impl.upload(data)
                self._say(f"uploaded {describe_key(key)} for {label} in {time.perf_counter() - t0:.2f} s")
            except Exception as exc:  # not retried: the settings must change first
                traceback.print_exc(file=sys.stderr)
                failed = self._upload_errors[(method, key)] = (
                    f"the {label} renderer could not take the {describe_key(key)}: {type(exc).__name__}: {exc}"
                )
            else:
                if shown is not None:
                    shown.impl.release(shown.handle)
                shown = self._shown[method] = Shown(key, handle, impl, describe_data(data))
        if failed is not None and (shown is None or shown.key != key):
            return Frame("failed", impl, message=failed)
        if shown is None:
            return Frame("building", impl, message=f"building the {describe_key(key)}…", key=key)
        return Frame("stale" if shown.key != key else "ready", impl, shown)

    def _target(self, size: tuple[int, int]) -> moderngl.Framebuffer:
        if self.fbo is not None and self._size == size:
            return self.fbo
        if self.fbo is not None:
            self.gl.free(*self.fbo.color_attachments, self.fbo.depth_attachment, self.fbo)
        ctx = self.gl.ctx
        color = self.gl.track(ctx.texture(size, 4, dtype="f1"))
        color.filter = (moderngl.LINEAR, moderngl.LINEAR)  # the 2x2 box filter when supersampled
        color.repeat_x = color.repeat_y = False
        depth = self.gl.track(ctx.depth_texture(size))
        self.fbo = self.gl.track(ctx.framebuffer(color_attachments=[color], depth_attachment=depth))
        self._size = size
        return self.fbo

    def _draw_options(self, impl, quality: str, splat: str) -> tuple[dict, int]:
        """Options the renderer takes, and the supersampling the viewer adds
        for "high" quality where the renderer has no quality option of its own
        (the polygons: 2x2 samples per pixel)."""
        options = {}
        if takes_option(impl, "splat"):
            options["splat"] = splat
        if takes_option(impl, "quality"):
            options["quality"] = quality
            return options, 1
        return options, 2 if quality == "high" else 1

    def render(self, state: ViewState, size: tuple[int, int]) -> Frame:
        """Draw the view for a window of ``size`` (w, h) pixels; logs the settled state when it changes."""
        w, h = size
        if w < 1 or h < 1:
            return self.frame
        s = state.settings
        frame = self.current(state)
        options, ssaa = self._draw_options(frame.impl, s.quality, s.splat) if frame.shown is not None else ({}, 1)
        if max(w, h) * ssaa > min(self.gl.max_texture_size, *self.gl.max_viewport):
            ssaa = 1
        fsize = (w * ssaa, h * ssaa)
        fbo = self._target(fsize)
        fbo.use()
        self.gl.ctx.viewport = (0, 0, *fsize)
        bg = self.renderer.lighting.background
        fbo.clear(bg[0], bg[1], bg[2], 0.0, depth=1.0)
        if frame.shown is not None:
            camera = state.orbit.camera()
            near, far = camera.clip_range(getattr(frame.shown.handle, "bounds", self.bounds))
            view = FrameView(camera, self.renderer.lighting, fsize, near, far, ssaa)
            try:
                t0 = time.perf_counter()
                frame.impl.draw(frame.shown.handle, view, fbo=fbo, **options)
                self.gl.ctx.finish()  # time the whole frame, not just queueing its commands
                ms = 1000.0 * (time.perf_counter() - t0)
                self.frame_ms = ms if self.frame_ms is None else 0.7 * self.frame_ms + 0.3 * ms
                self._draw_error = None
            except Exception as exc:  # a renderer bug shows on screen; the window stays
                if self._draw_error is None:
                    traceback.print_exc(file=sys.stderr)
                self._draw_error = f"the {METHOD_LABELS[s.method]} renderer failed: {type(exc).__name__}: {exc}"
                frame = Frame("failed", frame.impl, message=self._draw_error)
                fbo.use()
                fbo.clear(bg[0], bg[1], bg[2], 0.0, depth=1.0)
        self.frame = frame
        self._announce(state, size)
        return frame

    def _announce(self, state: ViewState, size: tuple[int, int]) -> None:
        """Log the settled state when it changes (the tests wait for these lines)."""
        frame, method = self.frame, state.settings.method
        if frame.state == "ready":
            status = (f"showing {method} ({frame.shown.counts}) at {size[0]}x{size[1]}, "
                      f"{settings_text(state.settings, state.kind)}")  # fmt: skip
        elif frame.state == "stale":
            status = f"building {method}: showing the previous {METHOD_LABELS[method]} meanwhile"
        else:
            status = f"{frame.state} {method}: {frame.message}"
        if status != self.status:
            self.status = status
            self._say(status)

    @property
    def image(self):
        """The scene's colour texture (None before the first :meth:`render`)."""
        return None if self.fbo is None else self.fbo.color_attachments[0]

    def release(self) -> None:
        """Release the uploads (the framebuffer goes with the GLContext)."""
        for shown in self._shown.values():
            shown.impl.release(shown.handle)
        self._shown.clear()
