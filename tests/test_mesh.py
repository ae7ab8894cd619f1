"""Stage 1: the Mesh object, loading files with their materials, built-in scenes."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from aniso3d import InputError, Mesh, load_mesh, scenes
from aniso3d.build.mesh import DEFAULT_KD, DEFAULT_KS, DEFAULT_SHININESS, MAX_SHININESS, concatenate

BYTE = 1.0 / 255 + 1e-7  # colours pass through 8-bit storage in most formats


def centroids(mesh: Mesh) -> np.ndarray:
    return mesh.triangles.mean(axis=1)


# ------------------------------------------------------------------ Mesh object


def test_mesh_from_arrays_broadcasts_material_and_types():
    m = Mesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2], [0, 1, 3]])
    assert m.vertices.dtype == np.float64 and m.faces.dtype == np.int64
    assert m.kd.shape == (2, 3) and m.kd.dtype == np.float32
    np.testing.assert_allclose(m.kd, [DEFAULT_KD] * 2)
    np.testing.assert_allclose(m.ks, DEFAULT_KS)
    np.testing.assert_allclose(m.shininess, DEFAULT_SHININESS)
    np.testing.assert_allclose(m.face_areas(), [0.5, 0.5])
    assert m.area() == pytest.approx(1.0)
    assert m.n_faces == 2 and m.triangles.shape == (2, 3, 3)
    assert m.nbytes == 4 * 12 + 2 * 12 + 2 * 20


def test_mesh_clamps_material_to_valid_ranges():
    m = Mesh.from_arrays(
        [[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], kd=[[2.0, -1.0, 0.5]], ks=7.0, shininess=1e9
    )
    np.testing.assert_allclose(m.kd, [[1.0, 0.0, 0.5]])
    assert m.ks[0] == 1.0 and m.shininess[0] == MAX_SHININESS


def test_bounds_ignore_unused_vertices():
    m = Mesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [100, 100, 100]], [[0, 1, 2]])
    np.testing.assert_array_equal(m.bounds, [[0, 0, 0], [1, 1, 0]])


@pytest.mark.parametrize(
    "vertices, faces, kwargs, match",
    [
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2, 0]], {}, "triangulate"),
        ([[0, 0], [1, 0], [0, 1]], [[0, 1, 2]], {}, r"\(V, 3\)"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.zeros((0, 3), int), {}, "no faces"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0.0, 1.0, 2.0]], {}, "integer"),
        ([[0, 0, 0], [np.nan, 0, 0], [0, 1, 0]], [[0, 1, 2]], {}, "NaN"),
        ([[0, 0, 0], [np.inf, 0, 0], [0, 1, 0]], [[0, 1, 2]], {}, "Inf"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]], {}, "outside 0..2"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, -1, 2]], {}, "outside"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], {"kd": [[1, 0, 0]] * 2}, "kd"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], {"ks": np.nan}, "NaN"),
    ],
    ids=["quads", "2d", "no-faces", "float-faces", "nan", "inf", "index-high", "index-negative",
         "kd-shape", "ks-nan"],
)  # fmt: skip
def test_mesh_rejects_bad_arrays(vertices, faces, kwargs, match):
    with pytest.raises(InputError, match=match):
        Mesh.from_arrays(np.asarray(vertices, float), np.asarray(faces), **kwargs)


def test_transformed_and_trimesh_round_trip():
    m = scenes.cube(size=2.0, kd=(0.2, 0.4, 0.6))
    t = np.eye(4)
    t[:3, 3] = [10, 0, -5]
    moved = m.transformed(t)
    np.testing.assert_allclose(moved.bounds, m.bounds + [[10, 0, -5]])
    assert moved.area() == pytest.approx(m.area())
    tm = m.to_trimesh()
    assert len(tm.faces) == m.n_faces and tm.area == pytest.approx(24.0)
    np.testing.assert_allclose(tm.visual.face_colors[:, :3] / 255, m.kd, atol=BYTE)


def test_concatenate_keeps_each_faces_material():
    a = scenes.quad(kd=(1, 0, 0), ks=0.3, shininess=5)
    b = scenes.quad(center=(0, 0, 1), kd=(0, 0, 1), ks=0.9, shininess=50)
    m = concatenate([a, b], name="ab")
    assert m.n_faces == 4 and m.name == "ab"
    np.testing.assert_allclose(m.kd, [[1, 0, 0]] * 2 + [[0, 0, 1]] * 2)
    np.testing.assert_allclose(m.ks, [0.3, 0.3, 0.9, 0.9], rtol=1e-6)
    np.testing.assert_allclose(m.triangles[2:], b.triangles)
    with pytest.raises(InputError, match="empty"):
        concatenate([])


# --------------------------------------------------------------------- loading

MTL = """\
newmtl leaf
Kd 0.1 0.6 0.2
Ks 0.4 0.4 0.4
Ns 40
newmtl bark
Kd 0.4 0.25 0.1
Ks 0.05 0.05 0.05
Ns 8
"""

OBJ = """\
mtllib two.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 5 5 5
v 6 5 5
v 5 6 5
usemtl leaf
f 1 2 3
f 1 3 4
usemtl bark
f 1 2 6 5
f 7 8 9
"""


def test_obj_with_mtl_gives_per_face_material(tmp_path):
    (tmp_path / "two.mtl").write_text(MTL)
    (tmp_path / "two.obj").write_text(OBJ)
    m = load_mesh(tmp_path / "two.obj")
    assert m.name == "two"
    assert m.n_faces == 5  # the quad face is triangulated
    assert m.area() == pytest.approx(1.0 + 1.0 + 0.5)
    c = centroids(m)
    leaf = np.isclose(c[:, 2], 0.0)
    bark = ~leaf
    assert leaf.sum() == 2 and bark.sum() == 3
    np.testing.assert_allclose(m.kd[leaf], [[0.1, 0.6, 0.2]] * 2, atol=BYTE)
    np.testing.assert_allclose(m.kd[bark], [[0.4, 0.25, 0.1]] * 3, atol=BYTE)
    np.testing.assert_allclose(m.ks[leaf], 0.4, atol=BYTE)
    np.testing.assert_allclose(m.ks[bark], 0.05, atol=BYTE)
    np.testing.assert_allclose(m.shininess[leaf], 40.0)
    np.testing.assert_allclose(m.shininess[bark], 8.0)


def test_a_zero_exponent_is_no_highlight(tmp_path):
    """MeshLab and Blender write ``Ns 0`` for no highlight, glTF roughness 1
    maps to exponent 0: both load as LEAST_SHININESS, not as a constant lobe
    that adds ks to every lit pixel (a Ks 0.8 sphere drew white on white)."""
    import trimesh

    from aniso3d.build.mesh import LEAST_SHININESS
    from aniso3d.rendering.lighting import Lighting, shade_np

    (tmp_path / "rough.mtl").write_text("newmtl rough\nKd 0.2 0.4 0.8\nKs 0.8 0.8 0.8\nNs 0\n")
    (tmp_path / "rough.obj").write_text("mtllib rough.mtl\nusemtl rough\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    m = load_mesh(tmp_path / "rough.obj")
    np.testing.assert_allclose(m.shininess, [LEAST_SHININESS])
    assert LEAST_SHININESS >= 1.0
    # Seen head-on, off the light's mirror direction: the highlight is a
    # share of ks (at exponent 0 it was all of it).
    n = np.array([[0.0, 0.0, 1.0]])
    view = n
    kd, ks = np.array([[0.2, 0.4, 0.8]]), np.array([0.8])
    light = Lighting()
    flat = shade_np(n, view, kd, ks, np.array([0.0]), light)
    read = shade_np(n, view, kd, ks, m.shininess, light)
    assert np.all(read < flat - 0.1)

    tri = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], process=False)
    tri.visual = trimesh.visual.TextureVisuals(
        material=trimesh.visual.material.PBRMaterial(baseColorFactor=[0.2, 0.4, 0.6, 1.0], roughnessFactor=1.0,
                                                     metallicFactor=1.0)  # fmt: skip
    )
    tri.export(tmp_path / "rough.glb")
    np.testing.assert_allclose(load_mesh(tmp_path / "rough.glb").shininess, [LEAST_SHININESS])


def test_obj_without_mtl_gets_defaults(tmp_path):
    (tmp_path / "plain.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    m = load_mesh(tmp_path / "plain.obj", name="custom")
    assert m.name == "custom" and m.n_faces == 1
    np.testing.assert_allclose(m.kd, [DEFAULT_KD])
    np.testing.assert_allclose(m.ks, [DEFAULT_KS])
    np.testing.assert_allclose(m.shininess, [DEFAULT_SHININESS])


def _coloured_quad():
    import trimesh

    tm = trimesh.Trimesh(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]], process=False
    )
    tm.visual.face_colors = [[255, 0, 0, 255], [0, 128, 255, 255]]
    return tm


def test_ply_with_face_colours(tmp_path):
    _coloured_quad().export(tmp_path / "q.ply")
    m = load_mesh(tmp_path / "q.ply")
    assert m.n_faces == 2 and m.area() == pytest.approx(1.0)
    np.testing.assert_allclose(m.kd, [[1, 0, 0], [0, 128 / 255, 1]], atol=BYTE)


def test_ply_with_vertex_colours_averages_per_face(tmp_path):
    import trimesh

    tm = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], process=False)
    tm.visual.vertex_colors = [[255, 0, 0, 255], [0, 255, 0, 255], [0, 0, 255, 255]]
    tm.export(tmp_path / "v.ply")
    m = load_mesh(tmp_path / "v.ply")
    np.testing.assert_allclose(m.kd, [[1 / 3, 1 / 3, 1 / 3]], atol=BYTE)


def test_stl(tmp_path):
    scenes.cube(size=2.0).to_trimesh().export(tmp_path / "c.stl")
    m = load_mesh(tmp_path / "c.stl")
    assert m.n_faces == 12 and m.area() == pytest.approx(24.0, rel=1e-6)
    np.testing.assert_allclose(m.kd, np.tile(DEFAULT_KD, (12, 1)))


def test_glb_exported_by_trimesh_keeps_face_colours(tmp_path):
    tm = _coloured_quad()
    tm.unmerge_vertices()  # glTF stores colours per vertex: keep faces apart
    tm.export(tmp_path / "q.glb")
    m = load_mesh(tmp_path / "q.glb")
    assert m.n_faces == 2 and m.area() == pytest.approx(1.0)
    c = centroids(m)
    first = c[:, 0] > c[:, 1]  # face [0, 1, 2] lies below the diagonal
    np.testing.assert_allclose(m.kd[first], [[1, 0, 0]], atol=BYTE)
    np.testing.assert_allclose(m.kd[~first], [[0, 128 / 255, 1]], atol=BYTE)


def test_glb_pbr_material_and_scene_transforms(tmp_path):
    import trimesh

    tri = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], process=False)
    tri.visual = trimesh.visual.TextureVisuals(
        material=trimesh.visual.material.PBRMaterial(
            baseColorFactor=[0.2, 0.4, 0.6, 1.0], roughnessFactor=0.5, metallicFactor=0.0
        )
    )
    scene = trimesh.Scene()
    t = np.eye(4)
    t[:3, 3] = [10, 20, 30]
    scene.add_geometry(tri, transform=t)
    scene.export(tmp_path / "pbr.glb")
    m = load_mesh(tmp_path / "pbr.glb")
    np.testing.assert_allclose(m.bounds, [[10, 20, 30], [11, 21, 30]], atol=1e-6)
    np.testing.assert_allclose(m.kd, [[0.2, 0.4, 0.6]], atol=BYTE)
    # roughness 0.5 -> Blinn-Phong exponent 2 / r^4 - 2 = 30, ks = 0.04 + 0.5 (1 - r)
    np.testing.assert_allclose(m.shininess, [30.0], rtol=1e-5)
    np.testing.assert_allclose(m.ks, [0.29], rtol=1e-5)


# ---------------------------------------------------------------- load errors


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="does not exist") as info:
        load_mesh(tmp_path / "nope.obj")
    assert "nope.obj" in str(info.value)


def test_directory(tmp_path):
    with pytest.raises(InputError, match="directory"):
        load_mesh(tmp_path)


def test_empty_file(tmp_path):
    (tmp_path / "e.obj").write_bytes(b"")
    with pytest.raises(InputError, match="empty"):
        load_mesh(tmp_path / "e.obj")


@pytest.mark.parametrize("name", ["mesh.xyz", "mesh", "mesh.obj.bak"])
def test_unknown_suffix(tmp_path, name):
    (tmp_path / name).write_text("v 0 0 0\n")
    with pytest.raises(InputError, match="suffix") as info:
        load_mesh(tmp_path / name)
    assert ".obj" in str(info.value)  # lists what is supported


def test_nan_coordinates_in_a_file(tmp_path):
    (tmp_path / "nan.obj").write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputError, match="NaN") as info:
        load_mesh(tmp_path / "nan.obj")
    assert "nan.obj" in str(info.value)


def test_faces_indexing_missing_vertices_in_a_file(tmp_path):
    (tmp_path / "bad.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n")
    with pytest.raises(InputError) as info:
        load_mesh(tmp_path / "bad.obj")
    assert "bad.obj" in str(info.value)


def test_garbage_with_a_mesh_suffix(tmp_path):
    for suffix in (".stl", ".ply", ".glb", ".obj"):
        p = tmp_path / f"junk{suffix}"
        p.write_bytes(np.random.default_rng(3).bytes(2000))
        with pytest.raises(InputError) as info:
            load_mesh(p)
        assert p.name in str(info.value), suffix


def test_point_cloud_file_is_not_a_mesh(tmp_path):
    import trimesh

    trimesh.PointCloud(np.random.default_rng(0).random((20, 3))).export(tmp_path / "pts.ply")
    with pytest.raises(InputError, match="no triangles"):
        load_mesh(tmp_path / "pts.ply")


@pytest.mark.parametrize("suffix, module", [(".3mf", "networkx"), (".dae", "collada"), (".zae", "collada")])
def test_3mf_and_collada_read_with_the_formats_extra(tmp_path, suffix, module):
    """3MF and COLLADA (plain, or zipped as .zae) need trimesh's optional
    readers ('aniso3d[formats]')."""
    pytest.importorskip(module)
    import zipfile

    import trimesh

    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    if suffix == ".zae":
        box.export(tmp_path / "box.dae")
        with zipfile.ZipFile(tmp_path / "box.zae", "w") as z:
            z.write(tmp_path / "box.dae", "box.dae")
    else:
        box.export(tmp_path / f"box{suffix}")
    mesh = load_mesh(tmp_path / f"box{suffix}")
    assert len(mesh.faces) == 12
    assert mesh.area() == pytest.approx(2 * (1 * 2 + 2 * 3 + 1 * 3), rel=1e-6)
    np.testing.assert_allclose(mesh.bounds, [[-0.5, -1.0, -1.5], [0.5, 1.0, 1.5]], atol=1e-6)


@pytest.mark.parametrize(
    "raised, module",
    [
        (ModuleNotFoundError("No module named 'networkx'"), "networkx"),  # trimesh drops .name
        (ModuleNotFoundError("No module named 'lxml'", name="lxml"), "lxml"),
        (ImportError("missing `pip install pycollada`"), "pycollada"),
    ],
)
def test_a_missing_optional_reader_is_named_with_the_way_out(tmp_path, monkeypatch, raised, module):
    import trimesh

    def load(*args, **kwargs):
        raise raised

    monkeypatch.setattr(trimesh, "load", load)
    (tmp_path / "part.3mf").write_bytes(b"PK\x03\x04")
    with pytest.raises(InputError) as info:
        load_mesh(tmp_path / "part.3mf")
    text = str(info.value)
    assert f"'{module}'" in text and "aniso3d[formats]" in text and "part.3mf" in text
    assert "'?'" not in text


# ---------------------------------------------------------------------- scenes


def test_tree_is_deterministic_per_seed_and_differs_across_seeds():
    a = scenes.tree(seed=3, levels=4, leaves_per_twig=20)
    b = scenes.tree(seed=3, levels=4, leaves_per_twig=20)
    c = scenes.tree(seed=4, levels=4, leaves_per_twig=20)
    for name in ("vertices", "faces", "kd", "ks", "shininess"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), name
    assert a.n_faces == c.n_faces  # same structure...
    assert not np.array_equal(a.vertices, c.vertices)  # ...different shape
    assert not np.array_equal(a.kd, c.kd)


def test_default_tree_is_the_big_one():
    t = scenes.tree()
    assert 200_000 < t.n_faces < 400_000
    extent = t.bounds[1] - t.bounds[0]
    assert 8 < extent[1] < 16  # about 10 m tall, y up
    assert np.all(t.face_areas() > 0)
    # bark and leaves
    assert len(np.unique(t.ks)) == 2


@pytest.mark.parametrize(
    "kwargs", [{"levels": 0}, {"children": 0}, {"leaves_per_twig": -1}, {"sides": 2}, {"height": 0},
               {"leaf_size": -1}],
)  # fmt: skip
def test_tree_rejects_bad_parameters(kwargs):
    with pytest.raises(InputError):
        scenes.tree(**kwargs)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_quad_faces_its_axis(axis):
    from aniso3d.build.clip import triangle_normals

    q = scenes.quad(size=3.0, center=(1, 2, 3), normal_axis=axis)
    n, _ = triangle_normals(q.triangles)
    want = np.zeros(3)
    want[axis] = 1
    np.testing.assert_allclose(n, [want, want], atol=1e-15)
    assert q.area() == pytest.approx(9.0)
    np.testing.assert_allclose(q.triangles.reshape(-1, 3).mean(0)[axis], [1, 2, 3][axis])


def test_cube_and_sphere():
    from aniso3d.build.clip import triangle_normals

    c = scenes.cube(size=2.0, center=(1, 1, 1))
    assert c.area() == pytest.approx(24.0)
    n, _ = triangle_normals(c.triangles)
    outward = np.einsum("ij,ij->i", n, centroids(c) - 1.0)
    assert np.all(outward > 0)
    s = scenes.sphere(radius=2.0, subdivisions=3)
    assert s.n_faces == 20 * 4**3
    assert s.area() == pytest.approx(4 * np.pi * 4, rel=0.02)
    with pytest.raises(InputError, match="unknown built-in scene"):
        scenes.get_scene("teapot")
    assert scenes.get_scene("quad").n_faces == 2


def textured_quad(folder: Path, texture_path: str, mtl_path: str = "quad.mtl") -> Path:
    """A unit quad with UVs whose material library (at ``mtl_path`` from the
    OBJ's folder) names the texture ``texture_path`` (from the library's)."""
    (folder / "quad.obj").write_text(
        f"mtllib {mtl_path}\nusemtl painted\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n"
    )
    return folder / "quad.obj"


def red_texture(path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.new("RGB", (4, 4), (230, 20, 10)).save(path)


def painted_mtl(path: Path, texture_path: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"newmtl painted\nKd 1 1 1\nmap_Kd {texture_path}\n")


RED_KD = np.array([230, 20, 10]) / 255.0


def test_a_texture_in_a_sibling_folder_is_read(tmp_path):
    # Exporters write ../textures/x.png; trimesh 5 refuses paths that leave
    # the mesh's folder unless told, and dropped the texture silently.
    red_texture(tmp_path / "textures" / "red.png")
    painted_mtl(tmp_path / "model" / "quad.mtl", "../textures/red.png")
    m = load_mesh(textured_quad(tmp_path / "model", "../textures/red.png"))
    np.testing.assert_allclose(m.kd, [RED_KD] * 2, atol=BYTE)


@pytest.mark.skipif(not hasattr(os, "symlink"), reason="no symlinks here")
def test_a_mesh_folder_of_symlinks_keeps_its_materials(tmp_path):
    # A folder of links to files kept elsewhere (a dataset's view): the
    # library and texture resolve to the other folder.
    store = tmp_path / "store"
    red_texture(store / "red.png")
    painted_mtl(store / "quad.mtl", "red.png")
    textured_quad(store, "red.png")
    view = tmp_path / "view"
    view.mkdir()
    for name in ("quad.obj", "quad.mtl", "red.png"):
        (view / name).symlink_to(store / name)
    m = load_mesh(view / "quad.obj")
    np.testing.assert_allclose(m.kd, [RED_KD] * 2, atol=BYTE)


@pytest.mark.gpu
def test_a_missing_texture_is_one_warning_that_names_it(tmp_path, capsys):
    from aniso3d import InputWarning
    from aniso3d.app.cli import main

    painted_mtl(tmp_path / "quad.mtl", "gone.png")
    obj = textured_quad(tmp_path, "gone.png")
    with pytest.warns(InputWarning, match="gone.png"):
        m = load_mesh(obj)
    np.testing.assert_allclose(m.kd, 1.0, atol=BYTE)  # the material's Kd
    (tmp_path / "quad.mtl").unlink()
    with pytest.warns(InputWarning, match="quad.mtl"):
        load_mesh(obj)
    # The CLI: one line on stderr, and the picture is still drawn.
    code = main(["render", str(obj), "--method", "mesh", "--size", "32", "-o", str(tmp_path / "q.png")])
    err = capsys.readouterr().err
    assert code == 0 and (tmp_path / "q.png").exists()
    lines = [line for line in err.splitlines() if "warning" in line]
    assert len(lines) == 1 and lines[0].startswith("aniso3d render: warning: 'quad.obj'") and "quad.mtl" in lines[0]


def test_a_face_takes_its_textures_mean_not_one_texel(tmp_path):
    """A texture of thin lines (one texel in eight lit, the rest black):
    each of the quad's two faces covers many lines and takes their mean
    (about 1/8 of the line colour), where the texel at its centroid gave
    full colour or black depending on where the centroid fell."""
    img = np.zeros((64, 64, 3), np.uint8)
    img[:, ::8] = (240, 200, 40)
    (tmp_path / "lines.png").parent.mkdir(exist_ok=True)
    Image.fromarray(img).save(tmp_path / "lines.png")
    painted_mtl(tmp_path / "quad.mtl", "lines.png")
    m = load_mesh(textured_quad(tmp_path, "lines.png"))
    want = np.array([240, 200, 40]) / 255.0 / 8.0
    np.testing.assert_allclose(m.kd, [want] * 2, atol=0.02)


def test_uvs_far_out_wrap_without_error(tmp_path):
    """UVs of 1e200 (and their areas past float range) wrap round the
    texture like any other: the faces take a colour of it, no error."""
    red_texture(tmp_path / "red.png")
    painted_mtl(tmp_path / "quad.mtl", "red.png")
    obj = textured_quad(tmp_path, "red.png")
    obj.write_text(obj.read_text().replace("vt 1 0\n", "vt 1e200 0\n").replace("vt 0 1\n", "vt 0 1e200\n"))
    m = load_mesh(obj)
    np.testing.assert_allclose(m.kd, [RED_KD] * 2, atol=BYTE)
