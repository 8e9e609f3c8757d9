"""Tests for evio_lib.features.evaluation.evaluate: constructed cases with known answers, brute-force references and
OpenCV."""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from evio_lib.features.evaluation.evaluate import (
    average_precision,
    corner_error,
    descriptor_distances,
    diagnose_matches,
    estimate_homography,
    homography_correctness,
    localisation_error,
    match_descriptors,
    matching_score,
    mean_average_precision,
    repeatability,
)

SHAPE = (60, 80)  # (height, width) of the constructed images


def grid_points(shape=SHAPE, step=10, margin=5) -> np.ndarray:
    """Return (N, 2) points (x, y) on a regular grid inside an image of the given shape."""
    xs, ys = np.meshgrid(np.arange(margin, shape[1] - margin, step), np.arange(margin, shape[0] - margin, step))
    return np.column_stack([xs.ravel(), ys.ravel()]).astype(np.float64)


def translation(dx: float, dy: float) -> np.ndarray:
    return np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]])


def random_homography(rng: np.random.Generator, shape=SHAPE, jitter=0.08) -> np.ndarray:
    """Return a mild random homography: the image corners moved by up to jitter * size (OpenCV's 4-point solve)."""
    h, w = shape
    src = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], np.float32)
    dst = src + rng.uniform(-jitter, jitter, (4, 2)).astype(np.float32) * np.array([w, h], np.float32)
    return cv2.getPerspectiveTransform(src, dst).astype(np.float64)


