"""Why an open sheet's folds leaked in quality "high": the NumPy twin's
surfaces on the corpus shell's own fragments (docs/splat_aa.md, "An open
sheet's folds").

The shell's texture points (128^3, K = 16, with their clip planes and sheet
flags, ``texture_points``) are drawn by the twin from the corpus bench's
minified camera moved back until every splat is sub-pixel (the twin draws
those only). For the pixels inside the polygons' outline whose alpha falls
below 0.98, and for the rest, it prints how many surfaces the pixel holds,
the spread of its fragments' depth slices against the span, its coverage
sum, and how much of that sum its nearest surface holds; first with no
sheet reaching (``AA_SHEET_REACH`` off), then with the defaults. Of the
pixels that still leak, those of one surface are short of coverage (the
splats' tiling); of the others, some hold a few fragments of tiny coverage
in front of the grazing sheet, which make the nearest surface (the share
below 0.05), and the grazing sheet behind, which does not reach, splits.

    .venv/bin/python demos/probe_splat_folds.py [--scene shell] [--back 1.35]
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
from aniso3d.rendering.splat.clips import texture_points
from aniso3d.rendering.splat.options import SplatOptions

SIZE = (512, 512)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="shell")
    ap.add_argument("--back", type=float, default=1.35, help="the minified camera's distance times this")
    args = ap.parse_args()

    mesh = scenes.get_scene(args.scene)
    pts = texture_points(build_texture(mesh, 128, 16, bounds=mesh.bounds), BASELINE["placement"],
                         BASELINE["per_entry"], BASELINE["point_normal"])  # fmt: skip
    share = 0.0 if pts.sheet is None else float(pts.sheet.mean())
    c0 = corpus_cameras(mesh, SIZE, 128)[1].camera
    target = np.asarray(c0.target)
    cam = Camera(tuple(target + args.back * (np.asarray(c0.position) - target)), c0.target, c0.up, c0.fov)
    view = FrameView(cam, Lighting(), SIZE, *cam.clip_range(pts.bounds))
    with Renderer(SIZE) as r:
        inside = r.render(mesh, cam, "mesh", ssaa=8, alpha=True)[..., 3] > 254
    opts = SplatOptions(splat=BASELINE["splat"], quality="high")
    n = SIZE[0] * SIZE[1]
    print(f"{args.scene}: {100 * share:.0f} % of {len(pts)} points on surface sheets")
    saved = params.AA_SHEET_REACH
    try:
        for on in (False, True):
            params.AA_SHEET_REACH = on
            frags = twin.subpixel_fragments_np(pts, view, opts)
            _, alpha = twin.composite_np(frags)
            span = frags.slicing[2]
            keep, s, starts, count = twin.fragment_surfaces(frags)
            count = count.reshape(SIZE[1], SIZE[0])
            px, c = frags.pixel[keep], frags.coverage[keep]
            lo_s, hi_s = np.full(n, np.inf), np.full(n, -np.inf)
            np.minimum.at(lo_s, px, s)
            np.maximum.at(hi_s, px, s)
            spread = (hi_s - lo_s).reshape(SIZE[1], SIZE[0])
            cover = np.bincount(px, c, n)
            nearest = np.bincount(px, c * (s < starts[px, 1]), n) if starts.shape[1] > 1 else cover
            front = (nearest / np.maximum(cover, 1e-12)).reshape(SIZE[1], SIZE[0])
            cover = cover.reshape(SIZE[1], SIZE[0])
            leak = inside & (alpha < 0.98)
            print(f"sheets reach {'on' if on else 'off'}: span {span:.2f} slices; {int(inside.sum())} pixels "
                  f"inside the outline, {int(leak.sum())} below alpha 0.98 (alpha there: mean "
                  f"{alpha[leak].mean() if leak.any() else 1.0:.3f})")  # fmt: skip
            for name, m in (("leaking", leak), ("the rest", inside & ~leak)):
                if not m.any():
                    continue
                hist = np.bincount(np.minimum(count[m], 6), minlength=7)[1:]
                print(f"  {name}: surfaces 1..6+ {hist.tolist()}; slice spread median {np.median(spread[m]):.1f}, "
                      f"90th percentile {np.percentile(spread[m], 90):.1f}; coverage sum median "
                      f"{np.median(cover[m]):.2f}; the nearest surface's share of it median "
                      f"{np.median(front[m]):.2f}, below 0.05 in {100 * np.mean(front[m] < 0.05):.0f} %")  # fmt: skip
    finally:
        params.AA_SHEET_REACH = saved


if __name__ == "__main__":
    main()
