"""Stage 1: triangle meshes with per-face Phong material, loaded from files.

A :class:`Mesh` is the plain data object every later stage starts from. Loading
goes through trimesh; scenes are flattened into one mesh with their transforms
applied, and whatever colour information a file has (face colours, vertex
colours, material colours, a texture's mean over each face) becomes
the per-face diffuse reflectance ``kd``.
"""

from __future__ import annotations

import logging
import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aniso3d.build.outside import ENCLOSED, outside_sides
from aniso3d.build.ply import read_ply_header
from aniso3d.errors import InputError, InputWarning

#: Diffuse reflectance of faces whose file carries no colour (a light grey).
DEFAULT_KD = (0.7, 0.7, 0.7)
#: Specular coefficient where the material does not give one.
DEFAULT_KS = 0.1
#: Phong exponent where the material does not give one.
DEFAULT_SHININESS = 16.0
#: A file's Phong exponent below this is read as this. MeshLab and Blender
#: write ``Ns 0`` for a surface with no highlight (Blender: roughness 1),
#: and glTF's roughness 1 maps to 0; exponent 0 is a constant lobe, which
#: added ks to every lit pixel and drew such models washed out, a white
#: sphere on the white background.
LEAST_SHININESS = 1.0
#: Vertices closer than this share of a mesh's extent are one position when
#: its topology is read (:func:`face_topology`): float noise of exporters is
#: far below it, any detail a texture resolves far above.
MERGE_SHARE = 2.0**-20
#: A consistently wound surface is taken as closed while its holes are small:
#: the sum over its holes of each one's squared length at most this share
#: of its area (0: watertight only). A sphere with a hole of 23 degrees'
#: radius (4 % of its area), a head with open eye sockets or a scanned
#: animal with a few holes in its base (the Stanford bunny: 0.47) passes; a
#: bowl (pi), a box without its lid (3.2), a leaf (16) or a tube open at
#: both ends shorter than 25 times its radius (4 pi r / length) does not.
#: (Before 90240ac the holes' lengths were summed before squaring, and
#: edges of three faces or more counted as holes: the bunny read 51.)
HOLE_SHARE = 0.5
#: Patches (closed components ending at edges of three faces or more) are
#: signed by rays (:mod:`aniso3d.build.outside`) while a mesh has at most
#: this many of them, and their wholes at most this many faces; beyond,
#: they are open, as every such face was before the rays (their cost then
#: would outgrow the build's).
OUTSIDE_PATCHES = 1 << 17
OUTSIDE_FACES = 1 << 21
#: Largest Phong exponent accepted; higher ones are clamped (a mirror-like lobe
#: narrower than this is below a pixel at any size we render).
MAX_SHININESS = 1.0e4


