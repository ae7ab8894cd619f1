"""Per-frame bounds on the CPU, from an upload's block bounds: which blocks of
points may hold a splat too wide for a point sprite (:func:`large_blocks`),
the screen box holding every splat (:func:`screen_box`), to which clears
and full-screen passes are restricted, and the view depths the splats span
(:func:`depth_range`). All are conservative."""

from __future__ import annotations

import math

import numpy as np

from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.splat.buffers import GPULodPoints, GPUPoints

#: (8, 3) selectors of a box's corners.
_CORNERS = np.array([[i & 1, i & 2, i & 4] for i in range(8)], bool)


def large_blocks(
    handle: GPUPoints, view: FrameView, extent: tuple[float, float], limit: float,
    reach: float | None = None,
) -> list[tuple[int, int]]:  # fmt: skip
    """(first, count) ranges of points that may hold a splat wider than
    ``limit`` pixels in this frame: a conservative bound per block.
    ``extent``: the shape's half-axes per unit of ``sqrt(area)``; ``reach``:
    the pixel filter's radius (pixels) of a coverage-aware pass, None for the
    others (whose boxes hold the centre's pixel instead)."""
    w, h = view.size
    # Boxes hold the centre's pixel, or with AA the filter's reach, besides the shape.
    slack = 2.0 + (2.0 * reach + 1.0 if reach is not None else 0.0)
    if max(w, h) + slack <= limit:  # boxes are clamped to the viewport
        return []
    cam = view.camera
    r, u, f = cam.basis()
    rot = np.stack([r, u, -f])
    eye = np.asarray(view.eye_local(handle.origin))
    corners = np.where(
        _CORNERS[None], handle.block_hi[:, None], handle.block_lo[:, None]
    )  # (B, 8, 3)
    e = (corners - eye) @ rot.T
    radius = handle.block_size * math.hypot(*extent)
    depth_lo = -e[..., 2].max(axis=1) - radius
    depth_hi = -e[..., 2].min(axis=1) + radius
    zlo = np.maximum(depth_lo, view.near)
    tan = math.tan(math.radians(cam.fov) / 2)
    wide = np.zeros(len(radius), bool)
    # Over a ball of radius rho clipped to depth >= zlo, x/z varies by at
    # most 2 rho (1/zlo + max|x| / zlo^2) (mean value theorem).
    for axis, scale, pixels in ((0, 1.0 / (tan * view.aspect), w), (1, 1.0 / tan, h)):
        lateral = np.abs(e[..., axis]).max(axis=1) + radius
        size = scale * 2.0 * radius * (1.0 / zlo + lateral / zlo**2) * 0.5 * pixels
        wide |= size + slack > limit
    wide &= depth_hi >= view.near
    ranges: list[tuple[int, int]] = []
    for i in np.flatnonzero(wide):
        s, c = int(handle.block_start[i]), int(handle.block_count[i])
        if ranges and ranges[-1][0] + ranges[-1][1] == s:
            ranges[-1] = (ranges[-1][0], ranges[-1][1] + c)
        else:
            ranges.append((s, c))
    return ranges


def _frame_bounds(handle: GPUPoints, extent: tuple[float, float]) -> np.ndarray:
    """(8, 3) corners, in the local frame, of a box holding every splat of the
    cloud (for a pyramid upload, of the levels this frame draws)."""
    bounds, largest = handle.bounds, float(handle.block_size.max())
    if isinstance(handle, GPULodPoints) and handle.frame_box is not None:
        bounds, largest = handle.frame_box  # the levels this frame draws
    grow = largest * math.hypot(*extent)
    lo, hi = bounds[0] - handle.origin - grow, bounds[1] - handle.origin + grow
    return np.where(_CORNERS, hi, lo)


def depth_range(handle: GPUPoints, view: FrameView, extent: tuple[float, float]) -> tuple[float, float]:
    """(nearest, farthest) view depth, world units, that a splat of the cloud
    may reach in this frame (its box grown by the largest splat)."""
    depth = (_frame_bounds(handle, extent) - np.asarray(view.eye_local(handle.origin))) @ view.camera.forward
    return float(depth.min()), float(depth.max())


def screen_box(
    handle: GPUPoints, view: FrameView, extent: tuple[float, float], reach: float | None = None
) -> tuple[int, int, int, int] | None:
    """(x, y, width, height) pixels holding every splat of the cloud (its
    bounds grown by the largest splat, projected; for a pyramid upload, the
    levels this frame draws), or None when the box would be the whole
    viewport or the cloud reaches behind the near plane. ``extent`` and
    ``reach`` as for :func:`large_blocks`."""
    w, h = view.size
    corners = _frame_bounds(handle, extent) - np.asarray(view.eye_local(handle.origin))
    cam = view.camera
    r, u, f = cam.basis()
    depth = corners @ f
    if depth.min() < view.near:
        return None
    tan = math.tan(math.radians(cam.fov) / 2)
    x = ((corners @ r) / depth / (tan * view.aspect) * 0.5 + 0.5) * w
    y = ((corners @ u) / depth / tan * 0.5 + 0.5) * h
    pad = 2 + (math.ceil(reach) + 1 if reach is not None else 0)
    x0, y0 = max(0, math.floor(x.min()) - pad), max(0, math.floor(y.min()) - pad)
    x1, y1 = min(w, math.ceil(x.max()) + pad), min(h, math.ceil(y.max()) + pad)
    if x0 <= 0 and y0 <= 0 and x1 >= w and y1 >= h:
        return None
    return (x0, y0, max(0, x1 - x0), max(0, y1 - y0))
