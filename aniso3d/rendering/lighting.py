"""The one lighting model shared by the three renderers.

Ambient + Lambert diffuse + Phong specular from directional lights, two-sided.
``shaders/lighting.glsl`` implements :func:`shade_np` for the GPU; the NumPy
twin is the reference the tests hold the shaders to.

An entry of a texture, or a point made from one, stands for many facets; the
length of their area-weighted mean unit normal (its *coherence*, 1 for one
plane) says how far their normals spread. With :attr:`Lighting.normal_spread`
the model shades that spread (a wider, dimmer-peaked specular lobe after
Toksvig, and the diffuse term averaged over the spread): see lighting.glsl and
docs/shading.md.
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
    """Ambient term and up to :data:`MAX_LIGHTS` directional lights, the
    background colour the renderers clear to, and whether the texture
    renderers shade their entries' normal spread (``normal_spread``)."""

    ambient: tuple[float, float, float] = (0.22, 0.22, 0.24)
    lights: tuple[Light, ...] = field(default_factory=_default_lights)
    background: tuple[float, float, float] = (1.0, 1.0, 1.0)
    #: Shade the spread of an aggregate's normals (its coherence, see
    #: :func:`shade_np`); off: every entry and point is shaded as one plane.
    normal_spread: bool = True

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
            "u_normal_spread": int(bool(self.normal_spread)),
        }


def shade_np(
    normal: np.ndarray,
    view: np.ndarray,
    kd: np.ndarray,
    ks: np.ndarray,
    shininess: np.ndarray,
    lighting: Lighting,
    coherence: np.ndarray | float | None = None,
) -> np.ndarray:
    """(N, 3) shaded colours; ``normal`` (N, 3) any sign, ``view`` (N, 3) unit
    vectors from the surface to the eye. Mirrors ``shade()`` in lighting.glsl.

    ``coherence`` (N,) or a scalar in [0, 1]: the length of the area-weighted
    mean of the unit normals the sample stands for (None or 1: one plane, the
    plain closed form). Used when ``lighting.normal_spread`` is on: the
    diffuse term becomes the mean of ``max(0, n_i . l)`` over normals whose
    ``n . l`` spreads uniformly about ``c (n . l)`` with variance
    ``(1 - c)(1 - (n . l)^2)``, and the Phong exponent Toksvig's
    ``s' = c s / (c + 4 s (1 - c))`` (the reflected vector turns twice as far
    as the normal) with the lobe's energy kept, ``(1 + s') / (1 + s)``.
    """
    n = np.asarray(normal, dtype=np.float64)
    v = np.broadcast_to(np.asarray(view, dtype=np.float64), n.shape)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(length > 0, n / np.where(length > 0, length, 1), v)
    n = np.where((np.sum(n * v, axis=1) < 0)[:, None], -n, n)
    kd = np.broadcast_to(np.asarray(kd, dtype=np.float64), n.shape)
    ks = np.broadcast_to(np.asarray(ks, dtype=np.float64), n.shape[:1])
    sh = np.broadcast_to(np.asarray(shininess, dtype=np.float64), n.shape[:1])
    if coherence is None or not lighting.normal_spread:
        c = np.ones(len(n))
    else:
        c = np.clip(np.broadcast_to(np.asarray(coherence, dtype=np.float64), n.shape[:1]), 0.0, 1.0)
    spread = 1.0 - c
    rough = spread > 0
    s = np.where(rough, c * sh / np.maximum(c + 4.0 * sh * spread, 1e-30), sh)
    energy = np.where(rough, (1.0 + s) / (1.0 + sh), 1.0)
    color = np.asarray(lighting.ambient, dtype=np.float64) * kd
    for l_dir, l_col in zip(lighting.directions(), lighting.colors(), strict=True):
        ndl = n @ l_dir
        lit = ndl > 0
        mu = c * ndl
        a = np.sqrt(3.0 * spread * np.maximum(1.0 - ndl * ndl, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            part = np.where(mu >= a, mu, np.where(mu <= -a, 0.0, (mu + a) ** 2 / (4.0 * a)))
        diffuse = np.where(rough, part, np.maximum(ndl, 0.0))
        r = 2.0 * ndl[:, None] * n - l_dir
        rv = np.maximum(np.sum(r * v, axis=1), 0.0)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            spec = np.where(lit, energy * np.where(s > 0, np.power(rv, s), 1.0), 0.0)
        color = color + l_col * (kd * diffuse[:, None] + (ks * spec)[:, None])
    return color
