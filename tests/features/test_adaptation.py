"""Tests for evio_lib.features.training.adaptation: equivariant detectors are reproduced, counts match an independent
computation, non-equivariant responses are averaged out, NMS matches a brute-force greedy loop."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from evio_lib.features.training.adaptation import (
    adaptation_homographies,
    heatmap_to_keypoints,
    homographic_adaptation,
    label_images,
)
from evio_lib.features.training.augment import HOMOGRAPHIC_ADAPTATION
from evio_lib.geometry.homography import valid_mask, warp_points

SHAPE = (96, 128)


def smooth_image(rng: np.random.Generator, shape=SHAPE) -> np.ndarray:
    noise = rng.random((shape[0] // 12, shape[1] // 12)).astype(np.float32)
    img = cv2.resize(noise, (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC)
    img = cv2.GaussianBlur(img, (0, 0), 4.0)
    return ((img - img.min()) / (img.max() - img.min())).astype(np.float32)


def blob_image(points, shape=SHAPE, sigma=2.0) -> np.ndarray:
    ys, xs = np.mgrid[0 : shape[0], 0 : shape[1]]
    img = np.zeros(shape, np.float32)
    for x, y in points:
        img = np.maximum(img, np.exp(-((xs - x) ** 2 + (ys - y) ** 2) / (2 * sigma**2)).astype(np.float32))
    return img


def test_homographies_start_with_identity_and_are_seeded():
    Hs = adaptation_homographies(SHAPE, 5, 3)
    assert Hs.shape == (5, 3, 3)
    np.testing.assert_array_equal(Hs[0], np.eye(3))
    np.testing.assert_array_equal(Hs, adaptation_homographies(SHAPE, 5, np.random.default_rng(3)))
    assert not np.allclose(Hs[1], Hs[2])
    with pytest.raises(ValueError, match="n_homographies must be a positive int"):
        adaptation_homographies(SHAPE, 0, 3)


def test_counts_and_normalisation(rng):
    img = smooth_image(rng)
    result = homographic_adaptation(img, lambda b: np.ones_like(b), rng=4, n_homographies=20)
    seen = result.counts > 0
    assert seen.all()  # the identity view sees every pixel
    np.testing.assert_allclose(result.heatmap[seen], 1.0, atol=1e-6)  # mean of ones is one
    # independent count: pixel u counts for view i when round(H_i u) is a valid (eroded) pixel of view i
    ys, xs = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]]
    grid = np.stack([xs.ravel(), ys.ravel()], 1).astype(float)
    expected = np.zeros(SHAPE[0] * SHAPE[1], int)
    for H in result.homographies:
        mask = valid_mask(SHAPE, H, erode=HOMOGRAPHIC_ADAPTATION.valid_border_margin)
        v = np.rint(warp_points(H, grid)).astype(int)
        inside = (v[:, 0] >= 0) & (v[:, 0] < SHAPE[1]) & (v[:, 1] >= 0) & (v[:, 1] < SHAPE[0])
        ok = np.zeros(len(grid), bool)
        ok[inside] = mask[v[inside, 1], v[inside, 0]]
        expected += ok
    expected = expected.reshape(SHAPE)
    agree = (result.counts == expected).mean()
    assert agree > 0.995, agree  # rounding at exact half-pixels may differ (OpenCV's fixed-point remap)
    assert np.abs(result.counts - expected).max() <= 1
    assert result.counts.max() == 20 and result.counts.min() >= 1


def test_equivariant_detector_is_reproduced(rng):
    img = smooth_image(rng)
    response = img**2  # a pixel-wise detector commutes with every warp
    result = homographic_adaptation(img, lambda b: b**2, rng=1, n_homographies=30)
    err = np.abs(result.heatmap - response)
    assert err.max() < 0.02 and err.mean() < 0.003, (err.max(), err.mean())


def test_viewpoint_dependent_responses_are_averaged_out():
    point = (60.0, 45.0)
    img = blob_image([point])

    def fixed_spot(batch):  # fires at the same view pixel whatever the image: not equivariant
        return np.broadcast_to(blob_image([point]), batch.shape).copy()

    real = homographic_adaptation(img, lambda b: b, rng=2, n_homographies=40)
    fake = homographic_adaptation(img, fixed_spot, rng=2, n_homographies=40)
    r, c = int(point[1]), int(point[0])
    assert real.heatmap[r, c] > 0.8  # the image's own blob survives the averaging
    assert fake.heatmap[r, c] < 0.3  # a response tied to the view position is diluted
    assert fake.heatmap.max() < 0.5


def test_deterministic_and_independent_of_batch_size(rng):
    img = smooth_image(rng)

    def detector(batch):
        return np.stack([cv2.cornerMinEigenVal(b, 3) for b in batch])

    a = homographic_adaptation(img, detector, rng=5, n_homographies=12, batch_size=1)
    b = homographic_adaptation(img, detector, rng=5, n_homographies=12, batch_size=5)
    c = homographic_adaptation(img, detector, rng=6, n_homographies=12, batch_size=5)
    np.testing.assert_allclose(a.heatmap, b.heatmap, atol=1e-7)
    np.testing.assert_array_equal(a.counts, b.counts)
    assert not np.allclose(a.heatmap, c.heatmap)
    m = homographic_adaptation(img, detector, rng=5, n_homographies=12, aggregation="max")
    assert (m.heatmap >= a.heatmap - 1e-7).all()


def test_torch_detector_and_bad_detectors(rng):
    img = smooth_image(rng)
    out = homographic_adaptation(img, lambda b: torch.from_numpy(b) * 2.0, rng=0, n_homographies=3)
    assert out.heatmap.dtype == np.float32 and out.heatmap.max() > 1.0
    with pytest.raises(ValueError, match=r"heatmap_fn must return heatmaps of shape \(3, 96, 128\)"):
        homographic_adaptation(img, lambda b: b[:, ::2], rng=0, n_homographies=3, batch_size=3)
    with pytest.raises(ValueError, match="heatmap_fn must be callable"):
        homographic_adaptation(img, None, rng=0)
    with pytest.raises(ValueError, match="aggregation must be 'mean' or 'max'"):
        homographic_adaptation(img, lambda b: b, rng=0, aggregation="median")
    with pytest.raises(ValueError, match=r"homographies must have shape \(N, 3, 3\)"):
        homographic_adaptation(img, lambda b: b, rng=0, homographies=np.eye(3))


def brute_force_nms(heatmap, threshold, radius, border):
    """Greedy NMS by a plain loop: visit pixels by descending score, keep unless a kept one is within the box."""
    h, w = heatmap.shape
    rows, cols = np.nonzero(heatmap >= threshold)
    order = sorted(range(len(rows)), key=lambda i: (-heatmap[rows[i], cols[i]], i))
    kept = []
    for i in order:
        r, c = rows[i], cols[i]
        if r < border or c < border or r >= h - border or c >= w - border:
            continue
        if all(max(abs(r - kr), abs(c - kc)) > radius for kr, kc in kept):
            kept.append((r, c))
    return [(float(c), float(r)) for r, c in kept]


def test_heatmap_to_keypoints_matches_greedy_nms(rng):
    heat = cv2.GaussianBlur(rng.random((40, 50)).astype(np.float32), (0, 0), 1.0)
    heat[heat < np.percentile(heat, 80)] = 0.0
    kp, scores = heatmap_to_keypoints(heat, threshold=0.3, nms_radius=2, border=3)
    assert kp.dtype == np.float32 and scores.dtype == np.float32
    assert [tuple(p) for p in kp.tolist()] == brute_force_nms(heat, 0.3, 2, 3)
    assert (np.diff(scores) <= 0).all()
    top, _ = heatmap_to_keypoints(heat, threshold=0.3, nms_radius=2, border=3, max_keypoints=5)
    np.testing.assert_array_equal(top, kp[:5])
    mask = np.zeros(heat.shape, bool)
    mask[:, :25] = True
    left, _ = heatmap_to_keypoints(heat, 0.3, 2, 3, valid=mask)
    assert (left[:, 0] < 25).all() and len(left) < len(kp)
    with pytest.raises(ValueError, match="border must be a non-negative int"):
        heatmap_to_keypoints(heat, border=-1)
    with pytest.raises(ValueError, match=r"valid must have shape \(40, 50\)"):
        heatmap_to_keypoints(heat, valid=np.ones((2, 2), bool))


def test_label_images_finds_blob_centres():
    points = [(30.0, 30.0), (90.0, 60.0)]
    images = [blob_image(points, sigma=2.5), blob_image(points[:1], sigma=2.5)]
    labels = label_images(images, lambda b: b, rng=0, n_homographies=10, threshold=0.5)
    assert [len(k) for k in labels] == [2, 1]
    np.testing.assert_allclose(sorted(labels[0].tolist()), points, atol=1.0)
    again = label_images(images, lambda b: b, rng=0, n_homographies=10, threshold=0.5)
    assert all(np.array_equal(a, b) for a, b in zip(labels, again))
