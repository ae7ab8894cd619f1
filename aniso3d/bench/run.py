"""Running a plan: the ground truth, texture and point builds, timed frames and
image errors, one row (a dict) per case.

For every row: build seconds, bytes (mesh, texture, points, GPU upload), frame
seconds (median, fastest and slowest of several frames after a warm-up frame),
the machine's load average when the row was measured, and PSNR, SSIM and FLIP
against the ground truth: the polygon model supersampled (8 x 8 samples per
pixel by default), drawn with the same camera, lights and image size. Errors are
computed on the 8-bit images as the renderers write them, read as
display-referred sRGB-encoded values (see :mod:`aniso3d.metrics`), inside the
box the object's bounds project to (plus a margin), so that a far, small object
is not scored mostly on empty background.

A renderer that raises NotImplementedError is recorded as ``skipped`` with the
reason; any other error is recorded as ``failed``, and the sweep goes on.
"""

from __future__ import annotations

import math
import os
import platform
import subprocess
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from aniso3d import metrics
from aniso3d.bench.analyse import mark_pareto
from aniso3d.bench.cameras import CameraSpec, make_cameras, near_far, pixels_per_unit
from aniso3d.bench.plan import Case, plan_cases
from aniso3d.bench.settings import Settings
from aniso3d.build.mesh import Mesh
from aniso3d.build.texture import build_texture
from aniso3d.errors import InputError
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.renderer import Renderer, downsample
from aniso3d.rendering.splat.clips import texture_points

#: Row columns, in CSV order; rows may carry more keys, written after these.
# fmt: off
COLUMNS = (
    "status", "reason", "blocks", "camera", "renderer", "method", "ssaa", "resolution",
    "directions", "placement", "per_entry", "point_normal", "splat", "quality", "image_w",
    "image_h", "gt_ssaa", "distance_scale", "camera_distance", "camera_voxel_px", "voxel_px",
    "crop_w", "crop_h", "n_triangles", "n_voxels", "n_entries", "n_points", "mesh_bytes",
    "texture_bytes", "density_bytes", "centroid_bytes", "mean_normal_bytes", "points_bytes",
    "upload_bytes", "build_s", "points_s", "first_frame_s", "frame_s", "frame_min_s", "frame_max_s",
    "frame_wall_s", "frame_cpu_s", "downfilter_cpu_s", "frames", "load_1min", "psnr", "ssim", "flip",
    "error", "coverage", "pareto",
)
# fmt: on

COLOUR_SPACE = (
    "Images are compared as the renderers write them: 8-bit RGB, read as display-referred "
    "sRGB-encoded values. PSNR and SSIM use those encoded values (peak 255); SSIM is computed "
    "per R, G, B channel with an 11x11 Gaussian window (sigma 1.5, K1 = 0.01, K2 = 0.03) and "
    "averaged; FLIP (LDR, 67 pixels per degree) receives the same values as sRGB and linearises "
    "them itself. All three are computed inside the pixel box that the object's bounding box "
    "projects to, plus 8 pixels, so far cameras are not scored on empty background."
)

Progress = Callable[[float, str], None]


@dataclass
class BenchResult:
    """What a run produced: one dict per row (keys: :data:`COLUMNS` and more),
    the run's description, and cropped RGB images (uint8, h x w x 3) of the grid
    block (camera label -> renderer -> image) for the montage."""

    rows: list[dict]
    meta: dict
    images: dict[str, dict[str, np.ndarray]]

    @property
    def failed(self) -> list[dict]:
        return [r for r in self.rows if r["status"] == "failed"]


def classify_failure(exc: BaseException, method: str) -> tuple[str, str]:
    """("skipped", why) when the renderer says it cannot draw this case
    (NotImplementedError), else ("failed", what)."""
    if isinstance(exc, NotImplementedError):
        return "skipped", f"renderer '{method}' not available yet: {exc}".rstrip(": ")
    return "failed", f"{type(exc).__name__}: {exc}"


def loadavg() -> tuple[float, float, float] | None:
    """The 1, 5 and 15-minute load averages (other processes slow every frame
    time), or None where the system does not report them."""
    try:
        one, five, fifteen = os.getloadavg()
    except (AttributeError, OSError):
        return None
    return float(one), float(five), float(fifteen)


