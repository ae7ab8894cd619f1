"""The viewer's state without a window: the camera orbit, the settings the
keys change, and each key's effect on them.

Nothing here touches pyglet or OpenGL, so every transition is testable on its
own. The window (:mod:`aniso3d.app.viewer.window`) turns a key press into an
action name through :data:`KEYS`, hands it to :meth:`ViewState.press`, and
acts on the :class:`Reply` (log a line, redraw, save a screenshot, quit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from aniso3d.build.bounds import bounds_of
from aniso3d.build.mesh import Mesh
from aniso3d.build.points import PointCloud
from aniso3d.build.scene import Scene
from aniso3d.build.texture import DEFAULT_DIRECTIONS, PLACEMENTS, AnisoTexture
from aniso3d.errors import InputError
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.select import needed_resolution

METHODS = ("mesh", "volume", "splat")
METHOD_LABELS = {"mesh": "polygons", "volume": "volume", "splat": "splats"}
SPLATS = ("square", "disc", "ellipse")
QUALITIES = ("fast", "high")
#: Voxels along the longest axis that ``[`` and ``]`` step through.
RESOLUTIONS = (8, 16, 24, 32, 48, 64, 96, 128, 192, 256)
DEFAULT_RESOLUTION = 64
#: ``Settings.resolution`` that :meth:`ViewState.resolve_resolution` turns into
#: the resolution the start view needs.
AUTO = "auto"

#: Start view, from the direction of ``aniso3d render``'s default camera: azimuth about +y from +z
#: towards +x, elevation above the horizon, degrees.
HOME_AZIMUTH, HOME_ELEVATION = 30.0, 15.0
DEGREES_PER_PIXEL = 0.4
#: Distance factor per wheel notch towards the target.
ZOOM_PER_STEP = 0.85
#: Zoom stays within these multiples of the start distance.
ZOOM_LIMITS = (0.01, 20.0)
#: Elevation stays this far short of the poles (degrees), where "up" would be the view direction.
MAX_ELEVATION = 89.0
FRAME_MARGIN = 1.1
TURNTABLE_DEGREES_PER_SECOND = 30.0

#: The controls, as the overlay's key bar and ``aniso3d view --help`` show
#: them: (keys, action).
CONTROLS: tuple[tuple[str, str], ...] = (
    ("drag", "orbit"),
    ("right/shift+drag", "pan"),
    ("wheel", "zoom"),
    ("r", "reset view"),
    ("t", "turntable"),
    ("1 2 3", "polygons/volume/splats"),
    ("m", "next renderer"),
    ("s", "splat shape"),
    ("h", "quality"),
    ("p", "point placement"),
    ("l", "level of detail"),
    ("[ ] or - +", "voxels down/up"),
    ("c or F12", "screenshot"),
    ("o", "overlay"),
    ("q or Esc", "quit"),
)

#: Key (pyglet's name in ``pyglet.window.key``) -> action for :meth:`ViewState.press`.
KEYS: dict[str, str] = {
    "ESCAPE": "quit", "Q": "quit",
    "_1": "mesh", "NUM_1": "mesh",
    "_2": "volume", "NUM_2": "volume",
    "_3": "splat", "NUM_3": "splat",
    "M": "next renderer",
    "S": "splat shape",
    "H": "quality",
    "P": "placement",
    "L": "level of detail",
    "BRACKETLEFT": "voxels down", "MINUS": "voxels down", "NUM_SUBTRACT": "voxels down",
    "BRACKETRIGHT": "voxels up", "EQUAL": "voxels up", "PLUS": "voxels up", "NUM_ADD": "voxels up",
    "R": "reset view",
    "T": "turntable",
    "C": "screenshot", "F12": "screenshot",
    "O": "overlay",
}  # fmt: skip

ACTIONS = tuple(dict.fromkeys(KEYS.values()))


def step_resolution(current: int, step: int) -> int:
    """The next resolution of :data:`RESOLUTIONS` above (``step`` > 0) or below
    (``step`` < 0) ``current``; ``current`` itself at either end."""
    if step > 0:
        return next((r for r in RESOLUTIONS if r > current), current)
    return next((r for r in reversed(RESOLUTIONS) if r < current), current)


def cycle(options: tuple, current):
    """The option after ``current`` (wrapping round), or the first when ``current`` is not one."""
    return options[(options.index(current) + 1) % len(options)] if current in options else options[0]


#: What the viewer takes: input class -> kind.
KINDS = ((Mesh, "mesh"), (AnisoTexture, "texture"), (PointCloud, "points"), (Scene, "scene"))


def input_kind(thing) -> str:
    """"mesh", "texture", "points" or "scene" (a :class:`~aniso3d.build.scene.Scene`
    of instances): what the viewer was given."""
    for cls, kind in KINDS:
        if isinstance(thing, cls):
            return kind
    raise InputError(
        f"cannot view a {type(thing).__name__}; give a mesh, a .a3d texture, a PLY point cloud or a scene"
    )


def orbit_direction(azimuth: float, elevation: float) -> np.ndarray:
    """(3,) unit vector from the target to the eye: ``azimuth`` degrees about
    +y from +z towards +x, ``elevation`` degrees above the horizon."""
    az, el = math.radians(azimuth), math.radians(elevation)
    return np.array([math.sin(az) * math.cos(el), math.sin(el), math.cos(az) * math.cos(el)])


# ------------------------------------------------------------------ the camera


class Orbit:
    """An orbiting camera: a target point, a distance, an azimuth about +y
    (from +z towards +x) and an elevation above the horizon, in degrees.

    Pixel arguments are window pixels with y up (pyglet's convention).
    """

    def __init__(self, bounds: np.ndarray, fov: float = 40.0, aspect: float = 1.0):
        self.bounds = np.asarray(bounds, dtype=np.float64)
        self.fov = float(fov)
        self.reset(aspect)

    def reset(self, aspect: float | None = None) -> None:
        """The start view: looking at the centre of the bounds from the home
        direction, just far enough that the box's eight corners fit the window
        with a 10% margin (tighter than :meth:`Camera.frame`'s bounding sphere,
        which leaves a cube at half the window)."""
        if aspect is not None:
            self.aspect = float(aspect)
        self.azimuth, self.elevation = HOME_AZIMUTH, HOME_ELEVATION
        home = orbit_direction(self.azimuth, self.elevation)
        cam = Camera.fit(self.bounds, home, self.fov, self.aspect, FRAME_MARGIN)
        self.target = np.asarray(cam.target, dtype=np.float64)
        self.distance = float(np.linalg.norm(np.subtract(cam.position, cam.target)))
        self.home_distance = self.distance

    def camera(self) -> Camera:
        eye = self.target + orbit_direction(self.azimuth, self.elevation) * self.distance
        return Camera(tuple(eye), tuple(self.target), (0.0, 1.0, 0.0), self.fov)

    def rotate(self, dx: float, dy: float) -> None:
        """Turn as if the scene were grabbed: dragging right turns it to the right."""
        self.azimuth = (self.azimuth - DEGREES_PER_PIXEL * dx) % 360.0
        self.elevation = float(np.clip(self.elevation - DEGREES_PER_PIXEL * dy, -MAX_ELEVATION, MAX_ELEVATION))

    def pan(self, dx: float, dy: float, viewport_height: float) -> None:
        """Move the target so the point under the cursor follows it (at the
        target's depth)."""
        right, up, _ = self.camera().basis()
        per_pixel = 2.0 * self.distance * math.tan(math.radians(self.fov) / 2) / max(viewport_height, 1.0)
        self.target = self.target - (right * dx + up * dy) * per_pixel

    def zoom(self, steps: float) -> None:
        """Move closer by ``steps`` wheel notches (negative: farther)."""
        lo, hi = (math.log(f * self.home_distance) for f in ZOOM_LIMITS)
        log_d = math.log(self.distance) + steps * math.log(ZOOM_PER_STEP)  # no overflow for any steps
        self.distance = math.exp(min(max(log_d, lo), hi))

    def spin(self, seconds: float) -> None:
        """The turntable: turn the eye about +y at :data:`TURNTABLE_DEGREES_PER_SECOND`."""
        self.azimuth = (self.azimuth + TURNTABLE_DEGREES_PER_SECOND * seconds) % 360.0

    def describe(self) -> str:
        t = ", ".join(f"{x:.3g}" for x in self.target)
        return (f"azimuth {self.azimuth:.1f} elevation {self.elevation:.1f} "
                f"distance {self.distance:.4g} target ({t})")  # fmt: skip


# --------------------------------------------------------------------- settings


@dataclass
class Settings:
    """What the user chose; every key of the viewer changes one of these."""

    method: str | None = None  # None: what the input is (mesh, volume for a texture, splat)
    splat: str = "disc"
    quality: str = "fast"
    placement: str = "centroid"
    resolution: int | str = DEFAULT_RESOLUTION  # or "auto": see ViewState.resolve_resolution
    directions: int = DEFAULT_DIRECTIONS
    turntable: bool = False
    overlay: bool = True
    lod: bool = False  # splats and volume from the texture's pyramid (aniso3d.build.pyramid)


def settings_text(s: Settings, kind: str) -> str:
    """The settings that shape the current image, as the log's "showing" lines state them."""
    parts = [f"quality {s.quality}"]
    if s.method == "splat":
        parts.insert(0, f"splat {s.splat}")
        if kind != "points":
            parts.append(f"placement {s.placement}")
    if s.method != "mesh" and kind != "points":
        parts.append(f"voxels {s.resolution}³ K={s.directions}" + (" per asset" if kind == "scene" else ""))
        if s.lod and kind != "scene":  # a scene's instances always choose their level
            parts.append("level of detail")
    return ", ".join(parts)


@dataclass(frozen=True)
class Reply:
    """What a key did. ``text`` is logged (and shown as a notice when
    ``notice``: the key could not do what it says); ``changed`` names the
    settings that changed; ``view`` says the camera moved."""

    text: str = ""
    notice: bool = False
    changed: tuple[str, ...] = ()
    view: bool = False
    screenshot: bool = False
    quit: bool = False


class ViewState:
    """The settings and the camera for one input of ``kind`` ("mesh",
    "texture", "points" or "scene") whose drawn content spans ``bounds`` (2, 3).
    A scene is converted per asset, as a mesh is (its resolution steps), and
    its instances always draw from their assets' pyramids."""

    def __init__(self, kind: str, bounds: np.ndarray, settings: Settings | None = None, aspect: float = 1.0):
        if kind not in ("mesh", "texture", "points", "scene"):
            raise InputError(f"unknown input kind '{kind}'; one of mesh, texture, points, scene")
        self.kind = kind
        self.settings = replace(settings) if settings is not None else Settings()
        if self.settings.method is None:
            self.settings.method = {"mesh": "mesh", "texture": "volume", "points": "splat", "scene": "mesh"}[kind]
        self.orbit = Orbit(bounds, aspect=aspect)

    @classmethod
    def for_input(cls, thing, settings: Settings | None = None, aspect: float = 1.0) -> ViewState:
        """The state for a Mesh, AnisoTexture, PointCloud or Scene; a texture fixes the
        resolution and directions to its own."""
        state = cls(input_kind(thing), bounds_of(thing), settings, aspect)
        if state.kind == "texture":
            state.settings.resolution, state.settings.directions = thing.resolution, thing.n_directions
        return state

    def resolve_resolution(self, size: tuple[int, int]) -> str | None:
        """Turn a resolution of "auto" into the one the current view needs in a
        window of ``size`` (w, h) pixels
        (:func:`~aniso3d.rendering.select.needed_resolution`: a power of two, so
        one of :data:`RESOLUTIONS`, which ``[`` and ``]`` step from); the line
        to log, or None when the resolution was a number already."""
        if self.settings.resolution != AUTO:
            return None
        if self.kind == "scene":  # assets of many sizes seen from many distances: one default for all
            self.settings.resolution = DEFAULT_RESOLUTION
            return f"voxels {DEFAULT_RESOLUTION}³ per asset (auto: a scene's default; [ and ] step it)"
        if self.kind != "mesh":  # nothing is converted: a texture keeps its own, points have none
            self.settings.resolution = DEFAULT_RESOLUTION
            return None
        res = needed_resolution(self.orbit.camera(), size, self.orbit.bounds)
        self.settings.resolution = res
        return f"voxels {res}³ (auto: a voxel about a pixel at the nearest point of the start view)"

    @property
    def lod(self) -> bool:
        """Whether the volume and splats draw from the pyramid (never for a
        point cloud; always for a scene, whose instances each choose a level)."""
        return self.kind == "scene" or (self.settings.lod and self.kind != "points")

    def press(self, action: str, aspect: float | None = None) -> Reply:
        """Apply one of :data:`ACTIONS`; ``aspect`` (width / height) is the
        window's, for "reset view"."""
        s = self.settings
        if action == "quit":
            return Reply("quit", quit=True)
        if action == "screenshot":
            return Reply(screenshot=True)
        if action in METHODS:
            return self._set("method", action, f"renderer {METHOD_LABELS[action]}")
        if action == "next renderer":
            return self.press(cycle(METHODS, s.method))
        if action == "splat shape":
            return self._set("splat", cycle(SPLATS, s.splat))
        if action == "quality":
            return self._set("quality", cycle(QUALITIES, s.quality))
        if action == "placement":
            if self.kind == "points":
                return Reply("placement is fixed: the input is a point cloud", notice=True)
            return self._set("placement", cycle(PLACEMENTS, s.placement))
        if action == "level of detail":
            if self.kind == "points":
                return Reply("level of detail needs a texture: the input is a point cloud", notice=True)
            if self.kind == "scene":
                return Reply("level of detail is always on for a scene: each instance draws its own level",
                             notice=True)  # fmt: skip
            state = "off" if s.lod else "on"
            if s.method == "mesh":
                return self._set("lod", not s.lod, f"level of detail {state}: it applies to the volume and splats",
                                 notice=True)  # fmt: skip
            return self._set("lod", not s.lod, f"level of detail {state}")
        if action in ("voxels down", "voxels up"):
            return self._step_resolution(1 if action == "voxels up" else -1)
        if action == "reset view":
            self.orbit.reset(aspect)
            return Reply(f"camera {self.orbit.describe()}", view=True)
        if action == "turntable":
            return self._set("turntable", not s.turntable, f"turntable {'off' if s.turntable else 'on'}")
        if action == "overlay":
            return self._set("overlay", not s.overlay, f"overlay {'off' if s.overlay else 'on'}")
        raise InputError(f"unknown viewer action '{action}'; one of {', '.join(ACTIONS)}")

    def _set(self, name: str, value, text: str | None = None, notice: bool = False) -> Reply:
        setattr(self.settings, name, value)
        return Reply(text if text is not None else f"{name} {value}", notice=notice, changed=(name,))

    def _step_resolution(self, step: int) -> Reply:
        if self.kind not in ("mesh", "scene"):
            what = "saved texture" if self.kind == "texture" else "point cloud"
            return Reply(f"resolution is fixed: the input is a {what}", notice=True)
        new = step_resolution(self.settings.resolution, step)
        if new == self.settings.resolution:
            return Reply(f"resolution {new}³ is the {'highest' if step > 0 else 'lowest'} step", notice=True)
        return self._set("resolution", new, f"voxels {new}³")
