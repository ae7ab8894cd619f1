"""What other bits cost the images through a file, per camera: scene by scene.

For each scene (built at 128^3, K = 16): PSNR of the texture as built
against the polygons (8x8 samples per pixel) at each camera of
``demos/bench_encoding.py`` (its direction, at the distance scales
``--scales``), then, for the default :class:`~aniso3d.build.encoding.Bits`
and for each ``--variants`` entry (``field=N,field=N``), the file's bytes
and the change of PSNR of the texture as a compact file stores it
(``as_stored``), per camera and as their mean (what bench_encoding
reports). ``--splat`` adds the high-quality splats.

    .venv/bin/python demos/sweep_encoding_bits.py blob sphere \\
        --variants depth=10,coherence=6 depth=10 coherence=6
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_encoding as be  # noqa: E402

from aniso3d.build.encoding import DEFAULT_BITS  # noqa: E402
from aniso3d.build.texture import build_texture  # noqa: E402
from aniso3d.build.texture_file import encoded_size  # noqa: E402
from aniso3d.metrics import psnr  # noqa: E402
from aniso3d.rendering.camera import Camera  # noqa: E402
from aniso3d.rendering.context import GLContext  # noqa: E402
from aniso3d.rendering.renderer import Renderer  # noqa: E402


def parse_bits(text: str):
    if text == "default":
        return DEFAULT_BITS
    return replace(DEFAULT_BITS, **{k: int(v) for k, v in (p.split("=") for p in text.split(","))})


def score(r: Renderer, thing, cams, truths, renders) -> dict[str, list[float]]:
    """PSNR of ``thing`` per renderer and camera, inside each truth's box."""
    return {method: [psnr(t[ys, xs], r.render(thing, cam, method, **opts)[ys, xs])
                     for cam, (t, (ys, xs)) in zip(cams, truths, strict=True)]
            for method, opts in renders}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--variants", nargs="*", default=[], help="bits to try, e.g. depth=10,coherence=6")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--scales", type=float, nargs="+", default=[1.0, 2.3])
    ap.add_argument("--splat", action="store_true", help="also the high-quality splats")
    args = ap.parse_args()
    renders = be.RENDERS if args.splat else be.RENDERS[:1]
    print(f"load average at the start: {' '.join(f'{x:.1f}' for x in os.getloadavg())}; "
          f"default bits {DEFAULT_BITS}")  # fmt: skip
    with GLContext("auto") as gl:
        for name in args.scenes:
            mesh = be.get_mesh(name)
            if mesh is None:
                print(f"{name}: not a scene here; skipped")
                continue
            tex = build_texture(mesh, 128, 16)
            cams = [Camera.fit(mesh.bounds, direction=be.direction(), aspect=1.0, distance_scale=s)
                    for s in args.scales]  # fmt: skip
            r = Renderer((args.size, args.size), gl=gl)
            try:
                truths = []
                for cam in cams:
                    gt = r.render(mesh, cam, "mesh", ssaa=8, alpha=True)
                    truths.append((gt[..., :3], be.crop(gt[..., 3])))

                base = score(r, tex, cams, truths, renders)
                print(f"{name} built " + " ".join(f"{m} {' '.join(f'{v:.3f}' for v in vals)}"
                                                  for m, vals in base.items()), flush=True)  # fmt: skip
                for text in ["default", *args.variants]:
                    bits = parse_bits(text)
                    size = encoded_size(tex._arrays(), tex.voxel_size, tex.meta, "compact", bits)
                    got = score(r, tex.as_stored(bits), cams, truths, renders)
                    parts = []
                    for m, vals in got.items():
                        d = [g - b for g, b in zip(vals, base[m], strict=True)]
                        parts.append(f"{m} " + " ".join(f"{x:+.3f}" for x in d) + f" mean {np.mean(d):+.3f}")
                    print(f"{name} {text} {size:,} B " + " | ".join(parts), flush=True)
            finally:
                r.release()


if __name__ == "__main__":
    main()
