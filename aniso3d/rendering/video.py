"""Turntables people can share: a sequence of frames as one animated GIF,
animated WebP (both through Pillow, a core dependency) or H.264 MP4 (through
imageio-ffmpeg, the optional ``video`` extra), the format chosen by the file
name's suffix.

Frames are taken one at a time from any iterable. With a generator that
renders as the video is written, MP4 keeps one frame in memory. GIF keeps
each frame's 8-bit palette image, a third of its RGB size. WebP keeps every
frame in RGB, because Pillow's encoder takes them all at once: 360 frames
of 1024^2 make about 1.1 GB, so long, large turntables are better as MP4. The file is
written like every other aniso3d output (:func:`aniso3d.files.atomic_write`):
a failed or interrupted run leaves no half-written video and leaves a file
already at that path untouched.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from aniso3d.errors import InputError, ResourceError
from aniso3d.files import atomic_write

#: Suffix -> format name; what ``-o`` of ``aniso3d frames`` turns into a video.
VIDEO_FORMATS = {".gif": "GIF", ".webp": "WebP", ".mp4": "MP4"}
INSTALL_VIDEO = "pip install 'aniso3d[video]'"
#: x264 constant rate factor: 18 is visually lossless for renders and keeps a
#: 1024^2, 360-frame turntable in a few megabytes.
MP4_CRF = 18
#: Lossy WebP quality (0-100): edges stay crisp at a tenth of lossless's size.
WEBP_QUALITY = 90


#: Frame rates each format can hold: GIF stores delays in hundredths of a
#: second and browsers slow delays under 20 ms to 100 ms, so at most 50.
FPS_RANGE = {"GIF": (1 / 600, 50.0), "WebP": (1 / 600, 240.0), "MP4": (1 / 600, 240.0)}


def is_video_path(path: str | os.PathLike) -> bool:
    """True when ``path`` names a video file aniso3d can write (by its suffix)."""
    return Path(path).suffix.lower() in VIDEO_FORMATS


def check_video_output(path: str | os.PathLike, fps: float) -> str:
    """Check, before any frame is rendered, that ``path`` can be written at
    ``fps`` frames per second; returns the format ("GIF", "WebP" or "MP4").

    Raises InputError for an unknown suffix, a bad frame rate or a missing
    folder, and ResourceError naming ``pip install 'aniso3d[video]'`` when MP4
    is asked for without imageio-ffmpeg.
    """
    p = Path(path)
    fmt = VIDEO_FORMATS.get(p.suffix.lower())
    if fmt is None:
        raise InputError(
            f"cannot tell a video format from '{p.name}'; end the name with one of {', '.join(VIDEO_FORMATS)}"
        )
    if isinstance(fps, bool) or not isinstance(fps, int | float) or not math.isfinite(fps) or fps <= 0:
        raise InputError(f"frames per second must be a positive number, got {fps!r}")
    low, high = FPS_RANGE[fmt]
    if not low <= fps <= high:
        raise InputError(f"{fmt} plays {low:g} to {high:g} frames per second; got {fps:g}")
    if p.is_dir():
        raise InputError(f"output '{p}' is a directory; name a {p.suffix} file to write")
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.exists():
        raise InputError(f"output folder '{folder}' does not exist; create it first")
    if fmt == "MP4":
        _ffmpeg()
    return fmt


def _ffmpeg():
    """imageio_ffmpeg, or a ResourceError that says how to install it."""
    try:
        import imageio_ffmpeg
    except ImportError:
        raise ResourceError(
            f"writing MP4 needs imageio-ffmpeg, which is not installed; run {INSTALL_VIDEO} "
            "(or write .gif or .webp, which need nothing more)"
        ) from None
    return imageio_ffmpeg


def _checked(frames: Iterable[np.ndarray]) -> Iterator[np.ndarray]:
    """The frames as (H, W, 3) uint8, all of the first one's size."""
    shape = None
    n = 0
    for n, frame in enumerate(frames, 1):
        img = np.asarray(frame)
        if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] not in (3, 4):
            raise InputError(f"video frame {n} must be (H, W, 3|4) uint8, got {img.shape} {img.dtype}")
        if shape is None:
            shape = img.shape[:2]
        elif img.shape[:2] != shape:
            raise InputError(f"video frame {n} is {img.shape[1]}x{img.shape[0]}, the first was "
                             f"{shape[1]}x{shape[0]}; every frame must have one size")  # fmt: skip
        yield np.ascontiguousarray(img[:, :, :3])
    if n == 0:
        raise InputError("a video needs at least one frame, got none")


