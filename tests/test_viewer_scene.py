"""The viewer's scene without a window: draw options made from the method
renderers' own ``Options`` dataclasses, uploads kept in (and released by) the
renderer's upload cache, conversions in a shared :class:`Cache`, and the
overlay reading the :class:`DrawStats` each draw returns."""

from __future__ import annotations

import numpy as np
import pytest

from aniso3d import ResourceError, scenes
from aniso3d.app.viewer import Settings, ViewState
from aniso3d.app.viewer.data import Conversions
from aniso3d.app.viewer.overlay import stats_lines, status_lines
from aniso3d.app.viewer.scene import SceneView, draw_options
from aniso3d.build.texture import build_texture
from aniso3d.rendering.cache import Cache
from aniso3d.rendering.frame import DrawStats
from aniso3d.rendering.polygon import MeshOptions, MeshRenderer
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.splat import SplatOptions, SplatRenderer
from aniso3d.rendering.volume import VolumeOptions, VolumeRenderer

SIZE = (64, 48)


def test_draw_options_are_the_renderers_own_dataclass():
    s = Settings(splat="ellipse", quality="high")
    opts, ssaa = draw_options(SplatRenderer, s)
    assert opts == SplatOptions(splat="ellipse", quality="high") and ssaa == 1
    # No quality option of their own: the viewer supersamples 2x2 for "high".
    opts, ssaa = draw_options(MeshRenderer, s)
    assert opts == MeshOptions() and ssaa == 2
    opts, ssaa = draw_options(VolumeRenderer, s)
    assert opts == VolumeOptions() and ssaa == 2
    assert draw_options(MeshRenderer, Settings(quality="fast"))[1] == 1


def test_stats_lines_read_the_draw_stats():
    assert stats_lines(None) == [] and stats_lines(DrawStats(12, "triangles")) == []
    lod = {"level": 2, "voxel_size": 0.25, "pixels": 0.8, "selection_ms": 0.5}
    lines = stats_lines(DrawStats(345, "voxels", (2,), lod))
    assert lines[0] == "this frame 345 voxels from level 2"
    assert lines[1].startswith("LOD level 2 · voxel 0.25 = 0.80 px")
    splat = {"points": 1200, "level0_points": 5000, "points_per_level": [0, 700, 500], "culled": 3,
             "selection_ms": 1.0}  # fmt: skip
    lines = stats_lines(DrawStats(1200, "points", (1, 2), splat))
    assert lines[0] == "this frame 1,200 points from levels 1 2" and "1:700 2:500" in lines[1]


def test_conversions_live_in_the_given_cache():
    mesh = scenes.cube()
    cache = Cache(1, None, "one entry")
    conv = Conversions(mesh, "mesh", cache)
    state = ViewState("mesh", mesh.bounds, Settings(method="splat", resolution=8, directions=4))
    assert conv.schedule(state) == "points (centroid) from the texture 8³ (K=4)"
    assert conv.builder.wait(120)
    assert not conv.collect().error
    # The job made the texture and its points; one entry fits: the wanted one stays.
    key = ("points", ("texture", 8, 4), "centroid")
    assert [k for k, _ in cache.items()] == [key]
    assert conv.lookup(key) is cache.get(mesh, key) and conv.lookup(("texture", 8, 4)) is None
    # Something put there by another user of the cache is found.
    tex = build_texture(mesh, 8, 4)
    cache.put(mesh, ("texture", 8, 4), tex)
    assert conv.lookup(("texture", 8, 4)) is tex


@pytest.fixture
def renderer():
    try:
        r = Renderer(SIZE, cache_entries=2, cache_bytes=None)
    except ResourceError as exc:
        pytest.skip(str(exc))
    yield r
    r.release()


def _ready(scene: SceneView, state: ViewState) -> None:
    """Run the background builds the state needs, then draw."""
    for _ in range(6):
        frame = scene.render(state, SIZE)
        if frame.state == "ready":
            return
        scene.data.schedule(state)
        assert scene.data.builder.wait(120)
        done = scene.data.collect()
        assert done is None or not done.error, done.text
    pytest.fail(f"the scene did not get ready: {scene.frame}")


