"""Where a frame of splat quality "high" spends its time, pass by pass.

The clouds of ``demos/bench_splat_speed.py`` (the noisy 1M-point torus and the
default tree, ``--size`` 1024 x 1024) are drawn with ``quality="fast"`` and
``"high"`` in turn; every pass is bracketed by ``glFinish`` so that its
wall and CPU time (all rasteriser threads of the process) can be read on
their own. The finishes cost a little parallelism between passes, so the
passes add up to somewhat more than an unbracketed frame. Per pass: median
[min-max] over ``--frames`` frames after a warm-up, and the load average.

    .venv/bin/python demos/profile_splat_high.py [--frames 5] [--clouds torus,tree]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_splat_speed import load_torus  # noqa: E402

import aniso3d  # noqa: E402
from aniso3d.bench.corpus import view_direction  # noqa: E402
from aniso3d.build import scenes  # noqa: E402
from aniso3d.rendering.camera import Camera  # noqa: E402
from aniso3d.rendering.renderer import Renderer  # noqa: E402
from aniso3d.rendering.splat import coverage, fast, pipeline  # noqa: E402


class PassClock:
    """Wraps the splat passes' entry points so each is timed between two
    ``glFinish`` calls; ``times[name]`` lists (wall, cpu) seconds."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.times: dict[str, list] = defaultdict(list)
        self.active = False

    def wrap(self, owner, attr: str, name) -> None:
        orig = getattr(owner, attr)
        clock = self

        def timed(*args, **kwargs):
            if not clock.active:
                return orig(*args, **kwargs)
            label = name(*args, **kwargs) if callable(name) else name
            clock.ctx.finish()
            t0, c0 = time.perf_counter(), time.process_time()
            out = orig(*args, **kwargs)
            clock.ctx.finish()
            clock.times[label].append((time.perf_counter() - t0, time.process_time() - c0))
            return out

        setattr(owner, attr, timed)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--clouds", default="torus,tree")
    ap.add_argument("--cache", default="/tmp/bench_splat_speed")
    args = ap.parse_args()
    cache = Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    clouds = []
    for name in args.clouds.split(","):
        if name == "torus":
            cloud = load_torus(1_000_000, cache)
            cam = Camera.fit(cloud.bounds, direction=view_direction(), fov=40.0, aspect=1.0)
        elif name == "tree":
            cloud = aniso3d.build_texture(scenes.tree(), 128, 64).to_points()
            cam = Camera.frame(cloud.bounds)
        else:
            raise SystemExit(f"unknown cloud {name!r} (torus, tree)")
        clouds.append((name, cloud, cam))

    with Renderer((args.size, args.size), backend="egl") as r:
        clock = PassClock(r.gl.ctx)
        clock.wrap(pipeline.SplatPipeline, "splats", lambda self, h, v, o, kind, u: kind)
        clock.wrap(coverage.HighPass, "composite", "composite")
        clock.wrap(coverage.HighPass, "draw", "high: whole draw")
        clock.wrap(fast.FastPass, "draw", "fast: whole draw")
        for name, cloud, cam in clouds:
            clock.times.clear()
            load0 = os.getloadavg()[0]
            frame = {"fast": [], "high": []}
            for rnd in range(args.frames + 1):
                for q in ("fast", "high"):
                    clock.active = rnd > 0
                    t0, c0 = time.perf_counter(), time.process_time()
                    r.render(cloud, cam, "splat", quality=q, alpha=True)
                    if rnd:
                        frame[q].append((time.perf_counter() - t0, time.process_time() - c0))
            load1 = os.getloadavg()[0]
            print(f"\n{name} ({len(cloud):,} points, {args.size}^2), load {load0:.1f}-{load1:.1f}; "
                  f"ms, median [min-max] of {args.frames}")  # fmt: skip
            print("| pass | wall | CPU |\n|---|---|---|")
            rows = list(clock.times.items()) + [(f"{q}: frame (render + read-back)", v) for q, v in frame.items()]
            for label, vals in rows:
                w, c = (np.array(x) * 1e3 for x in zip(*vals, strict=True))
                print(f"| {label} | {np.median(w):.0f} [{w.min():.0f}-{w.max():.0f}] | {np.median(c):.0f} |")


if __name__ == "__main__":
    main()