#: What the code that measures is: a change elsewhere (the docs a bench run
#: writes beside another) does not make a run's code "uncommitted".
CODE_PATHS = ("aniso3d", "shaders")


def code_version(paths: tuple[str, ...] = ()) -> dict:
    """Which code measured: the git commit of the package's checkout (None when
    it is not one) and whether tracked files differed from it (only those
    under ``paths``, folders from the checkout's top, when given)."""
    where = Path(__file__).resolve().parent
    out: dict = {"commit": None, "dirty": None}
    try:
        run = {"cwd": where, "capture_output": True, "text": True, "timeout": 10, "check": True}
        out["commit"] = subprocess.run(["git", "rev-parse", "HEAD"], **run).stdout.strip() or None
        spec = ["--", *(f":/{p}" for p in paths)] if paths else []
        status = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", *spec], **run).stdout
        out["dirty"] = bool(status.strip())
    except (OSError, subprocess.SubprocessError):
        pass
    return out


@dataclass
class ScenesRun:
    """What :func:`run_scenes` measured: the rows, and the run's facts for
    its header (:meth:`header`)."""

    rows: list
    commit: str
    gl_name: str
    minutes: float
    load_start: tuple[float, float, float]
    load_end: tuple[float, float, float]

    def header(self, command: str) -> str:
        """The sentence a bench's Markdown block starts with: when, at which
        commit, how long, on what and at what load, and ``command``."""
        a, b = self.load_start, self.load_end
        return (
            f"Run {time.strftime('%Y-%m-%d %H:%M')} at commit {self.commit} in {self.minutes:.1f} min on "
            f"{self.gl_name}, {platform.machine()}, {os.cpu_count()} CPUs, load average (1, 5, 15 min) "
            f"{a[0]:.1f} {a[1]:.1f} {a[2]:.1f} at the start and {b[0]:.1f} {b[1]:.1f} {b[2]:.1f} at the end; "
            f"`{command}`."
        )


def run_scenes(names, size: int, run_scene: Callable) -> ScenesRun:
    """``run_scene(name, renderer)`` (a list of rows) for each scene of
    ``names`` on one square ``size`` renderer: the demos' corpus loop. The
    commit is the checkout's when the run starts, marked when the code (not
    the docs being written) differs from it."""
    started, load0 = time.time(), os.getloadavg()
    version = code_version((*CODE_PATHS, "demos"))
    commit = (version["commit"] or "unknown")[:7]
    commit += " (with uncommitted changes to the code)" if version["dirty"] else ""
    rows: list = []
    with GLContext("auto") as gl, Renderer((size, size), gl=gl) as renderer:
        gl_name = gl.renderer
        for name in names:
            print(f"{name}:", flush=True)
            rows += run_scene(name, renderer)
    return ScenesRun(rows, commit, gl_name, (time.time() - started) / 60, load0, os.getloadavg())


