"""What the clip planes of quality "high" splats cost (aniso3d.rendering.splat.clips),
per corpus scene, and what they do for level-of-detail drawing.

Per scene, the texture at ``--resolution`` (128^3, K = 16, over the mesh's
bounds) and its points as the corpus bench makes them (``texture_points``):

- **bytes**: points, how many have clip planes, ``PointCloud.nbytes`` (what
  the corpus bench reports as the points' bytes) per point and over the
  mesh's binary PLY, and the bytes the GPU upload holds (``nbytes`` of the
  splat renderer's handle: vertex buffer, attribute texture, clip planes)
  per point;
- **time**: seconds of ``texture_points(tex)`` computing the clip planes
  afresh (any cache of them emptied first), median and range of ``--runs``
  runs, wall and CPU time of the process; and a second call on the same
  texture (the planes cached where the code caches them);
- **frame time** (``--frames N``): N frames of the points with quality
  "high" at the corpus bench's two cameras (``Renderer.render``, after one
  warm-up), the median CPU time of the process (all rasteriser threads; the
  JSON has wall times too);
- **level of detail** (``--lod``): the texture's pyramid drawn with quality
  "high" (``LodPoints``, screen-space error 1 px) from the corpus bench's
  minified camera and 2 and 4 times as far, with and without each level's
  clip planes (``LodPoints(..., clips=False)``), PSNR / FLIP against 8 x 8
  polygons in the object's box; and the share of each level's points with
  clip planes.

``--images DIR`` saves the float RGBA of the points drawn with quality
"high" at the corpus bench's two cameras; ``--images-against DIR`` (the
``--images`` of a run on earlier code) reports the largest difference from
them per scene.

``--json`` writes the numbers; ``--compare BEFORE.json`` (the ``--json`` of
a run of the same script on earlier code, e.g. a copy of the parent commit
put first on ``PYTHONPATH``) adds the bytes and times side by side.

    .venv/bin/python demos/bench_splat_clips.py [tree room ...] [--runs 5] [--lod] \\
        [--json /tmp/after.json] [--compare /tmp/before.json] [--md docs/splat_aa.md]
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from aniso3d import metrics
from aniso3d.bench.cameras import crop_box
from aniso3d.bench.corpus import VIEW_FOV, corpus_cameras, ply_bytes, surface_sample, view_direction
from aniso3d.bench.outputs import markdown_table, write_between_markers
from aniso3d.bench.run import run_scenes
from aniso3d.bench.settings import BASELINE
from aniso3d.build import scenes
from aniso3d.build.pyramid import LodPoints, pyramid
from aniso3d.build.texture import build_texture
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.splat import clips as clips_module
from aniso3d.rendering.splat.clips import clipped, texture_points

BEGIN = "<!-- bench_splat_clips: begin -->"
END = "<!-- bench_splat_clips: end -->"
OPTS = (BASELINE["placement"], BASELINE["per_entry"], BASELINE["point_normal"])


def n_cut(cloud) -> int:
    """Points of ``cloud`` with at least one clip plane."""
    return 0 if cloud.clips is None else int(np.any(cloud.clips[..., :3] != 0, axis=(1, 2)).sum())


def forget_clips() -> None:
    """Empty the clip planes' cache, where the code has one."""
    cache = getattr(clips_module, "_CACHE", None)
    if cache is not None:
        cache.clear()


def timed(fn, runs: int) -> dict:
    """Wall and CPU seconds of ``runs`` calls of ``fn`` (each after
    :func:`forget_clips`): median, fastest, slowest."""
    wall, cpu = [], []
    for _ in range(runs):
        forget_clips()
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
    return {"wall": [float(np.median(wall)), min(wall), max(wall)], "cpu": [float(np.median(cpu)), min(cpu), max(cpu)]}


