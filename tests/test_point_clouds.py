"""Point clouds from other tools: splat sizes from the local spacing, normals
by PCA, the PLY properties other tools write, and no holes when drawn.

Closed forms: on a square grid of spacing s the local spacing of an interior
point over its k = 8 nearest neighbours (4 at s, 4 at sqrt(2) s) is
``sqrt(2 pi 1.5 / 9) s = sqrt(pi / 3) s``; the neighbour searches agree with
brute force; the normal of a sphere is radial; Gaussian splatting's
``scale_i`` are logs of standard deviations. Rendering checks use the polygon
renderer on the same plane or sphere as the truth: inside its silhouette
(eroded by 2 pixels) no splat pixel may show the background.
"""

from __future__ import annotations

import math

import numpy as np
import plyfile
import pytest

from aniso3d import InputError, PointCloud, scenes
from aniso3d.build.ply import point_layout
from aniso3d.build.spacing import COVERAGE, DEFAULT_K, local_spacing, nearest_neighbours, pca_normals, splat_radii
from aniso3d.rendering.camera import Camera

METHODS = ("kdtree", "grid")


def brute_knn(p: np.ndarray, k: int) -> np.ndarray:
    d2 = ((p[:, None, :] - p[None, :, :]) ** 2).sum(-1)
    np.fill_diagonal(d2, np.inf)
    return np.sqrt(np.sort(d2, axis=1)[:, :k])


def write_cloud(path, pos, normals=None, extra: dict | None = None, text: bool = False):
    """A PLY vertex element with x y z (float32), optional nx ny nz and any
    ``extra`` columns (name -> array, dtype kept), written by plyfile."""
    cols = {"x": pos[:, 0], "y": pos[:, 1], "z": pos[:, 2]}
    if normals is not None:
        cols.update(nx=normals[:, 0], ny=normals[:, 1], nz=normals[:, 2])
    cols.update(extra or {})
    dtype = [(k, "<f4" if k in "x y z nx ny nz".split() else np.asarray(v).dtype.str) for k, v in cols.items()]
    rec = np.empty(len(pos), dtype=dtype)
    for k, v in cols.items():
        rec[k] = v
    plyfile.PlyData([plyfile.PlyElement.describe(rec, "vertex")], text=text).write(str(path))
    return path


