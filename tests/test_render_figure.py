"""``aniso3d render``'s resolution "auto" and the figure of ``--method all``:
a close-up row and a minified row, each panel with its frame time and its
error (PSNR in the object's screen box against the supersampled polygons)."""

from __future__ import annotations

import argparse
import math

import numpy as np
import pytest

from aniso3d import ResourceError, scenes
from aniso3d.app.cli import build_parser, main
from aniso3d.app.render_cmd import (
    MINIFIED_RESOLUTION,
    camera_from_args,
    enlarge,
    figure,
    minified_camera,
    resolution_arg,
)
from aniso3d.build.bounds import bounds_of, surface_sample
from aniso3d.build.texture import build_texture
from aniso3d.rendering.camera import Camera, turntable
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.select import nearest_depth, needed_resolution

SIZE = 96


def test_resolution_argument():
    assert resolution_arg("auto") == resolution_arg(" AUTO ") == "auto"
    assert resolution_arg("24") == 24
    for bad, words in (("0", "at least 1"), ("fine", "whole number")):
        with pytest.raises(argparse.ArgumentTypeError, match=words) as exc:
            resolution_arg(bad)
        assert "'auto'" in str(exc.value)
    for command in ("render", "frames", "view"):
        assert build_parser().parse_args([command]).resolution == "auto"


@pytest.mark.parametrize("resolution", [16, 128])
def test_minified_camera_puts_one_voxel_on_one_pixel_at_the_nearest_point(resolution):
    box = np.array([[0.0, 0.0, 0.0], [4.0, 2.0, 1.0]])
    cam = Camera((9.0, 5.0, 12.0), (2.0, 1.0, 0.5), fov=35.0)
    size = (300, 200)
    far = minified_camera(cam, box, size, resolution)
    assert far.target == cam.target and far.fov == cam.fov
    assert np.allclose(far.forward, cam.forward)
    pixel = nearest_depth(far, box) * 2 * math.tan(math.radians(35.0) / 2) / size[1]
    assert 4.0 / resolution == pytest.approx(pixel)  # a voxel (longest extent / resolution) is a pixel
    assert needed_resolution(far, size, box, maximum=4096) == resolution


def test_enlarge_cuts_around_the_box_and_repeats_pixels():
    img = np.arange(60 * 80 * 3, dtype=np.int64).reshape(60, 80, 3).astype(np.uint8)
    out, k = enlarge([img, img], (30, 20, 50, 40))  # a 20 x 20 box: 3x fits 60 rows
    assert k == 3 and out[0].shape == img.shape and np.array_equal(out[0], out[1])
    # The window (27 x 20 pixels) is centred on the box; each pixel a 3 x 3 square.
    assert np.array_equal(out[0][::3, ::3], img[20:40, 27:54])
    assert np.array_equal(out[0][1::3, 2::3], img[20:40, 27:53])  # the last column is cut at 80
    same, k = enlarge([img], (0, 0, 80, 60))
    assert k == 1 and same[0] is img


@pytest.fixture(scope="module")
def r():
    try:
        renderer = Renderer((SIZE, SIZE))
    except ResourceError as exc:
        pytest.skip(str(exc))
    yield renderer
    renderer.release()


def _args(*extra):
    return build_parser().parse_args(["render", "--method", "all", "--size", str(SIZE), *extra])


@pytest.mark.gpu
def test_captions_wrap_to_their_panel_and_keep_every_word():
    """Small panels: a caption broken between words, no line wider than its
    panel (a single word wider than the panel stays whole), nothing lost."""
    from PIL import Image, ImageDraw, ImageFont

    from aniso3d.rendering.images import wrap_text

    font = ImageFont.load_default(size=12)
    draw = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    text = "ground truth: polygons 8x8\n26 ms, PSNR 28.4 dB inside the object's screen box"
    for width in (40, 80, 120, 400):
        wrapped = wrap_text(draw, text, font, width)
        assert wrapped.split() == text.split()
        for line in wrapped.split("\n"):
            assert draw.textlength(line, font=font) <= width or " " not in line
    assert wrap_text(draw, text, font, 400).count("\n") == 1  # wide enough: as written


