"""High-quality splats on the corpus where surfaces should be whole: the
speckle of a minified smooth surface (docs/splat_aa.md, "Whole surfaces").

Every scene of ``aniso3d.scenes.CORPUS`` (``--scenes`` for fewer), built as
``aniso3d bench --corpus`` builds it (``build_texture(mesh, 128, 16)``, the
bench's baseline points, disc splats), drawn at 512x512 from the corpus
cameras (:func:`aniso3d.bench.corpus.corpus_cameras`: *close*, the object
filling the image, and *minified*, a voxel about a pixel) by polygons at one
sample per pixel and splats in quality "high". Scored as the corpus bench
scores (:func:`aniso3d.bench.run.score`: PSNR, FLIP and coverage against the
polygons at 8x8 samples, inside the object's box plus 8 px), plus the
*interior MSE*: the mean squared error (8-bit levels, averaged over RGB) over
the pixels the truth covers wholly (alpha 255) and whose neighbours within
2 px do too, where the truth is a smooth surface and a speckle shows.

``--frames N`` also times quality "high" on the blob and the tree at both
cameras: the median of N frames after a warm-up, ``Renderer.last_frame_seconds``
and this process's CPU time over all threads (steadier on a shared machine).

The table goes to stdout and, with ``--md``, between ``<!-- MARKER:begin -->``
and ``<!-- MARKER:end -->`` of that Markdown file (``--marker``, default
``bench_splat_whole``). To measure an older version of the library, put a
copy of it first on ``PYTHONPATH`` (its ``shaders`` folder copied into its
``aniso3d`` package, where the installed one is looked up); the report names
the folder the library was loaded from.

    .venv/bin/python demos/bench_splat_whole.py [--scenes blob,shell] [--frames 5] \\
        [--md docs/splat_aa.md] [--marker bench_splat_whole]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

import aniso3d
from aniso3d.bench.corpus import CORPUS_PRESETS, corpus_cameras
from aniso3d.bench.outputs import markdown_table, write_between_markers
from aniso3d.bench.run import score
from aniso3d.bench.settings import BASELINE
from aniso3d.build.texture import build_texture
from aniso3d.rendering.renderer import Renderer

TIMED = ("blob", "tree")


def interior(truth: np.ndarray, margin: int = 2) -> np.ndarray:
    """(H, W) bool: pixels the truth (RGBA uint8) covers wholly, as do all
    within ``margin`` pixels along each axis."""
    covered = truth[..., 3] == 255
    inside = covered.copy()
    for axis in (0, 1):
        for k in range(1, margin + 1):
            inside &= np.roll(covered, k, axis) & np.roll(covered, -k, axis)
    return inside


def interior_mse(truth: np.ndarray, img: np.ndarray, inside: np.ndarray) -> float:
    d = img[..., :3].astype(np.float64) - truth[..., :3]
    return float((d * d).mean(-1)[inside].mean()) if inside.any() else float("nan")


def measure(r: Renderer, name: str, frames: int) -> list[dict]:
    s = CORPUS_PRESETS["full"]
    mesh = aniso3d.scenes.get_scene(name)
    tex = build_texture(mesh, s.resolution, s.directions, bounds=mesh.bounds)
    points = tex.to_points(BASELINE["placement"], BASELINE["per_entry"], BASELINE["point_normal"])
    rows = []
    for spec in corpus_cameras(mesh, s.size, s.resolution):
        truth = r.render(mesh, spec.camera, "mesh", ssaa=s.gt_ssaa, alpha=True)
        x0, y0, x1, y1 = spec.crop
        inside = np.zeros(truth.shape[:2], bool)
        inside[y0:y1, x0:x1] = interior(truth)[y0:y1, x0:x1]
        high = {"splat": s.splat, "quality": "high"}
        for label, thing, method, opts in (("mesh 1spp", mesh, "mesh", {}), ("splat high", points, "splat", high)):
            img = r.render(thing, spec.camera, method, alpha=True, **opts)
            row = {"scene": name, "camera": spec.label, "voxel_px": spec.voxel_px, "renderer": label,
                   **score(truth, img, spec.crop, True), "interior": interior_mse(truth, img, inside),
                   "wall": None, "cpu": None}  # fmt: skip
            if frames and label == "splat high" and name in TIMED:
                walls, cpus = [], []
                for _ in range(frames):
                    c = time.process_time()
                    r.render(thing, spec.camera, method, **opts)
                    cpus.append(time.process_time() - c)
                    walls.append(r.last_frame_seconds)
                row["wall"], row["cpu"] = 1e3 * float(np.median(walls)), 1e3 * float(np.median(cpus))
            rows.append(row)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(aniso3d.scenes.CORPUS), help="comma-separated corpus scenes")
    ap.add_argument("--frames", type=int, default=0, help="timed frames of quality high on the blob and tree")
    ap.add_argument("--md", default="", help="Markdown file to write the table into")
    ap.add_argument("--marker", default="bench_splat_whole", help="name of the Markdown markers")
    args = ap.parse_args()
    scenes = [x.strip() for x in args.scenes.split(",") if x.strip()]
    unknown = sorted(set(scenes) - set(aniso3d.scenes.CORPUS))
    if unknown:
        ap.error(f"unknown scenes {unknown}; choose from {', '.join(aniso3d.scenes.CORPUS)}")
    started, load0 = time.time(), os.getloadavg()[0]
    rows: list[dict] = []
    with Renderer(CORPUS_PRESETS["full"].size, backend="egl") as r:
        gl_name = r.gl.renderer
        for name in scenes:
            rows += measure(r, name, args.frames)
            print(f"{name} done", flush=True)
    load1 = os.getloadavg()[0]

    def ms(x: float | None) -> str:
        return "–" if x is None else f"{x:.0f}"

    table = markdown_table(
        ["scene", "camera", "voxel px", "renderer", "PSNR dB", "FLIP", "coverage", "interior MSE", "wall ms",
         "cpu ms"],
        [[x["scene"], x["camera"], f"{x['voxel_px']:.2f}", x["renderer"], f"{x['psnr']:.2f}", f"{x['flip']:.4f}",
          f"{x['coverage']:.3f}", f"{x['interior']:.2f}", ms(x["wall"]), ms(x["cpu"])] for x in rows],
    )  # fmt: skip
    library = Path(aniso3d.__file__).resolve().parents[1]
    head = (
        f"Run {time.strftime('%Y-%m-%d %H:%M')} in {(time.time() - started) / 60:.1f} min on {gl_name}, "
        f"{platform.machine()}; `demos/bench_splat_whole.py --scenes {','.join(scenes)} --frames {args.frames}` "
        f"(library loaded from `{library}`). Load average {load0:.1f} at the start and {load1:.1f} at the end "
        f"on {os.cpu_count()} CPUs (frame times: median of {args.frames} after a warm-up, draw and read back)."
    )
    text = f"{head}\n\n{table}\n"
    print(text)
    if args.md:
        begin, end = f"<!-- {args.marker}:begin -->", f"<!-- {args.marker}:end -->"
        write_between_markers(args.md, f"{begin}\n{text}{end}", begin, end)

if __name__ == "__main__":
    main()
