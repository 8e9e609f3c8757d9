"""Tests of evio_lib.features.training.metrics: closed-form precision/recall cases, tolerance, masks, batches, and a
brute-force nearest-neighbour reference."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

from evio_lib.features.training.metrics import detection_counts, keypoints_to_map, precision_recall


def test_exact_precision_recall_closed_form() -> None:
    true = np.zeros((6, 6))
    pred = np.zeros((6, 6))
    true[[1, 2, 4, 5], [1, 3, 4, 0]] = 1  # 4 labels
    pred[[1, 2, 0], [1, 3, 5]] = 1  # 3 detections, 2 on labels
    p, r = precision_recall(pred, true)
    assert (p, r) == (2 / 3, 2 / 4)  # Eq. 13: sum(y_true y_pred) / sum(y_pred); Eq. 14: ... / sum(y_true)
    assert precision_recall(true, true) == (1.0, 1.0)


def test_tolerance_one_pixel_is_euclidean() -> None:
    true = np.zeros((7, 7))
    true[3, 3] = 1
    for (r, c), within_1 in {(3, 4): True, (2, 3): True, (4, 4): False, (3, 5): False}.items():
        pred = np.zeros((7, 7))
        pred[r, c] = 1
        assert precision_recall(pred, true) == (0.0, 0.0)
        assert precision_recall(pred, true, tolerance=1) == ((1.0, 1.0) if within_1 else (0.0, 0.0))
    pred = np.zeros((7, 7))
    pred[4, 4] = 1  # diagonal neighbour, sqrt(2) px away
    assert precision_recall(pred, true, tolerance=1.5) == (1.0, 1.0)


def test_tolerance_counts_detections_and_labels_separately() -> None:
    true = np.zeros((5, 8))
    pred = np.zeros((5, 8))
    true[2, 2] = 1
    pred[2, 1] = pred[2, 3] = 1  # two detections next to one label
    counts = detection_counts(pred, true, tolerance=1)
    assert counts.correct_predictions.tolist() == [2] and counts.predictions.tolist() == [2]
    assert counts.found_labels.tolist() == [1] and counts.labels.tolist() == [1]
    assert precision_recall(pred, true, tolerance=1) == (1.0, 1.0)


def test_valid_mask_ignores_pixels() -> None:
    true = np.zeros((4, 4))
    pred = np.zeros((4, 4))
    true[0, 0] = true[3, 3] = 1
    pred[0, 0] = pred[1, 2] = 1
    mask = np.ones((4, 4), bool)
    mask[3, 3] = mask[1, 2] = False  # one label and one false detection lie in the warp fill
    assert precision_recall(pred, true) == (0.5, 0.5)
    assert precision_recall(pred, true, valid_mask=mask) == (1.0, 1.0)


def test_batch_micro_average_and_torch_input() -> None:
    true = np.zeros((2, 4, 4))
    pred = np.zeros((2, 4, 4))
    true[0, 1, 1] = 1
    pred[0, 1, 1] = 1  # image 0: 1 / 1
    true[1, [0, 1, 2], [0, 1, 2]] = 1
    pred[1, [0, 3], [0, 3]] = 1  # image 1: 1 correct of 2 detections, 1 of 3 labels
    counts = detection_counts(pred, true)
    assert counts.correct_predictions.tolist() == [1, 1] and counts.labels.tolist() == [1, 3]
    assert precision_recall(pred, true) == (2 / 3, 2 / 4)
    assert precision_recall(torch.from_numpy(pred), torch.from_numpy(true).bool()) == (2 / 3, 2 / 4)


def test_matches_brute_force_nearest_neighbours(rng: np.random.Generator) -> None:
    shape = (2, 30, 40)
    pred = rng.random(shape) > 0.97
    true = rng.random(shape) > 0.97
    for tol in (0.0, 1.0, 2.0, 2.5):
        correct = found = 0
        for b in range(shape[0]):
            p = np.argwhere(pred[b])
            t = np.argwhere(true[b])
            correct += int((cKDTree(t).query(p)[0] <= tol).sum())
            found += int((cKDTree(p).query(t)[0] <= tol).sum())
        expected = (correct / pred.sum(), found / true.sum())
        assert precision_recall(pred, true, tolerance=tol) == pytest.approx(expected)


def test_empty_maps_and_zero_division() -> None:
    empty = np.zeros((4, 4))
    assert precision_recall(empty, empty) == (0.0, 0.0)
    p, r = precision_recall(empty, empty, zero_division=float("nan"))
    assert np.isnan(p) and np.isnan(r)


def test_keypoints_to_map_rounds_and_drops_outside() -> None:
    m = keypoints_to_map(np.array([[0.4, 0.4], [3.6, 2.2], [-1.0, 0.0], [2.0, 9.0]]), (4, 5))
    assert m.dtype == bool and m.sum() == 2 and m[0, 0] and m[2, 4]
    assert keypoints_to_map(np.zeros((0, 2)), (3, 3)).sum() == 0


def test_bad_input() -> None:
    with pytest.raises(ValueError, match="true must have the shape of pred"):
        precision_recall(np.zeros((4, 4)), np.zeros((4, 5)))
    with pytest.raises(ValueError, match=r"pred must have shape \(H, W\) or \(B, H, W\)"):
        precision_recall(np.zeros(4), np.zeros(4))
    with pytest.raises(ValueError, match="tolerance must be a finite number"):
        precision_recall(np.zeros((4, 4)), np.zeros((4, 4)), tolerance=-1)
    with pytest.raises(ValueError, match="valid_mask must have the shape"):
        precision_recall(np.zeros((4, 4)), np.zeros((4, 4)), valid_mask=np.ones((2, 2)))
    with pytest.raises(ValueError, match=r"keypoints must be a finite \(N, 2\)"):
        keypoints_to_map(np.zeros((3, 3)), (4, 4))
