"""The corpus bench: every built-in scene at the default texture, judged
against the polygon truth at two distances and on a turntable.

No default of aniso3d should be chosen on one object. For each scene of
:data:`aniso3d.build.scenes.CORPUS` this measures, at the default texture
resolution and K:

- **bytes**: the mesh as binary PLY (12 bytes a vertex, 13 a triangle), the
  texture (``AnisoTexture.nbytes``) and its points (``PointCloud.nbytes``);
- **two cameras**, both from ``aniso3d render``'s default view: *close* (its
  framing: the object fills the image) and *minified* (moved back until a
  texture voxel spans about one pixel, the distance rule of
  :func:`~aniso3d.bench.cameras.make_cameras`);
- per camera and renderer (:data:`RENDERERS`): PSNR, SSIM and FLIP against
  the polygon truth supersampled ``gt_ssaa`` x ``gt_ssaa``, inside the box the
  object's bounds project to, and the frame time (median, fastest and slowest
  of several frames as ``Renderer.last_frame_seconds`` times them,
  :func:`~aniso3d.bench.run.measure`);
- **close up at the resolution ``--resolution auto`` picks** (camera
  ``close-auto``): the close camera again, the texture renderers drawing a
  texture built as finely as that view needs
  (:func:`~aniso3d.rendering.select.needed_resolution`, at most 256^3), which
  is what ``aniso3d render`` and the viewer draw by default; the fixed
  resolution's close-up magnifies every voxel to several pixels;
- **flicker** on a turntable at the minified distance (:func:`flicker`);
- the **targets** (:data:`TARGETS`), pass or fail per scene.

The turntable is drawn in a square window around the image centre, with the
same camera and a field of view narrowed in proportion: the pixels are exactly
those of the full image's centre (:func:`turntable_window`), and the object
stays inside the window at every angle, so nothing is lost and the empty
border is not drawn 36 times over.
"""

from __future__ import annotations

import math
import os
import platform
import time
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, replace

import numpy as np

from aniso3d import metrics
from aniso3d.bench.cameras import CameraSpec, crop_box, pixels_per_unit
from aniso3d.bench.plan import Case, splat_case, volume_case
from aniso3d.bench.run import (
    CODE_PATHS,
    classify_failure,
    code_version,
    cpu_model,
    loadavg,
    measure,
    score,
    truth_ssaa,
)
from aniso3d.bench.settings import BASELINE
from aniso3d.build import scenes
from aniso3d.build.bounds import surface_sample
from aniso3d.build.mesh import Mesh
from aniso3d.build.texture import DEFAULT_DIRECTIONS, DEFAULT_RESOLUTION, build_texture
from aniso3d.errors import InputError
from aniso3d.rendering.camera import Camera, turntable
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.select import needed_resolution
from aniso3d.rendering.splat.clips import texture_points

#: The renderers measured, in table order.
RENDERERS = ("mesh-1spp", "mesh-2x2", "mesh-4x4", "volume", "splat-fast", "splat-high")
#: The texture renderers the targets hold to account (the defaults of ``aniso3d render``).
TEXTURE_RENDERERS = ("volume", "splat-high")
CAMERAS = ("close", "minified")
#: The close camera with the texture at the resolution "auto" picks there.
AUTO_CAMERA = "close-auto"
#: What is drawn at :data:`AUTO_CAMERA` (the polygons are the close camera's).
AUTO_RENDERERS = ("volume", "splat-fast", "splat-high")
#: ``aniso3d render``'s default view (``--azimuth 30 --elevation 15 --fov 40``).
VIEW_AZIMUTH, VIEW_ELEVATION, VIEW_FOV = 30.0, 15.0, 40.0
#: The targets, by column name, as the report states them.
TARGETS = {
    "minified_vs_2x2": "minified: volume and high splats at least as good as 2x2 polygons (PSNR and FLIP)",
    "volume_faster": "minified: volume frame time below 1-spp polygons",
    "volume_2x": "volume frame time at most twice 1-spp polygons' (both distances)",
    "never_worse_1spp": "volume and high splats never worse than 1-spp polygons (PSNR and FLIP, both distances)",
    "never_worse_1spp_auto": "the same, close up at the resolution `--resolution auto` picks for that view "
                             "(minified: the corpus resolution, a voxel about a pixel there)",
    "less_flicker": "volume and high splats flicker less than 1-spp polygons",
    "bytes_fifth": "texture bytes at most 1/5 of the mesh's (binary PLY)",
}

