"""Training losses of the SuperPoint-style network: detector cross-entropy, descriptor hinge loss, total loss.

Notation (thesis §3.2.4.1): X (B, 65, Hc, Wc) detector logits, Y (B, Hc, Wc) cell labels in 0..64 (64 = no point,
the dustbin), D and D' (B, Dim, Hc, Wc) descriptor maps of an image and of its warp by the homography H, S the cell
correspondences. Cells are 8x8 pixels; cell (h, w) covers pixels x in [8w, 8w + 7], y in [8h, 8h + 7], its centre is
the pixel (8w + 3.5, 8h + 3.5) (pixel centres at integer coordinates, as in ``evio_lib.geometry.homography``).
Label channel k of a cell is its pixel (row k // 8, col k % 8), the order of ``F.pixel_unshuffle`` and of
:func:`evio_lib.features.network.logits_to_heatmap`.

- Detector loss (Eq. 9): softmax cross-entropy per cell, averaged over the valid cells. Labels come from a keypoint
  map; a cell with several labelled pixels takes one of them at random (uniformly, from a seeded torch.Generator),
  a cell without any takes the dustbin. A cell is valid when all its 64 pixels are valid (inside the warped image).
- Descriptor loss (Eqs. 10-12): for every pair of cells (h, w) of image 1 and (h', w') of image 2, s = 1 when the
  warped centre H p_hw lies within 8 px of p'_h'w' (strictly, Eq. 10), and
  ``l_d = lambda_d s max(0, m_p - d^T d') + (1 - s) max(0, d^T d' - m_n)`` on L2-normalised cell descriptors;
  averaged over the valid pairs (both cells valid). m_p = 1, m_n = 0.2, lambda_d = 250 by default (SuperPoint;
  see the weights below).
- Total (Eq. 8): ``L = L_p(X, Y) + L_p(X', Y') + lambda L_d(D, D', S)``.

Weights: each image-1 cell has about pi 8^2 / 8^2 ~ 3 positive cells (Eq. 10's 8 px disc) and Hc Wc - 3 negatives, so
lambda_d sets the balance ``lambda_d * 3 / (Hc Wc)`` between the pull of the positives and the push of the negatives.
SuperPoint's lambda_d = 250 at 240 x 320 (1 200 cells) gives ~0.6; the same 250 on 120 x 160 crops (300 cells) gives
~2.5, and there the positives win: every descriptor drifts towards every other, although the loss keeps falling (as
this project's early CPU chains showed: docs/archive.md, "Second CPU chain"). The DetDesc configs therefore use
lambda_d = 62.5 = 250 * 300 / 1 200 at 120 x 160; :func:`descriptor_cell_stats` reports the two mean cosines and the
retrieval, which the training validation records. The thesis's lambda_d = 0.05, lambda = 10 000 belong to a
differently normalised descriptor loss. With the mean over pairs used here, lambda = 1 (default) makes the descriptor
term comparable to the detector terms (SuperPoint's 1e-4 assumes the sum over all pairs divided by (Hc Wc)^2 with an
unnormalised positive count). All are arguments.

Reference: thesis §3.2.4.1, Eqs. 8-12; DeTone et al., "SuperPoint", CVPRW 2018, §3.4.
"""
from __future__ import annotations

import math
from numbers import Integral, Real
from typing import NamedTuple

import numpy as np
import torch
import torch.nn.functional as F

__all__ = [
    "CELL",
    "DUSTBIN",
    "cell_centres",
    "cell_valid_mask",
    "keypoint_map_to_labels",
    "detector_loss",
    "cell_correspondences",
    "descriptor_loss",
    "DescriptorStats",
    "descriptor_cell_stats",
    "LossTerms",
    "superpoint_loss",
]

CELL = 8  # pixels per cell side
DUSTBIN = CELL * CELL  # label 64: no keypoint in the cell


# ---------------------------------------------------------------------------------------------- labels and masks
def _as_float_maps(value: object, name: str, ndim: int = 3) -> torch.Tensor:
    """Return value as a float tensor with ``ndim`` dims (a 2-D map gets a batch axis), or raise ValueError."""
    tensor = torch.as_tensor(value) if not isinstance(value, torch.Tensor) else value
    if tensor.ndim == ndim - 1:
        tensor = tensor[None]
    if tensor.ndim != ndim:
        raise ValueError(f"{name} must have shape (B, H, W) (or (H, W)); got {tuple(tensor.shape)}")
    if tensor.shape[-1] % CELL or tensor.shape[-2] % CELL or tensor.shape[-1] == 0 or tensor.shape[-2] == 0:
        raise ValueError(
            f"{name} must have H and W that are positive multiples of {CELL}; got {tuple(tensor.shape[-2:])}"
        )
    return tensor.float()


