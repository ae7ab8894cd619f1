"""A crease partner's angle about its edge taken from its plane, against
the direction to its centroid (render/sheet_edges.py, ``PHI_PLANE_MIN``),
in both texture renderers.

Where a surface sheet's edge on a voxel face is creased, the sheet meeting
it there (its partner) is taken as a half-plane about the edge at an angle
phi: the volume's silhouette ramps and quality "high"'s drop of splats the
partner hides read it. The partner's plane passes up to ``EDGE_NEAR`` from
the edge, so the direction to its centroid can tilt far from its plane's: a
wall standing 0.2 voxel inside its plate's voxel face, with the plate's top
0.2 voxel above the voxel's floor, stood at 63 degrees instead of 90, and
the plate's splats by the wall were dropped for eyes between the two (a
line of background along a CAD part's inner corner, close up at 256^3).

Per scene (built-in or a mesh file) and camera (the corpus bench's close
and minified views at ``--resolution``, and the close view at
``--close-resolution``, the one ``--resolution auto`` picks there for the
corpus framing): PSNR (dB) / FLIP against 8x8 polygons inside the object's
box for 1-spp and 2x2 polygons, and for the volume and quality "high" disc
splats with the centroid's angle (off) and the plane's (on); and per
renderer the pinholes: pixels whose 3 x 3 neighbourhood the truth covers
whole but whose alpha is below 0.8. The images are deterministic: no spread
to report.

    .venv/bin/python demos/bench_crease_angle.py [tree room /path/mesh.stl ...] [--md docs/splat_aa.md]
"""

from __future__ import annotations

import copy

import numpy as np

from aniso3d.bench.corpus import corpus_cameras
from aniso3d.bench.outputs import markdown_table
from aniso3d.bench.settings import BASELINE
from aniso3d.bench.variants import (
    POLYGON_BASELINES,
    command,
    corpus_parser,
    delta,
    pair,
    print_scores,
    publish,
    run_corpus_demo,
    scene_or_mesh,
    scored,
)
from aniso3d.build import scenes
from aniso3d.build.texture import build_texture
from aniso3d.rendering import sheet_edges
from aniso3d.rendering.renderer import Renderer

BEGIN = "<!-- bench_crease_angle: begin -->"
END = "<!-- bench_crease_angle: end -->"
#: A pinhole: alpha below this where the truth covers the pixel and its 8 neighbours whole.
PINHOLE_ALPHA = 0.8
METHODS = {"volume": ("volume", {}), "high": ("splat", {"splat": BASELINE["splat"], "quality": "high"})}


def pinholes(truth_a: np.ndarray, img_a: np.ndarray, crop) -> int:
    x0, y0, x1, y1 = crop
    t = truth_a[y0:y1, x0:x1]
    whole = t == 255
    inner = whole.copy()
    inner[1:-1, 1:-1] = np.logical_and.reduce([whole[1 + dy : t.shape[0] - 1 + dy, 1 + dx : t.shape[1] - 1 + dx]
                                               for dy in (-1, 0, 1) for dx in (-1, 0, 1)])  # fmt: skip
    inner[[0, -1], :] = False
    inner[:, [0, -1]] = False
    return int((img_a[y0:y1, x0:x1][inner] < PINHOLE_ALPHA * 255).sum())


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh, label = scene_or_mesh(name)
    textures = {r: build_texture(mesh, r, args.directions) for r in {args.resolution, args.close_resolution}}
    # The rule-off drawings from a copy: the splats' clip planes are cached per texture object.
    copies = {r: copy.copy(t) for r, t in textures.items()}
    views = [(spec, args.resolution) for spec in corpus_cameras(mesh, (args.size, args.size), args.resolution)]
    close = [s for s, _ in views if s.label == "close"]
    views.insert(1, (close[0], args.close_resolution))
    on = sheet_edges.PHI_PLANE_MIN
    rows = []
    with Renderer((args.size, args.size)) as before:
        for spec, res in views:
            truth_rgba = renderer.render(mesh, spec.camera, "mesh", ssaa=args.gt_ssaa, alpha=True)
            truth = truth_rgba[..., :3]
            cam = spec.label if res == args.resolution else f"{spec.label} {res}^3"
            row: dict = {"scene": label, "camera": cam}
            for base, ssaa in POLYGON_BASELINES.items():
                row[base] = scored(truth, renderer.render(mesh, spec.camera, "mesh", ssaa=ssaa), spec)
            for key, (method, options) in METHODS.items():
                sheet_edges.PHI_PLANE_MIN = float("inf")
                try:
                    old = before.render(copies[res], spec.camera, method, alpha=True, **options)
                finally:
                    sheet_edges.PHI_PLANE_MIN = on
                new = renderer.render(textures[res], spec.camera, method, alpha=True, **options)
                for variant, img in (("off", old), ("on", new)):
                    row[f"{key} {variant}"] = scored(truth, img[..., :3], spec)
                    row[f"{key} {variant} holes"] = pinholes(truth_rgba[..., 3], img[..., 3], spec.crop)
            rows.append(row)
            print_scores(cam, row)
            print("    pinholes: " + ", ".join(f"{k[:-6]} {v}" for k, v in row.items() if k.endswith(" holes")),
                  flush=True)  # fmt: skip
    return rows


def main() -> None:
    ap = corpus_parser(__doc__.splitlines()[0], (*scenes.CORPUS, "cube", "sphere"))
    ap.add_argument("--close-resolution", type=int, default=256)
    args = ap.parse_args()
    run = run_corpus_demo(args, run_scene)
    head = ["scene", "camera", "1 spp", "2x2"]
    for key in METHODS:
        head += [f"{key}, centroid", f"{key}, plane", "Δ PSNR", "Δ FLIP", "pinholes"]
    table = []
    for r in run.rows:
        cells = [r["scene"], r["camera"], pair(r["1 spp"]), pair(r["2x2"])]
        for key in METHODS:
            cells += [pair(r[f"{key} off"]), pair(r[f"{key} on"]), *delta(r[f"{key} on"], r[f"{key} off"]),
                      f"{r[f'{key} off holes']} → {r[f'{key} on holes']}"]  # fmt: skip
        table.append(cells)
    parts = [
        f"{run.header(command('demos/bench_crease_angle.py', args))} Textures {args.resolution}^3 and "
        f"{args.close_resolution}^3 (the close view's second row), K = {args.directions}; truth {args.gt_ssaa}x"
        f"{args.gt_ssaa} polygons; PSNR (dB) / FLIP inside the object's box, as the corpus bench; volume and "
        f"{BASELINE['splat']} splats, quality \"high\"; centroid: the partner's angle from the direction to "
        f"its centroid (before), plane: from its plane (PHI_PLANE_MIN {sheet_edges.PHI_PLANE_MIN}); pinholes: "
        f"pixels the truth covers whole with their 8 neighbours, alpha below {PINHOLE_ALPHA}, centroid → plane.",
        "",
        markdown_table(head, table),
    ]
    publish(parts, args.md, BEGIN, END, "Anti-aliased splats")


if __name__ == "__main__":
    main()
