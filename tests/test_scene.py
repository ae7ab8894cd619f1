"""Scenes of many instances: the Scene data, glTF instancing, the forest, the
vectorised per-instance culling and level choice, and the three renderers
drawing instances like the same geometry flattened into one mesh."""

import base64
import json
import math

import numpy as np
import pytest

import aniso3d
from aniso3d import InputError, scenes
from aniso3d.build.bounds import bounds_of
from aniso3d.build.scene import INSTANCE_BYTES, Scene, load_scene, trs_matrices
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.instances import (
    INSTANCE_STRIDE,
    ViewCone,
    back_to_front,
    groups,
    instance_data,
    instance_levels,
    instance_spheres,
    largest_eigenvalue,
    visible_instances,
)


def translation(x, y, z) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def yaw(angle: float, scale: float = 1.0) -> np.ndarray:
    c, s = math.cos(angle) * scale, math.sin(angle) * scale
    m = np.eye(4)
    m[:3, :3] = [[c, 0, s], [0, scale, 0], [-s, 0, c]]
    return m


def two_quads() -> Scene:
    sc = Scene(name="two")
    a = translation(-0.7, 0.0, 0.0)
    b = translation(0.7, 0.1, -0.3) @ yaw(0.5)
    sc.add(scenes.quad(1.0, kd=(0.8, 0.5, 0.3)), np.stack([a, b]))
    return sc


# ------------------------------------------------------------------ the data


def test_add_keeps_arrays_and_bounds():
    sc = two_quads()
    assert sc.n_instances == 2 and sc.counts == [2]
    assert sc.transforms[0].dtype == np.float32 and sc.transforms[0].shape == (2, 4, 4)
    assert sc.tints[0].dtype == np.uint8 and (sc.tints[0] == 255).all()
    # The flattened mesh's vertices span exactly the scene's bounds.
    flat = sc.flattened()
    np.testing.assert_allclose(bounds_of(sc), flat.bounds, atol=1e-6)
    # (N, 3, 4) is completed with (0, 0, 0, 1); the same asset appends.
    sc.add(sc.assets[0], translation(0, 2, 0)[:3], tints=np.array([[0.5, 1.0, 0.0]]))
    assert sc.counts == [3] and sc.tints[0][2].tolist() == [128, 255, 0]
    np.testing.assert_array_equal(sc.transforms[0][2, 3], [0, 0, 0, 1])
    assert sc.instance_nbytes == 3 * INSTANCE_BYTES
    assert INSTANCE_STRIDE <= 100


@pytest.mark.parametrize(
    "transforms, words",
    [
        (np.eye(3), "shape"),
        (np.zeros((2, 4, 3)), "shape"),
        (np.stack([np.eye(4), np.full((4, 4), np.nan)]), "NaN"),
        (np.stack([np.eye(4), np.diag([1.0, 0.0, 1.0, 1.0])]), "singular"),
        (np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]], float), "affine"),
        (np.array([["a"] * 4] * 4), "numbers"),
    ],
)
def test_bad_transforms_give_one_input_error(transforms, words):
    sc = Scene()
    with pytest.raises(InputError, match=words):
        sc.add(scenes.quad(), transforms)
    assert sc.n_instances == 0 and not sc.assets


def test_bad_tints_and_empty_scene():
    with pytest.raises(InputError, match="tints"):
        Scene().add(scenes.quad(), np.stack([np.eye(4)] * 2), tints=np.ones((3, 3)))
    with pytest.raises(InputError, match="float tints"):
        Scene().add(scenes.quad(), np.eye(4), tints=np.array([[np.nan, 0, 0]]))
    with pytest.raises(InputError, match="no instances"):
        bounds_of(Scene())
    with pytest.raises(InputError, match="Mesh"):
        Scene().add("quad", np.eye(4))


