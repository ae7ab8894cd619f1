"""Quality "high" splats cut where their surface ends (aniso3d.rendering.splat.clips),
on the corpus and the cube and sphere at the corpus bench's two cameras.

Per scene and camera: PSNR (dB) / FLIP against 8x8 polygons in the object's
box, as the corpus bench measures, for 1-spp and 2x2 polygons, the texture's
points as ``to_points`` makes them (``uncut``: no clip planes, the splats as
before) and with their clip planes (``cut``: ``texture_points``, what the
renderer and the corpus bench draw now). The images are deterministic: no
spread to report.

    .venv/bin/python demos/bench_splat_edges.py [room blob ...] [--size 512] [--md docs/splat_aa.md]
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
from aniso3d.rendering.splat.clips import clipped

BEGIN = "<!-- bench_splat_edges: begin -->"
END = "<!-- bench_splat_edges: end -->"
SCENES = (*scenes.CORPUS, "cube", "sphere")


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh = scenes.get_scene(name)
    tex = build_texture(mesh, args.resolution, args.directions, bounds=mesh.bounds)
    uncut = tex.to_points(BASELINE["placement"], BASELINE["per_entry"], BASELINE["point_normal"])
    cut = clipped(uncut, tex, None, BASELINE["per_entry"])
    rows = []
    for spec in corpus_cameras(mesh, (args.size, args.size), args.resolution):
        truth = renderer.render(mesh, spec.camera, "mesh", ssaa=args.gt_ssaa)
        row = {"scene": name, "camera": spec.label}
        for label, ssaa in (("1 spp", 1), ("2x2", 2)):
            m = metrics.compare_in_box(truth, renderer.render(mesh, spec.camera, "mesh", ssaa=ssaa), spec.crop,
                                       with_flip=True)  # fmt: skip
            row[label] = (m["psnr"], m["flip"])
        for label, cloud in (("uncut", uncut), ("cut", cut)):
            img = renderer.render(cloud, spec.camera, "splat", splat=BASELINE["splat"], quality="high")
            m = metrics.compare_in_box(truth, img, spec.crop, with_flip=True)
            row[label] = (m["psnr"], m["flip"])
        rows.append(row)
        print(f"  {spec.label}: " + ", ".join(f"{k} {v[0]:.2f}/{v[1]:.4f}" for k, v in row.items()
                                              if isinstance(v, tuple)), flush=True)  # fmt: skip
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=list(SCENES))
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--gt-ssaa", type=int, default=8)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=16)
    ap.add_argument("--md", default="", help="Markdown file to write the table into (between its markers)")
    args = ap.parse_args()

    run = run_scenes(args.scenes, args.size, lambda name, renderer: run_scene(name, args, renderer))
    columns = ["1 spp", "2x2", "uncut", "cut"]
    table = []
    for r in run.rows:
        table.append([r["scene"], r["camera"], *(f"{r[c][0]:.2f} / {r[c][1]:.4f}" for c in columns),
                      f"{r['cut'][0] - r['uncut'][0]:+.2f}", f"{r['cut'][1] - r['uncut'][1]:+.4f}",
                      "yes" if r["cut"][0] >= r["2x2"][0] and r["cut"][1] <= r["2x2"][1] else "no",
                      "yes" if r["cut"][0] >= r["1 spp"][0] and r["cut"][1] <= r["1 spp"][1] else "no"])  # fmt: skip
    block = "\n".join([
        BEGIN,
        run.header(f"demos/bench_splat_edges.py {' '.join(args.scenes)} --size {args.size}") + " "
        f"Texture {args.resolution}^3 over the mesh's bounds, K = {args.directions}, the corpus bench's points and "
        f"{BASELINE['splat']} splats, quality \"high\"; truth {args.gt_ssaa}x{args.gt_ssaa} polygons; PSNR (dB) / "
        "FLIP inside the object's box, as the corpus bench. uncut: the points as to_points makes them; cut: with "
        "their clip planes (texture_points). Δ: cut - uncut. ≥ 2x2, ≥ 1 spp: cut at least as good in PSNR and FLIP.",
        "",
        markdown_table(["scene", "camera", *columns, "Δ PSNR", "Δ FLIP", "≥ 2x2", "≥ 1 spp"], table),
        END,
    ])  # fmt: skip
    print("\n" + block)
    if args.md:
        path = write_between_markers(args.md, block, BEGIN, END, title="# Anti-aliased splats\n\n")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
