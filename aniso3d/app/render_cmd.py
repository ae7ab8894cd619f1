"""``aniso3d render`` and ``aniso3d frames``: headless images from the CLI.

``--resolution auto`` (the default) converts a mesh only as finely as the
view needs (:func:`~aniso3d.rendering.select.needed_resolution`: a voxel
about a pixel where the object is nearest); ``frames`` takes the finest any
camera of its path needs, built once.

``render --method all`` writes the paper's figure 3, twice, to show the
trade: a close-up row (the command's camera) and a minified row (the camera
moved back until a voxel covers about a pixel), each with the ground truth
(polygons supersampled, ``--gt-ssaa``), polygons at one sample per pixel, the
anisotropic texture by volume rendering, and its points drawn as splats; every
panel labelled with its frame time and its error as ``aniso3d bench``
measures it (PSNR inside the object's screen box against the ground truth).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aniso3d.app.common import (
    Progress,
    add_point_cloud_options,
    image_size,
    load_input,
    load_scene_input,
    point_cloud_options,
    positive_float,
    positive_int,
)
from aniso3d.build.bounds import bounds_of, surface_sample
from aniso3d.build.mesh import Mesh
from aniso3d.build.points import PointCloud
from aniso3d.build.scene import Scene
from aniso3d.build.texture import DEFAULT_DIRECTIONS
from aniso3d.errors import InputError
from aniso3d.rendering.camera import Camera, turntable
from aniso3d.rendering.select import AUTO_MIN_RESOLUTION, describe_stats, needed_resolution

PANEL_METHODS = ("mesh", "volume", "splat")
AUTO = "auto"
#: The figure's minified row with ``--resolution auto``: the camera where a
#: voxel of a texture of this resolution (the bench's baseline), or of half
#: the close-up's if that is coarser, covers a pixel at the object's nearest
#: point, so that "auto" picks this texture there: a level of the close-up's.
MINIFIED_RESOLUTION = 128
#: Frames timed per panel of the figure (the median is shown), after a warm-up frame.
FIGURE_FRAMES = 3


def resolution_arg(text: str) -> int | str:
    """``--resolution``: "auto" or a whole number of voxels >= 1."""
    if text.strip().lower() == AUTO:
        return AUTO
    try:
        return positive_int(text)
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(f"{exc} (or 'auto')") from None


def add_render_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", nargs="?", default=None,
                   help="mesh, saved texture (.a3d) or PLY point cloud; default: the built-in tree")
    p.add_argument("--size", type=image_size, default=(1024, 1024), help="image size, e.g. 800x600")
    p.add_argument("--ssaa", type=positive_int, default=1,
                   help="supersampling factor per axis (1 = one sample per pixel)")
    p.add_argument("--gt-ssaa", type=positive_int, default=8,
                   help="supersampling of the polygon ground truth errors are measured against")
    p.add_argument("--resolution", "-r", type=resolution_arg, default=AUTO,
                   help="voxels along the longest axis when a mesh is converted, or 'auto' (default): "
                        "a voxel about a pixel where the object is nearest, a power of two from 8 to 256")
    p.add_argument("--directions", "-k", type=positive_int, default=DEFAULT_DIRECTIONS,
                   help="sphere sample directions K")
    p.add_argument("--placement", choices=("centroid", "center", "sphere"), default="centroid")
    p.add_argument("--points-per-entry", type=positive_int, default=1)
    p.add_argument("--splat", choices=("square", "disc", "ellipse"), default="disc")
    p.add_argument("--quality", choices=("fast", "high", "blend"), default="high",
                   help="splats: high = coverage-aware anti-aliasing (most accurate; docs/splat_aa.md), "
                        "fast = one splat per pixel (2x the GL_POINTS floor), blend = weighted blending")
    p.add_argument("--azimuth", type=float, default=30.0, help="camera azimuth about +y, degrees")
    p.add_argument("--elevation", type=float, default=15.0, help="camera elevation, degrees")
    p.add_argument("--distance", type=positive_float, default=1.0,
                   help="camera distance as a multiple of the framing distance (>1 = farther)")
    p.add_argument("--fov", type=_fov, default=40.0, help="vertical field of view, degrees")
    p.add_argument("--camera-position", type=_vec3, default=None, metavar="X,Y,Z")
    p.add_argument("--camera-target", type=_vec3, default=None, metavar="X,Y,Z")
    p.add_argument("--lod", action="store_true",
                   help="splats and volume: draw from the texture's level-of-detail pyramid, "
                        "per frame only as fine as the view needs")
    p.add_argument("--pixel-error", type=positive_float, default=1.0,
                   help="with --lod: the largest a drawn voxel may be on screen, in "
                        "framebuffer pixels (--ssaa subdivides them)")
    p.add_argument("--backend", choices=("auto", "egl", "osmesa", "x11"), default="auto")
    p.add_argument("--scene", default=None, metavar="forest|FILE.gltf",
                   help="draw a scene of instances instead of one input: the built-in forest or a glTF file "
                        "whose nodes share meshes (EXT_mesh_gpu_instancing too)")
    p.add_argument("--trees", type=positive_int, default=100, help="trees of --scene forest")
    add_point_cloud_options(p)


def _fov(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of degrees, got '{text}'") from None
    if not 0.0 < value < 180.0:
        raise argparse.ArgumentTypeError(f"must be between 0 and 180 degrees, exclusive: {text}")
    return value


def _vec3(text: str) -> tuple[float, float, float]:
    try:
        v = tuple(float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y,Z numbers, got '{text}'") from None
    if len(v) != 3 or not np.isfinite(v).all():
        raise argparse.ArgumentTypeError(f"expected three finite numbers X,Y,Z, got '{text}'")
    return v  # type: ignore[return-value]


def camera_from_args(args, bounds: np.ndarray, points: np.ndarray | None = None) -> Camera:
    if args.camera_position is not None:
        target = args.camera_target or tuple(0.5 * (bounds[0] + bounds[1]))
        return Camera(args.camera_position, target, fov=args.fov)
    az, el = np.radians(args.azimuth), np.radians(args.elevation)
    direction = (np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el))
    cam = Camera.fit(bounds, direction=direction, fov=args.fov, aspect=args.size[0] / args.size[1],
                     distance_scale=args.distance, points=points)
    if args.camera_target is not None:
        cam = Camera(cam.position, args.camera_target, fov=args.fov)
    return cam


def _lod(method: str, args) -> bool:
    """``--lod`` applies to the methods that draw from a pyramid."""
    return bool(getattr(args, "lod", False)) and method in ("splat", "volume")


def build_options(method: str, args):
    """The :class:`~aniso3d.rendering.renderer.BuildOptions` of ``method`` from the
    command line (how the input is converted; ``--lod``)."""
    from aniso3d.rendering.renderer import BuildOptions

    return BuildOptions(resolution=args.resolution, directions=args.directions, placement=args.placement,
                        per_entry=args.points_per_entry, lod=_lod(method, args))  # fmt: skip


def draw_options(method: str, args):
    """The draw options of ``method``'s renderer from the command line: its
    ``Options`` dataclass (``--splat``, ``--quality``; ``--pixel-error`` with
    ``--lod``)."""
    scene = bool(getattr(args, "scene", None))  # a scene's instances always choose a level
    pixel_error = args.pixel_error if _lod(method, args) or scene else None
    if method == "splat":
        from aniso3d.rendering.splat import SplatOptions

        return SplatOptions(splat=args.splat, quality=args.quality, pixel_error=pixel_error)
    if method == "volume":
        from aniso3d.rendering.volume import VolumeOptions

        return VolumeOptions(pixel_error=pixel_error)
    from aniso3d.rendering.polygon import MeshOptions

    return MeshOptions()


def frame_options(method: str, args) -> dict:
    """``build`` and ``options`` keywords of ``Renderer.render`` for ``method``."""
    return {"build": build_options(method, args), "options": draw_options(method, args)}


def resolve_resolution(r, thing, method: str | None, cameras, args) -> str:
    """Turn ``--resolution auto`` into a number in ``args`` where a mesh is
    converted (the finest any of ``cameras`` needs, the texture made ready in
    ``r``'s cache; a scene's assets: :data:`SCENE_RESOLUTION`); the words for
    the output ("" where no texture is made)."""
    if isinstance(thing, Scene) and method != "mesh":
        if args.resolution == AUTO:
            args.resolution = SCENE_RESOLUTION
        return f"texture {args.resolution}³ per asset, {thing.n_instances:,} instances"
    if not isinstance(thing, Mesh) or method == "mesh":
        return ""
    if args.resolution != AUTO:
        return f"texture {args.resolution}³"
    args.resolution = r.resolve_resolution(thing, cameras, args.size, args.directions)
    return f"texture {args.resolution}³ (auto)"


#: Voxels along each asset's longest axis for a scene at ``--resolution auto``.
SCENE_RESOLUTION = 64


def read_input(args):
    """The thing a command draws: ``--scene`` (a :class:`Scene`) or the input."""
    if getattr(args, "scene", None):
        if args.input is not None:
            raise InputError(f"give either an input ('{args.input}') or --scene, not both")
        return load_scene_input(args.scene, args.trees)
    return load_input(args.input, point_options=point_cloud_options(args))


def default_method(thing) -> str:
    """The paper's method, splats, for every input (a mesh is converted)."""
    return "splat"


