"""Reprojection loss: a keypoint found in one image of a pair must land, sub-pixel, where the homography puts it.

The detector loss (Eq. 9) only says in which pixel of a cell a label lies. It never asks the heat map to follow the
image when it moves by a fraction of a cell, and a network trained on it alone keeps favoured positions inside its
8 x 8 cells (``bench/detector_localisation.py``: after a 1 px shift the points are off by 0.6-0.8 px). This term
trains the localisation the post-processing uses (peaks kept by box NMS, then the heat centroid of a 5 x 5 window
around each, :func:`evio_lib.features.network.refine_keypoints`) to be equivariant under the pair's homography, in the
spirit of the reprojection losses of SuperPoint's descendants (ALIKE's differentiable keypoint detection; Zhao et
al., "ALIKE", IEEE TMM 2022, §III-C), without any label:

1. In image 1, every cell's most probable pixel (x0, y0) (argmax of its 64 non-dustbin logits) that the detector
   would keep (probability >= 1/65 and no larger heat within 4 px: a detection, not the tail of a neighbour's point
   or flat background) is refined to the heat
   centroid of the (2r + 1)^2 window around it (differentiable in the heat map)::

       c1 = (x0, y0) + sum_{u,v} p1(x0 + u, y0 + v) (u, v) / sum_{u,v} p1(x0 + u, y0 + v)

2. c1 is mapped by H to q = H c1 in image 2. There the detection that the post-processing would report is the
   detection of image 2 nearest q (within 2r pixels; farther means no counterpart), refined the same way to c2
   (so a network whose points follow the image gives c2 = q). Taking the window around image 2's own peak, not
   around q, matters: a window centred on q would let a flat heat map score well, its centroid being the window's
   centre, while the reported peaks stayed where they were.
3. ``L_r = sum_i w_i min(||c2_i - q_i||, d_max) / sum_i w_i``, with w_i the cell's keypoint probability
   ``1 - p(dustbin)`` in image 1 (not differentiated), over cells whose window and mapped window lie inside the
   valid pixels of both images (the counterpart's window too) and that have a counterpart; the same from image 2 back to image 1 with H^-1, and
   the mean of the two.

The distance is capped at ``d_max`` (default 3 px) so that cells without a counterpart (occlusion by the warp, a
repeated texture) pull no harder than a near miss. The term enters the total as ``L + lambda_r L_r``
(``TrainConfig.lambda_reprojection``; 0, the default, leaves the thesis's loss unchanged).
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from evio_lib.features.network.postprocessing import logits_to_heatmap, window_centroids
from evio_lib.features.training.losses import CELL, DUSTBIN, _as_homographies, _check_logits

__all__ = ["cell_peaks", "reprojection_loss"]


def cell_peaks(logits: torch.Tensor) -> torch.Tensor:
    """Return (B, Hc Wc, 2) float (x, y) pixels of every cell's most probable non-dustbin pixel, cells row-major.

    >>> logits = torch.zeros(1, 65, 1, 2); logits[0, 8 * 2 + 5, 0, 1] = 5.0   # cell (0, 1): pixel row 2, col 5
    >>> cell_peaks(logits)[0, 1].tolist()
    [13.0, 2.0]
    """
    logits = _check_logits(logits)
    b, _, hc, wc = logits.shape
    k = logits[:, :DUSTBIN].argmax(dim=1)  # (B, Hc, Wc) channel = row * 8 + col inside the cell
    rows = torch.arange(hc, device=logits.device)[:, None] * CELL + torch.div(k, CELL, rounding_mode="floor")
    cols = torch.arange(wc, device=logits.device)[None, :] * CELL + k % CELL
    return torch.stack([cols, rows], dim=-1).reshape(b, hc * wc, 2).float()


def _map_points(h: torch.Tensor, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Return H applied to (B, N, 2) points and a mask of those in front (w > 0)."""
    ph = torch.cat([points.double(), torch.ones_like(points[..., :1]).double()], dim=-1)
    mapped = ph @ h.transpose(1, 2)
    w = mapped[..., 2]
    ahead = w > 1e-9
    xy = mapped[..., :2] / torch.where(ahead, w, torch.ones_like(w))[..., None]
    return xy.to(points.dtype), ahead


def _inside(points: torch.Tensor, mask: torch.Tensor | None, shape: tuple[int, int], margin: int) -> torch.Tensor:
    """Return (B, N) bool: the window of ``margin`` around each point's pixel lies in the image and its valid mask."""
    height, width = shape
    x, y = points[..., 0].round(), points[..., 1].round()
    inside = (x >= margin) & (x <= width - 1 - margin) & (y >= margin) & (y <= height - 1 - margin)
    if mask is None:
        return inside
    eroded = -F.max_pool2d(-mask.float()[:, None], 2 * margin + 1, stride=1, padding=margin)[:, 0]  # min filter
    b = points.shape[0]
    xi = x.long().clamp(0, width - 1)
    yi = y.long().clamp(0, height - 1)
    return inside & (eroded[torch.arange(b, device=points.device)[:, None], yi, xi] > 0.5)


def _detections(logits: torch.Tensor, heat: torch.Tensor, nms: int, threshold: float
                ) -> tuple[torch.Tensor, torch.Tensor]:
    """Return every cell's peak (B, N, 2) and whether it is a detection: at least ``threshold`` and the largest heat
    within ``nms`` pixels (Chebyshev), as the detector keeps it, so that a cell whose peak is only the tail of a
    neighbour's point, or flat background, counts not."""
    peaks = cell_peaks(logits)
    box_max = F.max_pool2d(heat[:, None].detach(), 2 * nms + 1, stride=1, padding=nms)[:, 0]
    b = peaks.shape[0]
    rows, cols = peaks[..., 1].long(), peaks[..., 0].long()
    batch = torch.arange(b, device=heat.device)[:, None]
    value = heat.detach()[batch, rows, cols]
    return peaks, (value >= box_max[batch, rows, cols]) & (value >= threshold)


