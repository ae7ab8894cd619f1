"""aniso3d.build.outside: which side of a patch the outside sees."""

from __future__ import annotations

import numpy as np

from aniso3d.build.mesh import merged_vertices
from aniso3d.build.outside import ENCLOSED, _Caster, outside_sides


def prism(outline: list[tuple[float, float]], height: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A closed prism over a counter-clockwise outline, wound outwards; its
    caps fanned from the outline's first corner (which must see every other
    corner)."""
    n = len(outline)
    xy = np.asarray(outline, dtype=np.float64)
    v = np.vstack([np.c_[xy, np.zeros(n)], np.c_[xy, np.full(n, height)]])
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [[i, j, n + j], [i, n + j, n + i]]
    for i in range(1, n - 1):
        faces += [[n, n + i, n + i + 1], [0, i + 1, i]]
    return v, np.asarray(faces, dtype=np.int64)


def sides_per_face(v: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Every face its own patch."""
    ids = merged_vertices(v)[faces]
    return outside_sides(v, faces, ids, np.arange(len(faces)), np.arange(len(faces)))


def test_every_face_of_a_concave_solid_reads_outward():
    """A U-shaped prism, each face a patch of its own: every face reads
    outward (+1), or inward (-1) with the winding turned, though the faces at
    the bottom of the U's gap face the mean of its corners, which lies in
    the gap: the sign of their cone to it, a patch's own signed volume,
    calls them inward."""
    v, f = prism_u()
    sides = sides_per_face(v, f)
    np.testing.assert_array_equal(sides, 1)
    np.testing.assert_array_equal(sides_per_face(v, f[:, ::-1]), -1)
    t = v[f]
    c = t.mean(axis=1)
    gap = np.flatnonzero(np.isclose(c[:, 1], 1.0) & np.isclose(c[:, 0], 1.5, atol=0.5) & (c[:, 0] > 1) & (c[:, 0] < 2))
    assert len(gap) == 2
    p0, p1, p2 = (t[gap, k] - v.mean(axis=0) for k in range(3))
    assert np.all(np.einsum("ij,ij->i", p0, np.cross(p1, p2)) < 0)


def prism_u() -> tuple[np.ndarray, np.ndarray]:
    """A U-shaped prism wound outwards; its caps triangulated by hand (the
    U is not star-shaped from any corner)."""
    outline = [(0.0, 0.0), (3.0, 0.0), (3.0, 3.0), (2.0, 3.0), (2.0, 1.0), (1.0, 1.0), (1.0, 3.0), (0.0, 3.0)]
    n = len(outline)
    xy = np.asarray(outline)
    v = np.vstack([np.c_[xy, np.zeros(n)], np.c_[xy, np.ones(n)]])
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [[i, j, n + j], [i, n + j, n + i]]
    # The caps' triangles, counter-clockwise from above.
    cap = [[0, 1, 4], [0, 4, 5], [1, 2, 3], [1, 3, 4], [0, 5, 6], [0, 6, 7]]
    for a, b, c in cap:
        faces += [[n + a, n + b, n + c], [a, c, b]]
    return v, np.asarray(faces, dtype=np.int64)


def test_a_free_sheet_is_open_and_a_wall_inside_enclosed():
    # The free sheet is seen from both sides (open); no ray from the wall
    # inside leaves the box (enclosed: no view shows it).
    v, f = prism([(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)])
    # A quad across the box's middle (inside) and one far beside it (free).
    inner = np.array([[0.2, 0.2, 0.5], [0.8, 0.2, 0.5], [0.8, 0.8, 0.5], [0.2, 0.8, 0.5]])
    free = inner + [3.0, 0.0, 0.0]
    vv = np.vstack([v, inner, free])
    quad = np.array([[0, 1, 2], [0, 2, 3]])
    ff = np.vstack([f, quad + len(v), quad + len(v) + 4])
    patch = np.r_[np.zeros(len(f), np.int64), [1, 1, 2, 2]]
    sides = outside_sides(vv, ff, merged_vertices(vv)[ff], patch, np.array([0, 1, 2]))
    np.testing.assert_array_equal(sides, [1, ENCLOSED, 0])


def test_a_ray_through_an_edge_meets_one_of_its_faces():
    # A square of two triangles; rays along x aimed at their shared diagonal
    # (and at the square's inside, corners excepted) meet it exactly once.
    v = np.array([[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 1.0, 1.0], [1.0, 0.0, 1.0]])
    f = np.array([[0, 1, 2], [0, 2, 3]])
    caster = _Caster(v, f, np.array([1.0, 0.0, 0.0]))
    t = np.linspace(0.05, 0.95, 19)
    diagonal = np.c_[np.zeros_like(t), t, t] @ caster.frame.T
    hits = caster.meets(diagonal, np.zeros(len(t), np.int64)).astype(int)
    hits += caster.meets(diagonal, np.ones(len(t), np.int64))
    np.testing.assert_array_equal(hits, 1)
    # Seen along the ray: blocked in front of the square, free behind it.
    front = np.c_[np.zeros_like(t), t, 1.0 - t]
    behind = front + [2.0, 0.0, 0.0]
    assert not caster.escapes(front).any()
    assert caster.escapes(behind).all()


def test_dropping_the_faces_no_test_ray_can_meet_changes_no_answer():
    """A caster told its rays' origins keeps only the faces whose (y, z) box
    holds one of them; every ray's answer is the one the caster over every
    face gives. Small random triangles in a cube, points among them (and on
    some faces' corners), each direction both ways."""
    rng = np.random.default_rng(7)
    n = 3000
    v = rng.random((n, 1, 3)) + 0.03 * rng.standard_normal((n, 3, 3))
    v = v.reshape(-1, 3)
    f = np.arange(3 * n).reshape(n, 3)
    points = np.vstack([rng.random((400, 3)), v[rng.choice(len(v), 50)] + [0.0, 0.0, 1e-9]])
    forward = rng.random(len(points)) < 0.5
    for d in rng.standard_normal((4, 3)):
        d /= np.linalg.norm(d)
        every = _Caster(v, f, d)
        culled = _Caster(v, f, d, near=points)
        assert len(culled.ids) < 0.8 * len(every.ids)  # the cull drops faces here...
        free = every.escapes(points, forward=forward)
        assert 0.1 < free.mean() < 0.9  # ... and the rays meet some
        np.testing.assert_array_equal(culled.escapes(points, forward=forward), free)