def cell_centres(grid_shape: tuple[int, int], device: torch.device | str | None = None) -> torch.Tensor:
    """Return the (Hc * Wc, 2) pixel centres (x, y) = (8w + 3.5, 8h + 3.5) of the cells, row-major (h, w).

    >>> cell_centres((2, 3)).tolist()
    [[3.5, 3.5], [11.5, 3.5], [19.5, 3.5], [3.5, 11.5], [11.5, 11.5], [19.5, 11.5]]
    """
    hc, wc = int(grid_shape[0]), int(grid_shape[1])
    if hc < 1 or wc < 1:
        raise ValueError(f"grid_shape must be (Hc, Wc) of positive integers; got {grid_shape!r}")
    ys, xs = torch.meshgrid(torch.arange(hc, device=device), torch.arange(wc, device=device), indexing="ij")
    return torch.stack([xs, ys], dim=-1).reshape(-1, 2).float() * CELL + (CELL - 1) / 2.0  # p = 8 i + 3.5


def cell_valid_mask(valid_mask: torch.Tensor) -> torch.Tensor:
    """Return the bool (B, Hc, Wc) mask of cells whose 64 pixels are all valid, from a (B, H, W) pixel mask.

    >>> m = torch.ones(1, 8, 16); m[0, 7, 9] = 0
    >>> cell_valid_mask(m).tolist()
    [[[True, False]]]
    """
    mask = _as_float_maps(valid_mask, "valid_mask")
    return F.pixel_unshuffle((mask > 0.5).float()[:, None], CELL).amin(dim=1) > 0.5  # all 64 pixels valid


def _as_generator(generator: torch.Generator | int | None, name: str = "generator") -> torch.Generator:
    """Return a torch.Generator from a Generator or an int seed (None is refused: no global random state)."""
    if isinstance(generator, torch.Generator):
        return generator
    if isinstance(generator, Integral) and not isinstance(generator, bool):
        return torch.Generator().manual_seed(int(generator))
    raise ValueError(f"{name} must be a torch.Generator or an int seed (the label choice is random); got {generator!r}")


def keypoint_map_to_labels(keypoint_map: torch.Tensor, generator: torch.Generator | int) -> torch.Tensor:
    """Return (B, Hc, Wc) int64 cell labels in 0..64 from a (B, H, W) keypoint map (pixels >= 0.5 are keypoints).

    Label k < 64 is the cell's pixel (row k // 8, col k % 8); 64 (dustbin) means no keypoint in the cell. A cell
    with several keypoint pixels gets one of them uniformly at random: each keypoint pixel scores ``1 + u`` with
    u ~ U[0, 1) from ``generator``, the dustbin 0.5, other pixels 0, and the label is the argmax (thesis Eq. 9:
    "one point is randomly selected").

    Args:
        keypoint_map: (B, H, W) or (H, W) map, 1 at labelled pixels and 0 elsewhere; H, W multiples of 8.
        generator: torch.Generator (pass the same one through training) or an int seed. The random numbers are
            drawn on the generator's device and moved to the map's.

    >>> kmap = torch.zeros(1, 8, 16); kmap[0, 2, 5] = 1; kmap[0, 0, 8] = kmap[0, 7, 15] = 1
    >>> keypoint_map_to_labels(kmap, 0)[0, 0, 0].item(), keypoint_map_to_labels(kmap, 0)[0, 0, 1].item() in (0, 63)
    (21, True)
    """
    kmap = _as_float_maps(keypoint_map, "keypoint_map")
    gen = _as_generator(generator)
    # (B, 64, Hc, Wc): channel k = pixel (k // 8, k % 8) of the cell
    cells = F.pixel_unshuffle((kmap >= 0.5).float()[:, None], CELL)
    noise = torch.rand(cells.shape, generator=gen, device=gen.device).to(cells.device)
    scores = cells * (1.0 + noise)  # labelled pixels score in [1, 2), random order among them
    dustbin = torch.full_like(scores[:, :1], 0.5)  # wins only when the cell has no label
    return torch.cat([scores, dustbin], dim=1).argmax(dim=1)


