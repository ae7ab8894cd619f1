"""The viewer's scene image: the selected renderer's view of the current data,
drawn through the :class:`~aniso3d.rendering.renderer.Renderer`'s per-method
renderers into an offscreen framebuffer that the window shows with one quad.

Uploads go to the renderer's upload cache
(:class:`~aniso3d.rendering.cache.Cache`, keyed by the data uploaded, released
through the method renderer when they leave it): data is uploaded once per
method when it becomes ready, found again when the user switches back, and a
method keeps drawing its previous data while a rebuild runs. Each frame's
draw options are the method renderer's own ``Options`` dataclass, built from
the fields it declares, and its :class:`~aniso3d.rendering.frame.DrawStats`
go to the overlay. A renderer that fails to start, to take its data, or to
draw is reported in the frame (and its traceback on stderr) instead of taking
the window down.

A :class:`~aniso3d.build.scene.Scene` of instances is drawn by the
renderer's own scene path (:func:`~aniso3d.rendering.scene_draw.upload_scene`
each frame, as :meth:`Renderer.render <aniso3d.rendering.renderer.Renderer.render>`
does: cache hits once its assets are uploaded, then
:func:`~aniso3d.rendering.scene_draw.draw_scene`), its conversions made
beforehand in the background (:mod:`aniso3d.app.viewer.data`).
"""

from __future__ import annotations

import sys
import time
import traceback
from dataclasses import dataclass

import moderngl
import numpy as np

from aniso3d.app.viewer.data import Conversions, describe_data, describe_key
from aniso3d.app.viewer.state import METHOD_LABELS, Settings, ViewState, settings_text
from aniso3d.rendering.base import DrawOptions, MethodRenderer
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.frame import DrawStats, FrameView
from aniso3d.rendering.renderer import BuildOptions, Renderer
from aniso3d.rendering.scene_draw import SceneUpload, draw_scene, scene_clip_range, upload_scene


@dataclass
class Shown:
    """What a method shows: the data key, the data itself (held, so that its
    upload stays in the cache's reach while it is shown), the method renderer
    and a count for the overlay."""

    key: tuple
    data: object
    impl: object
    counts: str


@dataclass
class Frame:
    """What the scene shows: state is ready, stale (older settings while a
    build runs), building, unavailable (the method cannot draw this input)
    or failed; message says why; stats is what the last draw returned."""

    state: str
    impl: object = None
    shown: Shown | None = None
    message: str = ""
    key: tuple | None = None  # the data being built, when building
    stats: DrawStats | None = None


def draw_options(impl: MethodRenderer, settings: Settings) -> tuple[DrawOptions, int]:
    """The method renderer's ``Options`` for the viewer's settings, made from
    the fields it declares (``splat``, ``quality``), and the supersampling the
    viewer adds for "high" quality where the renderer has no quality option of
    its own (the polygons: 2x2 samples per pixel)."""
    names = impl.Options.names()
    values = {name: getattr(settings, name) for name in ("splat", "quality") if name in names}
    ssaa = 2 if settings.quality == "high" and "quality" not in names else 1
    return impl.Options(**values), ssaa


