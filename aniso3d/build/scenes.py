"""Built-in scenes: a procedural tree (the paper's test object), the corpus
of scenes the bench runs (:data:`CORPUS`: bush, grass, lattice, fur, shell,
blob, room, mixed; docs/corpus.md) and the small analytic shapes the tests
use. All are deterministic; the procedural ones are seeded and take their
sizes as parameters, and every one is built with array operations (no Python
loop per leaf, blade, strand or triangle).

The world is y-up, in metres for the tree (about 10 m tall), the bush, grass,
room and mixed scenes.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from aniso3d.build.mesh import Mesh, concatenate
from aniso3d.errors import InputError

BARK_KD = (0.36, 0.25, 0.16)


def quad(
    size: float = 1.0,
    center=(0.0, 0.0, 0.0),
    normal_axis: int = 2,
    kd=(0.8, 0.8, 0.8),
    ks: float = 0.1,
    shininess: float = 16.0,
) -> Mesh:
    """An axis-aligned square of edge ``size`` facing +``normal_axis`` (2 triangles)."""
    a, b = [i for i in range(3) if i != normal_axis]
    s = 0.5 * size
    v = np.zeros((4, 3))
    v[:, a] = [-s, s, s, -s]
    v[:, b] = [-s, -s, s, s]
    # Orient so the normal is +axis: (a, b, normal_axis) must be right-handed.
    faces = np.array([[0, 1, 2], [0, 2, 3]]) if (normal_axis - a) % 3 == 2 else np.array([[0, 2, 1], [0, 3, 2]])
    return Mesh.from_arrays(v + np.asarray(center, float), faces, kd, ks, shininess, name="quad")


def cube(size: float = 1.0, center=(0.0, 0.0, 0.0), kd=(0.8, 0.8, 0.8), ks=0.1, shininess=16.0) -> Mesh:
    """An axis-aligned cube of edge ``size``, outward normals (12 triangles)."""
    import trimesh

    box = trimesh.creation.box(extents=(size, size, size))
    return Mesh.from_arrays(
        np.asarray(box.vertices) + np.asarray(center, float), np.asarray(box.faces), kd, ks, shininess, name="cube"
    )


def sphere(radius: float = 1.0, center=(0.0, 0.0, 0.0), subdivisions: int = 4, kd=(0.8, 0.8, 0.8),
           ks=0.1, shininess=16.0) -> Mesh:  # fmt: skip
    """An icosphere (20 * 4**subdivisions triangles)."""
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return Mesh.from_arrays(
        np.asarray(s.vertices) + np.asarray(center, float), np.asarray(s.faces), kd, ks, shininess, name="sphere"
    )


def storeys(levels: int = 2, size: float = 1.0, kd=(0.8, 0.8, 0.8), ks=0.1, shininess=16.0) -> Mesh:
    """``levels`` cubes of edge ``size`` stacked along +y, each storey's
    floor the one below's roof, drawn once (wound upwards, as the lower
    box's lid): the plates' edges are shared by three faces, the way
    modelling tools build a building's storeys. Outward normals; the
    plates between storeys are its faces whose corners all lie at an inner
    level (0 < y < levels * size)."""
    _check_count("storeys", levels=levels)
    _check_positive("storeys", size=size)
    h = 0.5 * size
    ring = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])  # counter-clockwise seen from +y
    y = np.arange(levels + 1, dtype=np.float64) * size
    v = np.stack([np.repeat(ring[None, :, 0], levels + 1, 0), np.repeat(y[:, None], 4, 1),
                  -np.repeat(ring[None, :, 1], levels + 1, 0)], axis=-1).reshape(-1, 3)  # fmt: skip
    i = np.arange(4)
    j = (i + 1) % 4
    lvl = np.arange(levels)[:, None] * 4
    b0, b1, t0, t1 = lvl + i, lvl + j, lvl + 4 + i, lvl + 4 + j
    walls = np.concatenate([np.stack([b0, b1, t1], -1), np.stack([b0, t1, t0], -1)], axis=1).reshape(-1, 3)
    up = np.array([[0, 1, 2], [0, 2, 3]])
    caps = np.concatenate([up[:, ::-1]] + [up + 4 * k for k in range(1, levels + 1)])  # the floor downwards
    return Mesh.from_arrays(v, np.concatenate([walls, caps]), kd, ks, shininess, name="storeys")


def _rotate(v: np.ndarray, axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues rotation of vectors v (n, 3) about unit axes (n, 3) by angles (n,)."""
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return v * c + np.cross(axis, v) * s + axis * np.sum(axis * v, axis=1, keepdims=True) * (1 - c)


def _perpendicular(d: np.ndarray) -> np.ndarray:
    helper = np.where((np.abs(d[:, 1]) < 0.9)[:, None], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0])
    p = np.cross(d, helper)
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def _cylinders(start, direction, length, r0, r1, sides: int):
    """Vertices and faces of open tapered cylinders, vectorised over branches."""
    n = len(start)
    u = _perpendicular(direction)
    w = np.cross(direction, u)
    ang = np.linspace(0.0, 2 * np.pi, sides, endpoint=False)
    ring = np.cos(ang)[None, :, None] * u[:, None] + np.sin(ang)[None, :, None] * w[:, None]
    end = start + direction * length[:, None]
    bottom = start[:, None] + ring * r0[:, None, None]
    top = end[:, None] + ring * r1[:, None, None]
    verts = np.concatenate([bottom, top], axis=1).reshape(-1, 3)
    i = np.arange(sides)
    j = (i + 1) % sides
    quad_faces = np.concatenate(
        [np.stack([i, j, sides + j], 1), np.stack([i, sides + j, sides + i], 1)]
    )
    faces = (quad_faces[None] + (np.arange(n) * 2 * sides)[:, None, None]).reshape(-1, 3)
    return verts, faces