def test_forest_is_deterministic_and_framed():
    a, b = scenes.forest(40, seed=5), scenes.forest(40, seed=5)
    c = scenes.forest(40, seed=6)
    assert a.n_instances == 41  # 40 trees and the ground
    for ma, mb in zip(a.transforms, b.transforms, strict=True):
        np.testing.assert_array_equal(ma, mb)
    for ta, tb in zip(a.tints, b.tints, strict=True):
        np.testing.assert_array_equal(ta, tb)
    assert any(
        ma.shape != mc.shape or not np.array_equal(ma, mc) for ma, mc in zip(a.transforms, c.transforms, strict=True)
    )
    # Every kind is one asset shared by its instances; the trees stand on the ground.
    assert len(a.assets) == 4 and sum(a.counts[1:]) == 40
    box = bounds_of(a)
    assert box[0, 1] == pytest.approx(0.0, abs=1e-9) and box[1, 1] > 5.0
    side = 8.0 * math.sqrt(40)
    np.testing.assert_allclose(box[:, [0, 2]], [[-side / 2] * 2, [side / 2] * 2], atol=side * 0.2)
    corners = a.corners()
    np.testing.assert_allclose([corners.min(0), corners.max(0)], box)  # the framing points span the scene
    cam = aniso3d.framing_camera(a, (64, 64))
    assert visible_instances(*instance_spheres(a.transforms[1], a.asset_bounds(1))[:2],
                             ViewCone.of(cam, (64, 64))).all()  # fmt: skip
    with pytest.raises(InputError, match="species"):
        scenes.forest(10, species=7)
    with pytest.raises(InputError, match="n_trees"):
        scenes.forest(0)


# ------------------------------------------------------------------ glTF


def _gltf(path, nodes, accessors_data) -> None:
    """A tiny glTF: one quad mesh (accessors 0, 1) and extra float accessors."""
    pos = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]], np.float32)
    idx = np.array([0, 1, 2, 0, 2, 3], np.uint16)
    blobs = [pos.tobytes(), idx.tobytes() + b"\0\0"] + [a.astype(np.float32).tobytes() for a in accessors_data]
    views, offset = [], 0
    for blob in blobs:
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(blob)})
        offset += len(blob)
    views[1]["byteLength"] = 12
    accessors = [
        {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
         "min": [-0.5, -0.5, 0], "max": [0.5, 0.5, 0]},
        {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"},
    ] + [
        {"bufferView": 2 + k, "componentType": 5126, "count": len(a), "type": {3: "VEC3", 4: "VEC4"}[a.shape[1]]}
        for k, a in enumerate(accessors_data)
    ]  # fmt: skip
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": [{"name": "quad", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": offset,
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(b"".join(blobs)).decode()}],
        "bufferViews": views,
        "accessors": accessors,
    }  # fmt: skip
    if any("extensions" in n for n in nodes):
        doc["extensionsUsed"] = ["EXT_mesh_gpu_instancing"]
    path.write_text(json.dumps(doc))


def test_gltf_nodes_sharing_a_mesh_are_one_asset(tmp_path):
    p = tmp_path / "shared.gltf"
    _gltf(p, [
        {"mesh": 0, "translation": [2.0, 0.0, 0.0]},
        {"mesh": 0, "translation": [-1.0, 0.5, 0.0], "scale": [2.0, 2.0, 2.0]},
    ], [])  # fmt: skip
    sc = load_scene(p)
    assert len(sc.assets) == 1 and sc.counts == [2]
    got = sorted(sc.transforms[0].tolist(), key=lambda m: m[0][3])
    want = [translation(-1.0, 0.5, 0.0) @ np.diag([2.0, 2.0, 2.0, 1.0]), translation(2.0, 0.0, 0.0)]
    np.testing.assert_allclose(got, want, atol=1e-6)
    box = bounds_of(sc)
    np.testing.assert_allclose(box, [[-2.0, -0.5, 0.0], [2.5, 1.5, 0.0]], atol=1e-6)


