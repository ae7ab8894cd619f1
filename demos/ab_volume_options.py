"""Process CPU time of volume frames under several option sets, interleaved,
at the bench's cameras: the quick A/B for a volume option (CPU time, every
llvmpipe thread of this process, is steadier than wall time on a shared
machine).

    .venv/bin/python demos/ab_volume_options.py pixel=shading:pixel table=shading:table
        [--scene tree] [--size 1024] [--cameras fill,1px,0.25px] [--frames 5]

Each case is name=option:value,option:value (an empty list: the defaults).
Prints per camera the median (min-max) ms of each case, its ratio to the
first, and its largest difference from the first case's image (0-255).
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
from aniso3d.rendering.renderer import Renderer


def parse_case(text: str) -> tuple[str, dict[str, str]]:
    name, _, rest = text.partition("=")
    opts = dict(kv.split(":", 1) for kv in rest.split(",") if kv)
    return name, opts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="+", help="name=option:value,...")
    ap.add_argument("--scene", default="tree")
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--cameras", default="fill,1px,0.25px")
    ap.add_argument("--frames", type=int, default=5)
    args = ap.parse_args()
    cases = dict(parse_case(c) for c in args.cases)
    mesh = aniso3d.scenes.get_scene(args.scene)
    tex = aniso3d.build_texture(mesh)
    settings = replace(PRESETS["full"], size=(args.size, args.size))
    ver = code_version(("aniso3d", "shaders", "demos"))
    load0 = os.getloadavg()
    print(
        f"{args.scene} at {args.size}^2, commit {(ver['commit'] or 'unknown')[:7]}"
        f"{' (with uncommitted code)' if ver['dirty'] else ''}, "
        f"load before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}"
    )
    first = next(iter(cases))
    with Renderer((args.size, args.size)) as r:
        for spec in make_cameras(mesh.bounds, settings):
            if spec.label not in args.cameras.split(","):
                continue
            images = {n: r.render(tex, spec.camera, "volume", **o).astype(np.float64) for n, o in cases.items()}
            cpu: dict[str, list[float]] = {n: [] for n in cases}
            for _ in range(args.frames):
                for n, o in cases.items():
                    c0 = time.process_time()
                    r.render(tex, spec.camera, "volume", **o)
                    cpu[n].append(1000 * (time.process_time() - c0))
            base = float(np.median(cpu[first]))
            cells = [
                f"{n} {np.median(v):.0f} ({min(v):.0f}-{max(v):.0f}) x{np.median(v) / base:.3f} "
                f"maxdiff {np.abs(images[n] - images[first]).max():.0f}"
                for n, v in cpu.items()
            ]
            print(f"{spec.label}: " + " | ".join(cells), flush=True)
    load1 = os.getloadavg()
    print(f"load after {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")


if __name__ == "__main__":
    main()
