"""Image error metrics for comparing a rendering with its ground truth.

The colour space, once for all three metrics: aniso3d's renderers write their
shaded colours straight into an 8-bit framebuffer without a transfer function,
and that uint8 image is what a viewer shows. The images are therefore taken as
**display-referred, sRGB-encoded 8-bit RGB**, and

- :func:`psnr` and :func:`ssim` are computed on those encoded values as they
  are (data range L = 255), not on linearised light: this is the usual
  convention for both metrics, and encoded values are closer to perceptually
  uniform than linear ones;
- :func:`flip` hands the same values, scaled to [0, 1], to NVIDIA's LDR-FLIP
  as sRGB input; FLIP linearises them itself on the way into its own
  perceptual colour space.

Every function takes two (H, W, 3) uint8 arrays of the same shape: the
reference (ground truth) first, then the test image.

Where the errors are measured: inside :func:`screen_box`, the pixel box the
object's bounds project to (plus a margin), so that a far, small object is
not scored mostly on empty background (``aniso3d bench`` and the figure of
``aniso3d render --method all`` measure the same way: :func:`compare_in_box`).
"""

from __future__ import annotations

import math

import numpy as np

from aniso3d.errors import InputError

#: Peak value of the 8-bit encoded images all metrics work on.
DATA_RANGE = 255.0
#: SSIM constants of Wang, Bovik, Sheikh & Simoncelli (2004).
SSIM_K1 = 0.01
SSIM_K2 = 0.03
SSIM_WINDOW = 11
SSIM_SIGMA = 1.5
#: FLIP's default viewing condition: pixels per degree of visual angle
#: (a 0.7 m viewing distance from a 0.7 m wide 3840-pixel monitor).
FLIP_PPD = 67.0

FLIP_MISSING = (
    "FLIP not computed: the optional package flip-evaluator is not installed; "
    "install it with: pip install 'aniso3d[metrics]'"
)


