"""Training metrics of the detector: precision and recall of detections against labels, exact and within a tolerance.

With binary maps y_pred (detections) and y_true (labels) of shape (H, W):

- precision (Eq. 13): ``p = sum(y_true * y_pred) / sum(y_pred)``
- recall (Eq. 14): ``r = sum(y_true * y_pred) / sum(y_true)``

The thresholded versions (thesis §3.2.4.2, "within one pixel") count a detection as correct when a label lies
within Euclidean distance ``tolerance`` of it, and a label as found when a detection lies within ``tolerance``:
``p_t = #{pred with a label within t} / #pred``, ``r_t = #{labels with a pred within t} / #labels`` (at t = 0 these
are Eqs. 13-14). Tolerance 1 therefore accepts the 4-neighbours but not the diagonal ones (sqrt 2 px away). Pixels
outside ``valid_mask`` (warp fill) are ignored in both maps. Over a batch, counts are summed before dividing
(micro average).

Reference: thesis §3.2.4.2, Eqs. 13-14.
"""
from __future__ import annotations

import math
from numbers import Real
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

__all__ = ["keypoints_to_map", "DetectionCounts", "detection_counts", "precision_recall"]


def _as_maps(value: object, name: str) -> NDArray[np.bool_]:
    """Return a (B, H, W) bool array from a (H, W) / (B, H, W) array or torch tensor (values >= 0.5 are True)."""
    if hasattr(value, "detach"):  # torch tensor
        value = value.detach().cpu().numpy()
    arr = np.asarray(value)
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == np.bool_):
        raise ValueError(f"{name} must be a numeric or bool map of shape (H, W) or (B, H, W); got dtype {arr.dtype}")
    if arr.ndim == 2:
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[1] == 0 or arr.shape[2] == 0:
        raise ValueError(f"{name} must have shape (H, W) or (B, H, W); got {arr.shape}")
    return arr >= 0.5 if arr.dtype != np.bool_ else arr


def keypoints_to_map(keypoints: ArrayLike, shape: tuple[int, int]) -> NDArray[np.bool_]:
    """Return a bool (H, W) map that is True at the pixels nearest to (N, 2) keypoints (x, y); outside ones are dropped.

    >>> keypoints_to_map([[1.2, 0.4], [2.6, 1.3], [9.0, 0.0]], (2, 4)).astype(int)
    array([[0, 1, 0, 0],
           [0, 0, 0, 1]])
    """
    kp = np.asarray(keypoints, dtype=np.float64)
    if kp.size == 0:
        kp = kp.reshape(0, 2)
    if kp.ndim != 2 or kp.shape[1] != 2 or not np.isfinite(kp).all():
        raise ValueError(f"keypoints must be a finite (N, 2) array of (x, y) pixels; got shape {kp.shape}")
    try:
        height, width = (int(s) for s in shape)
    except (TypeError, ValueError):
        raise ValueError(f"shape must be (H, W); got {shape!r}") from None
    if height < 1 or width < 1:
        raise ValueError(f"shape must be (H, W) of positive integers; got {shape!r}")
    cols = np.rint(kp[:, 0]).astype(np.int64)  # nearest pixel centre
    rows = np.rint(kp[:, 1]).astype(np.int64)
    inside = (cols >= 0) & (cols < width) & (rows >= 0) & (rows < height)
    out = np.zeros((height, width), bool)
    out[rows[inside], cols[inside]] = True
    return out


class DetectionCounts(NamedTuple):
    """Per-image counts (each an int64 array of shape (B,)) behind precision and recall."""

    correct_predictions: NDArray[np.int64]  # detections with a label within the tolerance
    predictions: NDArray[np.int64]  # detections (inside the valid mask)
    found_labels: NDArray[np.int64]  # labels with a detection within the tolerance
    labels: NDArray[np.int64]  # labels (inside the valid mask)


def _disk(tolerance: float) -> NDArray[np.bool_]:
    """Return the (1, k, k) footprint of pixel offsets with Euclidean length <= tolerance."""
    r = int(math.floor(tolerance))
    dy, dx = np.mgrid[-r : r + 1, -r : r + 1]
    return (dx * dx + dy * dy <= tolerance * tolerance + 1e-9)[None]  # (1, k, k): no mixing across the batch


