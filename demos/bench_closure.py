"""Which faces a texture takes as a closed skin, and what that does to the
volume and quality "high" splats, on the corpus and on mesh files.

The built-in scenes are clean: their closed skins are watertight, their
corners shared exactly. Meshes made by other tools are not: an exporter
writes one corner with float noise, a sphere's poles as slivers with two
corners at the pole, a model drawn double-sided carries every face twice
(once each way), a scanned or modelled head has a few holes. Read strictly
(corners matched exactly, watertight skins only, every face counted), such
a mesh has no closed face: its thin parts are covered front and back, its
splats are two-sided, and a face drawn twice is counted twice. Variants
(``aniso3d.build.mesh``):

- ``before``: corners matched exactly (``MERGE_SHARE`` 0), watertight skins
  only (``HOLE_SHARE`` 0), repeated faces kept;
- ``corners``: corners matched within ``MERGE_SHARE`` of the extent, a
  face drawn twice counted once; still watertight skins only;
- ``all``: the defaults, skins with small holes closed too (``HOLE_SHARE``).

Degenerate faces are out of the topology in every variant. Per scene and
camera (the corpus bench's two): the share of faces taken as
closed, and PSNR (dB) / FLIP against 8x8 polygons in the object's box for
1-spp and 2x2 polygons, the volume and the high splats of each variant.
The images are deterministic: no spread to report.

    .venv/bin/python demos/bench_closure.py [tree bush ... | mesh files] [--size 512] [--md docs/coverage.md]
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import aniso3d.build.mesh as mesh_module
import aniso3d.build.mesh_stream as mesh_stream
from aniso3d.bench.outputs import markdown_table
from aniso3d.bench.settings import BASELINE
from aniso3d.bench.variants import (
    command,
    corpus_parser,
    pair,
    print_scores,
    publish,
    run_corpus_demo,
    scene_cameras,
    scored,
)
from aniso3d.build import scenes
from aniso3d.build.mesh import load_mesh
from aniso3d.build.texture import build_texture
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.splat.clips import texture_points

BEGIN = "<!-- bench_closure: begin -->"
END = "<!-- bench_closure: end -->"
#: variant: (MERGE_SHARE, HOLE_SHARE, repeated faces left out); None: the default.
VARIANTS = {"before": (0.0, 0.0, False), "corners": (None, 0.0, True), "all": (None, None, True)}


def set_variant(name: str, defaults: tuple[float, float]):
    merge, hole, drop = VARIANTS[name]
    mesh_module.MERGE_SHARE = defaults[0] if merge is None else merge
    mesh_module.HOLE_SHARE = defaults[1] if hole is None else hole

    def topology(v, f):
        sides, repeat = mesh_module.face_topology(v, f)
        return sides, repeat if drop else np.zeros_like(repeat)

    mesh_stream.face_topology = topology


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh = load_mesh(name) if Path(name).suffix else scenes.get_scene(name)
    label = Path(name).name if Path(name).suffix else name
    defaults = mesh_module.MERGE_SHARE, mesh_module.HOLE_SHARE
    original = mesh_stream.face_topology
    made = {}
    try:
        for v in VARIANTS:
            set_variant(v, defaults)
            closed = float(np.mean(mesh_module.closed_sides(mesh.vertices, mesh.faces) != 0))
            tex = build_texture(mesh, args.resolution, args.directions)
            made[v] = (closed, tex, texture_points(tex, BASELINE["placement"], BASELINE["per_entry"],
                                                   BASELINE["point_normal"]))  # fmt: skip
    finally:
        mesh_module.MERGE_SHARE, mesh_module.HOLE_SHARE = defaults
        mesh_stream.face_topology = original
    rows = []
    for spec, truth, row in scene_cameras(renderer, mesh, label, args):
        for v, (closed, tex, points) in made.items():
            row[f"closed {v}"] = closed
            row[f"volume {v}"] = scored(truth, renderer.render(tex, spec.camera, "volume"), spec)
            img = renderer.render(points, spec.camera, "splat", splat=BASELINE["splat"], quality="high")
            row[f"splat {v}"] = scored(truth, img, spec)
        rows.append(row)
        print_scores(spec.label, row)
    return rows


def main() -> None:
    args = corpus_parser(__doc__.splitlines()[0], scenes.CORPUS).parse_args()
    run = run_corpus_demo(args, run_scene)
    columns = ["1 spp", "2x2", *(f"{m} {v}" for m in ("volume", "splat") for v in VARIANTS)]
    table = [[r["scene"], r["camera"], " / ".join(f"{100 * r[f'closed {v}']:.0f}" for v in VARIANTS),
              *(pair(r[c]) for c in columns)] for r in run.rows]  # fmt: skip
    publish([
        run.header(command("demos/bench_closure.py", args)) + " "
        f"Texture {args.resolution}^3, K = {args.directions}, the corpus bench's points and {BASELINE['splat']} "
        f"splats, quality \"high\"; truth {args.gt_ssaa}x{args.gt_ssaa} polygons; PSNR (dB) / FLIP inside the "
        "object's box, as the corpus bench. closed %: the share of faces taken as a closed skin in each variant "
        "(before / corners / all). before: corners matched exactly, watertight skins only, faces drawn twice "
        f"counted twice; corners: corners matched within {mesh_module.MERGE_SHARE:.3g} of the extent, "
        "a face drawn twice counted once; all: the defaults, skins with "
        f"small holes closed too (HOLE_SHARE {mesh_module.HOLE_SHARE:g}). Degenerate faces are out of the "
        "topology in every variant.",
        "",
        markdown_table(["scene", "camera", "closed %", *columns], table),
    ], args.md, BEGIN, END, title="# Coverage\n\n")  # fmt: skip


if __name__ == "__main__":
    main()
