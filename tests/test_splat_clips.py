"""Splats cut where their surface ends (aniso3d.rendering.splat.clips,
docs/splat_aa.md "Where a surface ends"): each point of a texture carries the
faces of its voxel where its surface sheet's edge is open or creased, and
quality "high" cuts its splat there and drops it where the surface meeting it
hides it. Checked without a GPU against closed forms (the kept area of a
rectangle, which faces a wall's points get, which splat a crease hides) and
with the GPU: nothing past a wall's end, a square sheet's alpha, the twin
(reference.py) pixel by pixel.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import module_renderer

from aniso3d import PointCloud
from aniso3d.build.mesh import Mesh
from aniso3d.build.pyramid import LodPoints, pyramid
from aniso3d.build.texture import build_texture
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.frame import FrameView
from aniso3d.rendering.lighting import Lighting
from aniso3d.rendering.splat import SplatOptions
from aniso3d.rendering.splat.clips import entry_clips, texture_points
from aniso3d.rendering.splat.reference import clip_geometry_np, composite_np, rect_kept_np, subpixel_fragments_np

SIZE = (96, 96)
RES = 32
H = 1.0 / RES
#: The grid: the unit cube (bounds given), voxels of H.
BOUNDS = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
GREY = (0.5, 0.5, 0.5)


r = module_renderer(SIZE)


def quad(x0, x1, y0, y1, z) -> Mesh:
    """A rectangle facing +z at depth z, its corners as given."""
    v = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], float)
    return Mesh.from_arrays(v, np.array([[0, 1, 2], [0, 2, 3]]), GREY, 0.0, 8.0, name="quad")


def step(x_wall: float, z_plate: float) -> Mesh:
    """A closed L-shaped prism along y (0.25 to 0.75): a plate from x = 0.25
    to 0.75 with its top at ``z_plate``, and on its left a block up to z =
    0.75 whose right wall stands at ``x_wall`` (a concave corner where the
    wall meets the plate's top)."""
    x0, x1, z0, zt = 0.25, 0.75, 0.25, 0.75
    ring = [(x0, z0), (x1, z0), (x1, z_plate), (x_wall, z_plate), (x_wall, zt), (x0, zt)]
    v = np.array([(x, y, z) for y in (0.25, 0.75) for x, z in ring], float)
    n = len(ring)
    fan = [(0, i, i + 1) for i in range(1, n - 1)]  # the cap at y = 0.25, facing -y
    faces = fan + [(n + a, n + c, n + b) for a, b, c in fan]
    for i in range(n):
        j = (i + 1) % n
        faces += [(i, n + j, j), (i, n + i, n + j)]
    return Mesh.from_arrays(v, np.array(faces), GREY, 0.0, 8.0, name="step")


def points_of(mesh: Mesh) -> tuple:
    tex = build_texture(mesh, RES, 16, bounds=BOUNDS)
    return tex, texture_points(tex)


def draw_rgba(r, cloud: PointCloud | LodPoints, cam: Camera, **options) -> tuple[np.ndarray, FrameView]:
    """(H, W, 4) float32 RGBA of ``cloud`` drawn with ``options`` (quality
    "high" unless given) at ``r``'s size, row 0 at the top."""
    impl = r.method_renderer("splat")
    handle = impl.upload(cloud)
    near, far = cam.clip_range(handle.bounds)
    size = tuple(r.size)
    view = FrameView(cam, r.lighting, size, near, far)
    ctx = r.gl.ctx
    col, dep = ctx.texture(size, 4, dtype="f4"), ctx.depth_texture(size)
    fbo = ctx.framebuffer([col], dep)
    try:
        fbo.use()
        ctx.viewport = (0, 0, *size)
        fbo.clear(*r.lighting.background, 0.0, depth=1.0)
        impl.draw(handle, view, fbo=fbo, **{"quality": "high", **options})
        img = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(size[1], size[0], 4)
    finally:
        for obj in (fbo, col, dep):
            obj.release()
        impl.release(handle)
    return img[::-1].copy(), view


def draw_alpha(r, cloud: PointCloud | LodPoints, cam: Camera, **options) -> tuple[np.ndarray, FrameView]:
    """(H, W) float32 alpha of ``cloud`` drawn with quality "high" (and
    ``options``), row 0 at the top."""
    img, view = draw_rgba(r, cloud, cam, **options)
    return img[..., 3].copy(), view


def flat_grid(g: np.ndarray) -> np.ndarray:
    """(N, 3) the points of the square grid with coordinates ``g`` along x and
    y in the plane z = 0, row by row."""
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    return np.c_[x, y, np.zeros(x.size)]


def facing_cloud(pos: np.ndarray, side: float, rng, **fields) -> PointCloud:
    """Points at ``pos`` facing +z, each of area ``side``^2, their colours drawn
    from ``rng``; ``fields``: the cloud's other fields (clips, one_sided)."""
    n = len(pos)
    return PointCloud(pos, np.tile([0.0, 0.0, 1.0], (n, 1)), np.full(n, side**2), rng.uniform(0.1, 0.9, (n, 3)),
                      np.zeros(n), np.full(n, 8.0), **fields)  # fmt: skip


def assert_alpha_matches_twin(r, cloud: PointCloud, cam: Camera) -> tuple[np.ndarray, FrameView]:
    """The GPU's alpha of ``cloud`` (quality "high", every splat sub-pixel),
    pixel by pixel, within 2e-4 of the twin's; returns it and its view."""
    img_alpha, view = draw_alpha(r, cloud, cam)
    _, alpha = composite_np(subpixel_fragments_np(cloud, view, SplatOptions(quality="high")), view.lighting.background)
    assert np.abs(img_alpha - alpha).max() < 2e-4, np.abs(img_alpha - alpha).max()
    return img_alpha, view


def hit_points(view: FrameView, z: float) -> np.ndarray:
    """(H, W, 3) where each pixel centre's ray meets the plane at depth z
    (row 0 at the top)."""
    cam = view.camera
    r_, u, f = cam.basis()
    tan = math.tan(math.radians(cam.fov) / 2)
    w, h = view.size
    x = ((np.arange(w) + 0.5) / w * 2 - 1) * tan * view.aspect
    y = ((np.arange(h) + 0.5) / h * 2 - 1)[::-1] * tan
    d = f + x[None, :, None] * r_ + y[:, None, None] * u
    eye = np.asarray(cam.position, float)
    t = (z - eye[2]) / d[..., 2]
    return eye + t[..., None] * d


def px_size(view: FrameView, z: float) -> float:
    """World units a pixel spans at the plane z, along the view axis's depth."""
    depth = abs(float(np.asarray(view.camera.position)[2]) - z)
    return depth * 2 * math.tan(math.radians(view.camera.fov) / 2) / view.size[1]


# ---------------------------------------------------------------- no GPU


def test_rect_kept_is_the_area_on_the_kept_side():
    rng = np.random.default_rng(3)
    n = 200
    lo = rng.uniform(-1, 0, (n, 2))
    hi = lo + rng.uniform(0.05, 1.5, (n, 2))
    line = rng.normal(size=(n, 3))
    line[:20, 1] = 0.0  # lines along an axis
    line[20:30, 1:] = 0.0  # no line: all or nothing
    kept = rect_kept_np(lo, hi, line)
    s = (np.arange(400) + 0.5) / 400
    gx, gy = np.meshgrid(s, s)
    for i in range(n):
        x = lo[i, 0] + gx * (hi[i, 0] - lo[i, 0])
        y = lo[i, 1] + gy * (hi[i, 1] - lo[i, 1])
        inside = (line[i, 0] + line[i, 1] * x + line[i, 2] * y >= 0).mean() * np.prod(hi[i] - lo[i])
        assert abs(kept[i] - inside) < 5e-3 * np.prod(hi[i] - lo[i]), (i, kept[i], inside)


def test_a_walls_points_are_cut_where_it_ends_on_a_grid_plane():
    # A wall from y = 0 to 0.5 (a grid plane) inside the voxels at z = 0.5 + H / 2.
    tex, pts = points_of(quad(0.25, 0.75, 0.0, 0.5, 0.5 + H / 2))
    clips = entry_clips(tex)
    cell = np.asarray(tex.coords)[tex.entry_voxel]
    faces = {tuple(cell[i]): {(int(np.flatnonzero(c[:3])[0]), float(c[np.flatnonzero(c[:3])[0]]), round(c[3] / H))
                              for c in clips[i] if np.any(c[:3])} for i in range(tex.n_entries)}  # fmt: skip
    top, right, left = 0.5 / H - 1, 0.75 / H - 1, 0.25 / H
    for (x, y, z), f in faces.items():
        want = set()
        if y == top:
            want.add((1, 1.0, 16))  # y <= 0.5
        if x == right:
            want.add((0, 1.0, 24))  # x <= 0.75
        if x == left:
            want.add((0, -1.0, -8))  # x >= 0.25
        if y == 0:
            want.add((1, -1.0, 0))  # y >= 0 (the grid's outer plane)
        assert f == want or (len(want) > 2 and f < want and len(f) == 2), ((x, y, z), f, want)
    assert pts.clips is not None and len(pts.clips) == tex.n_entries


def test_the_surface_meeting_a_splat_hides_it_only_from_where_it_is_in_front():
    # A floor's point by its front edge z = 0, where a wall goes up (phi = 90 degrees).
    pos = np.array([[0.0, 0.0, -0.5 * H]])
    nrm = np.array([[0.0, 1.0, 0.0]])
    clips = np.zeros((1, 2, 5))
    clips[0, 0] = (0.0, 0.0, 1.0, 0.0, math.pi / 2)
    hidden = lambda eye: bool(clip_geometry_np(pos, nrm, clips, np.asarray(eye, float))[3][0])  # noqa: E731
    assert hidden((0.0, 1.0, 5.0))  # outside the room, above: behind the wall
    assert not hidden((0.0, 1.0, -5.0))  # inside the room: in front of the wall
    assert not hidden((0.0, -1.0, 5.0))  # below the floor: the wall is above it
    # One-sided (a closed surface's point): never. The wall, wound as the
    # floor, faces the room (its normal sin(phi) u - cos(phi) n = u = -z);
    # from outside it is seen from behind, culled, and hides nothing.
    sided = lambda eye: bool(clip_geometry_np(pos, nrm, clips, np.asarray(eye, float), np.array([True]))[3][0])  # noqa: E731
    assert not sided((0.0, 1.0, 5.0))
    assert not sided((0.0, 1.0, -5.0)) and not sided((0.0, -1.0, 5.0))
    # A crease turning down (phi = -90 degrees: a box's edge, the floor its
    # top): from outside below, the side hides the top, which faces away.
    clips[0, 0, 4] = -math.pi / 2
    assert hidden((0.0, -1.0, 5.0)) and not sided((0.0, -1.0, 5.0))
    clips[0, 0, 4] = 0.0  # an open edge hides nothing
    assert not hidden((0.0, 1.0, 5.0))


def test_a_crease_partners_angle_is_its_planes_not_its_centroids():
    """A wall standing 0.2 voxel inside the voxel face where the plate's
    sheet ends, the plate's top 0.2 voxel above the voxel's floor (as in
    a CAD part that showed the crack): the plate's crease partner (the
    wall, in the same voxel) rises at 90 degrees from it, though the
    wall's centroid, 0.4 voxel up and 0.2 across, lies at 63 degrees from
    the edge (the angle taken before hid the plate's splats from eyes
    between the two)."""
    tex, pts = points_of(step(0.5 + 0.2 * H, 0.5 + 0.2 * H))
    clips = entry_clips(tex)
    normal = np.asarray(tex.entry_normal, float)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    cell = np.asarray(tex.coords)[tex.entry_voxel]
    plate = (normal[:, 2] > 0.99) & (cell[:, 0] == 16)  # the plate's voxels holding the wall's foot
    at_wall = plate[:, None] & (clips[:, :, 0] == -1.0)  # cut at x >= 0.5, the face left of the foot
    assert at_wall.sum() >= 10, at_wall.sum()
    phi = clips[..., 4][at_wall]
    assert np.all(np.abs(phi - math.pi / 2) < 0.03), np.degrees(phi)


def test_a_cut_subpixel_splat_keeps_its_area_inside_a_surface():
    """Sub-pixel splats facing the camera, each cut by a plane through, near
    or far from its centre: the twin's coverages still sum to each one's
    true projected area (the box is cut and scaled back up: all of the
    facets' area lies on the kept side), and none lies past its plane."""
    cam = Camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov=40.0)
    view = FrameView(cam, Lighting(), SIZE, 1.0, 5.0)
    px = 3.0 * 2 * math.tan(math.radians(20.0)) / SIZE[1]
    rng = np.random.default_rng(1)
    n = 40
    pos = np.c_[rng.uniform(-30, 30, (n, 2)) * px, np.zeros(n)]
    offset = np.r_[np.full(10, 0.05), rng.uniform(0.05, 2.0, n - 10)] * px  # the plane x <= centre + offset
    clips = np.zeros((n, 2, 5))
    clips[:, 0, 0] = 1.0
    clips[:, 0, 3] = pos[:, 0] + offset
    for i in range(n):
        one = PointCloud(pos[i : i + 1], [[0.0, 0.0, 1.0]], [(0.8 * px) ** 2], [GREY], [0.0], [8.0],
                         clips=clips[i : i + 1])  # fmt: skip
        cut = subpixel_fragments_np(one, view, SplatOptions(quality="high"))
        # 0.64 px^2, less fragments below MIN_COVERAGE (1e-4), dropped.
        assert abs(cut.coverage.sum() - 0.64) < 4e-4, (i, cut.coverage.sum())
        # Pixels whose left edge lies past the plane get nothing.
        col = cut.pixel % SIZE[0]
        left = (col - SIZE[0] / 2) * px
        assert not np.any(left > clips[i, 0, 3] + 1e-9), i


