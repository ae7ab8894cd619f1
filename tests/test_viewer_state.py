"""The viewer's parts that need no window and no OpenGL: the key transitions
of :class:`ViewState`, the orbit camera against closed forms and the
camera's own projection, the data each renderer needs and its background
builds, and the overlay's text layout."""

from __future__ import annotations

import importlib.util
import math
import re
import threading
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

from aniso3d import scenes
from aniso3d.app.viewer import ACTIONS, CONTROLS, KEYS, RESOLUTIONS, Orbit, Settings, ViewState
from aniso3d.app.viewer.data import Conversions, describe_key
from aniso3d.app.viewer.overlay import GREY, YELLOW, key_lines, load_font, status_lines, wrap
from aniso3d.app.viewer.scene import Frame, Shown
from aniso3d.app.viewer.state import (
    DEGREES_PER_PIXEL,
    HOME_AZIMUTH,
    HOME_ELEVATION,
    MAX_ELEVATION,
    TURNTABLE_DEGREES_PER_SECOND,
    ZOOM_LIMITS,
    ZOOM_PER_STEP,
    settings_text,
)
from aniso3d.app.viewer.worker import Builder, Cancelled
from aniso3d.build.points import PointCloud
from aniso3d.build.texture import PLACEMENTS, AnisoTexture, build_texture
from aniso3d.errors import InputError

BOX = np.array([[-1.0, -2.0, -1.0], [1.0, 2.0, 1.0]])


@pytest.fixture(scope="module")
def texture() -> AnisoTexture:
    return build_texture(scenes.cube(), 8, 8)


# ------------------------------------------------------------------ keys


def test_every_control_has_its_keys_and_every_key_is_pyglets():
    """The key bar (CONTROLS) and the key table (KEYS) say the same thing."""
    expect = {
        "r": ["R"], "t": ["T"], "1 2 3": ["_1", "_2", "_3"], "m": ["M"], "s": ["S"], "h": ["H"],
        "p": ["P"], "l": ["L"], "[ ] or - +": ["BRACKETLEFT", "BRACKETRIGHT", "MINUS", "PLUS"],
        "c or F12": ["C", "F12"], "o": ["O"], "q or Esc": ["Q", "ESCAPE"],
    }  # fmt: skip
    controls = dict(CONTROLS)
    for keys, names in expect.items():
        assert keys in controls
        for name in names:
            assert name in KEYS, f"{name} ({keys}: {controls[keys]}) has no action"
    assert [KEYS[n] for n in ("_1", "_2", "_3")] == ["mesh", "volume", "splat"]
    assert {KEYS[n] for n in ("BRACKETLEFT", "MINUS")} == {"voxels down"}
    assert {KEYS[n] for n in ("BRACKETRIGHT", "PLUS")} == {"voxels up"}
    assert set(ACTIONS) == set(KEYS.values())
    # Each name is a constant of pyglet's key module (read as text: importing
    # pyglet.window needs a display).
    spec = importlib.util.find_spec("pyglet")
    if spec is None:
        pytest.skip("pyglet (aniso3d[viewer]) missing")
    source = (Path(spec.submodule_search_locations[0]) / "window" / "key.py").read_text()
    defined = set(re.findall(r"^(\w+)\s*=", source, re.M))
    assert set(KEYS) <= defined, sorted(set(KEYS) - defined)


def test_start_method_follows_the_input_and_settings_are_copied():
    assert ViewState("mesh", BOX).settings.method == "mesh"
    assert ViewState("texture", BOX).settings.method == "volume"
    assert ViewState("points", BOX).settings.method == "splat"
    given = Settings(method="splat", quality="high")
    state = ViewState("mesh", BOX, given)
    state.press("quality")
    assert state.settings.method == "splat" and state.settings.quality == "fast"
    assert given.quality == "high", "the caller's settings were changed"
    with pytest.raises(InputError, match="kind"):
        ViewState("image", BOX)


def test_renderer_keys():
    state = ViewState("mesh", BOX)
    reply = state.press("splat")
    assert state.settings.method == "splat" and reply.changed == ("method",)
    assert reply.text == "renderer splats" and not reply.notice
    seen = []
    for _ in range(4):
        state.press("next renderer")
        seen.append(state.settings.method)
    assert seen == ["mesh", "volume", "splat", "mesh"]


