"""The interactive viewer (``aniso3d view``).

Layers: the camera arithmetic, without any window; GLContext.wrap, which
the viewer draws through; the clear messages where no display or no OpenGL
3.3 exists; and the real viewer in a real window on a virtual X server
(Xvfb), driven with xdotool key presses and a mouse drag and checked through
its own screenshot key, against the headless renderer where the view is known
exactly. The viewer logs one line per settled state on stdout ("showing mesh
...", "camera azimuth ...", "overlay off"), one line per frame presented
after such a change ("frame 12 presented (overlay on; idle): showing ...")
and the frame each screenshot captured; after an input the tests wait for
the state's line, then for a frame presented after it, then take the
screenshot and check it is of a later frame showing that state (see
:class:`Session`). The state module itself is tested in test_viewer_state.py.
"""

import importlib.util
import os
import re
import select
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest

from aniso3d import ResourceError, scenes
from aniso3d.app.viewer import (
    CONTROLS,
    DEGREES_PER_PIXEL,
    HOME_AZIMUTH,
    HOME_ELEVATION,
    RESOLUTIONS,
    Orbit,
    step_resolution,
)
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.images import load_png
from aniso3d.rendering.renderer import Renderer

BOX = np.array([[-1.0, -2.0, -1.0], [1.0, 2.0, 1.0]])


# --------------------------------------------------------------- no window


def corners_in_pixels(orbit: Orbit, size) -> np.ndarray:
    lo, hi = BOX
    corners = np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )
    return orbit.camera().project(corners, size)


@pytest.mark.parametrize("size", [(400, 300), (300, 600), (800, 200)])
def test_start_view_fits_the_bounds_snugly(size):
    orbit = Orbit(BOX, aspect=size[0] / size[1])
    px = corners_in_pixels(orbit, size)
    assert px.min() >= 0 and (px <= np.array(size)).all(), "a corner of the bounds is outside"
    # Snug: some corner reaches the 10% margin in one direction.
    gap = np.minimum(px, np.array(size) - px) / np.array(size)
    assert gap.min() < 0.06
    assert np.allclose(orbit.camera().target, 0.5 * BOX.sum(axis=0))


def test_horizontal_drag_turns_about_the_vertical_only():
    orbit = Orbit(BOX)
    before = np.array(orbit.camera().position)
    orbit.rotate(50, 0)
    after = np.array(orbit.camera().position)
    assert orbit.azimuth == pytest.approx((HOME_AZIMUTH - 50 * DEGREES_PER_PIXEL) % 360)
    assert orbit.elevation == HOME_ELEVATION
    assert after[1] == pytest.approx(before[1])  # height kept: a turn about +y
    assert np.linalg.norm(after) == pytest.approx(np.linalg.norm(before))
    # Dragging right turns the scene right: the eye moves to the camera's left.
    assert np.dot(after - before, Orbit(BOX).camera().basis()[0]) < 0
    orbit.rotate(0, -10_000)  # elevation is clamped short of the pole
    assert orbit.elevation == 89.0
    orbit.camera()  # still a valid camera (up not parallel to the view)
    orbit.reset()
    assert np.allclose(orbit.camera().position, before)


def test_pan_follows_the_cursor_and_zoom_is_clamped():
    orbit = Orbit(BOX)
    right, up, _ = orbit.camera().basis()
    orbit.pan(10, 0, viewport_height=400)
    moved = orbit.target.copy()
    assert np.dot(moved, right) < 0 and abs(np.dot(moved, up)) < 1e-12  # scene follows right
    orbit.zoom(1)
    assert orbit.distance < orbit.home_distance
    orbit.zoom(1000)
    assert orbit.distance == pytest.approx(0.01 * orbit.home_distance)
    orbit.zoom(-1000)
    assert orbit.distance == pytest.approx(20 * orbit.home_distance)


