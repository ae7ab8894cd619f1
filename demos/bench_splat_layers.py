"""What the last layer's weights, the least surface span and one-sided points
do to quality "high" splats, on the corpus at the corpus bench's two cameras.

Quality "high" keeps the first ``AA_LAYERS - 1`` surfaces of a pixel in one
layer each and every surface from there on in the last. Two rules are
measured, each on and off (``aniso3d.rendering.splat.params``):

- ``AA_LAST_WEIGHTS``: the last layer weighs each surface's colour by what
  the surfaces in front of it leave, ``(1 - a_s)^j`` (off: an equal-weight
  mean, which gave the deepest surfaces of dense foliage as much weight as
  the front one);
- ``AA_SPAN_MIN``: the least span of a surface, 2 slices (off: 1, where a
  sheet whose fragments' depths straddle a slice boundary split in two
  surfaces that composed as independent layers);
- one-sided points (``PointCloud.one_sided``): points of closed surfaces
  face out and are culled where they face away, keeping their whole area
  (off: every point two-sided, its area times its entry's cover, as before).

Per scene and camera: PSNR (dB) / FLIP against 8x8 polygons in the object's
box, as the corpus bench measures, for 1-spp and 2x2 polygons and the
variants (``before``: all off; one rule on each; ``all``: the defaults). The images are
deterministic: no spread to report.

    .venv/bin/python demos/bench_splat_layers.py [tree bush ...] [--size 512] [--md docs/splat_aa.md]
"""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np

from aniso3d import PointCloud
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

BEGIN = "<!-- bench_splat_layers: begin -->"
END = "<!-- bench_splat_layers: end -->"
#: variant: (AA_LAST_WEIGHTS, AA_SPAN_MIN, one-sided points)
VARIANTS = {"before": (False, 1.0, False), "weights": (True, 1.0, False), "span": (False, 2.0, False),
            "one-sided": (False, 1.0, True), "all": (True, 2.0, True)}  # fmt: skip


@contextmanager
def variant(name: str):
    saved = params.AA_LAST_WEIGHTS, params.AA_SPAN_MIN
    params.AA_LAST_WEIGHTS, params.AA_SPAN_MIN, _ = VARIANTS[name]
    try:
        yield
    finally:
        params.AA_LAST_WEIGHTS, params.AA_SPAN_MIN = saved


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh = scenes.get_scene(name)
    tex = build_texture(mesh, args.resolution, args.directions)
    points = tex.to_points(BASELINE["placement"], BASELINE["per_entry"], BASELINE["point_normal"])
    # Every point two-sided, its area times its entry's cover (one point an entry).
    one = np.zeros(len(points), bool) if points.one_sided is None else points.one_sided
    cover = np.asarray(tex.entry_cover, dtype=np.float64)
    two = PointCloud(points.positions, points.normals, points.areas * np.where(one, cover, 1.0), points.kd,
                     points.ks, points.shininess, coherence=points.coherence)  # fmt: skip
    rows = []
    for spec, truth, row in scene_cameras(renderer, mesh, name, args):
        for v in VARIANTS:
            with variant(v):
                cloud = points if VARIANTS[v][2] else two
                img = renderer.render(cloud, spec.camera, "splat", splat=BASELINE["splat"], quality="high")
            row[v] = scored(truth, img, spec)
        rows.append(row)
        print_scores(spec.label, row)
    return rows


def main() -> None:
    args = corpus_parser(__doc__.splitlines()[0], scenes.CORPUS).parse_args()
    run = run_corpus_demo(args, run_scene)
    columns = ["1 spp", "2x2", *VARIANTS]
    table = [[r["scene"], r["camera"], *(pair(r[c]) for c in columns), *delta(r["all"], r["before"]),
              as_good(r["all"], r["2x2"])] for r in run.rows]  # fmt: skip
    publish([
        run.header(command("demos/bench_splat_layers.py", args)) + " "
        f"Texture {args.resolution}^3, K = {args.directions}, the corpus bench's points and {BASELINE['splat']} "
        "splats, quality \"high\"; truth "
        f"{args.gt_ssaa}x{args.gt_ssaa} polygons; PSNR (dB) / FLIP inside the object's box, as the corpus bench. "
        "before: an equal-weight last layer, a least span of 1 slice, every point two-sided; weights, span, "
        "one-sided: one rule each; all: the defaults. Δ: all - before. ≥ 2x2: all at least as good as 2x2 "
        "polygons in PSNR and FLIP.",
        "",
        markdown_table(["scene", "camera", *columns, "Δ PSNR", "Δ FLIP", "≥ 2x2"], table),
    ], args.md, BEGIN, END, title="# Anti-aliased splats\n\n")  # fmt: skip


if __name__ == "__main__":
    main()