def _one_way(logits_src: torch.Tensor, logits_dst: torch.Tensor, heat_src: torch.Tensor, heat_dst: torch.Tensor,
             h: torch.Tensor,
             mask_src: torch.Tensor | None, mask_dst: torch.Tensor | None, radius: int, d_max: float, nms: int,
             threshold: float) -> torch.Tensor:
    """Return the weighted mean capped distance ||c_dst - H c_src|| of one direction (see the module docstring)."""
    peaks, is_peak = _detections(logits_src, heat_src, nms, threshold)
    c_src, _ = window_centroids(heat_src, peaks, radius)
    q, ahead = _map_points(h, c_src)
    peaks_dst, is_peak_dst = _detections(logits_dst, heat_dst, nms, threshold)
    gap = torch.cdist(q.detach().float(), peaks_dst)  # (B, N, N'): distance of each mapped point to every peak
    gap = torch.where(is_peak_dst[:, None, :], gap, torch.full_like(gap, float("inf")))  # detections only
    nearest_gap, nearest = gap.min(dim=-1)
    found = torch.gather(peaks_dst, 1, nearest[..., None].expand(-1, -1, 2))  # the detection the target makes
    c_dst, mass = window_centroids(heat_dst, found, radius)
    shape = tuple(heat_src.shape[1:])
    valid = ahead & is_peak & _inside(peaks, mask_src, shape, radius) & _inside(q, mask_dst, shape, radius)
    valid &= (nearest_gap <= 2 * radius) & _inside(found, mask_dst, shape, radius)  # a near detection, valid window
    valid &= mass.detach() > 1e-6
    score = 1.0 - torch.softmax(logits_src.float(), dim=1)[:, DUSTBIN]  # keypoint probability per cell
    weight = score.reshape(score.shape[0], -1).detach() * valid.float()
    dist = torch.linalg.vector_norm(c_dst - q, dim=-1).clamp(max=d_max)
    return (weight * dist).sum() / weight.sum().clamp_min(1e-12)


def reprojection_loss(
    logits: torch.Tensor,
    logits_warped: torch.Tensor,
    homographies: torch.Tensor,
    *,
    valid_mask: torch.Tensor | None = None,
    valid_mask_warped: torch.Tensor | None = None,
    radius: int = 2,
    d_max: float = 3.0,
    nms: int = 4,
    threshold: float = 1.0 / 65.0,
) -> torch.Tensor:
    """Return L_r (pixels): the mean of both directions' weighted capped reprojection distances (module docstring).

    Args:
        logits, logits_warped: (B, 65, Hc, Wc) detector logits of image 1 and of image 2 = warp of image 1 by H.
        homographies: (B, 3, 3) H (image-1 pixels -> image-2 pixels).
        valid_mask, valid_mask_warped: optional (B, 8 Hc, 8 Wc) masks of the pixels holding image content.
        radius: half-size r of the centroid windows (that of the detector's ``subpixel_radius``, default 2).
        d_max: cap of each distance in pixels.
        nms: a cell's peak is a detection only if no larger heat lies within this many pixels (box NMS; the
            detector's default radius 4).
        threshold: ... and only if its keypoint probability is at least this (the detector's default 1/65).

    >>> _ = torch.manual_seed(0); logits = torch.randn(1, 65, 4, 4)
    >>> shift = torch.tensor([[[1.0, 0, 8], [0, 1, 0], [0, 0, 1]]])   # one cell to the right
    >>> moved = torch.roll(logits, 1, dims=3)                        # a network that follows the shift exactly
    >>> round(float(reprojection_loss(logits, moved, shift)), 6)
    0.0
    """
    logits = _check_logits(logits)
    logits_warped = _check_logits(logits_warped, "logits_warped")
    if logits.shape != logits_warped.shape:
        raise ValueError(f"logits and logits_warped must have the same shape; got {tuple(logits.shape)} and "
                         f"{tuple(logits_warped.shape)}")
    if isinstance(radius, bool) or not isinstance(radius, int) or radius < 1:
        raise ValueError(f"radius must be an integer >= 1 (pixels); got {radius!r}")
    if not (isinstance(d_max, (int, float)) and math.isfinite(d_max) and d_max > 0):
        raise ValueError(f"d_max must be a positive number of pixels; got {d_max!r}")
    if not (isinstance(threshold, (int, float)) and 0.0 <= threshold < 1.0):
        raise ValueError(f"threshold must be a probability in [0, 1); got {threshold!r}")
    if isinstance(nms, bool) or not isinstance(nms, int) or nms < 0:
        raise ValueError(f"nms must be an integer >= 0 (pixels); got {nms!r}")
    h = _as_homographies(homographies, logits.shape[0], logits.device)
    heat1, heat2 = logits_to_heatmap(logits), logits_to_heatmap(logits_warped)
    forward = _one_way(logits, logits_warped, heat1, heat2, h, valid_mask, valid_mask_warped, radius, float(d_max),
                       nms, threshold)
    backward = _one_way(logits_warped, logits, heat2, heat1, torch.linalg.inv(h), valid_mask_warped, valid_mask,
                        radius, float(d_max), nms, threshold)
    return (forward + backward) / 2
