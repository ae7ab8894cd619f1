"""``aniso3d render`` and ``aniso3d frames``: headless images from the CLI.

``render --method all`` writes the paper's figure 3: the scene drawn as
polygons (one sample per pixel), as the anisotropic texture by volume
rendering, and as the texture's points drawn as splats, side by side and
labelled with each one's frame time and error against the supersampled
polygon ground truth.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from aniso3d.app.common import (
    Progress,
    add_point_cloud_options,
    image_size,
    load_input,
    point_cloud_options,
    positive_float,
    positive_int,
)
from aniso3d.build.bounds import bounds_of
from aniso3d.build.mesh import Mesh
from aniso3d.build.points import PointCloud
from aniso3d.build.texture import DEFAULT_DIRECTIONS, DEFAULT_RESOLUTION, AnisoTexture
from aniso3d.errors import InputError
from aniso3d.render.camera import Camera, turntable
from aniso3d.render.select import describe_stats

PANEL_METHODS = ("mesh", "volume", "splat")


def add_render_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", nargs="?", default=None,
                   help="mesh, saved texture (.a3d) or PLY point cloud; default: the built-in tree")
    p.add_argument("--size", type=image_size, default=(1024, 1024), help="image size, e.g. 800x600")
    p.add_argument("--ssaa", type=positive_int, default=1,
                   help="supersampling factor per axis (1 = one sample per pixel)")
    p.add_argument("--gt-ssaa", type=positive_int, default=4,
                   help="supersampling of the polygon ground truth errors are measured against")
    p.add_argument("--resolution", "-r", type=positive_int, default=DEFAULT_RESOLUTION,
                   help="voxels along the longest axis")
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


def frame_points(thing, limit: int = 50_000) -> np.ndarray | None:
    """Up to ``limit`` points of the thing's surface (every k-th), for a
    framing tighter than its bounding box."""
    if isinstance(thing, Mesh):
        pts = thing.vertices
    elif isinstance(thing, PointCloud):
        pts = thing.positions
    elif isinstance(thing, AnisoTexture):
        pts = thing.entry_centroid
    else:
        return None
    return pts[:: max(1, len(pts) // limit)]


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


def render_options(args) -> dict:
    return {
        "resolution": args.resolution,
        "directions": args.directions,
        "placement": args.placement,
        "per_entry": args.points_per_entry,
    }


def draw_options(method: str, args) -> dict:
    opts = {"splat": args.splat, "quality": args.quality} if method == "splat" else {}
    if getattr(args, "lod", False) and method in ("splat", "volume"):
        opts.update(lod=True, pixel_error=args.pixel_error)
    return opts


def default_method(thing) -> str:
    """The paper's method, splats, for every input (a mesh is converted)."""
    return "splat"


# ----------------------------------------------------------------------- render


def cmd_render(args) -> int:
    from aniso3d.files import refuse_overwriting_input
    from aniso3d.render.images import save_png
    from aniso3d.render.renderer import Renderer

    out = Path(args.output)
    if out.suffix.lower() != ".png":
        raise InputError(f"output '{out}' must end in .png")
    refuse_overwriting_input(out, args.input)
    thing = load_input(args.input, point_options=point_cloud_options(args))
    bounds = bounds_of(thing)
    camera = camera_from_args(args, bounds, frame_points(thing))
    with Renderer(args.size, backend=args.backend) as r:
        if args.method == "all":
            img, rows = figure(r, thing, camera, args)
            for row in rows:
                print(row)
        else:
            method = args.method or default_method(thing)
            img = r.render(thing, camera, method, ssaa=args.ssaa, **render_options(args),
                           **draw_options(method, args))  # fmt: skip
            # A second frame measures the steady state (the first includes uploads).
            r.render(thing, camera, method, ssaa=args.ssaa, **render_options(args), **draw_options(method, args))
            print(f"{method}: {args.size[0]}x{args.size[1]}, ssaa {args.ssaa}, "
                  f"frame {1000 * r.last_frame_seconds:.1f} ms on {r.gl.renderer}")  # fmt: skip
            if r.last_lod_stats:
                print(describe_stats(r.last_lod_stats))
    save_png(out, img)
    print(f"wrote {out}")
    return 0


