"""Holes in point clouds from other tools: one splat size for all, or sized by spacing.

A noisy torus (major radius 1, minor 0.4, points scattered uniformly over its
area, each moved along its normal by Gaussian noise of 0.25 % of the minor
radius, with the torus's normals and a colour pattern) is written as binary
PLY without an ``area`` property, as a scanner or another tool would, and
read back two ways:

- ``uniform``: the bounding-box rule aniso3d used before (one area for every
  point from the box's two largest sides and the count);
- ``spacing``: :func:`aniso3d.build.spacing.splat_radii` (each point's radius
  from its 8 nearest neighbours, the default of ``PointCloud.load_ply``).

Each is drawn as disc splats in quality ``fast`` and ``high`` at 1024 x 1024;
the ground truth is the torus as polygons (a 1024 x 512 quad grid), whose
silhouette (alpha > 0), eroded by 2 pixels, is the region where every pixel
must be covered. Reported: the fraction of those pixels where the background
shows (alpha 0: nothing drawn; alpha < 1/2: more background than surface;
alpha < 1: any of it),
and the splat pixels outside the truth's silhouette dilated by 2 pixels
(overhang), as a fraction of the silhouette.

``--plane`` measures what chose :data:`aniso3d.build.spacing.COVERAGE`: random
points on a plane (periodic square), the fraction of the plane that no disc
of radius ``c * spacing`` covers, for several ``c`` (discs drawn with the
renderer's disc size factor 1.25 count as ``1.25 c``).

``--knn`` times the two exact neighbour searches of
:mod:`aniso3d.build.spacing` (scipy's k-d tree, NumPy's grid hash) on the torus
at 100k and 1M points, each in a fresh process for its peak memory.

    .venv/bin/python demos/bench_point_holes.py [--points 1000000 100000] [--size 1024] \\
        [--plane] [--knn] [--md docs/point_clouds.md]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import plyfile

# The torus of `aniso3d bench peers`: the same points and the same truth.
from aniso3d.bench.peers import AZIMUTH, ELEVATION, MAJOR, MINOR, torus_mesh, torus_points  # noqa: E402


def bbox_area(path: Path) -> float:
    """The earlier rule of ``PointCloud.load_ply`` for files without sizes: one
    area for every point, twice the area per point of a surface as large as the
    bounding box's two longest sides."""
    vertex = plyfile.PlyData.read(str(path))["vertex"].data
    pos = np.stack([vertex[c] for c in "xyz"], axis=1).astype(np.float64)
    ext = np.sort(np.ptp(pos, axis=0))[::-1]
    return 2.0 * max(ext[0] * ext[1], ext[0] ** 2 * 1e-6, 1e-300) / len(pos)


def write_ply(path: Path, pos: np.ndarray, normal: np.ndarray, colour: np.ndarray) -> Path:
    """Binary little-endian PLY with x y z nx ny nz red green blue (uchar), no area."""
    rec = np.empty(len(pos), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("nx", "<f4"), ("ny", "<f4"),
                                    ("nz", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])  # fmt: skip
    for i, c in enumerate("xyz"):
        rec[c], rec["n" + c] = pos[:, i], normal[:, i]
    rgb = np.round(np.clip(colour, 0, 1) * 255).astype(np.uint8)
    rec["red"], rec["green"], rec["blue"] = rgb.T
    plyfile.PlyData([plyfile.PlyElement.describe(rec, "vertex")]).write(str(path))
    return path


# ----------------------------------------------------------------- --knn


def _status_kib(field: str) -> int:
    line = next(x for x in Path("/proc/self/status").read_text().splitlines() if x.startswith(field + ":"))
    return int(line.split()[1])


def knn_worker(npy: str, method: str, k: int) -> None:
    """Child process: time one neighbour search; print seconds and peak memory."""
    from aniso3d.build.spacing import nearest_neighbours

    pts = np.load(npy)
    Path("/proc/self/clear_refs").write_text("5")  # resets the peak (VmHWM) to the current size
    base = _status_kib("VmRSS")
    t0, c0 = time.perf_counter(), time.process_time()
    nearest_neighbours(pts, k, method)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    peak = _status_kib("VmHWM")
    print(f"{wall:.3f} {cpu:.3f} {(peak - base) / 1024:.1f}")