def test_resolution_steps_and_controls():
    assert step_resolution(64, 1) == 96 and step_resolution(64, -1) == 48
    assert step_resolution(RESOLUTIONS[-1], 1) == RESOLUTIONS[-1]
    assert step_resolution(RESOLUTIONS[0], -1) == RESOLUTIONS[0]
    assert step_resolution(100, 1) == 128 and step_resolution(100, -1) == 96
    keys = " ".join(k for k, _ in CONTROLS)
    for key in ("drag", "wheel", "r", "t", "1 2 3", "m", "s", "h", "p", "[ ]", "F12", "Esc"):
        assert key in keys


@pytest.mark.gpu
def test_wrapped_context_releases_its_objects_but_not_the_context():
    """The viewer draws through GLContext.wrap(window context)."""
    import moderngl

    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=330)
    except Exception as exc:
        pytest.skip(f"no EGL OpenGL 3.3 context: {exc}")
    try:
        gl = GLContext.wrap(ctx)
        assert gl.ctx is ctx and gl.renderer and gl.max_texture_size > 0
        buf = gl.track(ctx.buffer(reserve=64))
        prog = gl.program("mesh.vert", "mesh.frag")
        gl.release()
        assert gl.ctx is None and gl.n_objects == 0
        assert (
            type(buf.mglo).__name__ == "InvalidObject"
            and type(prog.mglo).__name__ == "InvalidObject"
        )
        ctx.buffer(reserve=16).release()  # the context itself is still alive
    finally:
        ctx.release()


def _cli(args, env, timeout=60):
    cmd = [sys.executable, "-m", "aniso3d.app.cli", *args]
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout)


def test_no_display_is_a_clear_message_and_status_2():
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = _cli(["view", "scene:cube"], env)
    assert r.returncode == 2, r.stderr
    assert "no display" in r.stderr and "aniso3d render" in r.stderr
    assert "Traceback" not in r.stderr


@pytest.mark.skipif(
    importlib.util.find_spec("pyglet") is None, reason="pyglet (aniso3d[viewer]) missing"
)
def test_unreachable_display_is_a_clear_message_and_status_2():
    env = dict(os.environ, DISPLAY=":4093")  # nothing listens there
    r = _cli(["view", "scene:cube"], env)
    assert r.returncode == 2, r.stderr
    assert "cannot open" in r.stderr and "aniso3d render" in r.stderr
    assert "Traceback" not in r.stderr


# ------------------------------------------------------- the real window


