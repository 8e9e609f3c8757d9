"""The real-photograph benchmark: held-out natural photographs fitted to the evaluation size, HPatches-style pairs.

``photo_images(folder, split)`` reads the photographs of one held-out split of a photo folder
(:func:`evio_lib.sim.photos.list_photos`: the split follows a hash of each relative path, so the ``test`` photographs
are never trained on, and ``val`` chooses networks without looking at them) and fits each to (height, width) =
(480, 640) without distorting it (:func:`fit_photo`). ``benchmark.photo_pairs`` passes them to
:func:`evio_lib.features.evaluation.benchmark.heldout_pairs` (``images=``), so the viewpoint (random homographies)
and illumination (photometric change, H = I) pairs come from the same generators and seeds as the built-in
benchmark. ``python -m evio_lib features-benchmark --dataset photos [--photos DIR] [--photo-split val]`` runs it.
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

__all__ = ["PHOTO_BENCHMARK_SPLITS", "fit_photo", "photo_images"]

#: splits of the photo folder a benchmark may use (the training split never is one)
PHOTO_BENCHMARK_SPLITS = ("test", "val")


def fit_photo(image: np.ndarray, size: tuple[int, int] = (480, 640)) -> NDArray[np.float32]:
    """Return ``image`` cut to the aspect ratio of ``size`` around its centre, then resized to ``size``.

    With the image (h, w) and ``size`` (H, W), the crop keeps the whole width when ``h / w >= H / W`` (height
    ``round(w H / W)``) and the whole height otherwise (width ``round(h W / H)``), cut from the centre; then both axes
    are scaled by the same ``s = W / crop width`` (up to rounding of the crop), so nothing is stretched. Shrinking
    (``s < 1``) averages areas (``cv2.INTER_AREA``, no aliasing); enlarging (``s > 1``) is bicubic
    (``cv2.INTER_CUBIC``), clipped back to [0, 1]. Photographs smaller than the evaluation size are enlarged:
    several held-out photographs of the shared folder are under 480 pixels high (e.g. 340 x 512, cropped to
    340 x 453 and enlarged 1.41 times), so their fine detail is interpolated, not seen. A portrait photograph keeps
    only its central landscape band (its width by three quarters of it).

    Args:
        image: (h, w) grayscale image, float32 in [0, 1] or uint8.
        size: (H, W) of the output.

    Returns:
        (H, W) float32 image in [0, 1].

    >>> fit_photo(np.zeros((340, 512), np.float32)).shape
    (480, 640)
    >>> ramp = np.tile(np.arange(1200, dtype=np.float32) / 1200, (600, 1))  # 600 x 1200: columns 200..999 kept
    >>> out = fit_photo(ramp, (30, 40))      # 20 x 20 blocks averaged: column 0 is the mean of x / 1200, x in 200..219
    >>> out.shape, round(float(out[0, 0]), 4), round(float(out[0, -1]), 4)
    ((30, 40), 0.1746, 0.8246)
    """
    import cv2

    img = np.asarray(image)
    if img.ndim != 2 or min(img.shape) < 8:
        raise ValueError(f"image must be a grayscale (h, w) image of at least 8 x 8 pixels; got shape {img.shape}")
    if img.dtype == np.uint8:
        img = img.astype(np.float32) / np.float32(255.0)
    img = img.astype(np.float32)
    out_h, out_w = (int(v) for v in size)
    if out_h < 1 or out_w < 1:
        raise ValueError(f"size must be (height, width) of positive integers; got {size!r}")
    h, w = img.shape
    if h * out_w >= w * out_h:  # taller than the target: keep the width, cut rows
        crop_h, crop_w = max(1, min(h, round(w * out_h / out_w))), w
    else:  # wider: keep the height, cut columns
        crop_h, crop_w = h, max(1, min(w, round(h * out_w / out_h)))
    top, left = (h - crop_h) // 2, (w - crop_w) // 2
    crop = img[top:top + crop_h, left:left + crop_w]
    if (crop_h, crop_w) == (out_h, out_w):
        return np.ascontiguousarray(crop)
    shrink = crop_w > out_w
    resized = cv2.resize(crop, (out_w, out_h), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_CUBIC)
    return np.clip(resized, 0.0, 1.0).astype(np.float32)


def photo_images(
    folder: str | Path, split: str = "test", *, n_images: int | None = None, size: tuple[int, int] = (480, 640)
) -> list[NDArray[np.float32]]:
    """Return the photographs of one held-out split of ``folder``, in the order of their relative paths, fitted to
    ``size`` by :func:`fit_photo` (the first ``n_images`` only, when given).

    Raises ValueError (one line, naming ``--photos``) for a split other than ``test``/``val``, a missing folder, or
    one without photographs of that split.
    """
    from evio_lib.sim.photos import list_photos, load_photo

    if split not in PHOTO_BENCHMARK_SPLITS:
        raise ValueError(f"the photo split must be one of {PHOTO_BENCHMARK_SPLITS} (train is never a benchmark); "
                         f"got {split!r}")
    paths = list_photos(folder, split)
    if n_images is not None:
        if isinstance(n_images, bool) or not isinstance(n_images, int) or n_images < 1:
            raise ValueError(f"n_images must be a positive integer; got {n_images!r}")
        paths = paths[:n_images]
    return [fit_photo(load_photo(path), size) for path in paths]
