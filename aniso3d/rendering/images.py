"""Image files and image arithmetic shared by the front ends."""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from aniso3d.errors import InputError
from aniso3d.files import atomic_write


def png_bytes(image: np.ndarray) -> bytes:
    """An (H, W, 3|4) uint8 image encoded as PNG (lossless)."""
    from PIL import Image

    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] not in (3, 4):
        raise InputError(f"an image must be (H, W, 3|4) uint8, got {img.shape} {img.dtype}")
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    return buf.getvalue()


def save_png(path: str | os.PathLike, image: np.ndarray) -> Path:
    """Write an (H, W, 3|4) uint8 image as PNG, atomically."""
    return atomic_write(path, png_bytes(image))


def load_png(path: str | os.PathLike) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"))


def wrap_text(draw, text: str, font, width: float) -> str:
    """``text`` with each of its lines broken between words so that none is
    wider than ``width`` pixels in ``font`` (a word wider than that stays
    whole): captions of small panels must not run into their neighbours."""
    out: list[str] = []
    for line in text.split("\n"):
        words, cur = line.split(" "), ""
        for word in words:
            trial = f"{cur} {word}" if cur else word
            if cur and draw.textlength(trial, font=font) > width:
                out.append(cur)
                cur = word
            else:
                cur = trial
        out.append(cur)
    return "\n".join(out)


def label_panels(panels: list[np.ndarray], labels: list[str], gap: int = 8) -> np.ndarray:
    """Panels of equal height side by side on white, each captioned below
    (captions wrapped to their panel's width)."""
    from PIL import Image, ImageDraw, ImageFont

    h = max(p.shape[0] for p in panels)
    font_px = max(12, h // 28)
    try:
        font = ImageFont.load_default(size=font_px)
    except TypeError:  # Pillow < 10.1 has one bitmap size
        font = ImageFont.load_default()
    measure = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    labels = [wrap_text(measure, label, font, p.shape[1] - 4) for p, label in zip(panels, labels, strict=True)]
    lines = max(label.count("\n") + 1 for label in labels)
    caption = int(lines * font_px * 1.35) + gap
    w = sum(p.shape[1] for p in panels) + gap * (len(panels) + 1)
    canvas = Image.new("RGB", (w, h + caption + 2 * gap), (255, 255, 255))
    draw = ImageDraw.Draw(canvas)
    x = gap
    for img, label in zip(panels, labels, strict=True):
        canvas.paste(Image.fromarray(np.ascontiguousarray(img[:, :, :3])), (x, gap))
        draw.rectangle([x - 1, gap - 1, x + img.shape[1], gap + img.shape[0]], outline=(200, 200, 200))
        draw.multiline_text((x + 4, gap + h + gap // 2), label, fill=(0, 0, 0), font=font, spacing=4)
        x += img.shape[1] + gap
    return np.asarray(canvas)
