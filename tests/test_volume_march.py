"""The volume renderer's marching modes: "skip" (default; arrays as textures,
each ray's next occupied voxel found before it is composited) against
"plain" (the first version: storage buffers, compositing inside the DDA),
and the occupancy index both walk against a NumPy brute force.

Tolerance skip vs plain: 2/255 on RGB and alpha. The two walk the same
voxels with the same arithmetic; they differ only in where they stop: "skip"
at T < T_MIN (0.005), "plain" at T < T_MIN_PLAIN (0.001), and what a ray
leaves behind changes its pixel by at most T (1.3/255).
"""

from __future__ import annotations

import numpy as np
import pytest

import aniso3d
from aniso3d.rendering import volume
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.images import save_png
from aniso3d.rendering.sheet_edges import GRID_PAD
from aniso3d.rendering.volume import BRICK, T_MIN, T_MIN_PLAIN, TEX_WIDTH, pack_volume, pack_volume_grid

SIZE = (96, 96)


@pytest.fixture(scope="module")
def scenes():
    """A dense one (sphere), a sparse one (lattice: thin bars, mostly empty
    bricks), and leaves (a small tree)."""
    return {
        "sphere": aniso3d.build_texture(aniso3d.scenes.sphere(1.0, subdivisions=3), 24, 16),
        "lattice": aniso3d.build_texture(aniso3d.scenes.get_scene("lattice"), 48, 16),
        "tree": aniso3d.build_texture(aniso3d.scenes.tree(levels=4, leaves_per_twig=60), 40, 16),
    }


def test_termination_bound_is_within_the_tolerance():
    assert max(T_MIN, T_MIN_PLAIN) * 255 <= 2.0


