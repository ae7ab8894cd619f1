"""Stage 4: oriented points from a texture, and their PLY files."""

from __future__ import annotations

import numpy as np
import plyfile
import pytest
from conftest import build_open

from aniso3d import FormatError, InputError, Mesh, PointCloud, build_texture, scenes
from aniso3d.build.bounds import bounds_of
from aniso3d.build.mesh import concatenate
from aniso3d.build.ply import read_ply_header
from aniso3d.build.texture import entry_points

UNIT_BOX = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])


@pytest.fixture(scope="module")
def tree_texture():
    mesh = scenes.tree(levels=4, leaves_per_twig=20)
    return mesh, build_open(mesh, 16, 24)


# --------------------------------------------------------------------- areas


@pytest.mark.parametrize("placement", ["centroid", "center", "sphere"])
@pytest.mark.parametrize("per_entry", [1, 3])
@pytest.mark.parametrize("normal", ["mean", "sample"])
def test_point_areas_sum_to_mesh_area(tree_texture, placement, per_entry, normal):
    mesh, tex = tree_texture
    pc = tex.to_points(placement=placement, per_entry=per_entry, normal=normal)
    assert len(pc) == tex.n_entries * per_entry
    assert pc.total_area() == pytest.approx(mesh.area(), rel=1e-12)
    assert np.all(pc.areas > 0)
    np.testing.assert_allclose(np.linalg.norm(pc.normals, axis=1), 1.0, rtol=1e-6)
    # material carried over from the entries
    np.testing.assert_array_equal(pc.kd[::per_entry], tex.entry_kd)
    np.testing.assert_array_equal(pc.ks[::per_entry], tex.entry_ks)
    np.testing.assert_array_equal(pc.shininess[::per_entry], tex.entry_shininess)


# ----------------------------------------------------------------- placement


def test_centroid_of_a_single_quad_is_its_centre():
    centre = np.array([0.3, -1.2, 4.0])
    q = scenes.quad(size=2.0, center=centre, normal_axis=1)
    tex = build_texture(q, 1, 16)
    pc = tex.to_points("centroid")
    assert len(pc) == 1
    np.testing.assert_allclose(pc.positions[0], centre, atol=1e-12)
    np.testing.assert_allclose(pc.normals[0], [0, 1, 0], atol=1e-7)
    assert pc.areas[0] == pytest.approx(4.0)


def test_centroid_points_lie_on_the_quad_and_average_to_its_centre():
    centre = np.array([0.5, 0.5, 0.37])
    q = scenes.quad(size=0.9, center=centre)
    tex = build_texture(q, 5, 16, bounds=UNIT_BOX)
    pc = tex.to_points("centroid")
    assert len(pc) > 1
    np.testing.assert_allclose(pc.positions[:, 2], 0.37, atol=1e-14)
    mean = (pc.areas[:, None] * pc.positions).sum(0) / pc.areas.sum()
    np.testing.assert_allclose(mean, centre, atol=1e-12)
    # each point is inside its voxel
    cells = np.floor((pc.positions - tex.origin) / tex.voxel_size).astype(int)
    np.testing.assert_array_equal(cells, tex.coords[tex.entry_voxel])


