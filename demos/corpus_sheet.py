"""The scene corpus at a glance: a contact sheet and a table of sizes.

For every scene of ``aniso3d.scenes.CORPUS`` at its default size: the polygon
ground truth (the mesh renderer at ``--ssaa`` x ``--ssaa`` samples per pixel,
the camera of ``aniso3d render``: azimuth 30, elevation 15 degrees, fitted to
the mesh) as one tile of the sheet, and a row of the table: triangles, bounds,
what the scene stresses, the mesh as binary PLY (12 bytes per float32 vertex,
13 per triangle: a count byte and three int32 indices) against the
anisotropic texture built at ``--resolution`` (``AnisoTexture.nbytes``: the
in-memory arrays, K = ``--directions``), and the build time (wall clock and
the process's CPU time, steadier on a shared machine).

The sheet goes to ``--out`` and the table to stdout and, with ``--md``,
between the markers ``<!-- corpus:begin -->`` and ``<!-- corpus:end -->`` of
that Markdown file (created if missing), so the prose around them is kept.

    .venv/bin/python demos/corpus_sheet.py [--out docs/corpus.png] [--md docs/corpus.md]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

import aniso3d
from aniso3d.build import scenes
from aniso3d.build.texture import DEFAULT_DIRECTIONS
from aniso3d.files import atomic_write
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.images import save_png
from aniso3d.rendering.renderer import Renderer

BEGIN, END = "<!-- corpus:begin -->", "<!-- corpus:end -->"

#: What each scene is there to test.
STRESSES = {
    "tree": "the paper's object: leaves about a voxel, thin twigs, a trunk",
    "bush": "sub-voxel foliage: 250k leaves under half a voxel, many per voxel, partial coverage",
    "grass": "thin, long strips over a ground: coverage that depends strongly on the view",
    "lattice": "thin straight beams (under a voxel wide) at an angle to the grid: aliasing along lines",
    "fur": "long, overlapping sub-voxel strands with a specular sheen",
    "shell": "one open, single-sided layer: two-sided surface with no inside",
    "blob": "a closed, smooth, glossy surface that must render opaque",
    "room": "facets exactly on grid planes (the outermost ones too): the half-open cell rule",
    "mixed": "all scales in one grid: sub-voxel leaves, a tree, beams, a closed object, a large ground",
}


def camera_for(mesh: aniso3d.Mesh, azimuth: float = 30.0, elevation: float = 15.0) -> Camera:
    """The default camera of ``aniso3d render`` for a square image."""
    az, el = np.radians(azimuth), np.radians(elevation)
    direction = (np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el))
    pts = mesh.vertices[:: max(1, len(mesh.vertices) // 50_000)]
    return Camera.fit(mesh.bounds, direction=direction, points=pts)


def ply_bytes(mesh: aniso3d.Mesh) -> int:
    """Size of the mesh as binary PLY without materials (header not counted)."""
    return 12 * len(mesh.vertices) + 13 * mesh.n_faces


def fmt_bytes(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    raise AssertionError


def label(tile: np.ndarray, text: str, font) -> np.ndarray:
    img = Image.fromarray(tile)
    ImageDraw.Draw(img).text((8, 6), text, fill=(30, 30, 30), font=font)
    return np.asarray(img)


def sheet(tiles: list[np.ndarray], columns: int) -> np.ndarray:
    h, w, c = tiles[0].shape
    rows = -(-len(tiles) // columns)
    out = np.full((rows * h, columns * w, c), 255, np.uint8)
    for i, t in enumerate(tiles):
        r, col = divmod(i, columns)
        out[r * h : (r + 1) * h, col * w : (col + 1) * w] = t
    return out


def table(rows: list[dict], resolution: int, directions: int) -> str:
    head = (
        f"| scene | triangles | bounds (min .. max) | stresses | mesh PLY | texture at {resolution}^3, K = "
        f"{directions} | texture / mesh | occupied voxels | grid | build s (CPU s) |\n"
        "|---|---:|---|---|---:|---:|---:|---:|---|---:|\n"
    )
    lines = []
    for r in rows:
        lo, hi = r["bounds"]
        b = f"({', '.join(f'{v:.2f}' for v in lo)}) .. ({', '.join(f'{v:.2f}' for v in hi)})"
        lines.append(
            f"| {r['name']} | {r['triangles']:,} | {b} | {STRESSES[r['name']]} | {fmt_bytes(r['ply_bytes'])} | "
            f"{fmt_bytes(r['texture_bytes'])} | {r['texture_bytes'] / r['ply_bytes']:.1f} | {r['voxels']:,} | "
            f"{' x '.join(str(int(s)) for s in r['shape'])} | {r['build_s']:.1f} ({r['cpu_s']:.1f}) |"
        )
    return head + "\n".join(lines) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="docs/corpus.png", help="contact sheet PNG")
    p.add_argument("--md", default=None, help="Markdown file to put the table in (between the markers)")
    p.add_argument("--tile", type=int, default=320, help="tile size, pixels")
    p.add_argument("--ssaa", type=int, default=4, help="ground-truth supersampling per axis")
    p.add_argument("--resolution", type=int, default=128)
    p.add_argument("--directions", type=int, default=DEFAULT_DIRECTIONS)
    p.add_argument("--columns", type=int, default=3)
    args = p.parse_args()

    font = ImageFont.load_default(size=max(12, args.tile // 18))
    rows, tiles = [], []
    with Renderer((args.tile, args.tile)) as r:
        for name, mesh in scenes.corpus():
            t0, c0 = time.perf_counter(), time.process_time()
            tex = aniso3d.build_texture(mesh, args.resolution, args.directions)
            build_s, cpu_s = time.perf_counter() - t0, time.process_time() - c0
            rows.append({
                "name": name, "triangles": mesh.n_faces, "bounds": mesh.bounds.tolist(),
                "ply_bytes": ply_bytes(mesh), "texture_bytes": tex.nbytes, "voxels": tex.n_voxels,
                "shape": tex.shape.tolist(), "build_s": build_s, "cpu_s": cpu_s,
            })  # fmt: skip
            img = r.render(mesh, camera_for(mesh), "mesh", ssaa=args.ssaa)
            tiles.append(label(img, f"{name}  ({mesh.n_faces:,} triangles)", font))
            print(f"{name}: {mesh.n_faces} triangles, texture {tex.nbytes} B, build {build_s:.1f} s", flush=True)
            del tex
    save_png(args.out, sheet(tiles, args.columns))
    print(f"wrote {args.out}")

    machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    block = (
        f"{BEGIN}\n"
        f"Made by `demos/corpus_sheet.py` ({machine}; build seconds are wall-clock on a shared machine, "
        "CPU seconds of the process beside them).\n\n"
        + table(rows, args.resolution, args.directions)
        + f"{END}"
    )
    print(block)
    if args.md:
        path = Path(args.md)
        text = path.read_text() if path.exists() else ""
        if BEGIN in text and END in text:
            text = text[: text.index(BEGIN)] + block + text[text.index(END) + len(END) :]
        else:
            text = text + ("\n" if text and not text.endswith("\n") else "") + block + "\n"
        atomic_write(path, text.encode())
        print(f"wrote the table into {path}")


if __name__ == "__main__":
    main()
