"""``aniso3d bench``: the speed/accuracy trade of every renderer and setting, in numbers.

For one scene (the built-in tree, or any mesh) the bench renders each
configuration, times it, and compares its image with a ground truth: the
polygon model supersampled (8 x 8 samples per pixel by default), drawn with the
same camera, lights and image size. The paper claims that the anisotropic
texture reduces data and aliases less than polygons; this turns both claims
into numbers, and gives users the tool for their own scenes.

The sweep is not the full cartesian product. Around one *baseline*
configuration (resolution, directions K, placement, points per entry, point
normal, splat shape, quality) it runs

- the **grid**: every renderer (polygons at 1, 2x2 and 4x4 samples per pixel,
  volume, splat) at every camera distance, from the frame-filling camera to
  cameras where a baseline voxel spans 1 pixel and less (the distance follows
  from the voxel size, the image height and the field of view);
- the **one-axis blocks**: each setting varied alone around the baseline
  (resolution, K, placement, points per entry, point normal, splat shape,
  quality), each at two cameras: ``near`` (the frame-filling one) and ``far``
  (a baseline voxel about one pixel wide, where aliasing starts).

A configuration shared by several blocks (the baseline itself) is measured once
and its row lists every block it belongs to.

For every row: build seconds, bytes (mesh, texture, points, GPU upload), frame
seconds (median of several frames after a warm-up frame), and PSNR, SSIM and
FLIP against the ground truth. Errors are computed on the 8-bit images as the
renderers write them, read as display-referred sRGB-encoded values (see
:mod:`aniso3d.metrics`), inside the box the object's bounds project to (plus a
margin), so that a far, small object is not scored mostly on empty background.

A configuration whose renderer is not available (its module is missing, or it
raises NotImplementedError) is recorded as ``skipped`` with the reason; any
other error is recorded as ``failed`` and makes the command exit with status 1
after writing everything else.

New measurements plug in as another block in :func:`plan_cases`. A case's
``extra`` options go to ``Renderer.render`` and become columns: a
level-of-detail block is cases with ``extra=(("lod", True),)``, drawn from the
texture's pyramid, and whatever the renderer reports in ``last_lod_stats``
(points drawn, level) lands in ``lod_*`` columns. The CSV and JSON writers keep
every key a row has.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from aniso3d.errors import InputError

# ------------------------------------------------------------------ settings

RENDERERS = ("mesh-1spp", "mesh-2x2", "mesh-4x4", "volume", "splat")
MESH_LABEL = {1: "mesh-1spp", 2: "mesh-2x2", 4: "mesh-4x4"}
#: The one-axis blocks and the Case field each one varies.
AXES = {
    "resolution": "resolution",
    "directions": "directions",
    "placement": "placement",
    "per_entry": "per_entry",
    "point_normal": "point_normal",
    "splat": "splat",
    "quality": "quality",
}
#: Axes that only the splat renderer has (the volume renderer draws the texture;
#: it has a shading normal of its own, swept with the points' normal).
SPLAT_AXES = ("placement", "per_entry", "splat", "quality")


@dataclass(frozen=True)
class Settings:
    """What one bench run sweeps.

    Attributes:
        name: preset name ("full", "quick", "smoke").
        size: (width, height) of every image, pixels.
        gt_ssaa: samples per pixel along each axis of the polygon ground truth.
        mesh_ssaa: supersampling factors of the polygon renderer rows.
        resolutions, directions, placements, per_entry, point_normals, splats,
            qualities: the values of each one-axis block.
        baseline: the configuration the one-axis blocks vary around; each value
            must be among its axis' values.
        footprints: camera distances of the grid, as the width in pixels of a
            baseline voxel (the frame-filling camera is always added first).
        frames: timed frames per configuration (median reported).
        warmup: untimed frames first (the first one also uploads).
        frame_budget: seconds after which a configuration stops timing more
            frames (at least one is always timed).
    """

    name: str
    size: tuple[int, int]
    gt_ssaa: int
    mesh_ssaa: tuple[int, ...]
    resolutions: tuple[int, ...]
    directions: tuple[int, ...]
    placements: tuple[str, ...]
    per_entry: tuple[int, ...]
    point_normals: tuple[str, ...]
    splats: tuple[str, ...]
    qualities: tuple[str, ...]
    baseline: dict = field(default_factory=dict)
    footprints: tuple[float, ...] = (1.0,)
    frames: int = 5
    warmup: int = 1
    frame_budget: float = 10.0

    def __post_init__(self) -> None:
        for axis, fieldname in (
            ("resolution", "resolutions"),
            ("directions", "directions"),
            ("placement", "placements"),
            ("per_entry", "per_entry"),
            ("point_normal", "point_normals"),
            ("splat", "splats"),
            ("quality", "qualities"),
        ):
            values = getattr(self, fieldname)
            if not values:
                raise InputError(f"bench settings: no values for {fieldname}")
            if self.baseline.get(axis) not in values:
                raise InputError(
                    f"bench settings: baseline {axis}={self.baseline.get(axis)!r} "
                    f"is not in {values}"
                )
        if self.frames < 1 or self.warmup < 1:
            raise InputError("bench settings: need at least 1 warm-up frame and 1 timed frame")
        if self.gt_ssaa < 2:
            raise InputError(
                f"the ground truth needs supersampling (>= 2 samples a side), got {self.gt_ssaa}"
            )


#: The sweep varies one setting at a time around the code's defaults (which
#: were themselves chosen from an earlier run of this sweep).
_BASELINE = {
    "resolution": 128,
    "directions": 16,
    "placement": "centroid",
    "per_entry": 1,
    "point_normal": "mean",
    "splat": "disc",
    "quality": "fast",
}

PRESETS = {
    # Ten to twenty minutes on a 2-core software rasteriser. At 1024 pixels a
    # 128^3 voxel of a frame-filling object spans about 4.6 pixels.
    "full": Settings(
        name="full",
        size=(1024, 1024),
        gt_ssaa=8,
        mesh_ssaa=(1, 2, 4),
        resolutions=(32, 64, 128, 256),
        directions=(16, 64, 256),
        placements=("centroid", "center", "sphere"),
        per_entry=(1, 4),
        point_normals=("mean", "sample"),
        splats=("square", "disc", "ellipse"),
        qualities=("fast", "high"),
        baseline=dict(_BASELINE),
        footprints=(2.0, 1.5, 1.0, 0.7, 0.5, 0.35, 0.25),
        frames=7,
        warmup=1,
        frame_budget=10.0,
    ),
    # About a minute: 256 x 256 images and a 64^3 baseline (a voxel of the
    # frame-filling object spans about 2.3 pixels).
    "quick": Settings(
        name="quick",
        size=(256, 256),
        gt_ssaa=8,
        mesh_ssaa=(1, 2, 4),
        resolutions=(32, 64, 128),
        directions=(16, 64),
        placements=("centroid", "center", "sphere"),
        per_entry=(1,),
        point_normals=("mean",),
        splats=("square", "disc", "ellipse"),
        qualities=("fast", "high"),
        baseline={**_BASELINE, "resolution": 64},
        footprints=(1.0, 0.5),
        frames=3,
        warmup=1,
        frame_budget=2.0,
    ),
    # Seconds: for the test suite; every code path, no meaningful numbers.
    "smoke": Settings(
        name="smoke",
        size=(96, 96),
        gt_ssaa=4,
        mesh_ssaa=(1, 2),
        resolutions=(16, 32),
        directions=(16,),
        placements=("centroid", "sphere"),
        per_entry=(1,),
        point_normals=("mean",),
        splats=("square", "disc"),
        qualities=("fast",),
        baseline={**_BASELINE, "resolution": 16, "directions": 16},
        footprints=(1.0,),
        frames=1,
        warmup=1,
        frame_budget=1.0,
    ),
}


# ------------------------------------------------------------------- cameras


@dataclass(frozen=True)
class CameraSpec:
    """One camera of the sweep.

    Attributes:
        label: "fill" or the baseline voxel's width in pixels, e.g. "1px".
        scale: ``distance_scale`` of :meth:`Camera.frame` (1 = fills the frame).
        camera: the camera.
        distance: eye-to-target distance, world units.
        voxel_px: width in pixels of a baseline voxel at the target.
        crop: (x0, y0, x1, y1) pixel box the errors are computed in.
    """

    label: str
    scale: float
    camera: object
    distance: float
    voxel_px: float
    crop: tuple[int, int, int, int]


def pixels_per_unit(size: tuple[int, int], fov: float, distance: float) -> float:
    """Image pixels spanned by one world unit at ``distance`` (vertical fov, degrees)."""
    return size[1] / (2.0 * distance * math.tan(math.radians(fov) / 2.0))


def crop_box(
    camera, bounds: np.ndarray, size: tuple[int, int], margin: int = 8, min_side: int = 16
) -> tuple[int, int, int, int]:
    """Pixel box (x0, y0, x1, y1) around the projection of the 8 corners of
    ``bounds``, grown by ``margin``, clamped to the image, at least ``min_side``
    pixels a side (SSIM needs 11)."""
    b = np.asarray(bounds, dtype=np.float64)
    corners = np.array(
        [[b[i, 0], b[j, 1], b[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    )
    xy = camera.project(corners, size, bounds)
    w, h = size
    x0, y0 = np.floor(xy.min(axis=0)) - margin
    x1, y1 = np.ceil(xy.max(axis=0)) + margin
    box = []
    for lo, hi, n in ((x0, x1, w), (y0, y1, h)):
        lo, hi = int(max(0, lo)), int(min(n, hi))
        side = min(n, max(min_side, hi - lo))
        if hi - lo < side:
            mid = (lo + hi) // 2
            lo = max(0, min(n - side, mid - side // 2))
            hi = lo + side
        box.append((lo, hi))
    (x0, x1), (y0, y1) = box
    return x0, y0, x1, y1


def make_cameras(bounds: np.ndarray, settings: Settings) -> list[CameraSpec]:
    """The frame-filling camera, then one per footprint that lies farther away.

    A baseline voxel (edge ``longest extent / baseline resolution``) spans
    ``h * H / (2 d tan(fov / 2))`` pixels at distance d, so the distance for a
    footprint f is the frame-filling one times ``footprint_at_fill / f``.
    """
    from aniso3d.rendering.camera import Camera

    b = np.asarray(bounds, dtype=np.float64)
    h0 = float(np.max(b[1] - b[0])) / settings.baseline["resolution"]
    fill = Camera.frame(b)
    d0 = float(np.linalg.norm(np.subtract(fill.position, fill.target)))
    fp0 = h0 * pixels_per_unit(settings.size, fill.fov, d0)
    specs = [CameraSpec("fill", 1.0, fill, d0, fp0, crop_box(fill, b, settings.size))]
    for f in sorted(set(settings.footprints), reverse=True):
        scale = fp0 / f
        if scale < 1.05:  # would not be farther than the frame-filling camera
            continue
        cam = Camera.frame(b, distance_scale=scale)
        specs.append(
            CameraSpec(f"{f:g}px", scale, cam, d0 * scale, f, crop_box(cam, b, settings.size))
        )
    return specs


def near_far(cameras: list[CameraSpec]) -> tuple[CameraSpec, CameraSpec]:
    """The one-axis blocks' cameras: frame-filling, and the one where a
    baseline voxel is one pixel wide (else the farthest)."""
    far = next((c for c in cameras if c.label == "1px"), cameras[-1])
    return cameras[0], far


# --------------------------------------------------------------------- cases


@dataclass(frozen=True)
class Case:
    """One configuration at one camera. Unused fields are None (a polygon
    rendering has no resolution; a volume rendering has no splat shape)."""

    renderer: str
    method: str
    camera: str
    ssaa: int = 1
    resolution: int | None = None
    directions: int | None = None
    placement: str | None = None
    per_entry: int | None = None
    point_normal: str | None = None
    splat: str | None = None
    quality: str | None = None
    #: Further ``Renderer.render`` options as (name, value) pairs, e.g.
    #: ``(("lod", True),)`` for a level-of-detail block; each is also a column.
    extra: tuple[tuple[str, object], ...] = ()

    @property
    def lod(self) -> bool:
        """Drawn from the texture's pyramid (``Renderer.render(..., lod=True)``)."""
        return bool(dict(self.extra).get("lod"))

    @property
    def texture_key(self) -> tuple | None:
        return None if self.resolution is None else (self.resolution, self.directions)

    @property
    def points_key(self) -> tuple | None:
        if self.method != "splat" or self.lod:
            return None
        return (self.resolution, self.directions, self.placement, self.per_entry, self.point_normal)

    def render_options(self) -> dict:
        """Options for ``Renderer.render``: the splat shape and quality, and the
        volume renderer's shading normal (the points carry theirs), and
        ``extra``. Level-of-detail splats are made by the renderer from the
        texture, so they also take the point build options."""
        if self.method == "volume":
            opts = {} if self.point_normal is None else {"normal": self.point_normal}
        else:
            pairs = [("splat", self.splat), ("quality", self.quality)]
            if self.lod:
                pairs += [("placement", self.placement), ("per_entry", self.per_entry),
                          ("point_normal", self.point_normal)]  # fmt: skip
            opts = {k: v for k, v in pairs if v is not None}
        return {**opts, **dict(self.extra)}


