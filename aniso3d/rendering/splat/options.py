"""Splat draw options (:class:`SplatOptions`) and the size of a splat's shape.

Each point is a small flat shape in its tangent plane, sized from its area:

- ``square`` (the paper's): side ``sqrt(area) * size_factor``;
- ``disc``: radius ``sqrt(area / pi) * size_factor``;
- ``ellipse``: the disc stretched by ``sqrt(aspect)`` along the point's first
  tangent axis and shrunk by as much along the second (same area). A
  :class:`~aniso3d.build.points.PointCloud` carries no anisotropy, so the axis is a
  fixed function of the normal (:func:`~aniso3d.rendering.splat.geometry.tangent_frame`,
  the convention ``texture.to_points`` spreads points with) and ``aspect`` is an
  option; the ellipse is a well-defined shape, not a view-dependent stretch.

``size_factor`` > 1 makes neighbouring splats overlap so the surface closes;
the defaults (:func:`default_size_factor`: 1.3 for squares, 1.25 for discs,
1.40 for ellipses of aspect 2) come from measuring holes and overhang against
the supersampled polygon model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from aniso3d.rendering.base import DrawOptions, choice, number

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
#: splat's larger half-axis, along the view axis: in "blend", splats of the
#: front surface within this depth of the nearest one blend and farther ones
#: are hidden; in "high", one surface spans AA_SPAN times this times a typical
#: splat's larger half-axis (splats within it add, surfaces beyond compose).
DEFAULT_PUSH = 1.0


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


@dataclass(frozen=True)
class SplatOptions(DrawOptions):
    """How splats are drawn (see :mod:`aniso3d.rendering.splat`).

    Attributes:
        splat: the shape, one of :data:`SHAPES`.
        quality: "fast" (one splat per pixel, shaded once), "high"
            (coverage-aware, anti-aliased) or "blend" (weighted blending).
        size_factor: linear scale of the shape over its area-equivalent size;
            None (given) is :func:`default_size_factor` (what it holds after
            construction).
        aspect: major over minor axis of ``ellipse`` splats, >= 1.
        push: visibility push-back of "high" and "blend", in units of a
            splat's larger half-axis, >= 0; in "high" also the depth one
            surface spans (times ``AA_SPAN`` and a typical splat's).
        pixel_error: level-of-detail uploads only: the largest a drawn voxel
            may be on screen, framebuffer pixels (None: 1).
    """

    what: ClassVar[str] = "splat"

    splat: str = "square"
    quality: str = "fast"
    size_factor: float | None = None
    aspect: float = DEFAULT_ASPECT
    push: float = DEFAULT_PUSH
    pixel_error: float | None = None

    def __post_init__(self) -> None:
        choice(self.splat, SHAPES, "splat shape")
        choice(self.quality, QUALITIES, "splat quality")
        aspect = number(self.aspect, "splat option aspect (major over minor axis)", 1, False)
        size_factor = default_size_factor(self.splat, aspect) if self.size_factor is None else self.size_factor
        object.__setattr__(self, "aspect", aspect)
        object.__setattr__(self, "size_factor", number(size_factor, "splat option size_factor", 0, True))
        object.__setattr__(self, "push", number(self.push, "splat option push", 0, False))
        if self.pixel_error is not None:
            object.__setattr__(
                self, "pixel_error", number(self.pixel_error, "splat option pixel_error (pixels)", 0, True)
            )

    @property
    def extent(self) -> tuple[float, float]:
        """Half-axes of the shape per unit of ``sqrt(area)`` (:func:`shape_extent`)."""
        return shape_extent(self.splat, self.size_factor, self.aspect)
