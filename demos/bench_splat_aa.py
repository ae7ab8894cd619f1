"""Anti-aliased (coverage-aware) splats against the other renderers, near to far.

The default tree (``aniso3d.scenes.tree()``) -> ``build_texture(mesh, 128, 64)``
-> ``to_points()``, drawn at 512x512 from ``Camera.fit(bounds, direction=...,
aspect=1, distance_scale=s)`` (azimuth 30, elevation 15 degrees, the bench's
view) for s = 1, 2.3, 4.6, 9 and 18, by:

- the polygons at 1 and 2x2 samples per pixel;
- the volume renderer, single level and with ``lod=True``;
- splats (square, the renderer's default) in quality ``fast``, ``blend`` (the
  earlier "high": on/off coverage, Gaussian-weighted colour) and ``high``
  (coverage-aware), each single level and with ``lod=True``
  (``pixel_error`` 1), and ``high`` with ``pixel_error`` 2 (voxels of one to
  two pixels, splats of about one).

Errors against the polygons at 8x8 samples per pixel (same camera, lights and
size), inside the pixel box the tree's bounds project to plus 8 px
(:func:`aniso3d.bench.cameras.crop_box`): PSNR and SSIM (aniso3d.metrics, on the 8-bit
sRGB-encoded values), FLIP when ``flip-evaluator`` is installed, and
coverage, the image's summed alpha over the truth's in the same box. Frame
time: the median of ``--frames`` frames after one warm-up, the configurations
interleaved round by round, as ``Renderer.last_frame_seconds`` (bind, clear,
select, draw, read back; the 2x2 polygons' down-filtering on the CPU is not
in it) and this process's CPU time over all threads (steadier when other
work shares the machine).

The table goes to stdout and, with ``--md``, between the markers
``<!-- bench_splat_aa:begin -->`` and ``<!-- bench_splat_aa:end -->`` of that
Markdown file (created if missing), so the prose around them is kept.

    .venv/bin/python demos/bench_splat_aa.py [--size 512] [--frames 5] \\
        [--md docs/splat_aa.md] [--images /tmp/splat_aa]
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
from aniso3d.metrics import flip, flip_available, psnr, ssim
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.images import save_png
from aniso3d.rendering.renderer import Renderer

BEGIN, END = "<!-- bench_splat_aa:begin -->", "<!-- bench_splat_aa:end -->"
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
    ("splat high (new)", "splat", {"quality": "high"}),
    ("splat high LOD", "splat", {"quality": "high", "lod": True}),
    ("splat high LOD pe2", "splat", {"quality": "high", "lod": True, "pixel_error": 2.0}),
)


def direction() -> tuple[float, float, float]:
    a, e = math.radians(AZIMUTH), math.radians(ELEVATION)
    return (math.sin(a) * math.cos(e), math.sin(e), math.cos(a) * math.cos(e))


def md_table(head: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=64)
    ap.add_argument("--gt-ssaa", type=int, default=8)
    ap.add_argument("--md", default="", help="Markdown file to write the table into")
    ap.add_argument("--images", default="", help="folder to save the images to (optional)")
    args = ap.parse_args()

    started = time.time()
    load0 = os.getloadavg()[0]
    mesh = aniso3d.scenes.tree()
    t = time.perf_counter()
    tex = aniso3d.build_texture(mesh, args.resolution, args.directions)
    points = tex.to_points()
    build_s = time.perf_counter() - t
    print(f"tree: {mesh.n_faces:,} triangles -> {tex.n_voxels:,} voxels, "
          f"{len(points):,} points in {build_s:.1f} s")  # fmt: skip
    with_flip = flip_available()
    size = (args.size, args.size)
    cams = [Camera.fit(mesh.bounds, direction=direction(), aspect=1.0, distance_scale=s)
            for s in SCALES]  # fmt: skip

    def thing_for(method: str, opts: dict):
        if method == "mesh":
            return mesh
        if method == "volume" or opts.get("lod"):
            return tex  # LOD needs the texture (its pyramid)
        return points

    results: dict[tuple[int, str], dict] = {}
    images: dict[str, np.ndarray] = {}
    with Renderer(size, backend="egl") as r:
        gl_name = r.gl.renderer
        print(f"OpenGL: {gl_name}")
        truths, truth_alpha, boxes, voxel_px = [], [], [], []
        for cam in cams:
            t = time.perf_counter()
            gt = r.render(mesh, cam, "mesh", ssaa=args.gt_ssaa, alpha=True)
            truths.append(gt[..., :3])
            truth_alpha.append(gt[..., 3].astype(np.float64) / 255.0)
            boxes.append(crop_box(cam, mesh.bounds, size, margin=8))
            dist = float(np.linalg.norm(np.subtract(cam.position, cam.target)))
            voxel_px.append(
                tex.voxel_size * size[1] / (2.0 * dist * math.tan(math.radians(cam.fov) / 2.0))
            )
            print(f"s={SCALES[len(truths) - 1]:g}: truth in {time.perf_counter() - t:.1f} s")
        # Warm-up: uploads, pyramids, programs.
        for _, method, opts in CONFIGS:
            for cam in cams:
                r.render(thing_for(method, opts), cam, method, **opts)
        walls: dict[tuple[int, str], list[float]] = {}
        cpus: dict[tuple[int, str], list[float]] = {}
        stats: dict[tuple[int, str], dict | None] = {}
        for rnd in range(args.frames + 1):
            for i, cam in enumerate(cams):
                for name, method, opts in CONFIGS:
                    c = time.process_time()
                    img = r.render(thing_for(method, opts), cam, method, alpha=True, **opts)
                    c = time.process_time() - c
                    if rnd == 0:
                        key = (i, name)
                        x0, y0, x1, y1 = boxes[i]
                        ref, tst = truths[i][y0:y1, x0:x1], img[y0:y1, x0:x1, :3]
                        a = img[y0:y1, x0:x1, 3].astype(np.float64) / 255.0
                        results[key] = {
                            "psnr": psnr(ref, tst),
                            "ssim": ssim(ref, tst),
                            "flip": flip(ref, tst) if with_flip else math.nan,
                            "coverage": a.sum() / max(truth_alpha[i][y0:y1, x0:x1].sum(), 1e-9),
                        }
                        stats[key] = r.last_lod_stats
                        images[f"s{SCALES[i]:g}_{name.split(' (')[0].replace(' ', '_')}"] = (
                            np.ascontiguousarray(img[y0:y1, x0:x1, :3])
                        )
                        continue
                    walls.setdefault((i, name), []).append(r.last_frame_seconds)
                    cpus.setdefault((i, name), []).append(c)
            if rnd == 0:
                print("scored; timing ...")
        for i in range(len(cams)):
            x0, y0, x1, y1 = boxes[i]
            images[f"s{SCALES[i]:g}_truth"] = np.ascontiguousarray(truths[i][y0:y1, x0:x1])

    load1 = os.getloadavg()[0]
    minutes = (time.time() - started) / 60

    def drawn(st: dict | None) -> str:
        if not st:
            return ""
        if "points" in st:
            return f"{st['points']:,} pts"
        return f"level {st['level']}" if "level" in st else ""

    rows = []
    for i, s in enumerate(SCALES):
        for name, _, _ in CONFIGS:
            res = results[(i, name)]
            rows.append([
                f"{s:g}", f"{voxel_px[i]:.2f}", name, drawn(stats[(i, name)]),
                f"{res['psnr']:.2f}", f"{res['ssim']:.4f}",
                "–" if math.isnan(res["flip"]) else f"{res['flip']:.4f}",
                f"{res['coverage']:.2f}",
                f"{1e3 * np.median(walls[(i, name)]):.0f}",
                f"{1e3 * np.median(cpus[(i, name)]):.0f}",
            ])  # fmt: skip
    # Means over the cameras where a voxel covers a pixel or less.
    minified = [i for i in range(len(SCALES)) if voxel_px[i] <= 1.05]
    mean_rows = []
    for config in CONFIGS:
        name = config[0]

        def mean(field, name=name):
            return float(np.mean([results[(i, name)][field] for i in minified]))

        def mean_ms(table, name=name):
            return 1e3 * float(np.mean([np.median(table[(i, name)]) for i in minified]))

        mean_rows.append([
            name, f"{mean('psnr'):.2f}", f"{mean('ssim'):.4f}",
            "–" if not with_flip else f"{mean('flip'):.4f}", f"{mean('coverage'):.2f}",
            f"{mean_ms(walls):.0f}", f"{mean_ms(cpus):.0f}",
        ])  # fmt: skip

    busy = (
        f"Load average {load0:.1f} at the start and {load1:.1f} at the end on "
        f"{os.cpu_count()} CPUs: wall times include contention from other work; the CPU "
        "column counts this process's work over all rasteriser threads."
    )
    parts = [
        BEGIN,
        f"Run {time.strftime('%Y-%m-%d %H:%M')} in {minutes:.1f} min on {gl_name}, "
        f"{platform.machine()}; `demos/bench_splat_aa.py --size {args.size} --frames "
        f"{args.frames}`. Scene: the default tree, {mesh.n_faces:,} triangles, "
        f"{args.resolution}^3 voxels ({tex.n_voxels:,}), K = {args.directions}, "
        f"{len(points):,} points. Images {size[0]}x{size[1]}, camera `Camera.fit(bounds, "
        f"direction=(azimuth {AZIMUTH:g}, elevation {ELEVATION:g}), aspect=1, "
        f"distance_scale=s)`; square splats. Errors against the polygons at "
        f"{args.gt_ssaa}x{args.gt_ssaa} samples per pixel inside the tree's projected box + "
        f"8 px; coverage: summed alpha over the truth's there. Frame ms: median of "
        f"{args.frames} after a warm-up, interleaved, draw + read back (LOD: with the "
        f"selection). {busy}",
        "",
        md_table(
            [
                "s",
                "voxel px",
                "renderer",
                "drawn",
                "PSNR dB",
                "SSIM",
                "FLIP",
                "coverage",
                "wall ms",
                "cpu ms",
            ],
            rows,
        ),  # fmt: skip
        "",
        f"**Mean over the {len(minified)} cameras where a voxel covers a pixel or less** "
        f"(s = {', '.join(f'{SCALES[i]:g}' for i in minified)}):",
        "",
        md_table(
            ["renderer", "PSNR dB", "SSIM", "FLIP", "coverage", "wall ms", "cpu ms"], mean_rows
        ),  # fmt: skip
        END,
    ]
    block = "\n".join(parts)
    print("\n" + block)
    if args.md:
        path = Path(args.md)
        text = path.read_text() if path.exists() else "# Anti-aliased splats\n\n"
        if BEGIN in text and END in text:
            text = text[: text.index(BEGIN)] + block + text[text.index(END) + len(END) :]
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
