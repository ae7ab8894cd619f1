"""Triangles in chunks: meshes in memory, and mesh files read piece by piece.

A *triangle source* tells how many faces it has and the bounds of the
vertices they use, and reads any run of faces ``[start, stop)`` as a
:class:`~aniso3d.build.stream.TriangleChunk` (corners and per-face material).
The streaming build (:mod:`aniso3d.build.stream`) fixes the grid from the
bounds first, then reads chunk after chunk, so a file never needs to be in
memory whole.

Readers, chosen by :func:`open_source`:

- binary STL: fixed 50-byte records, each chunk one ``np.fromfile`` at its
  offset; the default material (STL has no colours trimesh reads).
- binary little-endian PLY whose faces are all triangles with a ``uchar``
  count (fixed-size face records): each chunk reads its face records and the
  run of vertex records they use; face colours, else vertex colours averaged
  per face, else the default material (what :func:`~aniso3d.build.mesh.load_mesh`
  makes of such a file through trimesh, bit for bit).
- anything else (ASCII, polygons, OBJ, glTF, ...): loaded whole with
  :func:`~aniso3d.build.mesh.load_mesh`, then served in chunks; the source's
  ``note`` says so and why.

Sources that read from a path are ``portable``: pickling one is cheap, so a
worker process (or a Dask worker that sees the same path) reads its own chunk.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from aniso3d.build.mesh import (
    DEFAULT_KD,
    DEFAULT_KS,
    DEFAULT_SHININESS,
    MAX_SHININESS,
    Mesh,
    check_readable_file,
    face_topology,
    load_mesh,
)
from aniso3d.build.stream import TriangleChunk
from aniso3d.errors import InputError

#: Faces per read in a source's bounds pass.
READ_FACES = 1 << 18
#: Bytes a face takes while :meth:`TriangleSource.find_closed` runs (its
#: corners, the merged corners, the edge keys and their sorts; 72 + 707
#: measured with tracemalloc on the default tree read as a soup), for the
#: memory budget.
CLOSED_BYTES_PER_FACE = 800


def _check_finite(xyz: np.ndarray, path: Path) -> None:
    if not np.all(np.isfinite(xyz)):
        bad = int(np.count_nonzero(~np.isfinite(xyz.reshape(-1, 3)).all(axis=1)))
        raise InputError(
            f"mesh file '{path}' has {bad} vertices with NaN or Inf coordinates; repair or remove them before building"
        )


class TriangleSource:
    """Triangles with per-face material, read in runs of faces.

    Attributes:
        name: label of the input (the file's stem, the mesh's name).
        n_faces: number of faces.
        n_vertices: number of vertices (as a mesh loaded from the input has them).
        portable: True if pickling the source is cheap (workers read their own chunks).
        note: how the input is read, for reports.
    """

    name: str = "mesh"
    n_faces: int = 0
    n_vertices: int = 0
    portable: bool = False
    note: str = ""
    #: (n_faces,) int8 once :meth:`find_closed` found them, else None: +1 or -1
    #: on closed surfaces (outward or inward winding), 0 elsewhere.
    closed: np.ndarray | None = None
    #: (n_faces,) bool once :meth:`find_closed` found them, else None: faces
    #: that repeat an earlier one (:func:`~aniso3d.build.mesh.face_topology`),
    #: left out of the build.
    repeat: np.ndarray | None = None
    #: (n_faces,) bool once :meth:`find_closed` found them, else None: faces
    #: of patches their whole encloses (:func:`~aniso3d.build.mesh.face_topology`),
    #: left out of the build.
    enclosed: np.ndarray | None = None

    def find_closed(self, memory_budget: int | None = None) -> bool:
        """Find which faces lie on a closed surface, which repeat an
        earlier face and which their whole encloses (:func:`~aniso3d.build.mesh.face_topology`, vertices
        matched by position), reading every triangle once, unless that would
        take more than ``memory_budget`` bytes (about
        :data:`CLOSED_BYTES_PER_FACE` a face): then none is taken as closed
        or repeated. True if found."""
        if self.closed is not None:
            return True
        if memory_budget is not None and self.n_faces * CLOSED_BYTES_PER_FACE > memory_budget:
            return False
        tri = [self.read(a, min(self.n_faces, a + READ_FACES)).triangles for a in range(0, self.n_faces, READ_FACES)]
        tri = np.concatenate(tri) if tri else np.zeros((0, 3, 3))
        faces = np.arange(3 * len(tri)).reshape(-1, 3)
        self.closed, self.repeat, self.enclosed = face_topology(tri.reshape(-1, 3), faces)
        return True

    def bounds(self) -> np.ndarray:
        """(2, 3) float64 min and max corner of the vertices the faces use."""
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for a in range(0, self.n_faces, READ_FACES):
            t = self.read(a, min(self.n_faces, a + READ_FACES)).triangles.reshape(-1, 3)  # checked finite
            lo = np.minimum(lo, t.min(axis=0))
            hi = np.maximum(hi, t.max(axis=0))
        return np.stack([lo, hi])

    def read(self, start: int, stop: int) -> TriangleChunk:
        raise NotImplementedError


def _material(n: int, kd=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """kd (n, 3), ks (n,), shininess (n,) float32 as :class:`Mesh` stores them."""
    if kd is None:
        kd = np.broadcast_to(np.asarray(DEFAULT_KD, dtype=np.float64), (n, 3))
    kd = np.clip(kd, 0.0, 1.0).astype(np.float32)
    ks = np.full(n, np.float32(np.clip(DEFAULT_KS, 0.0, 1.0)))
    sh = np.full(n, np.float32(np.clip(DEFAULT_SHININESS, 0.0, MAX_SHININESS)))
    return kd, ks, sh


class MeshSource(TriangleSource):
    """One :class:`Mesh` in memory."""

    note = "in memory"

    def __init__(self, mesh: Mesh):
        self.mesh = mesh
        self.name = mesh.name
        self.n_faces = mesh.n_faces
        self.n_vertices = len(mesh.vertices)

    def bounds(self) -> np.ndarray:
        return self.mesh.bounds

    def read(self, start: int, stop: int) -> TriangleChunk:
        m = self.mesh
        return TriangleChunk(m.vertices[m.faces[start:stop]], m.kd[start:stop], m.ks[start:stop],
                             m.shininess[start:stop])  # fmt: skip

    def find_closed(self, memory_budget: int | None = None) -> bool:
        if self.closed is None:  # the mesh is in memory already
            self.closed, self.repeat, self.enclosed = face_topology(self.mesh.vertices, self.mesh.faces)
        return True


class ConcatSource(TriangleSource):
    """Several sources one after the other, as if concatenated."""

    def __init__(self, sources: list[TriangleSource], name: str | None = None):
        if not sources:
            raise InputError("nothing to build: the list of meshes is empty")
        self.sources = list(sources)
        self.offsets = np.cumsum([0] + [s.n_faces for s in self.sources])
        self.n_faces = int(self.offsets[-1])
        self.n_vertices = sum(getattr(s, "n_vertices", 3 * s.n_faces) for s in self.sources)
        self.name = name or "+".join(dict.fromkeys(s.name for s in self.sources))
        self.portable = all(s.portable for s in self.sources)
        self.note = "; ".join(dict.fromkeys(s.note for s in self.sources))

    def bounds(self) -> np.ndarray:
        b = np.stack([s.bounds() for s in self.sources])
        return np.stack([b[:, 0].min(axis=0), b[:, 1].max(axis=0)])

    def read(self, start: int, stop: int) -> TriangleChunk:
        parts = []
        for s, off in zip(self.sources, self.offsets[:-1], strict=True):
            a, b = max(start, int(off)), min(stop, int(off) + s.n_faces)
            if a < b:
                parts.append(s.read(a - int(off), b - int(off)))
        if len(parts) == 1:
            return parts[0]
        return TriangleChunk(*(np.concatenate([getattr(p, n) for p in parts])
                               for n in ("triangles", "kd", "ks", "shininess")))  # fmt: skip




class LoadedSource(MeshSource):
    """A file loaded whole with :func:`load_mesh` (formats that cannot be streamed)."""

    def __init__(self, path: Path, why: str):
        super().__init__(load_mesh(path))
        self.note = f"loaded whole ({why})"


# -------------------------------------------------------------------- STL

_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)), ("attributes", "<u2")])


class StlSource(TriangleSource):
    """A binary STL file, read 50-byte record by record."""

    portable = True
    note = "binary STL, read in chunks"

    def __init__(self, path: Path, n_faces: int):
        self.path = Path(path)
        self.name = self.path.stem
        self.n_faces = n_faces
        self.n_vertices = 3 * n_faces  # what trimesh makes of it: three corners per record

    def read(self, start: int, stop: int) -> TriangleChunk:
        rec = np.fromfile(self.path, dtype=_STL_RECORD, count=stop - start, offset=84 + 50 * start)
        if len(rec) != stop - start:
            raise InputError(f"binary STL '{self.path}' ended early: it changed or was truncated while being read")
        tri = rec["corners"].astype(np.float64)
        _check_finite(tri, self.path)
        return TriangleChunk(tri, *_material(len(tri)))


def _binary_stl_faces(p: Path) -> int | None:
    """Face count of a binary STL (None if the file is not one): binary iff
    its size is exactly 84 + 50 n bytes, the test trimesh applies."""
    with open(p, "rb") as fh:
        head = fh.read(84)
    if len(head) < 84:
        return None
    n = int.from_bytes(head[80:84], "little")
    return n if p.stat().st_size == 84 + 50 * n else None


# -------------------------------------------------------------------- PLY

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
_COLOURS = ("red", "green", "blue")
#: Vertex properties a streamed PLY may have; anything else (texture
#: coordinates above all) changes what trimesh makes of the file.
_VERTEX_PROPS = {"x", "y", "z", "nx", "ny", "nz", "red", "green", "blue", "alpha"}
_FACE_PROPS = {"red", "green", "blue", "alpha"}


def _ply_layout(p: Path):
    """(header bytes, vertex dtype, face dtype, counts) of a PLY file that can
    be streamed, or (None, reason) if it cannot."""
    with open(p, "rb") as fh:
        head = fh.read(65536)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        return None, "not a readable PLY header"
    nl = head.find(b"\n", end)
    if nl < 0:
        return None, "not a readable PLY header"
    header_len = nl + 1
    fmt = None
    elements: list[tuple[str, int, list]] = []
    for raw in head[:end].splitlines()[1:]:
        parts = raw.decode("ascii", errors="replace").split()
        if not parts:
            continue
        if parts[0] == "format":
            fmt = parts[1] if len(parts) > 1 else None
        elif parts[0] == "comment" and len(parts) > 1 and parts[1].lower().startswith("texturefile"):
            return None, "it names a texture image"
        elif parts[0] == "element" and len(parts) == 3 and parts[2].isdigit():
            elements.append((parts[1], int(parts[2]), []))
        elif parts[0] == "property" and elements:
            elements[-1][2].append(parts[1:])
    if fmt != "binary_little_endian":
        return None, f"{fmt or 'unknown'} PLY"
    names = [e[0] for e in elements if e[1] > 0]
    if names != ["vertex", "face"]:
        return None, f"elements {', '.join(names) or 'none'} (streamed: vertex then face)"
    (_, nv, vprops), (_, nf, fprops) = elements[0], elements[1]
    vfields = []
    for prop in vprops:
        if len(prop) != 2 or prop[0] not in _PLY_TYPES or prop[1] not in _VERTEX_PROPS:
            return None, f"vertex property '{' '.join(prop)}'"
        vfields.append((prop[1], "<" + _PLY_TYPES[prop[0]]))
    if not {"x", "y", "z"} <= {f[0] for f in vfields}:
        return None, "vertices without x, y, z"
    ffields = []
    for prop in fprops:
        if prop[0] == "list":
            if (len(prop) != 4 or prop[3] not in ("vertex_indices", "vertex_index") or ffields
                    or _PLY_TYPES.get(prop[1]) not in ("u1", "i1") or _PLY_TYPES.get(prop[2], "f")[0] not in "iu"):
                return None, f"face property '{' '.join(prop)}'"
            ffields += [("count", "u1"), ("index", "<" + _PLY_TYPES[prop[2]], (3,))]
        elif len(prop) == 2 and prop[0] == "uchar" and prop[1] in _FACE_PROPS and ffields:
            ffields.append((prop[1], "u1"))
        else:
            return None, f"face property '{' '.join(prop)}'"
    vdt, fdt = np.dtype(vfields), np.dtype(ffields)
    if p.stat().st_size != header_len + nv * vdt.itemsize + nf * fdt.itemsize:
        return None, "faces that are not all triangles"
    return (header_len, vdt, fdt, nv, nf), None


class PlySource(TriangleSource):
    """A binary little-endian PLY of triangles, read in runs of face records
    with the runs of vertex records they use."""

    portable = True
    note = "binary PLY, read in chunks"

    def __init__(self, path: Path, layout):
        self.path = Path(path)
        self.name = self.path.stem
        self.header_len, self.vdt, self.fdt, self.n_vertices, self.n_faces = layout
        self.face_offset = self.header_len + self.n_vertices * self.vdt.itemsize
        self.face_colours = all(c in self.fdt.names for c in _COLOURS)
        self.vertex_colours = all(c in self.vdt.names for c in _COLOURS)

    def _faces(self, start: int, stop: int) -> np.ndarray:
        offset = self.face_offset + start * self.fdt.itemsize
        rec = np.fromfile(self.path, dtype=self.fdt, count=stop - start, offset=offset)
        if len(rec) != stop - start:
            raise InputError(f"PLY '{self.path}' ended early: it changed or was truncated while being read")
        if np.any(rec["count"] != 3):
            raise InputError(f"PLY '{self.path}' has faces that are not triangles; it changed while being read")
        return rec

    def _check_index(self, idx: np.ndarray) -> None:
        if len(idx) and (idx.min() < 0 or idx.max() >= self.n_vertices):
            raise InputError(
                f"mesh file '{self.path}' has faces indexing vertices outside 0..{self.n_vertices - 1} "
                f"(found {int(idx.min())}..{int(idx.max())}); the file is damaged"
            )

    def _vertices(self, first: int, last: int) -> np.ndarray:
        offset = self.header_len + first * self.vdt.itemsize
        rec = np.fromfile(self.path, dtype=self.vdt, count=last - first, offset=offset)
        if len(rec) != last - first:
            raise InputError(f"PLY '{self.path}' ended early: it changed or was truncated while being read")
        return rec

    def read(self, start: int, stop: int) -> TriangleChunk:
        rec = self._faces(start, stop)
        idx = rec["index"].astype(np.int64)
        self._check_index(idx)
        n = len(idx)
        if n == 0:
            return TriangleChunk(np.zeros((0, 3, 3)), *_material(0))
        first, last = int(idx.min()), int(idx.max()) + 1
        if last - first <= 4 * idx.size + 4096:
            verts = self._vertices(first, last)  # the run of vertex records these faces use
            idx -= first
        else:  # faces reaching all over the vertex block: map it and gather
            verts = np.memmap(self.path, dtype=self.vdt, mode="r", offset=self.header_len, shape=(self.n_vertices,))
        used = verts[idx.ravel()]
        del verts
        xyz = np.stack([used["x"], used["y"], used["z"]], axis=-1).astype(np.float64).reshape(n, 3, 3)
        _check_finite(xyz, self.path)
        kd = None
        if self.face_colours:
            kd = np.stack([rec[c] for c in _COLOURS], axis=1).astype(np.float64) / 255.0
        elif self.vertex_colours:
            vc = np.stack([used[c] for c in _COLOURS], axis=1).astype(np.float64) / 255.0
            kd = vc.reshape(n, 3, 3).mean(axis=1)
        return TriangleChunk(xyz, *_material(n, kd))

    def bounds(self) -> np.ndarray:
        """Bounds of the vertices some face uses (not of every vertex record)."""
        used = np.zeros(self.n_vertices, dtype=bool)
        for a in range(0, self.n_faces, READ_FACES):
            idx = self._faces(a, min(self.n_faces, a + READ_FACES))["index"]
            self._check_index(idx)
            used[idx.ravel()] = True
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for a in range(0, self.n_vertices, 4 * READ_FACES):
            b = min(self.n_vertices, a + 4 * READ_FACES)
            v = self._vertices(a, b)[used[a:b]]
            if len(v):
                xyz = np.stack([v["x"], v["y"], v["z"]], axis=-1).astype(np.float64)
                _check_finite(xyz, self.path)
                lo = np.minimum(lo, xyz.min(axis=0))
                hi = np.maximum(hi, xyz.max(axis=0))
        return np.stack([lo, hi])


# ------------------------------------------------------------------ opening


def open_source(thing) -> TriangleSource:
    """A triangle source for a :class:`Mesh`, a mesh file path, a source, or a
    list of any of these (read one after the other, as if concatenated)."""
    if isinstance(thing, TriangleSource):
        return thing
    if isinstance(thing, Mesh):
        return MeshSource(thing)
    if isinstance(thing, (str, os.PathLike)):
        return _open_path(Path(thing))
    if isinstance(thing, (list, tuple)):
        sources = [open_source(t) for t in thing]
        return sources[0] if len(sources) == 1 else ConcatSource(sources)
    raise InputError(
        f"build_texture needs an aniso3d.Mesh, a mesh file path, or a list of them, got {type(thing).__name__}"
    )


def _open_path(p: Path) -> TriangleSource:
    p = check_readable_file(p, "mesh")
    suffix = p.suffix.lower()
    if suffix == ".stl":
        n = _binary_stl_faces(p)
        if n:
            return StlSource(p, n)
        return LoadedSource(p, "ASCII STL")
    if suffix == ".ply":
        layout, why = _ply_layout(p)
        if layout is not None and layout[4] > 0:
            return PlySource(p, layout)
        return LoadedSource(p, why or "a PLY without faces")
    return LoadedSource(p, f"{suffix or 'suffix-less'} files are read whole")