def test_center_placement_gives_voxel_centres(tree_texture):
    _, tex = tree_texture
    pc = tex.to_points("center")
    want = tex.origin + (tex.coords[tex.entry_voxel] + 0.5) * tex.voxel_size
    np.testing.assert_allclose(pc.positions, want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(pc.positions, tex.voxel_centers()[tex.entry_voxel], atol=1e-12)


def test_sphere_placement_is_on_the_virtual_sphere(tree_texture):
    _, tex = tree_texture
    pc = tex.to_points("sphere", normal="sample")
    offset = pc.positions - tex.voxel_centers()[tex.entry_voxel]
    np.testing.assert_allclose(np.linalg.norm(offset, axis=1), 0.5 * tex.voxel_size, rtol=1e-12)
    np.testing.assert_allclose(
        offset / (0.5 * tex.voxel_size), tex.directions[tex.entry_direction], atol=1e-12
    )
    np.testing.assert_allclose(pc.normals, tex.directions[tex.entry_direction], atol=1e-6)


def test_mean_normal_of_a_two_sided_sheet():
    up = scenes.quad(size=1.0, center=(0.5, 0.5, 0.5))
    # the same square a quarter voxel lower, facing -z (drawn at the same
    # place it would repeat the first: test_texture.py)
    down = Mesh.from_arrays(up.vertices - [0.0, 0.0, 0.25], up.faces[:, ::-1])
    sheet = concatenate([up, down])
    # K = 16: the two sides register at different samples, each keeps its normal
    tex = build_texture(sheet, 1, 16, bounds=UNIT_BOX)
    pc = tex.to_points(normal="mean")
    np.testing.assert_allclose(sorted(pc.normals[:, 2]), [-1, 1], atol=1e-7)
    # K = 1: both sides share the only sample, their mean normal cancels and the
    # sample direction is used instead of a NaN
    tex1 = build_texture(sheet, 1, 1, bounds=UNIT_BOX)
    assert tex1.n_entries == 1
    np.testing.assert_allclose(tex1.entry_normal, 0.0, atol=1e-7)
    pc1 = tex1.to_points(normal="mean")
    np.testing.assert_allclose(pc1.normals, tex1.directions.astype(np.float32), atol=1e-6)
    assert pc1.total_area() == pytest.approx(2.0)


def test_per_entry_points_stay_in_the_tangent_plane_and_near_the_entry():
    q = scenes.quad(size=0.9, center=(0.5, 0.5, 0.37))
    tex = build_texture(q, 3, 16, bounds=UNIT_BOX)
    pc = tex.to_points("centroid", per_entry=5)
    np.testing.assert_allclose(pc.positions[:, 2], 0.37, atol=1e-14)
    centres = np.repeat(tex.entry_centroid, 5, axis=0)
    assert np.all(np.linalg.norm(pc.positions - centres, axis=1) <= 0.5 * tex.voxel_size + 1e-12)
    np.testing.assert_allclose(pc.areas, np.repeat(tex.entry_area * tex.voxel_size**2 / 5, 5))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"placement": "corner"}, "placement"),
        ({"normal": "up"}, "normal"),
        ({"per_entry": 0}, "per entry"),
        ({"per_entry": 1.5}, "per entry"),
        ({"per_entry": True}, "per entry"),
    ],
)
def test_to_points_rejects_bad_options(tree_texture, kwargs, match):
    _, tex = tree_texture
    with pytest.raises(InputError, match=match):
        tex.to_points(**kwargs)


# ---------------------------------------------------------------- PointCloud


def test_point_cloud_validation():
    p = np.zeros((2, 3))
    n = np.array([[0, 0, 1], [0, 2, 0]], float)
    pc = PointCloud(p, n, [1.0, 2.0], (0.5, 0.5, 0.5), 0.1, 10.0)
    np.testing.assert_allclose(pc.normals, [[0, 0, 1], [0, 1, 0]])  # normalised
    assert pc.kd.shape == (2, 3) and pc.ks.shape == (2,)
    with pytest.raises(InputError, match="zero normal"):
        PointCloud(p, [[0, 0, 1], [0, 0, 0]], [1.0, 1.0], (0.5,) * 3, 0.1, 1.0)
    with pytest.raises(InputError, match="NaN"):
        PointCloud([[np.nan, 0, 0], [0, 0, 0]], n, [1.0, 1.0], (0.5,) * 3, 0.1, 1.0)
    with pytest.raises(InputError, match="non-negative"):
        PointCloud(p, n, [1.0, -1.0], (0.5,) * 3, 0.1, 1.0)
    with pytest.raises(InputError, match="shape"):
        PointCloud(p, n[:1], [1.0, 1.0], (0.5,) * 3, 0.1, 1.0)
    with pytest.raises(InputError, match="empty"):
        PointCloud(np.zeros((0, 3)), np.zeros((0, 3)), [], (0.5,) * 3, 0.1, 1.0).bounds  # noqa: B018


# ----------------------------------------------------------------------- PLY


def test_ply_round_trip_float32(tree_texture, tmp_path):
    _, tex = tree_texture
    pc = tex.to_points()
    path = pc.save_ply(tmp_path / "pts.ply")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pts.ply"]  # no temp file left
    back = PointCloud.load_ply(path)
    assert len(back) == len(pc)
    f32 = lambda a: np.asarray(a, np.float32).astype(np.float64)  # noqa: E731
    np.testing.assert_array_equal(back.positions, f32(pc.positions))
    np.testing.assert_allclose(back.normals, pc.normals, atol=1e-6)
    np.testing.assert_array_equal(back.areas, f32(pc.areas))
    np.testing.assert_allclose(back.kd, np.round(pc.kd * 255) / 255, atol=1e-6)
    np.testing.assert_array_equal(back.ks, pc.ks)
    np.testing.assert_array_equal(back.shininess, pc.shininess)
    assert back.name == "pts"


