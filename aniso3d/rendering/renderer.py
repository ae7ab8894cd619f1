"""The batch-frame Python API: one :class:`Renderer` for the three methods.

``Renderer.render(thing, camera, method=...)`` draws a mesh, texture or point
cloud and returns an (H, W, 3) uint8 image (row 0 at the top);
``Renderer.render_frame`` returns a :class:`~aniso3d.rendering.frame.Frame` with
the same image, its depth and what was drawn.

Three kinds of options, each a frozen dataclass checked on construction,
given as dataclasses or as keywords:

- build options (:class:`BuildOptions`, ``build=``): how a thing is converted
  (mesh -> texture -> points) and what is uploaded (``lod``: the texture's
  pyramid, :mod:`aniso3d.build.pyramid`);
- draw options (``options=``): the method renderer's own ``Options``
  (:class:`~aniso3d.rendering.splat.SplatOptions`,
  :class:`~aniso3d.rendering.volume.VolumeOptions`,
  :class:`~aniso3d.rendering.polygon.MeshOptions`);
- frame options, arguments of ``render``: ``ssaa``, ``alpha``, ``size``.

Conversions and GPU uploads are made once per thing and options and kept in
two bounded caches (:class:`~aniso3d.rendering.cache.Cache`: host memory and GPU
memory), which hold the things weakly: a thing that is garbage-collected takes
what was made from it along.

A :class:`~aniso3d.build.scene.Scene` (many instances of a few meshes) is
drawn by every method: each asset converted and uploaded once, every
instance culled and, for splats and volume, given its own pyramid level, all
at once (:mod:`~aniso3d.rendering.scene_draw`,
:mod:`~aniso3d.rendering.instances`); ``last_lod_stats`` then holds the
per-instance choices.

``resolution="auto"`` (a mesh drawn as volume or splats) converts it only as
finely as the frame needs: :func:`~aniso3d.rendering.select.needed_resolution`
of the camera, image size and mesh bounds (a power of two). A texture already
built finer by a power of two is not rebuilt: the coarser one is the level of
its pyramid, exact. :meth:`Renderer.render_path` takes the finest any of its
cameras needs, for every frame.

``lod=True`` (methods "splat" and "volume", a mesh or texture) draws from the
texture's exact pyramid (:mod:`aniso3d.build.pyramid`), built and uploaded once: splats
select per frame, per region, the coarsest level whose voxels cover at most
``pixel_error`` framebuffer pixels and draw only those points; the volume
renderer marches, per frame, the one level fine enough at the object's
nearest visible depth. :attr:`Renderer.last_lod_stats` holds the frame's
selection.
"""

from __future__ import annotations

import contextlib
import os
import time
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import moderngl
import numpy as np

from aniso3d.build.mesh import Mesh
from aniso3d.build.points import PointCloud
from aniso3d.build.pyramid import LodPoints, Pyramid, pyramid
from aniso3d.build.scene import Scene
from aniso3d.build.texture import (
    DEFAULT_DIRECTIONS,
    DEFAULT_RESOLUTION,
    PLACEMENTS,
    POINT_NORMALS,
    AnisoTexture,
    build_texture,
)
from aniso3d.errors import InputError
from aniso3d.rendering.base import DrawOptions, MethodRenderer, choice, unknown_names
from aniso3d.rendering.cache import Cache
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.context import BACKENDS, GLContext
from aniso3d.rendering.frame import Frame, FrameView, view_depth
from aniso3d.rendering.lighting import Lighting
from aniso3d.rendering.select import needed_resolution
from aniso3d.rendering.splat.clips import clipped

METHODS = ("mesh", "volume", "splat")
#: ``BuildOptions.resolution`` that asks for :func:`~aniso3d.rendering.select.needed_resolution`.
AUTO = "auto"
#: Default bounds of each of a renderer's two caches.
CACHE_ENTRIES = 32
CACHE_BYTES = 2 << 30


def _whole(value: Any, what: str) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < 1:
        raise InputError(f"{what} must be a whole number >= 1, got {value!r}")
    return int(value)