Progress = Callable[[float, str], None]


@dataclass(frozen=True)
class CorpusSettings:
    """What one corpus run measures.

    Attributes:
        name: preset name ("full", "quick").
        size: (width, height) of the still images, pixels.
        gt_ssaa: samples per pixel along each axis of the polygon truth.
        frames: timed frames per renderer and camera (median reported).
        warmup: untimed frames first (the first one also uploads).
        frame_budget: seconds after which a renderer stops timing more frames.
        turntable: frames of the turntable (a full turn), at least 2.
        resolution, directions: the texture (default: the build's defaults).
        splat: splat shape, drawn in "fast" and "high" quality.
        auto_close: also draw the close camera at the resolution ``--resolution
            auto`` picks there (:data:`AUTO_CAMERA`).
        scenes: names from :data:`aniso3d.build.scenes.CORPUS`.
    """

    name: str
    size: tuple[int, int]
    gt_ssaa: int = 8
    frames: int = 5
    warmup: int = 1
    frame_budget: float = 10.0
    turntable: int = 36
    resolution: int = DEFAULT_RESOLUTION
    directions: int = DEFAULT_DIRECTIONS
    splat: str = BASELINE["splat"]
    auto_close: bool = True
    scenes: tuple[str, ...] = scenes.CORPUS

    def __post_init__(self) -> None:
        if self.frames < 1 or self.warmup < 1:
            raise InputError("corpus bench: need at least 1 warm-up frame and 1 timed frame")
        if self.turntable < 2:
            raise InputError(f"corpus bench: flicker needs a turntable of at least 2 frames, got {self.turntable}")
        if self.gt_ssaa < 2:
            raise InputError(f"the ground truth needs supersampling (>= 2 samples a side), got {self.gt_ssaa}")
        if not self.scenes:
            raise InputError("corpus bench: no scenes chosen")
        unknown = [s for s in self.scenes if s not in scenes.CORPUS]
        if unknown:
            raise InputError(f"unknown corpus scene(s) {unknown}; choose from {', '.join(scenes.CORPUS)}")


CORPUS_PRESETS = {
    # 512 x 512, 8 x 8 truth, 5 timed frames, a 36-frame turntable.
    "full": CorpusSettings("full", (512, 512)),
    # Small images (a 128^3 voxel spans about 1.7 pixels close up, so the two
    # cameras differ), 2 timed frames, an 8-frame turntable: seconds for a
    # small scene, a few minutes for the corpus.
    "quick": CorpusSettings("quick", (256, 256), frames=2, frame_budget=2.0, turntable=8),
}


def corpus_settings(
    name: str,
    size: tuple[int, int] | None = None,
    frames: int | None = None,
    gt_ssaa: int | None = None,
    turntable: int | None = None,
    scene_names: tuple[str, ...] | None = None,
) -> CorpusSettings:
    """The corpus preset ``name`` with the given fields overridden (None keeps the preset's)."""
    if name not in CORPUS_PRESETS:
        raise InputError(f"unknown corpus bench preset {name!r}; choose one of {', '.join(CORPUS_PRESETS)}")
    given = {"size": tuple(size) if size else None, "frames": frames, "gt_ssaa": gt_ssaa,
             "turntable": turntable, "scenes": tuple(scene_names) if scene_names else None}  # fmt: skip
    return replace(CORPUS_PRESETS[name], **{k: v for k, v in given.items() if v is not None})


