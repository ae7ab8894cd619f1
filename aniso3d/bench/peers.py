"""``aniso3d bench peers``: one point cloud drawn by aniso3d and by the point
renderers people use, side by side, in one run.

Contenders (:data:`CONTENDERS`; the peers are optional, the ``peers`` extra):

- ``aniso3d fast`` / ``aniso3d high``: disc splats sized from each point's
  neighbours (:mod:`aniso3d.build.spacing`), quality "fast" and "high";
- ``GL_POINTS 2 px``: the floor, a bare moderngl program drawing one square
  2-pixel point per point with a depth test: nothing cheaper draws every point;
- ``GL_POINTS``: the same at the splats' on-screen size;
- ``PyVista points`` / ``PyVista points_gaussian``: VTK through PyVista
  (offscreen, EGL or OSMesa, whichever VTK finds);
- ``pyrender``: pyrender's OffscreenRenderer (``PYOPENGL_PLATFORM=egl``);
- ``Open3D``: Open3D's Filament OffscreenRenderer (headless).

Each contender runs in a process of its own (its own GL context, its own
peak memory), started once and kept: the parent asks each in turn for a few
frames, round after round, so that the machine's load falls on all alike.
A frame is the camera moved (an orbit of one degree per frame about the
object's up axis), drawn, and read back into a NumPy array; frame times are
wall-clock seconds of that in the worker. A peer whose package or GL
platform is missing is skipped with a note.

"Equal on-screen splat size": the peers that draw fixed-size points get the
median diameter, in pixels at the object's centre, of aniso3d's drawn discs;
``points_gaussian`` (world-sized splats) gets their median radius in world
units. Holes: pixels inside the truth's silhouette (the generated torus drawn
as polygons) where the background shows, a share of the silhouette; also in
the silhouette eroded by 2 pixels (the edge's rasterisation set aside), and
the overhang (drawn pixels outside the silhouette dilated by 2 pixels).
"""

from __future__ import annotations

import json
import os
import resource
import shlex
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from aniso3d.errors import InputError
from aniso3d.rendering.camera import Camera

#: name -> (label, what it needs installed, how it sizes its points)
CONTENDERS: dict[str, tuple[str, str, str]] = {
    "aniso3d-fast": ("aniso3d fast", "", "splat"),
    "aniso3d-high": ("aniso3d high", "", "splat"),
    "gl-points-2px": ("GL_POINTS 2 px", "", "floor"),
    "gl-points": ("GL_POINTS", "", "pixels"),
    "pyvista-points": ("PyVista points", "pyvista", "pixels"),
    "pyvista-gaussian": ("PyVista points_gaussian", "pyvista", "world"),
    "pyrender": ("pyrender", "pyrender", "pixels"),
    "open3d": ("Open3D", "open3d", "pixels"),
}
#: The contenders that need nothing beyond aniso3d's own dependencies.
CORE = ("aniso3d-fast", "aniso3d-high", "gl-points-2px", "gl-points")
PEERS = tuple(n for n in CONTENDERS if n not in CORE)
FLOOR = "gl-points-2px"
#: Background of every contender: magenta, which neither the torus's colours
#: nor any shade of them reach, so "background" is a colour test.
BACKGROUND = (1.0, 0.0, 1.0)
#: Largest difference (per channel, 0-255) still read as the background.
BACKGROUND_TOLERANCE = 2
#: The generated torus: radii, noise along the normal (0.25 % of the minor radius).
MAJOR, MINOR, NOISE = 1.0, 0.4, 0.001
#: The view: azimuth and elevation of the camera, degrees.
AZIMUTH, ELEVATION = 20.0, 40.0
#: Views (orbit degrees) at which holes are counted; the worst is reported.
HOLE_VIEWS = (0.0, 45.0, 90.0)
ERODE_PX = 2
#: The disc splat's drawn radius over the point's radius (aniso3d's default for discs).
DISC_FACTOR = 1.25
#: Radius of a PyVista ``points_gaussian`` disc over the mapper's scale factor
#: (measured: a splat of scale factor 0.1 seen at 11 pixels per 0.1 units covers
#: about 4,100 pixels, a disc of radius 36 px).
PYVISTA_SPLAT_EXTENT = 3.0
#: Targets: aniso3d fast at most this many times the floor's frame time ...
FLOOR_RATIO = 1.2
#: ... and fewer background pixels than this inside the torus's silhouette.
HOLE_TARGET = 1e-3


# ---------------------------------------------------------------- the torus


