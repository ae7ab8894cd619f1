"""The one lighting model shared by the three renderers.

Ambient + Lambert diffuse + Phong specular from directional lights, two-sided.
``shaders/lighting.glsl`` implements :func:`shade_np` for the GPU; the NumPy
twin is the reference the tests hold the shaders to.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from aniso3d.errors import InputError

MAX_LIGHTS = 4


@dataclass(frozen=True)
class Light:
    """A directional light. ``direction`` points from the scene towards the light."""

    direction: tuple[float, float, float] = (0.4, 0.8, 0.45)
    color: tuple[float, float, float] = (0.85, 0.85, 0.85)


def _default_lights() -> tuple[Light, ...]:
    return (Light((0.4, 0.8, 0.45), (0.85, 0.85, 0.8)), Light((-0.6, 0.2, -0.5), (0.25, 0.25, 0.3)))


@dataclass(frozen=True)
class Lighting:
    """Ambient term and up to :data:`MAX_LIGHTS` directional lights, and the
    background colour the renderers clear to."""

    ambient: tuple[float, float, float] = (0.22, 0.22, 0.24)
    lights: tuple[Light, ...] = field(default_factory=_default_lights)
    background: tuple[float, float, float] = (1.0, 1.0, 1.0)

    def __post_init__(self) -> None:
        if len(self.lights) > MAX_LIGHTS:
            raise InputError(f"at most {MAX_LIGHTS} lights are supported, got {len(self.lights)}")
        for light in self.lights:
            d = np.asarray(light.direction, dtype=np.float64)
            if d.shape != (3,) or not np.isfinite(d).all() or np.linalg.norm(d) == 0:
                raise InputError(f"light direction must be a non-zero 3-vector, got {light.direction}")

    def directions(self) -> np.ndarray:
        d = np.array([light.direction for light in self.lights], dtype=np.float64).reshape(-1, 3)
        return d / np.linalg.norm(d, axis=1, keepdims=True) if len(d) else d

    def colors(self) -> np.ndarray:
        return np.array([light.color for light in self.lights], dtype=np.float64).reshape(-1, 3)

    def uniforms(self) -> dict[str, object]:
        """Values for the uniforms declared in ``lighting.glsl``."""
        dirs = np.zeros((MAX_LIGHTS, 3), np.float32)
        cols = np.zeros((MAX_LIGHTS, 3), np.float32)
        dirs[: len(self.lights)] = self.directions()
        cols[: len(self.lights)] = self.colors()
        return {
            "u_ambient": tuple(float(x) for x in self.ambient),
            "u_num_lights": len(self.lights),
            "u_light_dir": [tuple(map(float, r)) for r in dirs],
            "u_light_color": [tuple(map(float, r)) for r in cols],
        }


def shade_np(
    normal: np.ndarray,
    view: np.ndarray,
    kd: np.ndarray,
    ks: np.ndarray,
    shininess: np.ndarray,
    lighting: Lighting,
) -> np.ndarray:
    """(N, 3) shaded colours; ``normal`` (N, 3) any sign, ``view`` (N, 3) unit
    vectors from the surface to the eye. Mirrors ``shade()`` in lighting.glsl."""
    n = np.asarray(normal, dtype=np.float64)
    v = np.broadcast_to(np.asarray(view, dtype=np.float64), n.shape)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(length > 0, n / np.where(length > 0, length, 1), v)
    n = np.where((np.sum(n * v, axis=1) < 0)[:, None], -n, n)
    kd = np.broadcast_to(np.asarray(kd, dtype=np.float64), n.shape)
    ks = np.broadcast_to(np.asarray(ks, dtype=np.float64), n.shape[:1])
    sh = np.broadcast_to(np.asarray(shininess, dtype=np.float64), n.shape[:1])
    color = np.asarray(lighting.ambient, dtype=np.float64) * kd
    for l_dir, l_col in zip(lighting.directions(), lighting.colors(), strict=True):
        ndl = n @ l_dir
        lit = ndl > 0
        r = 2.0 * ndl[:, None] * n - l_dir
        rv = np.maximum(np.sum(r * v, axis=1), 0.0)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            spec = np.where(sh > 0, np.power(rv, sh), 1.0)
        term = kd * ndl[:, None] + (ks * spec)[:, None]
        color = color + np.where(lit[:, None], l_col * term, 0.0)
    return color