def cv_warp(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Warp points with OpenCV (an implementation independent of the module's)."""
    return cv2.perspectiveTransform(pts.reshape(-1, 1, 2).astype(np.float64), H).reshape(-1, 2)


def inside(p, shape):
    """Return whether each (x, y) lies on the pixel area of an image of the given (height, width)."""
    return (p[:, 0] >= -0.5) & (p[:, 0] < shape[1] - 0.5) & (p[:, 1] >= -0.5) & (p[:, 1] < shape[0] - 0.5)


def brute_force_repeatability(kp1, kp2, H, shape1, shape2, eps):
    """SuperPoint's definition written out with full distance matrices and OpenCV warps."""
    w1 = cv_warp(H, kp1)
    a = w1[inside(w1, shape2)]
    b = kp2[inside(cv_warp(np.linalg.inv(H), kp2), shape1)]
    if len(a) + len(b) == 0:
        return math.nan
    count = 0
    for p in a:
        count += len(b) > 0 and min(np.hypot(*(p - q)) for q in b) <= eps
    for q in b:
        count += len(a) > 0 and min(np.hypot(*(q - p)) for p in a) <= eps
    return count / (len(a) + len(b))


# ---------------------------------------------------------------------------------------------- repeatability
def test_repeatability_identical_keypoints_is_one():
    kp = grid_points()
    assert repeatability(kp, kp, np.eye(3), SHAPE, SHAPE, eps=1.0) == 1.0
    np.testing.assert_array_equal(repeatability(kp, kp, np.eye(3), SHAPE, SHAPE, eps=[1, 3, 5]), [1.0, 1.0, 1.0])


def test_repeatability_shift_of_two_pixels():
    kp1 = grid_points()
    kp2 = kp1 + [2.0, 0.0]  # detections 2 px away from where H (identity) puts them
    assert repeatability(kp1, kp2, np.eye(3), SHAPE, SHAPE, eps=1.0) == 0.0
    assert repeatability(kp1, kp2, np.eye(3), SHAPE, SHAPE, eps=3.0) == 1.0
    # with a homography that predicts the shift, the same detections repeat exactly
    assert repeatability(kp1, kp2, translation(2, 0), SHAPE, SHAPE, eps=1.0) == 1.0


def test_repeatability_shift_inside_the_view_is_exact_at_eps_3():
    kp1 = grid_points(margin=10)  # every point and its shifted copy stay well inside the image
    rep = repeatability(kp1, kp1 + [0.0, 2.0], np.eye(3), SHAPE, SHAPE, eps=[1.0, 2.0, 3.0])
    np.testing.assert_array_equal(rep, [0.0, 1.0, 1.0])  # <= eps counts (thesis Eq. 15)


def test_repeatability_excludes_points_outside_the_shared_view():
    H = translation(30.0, 0.0)  # image 2 sees image 1 moved 30 px to the right
    kp1 = grid_points()
    warped = kp1 + [30.0, 0.0]
    visible = warped[:, 0] < SHAPE[1] - 0.5
    assert 0 < visible.sum() < len(kp1)
    kp2 = warped[visible]  # image 2 detects exactly the visible ones ...
    extra = np.array([[5.0, 20.0], [12.0, 40.0]])  # ... plus points left of x = 29.5, which image 1 never saw
    rep = repeatability(kp1, np.vstack([kp2, extra]), H, SHAPE, SHAPE, eps=1.0)
    assert rep == 1.0
    # a visible point of image 1 without a partner counts against it: (2 n) / (2 n + 1)
    n = int(visible.sum())
    rep = repeatability(kp1, kp2[1:], H, SHAPE, SHAPE, eps=1.0)
    assert rep == pytest.approx(2 * (n - 1) / (2 * n - 1))


def test_repeatability_matches_brute_force(rng):
    for _ in range(5):
        H = random_homography(rng)
        kp1 = rng.uniform([0, 0], [SHAPE[1] - 1, SHAPE[0] - 1], (40, 2))
        kp2 = np.vstack([cv_warp(H, kp1[:25]) + rng.normal(0, 1.5, (25, 2)),
                         rng.uniform([0, 0], [SHAPE[1] - 1, SHAPE[0] - 1], (10, 2))])
        for eps in (1.0, 3.0, 5.0):
            expected = brute_force_repeatability(kp1, kp2, H, SHAPE, SHAPE, eps)
            assert repeatability(kp1, kp2, H, SHAPE, SHAPE, eps) == pytest.approx(expected, abs=1e-12)


def test_repeatability_keep_k_uses_the_strongest_visible_points():
    kp = np.array([[10.0, 10.0], [30.0, 10.0], [50.0, 10.0], [70.0, 10.0]])
    scores = np.array([0.9, 0.8, 0.1, 0.2])
    kp2 = kp[[0, 1, 3]]  # image 2 misses point 2, the weakest of image 1
    # keep_k=2: image 1 keeps points 0, 1; image 2 keeps its points 0, 1 (scores 0.9, 0.8): all repeat
    assert repeatability(kp, kp2, np.eye(3), SHAPE, SHAPE, 1.0, scores1=scores, scores2=scores[[0, 1, 3]],
                         keep_k=2) == 1.0
    assert repeatability(kp, kp2, np.eye(3), SHAPE, SHAPE, 1.0) == pytest.approx(6 / 7)


def test_repeatability_empty_detections():
    kp = grid_points()
    assert math.isnan(repeatability(np.zeros((0, 2)), np.zeros((0, 2)), np.eye(3), SHAPE, SHAPE))
    assert repeatability(kp, np.zeros((0, 2)), np.eye(3), SHAPE, SHAPE) == 0.0


def test_repeatability_does_not_modify_inputs():
    kp1, kp2 = grid_points(), grid_points() + 1.0
    before = kp1.copy(), kp2.copy()
    repeatability(kp1, kp2, translation(1, 1), SHAPE, SHAPE, eps=[1, 3])
    np.testing.assert_array_equal(kp1, before[0])
    np.testing.assert_array_equal(kp2, before[1])


def test_repeatability_bad_input():
    kp = grid_points()
    with pytest.raises(ValueError, match=r"kp1 must have shape \(N, 2\)"):
        repeatability(np.zeros((5, 3)), kp, np.eye(3), SHAPE, SHAPE)
    with pytest.raises(ValueError, match="H must be an invertible"):
        repeatability(kp, kp, np.zeros((3, 3)), SHAPE, SHAPE)
    with pytest.raises(ValueError, match="eps must be a pixel threshold"):
        repeatability(kp, kp, np.eye(3), SHAPE, SHAPE, eps=-1.0)
    with pytest.raises(ValueError, match="shape2 must be an image shape"):
        repeatability(kp, kp, np.eye(3), SHAPE, (60.5, 80))
    with pytest.raises(ValueError, match="keep_k needs scores1 and scores2"):
        repeatability(kp, kp, np.eye(3), SHAPE, SHAPE, keep_k=10)
    with pytest.raises(ValueError, match=r"scores1 must have shape \(N1,\)"):
        repeatability(kp, kp, np.eye(3), SHAPE, SHAPE, scores1=np.ones(3), scores2=np.ones(len(kp)), keep_k=5)


# ---------------------------------------------------------------------------------------------- localisation error
def test_localisation_error_of_a_constant_offset_is_the_offset():
    kp = grid_points()  # 10 px apart: every point's nearest neighbour is its own copy
    assert localisation_error(kp, kp + [2.3, 0.0], translation(2, 0), SHAPE, SHAPE) == pytest.approx(0.3)
    assert localisation_error(kp, kp + [3.0, 4.0], np.eye(3), SHAPE, SHAPE, eps=6.0) == pytest.approx(5.0)
    assert math.isnan(localisation_error(kp, kp + [3.0, 4.0], np.eye(3), SHAPE, SHAPE, eps=3.0))  # none found


def test_localisation_error_matches_brute_force(rng):
    for _ in range(5):
        H = random_homography(rng)
        kp1 = rng.uniform([0, 0], [SHAPE[1] - 1, SHAPE[0] - 1], (40, 2))
        kp2 = np.vstack([cv_warp(H, kp1[:25]) + rng.normal(0, 1.0, (25, 2)),
                         rng.uniform([0, 0], [SHAPE[1] - 1, SHAPE[0] - 1], (10, 2))])
        w1 = cv_warp(H, kp1)
        a = w1[inside(w1, SHAPE)]
        b = kp2[inside(cv_warp(np.linalg.inv(H), kp2), SHAPE)]
        D = np.hypot(*(a[:, None, :] - b[None, :, :]).transpose(2, 0, 1))  # (len a, len b) in image 2's frame
        d = np.concatenate([D.min(axis=1), D.min(axis=0)])
        for eps in (1.0, 3.0):
            assert localisation_error(kp1, kp2, H, SHAPE, SHAPE, eps) == pytest.approx(d[d <= eps].mean(), abs=1e-12)


def test_localisation_error_bad_input():
    kp = grid_points()
    with pytest.raises(ValueError, match="eps must be a single pixel threshold"):
        localisation_error(kp, kp, np.eye(3), SHAPE, SHAPE, eps=[1.0, 3.0])
    with pytest.raises(ValueError, match="eps must be a pixel threshold"):
        localisation_error(kp, kp, np.eye(3), SHAPE, SHAPE, eps=math.inf)
    with pytest.raises(ValueError, match=r"kp2 must have shape \(N, 2\)"):
        localisation_error(kp, kp[:, :1], np.eye(3), SHAPE, SHAPE)


# ---------------------------------------------------------------------------------------------- homography
def test_corner_error_against_opencv_corners(rng):
    H_true = random_homography(rng)
    H_est = random_homography(rng)
    h, w = SHAPE
    corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], np.float64)
    expected = np.linalg.norm(cv_warp(H_est, corners) - cv_warp(H_true, corners), axis=1).mean()
    assert corner_error(H_est, H_true, SHAPE) == pytest.approx(expected, rel=1e-12)
    assert corner_error(3.0 * H_true, H_true, SHAPE) == pytest.approx(0.0, abs=1e-9)  # scale of H is irrelevant