def _check_pair(
    reference: np.ndarray, test: np.ndarray, min_side: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    ref, tst = np.asarray(reference), np.asarray(test)
    for name, img in (("reference", ref), ("test", tst)):
        if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
            raise InputError(f"{name} image must be (H, W, 3) uint8, got {img.shape} {img.dtype}")
    if ref.shape != tst.shape:
        raise InputError(f"images differ in shape: reference {ref.shape}, test {tst.shape}")
    if min(ref.shape[:2]) < min_side:
        raise InputError(
            f"images of {ref.shape[1]}x{ref.shape[0]} pixels are too small; need {min_side} a side"
        )
    return ref, tst


def screen_box(
    xy: np.ndarray, size: tuple[int, int], margin: int = 8, min_side: int = 16
) -> tuple[int, int, int, int]:
    """Pixel box ``(x0, y0, x1, y1)`` (x0, y0 inclusive, x1, y1 exclusive; y
    down) around the points ``xy`` (N, 2) in pixels, e.g. the eight corners of
    an object's bounds projected by ``Camera.project``, grown by ``margin``
    pixels, clamped to the image ``size = (W, H)``, and at least ``min_side``
    pixels a side where the image allows (SSIM needs 11), centred on the
    points' box when it had to grow."""
    pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    if len(pts) == 0 or not np.isfinite(pts).all():
        raise InputError(f"screen_box needs (N, 2) finite pixel positions, got {np.asarray(xy).shape}")
    w, h = int(size[0]), int(size[1])
    if w < 1 or h < 1:
        raise InputError(f"image size must be at least 1x1 pixels, got {size}")
    x0, y0 = np.floor(pts.min(axis=0)) - margin
    x1, y1 = np.ceil(pts.max(axis=0)) + margin
    box = []
    for lo, hi, n in ((x0, x1, w), (y0, y1, h)):
        lo, hi = int(min(max(0, lo), n)), int(max(min(n, hi), 0))
        side = min(n, max(min_side, hi - lo))
        if hi - lo < side:
            mid = (lo + hi) // 2
            lo = max(0, min(n - side, mid - side // 2))
            hi = lo + side
        box.append((lo, hi))
    (x0, x1), (y0, y1) = box
    return x0, y0, x1, y1


def crop(image: np.ndarray, box: tuple[int, int, int, int]) -> np.ndarray:
    """The RGB pixels of ``image`` (H, W, 3 or 4) inside ``box`` = (x0, y0, x1, y1)."""
    x0, y0, x1, y1 = box
    return np.asarray(image)[y0:y1, x0:x1, :3]


def mse(reference: np.ndarray, test: np.ndarray) -> float:
    """Mean squared error over all pixels and channels, in 8-bit code values squared."""
    ref, tst = _check_pair(reference, test)
    d = ref.astype(np.float64) - tst.astype(np.float64)
    return float(np.mean(d * d))


def psnr(reference: np.ndarray, test: np.ndarray) -> float:
    """Peak signal-to-noise ratio, dB: ``10 log10(255^2 / MSE)`` with the MSE
    over all pixels and all three channels of the encoded 8-bit values.
    ``inf`` for identical images."""
    e = mse(reference, test)
    return math.inf if e == 0.0 else 10.0 * math.log10(DATA_RANGE**2 / e)


def gaussian_window(size: int = SSIM_WINDOW, sigma: float = SSIM_SIGMA) -> np.ndarray:
    """(size,) normalised 1-D Gaussian taps; SSIM's 2-D window is its outer product."""
    x = np.arange(size, dtype=np.float64) - (size - 1) / 2.0
    g = np.exp(-(x * x) / (2.0 * sigma * sigma))
    return g / g.sum()


def _filter_valid(img: np.ndarray, taps: np.ndarray) -> np.ndarray:
    """Separable correlation of (H, W, C) with taps along H then W, 'valid'
    region only (no padding): (H - n + 1, W - n + 1, C)."""
    n = len(taps)
    h, w = img.shape[:2]
    rows = sum(taps[i] * img[i : h - n + 1 + i] for i in range(n))
    return sum(taps[i] * rows[:, i : w - n + 1 + i] for i in range(n))


def ssim_map(reference: np.ndarray, test: np.ndarray) -> np.ndarray:
    """(H - 10, W - 10, 3) local SSIM per channel (valid window positions only)."""
    ref, tst = _check_pair(reference, test, SSIM_WINDOW)
    x = ref.astype(np.float64)
    y = tst.astype(np.float64)
    g = gaussian_window()
    mx, my = _filter_valid(x, g), _filter_valid(y, g)
    # Weighted (population) variances and covariance, as in Wang et al.
    sxx = _filter_valid(x * x, g) - mx * mx
    syy = _filter_valid(y * y, g) - my * my
    sxy = _filter_valid(x * y, g) - mx * my
    c1 = (SSIM_K1 * DATA_RANGE) ** 2
    c2 = (SSIM_K2 * DATA_RANGE) ** 2
    return ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx * mx + my * my + c1) * (sxx + syy + c2))


def ssim(reference: np.ndarray, test: np.ndarray) -> float:
    """Structural similarity (Wang et al. 2004) on the encoded 8-bit values:
    11x11 Gaussian window (sigma 1.5), K1 = 0.01, K2 = 0.03, L = 255,
    computed **per R, G, B channel and averaged** over the channels and over
    every window position that lies wholly inside the image (no padding).
    1 for identical images; images must be at least 11 pixels a side."""
    return float(np.mean(ssim_map(reference, test)))


def flip_available() -> bool:
    """True if the optional FLIP package (import name ``flip_evaluator``) imports."""
    try:
        import flip_evaluator  # noqa: F401
    except ImportError:
        return False
    return True


def flip(reference: np.ndarray, test: np.ndarray, ppd: float = FLIP_PPD) -> float:
    """Mean LDR-FLIP error in [0, 1] (0 = identical), NVIDIA's perceptual
    difference metric; inputs are read as sRGB-encoded (see the module
    docstring), viewed at ``ppd`` pixels per degree.

    Raises :class:`ImportError` with an install hint when the optional package
    ``flip-evaluator`` is missing.
    """
    ref, tst = _check_pair(reference, test)
    if not (ppd > 0 and math.isfinite(ppd)):
        raise InputError(f"FLIP pixels per degree must be positive, got {ppd}")
    try:
        import flip_evaluator
    except ImportError:
        raise ImportError(FLIP_MISSING) from None
    r = np.ascontiguousarray(ref, dtype=np.float32) / np.float32(DATA_RANGE)
    t = np.ascontiguousarray(tst, dtype=np.float32) / np.float32(DATA_RANGE)
    _, mean, _ = flip_evaluator.evaluate(
        r, t, "LDR", inputsRGB=True, applyMagma=False, parameters={"ppd": float(ppd)}
    )
    return float(mean)


def compare(
    reference: np.ndarray, test: np.ndarray, with_flip: bool | None = None
) -> dict[str, float]:
    """``{"psnr", "ssim", "flip"}`` of ``test`` against ``reference``; ``flip``
    is NaN when FLIP is not installed (``with_flip=None``) or not wanted."""
    out = {"psnr": psnr(reference, test), "ssim": ssim(reference, test), "flip": math.nan}
    if with_flip is None:
        with_flip = flip_available()
    if with_flip:
        out["flip"] = flip(reference, test)
    return out


def compare_in_box(
    reference: np.ndarray, test: np.ndarray, box: tuple[int, int, int, int], with_flip: bool | None = None
) -> dict[str, float]:
    """:func:`compare` of the two images' RGB pixels inside ``box``
    (:func:`screen_box`): the errors ``aniso3d bench`` reports."""
    return compare(crop(reference, box), crop(test, box), with_flip)
