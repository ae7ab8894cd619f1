"""What the compact texture encoding (``.a3d`` version 7) costs in bytes and in image error.

Per scene: the mesh, built at ``--resolution`` with K = ``--directions``
(``build_texture``), its sizes (the mesh as a binary PLY: 12 bytes a vertex,
13 a triangle; the texture in memory, which is also what a version 1 file
stored; the compact file :meth:`AnisoTexture.save` writes by default), and
per stored field its compressed bytes in that file and what quantising that
field alone does to the images: PSNR against the polygons at ``--gt-ssaa``
x ``--gt-ssaa`` samples per pixel, of the volume renderer and of the
high-quality splats, from the texture with that one field as the file
stores it and every other field as built, minus the same from the texture
as built. ``all`` quantises everything (what loading the file gives);
``density`` is the density sphere as the file gives it (the entries' own
``F`` plus a coarse residual); the ``... N bits`` rows try finer
bit counts for one field (``--bits`` measures other defaults). PSNR inside the object's box in the truth image
(its pixels with alpha > 0, plus 8 px), 8-bit values.

Scenes are names of ``aniso3d.build.scenes.SCENES``, ``tree8``
(``scenes.tree(levels=8)``, about 4M triangles) or ``tilted`` (a square
turned off the axes); unknown names are skipped with a note. The table goes to stdout and, with ``--md``, between the
markers ``<!-- bench_encoding:begin -->`` and ``<!-- bench_encoding:end -->``
of that Markdown file (the prose around them is kept).

    .venv/bin/python demos/bench_encoding.py [tree tree8 cube sphere ...] \\
        [--size 512] [--md docs/encoding.md]
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import tempfile
import time
import zipfile
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from aniso3d.bench.outputs import markdown_table, write_between_markers
from aniso3d.build import scenes
from aniso3d.build.encoding import DEFAULT_BITS, facet_density
from aniso3d.build.mesh import Mesh
from aniso3d.build.texture import AnisoTexture, build_texture
from aniso3d.build.texture_file import FORMAT_VERSION
from aniso3d.metrics import psnr
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.renderer import Renderer

BEGIN, END = "<!-- bench_encoding:begin -->", "<!-- bench_encoding:end -->"
DEFAULT_SCENES = ("tree", "tree8", "cube", "sphere", "quad", "tilted", "bush", "grass", "lattice", "fur",
                  "shell", "blob", "room", "mixed")  # fmt: skip
AZIMUTH, ELEVATION = 30.0, 15.0

#: Field -> (texture arrays it sets, file members that store it).
FIELDS = {
    "area": (("entry_area",), ("entry_area",)),
    "normal": (("entry_normal",), ("entry_normal", "entry_coherence")),
    "centroid": (("entry_centroid",), ("entry_centroid",)),
    "kd": (("entry_kd",), ("entry_kd",)),
    "ks, shininess": (("entry_ks", "entry_shininess"), ("entry_ks", "entry_shininess")),
    "density": (("density",), ("density",)),
}
#: Everything else in the file: the grid, the sample directions, the cells,
#: which sample directions each voxel has entries at and which entries copy a
#: neighbour's normal and materials (exact), the header.
STRUCTURE = ("origin", "shape", "directions", "coords", "entry_mask", "entry_parent")
#: Which entries lie on closed surfaces, and on which side (version 6;
#: exact): a row of its own, bytes only (a texture as built knows them).
SIDES = ("entry_side",)

#: (row name, field, bits changed): other bit counts tried for one field
#: (coarser and finer than the defaults: what each bit saves or costs and buys).
ALTERNATIVES = (
    ("density derived, 0 bits", "density", {"density": 0}),
    ("density 8 bits", "density", {"density": 8}),
    ("area 10 bits", "area", {"area": 10}),
    ("area 12 bits", "area", {"area": 12}),
    ("normal 9 bits", "normal", {"normal": 9}),
    ("normal 11 bits", "normal", {"normal": 11}),
    ("normal length 6 bits", "normal", {"coherence": 6}),
    ("centroid 8 bits", "centroid", {"centroid": 8, "centroid_closed": 8}),
    ("centroid closed 6 bits", "centroid", {"centroid_closed": 6}),
    ("centroid depth 10 bits", "centroid", {"depth": 10}),
    ("centroid depth 14 bits", "centroid", {"depth": 14}),
    ("kd 8 bits", "kd", {"kd": 8}),
)

RENDERS = (("volume", {}), ("splat", {"quality": "high"}))


def tilted() -> Mesh:
    """A unit square turned off every axis (normal about (0.3, 0.5, 0.81)):
    a flat surface whose centroids and normals fall between the grid's steps."""
    q = scenes.quad()
    a, b = np.radians(31.0), np.radians(17.0)
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    return Mesh.from_arrays(q.vertices @ (ry @ rx).T, q.faces, q.kd, q.ks, q.shininess, name="tilted")