# ---------------------------------------------------------------- GPU


@pytest.mark.parametrize("distance, side", [(0.6, 0.12), (4.5, 0.6)])
def test_no_coverage_past_a_walls_end(r, distance, side):
    """A wall ending on grid planes (its top y = 0.5, its sides) seen from
    above at a slant: resolved (voxels of about 8 px) and sub-pixel splats
    (about 1 px). Without the cut, discs and boxes reach past its ends (the
    room's outlines)."""
    z = 0.5 + H / 2
    tex, pts = points_of(quad(0.25, 0.75, 0.125, 0.5, z))
    cam = Camera((0.5 + side * distance, 0.3 + 0.45 * distance, z + distance), (0.5, 0.3, z), fov=40.0)
    alpha, view = draw_alpha(r, pts, cam)
    hit = hit_points(view, z)
    # A pixel centre this far past an end (half a pixel's diagonal,
    # stretched by the slant) has none of the wall in its box.
    px = 0.75 * px_size(view, z) / abs(float(np.asarray(view.camera.forward)[2]))
    past = (hit[..., 1] > 0.5 + px) | (hit[..., 0] > 0.75 + px) | (hit[..., 0] < 0.25 - px) | (hit[..., 1] < 0.125 - px)
    inside = (hit[..., 1] < 0.5 - 2 * px) & (hit[..., 1] > 0.125 + 2 * px) & (np.abs(hit[..., 0] - 0.5) < 0.25 - 2 * px)
    assert past.sum() > 100 and inside.sum() > 20
    assert alpha[past].max() < 1e-3, alpha[past].max()
    assert alpha[inside].min() > 0.9, alpha[inside].min()
    # The same points uncut reach past the end.
    plain = PointCloud(pts.positions, pts.normals, pts.areas, pts.kd, pts.ks, pts.shininess)
    before, _ = draw_alpha(r, plain, cam)
    if distance < 1:  # resolved: discs reach a pixel and more past the ends
        assert before[past].max() > 0.1, before[past].max()