# ------------------------------------------------------------------ cameras


def view_direction(azimuth: float = VIEW_AZIMUTH, elevation: float = VIEW_ELEVATION) -> np.ndarray:
    """Unit vector from the target towards the eye, as ``aniso3d render`` makes it (degrees, y-up)."""
    az, el = math.radians(azimuth), math.radians(elevation)
    return np.array([math.sin(az) * math.cos(el), math.sin(el), math.cos(az) * math.cos(el)])


def corpus_cameras(mesh: Mesh, size: tuple[int, int], resolution: int) -> list[CameraSpec]:
    """The close camera (``aniso3d render``'s framing) and the minified one.

    A voxel (edge ``longest extent / resolution``) spans ``h * H / (2 d tan(fov
    / 2))`` pixels at distance d, so the minified camera is the close one moved
    back by that width at the close distance; it stays the close camera when a
    voxel is already under a pixel there.
    """
    b = np.asarray(mesh.bounds, dtype=np.float64)
    pts = surface_sample(mesh)
    fit = dict(direction=view_direction(), fov=VIEW_FOV, aspect=size[0] / size[1], points=pts)
    close = Camera.fit(b, **fit)
    d0 = float(np.linalg.norm(np.subtract(close.position, close.target)))
    h = float(np.max(b[1] - b[0])) / resolution
    fp0 = h * pixels_per_unit(size, close.fov, d0)
    scale = max(1.0, fp0)
    far = Camera.fit(b, distance_scale=scale, **fit) if scale > 1.0 else close
    return [
        CameraSpec("close", 1.0, close, d0, fp0, crop_box(close, b, size)),
        CameraSpec("minified", scale, far, d0 * scale, fp0 / scale, crop_box(far, b, size)),
    ]


def turntable_window(
    spec: CameraSpec, bounds: np.ndarray, size: tuple[int, int], margin: int = 4
) -> tuple[Camera, tuple[int, int]]:
    """A camera and a square image size that draw exactly the centre of
    ``spec``'s full image, large enough to hold the object at every angle of a
    turntable about the target.

    Every point of ``bounds`` lies within R of the target, so its projection
    stays within ``f tan(asin(R / d))`` pixels of the centre (f the focal length
    in pixels, d the distance). The window keeps the pixel size (its field of
    view is narrowed in proportion) and the pixel grid (its border is a whole
    number of pixels on each side). The full image is returned when the window
    would not be smaller.
    """
    cam = spec.camera
    w, h = size
    b = np.asarray(bounds, dtype=np.float64)
    corners = np.array([[x, y, z] for x in b[:, 0] for y in b[:, 1] for z in b[:, 2]])
    radius = float(np.max(np.linalg.norm(corners - np.asarray(cam.target), axis=1)))
    d = spec.distance
    if d <= radius * 1.0001:
        return cam, (w, h)
    tan_half = math.tan(math.radians(cam.fov) / 2.0)
    focal = h / (2.0 * tan_half)
    half = focal * radius / math.sqrt(d * d - radius * radius)
    side = 2 * (math.ceil(half) + margin)
    if (w - side) % 2:
        side += 1
    if side >= min(w, h) or (h - side) % 2:
        return cam, (w, h)
    fov = math.degrees(2.0 * math.atan(tan_half * side / h))
    return Camera(cam.position, cam.target, cam.up, fov, cam.near, cam.far), (side, side)


# ------------------------------------------------------------------ numbers


def ply_bytes(mesh: Mesh) -> int:
    """Bytes of the mesh as binary PLY without its header: float32 x, y, z per
    vertex (12) and a uint8 count and three int32 indices per triangle (13)."""
    return int(12 * len(mesh.vertices) + 13 * mesh.n_faces)