#: Scenes made here: the 4M-triangle tree and a tilted square.
EXTRA = {"tree8": lambda: scenes.tree(levels=8), "tilted": tilted}


def get_mesh(name: str) -> Mesh | None:
    if name in EXTRA:
        return EXTRA[name]()
    if name not in scenes.SCENES:
        return None
    return scenes.SCENES[name]()


def ply_bytes(mesh: Mesh) -> int:
    """A binary PLY of the mesh: float32 xyz per vertex, a count byte and three int32 per triangle."""
    return 12 * len(mesh.vertices) + 13 * mesh.n_faces


def member_bytes(tex: AnisoTexture, bits, folder: Path, times: dict | None = None) -> tuple[int, dict[str, int]]:
    """File size of the compact encoding and each member's compressed bytes
    (its zip local header included); the header member and the zip's
    directory are counted under ``header``. With ``times``, the seconds
    :meth:`AnisoTexture.save` and :meth:`AnisoTexture.load` took go there."""
    t0 = time.perf_counter()
    path = tex.save(folder / "x.a3d", bits=bits)
    if times is not None:
        times["save"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        AnisoTexture.load(path)
        times["load"] = time.perf_counter() - t0
    size = path.stat().st_size
    out = {}
    with zipfile.ZipFile(path) as zf:
        for info in zf.infolist():
            out[info.filename.removesuffix(".npy")] = info.compress_size + 30 + len(info.filename)
    out["header"] = size - sum(v for k, v in out.items() if k != "header.json")
    out.pop("header.json")
    return size, out


def hybrid(tex: AnisoTexture, stored: AnisoTexture, names: tuple[str, ...]) -> AnisoTexture:
    """``tex`` with the arrays ``names`` taken from ``stored``."""
    return replace(tex, **{n: getattr(stored, n) for n in names})


def crop(alpha: np.ndarray, margin: int = 8) -> tuple[slice, slice]:
    ys, xs = np.nonzero(alpha > 0)
    if not len(ys):
        return slice(None), slice(None)
    h, w = alpha.shape
    return (slice(max(0, ys.min() - margin), min(h, ys.max() + 1 + margin)),
            slice(max(0, xs.min() - margin), min(w, xs.max() + 1 + margin)))  # fmt: skip


def direction() -> tuple[float, float, float]:
    a, e = math.radians(AZIMUTH), math.radians(ELEVATION)
    return (math.sin(a) * math.cos(e), math.sin(e), math.cos(a) * math.cos(e))


def mib(n: float) -> str:
    return f"{n / 2**20:.2f} MiB" if n >= 2**20 else f"{n / 2**10:.1f} KiB"


def run_scene(name: str, mesh: Mesh, args, gl: GLContext, folder: Path) -> dict:
    t0 = time.perf_counter()
    tex = build_texture(mesh, args.resolution, args.directions)
    build_s = time.perf_counter() - t0
    times: dict[str, float] = {}
    size, members = member_bytes(tex, args.bits, folder, times)
    stored = tex.as_stored(args.bits)
    dens = np.asarray(tex.density)
    derived = facet_density(tex.entry_area, tex.entry_normal, tex.entry_offsets, tex.directions)
    cams = [Camera.fit(mesh.bounds, direction=direction(), aspect=1.0, distance_scale=s) for s in args.scales]
    res = {
        "name": name, "triangles": mesh.n_faces, "vertices": len(mesh.vertices), "voxels": tex.n_voxels,
        "entries": tex.n_entries, "ply": ply_bytes(mesh), "memory": tex.memory_nbytes, "file": size,
        "members": members, "build_s": build_s, "rows": [], "save_s": times["save"], "load_s": times["load"],
        "derived_l1": float(np.abs(dens - derived).sum() / max(dens.sum(), 1e-300)),
    }  # fmt: skip
    variants = [("all", None, stored)]
    variants += [(field, field, hybrid(tex, stored, arrays)) for field, (arrays, _) in FIELDS.items()]
    for row, field, change in ALTERNATIVES if args.alternatives else ():
        bits = replace(args.bits, **change)
        _, alt_members = member_bytes(tex, bits, folder)
        variants.append((row, field, hybrid(tex, tex.as_stored(bits), FIELDS[field][0])))
        res.setdefault("alt_bytes", {})[row] = sum(alt_members.get(m, 0) for m in FIELDS[field][1])
    size2 = (args.size, args.size)
    truths = []
    r = Renderer(size2, gl=gl)
    try:
        for cam in cams:
            gt = r.render(mesh, cam, "mesh", ssaa=args.gt_ssaa, alpha=True)
            truths.append((gt[..., :3], crop(gt[..., 3])))
    finally:
        r.release()

    def score(thing: AnisoTexture) -> list[float]:
        out = []
        rr = Renderer(size2, gl=gl)
        try:
            for method, opts in RENDERS:
                vals = []
                for cam, (truth, (ys, xs)) in zip(cams, truths, strict=True):
                    img = rr.render(thing, cam, method, **opts)
                    vals.append(psnr(truth[ys, xs], img[ys, xs]))
                out.append(float(np.mean(vals)))
        finally:
            rr.release()
        return out

    base = score(tex)
    res["base"] = base
    for row, field, thing in variants:
        got = score(thing)
        res["rows"].append((row, field, [g - b for g, b in zip(got, base, strict=True)]))
        print(f"  {name} {row:18s} " + " ".join(f"{d:+.3f}" for d in res["rows"][-1][2]), flush=True)
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=list(DEFAULT_SCENES))
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=16)
    ap.add_argument("--gt-ssaa", type=int, default=8)
    ap.add_argument("--scales", type=float, nargs="+", default=[1.0, 2.3],
                    help="camera distance scales (Camera.fit distance_scale); PSNR is their mean")
    ap.add_argument("--no-alternatives", dest="alternatives", action="store_false",
                    help="skip the rows that try other bit counts")
    ap.add_argument("--bits", nargs="*", default=[], metavar="FIELD=N",
                    help="bits to measure instead of the defaults (aniso3d.build.encoding.Bits), e.g. centroid=7")
    ap.add_argument("--md", default="", help="Markdown file to write the tables into")
    args = ap.parse_args()
    args.bits = replace(DEFAULT_BITS, **{k: int(v) for k, v in (b.split("=") for b in args.bits)})

    started = time.time()
    load0 = os.getloadavg()
    results, skipped = [], []
    with GLContext("auto") as gl, tempfile.TemporaryDirectory() as tmp:
        gl_name = gl.renderer
        for name in args.scenes:
            mesh = get_mesh(name)
            if mesh is None:
                skipped.append(name)
                print(f"{name}: not a scene of aniso3d.build.scenes here; skipped")
                continue
            print(f"{name}: {mesh.n_faces:,} triangles", flush=True)
            results.append(run_scene(name, mesh, args, gl, Path(tmp)))
    load1 = os.getloadavg()
    minutes = (time.time() - started) / 60

    size_rows, field_rows = [], []
    for res in results:
        size_rows.append([
            res["name"], f"{res['triangles']:,}", f"{res['voxels']:,}", f"{res['entries']:,}",
            mib(res["ply"]), mib(res["memory"]), mib(res["file"]),
            f"{res['memory'] / res['ply']:.2f}", f"{res['file'] / res['ply']:.3f}",
            f"{res['memory'] / res['file']:.1f}", f"{res['file'] / res['voxels']:.1f}",
            f"{res['base'][0]:.2f}", f"{res['base'][1]:.2f}", f"{100 * res['derived_l1']:.2f}",
            f"{res['save_s']:.2f}", f"{res['load_s']:.2f}",
        ])  # fmt: skip
        members = res["members"]
        structure = sum(members.get(m, 0) for m in STRUCTURE) + members["header"]
        field_rows.append([res["name"], "structure", mib(structure), f"{structure / res['entries']:.2f}", "", ""])
        sides = sum(members.get(m, 0) for m in SIDES)
        field_rows.append([res["name"], "sides", f"{sides:,} B", f"{sides / res['entries']:.4f}", "", ""])
        for row, field, deltas in res["rows"]:
            if row in FIELDS:
                n = sum(members.get(m, 0) for m in FIELDS[field][1])
            elif row == "all":
                n = res["file"]
            else:
                n = res["alt_bytes"][row]
            field_rows.append([res["name"], row, mib(n), f"{n / res['entries']:.2f}",
                               f"{deltas[0]:+.3f}", f"{deltas[1]:+.3f}"])  # fmt: skip

    changed = {k: v for k, v in asdict(args.bits).items() if v != getattr(DEFAULT_BITS, k)}
    bits_arg = ("--bits " + " ".join(f"{k}={v}" for k, v in changed.items()) + " ") if changed else ""
    if not args.alternatives:
        bits_arg += "--no-alternatives "
    worst = {m: min((d[i] for res in results for row, _, d in res["rows"] if row == "all"), default=math.nan)
             for i, m in enumerate(("volume", "splat"))}  # fmt: skip
    parts = [
        BEGIN,
        f"Run {time.strftime('%Y-%m-%d %H:%M')} in {minutes:.1f} min on {gl_name}, {platform.machine()}, "
        f"{os.cpu_count()} CPUs, load average (1, 5, 15 min) {load0[0]:.1f} {load0[1]:.1f} {load0[2]:.1f} "
        f"at the start and {load1[0]:.1f} {load1[1]:.1f} {load1[2]:.1f} at the end; "
        f"`demos/bench_encoding.py {' '.join(args.scenes)} {bits_arg}--size {args.size} --resolution {args.resolution} "
        f"--directions {args.directions} --scales {' '.join(f'{s:g}' for s in args.scales)}`. "
        f"Images {args.size}x{args.size}, `Camera.fit(bounds, direction=(azimuth {AZIMUTH:g}, elevation "
        f"{ELEVATION:g}), aspect=1, distance_scale=s)`; PSNR against the polygons at {args.gt_ssaa}x"
        f"{args.gt_ssaa} samples per pixel, mean over the scales."
        + (f" Skipped (not in aniso3d.build.scenes here): {', '.join(skipped)}." if skipped else ""),
        "",
        "**Sizes.** PLY: the mesh as a binary PLY (12 B a vertex, 13 a triangle). Memory: the "
        "texture's arrays as built (`memory_nbytes`; a version 1 file stored these). File: the "
        f"compact file (format version {FORMAT_VERSION}) `save()` writes with `{args.bits}` "
        "(`nbytes` with the defaults). "
        "PSNR: of the texture as built. F vs D: the density sphere derived from the entries, "
        "`F_v(p) = sum_e A_e |n_e . N_p|`, against the registered one, `sum |D - F| / sum D`. "
        "Save, load: seconds of `save()` (encoding, compressing, writing) and `AnisoTexture.load` "
        "of that file, on this machine at the load stated.",
        "",
        markdown_table(["scene", "triangles", "voxels", "entries", "PLY", "memory", "file", "memory / PLY",
                  "file / PLY", "memory / file", "file B / voxel", "volume PSNR dB", "splat PSNR dB",
                  "F vs D %", "save s", "load s"],
                 size_rows),  # fmt: skip
        "",
        "**Per field.** Bytes of the field's members in the compact file (compressed, with the zip's "
        "local header) and per shading entry; ΔPSNR (dB) of the volume and of the high-quality splats "
        "when only that field is quantised (`all`: every field, i.e. the loaded file). Negative: worse. "
        "`sides`: the member `entry_side` (which entries lie on closed surfaces, and on which side; "
        "exact), in bytes.",
        "",
        markdown_table(["scene", "field", "bytes", "B / entry", "Δ volume", "Δ splat"], field_rows),
        "",
        f"Worst ΔPSNR of `all` over the scenes: volume {worst['volume']:+.3f} dB, "
        f"splat {worst['splat']:+.3f} dB.",
        END,
    ]
    block = "\n".join(parts)
    print("\n" + block)
    if args.md:
        path = write_between_markers(args.md, block, BEGIN, END, title="# Texture encoding\n\n")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
