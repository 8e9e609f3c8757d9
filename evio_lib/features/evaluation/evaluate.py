"""Detector and descriptor metrics: repeatability, homography correctness, matching score, mean average precision.

Every metric compares two images related by a known homography ``H`` that maps pixels of image 1 to pixels of image 2
(``x2h ~ H x1h``, pixel centres at integer coordinates, the convention of ``evio_lib.geometry.homography``). A point is
"in the shared view" when its warp lands on the other image's pixel area ``[-0.5, W - 0.5) x [-0.5, H - 0.5)`` and in
front of the homography's vanishing line. Distances between a point of image 1 and one of image 2 are always measured
in image 2's frame, as in SuperPoint's evaluation code.

Reference: thesis §3.2.6, Eqs. 15-17; DeTone, Malisiewicz & Rabinovich, "SuperPoint: Self-Supervised Interest Point
Detection and Description", CVPRW 2018, §7 and its evaluation code; Mikolajczyk & Schmid, "A performance evaluation of
local descriptors", PAMI 2005 (matching score); Balntas et al., "HPatches", CVPR 2017 (mean average precision).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from numbers import Integral, Real
from typing import NamedTuple

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from evio_lib.geometry.homography import as_image_shape

__all__ = [
    "repeatability",
    "localisation_error",
    "corner_error",
    "homography_correctness",
    "descriptor_distances",
    "match_descriptors",
    "estimate_homography",
    "matching_score",
    "average_precision",
    "mean_average_precision",
    "MatchDiagnosis",
    "diagnose_matches",
]

RANSAC_THRESHOLD = 3.0  # px, cv2.findHomography's default reprojection threshold (thesis: OpenCV defaults, RANSAC on)
RANSAC_MAX_ITERS = 2000  # cv2.findHomography's default
RANSAC_CONFIDENCE = 0.995  # cv2.findHomography's default

EpsArg = float | Sequence[float] | NDArray[np.float64]


# ---------------------------------------------------------------------------------------------- input checks
def _as_points(value: ArrayLike, name: str) -> NDArray[np.float64]:
    """Return ``value`` as finite (N, 2) float64 pixels, or raise ValueError naming ``name``."""
    pts = np.asarray(value, dtype=np.float64)
    if pts.ndim == 1 and pts.size == 0:
        pts = pts.reshape(0, 2)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"{name} must have shape (N, 2) as (x, y) pixel rows; got {pts.shape}")
    if not np.isfinite(pts).all():
        raise ValueError(f"{name} must be finite; got NaN or inf entries")
    return pts


def _as_homography(value: ArrayLike, name: str) -> NDArray[np.float64]:
    """Return a finite, invertible (3, 3) float64 homography, or raise ValueError naming ``name``."""
    H = np.asarray(value, dtype=np.float64)
    if H.shape != (3, 3):
        raise ValueError(f"{name} must be a (3, 3) homography; got shape {H.shape}")
    if not np.isfinite(H).all():
        raise ValueError(f"{name} must be finite; got NaN or inf entries")
    scale = np.abs(H).max()
    if scale == 0.0 or abs(np.linalg.det(H / scale)) < 1e-12:
        raise ValueError(f"{name} must be an invertible (3, 3) homography; got a singular matrix")
    return H


def _as_eps(value: EpsArg) -> tuple[NDArray[np.float64], bool]:
    """Return the thresholds as a 1-D float64 array and whether a single number was given."""
    message = f"eps must be a pixel threshold >= 0 or a non-empty 1-D sequence of them; got {value!r}"
    if isinstance(value, (bool, np.bool_)):
        raise ValueError(message)
    try:
        eps = np.atleast_1d(np.asarray(value, dtype=np.float64))
    except (TypeError, ValueError):
        raise ValueError(message) from None
    if eps.ndim != 1 or eps.size == 0 or not np.isfinite(eps).all() or (eps < 0).any():
        raise ValueError(message)
    return eps, isinstance(value, Real)


def _result(values: NDArray[np.float64], scalar: bool) -> float | NDArray[np.float64]:
    """Return a float for a scalar eps, else the array (one entry per eps)."""
    return float(values[0]) if scalar else values


def _as_descriptors(value: ArrayLike, name: str, binary: bool) -> NDArray:
    """Return descriptors (N, D): uint8 packed bits when binary, else finite float64; ValueError names ``name``."""
    desc = np.asarray(value)
    if desc.ndim != 2:
        raise ValueError(f"{name} must have shape (N, D); got {desc.shape}")
    if binary:
        if desc.dtype != np.uint8:
            raise ValueError(f"{name} must be uint8 packed bits (N, D bytes) for binary=True; got dtype {desc.dtype}")
        return desc
    if not (np.issubdtype(desc.dtype, np.floating) or np.issubdtype(desc.dtype, np.integer)) or desc.dtype == bool:
        raise ValueError(f"{name} must hold float descriptors (N, D) for binary=False; got dtype {desc.dtype}")
    desc = desc.astype(np.float64)
    if not np.isfinite(desc).all():
        raise ValueError(f"{name} must be finite; got NaN or inf entries")
    return desc


# ---------------------------------------------------------------------------------------------- geometry helpers
def _geometry_inputs(kp1, kp2, H, shape1, shape2):  # type: ignore[no-untyped-def]
    """Validate two keypoint sets, the homography between them and both image shapes (ValueError names which)."""
    return (_as_points(kp1, "kp1"), _as_points(kp2, "kp2"), _as_homography(H, "H"),
            as_image_shape(shape1, "shape1"), as_image_shape(shape2, "shape2"))


def _warp(H: NDArray[np.float64], points: NDArray[np.float64], source_shape: tuple[int, int]) -> NDArray[np.float64]:
    """Return H applied to (N, 2) points; points that land on or beyond H's vanishing line become NaN.

    ``[x', y', w] = H [x, y, 1]``; a point is in front when w has the sign that the centre of the source image has.
    """
    mapped = points @ H[:, :2].T + H[:, 2]  # H [x, y, 1]^T
    centre = np.array([(source_shape[1] - 1) / 2.0, (source_shape[0] - 1) / 2.0, 1.0])
    sign = np.sign(H[2] @ centre) or 1.0
    w = mapped[:, 2] * sign
    in_front = w > 1e-12 * np.abs(mapped).max(axis=1, initial=1.0)
    out = np.full((len(points), 2), np.nan)
    out[in_front] = mapped[in_front, :2] / mapped[in_front, 2:]  # (x' / w, y' / w)
    return out


def _inside(points: NDArray[np.float64], shape: tuple[int, int]) -> NDArray[np.bool_]:
    """Return whether each (x, y) lies on the pixel area [-0.5, W - 0.5) x [-0.5, H - 0.5) (NaN -> False)."""
    with np.errstate(invalid="ignore"):
        x, y = points[:, 0], points[:, 1]
        return (x >= -0.5) & (x < shape[1] - 0.5) & (y >= -0.5) & (y < shape[0] - 0.5)


def _nearest_distance(queries: NDArray[np.float64], targets: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return the distance (M,) from each query to its nearest target (inf when there is no target)."""
    if len(targets) == 0 or len(queries) == 0:
        return np.full(len(queries), np.inf)
    distance, _ = cKDTree(targets).query(queries, k=1)
    return distance


