"""Stage 4: oriented points from a texture, and their PLY files."""

from __future__ import annotations

import numpy as np
import plyfile
import pytest

from aniso3d import FormatError, InputError, Mesh, PointCloud, build_texture, scenes
from aniso3d.build.mesh import concatenate

UNIT_BOX = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])


@pytest.fixture(scope="module")
def tree_texture():
    mesh = scenes.tree(levels=4, leaves_per_twig=20)
    return mesh, build_texture(mesh, 16, 24)


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
    down = Mesh.from_arrays(up.vertices, up.faces[:, ::-1])  # same square, facing -z
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