@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh with one Phong material per face.

    Attributes:
        vertices: (V, 3) float64, world units.
        faces: (F, 3) int64 indices into ``vertices``.
        kd: (F, 3) float32 diffuse reflectance in [0, 1] (display RGB values).
        ks: (F,) float32 specular coefficient in [0, 1].
        shininess: (F,) float32 Phong exponent n >= 0.
        name: label used in reports.
    """

    vertices: np.ndarray
    faces: np.ndarray
    kd: np.ndarray
    ks: np.ndarray
    shininess: np.ndarray
    name: str = "mesh"

    def __post_init__(self) -> None:
        v = np.ascontiguousarray(self.vertices, dtype=np.float64)
        f = np.asarray(self.faces)
        if v.ndim != 2 or v.shape[1] != 3:
            raise InputError(f"mesh vertices must have shape (V, 3), got {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3:
            raise InputError(
                f"mesh faces must have shape (F, 3) (triangles), got {f.shape}; "
                "triangulate polygons first"
            )
        if f.size and not np.issubdtype(f.dtype, np.integer):
            raise InputError(f"mesh faces must be integer indices, got dtype {f.dtype}")
        f = np.ascontiguousarray(f, dtype=np.int64)
        if len(f) == 0:
            raise InputError(
                f"mesh '{self.name}' has no faces: nothing to render. "
                "Check that the file holds triangles or polygons, not only points or lines"
            )
        if not np.all(np.isfinite(v)):
            bad = int(np.count_nonzero(~np.isfinite(v).all(axis=1)))
            raise InputError(
                f"mesh '{self.name}' has {bad} vertices with NaN or Inf coordinates; "
                "repair or remove them before building"
            )
        if f.min() < 0 or f.max() >= len(v):
            raise InputError(
                f"mesh '{self.name}' has faces indexing vertices outside 0..{len(v) - 1} "
                f"(found {int(f.min())}..{int(f.max())}); the file is damaged"
            )
        n = len(f)
        kd = _per_face(self.kd, n, 3, "kd")
        ks = _per_face(self.ks, n, None, "ks")
        sh = _per_face(self.shininess, n, None, "shininess")
        if not (np.isfinite(kd).all() and np.isfinite(ks).all() and np.isfinite(sh).all()):
            raise InputError(f"mesh '{self.name}' has NaN or Inf material values")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)
        object.__setattr__(self, "kd", np.clip(kd, 0.0, 1.0).astype(np.float32))
        object.__setattr__(self, "ks", np.clip(ks, 0.0, 1.0).astype(np.float32))
        object.__setattr__(self, "shininess", np.clip(sh, 0.0, MAX_SHININESS).astype(np.float32))

    @property
    def n_faces(self) -> int:
        return len(self.faces)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64: min and max corner of the vertices the faces use."""
        # A mask, not np.unique: numpy 2.4's hash-based unique takes ~1.5 s on
        # the default tree's 786k indices, the mask ~1 ms.
        mask = np.zeros(len(self.vertices), dtype=bool)
        mask[self.faces.ravel()] = True
        used = self.vertices[mask]
        return np.stack([used.min(axis=0), used.max(axis=0)])

    @property
    def triangles(self) -> np.ndarray:
        """(F, 3, 3) float64 corner positions."""
        return self.vertices[self.faces]

    def face_areas(self) -> np.ndarray:
        """(F,) float64 triangle areas in world units squared."""
        t = self.triangles
        return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)

    def area(self) -> float:
        return float(self.face_areas().sum())

    def closed_faces(self) -> np.ndarray:
        """(F,) bool: faces of closed surfaces, components of faces whose
        edges are each shared with exactly one other face, walked the other
        way (vertices matched by position): a solid's watertight skin.

        Where its front and back fall into one voxel (a thin beam, a wall
        under a voxel thick) the back lies behind the front, and the texture
        counts it once (:mod:`aniso3d.build.stream`); its points face one way
        (their backs are hidden). Open surfaces (leaves, blades, a sheet, a
        tube open at its ends) keep every side. See :func:`closed_sides`."""
        return closed_faces(self.vertices, self.faces)

    def closed_sides(self) -> np.ndarray:
        """(F,) int8: :func:`closed_sides`, +1 or -1 (outward or inward
        winding) on closed surfaces, 0 elsewhere."""
        return closed_sides(self.vertices, self.faces)

    def repeated_faces(self) -> np.ndarray:
        """(F,) bool: faces with the corners of an earlier face
        (:func:`face_topology`), which a texture counts once."""
        return repeated_faces(self.vertices, self.faces)

    @property
    def nbytes(self) -> int:
        """Bytes of the mesh as a renderer would hold it: float32 positions,
        uint32 indices and a float32 RGB + ks + n material per face."""
        return int(len(self.vertices) * 12 + len(self.faces) * 12 + len(self.faces) * 20)

    @classmethod
    def from_arrays(
        cls,
        vertices,
        faces,
        kd=DEFAULT_KD,
        ks=DEFAULT_KS,
        shininess=DEFAULT_SHININESS,
        name: str = "mesh",
    ) -> Mesh:
        """Build a mesh from arrays; material values may be per face or one for all."""
        return cls(np.asarray(vertices), np.asarray(faces), kd, ks, shininess, name)

    def transformed(self, matrix: np.ndarray) -> Mesh:
        """A copy with vertices multiplied by a 4x4 affine matrix."""
        m = np.asarray(matrix, dtype=np.float64)
        v = self.vertices @ m[:3, :3].T + m[:3, 3]
        return Mesh(v, self.faces, self.kd, self.ks, self.shininess, self.name)

    def to_trimesh(self):
        import trimesh

        colors = np.concatenate(
            [np.round(self.kd * 255).astype(np.uint8), np.full((self.n_faces, 1), 255, np.uint8)],
            axis=1,
        )
        return trimesh.Trimesh(self.vertices, self.faces, face_colors=colors, process=False)


def _per_face(value, n: int, width: int | None, what: str) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    shape = (n,) if width is None else (n, width)
    try:
        return np.broadcast_to(a, shape).copy()
    except ValueError:
        raise InputError(
            f"material '{what}' must be one value or one per face {shape}, got shape {a.shape}"
        ) from None


def concatenate(meshes: list[Mesh], name: str = "mesh") -> Mesh:
    """Join meshes into one, keeping each face's material."""
    if not meshes:
        raise InputError("nothing to concatenate: the list of meshes is empty")
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    return Mesh(
        np.concatenate([m.vertices for m in meshes]),
        np.concatenate([m.faces + o for m, o in zip(meshes, offsets, strict=True)]),
        np.concatenate([m.kd for m in meshes]),
        np.concatenate([m.ks for m in meshes]),
        np.concatenate([m.shininess for m in meshes]),
        name,
    )


