"""Renderer (c): oriented points drawn as splats, the paper's method (section 3.2).

Each point is a small flat shape in its tangent plane, sized from its area:

- ``square`` (the paper's): side ``sqrt(area) * size_factor``;
- ``disc``: radius ``sqrt(area / pi) * size_factor``;
- ``ellipse``: the disc stretched by ``sqrt(aspect)`` along the point's first
  tangent axis and shrunk by as much along the second (same area). A
  :class:`~aniso3d.build.points.PointCloud` carries no anisotropy, so the axis is a
  fixed function of the normal (:func:`~aniso3d.grid.tangent_frame`, the convention
  ``texture.to_points`` spreads points with) and ``aspect`` is an option; the
  ellipse is a well-defined shape, not a view-dependent stretch.

``size_factor`` > 1 makes neighbouring splats overlap so the surface closes;
the defaults (:func:`default_size_factor`: 1.3 for squares, 1.25 for discs,
1.40 for ellipses of aspect 2) come from measuring holes and overhang against
the supersampled polygon model.

Drawing is perspective-exact: every fragment intersects its pixel's eye ray
with the splat's plane (through the screen-to-plane homography, so a grazing
ray needs no division by the ray-plane cosine), discards what falls outside
the shape, and writes the true depth, so splats foreshorten and occlude like
polygons. In "fast" and "blend" quality the pixel holding a splat's projected
centre is always drawn, so a splat smaller than a pixel (or seen edge-on)
never vanishes; a point of zero area draws nothing. Most splats are point
sprites (one vertex, the cheapest primitive a software rasteriser has);
splats wider than the largest sprite (255 px on llvmpipe) go through a
geometry shader instead, for the blocks of points where the CPU finds that
possible.

Points are uploaded once, positions relative to the cloud's centre (float64
subtraction, then float32), and the shaders never form eye-relative positions
in float32 either (see splat.vert), so a far-off cloud, or a camera far away
with a narrow field of view, keeps its precision.

``quality="fast"`` (default) is two passes: the splats write each pixel's
nearest point id and exact depth, then a full-screen pass shades each pixel's
visible splat once with ``shade()`` (view vector along the pixel's ray, i.e.
from the intersection point to the eye). That is the colour forward shading
would give, without shading the hidden layers of a dense cloud, which is
most of the work on a software rasteriser.

``quality="high"`` is coverage-aware (anti-aliased), for accuracy at every
distance and above all where a voxel covers a pixel or less. A splat adds
the fraction ``c`` of each pixel it covers: its shape convolved with the
pixel's box filter (the ground truth's) and sampled at the pixel centre. A
splat well below a pixel is drawn as a filtered box of its *true* projected
area (``sqrt(area)`` a side, no size factor), so the coverages it leaves in
the pixels sum to exactly that area wherever it lies: no splat takes a whole
pixel, as in "fast", and none vanishes. A resolved splat (a few pixels and
more) is its exact perspective shape with the size factor, each pair of
edges filtered across its distance in pixels; between the two regimes
(:data:`AA_REGIME`) the two blend. Three passes: visibility (as "blend",
each pixel's nearest pushed depth, kept as a linear depth); accumulation of
``(colour c, c)`` into :data:`AA_SLABS` depth layers behind that depth
(the first holds the visible surface, the others are thicker and thicker
by :data:`AA_GROWTH`, and a fragment is shared between the two it lies
between); and compositing front to back, like the volume renderer's: the
visible surface's splats tile it (coverage added, at most what is left of
the pixel), the splats of a deep layer hide each other at random (coverage
``1 - exp(-sum)``; resolved ones there still tile), colour the
coverage-weighted mean. Splats of one surface shade once at their centre
when sub-pixel, per pixel when resolved. The result is composited over
what the target holds, or under it where that is nearer, so separately
drawn clouds combine in either order. Measured on the default tree against
8 x 8 supersampled polygons (docs/splat_aa.md): 30 to 34 dB PSNR at 512 x
512 from a frame-filling camera to 18 times as far, against 16 to 20 dB for
"fast" and "blend" and 24 to 30 dB for the volume renderer, for 1.2 to 1.5
times the frame time of "blend" (3 to 4 times "fast").

``quality="blend"`` (the earlier "high") is the classic three passes:
visibility (splats pushed back by ``push`` times their size), additive
accumulation of shaded colour times a Gaussian weight, and weight, into a
float texture (fragments behind the visibility depth are rejected before
shading), and normalisation. It blends overlapping splats of one surface
into a continuous one; coverage is on or off per pixel, as in "fast".

:func:`splat_coverage_np` is the slow, obvious twin of the GPU coverage test.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import moderngl
import numpy as np

from aniso3d.build.points import PointCloud
from aniso3d.build.pyramid import LodPoints
from aniso3d.errors import InputError, ResourceError
from aniso3d.grid import ranges, tangent_frame
from aniso3d.render.context import GLContext
from aniso3d.render.frame import FrameView
from aniso3d.render.select import select_voxels

SHAPES = ("square", "disc", "ellipse")
QUALITIES = ("fast", "high", "blend")

#: Major over minor axis of ``ellipse`` splats.
DEFAULT_ASPECT = 2.0
#: Default linear scale of a square over its area-equivalent side, measured
#: against the 4x4-supersampled polygons (sphere, cube, plane at 60 degrees;
#: textures of 16, 32 and 64 voxels): at 1.0 the sphere shows the back of its
#: far side through 1.6-6 % of its interior (points of curved surfaces are not
#: grid-aligned); holes fall to 0.5-1.5 % at 1.15 and 0.04-0.15 % at 1.3, while
#: splats overhanging the cube's edges spoil 0.1-0.5 % of its interior at 1.15,
#: 0.2-1.0 % at 1.3 and 0.3-1.6 % at 1.45. Holes show more, so 1.3. (The
#: image-wide mean colour error, dominated by silhouettes, is lowest at 1.15.)
SQUARE_SIZE_FACTOR = 1.3
#: Visibility push-back of ``quality="high"`` and ``"blend"``, in units of the
#: splat's larger half-axis, along the view axis: splats of the front surface
#: within this depth of the nearest one blend; farther ones are hidden
#: ("blend") or go to the layers behind ("high").
DEFAULT_PUSH = 1.0
#: Points per block of the CPU's large-splat test (points are Morton-sorted, so
#: a block is a compact piece of the cloud).
BLOCK = 4096
#: Accumulation texture type of ``quality="blend"``: half floats change at most
#: one pixel in a hundred by one grey level against float32 (tree, sphere),
#: for half the memory (RGBA16F; 32 MB at 2048 x 2048).
ACCUM_DTYPE = "f2"
#: Points per row of the attribute texture (two texels each).
ATTRIB_PER_ROW = 2048
#: Pixel filter of ``quality="high"`` (shaders/splat_filter.glsl): 0 the box
#: of one pixel, the ground truth's (supersampling averages each pixel's
#: samples); 1 the tent of radius 1 px (bilinear weights); 2 the quadratic
#: B-spline of radius 1.5 px. All three are B-splines, so a splat keeps its
#: projected area wherever it lies on the pixel grid. Measured on the default
#: tree at 512 x 512 against 8 x 8 supersampled polygons at the cameras of
#: demos/bench_splat_aa.py (distance scales 1 to 18), PSNR in the tree's box:
#: the box 30.2 to 34.1 dB; the tent 1.1-2.9 dB and the B-spline 2.1-4.1 dB
#: lower (blurrier than the truth, and more coverage spread past silhouettes).
AA_FILTER = 0
#: Depth layers of ``quality="high"``: the visible one and AA_SLABS - 1 behind
#: it (at most 7; at most 4 from AA_DEEP on). Measured as above (mean PSNR over
#: the five cameras): 4 layers growing by 4, 32.5 dB; 6 growing by 2, 32.6 dB
#: for about 10 % more time; 3 growing by 8, 32.4 dB; 2 (first deep layer 1)
#: 32.5 dB, but see AA_DEEP.
AA_SLABS = 4
#: Each layer behind the visible one is this many times as thick as the one
#: before; the first is ``push`` times a typical (median) splat's larger
#: half-axis.
AA_GROWTH = 4.0
#: First layer whose splats are taken to hide each other at random (coverage
#: 1 - exp(-sum), resolved splats excepted) rather than to tile one surface;
#: the layers before fill the pixel additively. Measured: with 1, a surface
#: seen at a grazing angle (a sphere's rim) spans the boundary and its
#: coverage flickers with the view (0.7 % of pixels of a telephoto sphere change
#: by more than 2 levels between 1e4 and 1e7 units away; 0.1 % with 2); with 3
#: the tree's mean PSNR drops by 0.9 dB (its crown is no surface). So 2.
AA_DEEP = 2
#: A splat whose true projected area is below AA_REGIME[0]^2 pixels is drawn as
#: a filtered box of its true area; above AA_REGIME[1]^2, as its exact shape
#: with the size factor (which closes the gaps between resolved splats); a
#: smooth blend between. Measured: (0.5, 2) and (2, 5) are 0.75 and 0.1 dB
#: below (1, 3) at the nearest camera, equal from the third on.
AA_REGIME = (1.0, 3.0)
#: In quality "high" a splat whose pixel box (with the filter's reach) is wider
#: than this many pixels is shaded per pixel in the visible layer (through the
#: geometry path); smaller ones take the colour shaded once at their centre,
#: whose view vector differs from their pixels' by under 0.7 degrees (40
#: degree field of view, 1024 pixels). Shading code in the sprites' shader
#: cost 70 ms per 1024 x 1024 frame of the tree on llvmpipe even where no
#: pixel ran it; at 8 px, every block of that frame took the (slower)
#: geometry path.
AA_SHADE_BOX = 32.0
#: Texture type of the layers: AA_SLABS + 1 targets, 80 bytes per pixel
#: (80 MiB at 1024 x 1024). Half floats drop small coverages added to large
#: sums; that happens to help where the crown's fringe is over-covered (0.5
#: and 1.6 dB higher PSNR at the two farthest cameras), which is no reason to
#: rely on it.
AA_DTYPE = "f4"

_ATTRIBUTES = (("in_position", 3), ("in_normal", 3), ("in_size", 1), ("in_kd", 3), ("in_spec", 2))
_FLOATS = sum(k for _, k in _ATTRIBUTES)


# --------------------------------------------------------------------- geometry


def default_size_factor(shape: str, aspect: float = DEFAULT_ASPECT) -> float:
    """The ``size_factor`` used when none is given.

    A point stands for a patch of about a square of its area. A disc or an
    ellipse of aspect A centred on that square covers it when its linear
    scale is ``sqrt(pi (A + 1/A) / 4)``: sqrt(pi/2) = 1.25 for discs, 1.40 for
    the default ellipse; the measurements that chose :data:`SQUARE_SIZE_FACTOR`
    agree (lowest colour error at 1.25 for discs and 1.4 for ellipses of
    aspect 2; holes plus edge overhang lowest at 1.25 for discs).
    """
    if shape == "square":
        return SQUARE_SIZE_FACTOR
    a = 1.0 if shape == "disc" else float(aspect)
    return math.sqrt(math.pi * (a + 1.0 / a) / 4.0)


def shape_extent(
    shape: str, size_factor: float, aspect: float = DEFAULT_ASPECT
) -> tuple[float, float]:
    """Half-axes (along t, along b) of a splat per unit of ``sqrt(area)``."""
    if shape == "square":
        return 0.5 * size_factor, 0.5 * size_factor
    r = size_factor / math.sqrt(math.pi)
    if shape == "disc":
        return r, r
    s = math.sqrt(aspect)
    return r * s, r / s


def splat_coverage_np(
    position,
    normal,
    area: float,
    view: FrameView,
    shape: str = "square",
    size_factor: float | None = None,
    aspect: float = DEFAULT_ASPECT,
    margin: float = 0.0,
) -> np.ndarray:
    """(H, W) bool: the pixels (row 0 at the top) one splat covers, in float64.

    The reference for splat.vert/splat.frag: the ray through each pixel centre
    meets the splat's plane at view depth t in [near, far] inside the shape;
    the pixel holding the projected centre is covered too. ``margin`` grows
    (> 0) or shrinks (< 0) the shape in its normalised coordinates, to tell
    pixels that are clearly in or out from those on the edge. A splat of zero
    area covers nothing.
    """
    if not area > 0:
        return np.zeros(view.size[::-1], bool)
    size_factor = default_size_factor(shape, aspect) if size_factor is None else size_factor
    cam = view.camera
    w, h = view.size
    e = np.asarray(cam.position, np.float64)
    c = np.asarray(position, np.float64) - e
    n = np.asarray(normal, np.float64)
    n = n / np.linalg.norm(n)
    t_ax, b_ax = tangent_frame(n[None])
    hu, hv = (x * math.sqrt(area) for x in shape_extent(shape, size_factor, aspect))
    d = cam.ray_directions((w, h))
    d = d / (d @ cam.forward)[..., None]  # unit component along the view axis
    denom = d @ n
    ok = np.abs(denom) > 1e-9 * np.linalg.norm(d, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(ok, float(n @ c) / np.where(ok, denom, 1.0), 0.0)
    q = t[..., None] * d - c
    u = (q @ t_ax[0]) / hu
    v = (q @ b_ax[0]) / hv
    lim = (1.0 + margin) ** 2
    inside = (
        u * u + v * v <= lim
        if shape != "square"
        else np.maximum(np.abs(u), np.abs(v)) <= 1.0 + margin
    )
    cover = ok & inside & (t >= view.near) & (t <= view.far)
    depth = float(c @ cam.forward)
    if view.near <= depth <= view.far:
        r, up, f = cam.basis()
        tan = math.tan(math.radians(cam.fov) / 2)
        x = (c @ r) / depth / (tan * view.aspect)
        y = (c @ up) / depth / tan
        px, py = (x * 0.5 + 0.5) * w, (y * 0.5 + 0.5) * h
        if 0 <= px < w and 0 <= py < h:
            cover[h - 1 - int(math.floor(py)), int(math.floor(px))] = True
    return cover


def _filter_radius() -> float:
    """Reach of the coverage-aware pixel filter, pixels (splat_filter.glsl)."""
    return {0: 0.5, 1: 1.0, 2: 1.5}[AA_FILTER]


def morton_order(points: np.ndarray) -> np.ndarray:
    """Indices sorting (N, 3) points along a Z-order curve (10 bits per axis),
    so consecutive points are close in space."""
    p = np.asarray(points, np.float64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    q = ((p - lo) / np.maximum(hi - lo, 1e-300) * 1023.0).astype(np.uint64)
    code = np.zeros(len(p), np.uint64)
    for bit in range(10):
        for axis in range(3):
            code |= ((q[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    return np.argsort(code, kind="stable")


# ------------------------------------------------------------------------ upload


@dataclass(eq=False)
class GPUPoints:
    """A point cloud uploaded once: 12 float32 per point, positions relative to
    ``origin``, Morton-sorted, in blocks of :data:`BLOCK` points; and the
    per-point shading attributes again as a texture (two RGBA32F texels per
    point, :data:`ATTRIB_PER_ROW` points per row) for the deferred shading pass.

    ``block_lo``/``block_hi`` (B, 3) are the blocks' position bounds in the
    local frame and ``block_size`` (B,) their largest ``sqrt(area)``.
    """

    vbo: moderngl.Buffer
    attrib: moderngl.Texture
    origin: np.ndarray
    bounds: np.ndarray
    n_points: int
    nbytes: int
    block_start: np.ndarray
    block_count: np.ndarray
    block_lo: np.ndarray
    block_hi: np.ndarray
    block_size: np.ndarray
    vaos: dict = field(default_factory=dict)
    #: Median ``sqrt(area)`` of the points (of level 0 for a pyramid).
    typical_size: float = 0.0


@dataclass(eq=False)
class GPULodPoints(GPUPoints):
    """Every level of a pyramid's points (:class:`~aniso3d.build.pyramid.LodPoints`)
    uploaded once, one after the other in one buffer (finest level first),
    each level's voxels in Morton order of their grid cells with every voxel's
    points contiguous. A frame draws only the voxels
    :func:`~aniso3d.render.select.select_voxels` chooses, through an index buffer
    rewritten per frame (4 bytes per point drawn), in ascending order.

    ``bounds`` (and so the clip range) covers every level's points, whatever a
    frame selects. Per level l: ``level_first[l]`` is its first point in the
    buffer, ``rank[l]`` (M_l,) each voxel's place in Morton order and
    ``run_first[l]``, ``run_count[l]`` (M_l,) the buffer range of the voxel
    of each rank. ``last_stats`` is the last frame's selection (see
    :meth:`SplatRenderer.draw`).
    """

    lod: LodPoints | None = None
    level_first: np.ndarray | None = None
    rank: list = field(default_factory=list)
    run_first: list = field(default_factory=list)
    run_count: list = field(default_factory=list)
    level_bounds: np.ndarray | None = None  # (L, 2, 3) each level's point bounds
    level_size: np.ndarray | None = None  # (L,) each level's largest sqrt(area)
    index_buffer: moderngl.Buffer | None = None
    indexed_vaos: dict = field(default_factory=dict)
    drawn: np.ndarray | None = None  # this frame's indices (sorted uint32)
    frame_box: tuple | None = None  # (bounds, largest size) of the levels drawn this frame
    last_stats: dict = field(default_factory=dict)


@dataclass(eq=False)
class _Targets:
    """Offscreen buffers for one framebuffer size, made on first use: the depth
    texture (geometry pass of "fast", visibility pass of "high" and "blend"),
    the point ids (R32UI, "fast"), the accumulation texture ("blend") and the
    layers of "high" (``slabs``: :data:`AA_SLABS` RGBA textures and one for the
    deep layers' resolved coverage)."""

    depth: moderngl.Texture
    visibility: moderngl.Framebuffer
    ids: moderngl.Texture | None = None
    geometry: moderngl.Framebuffer | None = None
    accum: moderngl.Texture | None = None
    accumulate: moderngl.Framebuffer | None = None
    slabs: tuple = ()
    layered: moderngl.Framebuffer | None = None

    def objects(self) -> tuple:
        return (self.geometry, self.accumulate, self.layered, self.visibility, self.ids,
                self.accum, *self.slabs, self.depth)  # fmt: skip


# ---------------------------------------------------------------------- renderer


class SplatRenderer:
    """Draws a :class:`~aniso3d.build.points.PointCloud` as perspective-exact splats.

    ``quality="fast"``: one geometry pass writes each pixel's nearest splat
    (exact depth, point id), then one full-screen pass shades it with
    ``shade()``. ``quality="high"``: coverage-aware, visibility, accumulation
    into depth layers, compositing. ``quality="blend"``: visibility,
    accumulation, normalisation.

    ``max_sprite`` (pixels) is the widest splat drawn as a point sprite; wider
    ones take the geometry-shader path. It defaults to the context's largest
    point size; set it to 0 to send every splat through the geometry path.
    """

    method = "splat"

    def __init__(self, gl: GLContext):
        self.gl = gl
        info = gl.ctx.info
        self.max_sprite = float(info.get("GL_POINT_SIZE_RANGE", (1.0, 64.0))[1])
        self._targets: dict[tuple[int, int], _Targets] = {}
        self._required: dict[int, frozenset[str]] = {}
        self._screen_vaos: dict[int, moderngl.VertexArray] = {}
        #: The last pyramid frame's selection statistics (see :meth:`select`).
        self.last_lod_stats: dict | None = None
        # Compile the default variant now so shader errors surface at once.
        self._program("geometry", "square", sprite=True)

    # ------------------------------------------------------------ programs

    def _program(self, kind: str, shape: str, sprite: bool, aa: bool = False) -> moderngl.Program:
        """The splat program of a pass (geometry, visibility, accumulate, floor);
        ``aa``: the coverage-aware variant of visibility and accumulate."""
        defines: dict[str, object] = {"ROUND": int(shape != "square")}
        if kind == "floor":
            return self.gl.program("splat.vert", "splat_floor.frag", defines=defines)
        defines["PASS"] = {"geometry": 0, "visibility": 1, "accumulate": 2}[kind]
        if aa:
            defines.update(
                AA=1, SLABS=AA_SLABS, DEEP=AA_DEEP, FILTER=AA_FILTER, GROWTH=f"{AA_GROWTH:.6f}"
            )
        if sprite:
            return self.gl.program("splat.vert", "splat.frag", defines=defines)
        defines["GEOMETRY_PATH"] = 1
        return self.gl.program("splat.vert", "splat.frag", geometry="splat.geom", defines=defines)

    def _bind(self, prog: moderngl.Program, values: dict[str, object]) -> None:
        """Set uniforms; every active uniform of ``prog`` must be given (a
        misspelt key leaves a real uniform unset and is caught here)."""
        required = self._required.get(id(prog))
        if required is None:
            required = frozenset(n for n in prog if isinstance(prog[n], moderngl.Uniform))
            self._required[id(prog)] = required
        missing = required - values.keys()
        if missing:
            raise ResourceError(f"splat shader uniforms not set: {sorted(missing)}")
        for name in required:
            prog[name].value = values[name]

    def _vao(
        self, handle: GPUPoints, prog: moderngl.Program, indexed: bool = False
    ) -> moderngl.VertexArray:
        """The points' vertex array for ``prog``; ``indexed``: through the
        handle's index buffer (a pyramid upload)."""
        cache = handle.indexed_vaos if indexed else handle.vaos
        vao = cache.get(id(prog))
        if vao is None:
            if "in_position" not in prog:
                raise ResourceError("splat vertex shader has no active in_position attribute")
            fmt, names = [], []
            for name, k in _ATTRIBUTES:
                if name in prog:  # attributes a variant does not read are skipped
                    fmt.append(f"{k}f")
                    names.append(name)
                else:
                    fmt.append(f"{4 * k}x")
            content = [(handle.vbo, " ".join(fmt), *names)]
            if indexed:
                vao = self.gl.ctx.vertex_array(
                    prog, content, index_buffer=handle.index_buffer, index_element_size=4
                )
            else:
                vao = self.gl.ctx.vertex_array(prog, content)
            vao = cache[id(prog)] = self.gl.track(vao)
        return vao

    def _screen(
        self, fragment: str, aa: bool = False
    ) -> tuple[moderngl.Program, moderngl.VertexArray]:
        """A full-screen pass: one triangle, no vertex buffer (``aa``: the
        compositing pass of quality "high", with its defines)."""
        defines = {"SLABS": AA_SLABS, "DEEP": AA_DEEP} if aa else None
        prog = self.gl.program("splat_resolve.vert", fragment, defines=defines)
        vao = self._screen_vaos.get(id(prog))
        if vao is None:
            vao = self._screen_vaos[id(prog)] = self.gl.track(self.gl.ctx.vertex_array(prog, []))
        return prog, vao

    # -------------------------------------------------------------- upload

    def upload(self, cloud: PointCloud | LodPoints) -> GPUPoints:
        """Upload ``cloud`` once: float64 positions minus the cloud's centre,
        then float32, so far-off clouds keep their precision.

        A :class:`~aniso3d.build.pyramid.LodPoints` uploads every level of its pyramid
        (:class:`GPULodPoints`); :meth:`draw` then selects per frame."""
        if isinstance(cloud, LodPoints):
            return self._upload_lod(cloud)
        if not isinstance(cloud, PointCloud):
            raise InputError(f"the splat renderer draws a PointCloud, got {type(cloud).__name__}")
        n = len(cloud)
        if n == 0:
            raise InputError("cannot draw an empty point cloud (it has no points)")
        bounds = cloud.bounds
        origin = 0.5 * (bounds[0] + bounds[1])
        order = morton_order(cloud.positions - origin)
        arrays = (cloud.positions, cloud.normals, cloud.areas, cloud.kd, cloud.ks, cloud.shininess)
        return self._upload_arrays(GPUPoints, arrays, order, bounds, origin)

    def _upload_arrays(self, cls, arrays, order, bounds, origin, **extra) -> GPUPoints:
        """Upload the points ``order`` of ``arrays`` (positions, normals,
        areas, kd, ks, shininess), in that order, relative to ``origin``."""
        positions, normals, areas, kd, ks, shininess = arrays
        n = len(order)
        rows = -(-n // ATTRIB_PER_ROW)
        if rows > self.gl.max_texture_size:
            raise ResourceError(
                f"{n} points need a {2 * ATTRIB_PER_ROW}x{rows} attribute texture, above this "
                f"OpenGL's limit of {self.gl.max_texture_size}; draw the cloud in parts"
            )
        local = positions[order] - origin
        size = np.sqrt(areas[order])
        data = np.empty((n, _FLOATS), dtype=np.float32)
        data[:, 0:3] = local
        data[:, 3:6] = normals[order]
        data[:, 6] = size
        data[:, 7:10] = kd[order]
        data[:, 10] = ks[order]
        data[:, 11] = shininess[order]
        attrib = np.zeros((rows * ATTRIB_PER_ROW, 8), dtype=np.float32)
        attrib[:n, 0:3] = data[:, 3:6]
        attrib[:n, 3] = data[:, 10]
        attrib[:n, 4:7] = data[:, 7:10]
        attrib[:n, 7] = data[:, 11]
        ctx = self.gl.ctx
        vbo = self.gl.track(ctx.buffer(data.tobytes()))
        tex = self.gl.track(
            ctx.texture((2 * ATTRIB_PER_ROW, rows), 4, attrib.tobytes(), dtype="f4")
        )
        tex.filter = moderngl.NEAREST, moderngl.NEAREST
        start = np.arange(0, n, BLOCK)
        count = np.minimum(BLOCK, n - start)
        return cls(
            vbo=vbo,
            attrib=tex,
            origin=origin,
            bounds=bounds,
            n_points=n,
            nbytes=data.nbytes + attrib.nbytes,
            block_start=start,
            block_count=count,
            block_lo=np.minimum.reduceat(local, start, axis=0),
            block_hi=np.maximum.reduceat(local, start, axis=0),
            block_size=np.maximum.reduceat(size, start),
            typical_size=float(np.median(size)),
            **extra,
        )

    def _upload_lod(self, lod: LodPoints) -> GPULodPoints:
        """Every level's points in one buffer: level by level, finest first,
        voxels in Morton order of their cells, a voxel's points together."""
        pyr = lod.pyramid
        clouds, parts, rank, run_first, run_count, level_first = [], [], [], [], [], []
        base = 0
        for lvl in range(len(pyr)):
            cloud, off = lod.level_cloud(lvl)
            m = pyr[lvl].n_voxels
            vorder = morton_order(pyr[lvl].coords) if m > 1 else np.arange(m)
            counts = (off[vorder + 1] - off[vorder]).astype(np.int64)
            r = np.empty(m, dtype=np.int64)
            r[vorder] = np.arange(m)
            clouds.append(cloud)
            parts.append(base + ranges(off[vorder], off[vorder + 1]))
            rank.append(r)
            run_first.append(base + np.cumsum(counts) - counts)
            run_count.append(counts)
            level_first.append(base)
            base += len(cloud)
        if len(clouds[0]) == 0:
            raise InputError("cannot draw an empty point cloud (it has no points)")
        if base >= 2**32:
            raise ResourceError(f"{base} points in all levels are too many for 32-bit indices")
        bounds = np.stack([
            np.min([c.bounds[0] for c in clouds if len(c)], axis=0),
            np.max([c.bounds[1] for c in clouds if len(c)], axis=0),
        ])  # fmt: skip
        b0 = clouds[0].bounds  # level 0 keeps the origin a plain upload of its points has
        origin = 0.5 * (b0[0] + b0[1])
        arrays = tuple(
            np.concatenate([getattr(c, name) for c in clouds])
            for name in ("positions", "normals", "areas", "kd", "ks", "shininess")
        )
        empty = np.full((2, 3), np.nan)
        handle = self._upload_arrays(
            GPULodPoints, arrays, np.concatenate(parts), bounds, origin,
            lod=lod, level_first=np.asarray(level_first, dtype=np.int64),
            rank=rank, run_first=run_first, run_count=run_count,
            level_bounds=np.stack([c.bounds if len(c) else empty for c in clouds]),
            level_size=np.array([np.sqrt(c.areas.max()) if len(c) else 0.0 for c in clouds]),
        )  # fmt: skip
        handle.index_buffer = self.gl.track(self.gl.ctx.buffer(reserve=4 * max(len(clouds[0]), 1)))
        handle.typical_size = float(np.median(np.sqrt(clouds[0].areas)))
        return handle

    def select(self, handle: GPULodPoints, view: FrameView, pixel_error: float = 1.0) -> dict:
        """This frame's points of a pyramid upload: :func:`~aniso3d.render.select.select_voxels`
        for the view's camera and framebuffer size (clip range ``view.near``
        to ``view.far``), their buffer indices written to the index buffer.
        Returns (and keeps as ``handle.last_stats`` and
        :attr:`last_lod_stats`) the frame's statistics: ``points`` drawn,
        ``points_per_level``, ``voxels_per_level``, ``culled`` (voxels found
        outside the view, their subtrees skipped), ``culled_per_level``,
        ``total_points`` (uploaded, all levels), ``select_ms`` (the voxel
        walk), ``index_ms`` (indices made and written) and ``selection_ms``
        (both)."""
        pyr = handle.lod.pyramid
        t0 = time.perf_counter()
        sel = select_voxels(pyr, view.camera, view.size, pixel_error, near=view.near, far=view.far)
        t1 = time.perf_counter()
        firsts, counts, per_level = [], [], []
        for lvl, vox in enumerate(sel.voxels):
            if len(vox) == 0:
                per_level.append(0)
                continue
            if len(vox) == len(handle.rank[lvl]):  # the whole level (a near view): one run
                c = np.array([handle.run_count[lvl].sum()])
                firsts.append(handle.level_first[lvl : lvl + 1])
            else:
                r = np.sort(handle.rank[lvl][vox])
                c = handle.run_count[lvl][r]
                firsts.append(handle.run_first[lvl][r])
            counts.append(c)
            per_level.append(int(c.sum()))
        if firsts:
            f, c = np.concatenate(firsts), np.concatenate(counts)
            idx = ranges(f, f + c).astype(np.uint32)
        else:
            idx = np.zeros(0, dtype=np.uint32)
        buf = handle.index_buffer
        if idx.nbytes > buf.size:
            buf.orphan(max(idx.nbytes, 2 * buf.size))
        if idx.nbytes:
            buf.write(idx)
        handle.drawn = idx
        used = [lvl for lvl, n in enumerate(per_level) if n]
        if used:
            lb = handle.level_bounds[used]
            box = np.stack([lb[:, 0].min(axis=0), lb[:, 1].max(axis=0)])
            handle.frame_box = (box, float(handle.level_size[used].max()))
        else:
            handle.frame_box = None
        t2 = time.perf_counter()
        stats = {
            "points": int(len(idx)),
            "points_per_level": per_level,
            "voxels_per_level": [int(len(v)) for v in sel.voxels],
            "culled": int(sum(sel.culled)),
            "culled_per_level": [int(c) for c in sel.culled],
            "total_points": int(handle.n_points),
            "level0_points": int(handle.level_first[1] if len(pyr) > 1 else handle.n_points),
            "pixel_error": float(pixel_error),
            "select_ms": 1000.0 * (t1 - t0),
            "index_ms": 1000.0 * (t2 - t1),
            "selection_ms": 1000.0 * (t2 - t0),
        }
        handle.last_stats = self.last_lod_stats = stats
        return stats

    def release(self, handle: GPUPoints) -> None:
        self.gl.free(*handle.vaos.values(), handle.vbo, handle.attrib)
        handle.vaos.clear()
        if isinstance(handle, GPULodPoints):
            self.gl.free(*handle.indexed_vaos.values(), handle.index_buffer)
            handle.indexed_vaos.clear()

    def release_all(self) -> None:
        """Free the offscreen buffers and full-screen pass objects."""
        for tg in self._targets.values():
            self.gl.free(*tg.objects())
        self._targets.clear()
        self.gl.free(*self._screen_vaos.values())
        self._screen_vaos.clear()

    # ------------------------------------------------------------- options

    @staticmethod
    def options(
        splat: str = "square",
        quality: str = "fast",
        size_factor: float | None = None,
        aspect: float = DEFAULT_ASPECT,
        push: float = DEFAULT_PUSH,
        **unknown,
    ) -> dict[str, object]:
        """Validated draw options (see the module docstring)."""
        if unknown:
            raise InputError(
                f"unknown splat option(s) {sorted(unknown)}; "
                "known: splat, quality, size_factor, aspect, push"
            )
        if splat not in SHAPES:
            raise InputError(f"unknown splat shape {splat!r}; choose one of {', '.join(SHAPES)}")
        if quality not in QUALITIES:
            raise InputError(
                f"unknown splat quality {quality!r}; choose one of {', '.join(QUALITIES)}"
            )

        def number(name, value, minimum, strict):
            if isinstance(value, bool) or not isinstance(
                value, (int, float, np.integer, np.floating)
            ):
                raise InputError(f"splat option {name} must be a number, got {value!r}")
            value = float(value)
            if not math.isfinite(value) or value < minimum or (strict and value == minimum):
                bound = f"{'>' if strict else '>='} {minimum:g}"
                raise InputError(
                    f"splat option {name} must be a finite number {bound}, got {value!r}"
                )
            return value

        aspect = number("aspect (major over minor axis)", aspect, 1, False)
        if size_factor is None:
            size_factor = default_size_factor(splat, aspect)
        return {
            "splat": splat,
            "quality": quality,
            "size_factor": number("size_factor", size_factor, 0, True),
            "aspect": aspect,
            "push": number("push", push, 0, False),
        }

    # -------------------------------------------------------------- frames

    def _uniforms(self, handle: GPUPoints, view: FrameView, opts: dict) -> dict[str, object]:
        cam = view.camera
        r, u, f = cam.basis()
        tan = math.tan(math.radians(cam.fov) / 2)
        rot = np.stack([r, u, -f])
        ray = np.stack([f, r * tan * view.aspect, u * tan], axis=1)  # columns f, R, U
        near, far = float(view.near), float(view.far)
        # float64 here, so the shaders never form eye-relative positions (see
        # splat.vert): t0, the view depth of the local origin, and q0, the foot
        # of the origin on the view axis, in the local frame.
        eye = np.asarray(view.eye_local(handle.origin), np.float64)
        t0 = -float(eye @ f)
        q0 = eye + t0 * f
        return {
            "u_q0": tuple(float(x) for x in q0),
            "u_t0": t0,
            "u_view_rot": tuple(float(x) for x in rot.T.ravel()),  # column-major
            "u_ray": tuple(float(x) for x in ray.T.ravel()),
            "u_proj_scale": (1.0 / (tan * view.aspect), 1.0 / tan),
            "u_viewport": (float(view.size[0]), float(view.size[1])),
            "u_near": near,
            "u_far": far,
            "u_extent": shape_extent(opts["splat"], opts["size_factor"], opts["aspect"]),
            "u_max_sprite": self.max_sprite,
            "u_push": opts["push"],
            "u_depth": (far / (far - near), t0 - near),
            "u_srange": (near - t0, far - t0),
            "u_range": far - near,
            "u_size_factor": opts["size_factor"],
            "u_regime": tuple(float(x) for x in AA_REGIME),
            "u_slab_min": handle.typical_size
            * max(shape_extent(opts["splat"], opts["size_factor"], opts["aspect"])),
            "u_background": tuple(float(x) for x in view.lighting.background),
            **view.lighting.uniforms(),
        }

    def large_blocks(
        self, handle: GPUPoints, view: FrameView, opts: dict, limit: float | None = None
    ) -> list[tuple[int, int]]:
        """(first, count) ranges of points that may hold a splat wider than
        ``limit`` pixels (default :attr:`max_sprite`) in this frame: a
        conservative bound per block."""
        limit = self.max_sprite if limit is None else limit
        w, h = view.size
        # Boxes hold the centre's pixel, or with AA the filter's reach, besides the shape.
        slack = 2.0 + (2.0 * _filter_radius() + 1.0 if opts["quality"] == "high" else 0.0)
        if max(w, h) + slack <= limit:  # boxes are clamped to the viewport
            return []
        cam = view.camera
        r, u, f = cam.basis()
        rot = np.stack([r, u, -f])
        eye = np.asarray(view.eye_local(handle.origin))
        pick = np.array([[i & 1, i & 2, i & 4] for i in range(8)], bool)  # (8, 3) corner selectors
        corners = np.where(
            pick[None], handle.block_hi[:, None], handle.block_lo[:, None]
        )  # (B, 8, 3)
        e = (corners - eye) @ rot.T
        radius = handle.block_size * math.hypot(
            *shape_extent(opts["splat"], opts["size_factor"], opts["aspect"])
        )
        depth_lo = -e[..., 2].max(axis=1) - radius
        depth_hi = -e[..., 2].min(axis=1) + radius
        zlo = np.maximum(depth_lo, view.near)
        tan = math.tan(math.radians(cam.fov) / 2)
        wide = np.zeros(len(radius), bool)
        # Over a ball of radius rho clipped to depth >= zlo, x/z varies by at
        # most 2 rho (1/zlo + max|x| / zlo^2) (mean value theorem).
        for axis, scale, pixels in ((0, 1.0 / (tan * view.aspect), w), (1, 1.0 / tan, h)):
            lateral = np.abs(e[..., axis]).max(axis=1) + radius
            extent = scale * 2.0 * radius * (1.0 / zlo + lateral / zlo**2) * 0.5 * pixels
            wide |= extent + slack > limit
        wide &= depth_hi >= view.near
        ranges: list[tuple[int, int]] = []
        for i in np.flatnonzero(wide):
            s, c = int(handle.block_start[i]), int(handle.block_count[i])
            if ranges and ranges[-1][0] + ranges[-1][1] == s:
                ranges[-1] = (ranges[-1][0], ranges[-1][1] + c)
            else:
                ranges.append((s, c))
        return ranges

    def screen_box(
        self, handle: GPUPoints, view: FrameView, opts: dict
    ) -> tuple[int, int, int, int] | None:
        """(x, y, width, height) pixels holding every splat of the cloud (its
        bounds grown by the largest splat, projected), or None when the box
        would be the whole viewport or the cloud reaches behind the near plane.
        Clears and full-screen passes are restricted to it."""
        w, h = view.size
        extent = shape_extent(opts["splat"], opts["size_factor"], opts["aspect"])
        bounds, largest = handle.bounds, float(handle.block_size.max())
        if isinstance(handle, GPULodPoints) and handle.frame_box is not None:
            bounds, largest = handle.frame_box  # the levels this frame draws
        grow = largest * math.hypot(*extent)
        lo, hi = bounds[0] - handle.origin - grow, bounds[1] - handle.origin + grow
        pick = np.array([[i & 1, i & 2, i & 4] for i in range(8)], bool)
        corners = np.where(pick, hi, lo) - np.asarray(view.eye_local(handle.origin))
        cam = view.camera
        r, u, f = cam.basis()
        depth = corners @ f
        if depth.min() < view.near:
            return None
        tan = math.tan(math.radians(cam.fov) / 2)
        x = ((corners @ r) / depth / (tan * view.aspect) * 0.5 + 0.5) * w
        y = ((corners @ u) / depth / tan * 0.5 + 0.5) * h
        pad = 2 + (math.ceil(_filter_radius()) + 1 if opts["quality"] == "high" else 0)
        x0, y0 = max(0, math.floor(x.min()) - pad), max(0, math.floor(y.min()) - pad)
        x1, y1 = min(w, math.ceil(x.max()) + pad), min(h, math.ceil(y.max()) + pad)
        if x0 <= 0 and y0 <= 0 and x1 >= w and y1 >= h:
            return None
        return (x0, y0, max(0, x1 - x0), max(0, y1 - y0))

    def _visible_then_accumulate(self, handle, view, opts, uniforms, tg, into) -> None:
        """The blended qualities' first two passes: each pixel's nearest
        (pushed-back) depth into ``tg.visibility``, then additive
        accumulation into ``into``, where splat.frag tests each fragment
        against that depth itself."""
        ctx = self.gl.ctx
        tg.visibility.use()
        tg.visibility.clear(depth=1.0)
        self._splats(handle, view, opts, "visibility", uniforms)
        into.use()
        into.clear(0.0, 0.0, 0.0, 0.0)
        ctx.disable(moderngl.DEPTH_TEST)
        ctx.enable(moderngl.BLEND)
        ctx.blend_equation = moderngl.FUNC_ADD
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        tg.depth.use(location=0)
        uniforms["u_visible"] = 0
        self._splats(handle, view, opts, "accumulate", uniforms)
        ctx.disable(moderngl.BLEND)
        ctx.enable(moderngl.DEPTH_TEST)

    def _splats(
        self, handle: GPUPoints, view: FrameView, opts: dict, kind: str, uniforms: dict
    ) -> None:
        """One pass over the points: sprites, then the wide splats' quads. A
        pyramid upload draws this frame's selection (``handle.drawn``)."""
        indexed = isinstance(handle, GPULodPoints)
        if indexed and not len(handle.drawn):
            return
        aa = opts["quality"] == "high"
        limit = self.max_sprite
        if aa and kind == "accumulate":
            # Quality "high" shades per pixel only splats of boxes wider than
            # AA_SHADE_BOX, in the geometry path (llvmpipe pays for shading
            # code in a shader even where no pixel runs it), so those go there.
            limit = min(limit, AA_SHADE_BOX)
        uniforms = {**uniforms, "u_max_sprite": limit, "u_shade_box": AA_SHADE_BOX}
        prog = self._program(kind, opts["splat"], sprite=True, aa=aa)
        self._bind(prog, uniforms)
        if indexed:
            self._vao(handle, prog, True).render(moderngl.POINTS, vertices=len(handle.drawn))
        else:
            self._vao(handle, prog).render(moderngl.POINTS)
        ranges = self.large_blocks(handle, view, opts, limit)
        if indexed and ranges:
            # Buffer ranges -> ranges of the (ascending) drawn indices.
            lo = np.searchsorted(handle.drawn, [f for f, _ in ranges])
            hi = np.searchsorted(handle.drawn, [f + c for f, c in ranges])
            ranges = [(int(a), int(b - a)) for a, b in zip(lo, hi, strict=True) if b > a]
        if ranges:
            prog = self._program(kind, opts["splat"], sprite=False, aa=aa)
            self._bind(prog, uniforms)
            vao = self._vao(handle, prog, indexed)
            for first, count in ranges:
                vao.render(moderngl.POINTS, vertices=count, first=first)

    def draw(
        self, handle: GPUPoints, view: FrameView, fbo=None, pixel_error: float | None = None,
        **options,
    ) -> None:  # fmt: skip
        """Draw into ``fbo`` (bound, cleared to the background with alpha 0,
        viewport covering it); writes colour, alpha 1 where a splat landed
        (coverage) and depth. With ``quality="high"`` alpha is the covered
        fraction, and the cloud is composited with what ``fbo`` holds
        (over it where nearer, under it where farther).

        A pyramid upload (:class:`GPULodPoints`) first selects this frame's
        points (:meth:`select`) with the screen-space error ``pixel_error``
        (framebuffer pixels, default 1), then draws only those."""
        opts = self.options(**options)
        if isinstance(handle, GPULodPoints):
            self.select(handle, view, 1.0 if pixel_error is None else pixel_error)
        elif pixel_error is not None:
            raise InputError(
                "pixel_error applies to a level-of-detail upload only (upload a LodPoints)"
            )
        ctx = self.gl.ctx
        target = fbo if fbo is not None else ctx.fbo
        viewport = ctx.viewport
        uniforms = self._uniforms(handle, view, opts)
        tg = self._offscreen(view.size, opts["quality"])
        box = self.screen_box(handle, view, opts)
        for buf in (tg.geometry, tg.visibility, tg.accumulate, tg.layered, target):
            if buf is not None:
                buf.scissor = box
        ctx.enable(moderngl.DEPTH_TEST | moderngl.PROGRAM_POINT_SIZE)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        ctx.depth_func = "<"
        try:
            if opts["quality"] == "fast":
                tg.visibility.use()  # depth only: the id target needs no clearing
                tg.visibility.clear(depth=1.0)
                tg.geometry.use()
                self._splats(handle, view, opts, "geometry", uniforms)
                fragment = "splat_deferred.frag"
                textures = {"u_ids": tg.ids, "u_geodepth": tg.depth, "u_attrib": handle.attrib}
                uniforms["u_per_row"] = ATTRIB_PER_ROW
            elif opts["quality"] == "high":
                self._visible_then_accumulate(handle, view, opts, uniforms, tg, tg.layered)
                fragment = "splat_aa_resolve.frag"
                textures = {"u_visible": tg.depth, "u_resolved": tg.slabs[-1]}
                for i, tex in enumerate(tg.slabs[:-1]):
                    textures[f"u_slab[{i}]"] = tex
            else:
                self._visible_then_accumulate(handle, view, opts, uniforms, tg, tg.accumulate)
                fragment = "splat_resolve.frag"
                textures = {"u_accum": tg.accum, "u_visible": tg.depth}
            target.use()
            ctx.viewport = viewport
            ctx.depth_func = "<="  # pushed depths may sit at the far plane
            for unit, (name, tex) in enumerate(textures.items()):
                tex.use(location=unit)
                uniforms[name] = unit
            if opts["quality"] == "high":
                units = [uniforms.pop(f"u_slab[{i}]") for i in range(len(tg.slabs) - 1)]
                uniforms["u_slab"] = units if len(units) > 1 else units[0]
            prog, vao = self._screen(fragment, opts["quality"] == "high")
            if opts["quality"] == "high":
                self._composite(prog, vao, uniforms, target)
            else:
                self._bind(prog, uniforms)
                vao.render(moderngl.TRIANGLES, vertices=3)
        finally:
            target.depth_mask = True
            target.scissor = None
            ctx.blend_equation = moderngl.FUNC_ADD
            ctx.depth_func = "<"
            ctx.blend_func = moderngl.DEFAULT_BLENDING
            ctx.disable(moderngl.BLEND)
            ctx.enable(moderngl.DEPTH_TEST)
            if ctx.fbo is not target:
                target.use()
                ctx.viewport = viewport

    def _composite(self, prog, vao, uniforms: dict, target) -> None:
        """The layers of ``quality="high"`` composited onto ``target`` (bound),
        which may hold earlier draws: over them where this cloud's visible
        layer is nearer (or nothing is there), and under them where it is
        farther, so that separately drawn clouds combine like one (up to
        rounding) in either order. The target's colour already holds its
        background, so "under" adds (1 - alpha) (this colour - background):
        the positive part, then the negative part by reverse subtraction."""
        ctx = self.gl.ctx
        ctx.enable(moderngl.BLEND)
        ctx.blend_equation = moderngl.FUNC_ADD
        ctx.blend_func = moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA
        self._bind(prog, {**uniforms, "u_mode": 0})
        vao.render(moderngl.TRIANGLES, vertices=3)
        ctx.depth_func = ">"
        target.depth_mask = False
        ctx.blend_func = (moderngl.ONE_MINUS_DST_ALPHA, moderngl.ONE, moderngl.ZERO, moderngl.ONE)
        self._bind(prog, {**uniforms, "u_mode": 1})
        vao.render(moderngl.TRIANGLES, vertices=3)
        ctx.blend_equation = (moderngl.FUNC_REVERSE_SUBTRACT, moderngl.FUNC_ADD)
        ctx.blend_func = (moderngl.ONE_MINUS_DST_ALPHA, moderngl.ONE) * 2
        self._bind(prog, {**uniforms, "u_mode": 2})
        vao.render(moderngl.TRIANGLES, vertices=3)

    def draw_floor(self, handle: GPUPoints, view: FrameView, fbo=None, **options) -> None:
        """The benchmark floor: the same points as plain GL_POINTS covering the
        same on-screen boxes as the splats' sprites, straight into ``fbo``,
        with a flat-colour shader (no intersection, discard, lighting, depth
        writes from the fragment stage or second pass). Splats wider than
        :attr:`max_sprite` are not drawn. Not for pyramid uploads."""
        if isinstance(handle, GPULodPoints):
            raise InputError("the benchmark floor draws a plain point cloud, not a pyramid upload")
        opts = self.options(**options)
        ctx = self.gl.ctx
        ctx.enable(moderngl.DEPTH_TEST | moderngl.PROGRAM_POINT_SIZE)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        ctx.depth_func = "<"
        prog = self._program("floor", opts["splat"], sprite=True)
        self._bind(prog, self._uniforms(handle, view, opts))
        self._vao(handle, prog).render(moderngl.POINTS)

    def _offscreen(self, size: tuple[int, int], quality: str) -> _Targets:
        ctx, track = self.gl.ctx, self.gl.track
        tg = self._targets.get(size)
        if tg is None:
            depth = track(ctx.depth_texture(size))
            depth.compare_func = ""  # read as plain values, not as a shadow sampler
            depth.filter = moderngl.NEAREST, moderngl.NEAREST
            vis = track(ctx.framebuffer(depth_attachment=depth))
            tg = self._targets[size] = _Targets(depth, vis)
        if quality == "fast" and tg.ids is None:
            tg.ids = track(ctx.texture(size, 1, dtype="u4"))
            tg.ids.filter = moderngl.NEAREST, moderngl.NEAREST
            tg.geometry = track(
                ctx.framebuffer(color_attachments=[tg.ids], depth_attachment=tg.depth)
            )
        if quality == "blend" and tg.accum is None:
            tg.accum = track(ctx.texture(size, 4, dtype=ACCUM_DTYPE))
            tg.accum.filter = moderngl.NEAREST, moderngl.NEAREST
            tg.accumulate = track(ctx.framebuffer(color_attachments=[tg.accum]))
        if quality == "high" and len(tg.slabs) != AA_SLABS + 1:
            self.gl.free(tg.layered, *tg.slabs)
            deep = min(4, max(1, AA_SLABS - AA_DEEP))  # channels of the resolved parts
            tg.slabs = tuple(
                track(ctx.texture(size, 4 if i < AA_SLABS else deep, dtype=AA_DTYPE))
                for i in range(AA_SLABS + 1)
            )
            for tex in tg.slabs:
                tex.filter = moderngl.NEAREST, moderngl.NEAREST
            tg.layered = track(ctx.framebuffer(color_attachments=list(tg.slabs)))
        return tg
