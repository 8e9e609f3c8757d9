"""Post-processing of the network's outputs into keypoints and descriptors (:func:`postprocess`) and its steps.

Softmax over the 65 channels, drop the dustbin, depth-to-space (pixel shuffle) to an (H, W) heatmap
(:func:`logits_to_heatmap`), keep pixels with probability >= ``threshold`` (1/65 by default: a pixel more likely
than a uniform guess over the 65 classes, thesis §3.2.4), zero an image border of ``border`` pixels, greedy box NMS
(:func:`nms_heatmap`, the same result as :func:`evio_lib.features.base.nms_keypoints`), best ``max_keypoints`` by
score (:func:`extract_keypoints`), optionally moved off the pixel grid (:func:`refine_keypoints`). Descriptors
(:func:`sample_descriptors`): the coarse descriptor map is L2-normalised per cell, interpolated at the keypoints with
**bicubic** interpolation (as in the thesis; ``descriptor_interpolation="bilinear"`` is the cheaper option) and
L2-normalised again. Cell (h, w) covers pixels x in [8w, 8w + 7], so its descriptor sits at the cell centre
(8w + 3.5, 8h + 3.5) (pixel centres at integer coordinates), the same centre the descriptor loss uses.
:func:`pad_to_cells` pads an image to multiples of the 8-pixel cell.

Reference: DeTone et al., "SuperPoint", CVPRW 2018; thesis §3.2.4 (post-processing), §3.2.6 (NMS, best-N points).
"""
from __future__ import annotations

from numbers import Integral
from typing import Any

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from evio_lib.features.base import Features
from evio_lib.features.network.checks import _check_count, _check_image_shape, _check_real
from evio_lib.features.network.model import CELL

__all__ = [
    "pad_to_cells",
    "logits_to_heatmap",
    "nms_heatmap",
    "extract_keypoints",
    "refine_keypoints",
    "window_centroids",
    "sample_descriptors",
    "postprocess",
]


def pad_to_cells(x: torch.Tensor) -> torch.Tensor:
    """Return (B, C, H', W') with H', W' the next multiples of 8, padding bottom and right by edge replication.

    Replication (not zeros) so that the padding adds no artificial step edge, whose corners would be detected.

    >>> tuple(pad_to_cells(torch.zeros(1, 1, 180, 240)).shape)
    (1, 1, 184, 240)
    """
    if not isinstance(x, torch.Tensor) or x.ndim != 4:
        raise ValueError(f"x must be a (B, C, H, W) tensor; got {tuple(getattr(x, 'shape', ())) or type(x).__name__}")
    pad_h = -x.shape[2] % CELL
    pad_w = -x.shape[3] % CELL
    if pad_h == 0 and pad_w == 0:
        return x
    return F.pad(x, (0, pad_w, 0, pad_h), mode="replicate")


def _check_logits(logits: torch.Tensor) -> torch.Tensor:
    """Return logits as (B, 65, Hc, Wc), adding a batch axis to (65, Hc, Wc)."""
    if not isinstance(logits, torch.Tensor):
        raise ValueError(f"logits must be a torch tensor (B, 65, Hc, Wc); got {type(logits).__name__}")
    if logits.ndim == 3:
        logits = logits[None]
    if logits.ndim != 4 or logits.shape[1] != CELL * CELL + 1:
        raise ValueError(f"logits must have shape (B, 65, Hc, Wc) or (65, Hc, Wc); got {tuple(logits.shape)}")
    return logits


def logits_to_heatmap(logits: torch.Tensor) -> torch.Tensor:
    """Return the (B, H, W) keypoint probability map ("pointness") of detector logits (B, 65, H/8, W/8).

    Softmax over the 65 channels, drop the dustbin (channel 64), depth-to-space: channel k of cell (h, w) becomes
    pixel (row 8h + k // 8, col 8w + k % 8) (``F.pixel_shuffle``). A (65, Hc, Wc) input gives (1, H, W).

    Reference: thesis §3.2.4; DeTone et al. 2018, §3.1.

    >>> logits = torch.zeros(1, 65, 1, 1); logits[0, 8 * 2 + 5] = 10.0   # cell pixel row 2, col 5
    >>> heat = logits_to_heatmap(logits)
    >>> tuple(heat.shape), [int(i) for i in divmod(int(heat.argmax()), 8)], round(float(heat.max()), 3)
    ((1, 8, 8), [2, 5], 0.997)
    """
    logits = _check_logits(logits)
    prob = torch.softmax(logits.float(), dim=1)  # p_k = exp(x_k) / sum_j exp(x_j), j = 0..64
    return F.pixel_shuffle(prob[:, : CELL * CELL], CELL)[:, 0]  # drop dustbin, (B, 64, Hc, Wc) -> (B, H, W)


