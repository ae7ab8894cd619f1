"""Benchmark of batch frames on a Dask cluster: frames per second of a
turntable drawn by ``render_frames`` in this process (serial) and on local
Dask clusters of 1 and 2 worker processes, per method.

    .venv/bin/python demos/bench_cluster.py [--frames 24] [--size 256] [--runs 3] [--resolution 64]

The input is the procedural tree (262k triangles); its texture (``--resolution``,
K = 16) is built once, before timing, so volume and splats time the frames and
not the conversion; the polygon method draws the mesh. Every timed call is a
whole ``render_frames`` call returning arrays: serial makes a renderer (GL
context, upload) per call; on a cluster the thing is scattered per call and
uploaded once per worker per call, on contexts the workers keep from a
warm-up call. Contenders are interleaved within each run (serial, 1 worker,
2 workers, per method), and the median and the spread (min to max) over the
runs are printed, with the load average before and after. Workers run one
Dask thread each with ``LP_NUM_THREADS`` = cores / workers (the default of a
local cluster, printed); the serial renderer keeps llvmpipe's default (one
thread per core). Every cluster frame is checked equal to the serial frame.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from aniso3d import Camera, build_texture, render_frames, scenes, turntable
from aniso3d.build.stream import local_cluster
from aniso3d.rendering import distributed as dist

METHODS = ("splat", "volume", "mesh")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--resolution", type=int, default=64)
    a = ap.parse_args()
    from distributed import Client

    mesh = scenes.tree()
    tex = build_texture(mesh, a.resolution, 16)
    cams = turntable(Camera.fit(mesh.bounds, direction=(0.6, 0.3, 0.75)), a.frames, 360.0)
    size = (a.size, a.size)
    things = {"mesh": mesh, "volume": tex, "splat": tex}
    load0 = os.getloadavg()
    print(f"tree {mesh.n_faces:,} triangles, texture {a.resolution}^3 K=16; {a.frames} frames at {a.size}^2, "
          f"{a.runs} runs; cores {os.cpu_count()}; load average before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}")
    with local_cluster(1) as c1, Client(c1) as k1, local_cluster(2) as c2, Client(c2) as k2:
        contenders = {"serial": None, "dask, 1 worker": (k1, dist.local_threads(1)),
                      "dask, 2 workers": (k2, dist.local_threads(2))}  # fmt: skip
        ref = {m: render_frames(things[m], cams, None, m, size=size) for m in METHODS}
        for k, t in (v for v in contenders.values() if v):  # warm-up: contexts made, shaders compiled
            for m in METHODS:
                got = render_frames(things[m], cams, None, m, size=size, client=k, threads=t)
                assert all(np.array_equal(x, y) for x, y in zip(ref[m], got, strict=True)), m
        for name, v in contenders.items():
            if v is not None:
                lp = sorted({s["lp_num_threads"] for s in v[0].run(dist.worker_state).values()})
                print(f"{name}: LP_NUM_THREADS per worker {lp}")
        times = {(m, n): [] for m in METHODS for n in contenders}
        for _ in range(a.runs):
            for m in METHODS:
                for name, v in contenders.items():
                    kw = {} if v is None else {"client": v[0], "threads": v[1]}
                    t0 = time.perf_counter()
                    render_frames(things[m], cams, None, m, size=size, **kw)
                    times[(m, name)].append(time.perf_counter() - t0)
    load1 = os.getloadavg()
    print(f"load average after {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")
    print("| method | executor | frames/s (median) | spread (min to max) | seconds per call (median) |")
    print("|---|---|---:|---|---:|")
    for m in METHODS:
        for name in contenders:
            fps = sorted(a.frames / s for s in times[(m, name)])
            print(f"| {m} | {name} | {np.median(fps):.1f} | {fps[0]:.1f} to {fps[-1]:.1f} | "
                  f"{np.median(times[(m, name)]):.2f} |")


if __name__ == "__main__":
    main()