def _volume_case(camera: str, cfg: dict) -> Case:
    return Case(
        "volume",
        "volume",
        camera,
        resolution=cfg["resolution"],
        directions=cfg["directions"],
        point_normal=cfg["point_normal"],
    )


def _splat_case(camera: str, cfg: dict) -> Case:
    return Case(
        "splat",
        "splat",
        camera,
        resolution=cfg["resolution"],
        directions=cfg["directions"],
        placement=cfg["placement"],
        per_entry=cfg["per_entry"],
        point_normal=cfg["point_normal"],
        splat=cfg["splat"],
        quality=cfg["quality"],
    )


def plan_cases(settings: Settings, cameras: list[CameraSpec]) -> dict[Case, list[str]]:
    """Every case to measure, each with the blocks it belongs to (in order)."""
    plan: dict[Case, list[str]] = {}

    def add(case: Case, block: str) -> None:
        blocks = plan.setdefault(case, [])
        if block not in blocks:
            blocks.append(block)

    base = settings.baseline
    for cam in cameras:
        for s in settings.mesh_ssaa:
            add(Case(MESH_LABEL.get(s, f"mesh-{s}x{s}"), "mesh", cam.label, ssaa=s), "grid")
        add(_volume_case(cam.label, base), "grid")
        add(_splat_case(cam.label, base), "grid")
        # The same two drawn from the texture's pyramid (issue 7): only what
        # the view needs, a voxel per pixel.
        lod = (("lod", True),)
        add(replace(_volume_case(cam.label, base), extra=lod), "lod")
        add(replace(_splat_case(cam.label, base), extra=lod), "lod")
    values = {
        "resolution": settings.resolutions,
        "directions": settings.directions,
        "placement": settings.placements,
        "per_entry": settings.per_entry,
        "point_normal": settings.point_normals,
        "splat": settings.splats,
        "quality": settings.qualities,
    }
    for cam in near_far(cameras):
        for axis, vals in values.items():
            for v in vals:
                cfg = {**base, axis: v}
                if axis not in SPLAT_AXES:
                    add(_volume_case(cam.label, cfg), axis)
                add(_splat_case(cam.label, cfg), axis)
    return plan


# ------------------------------------------------------------------- running

#: Row columns, in CSV order; rows may carry more keys, written after these.
# fmt: off
COLUMNS = (
    "status", "reason", "blocks", "camera", "renderer", "method", "ssaa", "resolution",
    "directions", "placement", "per_entry", "point_normal", "splat", "quality", "image_w",
    "image_h", "gt_ssaa", "distance_scale", "camera_distance", "camera_voxel_px", "voxel_px",
    "crop_w", "crop_h", "n_triangles", "n_voxels", "n_entries", "n_points", "mesh_bytes",
    "texture_bytes", "density_bytes", "centroid_bytes", "mean_normal_bytes", "points_bytes",
    "upload_bytes", "build_s", "points_s", "first_frame_s", "frame_s", "frame_min_s",
    "frame_wall_s", "frame_cpu_s", "downfilter_cpu_s", "frames", "psnr", "ssim", "flip",
    "error", "coverage", "pareto",
)
# fmt: on


def classify_failure(exc: BaseException, method: str) -> tuple[str, str]:
    """("skipped", why) when the renderer is not available, else ("failed", what)."""
    if isinstance(exc, ModuleNotFoundError) and (exc.name or "").startswith("aniso3d.rendering."):
        return "skipped", f"renderer '{method}' not available yet (module {exc.name} is missing)"
    if isinstance(exc, NotImplementedError):
        return "skipped", f"renderer '{method}' not implemented yet: {exc}".rstrip(": ")
    return "failed", f"{type(exc).__name__}: {exc}"