def test_gltf_ext_mesh_gpu_instancing(tmp_path):
    t = np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 0.0, -4.0]])
    half = math.sqrt(0.5)
    q = np.array([[0, 0, 0, 1], [0, half, 0, half], [half, 0, 0, half]])  # (x, y, z, w)
    s = np.array([[1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [1.0, 3.0, 1.0]])
    p = tmp_path / "instanced.gltf"
    node = {"mesh": 0, "translation": [0.0, 10.0, 0.0],
            "extensions": {"EXT_mesh_gpu_instancing": {"attributes": {"TRANSLATION": 2, "ROTATION": 3, "SCALE": 4}}}}
    _gltf(p, [node], [t, q, s])  # fmt: skip
    sc = load_scene(p)
    assert sc.counts == [3]
    # Independent: the rotations written out by hand (90 deg about y, 90 deg about x).
    r1 = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], float)
    r2 = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)
    want = np.zeros((3, 4, 4))
    for k, (rot, sc_) in enumerate(zip([np.eye(3), r1, r2], s, strict=True)):
        want[k, :3, :3] = rot @ np.diag(sc_)
        want[k, :3, 3] = t[k] + [0.0, 10.0, 0.0]
        want[k, 3, 3] = 1.0
    np.testing.assert_allclose(sc.transforms[0], want, atol=1e-6)
    np.testing.assert_allclose(trs_matrices(t, q, s)[:, :3, 3], t)


@pytest.mark.parametrize("attributes", [["TRANSLATION", 2], {"TRANSLATION": "x"}, {"TRANSLATION": 2.5}])
def test_gltf_damaged_instancing_is_one_clear_error(tmp_path, attributes):
    t = np.zeros((2, 3))
    p = tmp_path / "damaged.gltf"
    node = {"mesh": 0, "extensions": {"EXT_mesh_gpu_instancing": {"attributes": attributes}}}
    _gltf(p, [node], [t])
    with pytest.raises(InputError, match="EXT_mesh_gpu_instancing"):
        load_scene(p)


def test_zero_quaternions_are_refused():
    q = np.array([[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0]])
    with pytest.raises(InputError, match="quaternion"):
        trs_matrices(np.zeros((2, 3)), q, np.ones((2, 3)))


def test_gltf_refuses_other_files(tmp_path):
    p = tmp_path / "x.obj"
    p.write_text("v 0 0 0\n")
    with pytest.raises(InputError, match="glTF"):
        load_scene(p)


# ------------------------------------------------------------------ selection


def _brute_force_visible(centres, radii, cam, size, near, far):
    """One sphere at a time against the six planes of the projection matrix
    (Gribb-Hartmann), normalised: an independent twin of visible_instances."""
    w, h = size
    mvp = cam.projection_matrix(w / h, near, far) @ cam.view_matrix()
    rows = [mvp[3] + mvp[0], mvp[3] - mvp[0], mvp[3] + mvp[1], mvp[3] - mvp[1], mvp[3] + mvp[2], mvp[3] - mvp[2]]
    out = []
    for c, r in zip(centres, radii, strict=True):
        ok = True
        for plane in rows:
            n = np.linalg.norm(plane[:3])
            if (plane[:3] @ c + plane[3]) / n < -r:
                ok = False
        out.append(ok)
    return np.array(out)


def test_culling_matches_brute_force():
    rng = np.random.default_rng(3)
    centres = rng.uniform(-60, 60, (4000, 3))
    radii = rng.uniform(0.1, 6.0, 4000)
    cam = Camera(position=(5.0, 8.0, 70.0), target=(0.0, 0.0, 0.0), fov=35.0)
    size, near, far = (160, 90), 2.0, 110.0
    got = visible_instances(centres, radii, ViewCone.of(cam, size, near, far))
    want = _brute_force_visible(centres, radii, cam, size, near, far)
    assert 200 < got.sum() < 3800  # both kinds present
    np.testing.assert_array_equal(got, want)


