"""The detector/descriptor benchmark of the thesis (§3.2.6, Tables 2-5): data sets, the run, and the tables.

Data sets (lists of ``ImagePair``, each image 1, image 2 and the homography H of image 1 -> image 2):

* ``heldout_pairs``: an HPatches-style benchmark built from held-out images (the TEST split of
  ``evio_lib.features.training.datasets.image_pool``, never trained on): a "viewpoint" split whose second images are
  warped by seeded random homographies (``sample_homography``) and an "illumination" split whose second images differ only
  photometrically (identity H). Everything follows from one seed.
* ``event_frame_pairs``: event frames and warped copies with small random rotations and translations, like the
  thesis's aerial event-frame set (§3.2.3); split "event_frames".
* ``evio_lib.features.evaluation.hpatches.iter_hpatches_pairs``: the real HPatches folder layout, for anyone who has it.
* ``photo_pairs``: ``heldout_pairs`` of the held-out natural photographs of a photo
  folder (``--dataset photos``), cropped to 3:4 and resized to 480 x 640.

``run_benchmark(detector, pairs, settings)`` runs one detector over the pairs with the thesis's settings
(repeatability at 240 x 320 with the best 300 points and NMS 4; homography estimation at 480 x 640 with the best 1000
points and NMS 8; eps = 1, 3, 5) and returns repeatability, homography correctness, matching score, mAP and timing per
split; ``format_table(rows, kind)`` prints Markdown tables shaped like Tables 2-5 (one row per detector), and
``main_benchmark`` is the command ``python -m evio_lib features-benchmark``.

Reference: thesis §3.2.3, §3.2.6 and §4.3 (Tables 2-5); DeTone et al., "SuperPoint", CVPRW 2018, §7.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from numbers import Integral, Real
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from evio_lib.features.evaluation.evaluate import (
    corner_error,
    diagnose_matches,
    estimate_homography,
    match_descriptors,
    matching_score,
    mean_average_precision,
    repeatability,
)
from evio_lib.features.evaluation.hpatches import (
    N_IMAGES_PER_SCENE,
    SPLIT_PREFIXES,
    ImagePair,
    hpatches_scenes,
    iter_hpatches_pairs,
    resize_image,
    resize_pair,
)
from evio_lib.geometry.homography import crop_to_full_homography, sample_homography, warp_image
from evio_lib.features.evaluation.options import add_benchmark_arguments  # the options alone

__all__ = [
    "BenchmarkSettings",
    "VIEWPOINT_HOMOGRAPHY",
    "EVENT_FRAME_HOMOGRAPHY",
    "DISPLAY_NAMES",
    "illumination_change",
    "viewpoint_pairs",
    "illumination_pairs",
    "heldout_pairs",
    "photo_pairs",
    "event_frame_pairs",
    "run_benchmark",
    "diagnose_pairs",
    "measure_speed",
    "format_table",
    "add_benchmark_arguments",
    "main_benchmark",
]

# Random homographies of the viewpoint split (HPatches-like: perspective and scale, some rotation; the perspective
# amplitude is capped at the crop margin (1 - patch_ratio) / 2); the patch stays inside image 1 and is stretched to
# the whole of image 2 (see viewpoint_pairs). Tuned so that SIFT scores about as in the thesis's HPatches viewpoint
# row (Table 4: 0.46 / 0.77 / 0.83): on 32 pairs of skimage.data images it gets 0.44 / 0.75 / 0.84.
VIEWPOINT_HOMOGRAPHY: dict[str, Any] = dict(
    perspective=True, scaling=True, rotation=True, translation=True, patch_ratio=0.65,
    perspective_amplitude_x=0.3, perspective_amplitude_y=0.3, scaling_amplitude=0.2, max_angle=np.pi / 4,
    n_scales=5, n_angles=25, allow_artifacts=False,
)
# The thesis's aerial set: "small changes in rotation and translation" (§3.2.3).
EVENT_FRAME_HOMOGRAPHY: dict[str, Any] = dict(
    perspective=False, scaling=False, rotation=True, translation=True, patch_ratio=0.9,
    max_angle=np.pi / 18, n_angles=25, allow_artifacts=False,
)
# Table row names as the thesis writes them.
DISPLAY_NAMES = {
    "harris": "Harris", "shi_tomasi": "Shi-Tomasi", "fast": "FAST", "sift": "SIFT", "orb": "ORB",
    "fast_freak": "FAST-FREAK", "superpoint": "SuperPoint",
}
SPLIT_ORDER = ("viewpoint", "illumination", "event_frames")  # column order of the tables
SPLIT_TITLES = {"viewpoint": "Viewpoint", "illumination": "Illumination", "event_frames": "Event frames"}
TABLE_KINDS = ("repeatability", "homography", "matching_score", "mAP", "speed")
_SPLIT_SEEDS = {"viewpoint": 1, "illumination": 2, "event_frames": 3}  # keeps the splits' random streams apart


# ---------------------------------------------------------------------------------------------- settings
@dataclass(frozen=True)
class BenchmarkSettings:
    """Sizes, point budgets, NMS radii and thresholds of the benchmark (defaults: the thesis's HPatches settings).

    Attributes:
        repeatability_size: (height, width) both images are resized to for repeatability (None: keep).
        repeatability_keypoints: best N points kept per image for repeatability.
        repeatability_nms: NMS radius (pixels) of the repeatability detections.
        homography_size: (height, width) for homography estimation, matching score and mAP (None: keep).
        homography_keypoints: best N points kept per image for homography estimation.
        homography_nms: NMS radius (pixels) of the homography detections.
        eps: pixel thresholds of every metric.
        resize_mode: "crop" (keep the aspect ratio, cut the centre) or "stretch".
        mutual: mutual nearest-neighbour matching before RANSAC.
        ransac_threshold: RANSAC reprojection threshold (pixels; OpenCV's default 3).
        tasks: which of "repeatability" and "homography" to run.

    Reference: thesis §3.2.6 (last paragraph).
    """

    repeatability_size: tuple[int, int] | None = (240, 320)
    repeatability_keypoints: int = 300
    repeatability_nms: int = 4
    homography_size: tuple[int, int] | None = (480, 640)
    homography_keypoints: int = 1000
    homography_nms: int = 8
    eps: tuple[float, ...] = (1.0, 3.0, 5.0)
    resize_mode: str = "crop"
    mutual: bool = True
    ransac_threshold: float = 3.0
    tasks: tuple[str, ...] = ("repeatability", "homography")

    def __post_init__(self) -> None:
        for name in ("repeatability_size", "homography_size"):
            size = getattr(self, name)
            if size is not None:
                if len(tuple(size)) != 2 or not all(isinstance(d, Integral) and not isinstance(d, bool) and d > 0
                                                    for d in size):
                    raise ValueError(f"{name} must be (height, width) of positive integers or None; got {size!r}")
                object.__setattr__(self, name, (int(size[0]), int(size[1])))
        for name in ("repeatability_keypoints", "homography_keypoints"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, Integral) or value < 1:
                raise ValueError(f"{name} must be a positive integer; got {value!r}")
        for name in ("repeatability_nms", "homography_nms"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, Integral) or value < 0:
                raise ValueError(f"{name} must be an integer >= 0 (pixels); got {value!r}")
        eps = tuple(float(e) for e in np.atleast_1d(np.asarray(self.eps, dtype=np.float64)))
        if not eps or not all(math.isfinite(e) and e >= 0 for e in eps):
            raise ValueError(f"eps must be a non-empty sequence of pixel thresholds >= 0; got {self.eps!r}")
        object.__setattr__(self, "eps", eps)
        if self.resize_mode not in ("crop", "stretch"):
            raise ValueError(f"resize_mode must be 'crop' or 'stretch'; got {self.resize_mode!r}")
        tasks = (self.tasks,) if isinstance(self.tasks, str) else tuple(self.tasks)
        if not tasks or any(t not in ("repeatability", "homography") for t in tasks):
            raise ValueError(f"tasks must name 'repeatability' and/or 'homography'; got {self.tasks!r}")
        object.__setattr__(self, "tasks", tasks)

    @classmethod
    def thesis_hpatches(cls) -> "BenchmarkSettings":
        """Return the thesis's HPatches settings (repeatability 240x320, 300 points, NMS 4; homography 480x640,
        1000 points, NMS 8)."""
        return cls()

    @classmethod
    def thesis_event_frames(cls) -> "BenchmarkSettings":
        """Return the thesis's aerial event-frame settings (repeatability 240x320, 100 points; homography 240x320,
        1000 points; NMS 4 throughout)."""
        return cls(repeatability_keypoints=100, homography_size=(240, 320), homography_nms=4)


# ---------------------------------------------------------------------------------------------- data sets
def _check_images(images: Sequence[np.ndarray], name: str) -> list[NDArray[np.float32]]:
    """Return the images as float32 (H, W) in [0, 1] (uint8 divided by 255), or raise ValueError naming ``name``."""
    if isinstance(images, np.ndarray) and images.ndim == 2:
        raise ValueError(f"{name} must be a sequence of (H, W) images (or an (N, H, W) array); got one (H, W) image")
    out = []
    for i, image in enumerate(images):
        img = np.asarray(image)
        if img.ndim != 2 or min(img.shape, default=0) < 8:
            raise ValueError(f"{name}[{i}] must be a grayscale (H, W) image of at least 8 x 8 pixels; got {img.shape}")
        if img.dtype == np.uint8:
            img = img.astype(np.float32) / np.float32(255.0)
        elif not np.issubdtype(img.dtype, np.floating) or not np.isfinite(img).all() or img.min() < 0 or img.max() > 1:
            raise ValueError(f"{name}[{i}] must be uint8 or float in [0, 1]; got dtype {img.dtype}")
        out.append(img.astype(np.float32))
    if not out:
        raise ValueError(f"{name} must hold at least one image; got none")
    return out


def _check_count(value: object, name: str) -> int:
    """Return a positive int, or raise ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, Integral) or value < 1:
        raise ValueError(f"{name} must be a positive integer; got {value!r}")
    return int(value)


