"""Built-in scenes: a procedural tree (the paper's test object) and the small
analytic shapes the tests use. All are deterministic; the tree is seeded.

The world is y-up, in metres for the tree (about 10 m tall).
"""

from __future__ import annotations

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


SCENES = {"tree": tree, "quad": quad, "cube": cube, "sphere": sphere}


def get_scene(name: str, **kwargs) -> Mesh:
    """A built-in scene by name (``tree``, ``quad``, ``cube``, ``sphere``)."""
    if name not in SCENES:
        raise InputError(f"unknown built-in scene '{name}'; choose one of {', '.join(SCENES)}")
    return SCENES[name](**kwargs)
