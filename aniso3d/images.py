"""Image files and image arithmetic shared by the front ends."""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from .errors import InputError
from .util import atomic_write


def save_png(path: str | os.PathLike, image: np.ndarray) -> Path:
    """Write an (H, W, 3|4) uint8 image as PNG, atomically."""
    from PIL import Image

    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] not in (3, 4):
        raise InputError(f"an image must be (H, W, 3|4) uint8, got {img.shape} {img.dtype}")
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    return atomic_write(path, buf.getvalue())


def load_png(path: str | os.PathLike) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"))
