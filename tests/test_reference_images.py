"""Small reference images: each renderer and splat shape on a few shapes,
64 x 64 on llvmpipe, compared with PNGs stored in ``tests/reference/``.

These catch any change to what the renderers draw, including ones the
cross-renderer tolerances allow. Tolerance: llvmpipe is deterministic for a
given Mesa, so the images must agree to within rounding: the mean absolute
difference at most 0.5 grey levels and at most 1% of channel values off by
more than 8 levels (room for a Mesa update's rounding, not for a change of
method). On failure the actual image and an amplified difference are written
beside the reference as ``NAME.actual.png`` and ``NAME.diff.png``.

An intended change: ``./scripts/test tests/test_reference_images.py
--regen-references`` rewrites the references; look at them before committing.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from aniso3d import scenes
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.images import load_png, save_png

REFERENCE = Path(__file__).parent / "reference"
SIZE = (64, 64)
MEAN_TOLERANCE = 0.5
OUTLIER_LEVELS = 8
OUTLIER_SHARE = 0.01

SHAPES = ("quad", "cube", "sphere", "tree")
#: (name, method, draw options): every renderer, every splat shape and quality.
DRAWS = (
    ("mesh", "mesh", {}),
    ("mesh-ssaa4", "mesh", {"ssaa": 4}),
    ("volume", "volume", {}),
    ("splat-square", "splat", {"splat": "square"}),
    ("splat-disc", "splat", {"splat": "disc"}),
    ("splat-ellipse", "splat", {"splat": "ellipse"}),
    ("splat-disc-high", "splat", {"splat": "disc", "quality": "high"}),
)
BUILD = {"resolution": 16, "directions": 16}


def _mesh(shape: str):
    if shape == "tree":
        return scenes.tree(levels=4, leaves_per_twig=12)
    return scenes.get_scene(shape)


def _camera(mesh) -> Camera:
    return Camera.fit(mesh.bounds, direction=(0.6, 0.45, 1.0), points=mesh.vertices)


@pytest.mark.gpu
@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("draw", DRAWS, ids=[d[0] for d in DRAWS])
def test_reference_image(r, shape, draw, regen_references):
    name, method, options = draw
    mesh = _mesh(shape)
    opts = dict(options)
    if method != "mesh":
        opts.update(BUILD)
    image = r.render(mesh, _camera(mesh), method, size=SIZE, **opts)
    assert image.shape == (SIZE[1], SIZE[0], 3) and image.dtype == np.uint8
    path = REFERENCE / f"{shape}-{name}.png"
    if regen_references or not path.exists():
        if not regen_references:
            pytest.fail(f"no reference image {path.name}; run with --regen-references to make it")
        save_png(path, image)
        return
    expected = load_png(path)[:, :, :3]
    diff = np.abs(image.astype(np.int16) - expected.astype(np.int16))
    mean, outliers = float(diff.mean()), float((diff > OUTLIER_LEVELS).mean())
    for stale in (path.with_suffix(".actual.png"), path.with_suffix(".diff.png")):
        stale.unlink(missing_ok=True)
    if mean > MEAN_TOLERANCE or outliers > OUTLIER_SHARE:
        save_png(path.with_suffix(".actual.png"), image)
        save_png(path.with_suffix(".diff.png"), np.clip(diff * 8, 0, 255).astype(np.uint8))
        pytest.fail(
            f"{path.name}: mean difference {mean:.2f} grey levels (limit {MEAN_TOLERANCE}), "
            f"{100 * outliers:.2f}% of values off by more than {OUTLIER_LEVELS} (limit {100 * OUTLIER_SHARE:g}%); "
            f"see {path.with_suffix('.diff.png').name}"
        )


def test_the_comparison_can_fail(tmp_path):
    """The tolerance is a real limit: a one-pixel-wide change of colour fails it."""
    a = np.full((64, 64, 3), 200, np.uint8)
    b = a.copy()
    b[:, 10] = 0
    diff = np.abs(a.astype(np.int16) - b.astype(np.int16))
    assert diff.mean() > MEAN_TOLERANCE or (diff > OUTLIER_LEVELS).mean() > OUTLIER_SHARE