# ----------------------------------------------------------------------- render


def cmd_render(args) -> int:
    from aniso3d.files import refuse_overwriting_input
    from aniso3d.rendering.images import save_png
    from aniso3d.rendering.renderer import Renderer

    out = Path(args.output)
    if out.suffix.lower() != ".png":
        raise InputError(f"output '{out}' must end in .png")
    refuse_overwriting_input(out, args.input)
    thing = read_input(args)
    if isinstance(thing, Scene) and args.method == "all":
        raise InputError("--method all draws one object; give a scene --method mesh, splat or volume")
    bounds = bounds_of(thing)
    camera = camera_from_args(args, bounds, surface_sample(thing))
    with Renderer(args.size, backend=args.backend) as r:
        if args.method == "all":
            fig = figure(r, thing, camera, args)
            img = fig.image
            for line in fig.lines:
                print(line)
        else:
            method = args.method or default_method(thing)
            voxels = resolve_resolution(r, thing, method, camera, args)
            opts = frame_options(method, args)
            img = r.render(thing, camera, method, ssaa=args.ssaa, **opts)
            # A second frame measures the steady state (the first includes uploads).
            frame = r.render_frame(thing, camera, method, ssaa=args.ssaa, **opts)
            print(f"{method}: {args.size[0]}x{args.size[1]}, ssaa {args.ssaa}, "
                  f"frame {1000 * frame.seconds:.1f} ms on {r.gl.renderer}, "
                  f"{frame.stats.drawn:,} {frame.stats.unit}" + (f", {voxels}" if voxels else ""))  # fmt: skip
            if frame.stats.lod:
                print(describe_stats(frame.stats.lod))
    save_png(out, img)
    print(f"wrote {out}")
    return 0