def bench_knn(counts, k: int, repeats: int) -> list[str]:
    rows = ["| points | search | wall s | CPU s | peak memory MiB |", "| ---: | --- | ---: | ---: | ---: |"]
    with tempfile.TemporaryDirectory() as tmp:
        for n in counts:
            npy = os.path.join(tmp, f"torus{n}.npy")
            np.save(npy, torus_points(n)[0])
            for method in ("kdtree", "grid"):
                runs = []
                for _ in range(repeats):
                    out = subprocess.run([sys.executable, __file__, "--knn-worker", npy, method, str(k)],
                                         check=True, capture_output=True, text=True).stdout.split()  # fmt: skip
                    runs.append([float(x) for x in out])
                wall, cpu, mem = np.median(np.array(runs), axis=0)
                rows.append(f"| {n:,} | {method} | {wall:.2f} | {cpu:.2f} | {mem:.0f} |")
                print(rows[-1], flush=True)
    return rows


# ---------------------------------------------------------------- --plane


def bench_plane(n: int, queries: int, k: int, factors) -> list[str]:
    """Fraction of a periodic unit square that discs of radius c * spacing
    leave uncovered, n random points, ``queries`` random test points."""
    from scipy.spatial import cKDTree

    from aniso3d.build.spacing import local_spacing

    rng = np.random.default_rng(1)
    pts = rng.random((n, 2))
    tree = cKDTree(pts, boxsize=1.0)
    dist = tree.query(pts, k + 1)[0][:, 1:]
    spacing = local_spacing(dist)
    s = 1.0 / np.sqrt(n)
    uncovered = np.zeros(len(factors))
    done = 0
    while done < queries:
        m = min(1_000_000, queries - done)
        dq, iq = tree.query(rng.random((m, 2)), 32)
        for j, c in enumerate(factors):
            uncovered[j] += np.count_nonzero(~(dq < c * spacing[iq]).any(axis=1))
        done += m
    rows = [f"{n:,} random points on a periodic square, spacing from k = {k}; median spacing "
            f"{np.median(spacing) / s:.3f} / sqrt(area per point); {queries:,} test points", "",
            "| drawn disc radius / spacing | uncovered fraction of the plane |", "| ---: | ---: |"]  # fmt: skip
    print("\n".join(rows), flush=True)
    for c, u in zip(factors, uncovered, strict=True):
        frac = u / queries
        rows.append(f"| {c:.2f} | {frac:.1e}{' (none of ' + format(queries, ',') + ')' if u == 0 else ''} |")
        print(rows[-1], flush=True)
    return rows


# ---------------------------------------------------------------- holes


def hole_stats(img: np.ndarray, inner: np.ndarray, outer: np.ndarray) -> tuple[float, ...]:
    """(alpha == 0, alpha < 1/2 and alpha < 1 inside; alpha > 0 outside) as
    fractions of ``inner``'s pixels."""
    a = img[..., 3]
    n = max(int(inner.sum()), 1)
    return (np.count_nonzero((a == 0) & inner) / n, np.count_nonzero((a < 128) & inner) / n,
            np.count_nonzero((a < 255) & inner) / n, np.count_nonzero((a > 0) & ~outer) / n)  # fmt: skip


def erode(mask: np.ndarray, px: int) -> np.ndarray:
    out = mask.copy()
    for _ in range(px):
        m = out.copy()
        m[1:] &= out[:-1]
        m[:-1] &= out[1:]
        m[:, 1:] &= out[:, :-1]
        m[:, :-1] &= out[:, 1:]
        out = m
    return out