@dataclass
class BenchResult:
    """What a run produced: one dict per row, the run's description, and
    cropped images of the grid block (camera -> renderer -> image) for the montage."""

    rows: list[dict]
    meta: dict
    images: dict[str, dict[str, np.ndarray]]

    @property
    def failed(self) -> list[dict]:
        return [r for r in self.rows if r["status"] == "failed"]


def _measure(
    renderer, thing, case: Case, cam: CameraSpec, settings: Settings
) -> tuple[np.ndarray, dict]:
    """Render ``case`` (warm-up first, its RGBA image kept), then time frames."""
    opts = case.render_options()
    t0 = time.perf_counter()
    img = renderer.render(thing, cam.camera, case.method, ssaa=case.ssaa, alpha=True, **opts)
    first = time.perf_counter() - t0
    for _ in range(settings.warmup - 1):
        renderer.render(thing, cam.camera, case.method, ssaa=case.ssaa, **opts)
    gl_times, wall_times, cpu_times = [], [], []
    while len(gl_times) < settings.frames:
        t0, c0 = time.perf_counter(), time.process_time()
        renderer.render(thing, cam.camera, case.method, ssaa=case.ssaa, **opts)
        cpu_times.append(time.process_time() - c0)
        wall_times.append(time.perf_counter() - t0)
        gl_times.append(renderer.last_frame_seconds)
        if sum(wall_times) > settings.frame_budget:
            break
    downfilter = _downfilter_cpu(renderer.size, case.ssaa)
    handle = renderer.upload(thing, case.method) if not case.lod else None
    # What a level-of-detail frame selected (points drawn, level...), if anything.
    stats = getattr(renderer, "last_lod_stats", None)
    extra = {}
    if isinstance(stats, dict):
        extra = {f"lod_{k}": v for k, v in stats.items() if isinstance(v, (int, float, str))}
    return img, {
        **extra,
        "first_frame_s": first,
        "frame_s": float(np.median(gl_times)),
        "frame_min_s": float(np.min(gl_times)),
        "frame_wall_s": float(np.median(wall_times)),
        "frame_cpu_s": max(0.0, float(np.median(cpu_times)) - downfilter),
        "downfilter_cpu_s": downfilter,
        "frames": len(gl_times),
        "upload_bytes": getattr(handle, "nbytes", math.nan),
    }


def _downfilter_cpu(size: tuple[int, int], ssaa: int, repeats: int = 3) -> float:
    """CPU seconds that ``Renderer.render`` spends box-filtering an ``ssaa``
    framebuffer on the host (0 without supersampling), measured on a frame of
    the same size. Subtracted from ``frame_cpu_s``: a real-time renderer
    resolves on the GPU, so it is not the method's cost. Approximate: the
    filter's own CPU time varies by some 20% between runs."""
    if ssaa <= 1:
        return 0.0
    from aniso3d.rendering.renderer import downsample as _downsample  # the very filter render() applies

    # Filled (not lazily zero-mapped) and flipped like the read-back frame.
    raw = np.full((size[1] * ssaa, size[0] * ssaa, 4), 128, np.uint8)[::-1]
    times = []
    for _ in range(repeats):
        c0 = time.process_time()
        np.ascontiguousarray(np.round(_downsample(raw.astype(np.float32), ssaa)).astype(np.uint8))
        times.append(time.process_time() - c0)
    return float(np.median(times))


def _blank_row(case: Case, blocks: list[str], cam: CameraSpec, settings: Settings, mesh) -> dict:
    row = {c: None for c in COLUMNS}
    row.update({k: v for k, v in asdict(case).items() if k != "extra"})
    row.update(dict(case.extra))
    row.update(
        status="ok",
        reason="",
        blocks=";".join(blocks),
        image_w=settings.size[0],
        image_h=settings.size[1],
        distance_scale=cam.scale,
        camera_distance=cam.distance,
        camera_voxel_px=cam.voxel_px,
        crop_w=cam.crop[2] - cam.crop[0],
        crop_h=cam.crop[3] - cam.crop[1],
        n_triangles=mesh.n_faces,
        mesh_bytes=mesh.nbytes,
        pareto=False,
    )
    return row


def run_bench(
    mesh,
    settings: Settings,
    progress: Callable[[float, str], None] | None = None,
    with_flip: bool | None = None,
    backend: str = "auto",
) -> BenchResult:
    """Measure every case of :func:`plan_cases` for ``mesh``; see the module docstring."""
    from aniso3d import metrics
    from aniso3d.build.texture import build_texture
    from aniso3d.rendering.context import GLContext
    from aniso3d.rendering.renderer import Renderer

    report = progress or (lambda fraction, stage: None)
    if with_flip is None:
        with_flip = metrics.flip_available()
    t_start = time.perf_counter()
    load_start = _loadavg()
    bounds = mesh.bounds
    cameras = make_cameras(bounds, settings)
    by_label = {c.label: c for c in cameras}
    plan = plan_cases(settings, cameras)
    total = len(cameras) + len(plan) + len({c.texture_key for c in plan if c.texture_key})
    done = 0

    def step(stage: str) -> None:
        nonlocal done
        done += 1
        report(done / total, stage)

    rows: list[dict] = []
    images: dict[str, dict[str, np.ndarray]] = {c.label: {} for c in cameras}
    gl = GLContext(backend)
    try:
        limit = min(gl.max_texture_size, *gl.max_viewport)
        gt_ssaa = settings.gt_ssaa
        while gt_ssaa > 2 and max(settings.size) * gt_ssaa > limit:
            gt_ssaa //= 2
        if max(settings.size) * gt_ssaa > limit:
            raise InputError(
                f"this OpenGL's framebuffer limit ({limit} px) is too small for a "
                f"supersampled ground truth at {settings.size[0]}x{settings.size[1]}; "
                "use a smaller --size"
            )
        meshr = Renderer(settings.size, gl=gl)
        truth: dict[str, np.ndarray] = {}
        gt_seconds: dict[str, float] = {}
        for cam in cameras:
            t0 = time.perf_counter()
            truth[cam.label] = meshr.render(mesh, cam.camera, "mesh", ssaa=gt_ssaa, alpha=True)
            gt_seconds[cam.label] = time.perf_counter() - t0
            x0, y0, x1, y1 = cam.crop
            images[cam.label]["ground truth"] = truth[cam.label][y0:y1, x0:x1, :3]
            step("truth")

        def evaluate(row: dict, renderer, thing, case: Case, cam: CameraSpec) -> None:
            try:
                img, timing = _measure(renderer, thing, case, cam, settings)
            except Exception as exc:  # recorded in the row, never fatal to the sweep
                row["status"], row["reason"] = classify_failure(exc, case.method)
                return
            row.update(timing)
            x0, y0, x1, y1 = cam.crop
            ref, test = truth[cam.label][y0:y1, x0:x1, :3], img[y0:y1, x0:x1, :3]
            row.update(metrics.compare(ref, test, with_flip=with_flip))
            # Covered area (alpha) against the ground truth's: above 1 means the
            # rendering claims more of the background than the polygons do.
            gt_alpha = float(truth[cam.label][y0:y1, x0:x1, 3].sum(dtype=np.float64))
            alpha = float(img[y0:y1, x0:x1, 3].sum(dtype=np.float64))
            row["coverage"] = alpha / gt_alpha if gt_alpha > 0 else math.nan
            row["error"] = row["flip"] if with_flip else 1.0 - row["ssim"]
            if "grid" in row["blocks"].split(";"):
                images[cam.label][case.renderer] = test

        # Polygon rows share the ground truth's upload.
        for case, blocks in plan.items():
            if case.method == "mesh":
                cam = by_label[case.camera]
                row = _blank_row(case, blocks, cam, settings, mesh)
                row["gt_ssaa"] = gt_ssaa
                row["build_s"] = 0.0
                evaluate(row, meshr, mesh, case, cam)
                rows.append(row)
                step(case.renderer)

        # Texture rows, one texture (and one GPU upload set) at a time.
        groups: dict[tuple, list[Case]] = {}
        for case in plan:
            if case.texture_key:
                groups.setdefault(case.texture_key, []).append(case)
        for (res, k), cases in groups.items():
            timings: dict[str, float] = {}
            t0 = time.perf_counter()
            try:
                tex = build_texture(mesh, res, k, bounds=bounds, timings=timings)
            except Exception as exc:  # e.g. too little memory for this resolution
                step(f"build {res}")
                for case in cases:
                    row = _blank_row(case, plan[case], by_label[case.camera], settings, mesh)
                    row["status"] = "failed"
                    row["reason"] = f"texture build failed: {type(exc).__name__}: {exc}"
                    rows.append(row)
                    step(case.renderer)
                continue
            build_s = time.perf_counter() - t0
            step(f"build {res}")
            tex_info = {
                "n_voxels": tex.n_voxels,
                "n_entries": tex.n_entries,
                "texture_bytes": tex.nbytes,
                "density_bytes": tex.density.nbytes,
                "centroid_bytes": tex.entry_centroid.nbytes,
                "mean_normal_bytes": tex.entry_normal.nbytes,
                "build_s": build_s,
                "voxel_size": tex.voxel_size,
                **{f"build_{name}_s": v for name, v in timings.items()},
            }
            points: dict[tuple, tuple] = {}
            r = Renderer(settings.size, gl=gl)
            try:
                for case in cases:
                    cam = by_label[case.camera]
                    row = _blank_row(case, plan[case], cam, settings, mesh)
                    row.update(tex_info)
                    row["gt_ssaa"] = gt_ssaa
                    row["voxel_px"] = tex.voxel_size * pixels_per_unit(
                        settings.size, cam.camera.fov, cam.distance
                    )
                    thing = tex
                    if case.method == "splat" and not case.lod:
                        if case.points_key not in points:
                            t0 = time.perf_counter()
                            pts = tex.to_points(case.placement, case.per_entry, case.point_normal)
                            points[case.points_key] = (pts, time.perf_counter() - t0)
                        thing, row["points_s"] = points[case.points_key]
                        row["n_points"], row["points_bytes"] = len(thing), thing.nbytes
                    evaluate(row, r, thing, case, cam)
                    rows.append(row)
                    step(case.renderer)
            finally:
                r.release()
            del tex, points
        meshr.release()
        gl_info = {"renderer": gl.renderer, "version": gl.version, "backend": gl.backend}
    finally:
        gl.release()

    mark_pareto(rows)
    meta = {
        "scene": mesh.name,
        "triangles": mesh.n_faces,
        "mesh_bytes": mesh.nbytes,
        "bounds": np.asarray(bounds).tolist(),
        "preset": settings.name,
        "settings": {
            k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(settings).items()
        },
        "gt_ssaa": gt_ssaa,
        "error_metric": "flip" if with_flip else "1-ssim",
        "flip": with_flip,
        "cameras": [
            {
                "label": c.label,
                "distance_scale": c.scale,
                "distance": c.distance,
                "voxel_px": c.voxel_px,
                "crop": list(c.crop),
                "ground_truth_s": gt_seconds[c.label],
                "role": "near"
                if c is near_far(cameras)[0]
                else "far"
                if c is near_far(cameras)[1]
                else "",
            }
            for c in cameras
        ],
        "colour_space": COLOUR_SPACE,
        "opengl": gl_info,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "seconds": time.perf_counter() - t_start,
        "cpus": os.cpu_count(),
        "load_average": {"start": load_start, "end": _loadavg()},
        "date": time.strftime("%Y-%m-%d %H:%M"),
    }
    return BenchResult(rows, meta, images)