def test_homography_correctness_thresholds(rng):
    H_true = random_homography(rng)
    shifted = translation(3.0, 4.0) @ H_true  # every warped corner 5 px off
    assert corner_error(shifted, H_true, SHAPE) == pytest.approx(5.0)
    assert homography_correctness(shifted, H_true, SHAPE, eps=[1, 3, 5]).tolist() == [False, False, True]
    assert homography_correctness(H_true, H_true, SHAPE, eps=1) is True
    assert homography_correctness(None, H_true, SHAPE, eps=5) is False
    assert corner_error(None, H_true, SHAPE) == math.inf
    assert corner_error(np.full((3, 3), np.nan), H_true, SHAPE) == math.inf


def test_homography_correctness_bad_input():
    with pytest.raises(ValueError, match=r"H_est must be a \(3, 3\) homography or None"):
        homography_correctness(np.eye(2), np.eye(3), SHAPE)
    with pytest.raises(ValueError, match=r"H_true must be a \(3, 3\) homography"):
        homography_correctness(np.eye(3), np.eye(4), SHAPE)


# ---------------------------------------------------------------------------------------------- matching
def brute_force_mutual(dist: np.ndarray, mutual: bool) -> list[list[int]]:
    out = []
    for i in range(dist.shape[0]):
        j = int(np.argmin(dist[i]))
        if not mutual or int(np.argmin(dist[:, j])) == i:
            out.append([i, j])
    return out


