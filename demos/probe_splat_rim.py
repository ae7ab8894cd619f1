"""Why a closed surface's rim leaked in quality "high": the NumPy twin's
surfaces on the corpus blob's own fragments (docs/splat_aa.md, "A closed
surface's rim").

The blob's texture points (128^3, K = 16) are drawn by the twin from the
corpus bench's minified camera moved back until every splat is sub-pixel
(the twin draws those only). For the pixels inside the polygons' outline
whose alpha falls below 0.98, and for the rest, it prints how many surfaces
the pixel holds, the spread of its fragments' depth slices against the span,
and its coverage sum (a one-sided splat counting twice), first with the
span alone (``AA_SURFACE_REACH = 0``), then with the default reach.

    .venv/bin/python demos/probe_splat_rim.py [--scene blob] [--back 1.35]
"""

from __future__ import annotations

import argparse

import numpy as np

from aniso3d.bench.corpus import corpus_cameras
from aniso3d.bench.settings import BASELINE
from aniso3d.build import scenes
from aniso3d.build.texture import build_texture
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.lighting import Lighting
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.splat import params
from aniso3d.rendering.splat import reference as twin
from aniso3d.rendering.splat.options import SplatOptions

SIZE = (512, 512)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="blob")
    ap.add_argument("--back", type=float, default=1.35, help="the minified camera's distance times this")
    args = ap.parse_args()

    mesh = scenes.get_scene(args.scene)
    pts = build_texture(mesh, 128, 16, bounds=mesh.bounds).to_points(
        BASELINE["placement"], BASELINE["per_entry"], BASELINE["point_normal"]
    )
    c0 = corpus_cameras(mesh, SIZE, 128)[1].camera
    target = np.asarray(c0.target)
    cam = Camera(tuple(target + args.back * (np.asarray(c0.position) - target)), c0.target, c0.up, c0.fov)
    view = FrameView(cam, Lighting(), SIZE, *cam.clip_range(pts.bounds))
    with Renderer(SIZE) as r:
        inside = r.render(mesh, cam, "mesh", ssaa=8, alpha=True)[..., 3] > 254
    opts = SplatOptions(splat=BASELINE["splat"], quality="high")
    saved = params.AA_SURFACE_REACH
    try:
        for reach in (0.0, saved):
            params.AA_SURFACE_REACH = reach
            frags = twin.subpixel_fragments_np(pts, view, opts)
            _, alpha = twin.composite_np(frags)
            span = frags.slicing[2]
            n = SIZE[0] * SIZE[1]
            keep, s, _, count = twin.fragment_surfaces(frags)
            count = count.reshape(SIZE[1], SIZE[0])
            lo_s, hi_s = np.full(n, np.inf), np.full(n, -np.inf)
            np.minimum.at(lo_s, frags.pixel[keep], s)
            np.maximum.at(hi_s, frags.pixel[keep], s)
            spread = (hi_s - lo_s).reshape(SIZE[1], SIZE[0])
            counted = frags.coverage * (1.0 if frags.counts is None else frags.counts)
            cover = np.bincount(frags.pixel, counted, n).reshape(SIZE[1], SIZE[0])
            leak = inside & (alpha < 0.98)
            print(f"reach {reach:g} px: span {span:.2f} slices; {int(inside.sum())} pixels inside the outline, "
                  f"{int(leak.sum())} below alpha 0.98")  # fmt: skip
            for name, m in (("leaking", leak), ("the rest", inside & ~leak)):
                if not m.any():
                    continue
                hist = np.bincount(np.minimum(count[m], 6), minlength=7)[1:]
                print(f"  {name}: surfaces 1..6+ {hist.tolist()}; slice spread median {np.median(spread[m]):.1f}, "
                      f"90th percentile {np.percentile(spread[m], 90):.1f}; coverage sum median "
                      f"{np.median(cover[m]):.2f}")  # fmt: skip
    finally:
        params.AA_SURFACE_REACH = saved


if __name__ == "__main__":
    main()