class SceneView:
    """Draws the state's view into an offscreen framebuffer when asked
    (:meth:`render`); ``say`` receives the log lines (uploads, the settled state)."""

    def __init__(self, gl: GLContext, renderer: Renderer, data: Conversions, bounds: np.ndarray, say):
        self.gl, self.renderer, self.data, self.bounds, self._say = gl, renderer, data, bounds, say
        self._shown: dict[str, Shown] = {}  # method -> what is uploaded for it
        self._start_errors: dict[str, str] = {}  # method -> why its renderer did not start
        self._upload_errors: dict[tuple, str] = {}  # (method, data key) -> why the upload failed
        self._draw_error: str | None = None
        self._scene_uploaded: set[tuple] = set()  # (method, data key) of a scene, logged once
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
            try:
                self.handle(method, impl, data, key)
            except Exception as exc:  # not retried: the settings must change first
                traceback.print_exc(file=sys.stderr)
                failed = self._upload_errors[(method, key)] = (
                    f"the {METHOD_LABELS[method]} renderer could not take the {describe_key(key)}: "
                    f"{type(exc).__name__}: {exc}"
                )
            else:
                shown = self._shown[method] = Shown(key, data, impl, describe_data(data))
        if failed is not None and (shown is None or shown.key != key):
            return Frame("failed", impl, message=failed)
        if shown is None:
            return Frame("building", impl, message=f"building the {describe_key(key)}…", key=key)
        return Frame("stale" if shown.key != key else "ready", impl, shown)

    def handle(self, method: str, impl: MethodRenderer, data, key: tuple):
        """The GPU handle of ``data`` for ``method``: from the renderer's upload
        cache, or uploaded now (and logged) if it is not there (first use, or
        evicted since). For a scene: its :class:`SceneUpload`, from the
        renderer's scene path."""
        if self.data.kind == "scene":
            return self._scene_handle(method, key)
        uploads = self.renderer.uploads
        ukey = ("viewer upload", method)
        handle = uploads.get(data, ukey)
        if handle is None:
            t0 = time.perf_counter()
            handle = uploads.put(data, ukey, impl.upload(data), release=self._releaser(impl))
            self._say(
                f"uploaded {describe_key(key)} for {METHOD_LABELS[method]} in {time.perf_counter() - t0:.2f} s"
            )
        return handle

    def _scene_handle(self, method: str, key: tuple) -> SceneUpload:
        """The scene's upload for ``method`` and data ``key``: every asset
        uploaded through the renderer's caches (its conversions are there
        already: the data key is ready); the first upload of a key is logged."""
        build = BuildOptions()
        if key[0] != "scene":
            build = BuildOptions(resolution=key[1], directions=key[2],
                                 placement=key[3] if key[0] == "scene points" else "centroid")  # fmt: skip
        t0 = time.perf_counter()
        up = upload_scene(self.renderer, self.data.thing, method, build)
        if (method, key) not in self._scene_uploaded:
            self._scene_uploaded.add((method, key))
            what = "scene's assets" if key[0] == "scene" else describe_key(key)
            self._say(f"uploaded the {what} for {METHOD_LABELS[method]} in {time.perf_counter() - t0:.2f} s")
        return up

    def _releaser(self, impl: MethodRenderer):
        def release(handle) -> None:
            if self.gl.ctx is not None:  # a context released first took its objects along
                impl.release(handle)

        return release

    def collect(self) -> None:
        """Once per frame: release the uploads of data no longer held anywhere."""
        self.renderer.uploads.collect()
        self.data.cache.collect()

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

    def render(self, state: ViewState, size: tuple[int, int]) -> Frame:
        """Draw the view for a window of ``size`` (w, h) pixels; logs the settled state when it changes."""
        w, h = size
        if w < 1 or h < 1:
            return self.frame
        s = state.settings
        frame = self.current(state)
        options, ssaa = draw_options(frame.impl, s) if frame.shown is not None else (None, 1)
        if max(w, h) * ssaa > min(self.gl.max_texture_size, *self.gl.max_viewport):
            ssaa = 1
        fsize = (w * ssaa, h * ssaa)
        fbo = self._target(fsize)
        fbo.use()
        self.gl.ctx.viewport = (0, 0, *fsize)
        bg = self.renderer.lighting.background
        fbo.clear(bg[0], bg[1], bg[2], 0.0, depth=1.0)
        if frame.shown is not None:
            shown = frame.shown
            try:
                handle = self.handle(s.method, shown.impl, shown.data, shown.key)
                camera = state.orbit.camera()
                if isinstance(handle, SceneUpload):
                    near, far = scene_clip_range(handle, camera)
                else:
                    near, far = camera.clip_range(handle.bounds)
                view = FrameView(camera, self.renderer.lighting, fsize, near, far, ssaa)
                fbo.use()
                t0 = time.perf_counter()
                if isinstance(handle, SceneUpload):  # the renderer's scene path
                    frame.stats = draw_scene(shown.impl, handle, view, fbo, options)
                else:
                    fresh = {"cleared": True} if shown.impl.method == "splat" else {}  # fbo cleared above
                    frame.stats = shown.impl.draw(handle, view, fbo=fbo, options=options, **fresh)
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
        """Forget what is shown; the uploads are the renderer's to release
        (:meth:`Renderer.release <aniso3d.rendering.renderer.Renderer.release>`),
        the framebuffer goes with the GLContext."""
        self._shown.clear()