def flicker(frames, truth) -> float:
    """Mean absolute frame-to-frame change of ``frames`` over that of ``truth``.

    Both (T, H, W, C) (or (T, H, W)), T >= 2, the same shape. 1.0: the
    rendering changes from frame to frame as much as the truth does; above 1 it
    flickers; 0 for a sequence that does not change at all. A truth that does
    not change either gives 1.0 (0 / 0: as stable as the truth).
    """
    a, t = _sequences(frames, truth)
    da = float(np.abs(np.diff(a, axis=0)).mean())
    dt = float(np.abs(np.diff(t, axis=0)).mean())
    if dt == 0.0:
        return 1.0 if da == 0.0 else math.inf
    return da / dt


def flicker_error(frames, truth) -> float:
    """Mean absolute difference between the frame-to-frame changes of
    ``frames`` and of ``truth``, over the truth's mean change: the temporal
    error (0 when every change is the truth's). A blurred rendering can have a
    :func:`flicker` below 1 and still a large temporal error."""
    a, t = _sequences(frames, truth)
    dt = np.diff(t, axis=0)
    scale = float(np.abs(dt).mean())
    err = float(np.abs(np.diff(a, axis=0) - dt).mean())
    if scale == 0.0:
        return 0.0 if err == 0.0 else math.inf
    return err / scale


def _sequences(frames, truth) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(frames, dtype=np.float64)
    t = np.asarray(truth, dtype=np.float64)
    if a.shape != t.shape:
        raise InputError(f"flicker: the sequence {a.shape} and the truth {t.shape} differ in shape")
    if a.ndim < 3 or a.shape[0] < 2:
        raise InputError(f"flicker needs at least 2 frames of (T, H, W[, C]) images, got shape {a.shape}")
    return a, t


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _number(x) -> bool:
    """A real number, not NaN (PSNR is +inf for identical images)."""
    return isinstance(x, (int, float)) and not isinstance(x, bool) and not math.isnan(x)


def _as_good(a: dict | None, b: dict | None) -> bool | None:
    """``a`` at least as good as ``b``: PSNR not lower and FLIP not higher (FLIP
    only where both have it). None when a PSNR is missing."""
    if a is None or b is None or not (_number(a.get("psnr")) and _number(b.get("psnr"))):
        return None
    ok = a["psnr"] >= b["psnr"]
    if _finite(a.get("flip")) and _finite(b.get("flip")):
        ok = ok and a["flip"] <= b["flip"]
    return bool(ok)


def _all(values: list[bool | None]) -> bool | None:
    """False if any is False, else None if any is missing, else True."""
    if any(v is False for v in values):
        return False
    return None if any(v is None for v in values) else True


def check_targets(rows: list[dict], texture_ratio: float) -> dict[str, bool | None]:
    """Each target of :data:`TARGETS` for one scene: True (pass), False (fail)
    or None (a number it needs was not measured).

    ``rows`` are the scene's rows (keys camera, renderer, status, psnr, flip,
    frame_s, flicker; the turntable's rows have camera "turntable"),
    ``texture_ratio`` its texture bytes over the mesh's.
    """
    at = {(r["camera"], r["renderer"]): r for r in rows if r.get("status") == "ok"}
    out: dict[str, bool | None] = {}
    out["minified_vs_2x2"] = _all([_as_good(at.get(("minified", t)), at.get(("minified", "mesh-2x2")))
                                   for t in TEXTURE_RENDERERS])  # fmt: skip
    ratio = {}  # volume over 1-spp polygons' frame time, per camera (None: not measured)
    for cam in CAMERAS:
        vol, poly = at.get((cam, "volume")), at.get((cam, "mesh-1spp"))
        ok = vol is not None and poly is not None and _finite(vol.get("frame_s")) and _finite(poly.get("frame_s"))
        ratio[cam] = vol["frame_s"] / poly["frame_s"] if ok and poly["frame_s"] > 0 else None
    out["volume_faster"] = None if ratio["minified"] is None else bool(ratio["minified"] < 1.0)
    out["volume_2x"] = _all([None if r is None else bool(r <= 2.0) for r in ratio.values()])
    out["never_worse_1spp"] = _all([_as_good(at.get((cam, t)), at.get((cam, "mesh-1spp")))
                                    for cam in CAMERAS for t in TEXTURE_RENDERERS])  # fmt: skip
    out["never_worse_1spp_auto"] = _all([_as_good(at.get((auto, t)), at.get((cam, "mesh-1spp")))
                                         for auto, cam in ((AUTO_CAMERA, "close"), ("minified", "minified"))
                                         for t in TEXTURE_RENDERERS])  # fmt: skip
    less = []
    poly = at.get(("turntable", "mesh-1spp"), {}).get("flicker")
    for t in TEXTURE_RENDERERS:
        f = at.get(("turntable", t), {}).get("flicker")
        less.append(bool(f < poly) if _finite(f) and _finite(poly) else None)
    out["less_flicker"] = _all(less)
    out["bytes_fifth"] = bool(texture_ratio <= 0.2) if _finite(texture_ratio) else None
    return out


