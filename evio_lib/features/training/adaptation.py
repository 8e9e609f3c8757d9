"""Homographic adaptation: a detector's response averaged over many random warps of the same image.

SuperPoint's self-supervision step (thesis §3.2.5.2, "Exporting Detections"): to label an image without ground
truth, warp it by N random homographies ``H_i`` (``H_0`` = identity, default N = 100), run the detector on every
warped copy, map each response back to the original frame and average over the views that saw each pixel::

    F(I; f) = sum_i c_i(u) f(H_i I)(H_i u) / sum_i c_i(u),        c_i(u) = 1 if H_i u is a valid pixel of view i

where ``(H_i I)(v) = I(H_i^-1 v)`` is the warped image and ``c_i`` is 1 where view i saw the source image
(valid mask eroded by ``valid_border_margin`` so that responses to the artificial border are ignored). A
detector that is equivariant to homographies gives back its own response; the average suppresses the
detections that depend on the viewpoint, which makes the labels more repeatable. The response maps back by
bilinear sampling ``f_i(H_i u)`` and the count by nearest-neighbour sampling of the eroded mask.

Reference: thesis §3.2.5.2; DeTone, Malisiewicz & Rabinovich, "SuperPoint", CVPRW 2018, §5 (Eq. 10-11).
"""
from __future__ import annotations

import math
from numbers import Integral, Real
from typing import Any, Callable, NamedTuple, Sequence

import cv2
import numpy as np

from evio_lib.features.base import nms_keypoints
from evio_lib.features.training.augment import HOMOGRAPHIC_ADAPTATION, HomographicConfig, as_rng, check_image
from evio_lib.geometry.homography import valid_mask, warp_image

__all__ = [
    "AdaptationResult",
    "adaptation_homographies",
    "homographic_adaptation",
    "heatmap_to_keypoints",
    "label_images",
]

HeatmapFn = Callable[[np.ndarray], Any]


class AdaptationResult(NamedTuple):
    """Result of :func:`homographic_adaptation`."""

    heatmap: np.ndarray  #: (H, W) float32 aggregated response (0 where no view counted)
    counts: np.ndarray  #: (H, W) int32 number of views that saw each pixel
    homographies: np.ndarray  #: (N, 3, 3) float64, source pixels -> view pixels; [0] is the identity


def _positive_int(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, Integral) or value < 1:
        raise ValueError(f"{name} must be a positive int; got {value!r}")
    return int(value)


def adaptation_homographies(shape: tuple[int, int], n_homographies: int, rng: np.random.Generator | int,
                            config: HomographicConfig = HOMOGRAPHIC_ADAPTATION) -> np.ndarray:
    """Return (N, 3, 3) homographies: the identity, then N - 1 random ones drawn with ``config``.

    Args:
        shape: (height, width) of the image.
        n_homographies: N >= 1 (the identity counts as one).
        rng: Generator or seed.
        config: random-homography parameters (SuperPoint's adaptation preset by default).

    >>> Hs = adaptation_homographies((48, 64), 3, rng=0)
    >>> Hs.shape, bool(np.array_equal(Hs[0], np.eye(3)))
    ((3, 3, 3), True)
    """
    n = _positive_int(n_homographies, "n_homographies")
    if not isinstance(config, HomographicConfig):
        raise ValueError(f"config must be a HomographicConfig; got {type(config).__name__}")
    gen = as_rng(rng)
    out = np.empty((n, 3, 3))
    out[0] = np.eye(3)
    for i in range(1, n):
        out[i] = config.sample(tuple(shape)[:2], gen)
    return out


def _call_detector(heatmap_fn: HeatmapFn, batch: np.ndarray) -> np.ndarray:
    """Return heatmap_fn(batch) as a float32 (B, H, W) NumPy array (torch tensors are detached and moved to CPU)."""
    out = heatmap_fn(batch)
    if hasattr(out, "detach"):
        out = out.detach().cpu().numpy()
    out = np.asarray(out, dtype=np.float32)
    if out.shape != batch.shape:
        raise ValueError(f"heatmap_fn must return heatmaps of shape {batch.shape} (B, H, W) for images of that "
                         f"shape; got {out.shape}")
    if not np.isfinite(out).all():
        raise ValueError("heatmap_fn returned NaN or inf values")
    return out