def detection_counts(
    pred: ArrayLike, true: ArrayLike, *, valid_mask: ArrayLike | None = None, tolerance: float = 0.0
) -> DetectionCounts:
    """Return the per-image counts of correct detections, detections, found labels and labels.

    Args:
        pred: (H, W) or (B, H, W) detection map (values >= 0.5 or True are detections); numpy or torch.
        true: label map of the same shape.
        valid_mask: optional map of the same shape; pixels where it is False/0 are ignored.
        tolerance: maximum Euclidean distance in pixels between a detection and its label (0 = same pixel).

    >>> pred = np.zeros((5, 5)); true = np.zeros((5, 5)); pred[1, 1] = pred[3, 3] = 1; true[1, 2] = 1
    >>> detection_counts(pred, true, tolerance=1)
    DetectionCounts(correct_predictions=array([1]), predictions=array([2]), found_labels=array([1]), labels=array([1]))
    """
    p = _as_maps(pred, "pred")
    t = _as_maps(true, "true")
    if p.shape != t.shape:
        raise ValueError(f"true must have the shape of pred {p.shape}; got {t.shape}")
    if valid_mask is not None:
        valid = _as_maps(valid_mask, "valid_mask")
        if valid.shape != p.shape:
            raise ValueError(f"valid_mask must have the shape of pred {p.shape}; got {valid.shape}")
        p = p & valid
        t = t & valid
    if isinstance(tolerance, bool) or not isinstance(tolerance, Real) or not math.isfinite(tolerance) or tolerance < 0:
        raise ValueError(f"tolerance must be a finite number of pixels >= 0; got {tolerance!r}")
    if tolerance < 1.0:  # no other pixel centre is that close: exact matching, y_true * y_pred
        hit_pred = p & t
        hit_true = hit_pred
    else:
        disk = _disk(float(tolerance))
        hit_pred = p & ndimage.binary_dilation(t, structure=disk)  # a label within tolerance of the detection
        hit_true = t & ndimage.binary_dilation(p, structure=disk)  # a detection within tolerance of the label
    def count(m: NDArray[np.bool_]) -> NDArray[np.int64]:
        return m.sum(axis=(1, 2)).astype(np.int64)

    return DetectionCounts(count(hit_pred), count(p), count(hit_true), count(t))


def precision_recall(
    pred: ArrayLike,
    true: ArrayLike,
    *,
    valid_mask: ArrayLike | None = None,
    tolerance: float = 0.0,
    zero_division: float = 0.0,
) -> tuple[float, float]:
    """Return (precision, recall) of detections against labels, summed over the batch (Eqs. 13-14).

    ``precision = sum(correct detections) / sum(detections)``, ``recall = sum(found labels) / sum(labels)``, with
    ``zero_division`` returned for an empty denominator (no detections / no labels; use NaN to make it visible).

    Args:
        pred, true, valid_mask, tolerance: see :func:`detection_counts` (tolerance 1 = the thesis's "within one
            pixel" variant).
        zero_division: value for 0 / 0.

    >>> true = np.zeros((4, 4)); true[1, 1] = true[2, 3] = 1
    >>> pred = np.zeros((4, 4)); pred[1, 1] = pred[0, 0] = pred[3, 3] = 1
    >>> precision_recall(pred, true)                  # 1 of 3 detections exact, 1 of 2 labels found
    (0.3333333333333333, 0.5)
    >>> precision_recall(pred, true, tolerance=1)     # (3, 3) is 1 px from the label (2, 3)
    (0.6666666666666666, 1.0)
    """
    if isinstance(zero_division, bool) or not isinstance(zero_division, Real):
        raise ValueError(f"zero_division must be a number (e.g. 0.0 or nan); got {zero_division!r}")
    counts = detection_counts(pred, true, valid_mask=valid_mask, tolerance=tolerance)
    n_pred, n_true = int(counts.predictions.sum()), int(counts.labels.sum())
    precision = int(counts.correct_predictions.sum()) / n_pred if n_pred else float(zero_division)  # Eq. 13
    recall = int(counts.found_labels.sum()) / n_true if n_true else float(zero_division)  # Eq. 14
    return precision, recall