def _pair_rng(seed: int, split: str, image_index: int, pair_index: int) -> np.random.Generator:
    """Return the generator of one pair: independent of how many images or pairs the data set has."""
    return np.random.default_rng([int(seed), _SPLIT_SEEDS.get(split, 0), image_index, pair_index])


def illumination_change(image: np.ndarray, rng: np.random.Generator, strength: float = 1.0) -> NDArray[np.float32]:
    """Return a photometrically changed copy of ``image`` (float32 in [0, 1]); the geometry is untouched.

    Models what changes between HPatches' illumination images (other light sources, directions and exposures),
    in five steps, each scaled by ``strength``:
      1. tone curve: ``I^gamma`` with ``log(gamma) ~ U(-0.7, 0.7)`` (gamma in about [0.5, 2]);
      2. shading: times ``s(x, y) = 1 + a (f(x, y) - mean f)``, f a linear ramp in a random direction plus a broad
         Gaussian light spot at a random place, normalised to [0, 1], ``a ~ U(0.4, 1.0)``;
      3. exposure: times ``g``, ``log(g) ~ U(log 0.2, log 1.5)`` (dark shots lose contrast, bright ones saturate);
      4. sensor noise: Gaussian, std ``U(0.005, 0.02)``;
      5. 8-bit quantisation and clipping to [0, 1] (dark images keep few grey levels, as a real camera's).

    Args:
        image: (H, W) grayscale image, float32 in [0, 1] or uint8.
        rng: seeded numpy Generator.
        strength: scale of every change in [0, 2] (0 returns the image, quantised to 8 bits).

    Reference: thesis §3.2.3 (HPatches illumination scenes), §3.2.5 (photometric augmentation).

    >>> img = np.tile(np.linspace(0, 1, 32, dtype=np.float32), (24, 1))
    >>> out = illumination_change(img, np.random.default_rng(0))
    >>> out.shape, out.dtype, bool(0 <= out.min() and out.max() <= 1), bool(np.abs(out - img).mean() > 0.02)
    ((24, 32), dtype('float32'), True, True)
    """
    img = _check_images([image], "image")[0]
    if isinstance(strength, bool) or not isinstance(strength, Real) or not (0.0 <= strength <= 2.0):
        raise ValueError(f"strength must be a number in [0, 2]; got {strength!r}")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator; got {type(rng).__name__}")
    height, width = img.shape
    gamma = math.exp(rng.uniform(-0.7, 0.7) * strength)
    out = img.astype(np.float64) ** gamma  # I^gamma
    ys, xs = np.mgrid[0:height, 0:width] / float(max(height, width))
    angle = rng.uniform(0.0, 2.0 * np.pi)
    ramp = np.cos(angle) * xs + np.sin(angle) * ys
    centre = rng.uniform([0.0, 0.0], [width, height]) / float(max(height, width))
    sigma = rng.uniform(0.2, 0.5)
    spot = np.exp(-((xs - centre[0]) ** 2 + (ys - centre[1]) ** 2) / (2.0 * sigma**2))
    shading = ramp + rng.uniform(0.5, 1.5) * spot
    shading = (shading - shading.min()) / max(float(np.ptp(shading)), 1e-12)
    amplitude = rng.uniform(0.4, 1.0) * strength
    out = out * np.maximum(1.0 + amplitude * (shading - shading.mean()), 0.05)  # s(x, y) = 1 + a (f - mean f)
    out = out * math.exp(rng.uniform(math.log(0.2), math.log(1.5)) * strength)  # exposure g
    out = out + rng.normal(0.0, rng.uniform(0.005, 0.02) * strength, out.shape)  # sensor noise
    return (np.round(np.clip(out, 0.0, 1.0) * 255.0) / 255.0).astype(np.float32)  # 8-bit camera


