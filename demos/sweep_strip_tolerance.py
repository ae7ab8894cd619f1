"""How near a fitted strip's centroid must come to its facets' for an entry
to be drawn as a strip (render/sheet_strips.py ``STRIP_TOLERANCE``), swept.

Per scene (corpus names, or mesh files), at the corpus bench's two cameras,
the volume renderer's PSNR (dB) / FLIP inside the object's box against the
polygons at 8 x 8 samples, beside the polygons at 1 and 2 x 2 samples, for
each tolerance of ``--values`` (voxel units). A strip localises its entry's
coverage between two lines; an entry that is none spreads its fill over its
plane's whole section of the voxel. Each value is drawn by a renderer made
while it is set (the strips are fitted at upload).

    .venv/bin/python demos/sweep_strip_tolerance.py [SCENE | MESH FILE ...] [--values 0.03 0.1 0.2]
        [--frames 5] [--md docs/coverage.md]

``--frames N`` also times N frames of each value after the first.
"""

from __future__ import annotations

from aniso3d.bench.outputs import markdown_table
from aniso3d.bench.variants import (
    command,
    corpus_parser,
    ms,
    pair,
    publish,
    run_corpus_demo,
    scene_cameras,
    scene_or_mesh,
    scored,
)
from aniso3d.build import scenes
from aniso3d.build.texture import build_texture
from aniso3d.rendering import sheet_strips
from aniso3d.rendering.renderer import Renderer


def cell(row: dict, value: float) -> str:
    """PSNR / FLIP, and with frames timed the median frame time [fastest-slowest], ms."""
    times = row[f"{value} ms"]
    return pair(row[value]) + (f", {ms(times)} ms" if times else "")


def run_scene(name: str, args, renderer: Renderer) -> list[dict]:
    mesh, label = scene_or_mesh(name)
    tex = build_texture(mesh, args.resolution, args.directions)
    keep = sheet_strips.STRIP_TOLERANCE
    rows = []
    for spec, truth, row in scene_cameras(renderer, mesh, label, args):
        for value in args.values:
            sheet_strips.STRIP_TOLERANCE = value
            times = []
            try:
                with Renderer((args.size, args.size)) as own:
                    img = own.render(tex, spec.camera, "volume")
                    for _ in range(args.frames):
                        own.render(tex, spec.camera, "volume")
                        times.append(own.last_frame_seconds)
            finally:
                sheet_strips.STRIP_TOLERANCE = keep
            row[value] = scored(truth, img[..., :3], spec)
            row[f"{value} ms"] = times
        print(f"  {spec.label}: " + ", ".join(f"{v}: {cell(row, v)}" for v in args.values), flush=True)
        rows.append(row)
    return rows


def main() -> None:
    ap = corpus_parser(__doc__.splitlines()[0], scenes.CORPUS)
    ap.add_argument("--values", type=float, nargs="+", default=[0.03, 0.1, 0.2, 0.3, 0.5])
    ap.add_argument("--frames", type=int, default=0, help="frames timed per value after the first (0: none)")
    args = ap.parse_args()
    run = run_corpus_demo(args, run_scene)
    head = ["scene", "camera", "1 spp", "2x2", *(f"volume, {v}" for v in args.values)]
    table = [[r["scene"], r["camera"], pair(r["1 spp"]), pair(r["2x2"]), *(cell(r, v) for v in args.values)]
             for r in run.rows]  # fmt: skip
    extra = ["--values", *(str(v) for v in args.values)] + (["--frames", str(args.frames)] if args.frames else [])
    parts = [
        f"{run.header(command('demos/sweep_strip_tolerance.py', args, *extra))} Texture {args.resolution}^3, "
        f"K = {args.directions}; truth {args.gt_ssaa}x{args.gt_ssaa} polygons; PSNR (dB) / FLIP inside the "
        f"object's box, as the corpus bench; STRIP_TOLERANCE per column (default {sheet_strips.STRIP_TOLERANCE})"
        + (f"; volume frame time, median [fastest-slowest] of {args.frames} frames after one, through "
           "`Renderer.last_frame_seconds` (draw and read back)." if args.frames else "."),
        "",
        markdown_table(head, table),
    ]
    block = "sweep_strip_tolerance_frames" if args.frames else "sweep_strip_tolerance"
    publish(parts, args.md, f"<!-- {block}: begin -->", f"<!-- {block}: end -->", "Volume coverage")


if __name__ == "__main__":
    main()
