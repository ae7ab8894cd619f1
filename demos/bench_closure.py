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

``--holes`` compares instead how a skin's holes are measured: ``summed``,
as until 90240ac (:func:`summed_sides`, kept here for the comparison: the
lengths of all its open edges, an edge of three faces or more among them,
summed and then squared), against ``all`` (each hole's length squared,
summed; edges of three faces no hole).

``--enclosed`` compares the faces of patches their whole encloses (seen
from neither side: a storey's roof under the next storey's floor) built,
``drawn`` (before), against left out, the default.

``--fins`` compares how faces beside an edge of three faces or more are
read: ``fins open``, as until the rule of docs/coverage.md "Edges of three
faces" (:func:`fins_open_sides`: such faces open, the rest of their
components signed by their own signed volume), against ``all`` (such faces
kept in their components; a component beside such an edge signed by what
the outside sees of it, :mod:`aniso3d.build.outside`).

Per scene and camera (the corpus bench's two): the share of faces taken as
closed, and PSNR (dB) / FLIP against 8x8 polygons in the object's box for
1-spp and 2x2 polygons, the volume and the high splats of each variant.
The images are deterministic: no spread to report.

    .venv/bin/python demos/bench_closure.py [tree bush ... | mesh files] [--size 512] [--holes | --fins | --enclosed]
        [--md docs/coverage.md]
"""

from __future__ import annotations

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
    scene_or_mesh,
    scored,
)
from aniso3d.build import scenes
from aniso3d.build.texture import build_texture
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.splat.clips import texture_points

BEGIN = "<!-- bench_closure: begin -->"
END = "<!-- bench_closure: end -->"
#: variant: HOLE_SHARE (None: the default), or None for the strict reading.
VARIANTS = {"before": None, "corners": 0.0, "all": "default"}
#: --holes: the hole measure until 90240ac against the default.
HOLE_VARIANTS = {"summed": "summed", "all": "default"}
#: --fins: faces beside edges of three faces open (before) against the default.
FIN_VARIANTS = {"fins open": "fins", "all": "default"}
#: --enclosed: the faces of patches their whole encloses drawn (before) against the default (left out).
ENCLOSED_VARIANTS = {"drawn": "drawn", "left out": "default"}
FINS_BEGIN = "<!-- bench_closure_fins: begin -->"
FINS_END = "<!-- bench_closure_fins: end -->"
ENCLOSED_BEGIN = "<!-- bench_closure_enclosed: begin -->"
ENCLOSED_END = "<!-- bench_closure_enclosed: end -->"
HOLES_BEGIN = "<!-- bench_closure_holes: begin -->"
HOLES_END = "<!-- bench_closure_holes: end -->"


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
    sign = mesh_module.volume_signs(v, faces, root, nf)
    return np.where(open_count[root] == 0, sign[root], 0).astype(np.int8)


def summed_sides(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The sides as read until 90240ac: :func:`~aniso3d.build.mesh.face_topology`
    with a component's hole measure the squared sum of the lengths of its
    edges not shared by two faces walking them opposite ways (edges of
    three faces or more among them)."""
    faces = np.asarray(faces, dtype=np.int64)
    nf = len(faces)
    sides = np.zeros(nf, dtype=np.int8)
    if nf == 0:
        return sides
    v = np.asarray(vertices, dtype=np.float64)
    _, repeat, _ = mesh_module.face_topology(v, faces)
    f_all = mesh_module.merged_vertices(v)[faces]
    degenerate = (f_all[:, 0] == f_all[:, 1]) | (f_all[:, 1] == f_all[:, 2]) | (f_all[:, 2] == f_all[:, 0])
    topo = np.flatnonzero(~repeat & ~degenerate)
    if len(topo) == 0:
        return sides
    fc, f = faces[topo], f_all[topo]
    n_t = len(topo)
    a, b = f.reshape(-1), f[:, [1, 2, 0]].reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    _, inverse, count = np.unique(lo * (int(f.max()) + 1) + hi, return_inverse=True, return_counts=True)
    walk = np.bincount(inverse, weights=np.where(a < b, 1.0, -1.0), minlength=len(count))
    good = (count == 2) & (walk == 0)
    local = (good | (count == 1))[inverse].reshape(-1, 3).all(axis=1)
    order = np.argsort(inverse, kind="stable")
    pair = np.concatenate([[0], np.cumsum(count)[:-1]])[good]
    root = mesh_module.connected_components(n_t, order[pair] // 3, order[pair + 1] // 3)
    corner = v[fc.reshape(-1)]
    length = np.linalg.norm(v[fc[:, [1, 2, 0]].reshape(-1)] - corner, axis=1)
    hole = np.bincount(root[np.arange(len(a)) // 3], weights=np.where(good[inverse], 0.0, length), minlength=n_t)
    t = v[fc]
    skin = np.bincount(root, weights=0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1),
                       minlength=n_t)  # fmt: skip
    closed = hole**2 <= mesh_module.HOLE_SHARE * skin
    sign = mesh_module.volume_signs(v, fc, root, n_t)
    sides[topo] = np.where(local & closed[root], sign[root], 0)
    return sides


def fins_open_sides(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The sides as read before the rule of "Edges of three faces": a face
    beside an edge of three faces or more open, and every component signed
    by its own signed volume (the default's reading with its outside test
    replaced by that sign, and those faces opened)."""
    faces = np.asarray(faces, dtype=np.int64)
    v = np.asarray(vertices, dtype=np.float64)

    def volume_sign(v, fc, f, root, patches, whole=None):
        return mesh_module.volume_signs(v, fc, root, int(root.max()) + 1)[patches]

    original = mesh_module.outside_sides
    mesh_module.outside_sides = volume_sign
    try:
        sides, repeat, _ = mesh_module.face_topology(v, faces)
    finally:
        mesh_module.outside_sides = original
    f = mesh_module.merged_vertices(v)[faces]
    topo = np.flatnonzero(~repeat & (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0]))
    if len(topo):
        ft = f[topo]
        a, b = ft.reshape(-1), ft[:, [1, 2, 0]].reshape(-1)
        key = np.minimum(a, b) * (int(ft.max()) + 1) + np.maximum(a, b)
        _, inverse, count = np.unique(key, return_inverse=True, return_counts=True)
        sides[topo[(count > 2)[inverse].reshape(-1, 3).any(axis=1)]] = 0
    return sides


def set_variant(name: str, default_hole: float, variants: dict):
    hole = variants[name]
    mesh_module.HOLE_SHARE = default_hole if hole in ("default", "summed", "fins", "drawn") else (hole or 0.0)
    none = lambda f: np.zeros(len(f), bool)  # noqa: E731
    if hole is None:
        mesh_stream.face_topology = lambda v, f: (strict_sides(v, f), none(f), none(f))
    elif hole == "summed":
        mesh_stream.face_topology = lambda v, f: (summed_sides(v, f), mesh_module.face_topology(v, f)[1], none(f))
    elif hole == "fins":
        mesh_stream.face_topology = lambda v, f: (fins_open_sides(v, f), mesh_module.face_topology(v, f)[1], none(f))
    elif hole == "drawn":
        mesh_stream.face_topology = lambda v, f: (*mesh_module.face_topology(v, f)[:2], none(f))
    else:
        mesh_stream.face_topology = mesh_module.face_topology


def closed_share(mesh, name: str, variants: dict) -> float:
    if variants[name] is None:
        return float(np.mean(strict_sides(mesh.vertices, mesh.faces) != 0))
    if variants[name] == "summed":
        return float(np.mean(summed_sides(mesh.vertices, mesh.faces) != 0))
    if variants[name] == "fins":
        return float(np.mean(fins_open_sides(mesh.vertices, mesh.faces) != 0))
    return float(np.mean(mesh_module.closed_sides(mesh.vertices, mesh.faces) != 0))


def pick_variants(args) -> dict:
    if args.enclosed:
        return ENCLOSED_VARIANTS
    return FIN_VARIANTS if args.fins else HOLE_VARIANTS if args.holes else VARIANTS


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh, label = scene_or_mesh(name)
    default_hole = mesh_module.HOLE_SHARE
    original = mesh_stream.face_topology
    variants = pick_variants(args)
    made = {}
    try:
        for v in variants:
            set_variant(v, default_hole, variants)
            closed = closed_share(mesh, v, variants)
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
    ap = corpus_parser(__doc__.splitlines()[0], scenes.CORPUS)
    ap.add_argument("--holes", action="store_true", help="compare the hole measures (summed, all)")
    ap.add_argument("--fins", action="store_true", help="compare the readings of edges of three faces (fins open, all)")
    ap.add_argument("--enclosed", action="store_true", help="compare enclosed patches drawn and left out")
    args = ap.parse_args()
    run = run_corpus_demo(args, run_scene)
    variants = pick_variants(args)
    columns = ["1 spp", "2x2", *(f"{m} {v}" for m in ("volume", "splat") for v in variants)]
    table = [[r["scene"], r["camera"], " / ".join(f"{100 * r[f'closed {v}']:.1f}" for v in variants),
              *(pair(r[c]) for c in columns)] for r in run.rows]  # fmt: skip
    if args.enclosed:
        legend = ("(drawn / left out: the same). drawn: the faces of patches their whole encloses (seen from neither "
                  "side: a storey's roof under the next one's floor) built (before); left out: not built.")  # fmt: skip
        begin, end = ENCLOSED_BEGIN, ENCLOSED_END
    elif args.fins:
        legend = ("(fins open / all). fins open: a face beside an edge of three faces or more open, each component "
                  "signed by its own signed volume (before); all: such faces kept in their components, a component "
                  "beside such an edge signed by what the outside sees of it (aniso3d.build.outside).")  # fmt: skip
        begin, end = FINS_BEGIN, FINS_END
    elif args.holes:
        legend = ("(summed / all). summed: a skin's hole measure the squared sum of its open edges' lengths, edges of "
                  "three faces or more among them (until 90240ac); all: the sum of each hole's squared length, edges "
                  f"of three faces no hole (HOLE_SHARE {mesh_module.HOLE_SHARE:g} in both).")  # fmt: skip
        begin, end = HOLES_BEGIN, HOLES_END
    else:
        legend = ("in each variant (before / corners / all). before: the strict reading as it was (corners matched "
                  "exactly, watertight skins only, a degenerate or repeated face opening its skin, faces drawn twice "
                  f"built twice); corners: corners matched within {mesh_module.MERGE_SHARE:.3g} of the extent, "
                  "degenerate and repeated faces out of the topology, a face drawn twice built once, watertight skins "
                  "only; all: the defaults, skins with small holes closed too "
                  f"(HOLE_SHARE {mesh_module.HOLE_SHARE:g}).")  # fmt: skip
        begin, end = BEGIN, END
    publish([
        run.header(command("demos/bench_closure.py", args)) + " "
        f"Texture {args.resolution}^3, K = {args.directions}, the corpus bench's points and {BASELINE['splat']} "
        f"splats, quality \"high\"; truth {args.gt_ssaa}x{args.gt_ssaa} polygons; PSNR (dB) / FLIP inside the "
        "object's box, as the corpus bench. closed %: the share of faces taken as a closed skin " + legend,
        "",
        markdown_table(["scene", "camera", "closed %", *columns], table),
    ], args.md, begin, end, title="# Coverage\n\n")  # fmt: skip

if __name__ == "__main__":
    main()
