"""How much of its own pixel a surface must cover before quality "high"
splats may take it for whole (render/splat/params.py ``AA_CLOSE_OWN``), swept.

Per scene (corpus names, or mesh files), at the corpus bench's two cameras,
the high-quality splats' PSNR (dB) / FLIP inside the object's box against
the polygons at 8 x 8 samples, beside the polygons at 1 and 2 x 2 samples,
for each floor of ``--values``, with the pixels that differ from the first
value's image and the *dark* pixels (some channel more than 80 levels below
the truth's: a speck taken for the pixel's surface paints it its own colour).
The splats are the corpus bench's (``texture_points``, disc splats); each
value is drawn by a renderer made while it is set (it is compiled into the
compositing pass).

    .venv/bin/python demos/sweep_close_own.py [SCENE | MESH FILE ...] [--values 0 0.1 0.25] [--md docs/splat_aa.md]
"""

from __future__ import annotations

import numpy as np

from aniso3d.bench.outputs import markdown_table
from aniso3d.bench.variants import (
    command,
    corpus_parser,
    pair,
    publish,
    run_corpus_demo,
    scene_cameras,
    scene_or_mesh,
    scored,
)
from aniso3d.build import scenes
from aniso3d.build.texture import build_texture
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.splat import params
from aniso3d.rendering.splat.clips import texture_points

#: A pixel is dark where some channel lies more than this many levels below the truth's.
DARK = 80


def cell(row: dict, value: float) -> str:
    """PSNR / FLIP, changed pixels (against the first value) and dark pixels."""
    return f"{pair(row[value])}, {row[f'{value} changed']} ch, {row[f'{value} dark']} dark"


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh, label = scene_or_mesh(name)
    points = texture_points(build_texture(mesh, args.resolution, args.directions))
    keep = params.AA_CLOSE_OWN
    rows = []
    for spec, truth, row in scene_cameras(renderer, mesh, label, args):
        first = None
        for value in args.values:
            params.AA_CLOSE_OWN = value
            try:
                with Renderer((args.size, args.size)) as own:
                    img = own.render(points, spec.camera, "splat", quality="high", splat="disc")
            finally:
                params.AA_CLOSE_OWN = keep
            x0, y0, x1, y1 = spec.crop
            box, tbox = img[y0:y1, x0:x1].astype(np.int64), truth[y0:y1, x0:x1].astype(np.int64)
            first = box if first is None else first
            row[value] = scored(truth, img, spec)
            row[f"{value} changed"] = int((np.abs(box - first).max(axis=-1) > 0).sum())
            row[f"{value} dark"] = int(((tbox - box).max(axis=-1) > DARK).sum())
        print(f"  {spec.label}: " + ", ".join(f"{v}: {cell(row, v)}" for v in args.values), flush=True)
        rows.append(row)
    return rows


def main() -> None:
    ap = corpus_parser(__doc__.splitlines()[0], scenes.CORPUS)
    ap.add_argument("--values", type=float, nargs="+", default=[0.0, 0.1, 0.25])
    args = ap.parse_args()
    run = run_corpus_demo(args, run_scene)
    head = ["scene", "camera", "1 spp", "2x2", *(f"high, {v}" for v in args.values)]
    table = [[r["scene"], r["camera"], pair(r["1 spp"]), pair(r["2x2"]), *(cell(r, v) for v in args.values)]
             for r in run.rows]  # fmt: skip
    extra = ["--values", *(str(v) for v in args.values)]
    parts = [
        f"{run.header(command('demos/sweep_close_own.py', args, *extra))} Texture {args.resolution}^3, "
        f"K = {args.directions}, the corpus bench's points, disc splats, quality \"high\"; truth "
        f"{args.gt_ssaa}x{args.gt_ssaa} polygons; PSNR (dB) / FLIP inside the object's box, as the corpus bench; "
        f"AA_CLOSE_OWN per column (default {params.AA_CLOSE_OWN}); ch: pixels of the box that differ from the "
        f"first column's; dark: pixels of the box with a channel more than {DARK} levels below the truth's.",
        "",
        markdown_table(head, table),
    ]
    publish(parts, args.md, "<!-- sweep_close_own: begin -->", "<!-- sweep_close_own: end -->", "Splat AA")


if __name__ == "__main__":
    main()
