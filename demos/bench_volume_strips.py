"""The volume renderer's strips (a thin solid's face between two lines
inside its voxel: aniso3d/rendering/sheet_strips.py) on and off, on every
corpus scene.

Per scene, at the corpus bench's cameras (*close*, the object filling the
image; *minified*, a voxel about a pixel; both with the texture at
``--resolution``; and *close-auto*, the close camera with the texture at
the resolution ``--resolution auto`` picks there), the volume is drawn with
its closed partial sheets read as strips where they fit (``on``) and as
before (``off``: spread over their sections, or half-planes), and compared
with the polygons at 8 x 8 samples inside the object's box, as the corpus
bench does (PSNR dB / FLIP of the RGB image), beside the polygons at 1 and
2 x 2 samples (the bench's targets). Also: how many entries are strips,
the seconds their fit adds to the upload (median of 3), the mean alpha
error over the pixels the truth covers in part, and the frame time
(median [fastest-slowest] of ``--frames`` frames, the two modes drawn in
turn frame by frame).

``--strip-pixels`` draws strips from that voxel size in pixels on (the
renderer's ``STRIP_PIXELS``), ``--strip-foot`` over that share of the
pixel's footprint (``STRIP_FOOT``).

    .venv/bin/python demos/bench_volume_strips.py [SCENE ...] [--size 512]
        [--frames 3] [--strip-pixels X] [--md docs/coverage.md]
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from contextlib import contextmanager

import numpy as np

from aniso3d import metrics
from aniso3d.bench.corpus import AUTO_CAMERA, corpus_cameras
from aniso3d.bench.outputs import markdown_table, write_between_markers
from aniso3d.bench.run import run_scenes
from aniso3d.bench.variants import SUMMARY_HEAD, corpus_summary, ms
from aniso3d.build import scenes
from aniso3d.build.texture import build_texture
from aniso3d.rendering import sheet_strips as ss
from aniso3d.rendering import volume
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.select import needed_resolution
from aniso3d.rendering.sheet_halfplanes import sheet_halfplanes
from aniso3d.rendering.volume import RUN_SHARE, closed_sign, entry_sheets

BEGIN = "<!-- bench_volume_strips: begin -->"
END = "<!-- bench_volume_strips: end -->"
MODES = ("off", "on")


def no_strips(texture, sheets, surface, halfplanes, sigma) -> ss.SheetStrips:
    E = texture.n_entries
    return ss.SheetStrips(np.zeros(E, bool), np.zeros(E), np.zeros(E), np.zeros(E), np.full(E, np.inf))


@contextmanager
def mode(name: str):
    """Uploads in this mode: ``off`` finds no strips (the renderer as before)."""
    saved = volume.sheet_strips
    volume.sheet_strips = saved if name == "on" else no_strips
    try:
        yield
    finally:
        volume.sheet_strips = saved


def fit_seconds(tex) -> tuple[int, float]:
    sheets = entry_sheets(tex)
    surface = sheets.share >= RUN_SHARE
    half = sheet_halfplanes(tex, sheets, surface)
    sigma = closed_sign(tex)
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        st = ss.sheet_strips(tex, sheets, surface, half, sigma)
        times.append(time.perf_counter() - t0)
    return int(st.mask.sum()), float(np.median(times))


def measure(renderer: Renderer, texs: dict, spec, ref: np.ndarray, frames: int) -> dict:
    x0, y0, x1, y1 = spec.crop
    edge = (ref[..., 3] > 5) & (ref[..., 3] < 250)
    out = {}
    for m in MODES:
        with mode(m):
            img = renderer.render(texs[m], spec.camera, "volume", alpha=True)[y0:y1, x0:x1]
        c = metrics.compare(ref[..., :3], img[..., :3], with_flip=True)
        err = np.abs(img[..., 3].astype(np.float64) - ref[..., 3]) / 255.0
        out[m] = {"psnr": c["psnr"], "flip": c["flip"], "edge_err": float(err[edge].mean()) if edge.any() else 0.0,
                  "times": []}  # fmt: skip
    for _ in range(frames):  # the modes in turn: both see the same load
        for m in MODES:
            with mode(m):
                renderer.render(texs[m], spec.camera, "volume")
            out[m]["times"].append(renderer.last_frame_seconds)
    return out


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh = scenes.get_scene(name)
    size = (args.size, args.size)
    specs = corpus_cameras(mesh, size, args.resolution)
    close = specs[0]
    auto_res = needed_resolution(close.camera, size, mesh.bounds)
    cases = [(spec, args.resolution) for spec in specs]
    if not args.no_auto:
        cases.append((dataclasses.replace(close, label=AUTO_CAMERA,
                                          voxel_px=close.voxel_px * args.resolution / auto_res), auto_res))  # fmt: skip
    textures = {}
    rows = []
    truths = {}
    for spec, res in cases:
        if res not in textures:
            tex = build_texture(mesh, res, args.directions, bounds=mesh.bounds)
            # One copy of the texture per mode: each is uploaded once, with or without.
            textures[res] = ({m: dataclasses.replace(tex) for m in MODES}, fit_seconds(tex), tex.n_entries)
        texs, (n_strips, fit_s), n_entries = textures[res]
        x0, y0, x1, y1 = spec.crop
        key = np.asarray(spec.camera.position, np.float64).tobytes()
        if key not in truths:
            truth = renderer.render(mesh, spec.camera, "mesh", ssaa=args.gt_ssaa, alpha=True)[y0:y1, x0:x1]
            polys = {s: renderer.render(mesh, spec.camera, "mesh", ssaa=s)[y0:y1, x0:x1] for s in (1, 2)}
            truths[key] = (truth, {s: metrics.compare(truth[..., :3], p[..., :3], with_flip=True)
                                   for s, p in polys.items()})  # fmt: skip
        ref, poly = truths[key]
        row = {"scene": name, "camera": spec.label, "resolution": res, "voxel_px": spec.voxel_px,
               "entries": n_entries, "strips": n_strips, "fit_s": fit_s, "poly": poly}  # fmt: skip
        row.update(measure(renderer, texs, spec, ref, args.frames))
        rows.append(row)
        a, b = row["off"], row["on"]
        print(f"  {spec.label} ({res}^3, {spec.voxel_px:.2f} px): PSNR {a['psnr']:.2f} -> {b['psnr']:.2f}, "
              f"FLIP {a['flip']:.4f} -> {b['flip']:.4f}, edge err {a['edge_err']:.3f} -> {b['edge_err']:.3f}; "
              f"1 spp {poly[1]['psnr']:.2f} / {poly[1]['flip']:.4f}, 2x2 {poly[2]['psnr']:.2f} / "
              f"{poly[2]['flip']:.4f}; strips {n_strips} / {n_entries} ({fit_s:.2f} s); ms {ms(a['times'])} -> "
              f"{ms(b['times'])}", flush=True)  # fmt: skip
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=[*scenes.CORPUS])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--gt-ssaa", type=int, default=8)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=16)
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--strip-pixels", type=float, default=ss.STRIP_PIXELS)
    ap.add_argument("--strip-foot", type=float, default=ss.STRIP_FOOT)
    ap.add_argument("--no-auto", action="store_true", help="skip the close-auto camera")
    ap.add_argument("--md", default="", help="Markdown file to write the table into (between its markers)")
    args = ap.parse_args()
    # Compiled into the renderer's shader when it is made.
    volume.STRIP_PIXELS, volume.STRIP_FOOT = args.strip_pixels, args.strip_foot

    run = run_scenes(args.scenes, args.size, lambda name, renderer: run_scene(name, args, renderer))
    rows = run.rows
    table = []
    for r in rows:
        a, b, p = r["off"], r["on"], r["poly"]
        table.append([r["scene"], r["camera"], f"{r['resolution']}", f"{r['voxel_px']:.2f}",
                      f"{r['strips']} / {r['entries']}", f"{r['fit_s']:.2f}",
                      f"{p[1]['psnr']:.2f} / {p[1]['flip']:.4f}", f"{p[2]['psnr']:.2f} / {p[2]['flip']:.4f}",
                      f"{a['psnr']:.2f} / {a['flip']:.4f}", f"{b['psnr']:.2f} / {b['flip']:.4f}",
                      f"{b['psnr'] - a['psnr']:+.2f}", f"{b['flip'] - a['flip']:+.4f}",
                      f"{a['edge_err']:.3f}", f"{b['edge_err']:.3f}", ms(a["times"]), ms(b["times"])])  # fmt: skip
    summary = corpus_summary(rows, "on", "off", ("close", "minified", AUTO_CAMERA))
    command = f"demos/bench_volume_strips.py {' '.join(args.scenes)} --size {args.size} --frames {args.frames}"
    if args.strip_pixels != ss.STRIP_PIXELS:
        command += f" --strip-pixels {args.strip_pixels:g}"
    if args.strip_foot != ss.STRIP_FOOT:
        command += f" --strip-foot {args.strip_foot:g}"
    parts = [
        BEGIN,
        run.header(command) + " "
        f"Texture {args.resolution}^3 (close-auto: the resolution `--resolution auto` picks), K = {args.directions}; "
        f"truth {args.gt_ssaa}x{args.gt_ssaa} polygons; errors inside the object's box, as the corpus bench. The "
        "images are deterministic, so PSNR, FLIP and edge error have no spread; frame times are the median "
        "[fastest-slowest] of the frames, the two modes drawn in turn.",
        "",
        "**Per scene**: the texture's resolution and a voxel's size in pixels, the entries read as strips (of "
        "all), the seconds their fit adds to the upload (median of 3), PSNR (dB) / FLIP of the polygons at 1 and "
        "2 x 2 samples, of the volume without (`off`) and with strips (`on`), their difference (PSNR: positive is "
        "better; FLIP: negative is better), the mean alpha error over the pixels the truth covers in part, and "
        "the frame time (ms).",
        "",
        markdown_table(["scene", "camera", "res", "voxel px", "strips", "fit s", "1 spp", "2x2", "off", "on",
                        "Δ PSNR", "Δ FLIP", "edge err off", "edge err on", "ms off", "ms on"], table),  # fmt: skip
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
        path = write_between_markers(args.md, block, BEGIN, END, title="# Volume strips\n\n")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