# --------------------------------------------------------------------------- loading

MESH_SUFFIXES = {".obj", ".ply", ".stl", ".glb", ".gltf", ".off", ".dae", ".zae", ".3mf"}

#: Formats whose files name others (material libraries, textures, buffers)
#: by a path: read with those paths allowed anywhere, as the tools that write
#: them read them (trimesh 5 refuses a path that leaves the mesh's folder,
#: ``../textures/wood.png``, and a symlinked one whose target does, and drops
#: the materials without a word).
LINKED_SUFFIXES = {".obj", ".gltf", ".dae"}

#: trimesh's (mostly debug-level) log messages when a material library or
#: texture a mesh names cannot be read ("unable to load materials from:
#: x.mtl", "failed to load image", "unable to load base texture", ...; not
#: the bump or emissive maps, which aniso3d does not use).
_ASSET_FAILURES = re.compile(r"^(unable|failed) to load (materials|image|base texture|textures)")


class _AssetFailures(logging.Filter):
    """Collects what trimesh logs of the files a mesh names that it could
    not read, while letting through only the records its logger would have
    let through anyway."""

    def __init__(self, passes: int):
        super().__init__()
        self.passes = passes
        self.notes: list[str] = []

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage()
        if _ASSET_FAILURES.match(message):
            cause = record.exc_info[1] if record.exc_info else None
            self.notes.append(f"{message.rstrip(': !')}" + (f" ({cause})" if cause else ""))
        return record.levelno >= self.passes


def _load_scene(p: Path):
    """trimesh's scene of the file ``p`` and what could not be read of the
    material libraries and textures it names (one line each)."""
    import trimesh
    from trimesh.resolvers import FilePathResolver

    # trimesh logs per module (trimesh.util, ...), at its package logger's
    # level: lowered for the load, each module's records filtered where
    # they are made.
    log = logging.getLogger("trimesh")
    level = log.level
    notes = _AssetFailures(log.getEffectiveLevel())
    loggers = [log] + [
        logger for name, logger in logging.root.manager.loggerDict.items()
        if name.startswith("trimesh.") and isinstance(logger, logging.Logger)
    ]  # fmt: skip
    for logger in loggers:
        logger.addFilter(notes)
    log.setLevel(logging.DEBUG)
    try:
        resolver = FilePathResolver(str(p), allow_anywhere=True) if p.suffix.lower() in LINKED_SUFFIXES else None
        scene = trimesh.load(str(p), force="scene", process=False, resolver=resolver)
    finally:
        log.setLevel(level)
        for logger in loggers:
            logger.removeFilter(notes)
    return scene, list(dict.fromkeys(notes.notes))


def _missing_module(exc: ImportError) -> str:
    """The module an ImportError says is missing: trimesh re-raises them
    without ``name`` ("No module named 'networkx'", "missing `pip install
    pycollada`")."""
    if exc.name:
        return exc.name
    text = str(exc)
    for pattern in (r"No module named '([\w.]+)'", r"pip install ([\w.-]+)"):
        m = re.search(pattern, text)
        if m:
            return m.group(1)
    return text.strip() or "unknown"