def cpu_model() -> str | None:
    """The CPU's name from /proc/cpuinfo (Linux), else ``platform.processor()``."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or None


class FrameCounts(Protocol):
    """How :func:`measure` times a case (:class:`Settings` is one): ``warmup``
    untimed frames, then up to ``frames`` timed ones, stopping after
    ``frame_budget`` seconds."""

    warmup: int
    frames: int
    frame_budget: float


def measure(
    renderer: Renderer, thing, case: Case, cam: CameraSpec, settings: FrameCounts
) -> tuple[np.ndarray, dict]:
    """Render ``case`` (warm-up first, its RGBA image kept), then time frames.

    Returns the warm-up image (uint8, h x w x 4) and the timing columns: GL
    seconds per frame (median, min, max), wall and CPU seconds per frame
    (medians), frames timed, the upload's bytes and any level-of-detail stats.
    """
    opts = case.render_options()
    t0 = time.perf_counter()
    img = renderer.render(thing, cam.camera, case.method, ssaa=case.ssaa, alpha=True, **opts)
    first = time.perf_counter() - t0
    for _ in range(settings.warmup - 1):
        renderer.render(thing, cam.camera, case.method, ssaa=case.ssaa, **opts)
    gl_times, wall_times, cpu_times = [], [], []
    while len(gl_times) < settings.frames:
        t0, c0 = time.perf_counter(), time.process_time()
        # render(), not render_frame(): a frame's depth read-back is not part
        # of what is timed.
        renderer.render(thing, cam.camera, case.method, ssaa=case.ssaa, **opts)
        cpu_times.append(time.process_time() - c0)
        wall_times.append(time.perf_counter() - t0)
        gl_times.append(renderer.last_frame_seconds)
        if sum(wall_times) > settings.frame_budget:
            break
    downfilter = downfilter_cpu(renderer.size, case.ssaa)
    handle = renderer.upload(thing, case.method) if not case.lod else None
    # What a level-of-detail frame selected (points drawn, level...), if anything.
    stats = renderer.last_lod_stats
    extra = {}
    if isinstance(stats, dict):
        extra = {f"lod_{k}": v for k, v in stats.items() if isinstance(v, (int, float, str))}
    return img, {
        **extra,
        "first_frame_s": first,
        "frame_s": float(np.median(gl_times)),
        "frame_min_s": float(np.min(gl_times)),
        "frame_max_s": float(np.max(gl_times)),
        "frame_wall_s": float(np.median(wall_times)),
        "frame_cpu_s": max(0.0, float(np.median(cpu_times)) - downfilter),
        "downfilter_cpu_s": downfilter,
        "frames": len(gl_times),
        "upload_bytes": getattr(handle, "nbytes", math.nan),
    }


def downfilter_cpu(size: tuple[int, int], ssaa: int, repeats: int = 3) -> float:
    """CPU seconds that ``Renderer.render`` spends box-filtering an ``ssaa``
    framebuffer on the host (0 without supersampling), measured on a frame of
    the same size. Subtracted from ``frame_cpu_s``: a real-time renderer
    resolves on the GPU, so it is not the method's cost. Approximate: the
    filter's own CPU time varies by some 20% between runs."""
    if ssaa <= 1:
        return 0.0
    # Filled (not lazily zero-mapped), filtered and flipped like the read-back frame.
    raw = np.full((size[1] * ssaa, size[0] * ssaa, 4), 128, np.uint8)
    times = []
    for _ in range(repeats):
        c0 = time.process_time()
        np.ascontiguousarray(downsample(raw, ssaa)[::-1])
        times.append(time.process_time() - c0)
    return float(np.median(times))


def truth_ssaa(gl: GLContext, size: tuple[int, int], want: int) -> int:
    """The ground truth's samples per pixel along each axis: ``want``, halved
    while the supersampled framebuffer would exceed this OpenGL's limit (at
    least 2; raises InputError when even 2 does not fit)."""
    limit = min(gl.max_texture_size, *gl.max_viewport)
    ssaa = want
    while ssaa > 2 and max(size) * ssaa > limit:
        ssaa //= 2
    if max(size) * ssaa > limit:
        raise InputError(
            f"this OpenGL's framebuffer limit ({limit} px) is too small for a supersampled "
            f"ground truth at {size[0]}x{size[1]}; use a smaller --size"
        )
    return ssaa


def score(truth: np.ndarray, img: np.ndarray, crop: tuple[int, int, int, int], with_flip: bool) -> dict:
    """PSNR, SSIM and FLIP (NaN without it) of ``img`` against ``truth``
    (both RGBA uint8, h x w x 4) inside ``crop`` (x0, y0, x1, y1), and the
    ``coverage``: the covered area (alpha) over the truth's, above 1 when the
    rendering claims more of the background than the polygons do."""
    x0, y0, x1, y1 = crop
    ref, test = truth[y0:y1, x0:x1, :3], img[y0:y1, x0:x1, :3]
    out = metrics.compare(ref, test, with_flip=with_flip)
    gt_alpha = float(truth[y0:y1, x0:x1, 3].sum(dtype=np.float64))
    alpha = float(img[y0:y1, x0:x1, 3].sum(dtype=np.float64))
    out["coverage"] = alpha / gt_alpha if gt_alpha > 0 else math.nan
    return out


def blank_row(case: Case, blocks: list[str], cam: CameraSpec, settings: Settings, mesh: Mesh) -> dict:
    """A row for ``case`` with everything known before measuring filled in."""
    row = {c: None for c in COLUMNS}
    row.update(case.columns())
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


