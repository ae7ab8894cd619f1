"""Frame time of a forest against its number of trees, per method, and the
error of splats and volume against 8x8-supersampled polygons.

Each forest (``aniso3d.scenes.forest(n)``, ground side 8 sqrt(n) m) is seen
from the same direction by a camera framing it, so every forest covers about
the same screen area: many small far trees against a few large near ones.
Methods are interleaved per repetition; the median and the spread (min-max)
of the frames are reported with the load average. "volume" draws the
instances by instanced calls per (asset, level) group and depth slab,
"volume passes" one ray-marching pass per instance as first written
(``aniso3d.rendering.scene_draw.VOLUME_INSTANCED``; ``--no-passes`` leaves it
out). Writes docs/forest.md and docs/forest.png.

    ./.venv/bin/python demos/bench_forest.py [--size 512] [--reps 3] [--counts 100 10000]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

import aniso3d
from aniso3d.metrics import compare
from aniso3d.rendering.renderer import Renderer

VIEW = (0.5, 0.9, 1.0)
RESOLUTION = 64
COUNTS = (1, 10, 100, 1000, 10000)
#: Most trees drawn as polygons (each about 5,000-20,000 triangles).
POLYGON_MAX = 1000
#: Most trees the error is measured for (8x8 polygons).
ERROR_MAX = 100


def draw(r: Renderer, scene, cam, method: str, **opts):
    """``r.render`` of ``method``, "volume passes" being the volume without instancing."""
    from aniso3d.rendering import scene_draw

    scene_draw.VOLUME_INSTANCED = method != "volume passes"
    try:
        return r.render(scene, cam, method.split()[0], **opts)
    finally:
        scene_draw.VOLUME_INSTANCED = True


def frame(r: Renderer, scene, cam, method: str) -> tuple[float, dict]:
    opts = {} if method == "mesh" else {"resolution": RESOLUTION}
    draw(r, scene, cam, method, **opts)
    return r.last_frame_seconds, dict(r.last_lod_stats or {})


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--error-size", type=int, default=256)
    ap.add_argument("--out", default="docs")
    ap.add_argument("--counts", type=int, nargs="+", default=list(COUNTS))
    ap.add_argument("--no-passes", action="store_true", help="leave out the volume drawn one pass per instance")
    args = ap.parse_args()
    size = (args.size, args.size)
    rows = []
    load = [os.getloadavg()[0]]
    with Renderer(size, cache_entries=64) as r:
        for n in args.counts:
            scene = aniso3d.scenes.forest(n, seed=1)
            cam = aniso3d.framing_camera(scene, size, direction=VIEW)
            passes = [] if args.no_passes else ["volume passes"]
            methods = ["splat", "volume", *passes] + (["mesh"] if n <= POLYGON_MAX else [])
            for m in methods:  # warm-up: conversions, uploads, programs
                frame(r, scene, cam, m)
            times = {m: [] for m in methods}
            info = {}
            for _ in range(args.reps):
                for m in methods:
                    t, stats = frame(r, scene, cam, m)
                    times[m].append(t)
                    info[m] = stats
            load.append(os.getloadavg()[0])
            for m in methods:
                t = np.array(times[m]) * 1000
                st = info[m]
                rows.append({
                    "n": n, "method": m, "median_ms": float(np.median(t)), "min_ms": float(t.min()),
                    "max_ms": float(t.max()), "visible": st.get("visible"), "points": st.get("points"),
                    "levels": st.get("instances_per_level"), "selection_ms": st.get("selection_ms"),
                    "calls": st.get("draw_calls"),
                })  # fmt: skip
                print(rows[-1], flush=True)
        errors = []
        esize = (args.error_size, args.error_size)
        for n in [c for c in args.counts if c <= ERROR_MAX]:
            scene = aniso3d.scenes.forest(n, seed=1)
            cam = aniso3d.framing_camera(scene, esize, direction=VIEW)
            truth = r.render(scene, cam, "mesh", ssaa=8, size=esize)
            vols = [("volume", None)] + ([] if args.no_passes else [("volume passes", None)])
            for m, q in (("splat", "fast"), ("splat", "high"), *vols):
                opts = {"quality": q} if q else {}
                img = draw(r, scene, cam, m, size=esize, resolution=RESOLUTION, **opts)
                e = compare(truth, img)
                name = f"{m} {q}" if q else m
                errors.append({"n": n, "method": name, **{k: float(v) for k, v in e.items() if np.isfinite(v)}})
                print(errors[-1], flush=True)
            if n == ERROR_MAX:
                from aniso3d.rendering.images import save_png

                save_png("/tmp/forest_truth.png", truth)
    write(rows, errors, load, args, Path(args.out))


def write(rows, errors, load, args, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for m in ("mesh", "splat", "volume", "volume passes"):
        pts = [(r["n"], r["median_ms"], r["min_ms"], r["max_ms"]) for r in rows if r["method"] == m]
        if pts:
            n, med, lo, hi = map(np.array, zip(*pts, strict=True))
            ax.errorbar(n, med, yerr=[med - lo, hi - med], marker="o", label=m, capsize=3)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("trees (instances)")
    ax.set_ylabel(f"frame time, ms ({args.size}x{args.size})")
    ax.set_title("forest: frame time against trees, same screen area")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "forest.png", dpi=100)
    t = {(r["n"], r["method"]): r for r in rows}
    lines = [
        "# A forest of instances: frame time against the number of trees",
        "",
        f"`demos/bench_forest.py --size {args.size} --reps {args.reps}` on llvmpipe (2 cores shared with other "
        f"work), {time.strftime('%Y-%m-%d %H:%M')}. Load average (1 min) during the run: "
        f"{min(load):.1f}-{max(load):.1f}.",
        "",
        f"`aniso3d.scenes.forest(n)`: n trees of 3 kinds (5,000-20,000 triangles each) on a ground of side "
        f"8 sqrt(n) m, framed from the same direction, so every forest fills about the same screen area. Splats "
        f"and volume convert each tree kind once at resolution {RESOLUTION} and draw every instance from the "
        "pyramid level chosen for it (pixel_error 1). Frame time is `Renderer.last_frame_seconds`: "
        "selection, draw and read-back; median of the repetitions, (min-max). Splats: quality \"fast\", "
        "each instance's level also limited to one point per pixel of its projected bounding sphere "
        "(`aniso3d.rendering.instances.POINTS_PER_PIXEL`).",
        "",
        "| trees | method | frame ms | visible | points drawn | draw calls | instances per level (0 = finest) |",
        "| ---: | --- | ---: | ---: | ---: | ---: | --- |",
    ]
    for r in rows:
        lines.append(
            f"| {r['n']} | {r['method']} | {r['median_ms']:.0f} ({r['min_ms']:.0f}-{r['max_ms']:.0f}) | "
            f"{r['visible']} | {r['points'] if r['points'] is not None else '-'} | "
            f"{r['calls'] if r['calls'] is not None else '-'} | {r['levels']} |"
        )
    lines += ["", "Target: 10,000 trees at most 3x the time of 100 trees on the same screen area.", ""]
    for m in ("splat", "volume", "volume passes"):
        a, b = t.get((100, m)), t.get((10000, m))
        if a and b:
            lines.append(f"- {m}: 100 trees {a['median_ms']:.0f} ms, 10,000 trees {b['median_ms']:.0f} ms: "
                         f"ratio {b['median_ms'] / a['median_ms']:.1f}.")  # fmt: skip
    lines += [
        "",
        f"## Error against 8x8 supersampled polygons ({args.error_size}x{args.error_size})",
        "",
        "| trees | method | " + " | ".join(k for k in errors[0] if k not in ("n", "method")) + " |",
        "| ---: | --- |" + " ---: |" * (len(errors[0]) - 2),
    ]
    for e in errors:
        lines.append(f"| {e['n']} | {e['method']} | " + " | ".join(
            f"{v:.3g}" for k, v in e.items() if k not in ("n", "method")) + " |")  # fmt: skip
    lines += ["", "![frame time against trees](forest.png)", ""]
    (out / "forest.md").write_text("\n".join(lines))


if __name__ == "__main__":
    main()