def check_readable_file(path: str | os.PathLike, what: str = "input") -> Path:
    """Return ``path`` as a Path if it is a readable, non-empty regular file."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"{what} file '{p}' does not exist; check the path")
    if p.is_dir():
        raise InputError(f"{what} '{p}' is a directory; name a file inside it")
    if not os.access(p, os.R_OK):
        raise InputError(f"{what} file '{p}' is not readable; check its permissions")
    if p.stat().st_size == 0:
        raise InputError(f"{what} file '{p}' is empty")
    return p


def load_mesh(path: str | os.PathLike, name: str | None = None) -> Mesh:
    """Read a mesh file (OBJ+MTL, PLY, STL, GLB/GLTF, OFF, ...) with its materials.

    Scenes are flattened into one mesh with their node transforms applied.
    Per-face ``kd`` comes from, in order: face colours, vertex colours (averaged
    per face), a texture image's mean over each face (:func:`_sample_texture`), the material's
    main colour, else :data:`DEFAULT_KD`. ``ks`` and the Phong exponent come
    from the material where it has them (OBJ ``Ks``/``Ns``; glTF roughness
    mapped to an exponent; at least :data:`LEAST_SHININESS`), else
    :data:`DEFAULT_KS` / :data:`DEFAULT_SHININESS`.
    """
    import trimesh

    p = check_readable_file(path, "mesh")
    suffix = p.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise InputError(
            f"'{p.name}' has suffix '{suffix or '(none)'}', which aniso3d does not read as a "
            f"mesh; supported: {', '.join(sorted(MESH_SUFFIXES))}"
        )
    if suffix == ".stl":
        _check_binary_stl_size(p)
    try:
        scene, unread = _load_scene(p)
    except ImportError as exc:  # an optional reader (3MF, COLLADA), or a fallback for bad data
        name = _missing_module(exc)
        raise InputError(
            f"could not read mesh '{p}': reading {suffix} files needs the optional module '{name}'. "
            f"Install the optional readers with: pip install 'aniso3d[formats]'. If '{name}' is "
            "installed, the file is damaged or not in the format its suffix says"
        ) from None
    except Exception as exc:  # trimesh raises many types for damaged files
        raise InputError(
            f"could not read mesh '{p}': {type(exc).__name__}: {exc}. "
            "The file may be truncated or not in the format its suffix says"
        ) from None
    parts: list[Mesh] = []
    try:
        placed = _scene_geometry(scene)
    except Exception as exc:
        raise InputError(
            f"could not flatten the scene in '{p}': {str(exc).strip()}. "
            "The file may be truncated or damaged"
        ) from None
    dumped = [g for g, _ in placed]
    if suffix == ".ply":
        # trimesh reads a truncated ASCII PLY without a word: compare with the
        # face count its header declares (polygons only ever add triangles).
        declared = read_ply_header(p).count("face")
        loaded = sum(len(g.faces) for g in dumped if isinstance(g, trimesh.Trimesh))
        if loaded < declared:
            raise InputError(
                f"mesh file '{p}' declares {declared} faces but holds only {loaded}: "
                "the file is truncated or damaged"
            )
    for geom, transform in placed:
        if not isinstance(geom, trimesh.Trimesh) or len(geom.faces) == 0:
            continue
        part = _from_trimesh(geom, p.name)
        parts.append(part if transform is None else part.transformed(transform))
    if not parts:
        raise InputError(
            f"mesh file '{p}' holds no triangles (only points, lines or nothing): "
            "it is truncated, or not a surface mesh; aniso3d needs triangles or polygons"
        )
    # Read whole but for some of its materials: say so (after every check
    # above, so that a file refused is one error, not a warning and an error).
    for note in unread:
        warnings.warn(
            InputWarning(
                f"'{p.name}': {note}; its faces take their materials' colours or the default grey. "
                "Keep the material library and images at the paths the file names"
            ),
            stacklevel=2,
        )
    return concatenate(parts, name=name or p.stem)


def _scene_geometry(scene) -> list[tuple[object, np.ndarray | None]]:
    """(geometry, 4x4 world transform or None) for every instance in a trimesh
    scene, without copying geometry: ``Scene.dump`` copies each mesh with its
    visuals, which converts colours through scipy for no use of ours."""
    import trimesh

    if not isinstance(scene, trimesh.Scene):
        return [(scene, None)]
    out = []
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        geom = scene.geometry.get(name)
        if geom is None:
            continue
        t = np.asarray(transform, dtype=np.float64)
        out.append((geom, None if np.array_equal(t, np.eye(4)) else t))
    return out


def _check_binary_stl_size(p: Path) -> None:
    """Refuse a binary STL shorter than the triangle count in its header says
    (trimesh would otherwise try it as ASCII and fail with an unrelated error)."""
    with open(p, "rb") as fh:
        head = fh.read(84)
    if len(head) < 84 or head.lstrip().startswith(b"solid"):
        return  # ASCII STL (or too short for a binary one): trimesh decides
    n = int.from_bytes(head[80:84], "little")
    size = p.stat().st_size
    if size < 84 + 50 * n:
        raise InputError(
            f"binary STL '{p}' declares {n} triangles ({84 + 50 * n} bytes) but has only "
            f"{size} bytes: the file is truncated"
        )


def from_trimesh(tm, name: str = "mesh") -> Mesh:
    """A :class:`Mesh` from one ``trimesh.Trimesh`` with its materials (as :func:`load_mesh` reads them)."""
    return _from_trimesh(tm, name)


def _from_trimesh(tm, name: str = "mesh") -> Mesh:
    n = len(tm.faces)
    kd = np.tile(np.asarray(DEFAULT_KD, dtype=np.float64), (n, 1))
    ks = np.full(n, DEFAULT_KS)
    sh = np.full(n, DEFAULT_SHININESS)
    visual = tm.visual
    kind = getattr(visual, "kind", None)
    if kind == "face":
        kd = np.asarray(visual.face_colors, dtype=np.float64)[:, :3] / 255.0
    elif kind == "vertex":
        vc = np.asarray(visual.vertex_colors, dtype=np.float64)[:, :3] / 255.0
        kd = vc[tm.faces].mean(axis=1)
    elif kind == "texture" or hasattr(visual, "material"):
        mat = getattr(visual, "material", None)
        if mat is not None:
            kd_t, ks_m, sh_m = _material_values(mat)
            if kd_t is not None:
                kd[:] = kd_t
            if ks_m is not None:
                ks[:] = ks_m
            if sh_m is not None:
                sh[:] = sh_m
            image = _material_image(mat)
            uv = getattr(visual, "uv", None)
            if image is not None and uv is not None and len(uv) == len(tm.vertices):
                kd = _sample_texture(image, np.asarray(uv, dtype=np.float64)[tm.faces])
                if kd_t is not None and _is_pbr(mat):
                    kd = kd * kd_t  # glTF multiplies the base colour texture by its factor
    return Mesh(np.asarray(tm.vertices), np.asarray(tm.faces), kd, ks, sh, name)


def _is_pbr(mat) -> bool:
    return hasattr(mat, "baseColorFactor")


def _material_values(mat):
    """(kd RGB or None, ks or None, shininess or None) from a trimesh material."""
    kd = ks = sh = None
    if _is_pbr(mat):
        f = getattr(mat, "baseColorFactor", None)
        if f is not None:
            f = np.asarray(f, dtype=np.float64).ravel()
            kd = f[:3] / (255.0 if f.max() > 1.0 else 1.0)
        rough = getattr(mat, "roughnessFactor", None)
        metal = getattr(mat, "metallicFactor", None)
        if rough is not None:
            r = float(np.clip(rough, 0.02, 1.0))
            sh = max(2.0 / (r**4) - 2.0, LEAST_SHININESS)  # Blinn-Phong exponent equivalent to GGX roughness
            ks = 0.04 + 0.5 * (1.0 - r)
        if metal is not None and ks is not None:
            ks = min(1.0, ks + 0.5 * float(metal))
        return kd, ks, sh
    for attr in ("diffuse", "main_color"):
        c = getattr(mat, attr, None)
        if c is not None:
            c = np.asarray(c, dtype=np.float64).ravel()
            if c.size >= 3:
                kd = c[:3] / (255.0 if c.max() > 1.0 else 1.0)
                break
    spec = getattr(mat, "specular", None)
    if spec is not None:
        s = np.asarray(spec, dtype=np.float64).ravel()
        if s.size:
            ks = float(s[:3].mean() / (255.0 if s.max() > 1.0 else 1.0))
    gloss = getattr(mat, "glossiness", None)
    if gloss is not None and np.isfinite(gloss):
        sh = max(float(gloss), LEAST_SHININESS)
    return kd, ks, sh


def _material_image(mat):
    for attr in ("image", "baseColorTexture"):
        img = getattr(mat, attr, None)
        if img is not None:
            return img
    return None


#: A face's colour from its texture is the mean of the texels under it: it
#: is sampled at the centroids of the n x n equal triangles that split it,
#: n the power of two (at most this) that puts a sample about every two
#: texels, each sample read from the texture's mip level whose texels are
#: about the samples' spacing (a box filter over the face; a face over a few
#: texels: its centroid's texel). One texel at the centroid aliased:
#: trimesh's capsule, thin grid lines on black, came out as faces at random
#: full colour or black.
TEXTURE_SPLIT_MAX = 8
#: Faces sampled at once (bounds the samples' memory: about 40 MB at n = 8).
TEXTURE_FACES = 1 << 15


def _split_centroids(n: int) -> np.ndarray:
    """(n^2, 3) barycentric centroids of the n^2 equal triangles a triangle
    splits into (each edge in n)."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    up = (i + j <= n - 1).ravel()
    down = (i + j <= n - 2).ravel()
    a = np.concatenate([(i.ravel()[up] + 1 / 3) / n, (i.ravel()[down] + 2 / 3) / n])
    b = np.concatenate([(j.ravel()[up] + 1 / 3) / n, (j.ravel()[down] + 2 / 3) / n])
    return np.stack([1.0 - a - b, a, b], axis=1)