def test_float_distances_and_matching_against_brute_force_and_opencv(rng):
    d1 = rng.normal(size=(50, 16)).astype(np.float32)
    d2 = np.vstack([d1[:30] + rng.normal(0, 0.3, (30, 16)), rng.normal(size=(25, 16))]).astype(np.float32)
    d1 /= np.linalg.norm(d1, axis=1, keepdims=True)
    d2 /= np.linalg.norm(d2, axis=1, keepdims=True)
    dist = descriptor_distances(d1, d2)
    reference = np.array([[np.linalg.norm(a.astype(np.float64) - b) for b in d2] for a in d1])
    np.testing.assert_allclose(dist, reference, atol=1e-6)
    for mutual in (True, False):
        assert match_descriptors(d1, d2, mutual=mutual).tolist() == brute_force_mutual(reference, mutual)
    cv_matches = cv2.BFMatcher(cv2.NORM_L2, crossCheck=True).match(d1, d2)
    assert sorted([m.queryIdx, m.trainIdx] for m in cv_matches) == match_descriptors(d1, d2).tolist()


def test_hamming_distances_on_packed_bits_against_unpackbits(rng):
    d1 = rng.integers(0, 256, (40, 32), dtype=np.uint8)  # 256-bit descriptors, ORB-like
    d2 = np.vstack([d1[:20] ^ (rng.random((20, 32)) < 0.05).astype(np.uint8), rng.integers(0, 256, (15, 32))])
    d2 = d2.astype(np.uint8)
    dist = descriptor_distances(d1, d2, binary=True)
    reference = np.array([[np.unpackbits(a ^ b).sum() for b in d2] for a in d1], dtype=np.float64)
    np.testing.assert_array_equal(dist, reference)
    assert cv2.norm(d1[3], d2[7], cv2.NORM_HAMMING) == dist[3, 7]
    for mutual in (True, False):
        assert match_descriptors(d1, d2, binary=True, mutual=mutual).tolist() == brute_force_mutual(reference, mutual)
    assert match_descriptors(d1, d2, binary=True)[:20].tolist() == [[i, i] for i in range(20)]


def test_matching_empty_and_bad_input():
    assert match_descriptors(np.zeros((0, 8)), np.ones((3, 8))).shape == (0, 2)
    with pytest.raises(ValueError, match="desc1 and desc2 must have the same length D"):
        match_descriptors(np.zeros((2, 8)), np.zeros((2, 4)))
    with pytest.raises(ValueError, match="desc1 must be uint8 packed bits"):
        match_descriptors(np.zeros((2, 8), np.float32), np.zeros((2, 8), np.uint8), binary=True)
    with pytest.raises(ValueError, match=r"desc2 must have shape \(N, D\)"):
        descriptor_distances(np.zeros((2, 8)), np.zeros(8))


