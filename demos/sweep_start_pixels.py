"""Process CPU time of volume frames with the start pass forced (drawn at
every distance) against rays started at the grid's box (no pass), at the
bench's cameras: the sweep behind ``START_PIXELS``, the voxel size on screen
from which :func:`~aniso3d.rendering.volume.start_pass_pays` draws the pass.

    .venv/bin/python demos/sweep_start_pixels.py tree bush ... [--size 1024]
        [--cameras 2px,1.5px,1px,0.7px,0.5px] [--frames 4]

Per scene and camera: the median ms of each (frames interleaved, the two
cases alternating twice) and their ratio (below 1: the pass pays).
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace

import numpy as np

import aniso3d
from aniso3d.bench.cameras import make_cameras
from aniso3d.bench.run import code_version
from aniso3d.bench.settings import PRESETS
from aniso3d.rendering import volume
from aniso3d.rendering.renderer import Renderer


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--cameras", default="2px,1.5px,1px,0.7px,0.5px")
    ap.add_argument("--frames", type=int, default=4)
    args = ap.parse_args()
    ver = code_version(("aniso3d", "shaders", "demos"))
    load0 = os.getloadavg()
    print(f"commit {(ver['commit'] or 'unknown')[:7]}{' (with uncommitted code)' if ver['dirty'] else ''}, "
          f"{args.size}^2, load before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}")  # fmt: skip
    settings = replace(PRESETS["full"], size=(args.size, args.size))
    rule = volume.START_PIXELS
    try:
        with Renderer((args.size, args.size)) as r:
            impl = r.method_renderer("volume")
            for name in args.scenes:
                mesh = aniso3d.scenes.get_scene(name)
                tex = aniso3d.build_texture(mesh)
                for spec in make_cameras(mesh.bounds, settings):
                    if spec.label not in args.cameras.split(","):
                        continue
                    ms: dict[str, list[float]] = {"box": [], "pass": []}
                    for _ in range(2):
                        for case, start, pixels in (("box", "box", rule), ("pass", "bricks", 0.0)):
                            volume.START_PIXELS = pixels
                            r.render(tex, spec.camera, "volume", start=start)  # warm
                            for _ in range(args.frames):
                                c0 = time.process_time()
                                r.render(tex, spec.camera, "volume", start=start)
                                ms[case].append(1000 * (time.process_time() - c0))
                            if case == "pass" and not impl.last_start_pass:
                                raise SystemExit(f"{name} {spec.label}: the start pass was not drawn")
                    box, drawn = float(np.median(ms["box"])), float(np.median(ms["pass"]))
                    print(f"{name} {spec.label}: box {box:.0f} pass {drawn:.0f} x{drawn / box:.3f}", flush=True)
    finally:
        volume.START_PIXELS = rule
    load1 = os.getloadavg()
    print(f"load after {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")


if __name__ == "__main__":
    main()