def test_no_crack_where_a_wall_meets_a_plate_inside_a_voxel(r):
    """The step above, its points drawn two-sided, seen from the plate's
    side, 75 degrees up from it: between the wall's centroid's angle (63
    degrees) and its plane's (90),
    where the plate's splats by the wall were dropped as hidden behind it
    (a line of background along a CAD part's inner corner). Every pixel
    whose centre sees the plate or the wall near the corner is covered."""
    x_wall, z_plate = 0.5 + 0.2 * H, 0.5 + 0.2 * H
    tex, pts = points_of(step(x_wall, z_plate))
    # Two-sided, as an open sheet's (a closed surface's one-sided points are
    # never hidden by their partner: AA_PARTNER_HIDES_SIDED).
    pts = PointCloud(pts.positions, pts.normals, pts.areas, pts.kd, pts.ks, pts.shininess, clips=pts.clips)
    target = np.array([x_wall + 2 * H, 0.5, z_plate])
    up = math.radians(75.0)
    cam = Camera(target + 0.9 * np.array([math.cos(up), 0.25, math.sin(up)]), target, fov=40.0)
    alpha, view = draw_alpha(r, pts, cam)
    hit = hit_points(view, z_plate)
    px = px_size(view, z_plate)
    plate = (hit[..., 0] > x_wall + 2 * px) & (hit[..., 0] < x_wall + 6 * H) & (np.abs(hit[..., 1] - 0.5) < 0.15)
    assert plate.sum() > 100, plate.sum()
    assert alpha[plate].min() > 0.99, alpha[plate].min()