def bench_holes(counts, size: int, images: Path | None) -> list[str]:
    from aniso3d.build.points import PointCloud
    from aniso3d.rendering.camera import Camera
    from aniso3d.rendering.images import save_png
    from aniso3d.rendering.renderer import Renderer

    mesh = torus_mesh()
    r = MAJOR + MINOR
    bounds = np.array([[-r, -MINOR, -r], [r, MINOR, r]])
    az, el = np.radians(AZIMUTH), np.radians(ELEVATION)
    cam = Camera.fit(bounds, direction=(np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el)),
                     points=mesh.vertices[::7])  # fmt: skip
    rows = ["| points | areas | quality | background (alpha 0) | mostly background (alpha < 1/2) | "
            "some background (alpha < 1) | overhang | load time s | frame ms |",
            "| ---: | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |"]  # fmt: skip
    with Renderer((size, size)) as rend, tempfile.TemporaryDirectory() as tmp:
        truth = rend.render(mesh, cam, "mesh", alpha=True)
        sil = truth[..., 3] > 0
        inner, outer = erode(sil, 2), ~erode(~sil, 2)
        if images:
            images.mkdir(parents=True, exist_ok=True)
            save_png(images / "truth.png", truth[..., :3])
        for n in counts:
            path = write_ply(Path(tmp) / f"torus{n}.ply", *torus_points(n))
            for label in ("uniform", "spacing"):
                t0 = time.perf_counter()
                if label == "uniform":
                    cloud = PointCloud.load_ply(path, default_area=bbox_area(path))
                else:
                    cloud = PointCloud.load_ply(path)
                load_s = time.perf_counter() - t0
                for quality in ("fast", "high"):
                    rend.render(cloud, cam, "splat", splat="disc", quality=quality)  # upload, compile
                    img = rend.render(cloud, cam, "splat", alpha=True, splat="disc", quality=quality)
                    ms = 1000 * rend.last_frame_seconds
                    bg, mostly, some, over = hole_stats(img, inner, outer)
                    rows.append(f"| {n:,} | {label} | {quality} | {100 * bg:.3f} % | {100 * mostly:.3f} % | "
                                f"{100 * some:.3f} % | {100 * over:.2f} % | {load_s:.2f} | {ms:.0f} |")  # fmt: skip
                    print(rows[-1], flush=True)
                    if images:
                        save_png(images / f"torus{n}_{label}_{quality}.png", img[..., :3])
                del cloud
    return rows


def write_md(path: Path, name: str, rows: list[str]) -> None:
    begin, end = f"<!-- bench_point_holes:{name}:begin -->", f"<!-- bench_point_holes:{name}:end -->"
    text = path.read_text() if path.exists() else ""
    block = "\n".join([begin, *rows, end])
    if begin in text and end in text:
        text = text[: text.index(begin)] + block + text[text.index(end) + len(end):]
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    path.write_text(text)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, nargs="+", default=[1_000_000, 100_000])
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--plane", action="store_true", help="measure the plane's uncovered fraction instead")
    ap.add_argument("--plane-points", type=int, default=200_000)
    ap.add_argument("--plane-queries", type=int, default=20_000_000)
    ap.add_argument("--knn", action="store_true", help="time the neighbour searches instead")
    ap.add_argument("--repeats", type=int, default=3, help="--knn: runs per search (median)")
    ap.add_argument("--images", type=Path, default=None, help="write the images to this folder")
    ap.add_argument("--md", type=Path, default=None, help="write the table into this Markdown file")
    ap.add_argument("--knn-worker", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.knn_worker:
        knn_worker(args.knn_worker[0], args.knn_worker[1], int(args.knn_worker[2]))
        return 0
    from aniso3d.build.spacing import DEFAULT_K

    load0 = os.getloadavg()
    if args.plane:
        name = "plane"
        rows = bench_plane(args.plane_points, args.plane_queries, DEFAULT_K,
                           (1.0, 1.25, 1.5, 1.6, 1.7, 1.8, 1.9, 2.0, 2.2))  # fmt: skip
    elif args.knn:
        name = "knn"
        rows = bench_knn(args.points, DEFAULT_K, args.repeats)
    else:
        name = "holes"
        rows = bench_holes(args.points, args.size, args.images)
    load1 = os.getloadavg()
    note = (f"Machine load (1, 5, 15 min) {load0[0]:.1f} {load0[1]:.1f} {load0[2]:.1f} at the start, "
            f"{load1[0]:.1f} {load1[1]:.1f} {load1[2]:.1f} at the end, {os.cpu_count()} cores; "
            f"`{' '.join(['demos/bench_point_holes.py', *(argv if argv is not None else sys.argv[1:])])}`")  # fmt: skip
    print(note)
    if args.md:
        write_md(args.md, name, [*rows, "", note])
    return 0


if __name__ == "__main__":
    sys.exit(main())
