"""Edges of surface sheets on voxel faces (render/sheet_edges.py).

Where a surface ends on a voxel face (a wall's top on a grid plane) or meets
another at a crease (a box's edge), the volume renderer counts the share of
the pixel's footprint on the sheet's side of the edge, and a halo in the
voxel past it the share beyond. Held against closed forms (a plane's
segments on the cube's faces, the screen distance to an edge computed by
projection), the classification of simple shapes, the supersampled polygons
(silhouettes of a box and of the corpus room whose faces lie on grid planes,
no background through the room), and the NumPy twin of a GPU pixel.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_render_volume import pixel_angle, pixel_rays, render_float
from test_volume_coverage import corner, erode, truth, voxel_pixels

import aniso3d
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.sheet_edges import (
    CREASE,
    GRID_PAD,
    OPEN,
    edge_factors,
    edge_ramp,
    face_segments,
    inward,
)
from aniso3d.rendering.volume import march_ray_np, pack_volume_grid, sheet_layout

SIZE = (128, 128)


def texture_on_grid(mesh, resolution: int):
    """``mesh`` built over its own bounds: faces on its bounds' planes lie on
    the grid's outer planes."""
    return aniso3d.build_texture(mesh, resolution, 16, bounds=mesh.bounds)


# ------------------------------------------------------- no GPU: geometry