@dataclass(frozen=True)
class Panel:
    """One panel of the figure: ``name`` ("(b) volume rendering"), its
    caption, frame time (ms) and PSNR (dB) in the object's box against the
    ground truth (None without one, and for the ground truth itself)."""

    name: str
    label: str
    ms: float
    psnr: float | None
    lod: str = ""


@dataclass(frozen=True)
class FigureRow:
    """One row: its name ("close-up", "minified"), title (what it shows, in
    words), camera, the texture drawn ("" for none) and panels."""

    name: str
    title: str
    camera: Camera
    voxels: str
    panels: list[Panel]


@dataclass(frozen=True)
class Figure:
    """The figure of ``render --method all``: the image, its rows, and the
    text lines the command prints (one per method, both rows side by side)."""

    image: np.ndarray
    rows: list[FigureRow]
    lines: list[str]


def minified_camera(camera: Camera, bounds: np.ndarray, size: tuple[int, int], resolution: int) -> Camera:
    """``camera`` moved along its view axis (same target, direction and field
    of view) until a voxel of a texture of ``resolution`` voxels along the
    longest extent of ``bounds`` covers one pixel of an image of ``size`` at
    the box's nearest point (:func:`~aniso3d.rendering.select.nearest_depth`):
    the view where "auto" picks that resolution, and where structure finer
    than a voxel falls below a pixel."""
    from aniso3d.rendering.select import nearest_depth

    b = np.asarray(bounds, dtype=np.float64)
    voxel = float(np.max(b[1] - b[0])) / resolution
    want = voxel * size[1] / (2.0 * math.tan(math.radians(camera.fov) / 2.0))
    offset = np.subtract(camera.position, camera.target)
    # Moving the eye along the view axis adds the same depth to every point.
    shift = want - nearest_depth(Camera(camera.position, camera.target, camera.up, camera.fov), b)
    distance = float(np.linalg.norm(offset)) + shift
    if distance <= 0.0:  # the target itself lies beyond: keep a sliver in front
        distance = 1e-3 * float(np.linalg.norm(offset))
    eye = np.asarray(camera.target) + offset / np.linalg.norm(offset) * distance
    return Camera(tuple(eye), camera.target, camera.up, camera.fov)


