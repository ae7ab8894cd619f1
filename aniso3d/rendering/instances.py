"""Per-instance choices for a :class:`~aniso3d.build.scene.Scene`, for all
instances at once in NumPy (no Python loop per instance):

- :func:`instance_spheres`: each instance's world bounding sphere and the
  largest stretch of its transform;
- :func:`visible_instances`: frustum culling of those spheres;
- :func:`instance_levels`: the pyramid level each instance is drawn from, the
  coarsest whose voxels project to at most ``pixel_error`` pixels at the front
  of the instance's sphere (the rule of :func:`~aniso3d.rendering.select.volume_level`);
- :func:`groups`: instances gathered by (asset, level), so a renderer draws
  one instanced call per group;
- :func:`instance_data`: the per-instance vertex attributes (a float32 mat4,
  column-major, and an RGBA8 tint: 68 bytes) of the instances drawn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aniso3d.errors import InputError
from aniso3d.rendering.camera import Camera

#: Bytes of one drawn instance's vertex attributes: a float32 mat4 and RGBA8.
INSTANCE_STRIDE = 64 + 4


def instance_spheres(transforms: np.ndarray, bounds) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World bounding spheres of instances of an asset whose box is ``bounds``
    (2, 3): centres (N, 3) float64, radii (N,) and ``stretch`` (N,), the
    largest singular value of each linear part (a length in the asset grows
    by at most that much). ``transforms`` (N, 4, 4)."""
    m = np.asarray(transforms, dtype=np.float64)
    b = np.asarray(bounds, dtype=np.float64)
    centre = 0.5 * (b[0] + b[1])
    half = 0.5 * float(np.linalg.norm(b[1] - b[0]))
    a = m[:, :3, :3]
    stretch = np.sqrt(largest_eigenvalue(np.einsum("nki,nkj->nij", a, a)))
    centres = _apply(a, centre) + m[:, :3, 3]
    return centres, half * stretch, stretch