def _loadavg() -> float | None:
    """The 1-minute load average (other processes slow every frame time)."""
    try:
        return float(os.getloadavg()[0])
    except (AttributeError, OSError):
        return None


COLOUR_SPACE = (
    "Images are compared as the renderers write them: 8-bit RGB, read as display-referred "
    "sRGB-encoded values. PSNR and SSIM use those encoded values (peak 255); SSIM is computed "
    "per R, G, B channel with an 11x11 Gaussian window (sigma 1.5, K1 = 0.01, K2 = 0.03) and "
    "averaged; FLIP (LDR, 67 pixels per degree) receives the same values as sRGB and linearises "
    "them itself. All three are computed inside the pixel box that the object's bounding box "
    "projects to, plus 8 pixels, so far cameras are not scored on empty background."
)


# ------------------------------------------------------------------ analysis


def _ok(rows: list[dict]) -> list[dict]:
    return [
        r
        for r in rows
        if r["status"] == "ok" and _finite(r.get("error")) and _finite(r.get("frame_s"))
    ]


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points (cost, error) that no other point beats on both
    (lower is better for both), sorted by cost."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def mark_pareto(rows: list[dict]) -> None:
    """Set ``row["pareto"]``: on the (frame time, error) front of its camera."""
    for r in rows:
        r["pareto"] = False
    for cam in {r["camera"] for r in rows}:
        group = [r for r in _ok(rows) if r["camera"] == cam]
        for i in pareto_front([(r["frame_s"], r["error"]) for r in group]):
            group[i]["pareto"] = True


def in_block(row: dict, block: str) -> bool:
    return block in (row.get("blocks") or "").split(";")


def label(row: dict, verbose: bool = False) -> str:
    """Short human name of a row's configuration."""
    if row["method"] == "mesh":
        return row["renderer"]
    parts = [row["renderer"], f"{row['resolution']}^3", f"K={row['directions']}"]
    if row["method"] == "splat":
        parts += [row["placement"], row["splat"], row["quality"]]
        if verbose or row["per_entry"] != 1:
            parts.append(f"x{row['per_entry']}")
    if verbose or row["point_normal"] not in (None, "mean"):
        parts.append(f"n={row['point_normal']}")
    if row.get("lod"):
        parts.append("lod")
    return " ".join(str(p) for p in parts)


def _cost(row: dict) -> float:
    """CPU seconds per frame where measured, else the frame's wall seconds."""
    return row["frame_cpu_s"] if _finite(row.get("frame_cpu_s")) else row["frame_s"]


def recommend(rows: list[dict], tolerance: float = 0.01) -> list[dict]:
    """Per axis and renderer, the value to use, from the one-axis blocks.

    The most accurate value is the one with the lowest mean error over the
    near and far cameras. Among the values within ``tolerance`` (relative) of
    that error, the one with at least 5% fewer bytes wins (the smallest), else
    one no larger and at least 10% cheaper in CPU seconds per frame (CPU time
    counts the rasteriser's work and, unlike wall time, hardly depends on what
    else the machine runs), else the most accurate itself.

    Returns one dict per (axis, renderer): axis, renderer, value, best, why,
    and table {value: (error, frame seconds, bytes)}.
    """
    out = []
    ok = _ok(rows)
    for axis, fieldname in AXES.items():
        for method in ("volume", "splat"):
            if method == "volume" and axis in SPLAT_AXES:
                continue
            block = [r for r in ok if in_block(r, axis) and r["method"] == method]
            if not block:
                continue
            table: dict = {}
            for v in dict.fromkeys(r[fieldname] for r in block):
                sel = [r for r in block if r[fieldname] == v]
                key = "points_bytes" if method == "splat" else "texture_bytes"
                nbytes = [r[key] for r in sel if _finite(r.get(key))]
                table[v] = (
                    float(np.mean([r["error"] for r in sel])),
                    float(np.mean([_cost(r) for r in sel])),
                    float(np.mean(nbytes)) if nbytes else math.nan,
                )
            best = min(table, key=lambda v: table[v][0])
            e0, t0, b0 = table[best]
            near = [v for v in table if table[v][0] <= e0 * (1 + tolerance)]  # with best
            smallest = min(near, key=lambda v: table[v][2] if _finite(table[v][2]) else math.inf)
            # Only values about as large as the most accurate compete on time.
            same_size = [v for v in near if not table[v][2] > 1.05 * b0]
            cheapest = min(same_size, key=lambda v: table[v][1])
            if table[smallest][2] < 0.95 * b0:
                pick = smallest
                why = (
                    f"within {100 * tolerance:.0f}% of the most accurate ({best}) with "
                    f"{table[pick][2] / 2**20:.1f} instead of {b0 / 2**20:.1f} MiB"
                )
            elif table[cheapest][1] < 0.9 * t0:
                pick = cheapest
                why = (
                    f"within {100 * tolerance:.0f}% of the most accurate ({best}) and cheaper "
                    f"({1e3 * table[pick][1]:.0f} vs {1e3 * t0:.0f} CPU ms per frame)"
                )
            else:
                pick = best
                why = "lowest mean error; no cheaper value comes within 1% of it"
            out.append(
                {"axis": axis, "renderer": method, "value": pick, "best": best, "why": why,
                 "table": table}
            )  # fmt: skip
    return out


