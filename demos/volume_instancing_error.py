"""How far the instanced volume draw of a forest is from one pass per
instance, per number of depth slabs (``scene_draw.VOLUME_DEPTH_SLABS``):
mean and largest absolute difference (0-255) and the fraction of pixels off
by more than 2, with the draw calls. Inside one slab, instances of different
(asset, level) groups are composed group by group, not back to front.

    ./.venv/bin/python demos/volume_instancing_error.py [--size 512] [--counts 100 1000 10000]
"""

from __future__ import annotations

import argparse
import os

import numpy as np

import aniso3d
from aniso3d.rendering import scene_draw
from aniso3d.rendering.renderer import Renderer

VIEW = (0.5, 0.9, 1.0)  # as demos/bench_forest.py
RESOLUTION = 64
SLABS = (1, 4, 16, 64)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--counts", type=int, nargs="+", default=[100, 1000, 10000])
    args = ap.parse_args()
    size = (args.size, args.size)
    print(f"load {os.getloadavg()[0]:.1f}")
    print("| trees | slabs | draw calls | mean abs diff | max abs diff | pixels off by > 2 |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: |")
    with Renderer(size, cache_entries=64) as r:
        for n in args.counts:
            scene = aniso3d.scenes.forest(n, seed=1)
            cam = aniso3d.framing_camera(scene, size, direction=VIEW)
            scene_draw.VOLUME_INSTANCED = False
            want = r.render(scene, cam, "volume", resolution=RESOLUTION).astype(int)
            scene_draw.VOLUME_INSTANCED = True
            for slabs in SLABS:
                scene_draw.VOLUME_DEPTH_SLABS = slabs
                frame = r.render_frame(scene, cam, "volume", resolution=RESOLUTION)
                d = np.abs(frame.color.astype(int) - want)
                print(f"| {n} | {slabs} | {frame.stats.lod['draw_calls']} | {d.mean():.3f} | {d.max()} | "
                      f"{(d.max(axis=2) > 2).mean():.4f} |", flush=True)
    print(f"load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