def _warped_pairs(
    images: list[NDArray[np.float32]], seed: int, pairs_per_image: int, split: str, noise_std: float,
    homography_options: dict[str, Any], prefix: str,
) -> list[ImagePair]:
    """Return pairs (image, image warped by a random homography filling the whole view) for every image."""
    patch_ratio = float(homography_options.get("patch_ratio", 0.5))
    fill = not homography_options.get("allow_artifacts", False)
    pairs = []
    for i, image in enumerate(images):
        A = crop_to_full_homography(image.shape, patch_ratio) if fill else np.eye(3)
        for k in range(pairs_per_image):
            rng = _pair_rng(seed, split, i, k)
            H = A @ sample_homography(image.shape, rng, **homography_options)  # original -> patch -> whole view
            H = H / H[2, 2]
            warped = warp_image(image, H)
            if noise_std > 0:
                warped = np.clip(warped + rng.normal(0.0, noise_std, warped.shape), 0.0, 1.0).astype(np.float32)
            pairs.append(ImagePair(image, warped, H, split, f"{prefix}{i:04d}/1-{k + 2}"))
    return pairs


def viewpoint_pairs(
    images: Sequence[np.ndarray],
    seed: int,
    pairs_per_image: int = 5,
    *,
    noise_std: float = 0.01,
    **homography_options: Any,
) -> list[ImagePair]:
    """Return the viewpoint split: each image paired with ``pairs_per_image`` copies warped by random homographies.

    ``sample_homography(image.shape, rng, **VIEWPOINT_HOMOGRAPHY)`` (overridable by keyword) maps a random patch of
    image 1 onto the central crop of side ``patch_ratio``; unless ``allow_artifacts``, that crop is then stretched
    to the whole view (``H = A H_sample``, A the crop-to-image scaling), so image 2 ``= warp_image(image 1, H)`` is
    filled everywhere, like a real second photograph (no black border whose edges would fake corners), zoomed
    about ``1 / patch_ratio``. Gaussian noise of std ``noise_std`` is added to image 2. The generator of pair k of
    image i is seeded by (seed, split, i, k), so a pair does not depend on how many images are used.

    Args:
        images: grayscale (H, W) images, float32 in [0, 1] or uint8 (held out from training).
        seed: the data set's seed.
        pairs_per_image: warped copies per image (HPatches has 5).
        noise_std: std of the sensor noise added to image 2.
        **homography_options: overrides of ``VIEWPOINT_HOMOGRAPHY`` (arguments of ``sample_homography``).

    Reference: thesis §3.2.3 (HPatches viewpoint scenes); SuperPoint §7 (synthetic warps).
    """
    imgs = _check_images(images, "images")
    count = _check_count(pairs_per_image, "pairs_per_image")
    if isinstance(noise_std, bool) or not isinstance(noise_std, Real) or not 0.0 <= noise_std <= 0.5:
        raise ValueError(f"noise_std must be a number in [0, 0.5]; got {noise_std!r}")
    options = {**VIEWPOINT_HOMOGRAPHY, **homography_options}
    return _warped_pairs(imgs, int(seed), count, "viewpoint", float(noise_std), options, "viewpoint/")


def illumination_pairs(
    images: Sequence[np.ndarray], seed: int, pairs_per_image: int = 5, *, strength: float = 1.0
) -> list[ImagePair]:
    """Return the illumination split: each image paired with ``pairs_per_image`` photometric changes of itself (H = I).

    Image 2 is ``illumination_change(image 1, rng, strength)`` with the generator seeded by (seed, split, i, k).

    Args:
        images: grayscale (H, W) images, float32 in [0, 1] or uint8 (held out from training).
        seed: the data set's seed.
        pairs_per_image: changed copies per image (HPatches has 5).
        strength: scale of the photometric change (see ``illumination_change``).

    Reference: thesis §3.2.3 (HPatches illumination scenes).
    """
    imgs = _check_images(images, "images")
    count = _check_count(pairs_per_image, "pairs_per_image")
    pairs = []
    for i, image in enumerate(imgs):
        for k in range(count):
            changed = illumination_change(image, _pair_rng(int(seed), "illumination", i, k), strength)
            pairs.append(ImagePair(image, changed, np.eye(3), "illumination", f"illumination/{i:04d}/1-{k + 2}"))
    return pairs


def heldout_pairs(
    seed: int = 0,
    *,
    images: Sequence[np.ndarray] | None = None,
    n_images: int | None = None,
    pairs_per_image: int = 5,
    splits: Sequence[str] = ("viewpoint", "illumination"),
    size: tuple[int, int] = (480, 640),
    exclude_sources: Sequence[str] = ("texture:stripes",),
    pool: str = "test",
) -> list[ImagePair]:
    """Return the built-in HPatches-style benchmark: viewpoint and illumination pairs of held-out images.

    The images are ``evio_lib.features.training.datasets.image_pool("test", seed, size, n_images)`` (the held-out TEST
    split, never used in training; 60 images by default, 58 after leaving out the stripe textures, so 580 pairs with
    5 per image and split, as many as HPatches has) unless ``images`` is given, of which ``n_images`` keeps the
    first n. The viewpoint split comes first.

    Args:
        seed: seed of the image pool and of every random change.
        images: use these images instead of the test pool (e.g. in tests).
        n_images: number of images (default: the pool's default size, or all given images).
        pairs_per_image: pairs per image and split (HPatches: 5).
        splits: any of "viewpoint" and "illumination".
        size: (height, width) of the pool's images; the default is the largest evaluation size (homography,
            480 x 640), so no task works on upsampled images.
        exclude_sources: pool images whose source name starts with one of these are left out (default: stripe
            textures, whose homography is ill-posed by the aperture problem: any shift along the stripes fits).
        pool: the image pool's split: "test" (the benchmark) or "val" (the validation images, never trained on
            either: the same benchmark on them chooses checkpoints without looking at the test split).

    Reference: thesis §3.2.3; Balntas et al., "HPatches", CVPR 2017.
    """
    wanted = (splits,) if isinstance(splits, str) else tuple(splits)
    if not wanted or any(s not in ("viewpoint", "illumination") for s in wanted):
        raise ValueError(f"splits must name 'viewpoint' and/or 'illumination'; got {splits!r}")
    if n_images is not None:
        n_images = _check_count(n_images, "n_images")
    if pool not in ("test", "val"):
        raise ValueError(f"pool must be 'test' or 'val'; got {pool!r}")
    if images is None:
        from evio_lib.features.training.datasets import image_pool  # the held-out pool (TEST split, or VAL)

        images, sources = image_pool(pool, int(seed), size=tuple(size), n_images=n_images, return_sources=True)
        excluded = tuple(exclude_sources)
        images = [img for img, source in zip(images, sources) if not (excluded and source.startswith(excluded))]
    imgs = _check_images(images, "images")[:n_images]
    pairs: list[ImagePair] = []
    if "viewpoint" in wanted:
        pairs += viewpoint_pairs(imgs, seed, pairs_per_image)
    if "illumination" in wanted:
        pairs += illumination_pairs(imgs, seed, pairs_per_image)
    return pairs



