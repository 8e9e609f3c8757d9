"""Descriptor matching between consecutive frames: mutual nearest neighbours with a ratio and a distance test.

For the descriptor d_i of a tracked feature and the descriptors e_j of the new detections (L2 for float descriptors,
Hamming bits for packed binary ones), a pair (i, j) is a match when

0. optionally (guided matching) only pairs allowed by a mask are considered, e.g. detections within a radius of the
   position predicted for feature i by the gyroscope's rotation;
1. j is i's nearest neighbour and i is j's nearest neighbour (mutual, the cross-check of ``cv2.BFMatcher``);
2. Lowe's ratio test: dist(i, j) < ratio * dist(i, j2), with j2 the nearest other detection anywhere in the image
   (an ambiguous match, e.g. on a repeated texture, fails it; so does the wrong detection left in the window when the
   right one was not detected); with a single detection the test passes;
3. dist(i, j) <= max_distance (optional absolute gate).

Reference: Lowe, "Distinctive image features from scale-invariant keypoints", IJCV 2004, §7.1 (ratio 0.8);
thesis §3.3.5 (features matched between consecutive frames before two-point RANSAC).
"""
from __future__ import annotations

import math
from numbers import Real

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.features.evaluation.evaluate import descriptor_distances

__all__ = ["match_mutual_ratio"]


def match_mutual_ratio(
    desc_prev: ArrayLike,
    desc_curr: ArrayLike,
    *,
    binary: bool = False,
    ratio: float | None = 0.8,
    max_distance: float | None = None,
    allowed: ArrayLike | None = None,
) -> NDArray[np.int64]:
    """Return (M, 2) index pairs [i_prev, i_curr] of mutual nearest neighbours passing the ratio and distance tests.

    Args:
        desc_prev: (N1, D) float descriptors (or (N1, B) uint8 packed bits) of the tracked features.
        desc_curr: (N2, D) / (N2, B) descriptors of the current detections.
        binary: True for packed-bit descriptors (Hamming distance in bits).
        ratio: Lowe's ratio in (0, 1], or None to skip the test.
        max_distance: largest accepted descriptor distance (L2, or bits), or None.
        allowed: optional (N1, N2) bool mask of the pairs that may match (guided matching, e.g. detections within
            a radius of each feature's predicted position); nearest neighbours and the mutual check only consider
            allowed pairs, while the ratio test compares with the second nearest detection in the whole image, so
            a match must be distinctive, not merely alone in its window.

    Rows are sorted by i_prev.

    >>> prev = np.array([[1.0, 0.0], [0.0, 1.0]])
    >>> curr = np.array([[0.0, 1.0], [0.98, 0.2], [0.97, -0.22]])
    >>> match_mutual_ratio(prev, curr).tolist()        # feature 0 has two similar candidates: ambiguous
    [[1, 0]]
    >>> match_mutual_ratio(prev, curr, ratio=None).tolist()
    [[0, 1], [1, 0]]
    >>> window = [[False, True, False], [True, True, True]]   # guided: feature 0 may only match detection 1
    >>> match_mutual_ratio(prev, curr, allowed=window).tolist()      # ... still ambiguous with detection 2
    [[1, 0]]
    >>> match_mutual_ratio(prev, curr, allowed=window, ratio=None).tolist()
    [[0, 1], [1, 0]]
    """
    if ratio is not None and (isinstance(ratio, bool) or not isinstance(ratio, Real) or not 0.0 < ratio <= 1.0):
        raise ValueError(f"ratio must be a number in (0, 1] or None; got {ratio!r}")
    if max_distance is not None and (isinstance(max_distance, bool) or not isinstance(max_distance, Real)
                                     or not math.isfinite(max_distance) or max_distance < 0):
        raise ValueError(f"max_distance must be a finite number >= 0 or None; got {max_distance!r}")
    distances = descriptor_distances(desc_prev, desc_curr, binary)
    all_distances = distances
    n1, n2 = distances.shape
    if allowed is not None:
        mask = np.asarray(allowed)
        if mask.shape != (n1, n2) or mask.dtype != np.bool_:
            raise ValueError(f"allowed must be a bool array of shape (N1, N2) = ({n1}, {n2}); got {mask.dtype} "
                             f"{mask.shape}")
        distances = np.where(mask, distances, np.inf)
    if n1 == 0 or n2 == 0:
        return np.zeros((0, 2), dtype=np.int64)
    nn12 = np.argmin(distances, axis=1)  # nearest detection of each tracked feature (first on ties)
    nn21 = np.argmin(distances, axis=0)
    rows = np.arange(n1)
    best = distances[rows, nn12]
    keep = (nn21[nn12] == rows) & np.isfinite(best)  # mutual: i -> j -> i
    if ratio is not None and n2 >= 2:
        others = all_distances.copy()
        others[rows, nn12] = np.inf
        second = others.min(axis=1)  # the nearest other detection anywhere in the image
        keep &= best < ratio * second  # d1 < ratio d2
    if max_distance is not None:
        keep &= best <= max_distance
    return np.column_stack([rows[keep], nn12[keep]]).astype(np.int64)