def test_figure_has_a_close_up_and_a_minified_row_of_labelled_panels(r):
    mesh = scenes.sphere()
    args = _args("-r", "16")
    camera = camera_from_args(args, bounds_of(mesh), surface_sample(mesh))
    fig = figure(r, mesh, camera, args)

    assert [row.name for row in fig.rows] == ["close-up", "minified"]
    names = ["ground truth: polygons 8x8", "(a) polygons, 1 spp", "(b) volume rendering", "(c) disc splats (high)"]
    for row in fig.rows:
        assert [p.name for p in row.panels] == names and row.voxels == "texture 16³"
        assert row.panels[0].psnr is None and row.panels[0].label.startswith(names[0])
        for p in row.panels:
            assert p.label.startswith(p.name) and f"{p.ms:.0f} ms" in p.label and p.ms > 0
        for p in row.panels[1:]:
            assert math.isfinite(p.psnr) and 5 < p.psnr < 80 and f"PSNR {p.psnr:.1f} dB" in p.label
    close, far = (row.camera for row in fig.rows)
    assert needed_resolution(far, args.size, mesh.bounds, maximum=4096) == 16  # a voxel of 16³ on a pixel
    assert nearest_depth(far, mesh.bounds) > 2 * nearest_depth(close, mesh.bounds)
    # Two strips of four 96-pixel panels, one above the other.
    h, w, _ = fig.image.shape
    assert w >= 4 * SIZE and h >= 2 * SIZE
    # The printed table: one line per panel kind, each with both rows' numbers.
    for name in names:
        (line,) = [ln for ln in fig.lines if ln.startswith(name)]
        assert line.count(" ms") == 2 and line.count("PSNR") == (0 if name == names[0] else 2)
    assert [ln for ln in fig.lines if ln.startswith("row ")] == [f"row {row.title}" for row in fig.rows]


@pytest.mark.gpu
def test_auto_figure_draws_the_minified_row_from_the_close_up_pyramid(r):
    mesh = scenes.sphere()
    args = _args("--distance", "2.5")
    camera = camera_from_args(args, mesh.bounds, surface_sample(mesh))
    fine = needed_resolution(camera, args.size, mesh.bounds)
    coarse = min(MINIFIED_RESOLUTION, fine // 2)
    fig = figure(r, mesh, camera, args)
    assert [row.voxels for row in fig.rows] == [f"texture {fine}³ (auto)", f"texture {coarse}³ (auto)"]
    assert needed_resolution(fig.rows[1].camera, args.size, mesh.bounds) == coarse
    tex = r.conversions.get(mesh, ("texture", fine, args.directions))
    level = r.conversions.get(tex, ("pyramid",))[int(math.log2(fine // coarse))]
    assert r.conversions.get(mesh, ("texture", coarse, args.directions)) is level, "built twice"
    assert all(math.isfinite(p.psnr) for row in fig.rows for p in row.panels[1:])


@pytest.mark.gpu
def test_figure_of_a_texture_has_no_errors_and_keeps_its_voxels(r):
    tex = build_texture(scenes.sphere(), 16, 8)
    args = _args()
    fig = figure(r, tex, camera_from_args(args, bounds_of(tex), surface_sample(tex)), args)
    assert len(fig.rows) == 2
    for row in fig.rows:
        assert [p.name for p in row.panels] == ["(b) volume rendering", "(c) disc splats (high)"]
        assert all(p.psnr is None for p in row.panels) and row.voxels == "texture 16³"
    assert "no polygon ground truth for this input: errors not measured" in fig.lines
    assert fig.lines[-1].startswith("times: median of 3 frames at 96x96 on ") and "PSNR" not in fig.lines[-1]
    assert needed_resolution(fig.rows[1].camera, args.size, bounds_of(tex), maximum=4096) == 16


@pytest.mark.gpu
def test_render_and_frames_resolve_auto_and_say_so(r, tmp_path, capsys):
    common = ["scene:sphere", "--size", "48", "--distance", "3", "--backend", "egl"]
    args = build_parser().parse_args(["render", *common])
    mesh = scenes.sphere()
    cam = camera_from_args(args, mesh.bounds, surface_sample(mesh))
    assert main(["render", *common, "--method", "volume", "-o", str(tmp_path / "a.png")]) == 0
    want = needed_resolution(cam, (48, 48), mesh.bounds)
    assert f"texture {want}³ (auto)" in capsys.readouterr().out
    assert main(["render", *common, "--method", "splat", "-r", "8", "-o", str(tmp_path / "b.png")]) == 0
    out = capsys.readouterr().out
    assert "texture 8³" in out and "auto" not in out
    # Frames: the finest any camera of the turntable needs (the box turns, its nearest corner with it).
    cams = turntable(cam, 3, 120.0)
    want = max(needed_resolution(c, (48, 48), mesh.bounds) for c in cams)
    assert main(["frames", *common, "--frames", "3", "--degrees", "120", "-q", "--method", "volume",
                 "-o", str(tmp_path / "f")]) == 0  # fmt: skip
    assert capsys.readouterr().out.rstrip().endswith(f"texture {want}³ (auto)")
    assert len(list((tmp_path / "f").glob("*.png"))) == 3
