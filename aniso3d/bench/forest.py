"""The forest bench: frame time of a forest against its number of trees, per
method, and the error of splats and volume against 8x8-supersampled polygons
(``aniso3d bench forest``; docs/forest.md).

Each forest (``aniso3d.scenes.forest(n)``, ground side 8 sqrt(n) m) is seen
from the same direction by a camera framing it, so every forest covers about
the same screen area: many small far trees against a few large near ones.
Methods are interleaved per repetition; the median and the spread (min-max)
of the frames are reported with the load average. "volume" draws the
instances by instanced calls per (asset, level) group and depth slab,
"volume passes" one ray-marching pass per instance as first written
(``aniso3d.rendering.scene_draw.VOLUME_INSTANCED``; ``no_passes`` leaves it out).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aniso3d.bench.run import CODE_PATHS, code_version
from aniso3d.build.scenes import forest
from aniso3d.errors import InputError, ResourceError
from aniso3d.files import atomic_write
from aniso3d.metrics import compare
from aniso3d.rendering.quick import framing_camera
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


@dataclass(frozen=True)
class ForestSettings:
    """What :func:`run_forest` measures: square image sizes in pixels."""

    size: int = 512
    reps: int = 3
    error_size: int = 256
    counts: tuple[int, ...] = COUNTS
    no_passes: bool = False
    backend: str = "auto"


def run_forest(args: ForestSettings, progress=None) -> tuple[list[dict], list[dict], list[float]]:
    """Frame-time rows, error rows and the load averages (1 min) seen during the run."""
    if args.reps < 1 or args.size < 1 or args.error_size < 1 or not args.counts or min(args.counts) < 1:
        raise InputError("the forest bench needs positive sizes, repetitions and tree counts")
    size = (args.size, args.size)
    rows = []
    load = [os.getloadavg()[0]]
    with Renderer(size, cache_entries=64, backend=args.backend) as r:
        for k, n in enumerate(args.counts):
            if progress:
                progress(k / len(args.counts), f"{n} trees")
            scene = forest(n, seed=1)
            cam = framing_camera(scene, size, direction=VIEW)
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
        errors = []
        esize = (args.error_size, args.error_size)
        for n in [c for c in args.counts if c <= ERROR_MAX]:
            scene = forest(n, seed=1)
            cam = framing_camera(scene, esize, direction=VIEW)
            truth = r.render(scene, cam, "mesh", ssaa=8, size=esize)
            vols = [("volume", None)] + ([] if args.no_passes else [("volume passes", None)])
            for m, q in (("splat", "fast"), ("splat", "high"), *vols):
                opts = {"quality": q} if q else {}
                img = draw(r, scene, cam, m, size=esize, resolution=RESOLUTION, **opts)
                e = compare(truth, img)
                name = f"{m} {q}" if q else m
                errors.append({"n": n, "method": name, **{k: float(v) for k, v in e.items() if np.isfinite(v)}})
    if progress:
        progress(1.0, "done")
    return rows, errors, load


def check_output(out: Path):
    """Refuse, before a long run, an output that is a file and a missing
    matplotlib; returns the matplotlib module."""
    if out.exists() and not out.is_dir():
        raise InputError(f"output '{out}' is a file; the forest bench writes forest.md and forest.png into a folder")
    try:
        import matplotlib
    except ImportError:
        raise ResourceError("the forest plot needs matplotlib: pip install 'aniso3d[plots]'") from None
    return matplotlib


def write_report(rows, errors, load, args: ForestSettings, out: Path, command: str) -> Path:
    """forest.md and forest.png (matplotlib, the ``plots`` extra) into ``out``, atomically; the page's path."""
    code = _code()  # before this writes its own files into a checkout
    matplotlib = check_output(out)
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
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / "forest.png", lambda fh: fig.savefig(fh, dpi=100, format="png"))
    plt.close(fig)
    t = {(r["n"], r["method"]): r for r in rows}
    lines = [
        "# A forest of instances: frame time against the number of trees",
        "",
        f"`{command}` on llvmpipe, {time.strftime('%Y-%m-%d %H:%M')}, code at {code}. "
        f"Load average (1 min) during the run: "
        f"{min(load):.1f}-{max(load):.1f}.",
        "",
        f"`forest(n)`: n trees of 3 kinds (5,000-20,000 triangles each) on a ground of side "
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
    keys = list(dict.fromkeys(k for e in errors for k in e if k not in ("n", "method")))
    if errors:
        lines += [
            "",
            f"## Error against 8x8 supersampled polygons ({args.error_size}x{args.error_size})",
            "",
            "| trees | method | " + " | ".join(keys) + " |",
            "| ---: | --- |" + " ---: |" * len(keys),
        ]
    for e in errors:
        lines.append(f"| {e['n']} | {e['method']} | " + " | ".join(
            f"{e[k]:.3g}" if k in e else "-" for k in keys) + " |")  # fmt: skip
    lines += ["", "![frame time against trees](forest.png)", ""]
    return atomic_write(out / "forest.md", "\n".join(lines).encode())


def _code() -> str:
    code = code_version(CODE_PATHS)
    if not code["commit"]:
        return "an unknown commit"
    return f"commit {code['commit'][:10]}" + (" with uncommitted changes" if code["dirty"] else "")