def test_levels_coarser_far_away_and_grouped():
    cam = Camera(position=(0.0, 0.0, 0.0), target=(0.0, 0.0, -1.0), fov=40.0)
    cone = ViewCone.of(cam, (256, 256), 0.1, 1e4)
    depth = np.array([5.0, 40.0, 320.0, 2560.0, 0.5])
    centres = np.stack([np.zeros(5), np.zeros(5), -depth], axis=1)
    radii = np.full(5, 1.0)
    sizes = 0.01 * 2.0 ** np.arange(6)
    lv = instance_levels(centres, radii, np.ones(5), sizes, cone, 1.0)
    # Closed form: the coarsest l with 0.01 2^l scale / (d - 1) <= 1 pixel.
    scale = 256 / (2 * math.tan(math.radians(20)))
    want = [min(5, max(0, math.floor(math.log2((d - 1.0) / (0.01 * scale))))) if d > 1 else 0 for d in depth]
    assert lv.tolist() == want
    assert lv[0] < lv[1] < lv[2] and lv[4] == 0
    # With a points budget: no more points than pixels of the sphere's disc.
    pts = np.array([100000, 25000, 6000, 1500, 400, 100])
    lvb = instance_levels(centres, radii, np.ones(5), sizes, cone, 1.0, level_points=pts, points_per_pixel=2.0)
    disc = [math.pi * (scale / (d - 1.0)) ** 2 if d > 1 else math.inf for d in depth]
    within = [next((lvl for lvl in range(6) if pts[lvl] <= 2.0 * a), 5) for a in disc]
    assert lvb.tolist() == [max(a, b) if d > 1 else 0 for a, b, d in zip(want, within, depth, strict=True)]
    assert (lvb >= lv).all() and (lvb > lv).any()
    # A doubled instance is as coarse as an undoubled one half as far.
    lv2 = instance_levels(centres[:3] * 2, radii[:3] * 2, np.full(3, 2.0), sizes, cone, 1.0)
    np.testing.assert_array_equal(lv2, instance_levels(centres[:3], radii[:3], np.ones(3), sizes, cone, 1.0))
    g = groups(np.array([2, 0, 2, 1, 0]))
    assert [(lvl, idx.tolist()) for lvl, idx in g] == [(0, [1, 4]), (1, [3]), (2, [0, 2])]
    order = back_to_front(centres, cone)
    assert order.tolist() == [3, 2, 1, 0, 4]


def test_spheres_hold_the_transformed_box():
    """Stretch = largest singular value (against NumPy's SVD), and every
    transformed corner of the asset box lies in its instance's sphere."""
    rng = np.random.default_rng(7)
    m = np.tile(np.eye(4), (500, 1, 1))
    m[:, :3, :3] = rng.normal(size=(500, 3, 3))
    m[:, :3, 3] = rng.normal(size=(500, 3)) * 10
    m[:3, :3, :3] = [np.eye(3), 2 * np.eye(3), np.diag([1.0, 3.0, 0.5])]  # repeated eigenvalues
    box = np.array([[-1.0, 0.0, -2.0], [3.0, 5.0, 1.0]])
    c, r, s = instance_spheres(m, box)
    np.testing.assert_allclose(s, np.linalg.svd(m[:, :3, :3], compute_uv=False)[:, 0], rtol=1e-9)
    a = m[:, :3, :3]
    np.testing.assert_allclose(largest_eigenvalue(np.einsum("nki,nkj->nij", a, a)), s**2, rtol=1e-9)
    corners = np.array([[x, y, z] for x in box[:, 0] for y in box[:, 1] for z in box[:, 2]])
    world = np.einsum("nij,kj->nki", a, corners) + m[:, None, :3, 3]
    assert (np.linalg.norm(world - c[:, None], axis=2) <= r[:, None] * (1 + 1e-12)).all()
    sc = Scene()
    sc.add(scenes.quad(), m)
    qb = sc.asset_bounds(0)
    corners = np.array([[x, y, z] for x in qb[:, 0] for y in qb[:, 1] for z in qb[:, 2]])
    world = np.einsum("nij,kj->nki", sc.transforms[0][:, :3, :3].astype(float), corners) + m[:, None, :3, 3]
    np.testing.assert_allclose(sc.instance_boxes(0), np.stack([world.min(1), world.max(1)], axis=1), atol=1e-4)