def _keep_best(mask: NDArray[np.bool_], scores: NDArray[np.float64] | None, keep_k: int | None) -> NDArray[np.intp]:
    """Return indices of the True entries of ``mask``, cut to the ``keep_k`` highest scores when asked."""
    index = np.flatnonzero(mask)
    if keep_k is None or len(index) <= keep_k:
        return index
    order = np.argsort(-scores[index], kind="stable")[:keep_k]  # type: ignore[index]
    return np.sort(index[order])


# ---------------------------------------------------------------------------------------------- repeatability
def repeatability(
    kp1: ArrayLike,
    kp2: ArrayLike,
    H: ArrayLike,
    shape1: tuple[int, int],
    shape2: tuple[int, int],
    eps: EpsArg = 3.0,
    *,
    scores1: ArrayLike | None = None,
    scores2: ArrayLike | None = None,
    keep_k: int | None = None,
) -> float | NDArray[np.float64]:
    """Return the repeatability (fraction in [0, 1]) of two detections related by H, one value per eps.

    Thesis Eqs. 15-16 with SuperPoint's symmetric evaluation:
      1. keep the points of image 1 whose warp ``H x1`` lands inside image 2 (N1 of them) and the points of image 2
         whose warp ``H^-1 x2`` lands inside image 1 (N2); with ``keep_k`` only the ``keep_k`` best-scoring of each;
      2. ``Corr(x1_i) = min_j ||H x1_i - x2_j|| <= eps`` and ``Corr(x2_j) = min_i ||x2_j - H x1_i|| <= eps``
         (Eq. 15), both measured in image 2's frame;
      3. ``Rep = (sum_i Corr(x1_i) + sum_j Corr(x2_j)) / (N1 + N2)`` (Eq. 16).
    Eq. 16 of the thesis measures the second term in image 1's frame (``H^-1 x2_j`` against ``x1_i``); SuperPoint's
    code, which the thesis's numbers come from, measures both in image 2's frame, and so does this function. The two
    agree when H does not change scale. NaN when no point of either image lies in the shared view.

    Args:
        kp1: (N1, 2) keypoints (x, y) in image 1 pixels.
        kp2: (N2, 2) keypoints (x, y) in image 2 pixels.
        H: (3, 3) homography mapping image-1 pixels to image-2 pixels.
        shape1, shape2: (height, width) of image 1 and image 2.
        eps: distance threshold in pixels (image 2), or a sequence of them (e.g. (1, 3, 5)).
        scores1, scores2: (N1,), (N2,) detection scores (higher = stronger); needed with keep_k.
        keep_k: keep at most this many of the strongest points in the shared view of each image (thesis: 300).

    Returns:
        A float for a single eps, else an array with one repeatability per eps.

    Reference: thesis §3.2.6, Eqs. 15-16; SuperPoint (DeTone et al. 2018) §7.1 and ``compute_repeatability``.

    >>> kp = np.array([[10.0, 10.0], [30.0, 20.0], [50.0, 40.0]])
    >>> shift = np.array([[1.0, 0, 2], [0, 1.0, 0], [0, 0, 1]])       # image 2 = image 1 moved 2 px right
    >>> repeatability(kp, kp + [2, 0], shift, (60, 80), (60, 80), eps=[1, 3]).round(3)
    array([1., 1.])
    >>> repeatability(kp, kp + [4, 0], shift, (60, 80), (60, 80), eps=[1, 3]).round(3)   # 2 px off the truth
    array([0., 1.])
    """
    pts1, pts2, H, shape1, shape2 = _geometry_inputs(kp1, kp2, H, shape1, shape2)
    eps_values, scalar = _as_eps(eps)
    s1 = s2 = None
    if keep_k is not None:
        if isinstance(keep_k, bool) or not isinstance(keep_k, Integral) or keep_k < 1:
            raise ValueError(f"keep_k must be a positive integer or None; got {keep_k!r}")
        if scores1 is None or scores2 is None:
            raise ValueError("keep_k needs scores1 and scores2 (the detection scores) to pick the strongest points")
    if scores1 is not None:
        s1 = np.asarray(scores1, dtype=np.float64)
        if s1.shape != (len(pts1),):
            raise ValueError(f"scores1 must have shape (N1,) = ({len(pts1)},) like kp1; got {s1.shape}")
    if scores2 is not None:
        s2 = np.asarray(scores2, dtype=np.float64)
        if s2.shape != (len(pts2),):
            raise ValueError(f"scores2 must have shape (N2,) = ({len(pts2)},) like kp2; got {s2.shape}")

    d1, d2 = _shared_view_distances(pts1, pts2, H, shape1, shape2, s1, s2, keep_k)
    if len(d1) + len(d2) == 0:
        return _result(np.full(len(eps_values), np.nan), scalar)
    count = (d1[:, None] <= eps_values).sum(axis=0) + (d2[:, None] <= eps_values).sum(axis=0)  # Eq. 15 per eps
    return _result(count / (len(d1) + len(d2)), scalar)  # Eq. 16