@pytest.mark.parametrize("one_sided", [True, False])
def test_a_wall_seen_from_behind_hides_a_one_sided_floor_nowhere(r, one_sided):
    """Floor points (normal +z, a grid of voxels of H) cut at x <= 0.5 where
    a wall rises (phi = 90 degrees) that faces the floor, seen from beyond
    the wall and above, with no wall points drawn (a lip whose face towards
    the floor a mesh winds as seen from there). Two-sided, the wall would
    hide the floor's last column, which is dropped; one-sided, the wall is
    culled from there and the floor stays whole (a CAD part's and a
    truck's floors showed a line of background along such a lip)."""
    g = (np.arange(8) + 0.5) * H
    x, y = (a.ravel() for a in np.meshgrid(0.5 - g[::-1], 0.5 + g - 4 * H))
    n = x.size
    clips = np.zeros((n, 2, 5))
    last = x > 0.5 - H
    clips[last, 0] = (1.0, 0.0, 0.0, 0.5, math.pi / 2)
    cloud = PointCloud(np.c_[x, y, np.full(n, 0.5)], np.tile([0.0, 0.0, 1.0], (n, 1)), np.full(n, H * H),
                       GREY, 0.0, 8.0, one_sided=np.full(n, one_sided), clips=clips)  # fmt: skip
    cam = Camera((0.5 + 0.12, 0.5, 0.5 + 0.2), (0.5 - 3 * H, 0.5, 0.5), fov=40.0)
    alpha, view = draw_alpha(r, cloud, cam)
    hit = hit_points(view, 0.5)
    px = px_size(view, 0.5) * 2.0
    # The column's half by the edge: the next column's discs (radius 0.7 H) reach the rest.
    column = (hit[..., 0] > 0.5 - 0.5 * H + px) & (hit[..., 0] < 0.5 - px) & (np.abs(hit[..., 1] - 0.5) < 3 * H)
    assert column.sum() > 20, column.sum()
    hidden = clip_geometry_np(cloud.positions, cloud.normals, clips, np.asarray(cam.position, float),
                              cloud.one_sided)[3]  # fmt: skip
    if one_sided:
        assert not hidden.any()
        assert alpha[column].min() > 0.99, alpha[column].min()
    else:
        assert hidden[last].all() and not hidden[~last].any()
        assert alpha[column].max() < 0.5, alpha[column].max()


