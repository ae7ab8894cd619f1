"""The one camera model of all renderers: a pinhole with a vertical field of view.

World is right-handed, y-up by default; the camera looks down its -z axis
(OpenGL convention). Matrices are built in float64 with pyrr and only cast to
float32 at upload, *after* the translation to the uploaded object's local
origin has been folded in, so coordinates far from the world origin keep
their precision (see :meth:`Camera.view_matrix`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyrr

from aniso3d.errors import InputError


@dataclass(frozen=True)
class Camera:
    """A perspective camera.

    Attributes:
        position: eye position, world units.
        target: point looked at.
        up: approximate up vector (re-orthogonalised; must not be parallel to
            the view direction).
        fov: vertical field of view, degrees, in (0, 180).
        near, far: clip distances; None = chosen from the scene's bounds by
            :meth:`clip_range`.
    """

    position: tuple[float, float, float] = (0.0, 0.0, 5.0)
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    fov: float = 40.0
    near: float | None = None
    far: float | None = None

    def __post_init__(self) -> None:
        for name in ("position", "target", "up"):
            v = np.asarray(getattr(self, name), dtype=np.float64)
            if v.shape != (3,) or not np.isfinite(v).all():
                raise InputError(f"camera {name} must be 3 finite numbers, got {getattr(self, name)}")
            object.__setattr__(self, name, tuple(float(x) for x in v))
        if not (0.0 < float(self.fov) < 180.0):
            raise InputError(f"camera fov must be in (0, 180) degrees, got {self.fov}")
        fwd = np.subtract(self.target, self.position)
        dist = np.linalg.norm(fwd)
        if dist == 0.0:
            raise InputError("camera position and target coincide; move the camera or the target")
        up = np.asarray(self.up)
        if np.linalg.norm(np.cross(fwd / dist, up)) < 1e-9 * max(np.linalg.norm(up), 1e-300):
            raise InputError("camera up vector is parallel to the view direction; choose another up")
        if self.near is not None and not (self.near > 0):
            raise InputError(f"camera near must be positive, got {self.near}")
        if self.far is not None and self.near is not None and not (self.far > self.near):
            raise InputError(f"camera far ({self.far}) must exceed near ({self.near})")

    # ------------------------------------------------------------ geometry

    @property
    def forward(self) -> np.ndarray:
        f = np.subtract(self.target, self.position)
        return f / np.linalg.norm(f)

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(right, up, forward) unit vectors, world frame."""
        f = self.forward
        r = np.cross(f, self.up)
        r /= np.linalg.norm(r)
        return r, np.cross(r, f), f

    def view_matrix(self, local_origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        """4x4 float64 world->eye matrix for geometry stored relative to
        ``local_origin`` (i.e. the uploaded vertex is ``world - local_origin``).

        The eye position is subtracted from the local origin in float64, so the
        float32 matrix only carries the small camera-relative offset.
        """
        r, u, f = self.basis()
        rot = np.eye(4)
        rot[0, :3], rot[1, :3], rot[2, :3] = r, u, -f
        offset = np.asarray(local_origin, dtype=np.float64) - np.asarray(self.position)
        trans = np.eye(4)
        trans[:3, 3] = offset
        return rot @ trans

    def clip_range(self, bounds: np.ndarray | None) -> tuple[float, float]:
        """(near, far) covering ``bounds`` (2, 3), unless given explicitly.

        Near is the distance to the bounding sphere, but never less than
        1e-4 of its radius (a camera inside the object keeps usable depth
        precision); far reaches the sphere's back.
        """
        if bounds is None:
            near, far = self.near or 0.01, self.far or 1000.0
        else:
            b = np.asarray(bounds, dtype=np.float64)
            center = 0.5 * (b[0] + b[1])
            radius = max(0.5 * float(np.linalg.norm(b[1] - b[0])), 1e-12)
            d = float(np.dot(center - np.asarray(self.position), self.forward))
            far_auto = max(d + radius * 1.01, radius * 1e-3)
            near_auto = max(d - radius * 1.01, radius * 1e-4, far_auto * 1e-6)
            near = self.near if self.near is not None else near_auto
            far = self.far if self.far is not None else far_auto
        if far <= near:
            far = near * 2.0
        return float(near), float(far)

    def projection_matrix(self, aspect: float, near: float, far: float) -> np.ndarray:
        """4x4 float64 OpenGL perspective matrix (column vectors)."""
        return np.asarray(
            pyrr.matrix44.create_perspective_projection(self.fov, aspect, near, far, dtype=np.float64)
        ).T

    def project(self, points: np.ndarray, size: tuple[int, int], bounds=None) -> np.ndarray:
        """(N, 2) pixel coordinates (x right, y down, pixel centres at +0.5) of
        world points, for an image of ``size`` = (width, height)."""
        w, h = size
        near, far = self.clip_range(bounds)
        m = self.projection_matrix(w / h, near, far) @ self.view_matrix()
        p = np.concatenate([np.asarray(points, np.float64), np.ones((len(points), 1))], axis=1) @ m.T
        ndc = p[:, :2] / p[:, 3:4]
        return np.stack([(ndc[:, 0] + 1) * 0.5 * w, (1 - ndc[:, 1]) * 0.5 * h], axis=1)

    def ray_directions(self, size: tuple[int, int]) -> np.ndarray:
        """(H, W, 3) unit world ray directions through pixel centres."""
        w, h = size
        r, u, f = self.basis()
        t = np.tan(np.radians(self.fov) / 2)
        xs = ((np.arange(w) + 0.5) / w * 2 - 1) * t * (w / h)
        ys = (1 - (np.arange(h) + 0.5) / h * 2) * t
        d = f + xs[None, :, None] * r + ys[:, None, None] * u
        return d / np.linalg.norm(d, axis=2, keepdims=True)

    # -------------------------------------------------------------- helpers

    @classmethod
    def frame(
        cls,
        bounds: np.ndarray,
        direction=(0.55, 0.35, 1.0),
        fov: float = 40.0,
        margin: float = 1.05,
        up=(0.0, 1.0, 0.0),
        distance_scale: float = 1.0,
    ) -> Camera:
        """A camera looking at the centre of ``bounds`` from ``direction`` (from
        the target towards the eye), far enough that the bounding sphere fits
        the vertical field of view; ``distance_scale`` > 1 moves it away."""
        b = np.asarray(bounds, dtype=np.float64)
        center = 0.5 * (b[0] + b[1])
        radius = max(0.5 * float(np.linalg.norm(b[1] - b[0])), 1e-12)
        d = np.asarray(direction, dtype=np.float64)
        d = d / np.linalg.norm(d)
        dist = margin * radius / np.sin(np.radians(fov) / 2) * distance_scale
        return cls(tuple(center + d * dist), tuple(center), up, fov)

    @classmethod
    def fit(
        cls,
        bounds: np.ndarray,
        direction=(0.55, 0.35, 1.0),
        fov: float = 40.0,
        aspect: float = 1.0,
        margin: float = 1.1,
        up=(0.0, 1.0, 0.0),
        distance_scale: float = 1.0,
        points: np.ndarray | None = None,
    ) -> Camera:
        """Like :meth:`frame`, but just far enough that the eight corners of
        ``bounds`` (or, tighter still, the given ``points`` (N, 3), e.g. a
        mesh's vertices) fit an image of ``aspect`` (width / height) with
        ``margin``. Looks at the centre of ``bounds`` either way."""
        base = cls.frame(bounds, direction, fov, up=up)
        b = np.asarray(bounds, dtype=np.float64)
        target = np.asarray(base.target)
        right, upv, fwd = base.basis()
        if points is None or len(points) == 0:
            corners = np.array([[x, y, z] for x in b[:, 0] for y in b[:, 1] for z in b[:, 2]])
        else:
            corners = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        corners = corners - target
        if points is not None and len(points):
            # Centre the points' extent across the view (not the box's centre,
            # which an asymmetric object such as a tree does not fill).
            x, y = corners @ right, corners @ upv
            shift = right * 0.5 * (x.max() + x.min()) + upv * 0.5 * (y.max() + y.min())
            target, corners = target + shift, corners - shift
        tan_v = np.tan(np.radians(fov) / 2)
        tan_h = tan_v * aspect
        toward_eye = corners @ -fwd
        need = np.maximum(np.abs(corners @ right) / tan_h, np.abs(corners @ upv) / tan_v) * margin
        radius = max(0.5 * float(np.linalg.norm(b[1] - b[0])), 1e-12)
        dist = max(float(np.max(toward_eye + need)), float(np.max(toward_eye)) + 1e-3 * radius)
        return cls(tuple(target - fwd * dist * distance_scale), tuple(target), up, fov)

    def orbit(self, degrees: float, axis=None) -> Camera:
        """The camera turned by ``degrees`` about ``axis`` (default: its up
        vector) through the target, keeping the distance."""
        axis = np.asarray(self.up if axis is None else axis, dtype=np.float64)
        axis /= np.linalg.norm(axis)
        rot = np.asarray(pyrr.matrix33.create_from_axis_rotation(axis, np.radians(degrees), dtype=np.float64))
        offset = np.subtract(self.position, self.target)
        # pyrr matrices act on row vectors.
        new = np.asarray(self.target) + offset @ rot
        return Camera(tuple(new), self.target, self.up, self.fov, self.near, self.far)


def turntable(camera: Camera, frames: int, degrees: float = 360.0) -> list[Camera]:
    """``frames`` cameras orbiting ``camera`` about its up axis (last frame not
    repeating the first for a full turn)."""
    if frames < 1:
        raise InputError(f"a turntable needs at least 1 frame, got {frames}")
    step = degrees / frames
    return [camera.orbit(i * step) for i in range(frames)]
