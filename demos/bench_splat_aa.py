"""Anti-aliased (coverage-aware) splats against the other renderers, near to far.

The default tree (``aniso3d.scenes.tree()``; ``--scene NAME`` for another of
``aniso3d.scenes.CORPUS`` at its defaults) -> ``build_texture(mesh, 128, 64)``
-> ``to_points()``, drawn at 512x512 from ``Camera.fit(bounds, direction=...,
aspect=1, distance_scale=s)`` (azimuth 30, elevation 15 degrees, the bench's
view) for s = 1, 2.3, 4.6, 9 and 18 (``--scales``; ``--voxel-px 1`` instead
puts the camera where a voxel covers one pixel), by:

- the polygons at 1 and 2x2 samples per pixel;
- the volume renderer, single level and with ``lod=True``;
- splats (square, the renderer's default) in quality ``fast``, ``blend`` (the
  earlier "high": on/off coverage, Gaussian-weighted colour) and ``high``
  (coverage-aware), each single level and with ``lod=True``
  (``pixel_error`` 1), and ``high`` with ``pixel_error`` 2 (voxels of one to
  two pixels, splats of about one).

Errors against the polygons at 8x8 samples per pixel (same camera, lights and
size), inside the pixel box the tree's bounds project to plus 8 px
(:func:`aniso3d.bench.cli_tmp.crop_box`): PSNR and SSIM (aniso3d.metrics, on the 8-bit
sRGB-encoded values), FLIP when ``flip-evaluator`` is installed, and
coverage, the image's summed alpha over the truth's in the same box. Frame
time: the median of ``--frames`` frames after one warm-up, the configurations
interleaved round by round, as ``Renderer.last_frame_seconds`` (bind, clear,
select, draw, read back; the 2x2 polygons' down-filtering on the CPU is not
in it) and this process's CPU time over all threads (steadier when other
work shares the machine).

``--configs`` keeps only the renderers whose names start with one of the
given prefixes (``--configs "splat high"``).

The table goes to stdout and, with ``--md``, between the markers
``<!-- bench_splat_aa:begin -->`` and ``<!-- bench_splat_aa:end -->`` of that
Markdown file (created if missing), so the prose around them is kept;
``--marker NAME`` uses ``<!-- NAME:begin -->`` and ``<!-- NAME:end -->``
instead (so several runs fit one file).

    .venv/bin/python demos/bench_splat_aa.py [--size 512] [--frames 5] \\
        [--scene tree] [--scales 1,2.3] [--voxel-px 1] [--configs "splat high"] \\
        [--md docs/splat_aa.md] [--marker bench_splat_aa] [--images /tmp/splat_aa]
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
from aniso3d.bench.cli_tmp import crop_box
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
    ap.add_argument("--scene", default="tree", choices=aniso3d.scenes.CORPUS)
    ap.add_argument("--scales", default=",".join(f"{x:g}" for x in SCALES),
                    help="distance scales s, comma-separated")  # fmt: skip
    ap.add_argument("--voxel-px", type=float, default=0.0,
                    help="instead of --scales: one camera where a voxel covers this many pixels")  # fmt: skip
    ap.add_argument("--configs", default="", help="comma-separated name prefixes of the renderers to run")
    ap.add_argument("--md", default="", help="Markdown file to write the table into")
    ap.add_argument("--marker", default="bench_splat_aa", help="name of the Markdown markers")
    ap.add_argument("--images", default="", help="folder to save the images to (optional)")
    args = ap.parse_args()

    started = time.time()
    load0 = os.getloadavg()[0]
    begin, end = f"<!-- {args.marker}:begin -->", f"<!-- {args.marker}:end -->"
    prefixes = [c.strip() for c in args.configs.split(",") if c.strip()]
    configs = [c for c in CONFIGS if not prefixes or any(c[0].startswith(x) for x in prefixes)]
    mesh = aniso3d.scenes.get_scene(args.scene)
    scene = "the default tree" if args.scene == "tree" else f"scene {args.scene} (defaults)"
    t = time.perf_counter()
    tex = aniso3d.build_texture(mesh, args.resolution, args.directions)
    points = tex.to_points()
    build_s = time.perf_counter() - t
    print(f"{args.scene}: {mesh.n_faces:,} triangles -> {tex.n_voxels:,} voxels, "
          f"{len(points):,} points in {build_s:.1f} s")  # fmt: skip
    with_flip = flip_available()
    size = (args.size, args.size)

    def voxel_pixels(cam: Camera) -> float:
        dist = float(np.linalg.norm(np.subtract(cam.position, cam.target)))
        return tex.voxel_size * size[1] / (2.0 * dist * math.tan(math.radians(cam.fov) / 2.0))

    scales = [float(x) for x in args.scales.split(",")]
    if args.voxel_px > 0:
        near = Camera.fit(mesh.bounds, direction=direction(), aspect=1.0)
        scales = [round(voxel_pixels(near) / args.voxel_px, 2)]
    cams = [Camera.fit(mesh.bounds, direction=direction(), aspect=1.0, distance_scale=s)
            for s in scales]  # fmt: skip

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
            voxel_px.append(voxel_pixels(cam))
            print(f"s={scales[len(truths) - 1]:g}: truth in {time.perf_counter() - t:.1f} s")
        # Warm-up: uploads, pyramids, programs.
        for _, method, opts in configs:
            for cam in cams:
                r.render(thing_for(method, opts), cam, method, **opts)
        walls: dict[tuple[int, str], list[float]] = {}
        cpus: dict[tuple[int, str], list[float]] = {}
        stats: dict[tuple[int, str], dict | None] = {}
        for rnd in range(args.frames + 1):
            for i, cam in enumerate(cams):
                for name, method, opts in configs:
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
                        images[f"s{scales[i]:g}_{name.split(' (')[0].replace(' ', '_')}"] = (
                            np.ascontiguousarray(img[y0:y1, x0:x1, :3])
                        )
                        continue
                    walls.setdefault((i, name), []).append(r.last_frame_seconds)
                    cpus.setdefault((i, name), []).append(c)
            if rnd == 0:
                print("scored; timing ...")
        for i in range(len(cams)):
            x0, y0, x1, y1 = boxes[i]
            images[f"s{scales[i]:g}_truth"] = np.ascontiguousarray(truths[i][y0:y1, x0:x1])

    load1 = os.getloadavg()[0]
    minutes = (time.time() - started) / 60

    def drawn(st: dict | None) -> str:
        if not st:
            return ""
        if "points" in st:
            return f"{st['points']:,} pts"
        return f"level {st['level']}" if "level" in st else ""

    def ms(times: list[float] | None) -> str:
        return f"{1e3 * np.median(times):.0f}" if times else "–"

    rows = []
    for i, s in enumerate(scales):
        for name, _, _ in configs:
            res = results[(i, name)]
            rows.append([
                f"{s:g}", f"{voxel_px[i]:.2f}", name, drawn(stats[(i, name)]),
                f"{res['psnr']:.2f}", f"{res['ssim']:.4f}",
                "–" if math.isnan(res["flip"]) else f"{res['flip']:.4f}",
                f"{res['coverage']:.2f}",
                ms(walls.get((i, name))), ms(cpus.get((i, name))),
            ])  # fmt: skip
    # Means over the cameras where a voxel covers a pixel or less.
    minified = [i for i in range(len(scales)) if voxel_px[i] <= 1.05]
    mean_rows = []
    for config in configs if minified else ():
        name = config[0]

        def mean(field, name=name):
            return float(np.mean([results[(i, name)][field] for i in minified]))

        def mean_ms(table, name=name):
            if not args.frames:
                return "–"
            return f"{1e3 * float(np.mean([np.median(table[(i, name)]) for i in minified])):.0f}"

        mean_rows.append([
            name, f"{mean('psnr'):.2f}", f"{mean('ssim'):.4f}",
            "–" if not with_flip else f"{mean('flip'):.4f}", f"{mean('coverage'):.2f}",
            mean_ms(walls), mean_ms(cpus),
        ])  # fmt: skip

    busy = (
        f"Load average {load0:.1f} at the start and {load1:.1f} at the end on "
        f"{os.cpu_count()} CPUs: wall times include contention from other work; the CPU "
        "column counts this process's work over all rasteriser threads."
    )
    parts = [
        begin,
        f"Run {time.strftime('%Y-%m-%d %H:%M')} in {minutes:.1f} min on {gl_name}, "
        f"{platform.machine()}; `demos/bench_splat_aa.py --size {args.size} --frames "
        f"{args.frames} --scene {args.scene} --scales {','.join(f'{x:g}' for x in scales)}"
        f"{' --configs ' + repr(args.configs) if prefixes else ''}`. Scene: {scene}, {mesh.n_faces:,} triangles, "
        f"{args.resolution}^3 voxels ({tex.n_voxels:,}), K = {args.directions}, "
        f"{len(points):,} points. Images {size[0]}x{size[1]}, camera `Camera.fit(bounds, "
        f"direction=(azimuth {AZIMUTH:g}, elevation {ELEVATION:g}), aspect=1, "
        f"distance_scale=s)`; square splats. Errors against the polygons at "
        f"{args.gt_ssaa}x{args.gt_ssaa} samples per pixel inside the object's projected box + "
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
    ]
    if len(minified) > 1:
        parts += [
            "",
            f"**Mean over the {len(minified)} cameras where a voxel covers a pixel or less** "
            f"(s = {', '.join(f'{scales[i]:g}' for i in minified)}):",
            "",
            md_table(["renderer", "PSNR dB", "SSIM", "FLIP", "coverage", "wall ms", "cpu ms"], mean_rows),
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
