"""The bench's cameras: one view direction at distances chosen by how many
pixels a baseline voxel spans, and the pixel box each one is scored in."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aniso3d.bench.settings import Settings
from aniso3d.metrics import screen_box
from aniso3d.rendering.camera import Camera


@dataclass(frozen=True)
class CameraSpec:
    """One camera of the sweep.

    Attributes:
        label: "fill" or the baseline voxel's width in pixels, e.g. "1px".
        scale: ``distance_scale`` of :meth:`Camera.frame` (1 = fills the frame).
        camera: the camera.
        distance: eye-to-target distance, world units.
        voxel_px: width in pixels of a baseline voxel at the target.
        crop: (x0, y0, x1, y1) pixel box the errors are computed in.
    """

    label: str
    scale: float
    camera: Camera
    distance: float
    voxel_px: float
    crop: tuple[int, int, int, int]


def pixels_per_unit(size: tuple[int, int], fov: float, distance: float) -> float:
    """Image pixels spanned by one world unit at ``distance`` (vertical fov, degrees)."""
    return size[1] / (2.0 * distance * math.tan(math.radians(fov) / 2.0))


def crop_box(
    camera: Camera, bounds: np.ndarray, size: tuple[int, int], margin: int = 8, min_side: int = 16
) -> tuple[int, int, int, int]:
    """Pixel box (x0, y0, x1, y1) around the projection of the 8 corners of
    ``bounds`` (2 x 3, world units): :func:`aniso3d.metrics.screen_box`."""
    b = np.asarray(bounds, dtype=np.float64)
    corners = np.array([[b[i, 0], b[j, 1], b[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    return screen_box(camera.project(corners, size, bounds), size, margin, min_side)


def make_cameras(bounds: np.ndarray, settings: Settings) -> list[CameraSpec]:
    """The frame-filling camera, then one per footprint that lies farther away.

    A baseline voxel (edge ``longest extent / baseline resolution``) spans
    ``h * H / (2 d tan(fov / 2))`` pixels at distance d, so the distance for a
    footprint f is the frame-filling one times ``footprint_at_fill / f``.
    """
    b = np.asarray(bounds, dtype=np.float64)
    h0 = float(np.max(b[1] - b[0])) / settings.baseline["resolution"]
    fill = Camera.frame(b)
    d0 = float(np.linalg.norm(np.subtract(fill.position, fill.target)))
    fp0 = h0 * pixels_per_unit(settings.size, fill.fov, d0)
    specs = [CameraSpec("fill", 1.0, fill, d0, fp0, crop_box(fill, b, settings.size))]
    for f in sorted(set(settings.footprints), reverse=True):
        scale = fp0 / f
        if scale < 1.05:  # would not be farther than the frame-filling camera
            continue
        cam = Camera.frame(b, distance_scale=scale)
        specs.append(CameraSpec(f"{f:g}px", scale, cam, d0 * scale, f, crop_box(cam, b, settings.size)))
    return specs


def near_far(cameras: list[CameraSpec]) -> tuple[CameraSpec, CameraSpec]:
    """The one-axis blocks' cameras: frame-filling, and the one where a
    baseline voxel is one pixel wide (else the farthest)."""
    far = next((c for c in cameras if c.label == "1px"), cameras[-1])
    return cameras[0], far
