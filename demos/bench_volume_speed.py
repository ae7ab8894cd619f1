"""Frame time of the volume renderer against 1-spp polygons, before ("plain"
marching) and after ("skip", the default), per scene and bench distance.

The default tree at --size (1024) and every corpus scene at --corpus-size
(256: a 1024^2 sweep of nine scenes does not fit the time we have), each at
the bench's cameras (aniso3d.bench.cameras.make_cameras with the "full"
preset's footprints, the default texture: 128^3, K = 16). Per camera the
three renderers are timed interleaved (polygons, plain, skip, polygons, ...)
over --frames frames: median and spread (min-max) of Renderer.last_frame_seconds
(draw + read back), and the load average before and after. Accuracy: PSNR
of plain and skip against 8x8 polygons (aniso3d.metrics.compare_in_box in the
bench's crop box). Writes a Markdown table.

    .venv/bin/python demos/bench_volume_speed.py [--out docs/volume_speed.md]
        [--size 1024] [--corpus-size 256] [--frames 5] [--scenes tree,bush]
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import aniso3d
from aniso3d.bench.cameras import make_cameras
from aniso3d.bench.settings import PRESETS
from aniso3d.files import atomic_write
from aniso3d.metrics import compare_in_box
from aniso3d.rendering.renderer import Renderer


def time_interleaved(r: Renderer, cases: dict, cam, frames: int) -> dict[str, list[float]]:
    """Seconds per frame of each case (name -> (thing, method, options)),
    one frame of each in turn, after one warm-up frame each."""
    for thing, method, opts in cases.values():
        r.render(thing, cam, method, **opts)
    times: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(frames):
        for name, (thing, method, opts) in cases.items():
            r.render(thing, cam, method, **opts)
            times[name].append(r.last_frame_seconds)
    return times


def bench_scene(name: str, size: int, frames: int) -> list[dict]:
    mesh = aniso3d.scenes.get_scene(name)
    tex = aniso3d.build_texture(mesh)
    settings = replace(PRESETS["full"], size=(size, size))
    rows = []
    with Renderer((size, size)) as r:
        for spec in make_cameras(mesh.bounds, settings):
            cam = spec.camera
            cases = {
                "mesh": (mesh, "mesh", {}),
                "plain": (tex, "volume", {"march": "plain"}),
                "skip": (tex, "volume", {"march": "skip"}),
            }
            t = time_interleaved(r, cases, cam, frames)
            truth = r.render(mesh, cam, "mesh", ssaa=8)
            psnr = {
                m: compare_in_box(truth, r.render(tex, cam, "volume", march=m), spec.crop, with_flip=False)["psnr"]
                for m in ("plain", "skip")
            }
            row = {"scene": name, "size": size, "camera": spec.label, "psnr": psnr}
            for m, v in t.items():
                row[m] = (1000 * float(np.median(v)), 1000 * float(np.min(v)), 1000 * float(np.max(v)))
            rows.append(row)
            print(_line(row), flush=True)
    return rows


def _line(row: dict) -> str:
    m, p, s = row["mesh"], row["plain"], row["skip"]
    return (
        f"| {row['scene']} | {row['size']} | {row['camera']} | {m[0]:.0f} ({m[1]:.0f}-{m[2]:.0f}) "
        f"| {p[0]:.0f} ({p[1]:.0f}-{p[2]:.0f}) | {p[0] / m[0]:.1f} | {s[0]:.0f} ({s[1]:.0f}-{s[2]:.0f}) "
        f"| {s[0] / m[0]:.1f} | {row['psnr']['plain']:.2f} | {row['psnr']['skip']:.2f} "
        f"| {row['psnr']['skip'] - row['psnr']['plain']:+.3f} |"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("docs/volume_speed.md"))
    ap.add_argument("--size", type=int, default=1024, help="image side of the tree, pixels")
    ap.add_argument("--corpus-size", type=int, default=256, help="image side of the other corpus scenes")
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--scenes", default=",".join(aniso3d.scenes.CORPUS))
    args = ap.parse_args()
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    print("| scene | px | camera | polygons 1-spp ms | plain ms | plain / poly | skip ms | skip / poly "
          "| PSNR plain | PSNR skip | dPSNR |")
    rows = []
    for name in args.scenes.split(","):
        rows += bench_scene(name, args.size if name == "tree" else args.corpus_size, args.frames)
    load1 = os.getloadavg()
    head = [
        "# Volume renderer: frame time against 1-spp polygons",
        "",
        "Written by `demos/bench_volume_speed.py` "
        f"(`--size {args.size} --corpus-size {args.corpus_size} --frames {args.frames}`), "
        f"{time.perf_counter() - t0:.0f} s, on llvmpipe (LP_NUM_THREADS default, 2 cores shared with "
        f"other jobs). Load average (1, 5, 15 min) before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}, "
        f"after {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}.",
        "",
        "Default texture (128^3, K = 16), default options (opacity \"planar\"). Per camera of the bench "
        "(`fill`, then a baseline voxel of 2 ... 0.25 px), polygons, \"plain\" (the volume marching "
        "before: storage buffers, compositing inside the two-level DDA, T_MIN 0.001) and \"skip\" "
        "(now the default: arrays as 2D textures, each ray's next occupied voxel found before it is "
        "composited, T_MIN 0.005) are timed interleaved: median (min-max) of draw + read back, ms. "
        "PSNR against 8x8 polygons in the bench's crop box (`compare_in_box`). The tree at "
        f"{args.size}^2, the other corpus scenes at {args.corpus_size}^2.",
        "",
        "| scene | px | camera | polygons 1-spp ms | plain ms | plain / poly | skip ms | skip / poly "
        "| PSNR plain | PSNR skip | dPSNR |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    atomic_write(args.out, ("\n".join(head + [_line(row) for row in rows]) + "\n").encode())
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
