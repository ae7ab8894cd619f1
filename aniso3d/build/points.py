"""Stage 4: oriented points, the splat renderer's primitive (paper section 3.1).

A :class:`PointCloud` is a plain data object: each point is a small oriented
surface element with an area and a Phong material. aniso3d makes them from an
:class:`~aniso3d.build.texture.AnisoTexture` (``texture.to_points()``), and reads and
writes them as binary PLY that other tools (trimesh, MeshLab, CloudCompare)
open.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import plyfile

from aniso3d.build.mesh import DEFAULT_KD, DEFAULT_KS, DEFAULT_SHININESS, MAX_SHININESS, check_readable_file
from aniso3d.build.ply import read_ply_header
from aniso3d.errors import FormatError, InputError
from aniso3d.files import atomic_write


@dataclass(frozen=True, eq=False)
class PointCloud:
    """Oriented, sized, shaded points.

    Attributes:
        positions: (N, 3) float64, world units.
        normals: (N, 3) float32 unit normals (lighting is two-sided, so the sign
            only matters for point placement, not shading).
        areas: (N,) float64 splat area in world units squared; the areas of the
            points made from a texture sum to the mesh's area.
        kd: (N, 3) float32 diffuse reflectance in [0, 1].
        ks: (N,) float32 specular coefficient.
        shininess: (N,) float32 Phong exponent.
        name: label used in reports.
    """

    positions: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    kd: np.ndarray
    ks: np.ndarray
    shininess: np.ndarray
    name: str = "points"

    def __post_init__(self) -> None:
        p = np.ascontiguousarray(self.positions, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3:
            raise InputError(f"point positions must have shape (N, 3), got {p.shape}")
        n = len(p)
        nrm = np.asarray(self.normals, dtype=np.float64)
        if nrm.shape != (n, 3):
            raise InputError(f"point normals must have shape ({n}, 3), got {nrm.shape}")
        length = np.linalg.norm(nrm, axis=1)
        if n and not (np.isfinite(p).all() and np.isfinite(nrm).all()):
            raise InputError("point cloud has NaN or Inf positions or normals")
        if n and np.any(length < 1e-12):
            raise InputError(
                f"{int(np.count_nonzero(length < 1e-12))} points have a zero normal; "
                "splats need an orientation (recompute normals, e.g. in MeshLab)"
            )
        nrm = nrm / np.where(length > 0, length, 1.0)[:, None]
        areas = np.asarray(self.areas, dtype=np.float64)
        if areas.shape != (n,):
            raise InputError(f"point areas must have shape ({n},), got {areas.shape}")
        if n and (not np.isfinite(areas).all() or areas.min() < 0):
            raise InputError("point areas must be finite and non-negative")
        kd = np.broadcast_to(np.asarray(self.kd, dtype=np.float32), (n, 3))
        ks = np.broadcast_to(np.asarray(self.ks, dtype=np.float32), (n,))
        sh = np.broadcast_to(np.asarray(self.shininess, dtype=np.float32), (n,))
        object.__setattr__(self, "positions", p)
        object.__setattr__(self, "normals", nrm.astype(np.float32))
        object.__setattr__(self, "areas", areas)
        object.__setattr__(self, "kd", np.clip(kd, 0, 1).astype(np.float32))
        object.__setattr__(self, "ks", np.clip(ks, 0, 1).astype(np.float32))
        object.__setattr__(self, "shininess", np.clip(sh, 0, MAX_SHININESS).astype(np.float32))

    def __len__(self) -> int:
        return len(self.positions)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) min and max corner, grown by each splat's radius."""
        if len(self) == 0:
            raise InputError("an empty point cloud has no bounds")
        r = np.sqrt(self.areas / np.pi)[:, None]
        return np.stack([(self.positions - r).min(0), (self.positions + r).max(0)])

    @property
    def nbytes(self) -> int:
        """Bytes as uploaded for rendering: float32 position, normal, radius,
        RGB, ks, n = 12 floats per point."""
        return int(len(self) * 12 * 4)

    def total_area(self) -> float:
        return float(self.areas.sum())

    # ------------------------------------------------------------------ PLY

    def save_ply(self, path: str | os.PathLike) -> Path:
        """Write binary little-endian PLY: x y z nx ny nz red green blue (uchar),
        plus the properties ``area``, ``ks`` and ``shininess`` (float)."""
        n = len(self)
        dt = np.dtype(
            [
                ("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                ("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4"),
                ("red", "u1"), ("green", "u1"), ("blue", "u1"),
                ("area", "<f4"), ("ks", "<f4"), ("shininess", "<f4"),
            ]
        )  # fmt: skip
        rec = np.empty(n, dtype=dt)
        # PLY stores float32; positions are written relative to nothing, so very
        # far-off clouds lose precision here, as in every PLY tool.
        for i, c in enumerate("xyz"):
            rec[c] = self.positions[:, i]
            rec["n" + c] = self.normals[:, i]
        rgb = np.round(self.kd * 255).astype(np.uint8)
        rec["red"], rec["green"], rec["blue"] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
        rec["area"] = self.areas
        rec["ks"] = self.ks
        rec["shininess"] = self.shininess
        header = "\n".join(
            ["ply", "format binary_little_endian 1.0", "comment aniso3d point cloud",
             f"element vertex {n}"]
            + [f"property {'uchar' if dt[name] == np.uint8 else 'float'} {name}"
               for name in dt.names]
            + ["end_header"]
        ) + "\n"  # fmt: skip
        return atomic_write(path, header.encode("ascii") + rec.tobytes())

    @classmethod
    def load_ply(cls, path: str | os.PathLike, default_area: float | None = None) -> PointCloud:
        """Read a PLY point cloud with normals (ours or another tool's).

        Colours default to :data:`~aniso3d.build.mesh.DEFAULT_KD`. Files without an
        ``area`` property get one from ``default_area`` or, if that is None,
        from the mean spacing of the points (a square of the nearest-neighbour
        distance estimated from the bounding box and count).
        """
        p = check_readable_file(path, "point cloud")
        # The header says what the file holds before its body is read.
        names = read_ply_header(p).properties.get("vertex")
        if names is None:
            raise FormatError(f"'{p}' has no PLY vertex element; is it a PLY point cloud?")
        if not all(c in names for c in ("x", "y", "z")):
            raise FormatError(f"'{p}' vertices have no x, y, z properties")
        if not all(c in names for c in ("nx", "ny", "nz")):
            raise InputError(
                f"'{p}' has no normals (nx, ny, nz): splats need an orientation. "
                "Estimate normals first (e.g. Open3D estimate_normals or MeshLab)"
            )
        try:
            vertex = plyfile.PlyData.read(str(p), mmap=False)["vertex"].data
        except Exception as exc:  # plyfile raises several types for damaged files
            raise FormatError(f"could not read PLY '{p}': {type(exc).__name__}: {exc}") from None

        def col(name):
            return np.asarray(vertex[name], dtype=np.float64).reshape(-1)

        pos = np.stack([col("x"), col("y"), col("z")], axis=1)
        nrm = np.stack([col("nx"), col("ny"), col("nz")], axis=1)
        n = len(pos)
        if n == 0:
            raise InputError(f"'{p}' holds no points")
        if all(c in names for c in ("red", "green", "blue")):
            rgb = np.stack([col("red"), col("green"), col("blue")], axis=1)
            kd = rgb / (255.0 if np.issubdtype(vertex.dtype["red"], np.integer) else 1.0)
        else:
            kd = np.tile(DEFAULT_KD, (n, 1))
        ks = col("ks") if "ks" in names else np.full(n, DEFAULT_KS)
        sh = col("shininess") if "shininess" in names else np.full(n, DEFAULT_SHININESS)
        if "area" in names:
            areas = col("area")
        else:
            if default_area is None:
                finite = pos[np.isfinite(pos).all(axis=1)]
                ext = np.ptp(finite, axis=0) if len(finite) else np.ones(3)
                ext = np.sort(ext)[::-1]
                # points on a surface: spacing ~ sqrt(surface extent / N)
                surf = max(ext[0] * ext[1], ext[0] ** 2 * 1e-6, 1e-300)
                default_area = 2.0 * surf / max(n, 1)
            areas = np.full(n, float(default_area))
        return cls(pos, nrm, areas, kd, ks, sh, name=p.stem)