def test_instance_data_composes_origins():
    m = (translation(1.0, 2.0, 3.0) @ yaw(0.3, 2.0))[None]
    raw = np.frombuffer(instance_data(m, np.array([[10, 20, 30]], np.uint8), (1.0, 1.0, 1.0), (0.5, 0.0, 0.0)),
                        dtype=[("m", "<f4", (16,)), ("t", "u1", (4,))])  # fmt: skip
    mat = raw["m"][0].reshape(4, 4).T  # column-major
    p_asset = np.array([0.2, 0.3, 0.4])  # stored relative to the asset origin (0.5, 0, 0)
    want = m[0] @ np.append(p_asset + [0.5, 0, 0], 1.0) - np.array([1.0, 1.0, 1.0, 0.0])
    np.testing.assert_allclose(mat @ np.append(p_asset, 1.0), want, atol=1e-5)
    assert raw["t"][0].tolist() == [10, 20, 30, 255]


# ------------------------------------------------------------------ rendering


@pytest.mark.gpu
@pytest.mark.parametrize("method, mean_tol, bad_tol", [("mesh", 0.0, 0.0), ("splat", 2.0, 0.02),
                                                       ("volume", 4.0, 0.05)])  # fmt: skip
def test_two_instances_render_like_two_quads(r, method, mean_tol, bad_tol):
    """Instances against the flattened mesh: polygons exactly (the same
    triangles, the same float64 matrices); splats and volume, whose flattened
    texture has another voxel grid, within a grey level on average and a few
    per cent of pixels (the quads' edges) off by more than 30."""
    sc = two_quads()
    flat = sc.flattened()
    cam = aniso3d.framing_camera(flat, r.size)
    got = r.render(sc, cam, method, resolution=32)
    if method == "mesh":
        want = r.render(flat, cam, "mesh")
    else:
        want = r.render(flat, cam, method, resolution=32, lod=True)
    d = np.abs(got.astype(int) - want.astype(int))
    assert (got != 255).any(axis=2).mean() > 0.1  # the quads are drawn
    assert d.mean() <= mean_tol + 1e-9
    assert (d.max(axis=2) > 30).mean() <= bad_tol
    # Against the polygon truth too.
    truth = r.render(flat, cam, "mesh")
    assert np.abs(got.astype(int) - truth.astype(int)).mean() < 6.0


@pytest.mark.gpu
@pytest.mark.parametrize("quality, mean_tol, bad_tol", [("blend", 2.0, 0.02), ("high", 3.0, 0.04)])
def test_two_instances_every_splat_quality(r, quality, mean_tol, bad_tol):
    """The blended qualities run their own passes over the instanced draws."""
    sc = two_quads()
    flat = sc.flattened()
    cam = aniso3d.framing_camera(flat, r.size)
    frame = r.render_frame(sc, cam, "splat", resolution=32, quality=quality)
    want = r.render(flat, cam, "splat", resolution=32, lod=True, quality=quality)
    d = np.abs(frame.color.astype(int) - want.astype(int))
    assert (frame.color != 255).any(axis=2).mean() > 0.1
    assert d.mean() <= mean_tol and (d.max(axis=2) > 30).mean() <= bad_tol
    assert frame.stats.drawn == 2 * r.upload(sc.assets[0], "splat", resolution=32, lod=True).level_first[1]
    assert np.isfinite(frame.depth).any()


@pytest.mark.gpu
def test_tints_and_rotation_shade_like_flattened(r):
    sc = Scene()
    sc.add(scenes.quad(1.0, kd=(0.9, 0.9, 0.9)), np.stack([translation(-0.6, 0, 0) @ yaw(0.7),
                                                           translation(0.6, 0, 0) @ yaw(-0.4, 0.8)]),
           tints=np.array([[255, 64, 64], [64, 255, 64]], np.uint8))  # fmt: skip
    flat = sc.flattened()
    cam = aniso3d.framing_camera(flat, r.size)
    got, want = r.render(sc, cam, "mesh"), r.render(flat, cam, "mesh")
    assert np.abs(got.astype(int) - want.astype(int)).max() <= 1
    spl = r.render(sc, cam, "splat", resolution=32)
    assert np.abs(spl.astype(int) - want.astype(int)).mean() < 6.0