@pytest.mark.parametrize(
    "action, name, start, order",
    [
        ("splat shape", "splat", "disc", ["ellipse", "square", "disc"]),
        ("quality", "quality", "fast", ["high", "fast"]),
        ("placement", "placement", "centroid", [*PLACEMENTS[1:], PLACEMENTS[0]]),
    ],
)
def test_cycling_keys(action, name, start, order):
    state = ViewState("texture", BOX)
    assert getattr(state.settings, name) == start
    for value in order:
        reply = state.press(action)
        assert getattr(state.settings, name) == value
        assert reply.changed == (name,) and reply.text == f"{name} {value}"


def test_level_of_detail_key():
    state = ViewState("texture", BOX)
    assert state.press("level of detail").text == "level of detail on" and state.lod
    assert state.press("level of detail").text == "level of detail off" and not state.lod
    state.press("mesh")
    reply = state.press("level of detail")  # allowed, but the polygons do not use it: say so
    assert state.settings.lod and reply.notice and "applies to the volume and splats" in reply.text
    cloud = ViewState("points", BOX)
    reply = cloud.press("level of detail")
    assert reply.notice and reply.changed == () and not cloud.settings.lod
    cloud.settings.lod = True
    assert not cloud.lod, "a point cloud has no pyramid"


def test_fixed_settings_of_a_texture_or_point_cloud_are_notices():
    cloud = ViewState("points", BOX)
    before = asdict(cloud.settings)
    for action in ("placement", "voxels up", "voxels down"):
        reply = cloud.press(action)
        assert reply.notice and reply.changed == () and "point cloud" in reply.text
    tex = ViewState("texture", BOX)
    reply = tex.press("voxels up")
    assert reply.notice and "saved texture" in reply.text
    assert asdict(cloud.settings) == before


def test_resolution_keys_step_through_the_list_and_stop_at_the_ends():
    state = ViewState("mesh", BOX, Settings(resolution=RESOLUTIONS[0]))
    for expected in RESOLUTIONS[1:]:
        reply = state.press("voxels up")
        assert state.settings.resolution == expected and reply.text == f"voxels {expected}³"
    reply = state.press("voxels up")
    assert reply.notice and "highest" in reply.text and state.settings.resolution == RESOLUTIONS[-1]
    for expected in RESOLUTIONS[-2::-1]:
        state.press("voxels down")
        assert state.settings.resolution == expected
    assert "lowest" in state.press("voxels down").text


def test_toggles_reset_screenshot_and_quit():
    state = ViewState("mesh", BOX)
    assert state.press("overlay").text == "overlay off" and not state.settings.overlay
    assert state.press("overlay").text == "overlay on" and state.settings.overlay
    assert state.press("turntable").text == "turntable on" and state.settings.turntable
    before = asdict(state.settings)
    assert state.press("screenshot").screenshot and state.press("quit").quit
    assert asdict(state.settings) == before
    state.orbit.rotate(100, 40)
    state.orbit.zoom(3)
    reply = state.press("reset view", aspect=2.0)
    assert reply.view and reply.text.startswith(f"camera azimuth {HOME_AZIMUTH:.1f} elevation {HOME_ELEVATION:.1f}")
    assert state.orbit.distance == pytest.approx(Orbit(BOX, aspect=2.0).distance)
    with pytest.raises(InputError, match="unknown viewer action"):
        state.press("fly")


def test_for_input_takes_the_texture_resolution_and_rejects_empty_input(texture):
    state = ViewState.for_input(texture, Settings(resolution=128, directions=4))
    assert state.kind == "texture" and state.settings.method == "volume"
    assert (state.settings.resolution, state.settings.directions) == (8, 8)
    empty = PointCloud(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)), np.zeros(0), np.zeros(0))
    with pytest.raises(InputError, match="empty"):
        ViewState.for_input(empty)
    with pytest.raises(InputError, match="cannot view a str"):
        ViewState.for_input("cube.obj")


def test_settings_text_names_what_shapes_the_image():
    s = Settings(method="splat", lod=True, resolution=32, directions=16)
    assert settings_text(s, "mesh") == "splat disc, quality fast, placement centroid, voxels 32³ K=16, level of detail"
    assert settings_text(s, "points") == "splat disc, quality fast"
    assert settings_text(Settings(method="mesh", lod=True), "mesh") == "quality fast"


