"""Scenes of many instances: a few shared meshes (assets), each placed many
times by a transform, stored as arrays (never one object per instance).

A :class:`Scene` holds, per asset, the :class:`~aniso3d.build.mesh.Mesh` and
an (N, 4, 4) float32 array of affine transforms (world <- asset) with an
(N, 3) uint8 tint (the instance's diffuse colour is the asset's times
``tint / 255``). One instance costs 64 + 3 bytes here; everything made from an
asset (its texture, pyramid, points, uploads) is made once, by the
renderers' caches, and shared by all its instances.

Scenes come from code (:meth:`Scene.add`), from glTF files whose nodes
share meshes or use ``EXT_mesh_gpu_instancing`` (:func:`load_scene`), or
from :func:`aniso3d.scenes.forest <aniso3d.build.scenes.forest>`.
"""

from __future__ import annotations

import base64
import json
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from aniso3d.build.mesh import Mesh, check_readable_file, from_trimesh
from aniso3d.errors import InputError

#: Bytes one instance costs on the host: a float32 4x4 matrix and an RGB tint.
INSTANCE_BYTES = 64 + 3


def as_transforms(transforms, what: str = "transforms") -> np.ndarray:
    """``transforms`` as an (N, 4, 4) float32 array of affine matrices: from
    (N, 4, 4), (N, 3, 4) (the last row (0, 0, 0, 1) added) or one (4, 4) /
    (3, 4). Refuses any other shape, NaN or Inf, a projective last row and a
    singular (or nearly singular) linear part, each with one InputError."""
    m = np.asarray(transforms)
    if m.dtype == object or not (np.issubdtype(m.dtype, np.floating) or np.issubdtype(m.dtype, np.integer)):
        raise InputError(f"{what} must be numbers, got dtype {m.dtype}")
    m = m.astype(np.float64)
    if m.ndim == 2:
        m = m[None]
    if m.ndim != 3 or m.shape[1:] not in ((4, 4), (3, 4)):
        raise InputError(
            f"{what} must have shape (N, 4, 4) or (N, 3, 4) (one affine matrix per instance), got {m.shape}"
        )
    if m.shape[1] == 3:
        last = np.zeros((len(m), 1, 4))
        last[:, 0, 3] = 1.0
        m = np.concatenate([m, last], axis=1)
    if not np.isfinite(m).all():
        bad = int(np.count_nonzero(~np.isfinite(m).all(axis=(1, 2))))
        raise InputError(f"{what}: {bad} of {len(m)} matrices hold NaN or Inf; give finite matrices")
    if len(m) and not np.allclose(m[:, 3], [0.0, 0.0, 0.0, 1.0]):
        raise InputError(f"{what} must be affine: the last row of every matrix must be (0, 0, 0, 1)")
    if len(m):
        a = m[:, :3, :3]
        det = np.abs(np.linalg.det(a))
        scale = np.max(np.abs(a), axis=(1, 2))
        bad = ~(det > 1e-9 * scale**3)
        if bad.any():
            raise InputError(
                f"{what}: {int(bad.sum())} of {len(m)} matrices are singular (they flatten the "
                f"instance, first at index {int(np.argmax(bad))}); give invertible matrices"
            )
    return np.ascontiguousarray(m, dtype=np.float32)


def as_tints(tints, n: int) -> np.ndarray:
    """(n, 3) uint8 tints: None -> white; integers 0-255 as they are; floats in [0, 1] scaled by 255."""
    if tints is None:
        return np.full((n, 3), 255, dtype=np.uint8)
    t = np.asarray(tints)
    if t.ndim == 1 and t.shape == (3,):
        t = np.broadcast_to(t, (n, 3))
    if t.shape != (n, 3):
        raise InputError(f"tints must have shape ({n}, 3) (one RGB per instance), got {t.shape}")
    if t.dtype == np.uint8:
        return np.ascontiguousarray(t)
    if not (np.issubdtype(t.dtype, np.floating) or np.issubdtype(t.dtype, np.integer)):
        raise InputError(f"tints must be numbers, got dtype {t.dtype}")
    if np.issubdtype(t.dtype, np.integer):
        if t.size and (t.min() < 0 or t.max() > 255):
            raise InputError("integer tints must be in 0-255 (or give floats in [0, 1])")
        return np.ascontiguousarray(t, dtype=np.uint8)
    t = t.astype(np.float64)
    if t.size and (not np.isfinite(t).all() or t.min() < 0.0 or t.max() > 1.0):
        raise InputError("float tints must be finite and in [0, 1] (or give uint8 values 0-255)")
    return np.round(t * 255.0).astype(np.uint8)