# ------------------------------------------------------------------ running


def corpus_cases(settings: CorpusSettings, camera: str, resolution: int | None = None) -> list[Case]:
    """The six renderings of :data:`RENDERERS` at ``camera``: the texture ones
    at the default build (``BASELINE``) with ``settings``' resolution (or
    ``resolution``) and K; at :data:`AUTO_CAMERA` only :data:`AUTO_RENDERERS`."""
    cfg = {**BASELINE, "resolution": resolution or settings.resolution, "directions": settings.directions,
           "splat": settings.splat}  # fmt: skip
    cases = [
        Case("mesh-1spp", "mesh", camera, ssaa=1),
        Case("mesh-2x2", "mesh", camera, ssaa=2),
        Case("mesh-4x4", "mesh", camera, ssaa=4),
        volume_case(camera, cfg),
        replace(splat_case(camera, {**cfg, "quality": "fast"}), renderer="splat-fast"),
        replace(splat_case(camera, {**cfg, "quality": "high"}), renderer="splat-high"),
    ]
    return [c for c in cases if c.renderer in AUTO_RENDERERS] if camera == AUTO_CAMERA else cases


@dataclass
class CorpusResult:
    """What a corpus run produced: one summary per scene (bytes, cameras,
    ``targets``), one row per scene, camera ("close", "minified", "turntable")
    and renderer, and the run's description."""

    scenes: list[dict]
    rows: list[dict]
    meta: dict

    @property
    def failed(self) -> list[dict]:
        return [r for r in self.rows if r["status"] == "failed"]