def _mip_levels(arr: np.ndarray, count: int) -> list[np.ndarray]:
    """``arr`` (H, W, 3) uint8 and up to ``count`` halvings, each texel the
    rounded mean of 2 x 2 (an odd side's last row or column repeated)."""
    levels = [arr]
    while len(levels) <= count and max(levels[-1].shape[:2]) > 1:
        a = levels[-1]
        if a.shape[0] % 2:
            a = np.concatenate([a, a[-1:]], axis=0)
        if a.shape[1] % 2:
            a = np.concatenate([a, a[:, -1:]], axis=1)
        rows = a[0::2].astype(np.uint16) + a[1::2]
        total = rows[:, 0::2] + rows[:, 1::2]
        levels.append(((total + 2) >> 2).astype(np.uint8))
    return levels


def _sample_texture(image, uv: np.ndarray) -> np.ndarray:
    """Mean texture colour of each face with corner UVs ``uv`` (F, 3, 2)
    (wrapped), as (F, 3) in [0, 1] (:data:`TEXTURE_SPLIT_MAX`). The image
    and its mip levels stay 8-bit (a 16k texture as floats would take 6 GB)."""
    try:
        arr = np.asarray(image if image.mode == "RGB" else image.convert("RGB"), dtype=np.uint8)
    except Exception as exc:
        raise InputError(f"the mesh's texture image cannot be decoded: {exc}") from None
    h, w = arr.shape[:2]
    uv = np.nan_to_num(np.asarray(uv, dtype=np.float64), posinf=0.0, neginf=0.0)
    out = np.zeros((len(uv), 3))
    if len(uv) == 0:
        return out
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    with np.errstate(over="ignore", invalid="ignore"):
        texels = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) * w * h
    # A face over the whole texture at most (UVs far out wrap around it).
    texels = np.where(np.isfinite(texels), np.minimum(texels, float(w) * h), float(w) * h)
    # n^2 samples for about texels / 4 (n = 2^ceil(log2(sqrt(texels) / 2))),
    # each from the level whose texels are about their spacing.
    most = int(np.log2(TEXTURE_SPLIT_MAX))
    level = np.clip(np.ceil(np.log2(np.maximum(np.sqrt(texels) / 2.0, 1.0))), 0, most).astype(np.int64)
    n_face = 2**level
    spacing = np.sqrt(texels) / n_face
    mip = np.floor(np.log2(np.maximum(spacing, 1.0))).astype(np.int64)
    levels = _mip_levels(arr, int(mip.max()))
    mip = np.minimum(mip, len(levels) - 1)
    key = n_face * 64 + mip
    order = np.argsort(key, kind="stable")
    groups, starts = np.unique(key[order], return_index=True)
    for g, rows in zip(groups, np.split(order, starts[1:]), strict=True):
        n, m = int(g) // 64, int(g) % 64
        tex = levels[m]
        th, tw = tex.shape[:2]
        split = _split_centroids(n)[None]
        for a in range(0, len(rows), TEXTURE_FACES):  # bounded memory: (faces, n^2, 2) a chunk
            r = rows[a : a + TEXTURE_FACES]
            at = np.matmul(split, uv[r])  # (F, n^2, 2)
            x = np.clip((np.mod(at[..., 0], 1.0) * (w / 2**m)).astype(np.int64), 0, tw - 1)
            y = np.clip(((1.0 - np.mod(at[..., 1], 1.0)) * (h / 2**m)).astype(np.int64), 0, th - 1)
            out[r] = tex[y, x].sum(axis=1, dtype=np.uint32) / (255.0 * n * n)
    return out