def nms_heatmap(scores: torch.Tensor, radius: int) -> torch.Tensor:
    """Return the scores with every pixel zeroed that greedy box NMS suppresses (positive pixels are candidates).

    Greedy definition (SuperPoint's grid NMS, as :func:`evio_lib.features.base.nms_keypoints`): visit positive
    pixels by descending score; keep one unless a kept pixel lies within Chebyshev distance ``radius``
    (``max(|dx|, |dy|) <= r``). Computed with max-pooling in rounds, no loop over pixels: a pixel that is the largest
    remaining score in its (2r + 1)^2 box is kept, pixels in the boxes of kept ones are removed, repeat until nothing
    changes (usually 2-4 rounds). Equal scores inside one box are all kept (the greedy order would keep one).
    On the CPU the box maxima come from ``cv2.dilate`` (much faster than torch's CPU max-pool), on a GPU from
    ``F.max_pool2d``.

    Args:
        scores: (H, W), (B, H, W) or (B, 1, H, W) non-negative scores; zero = no candidate.
        radius: NMS radius r >= 0 in pixels (0 returns the scores unchanged).

    Reference: DeTone et al. 2018 (NMS of the detector output); thesis §3.2.6 (NMS 4 and 8).

    >>> s = torch.zeros(1, 7); s[0, 1], s[0, 2], s[0, 3], s[0, 5] = 0.5, 0.9, 0.8, 0.7
    >>> nms_heatmap(s, 1).double().numpy().round(2).tolist()   # 0.9 suppresses 0.5 and 0.8; 0.7 survives
    [[0.0, 0.0, 0.9, 0.0, 0.0, 0.7, 0.0]]
    """
    ndim = scores.ndim if isinstance(scores, torch.Tensor) else -1
    if ndim not in (2, 3, 4) or (ndim == 4 and scores.shape[1] != 1):
        raise ValueError(
            "scores must be a torch tensor of shape (H, W), (B, H, W) or (B, 1, H, W); "
            f"got {tuple(getattr(scores, 'shape', ())) or type(scores).__name__}"
        )
    if isinstance(radius, bool) or not isinstance(radius, Integral) or radius < 0:
        raise ValueError(f"radius must be an integer >= 0 (pixels); got {radius!r}")
    if radius == 0:
        return scores
    shape = scores.shape
    s = scores.reshape(-1, shape[-2], shape[-1])
    if s.device.type == "cpu":  # OpenCV's dilation is much faster than torch's CPU max-pool (speed.md: small costs)
        arr = s.detach().float().numpy()
        kept = np.stack([_nms_numpy(arr[i], int(radius)) for i in range(arr.shape[0])])
        return torch.from_numpy(kept).to(scores.dtype).reshape(shape)
    return _nms_torch(s[:, None], int(radius)).reshape(shape)


def _nms_numpy(s: np.ndarray, radius: int) -> np.ndarray:
    """Greedy box NMS of one (H, W) float32 map by rounds of box maxima (cv2.dilate); see :func:`nms_heatmap`."""
    box = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
    candidate = s > 0
    keep = (s == cv2.dilate(s, box)) & candidate  # round 1: box maxima are kept by greedy NMS
    while True:
        suppressed = cv2.dilate(keep.view(np.uint8), box) > 0  # within r of a kept pixel (kept ones included)
        remaining = np.where(suppressed, np.float32(0.0), s)
        new = (remaining == cv2.dilate(remaining, box)) & candidate & ~suppressed  # largest undecided in its box
        if not new.any():
            break
        keep |= new
    return np.where(keep, s, np.float32(0.0))


def _nms_torch(s: torch.Tensor, radius: int) -> torch.Tensor:
    """The same rounds with max-pooling, for (B, 1, H, W) tensors on a GPU."""
    k = 2 * radius + 1

    def box_max(t: torch.Tensor) -> torch.Tensor:
        return F.max_pool2d(t, kernel_size=k, stride=1, padding=radius)  # max over the (2r+1)^2 box

    candidate = s > 0
    keep = (s == box_max(s)) & candidate
    while True:
        suppressed = box_max(keep.to(s.dtype)) > 0
        remaining = torch.where(suppressed, torch.zeros_like(s), s)
        new = (remaining == box_max(remaining)) & candidate & ~suppressed
        if not bool(new.any()):
            break
        keep |= new
    return torch.where(keep, s, torch.zeros_like(s))