@dataclass(frozen=True)
class BuildOptions:
    """How :class:`Renderer` turns a thing into what a method draws, and what
    it uploads. Keys the conversion and upload caches.

    Attributes:
        resolution: voxels along the longest axis of a mesh's texture, or
            "auto": as many as the frame needs (see the module docstring; a
            camera is needed, so ``render``, ``render_frame`` and
            ``render_path`` take it, ``upload`` and ``pyramid`` do not).
        directions: sphere sample directions K of a mesh's texture.
        placement: where a texture's points sit (``AnisoTexture.to_points``).
        per_entry: points per shading entry, a whole number or "adaptive".
        point_normal: the points' normal, "mean" or "sample".
        lod: draw from the texture's pyramid (methods "splat" and "volume").
    """

    resolution: int | str = DEFAULT_RESOLUTION
    directions: int = DEFAULT_DIRECTIONS
    placement: str = "centroid"
    per_entry: int | str = 1
    point_normal: str = "mean"
    lod: bool = False

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if self.resolution != AUTO:
            set_(self, "resolution", _whole(self.resolution, "build option resolution (voxels, or 'auto')"))
        set_(self, "directions", _whole(self.directions, "build option directions"))
        choice(self.placement, PLACEMENTS, "placement")
        choice(self.point_normal, POINT_NORMALS, "point normal")
        if self.per_entry != "adaptive":
            set_(self, "per_entry", _whole(self.per_entry, "build option per_entry (points per entry, or 'adaptive')"))
        if not isinstance(self.lod, (bool, np.bool_)):
            raise InputError(f"build option lod must be True or False, got {self.lod!r}")
        set_(self, "lod", bool(self.lod))

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))

    @classmethod
    def parse(cls, **values: Any) -> BuildOptions:
        """Build options from keywords; None stands for the default."""
        unknown_names(values, cls.names(), "build")
        return cls(**{k: v for k, v in values.items() if v is not None})

    @classmethod
    def resolve(cls, build: BuildOptions | None, values: dict[str, Any]) -> BuildOptions:
        """``build`` if given, else :meth:`parse` of ``values``; not both."""
        if build is None:
            return cls.parse(**values)
        if values:
            raise InputError(
                f"pass build options either as BuildOptions or as keywords, not both (got {sorted(values)})"
            )
        if not isinstance(build, cls):
            raise InputError(f"build options must be BuildOptions, got {type(build).__name__}")
        return build


def check_size(size) -> tuple[int, int]:
    """(width, height) of an image, checked: whole pixels, 1 to 16384 a side."""
    try:
        w, h = (int(size[0]), int(size[1]))
    except (TypeError, ValueError, IndexError):
        raise InputError(f"image size must be (width, height), got {size!r}") from None
    if w < 1 or h < 1:
        raise InputError(f"image size must be at least 1x1 pixels, got {w}x{h}")
    if max(w, h) > 16384:
        raise InputError(f"image size {w}x{h} is above the maximum of 16384 pixels a side")
    return w, h


