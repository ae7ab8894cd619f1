"""Where a scene's error comes from, per pixel: its outline or its inside,
coverage or colour, for the polygons at 1 and 2 x 2 samples, the volume and
quality "high" splats (the points the renderer draws, ``texture_points``), at
the corpus bench's two cameras.

Against the polygons at 8 x 8 samples (inside the object's box, as the corpus
bench measures), per renderer:

- PSNR (dB) and FLIP of the RGB image;
- ``band``: the share of the squared RGB error on the outline band (the
  pixels the truth covers in part, dilated by one pixel), ``inside`` on
  pixels the truth covers whole outside the band;
- ``PSNR band ok`` / ``inside ok``: the PSNR with the band's (inside's)
  error taken away: what a perfect outline (inside) would reach;
- ``alpha err``: mean |alpha - truth alpha| over the band;
- ``colour``: the share of the band's error left when each pixel's alpha
  is set to the truth's (its colour over the background kept): the rest is
  coverage.

With ``--halfplanes off`` the volume draws no half-planes
(aniso3d/rendering/sheet_halfplanes.py).

    .venv/bin/python demos/probe_outline_errors.py [SCENE ...] [--size 512] [--halfplanes on|off]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy import ndimage

from aniso3d import metrics
from aniso3d.bench.corpus import corpus_cameras
from aniso3d.bench.settings import BASELINE
from aniso3d.build import scenes
from aniso3d.build.mesh import load_mesh
from aniso3d.build.texture import build_texture
from aniso3d.rendering import sheet_halfplanes
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.splat.clips import texture_points


def split(truth: np.ndarray, img: np.ndarray, background: np.ndarray) -> dict:
    t, v = truth.astype(np.float64), img.astype(np.float64)
    ta, va = t[..., 3] / 255.0, v[..., 3] / 255.0
    band = ndimage.binary_dilation((ta > 0.02) & (ta < 0.98), iterations=1)
    inside = (ta >= 0.98) & ~band
    se = ((v[..., :3] - t[..., :3]) ** 2).sum(-1)
    total = max(float(se.sum()), 1e-9)
    n = se.size

    def psnr(s: float) -> float:
        return float(10 * np.log10(255.0**2 * 3 * n / max(s, 1e-9)))

    with np.errstate(divide="ignore", invalid="ignore"):
        surface = (v[..., :3] - (1 - va[..., None]) * background) / va[..., None]
    fixed = np.where(va[..., None] > 0.05, surface * ta[..., None] + (1 - ta[..., None]) * background, t[..., :3])
    se_col = ((fixed - t[..., :3]) ** 2).sum(-1)
    m = metrics.compare(truth[..., :3], img[..., :3], with_flip=True)
    return {"psnr": m["psnr"], "flip": m["flip"], "band": se[band].sum() / total, "inside": se[inside].sum() / total,
            "band_ok": psnr(total - se[band].sum()), "inside_ok": psnr(total - se[inside].sum()),
            "alpha_err": float(np.abs(va - ta)[band].mean()) if band.any() else 0.0,
            "colour": float(se_col[band].sum() / max(se[band].sum(), 1e-9))}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=["shell"])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=16)
    ap.add_argument("--halfplanes", choices=("on", "off"), default="on")
    args = ap.parse_args()
    if args.halfplanes == "off":
        sheet_halfplanes.HALF_TOLERANCE = -1.0
    size = (args.size, args.size)
    with GLContext("auto") as gl, Renderer(size, gl=gl) as r:
        bg = 255.0 * np.asarray(r.lighting.background, dtype=np.float64)
        for name in args.scenes:
            mesh = load_mesh(name) if Path(name).suffix else scenes.get_scene(name)
            tex = build_texture(mesh, args.resolution, args.directions)
            points = texture_points(tex, BASELINE["placement"], BASELINE["per_entry"], BASELINE["point_normal"])
            for spec in corpus_cameras(mesh, size, args.resolution):
                x0, y0, x1, y1 = spec.crop
                imgs = {
                    "truth": r.render(mesh, spec.camera, "mesh", ssaa=8, alpha=True),
                    "1-spp": r.render(mesh, spec.camera, "mesh", ssaa=1, alpha=True),
                    "2x2": r.render(mesh, spec.camera, "mesh", ssaa=2, alpha=True),
                    "volume": r.render(tex, spec.camera, "volume", alpha=True),
                    "splat high": r.render(points, spec.camera, "splat", splat=BASELINE["splat"], quality="high",
                                           alpha=True),  # fmt: skip
                }
                crop = {k: v[y0:y1, x0:x1] for k, v in imgs.items()}
                print(f"{name} {spec.label} (voxel {spec.voxel_px:.2f} px, half-planes {args.halfplanes}):")
                print("  renderer     PSNR   FLIP    band inside  PSNR band ok  inside ok  alpha err  colour")
                for k in ("1-spp", "2x2", "volume", "splat high"):
                    s = split(crop["truth"], crop[k], bg)
                    print(f"  {k:10s} {s['psnr']:6.2f} {s['flip']:.4f}  {s['band']:5.2f} {s['inside']:5.2f}  "
                          f"{s['band_ok']:12.2f} {s['inside_ok']:10.2f} {s['alpha_err']:10.3f} "
                          f"{s['colour']:7.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