class _Sweep:
    """The state of one run: the ground truth per camera, the rows so far, the
    grid block's images and the progress count."""

    def __init__(self, mesh: Mesh, settings: Settings, progress: Progress | None, with_flip: bool) -> None:
        self.mesh, self.settings, self.with_flip = mesh, settings, with_flip
        self.report = progress or (lambda fraction, stage: None)
        self.cameras = make_cameras(mesh.bounds, settings)
        self.by_label = {c.label: c for c in self.cameras}
        self.plan = plan_cases(settings, self.cameras)
        self.rows: list[dict] = []
        self.images: dict[str, dict[str, np.ndarray]] = {c.label: {} for c in self.cameras}
        self.truth: dict[str, np.ndarray] = {}
        self.gt_seconds: dict[str, float] = {}
        self.gt_ssaa = settings.gt_ssaa
        n_textures = len({c.texture_key for c in self.plan if c.texture_key})
        self.total = len(self.cameras) + len(self.plan) + n_textures
        self.done = 0

    def step(self, stage: str) -> None:
        self.done += 1
        self.report(self.done / self.total, stage)

    def ground_truth(self, gl: GLContext, renderer: Renderer) -> None:
        """The supersampled polygon image of every camera (the largest
        supersampling this OpenGL's framebuffer limit allows, at least 2)."""
        self.gt_ssaa = truth_ssaa(gl, self.settings.size, self.gt_ssaa)
        for cam in self.cameras:
            t0 = time.perf_counter()
            self.truth[cam.label] = renderer.render(self.mesh, cam.camera, "mesh", ssaa=self.gt_ssaa, alpha=True)
            self.gt_seconds[cam.label] = time.perf_counter() - t0
            x0, y0, x1, y1 = cam.crop
            self.images[cam.label]["ground truth"] = self.truth[cam.label][y0:y1, x0:x1, :3]
            self.step("truth")

    def evaluate(self, row: dict, renderer: Renderer, thing, case: Case) -> None:
        """Measure ``case`` into ``row``: timings, errors, coverage, load."""
        cam = self.by_label[case.camera]
        try:
            img, timing = measure(renderer, thing, case, cam, self.settings)
        except Exception as exc:  # recorded in the row, never fatal to the sweep
            row["status"], row["reason"] = classify_failure(exc, case.method)
            return
        finally:
            load = loadavg()
            row["load_1min"] = load[0] if load else None
        row.update(timing)
        row.update(score(self.truth[cam.label], img, cam.crop, self.with_flip))
        x0, y0, x1, y1 = cam.crop
        test = img[y0:y1, x0:x1, :3]
        row["error"] = row["flip"] if self.with_flip else 1.0 - row["ssim"]
        if "grid" in row["blocks"].split(";"):
            self.images[cam.label][case.renderer] = test

    def new_row(self, case: Case) -> dict:
        row = blank_row(case, self.plan[case], self.by_label[case.camera], self.settings, self.mesh)
        row["gt_ssaa"] = self.gt_ssaa
        return row

    def mesh_rows(self, renderer: Renderer) -> None:
        """The polygon rows; they share the ground truth's renderer and upload."""
        for case in self.plan:
            if case.method == "mesh":
                row = self.new_row(case)
                row["build_s"] = 0.0
                self.evaluate(row, renderer, self.mesh, case)
                self.rows.append(row)
                self.step(case.renderer)

    def texture_rows(self, gl: GLContext) -> None:
        """The volume and splat rows, one texture (and one GPU upload set) at a time."""
        groups: dict[tuple, list[Case]] = {}
        for case in self.plan:
            if case.texture_key:
                groups.setdefault(case.texture_key, []).append(case)
        for (res, k), cases in groups.items():
            timings: dict[str, float] = {}
            t0 = time.perf_counter()
            try:
                tex = build_texture(self.mesh, res, k, bounds=self.mesh.bounds, timings=timings)
            except Exception as exc:  # e.g. too little memory for this resolution
                self.step(f"build {res}")
                for case in cases:
                    row = self.new_row(case)
                    row["status"] = "failed"
                    row["reason"] = f"texture build failed: {type(exc).__name__}: {exc}"
                    self.rows.append(row)
                    self.step(case.renderer)
                continue
            build_s = time.perf_counter() - t0
            self.step(f"build {res}")
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
            renderer = Renderer(self.settings.size, gl=gl)
            try:
                for case in cases:
                    cam = self.by_label[case.camera]
                    row = self.new_row(case)
                    row.update(tex_info)
                    row["voxel_px"] = tex.voxel_size * pixels_per_unit(self.settings.size, cam.camera.fov, cam.distance)
                    thing = tex
                    if case.points_key is not None:
                        if case.points_key not in points:
                            t0 = time.perf_counter()
                            pts = texture_points(tex, case.placement, case.per_entry, case.point_normal)
                            points[case.points_key] = (pts, time.perf_counter() - t0)
                        thing, row["points_s"] = points[case.points_key]
                        row["n_points"], row["points_bytes"] = len(thing), thing.nbytes
                    self.evaluate(row, renderer, thing, case)
                    self.rows.append(row)
                    self.step(case.renderer)
            finally:
                renderer.release()
            del tex, points

    def camera_meta(self) -> list[dict]:
        near, far = near_far(self.cameras)
        return [
            {
                "label": c.label,
                "distance_scale": c.scale,
                "distance": c.distance,
                "voxel_px": c.voxel_px,
                "crop": list(c.crop),
                "ground_truth_s": self.gt_seconds[c.label],
                "role": "near" if c is near else "far" if c is far else "",
            }
            for c in self.cameras
        ]