def photo_pairs(
    folder: str | Path,
    split: str = "test",
    seed: int = 0,
    *,
    n_images: int | None = None,
    pairs_per_image: int = 5,
    splits: Sequence[str] = ("viewpoint", "illumination"),
    size: tuple[int, int] = (480, 640),
) -> list:
    """Return viewpoint and illumination pairs (``ImagePair``) of the held-out photographs of ``folder``.

    ``heldout_pairs(seed, images=photo_images(folder, split, n_images=n_images, size=size),
    pairs_per_image=pairs_per_image, splits=splits)``: pair k of photograph i has the generator seeded by
    (seed, benchmark split, i, k), as in the built-in benchmark; the viewpoint split comes first.
    """
    from evio_lib.features.evaluation.photos import photo_images

    images = photo_images(folder, split, n_images=n_images, size=size)
    return heldout_pairs(seed, images=images, pairs_per_image=pairs_per_image, splits=splits)

def event_frame_pairs(
    frames: Sequence[np.ndarray], seed: int, pairs_per_frame: int = 1, **homography_options: Any
) -> list[ImagePair]:
    """Return the event-frame split: each event frame paired with warped copies (small rotation and translation).

    Like the thesis's aerial set (a base image and a copy warped by a random homography "limited to small changes in
    rotation and translation"): ``H = sample_homography(frame.shape, rng, **EVENT_FRAME_HOMOGRAPHY)`` (rotation up to
    10 degrees, a 0.9 crop moved within the frame; overridable by keyword). Frames come from the event reconstruction
    (``evio_lib.events``) or any (N, H, W) stack; split name "event_frames". Use with
    ``BenchmarkSettings.thesis_event_frames()``.

    Args:
        frames: event frames (H, W), float32 in [0, 1] or uint8, or an (N, H, W) array.
        seed: the data set's seed.
        pairs_per_frame: warped copies per frame (the thesis: 1).
        **homography_options: overrides of ``EVENT_FRAME_HOMOGRAPHY``.

    Reference: thesis §3.2.3 (UAV data set), Tables 3 and 5.
    """
    imgs = _check_images(frames, "frames")
    count = _check_count(pairs_per_frame, "pairs_per_frame")
    options = {**EVENT_FRAME_HOMOGRAPHY, **homography_options}
    return _warped_pairs(imgs, int(seed), count, "event_frames", 0.0, options, "event_frames/")


# ---------------------------------------------------------------------------------------------- detectors
DetectorArg = Any  # a name, a FeatureDetector, or a factory(max_keypoints=, nms_radius=) -> FeatureDetector


def _detector_name(detector: DetectorArg) -> str:
    """Return the name under which results of ``detector`` are reported."""
    if isinstance(detector, str):
        return detector
    return str(getattr(detector, "name", getattr(detector, "__name__", type(detector).__name__)))


def _make_detector(detector: DetectorArg, max_keypoints: int, nms_radius: int, options: dict[str, Any]) -> Any:
    """Return a detector configured for one task: by name, from a factory, or the given instance as it is."""
    if isinstance(detector, str):
        from evio_lib.features.base import create_detector

        return create_detector(detector, max_keypoints=max_keypoints, nms_radius=nms_radius, **options)
    if hasattr(detector, "detect_and_describe"):
        return detector
    if callable(detector):
        return detector(max_keypoints=max_keypoints, nms_radius=nms_radius, **options)
    raise ValueError(
        "detector must be a name (create_detector), a FeatureDetector or a factory(max_keypoints=, nms_radius=); "
        f"got {type(detector).__name__}"
    )


@dataclass
class _Detections:
    """Keypoints (N, 2) float64, scores (N,), descriptors (N, D) and the binary flag of one image, best first."""

    keypoints: np.ndarray
    scores: np.ndarray
    descriptors: np.ndarray
    binary: bool


@dataclass
class _Timer:
    """Accumulated detect_and_describe time of one task."""

    seconds: float = 0.0
    images: int = 0
    shapes: set = field(default_factory=set)


def _detect(detector: Any, image: np.ndarray, max_keypoints: int, timer: _Timer) -> _Detections:
    """Return the best ``max_keypoints`` detections of ``image`` (timing the call)."""
    start = time.perf_counter()
    features = detector.detect_and_describe(image)
    timer.seconds += time.perf_counter() - start
    timer.images += 1
    timer.shapes.add(image.shape[:2])
    keypoints = np.asarray(features.keypoints, dtype=np.float64).reshape(-1, 2)
    scores = np.asarray(features.scores, dtype=np.float64).reshape(-1)
    descriptors = np.asarray(features.descriptors)
    order = np.argsort(-scores, kind="stable")[:max_keypoints]  # the best N (detectors already sort; enforce it)
    binary = bool(getattr(features, "binary", False))
    return _Detections(keypoints[order], scores[order], descriptors[order], binary)