def figure(r, thing, camera: Camera, args) -> tuple[np.ndarray, list[str]]:
    """The three renderings side by side with labels, and one text row each."""
    from aniso3d.render.images import label_panels

    panels, labels, rows = [], [], []
    truth = None
    methods = PANEL_METHODS if isinstance(thing, Mesh) else tuple(
        m for m in PANEL_METHODS if m != "mesh" and (m == "splat" or not isinstance(thing, PointCloud))
    )
    if isinstance(thing, Mesh):
        truth = r.render(thing, camera, "mesh", ssaa=args.gt_ssaa)
        gt_ms = 1000 * r.last_frame_seconds
        panels.append(truth)
        labels.append(f"ground truth: polygons {args.gt_ssaa}x{args.gt_ssaa} SSAA\n{gt_ms:.0f} ms")
        rows.append(f"ground truth  polygons {args.gt_ssaa}x{args.gt_ssaa}  {gt_ms:8.1f} ms")
    else:
        rows.append("no polygon ground truth for this input: errors not measured")
    names = {"mesh": "(a) polygons", "volume": "(b) volume rendering",
             "splat": f"(c) {args.splat} splats ({args.quality})"}
    for method in methods:
        ssaa = args.ssaa
        opts = {**render_options(args), **draw_options(method, args)}
        r.render(thing, camera, method, ssaa=ssaa, **opts)  # warm-up: upload, compile
        ms = 1000 * r.time_frames(thing, camera, method, frames=3, warmup=0, ssaa=ssaa, **opts)
        img = r.render(thing, camera, method, ssaa=ssaa, **opts)
        text = f"{names[method]}{', ' + str(ssaa) + ' spp' if method == 'mesh' and ssaa == 1 else ''}\n{ms:.0f} ms"
        row = f"{names[method]:<22} {ms:8.1f} ms"
        lod_text = describe_stats(r.last_lod_stats)
        if truth is not None:
            from aniso3d.metrics import psnr

            p = psnr(img, truth)
            text += f", PSNR {p:.1f} dB"
            row += f"  PSNR {p:6.2f} dB"
        if lod_text:
            row += f"  {lod_text}"
        panels.append(img)
        labels.append(text)
        rows.append(row)
    return label_panels(panels, labels), rows


# ----------------------------------------------------------------------- frames


def cmd_frames(args) -> int:
    from aniso3d.render.renderer import Renderer

    folder = Path(args.output)
    if folder.exists() and not folder.is_dir():
        raise InputError(f"'{folder}' exists and is not a folder; 'frames' writes numbered PNGs into a folder")
    thing = load_input(args.input, point_options=point_cloud_options(args))
    camera = camera_from_args(args, bounds_of(thing), frame_points(thing))
    method = args.method or default_method(thing)
    cams = turntable(camera, args.frames, args.degrees)
    progress = Progress("frames", enabled=None if not args.quiet else False)
    with Renderer(args.size, backend=args.backend) as r:
        paths = r.render_path(thing, cams, folder, method, progress=progress, ssaa=args.ssaa,
                              **render_options(args), **draw_options(method, args))  # fmt: skip
    print(f"wrote {len(paths)} frames to {folder}/ ({paths[0].name} .. {paths[-1].name})")
    return 0


def register(sub) -> None:
    p = sub.add_parser("render", help="draw a mesh, texture or points to a PNG (headless)")
    add_render_options(p)
    p.add_argument("--method", choices=("mesh", "volume", "splat", "all"), default=None,
                   help="renderer; 'all' = the paper's three-way figure (default: splat)")
    p.add_argument("-o", "--output", default="render.png", help="output PNG")
    p.set_defaults(func=cmd_render)

    f = sub.add_parser("frames", help="render a turntable to numbered PNGs")
    add_render_options(f)
    f.add_argument("--method", choices=("mesh", "volume", "splat"), default=None)
    f.add_argument("--frames", type=positive_int, default=36)
    f.add_argument("--degrees", type=float, default=360.0, help="total turn")
    f.add_argument("-o", "--output", default="frames", help="output folder")
    f.add_argument("--quiet", "-q", action="store_true")
    f.set_defaults(func=cmd_frames, size=(512, 512))