def plane_grid(n: int, s: float, rotate: bool = True) -> np.ndarray:
    """An n x n square grid of spacing s, turned to a general orientation."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    p = np.stack([i.ravel() * s, j.ravel() * s, np.zeros(n * n)], axis=1) + [0.3, -0.2, 0.7]
    if rotate:
        q, _ = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))
        p = p @ q.T
    return p


# ------------------------------------------------------------------ spacing


@pytest.mark.parametrize("method", METHODS)
def test_neighbour_searches_match_brute_force(method):
    rng = np.random.default_rng(0)
    clouds = [
        rng.random((1500, 3)),  # a volume
        np.c_[rng.random((1500, 2)), np.zeros(1500)],  # a plane, flat in z
        np.r_[rng.random((1200, 3)) * 0.01, rng.random((6, 3)) * 50],  # a cluster and far outliers
        np.repeat(rng.random((200, 3)), 5, axis=0),  # every point five times
    ]
    for p in clouds:
        d, i = nearest_neighbours(p, 8, method)
        np.testing.assert_allclose(d, brute_knn(p, 8), rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(p[i] - p[:, None], axis=-1), d, rtol=0, atol=1e-12)
        assert not (i == np.arange(len(p))[:, None]).any()


@pytest.mark.parametrize("method", METHODS)
def test_grid_spacing_is_the_closed_form(method):
    s = 0.0137
    p = plane_grid(30, s)
    d, _ = nearest_neighbours(p, DEFAULT_K, method)
    i, j = np.meshgrid(np.arange(30), np.arange(30), indexing="ij")
    interior = ((i > 1) & (i < 28) & (j > 1) & (j < 28)).ravel()
    spacing = local_spacing(d)
    assert DEFAULT_K == 8  # the closed form below is for 4 steps of s and 4 of sqrt(2) s
    np.testing.assert_allclose(spacing[interior], math.sqrt(math.pi / 3) * s, rtol=1e-9)
    radii = splat_radii(p, method=method)
    np.testing.assert_allclose(radii[interior], COVERAGE * math.sqrt(math.pi / 3) * s, rtol=1e-9)
    # edge and corner points see neighbours on one side only: never smaller
    assert spacing.min() >= spacing[interior].min() * (1 - 1e-9)


def test_random_spacing_estimates_the_area_per_point():
    # pi lam d_j^2 has mean j for a random sample: spacing^2 averages 1 / lam.
    rng = np.random.default_rng(5)
    n = 40_000
    p = np.c_[rng.random((n, 2)), np.zeros(n)]
    d, _ = nearest_neighbours(p, DEFAULT_K)
    inner = (np.abs(p[:, :2] - 0.5) < 0.45).all(axis=1)
    mean_sq = np.mean(local_spacing(d)[inner] ** 2) * n
    assert abs(mean_sq - 1.0) < 0.01, mean_sq


def test_pca_normals_on_a_sphere():
    # A point and a ring of neighbours symmetric about its radius: the fitted
    # plane is exactly the tangent plane.
    c = np.array([0.0, 0.0, 1.0])
    ang = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    t = 0.05
    ring = np.stack([np.sin(t) * np.cos(ang), np.sin(t) * np.sin(ang), np.full(8, np.cos(t))], 1)
    n = pca_normals(np.r_[c[None], ring], np.r_[np.arange(1, 9)[None], np.zeros((8, 8), int)])
    np.testing.assert_allclose(n[0], [0, 0, 1], atol=1e-12)
    # A random sample of a sphere of radius 2 about (1, -1, 0.5): outward radial normals.
    rng = np.random.default_rng(7)
    u = rng.normal(size=(20_000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    centre = np.array([1.0, -1.0, 0.5])
    p = centre + 2.0 * u
    _, idx = nearest_neighbours(p, DEFAULT_K)
    n = pca_normals(p, idx)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    cos = np.einsum("ij,ij->i", n, u)
    assert cos.min() > 0  # all outward
    angle = np.degrees(np.arccos(np.clip(cos, -1, 1)))
    # The 8 nearest (within about 0.08 on a radius of 2) subtend about 2.3 degrees:
    # a lopsided neighbourhood tilts the fitted plane by a fraction of that.
    assert np.median(angle) < 0.6 and angle.max() < 4.0, (np.median(angle), angle.max())


def test_without_scipy_the_grid_hash_answers(monkeypatch):
    import aniso3d.build.spacing as spacing

    p = np.random.default_rng(4).random((500, 3))
    calls = []
    monkeypatch.setattr(spacing, "have_kdtree", lambda: False)
    monkeypatch.setattr(spacing, "knn_grid", lambda *a: calls.append(a) or ("grid", None))
    assert spacing.nearest_neighbours(p, 8)[0] == "grid" and len(calls) == 1


def test_spacing_needs_enough_points():
    with pytest.raises(InputError, match="at least 9 points"):
        nearest_neighbours(np.zeros((5, 3)), 8)
    with pytest.raises(InputError, match="finite"):
        nearest_neighbours(np.array([[0, 0, np.nan]] + [[1.0, 2, 3]] * 10), 8)
    with pytest.raises(InputError, match="unknown neighbour search"):
        nearest_neighbours(np.random.default_rng(0).random((20, 3)), 8, "octree")


# ------------------------------------------------------------ PLY properties


@pytest.fixture
def sample():
    rng = np.random.default_rng(11)
    n = 300
    pos = rng.uniform(-1, 1, (n, 3))
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    rgb8 = rng.integers(0, 256, (n, 3)).astype(np.uint8)
    return pos.astype(np.float32).astype(np.float64), nrm.astype(np.float32), rgb8


def colour_columns(encoding: str, rgb8: np.ndarray) -> dict:
    f = rgb8.astype(np.float32) / np.float32(255)
    alpha = np.full(len(rgb8), 200, np.uint8)
    return {
        "uchar": dict(red=rgb8[:, 0], green=rgb8[:, 1], blue=rgb8[:, 2]),
        "uchar+alpha": dict(red=rgb8[:, 0], green=rgb8[:, 1], blue=rgb8[:, 2], alpha=alpha),
        "float": dict(red=f[:, 0], green=f[:, 1], blue=f[:, 2]),
        "float+alpha": dict(red=f[:, 0], green=f[:, 1], blue=f[:, 2], alpha=np.full(len(f), 0.5, np.float32)),
        "float 0..255": dict(red=rgb8[:, 0].astype("<f4"), green=rgb8[:, 1].astype("<f4"),
                             blue=rgb8[:, 2].astype("<f4")),  # fmt: skip
        "r g b": dict(r=rgb8[:, 0], g=rgb8[:, 1], b=rgb8[:, 2]),
        "diffuse": dict(diffuse_red=rgb8[:, 0], diffuse_green=rgb8[:, 1], diffuse_blue=rgb8[:, 2]),
        "ushort": dict(red=rgb8[:, 0].astype("<u2") * 257, green=rgb8[:, 1].astype("<u2") * 257,
                       blue=rgb8[:, 2].astype("<u2") * 257),  # fmt: skip
        "double": dict(red=f[:, 0].astype("<f8"), green=f[:, 1].astype("<f8"), blue=f[:, 2].astype("<f8")),
    }[encoding]


@pytest.mark.parametrize(
    "encoding",
    ["uchar", "uchar+alpha", "float", "float+alpha", "float 0..255", "r g b", "diffuse", "ushort", "double"],
)
def test_colour_encodings_read_identically(tmp_path, sample, encoding):
    pos, nrm, rgb8 = sample
    path = write_cloud(tmp_path / "c.ply", pos, nrm, colour_columns(encoding, rgb8))
    pc = PointCloud.load_ply(path, default_area=0.01)
    np.testing.assert_allclose(pc.kd, rgb8 / 255.0, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(pc.positions, pos)
    np.testing.assert_allclose(pc.normals, nrm, atol=1e-6)


def test_gaussian_splat_files(tmp_path, sample):
    """3D Gaussian splatting's layout: zero nx ny nz, f_dc colours, log scales
    and a rotation quaternion."""
    pos, _, rgb8 = sample
    n = len(pos)
    rng = np.random.default_rng(12)
    quat = rng.normal(size=(n, 4))
    log_s = rng.uniform(-6, -3, (n, 3))
    f_dc = (rgb8 / 255.0 - 0.5) / 0.28209479177387814
    extra = {f"f_dc_{i}": f_dc[:, i].astype("<f4") for i in range(3)}
    extra |= {f"scale_{i}": log_s[:, i].astype("<f4") for i in range(3)}
    extra |= {f"rot_{i}": quat[:, i].astype("<f4") for i in range(4)}
    extra["opacity"] = np.zeros(n, "<f4")
    path = write_cloud(tmp_path / "g.ply", pos, np.zeros((n, 3), np.float32), extra)
    pc = PointCloud.load_ply(path)
    np.testing.assert_allclose(pc.kd, rgb8 / 255.0, atol=1e-5)
    sig = np.sort(np.exp(log_s.astype(np.float32).astype(np.float64)), axis=1)
    np.testing.assert_allclose(pc.areas, 2 * np.pi * sig[:, 1] * sig[:, 2], rtol=1e-6)
    # the normal is the rotated axis of the smallest scale: q v q* for that unit axis
    q = quat.astype(np.float32).astype(np.float64)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    axis = np.eye(3)[np.argmin(log_s.astype(np.float32), axis=1)]
    w, v = q[:, :1], q[:, 1:]
    rotated = axis + 2 * np.cross(v, np.cross(v, axis) + w * axis)
    np.testing.assert_allclose(pc.normals, rotated, atol=1e-5)


def test_size_properties_and_options(tmp_path, sample):
    pos, nrm, _ = sample
    n = len(pos)
    radius = np.linspace(0.01, 0.05, n).astype(np.float32)
    path = write_cloud(tmp_path / "r.ply", pos, nrm, {"radius": radius})
    np.testing.assert_allclose(PointCloud.load_ply(path).areas, np.pi * radius.astype(np.float64) ** 2, rtol=1e-12)
    # splat_scale multiplies radii; splat_size replaces every size
    np.testing.assert_allclose(PointCloud.load_ply(path, splat_scale=2.0).areas, 4 * np.pi * radius**2.0, rtol=1e-6)
    np.testing.assert_allclose(PointCloud.load_ply(path, splat_size=0.1).areas, np.pi * 0.01, rtol=1e-12)
    np.testing.assert_allclose(PointCloud.load_ply(path, splat_size=0.1, splat_scale=0.5).areas,
                               np.pi * 0.0025, rtol=1e-12)  # fmt: skip
    area = np.linspace(1e-4, 1e-3, n).astype(np.float32)
    path = write_cloud(tmp_path / "a.ply", pos, nrm, {"area": area, "radius": radius})
    np.testing.assert_array_equal(PointCloud.load_ply(path).areas, area)  # area wins over radius
    # no size in the file: the spacing radii
    path = write_cloud(tmp_path / "none.ply", pos, nrm)
    np.testing.assert_allclose(PointCloud.load_ply(path).areas, np.pi * splat_radii(pos) ** 2, rtol=1e-9)
    np.testing.assert_allclose(PointCloud.load_ply(path, k=4).areas, np.pi * splat_radii(pos, 4) ** 2, rtol=1e-9)
    for bad in ({"splat_size": 0.0}, {"splat_size": np.inf}, {"splat_scale": -1.0},
                {"splat_size": 1.0, "default_area": 1.0}):  # fmt: skip
        with pytest.raises(InputError, match="splat_size|splat_scale"):
            PointCloud.load_ply(path, **bad)


def test_layout_reads_only_complete_groups():
    lay = point_layout(("x", "y", "z", "nx", "ny", "red", "green", "blue", "scale_0"))
    assert lay.normals is None and lay.colour == ("red", "green", "blue") and lay.size is None
    lay = point_layout(("x", "y", "z", "r", "g", "b", "f_dc_0", "f_dc_1", "f_dc_2", "scale_0", "scale_1"))
    assert lay.colour == ("r", "g", "b") and lay.sh_colour is None
    assert lay.size == "log_scales" and lay.scales == ("scale_0", "scale_1")


def test_cloud_without_normals_is_one_clear_error(tmp_path, sample):
    pos, nrm, _ = sample
    path = write_cloud(tmp_path / "raw.ply", pos)
    with pytest.raises(InputError, match="no normals.*estimate_normals=True.*--estimate-normals.*Open3D"):
        PointCloud.load_ply(path)
    # zero normals in a file that has the properties: the same way out
    zero = nrm.copy()
    zero[::7] = 0
    with pytest.raises(InputError, match=r"43 points with a zero normal.*estimate_normals=True"):
        PointCloud.load_ply(write_cloud(tmp_path / "zero.ply", pos, zero))
    pc = PointCloud.load_ply(write_cloud(tmp_path / "zero.ply", pos, zero), estimate_normals=True)
    np.testing.assert_allclose(pc.normals[1::7], zero[1::7], atol=1e-6)  # file normals kept
    _, idx = nearest_neighbours(pos, DEFAULT_K)
    np.testing.assert_allclose(pc.normals[::7], pca_normals(pos, idx)[::7], atol=1e-6)


def test_estimated_normals_of_a_sphere_file(tmp_path):
    rng = np.random.default_rng(8)
    u = rng.normal(size=(5000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    pc = PointCloud.load_ply(write_cloud(tmp_path / "s.ply", u), estimate_normals=True)
    cos = np.einsum("ij,ij->i", pc.normals, pc.positions / np.linalg.norm(pc.positions, axis=1, keepdims=True))
    assert cos.min() > 0.98, cos.min()


def test_degenerate_spacing(tmp_path):
    with pytest.raises(InputError, match="one point"):
        PointCloud.load_ply(write_cloud(tmp_path / "one.ply", np.zeros((1, 3)), np.array([[0, 0, 1.0]])))
    same = np.zeros((12, 3))
    with pytest.raises(InputError, match="coincide"):
        PointCloud.load_ply(write_cloud(tmp_path / "same.ply", same, np.tile([0, 0, 1.0], (12, 1))))
    # two points: the one neighbour there is
    two = PointCloud.load_ply(write_cloud(tmp_path / "two.ply", np.array([[0, 0, 0], [0.3, 0, 0.4]]),
                                          np.tile([0, 0, 1.0], (2, 1))))  # fmt: skip
    np.testing.assert_allclose(two.areas, np.pi * (COVERAGE * math.sqrt(2 * math.pi * 0.25 / 2)) ** 2)
    rgb = np.full(12, 0.5, np.float32)
    rgb[3] = np.nan
    path = write_cloud(tmp_path / "nanrgb.ply", np.random.default_rng(0).random((12, 3)), np.tile([0, 0, 1.0], (12, 1)),
                       {"red": rgb, "green": rgb, "blue": rgb})  # fmt: skip
    with pytest.raises(InputError, match="1 points with NaN or Inf colours"):
        PointCloud.load_ply(path)
    nan = np.r_[np.array([[0, 0, np.nan]]), np.random.default_rng(0).random((11, 3))]
    with pytest.raises(InputError, match="1 points with NaN or Inf coordinates"):
        PointCloud.load_ply(write_cloud(tmp_path / "nan.ply", nan, np.tile([0, 0, 1.0], (12, 1))))


# ----------------------------------------------------------------- no holes

IMAGE = (192, 192)


@pytest.fixture(scope="module")
def rend():
    from aniso3d import ResourceError
    from aniso3d.rendering.renderer import Renderer

    try:
        renderer = Renderer(IMAGE)
    except ResourceError as exc:  # no OpenGL on this machine
        pytest.skip(str(exc))
    yield renderer
    renderer.release()


def erode(mask: np.ndarray, px: int) -> np.ndarray:
    out = mask.copy()
    for _ in range(px):
        m = out.copy()
        m[1:] &= out[:-1]
        m[:-1] &= out[1:]
        m[:, 1:] &= out[:, :-1]
        m[:, :-1] &= out[:, 1:]
        out = m
    return out


def random_plane(n: int, seed: int):
    rng = np.random.default_rng(seed)
    pos = np.c_[rng.uniform(-0.5, 0.5, (n, 2)), np.zeros(n)]
    return pos, np.tile([0.0, 0.0, 1.0], (n, 1)), scenes.quad(1.0)


def random_sphere(n: int, seed: int):
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, u, scenes.sphere(1.0, subdivisions=5)


@pytest.mark.gpu
@pytest.mark.parametrize("shape, n", [("plane", 1500), ("plane", 40_000), ("sphere", 6000), ("sphere", 60_000)])
def test_random_samples_render_without_holes(rend, tmp_path, shape, n):
    """A random sample written without sizes, read back and drawn as discs:
    inside the polygon truth's silhouette every pixel is covered, in both
    qualities, from splats of several pixels (fewer points) to about one."""
    pos, nrm, mesh = (random_plane if shape == "plane" else random_sphere)(n, seed=n)
    rgb = np.full((n, 3), 170, np.uint8)
    path = write_cloud(tmp_path / f"{shape}.ply", pos, nrm, {"red": rgb[:, 0], "green": rgb[:, 1], "blue": rgb[:, 2]})
    cloud = PointCloud.load_ply(path)
    cam = Camera.fit(mesh.bounds, direction=(0.35, 0.5, 1.0))
    inner = erode(rend.render(mesh, cam, "mesh", alpha=True)[..., 3] > 0, 2)
    assert inner.sum() > 0.2 * IMAGE[0] * IMAGE[1]
    # A third of the radius (about the size one area for all points gave before)
    # leaves holes the check must see.
    small = PointCloud.load_ply(path, splat_scale=1 / 3)
    for quality in ("fast", "high"):
        img = rend.render(cloud, cam, "splat", alpha=True, splat="disc", quality=quality)
        holes = inner & (img[..., 3] < 255)
        assert not holes.any(), (quality, int(holes.sum()), np.argwhere(holes)[:5])
        img = rend.render(small, cam, "splat", alpha=True, splat="disc", quality=quality)
        assert (inner & (img[..., 3] < 255)).sum() > 0.002 * inner.sum(), quality


# ---------------------------------------------------------------------- CLI


@pytest.mark.gpu
def test_render_command_point_cloud_options(rend, tmp_path, capsys):
    from aniso3d.app.cli import main
    from aniso3d.rendering.images import load_png

    pos, nrm, mesh = random_plane(800, seed=4)
    plain = write_cloud(tmp_path / "plain.ply", pos)
    args = ["render", str(plain), "--size", "64", "--method", "splat", "--quality", "fast"]
    # no normals: one line, status 2, the way out named
    assert main([*args, "-o", str(tmp_path / "a.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no normals" in err and "--estimate-normals" in err
    assert main([*args, "--estimate-normals", "-o", str(tmp_path / "b.png")]) == 0
    # a radius a tenth of the spacing's leaves most of the plane empty
    assert main([*args, "--estimate-normals", "--splat-scale", "0.1", "-o", str(tmp_path / "c.png")]) == 0
    assert main([*args, "--estimate-normals", "--splat-size", "0.2", "-o", str(tmp_path / "d.png")]) == 0
    bg = [int((load_png(tmp_path / f"{n}.png") == load_png(tmp_path / "c.png")[0, 0]).all(-1).sum())
          for n in "bcd"]  # fmt: skip
    assert bg[1] > bg[0] + 500 and bg[2] < bg[0], bg
    # the options belong to point clouds only
    mesh.to_trimesh().export(tmp_path / "quad.ply")
    capsys.readouterr()
    assert main(["render", str(tmp_path / "quad.ply"), "--splat-size", "1", "-o", str(tmp_path / "e.png")]) == 2
    assert "--splat-size is for PLY point clouds only" in capsys.readouterr().err


def test_view_command_takes_the_point_cloud_options():
    from aniso3d.app.cli import build_parser
    from aniso3d.app.common import point_cloud_options

    args = build_parser().parse_args(["view", "c.ply", "--splat-size", "0.1", "--estimate-normals"])
    assert point_cloud_options(args) == {"splat_size": 0.1, "estimate_normals": True}
    args = build_parser().parse_args(["frames", "c.ply", "--splat-scale", "2"])
    assert point_cloud_options(args) == {"splat_scale": 2.0}
    assert point_cloud_options(build_parser().parse_args(["render", "c.ply"])) == {}