def figure(r, thing, camera: Camera, args) -> Figure:
    """The figure of ``render --method all`` (see the module docstring): two
    rows (close-up: ``camera``; minified: :func:`minified_camera` for the
    texture's resolution: ``--resolution``, a saved texture's own, or with
    "auto" :data:`MINIFIED_RESOLUTION` or half the close-up's), panels labelled with frame time and PSNR
    in the object's screen box (:func:`~aniso3d.metrics.screen_box`)."""
    from aniso3d.metrics import crop, psnr, screen_box
    from aniso3d.rendering.images import label_panels
    from aniso3d.rendering.select import nearest_depth

    bounds = bounds_of(thing)
    is_mesh = isinstance(thing, Mesh)
    methods = PANEL_METHODS if is_mesh else tuple(
        m for m in PANEL_METHODS if m != "mesh" and (m == "splat" or not isinstance(thing, PointCloud))
    )
    auto = is_mesh and args.resolution == AUTO
    if auto:
        ref = max(AUTO_MIN_RESOLUTION, min(MINIFIED_RESOLUTION, needed_resolution(camera, args.size, bounds) // 2))
    elif is_mesh:
        ref = args.resolution
    else:  # a saved texture's own voxels; a point cloud's splats are as they are
        ref = getattr(thing, "resolution", MINIFIED_RESOLUTION)
    extent = float(np.max(bounds[1] - bounds[0]))
    corners = np.array([[x, y, z] for x in bounds[:, 0] for y in bounds[:, 1] for z in bounds[:, 2]])
    spp = f"{args.ssaa}x{args.ssaa} spp" if args.ssaa > 1 else "1 spp"
    names = {"mesh": f"(a) polygons, {spp}", "volume": "(b) volume rendering",
             "splat": f"(c) {args.splat} splats ({args.quality})"}  # fmt: skip

    rows, strips = [], []
    for title, cam in (("close-up", camera), ("minified", minified_camera(camera, bounds, args.size, ref))):
        xy = cam.project(corners, args.size, bounds)
        box = screen_box(xy, args.size)
        panels, images, truth = [], [], None
        if is_mesh:
            truth = r.render(thing, cam, "mesh", ssaa=args.gt_ssaa)
            ms = 1000 * r.last_frame_seconds
            gt = f"ground truth: polygons {args.gt_ssaa}x{args.gt_ssaa}"
            panels.append(Panel(gt, f"{gt}\n{ms:.0f} ms", ms, None))
            images.append(truth)
        for method in methods:
            opts = frame_options(method, args)
            r.render(thing, cam, method, ssaa=args.ssaa, **opts)  # warm-up: conversion, upload, compile
            frames = [r.render_frame(thing, cam, method, ssaa=args.ssaa, **opts) for _ in range(FIGURE_FRAMES)]
            ms, frame = 1000 * float(np.median([f.seconds for f in frames])), frames[-1]
            label, err = f"{names[method]}\n{ms:.0f} ms", None
            if truth is not None:
                err = psnr(crop(truth, box), crop(frame.color, box))
                label += f", PSNR {err:.1f} dB"
            panels.append(Panel(names[method], label, ms, err, describe_stats(frame.stats.lod)))
            images.append(frame.color)
        depth = nearest_depth(cam, bounds)
        if isinstance(thing, PointCloud):
            voxels, detail = "", "points as given"
        else:
            res = needed_resolution(cam, args.size, bounds) if auto else ref
            voxels = f"texture {res}³" + (" (auto)" if auto else "")
            px = (extent / res) * args.size[1] / (2 * depth * math.tan(math.radians(cam.fov) / 2))
            detail = f"{voxels}, a voxel {px:.2g} px at the nearest point" if depth > 0 else voxels
        # A small object is shown cut out and enlarged, its pixels as squares: aliasing stays visible.
        images, k = enlarge(images, box)
        if k > 1:
            detail += f"; shown enlarged {k}x"
        rows.append(FigureRow(title, f"{title}: {detail}", cam, voxels, panels))
        strips.append(label_panels(images, [p.label for p in panels]))
    note = (f"times: median of {FIGURE_FRAMES} frames at {args.size[0]}x{args.size[1]} on {r.gl.renderer}"
            + ("; PSNR inside the object's screen box against the ground truth" if is_mesh else ""))  # fmt: skip
    return Figure(_stack(strips, [row.title for row in rows], note), rows, _figure_lines(rows, args) + [note])


def enlarge(images: list[np.ndarray], box: tuple[int, int, int, int]) -> tuple[list[np.ndarray], int]:
    """Images of one size (H, W, C) cut to a window around ``box`` (x0, y0, x1,
    y1) and enlarged by the largest whole factor k that still shows all of the
    box, each pixel a k x k square, to (H, W, C) again; and k (1: unchanged)."""
    h, w = images[0].shape[:2]
    x0, y0, x1, y1 = box
    k = max(1, min(w // max(x1 - x0, 1), h // max(y1 - y0, 1)))
    if k == 1:
        return images, 1
    cw, ch = -(-w // k), -(-h // k)  # the window, rounded up to cover (W, H) once enlarged
    left = min(max(0, (x0 + x1) // 2 - cw // 2), w - cw)
    top = min(max(0, (y0 + y1) // 2 - ch // 2), h - ch)
    out = [np.repeat(np.repeat(im[top : top + ch, left : left + cw], k, axis=0), k, axis=1)[:h, :w] for im in images]
    return out, k


def _stack(strips: list[np.ndarray], titles: list[str], note: str = "", gap: int = 8) -> np.ndarray:
    """Rows of labelled panels one above the other on white, each under its
    title, and a ``note`` line at the foot."""
    from PIL import Image, ImageDraw, ImageFont

    from aniso3d.rendering.images import wrap_text

    h = max(s.shape[0] for s in strips)
    font_px = max(12, h // 24)
    try:
        font = ImageFont.truetype("DejaVuSans.ttf", font_px)
    except OSError:  # not installed: Pillow's own font, which has no superscripts
        titles = [t.replace("³", "^3") for t in titles]
        note = note.replace("³", "^3")
        try:
            font = ImageFont.load_default(size=font_px)
        except TypeError:  # Pillow < 10.1 has one bitmap size
            font = ImageFont.load_default()
    w = max(s.shape[1] for s in strips)
    small = font.font_variant(size=max(10, font_px * 3 // 4)) if hasattr(font, "font_variant") else font
    measure = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    titles = [wrap_text(measure, t, font, w - 2 * gap) for t in titles]
    note = wrap_text(measure, note, small, w - 2 * gap) if note else ""

    def height(text: str, px: int) -> int:
        return int((text.count("\n") + 1) * px * 1.3) + gap

    foot = height(note, max(10, font_px * 3 // 4)) if note else 0
    title_hs = [height(t, font_px) + gap // 2 for t in titles]
    canvas = Image.new("RGB", (w, sum(s.shape[0] for s in strips) + sum(title_hs) + foot), (255, 255, 255))
    draw = ImageDraw.Draw(canvas)
    y = 0
    for strip, title, title_h in zip(strips, titles, title_hs, strict=True):
        draw.multiline_text((gap, y + gap), title, fill=(0, 0, 0), font=font, spacing=4)
        canvas.paste(Image.fromarray(np.ascontiguousarray(strip)), (0, y + title_h))
        y += title_h + strip.shape[0]
    if note:
        draw.multiline_text((gap, y), note, fill=(90, 90, 90), font=small, spacing=3)
    return np.asarray(canvas)


def _figure_lines(rows: list[FigureRow], args) -> list[str]:
    """The printed table: the rows' titles, then one line per panel kind with
    each row's frame time and PSNR (and, with ``--lod``, each row's selection)."""
    lines = [f"row {row.title}" for row in rows]
    lines.append(f"{'':<28}" + "".join(f"{row.name:>12}{'':<19}" for row in rows).rstrip())
    for i, first in enumerate(rows[0].panels):
        cells = []
        for row in rows:
            p = row.panels[i]
            cells.append(f"{p.ms:9.1f} ms" + (f"  PSNR {p.psnr:6.2f} dB" if p.psnr is not None else " " * 17))
        line = f"{first.name:<28}" + "  ".join(cells).rstrip()
        lods = [f"{row.name} {row.panels[i].lod}" for row in rows if row.panels[i].lod]
        if lods:
            line += "  " + "; ".join(lods)
        lines.append(line)
    if not any(p.psnr is not None for row in rows for p in row.panels):
        lines.append("no polygon ground truth for this input: errors not measured")
    return lines


# ----------------------------------------------------------------------- frames


def cmd_frames(args) -> int:
    from aniso3d.files import refuse_overwriting_input
    from aniso3d.rendering.video import check_video_output, is_video_path

    out = Path(args.output)
    video = is_video_path(out)
    if video:  # checked before anything is loaded or rendered
        check_video_output(out, args.fps)
        refuse_overwriting_input(out, args.input)
    elif out.exists() and not out.is_dir():
        raise InputError(f"'{out}' exists and is not a folder; 'frames' writes numbered PNGs into a folder "
                         "(or a video: end the name with .gif, .webp or .mp4)")  # fmt: skip
    thing = read_input(args)
    camera = camera_from_args(args, bounds_of(thing), surface_sample(thing))
    method = args.method or default_method(thing)
    cams = turntable(camera, args.frames, args.degrees)
    progress = Progress("frames", enabled=None if not args.quiet else False)
    if args.scheduler is not None or args.workers > 1:
        if isinstance(thing, Scene) and method != "mesh" and args.resolution == AUTO:
            args.resolution = SCENE_RESOLUTION
        result, where = _frames_on_cluster(thing, cams, None if video else out, method, progress, args)
        voxels = _path_voxels(thing, method, cams, args)
        if video:
            from aniso3d.rendering.video import write_video

            path = write_video(result, out, args.fps)
        else:
            paths = result
    else:
        from aniso3d.rendering.renderer import Renderer

        with Renderer(args.size, backend=args.backend) as r:
            voxels = resolve_resolution(r, thing, method, cams, args)  # one texture for the whole path
            opts = frame_options(method, args)
            if video:
                path = r.render_video(thing, cams, out, method, fps=args.fps, progress=progress, ssaa=args.ssaa,
                                      **opts)  # fmt: skip
            else:
                paths = r.render_path(thing, cams, out, method, progress=progress, ssaa=args.ssaa, **opts)
        where = ""
    if video:
        what = f"wrote {len(cams)} frames to {path} at {args.fps:g} fps"
    else:
        what = f"wrote {len(paths)} frames to {out}/ ({paths[0].name} .. {paths[-1].name})"
    print(what + (f", {voxels}" if voxels else "") + where)
    return 0


def _frames_on_cluster(thing, cams, folder: Path | None, method: str, progress, args) -> tuple[list, str]:
    """``frames --workers N`` (a LocalCluster of N processes made here) or
    ``--scheduler ADDRESS`` (an existing Dask cluster): the paths written (the
    frames as arrays when ``folder`` is None) and where they were drawn, in words."""
    from aniso3d.rendering.distributed import frame_client, local_threads, worker_count
    from aniso3d.rendering.renderer import render_frames

    local = args.scheduler in (None, "local")
    threads = args.threads or (local_threads(args.workers) if local else None)
    with frame_client(workers=args.workers, scheduler=args.scheduler) as client:
        n = worker_count(client)
        paths = render_frames(thing, cams, folder, method, client=client, size=args.size, ssaa=args.ssaa,
                              backend=args.backend, progress=progress, threads=threads,
                              **frame_options(method, args))  # fmt: skip
    where = f"a local Dask cluster of {n} workers" if local else f"the Dask cluster at {args.scheduler} ({n} workers)"
    lp = f", {threads} llvmpipe thread{'s' if threads != 1 else ''} each" if threads else ""
    return paths, f"; drawn on {where}{lp}"


def _path_voxels(thing, method: str, cams, args) -> str:
    """The words for the texture a path is drawn from ("" for none), without a GL context."""
    if isinstance(thing, Scene) and method != "mesh":
        return f"texture {args.resolution}³ per asset, {thing.n_instances:,} instances"
    if not isinstance(thing, Mesh) or method == "mesh":
        return ""
    if args.resolution != AUTO:
        return f"texture {args.resolution}³"
    res = max(needed_resolution(c, args.size, thing.bounds) for c in cams)
    return f"texture {res}³ (auto)"


def register(sub) -> None:
    p = sub.add_parser("render", help="draw a mesh, texture or points to a PNG (headless)")
    add_render_options(p)
    p.add_argument("--method", choices=("mesh", "volume", "splat", "all"), default=None,
                   help="renderer; 'all' = the paper's three-way figure (default: splat)")
    p.add_argument("-o", "--output", default="render.png", help="output PNG")
    p.set_defaults(func=cmd_render)

    f = sub.add_parser("frames", help="render a turntable to numbered PNGs or a video (.gif, .webp, .mp4)")
    add_render_options(f)
    f.add_argument("--method", choices=("mesh", "volume", "splat"), default=None)
    f.add_argument("--frames", type=positive_int, default=36)
    f.add_argument("--degrees", type=float, default=360.0, help="total turn")
    f.add_argument("-o", "--output", default="frames",
                   help="output folder of numbered PNGs, or a video file: .gif, .webp (Pillow) or .mp4 "
                        "(needs pip install 'aniso3d[video]')")
    f.add_argument("--fps", type=positive_float, default=24.0, help="frames per second of a video (default 24)")
    f.add_argument("--quiet", "-q", action="store_true")
    f.add_argument("--workers", "-j", type=positive_int, default=1,
                   help="draw the frames on a local Dask cluster of this many worker processes (each with "
                        "its own GL context); needs aniso3d[cluster]. The frames are the same for any number")
    f.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="draw the frames on the Dask cluster whose scheduler is at ADDRESS (e.g. "
                        "tcp://host:8786), or 'local' (as --workers); needs aniso3d[cluster]")
    f.add_argument("--threads", type=positive_int, default=None,
                   help="llvmpipe threads per worker (LP_NUM_THREADS, set before a worker's first GL "
                        "context); default on a local cluster: the cores shared out among the workers")
    f.set_defaults(func=cmd_frames, size=(512, 512))
