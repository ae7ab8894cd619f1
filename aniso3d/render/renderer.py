"""The batch-frame Python API: one :class:`Renderer`, three methods.

``Renderer.render(thing, camera, method=...)`` draws a mesh, texture or point
cloud and returns an (H, W, 3) uint8 image (row 0 at the top). Conversions
(mesh -> texture -> points) and GPU uploads happen once per thing and options,
and are reused across frames.

``lod=True`` (methods "splat" and "volume", a mesh or texture) draws from the
texture's exact pyramid (:mod:`aniso3d.build.pyramid`), built and uploaded once: splats
select per frame, per region, the coarsest level whose voxels cover at most
``pixel_error`` framebuffer pixels and draw only those points; the volume
renderer marches, per frame, the one level fine enough at the object's
nearest visible depth. :attr:`Renderer.last_lod_stats` holds the frame's
selection.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import moderngl
import numpy as np

from aniso3d.build.mesh import Mesh
from aniso3d.build.points import PointCloud
from aniso3d.build.pyramid import LodPoints, Pyramid, pyramid
from aniso3d.build.texture import DEFAULT_DIRECTIONS, DEFAULT_RESOLUTION, AnisoTexture, build_texture
from aniso3d.errors import InputError
from aniso3d.render.camera import Camera
from aniso3d.render.context import GLContext
from aniso3d.render.frame import FrameView
from aniso3d.render.lighting import Lighting

METHODS = ("mesh", "volume", "splat")

#: Options that change how a thing is converted (and so key the upload cache).
BUILD_OPTIONS = ("resolution", "directions", "placement", "per_entry", "point_normal")
DEFAULT_BUILD = {"resolution": DEFAULT_RESOLUTION, "directions": DEFAULT_DIRECTIONS,
                 "placement": "centroid", "per_entry": 1, "point_normal": "mean"}  # fmt: skip


def check_size(size) -> tuple[int, int]:
    try:
        w, h = (int(size[0]), int(size[1]))
    except (TypeError, ValueError, IndexError):
        raise InputError(f"image size must be (width, height), got {size!r}") from None
    if w < 1 or h < 1:
        raise InputError(f"image size must be at least 1x1 pixels, got {w}x{h}")
    if max(w, h) > 16384:
        raise InputError(f"image size {w}x{h} is above the maximum of 16384 pixels a side")
    return w, h


def _downsample(img: np.ndarray, s: int) -> np.ndarray:
    """Box-filter an (H*s, W*s, C) float image by s."""
    if s == 1:
        return img
    h, w, c = img.shape
    return img.reshape(h // s, s, w // s, s, c).mean(axis=(1, 3))


class Renderer:
    """Draws meshes, anisotropic textures and point clouds with one camera and
    one lighting model.

    Args:
        size: (width, height) of the images, pixels.
        lighting: the shared lighting model (default :class:`Lighting`).
        gl: a :class:`GLContext` to draw with; by default one is made (and
            released with the renderer).
        backend: OpenGL backend for the context made here ("auto", "egl", ...).
    """

    def __init__(
        self,
        size=(512, 512),
        lighting: Lighting | None = None,
        gl: GLContext | None = None,
        backend: str = "auto",
    ):
        self.size = check_size(size)
        self.lighting = lighting or Lighting()
        self._own_gl = gl is None
        self.gl = gl or GLContext(backend)
        self._impl: dict[str, object] = {}
        self._converted: dict[tuple, tuple[object, object]] = {}
        self._uploads: dict[tuple, tuple[object, object]] = {}
        self._fbos: dict[tuple[int, int], moderngl.Framebuffer] = {}
        self._pyramids: dict[int, tuple[AnisoTexture, Pyramid]] = {}
        self.last_frame_seconds = 0.0
        #: Selection of the last ``lod=True`` frame (None after other frames):
        #: for splats ``points`` drawn, ``points_per_level``, ``culled``
        #: voxels, ``selection_ms``...; for the volume the ``level`` drawn.
        self.last_lod_stats: dict | None = None

    # ----------------------------------------------------------- plumbing

    def method_renderer(self, method: str):
        """The per-method renderer object (made on first use)."""
        if method not in METHODS:
            raise InputError(f"unknown render method '{method}'; choose one of {', '.join(METHODS)}")
        impl = self._impl.get(method)
        if impl is None:
            if method == "mesh":
                from aniso3d.render.polygon import MeshRenderer as cls
            elif method == "splat":
                from aniso3d.render.splat import SplatRenderer as cls
            else:
                from aniso3d.render.volume import VolumeRenderer as cls
            impl = self._impl[method] = cls(self.gl)
        return impl

    def _convert(self, thing, method: str, build: dict):
        """``thing`` as what ``method`` draws: Mesh, AnisoTexture or PointCloud."""
        want = {"mesh": Mesh, "volume": AnisoTexture, "splat": PointCloud}[method]
        if isinstance(thing, want):
            return thing
        if method == "mesh":
            raise InputError(
                f"the polygon renderer needs a mesh, got {type(thing).__name__}: "
                "a texture or point cloud no longer has its polygons"
            )
        if isinstance(thing, PointCloud):
            raise InputError("a point cloud can only be drawn with method 'splat'")
        key = (id(thing), method, tuple(sorted(build.items())))
        hit = self._converted.get(key)
        if hit is not None and hit[0] is thing:
            return hit[1]
        tex = thing
        if isinstance(thing, Mesh):
            tkey = (id(thing), "volume", (("directions", build["directions"]), ("resolution", build["resolution"])))
            cached = self._converted.get(tkey)
            if cached is not None and cached[0] is thing:
                tex = cached[1]
            else:
                tex = build_texture(thing, build["resolution"], build["directions"])
                self._converted[tkey] = (thing, tex)
        if not isinstance(tex, AnisoTexture):
            raise InputError(f"cannot render a {type(thing).__name__}; pass a Mesh, AnisoTexture or PointCloud")
        out = tex
        if method == "splat" and build["per_entry"] == "adaptive":  # counts per entry (build/pyramid.py)
            opts = (build["placement"], "adaptive", build["point_normal"])
            out = self.pyramid(tex).level_cloud(0, *opts)[0]
        elif method == "splat":
            out = tex.to_points(build["placement"], build["per_entry"], build["point_normal"])
        self._converted[key] = (thing, out)
        return out

    def pyramid(self, thing, **build) -> Pyramid:
        """The texture pyramid of ``thing`` (a mesh is converted with the
        build options ``resolution`` and ``directions`` first); built once
        per texture."""
        if isinstance(thing, PointCloud):
            raise InputError(
                "level of detail needs a mesh or a texture: a point cloud has no texture pyramid"
            )
        opts = {**DEFAULT_BUILD, **{k: v for k, v in build.items() if v is not None}}
        tex = self._convert(thing, "volume", opts)
        hit = self._pyramids.get(id(tex))
        if hit is None or hit[0] is not tex:
            hit = self._pyramids[id(tex)] = (tex, pyramid(tex))
        return hit[1]

    def _upload_lod(self, thing, method: str, build: dict):
        """Upload (once) the pyramid of ``thing`` for ``method``."""
        if method not in ("splat", "volume"):
            raise InputError(
                f"level of detail applies to the splat and volume methods, not '{method}'"
            )
        opts = {**DEFAULT_BUILD, **{k: v for k, v in build.items() if v is not None}}
        unknown = set(opts) - set(BUILD_OPTIONS)
        if unknown:
            raise InputError(f"unknown build option(s) {sorted(unknown)}; known: {BUILD_OPTIONS}")
        key = (id(thing), method, tuple(sorted(opts.items())) + (("lod", True),))
        hit = self._uploads.get(key)
        if hit is not None and hit[0] is thing:
            return hit[1]
        pyr = self.pyramid(thing, **opts)
        if method == "splat":
            data = LodPoints(pyr, opts["placement"], opts["per_entry"], opts["point_normal"])
        else:
            data = pyr
        handle = self.method_renderer(method).upload(data)
        self._uploads[key] = (thing, handle)
        return handle

    def upload(self, thing, method: str, **build):
        """Convert and upload ``thing`` for ``method`` (cached); returns the handle."""
        if method not in METHODS:
            raise InputError(f"unknown render method '{method}'; choose one of {', '.join(METHODS)}")
        opts = {**DEFAULT_BUILD, **{k: v for k, v in build.items() if v is not None}}
        unknown = set(opts) - set(BUILD_OPTIONS)
        if unknown:
            raise InputError(f"unknown build option(s) {sorted(unknown)}; known: {BUILD_OPTIONS}")
        key = (id(thing), method, tuple(sorted(opts.items())))
        hit = self._uploads.get(key)
        if hit is not None and hit[0] is thing:
            return hit[1]
        data = self._convert(thing, method, opts)
        handle = self.method_renderer(method).upload(data)
        self._uploads[key] = (thing, handle)
        return handle

    def _fbo(self, size: tuple[int, int]) -> moderngl.Framebuffer:
        fbo = self._fbos.get(size)
        if fbo is None:
            ctx = self.gl.ctx
            color = self.gl.track(ctx.texture(size, 4, dtype="f1"))
            depth = self.gl.track(ctx.depth_texture(size))
            fbo = self.gl.track(ctx.framebuffer(color_attachments=[color], depth_attachment=depth))
            self._fbos[size] = fbo
        return fbo

    # ------------------------------------------------------------- frames

    def render(
        self,
        thing,
        camera: Camera,
        method: str | None = None,
        ssaa: int = 1,
        alpha: bool = False,
        size=None,
        **options,
    ) -> np.ndarray:
        """Draw ``thing`` seen by ``camera``; returns (H, W, 3 or 4) uint8.

        ``method`` defaults to what the thing is: mesh -> "mesh", texture ->
        "volume", point cloud -> "splat". ``ssaa`` draws at ssaa x ssaa samples
        per pixel and box-filters. Build options (resolution, directions,
        placement, per_entry, point_normal) choose the conversion; other
        options go to the method's renderer (e.g. ``splat="disc"``,
        ``quality="high"``).

        ``lod=True`` (splat and volume, from a mesh or texture) draws from the
        texture's pyramid with the screen-space error ``pixel_error``
        (framebuffer pixels, default 1: with ``ssaa`` the selection is made
        for the supersampled framebuffer); the clip range comes from every
        level's bounds, not from what a frame selects. The frame's selection
        is kept in :attr:`last_lod_stats`.
        """
        if not isinstance(camera, Camera):
            raise InputError(f"render needs an aniso3d.Camera, got {type(camera).__name__}")
        if method is None:
            kinds = ((AnisoTexture, "volume"), (PointCloud, "splat"))
            method = next((m for cls, m in kinds if isinstance(thing, cls)), "mesh")
        if isinstance(ssaa, bool) or int(ssaa) != ssaa or ssaa < 1:
            raise InputError(f"supersampling factor must be a whole number >= 1, got {ssaa!r}")
        ssaa = int(ssaa)
        w, h = check_size(size or self.size)
        fw, fh = w * ssaa, h * ssaa
        limit = min(self.gl.max_texture_size, *self.gl.max_viewport)
        if max(fw, fh) > limit:
            raise InputError(
                f"{w}x{h} at {ssaa}x{ssaa} supersampling needs a {fw}x{fh} framebuffer, above this "
                f"OpenGL's limit of {limit}; lower --ssaa or --size"
            )
        build = {k: options.pop(k) for k in list(options) if k in BUILD_OPTIONS}
        lod = options.pop("lod", False)
        pixel_error = options.pop("pixel_error", None)
        if lod:
            handle = self._upload_lod(thing, method, build)
            # Selected for the framebuffer (view.size): ssaa x ssaa samples per
            # image pixel, so supersampling also selects finer levels.
            options["pixel_error"] = 1.0 if pixel_error is None else pixel_error
        elif pixel_error is not None:
            raise InputError("pixel_error applies with lod=True only")
        else:
            handle = self.upload(thing, method, **build)
        impl = self.method_renderer(method)
        near, far = camera.clip_range(handle.bounds)
        view = FrameView(camera, self.lighting, (fw, fh), near, far, ssaa)
        fbo = self._fbo((fw, fh))
        t0 = time.perf_counter()
        fbo.use()
        self.gl.ctx.viewport = (0, 0, fw, fh)
        bg = self.lighting.background
        fbo.clear(bg[0], bg[1], bg[2], 0.0, depth=1.0)
        impl.draw(handle, view, fbo=fbo, **options)
        raw = fbo.read(components=4, dtype="f1")
        self.last_frame_seconds = time.perf_counter() - t0
        self.last_lod_stats = dict(impl.last_lod_stats) if lod else None
        img = np.frombuffer(raw, dtype=np.uint8).reshape(fh, fw, 4)[::-1]
        if ssaa > 1:
            img = np.round(_downsample(img.astype(np.float32), ssaa)).astype(np.uint8)
        img = np.ascontiguousarray(img if alpha else img[:, :, :3])
        return img

    def time_frames(self, thing, camera: Camera, method: str | None = None, frames: int = 5,
                    warmup: int = 1, **options) -> float:  # fmt: skip
        """Median seconds per frame (draw and read back) after ``warmup`` frames."""
        times = []
        for i in range(warmup + frames):
            self.render(thing, camera, method, **options)
            if i >= warmup:
                times.append(self.last_frame_seconds)
        return float(np.median(times))

    def render_path(
        self,
        thing,
        cameras: list[Camera],
        folder: str | os.PathLike,
        method: str | None = None,
        pattern: str = "frame_{:04d}.png",
        progress=None,
        **options,
    ) -> list[Path]:
        """Render one frame per camera to numbered PNG files in ``folder``."""
        from aniso3d.render.images import save_png

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        paths = []
        for i, cam in enumerate(cameras):
            img = self.render(thing, cam, method, **options)
            paths.append(save_png(folder / pattern.format(i), img))
            if progress:
                progress((i + 1) / len(cameras), f"frame {i + 1}/{len(cameras)}")
        return paths

    # ----------------------------------------------------------- lifetime

    def release(self) -> None:
        """Free every upload and framebuffer; the context too if we made it."""
        for (_, method, _), (_, handle) in self._uploads.items():
            if self.gl.ctx is not None:
                self._impl[method].release(handle)
        self._uploads.clear()
        self._converted.clear()
        self._pyramids.clear()
        for impl in self._impl.values():
            rel = getattr(impl, "release_all", None)
            if rel:
                rel()
        self._impl.clear()
        if self._own_gl:
            self.gl.release()
        else:
            for fbo in self._fbos.values():
                for att in list(fbo.color_attachments) + [fbo.depth_attachment]:
                    self.gl.free(att)
                self.gl.free(fbo)
        self._fbos.clear()

    def __enter__(self) -> Renderer:
        return self

    def __exit__(self, *exc) -> None:
        self.release()