def _shared_view_distances(
    pts1: NDArray[np.float64],
    pts2: NDArray[np.float64],
    H: NDArray[np.float64],
    shape1: tuple[int, int],
    shape2: tuple[int, int],
    s1: NDArray[np.float64] | None = None,
    s2: NDArray[np.float64] | None = None,
    keep_k: int | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (d1, d2): each shared-view point's distance (image 2 frame) to the other image's nearest point.

    ``d1_i = min_j ||H x1_i - x2_j||`` over the points of image 1 that land inside image 2, ``d2_j = min_i ||x2_j -
    H x1_i||`` over the points of image 2 whose ``H^-1 x2_j`` lands inside image 1; with ``keep_k`` only the
    ``keep_k`` best-scoring of each side count.
    """
    warped1 = _warp(H, pts1, shape1)  # H x1, image 2 frame
    back2 = _warp(np.linalg.inv(H), pts2, shape2)  # H^-1 x2, image 1 frame
    keep1 = _keep_best(_inside(warped1, shape2), s1, keep_k)
    keep2 = _keep_best(_inside(back2, shape1), s2, keep_k)
    a, b = warped1[keep1], pts2[keep2]  # both in image 2's frame
    return _nearest_distance(a, b), _nearest_distance(b, a)


def localisation_error(
    kp1: ArrayLike,
    kp2: ArrayLike,
    H: ArrayLike,
    shape1: tuple[int, int],
    shape2: tuple[int, int],
    eps: float = 3.0,
) -> float:
    """Return the mean localisation error (px, image 2 frame) of the points that repeatability counts as found again.

    With the distances of :func:`repeatability` (Eq. 15, both directions, shared view only), ``d1_i = min_j ||H x1_i
    - x2_j||`` and ``d2_j = min_i ||x2_j - H x1_i||``, this is the mean of those that are at most ``eps``:
    ``(sum_{d1_i <= eps} d1_i + sum_{d2_j <= eps} d2_j) / #{d <= eps}`` (SuperPoint's "mean localisation error",
    DeTone et al. 2018, Table 3). A covariant detector scores ~0 under a pure shift of the image; one whose points
    stay on fixed positions of a grid scores about the part of the shift that the grid does not follow. NaN when no
    point is found again.

    Args:
        kp1, kp2: (N1, 2), (N2, 2) keypoints (x, y) in image 1 / image 2 pixels.
        H: (3, 3) homography mapping image-1 pixels to image-2 pixels.
        shape1, shape2: (height, width) of image 1 and image 2.
        eps: distance (px, finite, >= 0) within which a point counts as found again.

    >>> kp = np.array([[10.0, 10.0], [30.0, 20.0], [50.0, 40.0]])
    >>> shift = np.array([[1.0, 0, 2], [0, 1.0, 0], [0, 0, 1]])       # image 2 = image 1 moved 2 px right
    >>> localisation_error(kp, kp + [2.5, 0], shift, (60, 80), (60, 80))   # every point 0.5 px off
    0.5
    """
    pts1, pts2, H, shape1, shape2 = _geometry_inputs(kp1, kp2, H, shape1, shape2)
    eps_values, scalar = _as_eps(eps)
    if not scalar:
        raise ValueError(f"eps must be a single pixel threshold >= 0, not a sequence; got {eps!r}")
    d = np.concatenate(_shared_view_distances(pts1, pts2, H, shape1, shape2))
    found = d[d <= eps_values[0]]
    return float(found.mean()) if len(found) else math.nan


# ---------------------------------------------------------------------------------------------- homography
def corner_error(H_est: ArrayLike | None, H_true: ArrayLike, shape: tuple[int, int]) -> float:
    """Return the mean distance (pixels) between the four image corners warped by H_est and by H_true.

    ``e = 1/4 sum_j ||H_est c_j - H_true c_j||`` over the corners ``c_j`` of image 1 (pixel centres (0, 0),
    (W - 1, 0), (0, H - 1), (W - 1, H - 1)); inf when H_est is None (estimation failed), not finite, or sends a
    corner to infinity.

    Args:
        H_est: (3, 3) estimated homography (image 1 -> image 2), or None.
        H_true: (3, 3) ground-truth homography (image 1 -> image 2).
        shape: (height, width) of image 1.

    Reference: thesis §3.2.6, Eq. 17 (the inner mean); SuperPoint ``compute_homography``.

    >>> corner_error(np.eye(3) + [[0, 0, 3], [0, 0, 4], [0, 0, 0]], np.eye(3), (48, 64))   # shifted by (3, 4)
    5.0
    """
    H_true = _as_homography(H_true, "H_true")
    shape = as_image_shape(shape, "shape")
    if H_est is None:
        return math.inf
    H_est = np.asarray(H_est, dtype=np.float64)
    if H_est.shape != (3, 3):
        raise ValueError(f"H_est must be a (3, 3) homography or None; got shape {H_est.shape}")
    if not np.isfinite(H_est).all() or not np.abs(H_est).max() > 0.0:
        return math.inf
    height, width = shape
    corners = np.array([[0.0, 0.0], [width - 1.0, 0.0], [0.0, height - 1.0], [width - 1.0, height - 1.0]])
    true = _warp(H_true, corners, shape)
    est = _warp(H_est, corners, shape)
    error = np.linalg.norm(est - true, axis=1).mean()  # 1/4 sum_j ||c'_j - c^'_j||
    return float(error) if np.isfinite(error) else math.inf


def homography_correctness(
    H_est: ArrayLike | None, H_true: ArrayLike, shape: tuple[int, int], eps: EpsArg = 3.0
) -> bool | NDArray[np.bool_]:
    """Return whether H_est is correct: mean corner distance to H_true <= eps (thesis Eq. 17), one bool per eps.

    Averaging this over the image pairs of a data set gives the thesis's homography estimation correctness
    ``CorrH = 1/N sum_i [corner_error_i <= eps]``. A failed estimate (None) is never correct.

    Args:
        H_est: (3, 3) estimated homography (image 1 -> image 2), or None.
        H_true: (3, 3) ground-truth homography (image 1 -> image 2).
        shape: (height, width) of image 1.
        eps: threshold in pixels, or a sequence of them.

    Reference: thesis §3.2.6, Eq. 17; SuperPoint §7.2.

    >>> shifted = np.eye(3) + [[0, 0, 3], [0, 0, 4], [0, 0, 0]]   # every corner 5 px off
    >>> homography_correctness(shifted, np.eye(3), (48, 64), eps=[1, 3, 5]).tolist()
    [False, False, True]
    """
    eps_values, scalar = _as_eps(eps)
    correct = corner_error(H_est, H_true, shape) <= eps_values
    return bool(correct[0]) if scalar else correct


# ---------------------------------------------------------------------------------------------- matching
def descriptor_distances(desc1: ArrayLike, desc2: ArrayLike, binary: bool = False) -> NDArray[np.float64]:
    """Return the (N1, N2) distance matrix: L2 for float descriptors, Hamming (bits) for packed-bit uint8 ones.

    L2: ``||a - b||^2 = ||a||^2 + ||b||^2 - 2 a.b`` (one matrix product). Hamming on unpacked bits a, b in {0, 1}:
    ``popcount(a xor b) = |a| + |b| - 2 a.b`` (exact: integers far below float32's 2^24).

    Args:
        desc1: (N1, D) float descriptors, or (N1, B) uint8 packed bits (B bytes = 8 B bits) when binary.
        desc2: (N2, D) / (N2, B) likewise.
        binary: True for packed-bit descriptors (ORB, FREAK, BRIEF).

    >>> descriptor_distances(np.array([[0b1011], [0]], np.uint8), np.array([[0b0001]], np.uint8), binary=True)
    array([[2.],
           [1.]])
    """
    a = _as_descriptors(desc1, "desc1", binary)
    b = _as_descriptors(desc2, "desc2", binary)
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"desc1 and desc2 must have the same length D; got {a.shape[1]} and {b.shape[1]}")
    if binary:
        bits1 = np.unpackbits(a, axis=1).astype(np.float32)
        bits2 = np.unpackbits(b, axis=1).astype(np.float32)
        # popcount(a xor b) = |a| + |b| - 2 a.b
        ham = bits1.sum(1)[:, None] + bits2.sum(1)[None, :] - 2.0 * (bits1 @ bits2.T)
        return np.rint(ham).astype(np.float64)
    sq = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * (a @ b.T)  # ||a||^2 + ||b||^2 - 2 a.b
    return np.sqrt(np.maximum(sq, 0.0))


def _nearest_neighbours(distances: NDArray[np.float64]) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """Return, for each row, the column of its smallest distance (first on ties) and that distance."""
    nn = np.argmin(distances, axis=1)
    return nn, distances[np.arange(len(nn)), nn]


def match_descriptors(
    desc1: ArrayLike, desc2: ArrayLike, binary: bool = False, mutual: bool = True
) -> NDArray[np.int64]:
    """Return (M, 2) index pairs [i1, i2] of nearest-neighbour descriptor matches, sorted by i1.

    Each descriptor of image 1 is matched to its nearest neighbour in image 2 (L2 for float descriptors, Hamming for
    packed bits); with ``mutual`` only pairs that are each other's nearest neighbour are kept (cross-check, as
    ``cv2.BFMatcher(crossCheck=True)`` in SuperPoint's and the thesis's evaluation). Ties go to the lower index.

    Args:
        desc1: (N1, D) float or (N1, B) uint8 packed-bit descriptors of image 1.
        desc2: (N2, D) / (N2, B) descriptors of image 2.
        binary: True for packed-bit descriptors (Hamming distance).
        mutual: keep only mutual nearest neighbours.

    Reference: thesis §3.2.6 (OpenCV matching before findHomography); SuperPoint §7.2.

    >>> d1 = np.array([[1.0, 0.0], [0.0, 1.0], [0.6, 0.8]])
    >>> d2 = np.array([[0.0, 1.0], [1.0, 0.0]])
    >>> match_descriptors(d1, d2).tolist()                  # row 2's nearest (0) prefers row 1: dropped
    [[0, 1], [1, 0]]
    >>> match_descriptors(d1, d2, mutual=False).tolist()
    [[0, 1], [1, 0], [2, 0]]
    """
    distances = descriptor_distances(desc1, desc2, binary)
    n1, n2 = distances.shape
    if n1 == 0 or n2 == 0:
        return np.zeros((0, 2), dtype=np.int64)
    nn12, _ = _nearest_neighbours(distances)
    index1 = np.arange(n1)
    if mutual:
        nn21 = np.argmin(distances, axis=0)
        keep = nn21[nn12] == index1  # i -> j -> i
        index1 = index1[keep]
    return np.column_stack([index1, nn12[index1]]).astype(np.int64)


def estimate_homography(
    kp1: ArrayLike,
    kp2: ArrayLike,
    matches: ArrayLike,
    *,
    ransac_threshold: float = RANSAC_THRESHOLD,
    max_iters: int = RANSAC_MAX_ITERS,
    confidence: float = RANSAC_CONFIDENCE,
) -> tuple[NDArray[np.float64] | None, NDArray[np.bool_]]:
    """Return (H, inliers): the RANSAC homography image 1 -> image 2 (H[2, 2] = 1, or None) and the (M,) inlier mask.

    ``cv2.findHomography(x1[matches[:, 0]], x2[matches[:, 1]], cv2.RANSAC)`` with OpenCV's default settings
    (reprojection threshold 3 px, 2000 iterations, confidence 0.995), as the thesis does. H is None (and no match an
    inlier) with fewer than 4 matches or when OpenCV finds no homography. OpenCV's RANSAC is deterministic.

    Args:
        kp1: (N1, 2) keypoints (x, y) of image 1.
        kp2: (N2, 2) keypoints (x, y) of image 2.
        matches: (M, 2) int index pairs [i1, i2] (``match_descriptors``).
        ransac_threshold: largest reprojection error (pixels, image 2) of an inlier.
        max_iters: RANSAC iterations.
        confidence: RANSAC confidence in (0, 1).

    Reference: thesis §3.2.6; OpenCV ``findHomography``.

    >>> kp1 = np.array([[0.0, 0], [100, 0], [0, 80], [100, 80], [50, 40]])
    >>> H, inliers = estimate_homography(kp1, kp1 + [5, -3], np.column_stack([np.arange(5)] * 2))
    >>> H.round(6) + 0.0, inliers.all()
    (array([[ 1.,  0.,  5.],
           [ 0.,  1., -3.],
           [ 0.,  0.,  1.]]), np.True_)
    """
    pts1 = _as_points(kp1, "kp1")
    pts2 = _as_points(kp2, "kp2")
    pairs = np.asarray(matches)
    if pairs.ndim == 1 and pairs.size == 0:
        pairs = pairs.reshape(0, 2)
    if pairs.ndim != 2 or pairs.shape[1] != 2 or not (np.issubdtype(pairs.dtype, np.integer) or pairs.size == 0):
        raise ValueError(
            f"matches must be an (M, 2) int array of [i1, i2] index pairs; got {pairs.dtype} {pairs.shape}"
        )
    pairs = pairs.astype(np.int64)
    if len(pairs) and (
        (pairs < 0).any() or pairs[:, 0].max() >= len(pts1) or pairs[:, 1].max() >= len(pts2)
    ):
        raise ValueError(
            f"matches must index kp1 (0..{len(pts1) - 1}) and kp2 (0..{len(pts2) - 1}); got values outside that range"
        )
    for name, value, low, high in (("ransac_threshold", ransac_threshold, 0.0, math.inf),
                                   ("confidence", confidence, 0.0, 1.0)):
        if isinstance(value, bool) or not isinstance(value, Real) or not (low < value <= high) or math.isnan(value):
            raise ValueError(f"{name} must be a number in ({low}, {high}]; got {value!r}")
    if isinstance(max_iters, bool) or not isinstance(max_iters, Integral) or max_iters < 1:
        raise ValueError(f"max_iters must be a positive integer; got {max_iters!r}")
    no_inliers = np.zeros(len(pairs), dtype=bool)
    if len(pairs) < 4:
        return None, no_inliers
    src = pts1[pairs[:, 0]].astype(np.float32)
    dst = pts2[pairs[:, 1]].astype(np.float32)
    H, mask = cv2.findHomography(
        src, dst, cv2.RANSAC, float(ransac_threshold), maxIters=int(max_iters), confidence=float(confidence)
    )
    if H is None or not np.isfinite(H).all() or abs(H[2, 2]) < 1e-12:
        return None, no_inliers
    return H / H[2, 2], mask.ravel().astype(bool)


# ---------------------------------------------------------------------------------------------- descriptor metrics
def _directional_matches(
    pts1: NDArray[np.float64],
    pts2: NDArray[np.float64],
    distances: NDArray[np.float64],
    H: NDArray[np.float64],
    shape1: tuple[int, int],
    shape2: tuple[int, int],
) -> list[tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]]:
    """Return, for the directions 1 -> 2 and 2 -> 1, (descriptor distance, pixel error, best pixel error) per query.

    Queries are the points in the shared view. The pixel error is that of the query's nearest-neighbour descriptor
    match, the best pixel error that of the closest detection of the other image; both in image 2's frame.
    """
    warped1 = _warp(H, pts1, shape1)  # H x1 (image 2 frame)
    back2 = _warp(np.linalg.inv(H), pts2, shape2)
    out = []
    # direction 1 -> 2: query x1_i, candidates x2_j
    q1 = np.flatnonzero(_inside(warped1, shape2))
    if len(q1) and len(pts2):
        nn, d = _nearest_neighbours(distances[q1])
        error = np.linalg.norm(warped1[q1] - pts2[nn], axis=1)  # ||H x1_i - x2_nn(i)||
        best = _nearest_distance(warped1[q1], pts2)  # min_j ||H x1_i - x2_j||
        out.append((d, error, best))
    else:
        out.append((np.zeros(len(q1)), np.full(len(q1), np.inf), np.full(len(q1), np.inf)))
    # direction 2 -> 1: query x2_j, candidates x1_i (those with a finite warp)
    q2 = np.flatnonzero(_inside(back2, shape1))
    finite1 = np.flatnonzero(np.isfinite(warped1[:, 0]))
    if len(q2) and len(finite1):
        nn, d = _nearest_neighbours(distances[:, q2].T)
        with np.errstate(invalid="ignore"):
            error = np.linalg.norm(pts2[q2] - warped1[nn], axis=1)  # ||x2_j - H x1_nn(j)||
        error = np.where(np.isfinite(error), error, np.inf)
        best = _nearest_distance(pts2[q2], warped1[finite1])
        out.append((d, error, best))
    else:
        out.append((np.zeros(len(q2)), np.full(len(q2), np.inf), np.full(len(q2), np.inf)))
    return out


def _descriptor_inputs(kp1, kp2, desc1, desc2, H, shape1, shape2, binary):  # type: ignore[no-untyped-def]
    """Validate the common arguments of matching_score and mean_average_precision."""
    pts1, pts2, H, shape1, shape2 = _geometry_inputs(kp1, kp2, H, shape1, shape2)
    distances = descriptor_distances(desc1, desc2, binary)
    if distances.shape != (len(pts1), len(pts2)):
        raise ValueError(
            f"desc1/desc2 must have one row per keypoint: kp1 has {len(pts1)} and kp2 {len(pts2)} rows, "
            f"the descriptors {distances.shape[0]} and {distances.shape[1]}"
        )
    return pts1, pts2, distances, H, shape1, shape2


def matching_score(
    kp1: ArrayLike,
    kp2: ArrayLike,
    desc1: ArrayLike,
    desc2: ArrayLike,
    H: ArrayLike,
    shape1: tuple[int, int],
    shape2: tuple[int, int],
    eps: EpsArg = 3.0,
    binary: bool = False,
) -> float | NDArray[np.float64]:
    """Return the matching score (fraction in [0, 1]) of detector + descriptor on one image pair, one per eps.

    Definition (Mikolajczyk & Schmid 2005, as evaluated by SuperPoint and D2-Net): the ratio of correct matches found
    by the whole pipeline to the number of features it proposes in the shared view. For direction 1 -> 2, each point
    x1_i of image 1 whose warp lands in image 2 is matched to its nearest-neighbour descriptor x2_nn(i) among all
    points of image 2 (no cross-check); it is correct when ``||H x1_i - x2_nn(i)|| <= eps``;
    ``MS_12 = #correct / #points of image 1 in the shared view``. Direction 2 -> 1 likewise (distances again in image
    2's frame), and ``MS = (MS_12 + MS_21) / 2`` (the mean of the directions that have points; NaN if none has).

    Args:
        kp1, kp2: (N1, 2), (N2, 2) keypoints (x, y) of image 1 and image 2.
        desc1, desc2: (N1, D), (N2, D) descriptors (float, or uint8 packed bits when binary).
        H: (3, 3) homography mapping image-1 pixels to image-2 pixels.
        shape1, shape2: (height, width) of image 1 and image 2.
        eps: correctness threshold in pixels, or a sequence of them.
        binary: True for packed-bit descriptors (Hamming distance).

    Reference: Mikolajczyk & Schmid, PAMI 2005; DeTone et al. 2018 §7.2 (M. Score); thesis §5 (future work).

    >>> kp = np.array([[10.0, 10.0], [40.0, 10.0], [10.0, 40.0], [40.0, 40.0]])
    >>> desc = np.eye(4)
    >>> matching_score(kp, kp, desc, desc[[0, 1, 3, 2]], np.eye(3), (50, 50), (50, 50))  # two of four swapped
    0.5
    """
    pts1, pts2, distances, H, s1, s2 = _descriptor_inputs(kp1, kp2, desc1, desc2, H, shape1, shape2, binary)
    eps_values, scalar = _as_eps(eps)
    scores = []
    for _, error, _ in _directional_matches(pts1, pts2, distances, H, s1, s2):
        if len(error):
            scores.append((error[:, None] <= eps_values).mean(axis=0))  # #correct / #in shared view
    if not scores:
        return _result(np.full(len(eps_values), np.nan), scalar)
    return _result(np.mean(scores, axis=0), scalar)


def average_precision(distances: ArrayLike, correct: ArrayLike, n_positive: int) -> float:
    """Return the average precision of matches ranked by descriptor distance (smaller = more confident).

    Sweeping a threshold t over the distinct distances, precision ``P(t) = TP(t) / #matches with d <= t`` and recall
    ``R(t) = TP(t) / n_positive``; ``AP = sum_t (R(t) - R(t_prev)) P(t)``, the area under the step precision-recall
    curve (matches with equal distances enter together). ``n_positive`` counts the queries that have a correct
    partner at all, so AP < 1 when the matcher misses some. NaN when n_positive is 0.

    Args:
        distances: (M,) descriptor distance of each query's nearest-neighbour match.
        correct: (M,) bool, whether that match is geometrically correct.
        n_positive: number of queries with a correct partner (>= correct.sum()).

    Reference: Balntas et al., "HPatches", CVPR 2017 (mAP); DeTone et al. 2018 §7.2 (NN mAP).

    >>> round(average_precision([0.1, 0.2, 0.3, 0.4], [True, False, True, False], 3), 4)   # (1/1 + 2/3) / 3
    0.5556
    """
    d = np.asarray(distances, dtype=np.float64)
    c = np.asarray(correct)
    if d.ndim != 1 or c.shape != d.shape:
        raise ValueError(f"distances and correct must be 1-D arrays of equal length (M,); got {d.shape} and {c.shape}")
    if c.dtype != bool:
        raise ValueError(f"correct must be a bool array; got dtype {c.dtype}")
    if np.isnan(d).any():
        raise ValueError("distances must not contain NaN")
    n_correct = int(c.sum())
    if isinstance(n_positive, bool) or not isinstance(n_positive, Integral) or n_positive < n_correct:
        raise ValueError(
            f"n_positive must be an integer >= the number of correct matches ({n_correct}); got {n_positive!r}"
        )
    if n_positive == 0:
        return math.nan
    if len(d) == 0:
        return 0.0
    order = np.argsort(d, kind="stable")
    d_sorted, c_sorted = d[order], c[order]
    tp = np.cumsum(c_sorted)
    count = np.arange(1, len(d) + 1)
    last = np.append(d_sorted[1:] != d_sorted[:-1], True)  # last match of each group of equal distances
    precision = tp[last] / count[last]  # P(t) = TP(t) / #(d <= t)
    recall = tp[last] / n_positive  # R(t) = TP(t) / n_positive
    return float(np.sum(np.diff(recall, prepend=0.0) * precision))  # sum_t (R(t) - R(t_prev)) P(t)


def mean_average_precision(
    kp1: ArrayLike,
    kp2: ArrayLike,
    desc1: ArrayLike,
    desc2: ArrayLike,
    H: ArrayLike,
    shape1: tuple[int, int],
    shape2: tuple[int, int],
    eps: EpsArg = 3.0,
    binary: bool = False,
) -> float | NDArray[np.float64]:
    """Return the nearest-neighbour mean average precision (in [0, 1]) of one image pair, one value per eps.

    Definition (SuperPoint's "NN mAP", after HPatches): in direction 1 -> 2 every point of image 1 in the shared view
    is a query, matched to its nearest-neighbour descriptor in image 2 with distance d; the match is correct when
    ``||H x1_i - x2_nn(i)|| <= eps``, and the query is a positive when some detection of image 2 lies within eps of
    ``H x1_i``. Ranking the queries by d gives a precision-recall curve whose area is the average precision
    (``average_precision``); direction 2 -> 1 likewise, and the result is the mean over the directions (NaN when
    neither has a positive). Averaging it over the pairs of a data set gives the benchmark's mAP. Unlike the matching
    score it rewards descriptors whose distances rank correct matches first.

    Args:
        kp1, kp2: (N1, 2), (N2, 2) keypoints (x, y) of image 1 and image 2.
        desc1, desc2: (N1, D), (N2, D) descriptors (float, or uint8 packed bits when binary).
        H: (3, 3) homography mapping image-1 pixels to image-2 pixels.
        shape1, shape2: (height, width) of image 1 and image 2.
        eps: correctness threshold in pixels, or a sequence of them.
        binary: True for packed-bit descriptors (Hamming distance).

    Reference: DeTone et al. 2018 §7.2 (NN mAP); Balntas et al., CVPR 2017; thesis §5 (future work).

    >>> kp = np.array([[10.0, 10.0], [40.0, 10.0], [10.0, 40.0], [40.0, 40.0]])
    >>> desc = np.eye(4)
    >>> float(mean_average_precision(kp, kp, desc, desc, np.eye(3), (50, 50), (50, 50)))
    1.0
    """
    pts1, pts2, distances, H, s1, s2 = _descriptor_inputs(kp1, kp2, desc1, desc2, H, shape1, shape2, binary)
    eps_values, scalar = _as_eps(eps)
    per_direction = []
    for d, error, best in _directional_matches(pts1, pts2, distances, H, s1, s2):
        ap = [average_precision(d, error <= e, int((best <= e).sum())) for e in eps_values]  # a loop over eps only
        per_direction.append(ap)
    values = np.array(per_direction, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        valid = ~np.isnan(values)
        mean = np.where(valid.any(axis=0), np.nansum(values, axis=0) / np.maximum(valid.sum(axis=0), 1), np.nan)
    return _result(mean, scalar)


# ---------------------------------------------------------------------------------------------- diagnosis
class MatchDiagnosis(NamedTuple):
    """Where a homography estimate goes wrong on one pair (see :func:`diagnose_matches`).

    Attributes:
        n_matches: mutual nearest-neighbour descriptor matches (the benchmark's matches).
        n_correct: those whose error ``||H x1 - x2||`` (image 2 frame) is at most ``eps``.
        localisation_error: mean error (px) of the correct matches; NaN without any.
        corner_error_ransac: corner error (Eq. 17, px) of the benchmark's RANSAC estimate from all matches.
        corner_error_oracle: corner error of the least-squares homography fitted to the correct matches alone,
            as if outlier rejection were perfect; inf with fewer than 4 of them.
    """

    n_matches: int
    n_correct: int
    localisation_error: float
    corner_error_ransac: float
    corner_error_oracle: float


def diagnose_matches(
    kp1: ArrayLike,
    kp2: ArrayLike,
    desc1: ArrayLike,
    desc2: ArrayLike,
    H: ArrayLike,
    shape1: tuple[int, int],
    eps: float = 3.0,
    binary: bool = False,
) -> MatchDiagnosis:
    """Return a :class:`MatchDiagnosis`: why the homography of one pair is (in)correct.

    The benchmark's pipeline is matching (mutual nearest neighbours), then RANSAC, then the corner error of Eq. 17.
    Splitting it tells a matching failure from a localisation failure:

    * ``n_correct`` of ``n_matches`` matches have reprojection error ``e_k = ||H x1_k - x2_k|| <= eps``;
    * their mean error ``mean_k e_k`` is the keypoints' localisation error (both images' errors together);
    * the *oracle* homography minimises ``sum_k ||H' x1_k - x2_k||^2`` over the correct matches only
      (``cv2.findHomography`` with method 0: DLT, then Levenberg-Marquardt). Its corner error is the best that
      any outlier rejection could reach with these keypoints. If the oracle is off by more than eps, more or better
      localised correct matches are needed, not better RANSAC. Least squares averages independent errors, so the
      oracle's error shrinks about as ``localisation error / sqrt(n_correct)``, times a factor that grows when the
      matches cover little of image 1 and the corners lie far outside them.

    Args:
        kp1, kp2: (N1, 2), (N2, 2) keypoints (x, y) of image 1 and image 2.
        desc1, desc2: (N1, D), (N2, D) descriptors (float, or uint8 packed bits when binary).
        H: (3, 3) ground-truth homography mapping image-1 pixels to image-2 pixels.
        shape1: (height, width) of image 1 (its corners enter Eq. 17).
        eps: correctness threshold of a match in pixels (image 2 frame).
        binary: True for packed-bit descriptors (Hamming distance).

    Reference: thesis §3.2.6, Eq. 17; Hartley & Zisserman, *Multiple View Geometry*, 2nd ed., §4.1 (DLT) and
    §5.1.3 (the error of a least-squares estimate falls as the number of points grows).

    >>> kp = np.array([[0.0, 0], [60, 0], [0, 40], [60, 40], [30, 20], [10, 30]])
    >>> d = diagnose_matches(kp, kp + [2.0, 0.0], np.eye(6), np.eye(6), np.eye(3), (41, 61))
    >>> d.n_matches, d.n_correct, d.localisation_error, round(d.corner_error_oracle, 6)   # a 2 px shift, no noise
    (6, 6, 2.0, 2.0)
    """
    pts1 = _as_points(kp1, "kp1")
    pts2 = _as_points(kp2, "kp2")
    H_true = _as_homography(H, "H")
    shape1 = as_image_shape(shape1, "shape1")
    if isinstance(eps, bool) or not isinstance(eps, Real) or not eps > 0.0 or not math.isfinite(eps):
        raise ValueError(f"eps must be a positive number of pixels; got {eps!r}")
    rows = (len(np.asarray(desc1)), len(np.asarray(desc2)))
    if rows != (len(pts1), len(pts2)):
        raise ValueError(f"desc1/desc2 must have one row per keypoint: kp1 has {len(pts1)} and kp2 {len(pts2)} rows, "
                         f"the descriptors {rows[0]} and {rows[1]}")
    matches = match_descriptors(desc1, desc2, binary=binary)
    src, dst = pts1[matches[:, 0]], pts2[matches[:, 1]]
    with np.errstate(invalid="ignore"):
        error = np.linalg.norm(_warp(H_true, src, shape1) - dst, axis=1)  # ||H x1_k - x2_k||, NaN behind the camera
    correct = np.nan_to_num(error, nan=np.inf) <= eps
    H_ransac, _ = estimate_homography(pts1, pts2, matches)
    oracle = None
    if correct.sum() >= 4:
        oracle, _ = cv2.findHomography(src[correct].astype(np.float64), dst[correct].astype(np.float64), 0)
    return MatchDiagnosis(
        n_matches=int(len(matches)),
        n_correct=int(correct.sum()),
        localisation_error=float(error[correct].mean()) if correct.any() else math.nan,
        corner_error_ransac=corner_error(H_ransac, H_true, shape1),
        corner_error_oracle=corner_error(oracle, H_true, shape1),
    )
