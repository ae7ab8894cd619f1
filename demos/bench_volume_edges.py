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

import numpy as np

from aniso3d.bench.outputs import markdown_table
from aniso3d.bench.variants import (
    SUMMARY_HEAD,
    command,
    corpus_parser,
    corpus_summary,
    delta,
    ms,
    pair,
    publish,
    run_corpus_demo,
    volume_mode_rows,
)
from aniso3d.build import scenes
from aniso3d.rendering.renderer import Renderer

BEGIN = "<!-- bench_volume_edges: begin -->"
END = "<!-- bench_volume_edges: end -->"


def edge_pixels(ref: np.ndarray) -> np.ndarray:
    """The pixels the truth covers in part (silhouettes and edges)."""
    return (ref[..., 3] > 5) & (ref[..., 3] < 250)


def edge_error(img: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> float:
    """Mean |alpha - truth alpha| over ``mask``."""
    return float((np.abs(img[..., 3].astype(np.float64) - ref[..., 3]) / 255.0)[mask].mean())


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    return volume_mode_rows(name, args, renderer, "edges", ("sampled", "filtered"), "edge", edge_pixels, edge_error)


def main() -> None:
    args = corpus_parser(__doc__.splitlines()[0], scenes.CORPUS, frames=5).parse_args()
    run = run_corpus_demo(args, run_scene)
    rows = run.rows

    table = []
    for r in rows:
        s, f = r["sampled"], r["filtered"]
        table.append([r["scene"], r["camera"], f"{r['voxel_px']:.2f}", pair(s), pair(f), *delta(f, s),
                      f"{s['edge_err']:.3f}", f"{f['edge_err']:.3f}", ms(s["times"]), ms(f["times"])])  # fmt: skip
    publish([
        run.header(command("demos/bench_volume_edges.py", args, "--frames", str(args.frames))) + " "
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
        markdown_table(SUMMARY_HEAD, corpus_summary(rows, "filtered", "sampled")),
    ], args.md, BEGIN, END, title="# Volume edges\n\n")  # fmt: skip


if __name__ == "__main__":
    main()