# ---------------------------------------------------------------------------------------------- the run
def run_benchmark(
    detector: DetectorArg,
    pairs: Iterable[ImagePair],
    settings: BenchmarkSettings | None = None,
    *,
    name: str | None = None,
    detector_options: dict[str, Any] | None = None,
    progress: bool = False,
) -> dict[str, Any]:
    """Return the benchmark results of one detector on image pairs: metrics per split and eps, timing, per-pair values.

    For every pair, resized as the settings say (H updated):
      * repeatability task (``settings.repeatability_size``, best ``repeatability_keypoints`` points, NMS
        ``repeatability_nms``): ``repeatability`` (Eqs. 15-16) with the best points in the shared view;
      * homography task (``homography_size``, ``homography_keypoints``, ``homography_nms``): mutual nearest-neighbour
        descriptor matches, ``cv2.findHomography`` with RANSAC, correctness = mean corner error <= eps (Eq. 17);
        on the same detections the matching score and the NN mAP.
    Values are means over the pairs of each split (NaN-valued pairs, with no point in the shared view, are left out
    of repeatability, matching score and mAP; a failed homography counts as incorrect). Timing is the mean time of
    ``detect_and_describe`` per image after one untimed warm-up call per task.

    Args:
        detector: a detector name (``create_detector(name, max_keypoints=..., nms_radius=...)`` per task), a factory
            called the same way, or a FeatureDetector instance (used as it is for both tasks; its NMS radius is
            its own, the point budget is enforced by keeping the best-scoring points).
        pairs: ``ImagePair`` objects (a list, or an iterator such as ``iter_hpatches_pairs``).
        settings: ``BenchmarkSettings`` (default: the thesis's HPatches settings).
        name: the row name in the tables (default: the detector's name).
        detector_options: extra keyword options for ``create_detector`` / the factory (e.g. ``weights=``).
        progress: show a tqdm progress bar.

    Returns:
        ``{"detector", "settings", "n_pairs": {split: n}, "repeatability" | "homography" | "matching_score" |
        "mAP": {split: {eps: value}}, "keypoints": {task: mean per image}, "matches": {split: mean mutual matches},
        "speed": {"HxW": {"ms": ..., "fps": ...}}, "per_pair": [...]}``.

    Reference: thesis §3.2.6; SuperPoint §7.
    """
    settings = BenchmarkSettings() if settings is None else settings
    if not isinstance(settings, BenchmarkSettings):
        raise ValueError(f"settings must be a BenchmarkSettings; got {type(settings).__name__}")
    options = dict(detector_options or {})
    row_name = name or _detector_name(detector)
    eps = np.asarray(settings.eps)
    do_rep = "repeatability" in settings.tasks
    do_hom = "homography" in settings.tasks
    det_rep = det_hom = None
    if do_rep:
        det_rep = _make_detector(detector, settings.repeatability_keypoints, settings.repeatability_nms, options)
    if do_hom:
        det_hom = _make_detector(detector, settings.homography_keypoints, settings.homography_nms, options)
    timers = {"repeatability": _Timer(), "homography": _Timer()}
    counts = {"repeatability": [], "homography": []}  # keypoints per image
    per_pair: list[dict[str, Any]] = []
    warmed: set[str] = set()

    iterator = pairs
    if progress:
        from tqdm.auto import tqdm

        iterator = tqdm(pairs, desc=f"benchmark {row_name}", unit="pair")
    for pair in iterator:
        if not isinstance(pair, ImagePair):
            raise ValueError(f"pairs must hold ImagePair objects; got {type(pair).__name__}")
        record: dict[str, Any] = {"name": pair.name, "split": pair.split}
        if do_rep:
            small = resize_pair(pair, settings.repeatability_size, settings.resize_mode)
            if "repeatability" not in warmed:
                det_rep.detect_and_describe(small.image1)  # untimed warm-up (lazy loading, JIT)
                warmed.add("repeatability")
            k = settings.repeatability_keypoints
            f1 = _detect(det_rep, small.image1, k, timers["repeatability"])
            f2 = _detect(det_rep, small.image2, k, timers["repeatability"])
            counts["repeatability"] += [len(f1.keypoints), len(f2.keypoints)]
            record["repeatability"] = repeatability(
                f1.keypoints, f2.keypoints, small.H, small.image1.shape, small.image2.shape, eps,
                scores1=f1.scores, scores2=f2.scores, keep_k=k,
            )
        if do_hom:
            large = resize_pair(pair, settings.homography_size, settings.resize_mode)
            if "homography" not in warmed:
                det_hom.detect_and_describe(large.image1)
                warmed.add("homography")
            k = settings.homography_keypoints
            g1 = _detect(det_hom, large.image1, k, timers["homography"])
            g2 = _detect(det_hom, large.image2, k, timers["homography"])
            counts["homography"] += [len(g1.keypoints), len(g2.keypoints)]
            binary = g1.binary
            if len(g1.keypoints) and len(g2.keypoints):
                matches = match_descriptors(g1.descriptors, g2.descriptors, binary=binary, mutual=settings.mutual)
            else:
                matches = np.zeros((0, 2), np.int64)
            H_est, inliers = estimate_homography(
                g1.keypoints, g2.keypoints, matches, ransac_threshold=settings.ransac_threshold
            )
            error = corner_error(H_est, large.H, large.image1.shape)
            shape1, shape2 = large.image1.shape, large.image2.shape
            record.update(
                corner_error=error,
                homography=(error <= eps).astype(float),
                n_matches=len(matches),
                n_inliers=int(inliers.sum()),
                H_est=H_est,
            )
            if len(g1.keypoints) and len(g2.keypoints):
                record["matching_score"] = matching_score(g1.keypoints, g2.keypoints, g1.descriptors, g2.descriptors,
                                                          large.H, shape1, shape2, eps, binary)
                record["mAP"] = mean_average_precision(g1.keypoints, g2.keypoints, g1.descriptors, g2.descriptors,
                                                       large.H, shape1, shape2, eps, binary)
            else:
                record["matching_score"] = np.zeros(len(eps))
                record["mAP"] = np.full(len(eps), np.nan)
        per_pair.append(record)

    splits = sorted({r["split"] for r in per_pair}, key=_split_key)
    result: dict[str, Any] = {
        "detector": row_name,
        "settings": asdict(settings),
        "n_pairs": {s: sum(r["split"] == s for r in per_pair) for s in splits},
    }
    metrics = (["repeatability"] if do_rep else []) + (["homography", "matching_score", "mAP"] if do_hom else [])
    for metric in metrics:
        result[metric] = {}
        for s in splits:
            values = np.array([r[metric] for r in per_pair if r["split"] == s], dtype=np.float64).reshape(-1, len(eps))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns stay NaN
                means = np.nanmean(values, axis=0) if len(values) else np.full(len(eps), np.nan)
            result[metric][s] = {float(e): float(m) for e, m in zip(eps, means)}
    result["keypoints"] = {t: float(np.mean(c)) if c else math.nan for t, c in counts.items() if c}
    if do_hom:
        result["matches"] = {s: float(np.mean([r["n_matches"] for r in per_pair if r["split"] == s])) for s in splits}
    result["speed"] = {}
    for task, timer in timers.items():
        if timer.images:
            shape = next(iter(timer.shapes)) if len(timer.shapes) == 1 else None
            key = f"{shape[0]}x{shape[1]}" if shape else f"{task} (mixed sizes)"
            ms = 1000.0 * timer.seconds / timer.images
            result["speed"][key] = {"ms": ms, "fps": 1000.0 / ms if ms > 0 else math.inf, "images": timer.images}
    result["per_pair"] = per_pair
    return result


