"""What reading patches by the outside costs (aniso3d/build/outside.py).

A street of N x N two-storey buildings (``scenes.storeys``): two boxes
each, the upper standing on the lower's lid, drawn once (its edges shared
by three faces), so every building is three patches. Or, with ``--block
N``, N^3 unit cubes in a block, each drawn whole, sharing their faces with
their neighbours (a voxel export: every inner face a patch). Times
``closed_sides`` (the topology a build reads first) with the outside test
and with it replaced by "open", over several runs, and prints the closed
shares: the buildings' walls +1 and the floor plates between storeys 0;
the block's outer faces +1, its inner ones 0. ``--subdivide K`` splits
every face into 4^K first (a large mesh with few patches, as a scan with a
fin or a dense CAD export is: the case where the rays are few and the
faces many).

    .venv/bin/python demos/bench_outside.py [--n 40 | --block 20] [--subdivide K] [--runs 5]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import trimesh

import aniso3d.build.mesh as mesh_module
from aniso3d.build import scenes


def street(n: int) -> tuple[np.ndarray, np.ndarray]:
    building = scenes.storeys(2)
    bv, bf = building.vertices, building.faces
    step = float(np.ptp(bv, axis=0).max()) * 1.5
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    shift = np.stack([i.ravel() * step, np.zeros(n * n), j.ravel() * step], axis=1)
    v = (bv[None] + shift[:, None]).reshape(-1, 3)
    f = (bf[None] + (np.arange(n * n) * len(bv))[:, None, None]).reshape(-1, 3)
    return v, f


def block(n: int) -> tuple[np.ndarray, np.ndarray]:
    cube = scenes.cube()
    cv = cube.vertices - cube.vertices.min(axis=0)
    step = float(np.ptp(cv, axis=0).max())
    g = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3) * step
    v = (cv[None] + g[:, None]).reshape(-1, 3)
    f = (cube.faces[None] + len(cv) * np.arange(len(g))[:, None, None]).reshape(-1, 3)
    return v, f


def subdivide(v: np.ndarray, f: np.ndarray, times: int) -> tuple[np.ndarray, np.ndarray]:
    """Every face split into 4^times (midpoints shared by the faces beside an edge)."""
    for _ in range(times):
        v, f = trimesh.remesh.subdivide(v, f)
    return v, f


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=40, help="buildings along each side of the street grid")
    ap.add_argument("--block", type=int, default=0, help="instead: N^3 cubes sharing their faces")
    ap.add_argument("--subdivide", type=int, default=0, help="split every face into 4^K first")
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    if args.block:
        v, f = block(args.block)
        what = f"{args.block ** 3} cubes in a block"
    else:
        v, f = street(args.n)
        what = f"{args.n * args.n} buildings"
    if args.subdivide:
        v, f = subdivide(v, f, args.subdivide)
        what += f", every face split into 4^{args.subdivide}"
    print(f"{what}, {len(f)} faces; load average {os.getloadavg()} at the start")
    original = mesh_module.outside_sides
    for name, fn in (("outside", original), ("open", lambda *a: np.zeros(len(a[4]), np.int8))):
        mesh_module.outside_sides = fn
        try:
            times = []
            for _ in range(args.runs):
                t0 = time.perf_counter()
                sides = mesh_module.closed_sides(v, f)
                times.append(time.perf_counter() - t0)
        finally:
            mesh_module.outside_sides = original
        t = np.sort(times)
        shares = {int(k): int(c) for k, c in zip(*np.unique(sides, return_counts=True), strict=True)}
        print(f"{name:8s} median {np.median(t):.3f} s [{t[0]:.3f}-{t[-1]:.3f}], sides {shares}")
    print(f"load average {os.getloadavg()} at the end")


if __name__ == "__main__":
    main()