def run_bench(
    mesh: Mesh,
    settings: Settings,
    progress: Progress | None = None,
    with_flip: bool | None = None,
    backend: str = "auto",
) -> BenchResult:
    """Measure every case of :func:`~aniso3d.bench.plan.plan_cases` for ``mesh``.

    ``progress(fraction, stage)`` is called after each step; ``with_flip``
    None computes FLIP when its package is installed; ``backend`` picks the
    OpenGL platform (auto, egl, osmesa, x11).
    """
    if with_flip is None:
        with_flip = metrics.flip_available()
    t_start = time.perf_counter()
    load_start = loadavg()
    version = code_version(CODE_PATHS)
    sweep = _Sweep(mesh, settings, progress, with_flip)
    gl = GLContext(backend)
    try:
        meshr = Renderer(settings.size, gl=gl)
        try:
            sweep.ground_truth(gl, meshr)
            sweep.mesh_rows(meshr)
        finally:
            meshr.release()
        sweep.texture_rows(gl)
        gl_info = {"renderer": gl.renderer, "version": gl.version, "backend": gl.backend}
    finally:
        gl.release()
    load_end = loadavg()
    mark_pareto(sweep.rows)
    during = [r["load_1min"] for r in sweep.rows if r.get("load_1min") is not None]
    meta = {
        "scene": mesh.name,
        "triangles": mesh.n_faces,
        "mesh_bytes": mesh.nbytes,
        "bounds": np.asarray(mesh.bounds).tolist(),
        "preset": settings.name,
        "settings": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(settings).items()},
        "gt_ssaa": sweep.gt_ssaa,
        "error_metric": "flip" if with_flip else "1-ssim",
        "flip": with_flip,
        "cameras": sweep.camera_meta(),
        "colour_space": COLOUR_SPACE,
        "opengl": gl_info,
        "code": version,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpu_model": cpu_model(),
        "seconds": time.perf_counter() - t_start,
        "cpus": os.cpu_count(),
        # 1-minute averages at the start and end, the (1, 5, 15)-minute
        # triplets, and the 1-minute average sampled after each row.
        "load_average": {
            "start": load_start[0] if load_start else None,
            "end": load_end[0] if load_end else None,
            "start_1_5_15": list(load_start) if load_start else None,
            "end_1_5_15": list(load_end) if load_end else None,
            "during_min": min(during) if during else None,
            "during_median": float(np.median(during)) if during else None,
            "during_max": max(during) if during else None,
        },
        "date": time.strftime("%Y-%m-%d %H:%M"),
    }
    return BenchResult(sweep.rows, meta, sweep.images)
