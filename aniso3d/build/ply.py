"""PLY headers: what a PLY file declares, read once for every reader.

Several questions about a ``.ply`` file are answered by its header alone:
is it a mesh or a point cloud (does it declare faces), how many faces does a
mesh file promise (trimesh reads a truncated ASCII PLY without a word), has a
point cloud normals. :func:`read_ply_header` answers them without reading the
body; the body itself is read by trimesh (meshes) or plyfile (point clouds).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from aniso3d.errors import FormatError

#: Longest header read, bytes: far more than any real PLY header needs.
MAX_HEADER_BYTES = 65536


@dataclass(frozen=True)
class PlyHeader:
    """The declarations of a PLY header.

    Attributes:
        format: "ascii", "binary_little_endian" or "binary_big_endian" (as
            written in the file).
        elements: element name -> declared count, in file order.
        properties: element name -> its property names, in file order.
    """

    format: str
    elements: dict[str, int]
    properties: dict[str, tuple[str, ...]]

    def count(self, element: str) -> int:
        """Declared count of ``element``, 0 if the header does not declare it."""
        return self.elements.get(element, 0)

    @property
    def is_point_cloud(self) -> bool:
        """True if the file declares no faces (or zero of them)."""
        return self.count("face") == 0


def read_ply_header(path: str | os.PathLike) -> PlyHeader:
    """Parse the header of the PLY file at ``path`` (which must exist and be
    readable), refusing with a :class:`~aniso3d.errors.FormatError` a file
    that is not PLY or whose header is damaged."""
    p = Path(path)
    with open(p, "rb") as fh:
        head = fh.read(MAX_HEADER_BYTES)
    if not head.startswith(b"ply"):
        raise FormatError(f"'{p}' does not start with 'ply': it is not a PLY file")
    fmt = ""
    elements: dict[str, int] = {}
    properties: dict[str, list[str]] = {}
    current = None
    for raw in head.splitlines()[1:]:
        parts = raw.decode("ascii", errors="replace").split()
        if parts == ["end_header"]:
            return PlyHeader(fmt, elements, {k: tuple(v) for k, v in properties.items()})
        if not parts:
            continue
        if parts[0] == "format" and len(parts) >= 2:
            fmt = parts[1]
        elif parts[0] == "element":
            if len(parts) != 3 or not parts[2].isdigit():
                raise FormatError(f"'{p}' has a damaged PLY header line '{' '.join(parts)}'")
            current = parts[1]
            elements[current] = int(parts[2])
            properties[current] = []
        elif parts[0] == "property":
            if current is None or len(parts) < 3:
                raise FormatError(f"'{p}' has a damaged PLY header line '{' '.join(parts)}'")
            properties[current].append(parts[-1])
    raise FormatError(
        f"'{p}' has no 'end_header' line in its first {MAX_HEADER_BYTES // 1024} KiB: "
        "its PLY header is damaged"
    )


# ------------------------------------------------------------ point clouds

#: Colour property triples other tools write, in the order they are looked for.
COLOUR_NAMES = (
    ("red", "green", "blue"),
    ("r", "g", "b"),
    ("diffuse_red", "diffuse_green", "diffuse_blue"),
)
#: Gaussian splatting's colour: the zeroth spherical-harmonic coefficient.
SH_DC_NAMES = ("f_dc_0", "f_dc_1", "f_dc_2")
NORMAL_NAMES = ("nx", "ny", "nz")
#: Gaussian splatting's rotation quaternion (w, x, y, z, not normalised).
ROTATION_NAMES = ("rot_0", "rot_1", "rot_2", "rot_3")


@dataclass(frozen=True)
class PointLayout:
    """Which vertex properties of a PLY point cloud mean what (from the
    header's names alone; :mod:`aniso3d.build.points` reads the values).

    Attributes:
        normals: ("nx", "ny", "nz"), or None.
        colour: three property names (see :data:`COLOUR_NAMES`), or None.
        sh_colour: :data:`SH_DC_NAMES` if the file is a Gaussian splat file
            without plain colours, else None.
        size: how the file gives each point's size: "area" (world units
            squared), "radius" (world units), "log_scales" (Gaussian
            splatting: natural logs of the standard deviations along the
            Gaussian's axes, ``scale_0..2``, or ``scale_0..1`` for flat
            Gaussians), or None.
        scales: the ``scale_i`` names when ``size`` is "log_scales".
        rotation: :data:`ROTATION_NAMES` if present, else None.
    """

    normals: tuple[str, ...] | None
    colour: tuple[str, ...] | None
    sh_colour: tuple[str, ...] | None
    size: str | None
    scales: tuple[str, ...]
    rotation: tuple[str, ...] | None


def point_layout(names: tuple[str, ...]) -> PointLayout:
    """The :class:`PointLayout` of a vertex element with property ``names``."""
    have = set(names)

    def all_of(group):
        return tuple(group) if all(c in have for c in group) else None

    colour = next((g for g in COLOUR_NAMES if all_of(g)), None)
    scales = tuple(n for n in ("scale_0", "scale_1", "scale_2") if n in have)
    if len(scales) == 1 or (len(scales) == 2 and scales != ("scale_0", "scale_1")):
        scales = ()
    size = "area" if "area" in have else "radius" if "radius" in have else "log_scales" if scales else None
    return PointLayout(
        normals=all_of(NORMAL_NAMES),
        colour=colour,
        sh_colour=None if colour else all_of(SH_DC_NAMES),
        size=size,
        scales=scales if size == "log_scales" else (),
        rotation=all_of(ROTATION_NAMES),
    )
