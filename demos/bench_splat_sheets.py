"""What the reach of surface sheets (``AA_SHEET_REACH``) does to quality
"high" splats, on the corpus at the corpus bench's cameras.

A pixel's fragments are grouped into surfaces by depth; the nearest surface
spans a fixed depth from its first slice, and, where a pixel holds a closed
surface seen from outside (one-sided splats), reaches as far as their depths
change across ``AA_SURFACE_REACH`` pixels. An open sheet (the corpus shell)
seen at a grazing angle along a fold changes depth as fast as a closed
surface's rim, but its splats are two-sided: its fragments split into
several surfaces that composed as independent layers, and the background
showed through the folds as light lines. The points of surface sheets
(``PointCloud.sheet``: the entry fills its plane's section of the voxel, the
volume renderer's ``RUN_SHARE``; leaves and blades smaller than a voxel are
not) now reach as closed surfaces' do.

Per scene and camera: PSNR (dB) / FLIP against 8x8 polygons in the object's
box, as the corpus bench measures, for 1-spp and 2x2 polygons and the
variants (the points as the renderer makes them, ``texture_points``):
``before``: no sheet reaches (``AA_SHEET_REACH`` off); ``sheets``: the
defaults; ``ungated``: every sheet's fragment reaches, unchained, as a
closed surface's does (``AA_SHEET_GRAZE`` 0, ``AA_SHEET_CHAIN`` 1e9);
``graze 2``, ``chain 2``, ``chain 1``: ``AA_SHEET_GRAZE`` or
``AA_SHEET_CHAIN`` changed from the defaults (3 and 1.5 spans). Cameras:
close, minified and, with ``--auto``, close-auto (the close camera, the
texture at the resolution ``--resolution auto`` picks there, as the corpus
bench). The images are deterministic: no spread to
report. ``--frames N`` also times N frames of each variant (alternating,
after a warm-up) at the close and minified cameras and gives the median
and spread of each, with the machine's load.

    .venv/bin/python demos/bench_splat_sheets.py [tree bush ...] [--size 512] [--auto] [--frames 5] \\
        [--md docs/splat_aa.md]
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace

import numpy as np

from aniso3d import metrics
from aniso3d.bench.corpus import AUTO_CAMERA, corpus_cameras
from aniso3d.bench.outputs import markdown_table, write_between_markers
from aniso3d.bench.run import run_scenes
from aniso3d.bench.settings import BASELINE
from aniso3d.build import scenes
from aniso3d.build.texture import build_texture
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.select import needed_resolution
from aniso3d.rendering.splat import params
from aniso3d.rendering.splat.clips import texture_points

BEGIN = "<!-- bench_splat_sheets: begin -->"
END = "<!-- bench_splat_sheets: end -->"
#: Column: the parameters set for it (the rest as they are): ``before`` no
#: sheet reaches; ``sheets`` the defaults; ``ungated`` every sheet's fragment
#: reaches and the reach is not chained (as closed surfaces' do); the others
#: one value changed.
VARIANTS = {"before": {"AA_SHEET_REACH": False}, "sheets": {},
            "ungated": {"AA_SHEET_GRAZE": 0.0, "AA_SHEET_CHAIN": 1e9},
            "graze 2": {"AA_SHEET_GRAZE": 2.0}, "chain 2": {"AA_SHEET_CHAIN": 2.0},
            "chain 1": {"AA_SHEET_CHAIN": 1.0}}  # fmt: skip
#: The variants timed with ``--frames``.
TIMED = ("before", "sheets")


def points_of(mesh, resolution: int, directions: int):
    tex = build_texture(mesh, resolution, directions, bounds=mesh.bounds)
    return texture_points(tex, BASELINE["placement"], BASELINE["per_entry"], BASELINE["point_normal"])


def draw(renderer: Renderer, points, spec, variant: dict):
    saved = {k: getattr(params, k) for k in variant}
    try:
        for k, v in variant.items():
            setattr(params, k, v)
        t0 = time.perf_counter()
        img = renderer.render(points, spec.camera, "splat", splat=BASELINE["splat"], quality="high")
        return img, time.perf_counter() - t0
    finally:
        for k, v in saved.items():
            setattr(params, k, v)


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh = scenes.get_scene(name)
    points = points_of(mesh, args.resolution, args.directions)
    share = 0.0 if points.sheet is None else float(points.sheet.mean())
    specs = [(spec, points) for spec in corpus_cameras(mesh, (args.size, args.size), args.resolution)]
    if args.auto:
        close = specs[0][0]
        res = needed_resolution(close.camera, (args.size, args.size), mesh.bounds)
        auto = replace(close, label=AUTO_CAMERA, voxel_px=close.voxel_px * args.resolution / res)
        specs.append((auto, points_of(mesh, res, args.directions)))
    rows = []
    for spec, pts in specs:
        truth = renderer.render(mesh, spec.camera, "mesh", ssaa=args.gt_ssaa)
        row = {"scene": name, "camera": spec.label, "share": share if pts is points else
               (0.0 if pts.sheet is None else float(pts.sheet.mean()))}  # fmt: skip
        for label, ssaa in (("1 spp", 1), ("2x2", 2)):
            img = renderer.render(mesh, spec.camera, "mesh", ssaa=ssaa)
            m = metrics.compare_in_box(truth, img, spec.crop, with_flip=True)
            row[label] = (m["psnr"], m["flip"])
        for label, variant in VARIANTS.items():
            img, _ = draw(renderer, pts, spec, variant)
            m = metrics.compare_in_box(truth, img, spec.crop, with_flip=True)
            row[label] = (m["psnr"], m["flip"])
        if args.frames and spec.label != AUTO_CAMERA:
            times = {label: [] for label in TIMED}
            for label in TIMED:
                draw(renderer, pts, spec, VARIANTS[label])  # warm-up (programs compiled)
            for _ in range(args.frames):
                for label in TIMED:
                    times[label].append(1000.0 * draw(renderer, pts, spec, VARIANTS[label])[1])
            row["ms"] = {k: (float(np.median(v)), float(min(v)), float(max(v))) for k, v in times.items()}
        rows.append(row)
        print(f"  {spec.label}: " + ", ".join(f"{k} {v[0]:.2f}/{v[1]:.4f}" for k, v in row.items()
                                              if isinstance(v, tuple)), flush=True)  # fmt: skip
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=list(scenes.CORPUS))
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--gt-ssaa", type=int, default=8)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=16)
    ap.add_argument("--auto", action="store_true", help="also the close-auto camera")
    ap.add_argument("--frames", type=int, default=0, help="time this many frames of each variant")
    ap.add_argument("--md", default="", help="Markdown file to write the table into (between its markers)")
    args = ap.parse_args()

    run = run_scenes(args.scenes, args.size, lambda name, renderer: run_scene(name, args, renderer))
    columns = ["1 spp", "2x2", *VARIANTS]
    table = []
    for r in run.rows:
        new, old = r["sheets"], r["before"]
        beats2 = new[0] >= r["2x2"][0] and new[1] <= r["2x2"][1]
        beats1 = new[0] >= r["1 spp"][0] and new[1] <= r["1 spp"][1]
        table.append([r["scene"], r["camera"], f"{100 * r['share']:.0f} %",
                      *(f"{r[c][0]:.2f} / {r[c][1]:.4f}" for c in columns),
                      f"{new[0] - old[0]:+.2f}", f"{new[1] - old[1]:+.4f}", "yes" if beats2 else "no",
                      "yes" if beats1 else "no"])  # fmt: skip
    command = f"demos/bench_splat_sheets.py {' '.join(args.scenes)} --size {args.size}"
    command += " --auto" if args.auto else ""
    command += f" --frames {args.frames}" if args.frames else ""
    parts = [
        BEGIN,
        run.header(command) + " "
        f"Texture {args.resolution}^3 (close-auto: as `--resolution auto` picks), K = {args.directions}, the "
        f"corpus bench's points (`texture_points`) and {BASELINE['splat']} splats, quality \"high\"; truth "
        f"{args.gt_ssaa}x{args.gt_ssaa} polygons; PSNR (dB) / FLIP inside the object's box, as the corpus bench. "
        "Sheets: the share of points on surface sheets. before: no sheet reaches (AA_SHEET_REACH off); sheets: "
        f"the defaults (AA_SHEET_GRAZE {params.AA_SHEET_GRAZE:g}, AA_SHEET_CHAIN {params.AA_SHEET_CHAIN:g} spans); "
        "ungated: every sheet's fragment reaches, unchained (graze 0, chain 1e9); graze 2, chain 2, chain 1: "
        "one value changed. Δ: sheets - before. ≥ 2x2, ≥ 1 spp: sheets at least as good "
        "in PSNR and FLIP.",
        "",
        markdown_table(["scene", "camera", "sheets", *columns, "Δ PSNR", "Δ FLIP", "≥ 2x2", "≥ 1 spp"], table),
    ]
    timed = [r for r in run.rows if "ms" in r]
    if timed:
        parts += [
            "",
            f"Frame time, ms: median [fastest-slowest] of {args.frames} frames of before and sheets, alternating, "
            "after a warm-up (`Renderer.render`, draw and read back; wall clock on a shared machine, "
            f"{os.cpu_count()} CPUs, load as above).",
            "",
            markdown_table(["scene", "camera", *TIMED, "sheets / before"],
                           [[r["scene"], r["camera"], *(f"{r['ms'][k][0]:.0f} [{r['ms'][k][1]:.0f}-{r['ms'][k][2]:.0f}]"
                                                        for k in TIMED),
                             f"{r['ms']['sheets'][0] / r['ms']['before'][0]:.3f}"] for r in timed]),
        ]  # fmt: skip
    parts.append(END)
    block = "\n".join(parts)
    print("\n" + block)
    if args.md:
        path = write_between_markers(args.md, block, BEGIN, END, title="# Anti-aliased splats\n\n")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
