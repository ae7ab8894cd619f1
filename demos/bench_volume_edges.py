"""The volume renderer's surface crossings, counted over the pixel's footprint
(``edges="filtered"``, the default) or by the centre ray alone ("sampled"),
on every corpus scene.

Per scene, at the corpus bench's two cameras (``aniso3d render``'s view:
*close*, the object filling the image, and *minified*, a voxel about a
pixel), both drawn by the volume renderer and compared with the polygons at
8 x 8 samples inside the object's box, as the corpus bench does:

- PSNR (dB) and FLIP of the RGB image;
- ``edge err``: mean |alpha - truth alpha| over the pixels the truth covers
  in part (silhouettes and edges);
- frame time: median and [fastest-slowest] of ``--frames`` frames, the two
  modes taken in turn frame by frame (``Renderer.last_frame_seconds``).

    .venv/bin/python demos/bench_volume_edges.py [SCENE ...] [--size 512]
        [--frames 5] [--md docs/coverage.md]
"""

from __future__ import annotations

import argparse

import numpy as np

from aniso3d import metrics
from aniso3d.bench.corpus import corpus_cameras
from aniso3d.bench.outputs import markdown_table, write_between_markers
from aniso3d.bench.run import run_scenes
from aniso3d.build import scenes
from aniso3d.build.texture import build_texture
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.volume import EDGE_MODES

BEGIN = "<!-- bench_volume_edges: begin -->"
END = "<!-- bench_volume_edges: end -->"


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh = scenes.get_scene(name)
    tex = build_texture(mesh, args.resolution, args.directions)
    size = (args.size, args.size)
    rows = []
    for spec in corpus_cameras(mesh, size, args.resolution):
        x0, y0, x1, y1 = spec.crop
        truth = renderer.render(mesh, spec.camera, "mesh", ssaa=args.gt_ssaa, alpha=True)
        ref = truth[y0:y1, x0:x1]
        edge = (ref[..., 3] > 5) & (ref[..., 3] < 250)
        row = {"scene": name, "camera": spec.label, "voxel_px": spec.voxel_px, "edge_px": int(edge.sum())}
        for mode in EDGE_MODES:
            img = renderer.render(tex, spec.camera, "volume", alpha=True, edges=mode)[y0:y1, x0:x1]
            m = metrics.compare(ref[..., :3], img[..., :3], with_flip=True)
            err = np.abs(img[..., 3].astype(np.float64) - ref[..., 3]) / 255.0
            row[mode] = {"psnr": m["psnr"], "flip": m["flip"], "edge_err": float(err[edge].mean()), "times": []}
        for _ in range(args.frames):  # the modes in turn: both see the same load
            for mode in EDGE_MODES:
                renderer.render(tex, spec.camera, "volume", edges=mode)
                row[mode]["times"].append(renderer.last_frame_seconds)
        rows.append(row)
        f, s = row["filtered"], row["sampled"]
        print(f"  {spec.label}: PSNR {s['psnr']:.2f} -> {f['psnr']:.2f}, FLIP {s['flip']:.4f} -> "
              f"{f['flip']:.4f}, edge err {s['edge_err']:.3f} -> {f['edge_err']:.3f}", flush=True)  # fmt: skip
    return rows


def ms(times: list[float]) -> str:
    t = 1000 * np.asarray(times)
    return f"{np.median(t):.0f} [{t.min():.0f}-{t.max():.0f}]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=list(scenes.CORPUS))
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--gt-ssaa", type=int, default=8)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=16)
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--md", default="", help="Markdown file to write the table into (between its markers)")
    args = ap.parse_args()

    run = run_scenes(args.scenes, args.size, lambda name, renderer: run_scene(name, args, renderer))
    rows = run.rows

    table = []
    for r in rows:
        s, f = r["sampled"], r["filtered"]
        table.append([r["scene"], r["camera"], f"{r['voxel_px']:.2f}",
                      f"{s['psnr']:.2f} / {s['flip']:.4f}", f"{f['psnr']:.2f} / {f['flip']:.4f}",
                      f"{f['psnr'] - s['psnr']:+.2f}", f"{f['flip'] - s['flip']:+.4f}",
                      f"{s['edge_err']:.3f}", f"{f['edge_err']:.3f}", ms(s["times"]), ms(f["times"])])  # fmt: skip
    summary = []
    for cam in ("close", "minified"):
        d = [r["filtered"]["psnr"] - r["sampled"]["psnr"] for r in rows if r["camera"] == cam]
        df = [r["filtered"]["flip"] - r["sampled"]["flip"] for r in rows if r["camera"] == cam]
        tr = [np.median(r["filtered"]["times"]) / np.median(r["sampled"]["times"]) for r in rows if r["camera"] == cam]
        if d:
            summary.append([cam, f"{np.mean(d):+.2f}", f"{min(d):+.2f}", f"{max(d):+.2f}", f"{np.mean(df):+.4f}",
                            f"{max(df):+.4f}", f"{np.median(tr):.2f} [{min(tr):.2f}-{max(tr):.2f}]"])  # fmt: skip
    parts = [
        BEGIN,
        run.header(f"demos/bench_volume_edges.py {' '.join(args.scenes)} --size {args.size} "
                   f"--frames {args.frames}") + " "
        f"Texture {args.resolution}^3, K = {args.directions}; truth "
        f"{args.gt_ssaa}x{args.gt_ssaa} polygons; errors inside the object's box, as the corpus bench. "
        "The images are deterministic, so PSNR, FLIP and edge error have no spread; frame times are the "
        "median [fastest-slowest] of the frames, the two modes drawn in turn.",
        "",
        "**Per scene**: PSNR (dB) / FLIP of the volume with the centre ray's crossings (`sampled`) and the "
        "footprint's (`filtered`, the default), their difference (PSNR: positive is better; FLIP: negative "
        "is better), the mean alpha error over the pixels the truth covers in part, and the frame time (ms).",
        "",
        markdown_table(["scene", "camera", "voxel px", "sampled", "filtered", "Δ PSNR", "Δ FLIP",
                        "edge err sampled", "edge err filtered", "ms sampled", "ms filtered"], table),  # fmt: skip
        "",
        "**Over the corpus** (filtered - sampled; PSNR dB: mean, worst, best; FLIP: mean, worst; frame "
        "time ratio filtered / sampled: median [range] over the scenes):",
        "",
        markdown_table(["camera", "mean Δ PSNR", "worst", "best", "mean Δ FLIP", "worst Δ FLIP", "time ratio"],
                       summary),  # fmt: skip
        END,
    ]
    block = "\n".join(parts)
    print("\n" + block)
    if args.md:
        path = write_between_markers(args.md, block, BEGIN, END, title="# Volume edges\n\n")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