def test_occupancy_index_against_brute_force(scenes):
    """top[] marks a brick occupied exactly when one of its voxels is, and
    pool[] gives each occupied voxel's index: against a dense grid (the GPU
    grid: the texture's with a margin, its voxels then those holding only
    halos of edges, which the lattice has)."""
    for tex in scenes.values():
        grid = pack_volume_grid(tex)
        packed = grid.arrays
        shape = grid.shape
        c = grid.cells
        assert len(c) >= tex.n_voxels
        np.testing.assert_array_equal(c[: tex.n_voxels], tex.coords + GRID_PAD)
        assert len(np.unique(c, axis=0)) == len(c)
        dense = np.full(shape[::-1], -1, dtype=np.int64)  # z, y, x
        dense[c[:, 2], c[:, 1], c[:, 0]] = np.arange(len(c))
        bricks = -(-shape // BRICK)
        pad = np.full(bricks[::-1] * BRICK, -1, dtype=np.int64)
        pad[: shape[2], : shape[1], : shape[0]] = dense
        blocks = pad.reshape(bricks[2], BRICK, bricks[1], BRICK, bricks[0], BRICK)
        occupied = (blocks >= 0).any(axis=(1, 3, 5))
        top = packed["top"].reshape(bricks[::-1])
        np.testing.assert_array_equal(top >= 0, occupied)
        # Every voxel of every brick, through the index, equals the dense grid.
        bz, by, bx = np.meshgrid(*[np.arange(n) for n in bricks[::-1]], indexing="ij")
        ids = top[bz, by, bx]
        lz, ly, lx = np.meshgrid(np.arange(BRICK), np.arange(BRICK), np.arange(BRICK), indexing="ij")
        local = (lz * BRICK + ly) * BRICK + lx
        via = np.where(
            ids[..., None, None, None] >= 0,
            packed["pool"][np.maximum(ids, 0)[..., None, None, None] * BRICK**3 + local],
            -1,
        )
        want = blocks.transpose(0, 2, 4, 1, 3, 5)
        np.testing.assert_array_equal(via, want)


@pytest.mark.gpu
def test_uploaded_textures_hold_the_packed_arrays(r, scenes):
    """Each array read back from its texture (TEX_WIDTH texels a row) is the
    packed array, byte for byte."""
    impl = r.method_renderer("volume")
    tex = scenes["tree"]
    handle = impl.upload(tex)
    try:
        packed = pack_volume(tex)
        assert any(h.width == TEX_WIDTH and h.height > 1 for h in handle.textures.values())
        for name, arr in packed.items():
            assert handle.textures[name].read()[: arr.nbytes] == arr.tobytes(), name
    finally:
        impl.release(handle)


@pytest.mark.gpu
@pytest.mark.parametrize("opacity", ["planar", "exponential"])
@pytest.mark.parametrize("name", ["sphere", "lattice", "tree"])
def test_skip_draws_the_plain_image(r, scenes, name, opacity, tmp_path):
    tex = scenes[name]
    cams = [
        Camera.frame(tex.bounds, direction=(0.7, 0.2, 0.6)),
        Camera.frame(tex.bounds, direction=(0.0, 0.0, 1.0), distance_scale=0.6),  # close, along an axis
    ]
    for k, cam in enumerate(cams):
        plain = r.render(tex, cam, "volume", size=SIZE, alpha=True, march="plain", opacity=opacity)
        skip = r.render(tex, cam, "volume", size=SIZE, alpha=True, march="skip", opacity=opacity)
        diff = np.abs(plain.astype(int) - skip.astype(int)).max()
        if diff > 2:
            save_png(tmp_path / f"{name}_{k}.png", np.concatenate([plain, skip], axis=1)[..., :3])
        assert diff <= 2, (name, k, diff, str(tmp_path))
        assert (skip[..., 3] > 0).any()


#: Image size at which the close cameras put START_PIXELS or more in a voxel.
CLOSE_SIZE = (192, 192)


def _close_cameras(tex) -> list[Camera]:
    """Cameras at which a voxel spans START_PIXELS or more at CLOSE_SIZE (the
    start pass is drawn), from an oblique direction and along an axis."""
    return [
        Camera.frame(tex.bounds, direction=(0.7, 0.2, 0.6), distance_scale=0.7),
        Camera.frame(tex.bounds, direction=(0.0, 0.0, 1.0), distance_scale=0.7),
    ]


@pytest.mark.gpu
@pytest.mark.parametrize("name", ["sphere", "lattice", "tree"])
def test_start_pass_draws_the_box_image(r, scenes, name, tmp_path):
    """Rays started at the first occupied brick (start="bricks") draw the
    image of rays started at the grid's box, to 1/255: they walk the same
    voxels from there (the DDA restarted later rounds its crossings a little
    differently); a pixel whose ray enters no brick stays as cleared."""
    tex = scenes[name]
    impl = r.method_renderer("volume")
    for k, cam in enumerate(_close_cameras(tex)):
        box = r.render(tex, cam, "volume", size=CLOSE_SIZE, alpha=True, start="box")
        assert not impl.last_start_pass
        bricks = r.render(tex, cam, "volume", size=CLOSE_SIZE, alpha=True, start="bricks")
        assert impl.last_start_pass, (name, k)
        diff = np.abs(box.astype(int) - bricks.astype(int)).max()
        if diff > 1:
            save_png(tmp_path / f"{name}_{k}.png", np.concatenate([box, bricks], axis=1)[..., :3])
        assert diff <= 1, (name, k, diff, str(tmp_path))
        assert (bricks[..., 3] > 0).any() and (bricks[..., 3] == 0).any()


@pytest.mark.gpu
def test_start_pass_only_where_it_pays(r, scenes):
    """No start pass where a voxel spans under START_PIXELS (a far camera) or
    where the grid reaches the near plane (the eye inside it)."""
    tex = scenes["tree"]
    impl = r.method_renderer("volume")
    far = Camera.frame(tex.bounds, distance_scale=3.0)
    lo, hi = tex.bounds
    inside = Camera(position=tuple(0.5 * (lo + hi)), target=tuple(hi), fov=60.0)
    for cam in (far, inside):
        img = r.render(tex, cam, "volume", size=SIZE, alpha=True)
        assert not impl.last_start_pass
        assert np.isfinite(img).all()


@pytest.mark.gpu
@pytest.mark.parametrize("name", ["lattice", "tree"])
def test_screen_box_draws_the_full_frame_image(r, scenes, name, monkeypatch):
    """The march drawn only in the occupied bricks' screen box (a scissor)
    draws the image of the march over every pixel, bit for bit: far (the box
    a small part of the frame), off the view axis at both sides (the box at
    the frame's edges and past them: its orientation and clamping), near,
    and with the eye inside the grid (no box)."""
    tex = scenes[name]
    lo, hi = tex.bounds
    mid, ext = 0.5 * (lo + hi), float(np.max(hi - lo))
    cams = [
        Camera.frame(tex.bounds, direction=(0.7, 0.2, 0.6), distance_scale=3.0),
        Camera(position=tuple(mid + (0.3 * ext, 0.9 * ext, 2.0 * ext)), target=tuple(mid + (0.4 * ext, 0.5 * ext, 0)),
               fov=40.0),  # fmt: skip
        Camera(position=tuple(mid + (-0.8 * ext, -0.4 * ext, 1.5 * ext)),
               target=tuple(mid - (0.5 * ext, 0.6 * ext, 0)), fov=40.0),  # fmt: skip
        Camera.frame(tex.bounds, direction=(0.1, 0.9, 0.3), distance_scale=0.6),
        Camera(position=tuple(mid), target=tuple(hi), fov=60.0),
    ]
    size = (80, 64)
    boxes = []
    real_box = volume.screen_box

    def recorded(*args):
        boxes.append(real_box(*args))
        return boxes[-1]

    monkeypatch.setattr(volume, "screen_box", recorded)
    for k, cam in enumerate(cams):
        cut = r.render(tex, cam, "volume", size=size, alpha=True)
        full = r.render(tex, cam, "volume", size=size, alpha=True, start="frame")
        np.testing.assert_array_equal(cut, full, err_msg=f"{name} camera {k}")
        assert (full[..., 3] > 0).any(), (name, k)
    assert len(boxes) == len(cams)
    assert boxes[0] is not None and boxes[0][2] * boxes[0][3] < 0.5 * size[0] * size[1], boxes[0]
    assert boxes[-1] is None


@pytest.mark.gpu
@pytest.mark.parametrize(
    "opts",
    [
        {},
        {"opacity": "exponential"},
        {"opacity": "linear", "density": "kernel"},
        {"opacity": "split", "density": "nearest", "normal": "sample"},
        {"edges": "sampled"},
    ],
)
def test_compiled_modes_draw_the_uniform_image(r, scenes, opts):
    """The density, normal and opacity modes compiled into the program draw
    what the same modes read as uniforms do (the same arithmetic)."""
    tex = scenes["tree"]
    impl = r.method_renderer("volume")
    cam = Camera.frame(tex.bounds, direction=(0.7, 0.2, 0.6))
    try:
        impl.compile_modes = False
        uniform = r.render(tex, cam, "volume", size=SIZE, alpha=True, **opts)
    finally:
        impl.compile_modes = True
    compiled = r.render(tex, cam, "volume", size=SIZE, alpha=True, **opts)
    assert np.abs(uniform.astype(int) - compiled.astype(int)).max() <= 1
    assert (compiled[..., 3] > 0).any()
