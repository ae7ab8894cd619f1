"""Coverage of the volume renderer's opacity laws against supersampled polygons.

Each scene is drawn by the polygon renderer at 8 x 8 samples per pixel (the
truth) and by the volume renderer with each opacity law; per scene, case and
law the table gives, over the case's region:

- ``cover``: mean alpha of the volume; ``err``: minus the truth's (signed,
  absolute units of alpha);
- ``min``: the smallest alpha (for surfaces: 1 - the worst leak);
- ``a-rmse``: RMS alpha difference per pixel, over the whole image;
- ``psnr``: PSNR of the RGB image (on the white background), dB.

Regions: a *solid* case (planes, closed cube and sphere) is the truth's
opaque silhouette eroded by 2 pixels plus one voxel's projection (the
representation blurs an edge by up to a voxel); a *crown* case (leaf cloud)
is the disc of 0.8 times the crown's projected radius; anything else is
every pixel the truth covers at all.

    .venv/bin/python demos/bench_coverage.py [--scenes quad tilted cube sphere
        leaves tree] [--models exponential linear split planar ...] [--size 256]
        [--json out.json]

A model ``planar@fill=0.5:0.9,pixels=1:3`` draws "planar" with those
ramps (:data:`aniso3d.rendering.volume.SHEET_FILL`, ``SHEET_PIXELS``). Names of
:mod:`aniso3d.build.scenes` not listed here are benchmarked framed from
``(0.55, 0.35, 1)`` at resolution 64, region "any".
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

import aniso3d
from aniso3d.build.mesh import Mesh
from aniso3d.build.texture import AnisoTexture, build_texture
from aniso3d.metrics import psnr
from aniso3d.rendering import volume
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.renderer import Renderer

#: Supersampling of the truth.
TRUTH_SSAA = 8
#: Directions of every texture (the code's default).
DIRECTIONS = 16


@dataclass
class Case:
    """One image to compare: a mesh, its texture resolution, a camera, and
    which pixels the coverage is measured over (see the module docstring)."""

    scene: str
    label: str
    mesh: Mesh
    resolution: int
    camera: Camera
    kind: str = "any"  # "solid" | "crown" | "any"
    crown: tuple[np.ndarray, float] | None = None  # centre (3,) and radius, world
    size: int | None = None  # image side, pixels; None: the --size option
    margin: int | None = None  # solid: erosion, pixels; None: 2 + one voxel's projection


# ------------------------------------------------------------------ scenes


def rotation(axis, degrees: float) -> np.ndarray:
    """(4, 4) rotation about ``axis`` through the origin."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    t = np.radians(degrees)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    m = np.eye(4)
    m[:3, :3] = np.eye(3) + np.sin(t) * k + (1 - np.cos(t)) * k @ k
    return m


def view_at(normal, degrees: float, distance: float = 3.0, turn=(0.3, 1.0, 0.1), fov: float = 30.0) -> Camera:
    """A camera ``degrees`` off the unit ``normal``, turned about the axis
    ``normal x turn``, looking at the origin."""
    n = np.asarray(normal, dtype=np.float64)
    axis = np.cross(n, turn)
    axis /= np.linalg.norm(axis)
    d = rotation(axis, degrees)[:3, :3] @ n
    return Camera(tuple(distance * d), up=tuple(axis), fov=fov)


def tilted_quad(tilt: tuple[float, float, float]) -> tuple[Mesh, np.ndarray]:
    """A unit quad turned by ``tilt`` degrees about x, then y, then z; and its normal."""
    m = rotation((0, 0, 1), tilt[2]) @ rotation((0, 1, 0), tilt[1]) @ rotation((1, 0, 0), tilt[0])
    return aniso3d.scenes.quad(1.0).transformed(m), m[:3, :3] @ [0.0, 0.0, 1.0]