# ---------------------------------------------------------------------------------------------- detector loss
def _check_logits(logits: torch.Tensor, name: str = "logits") -> torch.Tensor:
    """Return (B, 65, Hc, Wc) logits or raise ValueError."""
    if not isinstance(logits, torch.Tensor) or logits.ndim != 4 or logits.shape[1] != DUSTBIN + 1:
        raise ValueError(f"{name} must be a (B, 65, Hc, Wc) torch tensor; got {tuple(getattr(logits, 'shape', ()))}")
    return logits


def detector_loss(
    logits: torch.Tensor,
    keypoint_map: torch.Tensor,
    *,
    generator: torch.Generator | int,
    valid_mask: torch.Tensor | None = None,
) -> torch.Tensor:
    """Return the detector loss L_p (Eq. 9): mean cross-entropy of the 65-way cell softmax over the valid cells.

    ``L_p = 1 / N_valid * sum_cells -log( exp(x_hw[y_hw]) / sum_k exp(x_hw[k]) )``, the thesis's 1 / (Hc Wc)
    restricted to cells whose pixels are all valid (0 if no cell is valid).

    Args:
        logits: (B, 65, Hc, Wc) detector logits X.
        keypoint_map: (B, 8 Hc, 8 Wc) keypoint map (1 = keypoint), see :func:`keypoint_map_to_labels`.
        generator: torch.Generator or int seed for the random label choice in multi-label cells.
        valid_mask: optional (B, 8 Hc, 8 Wc) mask of pixels that hold image content (1) or warp fill (0).

    >>> logits = torch.full((1, 65, 1, 1), -20.0); logits[0, 64] = 20.0   # confident "no point"
    >>> round(float(detector_loss(logits, torch.zeros(1, 8, 8), generator=0)), 6)
    0.0
    """
    logits = _check_logits(logits)
    kmap = _as_float_maps(keypoint_map, "keypoint_map")
    b, _, hc, wc = logits.shape
    if kmap.shape != (b, CELL * hc, CELL * wc):
        expected = (b, CELL * hc, CELL * wc)
        raise ValueError(f"keypoint_map must have shape (B, 8 Hc, 8 Wc) = {expected}; got {tuple(kmap.shape)}")
    labels = keypoint_map_to_labels(kmap.to(logits.device), generator)
    ce = F.cross_entropy(logits.float(), labels, reduction="none")  # -log softmax(x)[y] per cell, (B, Hc, Wc)
    if valid_mask is None:
        return ce.mean()
    cells = _mask_cells(valid_mask, (b, hc, wc), "valid_mask").to(ce.device).float()
    return (ce * cells).sum() / cells.sum().clamp_min(1.0)


def _mask_cells(valid_mask: torch.Tensor, cells_shape: tuple[int, int, int], name: str) -> torch.Tensor:
    """Return the (B, Hc, Wc) cell validity of a (B, 8 Hc, 8 Wc) pixel mask, checking its shape."""
    mask = _as_float_maps(valid_mask, name)
    b, hc, wc = cells_shape
    if mask.shape != (b, CELL * hc, CELL * wc):
        expected = (b, CELL * hc, CELL * wc)
        raise ValueError(f"{name} must have shape (B, 8 Hc, 8 Wc) = {expected}; got {tuple(mask.shape)}")
    return cell_valid_mask(mask)


# ---------------------------------------------------------------------------------------------- descriptor loss
def _as_homographies(homographies: object, batch: int, device: torch.device) -> torch.Tensor:
    """Return (B, 3, 3) float64 homographies on ``device`` from a (3, 3) or (B, 3, 3) array or tensor."""
    if isinstance(homographies, torch.Tensor):
        h = homographies.to(device=device, dtype=torch.float64)
    else:
        h = torch.as_tensor(np.asarray(homographies, dtype=np.float64), device=device)
    if h.shape == (3, 3):
        h = h[None].expand(batch, 3, 3)
    if h.shape != (batch, 3, 3):
        raise ValueError(f"homographies must have shape (B, 3, 3) = ({batch}, 3, 3) or (3, 3); got {tuple(h.shape)}")
    if not bool(torch.isfinite(h).all()):
        raise ValueError("homographies must be finite; got NaN or inf entries")
    return h


