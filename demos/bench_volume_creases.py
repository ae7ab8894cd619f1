"""The volume renderer's rules for closed solids' edges, each against
itself off. ``--rule crease`` (default): crease sheets (render/volume.py
``SHEET_CREASE``), a box's or a CAD part's edge crossing a voxel, each face
cut at the edge (its half-plane where the voxel spans ``HALF_PIXELS`` or
more, its line cutting it in the runs smaller); off, ``SHEET_CREASE`` 0:
every such face a surface sheet in the runs, counted over its whole section.
``--rule thick``: a thick solid's back hidden whole (``thick_backs``); off,
``THICK_OPPOSITE`` -inf: every closed back kept at ``1 - BACK_HIDE``, as a
thin solid's. ``--rule back``: a closed back in a run shows its colour only
as far as the planar law shows it (``RUN_BACK_MIN``; a far side of hidden
backs takes the near side's colour, a run of thick backs alone after
something drawn the colour so far); off, ``RUN_BACK_MIN`` 1: every back's
colour as its coverage (a read at compile time: the renderer drawing the
rule off makes its programs while it is off). ``--rule lines``: strips
drawn from ``STRIP_PIXELS`` 0.75 with their line halos
(render/sheet_line_halos.py); off, ``LINE_HALOS`` False and strips from
1.5 pixels, as before the halos. ``--rule foot``: the strips' ramps over
``STRIP_FOOT`` of the pixel's footprint; off, 1 (the whole footprint).
``--rule range``: the lines' offsets coded over ``C_RANGE`` 2 voxels, so
that a line halo's line (its neighbour's) fits; off, 0.875 (the halos whose
line falls outside are left out). ``--rule split``: where the plane goes
on across a face as another strip, a strip's halo carries the part of its
band that strip leaves (``sheet_line_halos.SPLIT_REST``: a beam's face
split by a voxel face along its length); off, None (no halo where the plane
goes on). ``--rule apart``: a run's closed backs summed apart from its
other sheets, per side, and the larger counted (``RUN_BACK_APART``: a
solid's back lies behind its own front); off, False: summed with the rest
(a chamfered edge on the outline covered the fills of the face seen and the
face turned away together). ``--rule strips``: a crease sheet that fits
no half-plane but a strip (a narrow face between two creases) drawn as its
strip (``CREASE_STRIPS``); off, False: a surface sheet in the runs.
``--rule tolerance``: an entry a strip when the fitted strip's centroid
lies within ``STRIP_TOLERANCE`` 0.2 voxel of its facets'; off, 0.03.
``--rule defer``: what a voxel adds outside the open run behind the run's
crossed surface goes behind the run (``RUN_DEFER``: the face between two
touching solids drew a line across their walls); off, False: at once.
``--rule front``: a run's sheets crossed after the voxel's first whole
surface sheet add nothing to its colour (``RUN_FRONT_GAP``: a wall and the
face behind it in one voxel mixed their colours); off, None.

Per scene (corpus names, or mesh files), at the corpus bench's two cameras
(*close*: the object filling the image; *minified*: a voxel about a pixel),
against the polygons at 8 x 8 samples inside the object's box, as the
corpus bench scores: PSNR (dB) / FLIP of the polygons at 1 and 2 x 2
samples and of the volume without and with the rule, the change, and
``edge err``, the mean |alpha - truth alpha| over the pixels the truth
covers in part. The variants are drawn by two renderers of one process, the
rule off in the second (each uploads the texture once, with the rule as set
then).

    .venv/bin/python demos/bench_volume_creases.py [SCENE | MESH FILE ...] [--size 512]
        [--rule crease|thick|back|lines|foot|range|split|apart|strips|tolerance|defer|front] [--md docs/coverage.md]
"""

from __future__ import annotations

import importlib

import numpy as np

from aniso3d.bench.outputs import markdown_table
from aniso3d.bench.variants import (
    command,
    corpus_parser,
    delta,
    pair,
    print_scores,
    publish,
    run_corpus_demo,
    scene_cameras,
    scene_or_mesh,
    scored,
)
from aniso3d.build import scenes
from aniso3d.build.texture import build_texture
from aniso3d.rendering import volume
from aniso3d.rendering.renderer import Renderer