def leaf_cloud(
    n_leaves: int, leaf: float, radius: float = 1.0, seed: int = 0, kd=(0.25, 0.55, 0.15)
) -> Mesh:
    """``n_leaves`` square leaves of edge ``leaf`` (two triangles each), centres
    uniform in a ball of ``radius``, orientations uniform: independent facets,
    the case the exponential law is exact for."""
    rng = np.random.default_rng(seed)
    c = rng.normal(size=(n_leaves, 3))
    c *= (radius * rng.random(n_leaves) ** (1 / 3) / np.linalg.norm(c, axis=1))[:, None]
    a = rng.normal(size=(n_leaves, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(a, rng.normal(size=(n_leaves, 3)))
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    h = 0.5 * leaf
    v = np.stack([c - h * a - h * b, c + h * a - h * b, c + h * a + h * b, c - h * a + h * b], axis=1)
    f = (np.array([[0, 1, 2], [0, 2, 3]])[None] + 4 * np.arange(n_leaves)[:, None, None]).reshape(-1, 3)
    return Mesh.from_arrays(v.reshape(-1, 3), f, kd, 0.1, 16.0, name="leaves")


def cases_quad(args) -> list[Case]:
    """The axis-aligned unit quad at 16^3 seen 0 to 85 degrees off its normal
    (its edges lie on voxel faces: eroded by 2 pixels only)."""
    q = aniso3d.scenes.quad(1.0)
    return [
        Case("quad", f"{a:2d} deg", q, 16, view_at((0, 0, 1), a), "solid", margin=2)
        for a in (0, 15, 30, 40, 45, 60, 75, 85)
    ]


def cases_tilted(args) -> list[Case]:
    """Quads at non-axis tilts in a 64^3 grid (their edges and the voxel
    layers cross), seen 0 to 85 degrees off their normals."""
    out = []
    for tilt in [(30, 20, 0), (45, 35, 10), (10, 60, 25)]:
        q, n = tilted_quad(tilt)
        for a in (0, 30, 60, 85):
            out.append(Case("tilted", f"{tilt} {a:2d} deg", q, 64, view_at(n, a), "solid"))
        # Far: a voxel about half a pixel.
        out.append(Case("tilted", f"{tilt} 45 deg far", q, 64, view_at(n, 45, distance=15.0), "solid"))
    return out


def cases_cube(args) -> list[Case]:
    c = aniso3d.scenes.cube(1.0)
    return [
        Case("cube", f"{r}^3 {name}", c, r, Camera.frame(c.bounds, d, fov=30.0), "solid")
        for r in (16, 64)
        for name, d in (("corner", (0.55, 0.35, 1.0)), ("face", (0.05, 0.1, 1.0)))
    ]


def cases_sphere(args) -> list[Case]:
    s = aniso3d.scenes.sphere(1.0, subdivisions=5)
    return [
        Case("sphere", f"{r}^3{' far' if far > 1 else ''}", s, r,
             Camera.frame(s.bounds, (0.55, 0.35, 1.0), fov=30.0, distance_scale=far), "solid")
        for r, far in ((16, 1.0), (64, 1.0), (64, 4.0))
    ]  # fmt: skip


def cases_leaves(args) -> list[Case]:
    """Random leaf clouds: sub-voxel leaves (0.4 h), leaves about a voxel, and
    leaves 3 voxels long, at 64^3 over the ball's diameter (h = 1/32); seen
    from far (a voxel below a pixel), framed, and close up."""
    out = []
    for leaf, n in ((0.0125, 40000), (0.03, 7000), (0.09, 800)):
        m = leaf_cloud(n, leaf)
        views = (("far", (0.55, 0.35, 1.0), 3.0), ("front", (0.55, 0.35, 1.0), 1.0), ("close", (0.3, -0.2, 1.0), 0.45))
        for name, d, scale in views:
            cam = Camera.frame(np.array([[-1.0] * 3, [1.0] * 3]), d, fov=30.0, distance_scale=scale)
            out.append(Case("leaves", f"{leaf / (2 / 64):.1f}h {name}", m, 64, cam, "crown",
                            (np.zeros(3), 1.0)))  # fmt: skip
    return out


def cases_tree(args) -> list[Case]:
    """The default tree at 128^3: minified (a voxel about a pixel, 160 px
    image) and close up (a 4 m box of the crown, a voxel about 6 px)."""
    t = aniso3d.scenes.tree()
    far = Camera.fit(t.bounds, points=t.vertices)
    c = np.array([1.0, 8.5, 1.5])
    near = Camera.frame(np.stack([c - 2.0, c + 2.0]), (0.55, 0.2, 1.0), fov=40.0)
    return [Case("tree", "minified", t, 128, far, "any", size=160), Case("tree", "close", t, 128, near, "any")]


SCENES: dict[str, Callable[[argparse.Namespace], list[Case]]] = {
    "quad": cases_quad,
    "tilted": cases_tilted,
    "cube": cases_cube,
    "sphere": cases_sphere,
    "leaves": cases_leaves,
    "tree": cases_tree,
}


def cases_builtin(name: str) -> list[Case]:
    """A scene of :mod:`aniso3d.build.scenes` not listed above."""
    m = aniso3d.scenes.get_scene(name)
    return [Case(name, "framed", m, 64, Camera.fit(m.bounds, points=m.vertices))]


# ---------------------------------------------------------------- measuring


@dataclass
class Model:
    """An opacity law, and for the sheet laws the ramps it is drawn with:
    ``planar@fill=0.5:0.9,pixels=1:3`` sets :data:`SHEET_FILL` and
    :data:`SHEET_PIXELS` of :mod:`aniso3d.rendering.volume` while it draws."""

    spec: str
    opacity: str = field(init=False)
    ramps: dict = field(init=False)

    def __post_init__(self) -> None:
        name, _, ramps = self.spec.partition("@")
        self.opacity = name
        self.ramps = {}
        for item in filter(None, ramps.split(",")):
            key, _, value = item.partition("=")
            self.ramps["SHEET_" + key.upper()] = tuple(float(x) for x in value.split(":"))


def erode(mask: np.ndarray, k: int) -> np.ndarray:
    """``mask`` eroded by a (2k + 1)^2 square."""
    out = mask.copy()
    for axis in (0, 1):
        for s in range(-k, k + 1):
            out &= np.roll(mask, s, axis=axis)
    return out


def voxel_pixels(case: Case, tex: AnisoTexture, size: int) -> float:
    """Pixels one voxel spans at the distance of the grid's centre."""
    cam = case.camera
    dist = float(np.linalg.norm(np.subtract(cam.position, tex.bounds.mean(axis=0))))
    return float(tex.voxel_size * size / (2.0 * dist * np.tan(np.radians(cam.fov) / 2)))


def region(case: Case, truth_alpha: np.ndarray, vox_px: float) -> np.ndarray:
    """The pixels a case's coverage is measured over (module docstring)."""
    size = truth_alpha.shape[0]
    if case.kind == "solid":
        margin = 2 + int(np.ceil(vox_px)) if case.margin is None else case.margin
        return erode(truth_alpha >= 254.5 / 255, margin)
    if case.kind == "crown":
        centre, radius = case.crown
        cam = case.camera
        right = cam.basis()[0]
        p = cam.project(np.stack([centre, centre + radius * right]), (size, size))
        r_px = float(np.linalg.norm(p[1] - p[0]))
        yy, xx = np.mgrid[:size, :size] + 0.5
        return (xx - p[0, 0]) ** 2 + (yy - p[0, 1]) ** 2 <= (0.8 * r_px) ** 2
    return truth_alpha > 0


def draw_volume(r: Renderer, tex: AnisoTexture, case: Case, model: Model, size: int) -> np.ndarray:
    """(H, W, 4) uint8 volume image drawn with ``model``; with ramps of its
    own the texture is uploaded anew (the sheets are derived at upload)."""
    saved = {k: getattr(volume, k) for k in model.ramps}
    for k, v in model.ramps.items():
        setattr(volume, k, v)
    try:
        thing = dataclasses.replace(tex) if model.ramps else tex  # a new object: a new upload
        return r.render(thing, case.camera, "volume", alpha=True, size=(size, size), opacity=model.opacity)
    finally:
        for k, v in saved.items():
            setattr(volume, k, v)


def measure(r: Renderer, case: Case, models: list[Model], size: int, textures: dict) -> list[dict]:
    size = case.size or size
    key = (id(case.mesh), case.resolution)
    if key not in textures:
        textures[key] = build_texture(case.mesh, case.resolution, DIRECTIONS)
    tex = textures[key]
    truth = r.render(case.mesh, case.camera, "mesh", ssaa=TRUTH_SSAA, alpha=True, size=(size, size))
    ta = truth[..., 3] / 255.0
    vox_px = voxel_pixels(case, tex, size)
    where = region(case, ta, vox_px)
    rows = []
    for model in models:
        img = draw_volume(r, tex, case, model, size)
        a = img[..., 3] / 255.0
        cover = float(a[where].mean()) if where.any() else float("nan")
        rows.append({
            "scene": case.scene, "case": case.label, "model": model.spec, "kind": case.kind,
            "voxel_px": vox_px, "pixels": int(where.sum()),
            "truth": float(ta[where].mean()) if where.any() else float("nan"),
            "cover": cover, "err": cover - float(ta[where].mean()) if where.any() else float("nan"),
            "min": float(a[where].min()) if where.any() else float("nan"),
            "alpha_rmse": float(np.sqrt(np.mean((a - ta) ** 2))),
            "psnr": psnr(truth[..., :3], img[..., :3]),
        })  # fmt: skip
    return rows


def print_table(rows: list[dict]) -> None:
    head = f"{'scene':8s} {'case':22s} {'model':22s} {'vox px':>6s} {'truth':>6s} {'cover':>6s} " \
           f"{'err':>7s} {'min':>6s} {'a-rmse':>7s} {'psnr':>6s}"  # fmt: skip
    print(head)
    print("-" * len(head))
    last = None
    for row in rows:
        if last is not None and (row["scene"], row["case"]) != last:
            print()
        last = (row["scene"], row["case"])
        print(
            f"{row['scene']:8s} {row['case']:22s} {row['model']:22s} {row['voxel_px']:6.1f} "
            f"{row['truth']:6.3f} {row['cover']:6.3f} {row['err']:+7.3f} {row['min']:6.3f} "
            f"{row['alpha_rmse']:7.4f} {row['psnr']:6.2f}"
        )


def summary(rows: list[dict], models: list[str]) -> None:
    """Per scene and model: the mean |err|, the worst min and the mean PSNR over its cases."""
    print(f"\n{'scene':8s} {'model':22s} {'mean|err|':>9s} {'worst min':>9s} {'mean psnr':>9s}")
    for scene in dict.fromkeys(r["scene"] for r in rows):
        for m in models:
            sel = [r for r in rows if r["scene"] == scene and r["model"] == m]
            if not sel:
                continue
            print(
                f"{scene:8s} {m:22s} {np.mean([abs(r['err']) for r in sel]):9.3f} "
                f"{min(r['min'] for r in sel):9.3f} {np.mean([r['psnr'] for r in sel]):9.2f}"
            )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), help="scene names (see SCENES)")
    ap.add_argument(
        "--models", nargs="+",
        default=["exponential", "linear", "split", "planar", "planar@fill=0:0", "planar@pixels=1e9:2e9"],
        help="opacity laws, e.g. planar@fill=0.5:0.9,pixels=1:3 (module docstring)",
    )  # fmt: skip
    ap.add_argument("--size", type=int, default=256, help="image side, pixels")
    ap.add_argument("--json", help="also write the rows to this file")
    args = ap.parse_args()
    models = [Model(s) for s in args.models]
    for m in models:
        if m.opacity not in volume.OPACITY_MODES:
            ap.error(f"unknown opacity law {m.opacity!r}; choose from {volume.OPACITY_MODES}")
    load = os.getloadavg()
    print(f"machine load (1, 5, 15 min): {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; "
          f"truth: polygons at {TRUTH_SSAA}x{TRUTH_SSAA} samples; K = {DIRECTIONS}")  # fmt: skip
    t0 = time.perf_counter()
    rows: list[dict] = []
    with Renderer((args.size, args.size)) as r:
        for name in args.scenes:
            cases = SCENES[name](args) if name in SCENES else cases_builtin(name)
            textures: dict = {}
            for case in cases:
                rows += measure(r, case, models, args.size, textures)
    print_table(rows)
    summary(rows, [m.spec for m in models])
    print(f"\n{time.perf_counter() - t0:.0f} s")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"load": load, "rows": rows}, fh, indent=1)


if __name__ == "__main__":
    main()