@pytest.mark.parametrize("pixel_error", [8.0, 16.0, 32.0])
def test_no_coverage_past_a_walls_end_at_every_level(r, pixel_error):
    """The same wall drawn close up through its pyramid (level of detail),
    with screen-space errors that draw levels 0 and 1, 1, and 2 (voxels up
    to 4 times as wide: the wall's ends still on their grid planes): each
    level's points are cut at their own voxels' faces; uncut
    (``clips=False``) their discs reach past the ends."""
    z = 0.5 + H / 2
    tex, _ = points_of(quad(0.25, 0.75, 0.125, 0.5, z))
    pyr = pyramid(tex)
    cam = Camera((0.62, 0.75, z + 1.0), (0.5, 0.3, z), fov=40.0)
    impl = r.method_renderer("splat")
    handle = impl.upload(LodPoints(pyr))
    try:
        near, far = cam.clip_range(handle.bounds)
        levels = impl.select(handle, FrameView(cam, r.lighting, SIZE, near, far), pixel_error)["points_per_level"]
        assert handle.n_clipped > 0 and sum(levels[1:]) > 0, levels  # coarser levels drawn, with clip planes
    finally:
        impl.release(handle)
    alpha, view = draw_alpha(r, LodPoints(pyr), cam, pixel_error=pixel_error)
    hit = hit_points(view, z)
    px = 0.75 * px_size(view, z) / abs(float(np.asarray(view.camera.forward)[2]))
    past = (hit[..., 1] > 0.5 + px) | (hit[..., 0] > 0.75 + px) | (hit[..., 0] < 0.25 - px) | (hit[..., 1] < 0.125 - px)
    inside = (hit[..., 1] < 0.5 - 2 * px) & (hit[..., 1] > 0.125 + 2 * px) & (np.abs(hit[..., 0] - 0.5) < 0.25 - 2 * px)
    assert past.sum() > 100 and inside.sum() > 20
    assert alpha[past].max() < 1e-3, alpha[past].max()
    assert alpha[inside].min() > 0.9, alpha[inside].min()
    before, _ = draw_alpha(r, LodPoints(pyr, clips=False), cam, pixel_error=pixel_error)
    assert before[past].max() > 0.1, before[past].max()