def _write_pillow(fh, frames: Iterator[np.ndarray], fmt: str, fps: float) -> None:
    from PIL import Image

    first = Image.fromarray(next(frames))
    # GIF stores delays in hundredths of a second: 24 fps plays at 25.
    duration = 1000.0 / fps
    rest = (Image.fromarray(f) for f in frames)
    if fmt == "GIF":
        first.save(fh, format="GIF", save_all=True, append_images=rest, duration=round(duration), loop=0,
                   optimize=False, disposal=1)  # fmt: skip
    else:
        first.save(fh, format="WEBP", save_all=True, append_images=rest, duration=round(duration), loop=0,
                   quality=WEBP_QUALITY, method=4)  # fmt: skip


def _even(img: np.ndarray) -> np.ndarray:
    """Pad an odd width or height by repeating the last column/row: H.264's
    4:2:0 colour needs even sizes, and padding keeps every pixel as drawn."""
    h, w = img.shape[:2]
    if h % 2 == 0 and w % 2 == 0:
        return img
    return np.pad(img, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")


def _write_mp4(fh, frames: Iterator[np.ndarray], fps: float, folder: Path) -> None:
    ffmpeg = _ffmpeg()
    first = _even(next(frames))
    h, w = first.shape[:2]
    # ffmpeg seeks in its output (the index goes to the front with +faststart,
    # so players start before the whole file is there): it writes a file of its
    # own beside the output, copied into the atomically written one at the end.
    fd, tmp = tempfile.mkstemp(prefix=".aniso3d-video.", suffix=".mp4", dir=folder)
    os.close(fd)
    try:
        writer = ffmpeg.write_frames(tmp, (w, h), fps=fps, quality=None, macro_block_size=1, codec="libx264",
                                     output_params=["-crf", str(MP4_CRF), "-movflags", "+faststart"],
                                     ffmpeg_log_level="error")  # fmt: skip
        writer.send(None)  # starts ffmpeg
        sent = 0
        try:
            writer.send(first)
            sent = 1
            for frame in frames:
                writer.send(_even(frame))
                sent += 1
        except BaseException:
            writer.close()  # stops ffmpeg; the half file is removed below
            raise
        writer.close()
        # imageio-ffmpeg does not check ffmpeg's exit status: read the file
        # back, so a failed encoder never replaces the user's video.
        try:
            got, _ = ffmpeg.count_frames_and_secs(tmp)
        except Exception as exc:  # noqa: BLE001 - any failure means a bad file
            raise ResourceError(f"ffmpeg did not write a readable MP4 ({exc}); nothing was written") from None
        if got != sent:
            raise ResourceError(f"ffmpeg wrote {got} of {sent} frames; nothing was written")
        with open(tmp, "rb") as src:
            shutil.copyfileobj(src, fh, 1 << 20)
    finally:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass


def write_video(frames: Iterable[np.ndarray], path: str | os.PathLike, fps: float = 24.0) -> Path:
    """Write ``frames`` ((H, W, 3|4) uint8 each, one size) as a video at ``path``.

    The suffix picks the format: ``.gif`` (256 colours per frame, delays in
    hundredths of a second), ``.webp`` (lossy, quality 90) or ``.mp4`` (H.264,
    yuv420p, CRF 18; needs ``pip install 'aniso3d[video]'``; an odd size is
    padded by one edge pixel). ``fps``: frames per second of playback. Every
    format loops (MP4 players decide for themselves). Written atomically.
    """
    fmt = check_video_output(path, fps)
    stream = _checked(frames)
    if fmt == "MP4":
        folder = Path(path).parent if str(Path(path).parent) else Path(".")
        return atomic_write(path, lambda fh: _write_mp4(fh, stream, float(fps), folder))
    return atomic_write(path, lambda fh: _write_pillow(fh, stream, fmt, float(fps)))


__all__ = ["INSTALL_VIDEO", "VIDEO_FORMATS", "check_video_output", "is_video_path", "write_video"]
