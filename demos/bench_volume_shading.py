"""The volume renderer's surface sheets shaded by their linear models across
their planes (``shading="smooth"``, the default) or with their voxels' values
("flat"), on every corpus scene.

Per scene, at the corpus bench's two cameras (``aniso3d render``'s view:
*close*, the object filling the image, and *minified*, a voxel about a
pixel), both drawn by the volume renderer and compared with the polygons at
8 x 8 samples inside the object's box, as the corpus bench does:

- PSNR (dB) and FLIP of the RGB image;
- ``inside err``: mean |RGB - truth RGB| (1/255) over the pixels the truth
  covers whole, eroded by 2 pixels (the shading, away from silhouettes);
- frame time: median and [fastest-slowest] of ``--frames`` frames, the two
  modes taken in turn frame by frame (``Renderer.last_frame_seconds``).

    .venv/bin/python demos/bench_volume_shading.py [SCENE ...] [--size 512]
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
from aniso3d.rendering.volume import SHADING_MODES

BEGIN = "<!-- bench_volume_shading: begin -->"
END = "<!-- bench_volume_shading: end -->"
#: The mode measured against ("flat") first, then the default.
MODES = tuple(reversed(SHADING_MODES))


def eroded(mask: np.ndarray, k: int) -> np.ndarray:
    """``mask`` with every pixel within ``k`` of its outside removed (a square)."""
    out = mask.copy()
    for axis in (0, 1):
        for s in range(-k, k + 1):
            out &= np.roll(mask, s, axis=axis)
    return out


def inside_pixels(ref: np.ndarray) -> np.ndarray:
    """The pixels the truth covers whole, eroded by 2 (away from silhouettes)."""
    return eroded(ref[..., 3] == 255, 2)


def inside_error(img: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> float:
    """Mean |RGB - truth RGB| (1/255) over ``mask`` (NaN where it is empty)."""
    err = np.abs(img[..., :3].astype(np.float64) - ref[..., :3]).mean(axis=-1)
    return float(err[mask].mean()) if mask.any() else float("nan")


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    return volume_mode_rows(name, args, renderer, "shading", MODES, "inside", inside_pixels, inside_error, digits=2)


def main() -> None:
    args = corpus_parser(__doc__.splitlines()[0], scenes.CORPUS, frames=5).parse_args()
    run = run_corpus_demo(args, run_scene)
    rows = run.rows

    table = []
    for r in rows:
        s, f = r["flat"], r["smooth"]
        table.append([r["scene"], r["camera"], f"{r['voxel_px']:.2f}", pair(s), pair(f), *delta(f, s),
                      f"{s['inside_err']:.2f}", f"{f['inside_err']:.2f}", ms(s["times"]), ms(f["times"])])  # fmt: skip
    publish([
        run.header(command("demos/bench_volume_shading.py", args, "--frames", str(args.frames))) + " "
        f"Texture {args.resolution}^3, K = {args.directions}; truth "
        f"{args.gt_ssaa}x{args.gt_ssaa} polygons; errors inside the object's box, as the corpus bench. "
        "The images are deterministic, so PSNR, FLIP and the inside error have no spread; frame times are "
        "the median [fastest-slowest] of the frames, the two modes drawn in turn.",
        "",
        "**Per scene**: PSNR (dB) / FLIP of the volume with its sheets shaded with their voxels' values "
        "(`flat`) and by their linear models (`smooth`, the default), their difference (PSNR: positive is "
        "better; FLIP: negative is better), the mean RGB error (1/255) over the pixels the truth covers "
        "whole, eroded by 2, and the frame time (ms).",
        "",
        markdown_table(["scene", "camera", "voxel px", "flat", "smooth", "Δ PSNR", "Δ FLIP",
                        "inside err flat", "inside err smooth", "ms flat", "ms smooth"], table),  # fmt: skip
        "",
        "**Over the corpus** (smooth - flat; PSNR dB: mean, worst, best; FLIP: mean, worst; frame "
        "time ratio smooth / flat: median [range] over the scenes):",
        "",
        markdown_table(SUMMARY_HEAD, corpus_summary(rows, "smooth", "flat")),
    ], args.md, BEGIN, END, title="# Volume shading\n\n")  # fmt: skip


if __name__ == "__main__":
    main()
