"""What the nearest surface's reach (``AA_SURFACE_REACH``) and the closure of
closed surfaces (``AA_CLOSE_SIDED``) do to quality "high" splats, on the
corpus at the corpus bench's two cameras.

A pixel's fragments are grouped into surfaces by depth; the nearest surface
spans a fixed depth from its first slice. Near a closed surface's rim the
surface runs along the view rays, its splats' planes meet a pixel's ray at
scattered depths, and its fragments split into several surfaces that
composed as independent layers: the background showed through the rim of a
minified blob as a speckle. Where a pixel holds one-sided splats (a closed
surface seen from outside), the nearest surface now also reaches as far as
their depths change across ``AA_SURFACE_REACH`` pixels. Two-sided splats
(leaves, open sheets) keep the span alone, so scenes without closed surfaces
draw exactly as before. And a closed surface has no holes: where a pixel
holds one-sided splats its nearest surface is taken as whole when the mean
coverage over it and its four neighbours reaches ``AA_CLOSE_SIDED`` (else
``AA_CLOSE``'s 0.9), which closes the pinholes resolved discs of a curved
closed surface leave close up.

Per scene and camera: PSNR (dB) / FLIP against 8x8 polygons in the object's
box, as the corpus bench measures, for 1-spp and 2x2 polygons and the
variants (the points as the renderer makes them, with their clip planes):
``before``: reach 0 (the span alone), closure 0.9; ``reach``: reach 1,
closure 0.9; ``all``: the defaults; ``closure 0.7``, ``reach 2``: one value
changed from the defaults. The images are deterministic: no spread to
report.

    .venv/bin/python demos/bench_splat_rim.py [tree bush ...] [--size 512] [--md docs/splat_aa.md]
"""

from __future__ import annotations

from aniso3d.bench.outputs import markdown_table
from aniso3d.bench.settings import BASELINE
from aniso3d.bench.variants import (
    as_good,
    command,
    corpus_parser,
    delta,
    pair,
    print_scores,
    publish,
    run_corpus_demo,
    scene_cameras,
    scored,
)
from aniso3d.build import scenes
from aniso3d.build.texture import build_texture
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.splat import params
from aniso3d.rendering.splat.clips import texture_points

BEGIN = "<!-- bench_splat_rim: begin -->"
END = "<!-- bench_splat_rim: end -->"
#: Column: (AA_SURFACE_REACH in pixels, AA_CLOSE_SIDED); None: the default.
VARIANTS = {"before": (0.0, 0.9), "reach": (1.0, 0.9), "all": (None, None), "closure 0.7": (None, 0.7),
            "reach 2": (2.0, None)}  # fmt: skip


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh = scenes.get_scene(name)
    tex = build_texture(mesh, args.resolution, args.directions)
    points = texture_points(tex, BASELINE["placement"], BASELINE["per_entry"], BASELINE["point_normal"])
    closed = 0.0 if points.one_sided is None else float(points.one_sided.mean())
    rows = []
    saved = params.AA_SURFACE_REACH, params.AA_CLOSE_SIDED
    try:
        for spec, truth, row in scene_cameras(renderer, mesh, name, args):
            row["closed"] = closed
            for label, (reach, closure) in VARIANTS.items():
                params.AA_SURFACE_REACH = saved[0] if reach is None else reach
                params.AA_CLOSE_SIDED = saved[1] if closure is None else closure
                img = renderer.render(points, spec.camera, "splat", splat=BASELINE["splat"], quality="high")
                row[label] = scored(truth, img, spec)
            rows.append(row)
            print_scores(spec.label, row)
    finally:
        params.AA_SURFACE_REACH, params.AA_CLOSE_SIDED = saved
    return rows


def main() -> None:
    args = corpus_parser(__doc__.splitlines()[0], [*scenes.CORPUS, "cube", "sphere"]).parse_args()
    run = run_corpus_demo(args, run_scene)
    columns = ["1 spp", "2x2", *VARIANTS]
    table = [[r["scene"], r["camera"], f"{100 * r['closed']:.0f} %", *(pair(r[c]) for c in columns),
              *delta(r["all"], r["before"]), as_good(r["all"], r["2x2"])] for r in run.rows]  # fmt: skip
    publish([
        run.header(command("demos/bench_splat_rim.py", args)) + " "
        f"Texture {args.resolution}^3, K = {args.directions}, the corpus bench's points and {BASELINE['splat']} "
        f"splats, quality \"high\"; truth {args.gt_ssaa}x{args.gt_ssaa} polygons; PSNR (dB) / FLIP inside the "
        "object's box, as the corpus bench. One-sided: the share of points on closed surfaces. before: the "
        "nearest surface's span alone and the closure of AA_CLOSE (0.9) everywhere; reach: a reach of 1 pixel; "
        f"all: the defaults (reach {params.AA_SURFACE_REACH:g}, closure {params.AA_CLOSE_SIDED:g} where a pixel "
        "holds one-sided splats); closure 0.7, reach 2: one value changed from the defaults. Δ: all - before. "
        "≥ 2x2: all at least as good as 2x2 polygons in PSNR and FLIP.",
        "",
        markdown_table(["scene", "camera", "one-sided", *columns, "Δ PSNR", "Δ FLIP", "≥ 2x2"], table),
    ], args.md, BEGIN, END, title="# Anti-aliased splats\n\n")  # fmt: skip


if __name__ == "__main__":
    main()
