"""Frame time of splat quality "high" against "fast", and the accuracy of "high"
on the corpus, in one run.

**Speed.** Three clouds at ``--size`` (default 1024 x 1024): a noisy torus of
1M and of 100k points (normals and colours, no sizes: written as a binary
PLY and read back with ``PointCloud.load_ply``, the path ``aniso3d render``
takes, so splat sizes come from the points' spacing) seen from ``aniso3d
render``'s default view, and the default tree (``aniso3d.scenes.tree()``,
128^3 voxels, K = 64, ``to_points()``) from ``Camera.frame(bounds)``. Per
cloud the two qualities alternate frame by frame (one warm-up each), each
frame ``Renderer.render`` (draw and read back); the table gives the median,
fastest and slowest wall time, the median CPU time of the process (all
rasteriser threads) and high / fast of the medians.

**Accuracy** (``--accuracy``): every scene of ``aniso3d.scenes.CORPUS`` (the
tree among them) at the default texture, splats "high" (discs, the corpus
bench's baseline) at the corpus bench's two cameras (close: the object fills
the image; minified: a voxel spans about a pixel), PSNR and FLIP against
polygons at 8 x 8 samples per pixel inside the object's box
(``metrics.compare_in_box``), at ``--accuracy-size`` (512). The truths are
cached in ``--cache`` (they do not depend on the splat code).

Tables go to stdout and, with ``--md``, between ``<!-- NAME:begin -->`` and
``<!-- NAME:end -->`` of that file, NAME from ``--marker``; ``--json`` also
writes the numbers. ``--compare BEFORE.json`` (the ``--json`` of an earlier
run, e.g. on the parent commit) adds tables of both runs side by side: the
high / fast ratios, and per scene and camera the PSNR and FLIP before and
after and their change.

    .venv/bin/python demos/bench_splat_speed.py [--frames 5] [--accuracy] \\
        [--md docs/splat_speed.md --marker after] [--json /tmp/after.json] \\
        [--compare /tmp/before.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
import plyfile

import aniso3d
from aniso3d import metrics
from aniso3d.bench.corpus import corpus_cameras, view_direction
from aniso3d.build import scenes
from aniso3d.build.points import PointCloud
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.images import save_png
from aniso3d.rendering.renderer import Renderer


def noisy_torus(n: int, seed: int = 1, major: float = 1.0, minor: float = 0.35, noise: float = 0.004) -> dict:
    """``n`` points uniform on a torus's surface (area-weighted by rejection),
    moved along their normals by Gaussian noise of ``noise`` (world units),
    normals from the torus, colours from the angles: PLY vertex columns."""
    rng = np.random.default_rng(seed)
    u, v = np.empty(0), np.empty(0)
    while len(u) < n:  # the area element is proportional to major + minor cos v
        m = 2 * (n - len(u)) + 1000
        uu, vv = rng.uniform(0, 2 * np.pi, m), rng.uniform(0, 2 * np.pi, m)
        keep = rng.uniform(0, major + minor, m) < major + minor * np.cos(vv)
        u, v = np.concatenate([u, uu[keep]]), np.concatenate([v, vv[keep]])
    u, v = u[:n], v[:n]
    nrm = np.stack([np.cos(v) * np.cos(u), np.sin(v), np.cos(v) * np.sin(u)], axis=1)
    centre = np.stack([major * np.cos(u), np.zeros(n), major * np.sin(u)], axis=1)
    pos = centre + nrm * (minor + rng.normal(0.0, noise, n))[:, None]
    rgb = np.stack([0.5 + 0.4 * np.cos(3 * u), 0.5 + 0.4 * np.sin(2 * v), 0.5 + 0.3 * np.cos(u + v)], axis=1)
    return {"pos": pos, "nrm": nrm, "rgb": (255 * rgb).astype(np.uint8)}


def write_ply(path: Path, cols: dict) -> None:
    """A binary PLY of x y z nx ny nz red green blue (no sizes)."""
    n = len(cols["pos"])
    names = [("x", "f4"), ("y", "f4"), ("z", "f4"), ("nx", "f4"), ("ny", "f4"), ("nz", "f4"),
             ("red", "u1"), ("green", "u1"), ("blue", "u1")]  # fmt: skip
    data = np.empty(n, dtype=names)
    for i, c in enumerate("xyz"):
        data[c] = cols["pos"][:, i]
        data["n" + c] = cols["nrm"][:, i]
    for i, c in enumerate(("red", "green", "blue")):
        data[c] = cols["rgb"][:, i]
    plyfile.PlyData([plyfile.PlyElement.describe(data, "vertex")]).write(str(path))


def load_torus(n: int, cache: Path) -> PointCloud:
    path = cache / f"torus_{n}.ply"
    if not path.exists():
        write_ply(path, noisy_torus(n))
    return PointCloud.load_ply(path)


def speed(args, clouds: list[tuple[str, PointCloud, Camera]]) -> list[dict]:
    """Fast and high alternating, per cloud."""
    size = (args.size, args.size)
    rows = []
    with Renderer(size, backend="egl") as r:
        for name, cloud, cam in clouds:
            times: dict[str, list] = {"fast": [], "high": []}
            cpus: dict[str, list] = {"fast": [], "high": []}
            load0 = os.getloadavg()[0]
            for rnd in range(args.frames + 1):
                for q in ("fast", "high"):
                    t0, c0 = time.perf_counter(), time.process_time()
                    img = r.render(cloud, cam, "splat", quality=q, alpha=True)
                    if rnd:
                        times[q].append(time.perf_counter() - t0)
                        cpus[q].append(time.process_time() - c0)
                    elif args.images:
                        out = Path(args.images)
                        out.mkdir(parents=True, exist_ok=True)
                        save_png(out / f"{name}_{q}.png", np.ascontiguousarray(img[..., :3]))
            load1 = os.getloadavg()[0]
            row = {"cloud": name, "points": len(cloud), "load": (load0, load1)}
            for q in ("fast", "high"):
                t = np.array(times[q]) * 1e3
                row[q] = {"median": float(np.median(t)), "min": float(t.min()), "max": float(t.max()),
                          "cpu": float(np.median(cpus[q]) * 1e3)}  # fmt: skip
            row["ratio"] = row["high"]["median"] / row["fast"]["median"]
            rows.append(row)
            print(f"{name}: fast {row['fast']['median']:.0f} ms, high {row['high']['median']:.0f} ms, "
                  f"x{row['ratio']:.2f} (load {load0:.1f}-{load1:.1f})", flush=True)  # fmt: skip
    return rows


def accuracy(args, cache: Path) -> list[dict]:
    """Splats "high" against the 8x8 polygon truth per corpus scene and camera."""
    size = (args.accuracy_size, args.accuracy_size)
    rows = []
    with Renderer(size, backend="egl") as r:
        for name, mesh in scenes.corpus():
            tex = aniso3d.build_texture(mesh, bounds=mesh.bounds)
            points = tex.to_points()
            for spec in corpus_cameras(mesh, size, tex.resolution):
                tpath = cache / f"truth_{name}_{spec.label}_{size[0]}.npy"
                if tpath.exists():
                    truth = np.load(tpath)
                else:
                    truth = r.render(mesh, spec.camera, "mesh", ssaa=8)
                    np.save(tpath, truth)
                img = r.render(points, spec.camera, "splat", splat="disc", quality="high")
                if args.images:
                    save_png(Path(args.images) / f"acc_{name}_{spec.label}.png", img)
                m = metrics.compare_in_box(truth, img, spec.crop, with_flip=True)
                rows.append({"scene": name, "camera": spec.label, "voxel_px": spec.voxel_px,
                             "psnr": m["psnr"], "flip": m.get("flip", float("nan"))})  # fmt: skip
                print(f"{name} {spec.label}: {m['psnr']:.2f} dB, FLIP {m.get('flip', float('nan')):.4f}", flush=True)
    return rows


def compare_tables(before: dict, speed_rows: list[dict], acc_rows: list[dict]) -> list[str]:
    """Markdown lines: this run against ``before`` (another run's ``--json``)."""
    lines = [f"Before: {before['head']}", ""]
    old = {r["cloud"]: r for r in before["speed"]}
    both = [(old[r["cloud"]], r) for r in speed_rows if r["cloud"] in old]
    if both:
        lines += ["| cloud | high ms before | high ms after | high / fast before | after | (CPU) before | after |",
                  "|---|---|---|---|---|---|---|"]  # fmt: skip
        for b, a in both:
            cpu = [x["high"]["cpu"] / x["fast"]["cpu"] for x in (b, a)]
            lines.append(f"| {a['cloud']} | {b['high']['median']:.0f} | {a['high']['median']:.0f} "
                         f"| {b['ratio']:.2f} | {a['ratio']:.2f} | {cpu[0]:.2f} | {cpu[1]:.2f} |")  # fmt: skip
        lines.append("")
    old_acc = {(r["scene"], r["camera"]): r for r in before["accuracy"]}
    pairs = [(old_acc[(r["scene"], r["camera"])], r) for r in acc_rows if (r["scene"], r["camera"]) in old_acc]
    if pairs:
        lines += ["| scene | camera | voxel px | PSNR before | PSNR after | change dB | FLIP before | FLIP after "
                  "| change |", "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
        for b, a in pairs:
            lines.append(f"| {a['scene']} | {a['camera']} | {a['voxel_px']:.2f} | {b['psnr']:.2f} | {a['psnr']:.2f} "
                         f"| {a['psnr'] - b['psnr']:+.3f} | {b['flip']:.4f} | {a['flip']:.4f} "
                         f"| {a['flip'] - b['flip']:+.4f} |")  # fmt: skip
        dp = [a["psnr"] - b["psnr"] for b, a in pairs]
        df = [a["flip"] - b["flip"] for b, a in pairs]
        lines += ["", f"Largest PSNR loss {-min(dp):.3f} dB, largest gain {max(dp):.3f} dB; "
                  f"largest FLIP increase {max(df):+.4f}.", ""]  # fmt: skip
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--torus", default="1000000,100000", help="torus point counts, comma-separated")
    ap.add_argument("--no-tree", action="store_true", help="skip the tree in the speed table")
    ap.add_argument("--no-speed", action="store_true", help="skip the speed table")
    ap.add_argument("--accuracy", action="store_true", help="also the corpus accuracy table")
    ap.add_argument("--accuracy-size", type=int, default=512)
    ap.add_argument("--cache", default="/tmp/bench_splat_speed", help="folder for the torus PLYs and truths")
    ap.add_argument("--images", default="", help="folder to save the images to (optional)")
    ap.add_argument("--md", default="", help="Markdown file to write the tables into")
    ap.add_argument("--marker", default="bench_splat_speed")
    ap.add_argument("--json", default="", help="file to write the numbers to")
    ap.add_argument("--compare", default="", help="an earlier run's --json, to set side by side")
    args = ap.parse_args()
    cache = Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    t_start, load_start = time.perf_counter(), os.getloadavg()

    speed_rows, acc_rows = [], []
    if not args.no_speed:
        clouds = []
        fit = dict(direction=view_direction(), fov=40.0, aspect=1.0)
        for n in (int(x) for x in args.torus.split(",") if x):
            cloud = load_torus(n, cache)
            clouds.append((f"torus {n // 1000}k", cloud, Camera.fit(cloud.bounds, **fit)))
        if not args.no_tree:
            tree = aniso3d.build_texture(scenes.tree(), 128, 64).to_points()
            clouds.append(("tree", tree, Camera.frame(tree.bounds)))
        speed_rows = speed(args, clouds)
    if args.accuracy:
        acc_rows = accuracy(args, cache)
    load_end = os.getloadavg()

    import moderngl  # noqa: PLC0415  (for the GL renderer string only)

    ctx = moderngl.create_context(standalone=True, backend="egl")
    gl_name = ctx.info["GL_RENDERER"]
    ctx.release()
    library = Path(aniso3d.__file__).resolve().parents[1]
    head = (f"Run {time.strftime('%Y-%m-%d %H:%M')} in {(time.perf_counter() - t_start) / 60:.1f} min on "
            f"{gl_name}, {platform.machine()}, {os.cpu_count()} CPUs (library: `{library.name}`); "
            f"load average (1 min) {load_start[0]:.1f} at the start and {load_end[0]:.1f} at the end.")  # fmt: skip
    lines = [head, ""]
    if speed_rows:
        lines += [f"Frame time at {args.size}x{args.size}, ms: median (fastest-slowest) of {args.frames} frames "
                  f"after a warm-up, fast and high alternating; CPU: median process CPU time.", "",
                  "| cloud | points | fast ms | high ms | fast CPU | high CPU | high / fast | high / fast (CPU) "
                  "| load |", "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
        for row in speed_rows:
            f, h = row["fast"], row["high"]
            lines.append(f"| {row['cloud']} | {row['points']:,} | {f['median']:.0f} ({f['min']:.0f}-{f['max']:.0f}) "
                         f"| {h['median']:.0f} ({h['min']:.0f}-{h['max']:.0f}) | {f['cpu']:.0f} | {h['cpu']:.0f} "
                         f"| {row['ratio']:.2f} | {h['cpu'] / f['cpu']:.2f} "
                         f"| {row['load'][0]:.1f}-{row['load'][1]:.1f} |")  # fmt: skip
        lines.append("")
    if acc_rows:
        lines += [f"Accuracy of splats high (discs) at {args.accuracy_size}x{args.accuracy_size} against "
                  "8x8 polygons inside the object's box:", "",
                  "| scene | camera | voxel px | PSNR dB | FLIP |", "|---|---|---|---|---|"]  # fmt: skip
        for row in acc_rows:
            lines.append(f"| {row['scene']} | {row['camera']} | {row['voxel_px']:.2f} | {row['psnr']:.2f} "
                         f"| {row['flip']:.4f} |")  # fmt: skip
        lines.append("")
    if args.compare:
        lines += compare_tables(json.loads(Path(args.compare).read_text()), speed_rows, acc_rows)
    block = "\n".join(lines)
    print(block)
    if args.json:
        Path(args.json).write_text(json.dumps({"speed": speed_rows, "accuracy": acc_rows, "head": head}, indent=1))
    if args.md:
        md = Path(args.md)
        text = md.read_text() if md.exists() else ""
        begin, end = f"<!-- {args.marker}:begin -->", f"<!-- {args.marker}:end -->"
        new = f"{begin}\n{block}\n{end}"
        if begin in text and end in text:
            text = text[: text.index(begin)] + new + text[text.index(end) + len(end):]
        else:
            text = text + ("\n" if text else "") + new + "\n"
        md.write_text(text)


if __name__ == "__main__":
    main()