# ---------------------------------------------------------------- orbit


def eye_angles(orbit: Orbit) -> tuple[float, float, float]:
    """(azimuth, elevation, distance) of the eye about the target, from the camera itself."""
    v = np.asarray(orbit.camera().position) - orbit.target
    d = float(np.linalg.norm(v))
    return math.degrees(math.atan2(v[0], v[2])) % 360.0, math.degrees(math.asin(v[1] / d)), d


def test_rotate_moves_the_eye_on_a_sphere_about_the_target():
    orbit = Orbit(BOX)
    d0 = orbit.distance
    for dx, dy in ((50, 0), (-30, 20), (400, -75)):
        az, el = orbit.azimuth, orbit.elevation
        orbit.rotate(dx, dy)
        assert orbit.azimuth == pytest.approx((az - DEGREES_PER_PIXEL * dx) % 360.0)
        assert orbit.elevation == pytest.approx(el - DEGREES_PER_PIXEL * dy)
        got = eye_angles(orbit)
        assert got[0] == pytest.approx(orbit.azimuth) and got[1] == pytest.approx(orbit.elevation)
        assert got[2] == pytest.approx(d0)
    orbit.rotate(0, -1e6)
    assert orbit.elevation == MAX_ELEVATION and eye_angles(orbit)[1] == pytest.approx(MAX_ELEVATION)
    orbit.rotate(0, 1e6)
    assert orbit.elevation == -MAX_ELEVATION


def test_pan_keeps_the_grabbed_point_under_the_cursor():
    """A point at the target's depth moves on screen by exactly the drag, in
    pixels (window y up, image y down), at any window size."""
    for size, (dx, dy) in (((400, 300), (25, -10)), ((300, 600), (-7, 40))):
        orbit = Orbit(BOX, aspect=size[0] / size[1])
        orbit.rotate(35, 12)
        grabbed = orbit.target.copy()
        before = orbit.camera().project(grabbed[None], size, BOX)[0]
        orbit.pan(dx, dy, viewport_height=size[1])
        after = orbit.camera().project(grabbed[None], size, BOX)[0]
        assert after - before == pytest.approx([dx, -dy], abs=1e-6)
        assert eye_angles(orbit)[2] == pytest.approx(orbit.distance)  # pan does not zoom


def test_zoom_is_geometric_and_clamped():
    orbit = Orbit(BOX)
    home = orbit.home_distance
    orbit.zoom(3)
    assert orbit.distance == pytest.approx(home * ZOOM_PER_STEP**3)
    orbit.zoom(-5)
    assert orbit.distance == pytest.approx(home * ZOOM_PER_STEP**-2)
    assert eye_angles(orbit)[2] == pytest.approx(orbit.distance)
    orbit.zoom(1e4)
    assert orbit.distance == pytest.approx(ZOOM_LIMITS[0] * home)
    orbit.zoom(-1e4)
    assert orbit.distance == pytest.approx(ZOOM_LIMITS[1] * home)


def test_turntable_spins_at_its_rate():
    orbit = Orbit(BOX)
    orbit.spin(2.0)
    assert orbit.azimuth == pytest.approx(HOME_AZIMUTH + 2.0 * TURNTABLE_DEGREES_PER_SECOND)
    orbit.spin(360.0 / TURNTABLE_DEGREES_PER_SECOND)  # one whole turn
    assert orbit.azimuth == pytest.approx(HOME_AZIMUTH + 2.0 * TURNTABLE_DEGREES_PER_SECOND)


# ------------------------------------------------------------------ data


def test_requirements_for_each_input(texture):
    mesh = scenes.cube()
    state = ViewState("mesh", mesh.bounds, Settings(resolution=16, directions=8))
    conv = Conversions(mesh, "mesh")
    tkey = ("texture", 16, 8)
    assert conv.requirement(state, "mesh") == (("mesh",), None)
    assert conv.requirement(state, "volume") == (tkey, None)
    assert conv.requirement(state, "splat") == (("points", tkey, "centroid"), None)
    assert conv.wanted(state) == [("mesh",), tkey, ("points", tkey, "centroid")]
    state.press("level of detail")
    state.press("volume")
    assert conv.wanted(state)[:2] == [("pyramid", tkey), ("lod points", tkey, "centroid")]

    tstate = ViewState.for_input(texture)
    tconv = Conversions(texture, "texture")
    key, why = tconv.requirement(tstate, "mesh")
    assert key is None and "keeps no polygons" in why
    assert tconv.lookup(("texture",)) is texture
    cloud = texture.to_points()
    pstate = ViewState.for_input(cloud)
    pconv = Conversions(cloud, "points")
    assert pconv.requirement(pstate, "volume")[0] is None
    assert pconv.wanted(pstate) == [("points",)]
    assert describe_key(("points", tkey, "sphere")) == "points (sphere) from the texture 16³ (K=8)"


