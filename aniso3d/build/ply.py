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