def test_a_square_sheets_alpha_is_its_projected_area(r):
    """A square on grid planes seen minified at a slant (voxels of about 0.7
    px, every splat a sub-pixel box): alpha sums to its projected area (within
    2 %), none more than a pixel outside it."""
    z = 0.5 + H / 2
    tex, pts = points_of(quad(0.25, 0.75, 0.25, 0.75, z))
    cam = Camera((0.8, 0.9, z + 3.2), (0.5, 0.5, z), fov=40.0)
    alpha, view = draw_alpha(r, pts, cam)
    # The projected area: the square's corners projected (a planar quad, exact).
    r_, u, f = cam.basis()
    tan = math.tan(math.radians(cam.fov) / 2)
    corners = np.array([[0.25, 0.25, z], [0.75, 0.25, z], [0.75, 0.75, z], [0.25, 0.75, z]]) - cam.position
    depth = corners @ f
    sx = (corners @ r_) / depth / (tan * view.aspect) * SIZE[0] / 2
    sy = (corners @ u) / depth / tan * SIZE[1] / 2
    area = 0.5 * abs(np.dot(sx, np.roll(sy, -1)) - np.dot(sy, np.roll(sx, -1)))
    assert abs(alpha.sum() / area - 1.0) < 0.02, (alpha.sum(), area)
    hit = hit_points(view, z)
    px = px_size(view, z) * 2.0
    past = (np.abs(hit[..., 0] - 0.5) > 0.25 + px) | (np.abs(hit[..., 1] - 0.5) > 0.25 + px)
    assert alpha[past].max() < 1e-3, alpha[past].max()


def test_gpu_matches_the_twin_with_cut_splats(r):
    """Sub-pixel splats with clip planes through and near them, random: the
    GPU's alpha and colour, pixel by pixel, against the twin."""
    cam = Camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov=40.0)
    px = 3.0 * 2 * math.tan(math.radians(20.0)) / SIZE[1]
    rng = np.random.default_rng(7)
    pos = flat_grid((np.arange(-20, 20, 0.7) + 0.35) * px)
    n = len(pos)
    clips = np.zeros((n, 2, 5))
    for k, axis in enumerate((0, 1)):
        on = rng.random(n) < 0.5
        sign = np.where(rng.random(n) < 0.5, 1.0, -1.0)
        clips[on, k, axis] = sign[on]
        clips[on, k, 3] = sign[on] * pos[on, axis] + rng.uniform(0.05, 0.6, on.sum()) * px
    cloud = facing_cloud(pos, 0.7 * px, rng, clips=clips)
    assert_alpha_matches_twin(r, cloud, cam)


def test_gpu_matches_the_twin_on_which_splats_their_partners_hide(r):
    """Sub-pixel splats, each with a clip plane whose partner meets it at a
    random angle, half of them one-sided, seen from a slant: the GPU drops
    the splats the twin drops (two-sided ones whose partner lies in front of
    them; one-sided ones never, their partners there facing away), pixel by
    pixel."""
    cam = Camera((1.2, 0.4, 2.6), (0.0, 0.0, 0.0), fov=40.0)
    px = 2.9 * 2 * math.tan(math.radians(20.0)) / SIZE[1]
    rng = np.random.default_rng(11)
    pos = flat_grid((np.arange(-16, 16, 0.8) + 0.4) * px)
    n = len(pos)
    axis = rng.integers(0, 2, n)
    sign = np.where(rng.random(n) < 0.5, 1.0, -1.0)
    clips = np.zeros((n, 2, 5))
    clips[np.arange(n), 0, axis] = sign
    clips[:, 0, 3] = sign * pos[np.arange(n), axis] + 0.3 * px
    clips[:, 0, 4] = rng.uniform(-2.8, 2.8, n)
    sided = rng.random(n) < 0.5
    cloud = facing_cloud(pos, 0.7 * px, rng, one_sided=sided, clips=clips)
    eye = np.asarray(cam.position, float)
    hidden = clip_geometry_np(pos, cloud.normals, clips, eye, sided)[3]
    as_two_sided = clip_geometry_np(pos, cloud.normals, clips, eye)[3]
    # Two-sided points hidden; one-sided ones the same partners would hide, kept.
    assert (hidden & ~sided).sum() > 20 and (as_two_sided & sided).sum() > 20
    assert not (hidden & sided).any() and np.array_equal(hidden, as_two_sided & ~sided)
    # ... as their partners, wound alike, face away from the eye (outward normal sin(phi) u - cos(phi) n).
    q, _, _, _ = clip_geometry_np(pos, cloud.normals, clips, eye)
    m = clips[:, 0, :3]
    u = -(m - m[:, 2:3] * np.array([0.0, 0.0, 1.0]))
    n2 = np.sin(clips[:, 0, 4])[:, None] * u - np.cos(clips[:, 0, 4])[:, None] * np.array([0.0, 0.0, 1.0])
    assert np.all(np.einsum("nc,nc->n", n2, eye - q[:, 0])[as_two_sided] < 0.0)
    assert_alpha_matches_twin(r, cloud, cam)