#: Per rule: the module constants and their values off, the Markdown block's name.
RULES = {"crease": ({"SHEET_CREASE": 0.0}, "bench_volume_creases"),
         "thick": ({"THICK_OPPOSITE": -float("inf")}, "bench_volume_thick"),
         "back": ({"RUN_BACK_MIN": 1.0}, "bench_volume_back_colour"),
         "lines": ({"LINE_HALOS": False, "STRIP_PIXELS": 1.5}, "bench_volume_line_halos"),
         "foot": ({"STRIP_FOOT": 1.0}, "bench_volume_strip_foot"),
         "range": ({"sheet_halfplanes.C_RANGE": 0.875, "HALF_C_RANGE": 0.875, "sheet_line_halos.C_RANGE": 0.875},
                   "bench_volume_line_range"),
         "split": ({"sheet_line_halos.SPLIT_REST": None}, "bench_volume_split_halos"),
         "apart": ({"RUN_BACK_APART": False}, "bench_volume_backs_apart"),
         "strips": ({"CREASE_STRIPS": False}, "bench_volume_crease_strips"),
         "tolerance": ({"sheet_strips.STRIP_TOLERANCE": 0.03}, "bench_volume_strip_tolerance"),
         "defer": ({"RUN_DEFER": False}, "bench_volume_run_defer"),
         "front": ({"RUN_FRONT_GAP": None}, "bench_volume_run_front")}  # fmt: skip


def _where(name: str):
    """The module (aniso3d.rendering's ``module.NAME``, else volume) and the
    constant's name."""
    module, _, const = name.rpartition(".")
    return (importlib.import_module(f"aniso3d.rendering.{module}") if module else volume), const


def constant(name: str):
    module, const = _where(name)
    return getattr(module, const)


def set_constant(name: str, value) -> None:
    module, const = _where(name)
    setattr(module, const, value)


def edge_error(truth_a: np.ndarray, img_a: np.ndarray, crop) -> float:
    x0, y0, x1, y1 = crop
    t = truth_a[y0:y1, x0:x1].astype(np.float64) / 255.0
    a = img_a[y0:y1, x0:x1].astype(np.float64) / 255.0
    edge = (t > 0.02) & (t < 0.98)
    return float(np.abs(a - t)[edge].mean()) if edge.any() else 0.0


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh, label = scene_or_mesh(name)
    tex = build_texture(mesh, args.resolution, args.directions)
    off, _ = RULES[args.rule]
    rule = {k: constant(k) for k in off}
    rows = []
    with Renderer((args.size, args.size)) as before:
        for spec, truth, row in scene_cameras(renderer, mesh, label, args):
            truth_a = renderer.render(mesh, spec.camera, "mesh", ssaa=args.gt_ssaa, alpha=True)[..., 3]
            for k, v in off.items():
                set_constant(k, v)
            try:
                old = before.render(tex, spec.camera, "volume", alpha=True)
            finally:
                for k, v in rule.items():
                    set_constant(k, v)
            new = renderer.render(tex, spec.camera, "volume", alpha=True)
            for key, img in (("off", old), ("on", new)):
                row[key] = scored(truth, img[..., :3], spec)
                row[f"{key} edge"] = edge_error(truth_a, img[..., 3], spec.crop)
            rows.append(row)
            print_scores(spec.label, row)
    return rows


def main() -> None:
    ap = corpus_parser(__doc__.splitlines()[0], scenes.CORPUS)
    ap.add_argument("--rule", choices=sorted(RULES), default="crease")
    args = ap.parse_args()
    off, block = RULES[args.rule]
    run = run_corpus_demo(args, run_scene)
    head = ["scene", "camera", "1 spp", "2x2", "volume, rule off", "volume, rule on", "Δ PSNR", "Δ FLIP",
            "edge err off", "edge err on"]  # fmt: skip
    table = [[r["scene"], r["camera"], pair(r["1 spp"]), pair(r["2x2"]), pair(r["off"]), pair(r["on"]),
              *delta(r["on"], r["off"]), f"{r['off edge']:.3f}", f"{r['on edge']:.3f}"] for r in run.rows]  # fmt: skip
    parts = [
        f"{run.header(command('demos/bench_volume_creases.py', args, '--rule', args.rule))} Texture "
        f"{args.resolution}^3, K = {args.directions}; truth {args.gt_ssaa}x{args.gt_ssaa} polygons; PSNR (dB) / "
        f"FLIP inside the object's box, as the corpus bench. Rule: "
        f"{', '.join(f'{k} {constant(k)}' for k in off)} "
        f"(off: {', '.join(f'{k} {v}' for k, v in off.items())}); "
        f"SHEET_CREASE {volume.SHEET_CREASE}, HALF_PIXELS {volume.HALF_PIXELS}, BACK_HIDE "
        f"{volume.BACK_HIDE}, THICK_STEPS {volume.THICK_STEPS}, RUN_BACK_MIN {volume.RUN_BACK_MIN}.",
        "",
        markdown_table(head, table),
    ]
    publish(parts, args.md, f"<!-- {block}: begin -->", f"<!-- {block}: end -->", "Volume coverage")


if __name__ == "__main__":
    main()