def cell_correspondences(
    homographies: torch.Tensor | np.ndarray,
    grid_shape: tuple[int, int],
    grid_shape_warped: tuple[int, int] | None = None,
    radius: float = 8.0,
) -> torch.Tensor:
    """Return S (B, Hc Wc, Hc' Wc') float: 1 where ||H p_hw - p'_h'w'|| < radius (Eq. 10), else 0.

    p_hw are the cell centres of image 1 (:func:`cell_centres`), H maps image-1 pixels to image-2 pixels; rows
    index cells of image 1 and columns cells of image 2, both row-major. Centres that H maps to infinity or beyond
    its vanishing line (w <= 0 once H is scaled so that image 1's centre has w > 0) correspond to nothing.

    >>> S = cell_correspondences(np.eye(3), (2, 2))
    >>> S[0].int().tolist()   # identity: each cell matches itself only (neighbours are exactly 8 px away)
    [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    """
    radius = float(radius)
    if not math.isfinite(radius) or radius <= 0:
        raise ValueError(f"radius must be a positive number of pixels; got {radius!r}")
    if not isinstance(homographies, torch.Tensor):
        homographies = torch.as_tensor(np.asarray(homographies, np.float64))
    h = homographies
    device = h.device
    h = _as_homographies(h, h.shape[0] if h.ndim == 3 else 1, device)
    p1 = cell_centres(grid_shape, device).double()  # (N1, 2)
    p2 = cell_centres(grid_shape if grid_shape_warped is None else grid_shape_warped, device).double()  # (N2, 2)
    p1h = torch.cat([p1, torch.ones_like(p1[:, :1])], dim=1)  # [x, y, 1]
    mapped = p1h @ h.transpose(1, 2)  # (B, N1, 3) = (H [x, y, 1]^T)^T
    # H and -H are the same homography: orient w so that image 1's centre has w > 0 (as valid_mask does)
    cx, cy = CELL * grid_shape[1] / 2 - 0.5, CELL * grid_shape[0] / 2 - 0.5  # pixel centre of image 1
    centre = torch.tensor([cx, cy, 1.0], dtype=h.dtype, device=device)
    orientation = torch.where((h @ centre)[:, 2] < 0, -1.0, 1.0).to(h.dtype)  # (B,)
    mapped = mapped * orientation[:, None, None]
    w = mapped[..., 2:]
    ahead = w > 1e-12 * mapped.abs().amax(dim=-1, keepdim=True)
    warped = mapped[..., :2] / torch.where(ahead, w, torch.ones_like(w))  # (x' / w, y' / w)
    dist = torch.cdist(warped, p2[None].expand(warped.shape[0], -1, -1))  # ||H p_hw - p'_h'w'||, (B, N1, N2)
    return ((dist < radius) & ahead).float()