def test_trimesh_opens_our_ply(tree_texture, tmp_path):
    import trimesh

    _, tex = tree_texture
    pc = tex.to_points()
    pc.save_ply(tmp_path / "pts.ply")
    loaded = trimesh.load(tmp_path / "pts.ply")
    assert isinstance(loaded, trimesh.PointCloud)
    assert len(loaded.vertices) == len(pc)
    np.testing.assert_allclose(loaded.vertices, pc.positions, rtol=1e-6, atol=1e-6)
    # and plyfile, another reader, sees every property we wrote
    raw = plyfile.PlyData.read(str(tmp_path / "pts.ply"))["vertex"].data
    assert {"nx", "ny", "nz", "area", "ks", "shininess", "red"} <= set(raw.dtype.names)
    np.testing.assert_array_equal(raw["area"], pc.areas.astype(np.float32))


def test_ply_without_normals_is_a_clear_input_error(tmp_path):
    import trimesh

    trimesh.PointCloud(np.random.default_rng(0).random((10, 3))).export(tmp_path / "raw.ply")
    with pytest.raises(InputError, match="no normals"):
        PointCloud.load_ply(tmp_path / "raw.ply")


def test_foreign_ply_with_normals_gets_default_area_and_colour(tmp_path):
    n = 50
    rng = np.random.default_rng(1)
    pos = rng.random((n, 3)).astype("<f4")
    nrm = np.tile(np.array([0, 0, 1], "<f4"), (n, 1))
    header = (
        "ply\nformat binary_little_endian 1.0\nelement vertex 50\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property float nx\nproperty float ny\nproperty float nz\nend_header\n"
    )
    (tmp_path / "foreign.ply").write_bytes(
        header.encode() + np.concatenate([pos, nrm], 1).tobytes()
    )
    pc = PointCloud.load_ply(tmp_path / "foreign.ply")
    assert len(pc) == n and np.all(pc.areas > 0) and np.all(np.isfinite(pc.areas))
    pc2 = PointCloud.load_ply(tmp_path / "foreign.ply", default_area=0.25)
    np.testing.assert_array_equal(pc2.areas, 0.25)
    np.testing.assert_allclose(pc2.kd, 0.7, atol=1e-6)