@pytest.mark.gpu
def test_scene_uploads_through_the_renderer_cache_and_reads_draw_stats(renderer):
    mesh = scenes.cube()
    log: list[str] = []
    state = ViewState("mesh", mesh.bounds, Settings(resolution=8, directions=4))
    data = Conversions(mesh, "mesh", renderer.conversions)
    scene = SceneView(renderer.gl, renderer, data, mesh.bounds, log.append)
    released: list[str] = []
    for method in ("mesh", "volume"):
        impl = renderer.method_renderer(method)
        release = impl.release
        impl.release = lambda handle, m=method, rel=release: (released.append(m), rel(handle))

    _ready(scene, state)
    assert scene.frame.stats == DrawStats(12, "triangles")
    assert [k for k, _ in renderer.uploads.items()] == [("viewer upload", "mesh")]
    assert sum("uploaded mesh for polygons" in line for line in log) == 1

    state.press("volume")
    _ready(scene, state)
    tex = data.lookup(("texture", 8, 4))
    assert scene.frame.stats == DrawStats(tex.n_voxels, "voxels")
    assert len(renderer.uploads) == 2 and released == []
    drawn = np.frombuffer(scene.fbo.read(components=3), np.uint8)
    assert drawn.min() < 200, "the volume drew nothing over the white background"

    # Level of detail: the volume's pyramid upload evicts the LRU upload (the
    # mesh's, two entries at most), released through its renderer.
    state.press("level of detail")
    _ready(scene, state)
    assert released == ["mesh"]
    stats = scene.frame.stats
    assert stats.unit == "voxels" and len(stats.levels) == 1 and stats.lod["level"] == stats.levels[0]
    lines = [t for t, _ in status_lines("cube", state, scene.frame, "", SIZE, None, None)]
    assert f"this frame {stats.drawn:,} voxels from level {stats.levels[0]}" in lines
    assert any(t.startswith(f"LOD level {stats.levels[0]}") for t in lines)

    # Back to the polygons: the mesh is uploaded again (it had been evicted).
    state.press("mesh")
    _ready(scene, state)
    assert sum("uploaded mesh for polygons" in line for line in log) == 2
    assert released == ["mesh", "volume"]



def test_auto_resolution_is_what_the_start_view_needs_and_steps_from_there():
    from aniso3d.app.viewer import RESOLUTIONS
    from aniso3d.rendering.select import needed_resolution

    mesh = scenes.cube()
    for size, expected in (((96, 72), 64), ((160, 120), 128)):
        state = ViewState("mesh", mesh.bounds, Settings(resolution="auto"), aspect=size[0] / size[1])
        line = state.resolve_resolution(size)
        assert state.settings.resolution == expected == needed_resolution(state.orbit.camera(), size, mesh.bounds)
        assert line == f"voxels {expected}³ (auto: a voxel about a pixel at the nearest point of the start view)"
        assert expected in RESOLUTIONS
        assert state.resolve_resolution(size) is None  # a number now: nothing to resolve
    state.press("voxels down")
    assert state.settings.resolution == 96  # the step below 128
    # Nothing is converted from a texture or a point cloud: no choice to make.
    tex = build_texture(mesh, 8, 4)
    tstate = ViewState.for_input(tex, Settings(resolution="auto"))
    assert tstate.resolve_resolution((96, 72)) is None and tstate.settings.resolution == 8
    pstate = ViewState.for_input(tex.to_points(), Settings(resolution="auto"))
    assert pstate.resolve_resolution((96, 72)) is None and isinstance(pstate.settings.resolution, int)


@pytest.mark.gpu
def test_a_scene_is_drawn_by_the_renderers_scene_path_in_every_method(renderer, monkeypatch):
    """A forest in the viewer's scene: its conversions made by the background
    builds, then each method's frame drawn by the renderer's own scene path
    is the headless renderer's picture of the scene from the same camera,
    and its DrawStats count every instance (all in view)."""
    import aniso3d.rendering.renderer as front
    from aniso3d.app.viewer.data import cache_entries

    forest = scenes.forest(3, species=2)
    r = Renderer(SIZE, cache_entries=cache_entries(forest), cache_bytes=None, gl=renderer.gl)
    log: list[str] = []
    state = ViewState.for_input(forest, Settings(resolution=8, directions=4), aspect=SIZE[0] / SIZE[1])
    data = Conversions(forest, "scene", r.conversions)
    scene = SceneView(r.gl, r, data, state.orbit.bounds, log.append)
    camera = state.orbit.camera()
    try:
        for method in ("mesh", "volume", "splat"):
            state.press(method)
            with monkeypatch.context() as m:  # the window's thread only uploads: no conversion there
                for name in ("build_texture", "pyramid"):
                    m.setattr(front, name, lambda *a, name=name, **k: pytest.fail(f"{name} on the main thread"))
                _ready(scene, state)
            stats = scene.frame.stats
            assert stats.lod["instances"] == stats.lod["visible"] == forest.n_instances == 4
            if method == "mesh":
                assert stats == DrawStats(forest.n_faces, "triangles", (), stats.lod)
            else:
                assert stats.drawn > 0 and sum(stats.lod["instances_per_level"]) == 4
            img = np.frombuffer(scene.fbo.read(components=3), np.uint8).reshape(SIZE[1], SIZE[0], 3)[::-1]
            options = {"splat": "disc", "quality": "fast"} if method == "splat" else {}
            expected = r.render(forest, camera, method, resolution=8, directions=4, **options)
            assert np.count_nonzero(img.min(axis=2) < 240) > 200, f"the {method} drew next to nothing"
            assert np.abs(img.astype(np.int16) - expected).mean() < 0.5, f"the viewer's {method} is not the scene's"
        assert sum(line.startswith("uploaded the ") for line in log) == 3
        assert any(line.startswith("showing splat (4 instances of 3 assets") for line in log)
    finally:
        scene.release()
        r.release()
