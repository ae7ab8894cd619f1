"""Stage 4: oriented points, the splat renderer's primitive (paper section 3.1).

A :class:`PointCloud` is a plain data object: each point is a small oriented
surface element with an area and a Phong material. aniso3d makes them from an
:class:`~aniso3d.build.texture.AnisoTexture` (``texture.to_points()``), and reads and
writes them as binary PLY that other tools (trimesh, MeshLab, CloudCompare)
open, and reads the point clouds those tools, scanners and Gaussian-splatting
programs write (:meth:`PointCloud.load_ply`, docs/point_clouds.md).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import plyfile

from aniso3d.build.mesh import DEFAULT_KD, DEFAULT_KS, DEFAULT_SHININESS, MAX_SHININESS, check_readable_file
from aniso3d.build.ply import point_layout, read_ply_header
from aniso3d.build.spacing import COVERAGE, DEFAULT_K, local_spacing, nearest_neighbours, pca_normals
from aniso3d.errors import FormatError, InputError
from aniso3d.files import atomic_write


@dataclass(frozen=True, eq=False)
class PointCloud:
    """Oriented, sized, shaded points.

    Attributes:
        positions: (N, 3) float64, world units.
        normals: (N, 3) float32 unit normals (lighting is two-sided, so the sign
            only matters for point placement, not shading).
        areas: (N,) float64 splat area in world units squared (a splat's
            radius is ``sqrt(area / pi)``); the areas of the points made from
            a texture sum to the mesh's area; a cloud read without sizes gets
            overlapping splats from its spacing (:mod:`aniso3d.build.spacing`).
        kd: (N, 3) float32 diffuse reflectance in [0, 1].
        ks: (N,) float32 specular coefficient.
        shininess: (N,) float32 Phong exponent.
        name: label used in reports.
        coherence: (N,) float32 in [0, 1], the length of the area-weighted
            mean unit normal of the facets a point stands for (1: one plane;
            None gives 1 everywhere, as for a scanned cloud); the lighting
            model shades the normals' spread from it
            (:func:`~aniso3d.rendering.lighting.shade_np`).
        one_sided: (N,) bool, the point stands for a piece of a closed
            surface and its normal points out of it, so its back is never
            seen: the renderers drop it where it faces away from the eye
            (at a silhouette it would cover the pixels the front covers
            again). None: every point two-sided, as for a scanned cloud.
        clips: (N, 2, 5) float64, up to two half-spaces ``m . x <= o`` each
            point's splat is cut to, rows ``(m, o, phi)`` with ``m`` a
            coordinate axis or its opposite (world units), ``m = 0`` for
            none: the faces of its voxel where the surface it stands for
            ends; ``phi`` (radians), where another surface meets it there,
            that surface's angle about the edge from the point's own,
            ``cos(phi) u + sin(phi) n`` (``u`` in the splat's plane from the
            edge towards its centre, ``n`` its normal), 0 where none does.
            Made by the renderer from the texture
            (:mod:`aniso3d.rendering.splat.clips`); None: no point is cut,
            as for a scanned cloud or the points ``to_points`` makes.
        sheet: (N,) bool, the point stands for a piece of a surface sheet:
            its facets fill their plane's section of the voxel, a surface
            that goes on into the neighbours (the volume renderer's
            :data:`~aniso3d.rendering.volume.RUN_SHARE`), not a leaf or a
            blade inside it. Quality "high" takes such a splat's surface
            to reach across a pixel's depth as a closed surface's does.
            Made by the renderer from the texture
            (:mod:`aniso3d.rendering.splat.clips`); None: no point is.
    """

    positions: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    kd: np.ndarray
    ks: np.ndarray
    shininess: np.ndarray
    name: str = "points"
    coherence: np.ndarray | None = None
    one_sided: np.ndarray | None = None
    clips: np.ndarray | None = None
    sheet: np.ndarray | None = None

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
        if self.coherence is None:
            coh = np.ones(n, dtype=np.float32)
        else:
            coh = np.asarray(self.coherence, dtype=np.float32)
            if coh.shape != (n,):
                raise InputError(f"point coherence must have shape ({n},), got {coh.shape}")
            if n and not np.isfinite(coh).all():
                raise InputError("point coherence holds NaN or Inf values")
        object.__setattr__(self, "coherence", np.clip(coh, 0.0, 1.0))
        if self.one_sided is not None:
            one = np.asarray(self.one_sided)
            if one.shape != (n,) or one.dtype != bool:
                raise InputError(f"point one_sided must be a ({n},) bool array, got {one.dtype} {one.shape}")
            object.__setattr__(self, "one_sided", None if not one.any() else one.copy())
        if self.clips is not None:
            cl = np.asarray(self.clips, dtype=np.float64)
            if cl.shape != (n, 2, 5):
                raise InputError(f"point clips must have shape ({n}, 2, 5), got {cl.shape}")
            if n and not np.isfinite(cl).all():
                raise InputError("point clips hold NaN or Inf values")
            m = np.abs(cl[..., :3])
            axis_like = ((m == 0.0).sum(-1) >= 2) & np.isin(m.sum(-1), (0.0, 1.0))
            if n and not axis_like.all():
                raise InputError("point clip normals must be a coordinate axis, its opposite, or 0 (no clip)")
            object.__setattr__(self, "clips", None if not m.any() else cl)
        if self.sheet is not None:
            sheet = np.asarray(self.sheet)
            if sheet.shape != (n,) or sheet.dtype != bool:
                raise InputError(f"point sheet must be a ({n},) bool array, got {sheet.dtype} {sheet.shape}")
            object.__setattr__(self, "sheet", None if not sheet.any() else sheet.copy())
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
        RGB, ks, n = 12 floats per point (the coherence rides as the uploaded
        normal's length), and for each point with clip planes 18 more: its
        12 again and its two planes (each an axis code, an offset and an
        angle), quality "high" drawing those points apart
        (aniso3d.rendering.splat.buffers.GPUPoints.cut)."""
        n = len(self)
        if self.clips is None:
            return int(n * 12 * 4)
        cut = int(np.any(self.clips[..., :3] != 0, axis=(1, 2)).sum())
        return int((n * 12 + cut * 18) * 4)

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
    def load_ply(
        cls,
        path: str | os.PathLike,
        default_area: float | None = None,
        *,
        splat_size: float | None = None,
        splat_scale: float = 1.0,
        estimate_normals: bool = False,
        k: int = DEFAULT_K,
    ) -> PointCloud:
        """Read a PLY point cloud (ours or another tool's; docs/point_clouds.md).

        Sizes, in order: ``splat_size`` if given (one radius for every point,
        world units); else the file's ``area`` (world units squared), its
        ``radius`` (area ``pi r^2``) or Gaussian splatting's log-scales
        ``scale_0..2`` (area ``2 pi s_a s_b`` of the two largest standard
        deviations, the integral of the Gaussian over its plane); else
        ``default_area`` if given; else each point's radius from the spacing
        of its ``k`` nearest neighbours (:func:`~aniso3d.build.spacing.splat_radii`),
        so that a randomly sampled surface shows no holes. ``splat_scale``
        then multiplies every radius.

        Normals: ``nx ny nz``; where they are missing or zero, a Gaussian
        splat's thinnest axis (from ``rot_0..3`` and its scales), else, with
        ``estimate_normals``, the least-squares plane of the point and its
        ``k`` nearest neighbours (:func:`~aniso3d.build.spacing.pca_normals`);
        otherwise an :class:`~aniso3d.errors.InputError` says how to get them.

        Colours: ``red green blue``, ``r g b`` or ``diffuse_red ...``,
        integers scaled by their type's maximum (255 for uchar), floats taken
        as 0..1 (as 0..255 if any exceeds 1); alpha is ignored (splats are
        opaque); a Gaussian splat's ``f_dc_0..2`` as ``0.5 + C0 f_dc``; else
        :data:`~aniso3d.build.mesh.DEFAULT_KD`. ``ks`` and ``shininess`` are
        read when present.
        """
        p = check_readable_file(path, "point cloud")
        # The header says what the file holds before its body is read.
        names = read_ply_header(p).properties.get("vertex")
        if names is None:
            raise FormatError(f"'{p}' has no PLY vertex element; is it a PLY point cloud?")
        if not all(c in names for c in ("x", "y", "z")):
            raise FormatError(f"'{p}' vertices have no x, y, z properties")
        layout = point_layout(names)
        gaussian_axes = layout.rotation is not None and layout.size == "log_scales"
        if layout.normals is None and not gaussian_axes and not estimate_normals:
            raise InputError(_no_normals(p, "has no normals (nx, ny, nz)"))
        for label, value in (("splat_size", splat_size), ("default_area", default_area)):
            if value is not None and not (0 < value < math.inf):
                raise InputError(f"{label} must be a positive, finite number, got {value}")
        if not (0 < splat_scale < math.inf):
            raise InputError(f"splat_scale must be a positive, finite number, got {splat_scale}")
        if splat_size is not None and default_area is not None:
            raise InputError("give splat_size (a radius) or default_area, not both")
        try:
            # Mapped (copy-on-write), binary bodies are read as one array; without
            # the map plyfile reads them value by value (25 s for 1M points).
            vertex = plyfile.PlyData.read(str(p), mmap="c")["vertex"].data
        except Exception as exc:  # plyfile raises several types for damaged files
            raise FormatError(f"could not read PLY '{p}': {type(exc).__name__}: {exc}") from None

        def col(name):  # a copy, so that nothing keeps the file mapped
            return np.array(vertex[name], dtype=np.float64).reshape(-1)

        pos = np.stack([col("x"), col("y"), col("z")], axis=1)
        n = len(pos)
        if n == 0:
            raise InputError(f"'{p}' holds no points")
        bad = ~np.isfinite(pos).all(axis=1)
        if bad.any():
            raise InputError(f"'{p}' has {int(bad.sum())} points with NaN or Inf coordinates; remove them first")

        nrm = np.stack([col(c) for c in layout.normals], axis=1) if layout.normals else np.zeros((n, 3))
        if gaussian_axes:
            missing = ~(np.linalg.norm(nrm, axis=1) > 1e-12)
            if missing.any():
                log_scales = np.stack([col(c) for c in layout.scales], axis=1)[missing]
                nrm[missing] = _gaussian_normals(np.stack([col(c) for c in layout.rotation], 1)[missing], log_scales)

        size_from_file = splat_size is None and layout.size is not None
        missing = ~(np.linalg.norm(nrm, axis=1) > 1e-12)
        need_spacing = splat_size is None and layout.size is None and default_area is None
        neighbours = None
        if need_spacing or (missing.any() and estimate_normals):
            if n < 2:
                raise InputError(f"'{p}' holds one point: it has no spacing; give it a size (splat_size)")
            neighbours = nearest_neighbours(pos, min(k, n - 1))
        if missing.any():
            if not estimate_normals:
                raise InputError(_no_normals(p, f"has {int(missing.sum())} points with a zero normal"))
            nrm[missing] = pca_normals(pos, neighbours[1])[missing]

        if layout.colour:
            kd = _colours(vertex, layout.colour)
        elif layout.sh_colour:
            kd = 0.5 + SH_C0 * np.stack([col(c) for c in layout.sh_colour], axis=1)
        else:
            kd = np.tile(DEFAULT_KD, (n, 1))
        if not np.isfinite(kd).all():
            bad = int((~np.isfinite(kd).all(axis=1)).sum())
            raise InputError(f"'{p}' has {bad} points with NaN or Inf colours; fix or drop its colour properties")
        ks = col("ks") if "ks" in names else np.full(n, DEFAULT_KS)
        sh = col("shininess") if "shininess" in names else np.full(n, DEFAULT_SHININESS)

        if splat_size is not None:
            areas = np.full(n, math.pi * splat_size**2)
        elif size_from_file and layout.size == "area":
            areas = col("area")
        elif size_from_file and layout.size == "radius":
            areas = math.pi * col("radius") ** 2
        elif size_from_file:
            sigma = np.sort(np.exp(np.stack([col(c) for c in layout.scales], axis=1)), axis=1)
            areas = 2.0 * math.pi * sigma[:, -1] * sigma[:, -2]
        elif default_area is not None:
            areas = np.full(n, float(default_area))
        else:
            radius = COVERAGE * local_spacing(neighbours[0])
            if not radius.max() > 0:
                raise InputError(f"all {n} points of '{p}' coincide: they have no spacing; give a size (splat_size)")
            # A point with k duplicates has no spacing of its own: the cloud's typical one.
            radius[radius == 0] = np.median(radius[radius > 0])
            areas = math.pi * radius**2
        return cls(pos, nrm, areas * splat_scale**2, kd, ks, sh, name=p.stem)


