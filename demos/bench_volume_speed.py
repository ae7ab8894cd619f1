"""Frame time of the volume renderer against 1-spp polygons: the first
marching ("plain"), the "skip" marching as it was ("before": its modes read
as uniforms, every pixel's ray from the grid's box) and as it is ("skip":
the modes compiled in, only the pixels of the occupied bricks' screen box,
the start pass where it pays), per scene and bench distance;
and the accuracy of both at the corpus cameras.

The default tree at --size (1024) and every corpus scene at --corpus-size
(256: a 1024^2 sweep of nine scenes does not fit the time we have), each at
the bench's cameras (aniso3d.bench.cameras.make_cameras with the "full"
preset's footprints, the default texture: 128^3, K = 16). Per camera the
four cases are timed interleaved (polygons, plain, before, skip, polygons, ...)
over --frames frames: median and spread (min-max) of Renderer.last_frame_seconds
(draw + read back), and the load average before and after. Accuracy: PSNR
of each volume case against 8x8 polygons (aniso3d.metrics.compare_in_box in
the bench's crop box); and, per corpus scene at the corpus cameras
(aniso3d.bench.corpus.corpus_cameras at 512^2, resolution 128), PSNR and FLIP
of "before" and "skip" against 8x8 polygons. Writes Markdown tables.

    .venv/bin/python demos/bench_volume_speed.py [--out docs/volume_speed.md]
        [--size 1024] [--corpus-size 256] [--frames 5] [--scenes tree,bush]
        [--no-accuracy]
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import aniso3d
from aniso3d.bench.cameras import make_cameras
from aniso3d.bench.corpus import corpus_cameras
from aniso3d.bench.run import code_version
from aniso3d.bench.settings import PRESETS
from aniso3d.files import atomic_write
from aniso3d.metrics import compare_in_box
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.volume import START_PIXELS

#: The volume cases: marching, whether the modes are compiled in
#: (VolumeRenderer.compile_modes), and where rays start (VolumeOptions.start).
VOLUME_CASES = {
    "plain": ("plain", False, "frame"), "before": ("skip", False, "frame"), "skip": ("skip", True, "bricks"),
}  # fmt: skip


def render_case(r: Renderer, thing, cam, case: str):
    """One frame of a case: "mesh" or one of :data:`VOLUME_CASES`."""
    if case == "mesh":
        return r.render(thing, cam, "mesh")
    march, compiled, start = VOLUME_CASES[case]
    r.method_renderer("volume").compile_modes = compiled
    try:
        return r.render(thing, cam, "volume", march=march, start=start)
    finally:
        r.method_renderer("volume").compile_modes = True


def time_interleaved(r: Renderer, cases: dict, cam, frames: int) -> tuple[dict, dict]:
    """Seconds per frame of each case (name -> thing), one frame of each in
    turn, after one warm-up frame each: wall (draw + read back) and process
    CPU time (every llvmpipe thread; steadier on a shared machine)."""
    for name, thing in cases.items():
        render_case(r, thing, cam, name)
    times: dict[str, list[float]] = {name: [] for name in cases}
    cpu: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(frames):
        for name, thing in cases.items():
            c0 = time.process_time()
            render_case(r, thing, cam, name)
            cpu[name].append(time.process_time() - c0)
            times[name].append(r.last_frame_seconds)
    return times, cpu


def bench_scene(name: str, size: int, frames: int) -> list[dict]:
    mesh = aniso3d.scenes.get_scene(name)
    tex = aniso3d.build_texture(mesh)
    settings = replace(PRESETS["full"], size=(size, size))
    rows = []
    with Renderer((size, size)) as r:
        for spec in make_cameras(mesh.bounds, settings):
            cam = spec.camera
            cases = {"mesh": mesh, **{m: tex for m in VOLUME_CASES}}
            t, cpu = time_interleaved(r, cases, cam, frames)
            truth = r.render(mesh, cam, "mesh", ssaa=8)
            psnr = {
                m: compare_in_box(truth, render_case(r, tex, cam, m), spec.crop, with_flip=False)["psnr"]
                for m in VOLUME_CASES
            }
            row = {"scene": name, "size": size, "camera": spec.label, "psnr": psnr}
            row["cpu"] = {m: 1000 * float(np.median(v)) for m, v in cpu.items()}
            for m, v in t.items():
                row[m] = (1000 * float(np.median(v)), 1000 * float(np.min(v)), 1000 * float(np.max(v)))
            rows.append(row)
            print(_line(row), flush=True)
    return rows


def accuracy_scene(name: str) -> list[str]:
    """Rows of PSNR / FLIP against 8x8 polygons of "before" and "skip" at the
    corpus cameras of scene ``name`` (512^2, resolution 128)."""
    mesh = aniso3d.scenes.get_scene(name)
    tex = aniso3d.build_texture(mesh)
    size = (512, 512)
    lines = []
    with Renderer(size) as r:
        for spec in corpus_cameras(mesh, size, 128):
            truth = r.render(mesh, spec.camera, "mesh", ssaa=8)
            got = {m: compare_in_box(truth, render_case(r, tex, spec.camera, m), spec.crop, with_flip=True)
                   for m in ("before", "skip")}  # fmt: skip
            u, k = got["before"], got["skip"]
            lines.append(
                f"| {name} | {spec.label} | {u['psnr']:.3f} | {k['psnr']:.3f} | {k['psnr'] - u['psnr']:+.3f} "
                f"| {u['flip']:.4f} | {k['flip']:.4f} |"
            )
            print(lines[-1], flush=True)
    return lines


def _ms(v: tuple[float, float, float]) -> str:
    return f"{v[0]:.0f} ({v[1]:.0f}-{v[2]:.0f})"


def _line(row: dict) -> str:
    m, p, u, s = row["mesh"], row["plain"], row["before"], row["skip"]
    ps = row["psnr"]
    return (
        f"| {row['scene']} | {row['size']} | {row['camera']} | {_ms(m)} | {_ms(p)} | {p[0] / m[0]:.1f} "
        f"| {_ms(u)} | {u[0] / m[0]:.1f} | {_ms(s)} | {s[0] / m[0]:.1f} | {s[0] / u[0]:.2f} "
        f"| {row['cpu']['before']:.0f} | {row['cpu']['skip']:.0f} | {row['cpu']['skip'] / row['cpu']['before']:.3f} "
        f"| {ps['plain']:.2f} | {ps['before']:.2f} | {ps['skip']:.2f} | {ps['skip'] - ps['before']:+.3f} |"
    )


HEADER = (
    "| scene | px | camera | polygons 1-spp ms | plain ms | plain / poly | before ms | before / poly "
    "| skip ms | skip / poly | skip / before | CPU before ms | CPU skip ms | CPU skip / before "
    "| PSNR plain | PSNR before | PSNR skip | dPSNR |"
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("docs/volume_speed.md"))
    ap.add_argument("--size", type=int, default=1024, help="image side of the tree, pixels")
    ap.add_argument("--corpus-size", type=int, default=256, help="image side of the other corpus scenes")
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--scenes", default=",".join(aniso3d.scenes.CORPUS))
    ap.add_argument("--no-accuracy", action="store_true", help="skip the corpus cameras' accuracy table")
    args = ap.parse_args()
    ver = code_version(("aniso3d", "shaders", "demos"))
    commit = f"commit {(ver['commit'] or 'unknown')[:7]}" + (" (with uncommitted code)" if ver["dirty"] else "")
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    print(HEADER)
    rows = []
    for name in args.scenes.split(","):
        rows += bench_scene(name, args.size if name == "tree" else args.corpus_size, args.frames)
    load1 = os.getloadavg()
    seconds = time.perf_counter() - t0
    acc: list[str] = []
    if not args.no_accuracy:
        for name in args.scenes.split(","):
            acc += accuracy_scene(name)
    head = [
        "# Volume renderer: frame time against 1-spp polygons",
        "",
        "Written by `demos/bench_volume_speed.py` "
        f"(`--size {args.size} --corpus-size {args.corpus_size} --frames {args.frames}`) on {commit}, "
        f"{seconds:.0f} s for the timings, on llvmpipe (LP_NUM_THREADS default, 2 cores shared with "
        f"other jobs). Load average (1, 5, 15 min) before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}, "
        f"after {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}.",
        "",
        'Default texture (128^3, K = 16), default options (opacity "planar"). Per camera of the bench '
        '(`fill`, then a baseline voxel of 2 ... 0.25 px), polygons, "plain" (the first marching: '
        'storage buffers, compositing inside the two-level DDA, T_MIN 0.001, every pixel), "before" (the '
        '"skip" marching as it was: the density, normal and opacity modes read as uniforms, every '
        'pixel\'s ray from the grid\'s box) and "skip" (now the default: the modes compiled in, only '
        "the pixels of the occupied bricks' screen box, rays from the first occupied brick where a "
        f"voxel spans {START_PIXELS:g} px or more) are timed interleaved: "
        "median (min-max) of draw + read back, ms, and the median process CPU time (ms, every "
        "llvmpipe thread: steadier than wall time on a shared machine). PSNR against 8x8 polygons "
        "in the bench's crop box "
        f"(`compare_in_box`). The tree at {args.size}^2, the other corpus scenes at {args.corpus_size}^2.",
        "",
        HEADER,
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        *[_line(row) for row in rows],
    ]
    if acc:
        head += [
            "",
            "## Accuracy at the corpus cameras",
            "",
            "`corpus_cameras(mesh, (512, 512), 128)`, default texture and options, against "
            '`Renderer.render(mesh, cam, "mesh", ssaa=8)` in the crop box (`compare_in_box`, FLIP '
            "lower is better).",
            "",
            "| scene | camera | PSNR before | PSNR skip | dPSNR | FLIP before | FLIP skip |",
            "|---|---|---|---|---|---|---|",
            *acc,
        ]
    # What people wrote after the tables (from its first "## Findings" on) is kept.
    kept = ""
    if Path(args.out).exists():
        old = Path(args.out).read_text()
        at = old.find("\n## Findings")
        kept = old[at:] if at >= 0 else ""
    atomic_write(args.out, ("\n".join(head) + "\n" + kept).encode())
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
