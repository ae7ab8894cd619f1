"""The extreme cases of issue 6 at full size: a table of case, result, time.

    .venv/bin/python demos/stress.py                # everything (~10 min, 2 cores)
    .venv/bin/python demos/stress.py --quick        # the same cases, smaller
    .venv/bin/python demos/stress.py --only tree-512 soup-1M

Each case runs in its own subprocess, so "peak" is that case's own peak RSS
(interpreter and imports included, ~130 MB). A case passes when its result
meets what tests/test_extremes.py holds the small version to; the "result"
column says what was measured. Exit status 1 if any case fails.

Build cases check, against the mesh in float64:
- area: registered area / mesh area - 1;
- identity: max over the K samples of |sum_v D_v(p) h^2 - sum_f A_f |N_f . N_p||
  relative to the mesh area (the registration identity of METHOD.md).
Render cases compare images: "differing" is the fraction of pixels whose
colour differs by more than 2 levels of 255.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from dataclasses import replace

import numpy as np

FAR = np.array([1.0e7, -3.0e6, 2.0e7])


# ------------------------------------------------------------------- helpers


def identity_error(tex, mesh) -> float:
    t = mesh.triangles
    cross = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    want = np.zeros(len(tex.directions))
    for s in range(0, len(cross), 1 << 16):  # (F, K) in slices
        want += 0.5 * np.abs(cross[s : s + (1 << 16)] @ tex.directions.T).sum(axis=0)
    got = tex.density.sum(axis=0) * tex.voxel_size**2
    return float(np.abs(got - want).max() / mesh.area())


def build_summary(tex, mesh) -> tuple[str, bool]:
    area = tex.total_area() / mesh.area() - 1
    ident = identity_error(tex, mesh)
    ok = abs(area) < 1e-11 and ident < 1e-11
    shape = "x".join(str(int(s)) for s in tex.shape)
    return (
        f"grid {shape}, {tex.n_voxels:,} voxels, {tex.meta['n_subpolygons']:,} pieces; "
        f"area {area:+.1e}, identity {ident:.1e}"
    ), ok


def moved(mesh, scale=1.0, shift=(0.0, 0.0, 0.0)):
    m = np.eye(4)
    m[:3, :3] *= scale
    m[:3, 3] = shift
    return mesh.transformed(m)


def differing(a, b, levels=2) -> float:
    d = np.abs(a[:, :, :3].astype(int) - b[:, :, :3].astype(int)).max(axis=2)
    return float(np.mean(d > levels))


# --------------------------------------------------------------------- cases


def case_tree_512(quick):
    from aniso3d import build_texture, scenes

    mesh = scenes.tree()
    res = 192 if quick else 512
    tex = build_texture(mesh, res, 64)
    text, ok = build_summary(tex, mesh)
    return f"default tree ({mesh.n_faces:,} tris) at {res}: " + text, ok


def case_resolution_1_2(quick):
    from aniso3d import build_texture, scenes

    mesh = scenes.tree()
    out, ok = [], True
    for res in (1, 2):
        tex = build_texture(mesh, res, 64)
        text, good = build_summary(tex, mesh)
        out.append(f"r={res}: {tex.n_voxels} voxels, " + text.split("; ", 1)[1])
        ok &= good
    return "; ".join(out), ok


def case_k_1024(quick):
    from aniso3d import build_texture, scenes

    mesh = scenes.tree(levels=5)
    k = 256 if quick else 1024
    tex = build_texture(mesh, 128, k)
    text, ok = build_summary(tex, mesh)
    return f"tree levels=5 ({mesh.n_faces:,} tris), K={k}: " + text, ok


def case_k_1(quick):
    from aniso3d import build_texture, scenes

    mesh = scenes.tree()
    tex = build_texture(mesh, 128, 1)
    text, ok = build_summary(tex, mesh)
    ok &= tex.n_entries == tex.n_voxels
    return "default tree, K=1 (one entry per voxel): " + text, ok


def _invariance(quick, scale, shift):
    from aniso3d import build_texture, scenes

    mesh = scenes.tree()
    res = 64 if quick else 128
    a = build_texture(mesh, res, 64)
    other = moved(mesh, scale, shift)
    b = build_texture(other, res, 64)
    same = np.array_equal(a.coords, b.coords) and np.array_equal(
        a.entry_direction, b.entry_direction
    )
    if not same:
        return f"voxels or entries differ ({a.n_voxels} vs {b.n_voxels} voxels)", False
    h = a.voxel_size
    dd = np.abs(a.density - b.density).max()
    # centroids as first moments A |dc| (h^3): see tests/test_extremes.py
    dc = (
        a.entry_area * np.linalg.norm((b.entry_centroid - shift) / scale - a.entry_centroid, axis=1)
    ).max() / h
    area = b.total_area() / other.area() - 1
    # stated tolerances: 100 ulp(|x|max)/h for a move to 1e7, 1e-12 for a scale
    tol = 100 * np.spacing(np.abs(shift).max()) / h if np.any(shift) else 1e-12
    tol_d = tol if np.any(shift) else tol * max(1.0, float(a.density.max()))
    ok = dd <= tol_d and dc <= tol and abs(area) < 1e-11
    return (
        f"default tree at {res}: same {a.n_voxels:,} voxels and entries; max |dD| {dd:.1e} h^2, "
        f"centroid moments {dc:.1e} h^3 (tolerance {tol:.0e}); area {area:+.1e}"
    ), ok


def case_far_1e7(quick):
    return _invariance(quick, 1.0, FAR)


def case_tiny_1e6(quick):
    return _invariance(quick, 1e-6, np.zeros(3))


def case_soup_1m(quick):
    from aniso3d import Mesh, build_texture

    n = 100_000 if quick else 1_000_000
    rng = np.random.default_rng(0)
    centre = rng.uniform(0, 1, (n, 1, 3))
    tri = centre + rng.normal(scale=0.01, size=(n, 3, 3))
    mesh = Mesh.from_arrays(tri.reshape(-1, 3), np.arange(3 * n).reshape(-1, 3), name="soup")
    tex = build_texture(mesh, 128, 64)
    text, ok = build_summary(tex, mesh)
    return f"{n:,} random triangles (edge ~0.01) at 128: " + text, ok


def case_tiny_triangles(quick):
    # 1e-12 m^2 triangles on grid points of a 10 m world beside 1e-6 ones
    from aniso3d import Mesh, build_texture, sphere_directions

    n = 20_000 if quick else 200_000
    rng = np.random.default_rng(3)
    res, size = 512, 10.0
    h = size / res
    d = sphere_directions(64)

    def tris(corners, area, normal):
        t1 = np.cross(normal, [0.3, 0.5, 0.8])
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(normal, t1)
        e = np.sqrt(2 * area)
        return corners[:, None] + np.stack([0 * t1, e * t1, e * t2])[None]

    big = tris(rng.uniform(0, size, (n, 3)), 1e-6, d[40])
    at = np.round(rng.uniform(0, size, (n, 3)) / h) * h + rng.uniform(-1e-7, 1e-7, (n, 3))
    tiny = tris(at, 1e-12, d[10])
    all_tris = np.concatenate([big, tiny])
    mesh = Mesh.from_arrays(all_tris.reshape(-1, 3), np.arange(6 * n).reshape(-1, 3))
    tex = build_texture(mesh, res, 64, bounds=np.array([[0.0] * 3, [size] * 3]))
    areas = mesh.face_areas()
    got = (tex.entry_area * h * h)[tex.entry_direction == 10].sum()
    err = got / areas[n:].sum() - 1
    return (
        f"{n:,} tris of 1e-12 m^2 on grid points + {n:,} of 1e-6, 10 m world at {res}: "
        f"tiny ones' registered area {err:+.1e}"
    ), abs(err) < 1e-9


def case_dense(quick):
    from aniso3d import Mesh, build_texture

    layers = 100 if quick else 1000
    z = (np.arange(layers) + 0.5) / layers
    q = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    v = np.concatenate([np.c_[q, np.full(4, zz)] for zz in z])
    f = np.concatenate([np.array([[0, 1, 2], [0, 2, 3]]) + 4 * i for i in range(layers)])
    mesh = Mesh.from_arrays(v, f)
    tex = build_texture(mesh, 1, 64, bounds=np.array([[0.0] * 3, [1.0] * 3]))
    cov = tex.coverage(np.array([0, 0, 1.0]))[0]
    want = layers * np.abs(tex.directions[np.argmax(np.abs(tex.directions[:, 2]))][2])
    ok = abs(cov - want) <= 1e-12 * layers
    return f"{layers} sheets in one voxel: coverage along z {cov:.6f} (kept, not clamped)", ok


def case_memory_refusal(quick):
    from aniso3d import InputError, build_texture, scenes
    from aniso3d.build.texture import _available_memory

    mesh = scenes.tree()
    t0 = time.perf_counter()
    try:
        build_texture(mesh, 2048, 4096)
    except InputError as exc:
        return f"tree at 2048 with K=4096 refused in {time.perf_counter() - t0:.2f} s: {exc}", True
    return f"not refused ({_available_memory()} bytes available)", False


def _renderer():
    from aniso3d.rendering.renderer import Renderer

    return Renderer((512, 512))


def case_render_far(quick):
    # telephoto from 1e3 .. 1e7 radii: the same picture (to 0.5% of pixels)
    from aniso3d import build_texture, scenes
    from aniso3d.rendering.camera import Camera

    sphere = scenes.sphere(1.0, subdivisions=5, center=(0.3, 0.2, 0.0))
    tex = build_texture(sphere, 64, 64)
    things = {"mesh": sphere, "volume": tex, "splat": tex.to_points()}
    out, ok = [], True
    with _renderer() as r:
        for method, thing in things.items():
            opts = {"quality": "high"} if method == "splat" else {}

            def cam(d):
                fov = 2 * np.degrees(np.arctan(np.tan(np.radians(20)) * 5.0 / d))
                return Camera((0, 0, d), (0, 0, 0), fov=fov)

            ref = r.render(thing, cam(1e3), method, **opts)
            worst = []
            for d in (1e4, 1e5, 1e6, 1e7):
                worst.append(differing(r.render(thing, cam(d), method, **opts), ref))
            good = [w <= 0.005 for w in worst]
            ok &= all(good)
            out.append(f"{method} " + "/".join(f"{100 * w:.1f}%" for w in worst))
    return "pixels differing from 1e3 radii away, at 1e4/1e5/1e6/1e7: " + ", ".join(out), ok


def case_render_1e7(quick):
    # the default tree and its texture moved by 1e7, camera with it
    from aniso3d import PointCloud, build_texture, scenes
    from aniso3d.rendering.camera import Camera

    tree = scenes.tree(levels=5 if quick else 6)
    tree = moved(tree)  # a copy
    v = np.round(tree.vertices * 2.0**20) / 2.0**20  # so the move is exact
    from aniso3d import Mesh

    tree = Mesh(v, tree.faces, tree.kd, tree.ks, tree.shininess)
    tex = build_texture(tree, 128, 64)
    pts = tex.to_points()
    far_tex = replace(tex, origin=tex.origin + FAR, entry_centroid=tex.entry_centroid + FAR)
    far_pts = PointCloud(pts.positions + FAR, pts.normals, pts.areas, pts.kd, pts.ks, pts.shininess)
    c0 = Camera((9.0, 8.0, 12.0), (0.0, 5.0, 0.0), fov=45)
    c1 = Camera(tuple(FAR + c0.position), tuple(FAR + c0.target), fov=45)
    out, ok = [], True
    with _renderer() as r:
        for method, a, b in (
            ("mesh", tree, moved(tree, shift=FAR)),
            ("volume", tex, far_tex),
            ("splat", pts, far_pts),
        ):
            d = differing(r.render(a, c0, method), r.render(b, c1, method), levels=1)
            ok &= d <= 0.002
            out.append(f"{method} {100 * d:.2f}%")
    return "tree at 1e7 vs at origin, pixels differing: " + ", ".join(out), ok


def case_render_inside(quick):
    # camera inside a sphere: the inside all around
    from aniso3d import scenes
    from aniso3d.rendering.camera import Camera

    sphere = scenes.sphere(1.0, subdivisions=5)
    cam = Camera((0.2, -0.1, 0.1), (1.0, 0.3, 0.5), fov=90)
    out, ok = [], True
    with _renderer() as r:
        for method in ("mesh", "volume", "splat"):
            # options under which each method draws a closed surface opaque
            # (see tests/test_extremes.py: SOLID)
            opts = {
                "mesh": {},
                "volume": {"opacity": "linear"},
                "splat": {"splat": "square", "size_factor": 1.5},
            }[method]
            if method != "mesh":
                opts.update(resolution=64, directions=64)
            img = r.render(sphere, cam, method, alpha=True, **opts)
            a = img[:, :, 3] / 255
            # a single voxel layer's coverage varies per ray (volume), splats
            # may leave pin holes; garbage would be a blank or black view
            ok &= a.mean() > 0.85 and np.mean(a == 0) < 0.01 and img[:, :, :3].mean() > 20
            out.append(
                f"{method} alpha mean {a.mean():.2f}, {100 * np.mean(a == 0):.2f}% uncovered"
            )
    return "camera inside a sphere, 512x512: " + ", ".join(out), ok


CASES = {
    "tree-512": case_tree_512,
    "resolution-1-2": case_resolution_1_2,
    "k-1024": case_k_1024,
    "k-1": case_k_1,
    "far-1e7": case_far_1e7,
    "tiny-1e-6": case_tiny_1e6,
    "soup-1M": case_soup_1m,
    "tiny-triangles": case_tiny_triangles,
    "dense-voxel": case_dense,
    "memory-refusal": case_memory_refusal,
    "render-far-camera": case_render_far,
    "render-at-1e7": case_render_1e7,
    "render-inside": case_render_inside,
}


def run_case(name: str, quick: bool) -> dict:
    t0 = time.perf_counter()
    try:
        result, ok = CASES[name](quick)
    except Exception as exc:  # a crash is a result too
        result, ok = f"CRASHED: {type(exc).__name__}: {exc}", False
    return {
        "case": name,
        "result": result,
        "ok": bool(ok),
        "seconds": time.perf_counter() - t0,
        "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="smaller sizes, same cases")
    ap.add_argument("--only", nargs="*", choices=list(CASES), help="run these cases only")
    ap.add_argument("--case", help=argparse.SUPPRESS)  # worker mode
    args = ap.parse_args()
    if args.case:
        print(json.dumps(run_case(args.case, args.quick)))
        return 0
    rows = []
    for name in args.only or CASES:
        cmd = [sys.executable, __file__, "--case", name] + (["--quick"] if args.quick else [])
        proc = subprocess.run(cmd, capture_output=True, text=True)
        try:
            row = json.loads(proc.stdout.strip().splitlines()[-1])
        except (IndexError, json.JSONDecodeError):
            row = {
                "case": name,
                "result": f"worker died (status {proc.returncode}): {proc.stderr[-300:]}",
                "ok": False,
                "seconds": float("nan"),
                "peak_mib": float("nan"),
            }
        rows.append(row)
        print(
            f"{row['case']:<18} {'ok  ' if row['ok'] else 'FAIL'} {row['seconds']:7.1f} s "
            f"{row['peak_mib']:7.0f} MiB  {row['result']}",
            flush=True,
        )
    print()
    print("| case | ok | result | time | peak RSS |")
    print("|---|---|---|---|---|")
    for row in rows:
        print(
            f"| {row['case']} | {'yes' if row['ok'] else '**no**'} | {row['result']} | "
            f"{row['seconds']:.1f} s | {row['peak_mib']:.0f} MiB |"
        )
    return 0 if all(r["ok"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
