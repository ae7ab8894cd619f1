"""What taking a thin solid's hidden back out of its voxels does to the images.

Per scene (the corpus, the cube and the sphere by default) the texture is
built three ways and drawn at the corpus bench's two cameras by the volume
and by the high-quality splats (discs), PSNR / FLIP against 8x8 polygons in
the object's box, as the corpus bench measures:

- ``off``: no face taken as closed (``Mesh.closed_faces`` all False): the
  density and the splats count a thin solid's front and back;
- ``axis``: the alternative law that counts the solid's cuts by the voxel's
  faces as axis-aligned, ``H = (D_c - sum_i |V_i| |w_i|) / 2`` and covers
  ``1 - (1 - sum_i |V_i| / A_c) / 2`` (keeps a box's corner whole);
- ``flat``: the law in ``aniso3d.build.closure`` (the default):
  ``H = (D_c - |V . w|) / 2``, covers ``1 - (1 - |V| / A_c) / 2``.

Also the share of each scene's faces that are closed and the mean entry
cover. The images are deterministic: no spread to report.

With ``--backs`` it measures instead the volume's hiding of closed surfaces'
backs along the ray (``VolumeOptions.back_hide``, :data:`~aniso3d.rendering.volume.BACK_HIDE`)
on the default texture: PSNR / FLIP at each share of :data:`BACKS` (0: not
hidden, the volume before it), the alpha summed over the object's box
against the truth's, and the frame time at 0 and at the default, drawn in
turn (the same program: only the share differs).

    .venv/bin/python demos/bench_thin_solids.py [tree bush ... cube sphere] \\
        [--size 512] [--backs [--frames 5]] [--md docs/coverage.md]
"""

from __future__ import annotations

import argparse
from contextlib import contextmanager

import numpy as np

import aniso3d.build.closure as closure
import aniso3d.build.mesh as mesh_module
from aniso3d import metrics
from aniso3d.bench.corpus import corpus_cameras
from aniso3d.bench.outputs import markdown_table, write_between_markers
from aniso3d.bench.run import run_scenes
from aniso3d.build import scenes
from aniso3d.build.texture import build_texture
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.volume import BACK_HIDE

BEGIN = "<!-- bench_thin_solids: begin -->"
END = "<!-- bench_thin_solids: end -->"
BACKS_BEGIN = "<!-- bench_thin_solids backs: begin -->"
BACKS_END = "<!-- bench_thin_solids backs: end -->"
LAWS = ("off", "axis", "flat")
#: The shares of closed surfaces' backs hidden that ``--backs`` draws.
BACKS = (0.0, 0.5, BACK_HIDE, 1.0)


def _axis_hidden(offsets, directions, closed_normal):
    m = len(offsets) - 1
    closed_normal = np.asarray(closed_normal, dtype=np.float64)
    dirs = np.asarray(directions, dtype=np.float64)
    if not np.any(closed_normal):
        return np.zeros((m, len(dirs)))
    _, net = closure.voxel_net(offsets, closed_normal)
    both = closure.facet_density(np.ones(len(closed_normal)), closed_normal, offsets, dirs)
    return np.maximum(both - np.abs(net) @ np.abs(dirs).T, 0.0) / 2.0


def _axis_cover(offsets, area, closed_area, closed_normal):
    m = len(offsets) - 1
    if not np.any(np.asarray(closed_area) > 0):
        return np.ones(len(area), dtype=np.float32)
    voxel, net = closure.voxel_net(offsets, closed_normal)
    total = np.bincount(voxel, closed_area, minlength=m)
    with np.errstate(divide="ignore", invalid="ignore"):
        facing = np.where(total > 0, 1.0 - np.abs(net).sum(axis=1) / total, 0.0)
        share = np.where(area > 0, np.clip(closed_area / area, 0.0, 1.0), 0.0)
    return (1.0 - 0.5 * np.clip(facing, 0.0, 1.0)[voxel] * share).astype(np.float32)


