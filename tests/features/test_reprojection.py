"""The reprojection loss: zero for a heat map that follows the image sub-pixel, about the offset for one that does not,
gradients that move a stuck peak, and the checks on its inputs."""
from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from evio_lib.features.network import logits_to_heatmap, refine_keypoints
from evio_lib.features.network.postprocessing import window_centroids
from evio_lib.features.training.reprojection import cell_peaks, reprojection_loss


def _blob_logits(centres: np.ndarray, shape: tuple[int, int], sigma: float = 0.8) -> torch.Tensor:
    """Logits (1, 65, H/8, W/8) whose heat map is a sum of Gaussian blobs at sub-pixel ``centres`` (x, y)."""
    h, w = shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    heat = np.zeros(shape)
    for cx, cy in centres:  # a handful of blobs
        heat += np.exp(-((xs - cx) ** 2 + (ys - cy) ** 2) / (2 * sigma ** 2))
    pixel_logits = torch.from_numpy(np.log(heat + 1e-6)).float()[None, None]
    cells = F.pixel_unshuffle(pixel_logits, 8)  # (1, 64, H/8, W/8), channel = row * 8 + col
    # a dustbin logit of 3 outweighs every cell's sum, so the probabilities stay proportional to the blobs' heat
    return torch.cat([cells, torch.full_like(cells[:, :1], 3.0)], dim=1)


def _translation(dx: float, dy: float) -> torch.Tensor:
    return torch.tensor([[[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]]], dtype=torch.float64)


@pytest.fixture
def blobs() -> np.ndarray:
    return np.array([[12.3, 11.6], [27.3, 19.6], [45.1, 28.2], [20.7, 35.4], [50.2, 12.9]])  # apart, off-centre


def test_cell_peaks_match_the_heat_map_argmax_of_each_cell() -> None:
    torch.manual_seed(0)
    logits = torch.randn(2, 65, 3, 4)
    heat = logits_to_heatmap(logits)
    peaks = cell_peaks(logits)
    for b in range(2):
        for i, (x, y) in enumerate(peaks[b].long().tolist()):
            cy, cx = divmod(i, 4)
            block = heat[b, 8 * cy:8 * cy + 8, 8 * cx:8 * cx + 8]
            assert (y - 8 * cy, x - 8 * cx) == divmod(int(block.argmax()), 8)


def test_window_centroids_agree_with_refine_keypoints() -> None:
    torch.manual_seed(1)
    heat = torch.rand(1, 24, 32)
    points = torch.tensor([[3.0, 4.0], [0.0, 0.0], [31.0, 23.0], [17.0, 9.0]])
    ours, _ = window_centroids(heat, points[None], radius=2)
    assert torch.allclose(ours[0], refine_keypoints(heat[0], points, radius=2), atol=1e-5)


def test_a_heat_map_that_follows_a_subpixel_shift_costs_almost_nothing(blobs: np.ndarray) -> None:
    shift = np.array([2.6, -1.3])
    logits1 = _blob_logits(blobs, (48, 64))
    logits2 = _blob_logits(blobs + shift, (48, 64))
    followed = float(reprojection_loss(logits1, logits2, _translation(*shift)))
    stuck = float(reprojection_loss(logits1, logits1, _translation(*shift)))  # the points did not move at all
    off_by_one = float(reprojection_loss(logits1, logits2, _translation(shift[0] + 1.0, shift[1])))
    assert followed < 0.06  # what is left: the sampled Gaussians' centroids in 5 x 5 windows
    assert abs(stuck - np.hypot(*shift)) < 0.1  # |(2.6, -1.3)| = 2.9 px
    assert 0.9 < off_by_one < 1.1


@pytest.mark.parametrize("shift, expected", [(1.0, 1.0), (2.5, 2.5), (3.5, 3.0)])
def test_points_that_stay_put_cost_the_shift_up_to_the_cap(blobs: np.ndarray, shift: float, expected: float) -> None:
    logits = _blob_logits(blobs, (48, 64))
    loss = float(reprojection_loss(logits, logits, _translation(shift, 0.0)))
    assert abs(loss - expected) < 0.1  # each point's counterpart is the same blob, 'shift' px from where H puts it