# ------------------------------------------------------------------- outputs


def _cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        if math.isnan(v):
            return ""
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return f"{v:.6g}"
    if isinstance(v, np.generic):
        return _cell(v.item())
    return str(v)


def columns_of(rows: list[dict]) -> list[str]:
    extra = sorted({k for r in rows for k in r} - set(COLUMNS))
    return list(COLUMNS) + extra


def to_csv(rows: list[dict]) -> bytes:
    """Every row; empty cells for unmeasured values, ``inf`` for infinite PSNR."""
    cols = columns_of(rows)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([_cell(r.get(c)) for c in cols])
    return buf.getvalue().encode("utf-8")


def _jsonable(v):
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def to_json(result: BenchResult) -> bytes:
    """``{"meta": ..., "columns": [...], "rows": [...]}``; unmeasured and
    infinite values (PSNR of an identical image) are null."""
    doc = {"meta": result.meta, "columns": columns_of(result.rows), "rows": result.rows}
    return (json.dumps(_jsonable(doc), indent=1, allow_nan=False) + "\n").encode("utf-8")


COLOURS = {
    "mesh-1spp": "#d62728",
    "mesh-2x2": "#ff7f0e",
    "mesh-4x4": "#8c564b",
    "volume": "#1f77b4",
    "splat": "#2ca02c",
}
PLOTS = ("pareto.png", "distance.png", "bytes.png", "montage.png")


def matplotlib_available() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def _figure(w: float, h: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w, h), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _plain_log_ticks(axis) -> None:
    """Log-scale ticks labelled 20, 50, 100 rather than 2x10^1."""
    from matplotlib.ticker import FuncFormatter, LogLocator

    axis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(FuncFormatter(lambda v, _: ""))


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()


def _error_name(meta: dict) -> str:
    return "FLIP" if meta["error_metric"] == "flip" else "1 - SSIM"


def plot_pareto(result: BenchResult) -> bytes:
    """Error vs frame time at the near and far cameras, Pareto front joined."""
    cams = [c for c in result.meta["cameras"] if c["role"]]
    fig = _figure(6.5 * len(cams), 5.0)
    axes = fig.subplots(1, len(cams), squeeze=False)[0]
    for ax, cam in zip(axes, cams, strict=True):
        group = [r for r in _ok(result.rows) if r["camera"] == cam["label"]]
        for name in RENDERERS:
            sel = [r for r in group if r["renderer"] == name]
            if sel:
                ax.scatter(
                    [1e3 * r["frame_s"] for r in sel],
                    [r["error"] for r in sel],
                    s=22,
                    color=COLOURS.get(name),
                    label=name,
                    alpha=0.8,
                )
        front = sorted((r for r in group if r["pareto"]), key=lambda r: r["frame_s"])
        if front:
            ax.step(
                [1e3 * r["frame_s"] for r in front],
                [r["error"] for r in front],
                where="post",
                color="k",
                lw=1,
                label="Pareto front",
            )
            for i, r in enumerate(front):
                ax.annotate(
                    label(r),
                    (1e3 * r["frame_s"], r["error"]),
                    fontsize=6,
                    xytext=(3, 3 if i % 2 == 0 else -8),
                    textcoords="offset points",
                )
        ax.set_xscale("log")
        _plain_log_ticks(ax.xaxis)
        ax.set_xlabel("frame time, ms (draw + read back)")
        ax.set_ylabel(f"error: {_error_name(result.meta)} (lower is better)")
        ax.set_title(
            f"{cam['role']} camera ({cam['label']}: baseline voxel {cam['voxel_px']:.2g} px)"
        )
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    return _png(fig)


