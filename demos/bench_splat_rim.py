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

import argparse

from aniso3d import metrics
from aniso3d.bench.corpus import corpus_cameras
from aniso3d.bench.outputs import markdown_table, write_between_markers
from aniso3d.bench.run import run_scenes
from aniso3d.bench.settings import BASELINE
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
        for spec in corpus_cameras(mesh, (args.size, args.size), args.resolution):
            truth = renderer.render(mesh, spec.camera, "mesh", ssaa=args.gt_ssaa)
            row = {"scene": name, "camera": spec.label, "closed": closed}
            for label, ssaa in (("1 spp", 1), ("2x2", 2)):
                img = renderer.render(mesh, spec.camera, "mesh", ssaa=ssaa)
                m = metrics.compare_in_box(truth, img, spec.crop, with_flip=True)
                row[label] = (m["psnr"], m["flip"])
            for label, (reach, closure) in VARIANTS.items():
                params.AA_SURFACE_REACH = saved[0] if reach is None else reach
                params.AA_CLOSE_SIDED = saved[1] if closure is None else closure
                img = renderer.render(points, spec.camera, "splat", splat=BASELINE["splat"], quality="high")
                m = metrics.compare_in_box(truth, img, spec.crop, with_flip=True)
                row[label] = (m["psnr"], m["flip"])
            rows.append(row)
            print(f"  {spec.label}: " + ", ".join(f"{k} {v[0]:.2f}/{v[1]:.4f}" for k, v in row.items()
                                                  if isinstance(v, tuple)), flush=True)  # fmt: skip
    finally:
        params.AA_SURFACE_REACH, params.AA_CLOSE_SIDED = saved
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=[*scenes.CORPUS, "cube", "sphere"])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--gt-ssaa", type=int, default=8)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=16)
    ap.add_argument("--md", default="", help="Markdown file to write the table into (between its markers)")
    args = ap.parse_args()

    run = run_scenes(args.scenes, args.size, lambda name, renderer: run_scene(name, args, renderer))
    columns = ["1 spp", "2x2", *VARIANTS]
    table = []
    for r in run.rows:
        new, old = r["all"], r["before"]
        beats = new[0] >= r["2x2"][0] and new[1] <= r["2x2"][1]
        table.append([r["scene"], r["camera"], f"{100 * r['closed']:.0f} %",
                      *(f"{r[c][0]:.2f} / {r[c][1]:.4f}" for c in columns),
                      f"{new[0] - old[0]:+.2f}", f"{new[1] - old[1]:+.4f}", "yes" if beats else "no"])  # fmt: skip
    parts = [
        BEGIN,
        run.header(f"demos/bench_splat_rim.py {' '.join(args.scenes)} --size {args.size}") + " "
        f"Texture {args.resolution}^3, K = {args.directions}, the corpus bench's points and {BASELINE['splat']} "
        f"splats, quality \"high\"; truth {args.gt_ssaa}x{args.gt_ssaa} polygons; PSNR (dB) / FLIP inside the "
        "object's box, as the corpus bench. One-sided: the share of points on closed surfaces. before: the "
        "nearest surface's span alone and the closure of AA_CLOSE (0.9) everywhere; reach: a reach of 1 pixel; "
        f"all: the defaults (reach {params.AA_SURFACE_REACH:g}, closure {params.AA_CLOSE_SIDED:g} where a pixel "
        "holds one-sided splats); closure 0.7, reach 2: one value changed from the defaults. Δ: all - before. "
        "≥ 2x2: all at least as good as 2x2 polygons in PSNR and FLIP.",
        "",
        markdown_table(["scene", "camera", "one-sided", *columns, "Δ PSNR", "Δ FLIP", "≥ 2x2"], table),
        END,
    ]
    block = "\n".join(parts)
    print("\n" + block)
    if args.md:
        path = write_between_markers(args.md, block, BEGIN, END, title="# Anti-aliased splats\n\n")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