@pytest.mark.gpu
def test_far_instance_drawn_coarser(r):
    sc = Scene()
    sc.add(scenes.tree(seed=3, levels=3, leaves_per_twig=20), np.stack([translation(0, 0, 0),
                                                                       translation(0, 0, -400.0)]))  # fmt: skip
    cam = Camera(position=(0.0, 5.0, 25.0), target=(0.0, 5.0, 0.0), fov=40.0)
    frame = r.render_frame(sc, cam, "splat", resolution=64)
    lv = frame.stats.lod["instance_levels"][0]
    assert lv[0] >= 0 and lv[1] > lv[0]
    assert len(frame.stats.levels) == 2
    # Points drawn: the near tree's level and the far tree's (far fewer).
    pyr = r.pyramid(sc.assets[0], resolution=64)
    assert frame.stats.lod["points"] < 2 * r.upload(sc.assets[0], "splat", resolution=64, lod=True).level_first[1]
    assert pyr[int(lv[1])].n_voxels < pyr[int(lv[0])].n_voxels
    # Behind the camera: culled, drawn nowhere.
    sc.add(sc.assets[0], translation(0, 0, 200.0))
    stats = r.render_frame(sc, cam, "splat", resolution=64).stats.lod
    assert stats["instance_levels"][0][2] == -1 and stats["culled"] == 1
    vol = r.render_frame(sc, cam, "volume", resolution=64).stats.lod
    assert vol["instance_levels"][0].tolist()[2] == -1 and vol["instance_levels"][0][1] > vol["instance_levels"][0][0]


def pitch(angle: float, scale: float = 1.0) -> np.ndarray:
    c, s = math.cos(angle) * scale, math.sin(angle) * scale
    m = np.eye(4)
    m[:3, :3] = [[scale, 0, 0], [0, c, -s], [0, s, c]]
    return m


@pytest.mark.gpu
def test_instanced_volume_equals_one_pass_per_instance(r, monkeypatch):
    """The instanced draws (camera moved into each instance's frame on the
    CPU, the lights turned per fragment) against one pass per instance:
    rotations about two axes, scales, two assets, two levels."""
    from aniso3d.rendering import scene_draw

    sc = Scene()
    sc.add(scenes.tree(seed=3, levels=3, leaves_per_twig=20),
           np.stack([translation(0, 0, 0), translation(9, 1, -4) @ yaw(0.8, 1.3),
                     translation(-30, 2, -70) @ pitch(0.4, 0.6) @ yaw(-1.1)]))  # fmt: skip
    sc.add(scenes.quad(30.0, normal_axis=1, kd=(0.5, 0.4, 0.3)), translation(0, -0.5, -5) @ pitch(0.1))
    cam = Camera(position=(4.0, 8.0, 25.0), target=(0.0, 3.0, -5.0), fov=50.0)
    frames = {}
    for instanced in (False, True):
        monkeypatch.setattr(scene_draw, "VOLUME_INSTANCED", instanced)
        frames[instanced] = r.render_frame(sc, cam, "volume", resolution=32)
    got, want = frames[True].color.astype(int), frames[False].color.astype(int)
    assert (want != 255).any(axis=2).mean() > 0.2  # drawn
    assert len(frames[True].stats.levels) == 2
    assert np.abs(got - want).max() <= 2
    assert frames[True].stats.drawn == frames[False].stats.drawn


@pytest.mark.gpu
def test_instanced_volume_calls_follow_groups(r, monkeypatch):
    """Draw calls: one per (asset, level) group with one depth slab, at most
    slabs x groups with several; one per instance without instancing."""
    from aniso3d.rendering import scene_draw

    sc = scenes.forest(40, seed=2)
    cam = aniso3d.framing_camera(sc, r.size, direction=(0.5, 0.9, 1.0))

    def calls(instanced: bool, slabs: int) -> tuple[int, int, int]:
        monkeypatch.setattr(scene_draw, "VOLUME_INSTANCED", instanced)
        monkeypatch.setattr(scene_draw, "VOLUME_DEPTH_SLABS", slabs)
        lod = r.render_frame(sc, cam, "volume", resolution=32).stats.lod
        n_groups = sum(len(np.unique(lv[lv >= 0])) for lv in lod["instance_levels"])
        return lod["draw_calls"], n_groups, lod["visible"]

    one, n_groups, visible = calls(True, 1)
    assert one == n_groups and visible == 41 and n_groups >= 4  # the ground and 3 kinds
    few, n_groups, _ = calls(True, 3)
    assert n_groups < few <= 3 * n_groups
    each, _, visible = calls(False, 1)
    assert each == visible