def test_estimate_homography_with_outliers(rng):
    H_true = random_homography(rng, jitter=0.15)
    kp1 = rng.uniform([0, 0], [SHAPE[1] - 1, SHAPE[0] - 1], (60, 2))
    kp2 = cv_warp(H_true, kp1) + rng.normal(0, 0.2, (60, 2))
    kp2[:15] = rng.uniform([0, 0], [SHAPE[1] - 1, SHAPE[0] - 1], (15, 2))  # 25 % outliers
    matches = np.column_stack([np.arange(60), np.arange(60)])
    H, inliers = estimate_homography(kp1, kp2, matches)
    assert H is not None and H[2, 2] == pytest.approx(1.0)
    assert corner_error(H, H_true, SHAPE) < 1.0
    assert inliers.shape == (60,) and inliers[15:].mean() > 0.95 and inliers[:15].mean() < 0.3
    H_again, _ = estimate_homography(kp1, kp2, matches)
    np.testing.assert_array_equal(H, H_again)  # deterministic


def test_estimate_homography_too_few_matches_and_bad_input():
    kp = grid_points()
    H, inliers = estimate_homography(kp, kp, np.array([[0, 0], [1, 1], [2, 2]]))
    assert H is None and inliers.tolist() == [False] * 3
    with pytest.raises(ValueError, match="matches must index kp1"):
        estimate_homography(kp, kp, np.array([[0, 0], [1, len(kp)]]))
    with pytest.raises(ValueError, match=r"matches must be an \(M, 2\) int array"):
        estimate_homography(kp, kp, np.zeros((4, 2)))
    with pytest.raises(ValueError, match="ransac_threshold must be a number"):
        estimate_homography(kp, kp, np.zeros((4, 2), int), ransac_threshold=0.0)


# ---------------------------------------------------------------------------------------------- descriptor metrics
def test_matching_score_hand_example():
    kp = np.array([[10.0, 10.0], [40.0, 10.0], [10.0, 40.0], [40.0, 40.0]])
    desc = np.eye(4)
    assert matching_score(kp, kp, desc, desc, np.eye(3), (50, 50), (50, 50)) == 1.0
    # the descriptors of points 2 and 3 are swapped in image 2: both directions find 2 of 4 correct
    assert matching_score(kp, kp, desc, desc[[0, 1, 3, 2]], np.eye(3), (50, 50), (50, 50)) == 0.5
    # image 2 shifted by 25 px: only points 1 and 3 (x = 40 -> 15) stay in view; both match correctly
    H = translation(-25.0, 0.0)
    score = matching_score(kp, kp + [-25.0, 0.0], desc, desc, H, (50, 50), (50, 50), eps=[1.0])
    # 1 -> 2: 2 visible queries, both correct; 2 -> 1: points 1, 3 visible, both correct
    np.testing.assert_array_equal(score, [1.0])


def test_average_precision_hand_examples():
    # ranks 1 and 3 correct, 3 positives: (1/1 + 2/3) / 3
    assert average_precision([0.1, 0.2, 0.3, 0.4], [True, False, True, False], 3) == pytest.approx(5 / 9)
    # order of the input does not matter, only the distances
    assert average_precision([0.4, 0.3, 0.2, 0.1], [False, True, False, True], 3) == pytest.approx(5 / 9)
    # ties enter together: t = 0.1 -> P = 1/2, R = 1/2; t = 0.2 -> P = 2/3, R = 1
    assert average_precision([0.1, 0.1, 0.2], [True, False, True], 2) == pytest.approx(0.5 * 0.5 + 0.5 * 2 / 3)
    assert average_precision([0.1, 0.2], [True, True], 2) == 1.0
    assert math.isnan(average_precision([0.1], [False], 0))
    with pytest.raises(ValueError, match="n_positive must be an integer >="):
        average_precision([0.1, 0.2], [True, True], 1)
    with pytest.raises(ValueError, match="correct must be a bool array"):
        average_precision([0.1, 0.2], [1, 0], 1)