def test_face_segments_closed_forms():
    """The plane z = 0 lies in face 4 and cuts faces 0-3 along unit edges at
    z = 0; the plane 0.6 x + 0.8 y = 0.7 cuts x = 0 at y = 7/8 and x = 1 at y
    = 1/8 (unit segments along z), misses y = 0 and y = 1, and crosses z = 0
    and z = 1 from (0, 7/8) to (1, 1/8): length 5/4, midpoint (1/2, 1/2)."""
    length, mid = face_segments(np.array([[0.0, 0.0, 1.0], [0.6, 0.8, 0.0]]), np.array([0.0, 0.7]))
    np.testing.assert_allclose(length[0], [1, 1, 1, 1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(mid[0, :4], [[0, 0.5, 0], [1, 0.5, 0], [0.5, 0, 0], [0.5, 1, 0]], atol=1e-12)
    np.testing.assert_allclose(length[1], [1, 1, 0, 0, 1.25, 1.25], atol=1e-12)
    np.testing.assert_allclose(mid[1, [0, 1, 4, 5]], [[0, 7 / 8, 0.5], [1, 1 / 8, 0.5], [0.5, 0.5, 0], [0.5, 0.5, 1]],
                               atol=1e-12)  # fmt: skip


def test_edge_ramp_is_the_footprint_share_across_the_projected_edge():
    """Random planes, crossings, faces and views: the ramp is 1/2 plus (a
    sheet's own edge) or minus (a halo) the screen distance from the
    crossing to the edge over the footprint's width, the distance found
    independently by projecting the crossing and the edge's line along the
    ray onto the screen plane."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        face = int(rng.integers(6))
        a, side = face // 2, face % 2
        if abs(n[a]) > 0.9:
            continue
        w = rng.normal(size=3)
        w /= np.linalg.norm(w)
        p = rng.random(3)
        # The edge: the plane through p normal to n, cut by the face's plane.
        t = np.cross(n, np.eye(3)[a])
        t /= np.linalg.norm(t)
        u = np.eye(3)[a] - n[a] * n  # across the edge in the plane, along the axis
        q = p + u * ((side - p[a]) / u[a])  # on the edge: in the plane, on the face
        screen = np.eye(3) - np.outer(w, w)  # projection along the ray
        tp = screen @ t / np.linalg.norm(screen @ t)
        off = screen @ (p - q)
        dist = np.linalg.norm(off - (off @ tp) * tp)
        on_voxel_side = (p[a] < side) if side == 1 else (p[a] > side)
        signed = dist if on_voxel_side else -dist
        foot = rng.uniform(0.2, 3.0)
        for inside, sgn in ((True, 1.0), (False, -1.0)):
            got = edge_ramp(np.array([face]), p[None], n[None], w, np.array([foot]), inside)[0]
            assert got == pytest.approx(np.clip(0.5 + sgn * signed / foot, 0, 1), abs=1e-9)


def test_edge_factors_tell_a_silhouette_crease():
    """A floor (normal +y) whose front edge (face +z) meets a wall going up
    (phi = 90 degrees). Seen from the front and above, the two half-planes lie
    on one side of the edge on screen: a silhouette, the floor (turned away)
    cut by the ramp, its halo nothing, the wall's halo (facing the viewer)
    the ramp. Seen from the back and above (inside the corner, as a room's
    floor meets its wall) it is no silhouette: the floor's coverage whole,
    its colour's weight the ramp."""
    n = np.array([[0.0, 1.0, 0.0]])
    np.testing.assert_allclose(inward(np.array([5]), n), [[0, 0, -1]])
    face, kind, phi, foot = np.array([5]), np.array([CREASE]), np.array([np.pi / 2]), np.array([1.0])
    p = np.array([[0.5, 0.0, 0.9]])  # 0.1 inside the edge
    front = np.array([0.0, -0.5, -1.0]) / np.sqrt(1.25)  # from +z, above
    cov, col = edge_factors(face, kind, phi, p, n, front, foot, halo=False)
    assert 0.5 < cov[0] < 1.0 and col[0] == cov[0]
    halo_p = np.array([[0.5, 0.0, 0.1]])  # in the voxel past the edge (face -z there)
    cov, col = edge_factors(np.array([4]), kind, phi, halo_p, n, front, foot, halo=True)
    assert cov[0] == 0.0 and col[0] == 0.0
    # The wall (normal +z) going up from the edge, the floor going back from
    # it (-z = sin(phi) n: phi = -90 degrees); its halo in the voxel below,
    # 0.1 under the edge (its face +y).
    wall = np.array([[0.0, 0.0, 1.0]])
    cov, _ = edge_factors(np.array([3]), kind, np.array([-np.pi / 2]), np.array([[0.5, 0.9, 0.5]]), wall, front,
                          foot, halo=True)  # fmt: skip
    assert 0.0 < cov[0] < 0.5
    back = np.array([0.0, -0.5, 1.0]) / np.sqrt(1.25)  # from -z, above: inside the corner
    cov, col = edge_factors(face, kind, phi, p, n, back, foot, halo=False)
    assert cov[0] == 1.0 and 0.5 < col[0] < 1.0
    # An open edge: the ramp, whatever the view.
    for w in (front, back):
        cov, col = edge_factors(face, np.array([OPEN]), np.zeros(1), p, n, w, foot, halo=False)
        assert 0.5 < cov[0] < 1.0 and col[0] == cov[0]


# --------------------------------------------- no GPU: edges of simple shapes


def _edge_table(tex):
    """(row, face, kind, angle) of every edge of the texture's sheets."""
    ed = sheet_layout(tex).edges
    rows, slot = np.nonzero(ed.face >= 0)
    return rows, ed.face[rows, slot], ed.kind[rows, slot], ed.angle[rows, slot], ed


def test_a_square_on_grid_planes_has_open_edges_all_round():
    """A square whose sides lie on the grid's outer planes (8 x 8 voxels):
    each border voxel's sheet has an open edge on its outer face (32 in all,
    two in each corner), the others none (the plane goes on in the next
    voxel); each edge has a halo in the voxel past its face, in the grid's
    margin, on the same plane."""
    q = aniso3d.scenes.quad(1.0)
    tex = texture_on_grid(q, 8)
    rows, faces, kinds, _, ed = _edge_table(tex)
    assert len(rows) == 32 and np.all(kinds == OPEN)
    cells = tex.coords[tex.entry_voxel[rows]]
    axis, side = faces // 2, faces % 2
    at = cells[np.arange(len(rows)), axis]
    assert np.all(np.where(side == 1, at == 7, at == 0))
    assert len(ed.halo_row) == 32
    step = np.zeros((32, 3), np.int64)
    step[np.arange(32), ed.halo_face // 2] = np.where(ed.halo_face % 2 == 1, 1, -1)  # back into the sheet's voxel
    np.testing.assert_array_equal(ed.halo_cell + step, tex.coords[tex.entry_voxel[ed.halo_row]])
    outside = np.any((ed.halo_cell < 0) | (ed.halo_cell >= tex.shape), axis=1)
    assert outside.all()
    # The halo's plane, in its voxel, is the sheet's plane moved by the step.
    sheets = sheet_layout(tex).sheets
    d = sheets.offset[ed.halo_row] + np.einsum("ek,ek->e", sheets.normal[ed.halo_row], step)
    np.testing.assert_allclose(ed.halo_offset, d, atol=1e-12)


def test_a_concave_corner_creases_at_right_angles():
    """A floor and a wall meeting along a grid line: their sheets next to
    the line have a crease there whose partner lies at 90 degrees (sin phi =
    +-1), the other borders on the grid's planes are open."""
    mesh = corner()
    tex = texture_on_grid(mesh, 12)
    rows, faces, kinds, angles, _ = _edge_table(tex)
    creased = kinds == CREASE
    assert creased.sum() == 24  # 12 floor voxels and 12 wall voxels along the line
    np.testing.assert_allclose(np.abs(np.sin(angles[creased])), 1.0, atol=0.03)
    assert (kinds == OPEN).sum() == 4 * 12 - 2 + 4 * 12 - 2 - 24 + 4  # the rest of both squares' borders


@pytest.mark.parametrize("resolution", [16, 32])
def test_smooth_closed_surfaces_have_no_edges(resolution):
    """A sphere's sheets all continue into their neighbours, also at its
    extreme points on the grid's outer planes, where the fitted planes lie
    nearly along a face (cut only at under 60 degrees: not an edge)."""
    tex = aniso3d.build_texture(aniso3d.scenes.sphere(1.0, subdivisions=5), resolution, 16)
    rows, *_ = _edge_table(tex)
    assert len(rows) == 0


def test_packed_halos_are_empty_entries_past_their_edges():
    """pack_volume: each halo is an entry of no area (no density, no colour
    of its own) in its own voxel of the GPU grid, listed after that voxel's
    entries, with its edge's face in bits 8-10 of word 11."""
    tex = texture_on_grid(aniso3d.scenes.quad(1.0), 8)
    grid = pack_volume_grid(tex)
    ent, off = grid.arrays["entries"], grid.arrays["offsets"].astype(np.int64)
    halo_face = (ent[:, 11] >> 8) & 7
    halo = halo_face != 7
    assert halo.sum() == 32 and len(ent) == tex.n_entries + 32
    assert np.all(ent[halo, 3].view(np.float32) == 0.0)
    vox = np.repeat(np.arange(len(off) - 1), np.diff(off))
    assert np.all(vox[halo] >= tex.n_voxels)  # the quad's halos lie in the margin: voxels of their own
    np.testing.assert_array_equal(grid.cells[: tex.n_voxels], tex.coords + GRID_PAD)


# ------------------------------------------------------------- GPU


@pytest.mark.gpu
@pytest.mark.parametrize(
    "name, scale, direction",
    [("cube", 2.0, (0.5, 0.27, 0.87)), ("cube", 4.0, (-0.6, 0.5, 0.6)), ("room", 2.0, (0.5, 0.27, 0.87)),
     ("room", 4.0, (-0.6, 0.5, 0.6))],
)  # fmt: skip
def test_edges_on_grid_planes_match_the_supersampled_polygons(r, name, scale, direction, tmp_path):
    """A cube (16^3) and the corpus room (32^3) whose faces lie on grid
    planes, their voxel spanning 0.7 to 2.2 pixels: on the silhouette (pixels
    the 8 x 8 polygons cover in part) the volume's alpha is within 0.05 of
    theirs on average (measured 0.015-0.027), and its covered area within 1%.
    Counting the centre ray alone there (``edges="sampled"``; and the
    footprint's shares of the runs without the edges, whose sheets fill
    their voxels) is all or nothing: measured 0.20-0.28."""
    mesh = aniso3d.scenes.cube(1.0) if name == "cube" else aniso3d.scenes.room(cells=32)
    tex = texture_on_grid(mesh, 16 if name == "cube" else 32)
    cam = Camera.frame(mesh.bounds, direction, fov=30.0, distance_scale=scale)
    assert 0.7 <= voxel_pixels(tex, cam) < 2.2
    ref = truth(r, mesh, cam, ssaa=8)
    edge = (ref[..., 3] > 0.02) & (ref[..., 3] < 0.98)
    assert edge.sum() > 60
    err = {}
    for edges in ("filtered", "sampled"):
        img, _ = render_float(r, tex, cam, edges=edges)
        err[edges] = float(np.abs(img[..., 3] - ref[..., 3])[edge].mean())
        if edges == "filtered":
            from test_render_volume import dump

            where = dump(tmp_path, name, ref, img)
            assert img[..., 3].sum() == pytest.approx(ref[..., 3].sum(), rel=0.01), where
    assert err["filtered"] < 0.05, err
    assert err["sampled"] > 0.15, err


@pytest.mark.gpu
@pytest.mark.parametrize("cells", [32, 64])
def test_the_room_shows_no_background_through_its_walls(r, cells, tmp_path):
    """The corpus room from five sides (in front and above, behind, from
    above, beside, from below) and three distances: alpha >= 0.99 at every
    pixel the 4 x 4 polygons cover whole, eroded by 2 pixels (measured: 1.0
    everywhere). A sheet's coverage cut at a crease that is no silhouette (a
    room's corner, a box's edge seen with both faces) would let light through
    where the ray misses the other face's halo."""
    mesh = aniso3d.scenes.room(cells=cells)
    tex = texture_on_grid(mesh, cells)
    for d in [(0.5, 0.27, 0.87), (-0.6, 0.5, -0.6), (0.2, 0.9, 0.3), (0.9, 0.1, -0.3), (-0.3, -0.4, 0.8)]:
        for scale in (0.8, 1.5, 3.0):
            cam = Camera.frame(mesh.bounds, d, fov=30.0, distance_scale=scale)
            ref = truth(r, mesh, cam)
            core = erode(ref[..., 3] >= 254.5 / 255, 2)
            assert core.sum() > 100
            img, _ = render_float(r, tex, cam)
            a = img[..., 3][core]
            if a.min() < 0.99:
                from test_render_volume import dump

                pytest.fail(f"{d} x{scale}: min alpha {a.min():.3f} " + dump(tmp_path, "room", ref, img))


@pytest.mark.gpu
@pytest.mark.parametrize("scale", [1.0, 3.0])
def test_twin_agrees_on_edges_and_halos(r, scale):
    """The room (32^3), voxels about 3 and 1 pixels: 40 partly covered
    pixels (its silhouette: open edges, creases, halos in the grid's margin)
    and 10 opaque ones against march_ray_np: RGB and alpha within 1/255."""
    mesh = aniso3d.scenes.room(cells=32)
    tex = texture_on_grid(mesh, 32)
    layout = sheet_layout(tex)
    cam = Camera.frame(mesh.bounds, (0.5, 0.27, 0.87), fov=40.0, distance_scale=scale)
    img, _ = render_float(r, tex, cam)
    dirs, t0, t1 = pixel_rays(cam, SIZE, tex.bounds)
    a = img[..., 3]
    rng = np.random.default_rng(5)
    partial, opaque = np.argwhere((a > 0.02) & (a < 0.98)), np.argwhere(a >= 0.98)
    assert len(partial) > 40
    picks = np.concatenate([partial[rng.choice(len(partial), 40, replace=False)], opaque[rng.choice(len(opaque), 10)]])
    for y, x in picks:
        rgb, alpha = march_ray_np(tex, cam.position, dirs[y, x], r.lighting, (t0[y, x], t1[y, x]),
                                  pixel_angle=pixel_angle(cam, SIZE), layout=layout)  # fmt: skip
        got = img[y, x]
        assert np.abs(rgb - got[:3]).max() < 1 / 255 and abs(alpha - got[3]) < 1 / 255, (y, x, rgb, alpha, got)