def test_builds_run_in_the_background_and_stale_ones_are_cancelled():
    mesh = scenes.cube()
    state = ViewState("mesh", mesh.bounds, Settings(resolution=8, directions=4))
    conv = Conversions(mesh, "mesh")
    assert conv.schedule(state) == "texture 8³ (K=4)"
    assert conv.builder.wait(120)
    done = conv.collect()
    assert done is not None and not done.error and done.text.startswith("built texture 8³ (K=4)")
    tex = conv.lookup(("texture", 8, 4))
    assert isinstance(tex, AnisoTexture) and tex.resolution == 8 and tex.n_voxels > 0
    assert conv.schedule(state) == "points (centroid) from the texture 8³ (K=4)"
    state.press("voxels up")  # the points of 8³ are no longer wanted
    assert conv.schedule(state) is None and conv.builder.cancelling
    assert conv.builder.wait(120)
    assert conv.collect() is not None and not conv.builder.busy
    assert conv.schedule(state) == "texture 16³ (K=4)"
    conv.builder.wait(120)


def test_a_failed_build_is_reported_once_and_not_retried(monkeypatch):
    mesh = scenes.cube()
    state = ViewState("mesh", mesh.bounds, Settings(resolution=8, directions=4))
    conv = Conversions(mesh, "mesh")

    def job(key):
        def fail(progress):
            raise InputError(f"no room for {key[0]}")

        return fail

    monkeypatch.setattr(conv, "job", job)
    assert conv.schedule(state) == "texture 8³ (K=4)"
    conv.builder.wait(60)
    done = conv.collect()
    assert done.error and done.text == "building texture 8³ (K=4) failed: no room for texture"
    assert conv.failed == {("texture", 8, 4): "no room for texture"}
    assert conv.schedule(state) == "points (centroid) from the texture 8³ (K=4)"  # the next one, not again
    conv.builder.wait(60)


def test_builder_cancels_at_the_next_progress_report():
    builder = Builder()
    reached, go = threading.Event(), threading.Event()

    def job(progress):
        progress(0.25)
        reached.set()
        assert go.wait(60)
        progress(0.5)  # raises Cancelled once cancel() was called
        return {"k": 1}

    builder.start(("k",), "a job", job)
    with pytest.raises(RuntimeError, match="already running"):
        builder.start(("k",), "another", job)
    assert reached.wait(60) and builder.fraction == 0.25
    assert builder.poll() is None  # still running
    builder.cancel()
    go.set()
    assert builder.wait(60)
    results, exc, seconds = builder.poll()
    assert results is None and isinstance(exc, Cancelled) and seconds >= 0
    assert not builder.busy and builder.poll() is None

    builder.start(("k",), "a job", lambda progress: {"k": 2})
    assert builder.wait(60) and builder.poll()[:2] == ({"k": 2}, None)


# --------------------------------------------------------------- overlay