def brute_force_map(kp1, kp2, desc1, desc2, H, shape1, shape2, eps):
    """NN mAP written out with loops over queries and thresholds."""
    def inside(p, shape):
        return -0.5 <= p[0] < shape[1] - 0.5 and -0.5 <= p[1] < shape[0] - 0.5

    w1 = cv_warp(H, kp1)
    b2 = cv_warp(np.linalg.inv(H), kp2)
    aps = []
    for queries, q_pos, cands, c_pos, dq, dc, target in (
        (range(len(kp1)), w1, range(len(kp2)), kp2, desc1, desc2, shape2),
        (range(len(kp2)), kp2, range(len(kp1)), w1, desc2, desc1, shape1),
    ):
        rows = []
        for q in queries:
            visible = inside(w1[q], shape2) if dq is desc1 else inside(b2[q], shape1)
            if not visible:
                continue
            dists = [np.linalg.norm(dq[q] - dc[c]) for c in cands]
            nn = int(np.argmin(dists))
            pix = [np.linalg.norm(q_pos[q] - c_pos[c]) for c in cands]
            rows.append((dists[nn], pix[nn] <= eps, min(pix) <= eps))
        positives = sum(r[2] for r in rows)
        if positives == 0:
            continue
        ap, prev_recall = 0.0, 0.0
        for t in sorted({r[0] for r in rows}):
            taken = [r for r in rows if r[0] <= t]
            tp = sum(r[1] for r in taken)
            ap += (tp / positives - prev_recall) * tp / len(taken)
            prev_recall = tp / positives
        aps.append(ap)
    return float(np.mean(aps)) if aps else math.nan


def test_mean_average_precision_hand_example_and_brute_force(rng):
    kp = np.array([[10.0, 10.0], [40.0, 10.0], [10.0, 40.0], [40.0, 40.0]])
    desc = np.eye(4)
    assert mean_average_precision(kp, kp, desc, desc, np.eye(3), (50, 50), (50, 50)) == 1.0
    # swapped descriptors of points 2 and 3: all four NN distances are 0 (one tie group), 2 of 4 correct,
    # 4 positives -> P = 1/2 at R = 1/2 -> AP = 1/4 in both directions
    assert mean_average_precision(kp, kp, desc, desc[[0, 1, 3, 2]], np.eye(3), (50, 50), (50, 50)) == 0.25
    for _ in range(3):
        H = random_homography(rng)
        kp1 = rng.uniform([0, 0], [SHAPE[1] - 1, SHAPE[0] - 1], (30, 2))
        kp2 = np.vstack([cv_warp(H, kp1[:20]) + rng.normal(0, 1.0, (20, 2)),
                         rng.uniform([0, 0], [SHAPE[1] - 1, SHAPE[0] - 1], (8, 2))])
        desc1 = rng.normal(size=(30, 8))
        desc2 = np.vstack([desc1[:20] + rng.normal(0, 0.7, (20, 8)), rng.normal(size=(8, 8))])
        for eps in (1.0, 3.0):
            expected = brute_force_map(kp1, kp2, desc1, desc2, H, SHAPE, SHAPE, eps)
            got = mean_average_precision(kp1, kp2, desc1, desc2, H, SHAPE, SHAPE, eps)
            assert got == pytest.approx(expected, abs=1e-12)


def test_descriptor_metrics_bad_input():
    kp = grid_points()
    with pytest.raises(ValueError, match="desc1/desc2 must have one row per keypoint"):
        matching_score(kp, kp, np.eye(3), np.eye(3), np.eye(3), SHAPE, SHAPE)
    with pytest.raises(ValueError, match="eps must be a pixel threshold"):
        mean_average_precision(kp[:2], kp[:2], np.eye(2), np.eye(2), np.eye(3), SHAPE, SHAPE, eps=[])