@contextmanager
def law(name: str):
    """Build under one of LAWS (patches undone on exit)."""
    saved = (mesh_module.Mesh.closed_faces, closure.hidden_density, closure.entry_cover)
    try:
        if name == "off":
            mesh_module.Mesh.closed_faces = lambda self: np.zeros(self.n_faces, dtype=bool)
        elif name == "axis":
            closure.hidden_density, closure.entry_cover = _axis_hidden, _axis_cover
        yield
    finally:
        mesh_module.Mesh.closed_faces, closure.hidden_density, closure.entry_cover = saved


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh = scenes.get_scene(name)
    textures = {}
    for lw in LAWS:
        with law(lw):
            textures[lw] = build_texture(mesh, args.resolution, args.directions)
    closed = float(np.mean(mesh.closed_faces()))
    cover = float(np.mean(textures["flat"].entry_cover))
    rows = []
    for spec in corpus_cameras(mesh, (args.size, args.size), args.resolution):
        truth = renderer.render(mesh, spec.camera, "mesh", ssaa=args.gt_ssaa)
        row = {"scene": name, "camera": spec.label, "closed": closed, "cover": cover}
        for lw, tex in textures.items():
            for method, thing, opts in (("volume", tex, {}), ("splat", tex.to_points(), {"quality": "high"})):
                img = renderer.render(thing, spec.camera, method, **opts)
                m = metrics.compare_in_box(truth, img, spec.crop, with_flip=True)
                row[(method, lw)] = (m["psnr"], m["flip"])
        rows.append(row)
        print(f"  {spec.label}: " + ", ".join(f"{k[0]} {k[1]} {v[0]:.2f}/{v[1]:.4f}" for k, v in row.items()
                                              if isinstance(k, tuple)), flush=True)  # fmt: skip
    return rows


def run_backs(name: str, args, renderer: Renderer) -> list[dict]:
    mesh = scenes.get_scene(name)
    tex = build_texture(mesh, args.resolution, args.directions)
    rows = []
    for spec in corpus_cameras(mesh, (args.size, args.size), args.resolution):
        x0, y0, x1, y1 = spec.crop
        truth = renderer.render(mesh, spec.camera, "mesh", ssaa=args.gt_ssaa, alpha=True)[y0:y1, x0:x1]
        row = {"scene": name, "camera": spec.label, "closed": float(np.mean(mesh.closed_faces())), "times": {}}
        for hide in BACKS:
            img = renderer.render(tex, spec.camera, "volume", alpha=True, back_hide=hide)[y0:y1, x0:x1]
            m = metrics.compare(truth[..., :3], img[..., :3], with_flip=True)
            ratio = float(img[..., 3].astype(np.float64).sum() / max(truth[..., 3].astype(np.float64).sum(), 1.0))
            row[hide] = (m["psnr"], m["flip"], ratio)
        for _ in range(args.frames):  # in turn: both see the same load
            for hide in (0.0, BACK_HIDE):
                renderer.render(tex, spec.camera, "volume", back_hide=hide)
                row["times"].setdefault(hide, []).append(renderer.last_frame_seconds)
        rows.append(row)
        print(f"  {spec.label}: " + ", ".join(f"{h:g}: {row[h][0]:.2f}/{row[h][1]:.4f} alpha {row[h][2]:.3f}"
                                              for h in BACKS), flush=True)  # fmt: skip
    return rows


