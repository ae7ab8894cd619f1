"""The scene corpus (aniso3d.build.scenes): determinism, sizes against closed
forms, clean triangles, the topology each scene claims (closed blob and
truss, open single-layer shell), the room's grid alignment, sub-voxel bush
leaves, and that every corpus scene builds and renders."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import trimesh

import aniso3d
from aniso3d import InputError
from aniso3d.build import scenes
from aniso3d.rendering.camera import Camera

#: Small versions of the corpus scenes, for the tests that build or render all.
SMALL = {
    "tree": {"levels": 3, "leaves_per_twig": 10},
    "bush": {"leaves": 2000, "stems": 3},
    "grass": {"blades": 300},
    "lattice": {"cells": 2},
    "fur": {"strands": 300},
    "shell": {"resolution": 12},
    "blob": {"subdivisions": 2},
    "room": {"cells": 16, "tile": 4},
    "mixed": {"detail": 0.02},
}

ARRAYS = ("vertices", "faces", "kd", "ks", "shininess")


def test_small_covers_the_corpus():
    assert set(SMALL) == set(scenes.CORPUS)
    assert scenes.CORPUS[0] == "tree"


def test_corpus_yields_every_scene_in_order_with_overrides():
    got = list(scenes.corpus(**SMALL))
    assert [n for n, _ in got] == list(scenes.CORPUS)
    for name, mesh in got:
        assert isinstance(mesh, aniso3d.Mesh)
        ref = scenes.get_scene(name, **SMALL[name])
        assert np.array_equal(mesh.vertices, ref.vertices)


def test_unknown_scene_names_are_refused():
    with pytest.raises(InputError, match="unknown built-in scene 'nope'.*bush"):
        scenes.get_scene("nope")
    with pytest.raises(InputError, match="nope"):
        list(scenes.corpus(nope={}))


@pytest.mark.parametrize("name", scenes.CORPUS)
def test_same_seed_same_arrays_other_seed_different(name):
    a = scenes.get_scene(name, seed=5, **SMALL[name])
    b = scenes.get_scene(name, seed=5, **SMALL[name])
    c = scenes.get_scene(name, seed=6, **SMALL[name])
    for k in ARRAYS:
        assert np.array_equal(getattr(a, k), getattr(b, k)), k
    assert not all(
        getattr(a, k).shape == getattr(c, k).shape and np.array_equal(getattr(a, k), getattr(c, k)) for k in ARRAYS
    )


@pytest.mark.parametrize("name", scenes.CORPUS)
def test_default_scene_has_clean_triangles(name):
    """At the sizes the bench uses: finite, three distinct corners, and no
    sliver thinner than 1e-4 of its longest edge (the thinnest designed ones,
    twig cylinders, are about 1e-3)."""
    m = scenes.get_scene(name)
    assert np.isfinite(m.vertices).all()
    f = m.faces
    assert (f[:, 0] != f[:, 1]).all() and (f[:, 1] != f[:, 2]).all() and (f[:, 0] != f[:, 2]).all()
    t = m.triangles
    longest = np.linalg.norm(t[:, [1, 2, 0]] - t, axis=2).max(axis=1)
    quality = 2 * m.face_areas() / longest**2
    assert quality.min() > 1e-4, f"{name}: sliver triangle {int(np.argmin(quality))}"
    for k in ("kd", "ks"):
        v = getattr(m, k)
        assert np.isfinite(v).all() and v.min() >= 0 and v.max() <= 1


def test_face_counts_follow_the_parameters():
    # bush: stems * (1 main + 4 shoots) six-sided cylinders of 12 triangles, one per leaf.
    for stems, leaves in ((3, 100), (5, 2345)):
        assert scenes.bush(stems=stems, leaves=leaves).n_faces == 60 * stems + leaves
    # grass: a 24 x 24 ground grid, 2 s - 1 triangles per blade.
    for blades, seg in ((10, 2), (500, 5)):
        assert scenes.grass(blades=blades, segments=seg).n_faces == 2 * 24 * 24 + blades * (2 * seg - 1)
    # fur: a 1280-triangle skin, 2 s - 1 per strand.
    for strands, seg in ((10, 3), (400, 6)):
        assert scenes.fur(strands=strands, segments=seg).n_faces == 1280 + strands * (2 * seg - 1)
    for n in (3, 17):
        assert scenes.shell(resolution=n).n_faces == 2 * n * n
    for s in (1, 3):
        assert scenes.blob(subdivisions=s).n_faces == 20 * 4**s
    # A full lattice: 3 n (n + 1)^2 beams of 4 sides, and the 6 (n + 1)^2 node
    # sides on the outside of the cube, 2 triangles each.
    for n in (1, 4):
        assert scenes.lattice(cells=n, missing=0.0).n_faces == 24 * n * (n + 1) ** 2 + 12 * (n + 1) ** 2
    assert scenes.lattice(cells=4, missing=0.3).n_faces < scenes.lattice(cells=4, missing=0.0).n_faces
    # room: 2 triangles per floor tile, 8 for the walls.
    for cells, tile in ((128, 8), (64, 5)):
        nx, nz = cells, round(6.0 / (8.0 / cells))
        tiles = -(-nx // tile) * -(-nz // tile)
        assert scenes.room(cells=cells, tile=tile, furniture=False).n_faces == 2 * tiles + 8
    assert scenes.mixed(detail=0.2).n_faces > scenes.mixed(detail=0.1).n_faces


def test_sizes_scale_the_bounds():
    for f, key in ((scenes.bush, "width"), (scenes.grass, "size"), (scenes.shell, "size"), (scenes.blob, "radius"),
                   (scenes.fur, "radius"), (scenes.mixed, "size"), (scenes.lattice, "cell_size")):  # fmt: skip
        small = SMALL[f.__name__]
        a = f(**small, **{key: 1.0}).bounds
        b = f(**small, **{key: 3.0}).bounds
        ext_a, ext_b = a[1] - a[0], b[1] - b[0]
        assert ext_b.max() > 2.0 * ext_a.max(), f.__name__
    assert np.allclose(scenes.room(width=4.0, depth=3.0, height=2.0).bounds, [[0, 0, 0], [4.0, 2.0, 3.0]])


def test_blob_is_watertight_with_outward_normals():
    for seed in (1, 2, 3):
        m = scenes.blob(seed=seed, subdivisions=3)
        tm = trimesh.Trimesh(m.vertices, m.faces, process=False)
        assert tm.is_watertight and tm.is_winding_consistent
        assert tm.euler_number == 2  # a sphere's topology
        assert tm.volume > 0  # outward normals
        radius = np.linalg.norm(m.vertices, axis=1)
        assert radius.min() > 0.5 and radius.max() < 1.5  # bumpiness 0.3 around the unit radius


def test_lattice_is_one_closed_surface_even_with_beams_missing():
    """Node cubes keep exactly the sides no beam attaches to: merged at shared
    corners the truss is watertight, and no face lies on another."""
    for missing in (0.0, 0.4):
        m = scenes.lattice(cells=3, missing=missing, seed=2)
        tm = trimesh.Trimesh(m.vertices, m.faces)  # process=True merges coincident corners
        assert tm.is_watertight and tm.is_winding_consistent
        assert tm.volume > 0
        centres = np.round(m.triangles.mean(axis=1), 9)
        assert len(np.unique(centres, axis=0)) == m.n_faces


def test_shell_is_one_open_layer():
    n = 20
    m = scenes.shell(resolution=n, seed=4)
    # No two vertices at one place, so index topology is the geometry's.
    assert len(np.unique(np.round(m.vertices, 12), axis=0)) == len(m.vertices)
    tm = trimesh.Trimesh(m.vertices, m.faces, process=False)
    assert not tm.is_watertight and tm.is_winding_consistent
    edges = np.sort(tm.edges, axis=1)
    _, uses = np.unique(edges, axis=0, return_counts=True)
    assert uses.max() == 2  # a manifold: no edge shared by three faces (no second layer)
    assert (uses == 1).sum() == 4 * n  # the open boundary: the sheet's four edges
    assert len(np.unique(np.sort(m.faces, axis=1), axis=0)) == m.n_faces  # no doubled face


def _grid_coords(tex, points):
    return (np.asarray(points) - tex.origin) / tex.voxel_size


def test_room_facets_lie_on_grid_planes_at_128():
    m = scenes.room()
    tex = aniso3d.build_texture(m, 128, 64)
    assert tex.shape.tolist() == [128, 48, 96]
    assert np.allclose(tex.origin, 0.0) and tex.voxel_size == pytest.approx(8.0 / 128)
    u = _grid_coords(tex, m.vertices)
    assert np.abs(u - np.round(u)).max() < 1e-9
    # The walls (after the floor tiles) lie on the outermost planes.
    n_tiles = 16 * 12
    walls = u[m.faces[2 * n_tiles : 2 * n_tiles + 8]]
    normal_axis = np.argmin(np.ptp(walls, axis=1), axis=1)
    planes = walls[np.arange(8), 0, normal_axis]
    assert set(zip(normal_axis.tolist(), planes.tolist(), strict=True)) == {(2, 0.0), (0, 0.0), (0, 128.0), (2, 96.0)}
    # Registered: each shading entry holds whole cell faces (an integer area
    # in h^2), and its centroid lies on a grid plane across its normal.
    assert np.abs(tex.entry_area - np.round(tex.entry_area)).max() < 1e-9
    axis = np.argmax(np.abs(tex.entry_normal), axis=1)
    c = _grid_coords(tex, tex.entry_centroid)[np.arange(tex.n_entries), axis]
    assert np.abs(c - np.round(c)).max() < 1e-6
    # The same check sees a room moved by half a voxel off the planes.
    shifted = m.vertices + 0.5 * tex.voxel_size * np.array([1.0, 0.0, 0.0])
    us = _grid_coords(tex, shifted)
    assert np.abs(us - np.round(us)).max() == pytest.approx(0.5)


def test_bush_leaves_are_much_smaller_than_a_voxel_at_128():
    m = scenes.bush()
    leaves = 250_000
    h = float(np.max(m.bounds[1] - m.bounds[0])) / 128
    t = m.vertices[m.faces[-leaves:]]
    longest = np.linalg.norm(t[:, [1, 2, 0]] - t, axis=2).max(axis=1)
    assert longest.max() < 0.5 * h
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    assert area.max() < 0.1 * h * h
    # The stems before them are not leaves: each spans many voxels.
    assert np.linalg.norm(np.ptp(m.vertices[m.faces[: -leaves]].reshape(-1, 3), axis=0)) > 50 * h


@pytest.mark.parametrize(
    "call, what",
    [
        (lambda: scenes.bush(leaves=-1), "leaves"),
        (lambda: scenes.grass(segments=1), "segments"),
        (lambda: scenes.lattice(beam_width=1.5), "beam_width"),
        (lambda: scenes.lattice(missing=1.0), "missing"),
        (lambda: scenes.fur(hair_length=0.0), "hair_length"),
        (lambda: scenes.shell(resolution=1), "resolution"),
        (lambda: scenes.blob(bumpiness=0.9), "bumpiness"),
        (lambda: scenes.room(width=2.0, depth=6.0), "width must be the longest"),
        (lambda: scenes.mixed(detail=float("nan")), "detail"),
    ],
)
def test_bad_parameters_name_what_is_wrong(call, what):
    with pytest.raises(InputError, match=what):
        call()


@pytest.mark.gpu
@pytest.mark.parametrize("name", scenes.CORPUS)
def test_every_corpus_scene_builds_and_renders(r, name):
    """Built at 16^3 and drawn by all three renderers: each draws the object
    where the polygons are (coverage centroids within 12% of the image)."""
    m = scenes.get_scene(name, **SMALL[name])
    tex = aniso3d.build_texture(m, 16, 16)
    assert tex.n_voxels > 0
    assert tex.total_area() == pytest.approx(m.area(), rel=1e-9)
    cam = Camera.fit(m.bounds, points=m.vertices)
    centroids = {}
    for method in ("mesh", "volume", "splat"):
        thing = m if method == "mesh" else tex
        img = r.render(thing, cam, method, alpha=True)
        cover = img[:, :, 3] > 0
        assert cover.sum() > 20, f"{name} {method}: nothing drawn"
        ys, xs = np.nonzero(cover)
        centroids[method] = np.array([xs.mean(), ys.mean()]) / img.shape[1]
    for method in ("volume", "splat"):
        assert np.linalg.norm(centroids[method] - centroids["mesh"]) < 0.12, (name, method, centroids)


@pytest.mark.gpu
def test_cli_renders_a_corpus_scene(tmp_path):
    out = tmp_path / "room.png"
    proc = subprocess.run(
        [sys.executable, "-m", "aniso3d.app.cli", "render", "scene:room", "--method", "mesh", "--size", "64",
         "-o", str(out)],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    if proc.returncode != 0 and "OpenGL" in proc.stderr:
        pytest.skip(proc.stderr.strip())
    assert proc.returncode == 0, proc.stderr
    from PIL import Image

    img = np.asarray(Image.open(out))
    assert img.shape[:2] == (64, 64) and (img[:, :, :3] < 250).any()