def closed_faces(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) bool: :meth:`Mesh.closed_faces` of ``vertices`` (V, 3) and
    ``faces`` (F, 3): the faces of :func:`closed_sides` that are not 0."""
    return closed_sides(vertices, faces) != 0


def closed_sides(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) int8: +1 for a face of a closed surface wound outwards, -1 for
    one wound inwards, 0 for a face of an open surface: the sides of
    :func:`face_topology`."""
    return face_topology(vertices, faces)[0]


def repeated_faces(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) bool: faces that repeat an earlier face: the repeats of :func:`face_topology`."""
    return face_topology(vertices, faces)[1]


def merged_vertices(vertices: np.ndarray) -> np.ndarray:
    """(V,) int64: one id per position, vertices within :data:`MERGE_SHARE`
    of the mesh's extent of each other sharing it (rounded to that grid; a
    share of 0: equal positions only)."""
    v = np.asarray(vertices, dtype=np.float64)
    if len(v) == 0:
        return np.zeros(0, dtype=np.int64)
    lo = v.min(axis=0)
    step = float(np.ptp(v, axis=0).max()) * MERGE_SHARE
    if MERGE_SHARE <= 0.0:
        _, same = np.unique(v, axis=0, return_inverse=True)
    elif not step > 0.0:  # every vertex at one point
        return np.zeros(len(v), dtype=np.int64)
    else:
        # Grid coordinates under 2^21 packed into one key: a 1-D unique,
        # far faster than one over rows.
        q = np.round((v - lo) / step).astype(np.int64)
        if int(q.max()) < 1 << 21:
            _, same = np.unique((q[:, 0] << 42) | (q[:, 1] << 21) | q[:, 2], return_inverse=True)
        else:  # a finer MERGE_SHARE than 2^-20
            _, same = np.unique(q, axis=0, return_inverse=True)
    return same.reshape(-1).astype(np.int64)


def face_topology(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(sides, repeat, enclosed)``: (F,) int8 +1 for a face of a closed
    surface wound outwards, -1 for one wound inwards, 0 for a face of an open
    surface; (F,) bool for a face that repeats an earlier one; and (F,) bool
    for a face of a patch its whole encloses (seen from neither side, see
    below). A texture leaves out the repeats and the enclosed faces.

    Vertices are matched by position (:func:`merged_vertices`: meshes split
    them along seams, and exporters write one corner with float noise). A
    face with the corners of an earlier one, in either winding, repeats it:
    meshes drawn double-sided carry every face twice, once each way, and a
    texture that counted both would cover a thin part twice over (the
    polygons' depth test keeps one). Repeats and degenerate faces (a
    repeated corner) take no part in the topology and are open.

    A closed surface is a component of the other faces, joined by edges
    that two faces walk opposite ways (a consistently wound skin), whose
    holes are small (:data:`HOLE_SHARE`: scans and modelled heads have a few;
    only its faces beside an edge walked the same way twice are open; an
    edge of three faces or more is no hole and leaves the faces beside it in
    their components). Its orientation is the sign of its signed volume;
    components enclosing no volume are open. A closed component that ends at
    an edge of three faces or more (a patch of a larger whole: a wall, a
    floor, a storey's roof) is signed by what rays from its sides see of the
    outside (:func:`~aniso3d.build.outside.outside_sides`); one they see
    from neither side lies inside its whole (a storey's roof under the next
    storey's floor, the faces where an assembly's parts touch): enclosed.
    Drawn, such faces showed as lines along the joints in the texture's
    renderers (docs/coverage.md, "Touching solids")."""
    faces = np.asarray(faces, dtype=np.int64)
    nf = len(faces)
    sides = np.zeros(nf, dtype=np.int8)
    repeat = np.zeros(nf, dtype=bool)
    enclosed = np.zeros(nf, dtype=bool)
    if nf == 0:
        return sides, repeat, enclosed
    v = np.asarray(vertices, dtype=np.float64)
    f = merged_vertices(v)[faces]
    degenerate = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])
    # Rows sorted by their sorted corners (stable: a group's first row is
    # its earliest face); a row equal to the one before repeats it.
    c = np.sort(f, axis=1)
    order = np.lexsort((c[:, 2], c[:, 1], c[:, 0]))
    c = c[order]
    again = np.all(c[1:] == c[:-1], axis=1)
    del c
    repeat[order[1:][again]] = True
    repeat &= ~degenerate
    topo = np.flatnonzero(~repeat & ~degenerate)
    if len(topo) == 0:
        return sides, repeat, enclosed
    sides[topo], enclosed[topo] = _closed_components(v, faces[topo], f[topo])
    return sides, repeat, enclosed