def test_overlay_text_layout():
    font = load_font(13)
    width = 300
    lines = key_lines(font, width)
    items = [f"{k} {a}" for k, a in CONTROLS]
    assert "   ".join(text for text, _ in lines) == "   ".join(items)  # all, in order
    assert all(font.getlength(text) <= width for text, _ in lines if "   " in text)
    assert all(color == GREY for _, color in lines) and len(lines) > 1

    text = "the volume renderer needs an anisotropic texture: a point cloud has none " * 3
    wrapped = wrap(text, font, 200, YELLOW)
    assert " ".join(t for t, _ in wrapped) == " ".join(text.split()) and len(wrapped) > 3

    state = ViewState("texture", BOX)
    frame = Frame("stale", shown=Shown(("texture",), object(), None, "12 voxels of 2x2x3"))
    lines = status_lines("tree.a3d", state, frame, "", (320, 240), "building pyramid… 50% 0.1 s",
                         ("overlay off", YELLOW))  # fmt: skip
    texts = [t for t, _ in lines]
    assert texts[0] == "aniso3d view · tree.a3d"
    assert "[2:volume]" in texts[1] and "[1:" not in texts[1]
    assert "voxels 64³ K=16 (fixed)" in texts[3]
    assert texts[4] == "frame – · 320x240"
    assert texts[5] == "drawing 12 voxels of 2x2x3 (previous settings)"
    assert lines[-2] == ("building pyramid… 50% 0.1 s", YELLOW) and lines[-1] == ("overlay off", YELLOW)


# ----------------------------------------------------------------- scenes


@pytest.fixture(scope="module")
def forest():
    """Three trees of two kinds and the ground: 4 instances of 3 assets."""
    sc = scenes.forest(3, species=2)
    assert sc.n_instances == 4 and len(sc.assets) == 3
    return sc


def test_scene_state_steps_voxels_and_keeps_level_of_detail_on(forest):
    state = ViewState.for_input(forest, Settings(resolution="auto"))
    assert state.kind == "scene" and state.settings.method == "mesh" and state.lod
    assert "per asset" in state.resolve_resolution((320, 240)) and state.settings.resolution == 64
    assert state.press("voxels up").changed == ("resolution",) and state.settings.resolution == 96
    reply = state.press("level of detail")
    assert reply.notice and "always on" in reply.text and reply.changed == ()
    assert state.press("placement").changed == ("placement",)
    s = Settings(method="volume", resolution=8, directions=4, lod=True)
    assert settings_text(s, "scene") == "quality fast, voxels 8³ K=4 per asset"


def test_scene_data_is_prepared_in_the_background_where_the_renderer_looks(forest):
    """The scene's keys per method, and their builds: each asset's texture
    under the renderer's own cache keys, equal to one built here, its
    pyramid, and (splats) every level's points in that pyramid."""
    state = ViewState.for_input(forest, Settings(resolution=8, directions=4))
    conv = Conversions(forest, "scene")
    pkey, skey = ("scene pyramids", 8, 4), ("scene points", 8, 4, "centroid")
    assert [conv.requirement(state, m)[0] for m in ("mesh", "volume", "splat")] == [("scene",), pkey, skey]
    assert conv.lookup(("scene",)) is forest and conv.lookup(pkey) is None and conv.lookup(skey) is None
    state.press("splat")
    assert conv.wanted(state) == [skey, pkey]
    state.press("volume")
    assert conv.wanted(state) == [pkey, skey]

    assert conv.schedule(state) == describe_key(pkey) == "scene's asset pyramids 8³ (K=4)"
    assert conv.builder.wait(120)
    done = conv.collect()
    assert not done.error and done.text.endswith(f"{forest.n_instances} instances of 3 assets, "
                                                 f"{sum(build_texture(a, 8, 4).n_voxels for a in forest.assets):,} "
                                                 "voxels at the finest")  # fmt: skip
    prep = conv.lookup(pkey)
    assert prep is not None and conv.lookup(skey) is None, "the points are not made yet"
    for asset, tex, pyr in zip(forest.assets, prep.textures, prep.pyramids, strict=True):
        assert conv.cache.get(asset, ("texture", 8, 4)) is tex and conv.cache.get(tex, ("pyramid",)) is pyr
        ref = build_texture(asset, 8, 4)
        assert np.array_equal(tex.coords, ref.coords) and np.allclose(tex.density, ref.density)
        assert pyr[0] is tex and len(pyr) >= 2

    # The splats' build reuses the pyramids and fills in their level points.
    assert conv.schedule(state) == "scene's asset points (centroid) 8³ (K=4)"
    assert conv.builder.wait(120)
    assert not conv.collect().error
    points = conv.lookup(skey)
    assert points is not None and points.placement == "centroid"
    assert all(a is b for a, b in zip(points.pyramids, prep.pyramids, strict=True))
    for pyr in points.pyramids:
        cloud, _ = pyr.level_cloud(0, "centroid")
        ref = pyr[0].to_points("centroid")
        assert len(cloud) == len(ref) and np.allclose(cloud.positions, ref.positions)
    assert conv.schedule(state) is None, "nothing left to build"

    # Another placement: its points are wanted; the pyramids stay as they are.
    state.press("placement")
    other = ("scene points", 8, 4, state.settings.placement)
    assert conv.lookup(other) is None and conv.lookup(pkey).pyramids == prep.pyramids
    # A pyramid rebuilt (evicted, say) has no points: the record no longer counts.
    conv.cache.discard(prep.textures[0])
    assert conv.lookup(pkey) is None and conv.lookup(skey) is None