@pytest.fixture(scope="module")
def xserver():
    """DISPLAY of a private Xvfb for this module."""
    missing = [tool for tool in ("Xvfb", "xdotool") if shutil.which(tool) is None]
    if missing:
        pytest.skip(f"{' and '.join(missing)} not installed (Debian: apt-get install xvfb xdotool; "
                    "scripts/test installs them)")  # fmt: skip
    if importlib.util.find_spec("pyglet") is None:
        pytest.skip("the viewer extra is not installed: pip install 'aniso3d[viewer]'")
    read, write = os.pipe()
    proc = subprocess.Popen(
        ["Xvfb", "-displayfd", str(write), "-screen", "0", "1024x768x24", "-nolisten", "tcp"],
        pass_fds=(write,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    os.close(write)
    number = b""
    deadline = time.monotonic() + 20
    while not number.endswith(b"\n") and time.monotonic() < deadline:
        if select.select([read], [], [], 0.5)[0]:
            chunk = os.read(read, 16)
            if not chunk:
                break
            number += chunk
    os.close(read)
    if not number.strip():
        proc.kill()
        pytest.skip("Xvfb did not start")
    yield f":{number.decode().strip()}"
    proc.terminate()
    proc.wait(timeout=10)


#: The line the viewer logs after a buffer swap that shows something new:
#: frame number, overlay, build under way (or idle), and the state shown.
FRAME_LINE = r"^aniso3d view: frame (\d+) presented \(overlay (on|off); (idle|building .*?)\): (.*)$"
SCREENSHOT_LINE = r"^aniso3d view: screenshot saved to (.+\.png) \(frame (\d+)\)$"


class Session:
    """One ``aniso3d view`` process in the virtual X server, and its log.

    The protocol: after an input, wait for the log line of the state it leads
    to, then for a frame presented after that line (with no build under way,
    unless told otherwise), and only then take a screenshot; the screenshot's
    own log line names the frame it captured, which must be a later one.
    """

    def __init__(self, display: str, folder, args: list[str]):
        self.env = {k: v for k, v in os.environ.items() if k != "WAYLAND_DISPLAY"}
        self.env["DISPLAY"] = display
        self.folder = folder
        self.log_path = folder / "viewer.log"
        self._log = open(self.log_path, "w")
        cmd = [sys.executable, "-m", "aniso3d.app.cli", "view", *args, "--screenshot-dir", str(folder)]
        self.proc = subprocess.Popen(cmd, stdout=self._log, stderr=subprocess.STDOUT, env=self.env)
        self.frame, self.state = 0, ""  # the last frame waited for, and the state it showed
        self.end = 0  # log position after the last line waited for
        try:
            self.wid = self.xdo("search", "--sync", "--name", "^aniso3d view", timeout=30).split()[0]
        except subprocess.TimeoutExpired:
            self.kill()
            pytest.fail(f"the viewer window did not appear; log:\n{self.log()}")
        self.xdo("mousemove", "--window", self.wid, "--sync", "20", "20")
        self.xdo("windowfocus", "--sync", self.wid)

    def xdo(self, *args, timeout=10) -> str:
        r = subprocess.run(
            ["xdotool", *args], env=self.env, capture_output=True, text=True, timeout=timeout
        )
        return r.stdout.strip()

    def log(self) -> str:
        return self.log_path.read_text()

    def mark(self) -> int:
        """The log's length now: wait for lines after it."""
        return len(self.log())

    def wait_for(self, pattern: str, timeout: float = 60, after: int = 0) -> re.Match:
        """The first complete log line matching ``pattern`` at or after
        character ``after``; ``self.end`` is set to the log position after it."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            text = self.log()
            text = text[: text.rfind("\n") + 1]  # whole lines only: the viewer may be mid-write
            m = re.compile(pattern, re.M).search(text, after)
            if m:
                self.end = text.index("\n", m.end()) + 1 if m.end() < len(text) else len(text)
                return m
            if self.proc.poll() is not None:
                break
            time.sleep(0.05)  # poll the log file
        self.kill()
        pytest.fail(f"no log line /{pattern}/ within {timeout} s; log:\n{self.log()}")

    def presented(self, after: int, idle: bool = True, timeout: float = 60) -> int:
        """Wait for a frame presented after log position ``after`` (``idle``:
        with no build under way); its number."""
        m = self.wait_for(FRAME_LINE, timeout, after)
        while idle and m.group(3) != "idle":
            m = self.wait_for(FRAME_LINE, timeout, self.end)
        self.frame, self.state = int(m.group(1)), m.group(4)
        return self.frame

    def settle(self, state: str, after: int, idle: bool = True) -> re.Match:
        """Wait for the log line ``aniso3d view: STATE`` (a pattern) after
        ``after``, then for a frame presented after that line; the line's match."""
        m = self.wait_for(rf"^aniso3d view: (?:{state})", after=after)
        self.presented(self.end, idle)
        return m

    def press(self, key: str, state: str, idle: bool = True) -> re.Match:
        """Send ``key`` and :meth:`settle` on the ``state`` it leads to."""
        mark = self.mark()
        self.key(key)
        return self.settle(state, mark, idle)

    def key(self, *names: str) -> None:
        self.xdo("key", *names)

    def drag(self, dx: int, dy: int = 0, button: str = "1", steps: int = 12) -> None:
        """Press ``button`` at (150, 120) in the window, move by (dx, dy) in
        ``steps`` (each one waited for by xdotool) and release."""
        x0, y0 = 150, 120
        self.xdo("mousemove", "--window", self.wid, "--sync", str(x0), str(y0))
        self.xdo("mousedown", button)
        for i in range(1, steps + 1):
            x, y = x0 + dx * i // steps, y0 + dy * i // steps
            self.xdo("mousemove", "--window", self.wid, "--sync", str(x), str(y))
        self.xdo("mouseup", button)

    def screenshot(self) -> np.ndarray:
        """Press the viewer's screenshot key and read the PNG it saved, which
        must be of a frame after the last one waited for, showing its state."""
        from PIL import Image

        mark = self.mark()
        self.key("c")
        m = self.wait_for(SCREENSHOT_LINE, timeout=30, after=mark)
        with Image.open(m.group(1)) as im:
            text = dict(im.text)
        frame = int(text["aniso3d frame"])
        assert frame == int(m.group(2)), "the PNG and the log name different frames"
        assert frame > self.frame, f"screenshot of frame {frame}, not after frame {self.frame}; log:\n{self.log()}"
        assert text["aniso3d state"] == self.state, f"the screenshot shows another state; log:\n{self.log()}"
        return load_png(m.group(1))

    def close(self, key: str, timeout: float = 15) -> int:
        self.key(key)
        try:
            return self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            pytest.fail(
                f"the viewer did not close on '{key}' within {timeout} s; log:\n{self.log()}"
            )

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self._log.close()


def headless_view(mesh, size, rotate=(0, 0), ssaa=1, method="mesh", **options):
    """``mesh`` seen from the viewer's start view turned by a drag of
    ``rotate`` pixels, drawn by the headless renderer with ``method``
    (polygons by default); None without OpenGL."""
    try:
        renderer = Renderer(size)
    except ResourceError:
        return None
    with renderer:
        orbit = Orbit(mesh.bounds, aspect=size[0] / size[1])
        orbit.rotate(*rotate)
        return renderer.render(mesh, orbit.camera(), method, ssaa=ssaa, **options)


def mean_diff(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a.astype(np.int16) - b.astype(np.int16)).mean())


def drawn(img: np.ndarray) -> int:
    """Pixels that are not the white background."""
    return int(np.count_nonzero(img.min(axis=2) < 240))


@pytest.mark.xvfb
def test_display_without_opengl_33_is_a_clear_message_and_status_2(xserver):
    # Mesa caps its OpenGL version by this variable: a display with GL 3.0 only.
    env = dict(os.environ, DISPLAY=xserver, MESA_GL_VERSION_OVERRIDE="3.0")
    env.pop("WAYLAND_DISPLAY", None)
    proc = subprocess.Popen([sys.executable, "-m", "aniso3d.app.cli", "view", "scene:cube"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        out, err = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        pytest.skip("the OpenGL here is not Mesa's (MESA_GL_VERSION_OVERRIDE had no effect)")
    assert proc.returncode == 2, err
    assert "OpenGL 3.3" in err and "aniso3d render" in err and "Traceback" not in err


@pytest.mark.xvfb
def test_window_switches_renderers_rotates_on_drag_resizes_and_quits(xserver, tmp_path):
    s = Session(xserver, tmp_path, ["scene:cube", "--size", "400x300", "--resolution", "16"])
    try:
        s.settle(r"showing mesh \(12 triangles\) at 400x300", after=0)
        with_overlay = s.screenshot()
        s.press("o", r"overlay off$")  # compare scenes, not frame-time digits
        mesh = s.screenshot()
        assert mesh.shape == (300, 400, 3)
        assert mean_diff(with_overlay[:60, :200], mesh[:60, :200]) > 5, "no overlay drawn"
        assert drawn(mesh) > 0.1 * mesh.shape[0] * mesh.shape[1], "the cube is not drawn"

        # A horizontal drag turns the view about the vertical axis.
        mark = s.mark()
        s.drag(120, 0)
        m = s.settle(r"camera azimuth ([\d.]+) elevation ([-\d.]+)", after=mark)
        assert float(m.group(1)) == pytest.approx(
            (HOME_AZIMUTH - 120 * DEGREES_PER_PIXEL) % 360, abs=1.0
        )
        assert float(m.group(2)) == pytest.approx(HOME_ELEVATION)
        turned = s.screenshot()
        assert mean_diff(turned, mesh) > 2, "the drag did not change the view"
        # The same view drawn headless from the orbit the drag should give.
        expected = headless_view(scenes.cube(), (400, 300), rotate=(120, 0))
        if expected is not None:
            assert mean_diff(turned, expected) < 0.5, "the drag did not turn the view as expected"
            assert mean_diff(mesh, headless_view(scenes.cube(), (400, 300))) < 0.5
        s.press("r", rf"camera azimuth {HOME_AZIMUTH:.1f} elevation {HOME_ELEVATION:.1f}")
        assert mean_diff(s.screenshot(), mesh) < 0.05, "reset did not return to the start view"

        # Quality "high" draws the polygons at 2x2 samples per pixel, box-filtered.
        s.press("h", r"showing mesh .* quality high$")
        high = s.screenshot()
        expected = headless_view(scenes.cube(), (400, 300), ssaa=2)
        if expected is not None:
            assert mean_diff(high, expected) < 0.5 and mean_diff(high, mesh) > 0.01
        s.press("h", r"showing mesh .* quality fast$")

        # Switching renderer changes the image: to the volume and splat renderers.
        images = {"mesh": mesh}
        for key, method in (("2", "volume"), ("3", "splat")):
            m = s.press(key, rf"(showing|unavailable|failed) {method}")
            if m.group(1) != "showing":
                pytest.fail(f"the {method} renderer did not draw in the viewer; log:\n{s.log()}")
            img = s.screenshot()
            # An opaque cube's volume and splat renderings are close to its
            # polygons, so "the image changed" is no test: it must be the
            # renderer's image, nearer the headless renderer's than the
            # polygons (the volume: the same to 0.5 levels; the splats,
            # measured: 0.55 from it and 0.90 from the polygons).
            expected = headless_view(scenes.cube(), (400, 300), method=method, resolution=16)
            if expected is not None:
                if method == "volume":
                    assert mean_diff(img, expected) < 0.5, "the viewer's volume differs from the headless volume"
                assert mean_diff(img, expected) < mean_diff(img, mesh), "the viewer still shows the polygons"
            else:
                assert mean_diff(img, mesh) > 0.2, f"switching to {method} did not change the image"
            assert drawn(img) > 0.5 * drawn(mesh), f"the {method} renderer drew too little"
            images[method] = img
        assert mean_diff(images["volume"], images["splat"]) > 0.5

        # Resizing the window re-renders at the new size.
        s.press("1", r"showing mesh .* at 400x300")
        mark = s.mark()
        s.xdo("windowsize", s.wid, "320", "240")
        s.settle(r"showing mesh .* at 320x240", after=mark)
        small = s.screenshot()
        assert small.shape == (240, 320, 3) and drawn(small) > 0.1 * 320 * 240

        assert s.close("q") == 0, s.log()
    finally:
        s.kill()


@pytest.mark.xvfb
def test_window_answers_while_a_texture_builds_and_esc_quits(xserver, tmp_path):
    """The built-in tree takes seconds to convert; the window keeps drawing
    (with a visible "building" state) and quits on Esc mid-build without
    waiting for it (128^3: a build far longer than the test's steps)."""
    s = Session(xserver, tmp_path, ["--size", "400x300", "--resolution", "128"])
    try:
        s.wait_for(r"building texture 128")
        s.settle(r"showing mesh \(262,140 triangles\)", after=0, idle=False)
        img = s.screenshot()
        log = s.log()
        assert "built texture" not in log[: log.index("screenshot saved")], (
            "the build finished before the screenshot: cannot tell whether the window answered"
        )
        yellow = (
            (img[:, :, 0] > 200)
            & (img[:, :, 1] > 150)
            & (img[:, :, 1] < 225)
            & (img[:, :, 2] < 130)
        )
        assert np.count_nonzero(yellow) > 30, "no visible 'building' line in the overlay"
        assert s.close("Escape") == 0, s.log()
        log = s.log()
        # The window quit with the build's thread still running, and nothing
        # after: the process did not wait for the build to finish.
        assert "quit while building texture 128" in log, log
        assert "built texture" not in log, log
    finally:
        s.kill()


@pytest.mark.xvfb
def test_window_picks_the_resolution_its_start_view_needs(xserver, tmp_path):
    """``--resolution auto`` (the default): the start view's need
    (needed_resolution for the window's size), logged, built, and stepped
    from with ``[``."""
    from aniso3d.rendering.select import needed_resolution

    cube = scenes.cube()
    expected = needed_resolution(Orbit(cube.bounds, aspect=160 / 120).camera(), (160, 120), cube.bounds)
    s = Session(xserver, tmp_path, ["scene:cube", "--size", "160x120", "--method", "volume"])
    try:
        m = s.wait_for(r"^aniso3d view: voxels (\d+)³ \(auto: .*start view\)$")
        assert int(m.group(1)) == expected
        s.settle(rf"showing volume \(.*\) at 160x120, quality fast, voxels {expected}³ K=16$", after=0)
        lower = step_resolution(expected, -1)
        s.press("bracketleft", rf"showing volume \(.*\) at 160x120, quality fast, voxels {lower}³ K=16$")
        assert s.close("q") == 0, s.log()
    finally:
        s.kill()


@pytest.mark.xvfb
def test_window_on_a_forest_draws_every_method(xserver, tmp_path):
    """``aniso3d view --scene forest --trees 3``: the scene's instances in
    each of the three renderers, each frame the headless renderer's picture
    of the scene from the viewer's start view, and the overlay's instance
    and draw lines."""
    forest = scenes.forest(3)
    size = (320, 240)
    s = Session(xserver, tmp_path, ["--scene", "forest", "--trees", "3", "--size", "320x240",
                                    "--resolution", "8", "-k", "4"])  # fmt: skip
    try:
        what = rf"{forest.n_instances} instances of {len(forest.assets)} assets"
        s.settle(rf"showing mesh \({what}, {forest.n_faces:,} triangles in all\) at 320x240", after=0)
        with_overlay = s.screenshot()
        s.press("o", r"overlay off$")
        camera = Orbit(forest.bounds, aspect=size[0] / size[1]).camera()
        try:
            renderer = Renderer(size)
        except ResourceError:
            renderer = None
        images = {}
        for key, method in (("1", "mesh"), ("2", "volume"), ("3", "splat")):
            if method != "mesh":
                m = s.press(key, rf"(showing|unavailable|failed) {method}")
                if m.group(1) != "showing":
                    pytest.fail(f"the {method} renderer did not draw the scene; log:\n{s.log()}")
                assert re.search(rf"^aniso3d view: showing {method} \({what}, [\d,]+ voxels at the finest\) "
                                 r"at 320x240, .*voxels 8³ K=4 per asset$", s.log(), re.M)  # fmt: skip
            img = images[method] = s.screenshot()
            assert drawn(img) > 0.05 * size[0] * size[1], f"the {method} renderer drew too little"
            if renderer is not None:
                options = {"splat": "disc", "quality": "fast"} if method == "splat" else {}
                expected = renderer.render(forest, camera, method, resolution=8, directions=4, **options)
                assert mean_diff(img, expected) < 0.5, f"the viewer's {method} is not the scene's picture"
        if renderer is not None:
            renderer.release()
        assert mean_diff(images["mesh"], images["volume"]) > 0.5 and mean_diff(images["volume"], images["splat"]) > 0.5
        assert mean_diff(with_overlay[:80, :200], images["mesh"][:80, :200]) > 5, "no overlay drawn"
        assert s.close("q") == 0, s.log()
    finally:
        s.kill()
