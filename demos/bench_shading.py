"""Does shading the normals' spread (``Lighting.normal_spread``) bring the texture renderers closer to the polygons?

Per scene of ``aniso3d.build.scenes.CORPUS`` (the tree among them): the
texture at the default build (``build_texture(mesh, --resolution,
--directions)``, points by ``to_points`` with the bench's baseline), the two
cameras of the corpus bench (:func:`aniso3d.bench.corpus.corpus_cameras`:
*close*, ``aniso3d render``'s framing, and *minified*, moved back until a
voxel spans about one pixel), and per camera the volume renderer and the
high-quality splats, each drawn with the spread shaded and without, one right
after the other. A third camera, *far* (``--far`` times the minified
distance, a voxel about a quarter of a pixel), draws both from the texture's
pyramid (``lod=True``), whose coarser levels merge entries and so hold lower
coherence: the minification the spread is meant for. Errors against the polygons at ``--gt-ssaa`` x ``--gt-ssaa``
samples per pixel inside the object's box (``aniso3d.metrics.compare_in_box``
on the corpus bench's crop): PSNR (dB, higher is better) and FLIP (lower is
better).

The renders are deterministic (the same image every run on one machine), so
one run gives the figures; the script checks that by drawing the first
scene's images twice.

    .venv/bin/python demos/bench_shading.py [tree bush ...] [--size 512] [--md docs/shading.md] [--png /tmp/shading]

With ``--md`` the tables go between ``<!-- bench_shading:begin -->`` and
``<!-- bench_shading:end -->`` of that file (the prose around is kept).
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import subprocess
import time
from pathlib import Path

import numpy as np

from aniso3d import metrics
from aniso3d.bench.cameras import CameraSpec, crop_box
from aniso3d.bench.corpus import VIEW_FOV, CorpusSettings, corpus_cameras, corpus_cases, view_direction
from aniso3d.bench.outputs import markdown_table, write_between_markers
from aniso3d.bench.settings import BASELINE
from aniso3d.build import scenes
from aniso3d.build.bounds import surface_sample
from aniso3d.build.texture import build_texture, entry_coherence
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.images import save_png
from aniso3d.rendering.lighting import Lighting
from aniso3d.rendering.renderer import Renderer

BEGIN, END = "<!-- bench_shading:begin -->", "<!-- bench_shading:end -->"
RENDERS = ("volume", "splat-high")
#: The rule for the default: the mean PSNR change over every scene, camera
#: and renderer positive, and no row worse by more than this (dB).
WORST_ALLOWED = 0.1


def far_camera(mesh, minified: CameraSpec, size: tuple[int, int], factor: float) -> CameraSpec:
    """The corpus bench's minified camera moved ``factor`` times as far back."""
    b = np.asarray(mesh.bounds, dtype=np.float64)
    fit = dict(direction=view_direction(), fov=VIEW_FOV, aspect=size[0] / size[1], points=surface_sample(mesh))
    scale = minified.scale * factor
    cam = Camera.fit(b, distance_scale=scale, **fit)
    return CameraSpec("far", scale, cam, minified.distance * factor, minified.voxel_px / factor,
                      crop_box(cam, b, size))  # fmt: skip