def tree(
    seed: int = 1,
    levels: int = 6,
    children: int = 4,
    leaves_per_twig: int = 120,
    height: float = 10.0,
    leaf_size: float = 0.12,
    sides: int = 6,
) -> Mesh:
    """A procedural broadleaf tree: bark-coloured tapered cylinders branching
    recursively, and many small two-triangle leaves in greens.

    The default (seed 1) has about 270,000 triangles: 4**5 = 1024 twigs with
    ``leaves_per_twig`` leaves each... scaled by the parameters. Deterministic
    for a given seed and parameters.
    """
    if levels < 1 or children < 1 or leaves_per_twig < 0 or sides < 3:
        raise InputError("tree needs levels >= 1, children >= 1, leaves_per_twig >= 0, sides >= 3")
    if not (height > 0 and leaf_size > 0):
        raise InputError("tree height and leaf_size must be positive")
    rng = np.random.default_rng(seed)
    trunk_len = 0.35 * height
    start = np.zeros((1, 3))
    direction = np.array([[0.0, 1.0, 0.0]])
    length = np.array([trunk_len])
    radius = np.array([0.035 * height])
    parts_v, parts_f, offset = [], [], 0
    twigs = None
    for level in range(levels):
        r_end = radius * 0.65
        v, f = _cylinders(start, direction, length, radius, r_end, sides)
        parts_v.append(v)
        parts_f.append(f + offset)
        offset += len(v)
        if level == levels - 1:
            twigs = (start, direction, length)
            break
        n = len(start)
        m = n * children
        parent = np.repeat(np.arange(n), children)
        t = rng.uniform(0.45, 1.0, m)
        t[::children] = 1.0  # one child continues from the tip
        cstart = start[parent] + direction[parent] * (length[parent] * t)[:, None]
        azimuth = (np.tile(np.arange(children), n) + rng.uniform(-0.3, 0.3, m)) * 2 * np.pi / children
        azimuth += rng.uniform(0, 2 * np.pi, n)[parent]
        spin_axis = _rotate(_perpendicular(direction[parent]), direction[parent], azimuth)
        tilt = rng.uniform(0.45, 0.85, m)
        cdir = _rotate(direction[parent], spin_axis, tilt)
        # A gentle upward tendency, as in real trees.
        cdir = cdir + np.array([0.0, 0.25, 0.0])
        cdir /= np.linalg.norm(cdir, axis=1, keepdims=True)
        start, direction = cstart, cdir
        length = length[parent] * rng.uniform(0.55, 0.75, m) * (1.3 if level == 0 else 1.0)
        radius = r_end[parent] * (1 - t * 0.3) * 0.75

    # Leaves along the twigs (and their parents' tips), random orientations.
    s, d, L = twigs
    n_leaf = len(s) * leaves_per_twig
    if n_leaf:
        owner = np.repeat(np.arange(len(s)), leaves_per_twig)
        t = rng.uniform(0.0, 1.3, n_leaf)
        base = s[owner] + d[owner] * (L[owner] * t)[:, None]
        base += rng.normal(scale=0.25 * L[owner, None], size=(n_leaf, 3))
        axis = rng.normal(size=(n_leaf, 3))
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        side = _perpendicular(axis)
        side = _rotate(side, axis, rng.uniform(0, 2 * np.pi, n_leaf))
        size = leaf_size * rng.uniform(0.7, 1.3, n_leaf)
        tip = base + axis * size[:, None]
        mid = base + axis * (0.5 * size)[:, None]
        half_w = (0.3 * size)[:, None]
        lv = np.stack([base, mid + side * half_w, tip, mid - side * half_w], axis=1).reshape(-1, 3)
        lf = (np.array([[0, 1, 2], [0, 2, 3]])[None] + (np.arange(n_leaf) * 4)[:, None, None]).reshape(-1, 3)
        greens = np.stack(
            [rng.uniform(0.10, 0.35, n_leaf), rng.uniform(0.35, 0.70, n_leaf), rng.uniform(0.05, 0.20, n_leaf)],
            axis=1,
        )
        leaves = Mesh.from_arrays(lv, lf, np.repeat(greens, 2, axis=0), 0.15, 24.0, name="leaves")
    wood_v = np.concatenate(parts_v)
    wood_f = np.concatenate(parts_f)
    wood = Mesh.from_arrays(wood_v, wood_f, BARK_KD, 0.05, 8.0, name="wood")
    parts = [wood, leaves] if n_leaf else [wood]
    return concatenate(parts, name="tree")



# --------------------------------------------------------------------------- corpus helpers
#
# The corpus scenes below share a few vectorised builders: many thin strips
# (grass blades, hairs), many boxes (beams, furniture), a height-field grid
# (ground, paper). Each builder makes all its parts in one set of array
# operations; a scene loops at most over a handful of parts.


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _random_directions(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 3) unit vectors uniform on the sphere."""
    return _unit(rng.normal(size=(n, 3)))


def _strips(points: np.ndarray, side: np.ndarray, half_width: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tapered strips (blades, hairs) along centrelines, all at once.

    Args:
        points: (n, s + 1, 3) centreline of each strip, base (0) to tip (s).
        side: (n, s, 3) unit vectors across the strip at points 0..s-1.
        half_width: (n, s) positive half widths there; the tip is one vertex.

    Returns (vertices (n * (2 s + 1), 3), faces (n * (2 s - 1), 3)). The faces
    of each strip are ordered by segment: segment j < s - 1 owns faces 2j and
    2j + 1, the last segment the single tip triangle (see :func:`_strip_segment`).
    """
    n, s1, _ = points.shape
    s = s1 - 1
    offset = side * half_width[..., None]
    ring = np.stack([points[:, :s] - offset, points[:, :s] + offset], axis=2).reshape(n, 2 * s, 3)
    verts = np.concatenate([ring, points[:, s:]], axis=1).reshape(-1, 3)
    j = np.arange(s - 1)
    left0, right0, left1, right1 = 2 * j, 2 * j + 1, 2 * j + 2, 2 * j + 3
    quads = np.stack([np.stack([left0, right0, right1], 1), np.stack([left0, right1, left1], 1)], 1).reshape(-1, 3)
    template = np.concatenate([quads, [[2 * s - 2, 2 * s - 1, 2 * s]]])
    faces = (template[None] + (np.arange(n) * (2 * s + 1))[:, None, None]).reshape(-1, 3)
    return verts, faces


def _strip_segment(segments: int) -> np.ndarray:
    """(2 s - 1,) segment index of each face of one strip made by :func:`_strips`."""
    return np.concatenate([np.repeat(np.arange(segments - 1), 2), [segments - 1]])


def _bent_centrelines(base, start_dir, bend_dir, bend, length, segments: int) -> tuple[np.ndarray, np.ndarray]:
    """Centrelines that leave ``base`` (n, 3) along unit ``start_dir`` (n, 3) and
    curve towards unit ``bend_dir`` (n, 3, perpendicular to start_dir) by a total
    angle ``bend`` (n,) radians, growing with the square of the distance along
    (a blade or hair bowing under its own weight), each of ``length`` (n,).

    Returns (points (n, s + 1, 3), tangents (n, s, 3) of the segments)."""
    t = (np.arange(segments) + 0.5) / segments
    angle = bend[:, None] * t[None] ** 2
    tangent = np.cos(angle)[..., None] * start_dir[:, None] + np.sin(angle)[..., None] * bend_dir[:, None]
    steps = tangent * (length / segments)[:, None, None]
    points = np.concatenate([base[:, None], base[:, None] + np.cumsum(steps, axis=1)], axis=1)
    return points, tangent