def downsample(img: np.ndarray, s: int) -> np.ndarray:
    """Box-filter an (H*s, W*s, C) image by ``s`` per axis to (H, W, C): the
    supersampling filter of :meth:`Renderer.render`. A uint8 image comes
    back as uint8, each pixel its samples' mean rounded half to even, summed
    in integers a row of samples at a time (an 8x8-supersampled 1024^2
    frame is 268 MB: a float copy of it took 1 GB and most of the time); a
    float image comes back as its float mean."""
    if s == 1:
        return img
    h, w, c = img.shape
    if img.dtype != np.uint8:
        return img.reshape(h // s, s, w // s, s, c).mean(axis=(1, 3))
    rows = img.reshape(h // s, s, w * c).sum(axis=1, dtype=np.uint16 if s * 255 <= 0xFFFF else np.uint32)
    total = rows.reshape(h // s, w // s, s, c).sum(axis=2, dtype=np.uint32)
    return np.round(total.astype(np.float64) / float(s * s)).astype(np.uint8)


class Renderer:
    """Draws meshes, anisotropic textures and point clouds with one camera and
    one lighting model.

    Args:
        size: (width, height) of the images, pixels.
        lighting: the shared lighting model (default :class:`Lighting`).
        gl: a :class:`GLContext` to draw with; by default one is made (and
            released with the renderer).
        backend: OpenGL backend for the context made here ("auto", "egl", ...).
        cache_entries, cache_bytes: bounds of each of the two caches
            (:attr:`conversions`, :attr:`uploads`).
    """

    def __init__(
        self,
        size=(512, 512),
        lighting: Lighting | None = None,
        gl: GLContext | None = None,
        backend: str = "auto",
        cache_entries: int = CACHE_ENTRIES,
        cache_bytes: int | None = CACHE_BYTES,
    ):
        self.size = check_size(size)
        self.lighting = lighting or Lighting()
        #: Conversions in host memory: a mesh's texture, a texture's points and pyramid.
        self.conversions = Cache(cache_entries, cache_bytes, "conversion cache")
        #: GPU uploads by (thing, method, build options), released through their
        #: method renderer when they leave. A handle from :meth:`upload` stays
        #: valid until then (or until :meth:`release`).
        self.uploads = Cache(cache_entries, cache_bytes, "upload cache")
        self._own_gl = gl is None
        self.gl = gl or GLContext(backend)
        self._impl: dict[str, MethodRenderer] = {}
        self._fbos: dict[tuple[int, int], moderngl.Framebuffer] = {}
        self.last_frame_seconds = 0.0
        #: Selection of the last ``lod=True`` frame (None after other frames):
        #: for splats ``points`` drawn, ``points_per_level``, ``culled``
        #: voxels, ``selection_ms``...; for the volume the ``level`` drawn.
        self.last_lod_stats: dict | None = None

    # ----------------------------------------------------------- plumbing

    def method_renderer(self, method: str) -> MethodRenderer:
        """The per-method renderer object (made on first use)."""
        if method not in METHODS:
            raise InputError(f"unknown render method '{method}'; choose one of {', '.join(METHODS)}")
        impl = self._impl.get(method)
        if impl is None:
            if method == "mesh":
                from aniso3d.rendering.polygon import MeshRenderer as cls
            elif method == "splat":
                from aniso3d.rendering.splat import SplatRenderer as cls
            else:
                from aniso3d.rendering.volume import VolumeRenderer as cls
            impl = self._impl[method] = cls(self.gl)
        return impl

    def _convert(self, thing, method: str, build: BuildOptions):
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
        if not isinstance(thing, (Mesh, AnisoTexture)):
            raise InputError(f"cannot render a {type(thing).__name__}; pass a Mesh, AnisoTexture or PointCloud")
        tex = thing
        if isinstance(thing, Mesh):
            res, dirs = build.resolution, build.directions
            tex = self.conversions.get_or_make(
                thing, ("texture", res, dirs), lambda: build_texture(thing, res, dirs)
            )
        if method == "volume":
            return tex
        opts = (build.placement, build.per_entry, build.point_normal)
        # Each point with the faces of its voxel where its surface ends
        # (aniso3d.rendering.splat.clips; quality "high" cuts its splat there).
        if build.per_entry == "adaptive":  # counts per entry (lod.py)
            def make():
                pyr = self.pyramid(tex)
                return clipped(pyr.level_cloud(0, *opts)[0], tex, None, pyr.adaptive_counts(0))
        else:
            make = lambda: clipped(tex.to_points(*opts), tex, None, build.per_entry)  # noqa: E731
        return self.conversions.get_or_make(tex, ("points", *opts), make)

    def pyramid(self, thing, **build) -> Pyramid:
        """The texture pyramid of ``thing`` (a mesh is converted with the
        build options ``resolution`` and ``directions`` first); built once
        per texture."""
        if isinstance(thing, PointCloud):
            raise InputError(
                "level of detail needs a mesh or a texture: a point cloud has no texture pyramid"
            )
        b = BuildOptions.parse(**build)
        self._concrete(thing, "volume", b, "pyramid")
        tex = self._convert(thing, "volume", b)
        return self.conversions.get_or_make(tex, ("pyramid",), lambda: pyramid(tex))

    def upload(self, thing, method: str, build: BuildOptions | None = None, **values):
        """Convert and upload ``thing`` for ``method`` (cached); returns the
        handle. Build options as ``build`` or as keywords (``lod=True``: the
        texture's pyramid)."""
        if method not in METHODS:
            raise InputError(f"unknown render method '{method}'; choose one of {', '.join(METHODS)}")
        b = BuildOptions.resolve(build, values)
        if b.lod and method not in ("splat", "volume"):
            raise InputError(
                f"level of detail applies to the splat and volume methods, not '{method}'"
            )
        self._concrete(thing, method, b, "upload")
        self.gl.use()
        # Only what changes the upload keys it.
        used = {"mesh": (), "volume": ("lod",), "splat": ("placement", "per_entry", "point_normal", "lod")}[method]
        if isinstance(thing, Mesh) and method != "mesh":
            used += ("resolution", "directions")
        key = ("upload", method, *((name, getattr(b, name)) for name in used))
        handle = self.uploads.get(thing, key)
        if handle is not None:
            return handle
        if b.lod:
            pyr = self.pyramid(thing, resolution=b.resolution, directions=b.directions)
            data = LodPoints(pyr, b.placement, b.per_entry, b.point_normal) if method == "splat" else pyr
        else:
            data = self._convert(thing, method, b)
        impl = self.method_renderer(method)
        return self.uploads.put(thing, key, impl.upload(data), release=self._releaser(impl))

    @staticmethod
    def _concrete(thing, method: str, build: BuildOptions, caller: str) -> None:
        """An InputError where a mesh would be converted at resolution "auto"
        without a camera to resolve it."""
        if build.resolution == AUTO and isinstance(thing, Mesh) and method != "mesh":
            raise InputError(
                f"resolution 'auto' needs a camera: give {caller}() a number of voxels, "
                "or draw with render(), render_frame() or render_path()"
            )

    def resolve_resolution(self, thing, cameras, size=None, directions: int = DEFAULT_DIRECTIONS) -> int:
        """The resolution "auto" stands for when ``thing`` (a mesh) is seen by
        ``cameras`` (one or a list) in images of ``size`` (default: the
        renderer's): the finest :func:`~aniso3d.rendering.select.needed_resolution`
        of them. The texture is made ready in the conversion cache: taken from
        the pyramid of a texture built finer by a power of two if there is one
        (every level is exact), else built."""
        if not isinstance(thing, Mesh):
            raise InputError(f"resolution 'auto' is for converting a mesh, got {type(thing).__name__}")
        cams = [cameras] if isinstance(cameras, Camera) else list(cameras)
        if not cams or not all(isinstance(c, Camera) for c in cams):
            raise InputError("resolution 'auto' needs one or more aniso3d.Camera objects")
        w, h = check_size(size or self.size)
        res = max(needed_resolution(c, (w, h), thing.bounds) for c in cams)
        key = ("texture", res, directions)
        if self.conversions.get(thing, key) is None:
            finer, k = None, 1
            while finer is None and res << k <= 65536:
                finer = self.conversions.get(thing, ("texture", res << k, directions))
                k += 1
            if finer is not None:
                pyr = self.conversions.get_or_make(finer, ("pyramid",), lambda: pyramid(finer))
                if len(pyr) >= k:
                    self.conversions.put(thing, key, pyr[k - 1])
        return res

    def _releaser(self, impl: MethodRenderer):
        def release(handle) -> None:
            if self.gl.ctx is not None:  # a context released first took its objects along
                impl.release(handle)

        return release

    def forget(self, thing) -> None:
        """Drop now what was made from ``thing``: its uploads (released) and
        its conversions, and what was made from those."""
        self.uploads.discard(thing)
        for value in self.conversions.discard(thing):
            self.forget(value)

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
        *,
        build: BuildOptions | None = None,
        options: DrawOptions | None = None,
        **values,
    ) -> np.ndarray:
        """Draw ``thing`` seen by ``camera``; returns (H, W, 3 or 4) uint8.

        ``method`` defaults to what the thing is: mesh -> "mesh", texture ->
        "volume", point cloud -> "splat". ``ssaa`` draws at ssaa x ssaa samples
        per pixel and box-filters. Build options (:class:`BuildOptions`, as
        ``build`` or keywords: resolution, directions, placement, per_entry,
        point_normal, lod) choose the conversion and upload; draw options (the
        method renderer's ``Options``, as ``options`` or keywords, e.g.
        ``splat="disc"``, ``quality="high"``) go to the method's renderer.

        ``lod=True`` (splat and volume, from a mesh or texture) draws from the
        texture's pyramid with the screen-space error ``pixel_error`` (a draw
        option: framebuffer pixels, default 1; with ``ssaa`` the selection is
        made for the supersampled framebuffer); the clip range comes from every
        level's bounds, not from what a frame selects. The frame's selection
        is kept in :attr:`last_lod_stats`.
        """
        return self._draw(thing, camera, method, ssaa, alpha, size, build, options, values)[0]

    def render_frame(
        self,
        thing,
        camera: Camera,
        method: str | None = None,
        ssaa: int = 1,
        alpha: bool = False,
        size=None,
        *,
        build: BuildOptions | None = None,
        options: DrawOptions | None = None,
        **values,
    ) -> Frame:
        """:meth:`render`, with the frame's depth and statistics: a
        :class:`~aniso3d.rendering.frame.Frame` (colour as :meth:`render` returns
        it; depth the view-axis distance, +inf on the background)."""
        img, stats, fbo, view = self._draw(thing, camera, method, ssaa, alpha, size, build, options, values)
        fw, fh = view.size
        raw = fbo.read(attachment=-1, components=1, dtype="f4")  # the depth attachment
        window = np.frombuffer(raw, dtype=np.float32).reshape(fh, fw)[::-1]
        depth = view_depth(window, view.near, view.far)
        s = view.ssaa
        if s > 1:  # the nearest sample of each pixel
            depth = depth.reshape(fh // s, s, fw // s, s).min(axis=(1, 3))
        return Frame(img, np.ascontiguousarray(depth), self.last_frame_seconds, stats)

    def _draw(self, thing, camera, method, ssaa, alpha, size, build, options, values):
        """Draw one frame into this size's framebuffer; (image, DrawStats, fbo, view)."""
        self.gl.use()
        if not isinstance(camera, Camera):
            raise InputError(f"render needs an aniso3d.Camera, got {type(camera).__name__}")
        if method is None:
            kinds = ((AnisoTexture, "volume"), (PointCloud, "splat"))
            method = next((m for cls, m in kinds if isinstance(thing, cls)), "mesh")
        if method not in METHODS:
            raise InputError(f"unknown render method '{method}'; choose one of {', '.join(METHODS)}")
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
        names = BuildOptions.names()
        b = BuildOptions.resolve(build, {k: values.pop(k) for k in list(values) if k in names})
        if b.resolution == AUTO and isinstance(thing, Mesh) and method != "mesh":
            b = replace(b, resolution=self.resolve_resolution(thing, camera, (w, h), b.directions))
        if b.lod and method not in ("splat", "volume"):
            raise InputError(f"level of detail applies to the splat and volume methods, not '{method}'")
        lod_frame = b.lod or isinstance(thing, Scene)  # a scene's instances always choose a level
        if not lod_frame and values.get("pixel_error", getattr(options, "pixel_error", None)) is not None:
            raise InputError("pixel_error applies with lod=True only")
        impl = self.method_renderer(method)
        opts = impl.Options.resolve(options, values)
        if isinstance(thing, Scene):  # instances of shared assets: aniso3d.rendering.scene_draw
            from aniso3d.rendering.scene_draw import draw_scene, scene_clip_range, upload_scene

            handle = upload_scene(self, thing, method, b)
            draw = lambda: draw_scene(impl, handle, view, fbo, opts)  # noqa: E731
            near, far = scene_clip_range(handle, camera)
        else:
            handle = self.upload(thing, method, build=b)
            # The splats may skip compositing under earlier draws: fbo is cleared just below.
            fresh = {"cleared": True} if method == "splat" else {}
            draw = lambda: impl.draw(handle, view, fbo=fbo, options=opts, **fresh)  # noqa: E731
            near, far = camera.clip_range(handle.bounds)
        view = FrameView(camera, self.lighting, (fw, fh), near, far, ssaa)
        fbo = self._fbo((fw, fh))
        t0 = time.perf_counter()
        fbo.use()
        self.gl.ctx.viewport = (0, 0, fw, fh)
        bg = self.lighting.background
        fbo.clear(bg[0], bg[1], bg[2], 0.0, depth=1.0)
        stats = draw()
        raw = fbo.read(components=4, dtype="f1")
        self.last_frame_seconds = time.perf_counter() - t0
        self.last_lod_stats = dict(stats.lod) if lod_frame and stats.lod is not None else None
        img = downsample(np.frombuffer(raw, dtype=np.uint8).reshape(fh, fw, 4), ssaa)[::-1]
        img = np.ascontiguousarray(img if alpha else img[:, :, :3])
        return img, stats, fbo, view

    def time_frames(self, thing, camera: Camera, method: str | None = None, frames: int = 5,
                    warmup: int = 1, **options) -> float:  # fmt: skip
        """Median seconds per frame (draw and read back) after ``warmup`` frames."""
        times = []
        for i in range(warmup + frames):
            self.render(thing, camera, method, **options)
            if i >= warmup:
                times.append(self.last_frame_seconds)
        return float(np.median(times))

    def _path_options(self, thing, cameras: list[Camera], method: str | None, options: dict) -> dict:
        """``options`` for every frame of a camera path: with ``resolution="auto"``
        one texture for the whole path, the finest any frame needs."""
        options = dict(options)
        build = options.get("build")
        resolution = build.resolution if isinstance(build, BuildOptions) else options.get("resolution")
        if resolution == AUTO and isinstance(thing, Mesh) and method not in (None, "mesh") and cameras:
            dirs = build.directions if isinstance(build, BuildOptions) else options.get("directions")
            res = self.resolve_resolution(thing, cameras, options.get("size"), dirs or DEFAULT_DIRECTIONS)
            if isinstance(build, BuildOptions):
                options["build"] = replace(build, resolution=res)
            else:
                options["resolution"] = res
        return options

    def render_video(
        self,
        thing,
        cameras: list[Camera],
        path: str | os.PathLike,
        method: str | None = None,
        fps: float = 24.0,
        progress=None,
        **options,
    ) -> Path:
        """Render one frame per camera into one video file (``.gif``, ``.webp``
        or ``.mp4``, by the suffix; :func:`aniso3d.rendering.video.write_video`),
        written atomically. Frames are rendered as the file is written."""
        from aniso3d.rendering.video import check_video_output, write_video

        check_video_output(path, fps)  # before the first frame: a bad name or a missing extra fails at once
        options = self._path_options(thing, cameras, method, options)

        def frames():
            for i, cam in enumerate(cameras):
                yield self.render(thing, cam, method, **options)
                if progress:
                    progress((i + 1) / len(cameras), f"frame {i + 1}/{len(cameras)}")

        return write_video(frames(), path, fps)

    def render_path(
        self,
        thing,
        cameras: list[Camera],
        folder: str | os.PathLike,
        method: str | None = None,
        pattern: str = "frame_{:04d}.png",
        progress=None,
        client=None,
        workers: int | None = None,
        **options,
    ) -> list[Path]:
        """Render one frame per camera to numbered PNG files in ``folder``.

        With a Dask ``client`` (or ``workers`` > 1: a local cluster of that
        many processes, made for the path), the frames are drawn on the
        cluster's workers by :func:`render_frames`, each worker with its own
        context and a renderer of this class, the same size and lighting;
        the files are the same."""
        from aniso3d.rendering.images import save_png

        if client is not None or (workers or 1) > 1:
            size = options.pop("size", None) or self.size
            backend = self.gl.backend if self.gl.backend in BACKENDS else "auto"
            return render_frames(thing, cameras, folder, method, client=client, workers=workers, size=size,
                                 lighting=self.lighting, backend=backend, pattern=pattern, progress=progress,
                                 renderer=type(self), **options)  # fmt: skip
        options = self._path_options(thing, cameras, method, options)
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
        self.gl.use()
        self.uploads.clear()
        self.conversions.clear()
        for impl in self._impl.values():
            impl.release_all()
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


def method_options(method: str) -> type[DrawOptions]:
    """The draw options class of ``method`` (no GL context needed)."""
    if method == "mesh":
        from aniso3d.rendering.polygon import MeshRenderer as cls
    elif method == "splat":
        from aniso3d.rendering.splat import SplatRenderer as cls
    elif method == "volume":
        from aniso3d.rendering.volume import VolumeRenderer as cls
    else:
        raise InputError(f"unknown render method '{method}'; choose one of {', '.join(METHODS)}")
    return cls.Options


def render_frames(
    thing,
    cameras,
    folder: str | os.PathLike | None = None,
    method: str | None = None,
    *,
    client=None,
    workers: int | None = None,
    size=(512, 512),
    ssaa: int = 1,
    alpha: bool = False,
    lighting: Lighting | None = None,
    backend: str = "auto",
    pattern: str = "frame_{:04d}.png",
    progress=None,
    batch_size: int | None = None,
    threads: int | None = None,
    retries: int = 1,
    renderer: type[Renderer] | None = None,
    build: BuildOptions | None = None,
    options: DrawOptions | None = None,
    **values,
) -> list[np.ndarray] | list[Path]:
    """One frame of ``thing`` per camera of ``cameras``, here or on a Dask
    cluster: (H, W, 3|4) uint8 arrays in camera order, or, with ``folder``,
    the numbered PNG files written there (``pattern``), each atomically.

    Executors: this process (no ``client``, ``workers`` None or 1); a Dask
    ``client`` (``dask.distributed.Client``); or ``workers`` > 1: a Dask
    ``LocalCluster`` of that many worker processes made for this call. On a
    cluster the path is cut into contiguous batches (``batch_size`` frames;
    default: four batches per worker), the thing is scattered once to every
    worker, and each worker draws with its own GL context and a renderer it
    keeps (:mod:`aniso3d.rendering.distributed`); a worker lost mid-batch
    has its batch drawn again elsewhere. The frames are the same pixel for
    pixel whatever the executor.

    ``threads``: llvmpipe threads per worker (``LP_NUM_THREADS``, set before
    a worker's first GL context); default on a local cluster: the cores
    shared out among the workers, elsewhere the workers' own setting.

    A mesh drawn as volume or splats is converted once, before any frame
    (on the cluster when there is one); ``resolution="auto"`` takes the
    finest any camera needs, as :meth:`Renderer.render_path` does. Build and
    draw options as in :meth:`Renderer.render`; ``renderer``: the class the
    frames are drawn with (default :class:`Renderer`).
    """
    from aniso3d.rendering import distributed as dist

    cams = [cameras] if isinstance(cameras, Camera) else list(cameras)
    if not cams or not all(isinstance(c, Camera) for c in cams):
        raise InputError("render_frames needs a list of one or more aniso3d.Camera objects")
    w, h = check_size(size)
    if method is None:
        kinds = ((AnisoTexture, "volume"), (PointCloud, "splat"))
        method = next((m for cls, m in kinds if isinstance(thing, cls)), "mesh")
    opts = method_options(method).resolve(options, {k: v for k, v in values.items() if k not in BuildOptions.names()})
    b = BuildOptions.resolve(build, {k: v for k, v in values.items() if k in BuildOptions.names()})
    if isinstance(ssaa, bool) or int(ssaa) != ssaa or ssaa < 1:
        raise InputError(f"supersampling factor must be a whole number >= 1, got {ssaa!r}")
    if workers is not None and (isinstance(workers, bool) or int(workers) != workers or workers < 1):
        raise InputError(f"workers must be a whole number of processes >= 1, got {workers!r}")
    if folder is not None:
        folder = Path(folder)
        if folder.exists() and not folder.is_dir():
            raise InputError(f"'{folder}' exists and is not a folder; frames are written as numbered PNGs there")
        folder.mkdir(parents=True, exist_ok=True)
    cls = renderer or Renderer
    lighting = lighting or Lighting()
    here = client is None and (workers or 1) == 1
    executor = contextlib.nullcontext() if here else dist.frame_client(client, workers)
    with executor as c:
        if isinstance(thing, Mesh) and method != "mesh":
            res = b.resolution
            if res == AUTO:
                res = max(needed_resolution(cam, (w, h), thing.bounds) for cam in cams)
            thing = build_texture(thing, res, b.directions, client=c)  # once, for every frame
            b = replace(b, resolution=res)
        if here:
            with cls((w, h), lighting, backend=backend) as r:
                if folder is not None:
                    return r.render_path(thing, cams, folder, method, pattern, progress, ssaa=ssaa, alpha=alpha,
                                         build=b, options=opts)  # fmt: skip
                out = []
                for i, cam in enumerate(cams):
                    out.append(r.render(thing, cam, method, ssaa=ssaa, alpha=alpha, build=b, options=opts))
                    if progress:
                        progress((i + 1) / len(cams), f"frame {i + 1}/{len(cams)}")
                return out
        if threads is None and client is None:
            threads = dist.local_threads(workers)
        job = dist.FrameJob(cls, (w, h), lighting, backend, method, int(ssaa), bool(alpha), b, opts, threads)
        return dist.run_batches(c, thing, cams, job, folder=folder, pattern=pattern, progress=progress,
                                batch_size=batch_size, retries=retries)  # fmt: skip
