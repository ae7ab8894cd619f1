"""Benchmark of the CPU build: the default tree -> anisotropic 3D texture -> points,
side by side with trimesh's own voxelisation at the same voxel size.

    .venv/bin/python demos/bench_build.py [--resolution 128] [--directions 64] [--repeat 3]

Every contender runs in a fresh subprocess, so its peak RSS (getrusage
ru_maxrss) is its own. Each is run ``--repeat`` times for timing (median
reported) and once more under tracemalloc for the Python-level peak (numpy
buffers included); tracemalloc slows things down, so that run is not timed.
The tree itself is generated in every subprocess before the clock starts; "RSS
before" is the high-water mark at that point (interpreter, imports, tree).

Contenders:
- aniso3d: ``build_texture`` (exact clipping of every triangle into voxels,
  registration onto K-direction density and shading spheres) + ``to_points``.
- trimesh: ``mesh.to_trimesh().voxelized(pitch=h)``, occupancy only (no
  areas, normals or materials), at the same voxel edge h.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
import tracemalloc


def _rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux


def worker(name: str, resolution: int, directions: int, trace: bool) -> dict:
    import numpy as np

    from aniso3d import build_texture, scenes
    from aniso3d.build.clip import make_grid

    t0 = time.perf_counter()
    mesh = scenes.tree()
    scene_s = time.perf_counter() - t0
    h = make_grid(mesh.bounds, resolution).voxel_size
    res: dict = {"name": name, "triangles": int(mesh.n_faces), "scene_s": scene_s, "voxel_size": h}
    rss_before = _rss_mib()
    if trace:
        tracemalloc.start()
        tracemalloc.reset_peak()
    t0 = time.perf_counter()
    if name == "aniso3d":
        timings: dict[str, float] = {}
        tex = build_texture(mesh, resolution, directions, timings=timings)
        t1 = time.perf_counter()
        points = tex.to_points()
        t2 = time.perf_counter()
        res.update(
            clip_s=timings["clip"],
            register_s=timings["register"],
            points_s=t2 - t1,
            total_s=t2 - t0,
            voxels=int(tex.n_voxels),
            entries=int(tex.n_entries),
            points=len(points),
            area_error=abs(tex.total_area() - mesh.area()) / mesh.area(),
        )
    elif name == "trimesh":
        tm = mesh.to_trimesh()
        t1 = time.perf_counter()
        vox = tm.voxelized(pitch=h)
        voxels = int(vox.filled_count)  # forces the occupancy to exist
        t2 = time.perf_counter()
        res.update(
            convert_s=t1 - t0,
            voxelize_s=t2 - t1,
            total_s=t2 - t1,
            voxels=voxels,
            vox_shape=[int(s) for s in vox.shape],
        )
    else:
        raise SystemExit(f"unknown contender {name}")
    if trace:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        res["py_peak_mib"] = peak / 2**20
    res["rss_before_mib"] = rss_before
    res["rss_peak_mib"] = _rss_mib()
    res["numpy"] = np.__version__
    return res


def run_worker(name: str, args, trace: bool) -> dict:
    cmd = [
        sys.executable,
        os.path.abspath(__file__),
        "--worker",
        name,
        "--resolution",
        str(args.resolution),
        "--directions",
        str(args.directions),
    ]
    if trace:
        cmd.append("--trace")
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"{name} worker failed:\n{proc.stderr}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=64)
    ap.add_argument("--repeat", type=int, default=3, help="timed runs per contender (median)")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--trace", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        print(json.dumps(worker(args.worker, args.resolution, args.directions, args.trace)))
        return

    import trimesh

    import aniso3d

    rows = {}
    for name in ("aniso3d", "trimesh"):
        runs = [run_worker(name, args, trace=False) for _ in range(args.repeat)]
        traced = run_worker(name, args, trace=True)
        med = {k: statistics.median(r[k] for r in runs) for k in runs[0] if k.endswith("_s")}
        rows[name] = {
            **runs[0],
            **med,
            "runs": [r["total_s"] for r in runs],
            "rss_peak_mib": max(r["rss_peak_mib"] for r in runs),
            "py_peak_mib": traced["py_peak_mib"],
        }

    a, t = rows["aniso3d"], rows["trimesh"]
    versions = (
        f"Python {platform.python_version()}, numpy {a['numpy']}, "
        f"trimesh {trimesh.__version__}, aniso3d {aniso3d.__version__}"
    )
    print(f"# Build benchmark: default tree, resolution {args.resolution}, K = {args.directions}\n")
    print(f"- machine: {platform.machine()}, {os.cpu_count()} CPUs, {versions}")
    print(
        f"- mesh: {a['triangles']:,} triangles (scene generation {a['scene_s']:.2f} s, "
        f"not counted); voxel edge h = {a['voxel_size']:.5g}"
    )
    print(
        f"- times: median of {args.repeat} fresh processes; Python peak from one extra "
        "run under tracemalloc\n"
    )
    header = [
        "contender", "clip s", "register s", "points s", "total s", "triangles/s",
        "Python peak MiB", "peak RSS MiB", "RSS before MiB", "occupied voxels",
    ]  # fmt: skip
    dash = "—"
    table = [
        [
            "aniso3d build_texture + to_points",
            f"{a['clip_s']:.2f}",
            f"{a['register_s']:.2f}",
            f"{a['points_s']:.2f}",
            f"**{a['total_s']:.2f}**",
            f"{a['triangles'] / a['total_s']:,.0f}",
            f"{a['py_peak_mib']:.0f}",
            f"{a['rss_peak_mib']:.0f}",
            f"{a['rss_before_mib']:.0f}",
            f"{a['voxels']:,}",
        ],
        [
            "trimesh voxelized(pitch=h), occupancy only",
            dash,
            dash,
            dash,
            f"**{t['total_s']:.2f}**",
            f"{t['triangles'] / t['total_s']:,.0f}",
            f"{t['py_peak_mib']:.0f}",
            f"{t['rss_peak_mib']:.0f}",
            f"{t['rss_before_mib']:.0f}",
            f"{t['voxels']:,}",
        ],
    ]
    print("| " + " | ".join(header) + " |")
    print("|---|" + "---:|" * (len(header) - 1))
    for row in table:
        print("| " + " | ".join(row) + " |")
    print()
    print(
        f"- aniso3d: {a['entries']:,} shading entries, {a['points']:,} points; registered "
        f"area off the mesh area by {a['area_error']:.1e} (relative)"
    )
    print(
        f"- trimesh: {t['vox_shape']} voxel grid; Mesh -> trimesh.Trimesh conversion "
        f"{t['convert_s']:.2f} s not counted in its time (counted in its memory)"
    )
    runs_a = ", ".join(f"{s:.2f}" for s in a["runs"])
    runs_t = ", ".join(f"{s:.2f}" for s in t["runs"])
    print(f"- total per run, aniso3d: {runs_a} s; trimesh: {runs_t} s")
    ratio = a["total_s"] / t["total_s"]
    verdict = "no slower than" if ratio <= 1.0 else "SLOWER than"
    print(
        f"- aniso3d's whole build takes {ratio:.2f}x trimesh's voxelisation time "
        f"({verdict} trimesh); target < 10 s: {'met' if a['total_s'] < 10 else 'NOT met'}"
    )


if __name__ == "__main__":
    main()