def diagnose_pairs(
    detector: DetectorArg,
    pairs: Iterable[ImagePair],
    settings: BenchmarkSettings | None = None,
    *,
    eps: float = 3.0,
    detector_options: dict[str, Any] | None = None,
) -> NDArray[np.float64]:
    """Return ``evaluate.diagnose_matches`` on every pair, one row per pair, for the homography task's detections.

    The detector sees what ``run_benchmark``'s homography task gives it: each pair resized to
    ``settings.homography_size``, the best ``homography_keypoints`` points with NMS ``homography_nms``. The rows
    split each pair's result into its correct matches, their localisation error and the oracle homography fitted
    to them (see :func:`evio_lib.features.evaluation.evaluate.diagnose_matches`).

    Args:
        detector, settings, detector_options: as for :func:`run_benchmark`.
        pairs: ``ImagePair`` objects.
        eps: the correctness threshold of a match (px).

    Returns:
        (n_pairs, 5) float64, columns in the order of ``MatchDiagnosis._fields``: n_matches, n_correct,
        localisation_error (NaN without correct matches), corner_error_ransac, corner_error_oracle (inf when
        there is no homography).
    """
    settings = BenchmarkSettings() if settings is None else settings
    if not isinstance(settings, BenchmarkSettings):
        raise ValueError(f"settings must be a BenchmarkSettings; got {type(settings).__name__}")
    k = settings.homography_keypoints
    det = _make_detector(detector, k, settings.homography_nms, dict(detector_options or {}))
    timer = _Timer()
    rows = []
    for pair in pairs:  # a loop over pairs; the per-pair work is vectorised in diagnose_matches
        if not isinstance(pair, ImagePair):
            raise ValueError(f"pairs must hold ImagePair objects; got {type(pair).__name__}")
        large = resize_pair(pair, settings.homography_size, settings.resize_mode)
        f1, f2 = _detect(det, large.image1, k, timer), _detect(det, large.image2, k, timer)
        rows.append(diagnose_matches(f1.keypoints, f2.keypoints, f1.descriptors, f2.descriptors, large.H,
                                     large.image1.shape, eps=eps, binary=f1.binary))
    return np.array(rows, dtype=np.float64).reshape(-1, 5)


def measure_speed(
    detector: DetectorArg,
    images: Sequence[np.ndarray],
    shape: tuple[int, int],
    *,
    n_frames: int = 20,
    max_keypoints: int = 300,
    nms_radius: int = 4,
    detector_options: dict[str, Any] | None = None,
) -> dict[str, float]:
    """Return {"ms", "fps", "images"}: the mean wall time of ``detect_and_describe`` on images of the given shape.

    The images are resized to ``shape`` (centre crop) beforehand and cycled through ``n_frames`` timed calls after
    two untimed warm-up calls; detection and description together, one image at a time, as a VIO front end calls it.

    Args:
        detector: a detector name, factory or instance (see ``run_benchmark``).
        images: grayscale images to time on.
        shape: (height, width), e.g. (180, 240) for the DAVIS resolution.
        n_frames: timed calls.
        max_keypoints, nms_radius: detector settings when it is created by name or factory.
        detector_options: extra options for create_detector / the factory.
    """
    imgs = _check_images(images, "images")
    count = _check_count(n_frames, "n_frames")
    det = _make_detector(detector, max_keypoints, nms_radius, dict(detector_options or {}))
    frames = [resize_image(img, shape, "crop")[0] for img in imgs]
    for frame in frames[:2] if len(frames) > 1 else frames * 2:
        det.detect_and_describe(frame)  # warm-up
    start = time.perf_counter()
    for i in range(count):
        det.detect_and_describe(frames[i % len(frames)])
    ms = 1000.0 * (time.perf_counter() - start) / count
    return {"ms": ms, "fps": 1000.0 / ms if ms > 0 else math.inf, "images": count}


# ---------------------------------------------------------------------------------------------- tables
def _split_key(split: str) -> tuple[int, str]:
    """Sort key putting the thesis's splits first, in its column order."""
    return (SPLIT_ORDER.index(split) if split in SPLIT_ORDER else len(SPLIT_ORDER), split)


def _display(name: str) -> str:
    """Return the thesis's spelling of a detector name (unknown names unchanged)."""
    return DISPLAY_NAMES.get(name.lower().replace("-", "_"), name)


def _format_eps(e: float) -> str:
    """Return eps without a trailing .0."""
    return f"{e:g}"


def format_table(rows: Sequence[dict[str, Any]], kind: str, *, digits: int = 3, bold_best: bool = True) -> str:
    """Return a Markdown table (one row per detector) in the form of thesis Tables 2-5.

    ``kind`` is "repeatability" (Tables 2, 3), "homography" (Tables 4, 5: homography estimation correctness),
    "matching_score", "mAP" or "speed" (ms per image and frames/s per resolution). Columns are the splits present
    (viewpoint, illumination, event frames, ...) times eps; a single split gives plain "ε = 1" columns as Tables 3
    and 5. The best value of each column is bold (highest; for speed, the most frames/s). Missing values show "-".

    Args:
        rows: results of ``run_benchmark`` (one per detector).
        kind: one of "repeatability", "homography", "matching_score", "mAP", "speed".
        digits: decimals of the metrics.
        bold_best: mark the best value of each column in bold.

    >>> row = {"detector": "sift", "repeatability": {"viewpoint": {1.0: 0.26, 3.0: 0.486}}}
    >>> print(format_table([row], "repeatability"))
    | Model | ε = 1 | ε = 3 |
    |---|---|---|
    | SIFT | **0.260** | **0.486** |
    """
    if kind not in TABLE_KINDS:
        raise ValueError(f"kind must be one of {TABLE_KINDS}; got {kind!r}")
    if isinstance(rows, dict):
        rows = [rows]
    if not rows:
        raise ValueError("rows must hold at least one benchmark result (a dict from run_benchmark); got none")
    names = [_display(str(r.get("detector", "?"))) for r in rows]
    columns: list[tuple[str, Callable[[dict[str, Any]], float]]] = []
    if kind == "speed":
        shapes = sorted({k for r in rows for k in r.get("speed", {})},
                        key=lambda k: tuple(int(v) for v in k.split("x")) if "x" in k and " " not in k else (10**9,))
        for s in shapes:
            columns.append((f"{s} ms", lambda r, s=s: r.get("speed", {}).get(s, {}).get("ms", math.nan)))
            columns.append((f"{s} frames/s", lambda r, s=s: r.get("speed", {}).get(s, {}).get("fps", math.nan)))
    else:
        splits = sorted({s for r in rows for s in r.get(kind, {})}, key=_split_key)
        for s in splits:
            eps_values = sorted({float(e) for r in rows for e in r.get(kind, {}).get(s, {})})
            for e in eps_values:
                title = f"ε = {_format_eps(e)}"
                if len(splits) > 1:
                    title = f"{SPLIT_TITLES.get(s, s)} {title}"
                columns.append((title, lambda r, s=s, e=e: _lookup_eps(r.get(kind, {}).get(s, {}), e)))
    if not columns:
        raise ValueError(f"rows hold no {kind!r} results (run_benchmark with that task first)")
    values = np.array([[float(get(r)) for _, get in columns] for r in rows], dtype=np.float64)
    best = np.zeros(values.shape, bool)
    if bold_best:
        for j, (title, _) in enumerate(columns):
            column = values[:, j]
            if np.isfinite(column).any():
                target = np.nanmin(column) if title.endswith(" ms") else np.nanmax(column)
                best[:, j] = np.isclose(column, target, rtol=0, atol=0.5 * 10.0**-digits)
    lines = ["| Model | " + " | ".join(t for t, _ in columns) + " |", "|---|" + "---|" * len(columns)]
    for i, row_name in enumerate(names):
        cells = []
        for j, (title, _) in enumerate(columns):
            v = values[i, j]
            places = 1 if kind == "speed" else digits
            text = "-" if not np.isfinite(v) else f"{v:.{places}f}"
            cells.append(f"**{text}**" if best[i, j] and text != "-" else text)
        lines.append(f"| {row_name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _lookup_eps(values: dict[Any, float], eps: float) -> float:
    """Return the value stored under eps (keys may be floats or their strings, as after a JSON round trip)."""
    for key, value in values.items():
        if math.isclose(float(key), eps):
            return float(value)
    return math.nan


# ---------------------------------------------------------------------------------------------- command line
def _parse_shape(text: str) -> tuple[int, int]:
    """Return (height, width) from 'HxW'."""
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"--speed-shapes entries must look like 180x240 (height x width); got {text!r}") from None
    if h < 8 or w < 8:
        raise ValueError(f"--speed-shapes entries must be at least 8x8; got {text!r}")
    from evio_lib.events.representations import check_sensor_pixels

    check_sensor_pixels(w, h, f"--speed-shapes {text}")  # before any image is made: 100000x100000 is 10 GB
    return h, w