def _apply(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(N, 3) ``a[n] @ v`` element-wise (a small matrix product would go to a
    threaded BLAS whose spinning threads slow the software rasteriser after)."""
    return a[:, :, 0] * v[0] + a[:, :, 1] * v[1] + a[:, :, 2] * v[2]


def largest_eigenvalue(s: np.ndarray) -> np.ndarray:
    """(N,) largest eigenvalue of symmetric (N, 3, 3) matrices, in closed form
    (the trigonometric solution of the characteristic cubic), vectorised;
    ``np.linalg.eigvalsh`` loops in LAPACK per matrix and takes ~10x longer."""
    s = np.asarray(s, dtype=np.float64)
    q = np.trace(s, axis1=1, axis2=2) / 3.0
    p1 = s[:, 0, 1] ** 2 + s[:, 0, 2] ** 2 + s[:, 1, 2] ** 2
    d = s - q[:, None, None] * np.eye(3)
    p2 = (d[:, 0, 0] ** 2 + d[:, 1, 1] ** 2 + d[:, 2, 2] ** 2) + 2.0 * p1
    p = np.sqrt(p2 / 6.0)
    safe = np.where(p > 0, p, 1.0)
    b = d / safe[:, None, None]
    det = (b[:, 0, 0] * (b[:, 1, 1] * b[:, 2, 2] - b[:, 1, 2] * b[:, 2, 1])
           - b[:, 0, 1] * (b[:, 1, 0] * b[:, 2, 2] - b[:, 1, 2] * b[:, 2, 0])
           + b[:, 0, 2] * (b[:, 1, 0] * b[:, 2, 1] - b[:, 1, 1] * b[:, 2, 0]))  # fmt: skip
    phi = np.arccos(np.clip(det / 2.0, -1.0, 1.0)) / 3.0
    return np.where(p > 0, q + 2.0 * p * np.cos(phi), q)


@dataclass(frozen=True)
class ViewCone:
    """A camera's frustum as :func:`visible_instances` tests it: eye, world ->
    eye-frame axes (columns right, up, forward), clip depths, the side planes'
    unit normals in the (lateral, depth) plane, and ``scale`` (framebuffer
    pixels per world unit at unit depth)."""

    eye: np.ndarray
    axes: np.ndarray
    near: float
    far: float
    cx: float
    sx: float
    cy: float
    sy: float
    scale: float

    @classmethod
    def of(cls, camera: Camera, size: tuple[int, int], near: float | None = None,
           far: float | None = None, caller: str = "instance selection") -> ViewCone:  # fmt: skip
        """The cone of ``camera`` for a framebuffer ``size`` (W, H); ``near``
        and ``far`` default to the camera's own, else 0 and no limit."""
        if not isinstance(camera, Camera):
            raise InputError(f"{caller} needs an aniso3d.Camera, got {type(camera).__name__}")
        w, h = int(size[0]), int(size[1])
        if w < 1 or h < 1:
            raise InputError(f"image size must be at least 1x1 pixels, got {size}")
        near = camera.near if near is None else near
        far = camera.far if far is None else far
        right, up, fwd = camera.basis()
        ty = math.tan(math.radians(camera.fov) / 2.0)
        tx = ty * w / h
        return cls(
            eye=np.asarray(camera.position, dtype=np.float64),
            axes=np.stack([right, up, fwd], axis=1),
            near=0.0 if near is None else float(near),
            far=math.inf if far is None else float(far),
            cx=1.0 / math.hypot(1.0, tx), sx=tx / math.hypot(1.0, tx),
            cy=1.0 / math.hypot(1.0, ty), sy=ty / math.hypot(1.0, ty),
            scale=h / (2.0 * ty),
        )  # fmt: skip

    def contains(self, x, y, z, rad) -> np.ndarray:
        """Which spheres (eye-frame centres x, y, z; radius rad) touch the
        frustum (the four side planes, near and far). Conservative: a sphere
        near a frustum corner may pass."""
        return (
            (z + rad >= self.near) & (z - rad <= self.far)
            & (np.abs(x) * self.cx - z * self.sx <= rad) & (np.abs(y) * self.cy - z * self.sy <= rad)
        )  # fmt: skip

    def eye_frame(self, centres: np.ndarray) -> np.ndarray:
        """(N, 3) eye-frame coordinates (x right, y up, z view depth)."""
        c = np.asarray(centres, dtype=np.float64) - self.eye
        return c[:, 0:1] * self.axes[0] + c[:, 1:2] * self.axes[1] + c[:, 2:3] * self.axes[2]


def visible_instances(centres: np.ndarray, radii: np.ndarray, cone: ViewCone) -> np.ndarray:
    """(N,) bool: which spheres touch the frustum (the four side planes, near
    and far). Conservative: a sphere near a frustum corner may pass."""
    e = cone.eye_frame(centres)
    return cone.contains(e[:, 0], e[:, 1], e[:, 2], np.asarray(radii, dtype=np.float64))


#: Splats: at most this many points per pixel of an instance's projected
#: bounding sphere (see :func:`instance_levels`): a far tree of a few pixels
#: is drawn from a level of a few points, however small its voxels are there.
POINTS_PER_PIXEL = 1.0


def instance_levels(
    centres: np.ndarray, radii: np.ndarray, stretch: np.ndarray, voxel_sizes, cone: ViewCone,
    pixel_error: float = 1.0, level_points=None, points_per_pixel: float = POINTS_PER_PIXEL,
) -> np.ndarray:  # fmt: skip
    """(N,) int64 pyramid level of each instance: the coarsest level l whose
    voxel (edge ``voxel_sizes[l]`` in the asset, times the instance's
    ``stretch`` in the world) covers at most ``pixel_error`` framebuffer
    pixels at the front of the instance's sphere (depth ``z - r``). An
    instance reaching the eye plane gets level 0; so does one no level is
    coarse enough for... i.e. every level too large. ``voxel_sizes`` (L,)
    ascending, finest first.

    With ``level_points`` (L,) (points of each level, decreasing), the level
    is also at least the finest whose points number at most
    ``points_per_pixel`` times the pixels of the sphere's projected disc
    (radius ``r scale / (z - r)``): the cost follows the pixels covered, so a
    forest seen from afar costs about what a few near trees do."""
    if not (pixel_error > 0 and math.isfinite(pixel_error)):
        raise InputError(f"pixel_error must be a positive number of pixels, got {pixel_error}")
    h = np.asarray(voxel_sizes, dtype=np.float64)
    z = cone.eye_frame(centres)[:, 2]
    front = z - np.asarray(radii, dtype=np.float64)
    safe = np.where(front > 0, front, 1.0)
    pixels = h[None, :] * (np.asarray(stretch) * cone.scale / safe)[:, None]  # (N, L)
    fine_enough = np.count_nonzero(pixels <= pixel_error, axis=1)
    level = np.maximum(fine_enough - 1, 0)
    if level_points is not None:
        if not (points_per_pixel > 0 and math.isfinite(points_per_pixel)):
            raise InputError(f"points_per_pixel must be a positive number, got {points_per_pixel}")
        n = np.asarray(level_points, dtype=np.float64)
        disc = math.pi * (np.asarray(radii, dtype=np.float64) * cone.scale / safe) ** 2
        over = np.count_nonzero(n[None, :] > (points_per_pixel * disc)[:, None], axis=1)
        level = np.maximum(level, np.minimum(over, len(n) - 1))
    return np.where(front > 0, level, 0).astype(np.int64)


def groups(levels: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """(level, instance indices ascending) for each level used: a stable sort,
    one loop step per level (never per instance)."""
    levels = np.asarray(levels, dtype=np.int64)
    if not len(levels):
        return []
    order = np.argsort(levels, kind="stable")
    used, first = np.unique(levels[order], return_index=True)
    bounds = np.append(first, len(order))
    return [(int(lvl), order[bounds[k] : bounds[k + 1]]) for k, lvl in enumerate(used)]


def back_to_front(centres: np.ndarray, cone: ViewCone) -> np.ndarray:
    """Indices of instances ordered farthest first by their centres' view depth."""
    return np.argsort(-cone.eye_frame(centres)[:, 2], kind="stable")


def instance_data(transforms: np.ndarray, tints: np.ndarray, origin, asset_origin) -> bytes:
    """Per-instance vertex data (:data:`INSTANCE_STRIDE` bytes each): the
    float32 mat4 ``T(-origin) M T(asset_origin)`` (column-major: geometry
    stored relative to ``asset_origin`` lands relative to the frame's
    ``origin``, composed in float64) and the tint as RGBA8."""
    m = np.asarray(transforms, dtype=np.float64).copy()
    a0 = np.asarray(asset_origin, dtype=np.float64)
    m[:, :3, 3] += m[:, :3, :3] @ a0 - np.asarray(origin, dtype=np.float64)
    n = len(m)
    out = np.empty(n, dtype=[("m", "<f4", (16,)), ("tint", "u1", (4,))])
    out["m"] = m.transpose(0, 2, 1).reshape(n, 16)
    out["tint"][:, :3] = tints
    out["tint"][:, 3] = 255
    return out.tobytes()


def describe_instances(stats: dict) -> str:
    """One line for a scene frame's statistics (``Renderer.last_lod_stats``):
    instances drawn and culled, instances per level, points drawn, selection time."""
    levels = " ".join(f"{lvl}:{n:,}" for lvl, n in enumerate(stats.get("instances_per_level", ())) if n)
    points = f" · {stats['points']:,} points" if "points" in stats else ""
    return (
        f"{stats['visible']:,} of {stats['instances']:,} instances ({stats['culled']:,} culled) · "
        f"instances per level {levels or 'none'}{points} · {stats['selection_ms']:.1f} ms"
    )