@dataclass(eq=False)
class Scene:
    """Assets and their instances.

    Attributes:
        assets: the shared meshes (world units of their own frame).
        transforms: per asset, (N_a, 4, 4) float32 affine world <- asset matrices.
        tints: per asset, (N_a, 3) uint8 diffuse multipliers (255 = unchanged).
        name: label used in reports.
    """

    assets: list[Mesh] = field(default_factory=list)
    transforms: list[np.ndarray] = field(default_factory=list)
    tints: list[np.ndarray] = field(default_factory=list)
    name: str = "scene"
    _bounds: list[np.ndarray] = field(default_factory=list, init=False, repr=False)

    def __post_init__(self) -> None:
        # A scene made by its constructor gets the checks of add().
        if not (len(self.assets) == len(self.transforms)) or (self.tints and len(self.tints) != len(self.assets)):
            raise InputError(f"a scene needs one transform array (and one tint array, if any) per asset: got "
                             f"{len(self.assets)} assets, {len(self.transforms)} transform arrays and "
                             f"{len(self.tints)} tint arrays")  # fmt: skip
        for mesh in self.assets:
            if not isinstance(mesh, Mesh):
                raise InputError(f"a scene's asset must be an aniso3d Mesh, got {type(mesh).__name__}")
        self.transforms = [as_transforms(m) for m in self.transforms]
        tints = self.tints or [None] * len(self.assets)
        self.tints = [as_tints(t, len(m)) for t, m in zip(tints, self.transforms, strict=True)]
        self._bounds = [mesh.bounds for mesh in self.assets]

    def add(self, mesh: Mesh, transforms, tints=None) -> int:
        """Place ``mesh`` by every matrix of ``transforms`` ((N, 4, 4), (N, 3, 4)
        or one matrix) with optional ``tints`` ((N, 3) uint8, or floats in
        [0, 1]). Adding a mesh already in the scene appends instances to it.
        Returns the asset's index."""
        if not isinstance(mesh, Mesh):
            raise InputError(f"a scene's asset must be an aniso3d Mesh, got {type(mesh).__name__}")
        m = as_transforms(transforms)
        t = as_tints(tints, len(m))
        for i, a in enumerate(self.assets):
            if a is mesh:
                self.transforms[i] = np.concatenate([self.transforms[i], m])
                self.tints[i] = np.concatenate([self.tints[i], t])
                return i
        self.assets.append(mesh)
        self.transforms.append(m)
        self.tints.append(t)
        self._bounds.append(mesh.bounds)
        return len(self.assets) - 1

    # ------------------------------------------------------------ queries

    @property
    def n_instances(self) -> int:
        return int(sum(len(m) for m in self.transforms))

    @property
    def counts(self) -> list[int]:
        """Instances per asset."""
        return [len(m) for m in self.transforms]

    def asset_bounds(self, i: int) -> np.ndarray:
        """(2, 3) float64 box of asset ``i`` in its own frame."""
        if len(self._bounds) != len(self.assets):  # assets set directly, not through add()
            self._bounds = [a.bounds for a in self.assets]
        return self._bounds[i]

    @property
    def instance_nbytes(self) -> int:
        """Host bytes of the instances (transforms and tints), beyond the assets."""
        return int(sum(m.nbytes + t.nbytes for m, t in zip(self.transforms, self.tints, strict=True)))

    @property
    def nbytes(self) -> int:
        """Host bytes: the assets as a renderer holds them plus the instances."""
        return int(sum(a.nbytes for a in self.assets)) + self.instance_nbytes

    @property
    def n_faces(self) -> int:
        """Triangles drawn if every instance were drawn as polygons."""
        return int(sum(a.n_faces * len(m) for a, m in zip(self.assets, self.transforms, strict=True)))

    def instance_boxes(self, i: int) -> np.ndarray:
        """(N, 2, 3) float64 world boxes of asset ``i``'s instances: exactly
        the box of the transformed asset box's eight corners, as centre
        ``A c + t`` plus or minus ``|A| h`` (h the half size), vectorised."""
        b = self.asset_bounds(i)
        c, h = 0.5 * (b[0] + b[1]), 0.5 * (b[1] - b[0])
        m = self.transforms[i].astype(np.float64)
        a = m[:, :3, :3]
        mid = a[:, :, 0] * c[0] + a[:, :, 1] * c[1] + a[:, :, 2] * c[2] + m[:, :3, 3]
        aa = np.abs(a)
        ext = aa[:, :, 0] * h[0] + aa[:, :, 1] * h[1] + aa[:, :, 2] * h[2]
        return np.stack([mid - ext, mid + ext], axis=1)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64 world box of every instance; InputError for an empty scene."""
        boxes = [self.instance_boxes(i) for i in range(len(self.assets)) if len(self.transforms[i])]
        if not boxes:
            raise InputError(f"scene '{self.name}' has no instances: nothing to draw; add meshes with Scene.add")
        b = np.concatenate(boxes)
        return np.stack([b[:, 0].min(axis=0), b[:, 1].max(axis=0)])

    def corners(self, limit: int = 50_000) -> np.ndarray:
        """Up to ``limit`` (every k-th) corners of the instances' world boxes,
        (M, 3) float64: a framing tighter than the scene's box (every instance
        seen, none of the empty space of an irregular layout)."""
        boxes = [self.instance_boxes(i) for i in range(len(self.assets)) if len(self.transforms[i])]
        if not boxes:
            return np.zeros((0, 3))
        b = np.concatenate(boxes)
        b = b[:: max(1, 8 * len(b) // limit)]
        sel = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)])  # (8, 3) of 0/1
        return np.where(sel[None].astype(bool), b[:, None, 1], b[:, None, 0]).reshape(-1, 3)

    def flattened(self) -> Mesh:
        """One mesh of every instance (transforms and tints applied): the
        reference the instanced renderers are checked against. Costs the full
        triangle count; for tests and small scenes."""
        from aniso3d.build.mesh import concatenate

        parts = []
        for a, ms, ts in zip(self.assets, self.transforms, self.tints, strict=True):
            if not len(ms):
                continue
            m = ms.astype(np.float64)
            v = np.einsum("nij,vj->nvi", m[:, :3, :3], a.vertices) + m[:, None, :3, 3]
            f = a.faces[None] + (np.arange(len(m)) * len(a.vertices))[:, None, None]
            kd = a.kd[None] * (ts[:, None, :].astype(np.float32) / 255.0)
            parts.append(Mesh(v.reshape(-1, 3), f.reshape(-1, 3), kd.reshape(-1, 3),
                              np.tile(a.ks, len(m)), np.tile(a.shininess, len(m)), a.name))  # fmt: skip
        if not parts:
            raise InputError(f"scene '{self.name}' has no instances: nothing to draw")
        return concatenate(parts, name=self.name)


# ---------------------------------------------------------------------- glTF

GLTF_SUFFIXES = (".gltf", ".glb")
_COMPONENTS = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}
_DTYPES = {5126: np.float32, 5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16}


def load_scene(path: str | os.PathLike, name: str | None = None) -> Scene:
    """A :class:`Scene` from a glTF file (.gltf or .glb): one asset per mesh
    primitive, one instance per node that uses it (with the node's world
    transform), and, where a node carries ``EXT_mesh_gpu_instancing``, one
    instance per entry of its TRANSLATION / ROTATION / SCALE accessors
    (node world transform times the entry's TRS)."""
    import trimesh

    p = check_readable_file(path, "scene")
    if p.suffix.lower() not in GLTF_SUFFIXES:
        raise InputError(f"a scene of instances is read from a glTF file (.gltf, .glb), got '{p.name}'")
    try:
        tscene = trimesh.load(str(p), force="scene", process=False)
    except Exception as exc:  # trimesh raises many types for damaged files
        raise InputError(f"could not read glTF scene '{p}': {type(exc).__name__}: {exc}") from None
    doc = None
    groups: dict[str, list[np.ndarray]] = {}
    extensions = _node_extensions(tscene)
    for node in tscene.graph.nodes_geometry:
        transform, geom_name = tscene.graph[node]
        geom = tscene.geometry.get(geom_name)
        if not isinstance(geom, trimesh.Trimesh) or len(geom.faces) == 0:
            continue
        world = np.asarray(transform, dtype=np.float64)[None]
        ext = extensions.get(node, {}).get("EXT_mesh_gpu_instancing")
        if ext is not None:
            if doc is None:
                doc = _GltfData(p)
            world = world @ doc.instance_matrices(ext)
        groups.setdefault(geom_name, []).append(world)
    scene = Scene(name=name or p.stem)
    for geom_name, mats in groups.items():
        scene.add(from_trimesh(tscene.geometry[geom_name], geom_name), np.concatenate(mats))
    if not scene.assets:
        raise InputError(f"glTF file '{p}' holds no triangle meshes: nothing to draw")
    return scene


def _node_extensions(tscene) -> dict:
    """Per node, the glTF ``extensions`` of the edge that leads to it (trimesh
    keeps them in the edge's metadata); one pass over the edges."""
    out = {}
    for (_, child), attrs in tscene.graph.transforms.edge_data.items():
        ext = (attrs.get("metadata") or {}).get("gltf_extensions")
        if ext:
            out[child] = ext
    return out


class _GltfData:
    """The JSON and binary buffers of a glTF file, read for accessors trimesh skips."""

    def __init__(self, path: Path):
        raw = path.read_bytes()
        self.bin = None
        try:
            if raw[:4] == b"glTF":
                length, kind = struct.unpack_from("<I4s", raw, 12)
                self.json = json.loads(raw[20 : 20 + length])
                rest = 20 + length
                if len(raw) >= rest + 8:
                    blen, _ = struct.unpack_from("<I4s", raw, rest)
                    self.bin = raw[rest + 8 : rest + 8 + blen]
            else:
                self.json = json.loads(raw)
        except (ValueError, struct.error) as exc:
            raise InputError(f"glTF file '{path}' is damaged: {exc}") from None
        self.folder = path.parent
        self._buffers: dict[int, bytes] = {}

    def buffer(self, i: int) -> bytes:
        if i not in self._buffers:
            b = self.json["buffers"][i]
            uri = b.get("uri")
            if uri is None:
                data = self.bin or b""
            elif uri.startswith("data:"):
                data = base64.b64decode(uri.split(",", 1)[1])
            else:
                data = (self.folder / uri).read_bytes()
            self._buffers[i] = data
        return self._buffers[i]

    def accessor(self, i: int) -> np.ndarray:
        """(count, components) float64 values of accessor ``i`` (normalised
        integer types mapped to [-1, 1] / [0, 1] as glTF says)."""
        try:
            acc = self.json["accessors"][i]
            view = self.json["bufferViews"][acc["bufferView"]]
            dtype = np.dtype(_DTYPES[acc["componentType"]])
            k = _COMPONENTS[acc["type"]]
            count = int(acc["count"])
            start = int(view.get("byteOffset", 0)) + int(acc.get("byteOffset", 0))
            stride = int(view.get("byteStride", 0)) or k * dtype.itemsize
            data = self.buffer(view["buffer"])
            rows = np.ndarray((count, k), dtype=dtype.newbyteorder("<"), buffer=data, offset=start,
                              strides=(stride, dtype.itemsize))  # fmt: skip
        except (KeyError, IndexError, TypeError, ValueError) as exc:
            raise InputError(f"glTF accessor {i} of EXT_mesh_gpu_instancing is damaged: {exc}") from None
        out = rows.astype(np.float64)
        if dtype.kind in "iu" and acc.get("normalized", False):
            out = np.maximum(out / np.iinfo(dtype).max, -1.0)
        return out

    def instance_matrices(self, ext: dict) -> np.ndarray:
        """(N, 4, 4) matrices T R S of an ``EXT_mesh_gpu_instancing`` extension."""
        attrs = ext.get("attributes", {}) if isinstance(ext, dict) else None
        if not isinstance(attrs, dict) or not all(
            isinstance(v, int) and not isinstance(v, bool) for k, v in attrs.items()
            if k in ("TRANSLATION", "ROTATION", "SCALE")
        ):  # fmt: skip
            raise InputError("EXT_mesh_gpu_instancing needs 'attributes': an object of accessor indices "
                             f"(got {attrs!r}); the glTF file is damaged")  # fmt: skip
        values = {k: self.accessor(v) for k, v in attrs.items() if k in ("TRANSLATION", "ROTATION", "SCALE")}
        if not values:
            raise InputError("EXT_mesh_gpu_instancing without TRANSLATION, ROTATION or SCALE attributes")
        n = {len(v) for v in values.values()}
        if len(n) != 1:
            raise InputError(f"EXT_mesh_gpu_instancing attributes have different counts {sorted(n)}")
        n = n.pop()
        t = values.get("TRANSLATION", np.zeros((n, 3)))
        q = values.get("ROTATION", np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))
        s = values.get("SCALE", np.ones((n, 3)))
        return trs_matrices(t, q, s)


def trs_matrices(translation: np.ndarray, rotation: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """(N, 4, 4) float64 ``T R S`` from (N, 3) translations, (N, 4) unit
    quaternions (x, y, z, w: glTF's order) and (N, 3) scales."""
    q = np.asarray(rotation, dtype=np.float64)
    length = np.linalg.norm(q, axis=1, keepdims=True)
    if not (np.isfinite(length).all() and (length > 1e-6).all()):
        raise InputError("rotations must be non-zero quaternions (x, y, z, w); "
                         f"{int((~(length > 1e-6)).sum())} are zero or not finite")  # fmt: skip
    q = q / length
    x, y, z, w = q.T
    r = np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=1),
    ], axis=1)  # fmt: skip
    m = np.zeros((len(q), 4, 4))
    m[:, :3, :3] = r * np.asarray(scale, dtype=np.float64)[:, None, :]
    m[:, :3, 3] = translation
    m[:, 3, 3] = 1.0
    return m