def plot_distance(result: BenchResult) -> bytes:
    """Grid block: each metric and the frame time vs camera distance, per renderer."""
    grid = [r for r in _ok(result.rows) if in_block(r, "grid")]
    panels = [("psnr", "PSNR, dB (higher is better)"), ("ssim", "SSIM (higher is better)")]
    if result.meta["flip"]:
        panels.append(("flip", "FLIP (lower is better)"))
    panels.append(("frame_s", "frame time, ms"))
    fig = _figure(4.2 * len(panels), 4.2)
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    for ax, (key, title) in zip(axes, panels, strict=True):
        for name in RENDERERS:
            sel = sorted(
                (r for r in grid if r["renderer"] == name and _finite(r.get(key))),
                key=lambda r: r["distance_scale"],
            )
            if sel:
                scale = 1e3 if key == "frame_s" else 1.0
                ax.plot(
                    [r["camera_voxel_px"] for r in sel],
                    [scale * r[key] for r in sel],
                    "o-",
                    color=COLOURS.get(name),
                    label=name,
                    ms=4,
                )
        ax.set_xscale("log")
        ticks = sorted({r["camera_voxel_px"] for r in grid})
        ax.set_xticks(ticks, [f"{t:.2g}" for t in ticks])
        ax.minorticks_off()
        ax.invert_xaxis()
        if key == "frame_s":
            ax.set_yscale("log")
            _plain_log_ticks(ax.yaxis)
        ax.axvline(1.0, color="grey", ls=":", lw=1)
        ax.set_xlabel("baseline voxel width, pixels (farther ->)")
        ax.set_title(title, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    return _png(fig)


def plot_bytes(result: BenchResult) -> bytes:
    """Texture and point bytes vs resolution, against the mesh's bytes."""
    rows = [r for r in result.rows if in_block(r, "resolution") and _finite(r.get("texture_bytes"))]
    base = result.meta["settings"]["baseline"]
    fig = _figure(6.5, 4.5)
    ax = fig.subplots()
    res = sorted({r["resolution"] for r in rows})

    def series(key, method=None, **match):
        out = []
        for v in res:
            vals = [
                r[key]
                for r in rows
                if r["resolution"] == v
                and _finite(r.get(key))
                and (method is None or r["method"] == method)
                and all(r.get(k) == x for k, x in match.items())
            ]
            out.append(vals[0] if vals else math.nan)
        return out

    ax.axhline(
        result.meta["mesh_bytes"],
        color="k",
        ls="--",
        label=f"mesh ({result.meta['triangles']:,} triangles)",
    )
    ax.plot(
        res,
        series("texture_bytes", directions=base["directions"]),
        "o-",
        color=COLOURS["volume"],
        label=f"texture, K={base['directions']}",
    )
    ax.plot(
        res,
        series("points_bytes", "splat", per_entry=1),
        "s-",
        color=COLOURS["splat"],
        label="points, 1 per entry",
    )
    krows = [
        r for r in result.rows if in_block(r, "directions") and _finite(r.get("texture_bytes"))
    ]
    for k in sorted({r["directions"] for r in krows} - {base["directions"]}):
        b = next(r["texture_bytes"] for r in krows if r["directions"] == k)
        ax.plot([base["resolution"]], [b], "^", color=COLOURS["volume"], alpha=0.6)
        ax.annotate(
            f"K={k}", (base["resolution"], b), fontsize=7, xytext=(4, 0), textcoords="offset points"
        )
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xticks(res, [f"{v}^3" for v in res])
    ax.set_xlabel("resolution (voxels along the longest axis)")
    ax.set_ylabel("bytes")
    ax.set_title(f"data size: {result.meta['scene']}")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return _png(fig)


def plot_montage(result: BenchResult) -> bytes:
    """The grid block's images at each camera, cropped, ground truth first."""
    cams = [c["label"] for c in result.meta["cameras"]]
    cols = ["ground truth"] + [n for n in RENDERERS if any(n in result.images[c] for c in cams)]
    fig = _figure(2.2 * len(cols), 2.3 * len(cams))
    axes = fig.subplots(len(cams), len(cols), squeeze=False)
    for i, cam in enumerate(cams):
        for j, name in enumerate(cols):
            ax = axes[i][j]
            ax.set_xticks([])
            ax.set_yticks([])
            img = result.images[cam].get(name)
            if img is not None:
                ax.imshow(img, interpolation="nearest")
            else:
                ax.text(0.5, 0.5, "skipped", ha="center", va="center", transform=ax.transAxes)
            if i == 0:
                ax.set_title(name, fontsize=9)
            if j == 0:
                ax.set_ylabel(cam, fontsize=9)
    return _png(fig)


def _fmt(v, spec: str = ".3g", scale: float = 1.0) -> str:
    if not _finite(v):
        return "inf" if isinstance(v, float) and math.isinf(v) else "-"
    return format(v * scale, spec)


def _mib(v) -> str:
    return "-" if not _finite(v) else f"{v / 2**20:.1f} MiB"


def _metrics_cells(r: dict) -> list[str]:
    if r["status"] != "ok":
        return [r["status"]] * 5
    return [
        _fmt(r["psnr"], ".2f"),
        _fmt(r["ssim"], ".4f"),
        _fmt(r["flip"], ".4f"),
        _fmt(r.get("coverage"), ".2f"),
        _fmt(r["frame_s"], ".1f", 1e3),
    ]


def _table(header: list[str], body: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(row) + " |" for row in body]
    return out + [""]


def _compare(a: float, b: float) -> str:
    """'x% lower' / 'x% higher' of error a relative to b."""
    if not (_finite(a) and _finite(b)) or b == 0:
        return "n/a"
    d = (a - b) / b
    return f"{abs(100 * d):.0f}% {'lower' if d < 0 else 'higher'}"


def _load_sentence(meta: dict) -> str:
    load = meta.get("load_average") or {}
    if load.get("start") is None:
        return ""
    # The end value includes this run's own rasteriser threads (about one per CPU).
    cpus = meta.get("cpus") or 1
    busy = load["start"] > 0.5 * cpus or (load["end"] or 0.0) > cpus + 0.5
    warning = (
        "**The machine was busy with other work during this run: compare frame times "
        "with care; differences under about 2x may be noise.**"
        if busy
        else ""
    )
    return (warning + " " if warning else "") + (
        f"Load average {load['start']:.1f} at the start and {load['end']:.1f} at the end, on "
        f"{meta.get('cpus')} CPUs: frame times are wall-clock and include any contention "
        "from other processes. Less affected, in the CSV: `frame_min_s` (the fastest frame) "
        "and `frame_cpu_s` (this process's CPU seconds per frame over all rasteriser threads, "
        "counting work rather than waiting, less the host-side down-filtering of supersampled "
        "rows, `downfilter_cpu_s`)."
    )


def _upload_sentences(rows: list[dict], camera: str, res: int) -> list[str]:
    """What each renderer holds on the GPU, and where the texture's bytes go."""

    def first(**match):
        return next(
            (
                r
                for r in rows
                if r["camera"] == camera
                and _finite(r.get("upload_bytes"))
                and all(r.get(k) == v for k, v in match.items())
            ),
            None,
        )

    out = []
    mesh = first(method="mesh", ssaa=1)
    vol = first(method="volume", resolution=res)
    spl = first(method="splat", resolution=res)
    parts = [
        f"{name} {_mib(r['upload_bytes'])}"
        for name, r in (("polygons", mesh), ("volume", vol), ("splats", spl))
        if r
    ]
    if parts:
        out.append(f"As uploaded to the GPU at {res}^3: " + ", ".join(parts) + ".")
    tex = vol or spl
    if tex and _finite(tex.get("density_bytes")):
        t = tex["texture_bytes"]
        d, c, n = tex["density_bytes"], tex["centroid_bytes"], tex["mean_normal_bytes"]
        out.append(
            f"Of the {_mib(t)} texture, the density spheres (float64, voxels x K) are {_mib(d)} "
            f"({100 * d / t:.0f}%), the entries' centroids {_mib(c)} and mean normals {_mib(n)} "
            f"(the cost of centroid placement and mean normals), the rest {_mib(t - d - c - n)}."
        )
    return out + ([""] if out else [])


def _axis_reading(rows: list[dict], fieldname: str, err: str) -> list[str]:
    """One generated line per renderer and camera: best and worst value and the spread."""
    out = []
    ok = _ok(rows)
    for method in ("volume", "splat"):
        for cam in dict.fromkeys(r["camera"] for r in ok):
            sel = [r for r in ok if r["method"] == method and r["camera"] == cam]
            if len(sel) < 2:
                continue
            sel.sort(key=lambda r: r["error"])
            best, worst = sel[0], sel[-1]
            fast = min(sel, key=lambda r: r["frame_s"])
            out.append(
                f"- {method} at `{cam}`: best {best[fieldname]} ({err} "
                f"{_fmt(best['error'], '.4f')}, "
                f"{_fmt(best['frame_s'], '.1f', 1e3)} ms), worst {worst[fieldname]} "
                f"({_fmt(worst['error'], '.4f')}): error spread "
                f"{_compare(worst['error'], best['error'])}; "
                f"fastest {fast[fieldname]} ({_fmt(fast['frame_s'], '.1f', 1e3)} ms)."
            )
    return out


def _aliasing_summary(rows: list[dict], cameras: list[str], err: str) -> list[str]:
    """Each grid renderer averaged over ``cameras``, and the texture renderers'
    mean error relative to the polygon renderings."""
    if not cameras:
        return []
    means: dict[str, dict[str, float]] = {}
    for name in RENDERERS:
        sel = [r for r in _ok(rows) if in_block(r, "grid") and r["renderer"] == name
               and r["camera"] in cameras]  # fmt: skip
        if len(sel) == len(cameras):
            means[name] = {
                k: float(np.mean([r[k] for r in sel]))
                for k in ("psnr", "ssim", "flip", "error", "coverage", "frame_s", "frame_cpu_s")
                if all(_finite(r.get(k)) for r in sel)
            }
    if not means:
        return []
    n = len(cameras)
    out = [f"Mean over the {n} camera{'s' if n != 1 else ''} where a baseline voxel is a pixel "
           "or less:", ""]  # fmt: skip
    body = [
        [name, _fmt(m.get("psnr"), ".2f"), _fmt(m.get("ssim"), ".4f"), _fmt(m.get("flip"), ".4f"),
         _fmt(m.get("coverage"), ".2f"), _fmt(m.get("frame_s"), ".0f", 1e3),
         _fmt(m.get("frame_cpu_s"), ".0f", 1e3)]
        for name, m in means.items()
    ]  # fmt: skip
    out += _table(["renderer", "PSNR dB", "SSIM", "FLIP", "coverage", "frame ms", "CPU ms"], body)
    for name in ("volume", "splat"):
        if name not in means:
            continue
        cmp_ = ", ".join(
            f"{_compare(means[name]['error'], means[m]['error'])} than {m}"
            for m in ("mesh-1spp", "mesh-2x2", "mesh-4x4")
            if m in means
        )
        out.append(f"- {name}: mean {err} {_fmt(means[name]['error'], '.4f')}, {cmp_}.")
    return out + [""]


def make_report(result: BenchResult, plots: list[str], notes: list[str]) -> str:
    """The Markdown report: setup, figures, tables, and a reading generated
    from the numbers."""
    meta, rows = result.meta, result.rows
    s = meta["settings"]
    err = _error_name(meta)
    cams = meta["cameras"]
    near = next(c for c in cams if c["role"] == "near")
    far = next((c for c in cams if c["role"] == "far"), near)
    L: list[str] = []
    L += [
        f"# aniso3d bench: {meta['scene']}",
        "",
        f"Preset `{meta['preset']}`, {s['size'][0]}x{s['size'][1]} images, run {meta['date']} in "
        f"{meta['seconds'] / 60:.1f} min on {meta['opengl']['renderer']} "
        f"({meta['opengl']['backend']}). "
        f"Scene: {meta['triangles']:,} triangles. Ground truth: the polygon model at "
        f"{meta['gt_ssaa']}x{meta['gt_ssaa']} samples per pixel, same camera, lights and "
        "image size. "
        f"Frame time: median of up to {s['frames']} frames after {s['warmup']} warm-up frame(s), "
        "draw plus read-back as `Renderer.last_frame_seconds` reports it (supersampled rows: "
        "their down-filtering on the CPU is in `frame_wall_s` only). " + _load_sentence(meta),
        "",
        f"**Colour space and metrics.** {meta['colour_space']} The error plotted and ranked is "
        f"**{err}**. `coverage` is the rendering's covered area (the sum of its alpha) over "
        "the ground truth's, in the same box: above 1, it hides more background than the "
        "polygons do.",
        "",
        "**Cameras.** "
        + "; ".join(
            f"`{c['label']}`: distance x{c['distance_scale']:.2f}, baseline voxel "
            f"{c['voxel_px']:.2f} px" + (f" ({c['role']})" if c["role"] else "")
            for c in cams
        )
        + ". "
        f"The baseline is {s['baseline']['resolution']}^3, K = {s['baseline']['directions']}, "
        f"{s['baseline']['placement']} placement, {s['baseline']['per_entry']} point(s) per entry, "
        f"{s['baseline']['point_normal']} normal, {s['baseline']['splat']} splats, "
        f"{s['baseline']['quality']} quality.",
        "",
    ]
    L += [f"> {n}" for n in notes] + ([""] if notes else [])

    # ---- data reduction
    L += ["## Data size", ""]
    if "bytes.png" in plots:
        L += ["![bytes vs resolution](bytes.png)", ""]
    res_rows = [r for r in rows if in_block(r, "resolution") and r["camera"] == near["label"]]
    body = []
    for res in sorted({r["resolution"] for r in res_rows}):
        tex = next(
            (r for r in res_rows if r["resolution"] == res and _finite(r.get("texture_bytes"))),
            None,
        )
        pts = next(
            (r for r in res_rows if r["resolution"] == res and _finite(r.get("points_bytes"))), None
        )
        if tex is None:
            continue
        mb = meta["mesh_bytes"]
        body.append(
            [
                f"{res}^3",
                f"{tex['n_voxels']:,}",
                f"{tex['n_entries']:,}",
                _mib(mb),
                _mib(tex["texture_bytes"]),
                f"{tex['texture_bytes'] / mb:.2f}",
                _mib(pts["points_bytes"]) if pts else "-",
                f"{pts['points_bytes'] / mb:.2f}" if pts else "-",
                _fmt(tex["build_s"], ".1f"),
            ]
        )
    L += _table(
        [
            "resolution",
            "voxels",
            "entries (points)",
            "mesh",
            "texture",
            "texture/mesh",
            "points",
            "points/mesh",
            "build s",
        ],
        body,
    )
    base_res = s["baseline"]["resolution"]
    b = next((x for x in body if x[0] == f"{base_res}^3"), None)
    if b:
        ratio_t, ratio_p = float(b[5]), float(b[7]) if b[7] != "-" else math.nan
        verdict = "smaller" if ratio_t < 1 else "larger"
        L += [
            f"At {base_res}^3 the texture is {ratio_t:.2f}x the mesh ({verdict}); the points are "
            f"{_fmt(ratio_p, '.2f')}x the mesh. Texture bytes count every stored array as held in "
            "memory (float64 density and area, the float64 centroid and float32 mean normal "
            "per entry); point bytes are 12 float32 per point as uploaded. "
            + (
                "The paper's data-reduction claim does not hold for this scene at this resolution."
                if ratio_t >= 1 and not (ratio_p < 1)
                else "The data reduction holds for the points."
                if ratio_p < 1 <= ratio_t
                else "The data reduction holds."
            ),
            "",
        ]
    L += _upload_sentences(rows, near["label"], base_res)
    krows = [
        r
        for r in rows
        if in_block(r, "directions") and r["camera"] == near["label"] and r["method"] == "volume"
    ]
    if krows:
        L += [
            "Texture bytes at the baseline resolution by K: "
            + ", ".join(
                f"K={r['directions']}: {_mib(r['texture_bytes'])}"
                for r in sorted(krows, key=lambda r: r["directions"])
            )
            + ".",
            "",
        ]

    # ---- renderer x distance
    L += ["## Error and frame time vs camera distance", ""]
    if "distance.png" in plots:
        L += ["![error vs distance](distance.png)", ""]
    if "montage.png" in plots:
        L += ["![images](montage.png)", ""]
    body = []
    for c in cams:
        for name in RENDERERS:
            r = next(
                (
                    x
                    for x in rows
                    if in_block(x, "grid") and x["camera"] == c["label"] and x["renderer"] == name
                ),
                None,
            )
            if r is not None:
                body.append([c["label"], name] + _metrics_cells(r))
    L += _table(["camera", "renderer", "PSNR dB", "SSIM", "FLIP", "coverage", "frame ms"], body)
    for c in cams:
        grid = [r for r in _ok(rows) if in_block(r, "grid") and r["camera"] == c["label"]]
        if not grid:
            continue
        best = min(grid, key=lambda r: r["error"])
        fast = min(grid, key=lambda r: r["frame_s"])
        one = next((r for r in grid if r["renderer"] == "mesh-1spp"), None)
        beat1 = sorted(
            (r for r in grid if one and r["error"] < one["error"] and r is not one),
            key=lambda r: r["frame_s"],
        )
        line = (
            f"- `{c['label']}` (voxel {c['voxel_px']:.2f} px): most accurate "
            f"**{best['renderer']}** ({err} {_fmt(best['error'], '.4f')}, "
            f"{_fmt(best['frame_s'], '.1f', 1e3)} ms); "
            f"fastest {fast['renderer']} ({_fmt(fast['frame_s'], '.1f', 1e3)} ms)"
        )
        if beat1:
            line += (
                f"; cheapest that beats 1-spp polygons: {beat1[0]['renderer']} "
                f"({_fmt(beat1[0]['frame_s'], '.1f', 1e3)} ms)"
            )
        L.append(line + ".")
    L.append("")

    # ---- aliasing
    L += ["## Aliasing: voxels of a pixel or less", ""]
    far_cams = [c for c in cams if c["voxel_px"] <= 1.0 + 1e-6]
    if not far_cams:
        L += ["No camera of this run puts a baseline voxel at a pixel or less.", ""]
    for c in far_cams:
        grid = {r["renderer"]: r for r in rows if in_block(r, "grid") and r["camera"] == c["label"]}
        ref = {n: grid.get(n) for n in ("mesh-1spp", "mesh-2x2", "mesh-4x4")}
        parts = []
        for name in ("volume", "splat"):
            r = grid.get(name)
            if r is None:
                continue
            if r["status"] != "ok":
                parts.append(f"{name}: not measured ({r['status']}: {r['reason']})")
                continue
            cmp_ = ", ".join(
                f"{_compare(r['error'], m['error'])} than {n} ({_fmt(m['error'], '.4f')}, "
                f"{_fmt(m['frame_s'], '.1f', 1e3)} ms)"
                for n, m in ref.items()
                if m is not None and m["status"] == "ok"
            )
            parts.append(
                f"{name}: {err} {_fmt(r['error'], '.4f')} at {_fmt(r['frame_s'], '.1f', 1e3)} ms, "
                f"{cmp_}"
            )
        L.append(f"- `{c['label']}` (voxel {c['voxel_px']:.2f} px): " + "; ".join(parts) + ".")
    L.append("")
    L += _aliasing_summary(rows, [c["label"] for c in far_cams], err)

    # ---- Pareto
    L += ["## Speed against accuracy", ""]
    if "pareto.png" in plots:
        L += ["![error vs frame time](pareto.png)", ""]
    for c in (near, far) if far is not near else (near,):
        front = sorted(
            (r for r in rows if r["camera"] == c["label"] and r["pareto"]),
            key=lambda r: r["frame_s"],
        )
        L.append(
            f"Pareto front at the {c['role']} camera (`{c['label']}`), fastest first: "
            + "; ".join(
                f"{label(r)} ({_fmt(r['frame_s'], '.1f', 1e3)} ms, {_fmt(r['error'], '.4f')})"
                for r in front
            )
            + "."
        )
        L.append("")

    # ---- one-axis blocks
    L += [
        "## One setting at a time",
        "",
        f"Each setting varied alone around the baseline, at the near (`{near['label']}`) and far "
        f"(`{far['label']}`) cameras. Bytes: the texture for volume rows, the points for "
        "splat rows.",
        "",
    ]
    for axis, fieldname in AXES.items():
        sel = [r for r in rows if in_block(r, axis)]
        if not sel:
            continue
        L += [f"### {axis}", ""]
        body = []
        for r in sorted(
            sel, key=lambda r: (r["method"], r["camera"] != near["label"], str(r[fieldname]))
        ):
            nbytes = r.get("points_bytes") if r["method"] == "splat" else r.get("texture_bytes")
            body.append(
                [str(r[fieldname]), r["method"], r["camera"]]
                + _metrics_cells(r)
                + [_mib(nbytes), _fmt(r.get("build_s"), ".1f")]
            )
        L += _table(
            [
                axis,
                "renderer",
                "camera",
                "PSNR dB",
                "SSIM",
                "FLIP",
                "coverage",
                "frame ms",
                "bytes",
                "build s",
            ],
            body,
        )
        L += _axis_reading(sel, fieldname, err) + [""]

    # ---- level of detail
    lod_rows = [r for r in rows if in_block(r, "lod")]
    if lod_rows:
        L += [
            "## Level of detail",
            "",
            "The baseline volume and splats drawn from the texture's exact pyramid "
            "(`lod=True`, one voxel per pixel): splats take, per region, the coarsest level "
            "whose voxels cover at most a pixel, and skip what is outside the view; the "
            "volume marches the one level fine enough at the object's nearest depth. "
            "Each against the same renderer on the single finest level.",
            "",
        ]
        body = []
        for cam in cams:
            for method in ("splat", "volume"):
                single = next((r for r in rows if in_block(r, "grid")
                               and r["camera"] == cam["label"] and r["method"] == method),
                              None)  # fmt: skip
                lod = next((r for r in lod_rows if r["camera"] == cam["label"]
                            and r["method"] == method), None)  # fmt: skip
                if single is None or lod is None:
                    continue
                if method == "splat":
                    drawn = (f"{_fmt(lod.get('lod_points'), ',.0f')} of "
                             f"{_fmt(single.get('n_points'), ',.0f')} points")  # fmt: skip
                else:
                    drawn = f"level {lod.get('lod_level', '?')}"
                pairs = zip(_metrics_cells(single), _metrics_cells(lod), strict=True)
                body.append([cam["label"], method, drawn] + [f"{a} / {b}" for a, b in pairs])
        L += _table(
            ["camera", "renderer", "LOD draws", "PSNR dB", "SSIM", err, "coverage", "frame ms"],
            body,
        )
        L += ["", "Cells read *single level / LOD*.", ""]

    # ---- recommendation
    rec = recommend(rows)
    L += [
        "## Recommended configuration",
        "",
        f"Chosen per setting and renderer from the one-axis blocks: the value with the lowest "
        f"mean {err} over the near and far cameras, unless a value within 1% of that error "
        "needs at least 5% fewer bytes or 10% less CPU time per frame (CPU time rather than "
        "wall time, as it hardly depends on other load).",
        "",
    ]
    body = []
    for v in rec:
        values = "; ".join(
            f"{k}: {_fmt(e, '.4f')}, {_fmt(t, '.0f', 1e3)} ms"
            for k, (e, t, _) in v["table"].items()
        )
        body.append(
            [v["axis"], v["renderer"], f"**{v['value']}**", str(v["best"]), values, v["why"]]
        )
    L += _table(
        [
            "setting",
            "renderer",
            "recommended",
            "most accurate",
            f"mean {err}, CPU per frame",
            "why",
        ],
        body,
    )

    # ---- skipped / failed
    bad = [r for r in rows if r["status"] != "ok"]
    if bad:
        L += ["## Not measured", ""]
        reasons: dict[tuple[str, str], int] = {}
        for r in bad:
            reasons[(r["status"], r["reason"])] = reasons.get((r["status"], r["reason"]), 0) + 1
        L += [f"- {n} row(s) {status}: {reason}" for (status, reason), n in reasons.items()] + [""]
    L += ["Every row is in `results.csv` and `results.json`.", ""]
    return "\n".join(L)


def write_outputs(
    result: BenchResult, outdir: Path, inputs: tuple = (), plots: bool = True
) -> tuple[list[Path], list[str]]:
    """Write CSV, JSON, plots and report.md into ``outdir`` (atomically, never
    over an input); returns the paths written and notes for the user."""
    from aniso3d.files import atomic_write, refuse_overwriting_input

    notes: list[str] = []
    written: list[Path] = []

    def put(name: str, data: bytes) -> None:
        path = outdir / name
        refuse_overwriting_input(path, *inputs)
        written.append(atomic_write(path, data))

    if not result.meta["flip"]:
        from aniso3d.metrics import FLIP_MISSING

        notes.append(FLIP_MISSING + "; errors are ranked by 1 - SSIM instead.")
    put("results.csv", to_csv(result.rows))
    put("results.json", to_json(result))
    made: list[str] = []
    if not plots:
        notes.append("Plots were not requested (--no-plots).")
    elif not matplotlib_available():
        notes.append(
            "Plots skipped: matplotlib is not installed; install it with: pip install "
            "'aniso3d[plots]'"
        )
    else:
        for name, fn in (
            ("pareto.png", plot_pareto),
            ("distance.png", plot_distance),
            ("bytes.png", plot_bytes),
            ("montage.png", plot_montage),
        ):
            put(name, fn(result))
            made.append(name)
    put("report.md", make_report(result, made, notes).encode("utf-8"))
    return written, notes


# ----------------------------------------------------------------------- CLI


def register(subparsers) -> None:
    from aniso3d.app.common import image_size, positive_int

    p = subparsers.add_parser(
        "bench",
        help=(
            "measure speed, size and error of every renderer and setting against a supersampled "
            "ground truth"
        ),
        description=(
            "Sweep resolution, directions K, point placement, splat shape, quality, renderer "
            "and camera distance for a scene; write results.csv, results.json, plots and "
            "report.md into OUTDIR."
        ),
    )
    p.add_argument(
        "mesh", nargs="?", default=None, help="mesh file or scene:NAME (default: the built-in tree)"
    )
    mode = p.add_mutually_exclusive_group()
    mode.add_argument(
        "--quick", action="store_true", help="a run of a minute or two (256x256, fewer settings)"
    )
    mode.add_argument(
        "--smoke", action="store_true", help="a run of seconds that exercises every path (tests)"
    )
    p.add_argument(
        "-o",
        "--output",
        default="bench-out",
        metavar="OUTDIR",
        help="output folder (default: ./bench-out)",
    )
    p.add_argument(
        "--size",
        type=image_size,
        default=None,
        help="image size, e.g. 512 or 800x600 (default: preset's)",
    )
    p.add_argument(
        "--frames", type=positive_int, default=None, help="timed frames per configuration"
    )
    p.add_argument(
        "--gt-ssaa",
        type=positive_int,
        default=None,
        help="ground-truth samples per pixel along each axis",
    )
    p.add_argument(
        "--no-flip", action="store_true", help="skip FLIP even when flip-evaluator is installed"
    )
    p.add_argument("--no-plots", action="store_true", help="write CSV, JSON and the report only")
    p.add_argument("--backend", default="auto", help="OpenGL backend: auto, egl, osmesa, x11")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_bench)


