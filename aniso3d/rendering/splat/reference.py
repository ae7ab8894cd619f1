"""NumPy twins of quality "high", slow, obvious and in float64, for the tests
to hold the GPU to: the fragments of sub-pixel splats
(:func:`subpixel_fragments_np`, the twin of splat.vert and splat.frag for
splats below a pixel) and the compositing of fragments
(:func:`composite_np`, the twin of the mask, surfaces, accumulation and
compositing passes).

The compositing rule, per pixel, from its fragments (coverage c: the
fraction of the pixel a splat covers; linear depth z; colour):

1. Fragments with c below :data:`MIN_COVERAGE` are dropped.
2. Depth is cut into :data:`~aniso3d.rendering.splat.params.AA_SLICES`
   slices over the cloud's depths (:func:`~aniso3d.rendering.splat.geometry.mask_slicing`);
   a slice holding a fragment is occupied.
3. Surfaces, front to back: the nearest occupied slice starts one, which
   takes every occupied slice less than ``span`` slices beyond its start
   (one surface's splats lie within a depth of a few splat sizes); the next
   occupied slice beyond starts the next surface. The nearest surface
   spans from the farther of its first slice and the slice of the least
   *reach* of the pixel's fragments: a fragment's depth, plus, for a
   one-sided splat drawn with its back culled, the change of its depth
   across :data:`~aniso3d.rendering.splat.params.AA_SURFACE_REACH` pixels
   where the pixel's ray meets its plane (at most its bounding sphere's
   depth), so that a closed surface nearly along the ray, whose fragments
   lie at scattered depths, stays one; the same for a two-sided splat of a
   surface sheet (:attr:`~aniso3d.build.points.PointCloud.sheet`, with
   :data:`~aniso3d.rendering.splat.params.AA_SHEET_REACH`) where that
   change is at least :data:`~aniso3d.rendering.splat.params.AA_SHEET_GRAZE`
   spans (a sheet grazing the ray). Where the pixel holds no one-sided
   splat drawn with its back culled, the nearest surface takes beyond its
   span only the slices chained to it, each less than
   :data:`~aniso3d.rendering.splat.params.AA_SHEET_CHAIN` spans beyond the
   one before (a fold's fragments lie slice after slice; a sheet behind a
   grazing one's edge lies apart).
4. Layer k holds surface k, for k < :data:`~aniso3d.rendering.splat.params.AA_LAYERS` - 1;
   the last layer every surface from there on.
5. Within a surface splats tile it, so coverages add: a = min(1, sum c); the
   last layer's n surfaces are taken to share its sum equally,
   a = 1 - (1 - min(1, sum c / n))^n. A layer's colour is the
   coverage-weighted mean of its fragments' colours; in the last layer a
   fragment weighs c (1 - a_s)^j, where a_s = min(1, sum of the pixel's c /
   its number of surfaces) is the pixel's mean surface coverage and j the
   place of the fragment's surface among the layer's n (0 the layer's
   first), taken from its slice: the surfaces spread evenly from the layer's
   first slice to the first slice of the pixel's last surface, j = (n - 1)
   (slice - first) / (last - first): what the j surfaces in front leave of
   it, had they that coverage each (for equal, evenly spaced surfaces
   exactly what independent layers give). Where the last layer holds more
   than one surface its sum is the pixel's coverage sum less the other
   layers' sums; in the pixel's coverage sum a one-sided splat drawn with
   its back culled counts twice (its back's share: a closed surface is
   opaque, and the equal shares of a last layer would let it leak). The
   nearest surface is whole (a = 1)
   where the mean of min(1, sum) over the pixel and its four neighbours
   reaches ``mean`` (:data:`~aniso3d.rendering.splat.params.AA_CLOSE`),
   a neighbour counting where its nearest surface starts less than ``reach``
   spans from this one's (0 otherwise, and off the image): sub-pixel
   footprints do not tile a sheet exactly, so its sums scatter about 1.
6. Surfaces hide each other at random, front to back: with T the
   transmittance left (1 at first), a layer adds T a times its colour and
   T *= 1 - a, so an opaque layer hides everything behind it, and
   translucent ones compose as 1 - prod(1 - a_k).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aniso3d.build.points import PointCloud
from aniso3d.errors import InputError
from aniso3d.grid import tangent_frame
from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.lighting import shade_np
from aniso3d.rendering.splat import params
from aniso3d.rendering.splat.geometry import mask_slicing
from aniso3d.rendering.splat.options import SplatOptions
from aniso3d.rendering.splat.params import AA_FILTER, AA_LAYERS, AA_PLANE_REACH, AA_REGIME, AA_SLICES
from aniso3d.rendering.splat.pipeline import outside

#: Fragments covering less of their pixel than this are dropped (splat.frag).
MIN_COVERAGE = 1e-4


@dataclass(frozen=True)
class Fragments:
    """What the splats of one draw leave in the pixels, one row per fragment.

    Attributes:
        pixel: (F,) int64 flat pixel index ``row * width + column``, row 0 at
            the top of the image.
        coverage: (F,) float64 fraction of the pixel the splat covers, [0, 1].
        depth: (F,) float64 linear depth (t - near) / (far - near) of the
            fragment (t: view depth, world units).
        rgb: (F, 3) float64 shaded colour in [0, 1].
        size: (width, height) of the image, pixels.
        slicing: (lo, scale, span) of the draw's depth slices
            (:func:`~aniso3d.rendering.splat.geometry.mask_slicing`).
        counts: (F,) float64, how many times the fragment's coverage counts
            in its pixel's coverage sum: 2 for a one-sided splat drawn with
            its back culled (the back's share), else 1; None: all 1.
        reach: (F,) float64, the linear depth from which the fragment's
            surface may span its span in its pixel (rule step 3): its depth
            plus its reach; None: the depth.
    """

    pixel: np.ndarray
    coverage: np.ndarray
    depth: np.ndarray
    rgb: np.ndarray
    size: tuple[int, int]
    slicing: tuple[float, float, float]
    counts: np.ndarray | None = None
    reach: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.pixel)
        for name, arr, shape in (("coverage", self.coverage, (n,)), ("depth", self.depth, (n,)),
                                 ("rgb", self.rgb, (n, 3))):  # fmt: skip
            if np.shape(arr) != shape:
                raise InputError(f"fragment {name} must have shape {shape}, got {np.shape(arr)}")


def _box_cdf(x: np.ndarray) -> np.ndarray:
    """The pixel box filter's cumulative distribution (splat_filter.glsl, FILTER 0)."""
    return np.clip(x + 0.5, 0.0, 1.0)


def rect_kept_np(lo: np.ndarray, hi: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Area of the rectangles [lo, hi] ((N, 2) each) where ``line`` (N, 3),
    ``c + gx x + gy y``, is at least 0: the kept height along the axis the
    line is flatter to, a clamped linear function of the other coordinate,
    integrated in closed form (splat_filter.glsl rect_kept())."""
    lo, hi, line = (np.asarray(a, dtype=np.float64) for a in (lo, hi, line))
    size = np.maximum(hi - lo, 0.0)
    full = size[:, 0] * size[:, 1]
    swap = np.abs(line[:, 1]) > np.abs(line[:, 2])
    sw = lambda a: np.where(swap[:, None], a[:, ::-1], a)  # noqa: E731
    lo, hi, size, g = sw(lo), sw(hi), sw(size), sw(line[:, 1:])
    flat = g[:, 1] == 0.0
    gy = np.where(flat, 1.0, g[:, 1])
    m, c = -g[:, 0] / gy, -line[:, 0] / gy
    y0, y1 = c + m * lo[:, 0], c + m * hi[:, 0]
    up = g[:, 1] > 0
    z0 = np.where(up, hi[:, 1] - y0, y0 - lo[:, 1])
    z1 = np.where(up, hi[:, 1] - y1, y1 - lo[:, 1])
    dz = z1 - z0

    def integral(z):
        return 0.5 * (np.maximum(z, 0.0) ** 2 - np.maximum(z - size[:, 1], 0.0) ** 2)

    small = np.abs(dz) < 1e-3 * size[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        ramp = size[:, 0] * (integral(z1) - integral(z0)) / np.where(small, 1.0, dz)
    mid = size[:, 0] * np.clip(0.5 * (z0 + z1), 0.0, size[:, 1])
    kept = np.where(small, mid, ramp)
    kept = np.where(flat, np.where(line[:, 0] >= 0, full, 0.0), kept)
    return np.where(full > 0, kept, 0.0)


def clip_geometry_np(
    positions: np.ndarray, normals: np.ndarray, clips: np.ndarray, eye: np.ndarray, sided: np.ndarray | None = None
):
    """For each point's clip planes (:attr:`~aniso3d.build.points.PointCloud.clips`,
    (N, 2, 5)): the edge's point nearest the centre ``q`` (N, 2, 3), the
    edge's direction (N, 2, 3), whether the plane is set (N, 2), and whether
    the surface meeting the splat there hides it from ``eye`` (N,): the eye's
    angle about the edge, from the splat's direction into its voxel, lies
    beyond the meeting surface's; never for a point ``sided`` ((N,) bool, the
    one-sided points culled from behind): that surface, wound as the point's
    closed surface is, faces away where it lies in front and is culled, or
    the point does (:data:`~aniso3d.rendering.splat.params.AA_PARTNER_HIDES_SIDED`;
    splat.vert hidden_at())."""
    m, o, phi = clips[..., :3], clips[..., 3], clips[..., 4]
    n = normals.astype(np.float64)[:, None, :]
    mp = m - np.einsum("nkc,nkc->nk", m, np.broadcast_to(n, m.shape))[..., None] * n
    length = np.linalg.norm(mp, axis=-1)
    has = np.linalg.norm(m, axis=-1) > 0
    ok = has & (length > 1e-6)
    u = -mp / np.where(ok, length, 1.0)[..., None]
    lam = (o - np.einsum("nkc,nc->nk", m, positions)) / np.where(ok, length, 1.0)
    q = positions[:, None, :] - lam[..., None] * u
    e = eye[None, None, :] - q
    th = np.arctan2(np.einsum("nkc,nkc->nk", e, np.broadcast_to(n, e.shape)), np.einsum("nkc,nkc->nk", e, u))
    hidden = ok & (phi != 0) & (phi * th > 0) & (np.abs(phi) < np.abs(th))
    if sided is not None and not params.AA_PARTNER_HIDES_SIDED:
        hidden &= ~np.asarray(sided, bool)[:, None]
    along = np.cross(np.broadcast_to(n, m.shape), m)
    along /= np.maximum(np.linalg.norm(along, axis=-1, keepdims=True), 1e-300)
    return q, along, ok, hidden.any(axis=1)


def subpixel_fragments_np(cloud: PointCloud, view: FrameView, opts: SplatOptions) -> Fragments:
    """The fragments quality "high" draws for ``cloud``, every splat of which
    must be in the sub-pixel regime (true projected area at most
    ``AA_REGIME[0]^2`` pixels) and in front of the near plane.

    The twin of splat.vert and splat.frag there: each splat is an axis-aligned
    box in the image with the second moments of its true projected area (no
    size factor) and an amplitude that keeps that area; its coverage of a pixel
    is the box filtered by the pixel's box and sampled at the pixel centre.
    A splat with clip planes (:attr:`~aniso3d.build.points.PointCloud.clips`)
    is dropped where the surface meeting it at one hides it
    (:func:`clip_geometry_np`); else its box is cut by the planes' lines in
    the image (each edge's two points projected), its amplitude grown by the
    share cut off (at most 4), and each fragment keeps the share of its
    rectangle (box times pixel) on the kept side of each line
    (:func:`rect_kept_np`; of both, the product of the shares).
    A fragment's depth is where the pixel centre's ray meets the splat's plane
    (else the centre's), clamped to the splat's bounding sphere grown by
    :data:`~aniso3d.rendering.splat.params.AA_PLANE_REACH` pixels; its colour
    is shade() at the centre, seen from the eye.
    """
    if AA_FILTER != 0:
        raise InputError("the NumPy twin implements the box pixel filter (AA_FILTER = 0) only")
    w, h = view.size
    cam = view.camera
    r, u, f = cam.basis()
    tan = math.tan(math.radians(cam.fov) / 2)
    proj = np.array([1.0 / (tan * view.aspect), 1.0 / tan])
    near, far = float(view.near), float(view.far)
    eye = np.asarray(cam.position, np.float64)
    full = cloud  # the slices span the whole cloud's depths, culled points included (as uploaded)
    culling = cloud.one_sided is not None and outside(eye, cloud.bounds)
    counts = np.ones(len(cloud))
    keep = np.ones(len(cloud), bool)
    if culling:
        # One-sided points seen from behind are culled (splat.vert).
        facing = np.einsum("ij,ij->i", cloud.normals.astype(np.float64), cloud.positions - eye)
        keep &= ~(cloud.one_sided & (facing > 0))
        counts = np.where(cloud.one_sided, 2.0, 1.0)
    if cloud.clips is not None:
        sided = cloud.one_sided if culling else None
        keep &= ~clip_geometry_np(cloud.positions, cloud.normals, cloud.clips, eye, sided)[3]
    if not keep.all():
        counts = counts[keep]
        cloud = PointCloud(cloud.positions[keep], cloud.normals[keep], cloud.areas[keep], cloud.kd[keep],
                           cloud.ks[keep], cloud.shininess[keep], coherence=cloud.coherence[keep],
                           clips=None if cloud.clips is None else cloud.clips[keep],
                           sheet=None if cloud.sheet is None else cloud.sheet[keep])  # fmt: skip
    p = cloud.positions - eye
    n = cloud.normals
    t_ax, b_ax = tangent_frame(n)
    size = np.sqrt(cloud.areas)
    hx, hy = (e * size for e in opts.extent)  # drawn half-axes, world units
    rot = np.stack([r, u, -f])  # eye <- world
    ce, te, be = p @ rot.T, (t_ax * hx[:, None]) @ rot.T, (b_ax * hy[:, None]) @ rot.T
    depth = -ce[:, 2]
    if np.any(depth < near):
        raise InputError("the NumPy twin draws splats whose centres lie beyond the near plane only")
    pix = 0.5 * np.array([w, h]) * proj / depth[:, None]
    cpx = (ce[:, :2] * proj / depth[:, None] * 0.5 + 0.5) * np.array([w, h])
    pu = pix * (te[:, :2] + ce[:, :2] * (te[:, 2] / depth)[:, None]) / opts.size_factor
    pv = pix * (be[:, :2] + ce[:, :2] * (be[:, 2] / depth)[:, None]) / opts.size_factor
    area_unit, moment = (4.0, 1.0) if opts.splat == "square" else (math.pi, 0.75)
    area = area_unit * np.abs(pu[:, 0] * pv[:, 1] - pu[:, 1] * pv[:, 0])
    if np.any(np.sqrt(area) > AA_REGIME[0]):
        raise InputError(
            f"the NumPy twin draws sub-pixel splats only (true projected area <= {AA_REGIME[0] ** 2:g} px^2); "
            f"the largest here is {area.max():.3g} px^2"
        )
    half = np.sqrt(moment * (pu * pu + pv * pv))
    box = 4.0 * half[:, 0] * half[:, 1]
    grow = area > box  # a disc's moment box is smaller than the disc
    half[grow] *= np.sqrt(area[grow] / box[grow])[:, None]
    box = np.where(grow, area, box)
    amp = np.divide(area, box, out=np.zeros_like(area), where=box > 0)
    # The clip planes' lines in the image, in pixels about the centre, each
    # through its edge's two points projected, positive on the kept side.
    lines = np.zeros((len(cloud), 2, 3))
    lines[..., 0] = 1.0
    if cloud.clips is not None:
        q, along, has, _ = clip_geometry_np(cloud.positions, cloud.normals, cloud.clips, eye)

        def project(x):  # world (N, 2, 3) -> pixels about the centre
            e = (x - eye) @ rot.T
            return (e[..., :2] * proj / -e[..., 2:3] * 0.5 + 0.5) * np.array([w, h]) - cpx[:, None, :]

        scale = np.sqrt(cloud.areas)[:, None, None]
        a, b = project(q), project(q + along * scale)
        g = np.stack([a[..., 1] - b[..., 1], b[..., 0] - a[..., 0]], axis=-1)  # normal to the line
        c0 = -np.einsum("nkc,nkc->nk", g, a)
        sign = np.where(c0 >= 0, 1.0, -1.0)  # the centre (0, 0) is kept
        lines = np.where(has[..., None], np.concatenate([c0[..., None], g], axis=-1) * sign[..., None], lines)
        cut = has.any(axis=1)
        box_area = 4.0 * half[:, 0] * half[:, 1]
        kept = np.ones(len(cloud))
        for k in range(2):
            kept *= np.divide(rect_kept_np(-half, half, lines[:, k]), box_area, out=np.ones_like(box_area),
                              where=box_area > 0)  # fmt: skip
        amp = np.where(cut & (box_area > 0), amp / np.maximum(kept, 0.25), amp)
    # Every pixel the filtered box reaches: a window of offsets around the centre.
    reach = int(math.ceil(float(half.max(initial=0.0)) + 1.0))
    off = np.arange(-reach, reach + 1)
    ox, oy = (a.ravel() for a in np.meshgrid(off, off))
    ix = np.floor(cpx[:, 0])[:, None].astype(np.int64) + ox[None]
    iy = np.floor(cpx[:, 1])[:, None].astype(np.int64) + oy[None]
    dx, dy = ix + 0.5 - cpx[:, :1], iy + 0.5 - cpx[:, 1:]
    cov = (amp[:, None] * (_box_cdf(dx + half[:, :1]) - _box_cdf(dx - half[:, :1]))
           * (_box_cdf(dy + half[:, 1:]) - _box_cdf(dy - half[:, 1:])))  # fmt: skip
    keep = (cov >= MIN_COVERAGE) & (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
    splat, _ = np.nonzero(keep)
    ix, iy, cov, dx, dy = ix[keep], iy[keep], cov[keep], dx[keep], dy[keep]
    if cloud.clips is not None:
        # Each fragment's rectangle (box times pixel) kept by the lines.
        d = np.stack([dx, dy], axis=1)
        lo, hi = np.maximum(-half[splat], d - 0.5), np.minimum(half[splat], d + 0.5)
        rect = np.prod(np.maximum(hi - lo, 0.0), axis=1)
        share = np.ones(len(splat))
        for k in range(2):
            share *= np.divide(rect_kept_np(lo, hi, lines[splat, k]), rect, out=np.zeros_like(rect), where=rect > 0)
        cov = cov * share
        keep = cov >= MIN_COVERAGE
        splat, ix, iy, cov = splat[keep], ix[keep], iy[keep], cov[keep]
    # Depth: the pixel centre's ray d = f + x R + y U (d . f = 1, so t is the
    # view depth) meets the plane n . (q - p) = 0 at t = n . p / n . d.
    x = (ix + 0.5) / w * 2.0 - 1.0
    y = (iy + 0.5) / h * 2.0 - 1.0
    d = f + x[:, None] * (r / proj[0]) + y[:, None] * (u / proj[1])
    nd = np.einsum("ij,ij->i", n[splat], d)
    npn = np.einsum("ij,ij->i", n[splat], p[splat])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = npn / nd
    hit = (nd != 0) & (t >= near) & (t <= far)
    lin = np.where(hit, (t - near) / (far - near), (depth[splat] - near) / (far - near))
    # The bounding sphere grown by AA_PLANE_REACH pixels at the centre's depth.
    rad = (np.hypot(hx, hy) + AA_PLANE_REACH / pix.min(axis=1))[splat]
    zlo = np.clip((depth[splat] - near - rad) / (far - near), 0.0, 1.0)
    zhi = np.clip((depth[splat] - near + rad) / (far - near), 0.0, 1.0)
    z = np.clip(lin, zlo, zhi)
    # The surface's reach: the span, plus for a one-sided splat whose back is
    # culled the change of the plane's depth across AA_SURFACE_REACH pixels
    # where the ray meets it, at most its bounding sphere's depth. (NDC
    # changes by 2 / w a pixel; d changes by R / proj_x per NDC unit.)
    with np.errstate(divide="ignore", invalid="ignore"):
        gx = npn * (n[splat] @ r) / proj[0] * (2.0 / w) / nd**2
        gy = npn * (n[splat] @ u) / proj[1] * (2.0 / h) / nd**2
    reaching = counts > 1
    if cloud.sheet is not None and params.AA_SHEET_REACH:
        reaching = reaching | cloud.sheet
    slope = np.where(hit & reaching[splat], np.hypot(gx, gy) / (far - near), 0.0)
    extra = np.minimum(slope * params.AA_SURFACE_REACH, zhi - zlo)
    view_dir = -p / np.linalg.norm(p, axis=1, keepdims=True)
    rgb = np.clip(shade_np(n, view_dir, cloud.kd, cloud.ks, cloud.shininess, view.lighting, cloud.coherence), 0.0, 1.0)
    # The slices span the view depths the cloud's splats may reach
    # (culling.depth_range: the bounds grown by the largest splat).
    full_size = np.sqrt(full.areas)
    b = full.bounds + np.array([[-1.0], [1.0]]) * float(full_size.max()) * math.hypot(*opts.extent)
    corners = np.array([[x_, y_, z_] for x_ in b[:, 0] for y_ in b[:, 1] for z_ in b[:, 2]])
    corner_depth = (corners - eye) @ f
    slicing = mask_slicing(view, float(corner_depth.min()), float(corner_depth.max()), float(np.median(full_size)),
                           opts)  # fmt: skip
    pixel = (h - 1 - iy) * w + ix
    if cloud.sheet is not None:
        # A two-sided sheet's fragment reaches only where it grazes the ray.
        two = cloud.sheet[splat] & (counts[splat] <= 1)
        extra = np.where(two & (extra * slicing[1] < params.AA_SHEET_GRAZE * slicing[2]), 0.0, extra)
    reach = z + extra
    return Fragments(pixel, cov, z, rgb[splat], (w, h), slicing, counts[splat], reach)


def surfaces_np(pixel: np.ndarray, slice_index: np.ndarray, n_pixels: int, span: float,
                first_end: np.ndarray | None = None, chained: np.ndarray | None = None):  # fmt: skip
    """The surfaces of each pixel (rule steps 2 and 3): (starts, count), with
    ``starts`` (n_pixels, S) float64 the first slice of each surface front to
    back (inf past the last) and ``count`` (n_pixels,) how many there are.
    ``first_end`` (n_pixels,): the nearest surface takes every slice below
    this when it lies farther than its first slice plus ``span``; where
    ``chained`` (n_pixels,) bool, only the slices chained to its span, each
    less than :data:`~aniso3d.rendering.splat.params.AA_SHEET_CHAIN` spans
    beyond the one before."""
    occupied = np.zeros((n_pixels, AA_SLICES), bool)
    occupied[pixel, slice_index] = True
    column = np.arange(AA_SLICES)
    limit = np.full(n_pixels, -np.inf)
    starts = []
    while True:
        later = occupied & (column[None] >= limit[:, None])
        found = later.any(axis=1)
        if not found.any():
            break
        first = np.where(found, np.argmax(later, axis=1), np.inf)
        limit = np.where(found, first + span, np.inf)
        if not starts and first_end is not None:
            end = np.where(found, np.maximum(limit, first_end), limit)
            if chained is not None:
                gap = params.AA_SHEET_CHAIN * span
                chain = chained & found & (end > limit)
                if chain.any():
                    # Each taken slice extends the surface, front to back.
                    lo, hi = int(first[chain].min()), int(min(np.ceil(end[chain].max()), AA_SLICES))
                    link = limit.copy()
                    for col in range(lo, hi):
                        taken = chain & occupied[:, col] & (col < link)
                        link = np.where(taken, np.maximum(link, np.minimum(col + gap, end)), link)
                    end = np.where(chain, link, end)
            limit = end
        starts.append(first)
    starts_arr = np.stack(starts, axis=1) if starts else np.full((n_pixels, 1), np.inf)
    return starts_arr, np.isfinite(starts_arr).sum(axis=1)


def _shifted(a: np.ndarray, dy: int, dx: int, fill: float) -> np.ndarray:
    """``a`` (H, W) moved by (dy, dx) pixels: out[y, x] = a[y - dy, x - dx],
    ``fill`` where that lies off the image."""
    h, w = a.shape
    out = np.full_like(a, fill)
    to = (slice(max(dy, 0), h + min(dy, 0)), slice(max(dx, 0), w + min(dx, 0)))
    out[to] = a[max(-dy, 0) : h - max(dy, 0), max(-dx, 0) : w - max(dx, 0)]
    return out


def closed_np(
    own: np.ndarray, start: np.ndarray, span: float, sided: np.ndarray | None = None, slope: np.ndarray | None = None
) -> np.ndarray:
    """(H, W) bool: where the nearest surface is whole (rule step 5), from its
    sum of coverages ``own`` (H, W) and first slice ``start`` (H, W; inf
    where the pixel holds nothing); ``sided`` (H, W) bool: the pixel holds a
    one-sided splat drawn with its back culled (the mean is then
    :data:`~aniso3d.rendering.splat.params.AA_CLOSE_SIDED`); ``slope`` (H,
    W): slices its nearest surface's depth changes across a pixel, which a
    neighbour's start may lie beyond the reach (where ``sided``: a closed
    surface seen at a grazing angle, its neighbours' starts several slices
    apart). The pixel's own sum must reach
    :data:`~aniso3d.rendering.splat.params.AA_CLOSE_OWN`."""
    mean, reach = (float(x) for x in params.AA_CLOSE)
    min_mean = mean if sided is None else np.where(sided, float(params.AA_CLOSE_SIDED), mean)
    within = reach * span + (0.0 if slope is None else slope)
    total = np.minimum(own, 1.0)
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        c, s = _shifted(own, dy, dx, 0.0), _shifted(start, dy, dx, np.inf)
        with np.errstate(invalid="ignore"):
            same = (c > 0) & (np.abs(s - start) < within)
        total += np.where(same, np.minimum(c, 1.0), 0.0)
    return (own < 1.0) & (own >= float(params.AA_CLOSE_OWN)) & (total >= 5.0 * min_mean)


def least_reach_slice(frags: Fragments, keep: np.ndarray) -> np.ndarray:
    """(H * W,) per pixel the slice of the least depth plus reach of its
    kept fragments (``keep``, (F,) bool; inf where none): what the
    visibility pass's green channel holds, in slices (splat_surfaces.frag,
    splat_aa_resolve.frag). ``frags.reach`` must be set."""
    w, h = frags.size
    least = np.full(w * h, np.inf)
    np.minimum.at(least, frags.pixel[keep], np.asarray(frags.reach, np.float64)[keep])
    with np.errstate(invalid="ignore"):
        return np.floor((least - frags.slicing[0]) * frags.slicing[1])


def fragment_surfaces(frags: Fragments) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The surfaces of each pixel of ``frags`` (rule steps 1 to 3): (keep,
    slice, starts, count), ``keep`` (F,) bool the fragments kept (coverage at
    least :data:`MIN_COVERAGE`), ``slice`` (K,) int64 the kept ones' slices,
    and :func:`surfaces_np`'s ``starts`` and ``count`` per pixel, the nearest
    surface spanning from its fragments' least reach where that lies farther."""
    w, h = frags.size
    lo, scale, span = frags.slicing
    keep = frags.coverage >= MIN_COVERAGE
    pixel = frags.pixel[keep]
    s = np.clip(np.floor((frags.depth[keep] - lo) * scale), 0, AA_SLICES - 1).astype(np.int64)
    first_end = None
    if frags.reach is not None:
        first_end = least_reach_slice(frags, keep) + span
    # Pixels without a closed surface seen from outside chain their reach.
    counted = np.ones(len(pixel)) if frags.counts is None else np.asarray(frags.counts, np.float64)[keep]
    chained = np.bincount(pixel, counted > 1, w * h) == 0
    starts, count = surfaces_np(pixel, s, w * h, span, first_end, chained)
    return keep, s, starts, count


