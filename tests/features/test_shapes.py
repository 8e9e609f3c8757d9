"""Tests for evio_lib.features.training.shapes: keypoints checked against OpenCV's sub-pixel corner refinement and
corner response, proportions against the thesis, determinism and the dataset interface."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from evio_lib.features.training.augment import Sample, keypoints_to_map
from evio_lib.features.training.shapes import (
    SHAPE_COUNTS,
    SHAPE_KINDS,
    UNLABELLED_KINDS,
    SyntheticShapes,
    generate_shape_image,
    kind_schedule,
)

LABELLED = [k for k in SHAPE_KINDS if k not in UNLABELLED_KINDS]
CORNER_KINDS = ["checkerboard", "polygon", "multiple_polygons", "cube", "stripes"]


def subpixel_errors(image: np.ndarray, keypoints: np.ndarray) -> np.ndarray:
    """Distances between keypoints and cv2.cornerSubPix refinements started at them (interior points only)."""
    h, w = image.shape
    inside = (keypoints[:, 0] > 6) & (keypoints[:, 0] < w - 7) & (keypoints[:, 1] > 6) & (keypoints[:, 1] < h - 7)
    start = keypoints[inside].reshape(-1, 1, 2).astype(np.float32)
    if len(start) == 0:
        return np.zeros(0)
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-5)
    refined = cv2.cornerSubPix(image, start.copy(), (4, 4), (-1, -1), criteria)
    return np.linalg.norm(refined - start, axis=-1).ravel()


@pytest.mark.parametrize("kind", SHAPE_KINDS)
def test_every_kind_gives_a_valid_image(kind):
    for seed in range(4):
        image, keypoints = generate_shape_image(kind, (120, 160), seed)
        assert image.shape == (120, 160) and image.dtype == np.float32
        assert 0.0 <= image.min() and image.max() <= 1.0 and image.std() > 0.02
        assert keypoints.dtype == np.float32 and keypoints.ndim == 2 and keypoints.shape[1] == 2
        if kind in UNLABELLED_KINDS:
            assert len(keypoints) == 0
        else:
            assert len(keypoints) >= 1
            r, c = np.rint(keypoints[:, 1]), np.rint(keypoints[:, 0])
            assert ((r >= 0) & (r <= 119) & (c >= 0) & (c <= 159)).all()


def test_generation_is_seeded():
    a = generate_shape_image("star", (60, 80), 5)
    b = generate_shape_image("star", (60, 80), np.random.default_rng(5))
    c = generate_shape_image("star", (60, 80), 6)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.array_equal(a[0], c[0])


@pytest.mark.parametrize("kind", CORNER_KINDS)
def test_corner_keypoints_are_where_opencv_refines_them(kind):
    # cornerSubPix converges to the corner/saddle point of the drawn image: the labels must sit there to well under
    # a pixel (pixel centres at integer coordinates); the same labels shifted by half a pixel must not
    errors, shifted = [], []
    for seed in range(12):
        image, keypoints = generate_shape_image(kind, (240, 320), seed)
        errors.append(subpixel_errors(image, keypoints))
        shifted.append(subpixel_errors(image, keypoints + 0.5))
    errors, shifted = np.concatenate(errors), np.concatenate(shifted)
    assert len(errors) >= 20
    assert np.median(errors) < 0.35, np.median(errors)
    assert np.median(shifted) > 0.55, np.median(shifted)


@pytest.mark.parametrize("kind", LABELLED)
def test_keypoints_have_a_strong_corner_response(kind):
    ratios = []
    for seed in range(6):
        image, keypoints = generate_shape_image(kind, (120, 160), seed)
        response = cv2.cornerMinEigenVal(image, 5)
        at_kp = response[np.rint(keypoints[:, 1]).astype(int), np.rint(keypoints[:, 0]).astype(int)]
        ratios.append(np.median(at_kp) / max(np.median(response), 1e-9))
    assert np.median(ratios) > 20.0, ratios


def test_kind_schedule_has_the_thesis_proportions():
    cycle = kind_schedule()
    assert len(cycle) == 66  # 66,000 images / 1,000
    for kind, count in SHAPE_COUNTS.items():
        assert cycle.count(kind) == count // 1000
    assert sum(SHAPE_COUNTS.values()) == 66000
    assert kind_schedule(seed=1) != cycle and sorted(kind_schedule(seed=1)) == sorted(cycle)
    assert kind_schedule({"polygon": 4, "lines": 2}).count("polygon") == 2
    with pytest.raises(ValueError, match="counts keys must be kinds from"):
        kind_schedule({"circle": 3})
    with pytest.raises(ValueError, match="at least one kind a positive count"):
        kind_schedule({"polygon": 0})


def test_bad_arguments_are_rejected():
    with pytest.raises(ValueError, match=r"kind must be one of"):
        generate_shape_image("triangle")
    with pytest.raises(ValueError, match=r"shape must be \(height, width\) of ints >= 16; got \(8, 8\)"):
        generate_shape_image("polygon", (8, 8))
    with pytest.raises(ValueError, match="split must be one of"):
        SyntheticShapes(split="dev")
    with pytest.raises(ValueError, match="n_images must be a positive int"):
        SyntheticShapes(0)


def test_dataset_items_and_determinism():
    data = SyntheticShapes(132, seed=3)
    assert len(data) == 132 and len(SyntheticShapes()) == 66000 and len(SyntheticShapes(split="val")) == 3200
    kinds = [data.kind_of(i) for i in range(132)]
    for kind, count in SHAPE_COUNTS.items():
        assert kinds.count(kind) == 2 * count // 1000  # exact proportions in every 66 images
    item = data[5]
    assert isinstance(item, Sample)
    assert tuple(item.image.shape) == (1, 120, 160) and item.image.dtype == torch.float32
    assert tuple(item.keypoint_map.shape) == (120, 160) and tuple(item.valid_mask.shape) == (120, 160)
    again = SyntheticShapes(132, seed=3)[5]
    assert torch.equal(item.image, again.image) and torch.equal(item.keypoint_map, again.keypoint_map)
    # augmentation: varies with the epoch, the underlying image does not
    raw_before = data.raw(5)[0]
    data.set_epoch(1)
    assert not torch.equal(data[5].image, item.image)
    np.testing.assert_array_equal(data.raw(5)[0], raw_before)
    # splits use different images
    val = SyntheticShapes(10, split="val", seed=3)
    assert not np.array_equal(val.raw(0)[0], SyntheticShapes(10, split="train", seed=3).raw(0)[0])


def test_augmented_labels_follow_the_homography():
    data = SyntheticShapes(20, seed=1)
    for i in range(6):
        sample = data.sample(i)
        raw_image, raw_kp = data.raw(i)
        if len(raw_kp) == 0:
            continue
        H = sample["homography"]
        moved = cv2.perspectiveTransform(raw_kp.reshape(-1, 1, 2).astype(np.float64), H).reshape(-1, 2)
        # every returned keypoint is the image of a raw keypoint, on a valid pixel
        d = np.linalg.norm(sample["keypoints"][:, None] - moved[None], axis=-1)
        assert len(sample["keypoints"]) == 0 or d.min(axis=1).max() < 1e-3
        rows, cols = np.rint(sample["keypoints"][:, 1]).astype(int), np.rint(sample["keypoints"][:, 0]).astype(int)
        assert sample["valid_mask"][rows, cols].all()
        assert not np.allclose(H, np.eye(3))


def test_validation_items_are_not_augmented():
    val = SyntheticShapes(10, split="val", seed=2)
    for i in range(3):
        image, keypoints = val.raw(i)
        item = val[i]
        np.testing.assert_array_equal(item.image[0].numpy(), image)
        np.testing.assert_array_equal(item.keypoint_map.numpy(), keypoints_to_map(keypoints, image.shape))
        assert float(item.valid_mask.min()) == 1.0


def test_dataloader_batches():
    loader = DataLoader(SyntheticShapes(8, seed=0), batch_size=4, shuffle=False)
    batch = next(iter(loader))
    assert isinstance(batch, Sample) and tuple(batch.image.shape) == (4, 1, 120, 160)
