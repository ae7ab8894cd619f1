"""How wide a quantised texture's sheets must be: the volume's PSNR from the
texture as built and as its compact file stores it, per scene and per value
of ``aniso3d.rendering.volume.SHEET_QUANTISED_V3`` (the widening of a texture
of format version 3, what ``as_stored()`` gives; ``SHEET_QUANTISED``, for
version 2 files, was chosen with this script on version 2's encoding).

    .venv/bin/python demos/sweep_sheet_quantised.py [--scenes sphere shell ...] [--values 0.01 0.02 0.03]

Truth: polygons at 8 x 8 samples, 256 x 256, the framing camera; PSNR over
the whole image. Images are deterministic, so one run per value.
"""

from __future__ import annotations

import argparse
import os

from aniso3d.build import scenes
from aniso3d.build.texture import build_texture
from aniso3d.metrics import psnr
from aniso3d.rendering import volume
from aniso3d.rendering.quick import framing_camera
from aniso3d.rendering.renderer import Renderer

DEFAULT_SCENES = ("sphere", "shell", "blob", "mixed", "room", "tree", "bush", "grass", "lattice", "fur")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=list(DEFAULT_SCENES))
    ap.add_argument("--values", type=float, nargs="+", default=[0.0, 0.0025, 0.005, 0.01, 0.02])
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--size", type=int, default=256)
    args = ap.parse_args()
    print(f"load average at the start: {os.getloadavg()}")
    for name in args.scenes:
        mesh = getattr(scenes, name)()
        tex = build_texture(mesh, args.resolution, 16)
        stored = tex.as_stored()
        cam = framing_camera(mesh, (args.size, args.size))
        with Renderer((args.size, args.size)) as r:
            truth = r.render(mesh, cam, "mesh", ssaa=8)
        cells = []
        for value in args.values:
            volume.SHEET_QUANTISED_V3 = value
            with Renderer((args.size, args.size)) as r:  # a new renderer: the sheets are made at upload
                built, loaded = psnr(truth, r.render(tex, cam, "volume")), psnr(truth, r.render(stored, cam, "volume"))
            cells.append(f"{value:g}: built {built:.2f} file {loaded:.2f} ({loaded - built:+.2f})")
        print(f"{name}: " + " | ".join(cells), flush=True)
    print(f"load average at the end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
