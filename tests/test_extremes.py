"""Numerical extremes (issue 6): each test checks the result, not only that
nothing crashed.

Foundation: resolutions 1, 2 and 512, long thin bounds, K = 1, 2 and 1024,
triangles of area 1e-12 beside ones 1e6 times larger, meshes at 1e7 and of
size 1e-6, facets on grid planes there, voxels with density far above 1.

Renderers (every one that exists): Phong exponents 0 and 1e4, cameras very
near, very far, grazing and inside the object, splats below a pixel and above
the screen, a scene at 1e7 drawn like one at the origin, and no memory growth.

Clipping and registration invariants on random triangle soups are property
tested in tests/test_clip.py and tests/test_texture.py; they are not repeated
here.
"""

from __future__ import annotations

import gc
import resource
from dataclasses import replace

import numpy as np
import pytest

from aniso3d import AnisoTexture, Mesh, PointCloud, build_texture, scenes, sphere_directions
from aniso3d.build.closure import hidden_density
from aniso3d.build.texture import estimate_build_bytes
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.lighting import Light, Lighting, shade_np

EPS = np.finfo(np.float64).eps


def ulp(x: float) -> float:
    return float(np.spacing(abs(x)))


def small_tree() -> Mesh:
    return scenes.tree(levels=4, leaves_per_twig=20)


def moved(mesh: Mesh, scale: float = 1.0, shift=(0.0, 0.0, 0.0)) -> Mesh:
    m = np.eye(4)
    m[:3, :3] *= scale
    m[:3, 3] = shift
    return mesh.transformed(m)


def soup(tris, **material) -> Mesh:
    """A mesh of separate triangles (n, 3, 3)."""
    tris = np.asarray(tris, dtype=np.float64).reshape(-1, 3, 3)
    return Mesh.from_arrays(
        tris.reshape(-1, 3), np.arange(3 * len(tris)).reshape(-1, 3), **material
    )


def square(axis: int, at: float, lo, hi) -> np.ndarray:
    """Two triangles (2, 3, 3) of the axis-aligned square in plane u[axis] = at
    over [lo[0], hi[0]] x [lo[1], hi[1]] in the other two axes (cyclic order),
    normal +axis."""
    a, b = (axis + 1) % 3, (axis + 2) % 3
    q = np.zeros((4, 3))
    q[:, axis] = at
    q[:, a] = [lo[0], hi[0], hi[0], lo[0]]
    q[:, b] = [lo[1], lo[1], hi[1], hi[1]]
    return q[[[0, 1, 2], [0, 2, 3]]]


def projected_area_per_direction(mesh: Mesh, directions: np.ndarray) -> np.ndarray:
    """sum over faces of area * |N . N_p|, straight from the mesh (float64)."""
    t = mesh.triangles
    cross = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    return 0.5 * np.abs(cross @ directions.T).sum(axis=0)


def assert_conservation(tex: AnisoTexture, mesh: Mesh, rtol: float = 1e-11):
    """The identity of registration: sum_v D_v(p) h^2 = sum_f A_f |N_f . N_p|
    for every sample p, and the registered area is the mesh's area. Rounding of
    float64 sums over ~1e5 terms stays far below 1e-11 of the total area. D as
    registered: the texture's density plus what closed surfaces hide of
    themselves in their voxels, from the closed sums kept with it."""
    total = mesh.area()
    registered = tex.density + hidden_density(tex.entry_offsets, tex.directions, tex.entry_closed_normal)
    got = registered.sum(axis=0) * tex.voxel_size**2
    want = projected_area_per_direction(mesh, tex.directions)
    assert np.all(np.abs(got - want) <= rtol * total), np.abs(got - want).max() / total
    assert abs(tex.total_area() - total) <= rtol * total
    # entries of a voxel are distinct samples, at most K of them
    assert np.all(np.diff(tex.entry_offsets) <= tex.n_directions)
    assert np.all(np.diff(tex.entry_offsets) >= 1)


def entry_area_by_voxel(tex: AnisoTexture) -> dict[tuple, float]:
    sums = np.add.reduceat(tex.entry_area, tex.entry_offsets[:-1]) if tex.n_voxels else []
    return {tuple(c): float(a) for c, a in zip(tex.coords.tolist(), sums, strict=True)}


# ------------------------------------------------------------------ resolution


def test_resolution_1_is_one_voxel_holding_everything():
    # A closed unit cube in one voxel: seen from any direction w its facets
    # cover the voxel twice (front and back), sum A |n . w| = 2 P(w); its
    # back hides behind its front (aniso3d.build.closure): D(w) = P(w)
    # exactly, the voxel's own shadow.
    cube = scenes.cube(1.0, center=(0.5, 0.5, 0.5))
    tex = build_texture(cube, 1, 64)
    assert tex.shape.tolist() == [1, 1, 1] and tex.coords.tolist() == [[0, 0, 0]]
    assert tex.voxel_size == 1.0
    p = np.abs(tex.directions).sum(axis=1)
    np.testing.assert_allclose(tex.density[0], p, rtol=1e-14)
    assert tex.entry_area.sum() == pytest.approx(6.0, rel=1e-15)
    # the tree too: one voxel, all of it, the identity holds
    tree = small_tree()
    t1 = build_texture(tree, 1, 16)
    assert t1.shape.tolist() == [1, 1, 1] and t1.n_voxels == 1
    assert_conservation(t1, tree)


def test_resolution_2_splits_a_cube_into_eight_half_covered_voxels():
    # Each of the 8 voxels holds three quarter-faces of area h^2 with normals
    # along x, y and z, pointing to its corner s (entries of +-1): registered,
    # D_v(w) = |w_x| + |w_y| + |w_z| = P(w), coverage 1; less what the faces
    # hide of each other (aniso3d.build.closure), D_v(w) = (P(w) + |s . w|) / 2.
    cube = scenes.cube(1.0, center=(0.5, 0.5, 0.5))
    tex = build_texture(cube, 2, 64)
    assert tex.shape.tolist() == [2, 2, 2] and tex.n_voxels == 8
    p = np.abs(tex.directions).sum(axis=1)
    corner = np.where(tex.coords > 0, 1.0, -1.0)
    np.testing.assert_allclose(tex.density, (p + np.abs(corner @ tex.directions.T)) / 2, rtol=1e-13)
    registered = tex.density + hidden_density(tex.entry_offsets, tex.directions, tex.entry_closed_normal)
    np.testing.assert_allclose(registered, np.broadcast_to(p, (8, 64)), rtol=1e-14)
    for d in tex.directions[[0, 17, 40, 63]]:  # coverage reads the sample nearest w
        np.testing.assert_allclose(tex.coverage(d), (1 + np.abs(corner @ d) / np.abs(d).sum()) / 2, rtol=1e-13)
    np.testing.assert_allclose(list(entry_area_by_voxel(tex).values()), 3.0, rtol=1e-15)


