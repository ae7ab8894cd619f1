"""Frame times of the splat renderer against a GL_POINTS floor, in one run.

The default tree (``aniso3d.scenes.tree()``) -> ``build_texture(mesh, 128, 64)``
-> ``to_points()``, drawn at 1024x1024 from ``Camera.frame(bounds)``: each
shape in fast and high quality, and the floor (the same points as plain
GL_POINTS covering the same on-screen boxes, flat colour). A frame is: bind,
clear, draw, read the pixels back (the read waits for the rasteriser), so
the times are what a caller of ``Renderer.render`` pays. Medians of
``--frames`` frames after one warm-up, the configurations interleaved; wall
time and the process's CPU time (all threads), the steadier of the two when
other work shares the machine.

    .venv/bin/python demos/bench_splat.py [--size 1024] [--frames 5] [--out /tmp/bench_splat]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import aniso3d
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.images import save_png
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.splat import SHAPES


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--out", default="", help="folder to save the images to (optional)")
    args = ap.parse_args()

    t0 = time.perf_counter()
    mesh = aniso3d.scenes.tree()
    points = aniso3d.build_texture(mesh, args.resolution, 64).to_points()
    sec = time.perf_counter() - t0
    print(f"tree: {mesh.n_faces} triangles -> {len(points)} points in {sec:.1f} s")

    size = (args.size, args.size)
    with Renderer(size, backend="egl") as r:
        print(f"OpenGL: {r.gl.renderer} ({r.gl.version})")
        cam = Camera.frame(points.bounds)
        handle = r.upload(points, "splat")
        splat = r.method_renderer("splat")
        near, far = cam.clip_range(handle.bounds)
        view = FrameView(cam, r.lighting, size, near, far)
        ctx = r.gl.ctx
        color = r.gl.track(ctx.texture(size, 4, dtype="f1"))
        depth = r.gl.track(ctx.depth_texture(size))
        fbo = r.gl.track(ctx.framebuffer(color_attachments=[color], depth_attachment=depth))
        bg = r.lighting.background

        def frame(draw, **opts) -> tuple[float, float, np.ndarray]:
            t, cpu = time.perf_counter(), time.process_time()
            fbo.use()
            fbo.clear(bg[0], bg[1], bg[2], 0.0, depth=1.0)
            draw(handle, view, fbo=fbo, **opts)
            raw = fbo.read(components=4)
            sec, cpu = time.perf_counter() - t, time.process_time() - cpu
            return sec, cpu, np.frombuffer(raw, np.uint8).reshape(size[1], size[0], 4)[::-1]

        configs = [("GL_POINTS floor", "-", splat.draw_floor, {})] + [
            (shape, quality, splat.draw, {"splat": shape, "quality": quality})
            for shape in SHAPES
            for quality in ("fast", "high")
        ]
        # Rounds interleave the configurations, so a machine whose load drifts
        # (shared CPUs) biases none of them; the first round is a warm-up.
        times: dict[int, list[float]] = {i: [] for i in range(len(configs))}
        cpus: dict[int, list[float]] = {i: [] for i in range(len(configs))}
        images = {}
        names = ["floor"] + [f"{shape}_{quality}" for shape, quality, _, _ in configs[1:]]
        for rnd in range(args.frames + 1):
            for i, (_, _, draw, opts) in enumerate(configs):
                sec, cpu, images[names[i]] = frame(draw, **opts)
                if rnd:
                    times[i].append(sec)
                    cpus[i].append(cpu)
        rows = [(shape, quality, float(np.median(times[i])), float(np.median(cpus[i])),
                 (images[names[i]][..., 3] > 0).mean())
                for i, (shape, quality, _, _) in enumerate(configs)]  # fmt: skip
        ref = r.render(mesh, cam, "mesh", alpha=True)
        mesh_sec = r.time_frames(mesh, cam, "mesh", frames=args.frames)
        images["mesh"] = ref

    print(f"\n{args.size}x{args.size}, {len(points)} points, "
          f"median of {args.frames} frames (draw + read back)")  # fmt: skip
    print("wall: elapsed time; cpu: CPU time of all the process's threads (steadier when the")
    print("machine is shared). 'x floor' divides by the GL_POINTS floor's time of the same kind.")
    head = ("splat", "quality", "wall ms", "x floor", "cpu ms", "x floor", "coverage")
    print("{:<16} {:<8} {:>8} {:>8} {:>8} {:>8} {:>9}".format(*head))
    floor, floor_cpu = rows[0][2], rows[0][3]
    for shape, quality, sec, cpu, cov in rows:
        print(f"{shape:<16} {quality:<8} {sec * 1e3:8.1f} {sec / floor:8.2f} {cpu * 1e3:8.1f} "
              f"{cpu / floor_cpu:8.2f} {cov:9.3f}")  # fmt: skip
    print(f"{'polygon mesh':<16} {'ssaa 1':<8} {mesh_sec * 1e3:8.1f} {mesh_sec / floor:8.2f} "
          f"{'':>8} {'':>8} {(ref[..., 3] > 0).mean():9.3f}")  # fmt: skip
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        for name, img in images.items():
            save_png(out / f"tree_{name}.png", np.ascontiguousarray(img[..., :3]))
        print(f"images in {out}")


if __name__ == "__main__":
    main()