def draw_rgba(renderer: Renderer, thing, camera: Camera, size: tuple[int, int]) -> np.ndarray:
    """(H, W, 4) float32 of ``thing`` (a cloud or LodPoints) drawn with quality "high"."""
    impl = renderer.method_renderer("splat")
    ctx = renderer.gl.ctx
    handle = impl.upload(thing)
    col, dep = ctx.texture(size, 4, dtype="f4"), ctx.depth_texture(size)
    fbo = ctx.framebuffer([col], dep)
    try:
        near, far = camera.clip_range(handle.bounds)
        view = FrameView(camera, renderer.lighting, size, near, far)
        fbo.use()
        ctx.viewport = (0, 0, *size)
        fbo.clear(*renderer.lighting.background, 0.0, depth=1.0)
        impl.draw(handle, view, fbo=fbo, quality="high", splat=BASELINE["splat"])
        rgba = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(size[1], size[0], 4)[::-1]
    finally:
        for obj in (fbo, col, dep):
            obj.release()
        impl.release(handle)
    return rgba.copy()


def draw_rgb(renderer: Renderer, thing, camera: Camera, size: tuple[int, int]) -> np.ndarray:
    """(H, W, 3) uint8 of ``thing`` drawn with quality "high"."""
    return (np.clip(draw_rgba(renderer, thing, camera, size)[..., :3], 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh = scenes.get_scene(name)
    tex = build_texture(mesh, args.resolution, args.directions, bounds=mesh.bounds)
    t = timed(lambda: texture_points(tex, *OPTS), args.runs)
    points = texture_points(tex, *OPTS)
    w0 = time.perf_counter()
    texture_points(tex, *OPTS)
    again = time.perf_counter() - w0
    impl = renderer.method_renderer("splat")
    handle = impl.upload(points)
    gpu = int(handle.nbytes)
    impl.release(handle)
    mesh_bytes = ply_bytes(mesh)
    row = {"scene": name, "points": len(points), "cut": n_cut(points), "nbytes": int(points.nbytes),
           "mesh_bytes": int(mesh_bytes), "gpu_bytes": gpu, "time": t, "again": again}  # fmt: skip
    print(f"  {len(points)} points, {row['cut']} cut; nbytes {points.nbytes} ({points.nbytes / len(points):.2f} B a "
          f"point, {points.nbytes / mesh_bytes:.2f}x the mesh); GPU {gpu} ({gpu / len(points):.2f} B a point); "
          f"texture_points {t['wall'][0]:.3f} s [{t['wall'][1]:.3f}-{t['wall'][2]:.3f}], cpu {t['cpu'][0]:.3f} s; "
          f"again {again:.3f} s", flush=True)  # fmt: skip
    if args.frames:
        row["frame"] = {}
        for spec in corpus_cameras(mesh, (args.size, args.size), args.resolution):
            draw = lambda cam=spec.camera: renderer.render(points, cam, "splat", splat=BASELINE["splat"],  # noqa: E731
                                                           quality="high")  # fmt: skip
            draw()
            wall, cpu = [], []
            for _ in range(args.frames):
                w0, c0 = time.perf_counter(), time.process_time()
                draw()
                wall.append(time.perf_counter() - w0)
                cpu.append(time.process_time() - c0)
            row["frame"][spec.label] = {"wall": [float(np.median(wall)), min(wall), max(wall)],
                                        "cpu": [float(np.median(cpu)), min(cpu), max(cpu)]}  # fmt: skip
        print(f"  frame {frame_cell(row)} ms", flush=True)
    if args.images or args.images_against:
        worst, differing = 0.0, 0
        for spec in corpus_cameras(mesh, (args.size, args.size), args.resolution):
            img = draw_rgba(renderer, points, spec.camera, (args.size, args.size))
            path = f"{name}_{spec.label}.npy"
            if args.images:
                os.makedirs(args.images, exist_ok=True)
                np.save(os.path.join(args.images, path), img)
            if args.images_against:
                diff = np.abs(img.astype(np.float64) - np.load(os.path.join(args.images_against, path)))
                worst, differing = max(worst, float(diff.max())), differing + int((diff.max(axis=-1) > 0).sum())
        if args.images_against:
            row["image_diff"] = [worst, differing]
            print(f"  images: largest difference {worst:.3g}, {differing} pixels differ", flush=True)
    if args.lod:
        row["lod"] = lod_rows(mesh, tex, args, renderer)
    return [row]


def lod_rows(mesh, tex, args, renderer: Renderer) -> dict:
    size = (args.size, args.size)
    pyr = pyramid(tex)
    shares = []
    for lvl in range(len(pyr)):
        cloud = pyr.level_cloud(lvl, *OPTS)[0]
        shares.append([len(cloud), n_cut(clipped(cloud, pyr[lvl], None, BASELINE["per_entry"])) if len(cloud) else 0])
    spec = corpus_cameras(mesh, size, args.resolution)[1]
    b = np.asarray(mesh.bounds, dtype=np.float64)
    fit = dict(direction=view_direction(), fov=VIEW_FOV, aspect=1.0, points=surface_sample(mesh))
    cams = [("minified", spec.camera, spec.crop)]
    for k in (2, 4):
        cam = Camera.fit(b, distance_scale=spec.scale * k, **fit)
        cams.append((f"minified x{k}", cam, crop_box(cam, b, size)))
    rows = []
    impl = renderer.method_renderer("splat")
    for label, cam, crop in cams:
        truth = renderer.render(mesh, cam, "mesh", ssaa=args.gt_ssaa)
        out = {"camera": label}
        for key, lod in (("uncut", LodPoints(pyr, *OPTS, clips=False)), ("cut", LodPoints(pyr, *OPTS))):
            m = metrics.compare_in_box(truth, draw_rgb(renderer, lod, cam, size), crop, with_flip=True)
            out[key] = [m["psnr"], m["flip"]]
        handle = impl.upload(LodPoints(pyr, *OPTS))
        near, far = cam.clip_range(handle.bounds)
        out["levels"] = impl.select(handle, FrameView(cam, renderer.lighting, size, near, far))["points_per_level"]
        impl.release(handle)
        rows.append(out)
        print(f"  {label}: uncut {out['uncut'][0]:.2f}/{out['uncut'][1]:.4f}, cut {out['cut'][0]:.2f}/"
              f"{out['cut'][1]:.4f}, points per level {out['levels']}", flush=True)  # fmt: skip
    return {"levels": shares, "cameras": rows}


def byte_cells(r: dict) -> list[str]:
    n = r["points"]
    return [f"{r['nbytes'] / n:.2f}", f"{r['nbytes'] / r['mesh_bytes']:.2f}", f"{r['gpu_bytes'] / 2**20:.2f}",
            f"{r['gpu_bytes'] / n:.2f}"]  # fmt: skip


def time_cell(r: dict) -> str:
    w = r["time"]["wall"]
    return f"{w[0]:.2f} [{w[1]:.2f}-{w[2]:.2f}]"


def frame_cell(r: dict) -> str:
    """CPU ms of a frame, median, at each camera."""
    if "frame" not in r:
        return "-"
    return " / ".join(f"{1000 * f['cpu'][0]:.0f}" for f in r["frame"].values())


def image_cell(r: dict) -> str:
    worst, differing = r["image_diff"]
    return f"{worst:.1e} ({differing:,})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=list(scenes.CORPUS))
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--gt-ssaa", type=int, default=8)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=16)
    ap.add_argument("--frames", type=int, default=0, help="also time this many frames of quality high")
    ap.add_argument("--lod", action="store_true", help="also the level-of-detail images")
    ap.add_argument("--images", default="", help="save the float RGBA images of quality high in this folder")
    ap.add_argument("--images-against", default="", help="an earlier run's --images: the largest differences")
    ap.add_argument("--json", default="", help="write the numbers here")
    ap.add_argument("--compare", default="", help="the --json of an earlier run: bytes and times side by side")
    ap.add_argument("--md", default="", help="Markdown file to write the tables into (between its markers)")
    args = ap.parse_args()

    run = run_scenes(args.scenes, args.size, lambda name, renderer: run_scene(name, args, renderer))
    command = f"demos/bench_splat_clips.py {' '.join(args.scenes)} --runs {args.runs}"
    command += f" --frames {args.frames}" if args.frames else ""
    command += " --lod" if args.lod else ""
    command += f" --images {args.images}" if args.images else ""
    command += f" --images-against {args.images_against}" if args.images_against else ""
    command += f" --compare {args.compare}" if args.compare else ""
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"header": run.header(command), "rows": run.rows}, fh, indent=1)
    parts = [BEGIN, run.header(command) + f" Texture {args.resolution}^3 over the mesh's bounds, K = "
             f"{args.directions}, the corpus bench's points (texture_points). B/pt: PointCloud.nbytes per point "
             "(the corpus bench's points bytes); x mesh: over the binary PLY; GPU: the upload's nbytes (vertex "
             "buffer, attribute texture, clip planes), MiB and per point. Time: texture_points afresh, seconds, "
             f"median [fastest-slowest] of {args.runs} (wall); again: a second call on the same texture."
             + (f" Frame: quality \"high\" at {args.size}² at the close and the minified camera, the median CPU "
                f"time of the process (all rasteriser threads) over {args.frames} frames, ms."
                if args.frames else "")
             + (" Image Δ: the largest difference of the float RGBA of quality \"high\" at the two corpus cameras "
                f"from {args.images_against}'s, and the pixels that differ at all." if args.images_against else ""),
             ""]
    head = ["scene", "points", "with clip planes", "B/pt", "x mesh", "GPU MiB", "GPU B/pt", "time s", "again s",
            *(["frame CPU ms close / minified"] if args.frames else []),
            *(["image Δ max (pixels)"] if args.images_against else [])]  # fmt: skip
    if args.compare:
        with open(args.compare) as fh:
            before = json.load(fh)
        parts += [f"Before: {before['header']}", ""]
        old = {r["scene"]: r for r in before["rows"]}
        table = []
        for r in run.rows:
            o = old.get(r["scene"])
            if o is None:
                continue
            bo, bn = byte_cells(o), byte_cells(r)
            table.append([r["scene"], f"{r['points']:,}", f"{r['cut']:,} ({100 * r['cut'] / r['points']:.2f} %)",
                          f"{bo[0]} → {bn[0]}", f"{bo[1]} → {bn[1]}", f"{bo[2]} → {bn[2]}", f"{bo[3]} → {bn[3]}",
                          f"{time_cell(o)} → {time_cell(r)}", f"{o['again']:.2f} → {r['again']:.2f}",
                          *([f"{frame_cell(o)} → {frame_cell(r)}"] if args.frames else []),
                          *([image_cell(r)] if args.images_against else [])])  # fmt: skip
        parts += [markdown_table(head, table), ""]  # fmt: skip
    else:
        table = [[r["scene"], f"{r['points']:,}", f"{r['cut']:,} ({100 * r['cut'] / r['points']:.2f} %)",
                  *byte_cells(r), time_cell(r), f"{r['again']:.2f}", *([frame_cell(r)] if args.frames else []),
                  *([image_cell(r)] if args.images_against else [])] for r in run.rows]  # fmt: skip
        parts += [markdown_table(head, table), ""]  # fmt: skip
    if args.lod:
        parts += [f"Level of detail: the pyramid drawn with quality \"high\" at {args.size}², screen-space error "
                  f"1 px, {BASELINE['splat']} splats, PSNR (dB) / FLIP against {args.gt_ssaa}x{args.gt_ssaa} "
                  "polygons in the object's box; uncut: LodPoints(..., clips=False), the level clouds as before; "
                  "cut: each level's clip planes. Levels: points drawn per level (finest first); with clip "
                  "planes: share of each level's points (levels 0-4).", ""]
        table = []
        for r in run.rows:
            shares = " / ".join(f"{100 * c / max(n, 1):.1f}" for n, c in r["lod"]["levels"][:5])
            for c in r["lod"]["cameras"]:
                table.append([r["scene"], c["camera"], f"{c['uncut'][0]:.2f} / {c['uncut'][1]:.4f}",
                              f"{c['cut'][0]:.2f} / {c['cut'][1]:.4f}", f"{c['cut'][0] - c['uncut'][0]:+.2f}",
                              f"{c['cut'][1] - c['uncut'][1]:+.4f}",
                              " / ".join(str(n) for n in c["levels"] if n) + f" (from level "
                              f"{next((i for i, n in enumerate(c['levels']) if n), 0)})", shares + " %"])  # fmt: skip
        parts += [markdown_table(["scene", "camera", "uncut", "cut", "Δ PSNR", "Δ FLIP", "points drawn",
                                  "with clip planes"], table)]  # fmt: skip
    parts.append(END)
    block = "\n".join(parts)
    print("\n" + block)
    if args.md:
        path = write_between_markers(args.md, block, BEGIN, END, title="# Anti-aliased splats\n\n")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