class _Scene:
    """One scene's measurements on a shared context."""

    def __init__(self, name: str, mesh: Mesh, settings: CorpusSettings, with_flip: bool, gt_ssaa: int,
                 step: Callable[[str], None]) -> None:  # fmt: skip
        self.name, self.mesh, self.settings = name, mesh, settings
        self.with_flip, self.gt_ssaa, self.step = with_flip, gt_ssaa, step
        self.rows: list[dict] = []

    def run(self, gl: GLContext) -> dict:
        s, mesh = self.settings, self.mesh
        t0 = time.perf_counter()
        tex = build_texture(mesh, s.resolution, s.directions, bounds=mesh.bounds)
        build_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        points = texture_points(tex, BASELINE["placement"], BASELINE["per_entry"], BASELINE["point_normal"])
        points_s = time.perf_counter() - t0
        self.step(f"{self.name}: texture")
        things = {"mesh": mesh, "volume": tex, "splat": points}
        cams = corpus_cameras(mesh, s.size, s.resolution)
        mesh_bytes = ply_bytes(mesh)
        summary = {
            "scene": self.name,
            "triangles": mesh.n_faces,
            "vertices": len(mesh.vertices),
            "mesh_ply_bytes": mesh_bytes,
            "texture_bytes": tex.nbytes,
            "points_bytes": points.nbytes,
            "n_voxels": tex.n_voxels,
            "n_points": len(points),
            "texture_ratio": tex.nbytes / mesh_bytes,
            "points_ratio": points.nbytes / mesh_bytes,
            "build_s": build_s,
            "points_s": points_s,
            "close_voxel_px": cams[0].voxel_px,
            "minified_scale": cams[1].scale,
            "minified_voxel_px": cams[1].voxel_px,
        }
        renderer = Renderer(s.size, gl=gl)
        try:
            truths = [self.still(renderer, spec, things) for spec in cams]
            summary["turntable_size"] = self.spin(renderer, cams[1], things)[0]
            if s.auto_close:
                del things, tex, points  # the fixed resolution's texture is done with
                summary.update(self.auto(renderer, cams[0], truths[0]))
        finally:
            renderer.release()
        summary["targets"] = check_targets(self.rows, summary["texture_ratio"])
        return summary

    def row(self, camera: str, case: Case, **values) -> dict:
        row = {"scene": self.name, "camera": camera, "renderer": case.renderer, "method": case.method,
               "ssaa": case.ssaa, "status": "ok", "reason": ""}  # fmt: skip
        row.update(values)
        self.rows.append(row)
        return row

    def auto(self, renderer: Renderer, close: CameraSpec, truth: np.ndarray) -> dict:
        """The texture renderers at the close camera, the texture built at the
        resolution ``--resolution auto`` picks there; its summary columns."""
        s = self.settings
        res = needed_resolution(close.camera, s.size, self.mesh.bounds)
        t0 = time.perf_counter()
        tex = build_texture(self.mesh, res, s.directions, bounds=self.mesh.bounds)
        build_s = time.perf_counter() - t0
        points = texture_points(tex, BASELINE["placement"], BASELINE["per_entry"], BASELINE["point_normal"])
        self.step(f"{self.name}: texture {res}^3")
        spec = replace(close, label=AUTO_CAMERA, voxel_px=close.voxel_px * s.resolution / res)
        self.still(renderer, spec, {"volume": tex, "splat": points}, truth=truth, resolution=res)
        return {"auto_resolution": res, "auto_voxel_px": spec.voxel_px, "auto_texture_bytes": tex.nbytes,
                "auto_points_bytes": points.nbytes, "auto_build_s": build_s}  # fmt: skip

    def still(self, renderer: Renderer, spec: CameraSpec, things: dict, truth: np.ndarray | None = None,
              resolution: int | None = None) -> np.ndarray:  # fmt: skip
        """The truth (unless given), then every renderer's image and frame
        times, at ``spec``; returns the truth."""
        if truth is None:
            truth = renderer.render(self.mesh, spec.camera, "mesh", ssaa=self.gt_ssaa, alpha=True)
            self.step(f"{self.name}: truth {spec.label}")
        common = {"distance_scale": spec.scale, "voxel_px": spec.voxel_px,
                  "crop_w": spec.crop[2] - spec.crop[0], "crop_h": spec.crop[3] - spec.crop[1]}  # fmt: skip
        if resolution is not None:
            common["resolution"] = resolution
        for case in corpus_cases(self.settings, spec.label, resolution):
            row = self.row(spec.label, case, **common)
            try:
                img, timing = measure(renderer, things[case.method], case, spec, self.settings)
            except Exception as exc:  # recorded in the row, never fatal to the run
                row["status"], row["reason"] = classify_failure(exc, case.method)
            else:
                row.update({k: timing[k] for k in ("frame_s", "frame_min_s", "frame_max_s", "frames")})
                row.update(score(truth, img, spec.crop, self.with_flip))
            finally:
                load = loadavg()
                row["load_1min"] = load[0] if load else None
            self.step(f"{self.name}: {spec.label} {case.renderer}")
        return truth

    def spin(self, renderer: Renderer, spec: CameraSpec, things: dict) -> tuple[int, int]:
        """The turntable at ``spec``'s distance: flicker and mean PSNR of each renderer."""
        cam, size = turntable_window(spec, self.mesh.bounds, self.settings.size)
        cams = turntable(cam, self.settings.turntable)
        truth = np.stack([renderer.render(self.mesh, c, "mesh", ssaa=self.gt_ssaa, size=size) for c in cams])
        for case in corpus_cases(self.settings, "turntable"):
            row = self.row("turntable", case, distance_scale=spec.scale, voxel_px=spec.voxel_px,
                           crop_w=size[0], crop_h=size[1], frames=len(cams))  # fmt: skip
            try:
                seq = np.stack([renderer.render(things[case.method], c, case.method, ssaa=case.ssaa, size=size,
                                                **case.render_options()) for c in cams])  # fmt: skip
            except Exception as exc:
                row["status"], row["reason"] = classify_failure(exc, case.method)
                continue
            row["flicker"] = flicker(seq, truth)
            row["flicker_error"] = flicker_error(seq, truth)
            row["psnr"] = float(np.mean([metrics.psnr(t, f) for t, f in zip(truth, seq, strict=True)]))
        self.step(f"{self.name}: turntable")
        return size