def _cell_pairs(
    descriptors: torch.Tensor,
    descriptors_warped: torch.Tensor,
    homographies: torch.Tensor | np.ndarray,
    valid_mask: torch.Tensor | None,
    valid_mask_warped: torch.Tensor | None,
    radius: float,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Return (d^T d', S, pair weight), each (B, N1, N2): cosine of every cell pair, Eq. 10's correspondences and
    1 where both cells are valid (all ones without masks)."""
    for name, value in (("descriptors", descriptors), ("descriptors_warped", descriptors_warped)):
        if not isinstance(value, torch.Tensor) or value.ndim != 4:
            got = tuple(getattr(value, "shape", ())) or type(value).__name__
            raise ValueError(f"{name} must be a (B, Dim, Hc, Wc) torch tensor; got {got}")
    b, dim, hc, wc = descriptors.shape
    if descriptors_warped.shape[:2] != (b, dim):
        raise ValueError(
            f"descriptors_warped must have shape (B, Dim, Hc', Wc') with (B, Dim) = ({b}, {dim}); "
            f"got {tuple(descriptors_warped.shape)}"
        )
    hc2, wc2 = descriptors_warped.shape[2:]
    h = _as_homographies(homographies, b, descriptors.device)
    s = cell_correspondences(h, (hc, wc), (hc2, wc2), radius).to(descriptors.dtype)  # (B, N1, N2)
    d1 = F.normalize(descriptors.flatten(2), p=2, dim=1)  # (B, Dim, N1), unit columns
    d2 = F.normalize(descriptors_warped.flatten(2), p=2, dim=1)  # (B, Dim, N2)
    dot = d1.transpose(1, 2) @ d2  # d^T d', (B, N1, N2)
    pair_weight = torch.ones_like(dot)
    if valid_mask is not None:
        cells1 = _mask_cells(valid_mask, (b, hc, wc), "valid_mask").to(device=dot.device, dtype=dot.dtype)
        pair_weight = pair_weight * cells1.flatten(1)[:, :, None]  # rows: cells of image 1
    if valid_mask_warped is not None:
        cells2 = _mask_cells(valid_mask_warped, (b, hc2, wc2), "valid_mask_warped")
        cells2 = cells2.to(device=dot.device, dtype=dot.dtype)
        pair_weight = pair_weight * cells2.flatten(1)[:, None, :]  # columns: cells of image 2
    return dot, s, pair_weight


def descriptor_loss(
    descriptors: torch.Tensor,
    descriptors_warped: torch.Tensor,
    homographies: torch.Tensor | np.ndarray,
    *,
    valid_mask: torch.Tensor | None = None,
    valid_mask_warped: torch.Tensor | None = None,
    positive_margin: float = 1.0,
    negative_margin: float = 0.2,
    lambda_d: float = 250.0,
    radius: float = 8.0,
) -> torch.Tensor:
    """Return the descriptor hinge loss L_d (Eqs. 10-12), averaged over the valid cell pairs.

    ``l_d(d, d', s) = lambda_d s max(0, m_p - d^T d') + (1 - s) max(0, d^T d' - m_n)`` on L2-normalised cell
    descriptors, s from :func:`cell_correspondences`; Eq. 11's 1 / (Hc Wc)^2 becomes 1 / (number of pairs whose two
    cells are valid).

    Args:
        descriptors: (B, Dim, Hc, Wc) raw descriptor map D of image 1.
        descriptors_warped: (B, Dim, Hc', Wc') map D' of image 2 (the warp of image 1 by H).
        homographies: (B, 3, 3) or (3, 3) H mapping image-1 pixels to image-2 pixels (tensor or array).
        valid_mask: optional (B, 8 Hc, 8 Wc) pixel mask of image 1.
        valid_mask_warped: optional (B, 8 Hc', 8 Wc') pixel mask of image 2 (pixels the warp filled from image 1).
        positive_margin, negative_margin: m_p, m_n.
        lambda_d: weight of the positive pairs.
        radius: correspondence radius in pixels (Eq. 10: 8).

    >>> d = torch.zeros(1, 4, 1, 2); d[0, 0, 0, 0] = d[0, 1, 0, 1] = 1.0   # orthogonal unit descriptors
    >>> float(descriptor_loss(d, d.clone(), np.eye(3)))   # positives align (dot 1), negatives dot 0 < m_n
    0.0
    """
    margins = (("positive_margin", positive_margin), ("negative_margin", negative_margin), ("lambda_d", lambda_d))
    for name, value in margins:
        if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value):
            raise ValueError(f"{name} must be a finite number; got {value!r}")
    if lambda_d < 0:
        raise ValueError(f"lambda_d must be >= 0; got {lambda_d!r}")
    dot, s, pair_weight = _cell_pairs(descriptors, descriptors_warped, homographies, valid_mask, valid_mask_warped,
                                      radius)
    positive = lambda_d * s * torch.clamp(positive_margin - dot, min=0.0)  # lambda_d s max(0, m_p - d^T d')
    negative = (1.0 - s) * torch.clamp(dot - negative_margin, min=0.0)  # (1 - s) max(0, d^T d' - m_n)
    return ((positive + negative) * pair_weight).sum() / pair_weight.sum().clamp_min(1.0)


class DescriptorStats(NamedTuple):
    """How well cell descriptors of a warped pair match (float scalars; NaN where nothing was counted)."""

    positive_dot: float  #: mean d^T d' over corresponding valid cell pairs (s = 1); 1 is perfect
    negative_dot: float  #: mean d^T d' over the other valid pairs (s = 0); the hinge wants it below m_n
    nn_accuracy: float  #: fraction of image-1 cells with a valid correspondence whose nearest neighbour corresponds


@torch.no_grad()
def descriptor_cell_stats(
    descriptors: torch.Tensor,
    descriptors_warped: torch.Tensor,
    homographies: torch.Tensor | np.ndarray,
    *,
    valid_mask: torch.Tensor | None = None,
    valid_mask_warped: torch.Tensor | None = None,
    radius: float = 8.0,
) -> DescriptorStats:
    """Return the mean cosine of corresponding and of other cell pairs, and nearest-neighbour cell retrieval.

    The descriptor loss can fall while descriptors stay useless: with a large ``lambda_d`` the positives win and all
    descriptors drift together (the negative dots rise far above m_n), and the loss alone does not show it.
    Retrieval does: for every valid image-1 cell that has a valid correspondence (s = 1, Eq. 10), the valid
    image-2 cell of largest d^T d' must be one of its correspondences. Arguments as :func:`descriptor_loss`.

    >>> d = torch.eye(4).reshape(1, 4, 2, 2)            # four orthogonal cell descriptors
    >>> descriptor_cell_stats(d, d.clone(), np.eye(3))   # identity warp: each cell finds itself
    DescriptorStats(positive_dot=1.0, negative_dot=0.0, nn_accuracy=1.0)
    >>> descriptor_cell_stats(d, torch.ones(1, 4, 2, 2), np.eye(3)).nn_accuracy   # collapsed: ties, first cell wins
    0.25
    """
    dot, s, weight = _cell_pairs(descriptors, descriptors_warped, homographies, valid_mask, valid_mask_warped, radius)
    valid = weight > 0
    positive, negative = (s > 0) & valid, (s == 0) & valid
    nan = float("nan")
    pos = float(dot[positive].mean()) if bool(positive.any()) else nan
    neg = float(dot[negative].mean()) if bool(negative.any()) else nan
    best = dot.masked_fill(~valid, -math.inf).argmax(dim=2)  # (B, N1) nearest valid image-2 cell
    hit = torch.gather(s, 2, best[..., None])[..., 0] > 0
    has = positive.any(dim=2)  # image-1 cells with a valid correspondence
    accuracy = float(hit[has].float().mean()) if bool(has.any()) else nan
    return DescriptorStats(pos, neg, accuracy)


# ---------------------------------------------------------------------------------------------- total loss
class LossTerms(NamedTuple):
    """The total loss (Eq. 8) and its terms, all scalar tensors (``total`` carries the gradient)."""

    total: torch.Tensor
    detector: torch.Tensor
    detector_warped: torch.Tensor
    descriptor: torch.Tensor


def superpoint_loss(
    outputs: dict[str, torch.Tensor],
    outputs_warped: dict[str, torch.Tensor],
    keypoint_map: torch.Tensor,
    keypoint_map_warped: torch.Tensor,
    homographies: torch.Tensor | np.ndarray,
    *,
    generator: torch.Generator | int,
    valid_mask: torch.Tensor | None = None,
    valid_mask_warped: torch.Tensor | None = None,
    lambda_loss: float = 1.0,
    lambda_d: float = 250.0,
    positive_margin: float = 1.0,
    negative_margin: float = 0.2,
) -> LossTerms:
    """Return Eq. 8, ``L = L_p(X, Y) + L_p(X', Y') + lambda L_d(D, D', S)``, and its terms.

    Args:
        outputs, outputs_warped: network outputs {"logits", "descriptors"} of image 1 and of its warp.
        keypoint_map, keypoint_map_warped: (B, H, W) keypoint maps of both images.
        homographies: (B, 3, 3) H (image 1 -> image 2 pixels).
        generator: torch.Generator or int seed for the random label choice (:func:`keypoint_map_to_labels`).
        valid_mask, valid_mask_warped: optional (B, H, W) pixel masks (warp fill = 0).
        lambda_loss: lambda of Eq. 8; lambda_d, positive_margin, negative_margin: see :func:`descriptor_loss`.
        A detector-only pair of outputs (no "descriptors") gives L_d = 0.
    """
    gen = _as_generator(generator)
    for name, out in (("outputs", outputs), ("outputs_warped", outputs_warped)):
        if not isinstance(out, dict) or "logits" not in out:
            raise ValueError(
                f"{name} must be the network's output dict with 'logits' (and 'descriptors'); got {type(out).__name__}"
            )
    bad = isinstance(lambda_loss, bool) or not isinstance(lambda_loss, Real)
    if bad or not math.isfinite(lambda_loss) or lambda_loss < 0:
        raise ValueError(f"lambda_loss must be a finite number >= 0; got {lambda_loss!r}")
    det = detector_loss(outputs["logits"], keypoint_map, generator=gen, valid_mask=valid_mask)
    det_warped = detector_loss(
        outputs_warped["logits"], keypoint_map_warped, generator=gen, valid_mask=valid_mask_warped
    )
    if "descriptors" in outputs and "descriptors" in outputs_warped:
        desc = descriptor_loss(
            outputs["descriptors"],
            outputs_warped["descriptors"],
            homographies,
            valid_mask=valid_mask,
            valid_mask_warped=valid_mask_warped,
            positive_margin=positive_margin,
            negative_margin=negative_margin,
            lambda_d=lambda_d,
        )
    else:
        desc = det.new_zeros(())
    return LossTerms(det + det_warped + lambda_loss * desc, det, det_warped, desc)
