"""Turntables as GIF, WebP and MP4: readable by other tools, the frames that
were rendered, written atomically, and a clear word when MP4's extra is missing."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from PIL import Image, ImageSequence

import aniso3d
from aniso3d import InputError, ResourceError, scenes
from aniso3d.app.cli import main
from aniso3d.rendering.camera import Camera, turntable
from aniso3d.rendering.video import INSTALL_VIDEO, check_video_output, write_video

FRAMES = 6
#: Mean absolute difference (grey levels, 0-255) allowed between a frame read
#: back and the frame rendered: GIF quantises to 256 colours, WebP and H.264
#: are lossy. Each is well below the difference between successive frames of
#: the turntable (checked in the test), so a shuffled or stale frame fails.
TOLERANCE = {"gif": 4.0, "webp": 4.0, "mp4": 4.0}


def leftovers(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def read_frames(path) -> list[np.ndarray]:
    """Every frame of a video file, as (H, W, 3) uint8, by a reader other than the writer."""
    if path.suffix == ".mp4":
        iio = pytest.importorskip("imageio.v3")
        return list(iio.imiter(path, plugin="FFMPEG"))
    with Image.open(path) as im:
        return [np.asarray(f.convert("RGB")) for f in ImageSequence.Iterator(im)]


@pytest.fixture(scope="module")
def rendered(r):
    """FRAMES frames of the blob turning 60 degrees, 128 x 128."""
    blob = scenes.get_scene("blob")
    cams = turntable(Camera.fit(blob.bounds, direction=(0.3, 0.4, 1.0)), FRAMES, 60.0)
    return blob, cams, [r.render(blob, c, "mesh") for c in cams]


def mad(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a.astype(np.float64) - b.astype(np.float64)).mean())


@pytest.mark.gpu
@pytest.mark.parametrize("ext", ["gif", "webp", "mp4"])
def test_video_holds_the_rendered_frames(rendered, tmp_path, ext):
    if ext == "mp4":
        pytest.importorskip("imageio_ffmpeg")
    _, _, frames = rendered
    path = write_video(frames, tmp_path / f"turn.{ext}", fps=12)
    back = read_frames(path)
    assert len(back) == FRAMES
    for i, (got, want) in enumerate(zip(back, frames, strict=True)):
        assert got.shape == want.shape == (128, 128, 3)
        err = mad(got, want)
        assert err < TOLERANCE[ext], f"frame {i}: {err}"
        if i:  # the frame is this one, not its neighbour
            assert err < 0.5 * mad(got, frames[i - 1]), f"frame {i} looks like frame {i - 1}"
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("ext", ["gif", "webp"])
def test_pillow_formats_keep_the_frame_rate(tmp_path, ext):
    frames = [np.full((8, 10, 3), 40 * i, np.uint8) for i in range(3)]
    path = write_video(frames, tmp_path / f"t.{ext}", fps=20)
    with Image.open(path) as im:
        assert im.n_frames == 3 and im.size == (10, 8)
        assert im.info.get("loop") == 0  # loops forever
        for i in range(3):
            im.seek(i)
            im.load()  # WebP reports a frame's duration once it is read
            assert im.info["duration"] == 50  # ms


def test_mp4_pads_an_odd_size_and_keeps_the_frame_rate(tmp_path):
    iio = pytest.importorskip("imageio.v3")
    pytest.importorskip("imageio_ffmpeg")
    yy, xx = np.mgrid[0:33, 0:47]
    frames = [np.stack([xx * 5, yy * 7, np.full_like(xx, 30 * i)], -1).astype(np.uint8) for i in range(5)]
    path = write_video(frames, tmp_path / "odd.mp4", fps=10)
    meta = iio.immeta(path, plugin="FFMPEG")
    assert meta["fps"] == pytest.approx(10)
    back = list(iio.imiter(path, plugin="FFMPEG"))
    assert len(back) == 5
    assert back[0].shape == (34, 48, 3)  # one edge row and column added
    for got, want in zip(back, frames, strict=True):
        assert mad(got[:33, :47], want) < 4.0
        assert mad(got[33], got[32]) < 4.0 and mad(got[:, 47], got[:, 46]) < 4.0  # the padding repeats the edge


def test_a_failing_encoder_never_replaces_the_old_video(tmp_path, monkeypatch):
    """imageio-ffmpeg ignores ffmpeg's exit status: the file is read back."""
    pytest.importorskip("imageio_ffmpeg")
    fake = tmp_path / "ffmpeg"
    # It writes a bad file where it is told to, and "truncated" on standard
    # output when asked to read one back ("-": the pipe, not a file here).
    fake.write_text(
        "#!/bin/sh\ncat > /dev/null\nfor last; do :; done\n"
        "if [ \"$last\" = - ]; then echo truncated; else echo truncated > \"$last\"; fi\nexit 1\n"
    )
    fake.chmod(0o755)
    monkeypatch.chdir(tmp_path)  # whatever it writes stays out of the checkout
    old = tmp_path / "kept.mp4"
    old.write_bytes(b"the user's video")
    monkeypatch.setenv("IMAGEIO_FFMPEG_EXE", str(fake))
    with pytest.raises(ResourceError, match="nothing was written"):
        write_video([np.zeros((8, 8, 3), np.uint8)] * 3, old, fps=10)
    assert old.read_bytes() == b"the user's video"
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("ext", ["gif", "webp", "mp4"])
@pytest.mark.parametrize("failure", [RuntimeError, KeyboardInterrupt])
def test_a_failing_write_leaves_the_old_file_and_no_temporary(tmp_path, ext, failure):
    if ext == "mp4":
        pytest.importorskip("imageio_ffmpeg")
    out = tmp_path / f"turn.{ext}"
    out.write_bytes(b"the earlier turntable")
    made = []

    def frames():
        for i in range(4):
            made.append(i)
            yield np.full((16, 16, 3), 50 * i, np.uint8)
        raise failure("renderer failed at frame 4")

    with pytest.raises(failure):
        write_video(frames(), out, fps=10)
    assert made == [0, 1, 2, 3]  # the writer had taken frames when it failed
    assert out.read_bytes() == b"the earlier turntable"
    assert sorted(p.name for p in tmp_path.iterdir()) == [out.name]


