"""Level of detail in the renderers: points drawn, frame time and error, LOD vs single level.

The default tree (``aniso3d.scenes.tree()``) -> ``build_texture(mesh, 128, 64)``
-> its exact pyramid (:mod:`aniso3d.build.pyramid`), drawn at 1024x1024 from
``Camera.fit(bounds, distance_scale=s)`` for s from next to the crown (0.25,
the eye just outside the tree's bounding box) to far away (32), four ways
with splats (single level / LOD, one point per entry / adaptive counts) and
two with the volume renderer (single level / LOD). Per camera and
configuration:

- points drawn (splats; the LOD selection's count) or the level drawn (volume);
- frame time: median of ``--frames`` frames after one warm-up, the
  configurations interleaved round by round, as ``Renderer.last_frame_seconds``
  (bind, clear, select, draw, read back) and the process's CPU time over all
  threads (steadier when other work shares the machine);
- selection ms (the voxel walk plus the index buffer);
- PSNR and SSIM against the polygons at 4x4 supersampling, inside the pixel box
  the tree's bounds project to plus 8 pixels (so a far camera is not scored on
  empty background), and PSNR over the whole image.

A second table weighs the two ways a splat renderer can draw a per-frame
subset: (A, used) every level uploaded once and the selection drawn through an
index buffer rewritten per frame; (B) the selected points gathered, packed
and uploaded into a reused, orphaned vertex buffer and attribute texture
every frame.

The tables go to stdout and, with ``--md``, between the markers
``<!-- bench_lod:begin -->`` and ``<!-- bench_lod:end -->`` of that Markdown
file (created if missing), so the prose around them is kept.

    .venv/bin/python demos/bench_lod.py [--size 1024] [--frames 3] [--md docs/lod.md]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

import aniso3d
from aniso3d.bench.outputs import markdown_table, write_between_markers
from aniso3d.build.pyramid import pyramid
from aniso3d.metrics import psnr, ssim
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.images import save_png
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.select import select_voxels, selection_points
from aniso3d.rendering.splat import ATTRIB_PER_ROW, FLOATS_PER_POINT

BEGIN, END = "<!-- bench_lod:begin -->", "<!-- bench_lod:end -->"
DISTANCES = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0)
SPLAT = "disc"  # the CLI's default shape

#: (name, method, options)
CONFIGS = (
    ("splat single", "splat", {}),
    ("splat LOD", "splat", {"lod": True}),
    ("splat single adaptive", "splat", {"per_entry": "adaptive"}),
    ("splat LOD adaptive", "splat", {"lod": True, "per_entry": "adaptive"}),
    ("volume single", "volume", {}),
    ("volume LOD", "volume", {"lod": True}),
)


def crop_box(cam: Camera, bounds: np.ndarray, size) -> tuple[slice, slice]:
    """Rows and columns of the pixel box ``bounds`` projects to, plus 8 px
    (the whole image when a corner is behind the eye)."""
    b = np.asarray(bounds)
    corners = np.array([[x, y, z] for x in b[:, 0] for y in b[:, 1] for z in b[:, 2]])
    if np.min((corners - np.asarray(cam.position)) @ cam.forward) <= 0:
        return slice(None), slice(None)
    px = cam.project(corners, size)
    x0, y0 = np.floor(px.min(axis=0)).astype(int) - 8
    x1, y1 = np.ceil(px.max(axis=0)).astype(int) + 8
    w, h = size
    return slice(max(y0, 0), min(y1, h)), slice(max(x0, 0), min(x1, w))


def gather_upload(ctx, pyr, cam, size, near, far, state: dict) -> tuple[float, int]:
    """Way (B): select, gather the points, pack them as the splat renderer
    does and write them into a reused (orphaned) vertex buffer and attribute
    texture. Returns (seconds, points)."""
    t = time.perf_counter()
    sel = select_voxels(pyr, cam, size, 1.0, near=near, far=far)
    pc = selection_points(pyr, sel)
    n = len(pc)
    data = np.empty((n, FLOATS_PER_POINT), np.float32)
    data[:, 0:3] = pc.positions - state["origin"]
    data[:, 3:6] = pc.normals
    data[:, 6] = np.sqrt(pc.areas)
    data[:, 7:10] = pc.kd
    data[:, 10] = pc.ks
    data[:, 11] = pc.shininess
    data[:, 12:] = 0.0  # no clip planes
    rows = max(-(-n // ATTRIB_PER_ROW), 1)
    attrib = np.zeros((rows * ATTRIB_PER_ROW, 8), np.float32)
    attrib[:n, 0:3] = data[:, 3:6]
    attrib[:n, 3] = data[:, 10]
    attrib[:n, 4:7] = data[:, 7:10]
    attrib[:n, 7] = data[:, 11]
    vbo, tex = state["vbo"], state["tex"]
    if data.nbytes > vbo.size:
        vbo.orphan(data.nbytes)
    else:
        vbo.orphan()
    vbo.write(data)
    tex.write(attrib, viewport=(0, 0, 2 * ATTRIB_PER_ROW, rows))
    ctx.finish()
    return time.perf_counter() - t, n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=64)
    ap.add_argument("--gt-ssaa", type=int, default=4)
    ap.add_argument("--distances", default=",".join(f"{d:g}" for d in DISTANCES))
    ap.add_argument("--no-volume", action="store_true", help="splats only (faster)")
    ap.add_argument("--md", default="", help="Markdown file to write the tables into")
    ap.add_argument("--images", default="", help="folder to save the images to (optional)")
    args = ap.parse_args()
    distances = [float(x) for x in args.distances.split(",")]
    configs = [c for c in CONFIGS if not (args.no_volume and c[1] == "volume")]
    size = (args.size, args.size)
    started = time.time()
    load0 = os.getloadavg()[0]

    t0 = time.perf_counter()
    mesh = aniso3d.scenes.tree()
    tex = aniso3d.build_texture(mesh, args.resolution, args.directions)
    build_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    pyr = pyramid(tex)
    pyr_s = time.perf_counter() - t0
    print(f"tree: {mesh.n_faces:,} triangles -> {args.resolution}^3, K={args.directions}: "
          f"{tex.n_voxels:,} voxels in {build_s:.1f} s; pyramid of {len(pyr)} levels "
          f"in {pyr_s:.2f} s")  # fmt: skip

    results: dict[tuple[float, str], dict] = {}
    design: list[list[str]] = []
    images: dict[str, np.ndarray] = {}
    with Renderer(size, backend="egl") as r:
        gl_name = r.gl.renderer
        print(f"OpenGL: {gl_name} ({r.gl.version}); {size[0]}x{size[1]}, splats: {SPLAT}")
        # Uploads and the pyramid's level clouds, timed once.
        cam0 = Camera.fit(mesh.bounds)
        upload_s = {}
        for name, method, opts in configs:
            extra = {"splat": SPLAT} if method == "splat" else {}
            t = time.perf_counter()
            r.render(tex, cam0, method, **extra, **opts)
            upload_s[name] = time.perf_counter() - t
        ctx = r.gl.ctx
        lod_handle = r.upload(tex, "splat", lod=True, per_entry=1)  # the cached upload
        splat_impl = r.method_renderer("splat")
        n0 = len(pyr.level_cloud(0)[0])
        n0_adaptive = len(pyr.level_cloud(0, per_entry="adaptive")[0])
        state = {
            "origin": lod_handle.origin,
            "vbo": r.gl.track(ctx.buffer(reserve=n0 * FLOATS_PER_POINT * 4)),
            "tex": r.gl.track(ctx.texture((2 * ATTRIB_PER_ROW, -(-n0 // ATTRIB_PER_ROW)), 4,
                                          dtype="f4")),  # fmt: skip
        }

        for d in distances:
            cam = Camera.fit(mesh.bounds, distance_scale=d)
            t = time.perf_counter()
            truth = r.render(mesh, cam, "mesh", ssaa=args.gt_ssaa)
            gt_s = time.perf_counter() - t
            rows_, cols_ = crop_box(cam, mesh.bounds, size)
            walls = {c[0]: [] for c in configs}
            cpus = {c[0]: [] for c in configs}
            sels = {c[0]: [] for c in configs}
            last = {}
            for rnd in range(args.frames + 1):  # round 0: warm-up
                for name, method, opts in configs:
                    extra = {"splat": SPLAT} if method == "splat" else {}
                    c = time.process_time()
                    img = r.render(tex, cam, method, **extra, **opts)
                    c = time.process_time() - c
                    if rnd:
                        walls[name].append(r.last_frame_seconds)
                        cpus[name].append(c)
                        if r.last_lod_stats:
                            sels[name].append(r.last_lod_stats["selection_ms"])
                    last[name] = (img, r.last_lod_stats)
            for name, method, _ in configs:
                img, st = last[name]
                if method == "splat":
                    drawn = st["points"] if st else n0 if "adaptive" not in name else n0_adaptive
                    what = f"{drawn:,}"
                    per_level = "0:all"
                    if st:
                        per_level = " ".join(
                            f"{i}:{n:,}" for i, n in enumerate(st["points_per_level"]) if n
                        )
                else:
                    what = f"level {st['level']}" if st else "level 0"
                    per_level = f"{st['pixels']:.2f} px" if st else ""
                    drawn = None
                results[(d, name)] = {
                    "drawn": drawn,
                    "what": what,
                    "levels": per_level,
                    "wall": 1e3 * float(np.median(walls[name])),
                    "cpu": 1e3 * float(np.median(cpus[name])),
                    "select": float(np.median(sels[name])) if sels[name] else None,
                    "psnr": psnr(truth[rows_, cols_], img[rows_, cols_]),
                    "ssim": ssim(truth[rows_, cols_], img[rows_, cols_]),
                    "psnr_full": psnr(truth, img),
                }
                images[f"d{d:g}_{name.replace(' ', '_')}"] = img
            images[f"d{d:g}_truth"] = truth

            # Ways A and B of drawing a per-frame subset, CPU side plus upload.
            near, far = cam.clip_range(lod_handle.bounds)
            view = FrameView(cam, r.lighting, size, near, far)
            a_t, b_t = [], []
            for _ in range(3):
                t = time.perf_counter()
                st = splat_impl.select(lod_handle, view, 1.0)
                ctx.finish()
                a_t.append(time.perf_counter() - t)
                sec, nb = gather_upload(ctx, pyr, cam, size, near, far, state)
                b_t.append(sec)
            design.append([f"{d:g}", f"{st['points']:,}", f"{1e3 * np.median(a_t):.1f}",
                           f"{1e3 * np.median(b_t):.1f}"])  # fmt: skip
            s_single, s_lod = results[(d, "splat single")], results[(d, "splat LOD")]
            print(f"x{d:g}: truth {gt_s:.1f} s; splats {s_single['what']} -> {s_lod['what']} "
                  f"points, {s_single['wall']:.0f} -> {s_lod['wall']:.0f} ms, PSNR "
                  f"{s_single['psnr']:.2f} -> {s_lod['psnr']:.2f} dB")  # fmt: skip

    load1 = os.getloadavg()[0]
    minutes = (time.time() - started) / 60

    def f1(x):
        return "–" if x is None else f"{x:.1f}"

    main_rows = []
    for d in distances:
        for name, _, _ in configs:
            if "adaptive" in name:
                continue
            res = results[(d, name)]
            main_rows.append([f"{d:g}", name, res["what"], res["levels"], f"{res['wall']:.0f}",
                              f"{res['cpu']:.0f}", f1(res["select"]), f"{res['psnr']:.2f}",
                              f"{res['ssim']:.4f}", f"{res['psnr_full']:.2f}"])  # fmt: skip
    adaptive_rows = []
    for d in distances:
        row = [f"{d:g}"]
        for name in ("splat single", "splat single adaptive", "splat LOD", "splat LOD adaptive"):
            res = results[(d, name)]
            row.append(f"{res['what']} / {res['psnr']:.2f} / {res['ssim']:.4f}")
        adaptive_rows.append(row)

    level_rows = [[str(s["level"]), f"{s['resolution']}", f"{s['voxel_size']:.3f}",
                   f"{s['voxels']:,}", f"{len(pyr.level_cloud(s['level'])[0]):,}",
                   f"{len(pyr.level_cloud(s['level'], per_entry='adaptive')[0]):,}",
                   f"{s['nbytes'] / 2**20:.1f}"]
                  for s in pyr.level_stats()]  # fmt: skip
    busy = (
        f"Load average {load0:.1f} at the start and {load1:.1f} at the end on "
        f"{os.cpu_count()} CPUs: wall times include contention from other work; "
        "the CPU column counts this process's work over all rasteriser threads."
    )
    parts = [
        BEGIN,
        f"Run {time.strftime('%Y-%m-%d %H:%M')} in {minutes:.1f} min on {gl_name}, "
        f"{platform.machine()}; `demos/bench_lod.py --size {args.size} --frames {args.frames}`. "
        f"Scene: the default tree, {mesh.n_faces:,} triangles, {args.resolution}^3 voxels, "
        f"K = {args.directions} (texture built in {build_s:.1f} s, pyramid in {pyr_s:.2f} s). "
        f"Images {size[0]}x{size[1]}, {SPLAT} splats, quality fast, pixel_error 1. {busy}",
        "",
        "**Pyramid levels** (points: one per entry / adaptive counts; MiB: the texture level "
        "in memory):",
        "",
        markdown_table(["level", "res", "voxel edge", "voxels", "points", "adaptive points", "MiB"],
                 level_rows),  # fmt: skip
        "",
        f"**Single level vs LOD** (camera `Camera.fit(bounds, distance_scale=s)`; frame ms: "
        f"median of {args.frames} after a warm-up, select + draw + read back; PSNR and SSIM "
        f"against the polygons at {args.gt_ssaa}x{args.gt_ssaa} samples per pixel inside the "
        "tree's projected box + 8 px; last column PSNR over the whole image; volume: the level "
        "drawn and one of its voxels in pixels at the nearest depth):",
        "",
        markdown_table(["s", "renderer", "points / level", "per level", "wall ms", "cpu ms",
                  "select ms", "PSNR dB", "SSIM", "PSNR full"], main_rows),  # fmt: skip
        "",
        "**Adaptive point counts vs one point per entry** (points / PSNR dB / SSIM, same box):",
        "",
        markdown_table(["s", "single, 1 per entry", "single, adaptive", "LOD, 1 per entry",
                  "LOD, adaptive"], adaptive_rows),  # fmt: skip
        "",
        "**Drawing a per-frame subset** (splats, one point per entry; median of 3; CPU work "
        "plus upload, finished): (A) every level uploaded once, select + index buffer; (B) "
        "select + gather + pack + upload into a reused, orphaned vertex buffer and attribute "
        "texture. One-time upload of all levels for (A): "
        f"{upload_s['splat LOD']:.2f} s (with building the level point sets), "
        f"single level {upload_s['splat single']:.2f} s (with `to_points`).",
        "",
        markdown_table(["s", "points drawn", "A: select + index ms", "B: gather + upload ms"], design),
        END,
    ]
    block = "\n".join(parts)
    print("\n" + block)
    if args.md:
        path = write_between_markers(args.md, block, BEGIN, END, title="# Level of detail\n\n")
        print(f"wrote {path}")
    if args.images:
        out = Path(args.images)
        out.mkdir(parents=True, exist_ok=True)
        for name, img in images.items():
            save_png(out / f"{name}.png", img)
        print(f"images in {out}")


if __name__ == "__main__":
    main()
