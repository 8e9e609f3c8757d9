"""Multi-scale inference: run the network on an image pyramid and merge the detections of every level.

The network sees a fixed receptive field in pixels, so its descriptor of a corner changes when the image is zoomed.
SIFT picks a scale per point; the network can be given the same freedom at test time by running it on resized
copies of the image, as R2D2 and D2-Net do with theirs: a corner zoomed by 1.5x in the second image then has, in
the first, a descriptor computed at nearly the same scale (levels 2^(1/4) apart). No training is involved.

The levels (:func:`pyramid_scales`): s_k = 2^(-k/4), k = 0, 1, ..., kept while the shorter side of the level,
s_k min(H, W), is at least ``min_side`` (default :data:`PYRAMID_MIN_SIDE` = 240 pixels), and, when there is such a
level below the image, :data:`PYRAMID_LEVELS_ABOVE` = 2 enlarged levels 2^(1/4) and 2^(1/2) on top (SIFT, too,
starts from an enlarged image). A 480 x 640 image gets seven levels (1.41, 1.19, 1, 0.84, 0.71, 0.59, 0.5: about
6.2 times the pixels of one); a 180 x 240 or 260 x 346 event frame gets one (the thesis's single-scale network). A
level is an area-averaged copy (``cv2.INTER_AREA``; bicubic when enlarging), clipped to [0, 1]; its keypoints
(x_s, y_s) map back to the image as x = (x_s + 1/2) W / W_s - 1/2 (pixel centres at integers, the level covering
the image's area), and likewise y. Every level keeps its own NMS (in its own pixels), so a corner may be found at
several levels, each time with that level's descriptor: :func:`merge_levels` pools them and keeps the best
``max_keypoints`` by probability, leaving out points within ``border`` pixels of the image's edge. The
enlarged levels cost the most: an image of shorter side m >= 286 gets 3 + floor(4 log2(m / 240)) levels; a 1080 x 1920
image gets 11, the largest 1527 x 2715 pixels, so give ``scales`` explicitly for large images where time matters.
(One NMS across the levels, one descriptor per place, loses most of the gain:
docs/archive.md.)

Chosen on the 111 viewpoint pairs of the 37 validation photographs (480 x 640, best 1000 points, NMS 8, mutual
nearest neighbours and RANSAC; ``python bench/pyramid_levels.py``), homography correctness at eps = 1 / 3 / 5 px of
``pretrained_detdesc_round1_gpu`` (the default network then) and the time per image on one thread of the 2-core Xeon beside other work: one level
0.027 / 0.207 / 0.306 (237 ms); levels 1 to 0.5 0.216 / 0.541 / 0.649 (632 ms); 1.19 to 0.5 0.378 / 0.577 / 0.730
(991 ms); 1.41 to 0.5, the default, 0.405 / 0.694 / 0.802 (1.6 s); 2 to 0.5 0.514 / 0.703 / 0.820 (3.5 s); SIFT
0.541 / 0.802 / 0.856 (119 ms). The enlarged levels place the points more finely (the network's cells cover less
of the scene); the level 2 doubles the time for little more at 3 px.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from evio_lib.features.base import Features

__all__ = ["PYRAMID_LEVELS_ABOVE", "PYRAMID_MIN_SIDE", "PYRAMID_STEP", "check_scales", "merge_levels", "parse_scales",
           "pyramid_scales", "resize_level"]

#: ratio between successive levels of the automatic pyramid (four levels per octave)
PYRAMID_STEP = 2.0 ** -0.25
#: the automatic pyramid stops before a level's shorter side falls below this many pixels
PYRAMID_MIN_SIDE = 240
#: enlarged levels (step^-1, ...) the automatic pyramid puts above the image when it has levels below it
PYRAMID_LEVELS_ABOVE = 2


def pyramid_scales(
    shape: tuple[int, int],
    min_side: int = PYRAMID_MIN_SIDE,
    step: float = PYRAMID_STEP,
    levels_above: int = PYRAMID_LEVELS_ABOVE,
) -> tuple[float, ...]:
    """Return the automatic levels of an image of ``shape`` (H, W), largest first.

    The levels below the image are 1, step, step^2, ..., kept while step^k min(H, W) >= ``min_side``. An image with
    at least one such level below it also gets ``levels_above`` enlarged levels step^-1, step^-2, ... on top (as
    SIFT starts from an enlarged image); an image too small for a level below keeps the single level 1, so the
    event frames stay single-scale.

    >>> [round(s, 2) for s in pyramid_scales((480, 640))]
    [1.41, 1.19, 1.0, 0.84, 0.71, 0.59, 0.5]
    >>> pyramid_scales((180, 240)), pyramid_scales((260, 346))
    ((1.0,), (1.0,))
    """
    height, width = (int(v) for v in shape[:2])
    if not 0.0 < step < 1.0:
        raise ValueError(f"step must lie in (0, 1); got {step!r}")
    if min_side < 1:
        raise ValueError(f"min_side must be a positive number of pixels; got {min_side!r}")
    if isinstance(levels_above, bool) or not isinstance(levels_above, int) or levels_above < 0:
        raise ValueError(f"levels_above must be an integer >= 0; got {levels_above!r}")
    short = min(height, width)
    below = [1.0]
    k = 1
    while short * round(step**k, 12) >= min_side:  # rounded: 2^(-4/4) is 0.5, not 0.49999999999999994
        below.append(round(step**k, 12))
        k += 1
    if len(below) == 1:
        return (1.0,)
    return tuple(round(step**-j, 12) for j in range(levels_above, 0, -1)) + tuple(below)


def check_scales(scales: object) -> str | tuple[float, ...]:
    """Return ``scales`` checked: "auto", or a non-empty sequence of distinct finite scales in [1/16, 4].

    >>> check_scales([1, 0.5])
    (1.0, 0.5)
    """
    form = "'auto' or a sequence of distinct scale factors in [1/16, 4] such as (1.0, 0.71, 0.5)"
    if isinstance(scales, str):
        if scales != "auto":
            raise ValueError(f"scales must be {form}; got {scales!r}")
        return scales
    try:
        items = list(scales)  # type: ignore[call-overload]
        values = tuple(float(s) for s in items)
    except (TypeError, ValueError):
        raise ValueError(f"scales must be {form}; got {scales!r}") from None
    if (not values or any(isinstance(s, (bool, np.bool_)) for s in items)
            or not all(math.isfinite(s) and 1 / 16 <= s <= 4.0 for s in values) or len(set(values)) != len(values)):
        raise ValueError(f"scales must be {form}; got {scales!r}")
    return values


def parse_scales(text: str) -> str | tuple[float, ...]:
    """Return the ``scales`` option written on a command line: "auto" or comma-separated factors ("1,0.71,0.5").

    Raises ValueError, naming the expected form, for anything else (:func:`check_scales`).

    >>> parse_scales("1,0.5"), parse_scales("auto")
    ((1.0, 0.5), 'auto')
    """
    text = str(text).strip()
    if text == "auto":
        return "auto"
    try:
        values = [float(part) for part in text.split(",")]
    except ValueError:
        raise ValueError(f"expected auto or comma-separated scale factors in [1/16, 4] such as 1,0.71,0.5; "
                         f"got {text!r}") from None
    try:
        return check_scales(values)
    except ValueError:
        raise ValueError(f"expected auto or comma-separated distinct scale factors in [1/16, 4] such as 1,0.71,0.5; "
                         f"got {text!r}") from None


def resize_level(image: NDArray[np.float32], scale: float) -> NDArray[np.float32]:
    """Return the level of ``image`` at ``scale``: (round(s H), round(s W)), area-averaged (bicubic when enlarging),
    clipped back to [0, 1].

    >>> resize_level(np.ones((480, 640), np.float32), 0.5).shape
    (240, 320)
    """
    import cv2

    height, width = image.shape[:2]
    if scale == 1.0:
        return image
    size = (max(1, round(width * scale)), max(1, round(height * scale)))
    interpolation = cv2.INTER_AREA if scale < 1.0 else cv2.INTER_CUBIC
    level = np.clip(cv2.resize(image, size, interpolation=interpolation), 0.0, 1.0)  # area sums may give 1 + 1e-7
    return np.ascontiguousarray(level, dtype=np.float32)


def merge_levels(
    levels: Sequence[Features],
    level_shapes: Sequence[tuple[int, int]],
    image_shape: tuple[int, int],
    max_keypoints: int,
    border: float = 0.0,
) -> Features:
    """Return the detections of every level in image pixels, pooled, best ``max_keypoints`` by probability first.

    ``levels[i]`` holds the keypoints found in a level of shape ``level_shapes[i]`` (H_s, W_s); they map to the image
    of ``image_shape`` (H, W) by x = (x_s + 1/2) W / W_s - 1/2, y = (y_s + 1/2) H / H_s - 1/2, clipped to the image;
    points closer than ``border`` pixels to the image's edge (x < border or x > W - 1 - border, likewise y) are
    dropped, so an enlarged level keeps the detector's border in image pixels. Ties in probability keep the order of
    the levels (the first level first).

    >>> a = Features(np.array([[10.0, 20.0]]), np.array([0.5]), np.ones((1, 2), np.float32))
    >>> b = Features(np.array([[4.5, 9.5]]), np.array([0.9]), np.ones((1, 2), np.float32))
    >>> merge_levels([a, b], [(100, 100), (50, 50)], (100, 100), 5).keypoints.tolist()
    [[9.5, 19.5], [10.0, 20.0]]
    """
    if len(levels) != len(level_shapes) or not levels:
        raise ValueError(f"need one shape per level; got {len(levels)} levels and {len(level_shapes)} shapes")
    height, width = image_shape
    points, scores, descriptors = [], [], []
    for feats, (h_s, w_s) in zip(levels, level_shapes):
        factor = np.array([width / w_s, height / h_s], np.float64)
        points.append((feats.keypoints.astype(np.float64) + 0.5) * factor - 0.5)
        scores.append(feats.scores)
        descriptors.append(feats.descriptors)
    kp = np.concatenate(points)
    kp[:, 0] = np.clip(kp[:, 0], 0.0, width - 1.0)
    kp[:, 1] = np.clip(kp[:, 1], 0.0, height - 1.0)
    sc = np.concatenate(scores)
    inside = ((kp[:, 0] >= border) & (kp[:, 0] <= width - 1.0 - border) & (kp[:, 1] >= border)
              & (kp[:, 1] <= height - 1.0 - border))
    order = np.flatnonzero(inside)[np.argsort(-sc[inside], kind="stable")][:max_keypoints]
    return Features(kp[order], sc[order], np.concatenate(descriptors)[order], binary=levels[0].binary)