@pytest.mark.gpu
def test_scene_bad_draws(r):
    sc = two_quads()
    cam = aniso3d.framing_camera(sc, r.size)
    sheared = Scene()
    m = np.eye(4)
    m[0, 1] = 0.5
    sheared.add(scenes.quad(), m)
    with pytest.raises(InputError, match="shear"):
        r.render(sheared, cam, "volume", resolution=16)
    with pytest.raises(InputError, match="no instances"):
        r.render(Scene(), cam, "mesh")


# ------------------------------------------------------------------ command line


@pytest.mark.gpu
def test_cli_renders_a_forest_and_a_gltf_scene(tmp_path, capsys):
    from PIL import Image

    from aniso3d.app.cli import main

    out = tmp_path / "forest.png"
    code = main(["render", "--scene", "forest", "--trees", "4", "--size", "64", "--method", "splat",
                 "-o", str(out)])  # fmt: skip
    text = capsys.readouterr().out
    assert code == 0 and out.exists()
    assert "5 instances" in text and "instances per level" in text
    img = np.asarray(Image.open(out))
    assert img.shape == (64, 64, 3) and (img != 255).any()
    p = tmp_path / "two.gltf"
    _gltf(p, [{"mesh": 0, "translation": [1.0, 0.0, 0.0]}, {"mesh": 0, "translation": [-1.0, 0.0, 0.0]}], [])
    code = main(["render", "--scene", str(p), "--size", "64", "--method", "mesh", "-o", str(tmp_path / "g.png")])
    assert code == 0 and "2 of 2 instances" in capsys.readouterr().out


def test_cli_scene_bad_arguments(tmp_path, capsys):
    from aniso3d.app.cli import main

    for argv, words in (
        (["render", "--scene", "nowhere.obj"], "glTF"),
        (["render", "in.ply", "--scene", "forest"], "not both"),
        (["render", "--scene", "forest", "--method", "all"], "--method all"),
    ):
        code = main([*argv, "-o", str(tmp_path / "x.png")])
        err = capsys.readouterr().err
        assert code == 2 and words in err and "Traceback" not in err


@pytest.mark.parametrize("method", ["mesh", "splat", "volume"])
def test_a_far_instance_does_not_clip_the_near_ones(method):
    """Near and far come from the instances' spheres, not the scene's box:
    a quad a million units away must not push the near plane past a close one."""
    near_only = Scene()
    near_only.add(scenes.quad(), np.eye(4))
    both = Scene()
    both.add(scenes.quad(), np.stack([np.eye(4), translation(1e6, 0, 0)]))
    cam = Camera((0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0))
    opts = {} if method == "mesh" else {"resolution": 8}
    with aniso3d.Renderer((64, 64)) as r:
        alone = r.render(near_only, cam, method, alpha=True, **opts)
        with_far = r.render(both, cam, method, alpha=True, **opts)
    assert (alone[..., 3] > 0).mean() > 0.1  # the close quad is drawn
    assert np.abs(alone.astype(int) - with_far.astype(int)).max() <= 2


def test_a_scene_made_by_its_constructor_is_checked():
    quad = scenes.quad()
    sc = Scene(assets=[quad], transforms=[np.eye(4)[None]])
    assert sc.tints[0].shape == (1, 3) and sc.transforms[0].dtype == np.float32
    with pytest.raises(InputError, match="singular"):
        Scene(assets=[quad], transforms=[np.diag([1.0, 0.0, 1.0, 1.0])[None]])
    with pytest.raises(InputError, match="per asset"):
        Scene(assets=[quad], transforms=[])
    assert Scene().add(quad, np.eye(4), tints=[[255, 0, 0]]) == 0  # integer tints are 0-255