def _box_template() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit-cube corners (8, 3), outward triangles (12, 3) and the side of each
    triangle (12,): 0..5 = -x, +x, -y, +y, -z, +z."""
    corners = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], dtype=np.float64)
    quads = []
    for axis in range(3):
        for high in (0, 1):
            idx = np.flatnonzero(corners[:, axis] == high)
            a, b = [i for i in range(3) if i != axis]
            # Order the four corners around the face, then orient outwards.
            c = corners[idx]
            order = np.argsort(np.arctan2(c[:, b] - 0.5, c[:, a] - 0.5))
            q = idx[order]
            normal = np.cross(corners[q[1]] - corners[q[0]], corners[q[2]] - corners[q[0]])
            if (normal[axis] > 0) != bool(high):
                q = q[::-1]
            quads.append(q)
    quads = np.array(quads)
    faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]], axis=1).reshape(-1, 3)
    return corners, faces, np.repeat(np.arange(6), 2)


_BOX_CORNERS, _BOX_FACES, _BOX_SIDE = _box_template()


def _boxes(lo: np.ndarray, hi: np.ndarray, keep: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Axis-aligned boxes [lo, hi] (n, 3), outward normals, all at once.

    ``keep`` (n, 6) bool chooses the sides (-x, +x, -y, +y, -z, +z) to emit,
    so that boxes which touch leave out the faces they share (no coplanar
    doubled area, no z-fighting). Returns (vertices (8 n, 3), faces (F, 3),
    owner (F,) index of each face's box)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    n = len(lo)
    verts = (lo[:, None] + _BOX_CORNERS[None] * (hi - lo)[:, None]).reshape(-1, 3)
    faces = (_BOX_FACES[None] + (np.arange(n) * 8)[:, None, None]).reshape(-1, 3)
    owner = np.repeat(np.arange(n), len(_BOX_FACES))
    if keep is not None:
        mask = np.asarray(keep, bool)[:, _BOX_SIDE].ravel()
        faces, owner = faces[mask], owner[mask]
    return verts, faces, owner


def _grid_faces(nu: int, nv: int) -> np.ndarray:
    """Triangles (2 nu nv, 3) of an (nu + 1) x (nv + 1) vertex grid, row-major
    in v then u (vertex i * (nv + 1) + j is (u_i, v_j))."""
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = (i * (nv + 1) + j).ravel()
    b, c, d = a + nv + 1, a + nv + 2, a + 1
    return np.stack([np.stack([a, d, c], 1), np.stack([a, c, b], 1)], 1).reshape(-1, 3)


def _waves(rng: np.random.Generator, count: int, wavelength: tuple[float, float]):
    """A smooth seeded function f(x, z) in [-1, 1]: the mean of ``count`` plane
    waves with random directions, wavelengths (world units) and phases."""
    k = 2 * np.pi / rng.uniform(*wavelength, count)
    theta = rng.uniform(0, 2 * np.pi, count)
    phase = rng.uniform(0, 2 * np.pi, count)
    kx, kz = k * np.cos(theta), k * np.sin(theta)

    def f(x: np.ndarray, z: np.ndarray) -> np.ndarray:
        x, z = np.asarray(x, np.float64), np.asarray(z, np.float64)
        return np.sin(x[..., None] * kx + z[..., None] * kz + phase).mean(axis=-1)

    return f


def _terrain(rng: np.random.Generator, size: float, cells: int, amplitude: float, kd, jitter: float = 0.04):
    """A square, gently undulating ground of edge ``size`` centred on the
    origin at y ~ 0, as a (cells x cells) grid facing +y; returns the mesh and
    its height function h(x, z) so that things can stand on it."""
    wave = _waves(rng, 4, (0.4 * size, 1.2 * size))

    def height(x, z):
        return amplitude * wave(x, z)

    u = np.linspace(-0.5 * size, 0.5 * size, cells + 1)
    x, z = np.meshgrid(u, u, indexing="ij")
    verts = np.stack([x, height(x, z), z], axis=-1).reshape(-1, 3)
    faces = _grid_faces(cells, cells)
    colour = np.asarray(kd) * rng.uniform(1 - jitter, 1 + jitter, (len(faces), 1))
    return Mesh.from_arrays(verts, faces, colour, 0.03, 4.0, name="ground"), height


def _check_positive(scene: str, **values) -> None:
    bad = {k: v for k, v in values.items() if not (isinstance(v, int | float) and np.isfinite(v) and v > 0)}
    if bad:
        raise InputError(f"{scene}: {', '.join(f'{k}={v!r}' for k, v in bad.items())} must be positive numbers")


def _check_count(scene: str, minimum: int = 1, **values) -> None:
    bad = {k: v for k, v in values.items() if isinstance(v, bool) or int(v) != v or v < minimum}
    if bad:
        raise InputError(f"{scene}: {', '.join(f'{k}={v!r}' for k, v in bad.items())} must be whole numbers "
                         f">= {minimum}")  # fmt: skip


# --------------------------------------------------------------------------- corpus scenes


def bush(
    seed: int = 1,
    leaves: int = 250_000,
    width: float = 1.6,
    height: float = 1.0,
    leaf_size: float = 0.0055,
    stems: int = 9,
    spray: float = 0.07,
) -> Mesh:
    """A dense, small-leaved bush (box or heather): brown stems fanning out from
    the root, and ``leaves`` single-triangle leaves at random orientations in
    sprays (leaves scattered by ``spray`` metres about a centre) crowded towards the surface of a lumpy,
    roughly ellipsoidal crown ``width`` wide and ``height`` tall.

    Metres, y-up, the root at the origin. A leaf is ``leaf_size`` long (about
    0.4 of a voxel of the default bush at 128^3: sub-voxel foliage, the
    case the texture exists for) and 0.8 of that wide. Faces: the stems'
    cylinders first (``stems`` * 5 cylinders of 6 sides, 12 triangles each),
    then one triangle per leaf.
    """
    _check_count("bush", 0, leaves=leaves)
    _check_count("bush", 1, stems=stems)
    _check_positive("bush", width=width, height=height, leaf_size=leaf_size)
    if not (np.isfinite(spray) and spray >= 0):
        raise InputError(f"bush: spray is a distance in metres >= 0, got {spray!r}")
    rng = np.random.default_rng(seed)
    centre = np.array([0.0, 0.55 * height, 0.0])
    radii = np.array([0.5 * width, 0.45 * height, 0.5 * width])

    # Stems: main stems from the root to points in the upper crown, each with
    # four side shoots towards the crown's surface.
    aim = centre + _random_directions(rng, stems) * radii * np.array([0.6, 0.5, 0.6])
    aim[:, 1] = np.maximum(aim[:, 1], 0.6 * height)
    main_len = np.linalg.norm(aim, axis=1)
    main_dir = aim / main_len[:, None]
    shoots = 4
    parent = np.repeat(np.arange(stems), shoots)
    t = rng.uniform(0.3, 0.9, stems * shoots)
    shoot_start = main_dir[parent] * (main_len[parent] * t)[:, None]
    shoot_aim = centre + _unit(rng.normal(size=(stems * shoots, 3)) + 0.8 * main_dir[parent]) * radii * 0.9
    shoot_vec = shoot_aim - shoot_start
    shoot_len = np.maximum(np.linalg.norm(shoot_vec, axis=1), 0.05 * height)
    shoot_dir = _unit(shoot_vec)
    r_main = 0.008 * height
    start = np.concatenate([np.zeros((stems, 3)), shoot_start])
    direction = np.concatenate([main_dir, shoot_dir])
    length = np.concatenate([main_len, shoot_len])
    r0 = np.concatenate([np.full(stems, r_main), np.full(stems * shoots, 0.45 * r_main)])
    sv, sf = _cylinders(start, direction, length, r0, 0.35 * r0, 6)
    wood = Mesh.from_arrays(sv, sf, BARK_KD, 0.05, 8.0, name="stems")
    if leaves == 0:
        return Mesh(wood.vertices, wood.faces, wood.kd, wood.ks, wood.shininess, "bush")

    # Leaves in sprays: spray centres crowd towards the crown's surface
    # (radius u^(1/6) of the crown's: as light shapes real bushes), the leaves
    # of a spray scatter about its centre by a normal of ``spray`` metres.
    sprays = max(1, leaves // 150)
    where = _random_directions(rng, sprays) * rng.uniform(0, 1, sprays)[:, None] ** (1 / 6)
    spray_of = rng.integers(0, sprays, leaves)
    base = centre + where[spray_of] * radii + rng.normal(scale=spray, size=(leaves, 3))
    # The crown's outline is lumpy: its radius along unit direction d is
    # 1 + 0.25 lump(d) of the ellipsoid's, lump a sum of smooth waves in [-1, 1].
    # Leaves scattered past it go back inside: a crisp, irregular outline.
    k = _random_directions(rng, 8) * rng.uniform(3.0, 6.0, 8)[:, None]
    phase = rng.uniform(0, 2 * np.pi, 8)
    rel = (base - centre) / radii
    depth = np.linalg.norm(rel, axis=1, keepdims=True)
    lump = np.sin((rel / np.maximum(depth, 1e-12)) @ k.T + phase).sum(axis=1, keepdims=True) / np.sqrt(8)
    depth = depth / (1.0 + 0.25 * np.clip(lump, -1.0, 1.0))
    inside = np.minimum(1.0, rng.uniform(0.93, 1.0, (leaves, 1)) / depth)
    base = centre + (base - centre) * inside
    depth = depth * inside
    base[:, 1] = np.maximum(base[:, 1], 0.05 * height)
    axis = _random_directions(rng, leaves)
    across = _rotate(_perpendicular(axis), axis, rng.uniform(0, 2 * np.pi, leaves))
    size = leaf_size * rng.uniform(0.85, 1.12, leaves)
    tip = base + axis * size[:, None]
    half = across * (0.4 * size)[:, None]
    lv = np.stack([base, tip - half, tip + half], axis=1).reshape(-1, 3)
    lf = np.arange(3 * leaves).reshape(-1, 3)
    shade = rng.uniform(0.75, 1.15, leaves)[:, None]
    # Inner leaves darker (self-shadowing the lighting model does not have).
    shade *= 0.5 + 0.5 * np.clip(depth, 0.0, 1.0)
    green = np.array([0.18, 0.46, 0.11]) * shade + rng.uniform(-0.03, 0.03, (leaves, 3))
    foliage = Mesh.from_arrays(lv, lf, green, 0.12, 20.0, name="leaves")
    return concatenate([wood, foliage], name="bush")


def grass(
    seed: int = 1,
    blades: int = 12_000,
    size: float = 1.0,
    blade_height: float = 0.22,
    blade_width: float = 0.006,
    segments: int = 4,
) -> Mesh:
    """A square patch of grass: ``blades`` thin blades on a gently undulating
    ground of edge ``size``.

    Metres, y-up, the patch centred on the origin. Each blade is a tapered strip
    of ``segments`` segments (2 * segments - 1 triangles, the last a pointed
    tip) rising with a random lean and bowing further towards its tip, green
    darkening towards the ground. The ground is a 24 x 24 grid (1152 triangles)
    first, then the blades. Blade widths (about 0.6 of a voxel of the default
    patch at 128^3) make this the thin-feature case with a dense, view-dependent
    coverage: seen from the side, the blades close; from above, the ground
    shows.
    """
    _check_count("grass", 0, blades=blades)
    _check_count("grass", 2, segments=segments)
    _check_positive("grass", size=size, blade_height=blade_height, blade_width=blade_width)
    rng = np.random.default_rng(seed)
    ground, ground_height = _terrain(rng, size, 24, 0.03 * blade_height, (0.33, 0.25, 0.15))
    if blades == 0:
        return Mesh(ground.vertices, ground.faces, ground.kd, ground.ks, ground.shininess, "grass")
    xz = rng.uniform(-0.5 * size, 0.5 * size, (blades, 2))
    base = np.stack([xz[:, 0], ground_height(xz[:, 0], xz[:, 1]) - 0.002 * blade_height, xz[:, 1]], axis=1)
    azimuth = rng.uniform(0, 2 * np.pi, blades)
    outward = np.stack([np.cos(azimuth), np.zeros(blades), np.sin(azimuth)], axis=1)
    lean = rng.uniform(0.0, 0.35, blades)
    up = np.array([0.0, 1.0, 0.0])
    start_dir = np.cos(lean)[:, None] * up + np.sin(lean)[:, None] * outward
    bend_dir = -np.sin(lean)[:, None] * up + np.cos(lean)[:, None] * outward
    length = blade_height * rng.uniform(0.55, 1.25, blades)
    points, tangent = _bent_centrelines(base, start_dir, bend_dir, rng.uniform(0.2, 1.2, blades), length, segments)
    # The blade's flat side faces the way it bends (perpendicular to the bend
    # plane), turned a little at random.
    flat = np.cross(start_dir, bend_dir)
    twist = rng.uniform(-0.5, 0.5, blades)[:, None, None]
    side = np.cos(twist) * flat[:, None] + np.sin(twist) * np.cross(tangent, flat[:, None])
    t = np.arange(segments) / segments
    half = 0.5 * blade_width * rng.uniform(0.7, 1.3, blades)[:, None] * (1.0 - 0.75 * t)[None]
    bv, bf = _strips(points, side, half)
    seg_t = (_strip_segment(segments) + 0.5) / segments
    hue = np.array([0.20, 0.50, 0.10]) * rng.uniform(0.8, 1.2, (blades, 1)) + rng.uniform(-0.04, 0.04, (blades, 3))
    hue[:, 0] += rng.uniform(0.0, 0.12, blades)  # some blades yellower
    kd = hue[:, None, :] * (0.45 + 0.6 * seg_t)[None, :, None]
    blade_mesh = Mesh.from_arrays(bv, bf, kd.reshape(-1, 3), 0.15, 18.0, name="blades")
    return concatenate([ground, blade_mesh], name="grass")


def lattice(
    seed: int = 1,
    cells: int = 8,
    cell_size: float = 1.0,
    beam_width: float = 0.07,
    missing: float = 0.1,
    tilt: float = 20.0,
) -> Mesh:
    """A truss: square-section beams along the edges of a ``cells``^3 cubic
    lattice, a fraction ``missing`` of the beams left out at random.

    World units of ``cell_size``; ``beam_width`` is a fraction of a cell (the
    default, 0.07 of a cell, is about 0.8 of a voxel at 128^3 for 8 cells: thin
    features along long straight lines, where aliasing is most visible). Each
    beam is an open square tube between two node cubes, and a node cube keeps
    only the sides no beam attaches to, so the truss is one closed surface
    with no doubled faces. The whole is turned by ``tilt`` degrees about y and
    half that about x, so that the beams do not line up with the voxel grid
    (the room scene covers that case).
    """
    _check_count("lattice", 1, cells=cells)
    _check_positive("lattice", cell_size=cell_size, beam_width=beam_width)
    if not (0 < beam_width < 1):
        raise InputError(f"lattice: beam_width is a fraction of a cell in (0, 1), got {beam_width!r}")
    if not (0 <= missing < 1):
        raise InputError(f"lattice: missing is a fraction of beams in [0, 1), got {missing!r}")
    rng = np.random.default_rng(seed)
    n = cells
    w = 0.5 * beam_width * cell_size
    # present[a]: beams along axis a, indexed by their lower node; shape n along
    # a and n + 1 across.
    present = []
    for a in range(3):
        shape = [n + 1] * 3
        shape[a] = n
        present.append(rng.uniform(size=shape) >= missing)
    lo_parts, hi_parts, keep_parts = [], [], []
    attached = np.zeros((n + 1, n + 1, n + 1, 6), dtype=bool)
    for a in range(3):
        idx = np.argwhere(present[a])
        node = idx * cell_size
        lo = node - w
        hi = node + w
        lo[:, a] = node[:, a] + w
        hi[:, a] = node[:, a] + cell_size - w
        keep = np.ones((len(idx), 6), dtype=bool)
        keep[:, 2 * a : 2 * a + 2] = False  # open ends: the node cubes close them
        lo_parts.append(lo)
        hi_parts.append(hi)
        keep_parts.append(keep)
        upper = idx.copy()
        upper[:, a] += 1
        attached[tuple(idx.T) + (2 * a + 1,)] = True  # the beam leaves its lower node on the + side
        attached[tuple(upper.T) + (2 * a,)] = True
    used = attached.any(axis=3)
    nodes = np.argwhere(used)
    lo_parts.append(nodes * cell_size - w)
    hi_parts.append(nodes * cell_size + w)
    keep_parts.append(~attached[used])
    v, f, owner = _boxes(np.concatenate(lo_parts), np.concatenate(hi_parts), np.concatenate(keep_parts))
    v = v - 0.5 * n * cell_size
    yaw, pitch = np.radians(tilt), np.radians(0.5 * tilt)
    ry = np.array([[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]])
    rx = np.array([[1, 0, 0], [0, np.cos(pitch), -np.sin(pitch)], [0, np.sin(pitch), np.cos(pitch)]])
    v = v @ (rx @ ry).T
    # Painted steel, each beam a slightly different shade.
    shade = rng.uniform(0.9, 1.1, len(np.concatenate(lo_parts)))[owner, None]
    kd = np.array([0.80, 0.42, 0.12]) * shade
    return Mesh.from_arrays(v, f, kd, 0.35, 40.0, name="lattice")


def fur(
    seed: int = 1,
    strands: int = 11_000,
    radius: float = 1.0,
    hair_length: float = 0.55,
    hair_width: float = 0.007,
    segments: int = 5,
) -> Mesh:
    """A fur ball: ``strands`` long, thin, curved hairs growing from a sphere.

    Units of ``radius``, centred on the origin. Each hair is a strip of
    ``segments`` segments (2 * segments - 1 triangles, pointed) that leaves the
    skin along its normal and bends (by up to about 70 degrees) towards a mix of
    "down" and a random direction, as combed fur lies. The skin (an icosphere,
    1280 triangles) comes first, then the hairs. Hairs are about a quarter of a
    voxel wide at 128^3 and many voxels long: thin, overlapping strands with a
    strong specular sheen.
    """
    _check_count("fur", 0, strands=strands)
    _check_count("fur", 2, segments=segments)
    _check_positive("fur", radius=radius, hair_length=hair_length, hair_width=hair_width)
    rng = np.random.default_rng(seed)
    skin = sphere(radius, subdivisions=3, kd=(0.22, 0.13, 0.07), ks=0.05, shininess=8.0)
    if strands == 0:
        return Mesh(skin.vertices, skin.faces, skin.kd, skin.ks, skin.shininess, "fur")
    normal = _random_directions(rng, strands)
    base = normal * (0.995 * radius)
    pull = 0.8 * np.array([0.0, -1.0, 0.0]) + rng.normal(scale=0.6, size=(strands, 3))
    pull -= normal * np.sum(pull * normal, axis=1, keepdims=True)
    norm = np.linalg.norm(pull, axis=1, keepdims=True)
    # Where the pull is (almost) along the normal, any perpendicular will do.
    bend_dir = np.where(norm > 1e-6, pull / np.maximum(norm, 1e-12), _perpendicular(normal))
    length = hair_length * radius * rng.uniform(0.6, 1.2, strands)
    points, tangent = _bent_centrelines(base, normal, bend_dir, rng.uniform(0.3, 1.2, strands), length, segments)
    flat = np.cross(normal, bend_dir)
    spin = rng.uniform(0, np.pi, strands)[:, None, None]
    side = np.cos(spin) * flat[:, None] + np.sin(spin) * np.cross(tangent, flat[:, None])
    t = np.arange(segments) / segments
    half = 0.5 * hair_width * radius * (1.0 - 0.6 * t)[None].repeat(strands, axis=0)
    hv, hf = _strips(points, side, half)
    seg_t = (_strip_segment(segments) + 0.5) / segments
    # Agouti hairs: dark roots, ginger shafts, pale tips; strands vary in tone.
    root, shaft, tip = np.array([0.25, 0.14, 0.07]), np.array([0.72, 0.42, 0.18]), np.array([0.92, 0.80, 0.60])
    k = seg_t[:, None]
    ramp = np.where(k < 0.6, root + (shaft - root) * (k / 0.6), shaft + (tip - shaft) * ((k - 0.6) / 0.4))
    kd = ramp[None] * rng.uniform(0.75, 1.15, (strands, 1, 1))
    hair = Mesh.from_arrays(hv, hf, kd.reshape(-1, 3), 0.35, 30.0, name="hair")
    return concatenate([skin, hair], name="fur")


def shell(
    seed: int = 1,
    resolution: int = 160,
    size: float = 2.0,
    creases: int = 16,
    crumple: float = 0.08,
    curl: float = 1.8,
) -> Mesh:
    """A crumpled sheet of paper: one open, single-sided layer of a
    ``resolution`` x ``resolution`` grid (2 * resolution^2 triangles).

    Units of ``size`` (the sheet's edge). The flat sheet is creased along
    ``creases`` random lines (ridges and valleys of height ``crumple`` * size,
    each a sharp fold that fades with distance), roughened with small waves,
    then curled about an axis by ``curl`` radians end to end, and leaned
    towards the viewer. One layer with an open boundary: a surface with two
    sides but no inside, which a renderer must not treat as a solid.
    """
    _check_count("shell", 2, resolution=resolution)
    _check_count("shell", 0, creases=creases)
    _check_positive("shell", size=size)
    if not (np.isfinite(crumple) and crumple >= 0 and np.isfinite(curl) and 0 <= curl < 2 * np.pi):
        raise InputError(f"shell: crumple must be >= 0 and curl in [0, 2 pi), got {crumple!r}, {curl!r}")
    rng = np.random.default_rng(seed)
    u = np.linspace(-0.5 * size, 0.5 * size, resolution + 1)
    x, z = np.meshgrid(u, u, indexing="ij")
    p = np.stack([x, z], axis=-1).reshape(-1, 2)
    # Creases: height a * exp(-|d| / reach) over the signed distance d to a
    # random line: a sharp fold that fades out.
    theta = rng.uniform(0, np.pi, creases)
    line_n = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    offset = rng.uniform(-0.35, 0.35, creases) * size
    amp = rng.choice([-1.0, 1.0], creases) * rng.uniform(0.4, 1.0, creases) * crumple * size
    reach = rng.uniform(0.08, 0.3, creases) * size
    d = p @ line_n.T - offset
    # |d| softened over about two grid cells, so a fold is not a zig-zag of the grid.
    soft = 2.0 * size / resolution
    y = (amp * np.exp(-np.sqrt(d**2 + soft**2) / reach)).sum(axis=1)
    y += 0.1 * crumple * size * _waves(rng, 6, (0.1 * size, 0.3 * size))(p[:, 0], p[:, 1])
    # Curl about the z axis: arc length x on a cylinder of radius R.
    if curl > 0:
        radius = size / curl
        ang = p[:, 0] / radius
        xc = (radius - y) * np.sin(ang)
        yc = radius - (radius - y) * np.cos(ang)
    else:
        xc, yc = p[:, 0], y
    verts = np.stack([xc, yc, p[:, 1]], axis=1)
    lean = np.radians(40.0)
    rx = np.array([[1, 0, 0], [0, np.cos(lean), -np.sin(lean)], [0, np.sin(lean), np.cos(lean)]])
    verts = verts @ rx.T
    faces = _grid_faces(resolution, resolution)
    kd = np.array([0.90, 0.87, 0.80]) * rng.uniform(0.97, 1.03, (len(faces), 1))
    return Mesh.from_arrays(verts, faces, kd, 0.08, 10.0, name="shell")


def blob(
    seed: int = 1,
    subdivisions: int = 6,
    radius: float = 1.0,
    bumpiness: float = 0.3,
) -> Mesh:
    """A closed, smooth, glossy blob: an icosphere (20 * 4**subdivisions
    triangles) displaced along its radii by a seeded sum of smooth waves.

    Units of ``radius``, centred on the origin. The displacement is radial and
    keeps every radius positive, so the surface stays watertight and free of
    self-intersections: the closed-surface case, where the volume renderer's
    per-voxel coverage must add up to an opaque object. Colour shifts with the
    displacement so the shape reads at a glance.
    """
    _check_count("blob", 0, subdivisions=subdivisions)
    _check_positive("blob", radius=radius)
    if not (np.isfinite(bumpiness) and 0 <= bumpiness < 0.8):
        raise InputError(f"blob: bumpiness must be in [0, 0.8), got {bumpiness!r}")
    import trimesh

    rng = np.random.default_rng(seed)
    ico = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    unit = np.asarray(ico.vertices)
    waves = 9
    k = _random_directions(rng, waves) * rng.uniform(1.5, 4.5, waves)[:, None]
    phase = rng.uniform(0, 2 * np.pi, waves)
    bump = np.sin(unit @ k.T + phase).sum(axis=1)
    bump /= np.abs(bump).max()  # in [-1, 1]
    verts = unit * (radius * (1.0 + bumpiness * bump))[:, None]
    faces = np.asarray(ico.faces)
    level = bump[faces].mean(axis=1)[:, None]
    low, high = np.array([0.55, 0.10, 0.12]), np.array([0.95, 0.55, 0.25])
    kd = low + (high - low) * np.clip(0.5 + level, 0.0, 1.0)
    return Mesh.from_arrays(verts, faces, kd, 0.5, 60.0, name="blob")


#: Furniture of :func:`room`, in metres: (name, lo, hi, RGB, sides left out).
#: The layout is for an 8 x 3 x 6 m room and scales with the room. Sides: any of "-x +x -y +y -z +z"; a piece
#: resting on another (or on the floor) leaves out its bottom, legs also their
#: tops, so that no two faces lie on one another.
_FURNITURE = (
    # A bed against the back wall: base, mattress, pillow, headboard.
    ("bed", (0.4, 0.0, 0.2), (2.4, 0.44, 3.4), (0.45, 0.30, 0.18), "-y -z"),
    ("bed", (0.5, 0.44, 0.3), (2.3, 0.62, 3.3), (0.85, 0.85, 0.88), "-y"),
    ("bed", (0.7, 0.62, 0.4), (2.1, 0.75, 0.9), (0.95, 0.95, 0.95), "-y"),
    ("bed", (0.4, 0.0, 0.125), (2.4, 1.0, 0.2), (0.40, 0.26, 0.15), "-y"),
    # A wardrobe against the left wall.
    ("wardrobe", (0.125, 0.0, 3.8), (0.75, 2.0, 5.2), (0.55, 0.40, 0.26), "-y"),
    # A table on four legs.
    ("table", (3.8, 0.69, 2.0), (5.8, 0.75, 3.2), (0.62, 0.44, 0.28), ""),
    ("table", (3.9, 0.0, 2.1), (4.0, 0.69, 2.2), (0.30, 0.20, 0.12), "-y +y"),
    ("table", (5.6, 0.0, 2.1), (5.7, 0.69, 2.2), (0.30, 0.20, 0.12), "-y +y"),
    ("table", (3.9, 0.0, 3.0), (4.0, 0.69, 3.1), (0.30, 0.20, 0.12), "-y +y"),
    ("table", (5.6, 0.0, 3.0), (5.7, 0.69, 3.1), (0.30, 0.20, 0.12), "-y +y"),
    # A cabinet and a low crate (boxes on the floor).
    ("cabinet", (6.6, 0.0, 0.125), (7.6, 1.1, 0.6), (0.30, 0.45, 0.60), "-y"),
    ("crate", (6.2, 0.0, 4.4), (7.0, 0.5, 5.2), (0.75, 0.62, 0.35), "-y"),
)
_SIDE_NAMES = ("-x", "+x", "-y", "+y", "-z", "+z")


def room(
    seed: int = 1,
    width: float = 8.0,
    depth: float = 6.0,
    height: float = 3.0,
    cells: int = 128,
    furniture: bool = True,
    tile: int = 8,
) -> Mesh:
    """A room whose walls lie exactly on grid planes: a tiled floor, four walls
    (the two facing the default camera, +x and +z, cut down to a quarter of
    the height as in a cut-away model; no ceiling), and box furniture.

    Metres, y-up, the room spans [0, width] x [0, height] x [0, depth]; width
    must be the longest side. How the grid comes about
    (:func:`aniso3d.build.clip.make_grid`): a texture built over the mesh's own
    bounds puts the origin at their minimum corner and gives the longest axis
    ``resolution`` cells, so the voxel edge is h = width / resolution. Here
    depth and height are rounded to whole multiples of h = width / ``cells``,
    the walls are the room's bounds, and every other vertex (floor tiles of
    ``tile`` cells, furniture, the cut-down walls' tops) is snapped to a
    multiple of h: at resolution ``cells`` (and any multiple of it) every
    facet lies on a grid plane, with facets on the outermost planes. The
    walls and floor are single-sided layers; the furniture boxes leave out
    the faces they rest on. Faces: floor tiles, then the four walls
    (2 triangles each), then the furniture; the seed shifts the furniture by
    up to two cells and varies its colours. The furniture layout scales with
    the room.
    """
    _check_count("room", 1, cells=cells, tile=tile)
    _check_positive("room", width=width, depth=depth, height=height)
    if width < depth or width < height:
        raise InputError(f"room: width must be the longest side (it sets the grid), got {width} x {height} x {depth}")
    rng = np.random.default_rng(seed)
    h = width / cells
    nx = cells
    ny = max(1, int(round(height / h)))
    nz = max(1, int(round(depth / h)))
    W, H, D = nx * h, ny * h, nz * h
    low = max(1, ny // 4) * h

    # Floor tiles: a checker of two wood tones, each tile a little different.
    ex = np.unique(np.minimum(np.arange(0, nx + tile, tile), nx)) * h
    ez = np.unique(np.minimum(np.arange(0, nz + tile, tile), nz)) * h
    x0, z0 = np.meshgrid(ex[:-1], ez[:-1], indexing="ij")
    x1, z1 = np.meshgrid(ex[1:], ez[1:], indexing="ij")
    x0, z0, x1, z1 = x0.ravel(), z0.ravel(), x1.ravel(), z1.ravel()
    zero = np.zeros_like(x0)
    tiles = np.stack([np.stack([x0, zero, z0], 1), np.stack([x0, zero, z1], 1),
                      np.stack([x1, zero, z1], 1), np.stack([x1, zero, z0], 1)], axis=1)  # fmt: skip
    n_tiles = len(tiles)
    quad_faces = np.array([[0, 1, 2], [0, 2, 3]])  # +y for the floor's corner order
    fv = tiles.reshape(-1, 3)
    ff = (quad_faces[None] + (np.arange(n_tiles) * 4)[:, None, None]).reshape(-1, 3)
    ix, iz = np.meshgrid(np.arange(len(ex) - 1), np.arange(len(ez) - 1), indexing="ij")
    checker = ((ix + iz).ravel() % 2)[:, None]
    tone = np.where(checker == 0, [0.62, 0.45, 0.28], [0.50, 0.34, 0.20]) * rng.uniform(0.94, 1.06, (n_tiles, 1))
    floor = Mesh.from_arrays(fv, ff, np.repeat(tone, 2, axis=0), 0.2, 30.0, name="floor")

    # Walls: one quad each, normals facing into the room.
    wv = np.array([
        [0, 0, 0], [W, 0, 0], [W, H, 0], [0, H, 0],          # back, z = 0, faces +z
        [0, 0, 0], [0, H, 0], [0, H, D], [0, 0, D],          # left, x = 0, faces +x
        [W, 0, 0], [W, 0, D], [W, low, D], [W, low, 0],      # right (low), x = W, faces -x
        [0, 0, D], [0, low, D], [W, low, D], [W, 0, D],      # front (low), z = D, faces -z
    ], dtype=np.float64)  # fmt: skip
    wf = (quad_faces[None] + (np.arange(4) * 4)[:, None, None]).reshape(-1, 3)
    wall_kd = np.repeat([[0.78, 0.80, 0.84], [0.86, 0.82, 0.74], [0.86, 0.82, 0.74], [0.78, 0.80, 0.84]], 2, axis=0)
    walls = Mesh.from_arrays(wv, wf, wall_kd, 0.05, 8.0, name="walls")
    parts = [floor, walls]

    if furniture:
        pieces = sorted({p[0] for p in _FURNITURE})
        shift = rng.integers(-2, 3, (len(pieces), 2))  # whole cells, per piece
        owner = np.array([pieces.index(p[0]) for p in _FURNITURE])
        lo = np.array([p[1] for p in _FURNITURE], dtype=np.float64)
        hi = np.array([p[2] for p in _FURNITURE], dtype=np.float64)
        # The layout is drawn for an 8 x 3 x 6 m room; it scales with the room.
        scale = np.array([W / 8.0, H / 3.0, D / 6.0])
        lo_c = np.round(lo * scale / h).astype(np.int64)
        hi_c = np.maximum(np.round(hi * scale / h).astype(np.int64), lo_c + 1)
        # Shift whole pieces, keeping at least a cell clear of every wall.
        p_lo = np.array([lo_c[owner == i].min(axis=0) for i in range(len(pieces))])
        p_hi = np.array([hi_c[owner == i].max(axis=0) for i in range(len(pieces))])
        shift = np.clip(shift, 1 - p_lo[:, [0, 2]], np.array([nx - 1, nz - 1]) - p_hi[:, [0, 2]])
        move = np.zeros((len(pieces), 3), dtype=np.int64)
        move[:, [0, 2]] = shift
        lo_c, hi_c = lo_c + move[owner], hi_c + move[owner]
        keep = np.array([[s not in p[4].split() for s in _SIDE_NAMES] for p in _FURNITURE])
        bv, bf, box = _boxes(lo_c * h, hi_c * h, keep)
        colour = np.array([p[3] for p in _FURNITURE]) * rng.uniform(0.9, 1.1, (len(pieces), 1))[owner]
        parts.append(Mesh.from_arrays(bv, bf, np.clip(colour, 0, 1)[box], 0.15, 20.0, name="furniture"))
    return concatenate(parts, name="room")


def _moved(mesh: Mesh, offset) -> Mesh:
    m = np.eye(4)
    m[:3, 3] = offset
    return mesh.transformed(m)


def mixed(seed: int = 1, size: float = 14.0, detail: float = 1.0) -> Mesh:
    """A garden: an undulating lawn of edge ``size`` with a tree, a bush, a
    climbing frame (a lattice piece) and a glossy closed sculpture (a blob).

    Metres, y-up, the lawn centred on the origin. ``detail`` scales the leaf
    counts. Everything the other scenes stress at once, at different scales in
    one grid: sub-voxel leaves (the bush), leaves about a voxel (the tree),
    thin beams, a closed surface and a large smooth ground.
    """
    _check_positive("mixed", size=size, detail=detail)
    rng = np.random.default_rng(seed)
    sub = rng.integers(0, 2**31, 4)  # one seed per part
    ground, height = _terrain(rng, size, 40, 0.01 * size, (0.30, 0.42, 0.16))
    s = size / 14.0

    def on_ground(part: Mesh, x: float, z: float, sink: float = 0.0) -> Mesh:
        x, z = x * s, z * s
        return _moved(part, (x, float(height(x, z)) - part.bounds[0, 1] - sink, z))

    t = tree(seed=int(sub[0]), levels=5, leaves_per_twig=max(1, int(round(150 * detail))), height=7.0 * s,
             leaf_size=0.1 * s)  # fmt: skip
    b = bush(seed=int(sub[1]), leaves=max(1, int(round(30_000 * detail))), width=2.4 * s, height=1.6 * s,
             leaf_size=0.03 * s, spray=0.1 * s)  # fmt: skip
    frame = lattice(seed=int(sub[2]), cells=3, cell_size=1.0 * s, beam_width=0.06, missing=0.0, tilt=0.0)
    yaw = np.radians(25.0)
    turn = np.eye(4)
    turn[[0, 0, 2, 2], [0, 2, 0, 2]] = [np.cos(yaw), np.sin(yaw), -np.sin(yaw), np.cos(yaw)]
    frame = frame.transformed(turn)
    sculpture = blob(seed=int(sub[3]), subdivisions=4, radius=1.0 * s)
    parts = [
        ground,
        on_ground(t, -2.0, -3.0, 0.1 * s),
        on_ground(b, 2.5, -1.5, 0.02 * s),
        on_ground(frame, -3.0, 2.5),
        on_ground(sculpture, 2.5, 3.0, 0.2 * s),
    ]
    return concatenate(parts, name="mixed")


SCENES = {
    "tree": tree,
    "bush": bush,
    "grass": grass,
    "lattice": lattice,
    "fur": fur,
    "shell": shell,
    "blob": blob,
    "room": room,
    "mixed": mixed,
    "quad": quad,
    "cube": cube,
    "sphere": sphere,
    "storeys": storeys,
}

#: The scenes the bench runs, so that no choice is tuned on one object. Each
#: one's defaults build at 128^3 in a few seconds (docs/corpus.md has the
#: triangle counts, bounds and bytes).
CORPUS = ("tree", "bush", "grass", "lattice", "fur", "shell", "blob", "room", "mixed")


def get_scene(name: str, **kwargs) -> Mesh:
    """A built-in scene by name (see :data:`SCENES`), built with ``kwargs``."""
    if name not in SCENES:
        raise InputError(f"unknown built-in scene '{name}'; choose one of {', '.join(SCENES)}")
    return SCENES[name](**kwargs)


def corpus(names=CORPUS, **kwargs_by_name: dict) -> Iterator[tuple[str, Mesh]]:
    """(name, mesh) for each scene of ``names`` (default :data:`CORPUS`), built
    one at a time as the iteration reaches it, with its defaults or with the
    keyword arguments given under its name, e.g. ``corpus(bush={"leaves": 500})``."""
    names = tuple(names)
    unknown = [n for n in (*names, *kwargs_by_name) if n not in SCENES]
    if unknown:
        raise InputError(f"unknown built-in scene(s) {unknown}; choose from {', '.join(SCENES)}")
    for name in names:
        yield name, get_scene(name, **kwargs_by_name.get(name, {}))


# --------------------------------------------------------------------------- forest

#: The tree kinds of :func:`forest`: :func:`tree` arguments, small trees
#: (5,000-20,000 triangles) so that a forest of thousands stays drawable as
#: polygons up to a few hundred.
FOREST_SPECIES = (
    {"seed": 11, "levels": 5, "leaves_per_twig": 30, "leaf_size": 0.22, "height": 8.0},
    {"seed": 12, "levels": 4, "children": 5, "leaves_per_twig": 60, "leaf_size": 0.30, "height": 6.0},
    {"seed": 13, "levels": 5, "children": 3, "leaves_per_twig": 20, "leaf_size": 0.18, "height": 11.0},
)
FOREST_GROUND_KD = (0.33, 0.30, 0.18)


def forest(n_trees: int = 100, species: int = 3, seed: int = 1, area: float | None = None):
    """A :class:`~aniso3d.build.scene.Scene`: ``n_trees`` trees of ``species``
    kinds (1 to 3, :data:`FOREST_SPECIES`) scattered on a square ground quad
    of edge ``area`` metres (default ``8 sqrt(n_trees)``: about 64 m^2 per
    tree), each turned about the vertical, scaled by 0.8-1.2 and slightly
    tinted. Every kind is one asset with many instances. Deterministic for a
    given seed and arguments."""
    from aniso3d.build.scene import Scene

    _check_count("forest", n_trees=n_trees)
    whole = isinstance(species, (int, np.integer)) and not isinstance(species, bool)
    if not (whole and 1 <= species <= len(FOREST_SPECIES)):
        raise InputError(f"forest species must be a whole number from 1 to {len(FOREST_SPECIES)}, got {species!r}")
    side = 8.0 * float(np.sqrt(n_trees)) if area is None else area
    _check_positive("forest", area=side)
    rng = np.random.default_rng(seed)
    kind = rng.integers(0, species, n_trees)
    xz = rng.uniform(-0.5 * side, 0.5 * side, (n_trees, 2))
    yaw = rng.uniform(0.0, 2.0 * np.pi, n_trees)
    scale = rng.uniform(0.8, 1.2, n_trees)
    tint = np.round(255 * rng.uniform(0.8, 1.0, (n_trees, 3))).astype(np.uint8)
    c, s = np.cos(yaw) * scale, np.sin(yaw) * scale
    m = np.zeros((n_trees, 4, 4))
    m[:, 0, 0], m[:, 0, 2], m[:, 2, 0], m[:, 2, 2] = c, s, -s, c
    m[:, 1, 1] = scale
    m[:, 0, 3], m[:, 2, 3] = xz[:, 0], xz[:, 1]
    m[:, 3, 3] = 1.0
    scene = Scene(name=f"forest{n_trees}")
    scene.add(quad(side, normal_axis=1, kd=FOREST_GROUND_KD, ks=0.02, shininess=4.0), np.eye(4))
    for k in range(species):
        mine = kind == k
        if mine.any():
            scene.add(tree(**FOREST_SPECIES[k]), m[mine], tint[mine])
    return scene