def run_corpus(
    settings: CorpusSettings,
    meshes: Iterable[tuple[str, Mesh]] | None = None,
    progress: Progress | None = None,
    with_flip: bool | None = None,
    backend: str = "auto",
    n_meshes: int | None = None,
) -> CorpusResult:
    """Measure every scene of ``settings.scenes`` (or the given (name, mesh)
    pairs, e.g. small versions for a test or a user's files, read as the run
    reaches them when ``n_meshes`` says how many to expect), one at a time on
    one GL context.

    ``progress(fraction, stage)`` is called after each step; ``with_flip``
    None computes FLIP when its package is installed.
    """
    if with_flip is None:
        with_flip = metrics.flip_available()
    if meshes is None:  # built one at a time as the run reaches them
        pairs: Iterable[tuple[str, Mesh]] = scenes.corpus(settings.scenes)
        n_scenes = len(settings.scenes)
    elif n_meshes is not None:
        pairs, n_scenes = meshes, n_meshes
    else:
        pairs = list(meshes)
        n_scenes = len(pairs)
    t_start = time.perf_counter()
    load_start = loadavg()
    version = code_version(CODE_PATHS)  # the code that measures, before anything can change it
    # Texture, two truths, two cameras of renderers, the turntable, the texture
    # and renderers at "auto", done.
    auto = 1 + len(AUTO_RENDERERS) if settings.auto_close else 0
    total = max(1, n_scenes * (1 + 2 * (1 + len(RENDERERS)) + 2 + auto))
    done = 0

    def step(stage: str) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(min(1.0, done / total), stage)

    summaries, rows = [], []
    gl = GLContext(backend)
    try:
        gt = truth_ssaa(gl, settings.size, settings.gt_ssaa)
        for name, mesh in pairs:
            t0 = time.perf_counter()
            sc = _Scene(name, mesh, settings, with_flip, gt, step)
            summary = sc.run(gl)
            summary["seconds"] = time.perf_counter() - t0
            step(f"{name}: done")
            summaries.append(summary)
            rows.extend(sc.rows)
        gl_info = {"renderer": gl.renderer, "version": gl.version, "backend": gl.backend}
    finally:
        gl.release()
    load_end = loadavg()
    meta = {
        "preset": settings.name,
        "settings": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(settings).items()},
        "size": list(settings.size),
        "gt_ssaa": gt,
        "flip": with_flip,
        "view": {"azimuth": VIEW_AZIMUTH, "elevation": VIEW_ELEVATION, "fov": VIEW_FOV},
        "targets": dict(TARGETS),
        "opengl": gl_info,
        "code": version,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpu_model": cpu_model(),
        "cpus": os.cpu_count(),
        "load_average": {"start": list(load_start) if load_start else None,
                         "end": list(load_end) if load_end else None},  # fmt: skip
        "seconds": time.perf_counter() - t_start,
        "date": time.strftime("%Y-%m-%d %H:%M"),
    }
    return CorpusResult(summaries, rows, meta)