def composite_np(
    frags: Fragments, background=(1.0, 1.0, 1.0), layers: int = AA_LAYERS, last_weights: bool | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The image quality "high" composites from ``frags`` over ``background``
    (the module docstring's rule): (rgb (H, W, 3), alpha (H, W)), float64,
    row 0 at the top; rgb = composited colour + (1 - alpha) background, as
    drawn over a target cleared to the background. ``last_weights``: weigh
    the last layer's surfaces (step 5), default
    :data:`~aniso3d.rendering.splat.params.AA_LAST_WEIGHTS`."""
    if last_weights is None:
        last_weights = params.AA_LAST_WEIGHTS
    w, h = frags.size
    span = frags.slicing[2]
    keep, s, starts, count = fragment_surfaces(frags)
    pixel, c, rgb = frags.pixel[keep], frags.coverage[keep], frags.rgb[keep]
    counted = c if frags.counts is None else c * np.asarray(frags.counts, dtype=np.float64)[keep]
    cover_sum = np.bincount(pixel, counted, w * h)
    surface = (starts[pixel] <= s[:, None]).sum(axis=1) - 1
    layer = np.minimum(surface, layers - 1)
    total = np.zeros((w * h, layers))
    colour = np.zeros((w * h, layers, 3))
    weight = np.zeros((w * h, layers))
    np.add.at(total, (pixel, layer), c)
    # The last layer's colour: each surface weighted by what the surfaces in
    # front of it leave, at the pixel's mean surface coverage.
    mean_cover = np.minimum(cover_sum / np.maximum(count, 1), 1.0)
    if layers > 1 and last_weights:
        first = starts[:, layers - 1] if starts.shape[1] >= layers else np.full(w * h, np.inf)
        last_start = np.where(np.isfinite(starts), starts, -np.inf).max(axis=1)
        n_last = np.maximum(count - (layers - 1), 1)
        first_f, spread = first[pixel], np.maximum(last_start - first, 1.0)[pixel]
        in_last = (n_last[pixel] > 1) & (s >= first_f)
        j = np.where(in_last, (s - np.where(in_last, first_f, 0.0)) / spread * (n_last[pixel] - 1), 0.0)
    else:
        j = np.zeros(len(s))
    cw = c * np.where(j > 0, (1.0 - mean_cover[pixel]) ** j, 1.0)
    np.add.at(weight, (pixel, layer), cw)
    np.add.at(colour, (pixel, layer), rgb * cw[:, None])
    sided = slope = None
    if frags.counts is not None:
        sided = np.bincount(pixel, np.asarray(frags.counts, np.float64)[keep] > 1, w * h).reshape(h, w) > 0
        if frags.reach is not None and params.AA_CLOSE_SLOPE:
            # The nearest surface's depth change across a pixel: its least reach's slice past its start.
            with np.errstate(invalid="ignore"):
                rise = least_reach_slice(frags, keep) - starts[:, 0]
            slope = np.where(sided.ravel() & np.isfinite(rise), np.maximum(rise, 0.0), 0.0).reshape(h, w)
    whole = closed_np(total[:, 0].reshape(h, w), starts[:, 0].reshape(h, w), span, sided, slope).ravel()
    whole &= layers > 1
    out = np.zeros((w * h, 3))
    trans = np.ones(w * h)
    last = np.maximum(count - (layers - 1), 1).astype(np.float64)
    front = total[:, : layers - 1].sum(axis=1)
    for k in range(layers):
        a_sum = total[:, k]
        if k == layers - 1 and layers > 1:
            # The pixel's coverage sum less the other layers' (what the GPU has).
            a_sum = np.where(last > 1, np.maximum(cover_sum - front, 0.0), a_sum)
        n = last if k == layers - 1 else np.ones(w * h)
        a = np.where(n > 1, 1.0 - (1.0 - np.minimum(a_sum / n, 1.0)) ** n, np.minimum(a_sum, 1.0))
        if k == 0:
            a = np.where(whole, 1.0, a)
        wk = weight[:, k][:, None]
        mean = np.divide(colour[:, k], wk, out=np.zeros((w * h, 3)), where=wk > 0)
        out += (trans * a)[:, None] * mean
        trans *= 1.0 - a
    out += trans[:, None] * np.asarray(background, np.float64)
    return out.reshape(h, w, 3), (1.0 - trans).reshape(h, w)