def run_scene(name: str, args, gl: GLContext, renderers: dict, png: Path | None, check: bool) -> list[dict]:
    mesh = scenes.get_scene(name)
    settings = CorpusSettings("shading", (args.size, args.size), gt_ssaa=args.gt_ssaa,
                              resolution=args.resolution, directions=args.directions)  # fmt: skip
    tex = build_texture(mesh, args.resolution, args.directions, bounds=mesh.bounds)
    points = tex.to_points(BASELINE["placement"], BASELINE["per_entry"], BASELINE["point_normal"])
    coh = entry_coherence(tex)
    area = np.asarray(tex.entry_area)
    spread = {"mean_coherence": float(np.sum(coh * area) / np.sum(area)),
              "below_0.9": float(np.sum(area[coh < 0.9]) / np.sum(area))}  # fmt: skip
    rows = []
    specs = corpus_cameras(mesh, settings.size, args.resolution)
    specs.append(far_camera(mesh, specs[1], settings.size, args.far))
    for spec in specs:
        truth = renderers[True].render(mesh, spec.camera, "mesh", ssaa=args.gt_ssaa, alpha=True)
        cases = {c.renderer: c for c in corpus_cases(settings, "minified")}
        for method in RENDERS:
            case = cases[method]
            thing = tex if case.method == "volume" else points
            options = case.render_options()
            if spec.label == "far":
                thing = tex  # the renderer builds the pyramid and its points
                options["lod"] = True
                if case.method == "splat":
                    options.update({k: BASELINE[k] for k in ("placement", "per_entry", "point_normal")})
            row = {"scene": name, "camera": spec.label, "renderer": method, "voxel_px": spec.voxel_px,
                   "triangles": mesh.n_faces, **spread}  # fmt: skip
            images = {}
            for on in (False, True):  # interleaved: the pair is drawn together
                img = renderers[on].render(thing, spec.camera, case.method, alpha=True, **options)
                if check:
                    again = renderers[on].render(thing, spec.camera, case.method, alpha=True, **options)
                    if not np.array_equal(img, again):
                        raise SystemExit(f"{name} {spec.label} {method}: two renders differ; "
                                         "the figures need several runs")
                m = metrics.compare_in_box(truth[..., :3], img[..., :3], spec.crop, with_flip=metrics.flip_available())
                key = "on" if on else "off"
                row[f"psnr_{key}"], row[f"flip_{key}"] = m["psnr"], m["flip"]
                images[key] = img
            rows.append(row)
            print(f"  {name:8s} {spec.label:8s} {method:10s} PSNR {row['psnr_off']:.3f} -> {row['psnr_on']:.3f} "
                  f"({row['psnr_on'] - row['psnr_off']:+.3f})  FLIP {row['flip_off']:.4f} -> {row['flip_on']:.4f}",
                  flush=True)  # fmt: skip
            if png is not None:
                x0, y0, x1, y1 = spec.crop
                strip = np.concatenate([truth[y0:y1, x0:x1, :3], images["off"][y0:y1, x0:x1, :3],
                                        images["on"][y0:y1, x0:x1, :3]], axis=1)  # fmt: skip
                save_png(png / f"{name}_{spec.label}_{method}.png", strip)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=list(scenes.CORPUS))
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--gt-ssaa", type=int, default=8)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=16)
    ap.add_argument("--far", type=float, default=4.0, help="the far camera's distance over the minified one's")
    ap.add_argument("--md", default="", help="Markdown file to write the tables into")
    ap.add_argument("--png", default="", help="folder for truth | without | with image strips")
    args = ap.parse_args()
    png = Path(args.png) if args.png else None
    if png is not None:
        png.mkdir(parents=True, exist_ok=True)

    started = time.time()
    load0 = os.getloadavg()
    try:  # the code measured: the commit checked out when the run starts
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                check=True).stdout.strip()  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        commit = "unknown"
    rows = []
    with GLContext("auto") as gl:
        gl_name = gl.renderer
        base = Lighting()
        renderers = {on: Renderer((args.size, args.size), gl=gl,
                                  lighting=Lighting(base.ambient, base.lights, base.background, normal_spread=on))
                     for on in (False, True)}  # fmt: skip
        try:
            for i, name in enumerate(args.scenes):
                print(f"{name}:", flush=True)
                rows += run_scene(name, args, gl, renderers, png, check=i == 0)
        finally:
            for r in renderers.values():
                r.release()
    load1 = os.getloadavg()
    minutes = (time.time() - started) / 60

    table = []
    for r in rows:
        table.append([r["scene"], r["camera"], f"{r['voxel_px']:.2f}", r["renderer"],
                      f"{r['psnr_off']:.2f}", f"{r['psnr_on']:.2f}", f"{r['psnr_on'] - r['psnr_off']:+.3f}",
                      f"{r['flip_off']:.4f}", f"{r['flip_on']:.4f}",
                      f"{r['flip_on'] - r['flip_off']:+.4f}"])  # fmt: skip
    coh_rows = []
    for name in dict.fromkeys(r["scene"] for r in rows):
        r = next(x for x in rows if x["scene"] == name)
        coh_rows.append([name, f"{r['triangles']:,}", f"{r['mean_coherence']:.4f}", f"{100 * r['below_0.9']:.1f}"])
    summary = []
    for cam in ("close", "minified", "far"):
        for method in RENDERS:
            d = [r["psnr_on"] - r["psnr_off"] for r in rows if r["camera"] == cam and r["renderer"] == method]
            f = [r["flip_on"] - r["flip_off"] for r in rows if r["camera"] == cam and r["renderer"] == method]
            if d:
                summary.append([cam, method, f"{np.mean(d):+.3f}", f"{np.median(d):+.3f}", f"{min(d):+.3f}",
                                f"{max(d):+.3f}", f"{np.mean(f):+.4f}"])  # fmt: skip
    deltas = [r["psnr_on"] - r["psnr_off"] for r in rows]
    mean_d, worst = (float(np.mean(deltas)), float(min(deltas))) if deltas else (math.nan, math.nan)
    helps = mean_d > 0 and worst >= -WORST_ALLOWED
    parts = [
        BEGIN,
        f"Run {time.strftime('%Y-%m-%d %H:%M')} at commit {commit} in {minutes:.1f} min on {gl_name}, "
        f"{platform.machine()}, {os.cpu_count()} CPUs, load average (1, 5, 15 min) "
        f"{load0[0]:.1f} {load0[1]:.1f} {load0[2]:.1f} at the start and {load1[0]:.1f} {load1[1]:.1f} "
        f"{load1[2]:.1f} at the end; `demos/bench_shading.py {' '.join(args.scenes)} --size {args.size} "
        f"--gt-ssaa {args.gt_ssaa} --far {args.far:g} --resolution {args.resolution} --directions {args.directions}`. "
        f"Images {args.size}x{args.size}, truth {args.gt_ssaa}x{args.gt_ssaa} polygons, errors inside the "
        "object's box. The images are deterministic (checked: every image of the first scene drawn twice "
        "is equal), so each figure is one run's and has no spread.",
        "",
        "**The spread in each scene**: area-weighted mean coherence of the entries (1: every entry a flat "
        "patch) and the share of the facet area in entries of coherence below 0.9.",
        "",
        markdown_table(["scene", "triangles", "mean coherence", "area below 0.9 %"], coh_rows),
        "",
        "**Per scene**: PSNR (dB) and FLIP without the spread (`off`) and with it (`on`); Δ = on - off "
        "(PSNR: positive is better; FLIP: negative is better). Voxel px: a voxel's width in pixels.",
        "",
        markdown_table(["scene", "camera", "voxel px", "renderer", "PSNR off", "PSNR on", "Δ PSNR",
                  "FLIP off", "FLIP on", "Δ FLIP"], table),  # fmt: skip
        "",
        "**Over the corpus** (ΔPSNR in dB over the scenes: mean, median, worst, best; mean ΔFLIP):",
        "",
        markdown_table(["camera", "renderer", "mean", "median", "worst", "best", "mean Δ FLIP"], summary),
        "",
        f"Mean ΔPSNR over every scene, camera and renderer {mean_d:+.3f} dB, worst {worst:+.3f} dB: by the "
        f"rule (mean positive, no row below -{WORST_ALLOWED} dB) the spread "
        + ("**helps**." if helps else "**does not pass**."),
        END,
    ]
    block = "\n".join(parts)
    print("\n" + block)
    if args.md:
        path = write_between_markers(args.md, block, BEGIN, END, title="# Shading the normals' spread\n\n")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
