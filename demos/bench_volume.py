"""Frame time and GPU memory of the volume renderer (b) on the paper's object.

The default tree, its anisotropic texture at 128^3 with K = 64 directions,
drawn at 1024 x 1024 from the framing camera; the polygon renderer (a) is
timed on the same frame for scale. Not a test: it prints numbers.

    .venv/bin/python demos/bench_volume.py [--size 1024] [--resolution 128]
        [--directions 64] [--frames 5] [--texture cache.a3d]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import aniso3d
from aniso3d.build.texture import AnisoTexture
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.renderer import Renderer


def frame_times(r: Renderer, thing, cam: Camera, method: str, frames: int, **opts):
    """Median wall and process-CPU seconds per frame, after one warm-up frame."""
    r.render(thing, cam, method, **opts)
    wall, cpu = [], []
    for _ in range(frames):
        w0, c0 = time.perf_counter(), time.process_time()
        r.render(thing, cam, method, **opts)
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
    return float(np.median(wall)), float(np.median(cpu))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1024, help="image width and height, pixels")
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=64)
    ap.add_argument("--frames", type=int, default=5, help="timed frames (after one warm-up)")
    ap.add_argument(
        "--texture", type=Path, help="load this .a3d if it exists, else build and save it"
    )
    args = ap.parse_args()

    mesh = aniso3d.scenes.tree()
    t0 = time.perf_counter()
    if args.texture and args.texture.exists():
        tex = AnisoTexture.load(args.texture)
        how = f"loaded from {args.texture}"
    else:
        tex = aniso3d.build_texture(mesh, args.resolution, args.directions)
        how = "built"
        if args.texture:
            tex.save(args.texture)
    t_tex = time.perf_counter() - t0
    print(f"tree: {mesh.n_faces} triangles, {mesh.nbytes / 2**20:.1f} MiB as a mesh")
    print(
        f"texture: grid {tuple(int(s) for s in tex.shape)}, K = {tex.n_directions}, "
        f"{tex.n_voxels} voxels, {tex.n_entries} entries, "
        f"{tex.nbytes / 2**20:.1f} MiB in memory ({how} in {t_tex:.1f} s)"
    )

    size = (args.size, args.size)
    cam = Camera.frame(mesh.bounds)
    with Renderer(size) as r:
        print(f"OpenGL: {r.gl.renderer} ({r.gl.version})")
        t0 = time.perf_counter()
        handle = r.upload(tex, "volume")
        t_up = time.perf_counter() - t0
        parts = ", ".join(f"{k} {v / 2**20:.2f}" for k, v in handle.sizes.items())
        print(f"uploaded: {handle.nbytes / 2**20:.1f} MiB in {t_up:.2f} s ({parts} MiB)")
        print(
            "per frame (draw + read back), median: wall ms, and CPU ms of this process "
            "(llvmpipe's threads run in it, so CPU time hardly depends on other load)"
        )
        for label, method, opts in [
            ("volume, planar (default)", "volume", {}),
            ("volume, exponential", "volume", {"opacity": "exponential"}),
            ("volume, linear", "volume", {"opacity": "linear"}),
            ("volume, nearest-sample density", "volume", {"density": "nearest"}),
            ("polygons (a), 1 sample/pixel", "mesh", {}),
        ]:
            thing = tex if method == "volume" else mesh
            wall, cpu = frame_times(r, thing, cam, method, args.frames, **opts)
            print(f"  {label:32s} {size[0]}x{size[1]}: {wall * 1e3:8.1f} wall {cpu * 1e3:8.1f} CPU")
        img = r.render(tex, cam, "volume", alpha=True)
        covered = float(np.mean(img[..., 3] > 0))
        print(f"pixels touched by the tree: {covered:.1%}")


if __name__ == "__main__":
    main()