def homographic_adaptation(image: np.ndarray, heatmap_fn: HeatmapFn, rng: np.random.Generator | int,
                           n_homographies: int = 100, config: HomographicConfig = HOMOGRAPHIC_ADAPTATION,
                           batch_size: int = 16, aggregation: str = "mean", min_count: int = 1,
                           homographies: np.ndarray | None = None) -> AdaptationResult:
    """Return the detector response of ``image`` aggregated over random homographic warps (+ counts, homographies).

    ``heatmap_fn`` is called on batches of warped copies, ``(B, H, W)`` float32 in [0, 1] -> ``(B, H, W)``
    responses (NumPy or torch). With ``aggregation="mean"`` the result is ``sum_i c_i f_i(H_i u) / sum_i c_i``
    (module docstring); ``"max"`` takes the largest counted response instead. Pixels seen by fewer than
    ``min_count`` views are set to 0. Deterministic for a given seed and independent of ``batch_size``.

    Args:
        image: (H, W) float32 image in [0, 1] (or uint8).
        heatmap_fn: detector, ``images (B, H, W) float32 -> heatmaps (B, H, W)``.
        rng: Generator or seed for the homographies.
        n_homographies: N, number of views including the identity (thesis: 100).
        config: random-homography parameters and the valid-border margin.
        batch_size: views per call of ``heatmap_fn``.
        aggregation: "mean" (SuperPoint) or "max".
        min_count: minimum number of views for a pixel to keep its response.
        homographies: optional fixed (N, 3, 3) homographies (then ``rng``/``n_homographies`` are unused).

    Reference: thesis §3.2.5.2; SuperPoint §5.

    >>> img = np.tile(np.linspace(0, 1, 64, dtype=np.float32), (48, 1))
    >>> res = homographic_adaptation(img, lambda b: b, rng=0, n_homographies=8)  # the identity detector
    >>> res.heatmap.shape, int(res.counts.min()) >= 1, round(float(np.abs(res.heatmap - img).max()), 2)
    ((48, 64), True, 0.0)
    """
    img = check_image(image)
    if not callable(heatmap_fn):
        raise ValueError(f"heatmap_fn must be callable (images (B, H, W) -> heatmaps (B, H, W)); got {heatmap_fn!r}")
    if aggregation not in ("mean", "max"):
        raise ValueError(f"aggregation must be 'mean' or 'max'; got {aggregation!r}")
    batch_size = _positive_int(batch_size, "batch_size")
    min_count = _positive_int(min_count, "min_count")
    if homographies is None:
        Hs = adaptation_homographies(img.shape, n_homographies, rng, config)
    else:
        Hs = np.asarray(homographies, dtype=np.float64)
        if Hs.ndim != 3 or Hs.shape[1:] != (3, 3) or len(Hs) < 1:
            raise ValueError(f"homographies must have shape (N, 3, 3) with N >= 1; got {Hs.shape}")
    margin = int(config.valid_border_margin)
    height, width = img.shape
    total = np.full((height, width), 0.0 if aggregation == "mean" else -np.inf, np.float64)
    counts = np.zeros((height, width), np.int32)
    for start in range(0, len(Hs), batch_size):  # loop over batches of views, not pixels
        chunk = Hs[start : start + batch_size]
        views = np.stack([warp_image(img, H) for H in chunk])  # (H_i I)(v) = I(H_i^-1 v), 0 outside
        responses = _call_detector(heatmap_fn, views)
        for H, response in zip(chunk, responses):
            H_inv = np.linalg.inv(H)
            mask = valid_mask(img.shape, H, erode=margin).astype(np.float32)  # view pixels that saw the image
            seen = warp_image(mask, H_inv, interpolation=cv2.INTER_NEAREST) > 0.5  # c_i(u) = mask(H_i u)
            # f_i(H_i u), bilinear; H_i u may lie up to half a pixel outside the view's frame where the nearest
            # pixel is counted, so the frame edge is replicated rather than mixed with zeros
            back = cv2.warpPerspective(response, H_inv, (width, height), flags=cv2.INTER_LINEAR,
                                       borderMode=cv2.BORDER_REPLICATE)
            if aggregation == "mean":
                total[seen] += back[seen]  # sum_i c_i f_i(H_i u)
            else:
                total[seen] = np.maximum(total[seen], back[seen])  # max_i over counted views
            counts += seen
    if aggregation == "mean":
        heatmap = np.where(counts > 0, total / np.maximum(counts, 1), 0.0)  # sum_i c_i f_i / sum_i c_i
    else:
        heatmap = np.where(counts > 0, total, 0.0)
    heatmap[counts < min_count] = 0.0
    return AdaptationResult(heatmap.astype(np.float32), counts, Hs)


