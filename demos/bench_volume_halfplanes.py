"""The volume renderer's half-planes (a partial sheet's edge inside its
voxel: aniso3d/rendering/sheet_halfplanes.py) on and off, on every corpus
scene.

Per scene, at the corpus bench's two cameras (*close*, the object filling
the image, and *minified*, a voxel about a pixel), the volume is drawn with
its partial sheets read as half-planes (``on``, the default) and as before
(``off``: every partial sheet's fill spread over its section, or a cloud),
and compared with the polygons at 8 x 8 samples inside the object's box, as
the corpus bench does:

- PSNR (dB) and FLIP of the RGB image;
- ``edge err``: mean |alpha - truth alpha| over the pixels the truth covers
  in part (outlines);
- frame time: median and [fastest-slowest] of ``--frames`` frames, the two
  modes drawn in turn frame by frame (``Renderer.last_frame_seconds``);
- the half-planes: how many entries are read as half-planes, and the
  seconds their fit adds to the upload (median of 3).

``--half-pixels`` draws half-planes from that voxel size in pixels on (the
renderer's ``HALF_PIXELS``, default 2).

    .venv/bin/python demos/bench_volume_halfplanes.py [SCENE ...] [--size 512]
        [--frames 5] [--half-pixels 2] [--md docs/coverage.md]
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from contextlib import contextmanager

import numpy as np

from aniso3d import metrics
from aniso3d.bench.corpus import corpus_cameras
from aniso3d.bench.outputs import markdown_table, write_between_markers
from aniso3d.bench.run import run_scenes
from aniso3d.bench.variants import SUMMARY_HEAD, corpus_summary, ms
from aniso3d.build import scenes
from aniso3d.build.texture import build_texture
from aniso3d.rendering import sheet_halfplanes as hp
from aniso3d.rendering import volume
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.volume import RUN_SHARE, entry_sheets

BEGIN = "<!-- bench_volume_halfplanes: begin -->"
END = "<!-- bench_volume_halfplanes: end -->"
MODES = ("off", "on")


@contextmanager
def mode(name: str):
    saved = hp.HALF_TOLERANCE
    hp.HALF_TOLERANCE = saved if name == "on" else -1.0
    try:
        yield
    finally:
        hp.HALF_TOLERANCE = saved


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh = scenes.get_scene(name)
    tex = build_texture(mesh, args.resolution, args.directions)
    # One copy of the texture per mode: each is uploaded once, with or without.
    texs = {m: dataclasses.replace(tex) for m in MODES}
    sheets = entry_sheets(tex)
    fit_s = []
    for _ in range(3):
        t0 = time.perf_counter()
        planes = hp.sheet_halfplanes(tex, sheets, sheets.share >= RUN_SHARE)
        fit_s.append(time.perf_counter() - t0)
    size = (args.size, args.size)
    rows = []
    for spec in corpus_cameras(mesh, size, args.resolution):
        x0, y0, x1, y1 = spec.crop
        truth = renderer.render(mesh, spec.camera, "mesh", ssaa=args.gt_ssaa, alpha=True)
        ref = truth[y0:y1, x0:x1]
        edge = (ref[..., 3] > 5) & (ref[..., 3] < 250)
        row = {"scene": name, "camera": spec.label, "voxel_px": spec.voxel_px, "entries": tex.n_entries,
               "halfplanes": int(planes.mask.sum()), "fit_s": float(np.median(fit_s))}  # fmt: skip
        for m in MODES:
            with mode(m):
                img = renderer.render(texs[m], spec.camera, "volume", alpha=True)[y0:y1, x0:x1]
            c = metrics.compare(ref[..., :3], img[..., :3], with_flip=True)
            err = np.abs(img[..., 3].astype(np.float64) - ref[..., 3]) / 255.0
            row[m] = {"psnr": c["psnr"], "flip": c["flip"], "edge_err": float(err[edge].mean()) if edge.any() else 0.0,
                      "times": []}  # fmt: skip
        for _ in range(args.frames):  # the modes in turn: both see the same load
            for m in MODES:
                with mode(m):
                    renderer.render(texs[m], spec.camera, "volume")
                row[m]["times"].append(renderer.last_frame_seconds)
        rows.append(row)
        a, b = row["off"], row["on"]
        print(f"  {spec.label}: PSNR {a['psnr']:.2f} -> {b['psnr']:.2f}, FLIP {a['flip']:.4f} -> {b['flip']:.4f}, "
              f"edge err {a['edge_err']:.3f} -> {b['edge_err']:.3f}, half-planes {row['halfplanes']} "
              f"({row['fit_s']:.2f} s)", flush=True)  # fmt: skip
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=[*scenes.CORPUS, "cube", "sphere"])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--gt-ssaa", type=int, default=8)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=16)
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--half-pixels", type=float, default=hp.HALF_PIXELS)
    ap.add_argument("--md", default="", help="Markdown file to write the table into (between its markers)")
    args = ap.parse_args()
    volume.HALF_PIXELS = args.half_pixels  # compiled into the renderer's shader when it is made

    run = run_scenes(args.scenes, args.size, lambda name, renderer: run_scene(name, args, renderer))
    rows = run.rows
    table = []
    for r in rows:
        a, b = r["off"], r["on"]
        table.append([r["scene"], r["camera"], f"{r['voxel_px']:.2f}", f"{r['halfplanes']} / {r['entries']}",
                      f"{r['fit_s']:.2f}", f"{a['psnr']:.2f} / {a['flip']:.4f}", f"{b['psnr']:.2f} / {b['flip']:.4f}",
                      f"{b['psnr'] - a['psnr']:+.2f}", f"{b['flip'] - a['flip']:+.4f}",
                      f"{a['edge_err']:.3f}", f"{b['edge_err']:.3f}", ms(a["times"]), ms(b["times"])])  # fmt: skip
    summary = corpus_summary(rows, "on", "off")
    parts = [
        BEGIN,
        run.header(f"demos/bench_volume_halfplanes.py {' '.join(args.scenes)} --size {args.size} "
                   f"--frames {args.frames}" + (f" --half-pixels {args.half_pixels:g}"
                                                if args.half_pixels != hp.HALF_PIXELS else "")) + " "
        f"Texture {args.resolution}^3, K = {args.directions}; truth {args.gt_ssaa}x{args.gt_ssaa} polygons; errors "
        "inside the object's box, as the corpus bench. The images are deterministic, so PSNR, FLIP and edge error "
        "have no spread; frame times are the median [fastest-slowest] of the frames, the two modes drawn in turn.",
        "",
        "**Per scene**: the entries read as half-planes (of all), the seconds their fit adds to the upload "
        "(median of 3), PSNR (dB) / FLIP of the volume without (`off`) and with them (`on`, the default), "
        "their difference (PSNR: positive is better; FLIP: negative is better), the mean alpha error over the "
        "pixels the truth covers in part, and the frame time (ms).",
        "",
        markdown_table(["scene", "camera", "voxel px", "half-planes", "fit s", "off", "on", "Δ PSNR", "Δ FLIP",
                        "edge err off", "edge err on", "ms off", "ms on"], table),  # fmt: skip
        "",
        "**Over the corpus** (on - off; PSNR dB: mean, worst, best; FLIP: mean, worst; frame time ratio "
        "on / off: median [range] over the scenes):",
        "",
        markdown_table(SUMMARY_HEAD, summary),
        END,
    ]
    block = "\n".join(parts)
    print("\n" + block)
    if args.md:
        path = write_between_markers(args.md, block, BEGIN, END, title="# Volume half-planes\n\n")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