#: Zeroth-order spherical-harmonic constant, 1 / (2 sqrt(pi)): Gaussian
#: splatting's colour is 0.5 + SH_C0 * f_dc.
SH_C0 = 0.28209479177387814


def _no_normals(path: Path, what: str) -> str:
    return (
        f"'{path}' {what}: splats need an orientation. Estimate them from the neighbours "
        "(PointCloud.load_ply(..., estimate_normals=True), or --estimate-normals on the command line) "
        "or in another tool (Open3D estimate_normals, MeshLab 'Compute normals for point sets')"
    )


def _colours(vertex: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
    """(N, 3) float64 colours in [0, 1] from three colour properties:
    integers over their type's maximum, floats as they are (over 255 if any
    exceeds 1)."""
    rgb = np.stack([np.array(vertex[c], dtype=np.float64).reshape(-1) for c in names], axis=1)
    dtype = vertex.dtype[names[0]]
    if np.issubdtype(dtype, np.integer):
        return rgb / float(np.iinfo(dtype).max)
    finite = rgb[np.isfinite(rgb)]
    return rgb / 255.0 if finite.size and finite.max() > 1.0 else rgb


def _gaussian_normals(quaternions: np.ndarray, log_scales: np.ndarray) -> np.ndarray:
    """(M, 3) normals of Gaussian splats: the rotated axis of the smallest
    scale (``scale_0..2``), or the third axis (flat ``scale_0..1``); zero
    where the quaternion (w, x, y, z) is zero."""
    q = quaternions / np.maximum(np.linalg.norm(quaternions, axis=1, keepdims=True), 1e-300)
    w, x, y, z = q.T
    rot = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )  # (M, 3, 3), rows of the rotation matrix
    axis = np.argmin(log_scales, axis=1) if log_scales.shape[1] == 3 else np.full(len(q), 2)
    return rot[np.arange(len(q)), :, axis]