def heatmap_to_keypoints(heatmap: np.ndarray, threshold: float = 0.015, nms_radius: int = 4, border: int = 4,
                         max_keypoints: int | None = None, valid: np.ndarray | None = None
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Return keypoints (N, 2) float32 (x, y) and scores (N,) float32, strongest first, from a heatmap.

    Pixels with response >= ``threshold`` (SuperPoint's export threshold 0.015, about 1/65), at least ``border``
    pixels from the image edge and on ``valid``, then the project's greedy box NMS
    (:func:`evio_lib.features.base.nms_keypoints`, radius ``nms_radius``), then the best ``max_keypoints``.

    Args:
        heatmap: (H, W) response.
        threshold: minimum response.
        nms_radius: NMS radius in pixels (>= 0).
        border: pixels at the image edge to drop (>= 0).
        max_keypoints: keep at most this many (None: all).
        valid: optional (H, W) bool mask of allowed pixels.

    >>> h = np.zeros((20, 20), np.float32); h[10, 5] = 0.5; h[10, 6] = 0.4; h[1, 1] = 0.9
    >>> kp, score = heatmap_to_keypoints(h, 0.1, nms_radius=2, border=2)
    >>> kp.tolist(), score.tolist()
    ([[5.0, 10.0]], [0.5])
    """
    heat = np.asarray(heatmap, dtype=np.float32)
    if heat.ndim != 2 or heat.size == 0:
        raise ValueError(f"heatmap must have shape (H, W); got {heat.shape}")
    if isinstance(threshold, bool) or not isinstance(threshold, Real) or not math.isfinite(threshold):
        raise ValueError(f"threshold must be a finite number; got {threshold!r}")
    for name, value in (("border", border), ("nms_radius", nms_radius)):
        if isinstance(value, bool) or not isinstance(value, Integral) or value < 0:
            raise ValueError(f"{name} must be a non-negative int (pixels); got {value!r}")
    keep = heat >= threshold
    if border > 0:
        keep[:border] = False
        keep[-border:] = False
        keep[:, :border] = False
        keep[:, -border:] = False
    if valid is not None:
        v = np.asarray(valid, dtype=bool)
        if v.shape != heat.shape:
            raise ValueError(f"valid must have shape {heat.shape}; got {v.shape}")
        keep &= v
    rows, cols = np.nonzero(keep)
    keypoints = np.stack([cols, rows], axis=1).astype(np.float32)
    scores = heat[rows, cols]
    order = nms_keypoints(keypoints, scores, int(nms_radius), heat.shape)  # strongest first
    if max_keypoints is not None:
        order = order[: _positive_int(max_keypoints, "max_keypoints")]
    return keypoints[order], scores[order].astype(np.float32)


def label_images(images: Sequence[np.ndarray], heatmap_fn: HeatmapFn, rng: np.random.Generator | int,
                 n_homographies: int = 100, config: HomographicConfig = HOMOGRAPHIC_ADAPTATION,
                 batch_size: int = 16, threshold: float = 0.015, nms_radius: int = 4, border: int = 4,
                 max_keypoints: int | None = None, progress: bool = False) -> list[np.ndarray]:
    """Return pseudo-ground-truth keypoints (one (N_i, 2) float32 array per image) by homographic adaptation.

    For each image: :func:`homographic_adaptation` with a child generator of ``rng``, then
    :func:`heatmap_to_keypoints`. This is the "export detections" step between training rounds.

    Args:
        images: sequence of (H, W) float32 images in [0, 1] (sizes may differ).
        heatmap_fn: detector, ``images (B, H, W) -> heatmaps (B, H, W)``.
        rng: Generator or seed.
        n_homographies, config, batch_size: see :func:`homographic_adaptation`.
        threshold, nms_radius, border, max_keypoints: see :func:`heatmap_to_keypoints`.
        progress: show a tqdm progress bar.

    Reference: thesis §3.2.5.2.
    """
    gen = as_rng(rng)
    children = gen.spawn(len(images))
    iterator: Any = range(len(images))
    if progress:
        from tqdm import tqdm

        iterator = tqdm(iterator, desc="homographic adaptation", unit="img")
    labels = []
    for i in iterator:  # loop over images
        result = homographic_adaptation(images[i], heatmap_fn, children[i], n_homographies, config, batch_size)
        keypoints, _ = heatmap_to_keypoints(result.heatmap, threshold, nms_radius, border, max_keypoints)
        labels.append(keypoints)
    return labels