def cmd_bench(args) -> int:
    from aniso3d.app.common import Progress, load_input
    from aniso3d.build.mesh import Mesh

    settings = PRESETS["smoke" if args.smoke else "quick" if args.quick else "full"]
    overrides = {}
    if args.size:
        overrides["size"] = tuple(args.size)
    if args.frames:
        overrides["frames"] = args.frames
    if args.gt_ssaa:
        overrides["gt_ssaa"] = args.gt_ssaa
    settings = replace(settings, **overrides)
    outdir = Path(args.output)
    if outdir.exists() and not outdir.is_dir():
        raise InputError(f"output '{outdir}' is a file; bench writes a folder of results")
    if args.mesh and Path(args.mesh).exists() and Path(args.mesh).resolve() == outdir.resolve():
        raise InputError(f"output folder '{outdir}' is the input; choose another -o")
    mesh = load_input(args.mesh)
    if not isinstance(mesh, Mesh):
        raise InputError(
            f"'{args.mesh}' is not a polygon mesh; the bench needs the polygons for its "
            "ground truth"
        )
    outdir.mkdir(parents=True, exist_ok=True)
    progress = Progress(f"bench {settings.name}", enabled=False if args.quiet else None)
    result = run_bench(
        mesh,
        settings,
        progress=progress,
        with_flip=False if args.no_flip else None,
        backend=args.backend,
    )
    written, notes = write_outputs(
        result, outdir, inputs=(args.mesh,) if args.mesh else (), plots=not args.no_plots
    )
    counts = {s: sum(r["status"] == s for r in result.rows) for s in ("ok", "skipped", "failed")}
    print(
        f"{len(result.rows)} configurations in {result.meta['seconds']:.0f} s: "
        f"{counts['ok']} measured, {counts['skipped']} skipped, {counts['failed']} failed"
    )
    reasons = sorted({r["reason"] for r in result.rows if r["status"] == "skipped"})
    for reason in reasons:
        print(f"skipped: {reason}")
    for note in notes:
        print(f"note: {note}")
    for path in written:
        print(f"wrote {path}")
    if result.failed:
        for r in result.failed:
            print(
                f"failed: {label(r, verbose=True)} at {r['camera']}: {r['reason']}", file=sys.stderr
            )
        return 1
    return 0