def backs_block(run, args) -> str:
    rows = run.rows

    def ms(t):
        t = 1000 * np.asarray(t)
        return f"{np.median(t):.0f} [{t.min():.0f}-{t.max():.0f}]"

    table = []
    for r in rows:
        d = r[BACK_HIDE][0] - r[0.0][0]
        df = r[BACK_HIDE][1] - r[0.0][1]
        table.append([r["scene"], r["camera"], f"{100 * r['closed']:.0f} %",
                      *(f"{r[h][0]:.2f} / {r[h][1]:.4f}" for h in BACKS),
                      f"{d:+.2f}", f"{df:+.4f}", f"{r[0.0][2]:.3f}", f"{r[BACK_HIDE][2]:.3f}",
                      ms(r["times"][0.0]), ms(r["times"][BACK_HIDE])])  # fmt: skip
    cmd = f"demos/bench_thin_solids.py {' '.join(args.scenes)} --size {args.size} --backs --frames {args.frames}"
    parts = [
        BACKS_BEGIN,
        run.header(cmd) + " "
        f"Texture {args.resolution}^3, K = {args.directions}; truth {args.gt_ssaa}x{args.gt_ssaa} polygons; "
        "PSNR (dB) / FLIP inside the object's box, as the corpus bench, of the volume hiding each share of "
        f"closed surfaces' backs (`back_hide`; 0: not hidden, as before; {BACK_HIDE:g}: the default); Δ: "
        f"{BACK_HIDE:g} - 0; alpha: the volume's alpha summed over the box over the truth's; frame times (ms): "
        "median [fastest-slowest], the two shares drawn in turn (one program).",
        "",
        markdown_table(["scene", "camera", "closed", *(f"hide {h:g}" for h in BACKS), "Δ PSNR", "Δ FLIP",
                        "alpha 0", f"alpha {BACK_HIDE:g}", "ms 0", f"ms {BACK_HIDE:g}"], table),  # fmt: skip
        BACKS_END,
    ]
    return "\n".join(parts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=[*scenes.CORPUS, "cube", "sphere"])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--gt-ssaa", type=int, default=8)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=16)
    ap.add_argument("--md", default="", help="Markdown file to write the table into (between its markers)")
    ap.add_argument("--backs", action="store_true", help="measure the volume's hiding of closed backs instead")
    ap.add_argument("--frames", type=int, default=5, help="--backs: frames timed per share")
    args = ap.parse_args()
    if args.backs:
        run = run_scenes(args.scenes, args.size, lambda name, renderer: run_backs(name, args, renderer))
        block = backs_block(run, args)
        print("\n" + block)
        if args.md:
            path = write_between_markers(args.md, block, BACKS_BEGIN, BACKS_END, title="# Coverage\n\n")
            print(f"wrote {path}")
        return

    run = run_scenes(args.scenes, args.size, lambda name, renderer: run_scene(name, args, renderer))
    rows = run.rows

    def cell(r, method, lw):
        p, f = r[(method, lw)]
        return f"{p:.2f} / {f:.4f}"

    table = []
    for r in rows:
        d = {m: r[(m, "flat")][0] - r[(m, "off")][0] for m in ("volume", "splat")}
        table.append([r["scene"], r["camera"], f"{100 * r['closed']:.0f} %", f"{r['cover']:.3f}",
                      *(cell(r, m, lw) for m in ("volume", "splat") for lw in LAWS),
                      f"{d['volume']:+.2f}", f"{d['splat']:+.2f}"])  # fmt: skip
    parts = [
        BEGIN,
        run.header(f"demos/bench_thin_solids.py {' '.join(args.scenes)} --size {args.size}") + " "
        f"Texture {args.resolution}^3, K = {args.directions}; truth {args.gt_ssaa}x{args.gt_ssaa} polygons; "
        "PSNR (dB) / FLIP inside the object's box, as the corpus bench. Closed: the share of the mesh's faces "
        "on closed surfaces; cover: the mean entry cover (flat law). Δ: flat - off, PSNR.",
        "",
        markdown_table(["scene", "camera", "closed", "cover",
                        *(f"{m} {lw}" for m in ("volume", "splat high") for lw in LAWS),
                        "Δ volume", "Δ splat"], table),  # fmt: skip
        END,
    ]
    block = "\n".join(parts)
    print("\n" + block)
    if args.md:
        path = write_between_markers(args.md, block, BEGIN, END, title="# Coverage\n\n")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
