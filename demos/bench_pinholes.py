"""Rules that keep quality "high" splats of closed surfaces free of
pinholes, each against itself off: ``--rule angle`` (default), a crease
partner's angle about its edge taken from its plane, not the direction to
its centroid, for the splats' clip planes (render/sheet_edges.py
``PHI_PLANE_MIN``; the volume keeps the centroid's, its crease ramps lost
up to 0.13 dB with the plane's: docs/splat_aa.md, the block at 8814f3f); ``--rule sided``, a one-sided point's
splat is never dropped behind its crease partner (splat/params.py
``AA_PARTNER_HIDES_SIDED``); ``--rule slope``, the whole-surface test counts
a neighbour within the closure's reach plus this pixel's depth change
across a pixel (``AA_CLOSE_SLOPE``).

Where a surface sheet's edge on a voxel face is creased, the sheet meeting
it there (its partner) is taken as a half-plane about the edge at an angle
phi, and quality "high" drops a splat the partner hides from the eye. The
partner's plane passes up to ``EDGE_NEAR`` from the edge, so the direction
to its centroid can tilt far from its plane's: a wall standing 0.2 voxel
inside its plate's voxel face, with the plate's top 0.2 voxel above the
voxel's floor, stood at 63 degrees instead of 90, and the plate's splats by
the wall were dropped for eyes between the two (a line of background along
a CAD part's inner corner, close up at 256^3). A one-sided point's partner
is its closed surface's too, wound alike: where it lies in front of the
point it faces away and is culled, so it hides nothing, and dropping the
point left a line of background along a lip seen from beyond it (a truck's
roof). A closed surface seen at a grazing angle changes depth by several
slices a pixel, so neighbouring pixels' nearest surfaces start farther
apart than the closure's reach and did not count: a low-poly head's brow
drew as a sieve of background.

Per scene (built-in or a mesh file) and camera (the corpus bench's close
and minified views at ``--resolution``, and the close view at
``--close-resolution``, the one ``--resolution auto`` picks there for the
corpus framing): PSNR (dB) / FLIP against 8x8 polygons inside the object's
box for 1-spp and 2x2 polygons, and for quality "high" disc splats with the
rule off and on; and the pinholes: pixels whose 3 x 3 neighbourhood the
truth covers whole but whose alpha is below 0.8. The images are
deterministic: no spread to report.

    .venv/bin/python demos/bench_pinholes.py [tree room /path/mesh.stl ...] [--rule angle|sided|slope]
        [--md docs/splat_aa.md]
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
from aniso3d.rendering.splat import params

#: Per rule: (module, constant, its value off), the Markdown block's name and what off and on mean.
RULES = {
    "angle": ((sheet_edges, "PHI_PLANE_MIN", float("inf")), "bench_crease_angle",
              "centroid: the partner's angle from the direction to its centroid (before), plane: from its plane"),
    "sided": ((params, "AA_PARTNER_HIDES_SIDED", True), "bench_partner_sided",
              "off: a one-sided point dropped behind its partner (before), on: never"),
    "slope": ((params, "AA_CLOSE_SLOPE", False), "bench_close_slope",
              "off: a neighbour counts within the closure's reach (before), on: plus the pixel's depth change"),
}  # fmt: skip
#: A pinhole: alpha below this where the truth covers the pixel and its 8 neighbours whole.
PINHOLE_ALPHA = 0.8
METHODS = {"high": ("splat", {"splat": BASELINE["splat"], "quality": "high"})}


def pinholes(truth_a: np.ndarray, img_a: np.ndarray, crop) -> int:
    x0, y0, x1, y1 = crop
    t = truth_a[y0:y1, x0:x1]
    whole = t == 255
    inner = np.zeros_like(whole)  # the border's pixels lack neighbours: never counted
    inner[1:-1, 1:-1] = np.logical_and.reduce([whole[1 + dy : t.shape[0] - 1 + dy, 1 + dx : t.shape[1] - 1 + dx]
                                               for dy in (-1, 0, 1) for dx in (-1, 0, 1)])  # fmt: skip
    return int((img_a[y0:y1, x0:x1][inner] < PINHOLE_ALPHA * 255).sum())


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh, label = scene_or_mesh(name)
    (module, const, off), _, _ = RULES[args.rule]
    on = getattr(module, const)
    textures = {r: build_texture(mesh, r, args.directions) for r in {args.resolution, args.close_resolution}}
    # The rule-off drawings from a copy: the splats' clip planes are cached per texture object.
    copies = {r: copy.copy(t) for r, t in textures.items()}
    views = [(spec, args.resolution) for spec in corpus_cameras(mesh, (args.size, args.size), args.resolution)]
    close = [s for s, _ in views if s.label == "close"]
    views.insert(1, (close[0], args.close_resolution))
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
                setattr(module, const, off)
                try:
                    old = before.render(copies[res], spec.camera, method, alpha=True, **options)
                finally:
                    setattr(module, const, on)
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
    ap.add_argument("--rule", choices=sorted(RULES), default="angle")
    args = ap.parse_args()
    (module, const, off), block, meaning = RULES[args.rule]
    run = run_corpus_demo(args, run_scene)
    head = ["scene", "camera", "1 spp", "2x2"]
    for key in METHODS:
        head += [f"{key}, off", f"{key}, on", "Δ PSNR", "Δ FLIP", "pinholes"]
    table = []
    for r in run.rows:
        cells = [r["scene"], r["camera"], pair(r["1 spp"]), pair(r["2x2"])]
        for key in METHODS:
            cells += [pair(r[f"{key} off"]), pair(r[f"{key} on"]), *delta(r[f"{key} on"], r[f"{key} off"]),
                      f"{r[f'{key} off holes']} → {r[f'{key} on holes']}"]  # fmt: skip
        table.append(cells)
    parts = [
        f"{run.header(command('demos/bench_pinholes.py', args, '--rule', args.rule))} Textures "
        f"{args.resolution}^3 and {args.close_resolution}^3 (the close view's second row), K = {args.directions}; "
        f"truth {args.gt_ssaa}x{args.gt_ssaa} polygons; PSNR (dB) / FLIP inside the object's box, as the corpus "
        f"bench; {BASELINE['splat']} splats, quality \"high\"; rule {const} "
        f"{getattr(module, const)} (off: {off}); {meaning}; pinholes: pixels the truth covers whole with their 8 "
        f"neighbours, alpha below {PINHOLE_ALPHA}, off → on.",
        "",
        markdown_table(head, table),
    ]
    publish(parts, args.md, f"<!-- {block}: begin -->", f"<!-- {block}: end -->", "Anti-aliased splats")


if __name__ == "__main__":
    main()