# ---------------------------------------------------------------------------------------------- diagnosis
def test_diagnose_matches_noise_free_pair_is_exact(rng):
    H = random_homography(rng, jitter=0.15)
    kp1 = rng.uniform([0, 0], [SHAPE[1] - 1, SHAPE[0] - 1], (40, 2))
    desc = rng.normal(size=(40, 16))
    d = diagnose_matches(kp1, cv_warp(H, kp1), desc, desc, H, SHAPE)
    assert (d.n_matches, d.n_correct) == (40, 40)
    assert d.localisation_error < 1e-6 and d.corner_error_oracle < 1e-4 and d.corner_error_ransac < 1e-3


def test_diagnose_matches_localisation_error_is_the_rayleigh_mean(rng):
    # isotropic Gaussian noise of std s per axis on x2: the error norm is Rayleigh, mean s sqrt(pi / 2)
    H = random_homography(rng)
    sigma = 0.5
    kp1 = rng.uniform([0, 0], [SHAPE[1] - 1, SHAPE[0] - 1], (4000, 2))
    desc = np.eye(4000)
    d = diagnose_matches(kp1, cv_warp(H, kp1) + rng.normal(0, sigma, (4000, 2)), desc, desc, H, SHAPE)
    assert d.n_correct == 4000  # 3 px is 6 sigma
    assert d.localisation_error == pytest.approx(sigma * math.sqrt(math.pi / 2), rel=0.03)


def test_diagnose_matches_oracle_error_falls_with_the_number_of_correct_matches(rng):
    # least squares averages the noise: 16 times the points -> about a quarter of the corner error
    H = random_homography(rng)
    errors = {}
    for n in (25, 400):
        values = []
        for _ in range(20):
            kp1 = rng.uniform([0, 0], [SHAPE[1] - 1, SHAPE[0] - 1], (n, 2))
            kp2 = cv_warp(H, kp1) + rng.normal(0, 0.7, (n, 2))
            values.append(diagnose_matches(kp1, kp2, np.eye(n), np.eye(n), H, SHAPE).corner_error_oracle)
        errors[n] = np.median(values)
    assert 2.5 < errors[25] / errors[400] < 6.5


def test_diagnose_matches_counts_wrong_matches_and_the_oracle_ignores_them(rng):
    H = translation(3.0, -2.0)
    kp1 = grid_points()  # 10 px apart: a wrong match is off by >= 10 px
    n = len(kp1)
    desc1 = np.eye(n)
    order = np.arange(n)
    order[:10] = np.roll(order[:10], 1)  # the first 10 points get a neighbour's descriptor
    kp2 = cv_warp(H, kp1)
    d = diagnose_matches(kp1, kp2, desc1, desc1[order], H, SHAPE)
    assert (d.n_matches, d.n_correct) == (n, n - 10)
    assert d.corner_error_oracle < 1e-6 and d.corner_error_ransac < 1e-3
    few = diagnose_matches(kp1[:3], kp2[:3], np.eye(3), np.eye(3), H, SHAPE)  # 3 correct: no homography
    assert few.n_correct == 3 and few.corner_error_oracle == math.inf and few.corner_error_ransac == math.inf
    none = diagnose_matches(kp1[:5], kp2[:5] + 50.0, np.eye(5), np.eye(5), H, SHAPE)
    assert none.n_correct == 0 and math.isnan(none.localisation_error)


def test_diagnose_matches_bad_input():
    kp = grid_points()
    n = len(kp)
    with pytest.raises(ValueError, match="desc1/desc2 must have one row per keypoint"):
        diagnose_matches(kp, kp, np.eye(3), np.eye(3), np.eye(3), SHAPE)
    with pytest.raises(ValueError, match="eps must be a positive number"):
        diagnose_matches(kp, kp, np.eye(n), np.eye(n), np.eye(3), SHAPE, eps=0.0)