def test_bad_ply_files(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        PointCloud.load_ply(tmp_path / "none.ply")
    (tmp_path / "empty.ply").write_bytes(b"")
    with pytest.raises(InputError, match="empty"):
        PointCloud.load_ply(tmp_path / "empty.ply")
    (tmp_path / "noise.ply").write_bytes(np.random.default_rng(0).bytes(3000))
    with pytest.raises(FormatError):
        PointCloud.load_ply(tmp_path / "noise.ply")


def test_ply_save_refuses_missing_folder(tree_texture, tmp_path):
    _, tex = tree_texture
    with pytest.raises(InputError, match="does not exist"):
        tex.to_points().save_ply(tmp_path / "missing" / "x.ply")


def test_ply_header_is_read_once_for_every_reader(tree_texture, tmp_path):
    _, tex = tree_texture
    pc = tex.to_points()
    pc.save_ply(tmp_path / "pts.ply")
    head = read_ply_header(tmp_path / "pts.ply")
    assert head.format == "binary_little_endian"
    assert head.elements == {"vertex": len(pc)} and head.is_point_cloud
    assert head.properties["vertex"] == ("x", "y", "z", "nx", "ny", "nz", "red", "green", "blue",
                                         "area", "ks", "shininess")  # fmt: skip
    mesh = scenes.sphere(1.0, subdivisions=1)
    mesh.to_trimesh().export(tmp_path / "mesh.ply")
    head = read_ply_header(tmp_path / "mesh.ply")
    assert head.count("face") == mesh.n_faces and not head.is_point_cloud
    assert head.count("edge") == 0


@pytest.mark.parametrize(
    "content, match",
    [
        (b"solid x\n", "does not start with 'ply'"),
        (b"ply\nformat ascii 1.0\nelement vertex many\nend_header\n", "damaged PLY header line"),
        (b"ply\nformat ascii 1.0\nproperty float x\nend_header\n", "damaged PLY header line"),
        (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n", "no 'end_header'"),
    ],
)
def test_damaged_ply_headers_are_refused(tmp_path, content, match):
    path = tmp_path / "bad.ply"
    path.write_bytes(content)
    with pytest.raises(FormatError, match=match):
        read_ply_header(path)
    with pytest.raises(FormatError, match=match):
        PointCloud.load_ply(path)


@pytest.mark.parametrize("text", [True, False])
def test_foreign_ascii_and_big_endian_ply_with_colours(tmp_path, text):
    # Written by plyfile, not by us: ASCII, or binary in the other byte order,
    # with float colours in [0, 1] and doubles for positions.
    n = 20
    rng = np.random.default_rng(2)
    rec = np.empty(n, dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("nx", "f4"), ("ny", "f4"), ("nz", "f4"),
                             ("red", "f4"), ("green", "f4"), ("blue", "f4"), ("area", "f4")])  # fmt: skip
    pos = rng.uniform(-1, 1, (n, 3))
    rgb = rng.uniform(0, 1, (n, 3)).astype(np.float32)
    for i, c in enumerate("xyz"):
        rec[c] = pos[:, i]
        rec["n" + c] = [0.0, 1.0, 0.0][i]
    rec["red"], rec["green"], rec["blue"] = rgb.T
    rec["area"] = 0.5
    el = plyfile.PlyElement.describe(rec, "vertex")
    plyfile.PlyData([el], text=text, byte_order=">").write(str(tmp_path / "f.ply"))
    pc = PointCloud.load_ply(tmp_path / "f.ply")
    np.testing.assert_array_equal(pc.positions, pos)  # doubles kept exactly
    np.testing.assert_array_equal(pc.kd, rgb)  # float colours are not divided by 255
    np.testing.assert_array_equal(pc.normals, np.tile([0, 1, 0], (n, 1)))
    np.testing.assert_array_equal(pc.areas, 0.5)


def test_truncated_binary_point_cloud_is_a_format_error(tree_texture, tmp_path):
    _, tex = tree_texture
    path = tex.to_points().save_ply(tmp_path / "pts.ply")
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(FormatError, match="could not read PLY"):
        PointCloud.load_ply(path)


# ------------------------------------------------------- entries -> points


def test_entry_points_of_some_voxels_are_those_of_to_points(tree_texture):
    _, tex = tree_texture
    voxels = np.array([5, 0, tex.n_voxels - 1, 17])  # any order: kept
    ent = np.concatenate([np.arange(tex.entry_offsets[v], tex.entry_offsets[v + 1]) for v in voxels])
    for placement, per_entry in (("centroid", 1), ("center", 1), ("sphere", 4), ("centroid", 3)):
        full = tex.to_points(placement, per_entry)
        rows = (ent[:, None] * per_entry + np.arange(per_entry)).reshape(-1)
        part = PointCloud(*entry_points(tex, voxels, placement, per_entry))
        for name in ("positions", "normals", "areas", "kd", "ks", "shininess"):
            assert np.array_equal(getattr(part, name), getattr(full, name)[rows]), (placement, per_entry, name)


def test_entry_points_with_counts_per_entry(tree_texture):
    _, tex = tree_texture
    counts = (np.arange(tex.n_entries) % 4 + 1).astype(np.int32)
    pos, nrm, area, kd, _, _ = entry_points(tex, per_entry=counts)
    assert len(pos) == counts.sum()
    # each entry's area is split evenly among its points, its material repeated
    np.testing.assert_allclose(np.repeat(tex.entry_area * tex.voxel_size**2 / counts, counts), area, rtol=1e-15)
    np.testing.assert_array_equal(np.repeat(tex.entry_kd, counts, axis=0), kd)
    # the points of an entry lie in its tangent plane through its centroid, within h/2
    src = np.repeat(np.arange(tex.n_entries), counts)
    offset = pos - tex.entry_centroid[src]
    assert np.abs(np.sum(offset * nrm, axis=1)).max() < 1e-12 * tex.voxel_size + 1e-15
    assert np.linalg.norm(offset, axis=1).max() <= 0.5 * tex.voxel_size * (1 + 1e-12)
    # one count for all is the same as that count everywhere
    same = entry_points(tex, per_entry=np.full(tex.n_entries, 3))
    for a, b in zip(same, entry_points(tex, per_entry=3), strict=True):
        assert np.array_equal(a, b)
    for bad in (counts[:-1], np.zeros(tex.n_entries, int), np.full(tex.n_entries, 1.5)):
        with pytest.raises(InputError, match="per-entry point counts"):
            entry_points(tex, per_entry=bad)


# ------------------------------------------------------------------- bounds


def test_bounds_of_a_point_cloud_include_the_splats():
    pc = PointCloud([[0, 0, 0], [1, 2, 3]], [[0, 0, 1]] * 2, [np.pi, 4 * np.pi], (0.5,) * 3, 0.1, 1.0)
    # radii sqrt(area / pi) = 1 and 2
    np.testing.assert_allclose(bounds_of(pc), [[-1, -1, -1], [3, 4, 5]], rtol=0, atol=1e-15)
    empty = PointCloud(np.zeros((0, 3)), np.zeros((0, 3)), [], (0.5,) * 3, 0.1, 1.0)
    with pytest.raises(InputError, match="point cloud is empty"):
        bounds_of(empty)
    with pytest.raises(InputError, match="cannot draw a str"):
        bounds_of("tree.obj")