def test_resolution_512_on_a_sparse_mesh_is_exact_and_cheap():
    # Two small squares at opposite corners of the unit box and a tilted
    # triangle in the middle: a 512^3 grid (134M cells) of which a handful are
    # occupied. h = 1/512 is a power of two, so every number below is exact.
    h = 1.0 / 512
    tris = np.concatenate(
        [
            square(2, 0.0, (0.0, 0.0), (2 * h, 2 * h)),  # cells (0..1, 0..1, 0)
            square(
                2, 1.0, (1 - 2 * h, 1 - 2 * h), (1.0, 1.0)
            ),  # far face: (510..511, 510..511, 511)
            [[[0.5, 0.5, 0.5], [0.5 + 3 * h, 0.5, 0.5 + 3 * h], [0.5, 0.5 + 3 * h, 0.5]]],
        ]
    )
    mesh = soup(tris)
    assert estimate_build_bytes(mesh, 512, 32) < 2**30  # the sparse build is not refused
    tex = build_texture(mesh, 512, 32)
    assert tex.shape.tolist() == [512, 512, 512]
    assert tex.voxel_size == h
    cells = entry_area_by_voxel(tex)
    for i in (0, 1):
        for j in (0, 1):
            assert cells.pop((i, j, 0)) == 1.0
            assert cells.pop((510 + i, 510 + j, 511)) == 1.0
    # the tilted triangle: a 3h x 3h right triangle in x, then sheared in z
    middle = sum(cells.values())
    assert middle == pytest.approx(mesh.face_areas()[-1] / h**2, rel=1e-12)
    assert all(256 <= c[a] < 256 + 3 for c in cells for a in range(3))
    assert_conservation(tex, mesh)


def test_long_thin_object_gets_resolution_along_its_long_axis_only():
    # A 64 x 1 x 0.5 box at resolution 128: h = 0.5, grid 128 x 2 x 1, every
    # cell on the surface. A middle voxel holds its z = 0 and z = 0.5 faces and
    # one y face (area h^2 each): 3; the two end voxels per end hold a cap too.
    box = Mesh.from_arrays(*_box((64.0, 1.0, 0.5)))
    tex = build_texture(box, 128, 32)
    assert tex.shape.tolist() == [128, 2, 1]
    assert tex.voxel_size == 0.5
    assert tex.n_voxels == 256
    cells = entry_area_by_voxel(tex)
    for (i, _, _), a in cells.items():
        assert a == pytest.approx(4.0 if i in (0, 127) else 3.0, rel=1e-14)
    assert tex.total_area() == pytest.approx(box.area(), rel=1e-14)
    assert_conservation(tex, box)
    # the same box along a diagonal: still resolution along its longest extent
    rot = _rotation(np.array([1.0, 2.0, 3.0]), 0.7)
    tilted = box.transformed(rot)
    t2 = build_texture(tilted, 128, 32)
    extent = tilted.bounds[1] - tilted.bounds[0]
    assert t2.shape[np.argmax(extent)] == 128
    assert t2.voxel_size == pytest.approx(extent.max() / 128, rel=1e-15)
    assert t2.n_voxels < 0.05 * np.prod(t2.shape)
    assert_conservation(t2, tilted)


def _box(size):
    import trimesh

    b = trimesh.creation.box(extents=size)
    return np.asarray(b.vertices) + 0.5 * np.asarray(size), np.asarray(b.faces)


def _rotation(axis, angle):
    import pyrr

    m = np.eye(4)
    m[:3, :3] = np.asarray(
        pyrr.matrix33.create_from_axis_rotation(axis / np.linalg.norm(axis), angle)
    )
    return m


# ------------------------------------------------------------------ directions


@pytest.mark.parametrize("k", [1, 2, 1024])
def test_extreme_direction_counts_keep_the_conservation_identity(k):
    tree = scenes.tree(levels=3, leaves_per_twig=20)
    tex = build_texture(tree, 16, k)
    assert tex.directions.shape == (k, 3)
    np.testing.assert_allclose(np.linalg.norm(tex.directions, axis=1), 1.0, rtol=1e-15)
    assert_conservation(tex, tree)
    if k == 1:
        # one sample: every voxel has exactly one entry holding all its area
        assert np.array_equal(tex.entry_offsets, np.arange(tex.n_voxels + 1))
        d = tex.directions[0]
        t = tree.triangles
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        assert tex.density.sum() * tex.voxel_size**2 == pytest.approx(
            0.5 * np.abs(n @ d).sum(), rel=1e-12
        )


def test_k_1024_matches_k_1_voxel_by_voxel_in_area():
    # The shading sphere only redistributes area among samples: per voxel the
    # entries' areas must not depend on K.
    tree = scenes.tree(levels=3, leaves_per_twig=20)
    a = entry_area_by_voxel(build_texture(tree, 16, 1))
    b = entry_area_by_voxel(build_texture(tree, 16, 1024))
    assert a.keys() == b.keys()
    for c in a:
        assert b[c] == pytest.approx(a[c], rel=1e-12)


# -------------------------------------------------------------- triangle sizes


