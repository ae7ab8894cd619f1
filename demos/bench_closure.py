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

- ``before``: the strict reading as it was (:func:`strict_sides`, kept here
  for the comparison): corners matched exactly, watertight skins only, a
  degenerate or repeated face opening its skin, repeated faces built;
- ``corners``: corners matched within ``MERGE_SHARE`` of the extent,
  degenerate and repeated faces out of the topology, a face drawn twice
  built once; still watertight skins only;
- ``all``: the defaults, skins with small holes closed too (``HOLE_SHARE``).

Per scene and camera (the corpus bench's two): the share of faces taken as
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
#: variant: HOLE_SHARE (None: the default), or None for the strict reading.
VARIANTS = {"before": None, "corners": 0.0, "all": "default"}


def strict_sides(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The sides as read before (corners matched exactly, watertight and
    consistently wound components only, a degenerate or repeated face
    opening its component): the baseline of this comparison."""
    faces = np.asarray(faces, dtype=np.int64)
    nf = len(faces)
    if nf == 0:
        return np.zeros(0, dtype=np.int8)
    v = np.asarray(vertices, dtype=np.float64)
    _, same = np.unique(v, axis=0, return_inverse=True)
    f = same.reshape(-1)[faces]
    a, b = f.reshape(-1), f[:, [1, 2, 0]].reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    _, inverse, count = np.unique(lo * (int(f.max()) + 1) + hi, return_inverse=True, return_counts=True)
    walk = np.bincount(inverse, weights=np.where(a < b, 1.0, -1.0), minlength=len(count))
    local = ((count == 2) & (walk == 0))[inverse] & (a != b)
    order = np.argsort(inverse, kind="stable")
    pair = np.concatenate([[0], np.cumsum(count)[:-1]])[count == 2]
    root = mesh_module.connected_components(nf, order[pair] // 3, order[pair + 1] // 3)
    open_count = np.bincount(root, weights=(~local.reshape(-1, 3).all(axis=1)).astype(np.float64), minlength=nf)
    p0, p1, p2 = (v[faces[:, k]] - v.mean(axis=0) for k in range(3))
    volume = np.bincount(root, weights=np.einsum("ij,ij->i", p0, np.cross(p1, p2)), minlength=nf)
    tiny = 1e-12 * float(np.ptp(v, axis=0).max()) ** 3
    sign = np.where(volume > tiny, 1, np.where(volume < -tiny, -1, 0))
    return np.where(open_count[root] == 0, sign[root], 0).astype(np.int8)


def set_variant(name: str, default_hole: float):
    hole = VARIANTS[name]
    mesh_module.HOLE_SHARE = default_hole if hole == "default" else (hole or 0.0)
    if hole is None:
        mesh_stream.face_topology = lambda v, f: (strict_sides(v, f), np.zeros(len(f), bool))
    else:
        mesh_stream.face_topology = mesh_module.face_topology


def closed_share(mesh, name: str) -> float:
    if VARIANTS[name] is None:
        return float(np.mean(strict_sides(mesh.vertices, mesh.faces) != 0))
    return float(np.mean(mesh_module.closed_sides(mesh.vertices, mesh.faces) != 0))


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh = load_mesh(name) if Path(name).suffix else scenes.get_scene(name)
    label = Path(name).name if Path(name).suffix else name
    default_hole = mesh_module.HOLE_SHARE
    original = mesh_stream.face_topology
    made = {}
    try:
        for v in VARIANTS:
            set_variant(v, default_hole)
            closed = closed_share(mesh, v)
            tex = build_texture(mesh, args.resolution, args.directions)
            made[v] = (closed, tex, texture_points(tex, BASELINE["placement"], BASELINE["per_entry"],
                                                   BASELINE["point_normal"]))  # fmt: skip
    finally:
        mesh_module.HOLE_SHARE = default_hole
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
        "(before / corners / all). before: the strict reading as it was (corners matched exactly, watertight "
        "skins only, a degenerate or repeated face opening its skin, faces drawn twice built twice); corners: "
        f"corners matched within {mesh_module.MERGE_SHARE:.3g} of the extent, degenerate and repeated faces out "
        "of the topology, a face drawn twice built once, watertight skins only; all: the defaults, skins with "
        f"small holes closed too (HOLE_SHARE {mesh_module.HOLE_SHARE:g}).",
        "",
        markdown_table(["scene", "camera", "closed %", *columns], table),
    ], args.md, BEGIN, END, title="# Coverage\n\n")  # fmt: skip


if __name__ == "__main__":
    main()
