"""The image metrics on images whose answer is known in closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest

from aniso3d import metrics
from aniso3d.errors import InputError


def _textured(shape=(96, 128, 3), seed=0, lo=64, hi=192) -> np.ndarray:
    """A smooth-plus-noisy test image kept well inside (0, 255) so that
    shifts and noise below never clip."""
    rng = np.random.default_rng(seed)
    h, w, _ = shape
    yy, xx = np.mgrid[0:h, 0:w]
    base = (
        0.5 * (lo + hi)
        + 0.25 * (hi - lo) * np.sin(xx / 7.0)[..., None] * np.cos(yy / 5.0)[..., None]
    )
    img = base + rng.uniform(-0.2, 0.2, shape) * (hi - lo)
    return np.clip(np.round(img), lo, hi).astype(np.uint8)


def test_identical_images_are_perfect():
    img = _textured()
    assert metrics.psnr(img, img) == math.inf
    assert metrics.mse(img, img) == 0.0
    assert metrics.ssim(img, img) == pytest.approx(1.0, abs=1e-12)


def test_psnr_of_known_gaussian_noise():
    # Noise of standard deviation sigma, then rounding to whole code values
    # (uniform error, variance 1/12): expected MSE = sigma^2 + 1/12.
    sigma = 5.0
    img = _textured((256, 256, 3), seed=1)
    rng = np.random.default_rng(2)
    noisy = np.round(img + rng.normal(0.0, sigma, img.shape))
    assert noisy.min() >= 0 and noisy.max() <= 255  # no clipping, or the formula is off
    noisy = noisy.astype(np.uint8)
    expected = 10 * math.log10(255.0**2 / (sigma**2 + 1.0 / 12.0))
    # 196,608 samples: the MSE estimate's relative spread is ~0.3 %, ~0.014 dB.
    assert metrics.psnr(img, noisy) == pytest.approx(expected, abs=0.06)
    # And the definition itself, exactly.
    assert metrics.psnr(img, noisy) == pytest.approx(
        10 * math.log10(255.0**2 / metrics.mse(img, noisy)), rel=1e-12
    )


def test_psnr_of_constant_error():
    a = np.full((16, 16, 3), 100, np.uint8)
    b = a + np.uint8(10)
    assert metrics.psnr(a, b) == pytest.approx(10 * math.log10(255.0**2 / 100.0), rel=1e-12)


def test_ssim_of_constant_shift_on_flat_images_is_the_luminance_term():
    # Flat images: zero variance, so SSIM is the luminance term alone,
    # (2 a b + C1) / (a^2 + b^2 + C1), with C1 = (0.01 * 255)^2.
    c1 = (0.01 * 255) ** 2
    for a, b in ((100, 110), (100, 150), (20, 200)):
        x = np.full((32, 40, 3), a, np.uint8)
        y = np.full((32, 40, 3), b, np.uint8)
        want = (2 * a * b + c1) / (a * a + b * b + c1)
        assert metrics.ssim(x, y) == pytest.approx(want, rel=1e-12)
        assert metrics.ssim(y, x) == pytest.approx(want, rel=1e-12)


def test_ssim_of_constant_shift_on_textured_image():
    # A shift leaves variances and covariance unchanged (contrast-structure
    # term exactly 1), so SSIM drops only through luminance: below 1, above
    # the flat-image value at the darkest local mean, and falling with the shift.
    img = _textured(seed=3)
    values = [metrics.ssim(img, img + np.uint8(s)) for s in (5, 20, 40)]
    assert all(0.0 < v < 1.0 for v in values)
    assert values[0] > values[1] > values[2]
    c1 = (0.01 * 255) ** 2
    lo = 64.0
    for s, v in zip((5, 20, 40), values, strict=True):
        assert v > (2 * lo * (lo + s) + c1) / (lo * lo + (lo + s) ** 2 + c1)


def test_ssim_is_per_channel_mean():
    img = _textured(seed=4)
    other = img.copy()
    other[..., 1] = _textured(seed=5)[..., 1]
    per_channel = [
        metrics.ssim(
            np.repeat(img[..., c : c + 1], 3, axis=2), np.repeat(other[..., c : c + 1], 3, axis=2)
        )
        for c in range(3)
    ]
    assert per_channel[0] == pytest.approx(1.0) and per_channel[2] == pytest.approx(1.0)
    assert metrics.ssim(img, other) == pytest.approx(np.mean(per_channel), rel=1e-12)


def test_ssim_matches_scikit_image_when_present():
    skm = pytest.importorskip(
        "skimage.metrics", reason="scikit-image not installed (optional cross-check)"
    )
    rng = np.random.default_rng(6)
    a = rng.integers(0, 256, (60, 70, 3), dtype=np.uint8)
    b = np.clip(a + rng.normal(0, 25, a.shape), 0, 255).astype(np.uint8)
    want = skm.structural_similarity(
        a,
        b,
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
        data_range=255,
        channel_axis=2,
    )
    assert metrics.ssim(a, b) == pytest.approx(want, rel=1e-9)


def test_bad_inputs_are_named():
    a = np.zeros((20, 20, 3), np.uint8)
    with pytest.raises(InputError, match="differ in shape"):
        metrics.psnr(a, np.zeros((20, 21, 3), np.uint8))
    with pytest.raises(InputError, match="uint8"):
        metrics.psnr(a, a.astype(np.float32))
    with pytest.raises(InputError, match="too small"):
        metrics.ssim(a[:8], a[:8])


def test_flip_of_identical_images_is_zero():
    if not metrics.flip_available():
        pytest.skip("flip-evaluator not installed (optional: pip install 'aniso3d[metrics]')")
    img = _textured(seed=7)
    assert metrics.flip(img, img) == pytest.approx(0.0, abs=1e-7)
    noisy = np.clip(img + np.random.default_rng(8).normal(0, 20, img.shape), 0, 255).astype(
        np.uint8
    )
    assert 0.0 < metrics.flip(img, noisy) < 1.0


def test_flip_missing_says_how_to_install(monkeypatch):
    import builtins

    real_import = builtins.__import__

    def fake_import(name, *args, **kwargs):
        if name == "flip_evaluator":
            raise ImportError("No module named 'flip_evaluator'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake_import)
    img = _textured(seed=9)
    assert not metrics.flip_available()
    with pytest.raises(ImportError, match=r"pip install 'aniso3d\[metrics\]'"):
        metrics.flip(img, img)
    out = metrics.compare(img, img)
    assert math.isnan(out["flip"]) and out["psnr"] == math.inf