def test_missing_imageio_ffmpeg_names_the_extra(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # import raises ImportError
    with pytest.raises(ResourceError, match=r"imageio-ffmpeg.*pip install 'aniso3d\[video\]'"):
        write_video([np.zeros((4, 4, 3), np.uint8)], tmp_path / "t.mp4")
    assert list(tmp_path.iterdir()) == []
    # The command refuses before it loads or renders anything: one line, status 2.
    code = main(["frames", "scene:blob", "-o", str(tmp_path / "t.mp4"), "--frames", "2", "-q"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.strip().splitlines() == [err.strip()] and INSTALL_VIDEO in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []
    # GIF and WebP need nothing more.
    assert write_video([np.zeros((4, 4, 3), np.uint8)], tmp_path / "t.gif").exists()


@pytest.mark.parametrize(
    "frames, path, fps, words",
    [
        ([np.zeros((4, 4, 3), np.uint8)], "t.avi", 10, ".gif, .webp, .mp4"),
        ([np.zeros((4, 4, 3), np.uint8)], "t.gif", 0, "positive"),
        ([np.zeros((4, 4, 3), np.uint8)], "t.gif", float("nan"), "positive"),
        ([], "t.gif", 10, "at least one frame"),
        ([np.zeros((4, 4, 3), np.uint8), np.zeros((4, 5, 3), np.uint8)], "t.webp", 10, "one size"),
        ([np.zeros((4, 4, 3), np.float32)], "t.gif", 10, "uint8"),
        ([np.zeros((4, 4, 3), np.uint8)], "missing/t.gif", 10, "does not exist"),
        ([np.zeros((4, 4, 3), np.uint8)], "t.gif", 60, "GIF plays"),
        ([np.zeros((4, 4, 3), np.uint8)], "t.mp4", 1e12, "MP4 plays"),
    ],
)
def test_bad_video_requests_are_one_clear_error(tmp_path, frames, path, fps, words):
    with pytest.raises(InputError, match=words.replace(".", r"\.")):
        write_video(frames, tmp_path / path, fps=fps)
    assert leftovers(tmp_path) == []


def test_check_video_output_names_the_format(tmp_path):
    assert check_video_output(tmp_path / "a.GIF", 24) == "GIF"
    assert check_video_output(tmp_path / "a.webp", 24) == "WebP"
    assert aniso3d.write_video is write_video


@pytest.mark.gpu
def test_render_video_matches_render(r, rendered, tmp_path):
    blob, cams, frames = rendered
    path = r.render_video(blob, cams, tmp_path / "turn.webp", "mesh", fps=8)
    back = read_frames(path)
    assert len(back) == FRAMES
    assert all(mad(g, w) < TOLERANCE["webp"] for g, w in zip(back, frames, strict=True))


@pytest.mark.gpu
def test_frames_command_writes_a_gif(tmp_path, capsys):
    out = tmp_path / "turn.gif"
    code = main(["frames", "scene:blob", "--method", "mesh", "--size", "64", "--frames", "4", "--fps", "10",
                 "-o", str(out), "-q"])  # fmt: skip
    stdout = capsys.readouterr().out
    assert code == 0 and f"wrote 4 frames to {out} at 10 fps" in stdout
    with Image.open(out) as im:
        assert im.n_frames == 4 and im.size == (64, 64) and im.info["duration"] == 100
    # numbered PNGs as before when the output is a folder
    code = main(["frames", "scene:blob", "--method", "mesh", "--size", "32", "--frames", "2",
                 "-o", str(tmp_path / "pngs"), "-q"])  # fmt: skip
    assert code == 0 and sorted(p.name for p in (tmp_path / "pngs").iterdir()) == ["frame_0000.png", "frame_0001.png"]


def test_a_write_error_is_one_line(tmp_path, monkeypatch, capsys):
    """A full disk or a read-only folder: one line naming the file, no traceback."""
    import errno

    import aniso3d.files

    def full(path, data):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(aniso3d.files, "atomic_write", full)
    monkeypatch.setattr(aniso3d.rendering.video, "atomic_write", full)
    code = main(["frames", "scene:lattice", "-r", "8", "--frames", "2", "--size", "32", "-q",
                 "-o", str(tmp_path / "t.gif")])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "No space left on device" in err and "t.gif" in err
