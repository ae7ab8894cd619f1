"""Splat geometry on the CPU, float64: the
pixels one splat covers (:func:`splat_coverage_np`, the slow, obvious twin of
the GPU coverage test), the Z-order the points are uploaded in and the depth
slices of quality "high" (:func:`mask_slicing`)."""

from __future__ import annotations

import math

import numpy as np

from aniso3d.grid import tangent_frame
from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.splat import params
from aniso3d.rendering.splat.options import DEFAULT_ASPECT, SplatOptions, default_size_factor, shape_extent
from aniso3d.rendering.splat.params import AA_SLICES, AA_SPAN


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



def mask_slicing(
    view: FrameView, depth_lo: float, depth_hi: float, typical_size: float, opts: SplatOptions
) -> tuple[float, float, float]:
    """The depth slices of quality "high" for a cloud whose splats reach view
    depths ``depth_lo`` .. ``depth_hi`` (world units) and whose typical
    (median) ``sqrt(area)`` is ``typical_size``: (lo, scale, span). A linear
    depth z = (t - near) / (far - near) lies in slice ``floor((z - lo) * scale)``
    (:data:`~aniso3d.rendering.splat.params.AA_SLICES` slices over the cloud's
    depths); one surface spans ``span`` slices:
    :data:`~aniso3d.rendering.splat.params.AA_SPAN` times ``push`` times a
    typical splat's larger half-axis, at least
    :data:`~aniso3d.rendering.splat.params.AA_SPAN_MIN`."""
    near, far = float(view.near), float(view.far)
    lo, hi = (min(max((d - near) / (far - near), 0.0), 1.0) for d in (depth_lo, depth_hi))
    scale = AA_SLICES / max(hi - lo, 1e-30)
    span = AA_SPAN * opts.push * typical_size * max(opts.extent) / (far - near) * scale
    return lo, scale, max(span, params.AA_SPAN_MIN)