def test_scene_status_shows_the_instances_and_what_was_drawn(forest):
    state = ViewState.for_input(forest, Settings(method="splat", resolution=8, directions=4))
    lod = {"instances": 4, "visible": 3, "culled": 1, "instance_levels": [], "instances_per_level": [2, 1],
           "points": 1234, "selection_ms": 0.25}  # fmt: skip
    from aniso3d.rendering.frame import DrawStats

    shown = Shown(("scene points", 8, 4, "centroid"), None, None, "4 instances of 3 assets, 316 voxels at the finest")
    frame = Frame("ready", shown=shown, stats=DrawStats(1234, "points", (0, 1), lod))
    lines = [t for t, _ in status_lines("forest3", state, frame, "", (320, 240), None, None)]
    assert "voxels 8³ K=4 per asset" in lines
    assert "drawing 4 instances of 3 assets, 316 voxels at the finest" in lines
    assert "this frame 1,234 points from levels 0 1" in lines
    assert any(t.startswith("3 of 4 instances (1 culled) · instances per level 0:2 1:1 · 1,234 points") for t in lines)
    # Polygons draw no levels: the instances are still reported.
    mesh = Frame("ready", shown=shown, stats=DrawStats(500, "triangles", (), dict(lod, instances_per_level=[3])))
    lines = [t for t, _ in status_lines("forest3", state, mesh, "", (320, 240), None, None)]
    assert "this frame 500 triangles" in lines and any(t.startswith("3 of 4 instances") for t in lines)


def test_view_command_reads_scenes_and_refuses_bad_combinations(tmp_path, capsys):
    import trimesh

    from aniso3d.app.cli import build_parser, main
    from aniso3d.app.view_cmd import read_view_input
    from aniso3d.build.mesh import Mesh
    from aniso3d.build.scene import Scene

    box = trimesh.creation.box()
    two, one = trimesh.Scene(), trimesh.Scene()
    for x in (-2.0, 2.0):
        two.add_geometry(box, geom_name="box", node_name=f"box{x}",
                         transform=trimesh.transformations.translation_matrix([x, 0.0, 0.0]))  # fmt: skip
    one.add_geometry(box, geom_name="box")
    two.export(tmp_path / "two.glb")
    one.export(tmp_path / "one.glb")
    parse = build_parser().parse_args
    sc = read_view_input(parse(["view", str(tmp_path / "two.glb")]))
    assert isinstance(sc, Scene) and sc.n_instances == 2
    np.testing.assert_allclose(sc.bounds, [[-2.5, -0.5, -0.5], [2.5, 0.5, 0.5]], atol=1e-6)
    assert isinstance(read_view_input(parse(["view", str(tmp_path / "one.glb")])), Mesh), "one placed mesh: a mesh"
    forest = read_view_input(parse(["view", "--scene", "forest", "--trees", "5"]))
    assert isinstance(forest, Scene) and forest.n_instances == 6  # the trees and the ground

    for argv, words in (
        (["view", "scene:cube", "--scene", "forest"], "not both"),
        (["view", "--trees", "5"], "--trees applies to --scene forest"),
        (["view", str(tmp_path / "two.glb"), "--trees", "5"], "--trees applies to --scene forest"),
        (["view", "--scene", str(tmp_path / "two.glb"), "--trees", "5"], "not to --scene"),
        (["view", "--scene", "forest", "--splat-size", "0.1"], "--splat-size for PLY point clouds only"),
        (["view", "--scene", "meadow"], "--scene takes 'forest' or a glTF file"),
    ):
        code = main(argv)
        err = capsys.readouterr().err
        assert code == 2 and words in err and "Traceback" not in err, (argv, err)
        assert len(err.strip().splitlines()) == 1, err