def _check_tensor(value: Any, name: str, form: str, ndim: int, *, last: int | None = None, what: str = "") -> None:
    """Raise ValueError naming ``name`` and its expected ``form`` unless ``value`` is a torch tensor of that rank."""
    if not isinstance(value, torch.Tensor) or value.ndim != ndim or (last is not None and value.shape[-1] != last):
        got = tuple(getattr(value, "shape", ())) or type(value).__name__
        raise ValueError(f"{name} must be a {form} torch tensor{what}; got {got}")


def extract_keypoints(
    heatmap: torch.Tensor,
    threshold: float = 1.0 / 65.0,
    nms_radius: int = 4,
    border: int = 4,
    max_keypoints: int | None = 1000,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Return keypoints (N, 2) float32 (x, y) and scores (N,) of one (H, W) heatmap, strongest first.

    Steps: keep pixels with ``heatmap >= threshold``; drop a band of ``border`` pixels at the image edge (before
    NMS, so that a dropped border pixel suppresses nothing); greedy box NMS of ``nms_radius``; sort by score
    (ties in raster order); keep the best ``max_keypoints`` (None: all).

    >>> heat = torch.zeros(16, 16); heat[5, 7], heat[6, 8], heat[10, 3], heat[1, 1] = 0.9, 0.5, 0.3, 1.0
    >>> kp, sc = extract_keypoints(heat, threshold=0.2, nms_radius=2, border=2)
    >>> kp.tolist(), sc.double().numpy().round(2).tolist()   # (1, 1) is in the border, (8, 6) is suppressed by (7, 5)
    ([[7.0, 5.0], [3.0, 10.0]], [0.9, 0.3])
    """
    _check_tensor(heatmap, "heatmap", "(H, W)", 2)
    threshold = _check_real("threshold", threshold, minimum=0.0)
    border = _check_count("border", border)
    nms_radius = _check_count("nms_radius", nms_radius)
    if max_keypoints is not None:
        max_keypoints = _check_count("max_keypoints", max_keypoints, minimum=1)
    heat = heatmap.float()
    scores = torch.where(heat >= threshold, heat, torch.zeros_like(heat))  # threshold: p >= 1/65
    if threshold == 0.0:
        scores = scores.clamp_min(torch.finfo(torch.float32).tiny)  # every pixel is a candidate
    if border > 0:
        inner = torch.zeros_like(scores)
        inner[border:-border, border:-border] = 1.0  # keep border <= x <= W - 1 - border (same for y)
        scores = scores * inner
    scores = nms_heatmap(scores, nms_radius)
    ys, xs = torch.nonzero(scores > 0, as_tuple=True)  # raster order
    values = scores[ys, xs]
    order = torch.sort(values, descending=True, stable=True).indices
    if max_keypoints is not None:
        order = order[:max_keypoints]
    keypoints = torch.stack([xs[order], ys[order]], dim=1).to(torch.float32)
    return keypoints, values[order]


def refine_keypoints(heatmap: torch.Tensor, keypoints: torch.Tensor, radius: int = 2) -> torch.Tensor:
    """Return keypoints (N, 2) float32 moved to the centroid of the heatmap around each integer peak (sub-pixel).

    For a peak at integer pixel (x, y) and the (2r + 1) x (2r + 1) window of probabilities p(u, v) around it
    (u, v in -r..r; pixels outside the image count as 0), the refined point is::

        x* = x + sum p(u, v) u / sum p(u, v),   y* = y + sum p(u, v) v / sum p(u, v)

    (a weighted mean of pixels of the image, so it stays inside it). The network's cell head can only place a
    point on a pixel; the mass it spreads over the neighbours says on which side of that pixel the corner lies, so
    the centroid recovers part of the lost half pixel (SuperPoint's own post-processing stops at integer peaks, as
    the thesis does). ``radius = 0`` returns the points unchanged.

    Args:
        heatmap: (H, W) keypoint probabilities (:func:`logits_to_heatmap`).
        keypoints: (N, 2) integer-valued (x, y) peaks inside the heatmap (:func:`extract_keypoints`).
        radius: half-size r of the window (pixels, >= 0).

    >>> heat = torch.zeros(8, 8); heat[3, 4], heat[3, 5] = 0.6, 0.2   # mass right of the peak at (4, 3)
    >>> refine_keypoints(heat, torch.tensor([[4.0, 3.0]]), radius=1).tolist()
    [[4.25, 3.0]]
    """
    _check_tensor(heatmap, "heatmap", "(H, W)", 2)
    _check_tensor(keypoints, "keypoints", "(N, 2)", 2, last=2, what=" of (x, y) pixels")
    radius = _check_count("radius", radius)
    if radius == 0 or keypoints.shape[0] == 0:
        return keypoints.to(torch.float32)
    height, width = heatmap.shape
    cols = keypoints[:, 0].round().long()
    rows = keypoints[:, 1].round().long()
    if (cols < 0).any() or (cols >= width).any() or (rows < 0).any() or (rows >= height).any():
        raise ValueError(f"keypoints must lie inside the ({height}, {width}) heatmap")
    centroids, _ = window_centroids(heatmap.float().clamp_min(0.0)[None], keypoints[None], radius)
    return centroids[0]


def window_centroids(heat: torch.Tensor, centres: torch.Tensor, radius: int = 2) -> tuple[torch.Tensor, torch.Tensor]:
    """Return the heat centroids (B, N, 2) of the windows around the pixels nearest ``centres``, and their masses.

    ``heat`` is (B, H, W); ``centres`` (B, N, 2) float (x, y) pixels; each is rounded to the nearest pixel (x0, y0)
    and the (2r + 1)^2 window there (pixels outside the image count as 0) gives
    ``(x0, y0) + sum p (u, v) / sum p``, differentiable in ``heat`` (the batched form of :func:`refine_keypoints`,
    also used by the training's reprojection loss). Centres outside the image are clamped to its nearest pixel.

    >>> heat = torch.zeros(1, 8, 8); heat[0, 3, 4], heat[0, 3, 5] = 0.6, 0.2
    >>> c, m = window_centroids(heat, torch.tensor([[[4.2, 2.9]]]), radius=1)
    >>> c[0, 0].tolist(), round(float(m[0, 0]), 3)
    ([4.25, 3.0], 0.8)
    """
    b, height, width = heat.shape
    padded = F.pad(heat, (radius,) * 4)  # zeros outside the image
    cols = centres[..., 0].round().clamp(0, width - 1).long()
    rows = centres[..., 1].round().clamp(0, height - 1).long()
    offsets = torch.arange(-radius, radius + 1, device=heat.device)
    du, dv = offsets[None, None, None, :], offsets[None, None, :, None]  # column and row offsets of the window
    batch = torch.arange(b, device=heat.device)[:, None, None, None]
    window = padded[batch, rows[..., None, None] + radius + dv, cols[..., None, None] + radius + du]  # (B, N, k, k)
    mass = window.sum(dim=(2, 3))
    safe = mass.clamp_min(torch.finfo(torch.float32).tiny)
    x = cols.float() + (window * du).sum(dim=(2, 3)) / safe
    y = rows.float() + (window * dv).sum(dim=(2, 3)) / safe
    return torch.stack([x, y], dim=-1), mass


def sample_descriptors(
    descriptor_map: torch.Tensor, keypoints: torch.Tensor, interpolation: str = "bicubic"
) -> torch.Tensor:
    """Return (N, D) unit descriptors interpolated from a coarse (D, Hc, Wc) map at (N, 2) pixel keypoints (x, y).

    Cell (h, w) holds the descriptor of pixel (8w + 3.5, 8h + 3.5); the map is L2-normalised per cell, interpolated
    (``F.grid_sample``, ``align_corners=False`` so that normalised coordinate ``(x + 0.5) / (8 Wc) * 2 - 1`` is
    exactly pixel x; border cells are extended outwards) and each result L2-normalised.

    Args:
        descriptor_map: (D, Hc, Wc) raw descriptors of one image.
        keypoints: (N, 2) pixels (x, y) in the (8 Hc, 8 Wc) image.
        interpolation: "bicubic" (thesis §3.2.4) or "bilinear".

    >>> dmap = torch.zeros(2, 1, 2); dmap[0, 0, 0] = 1.0; dmap[1, 0, 1] = 1.0   # left cell e_x, right cell e_y
    >>> sample_descriptors(dmap, torch.tensor([[3.5, 3.5], [7.5, 3.5]]), "bilinear").numpy().round(3)
    array([[1.   , 0.   ],
           [0.707, 0.707]], dtype=float32)
    """
    _check_tensor(descriptor_map, "descriptor_map", "(D, Hc, Wc)", 3)
    _check_tensor(keypoints, "keypoints", "(N, 2)", 2, last=2, what=" of (x, y) pixels")
    if interpolation not in ("bicubic", "bilinear"):
        raise ValueError(f"interpolation must be 'bicubic' or 'bilinear'; got {interpolation!r}")
    d, hc, wc = descriptor_map.shape
    if keypoints.shape[0] == 0:
        return torch.zeros((0, d), dtype=torch.float32, device=descriptor_map.device)
    dmap = F.normalize(descriptor_map.float(), p=2, dim=0)  # unit descriptor per cell
    kp = keypoints.to(device=dmap.device, dtype=torch.float32)
    size = torch.tensor([CELL * wc, CELL * hc], dtype=torch.float32, device=dmap.device)
    grid = (kp + 0.5) / size * 2.0 - 1.0  # pixel x -> [-1, 1] with align_corners=False (pixel edges at -1, 1)
    sampled = F.grid_sample(
        dmap[None], grid[None, None], mode=interpolation, padding_mode="border", align_corners=False
    )  # (1, D, 1, N)
    return F.normalize(sampled[0, :, 0].T, p=2, dim=1)  # (N, D), ||d|| = 1


def postprocess(
    logits: torch.Tensor,
    descriptors: torch.Tensor | None = None,
    *,
    image_shape: tuple[int, int] | None = None,
    threshold: float = 1.0 / 65.0,
    nms_radius: int = 4,
    border: int = 4,
    max_keypoints: int | None = 1000,
    descriptor_interpolation: str = "bicubic",
    subpixel_radius: int = 0,
) -> list[Features]:
    """Return one Features record per image from network outputs (the detector's whole post-processing).

    Args:
        logits: (B, 65, Hc, Wc) (or (65, Hc, Wc)) detector logits.
        descriptors: (B, D, Hc, Wc) raw descriptor map, or None (detector-only: (N, 0) descriptors).
        image_shape: (H, W) of the unpadded input; the heatmap is cropped to it before thresholding (default
            (8 Hc, 8 Wc)).
        threshold, nms_radius, border, max_keypoints: see :func:`extract_keypoints`.
        descriptor_interpolation: "bicubic" or "bilinear", see :func:`sample_descriptors`.
        subpixel_radius: window half-size of :func:`refine_keypoints` (0, the default: integer peaks as in the
            thesis); descriptors are sampled at the refined points.

    Reference: thesis §3.2.4 (softmax, dustbin, reshape, threshold 1/65, NMS, bicubic descriptors, L2 norm).

    >>> logits = torch.full((1, 65, 4, 4), -5.0); logits[:, 64] = 5.0; logits[0, 8 * 3 + 4, 1, 2] = 12.0
    >>> f = postprocess(logits, torch.randn(1, 16, 4, 4, generator=torch.Generator().manual_seed(0)))[0]
    >>> f.keypoints.tolist(), f.descriptors.shape, round(float(np.linalg.norm(f.descriptors[0])), 4)
    ([[20.0, 11.0]], (1, 16), 1.0)
    """
    logits = _check_logits(logits)
    b, _, hc, wc = logits.shape
    if descriptors is not None:
        if not isinstance(descriptors, torch.Tensor) or descriptors.ndim != 4 or descriptors.shape[0] != b or tuple(
            descriptors.shape[2:]
        ) != (hc, wc):
            raise ValueError(
                f"descriptors must have shape (B, D, Hc, Wc) = ({b}, D, {hc}, {wc}) to match logits; "
                f"got {tuple(getattr(descriptors, 'shape', ()))}"
            )
    if image_shape is None:
        height, width = CELL * hc, CELL * wc
    else:
        height, width = _check_image_shape(image_shape)
        if height > CELL * hc or width > CELL * wc:
            raise ValueError(
                f"image_shape {(height, width)} exceeds the {(CELL * hc, CELL * wc)} pixels that the logits cover"
            )
    heat = logits_to_heatmap(logits)[:, :height, :width]
    records = []
    for i in range(b):  # loop over images only
        keypoints, scores = extract_keypoints(heat[i], threshold, nms_radius, border, max_keypoints)
        keypoints = refine_keypoints(heat[i], keypoints, subpixel_radius)
        if descriptors is None:
            desc = np.zeros((keypoints.shape[0], 0), np.float32)
        else:
            desc = sample_descriptors(descriptors[i], keypoints, descriptor_interpolation).cpu().numpy()
        records.append(Features(keypoints.cpu().numpy(), scores.cpu().numpy(), desc))
    return records