def _closed_components(v: np.ndarray, faces: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`face_topology`'s sides and enclosed faces of non-degenerate,
    unrepeated faces ``faces`` whose merged corners are ``f``."""
    nf = len(faces)
    a = f.reshape(-1)
    b = f[:, [1, 2, 0]].reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    n = int(f.max()) + 1
    key = lo * n + hi
    _, inverse, count = np.unique(key, return_inverse=True, return_counts=True)
    # +1 walked low to high, -1 back: an edge shared the other way sums to 0.
    walk = np.bincount(inverse, weights=np.where(a < b, 1.0, -1.0), minlength=len(count))
    good = (count == 2) & (walk == 0)
    # A face beside an edge walked the same way by both its faces is open:
    # it may be wound against its neighbours. An edge of three faces or
    # more (a fin, a wall meeting a floor, a seam where a sheet touches the
    # skin) leaves its faces in the components their other edges join
    # them to, wound as those are (until the rule of docs/coverage.md,
    # "Edges of three faces", such faces were open too: a building whose
    # walls meet its floors read 17 % closed, now 61 %).
    local = (good | (count == 1) | (count > 2))[inverse].reshape(-1, 3).all(axis=1)
    # Components: faces joined by edges that two faces walk opposite ways.
    order = np.argsort(inverse, kind="stable")
    first = np.concatenate([[0], np.cumsum(count)[:-1]])
    pair = first[good]
    u, w = order[pair] // 3, order[pair + 1] // 3
    root = connected_components(nf, u, w)
    # A component's holes: chains of its border edges (edges of one face,
    # or walked the same way by two) joined at their corners, each the sum
    # of its edges' lengths; its hole measure the sum of their squares. An
    # edge of three faces or more is no hole.
    corner = v[faces.reshape(-1)]
    length = np.linalg.norm(v[faces[:, [1, 2, 0]].reshape(-1)] - corner, axis=1)
    border = ((count == 1) | ((count == 2) & (walk != 0)))[inverse]
    chain = connected_components(n, a[border], b[border])[a[border]]
    comp = root[np.arange(len(a)) // 3][border]
    pieces, piece = np.unique(comp * n + chain, return_inverse=True)
    loop = np.bincount(piece, weights=length[border], minlength=len(pieces))
    hole = np.bincount(pieces // n, weights=loop**2, minlength=nf)
    t = v[faces]
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    skin = np.bincount(root, weights=area, minlength=nf)
    closed = hole <= HOLE_SHARE * skin
    sign = volume_signs(v, faces, root, nf)
    # A closed component that ends at an edge of three faces or more (one
    # of its faces there, or three) is a patch of a larger whole (a wall, a
    # floor, a lid): enclosing nothing, its own signed volume says nothing
    # of its side; what the outside sees of it does. (A skin that goes on
    # across such an edge, a scan under a fin, is closed by itself.) Its
    # outside is that of the whole its patches make, joined by such edges:
    # rays meet only that whole's faces, not the next building's.
    ranked = inverse[order]
    many = count[ranked] > 2
    if many.any():
        # Per (edge, component) the number of the component's faces there.
        e, c = ranked[many], root[order[many] // 3]
        key = np.unique(e * nf + c, return_counts=True)
        ends = np.unique(key[0][key[1] % 2 == 1] % nf)
        patches = ends[closed[ends]]
        sign[patches] = 0  # open, unless the rays (within budget) read a side
        if 0 < len(patches) <= OUTSIDE_PATCHES:
            link = (ranked[:-1] == ranked[1:]) & (count[ranked[:-1]] > 2)
            whole = connected_components(nf, root[order[:-1][link] // 3], root[order[1:][link] // 3])[root]
            part = np.isin(whole, whole[np.isin(root, patches)])
            if np.count_nonzero(part) <= OUTSIDE_FACES:
                sign[patches] = outside_sides(v, faces[part], f[part], root[part], patches, whole[part])
                # Enclosed only in a watertight whole: where the whole has a
                # border (a window in a wall), rays from a few sample points
                # may all miss it, and the faces seen through it would go.
                border = (count == 1)[inverse].reshape(-1, 3).any(axis=1)
                leaky = np.zeros(nf, dtype=bool)
                leaky[whole[border]] = True
                sign[patches[(sign[patches] == ENCLOSED) & leaky[whole[patches]]]] = 0
    # A patch no ray from either side leaves its watertight whole by lies inside it.
    enclosed = sign[root] == ENCLOSED
    sign[sign == ENCLOSED] = 0
    return np.where(local & closed[root], sign[root], 0).astype(np.int8), enclosed


def volume_signs(v: np.ndarray, faces: np.ndarray, root: np.ndarray, n: int) -> np.ndarray:
    """(n,) int64: the sign of each component's signed volume (faces (F, 3)
    into ``v``, component labels ``root`` (F,) below ``n``), taken about the
    vertices' mean; 0 within 1e-12 of the extent cubed (no volume)."""
    p0, p1, p2 = (v[faces[:, k]] - v.mean(axis=0) for k in range(3))
    volume = np.bincount(root, weights=np.einsum("ij,ij->i", p0, np.cross(p1, p2)), minlength=n)
    extent = float(np.ptp(v, axis=0).max()) if len(v) else 0.0
    tiny = 1e-12 * extent**3
    return np.where(volume > tiny, 1, np.where(volume < -tiny, -1, 0))


def connected_components(n: int, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(n,) int64: a label per node of the graph of ``n`` nodes and edges
    ``u[i] - w[i]``, the smallest node of its component (hooking each root
    onto the smaller of two joined roots, then pointer jumping, until no
    edge joins two roots: a few rounds, no loop over nodes or edges)."""
    parent = np.arange(n, dtype=np.int64)
    u, w = np.asarray(u, dtype=np.int64), np.asarray(w, dtype=np.int64)
    while True:
        ru, rw = parent[u], parent[w]
        keep = ru != rw
        if not keep.any():
            return parent
        lo, hi = np.minimum(ru[keep], rw[keep]), np.maximum(ru[keep], rw[keep])
        np.minimum.at(parent, hi, lo)
        while True:
            jumped = parent[parent]
            if np.array_equal(jumped, parent):
                break
            parent = jumped