def test_tiny_triangles_beside_a_million_times_larger_ones():
    # A 10 m world at resolution 128 (h = 0.078 m, a tree's grid): 400
    # triangles of area 1e-6 facing +z, and 400 of area 1e-12 (edges 2e-5 h)
    # facing +x, each sitting on its own grid point (+- 1e-7 m), so most are cut
    # by two or three grid planes. Each tiny triangle's area must be found in
    # the 2 x 2 x 2 voxels around its grid point, at the +x sample, to 1e-9
    # relative: a per-triangle check, not a sum in which errors could cancel.
    rng = np.random.default_rng(3)
    size, res = 10.0, 128
    h = size / res

    dirs = sphere_directions(64)
    px, pz = 10, 40  # the tiny ones face sample 10, the big ones sample 40

    def triangles(corners, area, normal):
        # a right triangle of the given area in the plane normal to `normal`,
        # which is tilted against every grid plane
        t1 = np.cross(normal, [0.3, 0.5, 0.8])
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(normal, t1)
        e = np.sqrt(2 * area)
        return corners[:, None] + np.stack([0 * t1, e * t1, e * t2])[None]

    big = triangles(rng.uniform(0, size, (400, 3)), 1e-6, dirs[pz])
    lattice = rng.choice(63**3, 400, replace=False)  # distinct odd grid points
    points = 2 * np.stack(np.unravel_index(lattice, (63, 63, 63)), axis=1) + 1
    at = points * h + rng.uniform(-1e-7, 1e-7, (400, 3))
    tiny = triangles(at, 1e-12, dirs[px])
    mesh = soup(np.concatenate([big, tiny]))
    areas = mesh.face_areas()
    assert areas[:400] == pytest.approx(1e-6, rel=1e-9) and areas[400:] == pytest.approx(
        1e-12, rel=1e-6
    )
    tex = build_texture(mesh, res, 64, bounds=np.array([[0.0] * 3, [size] * 3]))
    assert tex.voxel_size == h
    assert set(tex.entry_direction.tolist()) == {px, pz}
    area = tex.entry_area * h**2
    sel = tex.entry_direction == px
    block = tex.coords[tex.entry_voxel[sel]] // 2  # voxels 2m, 2m+1 are beside point 2m+1
    per_point = {}
    for key, a in zip(map(tuple, block.tolist()), area[sel], strict=True):
        per_point[key] = per_point.get(key, 0.0) + a
    assert len(per_point) == 400
    for p, want in zip(map(tuple, (points // 2).tolist()), areas[400:], strict=True):
        assert abs(per_point[p] - want) <= 1e-9 * want, (p, per_point[p] / want - 1)
    big_sum = areas[:400].sum()
    assert abs(area[tex.entry_direction == pz].sum() - big_sum) <= 1e-12 * big_sum
    assert_conservation(tex, mesh)


# ------------------------------------------------------ translation and scale


def _dyadic(mesh: Mesh, bits: int = 20) -> Mesh:
    """The mesh with coordinates rounded to multiples of 2^-bits, so that
    adding integers up to ~2^30 is exact in float64."""
    v = np.round(mesh.vertices * 2.0**bits) / 2.0**bits
    return Mesh(v, mesh.faces, mesh.kd, mesh.ks, mesh.shininess, mesh.name)


FAR = (1.0e7, -3.0e6, 2.0e7)


def test_translation_to_1e7_is_exact_when_the_translation_is():
    # Coordinates that survive the move exactly give bit-identical spheres:
    # the pipeline works relative to the grid origin and loses nothing.
    tree = _dyadic(small_tree())
    far = moved(tree, shift=FAR)
    assert np.array_equal(far.vertices - FAR, tree.vertices)
    a, b = build_texture(tree, 64, 32), build_texture(far, 64, 32)
    for name in (
        "coords",
        "density",
        "entry_offsets",
        "entry_direction",
        "entry_area",
        "entry_kd",
        "entry_normal",
    ):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    # centroids are stored in world units: exact up to the rounding at 2e7
    assert np.abs(b.entry_centroid - FAR - a.entry_centroid).max() <= 2 * ulp(2e7)
    assert np.array_equal(b.origin - FAR, a.origin)


def test_translation_to_1e7_within_the_rounding_of_the_input():
    # An arbitrary mesh moved to 1e7 has every vertex rounded by up to
    # ulp(2e7)/2 ~ 1.9e-9 m: the results may differ by what that rounding
    # moves, stated as 100 ulp(2e7)/h in units of h (h^2 for densities), ~2e-6
    # at h = 0.16 m; the real difference is ~10x below.
    tree = small_tree()
    far = moved(tree, shift=FAR)
    a, b = build_texture(tree, 64, 32), build_texture(far, 64, 32)
    h = a.voxel_size
    tol = 100 * ulp(2e7) / h
    # h = extent / 64, and the extent itself is only known to ulp(2e7) there
    extent = np.max(tree.bounds[1] - tree.bounds[0])
    assert abs(b.voxel_size - h) <= 2 * ulp(2e7) / extent * h
    assert np.array_equal(a.coords, b.coords) and np.array_equal(
        a.entry_direction, b.entry_direction
    )
    assert np.abs(a.density - b.density).max() <= tol
    assert np.abs(a.entry_area - b.entry_area).max() <= tol
    # A centroid is a first moment over an area: an entry of area A (h^2)
    # moves by up to the input's rounding times its perimeter over A, so the
    # bound is on the moment A |dc|, the quantity the texture sums exactly.
    moment = a.entry_area * np.linalg.norm((b.entry_centroid - FAR) - a.entry_centroid, axis=1) / h
    assert moment.max() <= tol
    assert abs(b.total_area() - far.area()) <= 1e-12 * far.area()
    assert_conservation(b, far)


@pytest.mark.parametrize("scale", [1e-6, 1e3])
def test_scale_invariance(scale):
    # Grid coordinates (x - origin) / h do not depend on the scale beyond
    # rounding (~1e-16 relative): densities and entry areas in units of h^2
    # agree to 1e-12 (absolute, they are O(1..100)), centroid moments to
    # 1e-12 h^3.
    tree = small_tree()
    a, b = build_texture(tree, 64, 32), build_texture(moved(tree, scale), 64, 32)
    assert b.voxel_size == pytest.approx(a.voxel_size * scale, rel=1e-14)
    assert np.array_equal(a.coords, b.coords) and np.array_equal(
        a.entry_direction, b.entry_direction
    )
    assert np.abs(a.density - b.density).max() <= 1e-12 * max(1.0, a.density.max())
    assert np.abs(a.entry_area - b.entry_area).max() <= 1e-12 * max(1.0, a.entry_area.max())
    moment = (
        a.entry_area
        * np.linalg.norm(b.entry_centroid / scale - a.entry_centroid, axis=1)
        / a.voxel_size
    )
    assert moment.max() <= 1e-12  # see the 1e7 test: the centroid's moment, h^3
    assert np.array_equal(a.entry_kd, b.entry_kd)
    np.testing.assert_allclose(b.total_area(), a.total_area() * scale**2, rtol=1e-13)
    assert np.abs(a.entry_normal - b.entry_normal).max() <= 1e-6  # float32 storage


def _wall_lattice(n: int) -> Mesh:
    """Walls on every grid plane x, y, z = 0..n of the cube [0, n]^3 (each
    wall n x n unit squares' worth, normal +axis): facets on planes, their
    edges on grid lines and their corners on grid points."""
    walls = [
        square(axis, float(k), (0.0, 0.0), (float(n), float(n)))
        for axis in range(3)
        for k in range(n + 1)
    ]
    return soup(np.concatenate(walls))


@pytest.mark.parametrize("where", ["origin", "far", "tiny"])
def test_facets_on_grid_planes_are_counted_once_far_away_and_tiny(where):
    # Every voxel (i, j, k) holds the walls at its lower planes x = i, y = j,
    # z = k, and the last voxel along an axis also the far wall: area 1 per
    # wall and voxel, at the sample nearest the wall's normal. At 1e7 the
    # lattice moves exactly; at scale 2^-20 (~1e-6) too, and so every number
    # is exact.
    n = 4
    lattice = _wall_lattice(n)
    if where == "far":
        lattice = moved(lattice, shift=FAR)
    elif where == "tiny":
        lattice = moved(lattice, 2.0**-20)
    tex = build_texture(lattice, n, 64)
    assert tex.shape.tolist() == [n, n, n] and tex.n_voxels == n**3
    sample = [int(np.argmax(tex.directions @ np.eye(3)[a])) for a in range(3)]
    assert len(set(sample)) == 3
    got = np.zeros((n, n, n, 3))
    voxel = tex.coords[tex.entry_voxel]
    for a in range(3):
        sel = tex.entry_direction == sample[a]
        got[voxel[sel, 0], voxel[sel, 1], voxel[sel, 2], a] = tex.entry_area[sel]
    idx = np.indices((n, n, n)).transpose(1, 2, 3, 0)
    want = 1.0 + (idx == n - 1)
    assert np.array_equal(got, want)
    assert set(tex.entry_direction.tolist()) == set(sample)


def test_facets_on_planes_at_a_non_dyadic_scale_land_in_one_cell_each():
    # At scale 1e-6 a wall's grid coordinate may round to k - 1e-16 instead of
    # k: it may then belong to the cell below, but never to both and never
    # split: every voxel's x-entry holds a whole number of walls, and each
    # column of voxels holds all n + 1 walls of that axis once.
    n = 4
    lattice = moved(_wall_lattice(n), 1e-6, (3e-6, -1e-6, 0.0))
    tex = build_texture(lattice, n, 64)
    assert tex.shape.tolist() == [n, n, n]
    voxel = tex.coords[tex.entry_voxel]
    for a in range(3):
        p = int(np.argmax(tex.directions @ np.eye(3)[a]))
        sel = tex.entry_direction == p
        per = np.zeros((n, n, n))
        per[voxel[sel, 0], voxel[sel, 1], voxel[sel, 2]] = tex.entry_area[sel]
        np.testing.assert_allclose(per, np.round(per), atol=1e-9)
        np.testing.assert_allclose(per.sum(axis=a), n + 1, rtol=1e-12)
    assert tex.total_area() == pytest.approx(lattice.area(), rel=1e-12)


# ------------------------------------------------------------ dense voxels


def test_voxels_denser_than_one_are_kept_as_they_are(tmp_path):
    # 40 parallel sheets, each filling the voxel's cross-section: seen along
    # their normal the voxel is covered 40 times over. Nothing clamps it.
    layers = 40
    sheets = [square(2, (k + 0.5) / layers, (0.0, 0.0), (1.0, 1.0)) for k in range(layers)]
    sheets += [square(2, 0.0, (0.0, 0.0), (1e-3, 1e-3))]  # a corner marker keeps z bounds at [0, 1]
    mesh = soup(np.concatenate(sheets))
    tex = build_texture(mesh, 1, 64, bounds=np.array([[0.0] * 3, [1.0] * 3]))
    assert tex.n_voxels == 1
    d = tex.directions
    want = (layers + 1e-6) * np.abs(d[:, 2])
    np.testing.assert_allclose(tex.density[0], want, rtol=1e-13)
    w = np.array([0.0, 0.0, 1.0])
    pz = int(np.argmax(np.abs(d @ w)))
    assert tex.coverage(w)[0] == pytest.approx(want[pz] / 1.0, rel=1e-13)
    assert tex.coverage(w)[0] > 30
    assert tex.entry_area.sum() == pytest.approx(layers + 1e-6, rel=1e-13)
    tex.save(tmp_path / "dense.a3d", encoding="exact")
    back = AnisoTexture.load(tmp_path / "dense.a3d")
    assert np.array_equal(back.density, tex.density)
    pts = tex.to_points()
    assert pts.total_area() == pytest.approx(layers + 1e-6, rel=1e-13)


# ===================================================================== renderers

METHODS = ["mesh", "volume", "splat"]
#: How a mesh is turned into what the volume and splat renderers draw here.
BUILD = {"resolution": 32, "directions": 32}
#: Draw options that make each method show a closed surface as opaque, so the
#: checks below measure numerics, not the methods' documented softness
#: (exponential opacity lets part of a single layer through; touching discs
#: leave gaps).
SOLID = {
    "mesh": {},
    "volume": {"opacity": "linear"},
    "splat": {"splat": "square", "size_factor": 1.5},
}
SIZE = 64
ONE_LIGHT = Lighting(
    ambient=(0.1, 0.1, 0.1),
    background=(0.0, 0.0, 0.0),
    lights=(Light((0.3, 0.4, 0.866), (0.8, 0.8, 0.8)),),
)


@pytest.fixture(scope="module")
def gpu():
    """Renderers with the default lights and with one light on black."""
    from aniso3d import ResourceError
    from aniso3d.rendering.renderer import Renderer

    try:
        default = Renderer((SIZE, SIZE))
    except ResourceError as exc:
        pytest.skip(f"no OpenGL context: {exc}")
    one = Renderer((SIZE, SIZE), lighting=ONE_LIGHT, gl=default.gl)
    yield {"default": default, "one": one}
    one.release()
    default.release()


def draw(r, thing, cam, method, **options):
    opts = {**SOLID[method], **options}
    if method != "mesh" and isinstance(thing, Mesh):
        opts = {**BUILD, **opts}
    img = r.render(thing, cam, method, alpha=True, **opts)
    assert img.dtype == np.uint8 and img.shape == (SIZE, SIZE, 4)
    return img


def pixel_rays(cam: Camera, size=(SIZE, SIZE)) -> np.ndarray:
    return cam.ray_directions(size)


def fraction_differing(a, b, levels=2) -> float:
    d = np.abs(a[:, :, :3].astype(int) - b[:, :, :3].astype(int)).max(axis=2)
    return float(np.mean(d > levels))


# ------------------------------------------------------------- Phong extremes


@pytest.mark.gpu
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("shininess", [0.0, 1.0e4])
def test_phong_exponent_0_and_1e4_match_the_numpy_reference(gpu, method, shininess):
    # A large quad seen from the mirror direction of the light: the centre of
    # the image is the peak of the specular lobe. Exponent 0 is a constant
    # lobe (spec = 1 everywhere lit); 1e4 a lobe 0.8 degrees wide, a few
    # pixels here. Every pixel on the quad must equal the float64 reference
    # to within the uint8 rounding (0.5) plus float32 noise: 1 level.
    light = np.asarray(ONE_LIGHT.lights[0].direction)
    light /= np.linalg.norm(light)
    eye = 3.0 * (2 * light[2] * np.array([0, 0, 1.0]) - light)
    cam = Camera(tuple(eye), (0, 0, 0), fov=30)
    kd, ks = (0.6, 0.4, 0.2), 0.5
    quad = scenes.quad(size=4.0, kd=kd, ks=ks, shininess=shininess)
    img = draw(gpu["one"], quad, cam, method, resolution=8, directions=64)
    d = pixel_rays(cam)
    hit = eye + (-eye[2] / d[:, :, 2])[:, :, None] * d
    on_quad = (np.abs(hit[:, :, 0]) < 1.8) & (np.abs(hit[:, :, 1]) < 1.8)
    assert on_quad.mean() > 0.5
    ref = shade_np(
        np.tile([0, 0, 1.0], (SIZE * SIZE, 1)), -d.reshape(-1, 3), kd, ks, shininess, ONE_LIGHT
    )
    ref = np.clip(ref, 0, 1).reshape(SIZE, SIZE, 3) * 255
    err = np.abs(img[:, :, :3] - ref)[on_quad]
    assert err.max() <= 1.0, err.max()
    assert np.all(img[:, :, 3][on_quad] == 255)
    if shininess > 0:
        # the highlight is there and narrow: bright at the centre, gone 6 px away
        centre = img[30:34, 30:34, 0].astype(int)
        assert centre.max() - int(img[32, 38, 0]) > 20
        lobe = ref[:, :, 0] > ref[on_quad, 0].min() + 1
        assert 0 < lobe.sum() < 100


# ------------------------------------------------------------------- cameras


def _sphere_hit(cam: Camera, mesh: Mesh):
    """Per pixel: the face normal of the first triangle of ``mesh`` the ray
    through the pixel centre hits (Moller-Trumbore, float64), NaN if none."""
    o = np.asarray(cam.position)
    d = pixel_rays(cam).reshape(-1, 3)
    t = mesh.triangles
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    p = np.cross(d[:, None], e2[None])
    det = np.einsum("fi,rfi->rf", e1, p)
    inv = 1.0 / np.where(np.abs(det) > 1e-15, det, np.nan)
    s = o - t[:, 0]
    u = np.einsum("fi,rfi->rf", s, p) * inv
    q = np.cross(s, e1)
    v = np.einsum("ri,fi->rf", d, q) * inv
    dist = np.einsum("fi,fi->f", e2, q)[None] * inv
    ok = (u >= 0) & (v >= 0) & (u + v <= 1) & (dist > 0)
    dist = np.where(ok, dist, np.inf)
    first = np.argmin(dist, axis=1)
    n = np.cross(e1, e2)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    normal = np.where(np.isfinite(dist.min(axis=1))[:, None], n[first], np.nan)
    return normal, d


@pytest.mark.gpu
@pytest.mark.parametrize(
    "where, cam",
    [
        ("inside, at the centre", Camera((0, 0, 0), (0, 0, 1), fov=60)),
        ("inside, off centre", Camera((0.3, -0.2, 0.1), (1, 0.5, 1), fov=90)),
        ("near, 0.02 from the surface", Camera((0, 0, 1.02), (0, 0, 0), fov=40)),
    ],
)
def test_camera_inside_and_near_the_object_sees_the_right_surface(gpu, where, cam):
    # Polygons: every pixel is the (two-sided) shading of the very facet the
    # pixel's ray hits first, computed in float64: the inside of the sphere
    # seen from within, or the patch in front of a camera at 2% of the radius.
    sphere = scenes.sphere(1.0, subdivisions=2, kd=(0.7, 0.5, 0.3), ks=0.3, shininess=12)
    r = gpu["one"]
    img = draw(r, sphere, cam, "mesh")
    normal, d = _sphere_hit(cam, sphere)
    assert np.isfinite(normal).all()  # the sphere fills the view
    ref = np.clip(shade_np(normal, -d, (0.7, 0.5, 0.3), 0.3, 12.0, ONE_LIGHT), 0, 1).reshape(
        SIZE, SIZE, 3
    )
    err = np.abs(img[:, :, :3] - ref * 255).max(axis=2)
    assert np.all(img[:, :, 3] == 255)
    # pixels whose centre is within rounding of a facet edge may pick the
    # neighbour: allow them, but no more than 1% of the image
    assert np.mean(err > 1.0) < 0.01 and np.median(err) <= 0.5
    # The texture's renderers. Seen from inside, each voxel's entries are
    # single flat facets of this coarse sphere, so colours must be the
    # polygons' (compared un-premultiplied on black: the coverage of a single
    # voxel layer varies per ray, which is the method, not numerics), and no
    # pixel may be left at the background. From 0.02 away the camera is inside
    # the surface's voxel layer (h = 0.0625): splats and voxels are then
    # coarser than what is seen, so only sanity is required: opaque, and every
    # colour one the sphere's shading can take.
    normals = sphere.triangles.mean(axis=1)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    views = -d[:: SIZE // 4]  # a sample of the pixels' view vectors
    possible = np.concatenate(
        [shade_np(normals, v, (0.7, 0.5, 0.3), 0.3, 12.0, ONE_LIGHT) for v in views]
    )
    possible = np.clip(possible, 0, 1) * 255
    for method in METHODS[1:]:
        other = draw(r, sphere, cam, method)
        alpha = other[:, :, 3] / 255.0
        if where.startswith("inside"):
            assert alpha.min() > 0.0 and alpha.mean() > 0.85, (method, alpha.min(), alpha.mean())
            colour = other[:, :, :3] / np.maximum(alpha, 1 / 255)[:, :, None]
            diff = np.abs(colour - img[:, :, :3]).max(axis=2)
            assert np.median(diff) <= 1 and np.percentile(diff, 95) <= 3 and diff.max() <= 12, (
                method
            )
        else:
            assert np.all(alpha >= 250 / 255), method
            rgb = other[:, :, :3].reshape(-1, 3)
            assert np.all(rgb >= possible.min(axis=0) - 2) and np.all(
                rgb <= possible.max(axis=0) + 2
            ), method


def _telephoto(distance: float, d0: float = 5.0, fov0: float = 40.0) -> Camera:
    """A camera at ``distance`` whose field of view frames the unit sphere as
    one at d0 with fov0 would: far cameras must draw the same picture."""
    fov = 2 * np.degrees(np.arctan(np.tan(np.radians(fov0 / 2)) * d0 / distance))
    return Camera((0.0, 0.0, distance), (0.0, 0.0, 0.0), fov=fov)


def _far_cases():
    cases = []
    for method in METHODS:
        for distance in (1e4, 1e5, 1e7):
            cases.append(pytest.param(method, distance, id=f"{method}-{distance:g}"))
    return cases


@pytest.mark.gpu
@pytest.mark.parametrize("method, distance", _far_cases())
def test_very_far_camera_draws_what_a_near_telephoto_draws(gpu, method, distance):
    # From 1e3 to 1e7 times the sphere's radius with the field of view
    # narrowed to match, the picture is the same up to the (vanishing)
    # change of perspective: at most 0.5% of pixels may differ by > 2 levels
    # (the polygons differ in 0.1%, one silhouette pixel or two).
    # (Splats blend here, quality "high": with "fast", overlapping splats
    # take the nearest, and which one that is where two are equally near
    # flips with any change of the camera, in ~0.3% of pixels at any
    # distance.)
    sphere = scenes.sphere(1.0, subdivisions=3, center=(0.3, 0.2, 0.0))
    r = gpu["default"]
    thing = sphere
    if method != "mesh":
        tex = build_texture(sphere, 32, 32)
        thing = tex if method == "volume" else tex.to_points()
    opts = {"quality": "high"} if method == "splat" else {}
    ref = draw(r, thing, _telephoto(1e3), method, **opts)
    img = draw(r, thing, _telephoto(distance), method, **opts)
    assert (ref[:, :, 3] > 0).sum() > 500
    assert fraction_differing(img, ref) <= 0.005
    assert (
        np.abs((img[:, :, 3] > 0).sum() - (ref[:, :, 3] > 0).sum())
        <= 0.01 * (ref[:, :, 3] > 0).sum()
    )


@pytest.mark.gpu
@pytest.mark.parametrize("method", METHODS)
def test_far_camera_shows_a_small_object_at_the_right_place(gpu, method):
    # 200 radii away with a 40 degree lens the sphere is ~1 pixel: drawn at
    # its projected centre (alpha-weighted centroid within 0.6 px), with about
    # its projected area (4x4 supersampled), and nothing anywhere else.
    centre = np.array([60.0, -35.0, 10.0])
    sphere = scenes.sphere(1.0, subdivisions=3, center=centre)
    cam = Camera((0.0, 0.0, 200.0), (50.0, -30.0, 0.0), fov=40)
    opts = {**SOLID[method], **(BUILD if method != "mesh" else {})}
    img = gpu["default"].render(sphere, cam, method, alpha=True, ssaa=4, **opts)
    a = img[:, :, 3].astype(float) / 255
    px = cam.project(centre[None], (SIZE, SIZE))[0]
    ys, xs = np.mgrid[0:SIZE, 0:SIZE] + 0.5
    assert a.sum() > 0
    cx, cy = (a * xs).sum() / a.sum(), (a * ys).sum() / a.sum()
    assert abs(cx - px[0]) < 0.6 and abs(cy - px[1]) < 0.6, (cx, cy, px)
    dist = np.linalg.norm(centre - cam.position)
    radius_px = SIZE / (2 * dist * np.tan(np.radians(20))) * 1.0
    assert 0.5 * np.pi * radius_px**2 < a.sum() < 2.5 * np.pi * radius_px**2
    assert np.all(a[np.hypot(xs - px[0], ys - px[1]) > 3] == 0)


@pytest.mark.gpu
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("elevation", [10.0, 1.0, 0.1, 0.0])
def test_grazing_views_of_a_plane(gpu, method, elevation):
    # A unit square seen from `elevation` degrees above its plane, 4x4
    # supersampled. The polygons' coverage is its projected area to within a
    # quarter of the perimeter in pixels; the texture's renderers may add the
    # voxel layer's thickness (volume) or keep edge-on splats a pixel wide
    # (splat) but must draw nothing outside the square's projected band, and
    # at 10 degrees the same area as the polygons.
    quad = scenes.quad(size=1.0, normal_axis=1)
    e = np.radians(elevation)
    cam = Camera((0.0, 3 * np.sin(e), 3 * np.cos(e)), (0.0, 0.0, 0.0), fov=25)
    # squares from a texture tile their voxel's piece of the plane exactly
    opts = {
        "mesh": {},
        "volume": {"opacity": "linear"},
        "splat": {"splat": "square", "size_factor": 1.0},
    }[method]
    if method != "mesh":
        opts.update(resolution=16, directions=32)
    img = gpu["default"].render(quad, cam, method, alpha=True, ssaa=4, **opts)
    mass = img[:, :, 3].sum() / 255
    corners = np.array([[-0.5, 0, -0.5], [0.5, 0, -0.5], [0.5, 0, 0.5], [-0.5, 0, 0.5]])
    p = cam.project(corners, (SIZE, SIZE))
    area = 0.5 * abs(np.dot(p[:, 0], np.roll(p[:, 1], 1)) - np.dot(p[:, 1], np.roll(p[:, 0], 1)))
    perimeter = np.linalg.norm(p - np.roll(p, 1, axis=0), axis=1).sum()
    if method == "mesh" or elevation >= 10:
        assert abs(mass - area) <= 0.25 * perimeter, (mass, area)
    # nothing outside the projected square, grown by the voxel thickness h
    # (1/16 here: its projection on screen is 3 px) or by one pixel
    grow = 1.0 + (3.5 if method == "volume" else 0.0)
    rows, cols = np.nonzero(img[:, :, 3])
    if len(rows):
        assert cols.min() >= p[:, 0].min() - grow and cols.max() <= p[:, 0].max() + grow
        assert rows.min() >= p[:, 1].min() - grow - 1 and rows.max() <= p[:, 1].max() + grow
    if method == "splat" and elevation < 1:
        assert mass > 0  # an edge-on splat keeps the pixel of its centre


# -------------------------------------------------------------- splat sizes

needs_splat = pytest.mark.skipif("splat" not in METHODS, reason="render_splat not there yet")


@pytest.mark.gpu
@needs_splat
@pytest.mark.parametrize("shape", ["square", "disc", "ellipse"])
@pytest.mark.parametrize("quality", ["fast", "blend", "high"])
def test_splats_smaller_than_a_pixel_each_keep_their_pixel(gpu, shape, quality):
    # 300 splats of area 1e-10 (1e-4 of a pixel): each must light exactly the
    # pixel its centre projects into, no more, no fewer, in its own colour.
    rng = np.random.default_rng(1)
    n = 300
    pos = np.c_[rng.uniform(-1, 1, (n, 2)), np.zeros(n)]
    cloud = PointCloud(
        pos, np.tile([0, 0, 1.0], (n, 1)), np.full(n, 1e-10), (0.8, 0.3, 0.1), 0.2, 16.0
    )
    cam = Camera((0, 0, 3), (0, 0, 0), fov=50)
    img = gpu["one"].render(cloud, cam, "splat", alpha=True, splat=shape, quality=quality)
    if quality == "high":
        # Coverage-aware: each splat gives its projected area, 1e-4 of a
        # pixel, as a supersampled polygon of that size would: nothing shows.
        assert not img[:, :, 3].any()
        return
    want = {tuple(p) for p in np.floor(cam.project(pos, (SIZE, SIZE))).astype(int).tolist()}
    got = {(x, y) for y, x in zip(*np.nonzero(img[:, :, 3]), strict=True)}
    assert got == want
    ys, xs = np.nonzero(img[:, :, 3])
    d = pixel_rays(cam)[ys, xs]
    ref = np.clip(
        shade_np(np.tile([0, 0, 1.0], (len(d), 1)), -d, (0.8, 0.3, 0.1), 0.2, 16.0, ONE_LIGHT), 0, 1
    )
    # shaded at the splat, not the pixel centre: the view vector differs by
    # less than half a pixel's angle, which moves the colour < 1 level here
    assert np.abs(img[ys, xs, :3] - 255 * ref).max() <= 1.5


@pytest.mark.gpu
@needs_splat
@pytest.mark.parametrize("size", [64, 320])
@pytest.mark.parametrize("shape", ["square", "disc"])
@pytest.mark.parametrize("quality", ["fast", "blend", "high"])
def test_splat_larger_than_the_screen(gpu, size, shape, quality):
    # One splat of 20 x 20 units, 1 unit in front of the camera: it covers the
    # whole screen, shaded per pixel like the plane it is. At 320 px splats
    # wider than the largest point sprite go through the geometry path.
    # Then the same splat tilted 60 degrees and farther: its outline is the
    # perspective projection of its square to within a pixel along the edges.
    from aniso3d.rendering.renderer import Renderer
    from aniso3d.rendering.splat import shape_extent, tangent_frame

    r = gpu["one"] if size == SIZE else Renderer((size, size), lighting=ONE_LIGHT, gl=gpu["one"].gl)
    try:
        n = np.array([[0, 0, 1.0]])
        cloud = PointCloud([[0.0, 0.0, 0.0]], n, [400.0], (0.8, 0.3, 0.1), 0.2, 16.0)
        cam = Camera((0.1, 0.2, 1.0), (0.1, 0.2, 0.0), fov=60)
        img = r.render(cloud, cam, "splat", alpha=True, splat=shape, quality=quality)
        assert np.all(img[:, :, 3] == 255)
        d = cam.ray_directions((size, size)).reshape(-1, 3)
        ref = np.clip(
            shade_np(np.tile(n, (len(d), 1)), -d, (0.8, 0.3, 0.1), 0.2, 16.0, ONE_LIGHT), 0, 1
        )
        assert np.abs(img[:, :, :3].reshape(-1, 3) - 255 * ref).max() <= 1.0
        if shape != "square":
            return
        # tilted: a 2 x 2 square splat about the x axis by 60 degrees
        tilt = np.array([[0.0, -np.sin(np.pi / 3), np.cos(np.pi / 3)]])
        sq = PointCloud([[0.0, 0.0, 0.0]], tilt, [4.0], (0.8, 0.3, 0.1), 0.2, 16.0)
        cam = Camera((0.3, 0.1, 2.5), (0.0, 0.0, 0.0), fov=70)
        img = r.render(
            sq, cam, "splat", alpha=True, splat="square", quality=quality, size_factor=1.0
        )
        t, b = tangent_frame(tilt)
        ex, ey = shape_extent("square", 1.0)
        half = np.array([ex, ey]) * 2.0  # extents are per unit sqrt(area)
        corners = np.array(
            [
                sx * half[0] * t[0] + sy * half[1] * b[0]
                for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))
            ]
        )
        p = cam.project(corners, (size, size))
        area = 0.5 * abs(
            np.dot(p[:, 0], np.roll(p[:, 1], 1)) - np.dot(p[:, 1], np.roll(p[:, 0], 1))
        )
        perimeter = np.linalg.norm(p - np.roll(p, 1, axis=0), axis=1).sum()
        assert area > 0.15 * size * size  # a big splat, not a speck
        assert p.min() > 0 and p.max() < size  # all of it on screen
        # Coverage-aware "high" draws its edge pixels' covered fractions, so its
        # area is the sum of alpha (measured: within 0.15 px of the projected
        # area; pixels counted on or off: within 3.5 px).
        drawn = img[:, :, 3].sum() / 255 if quality == "high" else (img[:, :, 3] > 0).sum()
        assert abs(drawn - area) <= 0.5 * perimeter + 4
    finally:
        if r is not gpu["one"]:
            r.release()


# --------------------------------------------------------- far from the origin


@pytest.mark.gpu
@pytest.mark.parametrize("method", METHODS)
def test_scene_at_1e7_renders_like_at_the_origin(gpu, method):
    # The same data moved by (1e7, -3e6, 2e7) and the camera with it: float64
    # on the CPU, positions relative to a local origin on the GPU, so the
    # images must match but for rounding (ulp(2e7) = 4e-9 of 1 m: nothing).
    # The texture and the points are moved exactly (origin and centroids),
    # so only the renderers' own arithmetic is compared.
    tree = small_tree()
    far = np.asarray(FAR)
    c0 = Camera((6.0, 7.0, 9.0), (0.0, 5.0, 0.0), fov=45)
    c1 = Camera(tuple(far + c0.position), tuple(far + c0.target), fov=45)
    if method == "mesh":
        a = _dyadic(tree)  # so that the move itself is exact
        b = moved(a, shift=FAR)
    else:
        tex = build_texture(tree, 48, 32)
        a = tex if method == "volume" else tex.to_points()
        if method == "volume":
            b = replace(tex, origin=tex.origin + far, entry_centroid=tex.entry_centroid + far)
        else:
            b = PointCloud(a.positions + far, a.normals, a.areas, a.kd, a.ks, a.shininess,
                           coherence=a.coherence, one_sided=a.one_sided, clips=a.clips)  # fmt: skip
    ia = draw(gpu["default"], a, c0, method)
    ib = draw(gpu["default"], b, c1, method)
    assert (ia[:, :, 3] > 0).mean() > 0.08
    assert fraction_differing(ia, ib, levels=1) <= 0.002
    assert np.abs(ia[:, :, 3].astype(int) - ib[:, :, 3]).max() <= 2 or method == "splat"


# ------------------------------------------------------------- dense voxels


@pytest.mark.gpu
@pytest.mark.skipif("volume" not in METHODS, reason="render_volume not there yet")
@pytest.mark.parametrize("opacity", ["exponential", "linear"])
def test_dense_voxels_render_opaque_in_the_sheets_colour(gpu, opacity):
    # 40 stacked sheets, 10 in every voxel (density 10 along z, far above 1),
    # seen from above, below and obliquely: opaque, and coloured exactly like
    # one sheet (all have the same normal and material), to 1 level, from the
    # float64 reference. No overflow from summing 40 layers, no NaN.
    layers = 40
    sheets = [square(2, (k + 0.5) / layers, (0.0, 0.0), (1.0, 1.0)) for k in range(layers)]
    kd = (0.2, 0.6, 0.3)
    mesh = soup(np.concatenate(sheets), kd=kd, ks=0.4, shininess=8.0)
    tex = build_texture(mesh, 4, 64, bounds=np.array([[0.0] * 3, [1.0] * 3]))
    assert tex.density.max() > 9.5  # 10 sheets per voxel
    for eye in [(0.5, 0.5, 3.0), (0.6, 0.4, -2.0), (2.3, 1.9, 2.2)]:
        cam = Camera(eye, (0.5, 0.5, 0.5), fov=20)
        img = draw(gpu["one"], tex, cam, "volume", opacity=opacity)
        centre = (slice(26, 38), slice(26, 38))
        assert np.all(img[centre][:, :, 3] == 255), (eye, img[centre][:, :, 3].min())
        d = pixel_rays(cam)[centre].reshape(-1, 3)
        ref = (
            np.clip(shade_np(np.tile([0, 0, 1.0], (len(d), 1)), -d, kd, 0.4, 8.0, ONE_LIGHT), 0, 1)
            * 255
        )
        assert np.abs(img[centre][:, :, :3].reshape(-1, 3) - ref).max() <= 1.0, eye


# ---------------------------------------------------------------------- leaks


def _rss_kib() -> int:
    """Current resident set size (not the peak), KiB."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * resource.getpagesize() // 1024


@pytest.mark.gpu
def test_renderers_release_every_gpu_object(gpu):
    # On a shared context every upload, framebuffer and per-method object a
    # Renderer made is gone after release(), for every method and option that
    # allocates something of its own (ssaa sizes, splat quality "high").
    from aniso3d.rendering.renderer import Renderer

    gl = gpu["default"].gl
    before = gl.n_objects
    sphere = scenes.sphere(1.0, subdivisions=2)
    cam = Camera((0, 0, 3), (0, 0, 0))
    for _ in range(3):
        r = Renderer((48, 48), gl=gl)
        for method in METHODS:
            for opts in ({}, {"ssaa": 2}) + (({"quality": "high"},) if method == "splat" else ()):
                r.render(sphere, cam, method, **opts, **(BUILD if method != "mesh" else {}))
        assert gl.n_objects > before
        r.release()
        assert gl.n_objects == before


@pytest.mark.gpu
@pytest.mark.parametrize("method", METHODS)
def test_no_memory_growth_over_many_renderers_and_frames(gpu, method):  # gpu: skip without GL
    # Renderers made and released 12 times (each with its own context), and
    # 150 frames on one renderer: the process must not grow. Current RSS, not
    # the peak, so that growth anywhere is seen; 16 MiB is far below one
    # leaked context (~40 MiB on llvmpipe) or 150 leaked 64x64 framebuffers
    # plus their uploads.
    from aniso3d.rendering.renderer import Renderer

    sphere = scenes.sphere(1.0, subdivisions=2)
    thing = sphere
    if method != "mesh":
        tex = build_texture(sphere, 16, 16)
        thing = tex if method == "volume" else tex.to_points()
    cam = Camera((0, 0, 3), (0, 0, 0))

    def cycle():
        with Renderer((64, 64)) as r:
            for ssaa in (1, 2):
                r.render(thing, cam, method, ssaa=ssaa)

    for _ in range(3):
        cycle()
    gc.collect()
    before = _rss_kib()
    for _ in range(12):
        cycle()
    gc.collect()
    assert _rss_kib() - before < 16 * 1024, (
        f"RSS grew {(_rss_kib() - before) / 1024:.1f} MiB over 12 renderers"
    )

    with Renderer((64, 64)) as r:
        cams = [cam.orbit(3.0 * i) for i in range(150)]
        for c in cams[:10]:
            r.render(thing, c, method)
        gc.collect()
        before, objects = _rss_kib(), r.gl.n_objects
        for c in cams:
            r.render(thing, c, method)
        gc.collect()
        assert r.gl.n_objects == objects  # no GPU object made per frame
        assert _rss_kib() - before < 16 * 1024