def test_each_point_reads_its_own_clip_planes(r):
    """Few points with clip planes, scattered through the cloud and uploaded
    in Morton order (not the cloud's): each plane passes near its own
    splat, at its own offset, so a point reading another point's table row
    (the next, the previous) is cut elsewhere or not at all, and the GPU's
    image leaves the twin's."""
    cam = Camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov=40.0)
    px = 3.0 * 2 * math.tan(math.radians(20.0)) / SIZE[1]
    rng = np.random.default_rng(11)
    grid = flat_grid((np.arange(-18, 18) * 2.5 + 0.3) * px)  # apart: each splat's alpha is its own
    n = len(grid)  # 1296 points
    pos = grid[rng.permutation(n)]
    cut = rng.random(n) < 0.15
    clips = np.zeros((n, 2, 5))
    axis = rng.integers(0, 2, n)
    sign = np.where(rng.random(n) < 0.5, 1.0, -1.0)
    clips[cut, 0, axis[cut]] = sign[cut]
    clips[cut, 0, 3] = sign[cut] * pos[cut, axis[cut]] + rng.uniform(0.05, 0.5, cut.sum()) * px
    cloud = facing_cloud(pos, 1.0 * px, rng, clips=clips)
    img_alpha, view = assert_alpha_matches_twin(r, cloud, cam)
    # Each point's planes moved to the next point with planes: the twin differs.
    shifted = clips.copy()
    idx = np.flatnonzero(cut)
    shifted[idx] = clips[np.roll(idx, 1)]
    wrong = PointCloud(pos, cloud.normals, cloud.areas, cloud.kd, cloud.ks, cloud.shininess, clips=shifted)
    _, alpha_wrong = composite_np(subpixel_fragments_np(wrong, view, SplatOptions(quality="high")),
                                  view.lighting.background)  # fmt: skip
    assert np.abs(img_alpha - alpha_wrong).max() > 0.05


@pytest.mark.parametrize("quality", ["blend", "fast"])
def test_points_with_clip_planes_draw_as_before_below_high(r, quality):
    """Qualities "blend" and "fast" do not cut: a cloud whose points (a
    third of them, at random) have clip planes draws exactly as without
    them, though those points' shininess is negated in the upload to mark
    them for quality "high", which draws them apart (its images are held to
    the twin above)."""
    cam = Camera((0.3, 0.2, 3.0), (0.0, 0.0, 0.0), fov=40.0)
    rng = np.random.default_rng(4)
    n = 3000
    pos = rng.uniform(-0.6, 0.6, (n, 3))
    nrm = rng.normal(size=(n, 3))
    clips = np.zeros((n, 2, 5))
    cut = rng.random(n) < 0.33
    clips[cut, 0, 0] = 1.0
    clips[cut, 0, 3] = 0.0  # x <= 0: through the cloud
    args = (pos, nrm, np.full(n, 0.03**2), rng.uniform(0.1, 0.9, (n, 3)), np.full(n, 0.5),
            rng.choice([0.0, 8.0, 40.0], n))  # fmt: skip
    plain, with_planes = PointCloud(*args), PointCloud(*args, clips=clips)
    a, _ = draw_rgba(r, plain, cam, quality=quality)
    b, _ = draw_rgba(r, with_planes, cam, quality=quality)
    assert a[..., 3].sum() > 100
    assert np.array_equal(a, b)
