"""Renderer (c): oriented points drawn as splats, the paper's method (section 3.2).

Each point is a small flat shape (square, disc or ellipse) in its tangent
plane, sized from its area, drawn perspective-exact. The modules, in the
order a frame uses them:

- :mod:`~aniso3d.rendering.splat.options`: :class:`SplatOptions` (shape, quality,
  size factor, ...) and the size of a shape per unit of ``sqrt(area)``;
- :mod:`~aniso3d.rendering.splat.geometry`: CPU geometry in float64 (tangent
  frame, Z-order) and :func:`splat_coverage_np`, the slow, obvious twin of the
  GPU coverage test;
- :mod:`~aniso3d.rendering.splat.buffers`: points on the GPU, a cloud or every
  level of a pyramid, uploaded once, and a pyramid frame's level-of-detail
  selection written to an index buffer;
- :mod:`~aniso3d.rendering.splat.culling`: per-frame CPU bounds (blocks of
  splats too wide for a point sprite, the screen box of the cloud);
- :mod:`~aniso3d.rendering.splat.pipeline`: what every pass shares (programs,
  uniforms, vertex arrays, one pass over the points, offscreen targets);
- :mod:`~aniso3d.rendering.splat.fast`: ``quality="fast"``, opaque splats shaded
  once per pixel;
- :mod:`~aniso3d.rendering.splat.coverage`: ``quality="high"`` (coverage-aware,
  anti-aliased) and ``quality="blend"``, with their resolves,
  :mod:`~aniso3d.rendering.splat.params`, their measured parameters, and
  :mod:`~aniso3d.rendering.splat.reference`, the NumPy twin of "high";
- :mod:`~aniso3d.rendering.splat.renderer`: :class:`SplatRenderer`, which
  implements :class:`~aniso3d.rendering.base.MethodRenderer` with the above.
"""

from aniso3d.rendering.splat.buffers import ATTRIB_PER_ROW, BLOCK, FLOATS_PER_POINT, GPULodPoints, GPUPoints
from aniso3d.rendering.splat.geometry import morton_order, splat_coverage_np, tangent_frame
from aniso3d.rendering.splat.options import (
    DEFAULT_ASPECT,
    DEFAULT_PUSH,
    QUALITIES,
    SHAPES,
    SQUARE_SIZE_FACTOR,
    SplatOptions,
    default_size_factor,
    shape_extent,
)
from aniso3d.rendering.splat.params import (
    AA_CLOSE,
    AA_DTYPE,
    AA_FILTER,
    AA_LAYERS,
    AA_PLANE_REACH,
    AA_REGIME,
    AA_SHADE_BOX,
    AA_SLICES,
    AA_SPAN,
    AA_SPAN_MIN,
    ACCUM_DTYPE,
)
from aniso3d.rendering.splat.renderer import SplatRenderer

__all__ = [
    "AA_CLOSE", "AA_DTYPE", "AA_FILTER", "AA_LAYERS", "AA_PLANE_REACH", "AA_REGIME", "AA_SHADE_BOX", "AA_SLICES",
    "AA_SPAN", "AA_SPAN_MIN", "ACCUM_DTYPE", "ATTRIB_PER_ROW", "BLOCK", "DEFAULT_ASPECT", "DEFAULT_PUSH",
    "FLOATS_PER_POINT",
    "GPULodPoints", "GPUPoints", "QUALITIES", "SHAPES", "SQUARE_SIZE_FACTOR", "SplatOptions",
    "SplatRenderer", "default_size_factor", "morton_order", "shape_extent", "splat_coverage_np",
    "tangent_frame",
]  # fmt: skip
