"""Training-time augmentation: photometric changes, homographic warps, and keypoint <-> label-map helpers.

Photometric augmentation (thesis §3.2.5: "an accumulation of small changes in noise, brightness, contrast,
shading and motion blur") applies every enabled operation once, in random order, each with its parameter
drawn from the range below. The thesis names the operations but not their ranges; the ranges are those of the
SuperPoint reference implementation (DeTone et al. 2018; the public TensorFlow re-implementation used by the
thesis), converted from 0..255 to the [0, 1] intensities of this library:

=====================  ==========================================  =====================  =====================
operation              what it does                                 synthetic shapes       real images
=====================  ==========================================  =====================  =====================
gaussian_noise         ``I + N(0, s^2)``, ``s ~ U(range)``          s in [5, 95] / 255     s in [0, 10] / 255
speckle_noise          salt & pepper: ``u <= p -> 0, u >= 1-p -> 1`` p in [0, 0.005]       p in [0, 0.0035]
brightness             ``I + b``, ``b ~ U(-m, m)``                  m = 50 / 255           m = 50 / 255
contrast               ``(I - mean) c + mean``, ``c ~ U(range)``    c in [0.5, 1.5]        c in [0.5, 1.5]
shade                  ``I (1 - t blur(ellipses))``, ``t ~ U``      t in [-0.5, 0.8],      t in [-0.5, 0.5],
                       (20 random ellipses, Gaussian-blurred)       kernel 250-350 px      kernel 100-150 px
motion_blur            line kernel of odd size k <= max, uniform    max 10 px              max 3 px
                       direction (SuperPoint: one of 4), Gaussian
                       weights (var k^2 / 16)
=====================  ==========================================  =====================  =====================

Every result is clipped to [0, 1]. Homographic augmentation warps an image, its keypoints and a valid-pixel
mask with a random homography from :func:`evio_lib.geometry.homography.sample_homography` (SuperPoint's
crop-centred construction: scaling, translation, in-plane rotation, perspective); the presets below copy the
SuperPoint configurations for synthetic shapes, real images (MagicPoint on COCO), warped pairs (SuperPoint on
COCO) and homographic adaptation.

Keypoints are (N, 2) float (x, y) pixels with pixel centres at integer coordinates; a label map is the (H, W)
float32 image with 1 at ``(round(y), round(x))`` of every keypoint and 0 elsewhere.

Reference: thesis §3.2.5; DeTone, Malisiewicz & Rabinovich, "SuperPoint: Self-Supervised Interest Point
Detection and Description", CVPRW 2018, §5-6.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any, NamedTuple

import cv2
import numpy as np

from evio_lib.geometry.homography import (
    crop_to_full_homography, sample_homography, valid_mask, warp_image, warp_points,
)

__all__ = [
    "PHOTOMETRIC_OPS",
    "PhotometricConfig",
    "PHOTOMETRIC_SYNTHETIC",
    "PHOTOMETRIC_REAL",
    "HomographicConfig",
    "HOMOGRAPHIC_SYNTHETIC",
    "HOMOGRAPHIC_REAL",
    "HOMOGRAPHIC_PAIR",
    "HOMOGRAPHIC_ADAPTATION",
    "HomographicSample",
    "Sample",
    "PairSample",
    "as_rng",
    "check_image",
    "check_keypoints",
    "additive_gaussian_noise",
    "additive_speckle_noise",
    "random_brightness",
    "random_contrast",
    "additive_shade",
    "motion_blur",
    "photometric_augment",
    "homographic_augment",
    "filter_keypoints",
    "keypoints_to_map",
    "map_to_keypoints",
    "to_torch_sample",
]

PHOTOMETRIC_OPS = ("gaussian_noise", "speckle_noise", "brightness", "contrast", "shade", "motion_blur")


# ---------------------------------------------------------------------------------------------- input checks
def as_rng(rng: np.random.Generator | int, name: str = "rng") -> np.random.Generator:
    """Return ``rng`` if it is a ``numpy.random.Generator``, else ``default_rng(rng)`` for a non-negative int seed.

    >>> float(as_rng(3).random()) == float(np.random.default_rng(3).random())
    True
    """
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, (bool, np.bool_)) or not isinstance(rng, Integral) or int(rng) < 0:
        raise ValueError(f"{name} must be a numpy.random.Generator or a non-negative int seed; got {rng!r}")
    return np.random.default_rng(int(rng))


def check_image(image: Any, name: str = "image") -> np.ndarray:
    """Return a grayscale image as float32 (H, W) in [0, 1] (uint8 is divided by 255); raise ValueError otherwise.

    The input is never modified (a float32 input is returned as a contiguous copy only when needed).

    >>> check_image(np.array([[0, 255]], np.uint8)).tolist()
    [[0.0, 1.0]]
    """
    array = np.asarray(image)
    if array.ndim != 2 or array.shape[0] < 1 or array.shape[1] < 1:
        raise ValueError(f"{name} must be a grayscale image of shape (H, W); got shape {array.shape}")
    if array.dtype == np.uint8:
        return array.astype(np.float32) / np.float32(255.0)
    if array.dtype not in (np.float32, np.float64):
        raise ValueError(f"{name} must have dtype float32 (values in [0, 1]) or uint8; got {array.dtype}")
    if not np.isfinite(array).all() or array.min() < 0.0 or array.max() > 1.0:
        raise ValueError(f"{name} must hold finite values in [0, 1]; got range [{np.nanmin(array):.3g}, "
                         f"{np.nanmax(array):.3g}]")
    return np.ascontiguousarray(array, dtype=np.float32)


def check_keypoints(keypoints: Any, name: str = "keypoints") -> np.ndarray:
    """Return keypoints as a float64 (N, 2) array of finite (x, y) pixels (None gives (0, 2)); else raise ValueError.

    >>> check_keypoints(None).shape
    (0, 2)
    """
    if keypoints is None:
        return np.zeros((0, 2))
    array = np.asarray(keypoints, dtype=np.float64)
    if array.size == 0:
        return np.zeros((0, 2))
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(f"{name} must have shape (N, 2) as (x, y) rows; got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must be finite; got NaN or inf entries")
    return array


def _range(value: Any, name: str, low: float, high: float = math.inf) -> tuple[float, float]:
    """Return a (lo, hi) pair with low <= lo <= hi <= high, or raise ValueError naming ``name``."""
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a (low, high) pair of numbers; got {value!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and low <= lo <= hi <= high):
        raise ValueError(f"{name} must satisfy {low:g} <= low <= high <= {high:g}; got {value!r}")
    return lo, hi


def _non_negative(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, Real) or not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be a finite number >= 0; got {value!r}")
    return float(value)


# ---------------------------------------------------------------------------------------------- photometric ops
def additive_gaussian_noise(image: np.ndarray, rng: np.random.Generator | int,
                            std_range: tuple[float, float] = (5 / 255, 95 / 255)) -> np.ndarray:
    """Return ``clip(I + n)`` with ``n ~ N(0, s^2)`` per pixel and ``s ~ U(std_range)`` (float32 (H, W)).

    Args:
        image: (H, W) float32 image in [0, 1] (or uint8).
        rng: Generator or seed.
        std_range: (low, high) of the noise standard deviation, intensity units.

    Reference: thesis §3.2.5 (noise); SuperPoint photometric augmentation.

    >>> out = additive_gaussian_noise(np.full((200, 200), 0.5, np.float32), 0, std_range=(0.1, 0.1))
    >>> round(float(out.std()), 2)
    0.1
    """
    img = check_image(image)
    lo, hi = _range(std_range, "std_range", 0.0)
    gen = as_rng(rng)
    std = gen.uniform(lo, hi)
    noise = gen.standard_normal(img.shape, dtype=np.float32) * np.float32(std)  # n ~ N(0, s^2)
    return np.clip(img + noise, 0.0, 1.0)


def additive_speckle_noise(image: np.ndarray, rng: np.random.Generator | int,
                           prob_range: tuple[float, float] = (0.0, 0.005)) -> np.ndarray:
    """Return the image with salt-and-pepper noise: ``u ~ U(0, 1)`` per pixel, ``u <= p`` -> 0, ``u >= 1 - p`` -> 1.

    ``p ~ U(prob_range)``, so about ``2 p`` of the pixels are replaced.

    Args:
        image: (H, W) float32 image in [0, 1] (or uint8).
        rng: Generator or seed.
        prob_range: (low, high) of p, within [0, 0.5].

    Reference: SuperPoint photometric augmentation (additive speckle noise).

    >>> out = additive_speckle_noise(np.full((100, 100), 0.5, np.float32), 0, prob_range=(0.05, 0.05))
    >>> round(float((out == 0).mean()), 2), round(float((out == 1).mean()), 2)
    (0.05, 0.05)
    """
    img = check_image(image)
    lo, hi = _range(prob_range, "prob_range", 0.0, 0.5)
    gen = as_rng(rng)
    prob = gen.uniform(lo, hi)
    u = gen.random(img.shape, dtype=np.float32)
    out = img.copy()
    out[u <= prob] = 0.0  # pepper
    out[u >= 1.0 - prob] = 1.0  # salt
    return out


def random_brightness(image: np.ndarray, rng: np.random.Generator | int, max_abs_change: float = 50 / 255
                      ) -> np.ndarray:
    """Return ``clip(I + b)`` with one ``b ~ U(-max_abs_change, max_abs_change)`` for the whole image.

    Args:
        image: (H, W) float32 image in [0, 1] (or uint8).
        rng: Generator or seed.
        max_abs_change: largest brightness change, intensity units (>= 0).

    Reference: thesis §3.2.5 (brightness); SuperPoint photometric augmentation.

    >>> img = np.full((2, 2), 0.5, np.float32)
    >>> bool(abs(float(random_brightness(img, 0, 0.1)[0, 0]) - 0.5) <= 0.1)
    True
    """
    img = check_image(image)
    change = _non_negative(max_abs_change, "max_abs_change")
    delta = as_rng(rng).uniform(-change, change)
    return np.clip(img + np.float32(delta), 0.0, 1.0)


def random_contrast(image: np.ndarray, rng: np.random.Generator | int,
                    strength_range: tuple[float, float] = (0.5, 1.5)) -> np.ndarray:
    """Return ``clip((I - mean(I)) c + mean(I))`` with ``c ~ U(strength_range)``.

    Args:
        image: (H, W) float32 image in [0, 1] (or uint8).
        rng: Generator or seed.
        strength_range: (low, high) of the contrast factor c (>= 0).

    Reference: thesis §3.2.5 (contrast); SuperPoint photometric augmentation.

    >>> img = np.array([[0.4, 0.6]], np.float32)
    >>> random_contrast(img, 0, strength_range=(2.0, 2.0)).astype(float).round(3).tolist()
    [[0.3, 0.7]]
    """
    img = check_image(image)
    lo, hi = _range(strength_range, "strength_range", 0.0)
    factor = np.float32(as_rng(rng).uniform(lo, hi))
    mean = np.float32(img.mean())
    return np.clip((img - mean) * factor + mean, 0.0, 1.0)  # (I - m) c + m


def _gaussian_blur_large(mask: np.ndarray, kernel_size: int) -> np.ndarray:
    """Return ``mask`` blurred by OpenCV's Gaussian of the given (odd) kernel size, computed on a decimated copy.

    The sigma is OpenCV's default for a kernel size k: ``0.3 ((k - 1) / 2 - 1) + 0.8``; a blur that wide is
    band-limited, so it is computed at 1/f of the resolution (f <= sigma / 4) and upsampled bilinearly.
    """
    sigma = 0.3 * ((kernel_size - 1) * 0.5 - 1.0) + 0.8
    height, width = mask.shape
    factor = max(1, min(int(sigma // 4), height // 4, width // 4))
    if factor > 1:
        small = cv2.resize(mask, (max(1, width // factor), max(1, height // factor)), interpolation=cv2.INTER_AREA)
        small = cv2.GaussianBlur(small, (0, 0), sigma / factor, borderType=cv2.BORDER_REFLECT_101)
        return cv2.resize(small, (width, height), interpolation=cv2.INTER_LINEAR)
    return cv2.GaussianBlur(mask, (0, 0), sigma, borderType=cv2.BORDER_REFLECT_101)


def additive_shade(image: np.ndarray, rng: np.random.Generator | int, n_ellipses: int = 20,
                   transparency_range: tuple[float, float] = (-0.5, 0.8),
                   kernel_size_range: tuple[int, int] = (250, 350)) -> np.ndarray:
    """Return ``clip(I (1 - t M))``: shading by a blurred mask M in [0, 1] of random ellipses, ``t ~ U(range)``.

    M: ``n_ellipses`` filled ellipses (semi-axes between min(H, W) / 20 and min(H, W) / 4, inside the image),
    Gaussian-blurred with a kernel size k drawn from ``kernel_size_range`` (pixels, made odd). ``t < 0`` brightens.

    Args:
        image: (H, W) float32 image in [0, 1] (or uint8).
        rng: Generator or seed.
        n_ellipses: number of ellipses (>= 0).
        transparency_range: (low, high) of t, within [-1, 1].
        kernel_size_range: (low, high) of the blur kernel size in pixels (>= 1).

    Reference: thesis §3.2.5 (shading); SuperPoint photometric augmentation (additive shade).

    >>> out = additive_shade(np.full((60, 80), 0.5, np.float32), 0, transparency_range=(0.5, 0.5))
    >>> bool(0.25 <= out.min() and out.max() <= 0.5)
    True
    """
    img = check_image(image)
    if isinstance(n_ellipses, bool) or not isinstance(n_ellipses, Integral) or n_ellipses < 0:
        raise ValueError(f"n_ellipses must be a non-negative int; got {n_ellipses!r}")
    t_lo, t_hi = _range(transparency_range, "transparency_range", -1.0, 1.0)
    k_lo, k_hi = _range(kernel_size_range, "kernel_size_range", 1.0)
    gen = as_rng(rng)
    height, width = img.shape
    min_dim = min(height, width) / 4.0
    mask = np.zeros((height, width), np.float32)
    for _ in range(int(n_ellipses)):  # a handful of shapes, not pixels
        ax = max(gen.random() * min_dim, min_dim / 5.0)
        ay = max(gen.random() * min_dim, min_dim / 5.0)
        radius = max(ax, ay)
        cx = gen.uniform(radius, max(radius, width - radius))
        cy = gen.uniform(radius, max(radius, height - radius))
        cv2.ellipse(mask, ((float(cx), float(cy)), (2.0 * ax, 2.0 * ay), float(gen.random() * 90.0)), 1.0, -1)
    transparency = gen.uniform(t_lo, t_hi)
    kernel_size = int(gen.integers(int(k_lo), int(k_hi) + 1)) | 1  # odd
    mask = np.clip(_gaussian_blur_large(mask, kernel_size), 0.0, 1.0)
    return np.clip(img * (np.float32(1.0) - np.float32(transparency) * mask), 0.0, 1.0)  # I (1 - t M)


def motion_blur(image: np.ndarray, rng: np.random.Generator | int, max_kernel_size: int = 10) -> np.ndarray:
    """Return the image convolved with a random linear motion kernel (odd size k <= max_kernel_size, k=1: unchanged).

    The kernel is a line through the kernel centre at a uniform random direction, weighted by a Gaussian of
    variance ``k^2 / 16`` around the centre and normalised to sum 1 (so a constant image stays constant).

    Args:
        image: (H, W) float32 image in [0, 1] (or uint8).
        rng: Generator or seed.
        max_kernel_size: largest kernel size in pixels (>= 1).

    Reference: thesis §3.2.5 (motion blur); SuperPoint photometric augmentation.

    >>> img = np.zeros((21, 21), np.float32); img[10, 10] = 1.0
    >>> out = motion_blur(img, 1, max_kernel_size=9)
    >>> round(float(out.sum()), 4)
    1.0
    """
    img = check_image(image)
    if isinstance(max_kernel_size, bool) or not isinstance(max_kernel_size, Integral) or max_kernel_size < 1:
        raise ValueError(f"max_kernel_size must be a positive int (pixels); got {max_kernel_size!r}")
    gen = as_rng(rng)
    size = 2 * int(gen.integers(0, (int(max_kernel_size) - 1) // 2 + 1)) + 1  # odd, 1 <= k <= max
    angle = gen.uniform(0.0, np.pi)
    if size == 1:
        return img.copy()
    centre = (size - 1) / 2.0
    kernel = np.zeros((size, size), np.float32)
    shift = 4  # sub-pixel end points (1/16 px)
    dx, dy = centre * math.cos(angle), centre * math.sin(angle)
    p0 = (int(round((centre - dx) * 2**shift)), int(round((centre - dy) * 2**shift)))
    p1 = (int(round((centre + dx) * 2**shift)), int(round((centre + dy) * 2**shift)))
    cv2.line(kernel, p0, p1, 1.0, 1, cv2.LINE_AA, shift)
    kernel = 0.5 * (kernel + kernel[::-1, ::-1])  # a line through the centre is point-symmetric; AA drawing is not
    grid = np.arange(size, dtype=np.float32) - np.float32(centre)
    kernel *= np.exp(-(grid[:, None] ** 2 + grid[None, :] ** 2) / np.float32(2.0 * size * size / 16.0))  # var k^2/16
    kernel /= kernel.sum()
    return np.clip(cv2.filter2D(img, -1, kernel, borderType=cv2.BORDER_REFLECT_101), 0.0, 1.0)


# ---------------------------------------------------------------------------------------------- photometric config
@dataclass(frozen=True)
class PhotometricConfig:
    """Parameter ranges of :func:`photometric_augment` (intensity units in [0, 1]; see the module table).

    Args:
        ops: names of the enabled operations, a subset of ``PHOTOMETRIC_OPS``.
        random_order: apply the enabled operations in a random order (else in ``ops`` order).
        probability: chance that each enabled operation is applied (1 = always, as SuperPoint does).
        gaussian_std_range, speckle_prob_range, brightness_max_abs_change, contrast_range,
        shade_n_ellipses, shade_transparency_range, shade_kernel_size_range, motion_blur_max_kernel_size:
            the parameters of the operations of the same names.
    """

    ops: tuple[str, ...] = PHOTOMETRIC_OPS
    random_order: bool = True
    probability: float = 1.0
    gaussian_std_range: tuple[float, float] = (0.0, 10 / 255)
    speckle_prob_range: tuple[float, float] = (0.0, 0.0035)
    brightness_max_abs_change: float = 50 / 255
    contrast_range: tuple[float, float] = (0.5, 1.5)
    shade_n_ellipses: int = 20
    shade_transparency_range: tuple[float, float] = (-0.5, 0.5)
    shade_kernel_size_range: tuple[int, int] = (100, 150)
    motion_blur_max_kernel_size: int = 3

    def __post_init__(self) -> None:
        ops = tuple(self.ops)
        unknown = [op for op in ops if op not in PHOTOMETRIC_OPS]
        if unknown:
            raise ValueError(f"ops must be names from {PHOTOMETRIC_OPS}; got unknown {unknown}")
        object.__setattr__(self, "ops", ops)
        if isinstance(self.probability, bool) or not isinstance(self.probability, Real) or \
                not 0.0 <= self.probability <= 1.0:
            raise ValueError(f"probability must be a number in [0, 1]; got {self.probability!r}")
        _range(self.gaussian_std_range, "gaussian_std_range", 0.0)
        _range(self.speckle_prob_range, "speckle_prob_range", 0.0, 0.5)
        _non_negative(self.brightness_max_abs_change, "brightness_max_abs_change")
        _range(self.contrast_range, "contrast_range", 0.0)
        _range(self.shade_transparency_range, "shade_transparency_range", -1.0, 1.0)
        _range(self.shade_kernel_size_range, "shade_kernel_size_range", 1.0)

    def replace(self, **changes: Any) -> "PhotometricConfig":
        """Return a copy with some fields changed (e.g. ``PHOTOMETRIC_REAL.replace(ops=("brightness",))``)."""
        return dataclasses.replace(self, **changes)


#: SuperPoint's defaults, used for MagicPoint on Synthetic Shapes (strong noise, wide shading, blur up to 10 px).
PHOTOMETRIC_SYNTHETIC = PhotometricConfig(
    gaussian_std_range=(5 / 255, 95 / 255),
    speckle_prob_range=(0.0, 0.005),
    brightness_max_abs_change=50 / 255,
    contrast_range=(0.5, 1.5),
    shade_transparency_range=(-0.5, 0.8),
    shade_kernel_size_range=(250, 350),
    motion_blur_max_kernel_size=10,
)
#: SuperPoint's configuration for real images (MagicPoint / SuperPoint on MS-COCO): milder noise and blur.
PHOTOMETRIC_REAL = PhotometricConfig()


def photometric_augment(image: np.ndarray, rng: np.random.Generator | int,
                        config: PhotometricConfig = PHOTOMETRIC_REAL) -> np.ndarray:
    """Return a photometrically augmented copy (float32 (H, W) in [0, 1]) of a grayscale image.

    Each operation of ``config.ops`` is applied with probability ``config.probability`` (default always), in a
    random order when ``config.random_order``; parameters are drawn from the config's ranges. Deterministic
    for a given seed.

    Args:
        image: (H, W) float32 image in [0, 1] (or uint8).
        rng: Generator or seed.
        config: a :class:`PhotometricConfig` (``PHOTOMETRIC_REAL`` or ``PHOTOMETRIC_SYNTHETIC``).

    Reference: thesis §3.2.5; SuperPoint photometric augmentation.

    >>> img = np.full((40, 40), 0.5, np.float32)
    >>> a, b = photometric_augment(img, 7), photometric_augment(img, 7)
    >>> a.dtype, bool(np.array_equal(a, b)), bool(np.array_equal(a, img))
    (dtype('float32'), True, False)
    """
    out = check_image(image).copy()
    if not isinstance(config, PhotometricConfig):
        raise ValueError(f"config must be a PhotometricConfig; got {type(config).__name__}")
    gen = as_rng(rng)
    order = list(config.ops)
    if config.random_order:
        order = [order[i] for i in gen.permutation(len(order))]
    for op in order:
        if config.probability < 1.0 and gen.random() >= config.probability:
            continue
        if op == "gaussian_noise":
            out = additive_gaussian_noise(out, gen, config.gaussian_std_range)
        elif op == "speckle_noise":
            out = additive_speckle_noise(out, gen, config.speckle_prob_range)
        elif op == "brightness":
            out = random_brightness(out, gen, config.brightness_max_abs_change)
        elif op == "contrast":
            out = random_contrast(out, gen, config.contrast_range)
        elif op == "shade":
            out = additive_shade(out, gen, config.shade_n_ellipses, config.shade_transparency_range,
                                 config.shade_kernel_size_range)
        else:  # motion_blur
            out = motion_blur(out, gen, config.motion_blur_max_kernel_size)
    return out.astype(np.float32, copy=False)


# ---------------------------------------------------------------------------------------------- homographic
@dataclass(frozen=True)
class HomographicConfig:
    """Parameters of random homographies (those of ``sample_homography``) plus the valid-border margin.

    Args:
        perspective, scaling, rotation, translation, n_scales, n_angles, scaling_amplitude,
        perspective_amplitude_x, perspective_amplitude_y, patch_ratio, max_angle, allow_artifacts,
        translation_overflow: passed to :func:`evio_lib.geometry.homography.sample_homography`.
        fill_view: stretch the central crop onto the whole view (``crop_to_full_homography``), so the random
            patch fills the warped image, zoomed about ``1 / patch_ratio`` (SuperPoint's convention, and that of the
            benchmark's viewpoint split); False keeps the patch on the central crop (no zoom, scale 1 +/- amplitude).
        valid_border_margin: the valid mask is eroded by this radius (pixels) so that labels and detections next
            to the warped border (where the image is filled with 0) are ignored.
    """

    perspective: bool = True
    scaling: bool = True
    rotation: bool = True
    translation: bool = True
    n_scales: int = 5
    n_angles: int = 25
    scaling_amplitude: float = 0.2
    perspective_amplitude_x: float = 0.2
    perspective_amplitude_y: float = 0.2
    patch_ratio: float = 0.85
    max_angle: float = 1.57
    allow_artifacts: bool = True
    translation_overflow: float = 0.0
    fill_view: bool = False
    valid_border_margin: int = 3

    def __post_init__(self) -> None:
        margin = self.valid_border_margin
        if isinstance(margin, bool) or not isinstance(margin, Integral) or margin < 0:
            raise ValueError(f"valid_border_margin must be a non-negative int (pixels); got {margin!r}")
        if not isinstance(self.fill_view, bool):
            raise ValueError(f"fill_view must be true or false; got {self.fill_view!r}")

    def homography_kwargs(self) -> dict[str, Any]:
        """Return the keyword arguments for ``sample_homography`` (every field but the margin and fill_view)."""
        kwargs = dataclasses.asdict(self)
        kwargs.pop("valid_border_margin")
        kwargs.pop("fill_view")
        return kwargs

    def sample(self, shape: tuple[int, int], rng: np.random.Generator | int) -> np.ndarray:
        """Return a random (3, 3) homography mapping pixels of an image of ``shape`` to its warped version.

        With ``allow_artifacts`` the perturbed patch can end up wider than the image, and then
        ``sample_homography`` finds an empty translation range and raises; such draws are rejected and redrawn
        (up to 100 times, from the same generator, so the result stays deterministic for a given seed).
        """
        gen = as_rng(rng)
        kwargs = self.homography_kwargs()
        error: ValueError | None = None
        shape = tuple(shape)[:2]
        fill = crop_to_full_homography(shape, self.patch_ratio) if self.fill_view else None
        for _ in range(100):
            try:
                H = sample_homography(shape, gen, **kwargs)
                return H if fill is None else (fill @ H) / (fill @ H)[2, 2]
            except ValueError as exc:  # empty translation range (or a bad parameter, raised below)
                error = exc
        assert error is not None
        raise error

    def replace(self, **changes: Any) -> "HomographicConfig":
        """Return a copy with some fields changed."""
        return dataclasses.replace(self, **changes)


#: SuperPoint's MagicPoint-on-shapes warp: wider crop (0.8), a little translation overflow, 2 px margin.
HOMOGRAPHIC_SYNTHETIC = HomographicConfig(patch_ratio=0.8, translation_overflow=0.05, valid_border_margin=2)
#: SuperPoint's warp for real images (MagicPoint on COCO): crop 0.85, rotations up to 90 deg, 3 px margin.
HOMOGRAPHIC_REAL = HomographicConfig()
#: SuperPoint's warped-pair homography for detector+descriptor training (same ranges as HOMOGRAPHIC_REAL).
HOMOGRAPHIC_PAIR = HomographicConfig()
#: SuperPoint's homographic-adaptation homographies (label export): same ranges, 3 px margin.
HOMOGRAPHIC_ADAPTATION = HomographicConfig()


class HomographicSample(NamedTuple):
    """Result of :func:`homographic_augment`."""

    image: np.ndarray  #: (H, W) float32 warped image (0 where the warp left the source image)
    keypoints: np.ndarray  #: (M, 2) float32 warped keypoints that land on valid pixels
    valid_mask: np.ndarray  #: (H, W) bool, pixels that saw the source image (eroded by the margin)
    homography: np.ndarray  #: (3, 3) float64 H, source pixels -> warped pixels


class Sample(NamedTuple):
    """One training sample as torch tensors (collates with ``torch.utils.data.default_collate``)."""

    image: Any  #: (1, H, W) float32 in [0, 1]
    keypoint_map: Any  #: (H, W) float32, 1 at keypoint pixels
    valid_mask: Any  #: (H, W) float32, 1 where the pixel saw the source image


class PairSample(NamedTuple):
    """An image and its warped copy for detector + descriptor training (thesis Eq. 8), as torch tensors."""

    image: Any  #: (1, H, W) float32
    keypoint_map: Any  #: (H, W) float32
    valid_mask: Any  #: (H, W) float32
    warped_image: Any  #: (1, H, W) float32
    warped_keypoint_map: Any  #: (H, W) float32
    warped_valid_mask: Any  #: (H, W) float32
    homography: Any  #: (3, 3) float32, pixels of ``image`` -> pixels of ``warped_image``


def filter_keypoints(keypoints: np.ndarray, shape: tuple[int, int], mask: np.ndarray | None = None) -> np.ndarray:
    """Return the boolean (N,) selection of keypoints whose rounded pixel lies in the image (and on ``mask``).

    Args:
        keypoints: (N, 2) (x, y) pixels.
        shape: (height, width) of the image.
        mask: optional (H, W) bool mask of allowed pixels.

    >>> filter_keypoints(np.array([[0.4, 0.0], [3.6, 1.0], [-0.6, 1.0]]), (2, 4)).tolist()
    [True, False, False]
    """
    pts = check_keypoints(keypoints)
    height, width = int(shape[0]), int(shape[1])
    cols, rows = np.rint(pts[:, 0]), np.rint(pts[:, 1])  # nearest pixel centre
    inside = (cols >= 0) & (cols <= width - 1) & (rows >= 0) & (rows <= height - 1)
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != (height, width):
            raise ValueError(f"mask must have shape {(height, width)}; got {m.shape}")
        keep = inside.copy()
        keep[inside] = m[rows[inside].astype(np.intp), cols[inside].astype(np.intp)].astype(bool)
        return keep
    return inside


def homographic_augment(image: np.ndarray, keypoints: np.ndarray | None, rng: np.random.Generator | int,
                        config: HomographicConfig = HOMOGRAPHIC_REAL, homography: np.ndarray | None = None
                        ) -> HomographicSample:
    """Return the image, its keypoints and its valid-pixel mask warped by a random homography (+ the homography).

    ``H = config.sample(shape, rng)`` (or ``homography`` if given) maps source pixels to warped pixels;
    ``I_w(u) = I(H^-1 u)`` (bilinear, 0 outside), keypoints ``x_w = H x`` (dropped unless their rounded pixel is
    valid), mask = ``valid_mask(shape, H, erode=config.valid_border_margin)``.

    Args:
        image: (H, W) float32 image in [0, 1] (or uint8).
        keypoints: (N, 2) (x, y) pixels in ``image``, or None.
        rng: Generator or seed.
        config: a :class:`HomographicConfig`.
        homography: optional fixed (3, 3) homography (then ``rng`` is unused).

    Reference: thesis §3.2.5; SuperPoint homographic augmentation.

    >>> img = np.zeros((60, 80), np.float32)
    >>> out = homographic_augment(img, [[40.0, 30.0]], 0, homography=np.diag([1.0, 1.0, 1.0]))
    >>> out.keypoints.tolist(), bool(out.valid_mask.all())
    ([[40.0, 30.0]], True)
    """
    img = check_image(image)
    pts = check_keypoints(keypoints)
    if not isinstance(config, HomographicConfig):
        raise ValueError(f"config must be a HomographicConfig; got {type(config).__name__}")
    H = config.sample(img.shape, rng) if homography is None else np.asarray(homography, dtype=np.float64)
    warped = warp_image(img, H)  # I_w(u) = I(H^-1 u)
    mask = valid_mask(img.shape, H, erode=int(config.valid_border_margin))
    moved = warp_points(H, pts) if len(pts) else pts  # x_w = H x
    keep = filter_keypoints(moved, img.shape, mask)
    return HomographicSample(np.clip(warped, 0.0, 1.0), moved[keep].astype(np.float32), mask, H)


# ---------------------------------------------------------------------------------------------- label maps
def keypoints_to_map(keypoints: np.ndarray | None, shape: tuple[int, int], valid: np.ndarray | None = None
                     ) -> np.ndarray:
    """Return the (H, W) float32 label map: 1 at ``(round(y), round(x))`` of each keypoint in the image, else 0.

    Args:
        keypoints: (N, 2) (x, y) pixels, or None.
        shape: (height, width) of the map.
        valid: optional (H, W) bool mask; keypoints on invalid pixels are dropped.

    >>> keypoints_to_map(np.array([[1.2, 0.4], [5.0, 5.0]]), (2, 3)).tolist()
    [[0.0, 1.0, 0.0], [0.0, 0.0, 0.0]]
    """
    height, width = int(shape[0]), int(shape[1])
    if height < 1 or width < 1:
        raise ValueError(f"shape must be (height, width) with positive sizes; got {shape!r}")
    pts = check_keypoints(keypoints)
    label = np.zeros((height, width), np.float32)
    keep = filter_keypoints(pts, (height, width), valid)
    label[np.rint(pts[keep, 1]).astype(np.intp), np.rint(pts[keep, 0]).astype(np.intp)] = 1.0
    return label


def map_to_keypoints(label_map: np.ndarray) -> np.ndarray:
    """Return the (N, 2) float32 (x, y) pixels where ``label_map > 0.5`` (row-major order).

    >>> map_to_keypoints(np.array([[0, 1, 0], [0, 0, 1]], np.float32)).tolist()
    [[1.0, 0.0], [2.0, 1.0]]
    """
    m = np.asarray(label_map)
    if m.ndim != 2:
        raise ValueError(f"label_map must have shape (H, W); got {m.shape}")
    rows, cols = np.nonzero(m > 0.5)
    return np.stack([cols, rows], axis=1).astype(np.float32)


def to_torch_sample(image: np.ndarray, keypoints: np.ndarray | None, valid: np.ndarray | None = None) -> Sample:
    """Return a :class:`Sample` of torch tensors: image (1, H, W), keypoint map (H, W), valid mask (H, W), float32.

    Args:
        image: (H, W) float32 image in [0, 1].
        keypoints: (N, 2) (x, y) pixels, or None (empty map).
        valid: optional (H, W) bool mask (default all valid); keypoints on invalid pixels are dropped.
    """
    import torch

    img = check_image(image)
    mask = np.ones(img.shape, bool) if valid is None else np.asarray(valid, dtype=bool)
    label = keypoints_to_map(keypoints, img.shape, mask)
    return Sample(torch.from_numpy(img[None].copy()), torch.from_numpy(label),
                  torch.from_numpy(mask.astype(np.float32)))