def _load_event_frames(path: Path) -> list[np.ndarray]:
    """Return the frames stored in a .npy (N, H, W) or .npz (array 'frames', else the first array) file."""
    if not path.is_file():
        raise ValueError(f"--event-frames {path} is not a file")
    data = np.load(path)
    if isinstance(data, np.lib.npyio.NpzFile):
        key = "frames" if "frames" in data.files else data.files[0]
        data = data[key]
    frames = np.asarray(data)
    if frames.ndim != 3:
        raise ValueError(f"--event-frames must hold an (N, H, W) stack of frames; got shape {frames.shape}")
    if np.issubdtype(frames.dtype, np.floating) and frames.size and (frames.min() < 0 or frames.max() > 1):
        lo, hi = float(frames.min()), float(frames.max())  # event-count frames: scale to [0, 1]
        frames = (frames - lo) / max(hi - lo, 1e-12)
    return list(frames)


class _LazyPairs:
    """A re-iterable source of pairs: every iteration calls ``make()`` afresh (HPatches is read from disk each pass)."""

    def __init__(self, make: Callable[[], Iterable[ImagePair]]) -> None:
        self._make = make

    def __iter__(self):  # type: ignore[no-untyped-def]
        return iter(self._make())


def _benchmark_pairs(args: argparse.Namespace) -> tuple[Iterable[ImagePair], dict[str, int], list[np.ndarray]]:
    """Return the pairs of the chosen data set, their count per split and a few images to time the detectors on."""
    n_images = 2 if args.fast and args.n_images is None else args.n_images
    per_image = 1 if args.fast else args.pairs_per_image
    if args.dataset == "hpatches":
        if args.hpatches_root is None:
            raise ValueError("--dataset hpatches needs --hpatches-root (the folder with the i_*/v_* scenes)")
        root = args.hpatches_root
        counts: dict[str, int] = {}
        for split, prefix in SPLIT_PREFIXES.items():  # count from the folder names, without reading images
            n = sum(p.name.startswith(prefix) for p in hpatches_scenes(root))
            n = n if n_images is None else min(n, n_images)
            if n:
                counts[split] = n * (N_IMAGES_PER_SCENE - 1)
        pairs: Iterable[ImagePair] = _LazyPairs(lambda: iter_hpatches_pairs(root, "all", max_scenes=n_images))
        first = [p.image1 for _, p in zip(range(1), pairs)]  # time the detectors on the first reference image
        return pairs, counts, first
    if args.dataset == "photos":
        from evio_lib.sim.photos import resolve_photo_option

        given = getattr(args, "photos", "auto")
        folder = resolve_photo_option(given)
        if folder is None:
            why = ("--photos none names no folder" if str(given) == "none"
                   else "no photo folder found at ../shared/data/photos or $EVIO_PHOTOS")
            raise ValueError(f"--dataset photos needs photographs ({why}): give --photos DIR, a folder of .jpg/.png "
                             f"photographs")
        listed = photo_pairs(folder, getattr(args, "photo_split", "test"), args.seed, n_images=n_images,
                             pairs_per_image=per_image)
    elif args.dataset == "events":
        if args.event_frames is None:
            raise ValueError("--dataset events needs --event-frames (an .npy/.npz stack of event frames)")
        frames = _load_event_frames(args.event_frames)[:n_images]
        listed = event_frame_pairs(frames, args.seed, per_image)
    else:
        listed = heldout_pairs(args.seed, n_images=n_images, pairs_per_image=per_image)
    counts = {}
    for pair in listed:
        counts[pair.split] = counts.get(pair.split, 0) + 1
    return listed, counts, [p.image1 for p in listed[:: max(1, len(listed) // 4)][:4]]


def main_benchmark(args: argparse.Namespace | Sequence[str] | None = None) -> int:
    """Run the benchmark from the command line; print the tables; return the exit code.

    ``args`` is the namespace of a parser that ``add_benchmark_arguments`` set up, or an argument list (parsed
    here). Writes ``results.json`` (everything but the per-pair records) and ``tables.md`` into ``--out``, atomically,
    once every detector has run. ``--fast`` fills in only the options the user left unset. Exit codes: 0 done; 2 a
    mistake in the arguments (one line ``error: ...``, found before the benchmark starts); 1 a detector failed
    (without ``--keep-going``) or none could be run.
    """
    from evio_lib.features.base import available_detectors, create_detector
    from evio_lib.io.output_dir import atomic_output_dir, check_output_dir

    if args is None or not isinstance(args, argparse.Namespace):
        parser = add_benchmark_arguments(argparse.ArgumentParser(prog="python -m evio_lib features-benchmark",
                                                                 description=__doc__.split("\n")[0]))
        args = parser.parse_args(None if args is None else list(args))
    args = argparse.Namespace(**vars(args))  # resolved below; the caller's namespace stays as it was
    fast, args.fast = bool(getattr(args, "fast", False)), False  # _benchmark_pairs must see only the resolved values
    if args.n_images is None and fast:
        args.n_images = 2
    if args.pairs_per_image is None:
        args.pairs_per_image = 1 if fast else 5
    if args.speed_frames is None:
        args.speed_frames = 5 if fast else 20
    if args.speed_shapes is None:
        args.speed_shapes = ["180x240", "240x320"]
    if args.settings is None:
        args.settings = "thesis-events" if args.dataset == "events" else "thesis-hpatches"
    force, keep_going = getattr(args, "force", False), getattr(args, "keep_going", False)
    weights = getattr(args, "weights", None)
    names = list(args.detectors) if args.detectors else available_detectors()

    cnn_scales = getattr(args, "cnn_scales", None)

    def options_of(detector_name: str) -> dict[str, Any]:
        options: dict[str, Any] = {}
        if weights is not None and _is_superpoint(detector_name):
            options["weights"] = weights
        if cnn_scales is not None and _is_network(detector_name):
            options["scales"] = cnn_scales
        return options

    def row_name_of(detector_name: str, options: dict[str, Any]) -> str | None:
        name = Path(str(weights)).stem if "weights" in options else None
        if "scales" in options:
            scales = options["scales"]
            label = scales if isinstance(scales, str) else ",".join(f"{v:g}" for v in scales)
            name = f"{name or detector_name} (scales {label})"
        return name

    failed: list[str] = []
    try:  # every check before the first pair is evaluated
        if args.out is not None:
            weights_file = weights if weights is not None and Path(str(weights)).exists() else None  # or a shipped name
            photos = None  # the photo folder, so that --out is not written inside it
            if args.dataset == "photos":
                from evio_lib.sim.photos import resolve_photo_option

                photos = resolve_photo_option(getattr(args, "photos", "auto"))
            check_output_dir(args.out, force, name="--out", inputs=[
                ("the --hpatches-root folder", args.hpatches_root), ("the --event-frames file", args.event_frames),
                ("the --photos folder", photos),
                ("the --weights checkpoint", weights_file)])
        shapes = [_parse_shape(text) for text in args.speed_shapes]
        if weights is not None:
            from evio_lib.features.network import load_checkpoint, resolve_weights

            try:
                load_checkpoint(resolve_weights(weights))
            except (ValueError, FileNotFoundError) as error:
                text = str(error)  # the checkpoint reader names the file first: do not name it twice
                text = text[len(f"{weights}: "):] if text.startswith(f"{weights}: ") else text
                raise ValueError(f"--weights {weights}: {text}") from error
            except Exception as error:  # torch.load on a file that is no checkpoint: pickle, zip or EOF errors
                detail = (str(error).strip().splitlines() or [""])[0].split(". ")[0][:120]  # torch's first sentence
                raise ValueError(f"--weights {weights}: not a readable SuperPoint checkpoint (torch.load: "
                                 f"{type(error).__name__}{': ' + detail if detail else ''})") from error
        frames_file = args.event_frames if args.dataset == "events" else None
        if frames_file is not None and Path(frames_file).is_file():
            try:  # the header only (memory-mapped .npy, lazy .npz): a file that is not NumPy's fails here
                loaded = np.load(frames_file, mmap_mode="r")
                if isinstance(loaded, np.lib.npyio.NpzFile):
                    loaded.close()
            except (ValueError, OSError, EOFError) as error:
                raise ValueError(f"--event-frames {frames_file}: not a NumPy .npy or .npz file of (N, H, W) frames "
                                 f"({type(error).__name__})") from error
        for detector_name in list(names):  # an unknown name or option fails now, not after an hour of other rows
            try:
                create_detector(detector_name, **options_of(detector_name))
            except (ImportError, RuntimeError) as error:
                if not keep_going:
                    raise ValueError(f"detector {detector_name} cannot be created: {error} "
                                     f"(--keep-going skips it)") from error
                print(f"skipping {detector_name} (--keep-going): {error}", file=sys.stderr)
                failed.append(detector_name)
                names.remove(detector_name)
        pairs, counts, timing_images = _benchmark_pairs(args)
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    settings = (BenchmarkSettings.thesis_event_frames() if args.settings == "thesis-events"
                else BenchmarkSettings.thesis_hpatches())
    print(f"{args.dataset} benchmark: {sum(counts.values())} pairs {counts}, settings {args.settings}, "
          f"detectors {names}")
    rows = []
    for detector_name in names:
        options = options_of(detector_name)
        row_name = row_name_of(detector_name, options)
        try:
            row = run_benchmark(detector_name, pairs, settings, name=row_name, detector_options=options or None,
                                progress=not args.quiet)
            for shape in shapes:
                key = f"{shape[0]}x{shape[1]}"
                row["speed"][key] = measure_speed(detector_name, timing_images, shape, n_frames=args.speed_frames,
                                                  max_keypoints=settings.repeatability_keypoints,
                                                  nms_radius=settings.repeatability_nms,
                                                  detector_options=options or None)
        except (ValueError, ImportError, FileNotFoundError, RuntimeError) as error:
            if not keep_going:
                print(f"error: detector {detector_name} failed: {error} (--keep-going skips a failing detector)",
                      file=sys.stderr)
                return 1
            print(f"skipping {detector_name} (--keep-going): {error}", file=sys.stderr)
            failed.append(detector_name)
            continue
        rows.append(row)
    if not rows:
        print("error: no detector could be run", file=sys.stderr)
        return 1
    titles = {"repeatability": "Repeatability", "homography": "Homography estimation correctness",
              "matching_score": "Matching score", "mAP": "Nearest-neighbour mAP", "speed": "Speed (detect + describe)"}
    sections = []
    for kind in TABLE_KINDS:
        try:
            sections.append(f"### {titles[kind]} ({args.dataset})\n\n{format_table(rows, kind)}\n")
        except ValueError:
            continue
    text = "\n".join(sections)
    print(text)
    if failed:
        print(f"skipped after an error (--keep-going): {', '.join(failed)}", file=sys.stderr)
    if args.out is not None:
        with atomic_output_dir(args.out, force) as tmp:
            summary = [{k: v for k, v in r.items() if k != "per_pair"} for r in rows]
            (tmp / "results.json").write_text(json.dumps(summary, indent=2, default=_json_default))
            (tmp / "tables.md").write_text(text)
        print(f"wrote {args.out / 'results.json'} and {args.out / 'tables.md'}")
    return 0


def _is_superpoint(detector_name: str) -> bool:
    """Return whether ``detector_name`` names the ``superpoint`` detector, however spelt."""
    from evio_lib.features.base import _normalise_name

    return _normalise_name(detector_name) == "superpoint"


def _is_network(detector_name: str) -> bool:
    """Return whether ``detector_name`` is a network detector (``superpoint`` or a shipped checkpoint's name)."""
    from evio_lib.features.base import _normalise_name
    from evio_lib.features.network import shipped_weights

    key = _normalise_name(detector_name)  # the registry's spelling: "SuperPoint" and "distilled-narrow" count
    return key == "superpoint" or key in {_normalise_name(name) for name in shipped_weights()}


def _json_default(value: Any) -> Any:
    """Return a JSON-friendly version of numpy values."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (set, tuple)):
        return list(value)
    raise TypeError(f"cannot write {type(value).__name__} to JSON")