def test_a_counterpart_farther_than_twice_the_window_is_no_counterpart(blobs: np.ndarray) -> None:
    logits = _blob_logits(blobs, (48, 64))
    assert float(reprojection_loss(logits, logits, _translation(6.0, 0.0))) == 0.0  # nothing within 4 px: left out


def test_each_pair_of_a_batch_uses_its_own_homography(blobs: np.ndarray) -> None:
    shifts = [np.array([1.7, 0.4]), np.array([-0.6, 2.2])]
    first = torch.cat([_blob_logits(blobs, (48, 64))] * 2)
    second = torch.cat([_blob_logits(blobs + s, (48, 64)) for s in shifts])
    right = torch.cat([_translation(*s) for s in shifts])
    swapped = torch.cat([_translation(*s) for s in shifts[::-1]])
    assert float(reprojection_loss(first, second, right)) < 0.06
    assert float(reprojection_loss(first, second, swapped)) > 1.5


def test_gradient_descent_moves_a_stuck_peak_towards_its_image(blobs: np.ndarray) -> None:
    shift = np.array([1.4, 0.6])
    target = _blob_logits(blobs + shift, (48, 64))
    logits2 = _blob_logits(blobs, (48, 64)).requires_grad_(True)  # image 2's points sit where image 1's were
    logits1 = _blob_logits(blobs, (48, 64))
    optimiser = torch.optim.Adam([logits2], lr=0.05)
    start = float(reprojection_loss(logits1, logits2.detach(), _translation(*shift)))
    for _ in range(150):  # a few steps of plain optimisation on the logits themselves
        optimiser.zero_grad()
        loss = reprojection_loss(logits1, logits2, _translation(*shift))
        loss.backward()
        optimiser.step()
    end = float(reprojection_loss(logits1, logits2.detach(), _translation(*shift)))
    assert start > 1.0 and end < 0.1  # from the shift |(1.4, 0.6)| = 1.5 px to a few hundredths
    assert float(reprojection_loss(logits1, target, _translation(*shift))) < 0.06  # what a perfect follower scores


def test_masked_cells_are_left_out(blobs: np.ndarray) -> None:
    shift = np.array([2.0, 0.0])
    logits1 = _blob_logits(blobs, (48, 64))
    no_pixels = torch.zeros(1, 48, 64)
    loss = reprojection_loss(logits1, logits1, _translation(*shift), valid_mask=no_pixels)
    assert float(loss) == 0.0  # no valid cell: nothing to average


def test_a_partial_mask_leaves_out_only_the_points_it_covers(blobs: np.ndarray) -> None:
    shift = np.array([1.0, 0.0])
    followed = _blob_logits(blobs + shift, (48, 64))
    stuck = _blob_logits(blobs, (48, 64))
    left_half = torch.zeros(1, 48, 64)
    left_half[..., :32] = 1.0  # image 2's right half holds warp fill
    both = torch.cat([followed, stuck], dim=3)  # (1, 65, 6, 16): one follower beside one stuck map, 48 x 128
    image1 = torch.cat([stuck, stuck], dim=3)
    right_masked = torch.cat([torch.ones(1, 48, 64), torch.zeros(1, 48, 64)], dim=2)
    loss = float(reprojection_loss(image1, both, _translation(*shift), valid_mask_warped=right_masked))
    assert loss < 0.06  # only the left half, whose points followed the shift, is scored
    unmasked = float(reprojection_loss(image1, both, _translation(*shift)))
    assert unmasked > 0.3  # the stuck right half costs about 1 px per point
    assert left_half.sum() == 48 * 32


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(radius=0), "radius must be an integer >= 1"),
        (dict(d_max=-1.0), "d_max must be a positive number"),
        (dict(nms=-1), "nms must be an integer >= 0"),
    ],
)
def test_bad_arguments_are_refused(kwargs: dict, message: str) -> None:
    logits = torch.zeros(1, 65, 2, 2)
    with pytest.raises(ValueError, match=message):
        reprojection_loss(logits, logits, torch.eye(3), **kwargs)


def test_logits_of_different_shapes_are_refused() -> None:
    with pytest.raises(ValueError, match="same shape"):
        reprojection_loss(torch.zeros(1, 65, 2, 2), torch.zeros(1, 65, 2, 3), torch.eye(3))
