"""Anti-aliased (coverage-aware) splats against the other renderers, near to far.

The default tree (``aniso3d.scenes.tree()``; ``--scenes`` for others of
``aniso3d.scenes.CORPUS``, at their defaults) -> ``build_texture(mesh, 128,
64)`` -> ``to_points()``, drawn at 512x512 from ``Camera.fit(bounds,
direction=..., aspect=1, distance_scale=s)`` (azimuth 30, elevation 15
degrees, the bench's view) for s = 1, 2.3, 4.6, 9 and 18 (``--scales``;
``--voxel-px 1,0.5`` instead puts one camera per value where a voxel covers
that many pixels), by:

- the polygons at 1 and 2x2 samples per pixel;
- the volume renderer, single level and with ``lod=True``;
- splats (square, the renderer's default) in quality ``fast``, ``blend`` (the
  earlier "high": on/off coverage, Gaussian-weighted colour) and ``high``
  (coverage-aware), each single level and with ``lod=True``
  (``pixel_error`` 1), and ``high`` with ``pixel_error`` 2 (voxels of one to
  two pixels, splats of about one).

``--configs`` keeps only the renderers named (``--configs "splat high,mesh
2x2"``; a name ending in ``*`` is a prefix: ``"splat high*"``).

Errors against the polygons at 8x8 samples per pixel (same camera, lights and
size), inside the pixel box the object's bounds project to plus 8 px
(:func:`aniso3d.bench.cameras.crop_box`): PSNR and SSIM (aniso3d.metrics, on the 8-bit
sRGB-encoded values), FLIP when ``flip-evaluator`` is installed, and
coverage, the image's summed alpha over the truth's in the same box. Frame
time: the median of ``--frames`` frames after one warm-up, the configurations
interleaved round by round, as ``Renderer.last_frame_seconds`` (bind, clear,
select, draw, read back; the 2x2 polygons' down-filtering on the CPU is not
in it) and this process's CPU time over all threads (steadier when other
work shares the machine); ``--frames 0`` scores without timing.

The table goes to stdout and, with ``--md``, between the markers
``<!-- bench_splat_aa:begin -->`` and ``<!-- bench_splat_aa:end -->`` of that
Markdown file (created if missing), so the prose around them is kept;
``--marker NAME`` uses ``<!-- NAME:begin -->`` and ``<!-- NAME:end -->``
instead (so several runs fit one file).

``--frame-time`` measures only the frame time of quality "high" and "fast"
on the default tree at ``--size`` (1024 is the usual) from
``Camera.frame(bounds)``: the median of ``--frames`` frames each after a
warm-up, and the machine's load; one line, for comparing two versions of the
library in alternating runs.

    .venv/bin/python demos/bench_splat_aa.py [--size 512] [--frames 5] \\
        [--scenes tree,bush] [--scales 1,2.3] [--voxel-px 1] [--configs "splat high*"] \\
        [--md docs/splat_aa.md] [--marker bench_splat_aa] [--images /tmp/splat_aa]
    .venv/bin/python demos/bench_splat_aa.py --frame-time --size 1024 --frames 5
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import time
from pathlib import Path

import numpy as np

import aniso3d
from aniso3d.bench.cameras import crop_box
from aniso3d.bench.outputs import markdown_table
from aniso3d.metrics import flip, flip_available, psnr, ssim
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.images import save_png
from aniso3d.rendering.renderer import Renderer

SCALES = (1.0, 2.3, 4.6, 9.0, 18.0)
AZIMUTH, ELEVATION = 30.0, 15.0

#: (name, method, render options)
CONFIGS = (
    ("mesh 1spp", "mesh", {}),
    ("mesh 2x2", "mesh", {"ssaa": 2}),
    ("volume", "volume", {}),
    ("volume LOD", "volume", {"lod": True}),
    ("splat fast", "splat", {"quality": "fast"}),
    ("splat fast LOD", "splat", {"quality": "fast", "lod": True}),
    ("splat blend (old high)", "splat", {"quality": "blend"}),
    ("splat blend LOD", "splat", {"quality": "blend", "lod": True}),
    ("splat high", "splat", {"quality": "high"}),
    ("splat high LOD", "splat", {"quality": "high", "lod": True}),
    ("splat high LOD pe2", "splat", {"quality": "high", "lod": True, "pixel_error": 2.0}),
)


def direction() -> tuple[float, float, float]:
    a, e = math.radians(AZIMUTH), math.radians(ELEVATION)
    return (math.sin(a) * math.cos(e), math.sin(e), math.cos(a) * math.cos(e))


def frame_time(args) -> None:
    """One line: median frame times of quality high and fast on the tree."""
    mesh = aniso3d.scenes.tree()
    points = aniso3d.build_texture(mesh, args.resolution, args.directions).to_points()
    size = (args.size, args.size)
    found = {}
    with Renderer(size, backend="egl") as r:
        cam = Camera.frame(points.bounds)
        for quality in ("high", "fast"):
            r.render(points, cam, "splat", quality=quality)  # warm-up
            walls, cpus = [], []
            for _ in range(args.frames):
                c = time.process_time()
                r.render(points, cam, "splat", quality=quality)
                cpus.append(time.process_time() - c)
                walls.append(r.last_frame_seconds)
            found[quality] = (1e3 * float(np.median(walls)), 1e3 * float(np.median(cpus)))
    where = Path(aniso3d.__file__).resolve().parents[1]
    print(f"{where}: tree {len(points):,} points {size[0]}x{size[1]}, median of {args.frames}: "
          + ", ".join(f"{q} wall {w:.0f} ms cpu {c:.0f} ms" for q, (w, c) in found.items())
          + f"; high / fast {found['high'][0] / found['fast'][0]:.2f} (cpu {found['high'][1] / found['fast'][1]:.2f})"
          f"; load {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")  # fmt: skip


def measure(r, scene: str, args, configs, images: dict) -> list[dict]:
    """Score (and time) ``configs`` on one scene; one dict per camera and config."""
    mesh = aniso3d.scenes.get_scene(scene)
    t = time.perf_counter()
    tex = aniso3d.build_texture(mesh, args.resolution, args.directions)
    points = tex.to_points()
    print(f"{scene}: {mesh.n_faces:,} triangles -> {tex.n_voxels:,} voxels, "
          f"{len(points):,} points in {time.perf_counter() - t:.1f} s")  # fmt: skip
    size = (args.size, args.size)

    def voxel_pixels(cam: Camera) -> float:
        dist = float(np.linalg.norm(np.subtract(cam.position, cam.target)))
        return tex.voxel_size * size[1] / (2.0 * dist * math.tan(math.radians(cam.fov) / 2.0))

    scales = [float(x) for x in args.scales.split(",")]
    if args.voxel_px:
        first = voxel_pixels(Camera.fit(mesh.bounds, direction=direction(), aspect=1.0))
        scales = [round(first / float(v), 2) for v in args.voxel_px.split(",")]
    cams = [Camera.fit(mesh.bounds, direction=direction(), aspect=1.0, distance_scale=s)
            for s in scales]  # fmt: skip

    def thing_for(method: str, opts: dict):
        if method == "mesh":
            return mesh
        if method == "volume" or opts.get("lod"):
            return tex  # LOD needs the texture (its pyramid)
        return points

    truths, truth_alpha, boxes = [], [], []
    for s, cam in zip(scales, cams, strict=True):
        t = time.perf_counter()
        gt = r.render(mesh, cam, "mesh", ssaa=args.gt_ssaa, alpha=True)
        truths.append(gt[..., :3])
        truth_alpha.append(gt[..., 3].astype(np.float64) / 255.0)
        boxes.append(crop_box(cam, mesh.bounds, size, margin=8))
        print(f"{scene} s={s:g}: truth in {time.perf_counter() - t:.1f} s")
    # Warm-up: uploads, pyramids, programs.
    for _, method, opts in configs:
        for cam in cams:
            r.render(thing_for(method, opts), cam, method, **opts)
    results = {}
    walls: dict[tuple[int, str], list[float]] = {}
    cpus: dict[tuple[int, str], list[float]] = {}
    with_flip = flip_available()
    for rnd in range(args.frames + 1):
        for i, cam in enumerate(cams):
            for name, method, opts in configs:
                c = time.process_time()
                img = r.render(thing_for(method, opts), cam, method, alpha=True, **opts)
                c = time.process_time() - c
                if rnd:
                    walls.setdefault((i, name), []).append(r.last_frame_seconds)
                    cpus.setdefault((i, name), []).append(c)
                    continue
                x0, y0, x1, y1 = boxes[i]
                ref, tst = truths[i][y0:y1, x0:x1], img[y0:y1, x0:x1, :3]
                a = img[y0:y1, x0:x1, 3].astype(np.float64) / 255.0
                results[(i, name)] = {
                    "scene": scene, "s": scales[i], "voxel_px": voxel_pixels(cam), "name": name,
                    "stats": r.last_lod_stats, "psnr": psnr(ref, tst), "ssim": ssim(ref, tst),
                    "flip": flip(ref, tst) if with_flip else math.nan,
                    "coverage": a.sum() / max(truth_alpha[i][y0:y1, x0:x1].sum(), 1e-9),
                }  # fmt: skip
                prefix = f"{scene}_s{scales[i]:g}"
                images[f"{prefix}_{name.split(' (')[0].replace(' ', '_')}"] = np.ascontiguousarray(tst)
        if rnd == 0:
            print(f"{scene}: scored" + ("; timing ..." if args.frames else ""))
    for i in range(len(cams)):
        x0, y0, x1, y1 = boxes[i]
        images[f"{scene}_s{scales[i]:g}_truth"] = np.ascontiguousarray(truths[i][y0:y1, x0:x1])
    for key, res in results.items():
        res["wall"], res["cpu"] = walls.get(key), cpus.get(key)
    return list(results.values())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=64)
    ap.add_argument("--gt-ssaa", type=int, default=8)
    ap.add_argument("--scenes", default="tree", help="comma-separated names of aniso3d.scenes.CORPUS")
    ap.add_argument("--scales", default=",".join(f"{x:g}" for x in SCALES),
                    help="distance scales s, comma-separated")  # fmt: skip
    ap.add_argument("--voxel-px", default="",
                    help="instead of --scales: cameras where a voxel covers so many pixels, comma-separated")
    ap.add_argument("--configs", default="", help="comma-separated names of the renderers to run (name* a prefix)")
    ap.add_argument("--md", default="", help="Markdown file to write the table into")
    ap.add_argument("--marker", default="bench_splat_aa", help="name of the Markdown markers")
    ap.add_argument("--images", default="", help="folder to save the images to (optional)")
    ap.add_argument("--frame-time", action="store_true", help="only the frame time of high and fast on the tree")
    args = ap.parse_args()
    if args.frame_time:
        frame_time(args)
        return

    started = time.time()
    load0 = os.getloadavg()[0]
    begin, end = f"<!-- {args.marker}:begin -->", f"<!-- {args.marker}:end -->"
    prefixes = [c.strip() for c in args.configs.split(",") if c.strip()]

    def wanted(name: str) -> bool:
        return any(name == x or (x.endswith("*") and name.startswith(x[:-1])) for x in prefixes)

    configs = [c for c in CONFIGS if not prefixes or wanted(c[0])]
    if not configs:
        ap.error(f"no renderer named {args.configs!r}; choose from {', '.join(c[0] for c in CONFIGS)}")
    scenes = [s.strip() for s in args.scenes.split(",") if s.strip()]
    unknown = sorted(set(scenes) - set(aniso3d.scenes.CORPUS))
    if unknown:
        ap.error(f"unknown scenes {unknown}; choose from {', '.join(aniso3d.scenes.CORPUS)}")
    size = (args.size, args.size)
    images: dict[str, np.ndarray] = {}
    results: list[dict] = []
    with Renderer(size, backend="egl") as r:
        gl_name = r.gl.renderer
        print(f"OpenGL: {gl_name}")
        for scene in scenes:
            results += measure(r, scene, args, configs, images)
    load1 = os.getloadavg()[0]
    minutes = (time.time() - started) / 60
    several = len(scenes) > 1

    def drawn(st: dict | None) -> str:
        if not st:
            return ""
        if "points" in st:
            return f"{st['points']:,} pts"
        return f"level {st['level']}" if "level" in st else ""

    def ms(times: list[float] | None) -> str:
        return f"{1e3 * np.median(times):.0f}" if times else "–"

    def fl(x: float) -> str:
        return "–" if math.isnan(x) else f"{x:.4f}"

    rows = [
        ([res["scene"]] if several else []) + [
            f"{res['s']:g}", f"{res['voxel_px']:.2f}", res["name"], drawn(res["stats"]), f"{res['psnr']:.2f}",
            f"{res['ssim']:.4f}", fl(res["flip"]), f"{res['coverage']:.2f}", ms(res["wall"]), ms(res["cpu"]),
        ]
        for res in results
    ]  # fmt: skip
    head = (["scene"] if several else []) + [
        "s", "voxel px", "renderer", "drawn", "PSNR dB", "SSIM", "FLIP", "coverage", "wall ms", "cpu ms",
    ]  # fmt: skip
    # Means over the cameras where a voxel covers a pixel or less.
    minified = [res for res in results if res["voxel_px"] <= 1.05]
    mean_rows = []
    for name, _, _ in configs:
        sel = [res for res in minified if res["name"] == name]
        if not sel:
            continue

        def mean(field, sel=sel):
            return float(np.mean([res[field] for res in sel]))

        def mean_ms(field, sel=sel):
            if not all(res[field] for res in sel):
                return "–"
            return f"{1e3 * float(np.mean([np.median(res[field]) for res in sel])):.0f}"

        mean_rows.append([
            name, f"{mean('psnr'):.2f}", f"{mean('ssim'):.4f}", fl(mean("flip")), f"{mean('coverage'):.2f}",
            mean_ms("wall"), mean_ms("cpu"),
        ])  # fmt: skip

    busy = (
        f"Load average {load0:.1f} at the start and {load1:.1f} at the end on "
        f"{os.cpu_count()} CPUs: wall times include contention from other work; the CPU "
        "column counts this process's work over all rasteriser threads."
    )
    cameras = f"--voxel-px {args.voxel_px}" if args.voxel_px else f"--scales {args.scales}"
    what = "the default tree" if scenes == ["tree"] else "scenes " + ", ".join(scenes) + " (defaults)"
    library = Path(aniso3d.__file__).resolve().parents[1]
    parts = [
        begin,
        f"Run {time.strftime('%Y-%m-%d %H:%M')} in {minutes:.1f} min on {gl_name}, "
        f"{platform.machine()}; `demos/bench_splat_aa.py --size {args.size} --frames {args.frames} "
        f"--scenes {','.join(scenes)} {cameras}{' --configs ' + repr(args.configs) if prefixes else ''}`"
        f" (library: `{library.name}`). Scene: {what}, {args.resolution}^3 voxels, K = {args.directions}. "
        f"Images {size[0]}x{size[1]}, camera `Camera.fit(bounds, "
        f"direction=(azimuth {AZIMUTH:g}, elevation {ELEVATION:g}), aspect=1, "
        f"distance_scale=s)`; square splats. Errors against the polygons at "
        f"{args.gt_ssaa}x{args.gt_ssaa} samples per pixel inside the object's projected box + "
        f"8 px; coverage: summed alpha over the truth's there. Frame ms: median of "
        f"{args.frames} after a warm-up, interleaved, draw + read back (LOD: with the "
        f"selection). {busy}",
        "",
        markdown_table(head, rows),
    ]
    if len(minified) > len(configs) or (several and minified):
        parts += [
            "",
            f"**Mean over the {len(minified) // max(len(mean_rows), 1)} cameras where a voxel covers a pixel "
            f"or less**:",
            "",
            markdown_table(["renderer", "PSNR dB", "SSIM", "FLIP", "coverage", "wall ms", "cpu ms"], mean_rows),
        ]
    parts.append(end)
    block = "\n".join(parts)
    print("\n" + block)
    if args.md:
        path = Path(args.md)
        text = path.read_text() if path.exists() else "# Anti-aliased splats\n\n"
        if begin in text and end in text:
            text = text[: text.index(begin)] + block + text[text.index(end) + len(end) :]
        else:
            text = text.rstrip("\n") + "\n\n" + block + "\n"
        path.write_text(text)
        print(f"wrote {path}")
    if args.images:
        out = Path(args.images)
        out.mkdir(parents=True, exist_ok=True)
        for name, img in images.items():
            save_png(out / f"{name}.png", img)
        print(f"images in {out}")


if __name__ == "__main__":
    main()
