"""Why strips are not drawn with a voxel about a pixel: the volume's
coverage of a scene with strips off, and on from every scale
(``STRIP_PIXELS`` 0) over several shares of the pixel's footprint
(``STRIP_FOOT``), at one of the corpus bench's cameras.

Per case: PSNR (dB) / FLIP of the RGB image inside the object's box
against 8 x 8 polygons, the volume's alpha summed over the box over the
truth's, and the RMS alpha error. With a voxel a pixel the footprint's
ramps reach past the voxel, into cells the ray's centre crosses and that
hold nothing of the strip (no halos), so the strip loses what it should
give there: the alpha sum falls below the truth's, and the narrower the
footprint, the less is lost and the more the lines alias.

    .venv/bin/python demos/probe_strip_footprint.py [SCENE] [--camera minified]
        [--resolution 128] [--feet 1 0.75 0.5 0.25]
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
from bench_volume_strips import mode

from aniso3d import metrics
from aniso3d.bench.corpus import corpus_cameras
from aniso3d.bench.run import run_scenes
from aniso3d.build import scenes
from aniso3d.build.texture import build_texture
from aniso3d.rendering import volume
from aniso3d.rendering.renderer import Renderer


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?", default="lattice")
    ap.add_argument("--camera", default="minified", choices=("close", "minified"))
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--feet", type=float, nargs="+", default=[1.0, 0.75, 0.5, 0.25])
    args = ap.parse_args()
    size = (args.size, args.size)
    volume.STRIP_PIXELS = 0.0  # compiled into each renderer's shader when it is made
    mesh = scenes.get_scene(args.scene)
    spec = {s.label: s for s in corpus_cameras(mesh, size, args.resolution)}[args.camera]
    tex = build_texture(mesh, args.resolution, 16, bounds=mesh.bounds)
    x0, y0, x1, y1 = spec.crop

    def case(renderer: Renderer, name: str, on: bool, ref: np.ndarray) -> list:
        with mode("on" if on else "off"):
            img = renderer.render(dataclasses.replace(tex), spec.camera, "volume", alpha=True)[y0:y1, x0:x1]
        c = metrics.compare(ref[..., :3], img[..., :3], with_flip=True)
        a, at = img[..., 3] / 255.0, ref[..., 3] / 255.0
        row = [name, c["psnr"], c["flip"], a.sum() / at.sum(), float(np.sqrt(np.mean((a - at) ** 2)))]
        print(f"  {name}: PSNR {row[1]:.2f}, FLIP {row[2]:.4f}, alpha sum {row[3]:.3f}, alpha RMSE {row[4]:.4f}",
              flush=True)  # fmt: skip
        return row

    def run_scene(name: str, renderer: Renderer) -> list:
        ref = renderer.render(mesh, spec.camera, "mesh", ssaa=8, alpha=True)[y0:y1, x0:x1]
        rows = [case(renderer, "off", False, ref)]
        for foot in args.feet:
            volume.STRIP_FOOT = foot
            with Renderer(size, gl=renderer.gl) as r:  # a renderer compiles its shader with the constants
                rows.append(case(r, f"on, foot {foot:g}", True, ref))
        return rows

    run = run_scenes([args.scene], args.size, run_scene)
    feet = " ".join(f"{f:g}" for f in args.feet)
    print(run.header(f"demos/probe_strip_footprint.py {args.scene} --camera {args.camera} --feet {feet}"))


if __name__ == "__main__":
    main()