def torus_points(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` points uniform over the torus's area (y up, around the y axis),
    moved along the normal by N(0, NOISE): positions (n, 3), unit normals
    (n, 3) and colours (n, 3) in [0, 1]."""
    if n < 1:
        raise InputError(f"the torus needs at least 1 point, got {n}")
    rng = np.random.default_rng(seed)
    u = rng.uniform(0, 2 * np.pi, n)
    v = np.zeros(0)
    while len(v) < n:  # the area element is proportional to MAJOR + MINOR cos v: rejection
        cand = rng.uniform(0, 2 * np.pi, 2 * n)
        keep = rng.uniform(0, MAJOR + MINOR, 2 * n) < MAJOR + MINOR * np.cos(cand)
        v = np.concatenate([v, cand[keep]])
    v = v[:n]
    normal = np.stack([np.cos(v) * np.cos(u), np.sin(v), np.cos(v) * np.sin(u)], axis=1)
    centre = np.stack([MAJOR * np.cos(u), np.zeros(n), MAJOR * np.sin(u)], axis=1)
    pos = centre + (MINOR + rng.normal(0, NOISE, n))[:, None] * normal
    colour = np.stack([0.55 + 0.35 * np.sin(6 * u), 0.5 + 0.3 * np.cos(3 * v), 0.45 + 0.25 * np.sin(4 * u + v)], 1)
    return pos, normal, colour


def torus_mesh(nu: int = 1024, nv: int = 512):
    """The same torus as polygons (nu x nv quads): the truth's silhouette."""
    from aniso3d.build.mesh import Mesh

    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, nu, endpoint=False), np.linspace(0, 2 * np.pi, nv, endpoint=False),
                       indexing="ij")  # fmt: skip
    ring = MAJOR + MINOR * np.cos(v)
    pos = np.stack([ring * np.cos(u), MINOR * np.sin(v), ring * np.sin(u)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a, b = i * nv + j, ((i + 1) % nu) * nv + j
    c, d = ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv
    faces = np.concatenate([np.stack([a, d, c], -1).reshape(-1, 3), np.stack([a, c, b], -1).reshape(-1, 3)])
    return Mesh.from_arrays(pos, faces, (0.6, 0.5, 0.4), 0.1, 16.0, name="torus")


def write_cloud_ply(path: str | os.PathLike, pos: np.ndarray, normal: np.ndarray, colour: np.ndarray) -> Path:
    """Binary little-endian PLY with x y z nx ny nz red green blue (uchar) and
    no size property, as a scanner or another tool writes (atomically)."""
    import plyfile

    from aniso3d.files import atomic_write

    rec = np.empty(len(pos), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("nx", "<f4"), ("ny", "<f4"),
                                    ("nz", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])  # fmt: skip
    for i, c in enumerate("xyz"):
        rec[c], rec["n" + c] = pos[:, i], normal[:, i]
    rgb = np.round(np.clip(colour, 0, 1) * 255).astype(np.uint8)
    rec["red"], rec["green"], rec["blue"] = rgb.T
    ply = plyfile.PlyData([plyfile.PlyElement.describe(rec, "vertex")])
    return atomic_write(path, ply.write)


# ------------------------------------------------------------- the cloud


@dataclass(frozen=True)
class Cloud:
    """What the peers draw: positions (N, 3) float32, colours (N, 3) uint8."""

    positions: np.ndarray
    colours: np.ndarray

    @classmethod
    def read(cls, path: str | os.PathLike) -> Cloud:
        """Positions and colours of a PLY point cloud (grey without colours)."""
        import plyfile

        from aniso3d.build.ply import COLOUR_NAMES

        vertex = plyfile.PlyData.read(str(path))["vertex"].data
        pos = np.stack([vertex[c] for c in "xyz"], axis=1).astype(np.float32)
        names = vertex.dtype.names or ()
        rgb = next((c for c in COLOUR_NAMES if all(n in names for n in c)), None)
        if rgb is None:
            col = np.full((len(pos), 3), 160, np.uint8)
        else:
            raw = np.stack([vertex[c] for c in rgb], axis=1)
            if raw.dtype == np.uint8:
                col = raw
            elif np.issubdtype(raw.dtype, np.integer):
                col = np.round(raw / np.iinfo(raw.dtype).max * 255).astype(np.uint8)
            else:
                scale = 1.0 if np.nanmax(raw) > 1 else 255.0
                col = np.round(np.clip(np.nan_to_num(raw) * scale, 0, 255)).astype(np.uint8)
        return cls(np.ascontiguousarray(pos), np.ascontiguousarray(col))


def view_camera(bounds: np.ndarray, sample: np.ndarray | None = None) -> Camera:
    """The camera every contender starts from: AZIMUTH/ELEVATION, fitted to the object."""
    az, el = np.radians(AZIMUTH), np.radians(ELEVATION)
    direction = (np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el))
    return Camera.fit(bounds, direction=direction, points=sample)


def pixels_per_unit(camera: Camera, height: int) -> float:
    """Pixels per world unit, for a length facing the camera at its target."""
    dist = float(np.linalg.norm(np.subtract(camera.target, camera.position)))
    return 0.5 * height / (np.tan(np.radians(camera.fov) / 2) * dist)


# ------------------------------------------------------------ contenders
# Each runs in a worker process: made from a config dict, then frame(camera)
# returns the (H, W, 3) uint8 image, read back.


class _AnisoSplats:
    def __init__(self, cfg: dict, quality: str):
        from aniso3d.build.points import PointCloud
        from aniso3d.rendering.lighting import Lighting
        from aniso3d.rendering.renderer import Renderer

        self.quality = quality
        self.r = Renderer(tuple(cfg["size"]), lighting=Lighting(background=BACKGROUND), backend=cfg["backend"])
        self.cloud = PointCloud.load_ply(cfg["ply"])

    def frame(self, camera: Camera) -> np.ndarray:
        return self.r.render(self.cloud, camera, "splat", splat="disc", quality=self.quality)

    def close(self) -> None:
        self.r.release()


_POINTS_VS = """#version 330
uniform mat4 mvp;
in vec3 position;
in vec3 colour;
out vec3 v_colour;
void main() { gl_Position = mvp * vec4(position, 1.0); v_colour = colour; }
"""
_POINTS_FS = """#version 330
in vec3 v_colour;
out vec4 f_colour;
void main() { f_colour = vec4(v_colour, 1.0); }
"""


class _GLPoints:
    """The floor: one vertex buffer, one draw call, square points, depth test."""

    def __init__(self, cfg: dict, px: float):
        from aniso3d.rendering.context import GLContext

        cloud = Cloud.read(cfg["ply"])
        self.gl = GLContext(cfg["backend"])
        ctx = self.gl.ctx
        self.size = tuple(cfg["size"])
        self.bounds = np.asarray(cfg["bounds"])
        self.px = float(px)
        self.prog = ctx.program(vertex_shader=_POINTS_VS, fragment_shader=_POINTS_FS)
        self.vbo = ctx.buffer(cloud.positions.tobytes())
        self.cbo = ctx.buffer(cloud.colours.tobytes())
        self.vao = ctx.vertex_array(self.prog, [(self.vbo, "3f", "position"), (self.cbo, "3f1", "colour")])
        w, h = self.size
        self.fbo = ctx.framebuffer([ctx.renderbuffer((w, h))], ctx.depth_renderbuffer((w, h)))

    def frame(self, camera: Camera) -> np.ndarray:
        import moderngl

        ctx = self.gl.ctx
        w, h = self.size
        near, far = camera.clip_range(self.bounds)
        mvp = camera.projection_matrix(w / h, near, far) @ camera.view_matrix()
        self.prog["mvp"].write(mvp.T.astype(np.float32).tobytes())  # column-major
        self.fbo.use()
        ctx.viewport = (0, 0, w, h)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.point_size = self.px
        self.fbo.clear(*BACKGROUND, 1.0, depth=1.0)
        self.vao.render(moderngl.POINTS)
        raw = self.fbo.read(components=3, dtype="f1")
        return np.frombuffer(raw, np.uint8).reshape(h, w, 3)[::-1]

    def close(self) -> None:
        self.gl.release()


class _PyVista:
    def __init__(self, cfg: dict, style: str, px: float, world_radius: float):
        import pyvista as pv

        cloud = Cloud.read(cfg["ply"])
        self.bounds = np.asarray(cfg["bounds"])
        w, h = cfg["size"]
        self.p = pv.Plotter(off_screen=True, window_size=(w, h))
        self.p.set_background(BACKGROUND)
        poly = pv.PolyData(cloud.positions)
        poly["rgb"] = cloud.colours
        actor = self.p.add_points(poly, scalars="rgb", rgb=True, style=style, point_size=px, lighting=False,
                                  emissive=False) if style == "points_gaussian" else \
            self.p.add_points(poly, scalars="rgb", rgb=True, style=style, point_size=px, lighting=False)  # fmt: skip
        if style == "points_gaussian":
            # World units, like aniso3d's discs; VTK draws each splat on a square
            # PYVISTA_SPLAT_EXTENT scale factors wide each way and PyVista's disc fills it.
            actor.mapper.scale_factor = world_radius / PYVISTA_SPLAT_EXTENT
        self.p.show(auto_close=False)

    def frame(self, camera: Camera) -> np.ndarray:
        cam = self.p.camera
        cam.position, cam.focal_point, cam.up = camera.position, camera.target, camera.up
        cam.view_angle = camera.fov
        cam.clipping_range = camera.clip_range(self.bounds)
        self.p.render()
        return np.ascontiguousarray(self.p.screenshot(return_img=True)[:, :, :3])

    def close(self) -> None:
        self.p.close()


def camera_pose(camera: Camera) -> np.ndarray:
    """4x4 camera-to-world matrix (camera looks down its -z, y up), as pyrender takes it."""
    r, u, f = camera.basis()
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = r, u, -f, camera.position
    return pose


class _Pyrender:
    def __init__(self, cfg: dict, px: float):
        import pyrender

        cloud = Cloud.read(cfg["ply"])
        self.pyrender = pyrender
        self.bounds = np.asarray(cfg["bounds"])
        w, h = cfg["size"]
        self.scene = pyrender.Scene(bg_color=[*BACKGROUND, 1.0], ambient_light=[1.0, 1.0, 1.0])
        self.scene.add(pyrender.Mesh.from_points(cloud.positions, colors=cloud.colours))
        self.cam = pyrender.PerspectiveCamera(yfov=np.radians(cfg["fov"]), aspectRatio=w / h)
        self.node = self.scene.add(self.cam, pose=np.eye(4))
        self.r = pyrender.OffscreenRenderer(w, h, point_size=px)

    def frame(self, camera: Camera) -> np.ndarray:
        self.cam.znear, self.cam.zfar = camera.clip_range(self.bounds)
        self.scene.set_pose(self.node, camera_pose(camera))
        colour, _ = self.r.render(self.scene, flags=self.pyrender.RenderFlags.FLAT)
        return np.ascontiguousarray(colour[:, :, :3])

    def close(self) -> None:
        self.r.delete()


class _Open3D:
    def __init__(self, cfg: dict, px: float):
        import open3d as o3d

        cloud = Cloud.read(cfg["ply"])
        self.bounds = np.asarray(cfg["bounds"])
        w, h = cfg["size"]
        self.aspect = w / h
        self.o3d = o3d
        rendering = o3d.visualization.rendering
        self.r = rendering.OffscreenRenderer(w, h)
        self.r.scene.set_background([*BACKGROUND, 1.0])
        # No tone mapping or colour grading: colours and background as given,
        # like every other contender's.
        self.r.scene.view.set_post_processing(False)
        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.positions.astype(np.float64)))
        pc.colors = o3d.utility.Vector3dVector(cloud.colours.astype(np.float64) / 255.0)
        mat = rendering.MaterialRecord()
        mat.shader = "defaultUnlit"
        mat.point_size = float(px)
        self.r.scene.add_geometry("cloud", pc, mat)

    def frame(self, camera: Camera) -> np.ndarray:
        cam = self.r.scene.camera
        near, far = camera.clip_range(self.bounds)
        cam.set_projection(camera.fov, self.aspect, near, far, self.o3d.visualization.rendering.Camera.FovType.Vertical)
        cam.look_at(list(camera.target), list(camera.position), list(camera.up))
        return np.ascontiguousarray(np.asarray(self.r.render_to_image())[:, :, :3])

    def close(self) -> None:
        del self.r


def make_contender(name: str, cfg: dict):
    """The contender ``name`` set up from a worker's config (raises ImportError
    when its package is missing)."""
    px, world = cfg["point_px"], cfg["world_radius"]
    if name == "aniso3d-fast":
        return _AnisoSplats(cfg, "fast")
    if name == "aniso3d-high":
        return _AnisoSplats(cfg, "high")
    if name == "gl-points-2px":
        return _GLPoints(cfg, 2.0)
    if name == "gl-points":
        return _GLPoints(cfg, px)
    if name == "pyvista-points":
        return _PyVista(cfg, "points", px, world)
    if name == "pyvista-gaussian":
        return _PyVista(cfg, "points_gaussian", px, world)
    if name == "pyrender":
        return _Pyrender(cfg, px)
    if name == "open3d":
        return _Open3D(cfg, px)
    raise InputError(f"unknown contender '{name}'; choose from {', '.join(CONTENDERS)}")


def worker_env(name: str) -> dict:
    """The environment of a contender's process: pyrender needs its GL platform named."""
    env = dict(os.environ)
    if name == "pyrender":
        env.setdefault("PYOPENGL_PLATFORM", "egl")
    return env


_REPLIES = None


def _peak_mib() -> float:
    """This process's peak resident memory, MiB. /proc's VmHWM belongs to the
    process's own memory map (ru_maxrss would keep the parent's peak, which
    Linux carries across fork and exec); ru_maxrss where /proc is missing."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _reply(obj: dict) -> None:
    _REPLIES.write(json.dumps(obj) + "\n")
    _REPLIES.flush()


def import_failure(exc: ImportError) -> str:
    """Why a peer could not be imported, and what to do: not installed (a
    missing Python module), or installed but missing a system library its
    compiled part links against (Open3D's libusb, for one)."""
    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    if not isinstance(exc, ModuleNotFoundError) and "shared object" in text:
        return (f"installed but cannot load: {text}; install that system library "
                "(docs/peers.md lists what each peer needs)")  # fmt: skip
    return f"not installed ({exc.name or text}); pip install 'aniso3d[peers]'"


def worker_main(name: str, cfg_json: str) -> int:
    """A contender's process: set up, then answer commands on stdin, one JSON
    line per command on stdout (anything the libraries print goes to stderr).

    Commands: ``frames K N`` (time frames at orbit degrees K .. K+N-1),
    ``image DEGREES PATH`` (save that view as PNG), ``quit`` (peak memory).
    """
    global _REPLIES
    cfg = json.loads(cfg_json)
    # Replies go to the original stdout; what the libraries print, from Python
    # or from C, goes to stderr (file descriptor 1 becomes a copy of 2).
    _REPLIES = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    base = Camera(tuple(cfg["position"]), tuple(cfg["target"]), tuple(cfg["up"]), cfg["fov"])
    t0 = time.perf_counter()
    try:
        contender = make_contender(name, cfg)
        contender.frame(base)  # warm-up: uploads, shader compilation
    except ImportError as exc:
        _reply({"skip": import_failure(exc)})
        return 0
    except Exception as exc:  # a GL platform or driver the library cannot use here
        _reply({"skip": f"cannot run here: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"})
        return 0
    _reply({"ready": True, "setup_s": time.perf_counter() - t0})
    for line in sys.stdin:
        cmd = line.split()
        if not cmd:
            continue
        if cmd[0] == "frames":
            k, n = int(cmd[1]), int(cmd[2])
            times = []
            for i in range(k, k + n):
                cam = base.orbit(float(i))
                t = time.perf_counter()
                img = contender.frame(cam)
                times.append(time.perf_counter() - t)
                del img
            _reply({"times": times})
        elif cmd[0] == "image":
            from aniso3d.rendering.images import save_png

            save_png(cmd[2], contender.frame(base.orbit(float(cmd[1]))))
            _reply({"saved": cmd[2]})
        elif cmd[0] == "quit":
            peak = _peak_mib()
            contender.close()
            _reply({"peak_mib": peak})
            return 0
    return 0


# ----------------------------------------------------------------- the run


@dataclass
class PeerSettings:
    """One ``aniso3d bench peers`` run.

    Attributes:
        ply: a user's PLY point cloud, or None for the generated torus.
        points: points of the generated torus.
        size: (width, height) of every image, pixels.
        frames: timed frames per contender (at least 5), in ``rounds`` rounds.
        contenders: names from :data:`CONTENDERS`.
        backend: aniso3d's OpenGL backend for its own contenders.
        images: folder for each contender's first view (PNG), or None.
    """

    ply: Path | None = None
    points: int = 1_000_000
    size: tuple[int, int] = (1024, 1024)
    frames: int = 6
    rounds: int = 3
    contenders: tuple[str, ...] = tuple(CONTENDERS)
    backend: str = "auto"
    images: Path | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        if self.frames < 5:
            raise InputError(f"the frame time needs at least 5 frames for its spread, got {self.frames}")
        if not 1 <= self.rounds <= self.frames:
            raise InputError(f"rounds must be between 1 and the frames ({self.frames}), got {self.rounds}")
        unknown = [c for c in self.contenders if c not in CONTENDERS]
        if unknown or not self.contenders:
            raise InputError(f"unknown contender(s) {', '.join(unknown) or '(none given)'}; "
                             f"choose from {', '.join(CONTENDERS)}")  # fmt: skip
        if self.points < 100:
            raise InputError(f"the torus needs at least 100 points, got {self.points}")


@dataclass
class PeerRow:
    """One contender's results (None where not measured)."""

    name: str
    label: str
    status: str = "ok"  # "ok" or "skipped"
    note: str = ""
    point_size: str = ""
    setup_s: float | None = None
    times: list[float] = field(default_factory=list)
    peak_mib: float | None = None
    holes: float | None = None  # background share inside the silhouette, worst view
    holes_inner: float | None = None  # ... inside the eroded silhouette
    overhang: float | None = None

    @property
    def median_ms(self) -> float | None:
        return 1000 * float(np.median(self.times)) if self.times else None


@dataclass
class PeerResult:
    settings: PeerSettings
    rows: list[PeerRow]
    meta: dict


def erode(mask: np.ndarray, px: int) -> np.ndarray:
    """``mask`` eroded by ``px`` pixels (4-neighbourhood, outside counts as False)."""
    out = mask.copy()
    for _ in range(px):
        m = out.copy()
        m[1:] &= out[:-1]
        m[:-1] &= out[1:]
        m[:, 1:] &= out[:, :-1]
        m[:, :-1] &= out[:, 1:]
        m[0], m[-1], m[:, 0], m[:, -1] = False, False, False, False
        out = m
    return out


def background_mask(img: np.ndarray) -> np.ndarray:
    """(H, W) True where ``img`` shows the background colour."""
    bg = np.round(np.asarray(BACKGROUND) * 255).astype(np.int16)
    return np.all(np.abs(img[..., :3].astype(np.int16) - bg) <= BACKGROUND_TOLERANCE, axis=-1)


def hole_stats(img: np.ndarray, silhouette: np.ndarray) -> tuple[float, float, float]:
    """(background inside the silhouette, background inside it eroded by
    ERODE_PX, drawn pixels outside it dilated by ERODE_PX), each a share of
    the silhouette's pixels."""
    bg = background_mask(img)
    n = max(int(silhouette.sum()), 1)
    inner = erode(silhouette, ERODE_PX)
    outer = ~erode(~silhouette, ERODE_PX)
    return (np.count_nonzero(bg & silhouette) / n, np.count_nonzero(bg & inner) / n,
            np.count_nonzero(~bg & ~outer) / n)  # fmt: skip


class _Worker:
    """The parent's handle on one contender's process."""

    def __init__(self, name: str, cfg: dict, log_dir: Path):
        self.name = name
        self.log = open(log_dir / f"{name}.log", "w+")  # noqa: SIM115 - closed in close()
        self.proc = subprocess.Popen([sys.executable, "-m", "aniso3d.bench.peers", name, json.dumps(cfg)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self.log, text=True,
                                     env=worker_env(name))  # fmt: skip

    def ask(self, command: str | None = None) -> dict:
        if command is not None:
            self.proc.stdin.write(command + "\n")
            self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            self.log.seek(0)
            tail = [x for x in self.log.read().splitlines() if x.strip()][-1:] or ["no message"]
            raise RuntimeError(f"the {self.name} process ended (status {self.proc.wait()}): {tail[0][:200]}")
        return json.loads(line)

    def close(self) -> None:
        try:
            if self.proc.poll() is None:
                self.proc.stdin.close()
                self.proc.wait(timeout=60)
        except (subprocess.TimeoutExpired, OSError):
            self.proc.kill()
            self.proc.wait()
        finally:
            self.log.close()


def _loadavg() -> tuple[float, float, float] | None:
    try:
        return tuple(round(x, 2) for x in os.getloadavg())
    except (AttributeError, OSError):
        return None


def run_peers(settings: PeerSettings, progress: Callable[[float, str], None] | None = None) -> PeerResult:
    """Run every contender of ``settings`` on one cloud; one :class:`PeerRow` each."""
    from aniso3d.build.points import PointCloud
    from aniso3d.rendering.renderer import Renderer

    say = progress or (lambda f, s: None)
    from aniso3d.bench.run import CODE_PATHS, code_version

    meta: dict = {"load_start": _loadavg(), "cpus": os.cpu_count(), "started": time.strftime("%Y-%m-%d %H:%M"),
                  "code": code_version(CODE_PATHS)}  # fmt: skip
    t_start = time.perf_counter()
    w, h = settings.size
    with tempfile.TemporaryDirectory(prefix="aniso3d-peers.") as tmp:
        tmp = Path(tmp)
        if settings.ply is None:
            pos, normal, colour = torus_points(settings.points, settings.seed)
            ply = write_cloud_ply(tmp / "torus.ply", pos, normal, colour)
            r = MAJOR + MINOR
            bounds = np.array([[-r, -MINOR, -r], [r, MINOR, r]])
            meta["input"] = (f"generated noisy torus, {settings.points:,} points (radii {MAJOR} and {MINOR}, "
                             f"noise {NOISE} along the normal), binary PLY with normals and colours, "
                             "no sizes")  # fmt: skip
        else:
            ply = Path(settings.ply)
            pos = Cloud.read(ply).positions.astype(np.float64)
            bounds = np.stack([pos.min(axis=0), pos.max(axis=0)])
            meta["input"] = f"{ply.name}, {len(pos):,} points"
        meta["points"] = len(pos)
        say(0.02, "sizing the splats")
        sizes = PointCloud.load_ply(ply)  # the splat sizes aniso3d gives these points
        radius = DISC_FACTOR * float(np.median(np.sqrt(sizes.areas / np.pi)))
        del sizes
        sample = pos[:: max(1, len(pos) // 20000)]
        camera = view_camera(bounds, sample)
        px = max(1.0, round(2 * radius * pixels_per_unit(camera, h)))
        meta["splat_radius"], meta["point_px"] = radius, px
        cfg = {"ply": str(ply), "size": [w, h], "bounds": bounds.tolist(), "position": list(camera.position),
               "target": list(camera.target), "up": list(camera.up), "fov": camera.fov, "point_px": px,
               "world_radius": radius, "backend": settings.backend}  # fmt: skip

        silhouettes = None
        if settings.ply is None:
            say(0.05, "the truth's silhouettes")
            nu = min(1024, max(128, 2 * max(w, h)))  # quads a few times finer than the pixels
            mesh = torus_mesh(nu, nu // 2)
            with Renderer((w, h), backend=settings.backend) as rend:
                meta["gl_renderer"] = rend.gl.renderer
                silhouettes = [rend.render(mesh, camera.orbit(a), "mesh", alpha=True)[..., 3] > 0 for a in HOLE_VIEWS]
            del mesh

        rows = {n: PeerRow(n, CONTENDERS[n][0]) for n in settings.contenders}
        workers: dict[str, _Worker] = {}
        try:
            for i, name in enumerate(settings.contenders):  # one at a time: set-up timings do not overlap
                say(0.1 + 0.3 * i / len(settings.contenders), f"starting {name}")
                row, kind = rows[name], CONTENDERS[name][2]
                row.point_size = {"splat": f"discs, median r {radius:.2g}", "floor": "2 px",
                                  "pixels": f"{px:g} px", "world": f"r {radius:.2g}"}[kind]  # fmt: skip
                wk = _Worker(name, cfg, tmp)
                try:
                    reply = wk.ask()
                except (RuntimeError, json.JSONDecodeError) as exc:
                    reply = {"skip": f"cannot run here: {exc}"}
                if "skip" in reply:
                    row.status, row.note = "skipped", reply["skip"]
                    wk.close()
                    continue
                row.setup_s = reply["setup_s"]
                workers[name] = wk
            per_round = [settings.frames // settings.rounds + (k < settings.frames % settings.rounds)
                         for k in range(settings.rounds)]  # fmt: skip
            done = 0
            for k, n in enumerate(per_round):  # interleaved: each contender in turn, round after round
                for name, wk in workers.items():
                    say(0.4 + 0.5 * (k + list(workers).index(name) / len(workers)) / settings.rounds,
                        f"round {k + 1}/{settings.rounds}: {name}")  # fmt: skip
                    rows[name].times += wk.ask(f"frames {done} {n}")["times"]
                done += n
            for name, wk in workers.items():
                say(0.92, f"holes: {name}")
                row = rows[name]
                if silhouettes is not None:
                    stats = []
                    for a, sil in zip(HOLE_VIEWS, silhouettes, strict=True):
                        path = tmp / f"{name}_{a:g}.png"
                        wk.ask(f"image {a} {path}")
                        from aniso3d.rendering.images import load_png

                        img = load_png(path)
                        stats.append(hole_stats(img, sil))
                        if settings.images is not None and a == HOLE_VIEWS[0]:
                            settings.images.mkdir(parents=True, exist_ok=True)
                            os.replace(path, settings.images / f"{name}.png")
                    row.holes, row.holes_inner, row.overhang = (max(s[j] for s in stats) for j in range(3))
                elif settings.images is not None:
                    settings.images.mkdir(parents=True, exist_ok=True)
                    wk.ask(f"image 0 {settings.images / f'{name}.png'}")
                row.peak_mib = wk.ask("quit")["peak_mib"]
        finally:
            for wk in workers.values():
                wk.close()
    meta["load_end"] = _loadavg()
    meta["seconds"] = time.perf_counter() - t_start
    say(1.0, "done")
    return PeerResult(settings, [rows[n] for n in settings.contenders], meta)


# ---------------------------------------------------------------- the report


def _commit(code: dict | None) -> str:
    if not code or not code.get("commit"):
        return ""
    return f", code at commit {code['commit'][:10]}" + (" with uncommitted changes" if code.get("dirty") else "")


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{100 * x:.3f} %"


def targets(result: PeerResult) -> list[str]:
    """The targets, each with its verdict and by how much."""
    rows = {r.name: r for r in result.rows if r.status == "ok"}
    out = []
    fast, floor = rows.get("aniso3d-fast"), rows.get(FLOOR)
    if fast and floor:
        ratio = fast.median_ms / floor.median_ms
        out.append(f"- aniso3d fast within {FLOOR_RATIO}x the bare GL_POINTS 2 px floor: "
                   f"{'PASS' if ratio <= FLOOR_RATIO else 'FAIL'}, {ratio:.2f}x "
                   f"({fast.median_ms:.0f} ms against {floor.median_ms:.0f} ms)")  # fmt: skip
    if fast:
        peers = [r for n, r in rows.items() if n in PEERS]
        if peers:
            slowest_ratio = min(p.median_ms / fast.median_ms for p in peers)
            closest = min(peers, key=lambda p: p.median_ms)
            out.append(f"- aniso3d fast ahead of every peer that ran ({', '.join(p.label for p in peers)}): "
                       f"{'PASS' if slowest_ratio > 1 else 'FAIL'}; the fastest peer, {closest.label}, takes "
                       f"{slowest_ratio:.2f}x aniso3d fast's time")  # fmt: skip
        skipped = [r.label for r in result.rows if r.status == "skipped" and r.name in PEERS]
        if skipped:
            out.append(f"  (not compared, could not run here: {', '.join(skipped)})")
    for name in ("aniso3d-fast", "aniso3d-high"):
        r = rows.get(name)
        if r and r.holes is not None:
            out.append(f"- {r.label}: fewer than {100 * HOLE_TARGET:.1f} % background pixels inside the truth's "
                       f"silhouette: {'PASS' if r.holes < HOLE_TARGET else 'FAIL'}, {_pct(r.holes)} "
                       f"(worst of {len(HOLE_VIEWS)} views)")  # fmt: skip
    return out


def table(result: PeerResult) -> list[str]:
    """The Markdown table, one line per contender."""
    floor = next((r for r in result.rows if r.name == FLOOR and r.status == "ok"), None)
    lines = ["| contender | point size | frame ms, median | min - max | x floor | set-up s | peak MiB | "
             "background in silhouette | in silhouette eroded 2 px | overhang |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]  # fmt: skip
    for r in result.rows:
        if r.status != "ok":
            lines.append(f"| {r.label} | skipped: {r.note} | | | | | | | | |")
            continue
        ms = 1000 * np.asarray(r.times)
        ratio = f"{r.median_ms / floor.median_ms:.2f}" if floor else "n/a"
        lines.append(f"| {r.label} | {r.point_size} | {r.median_ms:.1f} | {ms.min():.1f} - {ms.max():.1f} | {ratio} | "
                     f"{r.setup_s:.1f} | {r.peak_mib:.0f} | {_pct(r.holes)} | {_pct(r.holes_inner)} | "
                     f"{_pct(r.overhang)} |")  # fmt: skip
    return lines


def report(result: PeerResult, command: str) -> str:
    """docs/peers.md's measured part: the conditions, the table, the targets."""
    s, m = result.settings, result.meta

    def la(t):
        return " ".join(f"{x:.1f}" for x in t) if t else "n/a"

    lines = [
        f"`{command}`",
        "",
        f"Input: {m['input']}. Image {s.size[0]} x {s.size[1]}; {s.frames} timed frames per contender "
        f"(after one warm-up frame) in {s.rounds} interleaved rounds, the camera orbiting one degree per frame; "
        f"frame time = move the camera, draw, read the pixels back into NumPy (wall clock, in the contender's "
        f"own process). Peak MiB: the process's peak resident memory (interpreter, libraries, the cloud; "
        f"llvmpipe's buffers are host memory and count too). Equal splat size: aniso3d's median drawn disc "
        f"radius {m['splat_radius']:.3g} world units, {m['point_px']:g} px across at the object's centre, "
        f"given to the peers.",
        f"OpenGL: {m.get('gl_renderer', 'n/a')}. Machine load (1, 5, 15 min) {la(m['load_start'])} at the start, "
        f"{la(m['load_end'])} at the end, {m['cpus']} cores; {m['seconds']:.0f} s in all, started {m['started']}"
        f"{_commit(m.get('code'))}.",
        "",
        *table(result),
        "",
        "Targets:",
        "",
        *targets(result),
    ]
    notes = [f"- {r.label}: skipped, {r.note}" for r in result.rows if r.status == "skipped"]
    if notes:
        lines += ["", "Skipped:", "", *notes]
    return "\n".join(lines) + "\n"


def markers(result: PeerResult) -> tuple[str, str]:
    """The report's begin and end markers: one pair per input (the torus by
    its point count, a user's file by its name), so that runs at 1M and 100k
    points keep their own sections of one page."""
    key = result.settings.ply.name if result.settings.ply is not None else f"torus-{result.settings.points}"
    return f"<!-- bench peers:{key}:begin -->", f"<!-- bench peers:{key}:end -->"


def write_report(result: PeerResult, path: str | os.PathLike, command: str) -> Path:
    """Write the report into ``path`` between its markers (:func:`markers`;
    the rest of the page kept), appended when the page has no such section,
    the whole file when there is none; atomically."""
    from aniso3d.files import atomic_write

    begin, end = markers(result)
    body = f"{begin}\n{report(result, command)}{end}"
    p = Path(path)
    old = p.read_text() if p.exists() else ""
    if begin in old and end in old:
        text = old[: old.index(begin)] + body + old[old.index(end) + len(end):]
    elif old:
        text = old.rstrip("\n") + f"\n\n{body}\n"
    else:
        text = f"# aniso3d and its peers\n\n{body}\n"
    return atomic_write(p, text.encode())


def peers_command(argv: Sequence[str]) -> str:
    """The command line that repeats a run (printed atop its report)."""
    return shlex.join(["aniso3d", "bench", "peers", *argv])


if __name__ == "__main__":
    sys.exit(worker_main(sys.argv[1], sys.argv[2]))
